//! Robot description files and the calibration model: loading a description into the geometry
//! and [`MeasurementModel`] that the commands use, and writing a calibrated description.
//!
//! The geometry of a description is its joints plus its `[installation_errors_um]` when it
//! has that table (a calibration result, for example). A calibrated description written by
//! [`calibrated_description`] keeps the design joints in its `[[link]]` tables and carries the
//! calibrated installation errors in `[installation_errors_um]`, so that every reader sees the
//! calibrated machine and computes the link forces on the same design geometry as the fit.
//! `link_offset` and `link_scale` are written as known effects (the reading models stay the
//! description's); [`folded_reading_model`] gives the equivalent reading model of a link for a
//! controller that knows only `length = length_at_zero_mm + mm_per_unit * reading`: with the
//! effective length `L (1 + 1e-6 s) + 1e-3 o`, `length_at_zero_mm' = (1 + 1e-6 s)
//! length_at_zero_mm + 1e-3 o` and `mm_per_unit' = (1 + 1e-6 s) mm_per_unit`.
use std::path::Path;

use cpm_calib::{Determination, Effect, EffectSettings, KnownEffect, MeasurementModel};
use cpm_clearance::{ClearanceModel, Load};
use cpm_geometry::description::{CalibrationSpec, RobotDescription};
use cpm_geometry::{InstallationErrors, JointTable};

use super::{read_text, InputError, ReadError};

/// A loaded robot description with its geometry.
#[derive(Debug, Clone)]
pub struct Robot {
    /// The file it came from (for messages).
    pub file: String,
    /// The description as written.
    pub description: RobotDescription,
    /// The geometry: joints plus `[installation_errors_um]` when present; sensors; home.
    pub table: JointTable,
    /// True when `[installation_errors_um]` was applied to the joints.
    pub errors_applied: bool,
    /// The user effects ([`Effect::user`]) its `[calibration]` may name beside the library's:
    /// none for a description read on its own ([`Robot::from_toml_among`] gives them).
    pub user_effects: Vec<Effect>,
}

impl Robot {
    /// Reads and checks a description file.
    pub fn load(path: &Path) -> Result<Robot, ReadError> {
        let file = path.display().to_string();
        let text = read_text(path)?;
        Ok(Self::from_toml(&text, &file)?)
    }

    /// Parses and checks a description.
    pub fn from_toml(text: &str, file: &str) -> Result<Robot, InputError> {
        Self::from_toml_among(text, file, &[])
    }

