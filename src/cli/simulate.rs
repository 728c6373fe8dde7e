//! `cpm simulate`: a simulated measurement campaign (length-sensor readings or tracker pose
//! measurements), marked simulated in the file.
use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::common::{self, EffectsArg, PlanArgs, RobotArg};
use super::{input_error, usage_error, Ctx, Outcome};
use crate::calib::simulate::{
    simulate_inclinometer_angles, simulate_tracker_points, simulate_tracker_poses,
    unsupported_machine_effect, TrackerSimulation,
};
use crate::calib::{simulate_campaign, Campaign, Effect, Noise, SimulationOptions};
use crate::geometry::{InstallationErrors, Pose};
use crate::io::{self, Robot};
use crate::output::Target;

/// What the simulated campaign measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Measure {
    /// Length-sensor readings (every plan sensor at every pose).
    Lengths,
    /// Tracker pose measurements with the commanded link readings.
    Poses,
    /// Laser-tracker points of the description's `[[target]]`s (reflectors on the platform),
    /// every target at every pose, with the commanded link readings and pose.
    Points,
    /// Inclinometer angles of the description's `[[inclinometer]]`s (every axis of every
    /// instrument at every pose), with the commanded link readings and pose.
    Tilts,
}

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

/// The largest simulated noise, um.
pub const MAX_NOISE_UM: f64 = 1000.0;

/// The largest simulated angle noise (inclinometers), urad: 0.1 rad, 5.7 deg.
pub const MAX_NOISE_URAD: f64 = 1e5;

/// Parses a noise specification (um).
pub fn parse_noise(spec: &str) -> Result<Noise, String> {
    parse_noise_in(spec, "um", MAX_NOISE_UM, "1 mm")
}

/// Parses a noise specification in an instrument's unit (`um`, or `urad` for angles), with
/// its largest plausible value (and that value in words).
pub fn parse_noise_in(spec: &str, unit: &str, max: f64, max_words: &str) -> Result<Noise, String> {
    let spec = spec.trim();
    if spec == "none" {
        return Ok(Noise::None);
    }
    let (kind, value) = spec.split_once(':').ok_or_else(|| {
        format!("{spec:?}: expected none, uniform:HALF_WIDTH_UM or gaussian:SIGMA_UM")
    })?;
    let v: f64 = value
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v >= 0.0)
        .ok_or_else(|| format!("{spec:?}: {value:?} is not a non-negative number of {unit}"))?;
    if v > max {
        return Err(format!(
            "{spec:?}: {} {unit} is implausibly large (over {} {unit} = {max_words}; the noise is in {unit})",
            crate::io::table::show(v, None),
            crate::io::table::show(max, None)
        ));
    }
    match kind.trim() {
        "uniform" => Ok(Noise::Uniform { half_width_um: v }),
        "gaussian" | "normal" => Ok(Noise::Gaussian { sigma_um: v }),
        other => Err(format!(
            "{spec:?}: unknown noise kind {other:?} (none, uniform, gaussian)"
        )),
    }
}

/// The noise in words, e.g. `gaussian 1 um`, `uniform +-10 um`.
pub fn describe_noise(noise: &Noise) -> String {
    match noise {
        Noise::None => "none".into(),
        Noise::Uniform { half_width_um } => format!("uniform +-{half_width_um} um"),
        Noise::Gaussian { sigma_um } => format!("gaussian {sigma_um} um"),
    }
}

/// A simulation that fails with `--truth-effect` values given is a bad option value (exit 2,
/// naming the option); otherwise the error as it is.
fn blame_truth(args: &SimulateArgs, e: impl Into<anyhow::Error>) -> anyhow::Error {
    let e = e.into();
    if args.truth_effect.is_empty() {
        e
    } else {
        usage_error(format!(
            "--truth-effect {}: the machine with these values cannot be simulated: {}",
            args.truth_effect.join(" --truth-effect "),
            super::render_error(&e)
        ))
    }
}

pub use cpm_workflow::truth::{
    add_truth_effects, parse_truth_effect, truth_effect_for, MAX_TRUTH_COMPLIANCE, MAX_TRUTH_EFFECT,
};

