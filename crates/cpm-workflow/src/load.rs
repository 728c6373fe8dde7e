//! Loading what a job works on (the robot description, the measurement files, the effects)
//! and what every job shares: read options for a model, the model for a campaign's
//! instruments, locating a solver failure in the input files, staging `report.html`, and
//! committing a result directory.
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use crate::calib::{CalibError, Effect, IdentifyOptions, MeasurementModel};
use crate::error::{input_error, usage_error};
use crate::ingest::RegistrationOptions;
use crate::io::{self, merge, Merged, Provenance, ReadOptions, Robot};
use crate::progress::Progress;

/// The effects modelled beside the installation errors: the options' (`Some`, parsed at the
/// edge: [`crate::options::parse_effects`]), else the description's `[calibration] effects`.
pub fn resolve_effects(given: Option<&[Effect]>, robot: &Robot) -> anyhow::Result<Vec<Effect>> {
    match given {
        Some(effects) => Ok(effects.to_vec()),
        None => Ok(robot.declared_effects()?),
    }
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

/// `[calibration] calibrated_from` of a result in the folder `dir` calibrated from the
/// description `from`: relative to the result's folder when the description lies near it,
/// at most two folders up (the two then move together, as in a project folder); far away (a
/// shared library of descriptions), absolute, so that the result alone can move.
pub fn calibrated_from(from: &Path, dir: &Path) -> String {
    let relative = relative_to_dir(from, dir);
    let ups = relative
        .components()
        .take_while(|c| matches!(c, std::path::Component::ParentDir))
        .count();
    if relative.is_relative() && ups <= 2 {
        relative.display().to_string()
    } else {
        std::fs::canonicalize(from)
            .unwrap_or_else(|_| from.to_path_buf())
            .display()
            .to_string()
    }
}

/// Loads the robot description.
pub fn load_robot(path: &Path, progress: &dyn Progress) -> anyhow::Result<Robot> {
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
        progress.note(&format!(
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

/// Reads and merges measurement files (tracker files registered with `registration`).
pub fn load_data(
    paths: &[PathBuf],
    robot: &Robot,
    options: &ReadOptions,
    registration: &RegistrationOptions,
) -> anyhow::Result<Merged> {
    let files = crate::ingest::read_data_files(paths, robot, options, registration)?;
    let merged = merge(files, robot);
    if options.check_sensor_lengths {
        crate::gauges::check_readings(robot, &merged)?;
    }
    Ok(merged)
}

/// Warns (`FILE:LINE: pose "LABEL" excluded: REASON`) of each pose left out of the data (see
/// [`io::campaign::POSES_PER_EXCLUDED_POSE`]).
pub fn warn_excluded(progress: &dyn Progress, excluded: &[io::ExcludedPose]) {
    for e in excluded {
        progress.warn(&e.to_string());
    }
}

/// Read options for a model: sensor lengths are checked unless `sensor_offset` is modelled.
pub fn read_options(model: &MeasurementModel) -> ReadOptions {
    ReadOptions {
        check_sensor_lengths: !model.effects.contains(&Effect::SensorOffset),
        ..ReadOptions::default()
    }
}

/// Registration options for a model: tracker files are registered with the model's known
/// `tracker_frame` taken out.
pub fn registration_options(model: &MeasurementModel) -> RegistrationOptions {
    RegistrationOptions {
        known_tracker_frame: model
            .known(Effect::TrackerFrame)
            .and_then(|q| <[f64; 6]>::try_from(q).ok()),
        ..RegistrationOptions::default()
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
    progress: &dyn Progress,
) -> anyhow::Result<Vec<PathBuf>> {
    let done = crate::output::commit_dir(set, dir, inputs, command)
        .with_context(|| format!("writing {}", dir.display()))?;
    if done.waited {
        progress.note(&format!(
            "waited for another cpm run writing {} to finish; its result was replaced by this one",
            dir.display()
        ));
    }
    for r in &done.recovered {
        progress.note(r);
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

/// The model for a campaign with point target or inclinometer measurements: `model` with the
/// instruments' own unknowns estimated (each target's platform position and a tracker frame
/// per point session: `target_position`, `point_frame`; each inclinometer's mount and the
/// base's tilt per inclinometer session: `inclinometer_mount`, `base_tilt`), sized for
/// `campaign`. `None` when the campaign has neither.
pub fn with_instruments(
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
    // The model as given (its tracker sessions included), with the instruments' effects: a
    // model built again from the robot lost the tracker frame per session of a campaign
    // with tracker poses beside points or angles.
    let mut m = model.clone();
    m.effects = e;
    m.point_sessions = campaign.point_sessions();
    m.tilt_sessions = campaign.tilt_sessions();
    Some(m)
}

/// What [`with_instruments`] estimates, for a note.
pub fn instruments_note(m: &MeasurementModel) -> String {
    let mut v = Vec::new();
    if m.point_sessions > 0 {
        v.push(format!(
            "{} platform {} and a tracker frame per point session ({}; target_position, point_frame)",
            counted(m.targets.len(), "the target's", "targets'"),
            if m.targets.len() == 1 { "position" } else { "positions" },
            counted(m.point_sessions, "session", "sessions")
        ));
    }
    if m.tilt_sessions > 0 {
        v.push(format!(
            "{} mount {} and the base's tilt per inclinometer session ({}; inclinometer_mount, base_tilt)",
            counted(m.inclinometers.len(), "the inclinometer's", "inclinometers'"),
            if m.inclinometers.len() == 1 { "rotation" } else { "rotations" },
            counted(m.tilt_sessions, "session", "sessions")
        ));
    }
    format!(
        "instruments: {} are estimated with the machine",
        v.join("; ")
    )
}

/// `n` and its noun, singular for one: "the target's" or "the 3 targets'" for a noun given
/// with "the ", "1 session" or "3 sessions" otherwise.
fn counted(n: usize, one: &str, many: &str) -> String {
    match (n, one.strip_prefix("the ")) {
        (1, Some(_)) => one.to_string(),
        (_, Some(_)) => format!("the {n} {many}"),
        (1, None) => format!("1 {one}"),
        _ => format!("{n} {many}"),
    }
}

/// True when the robot's calibration was fitted to simulated data (`[calibration] simulated`).
pub fn simulated(robot: &Robot) -> bool {
    robot
        .description
        .calibration
        .as_ref()
        .is_some_and(|c| c.simulated)
}

/// The user effects a description written from `model` may name: the robot's own and those
/// the model estimates or knows (a reader is given them; nothing global knows them).
pub fn user_effects_of(robot: &Robot, model: &MeasurementModel) -> Vec<Effect> {
    let mut out = robot.user_effects.clone();
    let used = model
        .effects
        .iter()
        .copied()
        .chain(model.known_effects.iter().map(|k| k.effect));
    for e in used.filter(|e| matches!(e, Effect::User(_))) {
        if !out.contains(&e) {
            out.push(e);
        }
    }
    out
}

/// The inputs of a fit, loaded and checked.
pub struct Inputs {
    /// The robot.
    pub robot: Robot,
    /// The model.
    pub model: MeasurementModel,
    /// The merged data (shared with the outputs that stream from it, residuals.csv).
    pub merged: std::sync::Arc<Merged>,
    /// Identification options.
    pub identify: IdentifyOptions,
    /// Where it all came from.
    pub provenance: Provenance,
    /// The measurement files as read (the provenance may name them otherwise); empty for
    /// measurements read from memory.
    pub data_paths: Vec<PathBuf>,
}

impl Inputs {
    /// What a fit's report needs of the inputs.
    pub fn report_inputs(&self) -> crate::report::fit::FitInputs<'_> {
        crate::report::fit::FitInputs {
            robot: &self.robot,
            merged: &self.merged,
            provenance: &self.provenance,
            loss: &self.identify.lm.loss,
        }
    }
}

impl Inputs {
    /// The inputs without the poses a fit left out (`fit::leaving_out`, in its order),
    /// recorded in the merged data's `excluded`.
    pub fn without_poses(&self, excluded: &[(usize, crate::io::ExcludedPose)]) -> Inputs {
        let mut merged = Merged::clone(&self.merged);
        for (pose, e) in excluded {
            merged = merged.without_pose(*pose);
            merged.excluded.push(e.clone());
        }
        Inputs {
            robot: self.robot.clone(),
            model: self.model.clone(),
            merged: std::sync::Arc::new(merged),
            identify: self.identify.clone(),
            provenance: self.provenance.clone(),
            data_paths: self.data_paths.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::counted;

    /// One is singular ("the 1 inclinometers' ... (1 sessions" read wrong).
    #[test]
    fn one_is_singular() {
        assert_eq!(
            counted(1, "the inclinometer's", "inclinometers'"),
            "the inclinometer's"
        );
        assert_eq!(
            counted(2, "the inclinometer's", "inclinometers'"),
            "the 2 inclinometers'"
        );
        assert_eq!(counted(1, "session", "sessions"), "1 session");
        assert_eq!(counted(3, "session", "sessions"), "3 sessions");
    }
}