    /// [`from_toml`](Self::from_toml) for a description whose `[calibration]` may name the
    /// user effects `user` (a calibration of one's own effect, read back by the program that
    /// has it).
    pub fn from_toml_among(text: &str, file: &str, user: &[Effect]) -> Result<Robot, InputError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let description =
            RobotDescription::from_toml_str(text, file).map_err(|e| describe(file, e))?;
        let names = description
            .calibration
            .as_ref()
            .map(|c| c.effects.clone())
            .unwrap_or_default();
        Self::from_description_among(description, file, user)
            .map_err(|e| locate_effect_error(text, &names, e))
    }

    /// A robot from a description already in memory.
    pub fn from_description(
        description: RobotDescription,
        file: &str,
    ) -> Result<Robot, InputError> {
        Self::from_description_among(description, file, &[])
    }

    /// [`from_description`](Self::from_description) whose `[calibration]` may name the user
    /// effects `user`.
    pub fn from_description_among(
        description: RobotDescription,
        file: &str,
        user: &[Effect],
    ) -> Result<Robot, InputError> {
        let nominal = description.joint_table().map_err(|e| describe(file, e))?;
        let errors = description
            .installation_errors()
            .map_err(|e| describe(file, e))?;
        let errors_applied = errors.is_some();
        let table = match errors {
            Some(e) => e.apply(&nominal).map_err(|e| describe(file, e))?,
            None => nominal,
        };
        let robot = Robot {
            file: file.to_string(),
            description,
            table,
            errors_applied,
            user_effects: user
                .iter()
                .copied()
                .filter(|e| matches!(e, Effect::User(_)))
                .collect(),
        };
        robot.known_effects()?;
        robot.declared_effects()?;
        robot.covariance()?;
        // The model is built from the description in one place; what that builder refuses
        // (a known value that is not finite) is refused here, naming the file.
        robot.try_model().map_err(|e| InputError {
            file: robot.file.clone(),
            line: None,
            field: Some("calibration".to_string()),
            message: e.to_string(),
        })?;
        Ok(robot)
    }

    /// The design geometry: the description's joints without `[installation_errors_um]` (the
    /// table itself when the description has none). The commanded pose of a row that logs
    /// link readings alone is the forward kinematics of its commanded lengths on this
    /// geometry: it is the same for a description and for its calibration (which keeps the
    /// joints and adds the fitted errors), so every command that reads a file sees the poses
    /// the fit saw.
    pub fn design_table(&self) -> std::borrow::Cow<'_, JointTable> {
        if self.errors_applied {
            std::borrow::Cow::Owned(
                self.description
                    .joint_table()
                    .expect("checked when the robot was made (from_description)"),
            )
        } else {
            std::borrow::Cow::Borrowed(&self.table)
        }
    }

    /// Number of links.
    pub fn num_links(&self) -> usize {
        self.table.num_links()
    }

    /// Link length (mm) of link `i` for a reading.
    pub fn length_mm(&self, link: usize, reading: f64) -> f64 {
        self.description.links[link].length_mm(reading)
    }

    /// Reading of link `i` for a length (mm).
    pub fn reading(&self, link: usize, length_mm: f64) -> f64 {
        self.description.links[link].reading(length_mm)
    }

    /// True when every link's reading is its length in mm (the default reading model).
    pub fn readings_are_lengths(&self) -> bool {
        self.description
            .links
            .iter()
            .all(|l| l.length_at_zero_mm == 0.0 && l.mm_per_unit == 1.0)
    }

    /// The effects declared in `[calibration] effects`.
    pub fn declared_effects(&self) -> Result<Vec<Effect>, InputError> {
        let names = self
            .description
            .calibration
            .as_ref()
            .map(|c| c.effects.clone())
            .unwrap_or_default();
        names
            .iter()
            .enumerate()
            .map(|(k, n)| {
                Effect::parse_among(n, &self.user_effects).map_err(|m| InputError {
                    file: self.file.clone(),
                    line: None,
                    field: Some(format!("calibration.effects[{}]", k + 1)),
                    message: m,
                })
            })
            .collect()
    }

    /// The known effect values of `[calibration.known_effects]`, checked against the
    /// effect library and this machine's numbers of links and sensors.
    pub fn known_effects(&self) -> Result<Vec<KnownEffect>, InputError> {
        let Some(c) = &self.description.calibration else {
            return Ok(Vec::new());
        };
        let (n, s) = (self.num_links(), self.table.sensors.len());
        let mut out = Vec::with_capacity(c.known_effects.len());
        for (name, values) in &c.known_effects {
            let err = |message: String| InputError {
                file: self.file.clone(),
                line: None,
                field: Some(format!("calibration.known_effects.{name}")),
                message,
            };
            let effect = Effect::parse_among(name, &self.user_effects).map_err(err)?;
            let need = effect.num_params(n, s);
            if values.len() != need {
                return Err(err(format!(
                    "{} values, but {name} has {need} parameters here ({n} links, {s} sensors; {})",
                    values.len(),
                    effect.unit()
                )));
            }
            out.push(KnownEffect {
                effect,
                values: values.clone(),
            });
        }
        Ok(out)
    }

    /// `[calibration.covariance]`, checked: the model whose parameters it is of (this robot's
    /// with the effects it names, every parameter at its calibrated value), the covariance
    /// (model units squared) and what it does not bound; `None` when the description has
    /// none. Errors name the field.
    pub fn covariance(&self) -> Result<Option<Covariance>, InputError> {
        let Some(spec) = self
            .description
            .calibration
            .as_ref()
            .and_then(|c| c.covariance.as_ref())
        else {
            return Ok(None);
        };
        let err = |field: &str, message: String| InputError {
            file: self.file.clone(),
            line: None,
            field: Some(format!("calibration.covariance.{field}")),
            message,
        };
        let effects = spec
            .effects
            .iter()
            .enumerate()
            .map(|(k, n)| {
                Effect::parse_among(n, &self.user_effects)
                    .map_err(|m| err(&format!("effects[{}]", k + 1), m))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let model = self.model(&effects);
        let names = model.parameter_names();
        if spec.parameters != names {
            let at = names
                .iter()
                .zip(&spec.parameters)
                .position(|(a, b)| a != b)
                .unwrap_or(names.len().min(spec.parameters.len()));
            return Err(err(
                "parameters",
                format!(
                    "{} parameters, not those of this robot with effects {:?} ({}; the first to differ is number {})",
                    spec.parameters.len(),
                    spec.effects,
                    names.len(),
                    at + 1
                ),
            ));
        }
        let np = names.len();
        if spec.std.len() != np {
            return Err(err(
                "std",
                format!("{} values for {np} parameters", spec.std.len()),
            ));
        }
        if let Some(k) = spec.std.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(err(
                &format!("std[{}]", k + 1),
                format!("{}: not a standard deviation (finite, >= 0)", spec.std[k]),
            ));
        }
        if spec.correlation.len() != np {
            return Err(err(
                "correlation",
                format!("{} rows for {np} parameters", spec.correlation.len()),
            ));
        }
        let mut c = nalgebra::DMatrix::zeros(np, np);
        for (a, row) in spec.correlation.iter().enumerate() {
            if row.len() != np {
                return Err(err(
                    &format!("correlation[{}]", a + 1),
                    format!("{} values for {np} parameters", row.len()),
                ));
            }
            for (b, r) in row.iter().enumerate() {
                if !(r.is_finite() && r.abs() <= 1.0) {
                    return Err(err(
                        &format!("correlation[{}][{}]", a + 1, b + 1),
                        format!("{r}: not a correlation (between -1 and 1)"),
                    ));
                }
                c[(a, b)] = spec.std[a] * spec.std[b] * r;
            }
        }
        Ok(Some(Covariance {
            model,
            covariance: c,
            unbounded: spec.unbounded.clone(),
        }))
    }

    /// The effect settings of `[calibration]` (screw lead, reference temperature,
    /// non-linearity scale), defaults where not given.
    pub fn effect_settings(&self) -> EffectSettings {
        let mut s = EffectSettings::default();
        if let Some(c) = &self.description.calibration {
            if let Some(v) = c.screw_lead_mm {
                s.screw_lead_mm = v;
            }
            if let Some(v) = c.reference_temperature_c {
                s.reference_temperature_c = v;
            }
            if let Some(v) = c.nonlinearity_scale_mm {
                s.nonlinearity_scale_mm = v;
            }
            if let Some(v) = c.reference_time_s {
                s.reference_time_s = Some(v);
            }
        }
        s
    }

    /// `[calibration] tracker_position_sigma_um` and `tracker_orientation_sigma_urad` (um,
    /// urad) when declared: the tracker's noise, the weights of its positions and orientations.
    pub fn tracker_sigmas(&self) -> (Option<f64>, Option<f64>) {
        self.description
            .calibration
            .as_ref()
            .map_or((None, None), |c| {
                (
                    c.tracker_position_sigma_um,
                    c.tracker_orientation_sigma_urad,
                )
            })
    }

    /// The noise the description's instruments declare: a target's coordinate (`[[target]]
    /// sigma_um`, um) and an inclinometer's angle (`[[inclinometer]] sigma_urad`, urad).
    pub fn instrument_sigmas(&self) -> (Option<f64>, Option<f64>) {
        let d = &self.description;
        (
            d.targets.iter().find_map(|t| t.sigma_um),
            d.inclinometers.iter().find_map(|c| c.sigma_urad),
        )
    }

    /// The a-priori tolerances of `[calibration.tolerances]` and the groups of `[calibration]
    /// hold` (checked against the model when a fit uses them: a group the model does not
    /// have is an error naming it).
    pub fn tolerances(&self) -> Result<cpm_calib::fit::prior::Tolerances, InputError> {
        let mut t = cpm_calib::fit::prior::Tolerances::default();
        if let Some(c) = &self.description.calibration {
            for (name, v) in &c.tolerances {
                t.set(name, *v).map_err(|e| InputError {
                    file: self.file.clone(),
                    line: None,
                    field: Some(format!("calibration.tolerances.{name}")),
                    message: e.to_string(),
                })?;
            }
            t.hold = c.hold.clone();
            if let Some(limit) = c.tolerance_limit {
                t.set_limit(limit).map_err(|e| InputError {
                    file: self.file.clone(),
                    line: None,
                    field: Some("calibration.tolerance_limit".into()),
                    message: e.to_string(),
                })?;
            }
        }
        Ok(t)
    }

    /// `[calibration] sensor_noise_um` when declared and positive.
    pub fn sensor_noise_um(&self) -> Option<f64> {
        self.description
            .calibration
            .as_ref()
            .and_then(|c| c.sensor_noise_um)
            .filter(|s| *s > 0.0)
    }

    /// The joint clearance of the description; none without a `[clearance]` table.
    pub fn clearance(&self) -> ClearanceModel {
        match &self.description.clearance {
            Some(c) => ClearanceModel::from(c),
            None => ClearanceModel::none(),
        }
    }

    /// The load of the description; `cpm`'s default load without a `[load]` table.
    pub fn platform_load(&self) -> Load {
        match &self.description.load {
            Some(l) => Load::from(l),
            None => Load::default(),
        }
    }

    /// The measurement model: this geometry, clearance and load, the known effect values
    /// and settings of `[calibration]`, the targets and inclinometers
    /// ([`MeasurementModel::on_table`], the one builder), and `effects` to
    /// estimate.
    pub fn model(&self, effects: &[Effect]) -> MeasurementModel {
        let mut m = self
            .try_model()
            .expect("built once when the robot was made (from_description_among)");
        m.effects = effects.to_vec();
        m
    }

    /// The model of this robot's table and description, by the one builder.
    fn try_model(&self) -> Result<MeasurementModel, cpm_calib::CalibError> {
        // The design: the description's joints, when its installation errors were applied
        // (checked when the robot was made).
        let design = if self.errors_applied {
            self.description.joint_table().ok()
        } else {
            None
        };
        MeasurementModel::on_table(
            self.table.clone(),
            design,
            &self.description,
            &self.user_effects,
        )
    }

    /// The nominal positions of the platform's targets (`[[target]]`), platform frame, mm.
    pub fn target_positions_mm(&self) -> Vec<cpm_geometry::Vector3<f64>> {
        self.description
            .targets
            .iter()
            .map(|s| cpm_geometry::Vector3::from(s.platform_mm))
            .collect()
    }

    /// Nominal sensor names, for messages.
    pub fn sensor_names(&self) -> String {
        if self.table.sensors.is_empty() {
            "none: the robot description has no [[sensor]]".to_string()
        } else {
            self.table
                .sensors
                .iter()
                .map(|s| s.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        }
    }
}

/// Adds the line to an error about `[calibration]`'s effects: the quoted name in `effects`
/// (`names`, as declared), the `name = [...]` entry of `[calibration.known_effects]`, or the
/// key of `[calibration.covariance]` the field names.
fn locate_effect_error(text: &str, names: &[String], mut e: InputError) -> InputError {
    let field = e.field.clone().unwrap_or_default();
    let line_after = |header: &str, hit: &dyn Fn(&str) -> bool| {
        let start = text
            .lines()
            .position(|l| l.trim_start().starts_with(header))?;
        text.lines()
            .enumerate()
            .skip(start)
            .find(|(_, l)| hit(l))
            .map(|(i, _)| i + 1)
    };
    if let Some(rest) = field.strip_prefix("calibration.covariance.") {
        let key = rest.split('[').next().unwrap_or(rest);
        e.line = line_after("[calibration.covariance]", &|l: &str| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|r| r.trim_start().starts_with('='))
        });
    } else if let Some(name) = field.strip_prefix("calibration.known_effects.") {
        e.line = line_after("[calibration.known_effects]", &|l: &str| {
            l.trim_start()
                .strip_prefix(name)
                .is_some_and(|r| r.trim_start().starts_with('='))
        });
    } else if let Some(k) = field
        .strip_prefix("calibration.effects[")
        .and_then(|f| f.strip_suffix(']'))
        .and_then(|k| k.parse::<usize>().ok())
        .filter(|k| (1..=names.len()).contains(k))
    {
        let quoted = format!("{:?}", names[k - 1]);
        e.line = line_after("[calibration]", &|l: &str| l.contains(&quoted));
    }
    e
}