/// The truth: model effects and the full true parameter vector.
struct Truth {
    effects: Vec<Effect>,
    params: Vec<f64>,
    what: String,
    /// The true platform position of each of the robot's `[[target]]`s, mm (the truth's
    /// target of the same name, else the robot's).
    targets: Vec<nalgebra::Vector3<f64>>,
    /// Each of the robot's `[[inclinometer]]`s as it really is (the truth's of the same name,
    /// its axes and mount, else the robot's).
    inclinometers: Vec<crate::calib::tilts::Inclinometer>,
}

fn truth(args: &SimulateArgs, robot: &Robot, declared: Vec<Effect>) -> anyhow::Result<Truth> {
    let n = robot.num_links();
    let mut effects = declared;
    let mut installation = vec![0.0; 6 * n];
    let mut values: Vec<(Effect, Vec<f64>)> = Vec::new();
    let mut what = "zero installation errors (nominal machine)".to_string();
    let mut targets: Vec<nalgebra::Vector3<f64>> = robot
        .description
        .targets
        .iter()
        .map(|t| t.platform_mm.into())
        .collect();
    let mut inclinometers: Vec<crate::calib::tilts::Inclinometer> = robot
        .description
        .inclinometers
        .iter()
        .map(crate::calib::tilts::Inclinometer::from_spec)
        .collect();
    if args.paper_table2 {
        if n != 6 {
            return Err(usage_error(format!(
                "--paper-table2 needs a six-link robot; {} has {n} links",
                robot.file
            )));
        }
        installation = InstallationErrors::paper_table2().to_vec_um();
        what = "the paper's Table 2".into();
    }
    if let Some(path) = &args.truth {
        let t = Robot::load(path)?;
        for (k, spec) in robot.description.inclinometers.iter().enumerate() {
            if let Some(tc) = t
                .description
                .inclinometers
                .iter()
                .find(|x| x.name == spec.name)
            {
                inclinometers[k] = crate::calib::tilts::Inclinometer::from_spec(tc);
            }
        }
        for (k, spec) in robot.description.targets.iter().enumerate() {
            if let Some(tt) = t.description.targets.iter().find(|x| x.name == spec.name) {
                targets[k] = tt.platform_mm.into();
            }
        }
        let diff = io::robot::truth_from_description(robot, &t)
            .map_err(|m| input_error(format!("{}: {m}", t.file)))?;
        installation = diff.installation_um.clone();
        if diff.has_link_terms() {
            values.push((Effect::LinkOffset, diff.link_offset_um.clone()));
            values.push((Effect::LinkScale, diff.link_scale_ppm.clone()));
        }
        // The truth's sensor sockets (its [[sensor]] tables, matched by name) where they
        // differ from the robot's: simulated as socket errors, so the readings are the
        // truth's. A robot sensor the truth does not declare keeps the robot's sockets.
        let sockets: Vec<f64> = robot
            .table
            .sensors
            .iter()
            .flat_map(
                |b| match t.table.sensors.iter().find(|a| a.name == b.name) {
                    Some(a) => {
                        let (db, dp) = (a.base_mm - b.base_mm, a.platform_mm - b.platform_mm);
                        [db.x, db.y, db.z, dp.x, dp.y, dp.z].map(|v| v * 1e3)
                    }
                    None => [0.0; 6],
                },
            )
            .collect();
        if sockets.iter().any(|v| *v != 0.0) {
            values.push((Effect::SocketError, sockets));
        }
        // Known effect values of the truth beyond those of the robot are simulated too.
        let (robot_model, truth_model) = (robot.model(&[]), t.model(&[]));
        let mut known = Vec::new();
        // The library and any other effect (a pose map term) either description knows.
        let mut library = Effect::ALL.to_vec();
        for k in truth_model
            .known_effects
            .iter()
            .chain(&robot_model.known_effects)
        {
            if !library.contains(&k.effect) {
                library.push(k.effect);
            }
        }
        for e in library {
            let (a, b) = (truth_model.known(e), robot_model.known(e));
            if a.is_none() && b.is_none() {
                continue;
            }
            let need = e.num_params(n, robot.table.sensors.len());
            if a.is_some_and(|a| a.len() != need) {
                return Err(input_error(format!(
                    "{}: [calibration.known_effects] {e} has {} values, the robot {need} parameters (sensors differ?)",
                    t.file,
                    a.map_or(0, |a| a.len())
                )));
            }
            let v: Vec<f64> = (0..need)
                .map(|k| a.map_or(0.0, |a| a[k]) - b.map_or(0.0, |b| b[k]))
                .collect();
            if v.iter().any(|x| *x != 0.0) {
                if values.iter().any(|(x, _)| *x == e) {
                    return Err(input_error(format!(
                        "{}: [calibration.known_effects] {e} adds to the link reading models' difference; give one or the other",
                        t.file
                    )));
                }
                known.push(e.name());
                values.push((e, v));
            }
        }
        what = if known.is_empty() {
            format!("{} (its geometry and link reading models)", t.file)
        } else {
            format!(
                "{} (its geometry, link reading models and known {})",
                t.file,
                known.join(", ")
            )
        };
    }
    for s in &args.truth_effect {
        let (e, v) = truth_effect_for(s, robot)?;
        values.retain(|(x, _)| *x != e);
        values.push((e, v));
    }
    if !args.truth_effect.is_empty() {
        // Provenance: the header says which effects were simulated, with their values.
        what = format!(
            "{what}, plus --truth-effect {}",
            args.truth_effect.join(" --truth-effect ")
        );
    }
    for (e, _) in &values {
        if !effects.contains(e) {
            effects.push(*e);
        }
    }
    let model = robot.model(&effects);
    let mut params = installation;
    params.resize(model.num_params(), 0.0);
    for b in model.blocks() {
        if let Some(e) = b.effect {
            if let Some((_, v)) = values.iter().find(|(x, _)| *x == e) {
                params[b.offset..b.offset + b.len].copy_from_slice(v);
            }
        }
    }
    Ok(Truth {
        effects,
        params,
        what,
        targets,
        inclinometers,
    })
}

