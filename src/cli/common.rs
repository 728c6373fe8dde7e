//! What the commands share: loading the robot and the data, choosing the effects, building a
//! plan, the output directory, and locating solver failures in the input files.
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;

use super::{input_error, usage_error, Ctx};
use crate::calib::{campaign::circle, CalibError, Effect, MeasurementModel, Plan};
use crate::io::{self, merge, Merged, ReadOptions, Robot};

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
    #[arg(long, value_name = "LIST")]
    pub effects: Option<String>,
}

impl EffectsArg {
    /// The effects: the command line's, else the description's.
    pub fn resolve(&self, robot: &Robot) -> anyhow::Result<Vec<Effect>> {
        match self.effects.as_deref().map(str::trim) {
            Some("none") | Some("") => Ok(Vec::new()),
            Some(list) => {
                io::parse_effects(list).map_err(|m| usage_error(format!("--effects: {m}")))
            }
            None => Ok(robot.declared_effects()?),
        }
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
}

/// A plan with per-pose time and temperature (from a plan file).
#[derive(Debug, Clone)]
pub struct PlanSpec {
    /// The plan.
    pub plan: Plan,
    /// Per pose: time (s) and temperature (deg C) when the plan file gives them.
    pub conditions: Vec<(Option<f64>, Option<f64>)>,
}

impl PlanSpec {
    /// The plan's campaign skeleton, with the plan file's times and temperatures.
    pub fn skeleton(&self) -> crate::calib::Campaign {
        let mut c = self.plan.skeleton();
        for r in c.readings.iter_mut() {
            let (t, temp) = self.conditions[r.pose];
            r.time_s = t;
            r.temperature_c = temp;
        }
        c
    }
}

/// The sensors of `--sensors` (all when empty) as indices.
pub fn sensor_indices(names: &[String], robot: &Robot) -> anyhow::Result<Vec<usize>> {
    if robot.table.sensors.is_empty() {
        return Err(input_error(format!(
            "{}: the robot description has no [[sensor]]: nothing to read",
            robot.file
        )));
    }
    if names.is_empty() {
        return Ok((0..robot.table.sensors.len()).collect());
    }
    names
        .iter()
        .map(|n| {
            robot.table.sensor_index(n.trim()).ok_or_else(|| {
                usage_error(format!(
                    "--sensors: unknown sensor {:?} (the robot description has: {})",
                    n.trim(),
                    robot.sensor_names()
                ))
            })
        })
        .collect()
}

/// Builds the plan of `--plan`, `--circle` or `--random` (exactly one must be given).
pub fn build_plan(args: &PlanArgs, robot: &Robot, need_sensors: bool) -> anyhow::Result<PlanSpec> {
    let given = [args.plan.is_some(), args.circle, args.random.is_some()]
        .iter()
        .filter(|g| **g)
        .count();
    if given != 1 {
        return Err(usage_error(
            "give the poses with exactly one of --plan FILE, --circle or --random N",
        ));
    }
    let sensors = if need_sensors {
        sensor_indices(&args.sensors, robot)?
    } else {
        Vec::new()
    };
    let table = &robot.table;
    let ratio = ReadOptions::default().max_condition_ratio;
    for (n, name) in [
        (args.random.unwrap_or(0), "--random"),
        (if args.circle { args.count } else { 0 }, "--count"),
    ] {
        if n > MAX_PLAN_POSES {
            return Err(usage_error(format!(
                "{name} {n}: at most {MAX_PLAN_POSES} poses"
            )));
        }
    }
    if let Some(path) = &args.plan {
        let file = path.display().to_string();
        let rows = io::read_pose_list_file(path)?;
        io::campaign::check_pose_list_units(&rows, &file, robot)?;
        for r in &rows {
            io::campaign::check_reachable(table, &r.pose, ratio, &file, r.line, &r.label)?;
        }
        let poses: Vec<_> = rows.iter().map(|r| r.pose).collect();
        super::gauges::check_plan(robot, &sensors, &poses, &|k| (file.clone(), rows[k].line))?;
        return Ok(PlanSpec {
            conditions: rows.iter().map(|r| (r.time_s, r.temperature_c)).collect(),
            plan: Plan {
                poses: rows.iter().map(|r| r.pose).collect(),
                sensors,
            },
        });
    }
    let poses = if args.circle {
        if !(args.radius_mm.is_finite() && args.radius_mm >= 0.0) || args.count == 0 {
            return Err(usage_error(
                "--circle needs --radius-mm >= 0 and --count >= 1",
            ));
        }
        let poses = circle(&table.home, args.radius_mm, args.count);
        for (k, p) in poses.iter().enumerate() {
            io::campaign::check_reachable(table, p, ratio, "--circle", k + 1, &(k + 1).to_string())
                .map_err(|e| usage_error(format!("{}; try a smaller --radius-mm", e.message)))?;
        }
        poses
    } else {
        let n = args.random.unwrap_or(0);
        if n == 0
            || !(args.range_mm >= 0.0 && args.range_deg >= 0.0)
            || !(args.range_mm.is_finite() && args.range_deg.is_finite())
        {
            return Err(usage_error(
                "--random needs N >= 1 and finite, non-negative --range-mm, --range-deg",
            ));
        }
        let poses = crate::calib::paper::random_workspace_poses(
            table,
            n,
            args.range_mm,
            args.range_deg,
            3.0,
            args.seed,
        );
        if poses.len() < n {
            return Err(usage_error(format!(
                "--random: found only {} of {n} well-conditioned poses within the link limits; try a smaller --range-mm or --range-deg",
                poses.len()
            )));
        }
        poses
    };
    let how = if args.circle { "--circle" } else { "--random" };
    super::gauges::check_plan(robot, &sensors, &poses, &|k| (how.to_string(), k + 1))
        .map_err(|e| usage_error(e.to_string()))?;
    Ok(PlanSpec {
        conditions: vec![(None, None); poses.len()],
        plan: Plan { poses, sensors },
    })
}

/// `file` as a path relative to the directory `dir` (which need not exist yet), through
/// `..` where needed; `file` made absolute when the two share no root.
pub fn relative_to_dir(file: &Path, dir: &Path) -> PathBuf {
    let absolute = |p: &Path| -> Option<PathBuf> {
        if let Ok(c) = std::fs::canonicalize(p) {
            return Some(c);
        }
        let parent = p.parent().filter(|q| !q.as_os_str().is_empty());
        let parent = std::fs::canonicalize(parent.unwrap_or(Path::new("."))).ok()?;
        Some(parent.join(p.file_name()?))
    };
    let (Some(f), Some(d)) = (absolute(file), absolute(dir)) else {
        return file.to_path_buf();
    };
    let (fc, dc): (Vec<_>, Vec<_>) = (f.components().collect(), d.components().collect());
    let common = fc.iter().zip(&dc).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return f;
    }
    let mut rel = PathBuf::new();
    for _ in common..dc.len() {
        rel.push("..");
    }
    for c in &fc[common..] {
        rel.push(c);
    }
    rel
}