fn describe(file: &str, e: cpm_geometry::GeometryError) -> InputError {
    match e {
        cpm_geometry::GeometryError::Description { path, message } => {
            locate_description_error(&path, &message)
        }
        other => InputError::file(file, other.to_string()),
    }
}

/// Turns the description loader's messages into `file:line: field key: what`:
/// `key: what (line L, column C)` for checks, `TOML parse error at line L, column C` followed
/// by the source excerpt and the explanation for syntax and key errors.
fn locate_description_error(path: &str, message: &str) -> InputError {
    if let Some(rest) = message.strip_prefix("TOML parse error at line ") {
        let line = rest
            .split(|c: char| !c.is_ascii_digit())
            .next()
            .and_then(|n| n.parse::<usize>().ok());
        let what = message
            .lines()
            .rev()
            .find(|l| {
                !l.trim().is_empty() && !l.trim_start().starts_with('|') && !l.contains(" | ")
            })
            .unwrap_or(message)
            .trim()
            .to_string();
        if let Some(line) = line {
            // The key: named by the message, else the key of the excerpt's `key = value` line.
            let named = ["missing field `", "unknown field `", "duplicate key `"]
                .iter()
                .find_map(|p| what.split_once(p))
                .and_then(|(_, rest)| rest.split_once('`'))
                .map(|(k, _)| k.to_string())
                .filter(|k| !k.trim().is_empty());
            let excerpt_key = message
                .lines()
                .find_map(|l| l.split_once(" | "))
                .filter(|(n, _)| n.trim().parse::<usize>() == Ok(line))
                .and_then(|(_, src)| src.split_once('='))
                .map(|(k, _)| k.trim().to_string())
                .filter(|k| {
                    !k.is_empty()
                        && k.chars()
                            .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c))
                });
            return match named.or(excerpt_key) {
                Some(key) => InputError::field(path, line, key, what),
                None => InputError::line(path, line, what),
            };
        }
    }
    if let Some(open) = message.rfind(" (line ") {
        let tail = &message[open + 7..];
        let line = tail
            .split(|c: char| !c.is_ascii_digit())
            .next()
            .and_then(|n| n.parse::<usize>().ok());
        let body = &message[..open];
        if let (Some(line), Some((key, what))) = (line, body.split_once(": ")) {
            if !key.contains(' ') {
                return InputError::field(path, line, key, what);
            }
        }
    }
    InputError::file(path, message)
}

