//! What the commands' arguments share: the robot and effects options, building a plan, and
//! single-file outputs; loading and the rest live in the workflow layer
//! ([`cpm_workflow::load`], re-exported here).
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;

use super::Ctx;
use crate::calib::Effect;
use crate::io::Robot;
use cpm_workflow::fit::{FitOptions, NoisePerKind, TrackerResiduals};
pub use cpm_workflow::load::*;
use cpm_workflow::options::{self, Group, Tolerance};

/// The robot description argument.
#[derive(Debug, Clone, Args)]
pub struct RobotArg {
    /// Robot description (TOML, docs/robot-description.md).
    #[arg(long, value_name = "ROBOT.toml")]
    pub robot: PathBuf,
}

/// Choice of the effects modelled beside the installation errors.
#[derive(Debug, Clone, Args)]
pub struct EffectsArg {
    /// Effects to model beside the 36 installation errors, comma-separated (e.g.
    /// link_offset,link_scale); overrides `[calibration] effects` of the robot description;
    /// `none` for none.
    #[arg(long, value_name = "LIST", value_parser = effects_value)]
    pub effects: Option<EffectList>,
}

/// A list of effects as one value of an option (`--effects`, `--candidates`): clap would take
/// an `Option<Vec<_>>` for an option given any number of times.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectList(pub Vec<Effect>);

/// `--effects`' value parser ([`options::parse_effects`]).
fn effects_value(list: &str) -> Result<EffectList, options::OptionError> {
    options::parse_effects(list).map(EffectList)
}

/// `--candidates`' value parser ([`options::parse_candidates`]).
pub fn candidate_list(list: &str) -> Result<EffectList, options::OptionError> {
    options::parse_candidates(list).map(EffectList)
}

impl EffectsArg {
    /// The effects given (`None`: the description's).
    pub fn given(&self) -> Option<Vec<Effect>> {
        self.effects.as_ref().map(|l| l.0.clone())
    }

    /// The effects: the command line's, else the description's.
    pub fn resolve(&self, robot: &Robot) -> anyhow::Result<Vec<Effect>> {
        resolve_effects(self.given().as_deref(), robot)
    }
}

/// Where the poses of a plan come from.
#[derive(Debug, Clone, Args)]
pub struct PlanArgs {
    /// Poses to visit: a CSV list of poses (x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg;
    /// docs/formats.md).
    #[arg(long, value_name = "POSES.csv")]
    pub plan: Option<PathBuf>,
    /// Poses on a circle about home in its xy plane at the home orientation (the paper's
    /// design); see --radius-mm and --count.
    #[arg(long)]
    pub circle: bool,
    /// N random poses about home, well conditioned and within the link limits; see
    /// --range-mm, --range-deg and --seed.
    #[arg(long, value_name = "N")]
    pub random: Option<usize>,
    /// Radius of --circle, mm.
    #[arg(long, value_name = "MM", default_value_t = 100.0)]
    pub radius_mm: f64,
    /// Number of poses of --circle.
    #[arg(long, value_name = "N", default_value_t = 36)]
    pub count: usize,
    /// Half range of the positions of --random about home, mm.
    #[arg(long, value_name = "MM", default_value_t = 50.0)]
    pub range_mm: f64,
    /// Half range of roll, pitch and yaw of --random about home, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 10.0)]
    pub range_deg: f64,
    /// Sensors read at every pose, comma-separated names (default: every sensor of the robot).
    #[arg(long, value_name = "NAMES", value_delimiter = ',')]
    pub sensors: Vec<String>,
    /// Random seed (for --random poses and simulated noise).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
}

impl PlanArgs {
    /// True when a plan source is given.
    pub fn given(&self) -> bool {
        self.plan.is_some() || self.circle || self.random.is_some()
    }

    /// The workflow's options of these arguments.
    pub fn options(&self) -> PlanOptions {
        PlanOptions {
            plan: self.plan.clone(),
            circle: self.circle,
            random: self.random,
            radius_mm: self.radius_mm,
            count: self.count,
            range_mm: self.range_mm,
            range_deg: self.range_deg,
            sensors: self.sensors.clone(),
            seed: self.seed,
        }
    }
}

pub use cpm_workflow::plan::{sensor_indices, PlanOptions, PlanSpec, MAX_PLAN_POSES};

/// Builds the plan of `--plan`, `--circle` or `--random` (exactly one must be given):
/// [`cpm_workflow::plan::build_plan`] of [`PlanArgs::options`].
pub fn build_plan(args: &PlanArgs, robot: &Robot, need_sensors: bool) -> anyhow::Result<PlanSpec> {
    cpm_workflow::plan::build_plan(&args.options(), robot, need_sensors)
}

