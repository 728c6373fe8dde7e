//! `cpm compensate` as a library function: the actuator commands that bring a calibrated
//! machine to target poses ([`compensate`] with [`CompensateOptions`]).
//!
//! For each target the link lengths are the inverse kinematics with the calibrated joints,
//! minus the joint clearance shift the description's `[clearance]` and `[load]` predict and
//! minus the length changes of the link effects in `[calibration.known_effects]` (the
//! machine adds both back), turned into readings with each link's reading model (where a
//! calibrated description carries `link_offset` and `link_scale`).
//!
//! The known link effects depend on the commanded lengths (scale-like terms, screw error),
//! so the commands are found by a fixed-point iteration. Backlash depends on the direction
//! each link last moved: the targets are visited in file order, and the first target gets no
//! backlash correction (its approach is unknown) unless `--from-home` says the machine starts
//! at home. `thermal_drift` needs `--temperature-c`; without it no drift is corrected.
//!
//! A known pose error map (`pose_map_*` terms) moves the platform from where the lengths put
//! it: each target is aimed at the target moved back by the map. The map describes the poses
//! it was fitted on only (`[pose_map]` of the description): targets outside are flagged.
//!
//! ```
//! use cpm_workflow::compensate::{compensate, CompensateOptions};
//! use cpm_workflow::Silent;
//!
//! let options = CompensateOptions::new("../../examples/hexapod_66_truth.toml",
//!                                      "../../examples/targets.csv");
//! let job = compensate(&options, &Silent)?;
//! assert_eq!(job.readings.len(), job.targets.len());
//! assert!(job.csv.lines().count() > job.targets.len());
//! # Ok::<(), anyhow::Error>(())
//! ```
use std::path::{Path, PathBuf};

use crate::calib::effects::{is_link_effect, PoseContext};
use crate::calib::MeasurementModel;
use crate::error::{trouble, usage_error};
use crate::io::{self, campaign::check_reachable, PoseRow, ReadOptions};
use crate::progress::{check_cancelled, Progress};
use crate::report::commands::{CompensateSummary, PredictedError, TargetError};

/// The options of `cpm compensate`. [`CompensateOptions::new`] gives the defaults.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CompensateOptions {
    /// The (calibrated) robot description.
    pub robot: PathBuf,
    /// The target poses (a list of poses, docs/formats.md).
    pub poses: PathBuf,
    /// Where the commands go (`-`: standard output); default `None`: standard output.
    /// Checked by [`CompensateOptions::validate`]; the job itself writes nothing.
    pub out: Option<PathBuf>,
    /// The temperature of the machine, deg C, for a known `thermal_drift`; default `None`: no
    /// drift corrected.
    pub temperature_c: Option<f64>,
    /// The machine comes to the first target from its home pose (the first target's
    /// direction of motion for a known `backlash`); default `false`: the first target gets no
    /// backlash correction.
    pub from_home: bool,
}

impl CompensateOptions {
    /// The options for commanding `robot` to the targets of `poses`, every other option at
    /// its default.
    pub fn new(robot: impl Into<PathBuf>, poses: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            poses: poses.into(),
            out: None,
            temperature_c: None,
            from_home: false,
        }
    }

    /// Every input file (an output may not replace one).
    pub fn inputs(&self) -> [&Path; 2] {
        [self.robot.as_path(), self.poses.as_path()]
    }

    /// Checks what needs no input file read: the output file (never a device, FIFO, socket,
    /// directory or input) and the temperature (usage errors).
    pub fn validate(&self) -> anyhow::Result<()> {
        self.check_out()?;
        self.check_temperature()
    }

    fn check_out(&self) -> anyhow::Result<()> {
        if let Some(out) = &self.out {
            crate::load::out_target("--out", out, &self.inputs())?;
        }
        Ok(())
    }

    fn check_temperature(&self) -> anyhow::Result<()> {
        if let Some(t) = self.temperature_c {
            if !(t.is_finite() && (-273.15..=1000.0).contains(&t)) {
                return Err(usage_error(format!(
                    "--temperature-c {t}: not a temperature between -273.15 and 1000 deg C"
                )));
            }
        }
        Ok(())
    }
}