/// Parses a comma-separated list of effect names.
pub fn parse_effects(list: &str) -> Result<Vec<Effect>, String> {
    let mut out: Vec<Effect> = Vec::new();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let e = Effect::parse(name)?;
        if out.contains(&e) {
            return Err(format!("effect `{name}` given twice"));
        }
        out.push(e);
    }
    Ok(out)
}

/// Values of one parameter vector, split: installation errors (um) and each effect's block.
#[derive(Debug, Clone)]
pub struct SplitParams {
    /// Installation errors, um, `None` where not known.
    pub installation_um: Vec<Option<f64>>,
    /// Per effect of the model, its parameter values (`None` where not known).
    pub effects: Vec<(Effect, Vec<Option<f64>>)>,
}

/// Splits a parameter vector of `model` into its blocks.
pub fn split_params(model: &MeasurementModel, params: &[Option<f64>]) -> SplitParams {
    let blocks = model.blocks();
    let ni = model.num_installation_params();
    SplitParams {
        installation_um: params[..ni.min(params.len())].to_vec(),
        effects: blocks
            .iter()
            .filter_map(|b| {
                b.effect
                    .map(|e| (e, params[b.offset..b.offset + b.len].to_vec()))
            })
            .collect(),
    }
}

/// What [`calibrated_description`] did with the parameters.
#[derive(Debug, Clone, Default)]
pub struct CalibratedNotes {
    /// Installation-error components the data do not determine on their own: written at
    /// the fit's point of the solution set (the minimum-norm one), which reproduces the fit,
    /// but not measured values.
    pub undetermined: Vec<String>,
    /// Effect parameters the data do not determine on their own (written at the fit's
    /// point, like [`undetermined`](Self::undetermined)).
    pub undetermined_effects: Vec<String>,
    /// Every parameter the data do not determine, named (with its unit), with what holds
    /// it: held by tolerance, held by user, or blind.
    pub held: Vec<(Determination, String)>,
    /// Effects written to `[calibration.known_effects]`.
    pub known_effects: Vec<String>,
    /// One's own instruments whose per-instrument parameters were written to
    /// `[calibration.instruments]`.
    pub instruments: Vec<String>,
    /// Effects of the fit that describe a measurement session, not the machine, and are not
    /// written (`tracker_frame`: every session registers its own frame).
    pub session_effects: Vec<String>,
}