/// Loads the robot description.
pub fn load_robot(path: &Path, ctx: &Ctx<'_>) -> anyhow::Result<Robot> {
    let robot = Robot::load(path)?;
    // A calibration result (`calibrated.toml`, which records `calibrated_from`) is the joints
    // plus the errors by design: said once, in its header. Another description with errors
    // written in (a simulation truth used as the nominal robot, say) is worth a note.
    let calibrated = robot
        .description
        .calibration
        .as_ref()
        .is_some_and(|c| c.calibrated_from.is_some());
    if robot.errors_applied && !calibrated {
        ctx.note(format!(
            "{} has [installation_errors_um]: its geometry is the joints plus those errors",
            robot.file
        ));
    }
    Ok(robot)
}

/// Checks that the robot has six links (what the identification handles).
pub fn require_six_links(robot: &Robot) -> anyhow::Result<()> {
    if robot.num_links() != 6 {
        return Err(input_error(format!(
            "{}: has {} links; calibration in cpm handles six-link machines",
            robot.file,
            robot.num_links()
        )));
    }
    Ok(())
}

/// Reads and merges measurement files.
pub fn load_data(
    paths: &[PathBuf],
    robot: &Robot,
    options: &ReadOptions,
) -> anyhow::Result<Merged> {
    let files = io::read_data_files(paths, robot, options)?;
    let merged = merge(files, robot);
    if options.check_sensor_lengths {
        super::gauges::check_readings(robot, &merged)?;
    }
    Ok(merged)
}