/// What [`compensate`] gives: the commands per target, and the command file's text (for the
/// caller to write: nothing is written).
#[derive(Debug)]
pub struct Compensated {
    /// The robot as read.
    pub robot: io::Robot,
    /// Its measurement model (the known effects applied).
    pub model: MeasurementModel,
    /// The targets, in file order.
    pub targets: Vec<PoseRow>,
    /// Per target, the commanded link lengths, mm.
    pub lengths_mm: Vec<Vec<f64>>,
    /// Per target, the readings to command, in each link's reading units.
    pub readings: Vec<Vec<f64>>,
    /// Labels of the targets outside the pose range a known pose map was fitted on.
    pub outside: Vec<String>,
    /// What the calibration left undetermined (`[calibration] undetermined`).
    pub undetermined: Vec<String>,
    /// The pose error predicted after compensation at each target, from the description's
    /// `[calibration.covariance]` ([`predicted_error`]); `None` when it carries none.
    pub predicted: Option<PredictedError>,
    /// What the calibration's data could not see, in words.
    pub blind: Vec<String>,
    /// The commands file (CSV).
    pub csv: String,
}

impl Compensated {
    /// The notes for the user: parameters the calibration left undetermined, targets outside
    /// the pose map's range.
    pub fn warnings(&self) -> Vec<String> {
        let mut v = Vec::new();
        if !self.undetermined.is_empty() {
            v.push(undetermined_warning(
                &self.robot.file,
                &self.undetermined,
                &self.blind,
            ));
        }
        if !self.outside.is_empty() {
            v.push(format!(
                "{} target(s) lie outside the pose range the pose error map of {} was fitted on ([pose_map]); the map does not extrapolate, so their commands carry its error unknown: {}",
                self.outside.len(),
                self.robot.file,
                self.outside.join(", ")
            ));
        }
        v
    }

    /// The summary of the commands written to `out` (`--json`).
    pub fn summary(&self, out: &Path) -> CompensateSummary {
        CompensateSummary {
            clearance_um: self.robot.clearance().radius_um,
            known_effects: self
                .model
                .known_effects
                .iter()
                .map(|k| k.effect.name().to_string())
                .collect(),
            out: out.display().to_string(),
            outside_pose_map_range: self.outside.clone(),
            predicted_error: self.predicted.clone(),
            robot: self.robot.file.clone(),
            targets: self.targets.len(),
            undetermined: self.undetermined.clone(),
            blind_directions: self.blind.clone(),
        }
    }
}

/// `cpm compensate`: reads the robot and the targets and finds each target's commands.
pub fn compensate(
    options: &CompensateOptions,
    progress: &dyn Progress,
) -> anyhow::Result<Compensated> {
    compensate_in(options, crate::sources::InMemory::none(), progress)
}