/// The calibrated description: `robot`'s description with the fitted parameters `params`
/// (model order, the complete point the fit ended at) written so that reading it back gives
/// a model that predicts exactly what the fit predicted:
///
/// - the joints stay the design joints of `robot`'s description, and
///   `[installation_errors_um]` holds its own installation errors (if any) plus the fitted
///   ones: the link forces (joint clearance, compliance) are computed on the design joints by
///   every reader ([`MeasurementModel::design`]), as in the fit;
/// - `socket_error` moves the sensor sockets, `target_position` the `[[target]]`s,
///   `inclinometer_mount` the `[[inclinometer]]`s' `mount_rpy_deg`;
/// - every other effect's values, `link_offset` and `link_scale` included, are added to
///   `[calibration.known_effects]` (on top of the values the description already knew): the
///   link reading models stay the description's, so every reader derives the same commanded
///   lengths (and commanded poses) from the logged readings as the fit did; `tracker_frame`
///   `point_frame` and `base_tilt` belong to the measurement session and are not written (listed in
///   [`CalibratedNotes::session_effects`]);
/// - one's own instruments' per-instrument parameters go into `[calibration.instruments]`
///   under the instrument's name (their per-session ones, like a tracker's frame, describe a
///   session and are not written);
/// - `[calibration] effects` is set to `declare` when given.
///
/// `determination[k]` says what gives parameter `k` its value
/// ([`Calibration::determination`](cpm_calib::Calibration::determination)); those the data
/// do not determine are named in the notes with their word (their values are still written:
/// the fit's point, never a mix of fitted and nominal components).
pub fn calibrated_description(
    robot: &Robot,
    model: &MeasurementModel,
    params: &[f64],
    determination: &[Determination],
    declare: Option<&[Effect]>,
) -> (RobotDescription, CalibratedNotes) {
    let mut d = robot.description.clone();
    let mut notes = CalibratedNotes::default();
    let sensor_names: Vec<String> = robot.table.sensors.iter().map(|s| s.name.clone()).collect();
    let ni = model.num_installation_params();
    let is_determined = |k: usize| {
        determination
            .get(k)
            .is_none_or(|d| *d == Determination::Determined)
    };
    let names = model.parameter_names();
    notes.held = (0..determination.len().min(names.len()))
        .filter(|&k| !is_determined(k))
        .map(|k| (determination[k], names[k].clone()))
        .collect();
    // Installation errors: the description's own plus the fitted ones.
    let mut errors = vec![0.0; ni];
    if let Some(spec) = &d.installation_errors_um {
        errors = spec.to_errors().to_vec_um();
    }
    for (k, e) in errors.iter_mut().enumerate() {
        *e += params.get(k).copied().unwrap_or(0.0);
        if !is_determined(k) {
            notes
                .undetermined
                .push(InstallationErrors::component_name(k));
        }
    }
    if let Ok(e) = InstallationErrors::try_from_vec_um(&errors) {
        d.installation_errors_um =
            Some(cpm_geometry::description::InstallationErrorsSpec::from_errors(&e));
    }
    for b in model.blocks() {
        if let Some(i) = b.instrument {
            let instrument = &model.instruments[i];
            let own = instrument.num_instrument_params().min(b.len);
            if own > 0 {
                let values = params[b.offset..b.offset + own].to_vec();
                d.calibration
                    .get_or_insert_with(CalibrationSpec::default)
                    .instruments
                    .insert(instrument.name().to_string(), values);
                notes.instruments.push(instrument.name().to_string());
            }
            continue;
        }
        let Some(effect) = b.effect else { continue };
        let values = &params[b.offset..b.offset + b.len];
        for k in 0..b.len {
            if !is_determined(b.offset + k) {
                notes.undetermined_effects.push(format!(
                    "{} {} [{}]",
                    effect.name(),
                    effect.param_name(k, &sensor_names),
                    effect.param_unit(k)
                ));
            }
        }
        match effect {
            Effect::SocketError => {
                for (k, v) in values.iter().enumerate() {
                    let s = &mut d.sensors[k / 6];
                    let side = if k % 6 < 3 {
                        &mut s.base_mm
                    } else {
                        &mut s.platform_mm
                    };
                    side[k % 3] += v * 1e-3;
                }
            }
            Effect::TrackerFrame | Effect::PointFrame | Effect::BaseTilt => {
                notes.session_effects.push(effect.name().to_string())
            }
            Effect::MarkerFrame => {
                // The marker frame composes (the known one, then the fitted correction in
                // it), so that the written values give exactly the fitted frame.
                let known = d
                    .calibration
                    .get_or_insert_with(CalibrationSpec::default)
                    .known_effects
                    .entry(effect.name().to_string())
                    .or_insert_with(|| vec![0.0; 6]);
                if known.len() == 6 && values.len() == 6 {
                    let (kt, kr) = cpm_calib::effects::tracker_registration(known);
                    let (te, re) = cpm_calib::effects::tracker_registration(values);
                    *known = cpm_calib::effects::frame_params(&(kt + kr * te), &(kr * re)).to_vec();
                }
                notes.known_effects.push(effect.name().to_string());
            }
            Effect::InclinometerMount => {
                for (i, c) in d.inclinometers.iter_mut().enumerate() {
                    let Some(m) = values.get(3 * i..3 * i + 3) else {
                        continue;
                    };
                    let [r, p, y] = c.mount_rpy_deg.map(f64::to_radians);
                    let mount = cpm_geometry::rotation::from_rpy(r, p, y)
                        * cpm_geometry::Rotation3::new(
                            cpm_geometry::Vector3::new(m[0], m[1], m[2]) * 1e-6,
                        );
                    let (r, p, y) = cpm_geometry::rotation::rpy(&mount);
                    c.mount_rpy_deg = [r, p, y].map(f64::to_degrees);
                }
            }
            Effect::TargetPosition => {
                for (k, v) in values.iter().enumerate() {
                    if let Some(t) = d.targets.get_mut(k / 3) {
                        t.platform_mm[k % 3] += v * 1e-3;
                    }
                }
            }
            _ => {
                let known = d
                    .calibration
                    .get_or_insert_with(CalibrationSpec::default)
                    .known_effects
                    .entry(effect.name().to_string())
                    .or_insert_with(|| vec![0.0; values.len()]);
                for (kv, v) in known.iter_mut().zip(values) {
                    *kv += v;
                }
                notes.known_effects.push(effect.name().to_string());
            }
        }
    }
    if let Some(effects) = declare {
        let names: Vec<String> = effects
            .iter()
            .filter(|e| {
                !matches!(e, Effect::TrackerFrame | Effect::MarkerFrame) && !e.is_instrument()
            })
            .map(|e| e.name().to_string())
            .collect();
        match &mut d.calibration {
            Some(c) => c.effects = names,
            None if !names.is_empty() => {
                d.calibration = Some(CalibrationSpec {
                    effects: names,
                    ..Default::default()
                })
            }
            None => {}
        }
    }
    (d, notes)
}