/// Writes a single-file output to its checked target (re-checked now), atomically.
pub fn write_out(
    option: &str,
    path: &Path,
    inputs: &[&Path],
    contents: &str,
    ctx: &mut Ctx<'_>,
) -> anyhow::Result<crate::output::Target> {
    let target = out_target(option, path, inputs)?;
    match &target {
        crate::output::Target::Stdout => ctx.out.write_all(contents.as_bytes())?,
        crate::output::Target::File(p) => crate::output::write_file(p, contents.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?,
    }
    Ok(target)
}

/// The arguments every fit (`cpm calibrate`, `cpm refine`) takes.
#[derive(Debug, Clone, Args)]
pub struct FitArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Measurement files (length readings, tracker poses, reflector points or inclinometer angles; docs/formats.md); repeatable.
    #[arg(long, value_name = "DATA.csv", required = true)]
    pub data: Vec<PathBuf>,
    /// The effects modelled.
    #[command(flatten)]
    pub effects: EffectsArg,
    /// Sensor noise standard deviation, um (default: `[calibration] sensor_noise_um` of the
    /// description, else estimated from the residual).
    #[arg(long, value_name = "UM")]
    pub sigma_um: Option<f64>,
    /// Tracker position noise, um (standard deviation per coordinate, of pose measurements and
    /// of point targets; default cpm-calib's).
    #[arg(long, value_name = "UM")]
    pub pose_sigma_um: Option<f64>,
    /// Tracker orientation noise, urad, and the noise of an inclinometer angle (default
    /// cpm-calib's).
    #[arg(long, value_name = "URAD")]
    pub orientation_sigma_urad: Option<f64>,
    /// Robust loss against outlier readings: huber:K, cauchy:K or tukey:K with K in um of
    /// reading (where the loss departs from the square; e.g. 3 x the noise), or none (least
    /// squares, the default). Readings more than 5 robust standard deviations off are
    /// flagged in report.md and calibration.json either way.
    #[arg(long, value_name = "LOSS:K", value_parser = options::parse_loss)]
    pub robust: Option<crate::lm::Loss>,
    /// Fit the gross outliers too. By default a least-squares fit sets the observations more
    /// than 10 robust standard deviations off (per kind of observation) aside, continues
    /// without them and lists them under "Outliers" (one glitch in a log never drags the
    /// machine); with a robust loss they are down-weighted instead.
    #[arg(long)]
    pub keep_outliers: bool,
    /// Most iterations of the least-squares solver per fit (default 1000); a fit stopped by
    /// it has not converged (exit code 1, the outputs say so).
    #[arg(long, value_name = "N")]
    pub max_iterations: Option<usize>,
    /// Output directory (created; existing files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
    /// Weigh each kind of observation whose noise is not declared (the gauges, tracker
    /// positions, tracker orientations, point targets, inclinometer angles) by the noise its
    /// own residual shows, estimated per kind and never pooled (variance components,
    /// iterated; cpm_calib::noise): `auto` (the default) does so whenever the data hold two
    /// or more kinds and one of them has no declared noise; `on` (or the bare flag) always;
    /// `off` weighs undeclared kinds by cpm-calib's defaults (10 um, 20 urad) and estimates
    /// one common scale. The estimates are written to calibrated.toml's `[calibration]` for
    /// the tracker kinds, so validate weighs as the fit did.
    #[arg(
        long,
        value_enum,
        num_args = 0..=1,
        default_value_t = NoisePerKind::Auto,
        default_missing_value = "on",
        value_name = "auto|on|off"
    )]
    pub noise_per_kind: NoisePerKind,
    /// A-priori tolerance of a group of parameters, GROUP=VALUE in the group's unit
    /// (`installation_errors=2000` um, `link_scale=50000` ppm, `compliance=...` um/kN, `inf`
    /// frees the group); repeatable. A direction the data see less well than its tolerance
    /// is held near nominal and named in the report (a maximum a posteriori fit; see
    /// docs/estimation.md). Default: `[calibration.tolerances]` of the description, else
    /// cpm-calib's defaults scaled to the machine.
    #[arg(long = "tolerance", value_name = "GROUP=VALUE", value_parser = options::parse_tolerance)]
    pub tolerance: Vec<Tolerance>,
    /// Groups of parameters held at nominal and not fitted (comma-separated group names,
    /// e.g. `installation_errors` to fit only the effects). Default: `[calibration] hold`.
    #[arg(long, value_delimiter = ',', value_name = "GROUP")]
    pub hold: Vec<Group>,
    /// No prior: the plain least-squares fit in every direction the data see at all (the fit
    /// may then run off along directions the noise hides).
    #[arg(long)]
    pub no_prior: bool,
    /// Tolerances an undetermined parameter may reach: one the data pull further is held
    /// there, named in the report, and the fit repeated (`inf`: no limit). Default:
    /// `[calibration] tolerance_limit` of the description, else 1 (docs/estimation.md).
    #[arg(long, value_name = "N")]
    pub tolerance_limit: Option<f64>,
    /// Residuals of 6-D tracker poses: `pose` (position and orientation), `legs` (each link's
    /// length against the length the joints need for the measured pose: the
    /// inverse-kinematics formulation), or `auto` (the default: whichever predicts held-out
    /// poses better, judged by cross-validation in acquisition order; the report says which).
    #[arg(long, value_enum, default_value_t = TrackerResiduals::Auto)]
    pub tracker_residuals: TrackerResiduals,
}

impl FitArgs {
    /// The workflow's options of these arguments.
    pub fn options(&self) -> FitOptions {
        FitOptions {
            robot: self.robot.robot.clone(),
            data: self.data.clone(),
            effects: self.effects.given(),
            sigma_um: self.sigma_um,
            pose_sigma_um: self.pose_sigma_um,
            orientation_sigma_urad: self.orientation_sigma_urad,
            robust: self.robust,
            keep_outliers: self.keep_outliers,
            max_iterations: self.max_iterations,
            out: self.out.clone(),
            noise_per_kind: self.noise_per_kind,
            tolerance: self.tolerance.clone(),
            hold: self.hold.clone(),
            no_prior: self.no_prior,
            tolerance_limit: self.tolerance_limit,
            tracker_residuals: self.tracker_residuals,
        }
    }

    /// Checks the options, then loads and checks the robot, the effects and the data
    /// ([`FitOptions::load`]).
    pub fn load(&self, ctx: &Ctx<'_>) -> anyhow::Result<Inputs> {
        self.options().load(ctx)
    }

    /// The input files (an output may not replace one).
    pub fn input_paths(&self) -> Vec<&Path> {
        std::iter::once(self.robot.robot.as_path())
            .chain(self.data.iter().map(PathBuf::as_path))
            .collect()
    }
}