/// [`compensate`] with the robot and the targets held in memory (the robot as loaded, the
/// targets as values: see [`InMemory`](crate::sources::InMemory)) in place of the files the
/// options name.
pub fn compensate_in(
    options: &CompensateOptions,
    mut held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Compensated> {
    options.check_out()?;
    check_cancelled(progress)?;
    progress.stage("reading the robot description");
    let robot = held.robot_or_load(&options.robot, progress)?;
    let (targets, file) = crate::sources::pose_list(&options.poses, held.poses.as_deref())?;
    io::campaign::check_pose_list_units(&targets, &file, &robot)?;
    progress.stage(&format!("computing commands for {} targets", targets.len()));
    let ratio = ReadOptions::default().max_condition_ratio;
    options.check_temperature()?;
    let temperature_c = options.temperature_c;
    let model = robot.model(&[]);
    let mut previous = if options.from_home {
        let home = robot.table.home;
        let l = crate::kinematics::inverse_lengths(&robot.table, &home);
        Some(
            model
                .pose_context(&home, l, None, temperature_c, None)
                .map_err(|e| io::InputError::file(&robot.file, format!("home pose: {e}")))?,
        )
    } else {
        None
    };
    let mut readings = Vec::with_capacity(targets.len());
    let mut lengths = Vec::with_capacity(targets.len());
    for t in &targets {
        check_reachable(&robot.table, &t.pose, ratio, &file, t.line, &t.label)?;
        let c = commands_for(&robot, &model, &t.pose, previous.as_ref(), temperature_c)
            .map_err(|e| io::InputError::line(&file, t.line, format!("pose {:?}: {e}", t.label)))?;
        if c.last_change_mm > 1e-6 {
            return Err(trouble(format!(
                "pose {:?} (line {}): the commands did not settle against the known link effects (last change {:.2e} mm after {COMMAND_ITERATIONS} iterations)",
                t.label, t.line, c.last_change_mm
            )));
        }
        let (l, u) = (c.lengths_mm, c.readings);
        previous = Some(c.context);
        for (i, li) in l.iter().enumerate() {
            if let Some((lo, hi)) = robot.table.links[i].length_limits_mm {
                if *li < lo || *li > hi {
                    return Err(io::InputError::line(
                        &file,
                        t.line,
                        format!(
                            "pose {:?}: link {} would be commanded to {li:.3} mm, outside its limits [{lo}, {hi}] mm",
                            t.label,
                            i + 1
                        ),
                    )
                    .into());
                }
            }
        }
        lengths.push(l);
        readings.push(u);
    }
    let outside: Vec<String> = targets
        .iter()
        .filter(|t| outside_pose_map_range(&robot, &t.pose))
        .map(|t| t.label.clone())
        .collect();
    let predicted = predicted_error(&robot, &targets)?;
    let note = format!(
        "{}robot {}, targets {}; readings to command (length = length_at_zero_mm + mm_per_unit * reading){}",
        if crate::load::simulated(&robot) {
            "SIMULATED calibration (fitted to simulated data), "
        } else {
            ""
        },
        robot.file,
        file,
        predicted.as_ref().map_or(String::new(), |p| format!(
            "; predicted pose error, worst target, 95 %: position {:.3} um, orientation {:.3} urad",
            p.worst_target.ap_p_um,
            p.worst_orientation_95_urad()
        ))
    );
    let csv =
        crate::report::format::tidy_csv(&io::write_commands(&targets, &readings, &lengths, &note));
    let (undetermined, blind) = robot
        .description
        .calibration
        .as_ref()
        .map_or((Vec::new(), Vec::new()), |c| {
            (c.undetermined.clone(), c.blind_directions.clone())
        });
    Ok(Compensated {
        robot,
        model,
        targets,
        lengths_mm: lengths,
        readings,
        outside,
        undetermined,
        predicted,
        blind,
        csv,
    })
}

/// The pose error predicted after compensation at each of `targets`, from `robot`'s
/// `[calibration.covariance]` ([`crate::calib::promise`]): per target the standard deviations
/// and 95 % bands, and the worst of each ISO 9283 term; `None` without a covariance.
pub fn predicted_error(
    robot: &io::Robot,
    targets: &[PoseRow],
) -> anyhow::Result<Option<PredictedError>> {
    let Some(c) = robot.covariance()? else {
        return Ok(None);
    };
    let zeros = vec![0.0; c.model.num_params()];
    let poses: Vec<_> = targets.iter().map(|t| t.pose).collect();
    let bands =
        crate::calib::promise::predicted_pose_error(&c.model, &zeros, &c.covariance, &poses)
            .map_err(|e| {
                trouble(format!(
                    "the pose error predicted from {}'s covariance: {e}",
                    robot.file
                ))
            })?;
    let per_target = targets
        .iter()
        .zip(&bands)
        .map(|(t, b)| TargetError {
            orientation_std_urad: b.orientation_std_urad().into(),
            orientation_95_urad: b.orientation_95_urad(),
            pose: t.label.clone(),
            position_std_um: b.position_std_um().into(),
            position_95_um: b.position_95_um(),
        })
        .collect();
    Ok(Some(PredictedError::of(
        per_target,
        c.unbounded,
        crate::calib::promise::Z_95,
    )))
}

/// Fixed-point iterations of the commanded lengths against the known link effects.
pub const COMMAND_ITERATIONS: usize = 8;

/// What the commands of one target came out as.
#[derive(Debug, Clone)]
pub struct Commands {
    /// Commanded link lengths, mm.
    pub lengths_mm: Vec<f64>,
    /// Readings to command, in each link's reading units.
    pub readings: Vec<f64>,
    /// The pose context of this target (the next target's `previous`).
    pub context: PoseContext,
    /// The largest change of a commanded length in the last fixed-point iteration, mm.
    pub last_change_mm: f64,
}

/// Link lengths (mm) and readings that a machine described by `robot` (its measurement model
/// `model`, with the known effect values) needs to reach `pose`, coming from the target whose
/// context is `previous`.
pub fn commands_for(
    robot: &io::Robot,
    model: &MeasurementModel,
    pose: &crate::geometry::Pose,
    previous: Option<&PoseContext>,
    temperature_c: Option<f64>,
) -> Result<Commands, cpm_clearance::ClearanceError> {
    // A known pose error map moves the platform by `twist` from where the lengths put it:
    // aim at the target moved back (the map's variable is the commanded pose; the twist is
    // micrometres, so evaluating it at the target rather than the aim is second order).
    let pose = &pose_map_aim(robot, model, pose, previous, temperature_c)?;
    let mut target = crate::kinematics::inverse_lengths(&robot.table, pose);
    if model.clearance.radius_um > 0.0 {
        let shift =
            model
                .clearance
                .link_corrections_mm(model.statics_table(), pose, &model.load)?;
        for (l, s) in target.iter_mut().zip(shift) {
            *l -= s;
        }
    }
    let mut lengths = target.clone();
    let mut context = model.pose_context(pose, lengths.clone(), previous, temperature_c, None)?;
    let mut last_change_mm = 0.0;
    if model.known_effects.iter().any(|k| is_link_effect(k.effect)) {
        for _ in 0..COMMAND_ITERATIONS {
            let shift = model.known_link_shift_mm(&context, 0.0);
            let next: Vec<f64> = target.iter().zip(&shift).map(|(t, s)| t - s).collect();
            last_change_mm = next
                .iter()
                .zip(&lengths)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            lengths = next;
            context = model.pose_context(pose, lengths.clone(), previous, temperature_c, None)?;
            if last_change_mm < 1e-9 {
                break;
            }
        }
    }
    let readings = lengths
        .iter()
        .enumerate()
        .map(|(i, l)| robot.reading(i, *l))
        .collect();
    Ok(Commands {
        lengths_mm: lengths,
        readings,
        context,
        last_change_mm,
    })
}

/// The pose to command so that a known pose error map puts the platform at `pose`.
fn pose_map_aim(
    robot: &io::Robot,
    model: &MeasurementModel,
    pose: &crate::geometry::Pose,
    previous: Option<&PoseContext>,
    temperature_c: Option<f64>,
) -> Result<crate::geometry::Pose, cpm_clearance::ClearanceError> {
    if !model
        .known_effects
        .iter()
        .any(|k| k.effect.acts_through(crate::calib::Channel::PlatformPose))
    {
        return Ok(*pose);
    }
    let lengths = crate::kinematics::inverse_lengths(&robot.table, pose);
    let context = model.pose_context(pose, lengths, previous, temperature_c, None)?;
    Ok(pose.perturbed(&-model.known_pose_twist(&context, pose, 0.0)))
}

/// True when `pose` lies outside the range `[pose_map]` says the known pose map was fitted on.
fn outside_pose_map_range(robot: &io::Robot, pose: &crate::geometry::Pose) -> bool {
    match robot.description.pose_map {
        Some(crate::geometry::description::PoseMapSpec {
            fitted_min: Some(min),
            fitted_max: Some(max),
            ..
        }) => !crate::calib::refine::PoseRange { min, max }.contains(pose, 1e-6),
        _ => false,
    }
}

/// The warning of a compensation with a calibration that left `undetermined` parameters
/// (and could not see `blind`, in words): the commands cannot correct them.
pub fn undetermined_warning(file: &str, undetermined: &[String], blind: &[String]) -> String {
    let shown: Vec<&str> = undetermined.iter().take(8).map(String::as_str).collect();
    let more = undetermined.len().saturating_sub(shown.len());
    format!(
        "the calibration in {file} left {} parameter(s) undetermined by its data ({}{}){}: they stay at the fit's minimum-norm point, not measured values, and the commands cannot correct the machine's errors along them",
        undetermined.len(),
        shown.join(", "),
        if more > 0 {
            format!(", and {more} more")
        } else {
            String::new()
        },
        if blind.is_empty() {
            String::new()
        } else {
            format!("; the data could not see: {}", blind.join("; "))
        }
    )
}