/// The reading model `(length_at_zero_mm, mm_per_unit)` of link `i` with the robot's known
/// `link_offset` (o, um) and `link_scale` (s, ppm) folded in (see the module doc), for
/// controllers that take a reading model only: `length_at_zero_mm` becomes
/// `(1 + 1e-6 s) length_at_zero_mm + 1e-3 o` and `mm_per_unit` becomes
/// `(1 + 1e-6 s) mm_per_unit`.
pub fn folded_reading_model(robot: &Robot, i: usize) -> (f64, f64) {
    let link = &robot.description.links[i];
    let known = robot.known_effects().unwrap_or_default();
    let value = |e: Effect| {
        known
            .iter()
            .find(|k| k.effect == e)
            .and_then(|k| k.values.get(i).copied())
            .unwrap_or(0.0)
    };
    let (o, s) = (value(Effect::LinkOffset), value(Effect::LinkScale));
    let f = 1.0 + s * 1e-6;
    (link.length_at_zero_mm * f + o * 1e-3, link.mm_per_unit * f)
}

/// A calibration's `[calibration.covariance]` as a model and a matrix ([`Robot::covariance`]).
#[derive(Debug, Clone)]
pub struct Covariance {
    /// The robot's model with the effects the covariance covers (parameters at zero: the
    /// calibrated values).
    pub model: MeasurementModel,
    /// The covariance of its parameters, model units squared.
    pub covariance: nalgebra::DMatrix<f64>,
    /// What neither the data nor a tolerance bounded (parameter names): no band holds them.
    pub unbounded: Vec<String>,
}