/// The tracker (position noise, orientation noise, seed, frame) of `cpm simulate`.
fn tracker(
    noise: &Noise,
    orientation_urad: f64,
    seed: u64,
    frame: Option<Pose>,
) -> TrackerSimulation {
    TrackerSimulation {
        position: *noise,
        orientation_sigma_urad: orientation_urad,
        seed,
        frame,
    }
}

/// Refuses a truth the true machine of [`simulate_tracker_points`] and
/// [`simulate_inclinometer_angles`] cannot act out (effects other than link offsets and
/// scales with nonzero values).
fn machine_truth(robot: &Robot, truth: &Truth, what: &str) -> anyhow::Result<()> {
    let model = robot.model(&truth.effects);
    match unsupported_machine_effect(&model, &truth.params) {
        Some(e) => Err(usage_error(format!(
            "--measure {what} simulates installation errors, link_offset, link_scale and compliance; the truth has {} values",
            e.name()
        ))),
        None => Ok(()),
    }
}

/// Laser-tracker points of every `[[target]]` at each of `poses` on the true machine
/// ([`simulate_tracker_points`]), in the tracker's frame `frame` (default: the base frame).
fn simulate_points(
    robot: &Robot,
    truth: &Truth,
    poses: &[Pose],
    noise: &Noise,
    seed: u64,
    frame: Option<Pose>,
) -> anyhow::Result<Campaign> {
    if truth.targets.is_empty() {
        return Err(usage_error(format!(
            "--measure points needs [[target]] tables (name, platform_mm) in {}",
            robot.file
        )));
    }
    machine_truth(robot, truth, "points")?;
    let model = robot.model(&truth.effects);
    let tracker = tracker(noise, 0.0, seed, frame);
    Ok(simulate_tracker_points(
        &model,
        &truth.params,
        &truth.targets,
        poses,
        &tracker,
    )?)
}