/// Warns on stderr (`warning: FILE:LINE: pose "LABEL" excluded: REASON`) of each pose left
/// out of the data (see [`io::campaign::POSES_PER_EXCLUDED_POSE`]).
pub fn warn_excluded(ctx: &super::Ctx<'_>, excluded: &[io::ExcludedPose]) {
    for e in excluded {
        ctx.status(format!("warning: {e}"));
    }
}

/// Read options for a model: sensor lengths are checked unless `sensor_offset` is modelled;
/// tracker files are registered with the model's known `tracker_frame` taken out.
pub fn read_options(model: &MeasurementModel) -> ReadOptions {
    ReadOptions {
        check_sensor_lengths: !model.effects.contains(&Effect::SensorOffset),
        known_tracker_frame: model
            .known(Effect::TrackerFrame)
            .and_then(|q| <[f64; 6]>::try_from(q).ok()),
        ..ReadOptions::default()
    }
}

/// The campaign pose a calibration error is about, also when the least-squares solver
/// stopped on it (the model's error inside [`cpm_lm::LmError::Model`]).
pub fn error_pose(err: &CalibError) -> Option<usize> {
    match err {
        CalibError::Kinematics { pose, .. } | CalibError::Clearance { pose, .. } => Some(*pose),
        CalibError::Solver(cpm_lm::LmError::Model { source, .. }) => {
            source.downcast_ref::<CalibError>().and_then(error_pose)
        }
        _ => None,
    }
}

/// Turns a calibration error at a campaign pose into one that names the file and line.
pub fn locate(err: CalibError, merged: &Merged) -> anyhow::Error {
    match error_pose(&err).and_then(|p| merged.pose_location(p)) {
        Some(loc) => anyhow::Error::new(err).context(loc),
        None => anyhow::Error::new(err),
    }
}

/// The largest number of poses of `--circle --count` and `--random`.
pub const MAX_PLAN_POSES: usize = 1_000_000;

/// A robust loss from `huber:K`, `cauchy:K`, `tukey:K` (K in um of reading, > 0) or `none`.
pub fn parse_loss(spec: &str) -> Result<cpm_lm::Loss, String> {
    let spec = spec.trim();
    if spec == "none" || spec == "squared" {
        return Ok(cpm_lm::Loss::Squared);
    }
    let (kind, value) = spec.split_once(':').ok_or_else(|| {
        format!("{spec:?}: expected huber:K, cauchy:K or tukey:K (K in um, > 0) or none")
    })?;
    let k: f64 = value
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v > 0.0)
        .ok_or_else(|| format!("{spec:?}: K = {value:?} must be a number of um > 0"))?;
    match kind.trim() {
        "huber" => Ok(cpm_lm::Loss::Huber(k)),
        "cauchy" => Ok(cpm_lm::Loss::Cauchy(k)),
        "tukey" => Ok(cpm_lm::Loss::Tukey(k)),
        other => Err(format!(
            "{spec:?}: unknown loss {other:?} (huber, cauchy, tukey, none)"
        )),
    }
}

pub use crate::report::fit::{describe_loss, describe_model, effect_list};

/// Stages `report.html` of `markdown` (the `report.md` staged in `set` under `dir`), with
/// the SVG figures staged in the same directory inlined ([`crate::report::html::report_page`]).
pub fn stage_report_html(
    set: &mut crate::output::OutputSet,
    dir: &Path,
    title: &str,
    markdown: &str,
) {
    let figures: Vec<(String, String)> = set
        .paths()
        .filter(|p| p.parent() == Some(dir) && p.extension().is_some_and(|e| e == "svg"))
        .filter_map(|p| {
            let name = p.file_name()?.to_string_lossy().to_string();
            let svg = String::from_utf8_lossy(set.contents(p)?).to_string();
            Some((name, svg))
        })
        .collect();
    set.add(
        dir.join("report.html"),
        crate::report::html::report_page(title, markdown, &figures),
    );
}

