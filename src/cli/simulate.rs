//! `cpm simulate`: a simulated measurement campaign (length-sensor readings or tracker pose
//! measurements), marked simulated in the file. The arguments and where the data are written;
//! the job is [`cpm_workflow::simulate::simulate`].
use std::path::PathBuf;

use clap::Args;

use super::common::{self, EffectsArg, PlanArgs, RobotArg};
use super::{usage_error, Ctx, Outcome};
use crate::output::Target;
pub use cpm_workflow::simulate::*;
pub use cpm_workflow::truth::{
    add_truth_effects, parse_truth_effect, truth_effect_for, MAX_TRUTH_COMPLIANCE, MAX_TRUTH_EFFECT,
};

/// Arguments of `cpm simulate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm simulate --robot examples/paper_cubic.toml --circle --paper-table2 --noise uniform:10 --out paper.csv\n  cpm simulate --robot examples/hexapod_66.toml --random 40 --truth examples/hexapod_66_truth.toml --effects link_offset --noise gaussian:2 --seed 7 --out data.csv\n  cpm simulate --robot examples/hexapod_66.toml --random 20 --truth examples/hexapod_66_truth.toml --noise gaussian:2 --seed 8 --out held_out.csv\n  cpm simulate --robot examples/hexapod_66.toml --random 30 --truth examples/hexapod_66_truth.toml --measure poses --out tracker.csv"
)]
pub struct SimulateArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// The plan: where the poses come from.
    #[command(flatten)]
    pub plan: PlanArgs,
    /// The true machine: a robot description whose geometry (joints plus
    /// `[installation_errors_um]`) and link reading models (length_at_zero_mm, mm_per_unit)
    /// differ from --robot's by the errors to simulate.
    #[arg(long, value_name = "TRUTH.toml", conflicts_with = "paper_table2")]
    pub truth: Option<PathBuf>,
    /// The paper's Table 2 as the true installation errors (six links).
    #[arg(long)]
    pub paper_table2: bool,
    /// True values of an effect, in its units, one per parameter (e.g.
    /// sensor_offset=12 or link_offset=5,0,-3,0,0,2); repeatable. The effect is simulated.
    #[arg(long, value_name = "EFFECT=V1,V2,..")]
    pub truth_effect: Vec<String>,
    /// The effects modelled.
    #[command(flatten)]
    pub effects: EffectsArg,
    /// Noise: none, uniform:HALF_WIDTH_UM or gaussian:SIGMA_UM (default: gaussian with the
    /// description's `[calibration] sensor_noise_um`, else none). For --measure poses and
    /// --measure points it is the noise of each position coordinate; for --measure tilts that
    /// of each angle, in urad.
    #[arg(long, value_name = "SPEC")]
    pub noise: Option<String>,
    /// Orientation noise of simulated tracker poses, urad (standard deviation per axis).
    #[arg(long, value_name = "URAD", default_value_t = 0.0)]
    pub orientation_noise_urad: f64,
    /// With `--measure poses` or `points`: the tracker's own frame, `x,y,z,roll,pitch,yaw` (mm, deg): the
    /// base frame's pose in the tracker's coordinates (`p_tracker = R p_base + t`, R = Rz Ry
    /// Rx). A motion-capture system set up anywhere; `cpm calibrate` registers it. Default:
    /// the base frame.
    #[arg(long, value_name = "X,Y,Z,ROLL,PITCH,YAW", allow_hyphen_values = true)]
    pub tracker_frame: Option<String>,
    /// With `--measure tilts`: the base's tilt against gravity in this session, rotations about
    /// x and y in degrees (`up = R up_0`). Default level.
    #[arg(long, value_name = "RX,RY", allow_hyphen_values = true)]
    pub base_tilt_deg: Option<String>,
    /// What to measure.
    #[arg(long, value_enum, default_value_t = Measure::Lengths)]
    pub measure: Measure,
    /// Output CSV file (`-`: stdout). Never a device, FIFO or an input file.
    #[arg(long, value_name = "DATA.csv")]
    pub out: PathBuf,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

impl SimulateArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> SimulateOptions {
        SimulateOptions {
            robot: self.robot.robot.clone(),
            plan: self.plan.options(),
            truth: self.truth.clone(),
            paper_table2: self.paper_table2,
            truth_effect: self.truth_effect.clone(),
            effects: self.effects.given(),
            noise: self.noise.clone(),
            orientation_noise_urad: self.orientation_noise_urad,
            tracker_frame: self.tracker_frame.clone(),
            base_tilt_deg: self.base_tilt_deg.clone(),
            measure: self.measure,
            out: Some(self.out.clone()),
        }
    }
}

/// Runs `cpm simulate`: the job, then the data written where asked.
pub fn run(args: &SimulateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let options = args.options();
    let inputs = options.inputs();
    if common::out_target("--out", &args.out, &inputs)? == Target::Stdout && args.json {
        return Err(usage_error(
            "--json needs --out FILE (the data would share stdout)",
        ));
    }
    let job = simulate(&options, &*ctx)?;
    ctx.stage("writing");
    ctx.finish();
    if common::write_out("--out", &args.out, &inputs, &job.text, ctx)? == Target::Stdout {
        ctx.note(format!(
            "SIMULATED: {} at {} poses written to standard output",
            job.measured(),
            job.campaign.poses.len()
        ));
        return Ok(Outcome::Done);
    }
    if args.json {
        writeln!(ctx.out, "{}", job.summary(&args.out).to_json())?;
    } else {
        writeln!(ctx.out, "{}", job.console_line(&args.out))?;
    }
    Ok(Outcome::Done)
}