/// Inclinometer angles of every `[[inclinometer]]` axis at each of `poses` on the true machine
/// ([`simulate_inclinometer_angles`]), gravity's up tilted by `base_tilt` (rad about x and y).
fn simulate_tilts(
    robot: &Robot,
    truth: &Truth,
    poses: &[Pose],
    noise: &Noise,
    seed: u64,
    base_tilt: [f64; 2],
) -> anyhow::Result<Campaign> {
    if truth.inclinometers.is_empty() {
        return Err(usage_error(format!(
            "--measure tilts needs [[inclinometer]] tables (name, axes) in {}",
            robot.file
        )));
    }
    machine_truth(robot, truth, "tilts")?;
    let model = robot.model(&truth.effects);
    Ok(simulate_inclinometer_angles(
        &model,
        &truth.params,
        &truth.inclinometers,
        poses,
        *noise,
        seed,
        base_tilt,
    )?)
}

/// Runs `cpm simulate`.
pub fn run(args: &SimulateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let inputs: Vec<&std::path::Path> = std::iter::once(args.robot.robot.as_path())
        .chain(args.truth.as_deref())
        .chain(args.plan.plan.as_deref())
        .collect();
    if common::out_target("--out", &args.out, &inputs)? == Target::Stdout && args.json {
        return Err(usage_error(
            "--json needs --out FILE (the data would share stdout)",
        ));
    }
    ctx.stage("reading the robot description");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    let declared = args.effects.resolve(&robot)?;
    let noise = match &args.noise {
        Some(s) if args.measure == Measure::Tilts => {
            parse_noise_in(s, "urad", MAX_NOISE_URAD, "5.7 deg")
                .map_err(|m| usage_error(format!("--noise {m}")))?
        }
        Some(s) => parse_noise(s).map_err(|m| usage_error(format!("--noise {m}")))?,
        None => match robot.sensor_noise_um() {
            Some(s) => Noise::Gaussian { sigma_um: s },
            None => Noise::None,
        },
    };
    if !(args.orientation_noise_urad.is_finite()
        && (0.0..=1e5).contains(&args.orientation_noise_urad))
    {
        return Err(usage_error(
            "--orientation-noise-urad must be between 0 and 100000 (0.1 rad)",
        ));
    }
    let tracker_frame = match &args.tracker_frame {
        None => None,
        Some(spec) => {
            if args.measure == Measure::Lengths {
                return Err(usage_error(
                    "--tracker-frame needs --measure poses or --measure points",
                ));
            }
            let v: Vec<f64> = spec
                .split(',')
                .map(|x| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect::<Option<Vec<f64>>>()
                .filter(|v| v.len() == 6)
                .ok_or_else(|| {
                    usage_error(format!(
                        "--tracker-frame {spec:?}: expected six numbers x,y,z,roll,pitch,yaw (mm, deg)"
                    ))
                })?;
            if v[..3].iter().any(|x| x.abs() > 1e5) || v[3..].iter().any(|x| x.abs() > 360.0) {
                return Err(usage_error(format!(
                    "--tracker-frame {spec:?}: at most 100 m and 360 deg"
                )));
            }
            Some(Pose::from_xyz_rpy_deg(
                [v[0], v[1], v[2]],
                [v[3], v[4], v[5]],
            ))
        }
    };
    let base_tilt = match &args.base_tilt_deg {
        None => [0.0; 2],
        Some(spec) => {
            if args.measure != Measure::Tilts {
                return Err(usage_error("--base-tilt-deg needs --measure tilts"));
            }
            let v: Vec<f64> = spec
                .split(',')
                .map(|x| x.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect::<Option<Vec<f64>>>()
                .filter(|v| v.len() == 2 && v.iter().all(|a| a.abs() <= 10.0))
                .ok_or_else(|| {
                    usage_error(format!(
                        "--base-tilt-deg {spec:?}: expected two angles RX,RY in degrees, each within 10"
                    ))
                })?;
            [v[0].to_radians(), v[1].to_radians()]
        }
    };
    let truth = truth(args, &robot, declared)?;
    ctx.stage("building the plan");
    let spec = common::build_plan(&args.plan, &robot, args.measure == Measure::Lengths)?;
    ctx.stage(format!("simulating {} poses", spec.plan.poses.len()));
    // Inclinometer noise is in urad.
    let noise_words = match args.measure {
        Measure::Tilts => describe_noise(&noise).replace(" um", " urad"),
        _ => describe_noise(&noise),
    };
    let note = format!(
        "robot {}, truth {}, noise {}, seed {}",
        robot.file, truth.what, noise_words, args.plan.seed
    );
    let (campaign, text) = match args.measure {
        Measure::Lengths => {
            let model = robot.model(&truth.effects);
            let options = SimulationOptions {
                noise,
                repeats: 1,
                seed: args.plan.seed,
            };
            let skeleton = spec.skeleton();
            let c = simulate_campaign(&model, &truth.params, &skeleton, &options)
                .map_err(|e| blame_truth(args, e))?;
            let text = io::write_readings(&c, &robot, &note);
            (c, text)
        }
        Measure::Poses => {
            let tracker = tracker(
                &noise,
                args.orientation_noise_urad,
                args.plan.seed,
                tracker_frame,
            );
            // Through the prediction path the fit uses: every effect of the truth acts as
            // `calibrate` and `validate` model it.
            let c = simulate_tracker_poses(
                &robot.model(&truth.effects),
                &truth.params,
                &spec.plan.poses,
                &spec.conditions,
                &tracker,
            )
            .map_err(|e| blame_truth(args, e))?;
            let text = io::write_pose_measurements(&c, &robot, &note);
            (c, text)
        }
        Measure::Points => {
            let mut c = simulate_points(
                &robot,
                &truth,
                &spec.plan.poses,
                &noise,
                args.plan.seed,
                tracker_frame,
            )
            .map_err(|e| blame_truth(args, e))?;
            for m in c.point_measurements.iter_mut() {
                m.time_s = spec.conditions.get(m.pose).and_then(|(t, _)| *t);
            }
            let text = io::points::write_point_measurements(&c, &robot, &note);
            (c, text)
        }
        Measure::Tilts => {
            let mut c = simulate_tilts(
                &robot,
                &truth,
                &spec.plan.poses,
                &noise,
                args.plan.seed,
                base_tilt,
            )
            .map_err(|e| blame_truth(args, e))?;
            for m in c.tilt_measurements.iter_mut() {
                m.time_s = spec.conditions.get(m.pose).and_then(|(t, _)| *t);
            }
            let text = io::points::write_tilt_measurements(&c, &robot, &note);
            (c, text)
        }
    };
    ctx.stage("writing");
    ctx.finish();
    let measured = if !campaign.tilt_measurements.is_empty() {
        format!(
            "{} inclinometer angles of {} inclinometers",
            campaign.tilt_measurements.len(),
            robot.description.inclinometers.len()
        )
    } else if campaign.point_measurements.is_empty() {
        format!(
            "{} readings and {} pose measurements",
            campaign.readings.len(),
            campaign.pose_measurements.len()
        )
    } else {
        format!(
            "{} point measurements of {} targets",
            campaign.point_measurements.len(),
            robot.description.targets.len()
        )
    };
    if common::write_out("--out", &args.out, &inputs, &text, ctx)? == Target::Stdout {
        ctx.note(format!(
            "SIMULATED: {measured} at {} poses written to standard output",
            campaign.poses.len()
        ));
        return Ok(Outcome::Done);
    }
    if args.json {
        let summary = crate::report::commands::SimulateSummary {
            effects: truth.effects.iter().map(|e| e.name().to_string()).collect(),
            measure: format!("{:?}", args.measure).to_lowercase(),
            noise: noise_words.clone(),
            out: args.out.display().to_string(),
            point_measurements: campaign.point_measurements.len(),
            pose_measurements: campaign.pose_measurements.len(),
            poses: campaign.poses.len(),
            readings: campaign.readings.len(),
            seed: args.plan.seed,
            simulated: true,
            tilt_measurements: campaign.tilt_measurements.len(),
            truth: truth.what.clone(),
        };
        writeln!(ctx.out, "{}", summary.to_json())?;
    } else {
        writeln!(
            ctx.out,
            "SIMULATED: {measured} at {} poses (truth: {}; noise {}; seed {}) -> {}",
            campaign.poses.len(),
            truth.what,
            noise_words,
            args.plan.seed,
            args.out.display()
        )?;
    }
    Ok(Outcome::Done)
}