/// The noise standard deviation for the fit: `--sigma-um`, else the description's.
pub fn sigma(arg: Option<f64>, robot: &Robot) -> anyhow::Result<Option<f64>> {
    match arg {
        Some(s) if !(s.is_finite() && s > 0.0) => {
            Err(usage_error(format!("--sigma-um must be > 0, got {s}")))
        }
        Some(s) => Ok(Some(s)),
        None => Ok(robot.sensor_noise_um()),
    }
}

/// Checks that the output directory can be used (not an existing file, not a link to one).
pub fn check_out_dir(dir: &Path) -> anyhow::Result<()> {
    if std::fs::symlink_metadata(dir).is_ok() && !dir.is_dir() {
        return Err(usage_error(format!(
            "--out {}: exists and is not a directory",
            dir.display()
        )));
    }
    Ok(())
}

/// Commits a result directory as one step (`crate::output::commit_dir`: staged, swapped in,
/// under a lock), refusing output names that are `inputs`; notes a wait for another run and
/// any leftovers of an interrupted run it cleaned up.
pub fn commit_dir(
    set: crate::output::OutputSet,
    dir: &Path,
    inputs: &[&Path],
    command: &str,
    ctx: &Ctx<'_>,
) -> anyhow::Result<Vec<PathBuf>> {
    let done = crate::output::commit_dir(set, dir, inputs, command)
        .with_context(|| format!("writing {}", dir.display()))?;
    if done.waited {
        ctx.note(format!(
            "waited for another cpm run writing {} to finish; its result was replaced by this one",
            dir.display()
        ));
    }
    for r in &done.recovered {
        ctx.note(r);
    }
    Ok(done.written)
}

/// Checks a single-file output (`-` for standard output) before any work: never a device,
/// FIFO, socket or directory, never one of `inputs` (exit 2).
pub fn out_target(
    option: &str,
    path: &Path,
    inputs: &[&Path],
) -> anyhow::Result<crate::output::Target> {
    Ok(crate::output::output_target(option, path, inputs)?)
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

/// The model for a campaign with point target or inclinometer measurements: `model` with the
/// instruments' own unknowns estimated (each target's platform position and a tracker frame
/// per point session: `target_position`, `point_frame`; each inclinometer's mount and the
/// base's tilt per inclinometer session: `inclinometer_mount`, `base_tilt`), sized for
/// `campaign`. `None` when the campaign has neither.
pub fn with_instruments(
    robot: &Robot,
    model: &MeasurementModel,
    campaign: &crate::calib::Campaign,
) -> Option<MeasurementModel> {
    let points = !campaign.point_measurements.is_empty();
    let tilts = !campaign.tilt_measurements.is_empty();
    if !points && !tilts {
        return None;
    }
    let mut e = model.effects.clone();
    let wanted = [
        (Effect::TargetPosition, points),
        (Effect::PointFrame, points),
        (Effect::InclinometerMount, tilts),
        (Effect::BaseTilt, tilts),
    ];
    for (x, want) in wanted {
        if want && !e.contains(&x) {
            e.push(x);
        }
    }
    let mut m = robot.model(&e);
    m.point_sessions = campaign.point_sessions();
    m.tilt_sessions = campaign.tilt_sessions();
    Some(m)
}

/// What [`with_instruments`] estimates, for a note.
pub fn instruments_note(m: &MeasurementModel) -> String {
    let mut v = Vec::new();
    if m.point_sessions > 0 {
        v.push(format!(
            "the {} targets' platform positions and a tracker frame per point session ({} sessions; target_position, point_frame)",
            m.targets.len(),
            m.point_sessions
        ));
    }
    if m.tilt_sessions > 0 {
        v.push(format!(
            "the {} inclinometers' mount rotations and the base's tilt per inclinometer session ({} sessions; inclinometer_mount, base_tilt)",
            m.inclinometers.len(),
            m.tilt_sessions
        ));
    }
    format!(
        "instruments: {} are estimated with the machine",
        v.join("; ")
    )
}