/// The calibrated description as TOML text, with a comment header that says where it came
/// from and lists what the data did not determine.
pub fn calibrated_toml(
    d: &RobotDescription,
    notes: &CalibratedNotes,
    header: &[String],
) -> Result<String, String> {
    let body = d.to_toml_string().map_err(|e| e.to_string())?;
    let mut s = String::new();
    for h in header {
        s.push_str(&format!("# {h}\n"));
    }
    s.push_str("# The joints are the design joints; [installation_errors_um] holds the calibrated installation errors (every reader applies them).\n");
    // What holds each parameter the data do not determine, in the words of every output.
    for (d, what) in [
        (
            Determination::HeldByTolerance,
            "the data alone do not determine them; written where the fit ends between the data and the tolerance, not measured values",
        ),
        (Determination::HeldByUser, "written at their held value"),
        (
            Determination::Blind,
            "neither the data nor a tolerance determine them; written at the fit's minimum-norm point of the solution set, which reproduces the fit; not measured values",
        ),
    ] {
        let names: Vec<&str> = notes
            .held
            .iter()
            .filter(|h| h.0 == d)
            .map(|h| h.1.as_str())
            .collect();
        if !names.is_empty() {
            let word = d.word();
            s.push_str(&format!(
                "# {}{} ({}): {what}. {}\n",
                word[..1].to_uppercase(),
                &word[1..],
                names.len(),
                names.join(", ")
            ));
        }
    }
    if !notes.session_effects.is_empty() {
        s.push_str(&format!(
            "# Fitted but not written (they describe the measurement session, not the machine; every session registers its own): {}\n",
            notes.session_effects.join(", ")
        ));
    }
    if !notes.known_effects.is_empty() {
        s.push_str(&format!(
            "# Calibrated effect values in [calibration.known_effects] (applied by every cpm command that reads this file): {}\n",
            notes.known_effects.join(", ")
        ));
    }
    if !notes.instruments.is_empty() {
        s.push_str(&format!(
            "# One's own instruments' fitted parameters in [calibration.instruments] (read by a model with the same instruments): {}\n",
            notes.instruments.join(", ")
        ));
    }
    s.push('\n');
    s.push_str(&body);
    Ok(s)
}

/// The installation errors (um, model order) and link-effect values that turn `robot` into
/// `truth`: the difference of the two geometries, and each link's reading model difference as
/// `link_offset` (um) and `link_scale` (ppm).
pub fn truth_from_description(robot: &Robot, truth: &Robot) -> Result<TruthDiff, String> {
    if truth.num_links() != robot.num_links() {
        return Err(format!(
            "has {} links, the robot {}",
            truth.num_links(),
            robot.num_links()
        ));
    }
    let mut errors = Vec::with_capacity(6 * robot.num_links());
    for (a, b) in robot.table.links.iter().zip(&truth.table.links) {
        let db = (b.base_mm - a.base_mm) * 1e3;
        let dp = (b.platform_mm - a.platform_mm) * 1e3;
        errors.extend(db.iter());
        errors.extend(dp.iter());
    }
    let mut offset_um = Vec::new();
    let mut scale_ppm = Vec::new();
    for (a, b) in robot.description.links.iter().zip(&truth.description.links) {
        let ratio = b.mm_per_unit / a.mm_per_unit;
        scale_ppm.push((ratio - 1.0) * 1e6);
        offset_um.push((b.length_at_zero_mm - ratio * a.length_at_zero_mm) * 1e3);
    }
    Ok(TruthDiff {
        installation_um: errors,
        link_offset_um: offset_um,
        link_scale_ppm: scale_ppm,
    })
}

/// The difference between a robot and a truth description.
#[derive(Debug, Clone)]
pub struct TruthDiff {
    /// Installation errors, um (model order).
    pub installation_um: Vec<f64>,
    /// `link_offset` per link, um.
    pub link_offset_um: Vec<f64>,
    /// `link_scale` per link, ppm.
    pub link_scale_ppm: Vec<f64>,
}

impl TruthDiff {
    /// True when the link reading models differ (offset or scale non-zero).
    pub fn has_link_terms(&self) -> bool {
        self.link_offset_um
            .iter()
            .chain(&self.link_scale_ppm)
            .any(|v| v.abs() > 1e-9)
    }
}
