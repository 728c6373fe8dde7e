//! The fit of `cpm calibrate` and `cpm refine` as library functions: [`FitOptions`] loaded
//! into [`Inputs`] (robot, model, data, solver options: built once), [`fit_with`] staging every
//! output (`calibration.json`, `residuals.csv`, figures, `report.md`, `report.html`,
//! `calibrated.toml` checked by reading it back), and [`calibrate`], the whole job.
use std::path::{Path, PathBuf};

use crate::calib::Effect;
use crate::calib::{Calibration, Campaign, IdentifyOptions, MeasurementModel};
use crate::error::usage_error;
use crate::ingest::RegistrationOptions;
use crate::io::{self, Merged, Provenance, Robot};
pub use crate::load::Inputs;
use crate::options::{Group, Tolerance};
use crate::output::OutputSet;
use crate::progress::{check_cancelled, Progress};
use crate::report::calibrate::{CalibrateReport, CalibratedFile};
use crate::report::fit::FitReport;
pub use crate::report::fit::{
    misfit, misfit_message, observation_origin, warnings, ObservationOrigin,
};
pub use crate::report::residuals::residuals_csv;
pub use crate::staging::{provenance_lines, reproduces};
use cpm_lm::Loss;

/// Whether each kind of observation is weighed by the noise its own residual shows
/// (`--noise-per-kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum NoisePerKind {
    /// Per kind when two or more kinds are present and one of them is undeclared.
    Auto,
    /// Always per kind.
    On,
    /// Defaults for undeclared kinds, one common scale.
    Off,
}

/// The residuals of 6-D tracker poses (`--tracker-residuals`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum TrackerResiduals {
    /// Chosen out of sample.
    Auto,
    /// Pose residuals.
    Pose,
    /// Leg-length residuals (inverse kinematics of the measured pose).
    Legs,
}

/// The options every fit (`calibrate`, `refine`) takes: the robot, the data, the effects,
/// the noise, the solver and the output directory. [`FitOptions::new`] gives the defaults of
/// `cpm calibrate` (each field says its own).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitOptions {
    /// The robot description (TOML, docs/robot-description.md).
    pub robot: PathBuf,
    /// Measurement files (length readings, tracker poses, reflector points or inclinometer angles; docs/formats.md), in order.
    pub data: Vec<PathBuf>,
    /// Effects to model beside the installation errors (`Some(vec![])` for none; by name:
    /// a list, or `--effects`' text, [`crate::options::parse_effects`]); default `None`:
    /// `[calibration] effects` of the description.
    #[serde(with = "crate::options::effects")]
    pub effects: Option<Vec<Effect>>,
    /// Sensor noise standard deviation, um; default `None`: `[calibration]
    /// sensor_noise_um` of the description, else estimated from the residual.
    pub sigma_um: Option<f64>,
    /// Tracker position noise, um; default `None`: the description's, else cpm-calib's.
    pub pose_sigma_um: Option<f64>,
    /// Tracker orientation and inclinometer angle noise, urad; default `None`: the
    /// description's, else cpm-calib's.
    pub orientation_sigma_urad: Option<f64>,
    /// Robust loss (K in um; by name `huber:K`, `cauchy:K`, `tukey:K` or `none`,
    /// [`crate::options::parse_loss`]); default `None` (least squares).
    #[serde(with = "crate::options::robust")]
    pub robust: Option<Loss>,
    /// Fit gross outliers too instead of setting them aside; default false.
    pub keep_outliers: bool,
    /// Most solver iterations per fit; default `None` (cpm-lm's 1000).
    pub max_iterations: Option<usize>,
    /// The output directory (checked, never written by the job itself: the caller commits
    /// the staged set).
    pub out: PathBuf,
    /// Noise per kind of observation; default [`NoisePerKind::Auto`].
    pub noise_per_kind: NoisePerKind,
    /// A-priori tolerances, each in its group's unit (by name `GROUP=VALUE`,
    /// [`crate::options::parse_tolerance`]); default none (the description's, else
    /// cpm-calib's defaults).
    pub tolerance: Vec<Tolerance>,
    /// Groups held at nominal, on top of the description's `[calibration] hold`; default none.
    pub hold: Vec<Group>,
    /// No prior (plain least squares in every direction the data see); default false.
    pub no_prior: bool,
    /// Tolerances an undetermined parameter may reach before it is held there
    /// ([`Tolerances::limit`](crate::calib::Tolerances::limit)); default none (the
    /// description's `[calibration] tolerance_limit`, else cpm-calib's 1).
    pub tolerance_limit: Option<f64>,
    /// Residuals of 6-D tracker poses; default [`TrackerResiduals::Auto`].
    pub tracker_residuals: TrackerResiduals,
}

impl FitOptions {
    /// The options with every default, for `robot`, `data` and the output directory `out`.
    pub fn new(robot: impl Into<PathBuf>, data: Vec<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            data,
            effects: None,
            sigma_um: None,
            pose_sigma_um: None,
            orientation_sigma_urad: None,
            robust: None,
            keep_outliers: false,
            max_iterations: None,
            out: out.into(),
            noise_per_kind: NoisePerKind::Auto,
            tolerance: Vec::new(),
            hold: Vec::new(),
            no_prior: false,
            tolerance_limit: None,
            tracker_residuals: TrackerResiduals::Auto,
        }
    }

    /// Checks the options that need no file (usage errors, exit code 2): the output directory,
    /// the loss, the iteration limit, the noises.
    pub fn validate(&self) -> anyhow::Result<()> {
        crate::load::check_out_dir(&self.out)?;
        solver_options(
            &mut IdentifyOptions::default(),
            self.robust.as_ref(),
            self.max_iterations,
        )?;
        if let Some(s) = self.sigma_um.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(usage_error(format!("--sigma-um must be > 0, got {s}")));
        }
        for (v, name) in [
            (self.pose_sigma_um, "--pose-sigma-um"),
            (self.orientation_sigma_urad, "--orientation-sigma-urad"),
        ] {
            if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
                return Err(usage_error(format!("{name} must be > 0")));
            }
        }
        if let Some(l) = self.tolerance_limit.filter(|l| !(*l > 0.0)) {
            return Err(usage_error(format!(
                "--tolerance-limit must be > 0 (a number of tolerances; inf for no limit), got {l}"
            )));
        }
        // A prior switched off has no tolerances to take: say so rather than ignore them.
        if self.no_prior {
            let given = if !self.tolerance.is_empty() {
                Some("--tolerance")
            } else if self.tolerance_limit.is_some() {
                Some("--tolerance-limit")
            } else {
                None
            };
            if let Some(option) = given {
                return Err(usage_error(format!(
                    "--no-prior conflicts with {option}: without a prior no tolerance is used (give one or the other; --hold keeps a group at nominal in either)"
                )));
            }
        }
        Ok(())
    }
    /// The tolerances of the fit: the description's, then the options'.
    pub fn tolerances(&self, robot: &Robot) -> anyhow::Result<crate::calib::Tolerances> {
        let mut t = tolerances_of(robot, &self.tolerance, &self.hold, self.no_prior)?;
        if let Some(limit) = self.tolerance_limit {
            t.set_limit(limit)
                .map_err(|e| usage_error(format!("--tolerance-limit: {e}")))?;
        }
        Ok(t)
    }
    /// Checks the options (usage errors before any file is read), then loads and checks the
    /// robot, the effects and the data.
    pub fn load(&self, progress: &dyn Progress) -> anyhow::Result<Inputs> {
        self.validate()?;
        let inputs = load_inputs(self, progress)?;
        self.prepare(inputs, progress)
    }

    /// What [`load`](Self::load) does once the robot and the data are loaded: the solver
    /// options, the noise per kind, the tracker residuals (also for inputs loaded otherwise,
    /// [`crate::memory`]).
    pub fn prepare(&self, mut inputs: Inputs, progress: &dyn Progress) -> anyhow::Result<Inputs> {
        solver_options(
            &mut inputs.identify,
            self.robust.as_ref(),
            self.max_iterations,
        )?;
        inputs.identify.keep_outliers = self.keep_outliers;
        let per_kind = match self.noise_per_kind {
            NoisePerKind::On => true,
            NoisePerKind::Off => false,
            NoisePerKind::Auto => crate::calib::noise::needs_reweighing(
                &inputs.merged.campaign,
                crate::calib::noise::Declared::of(&inputs.merged.campaign, &inputs.identify),
            ),
        };
        if per_kind {
            progress.stage("estimating the noise of each kind of observation");
            let campaign = &inputs.merged.campaign;
            let declared = crate::calib::noise::Declared::of(campaign, &inputs.identify);
            let r =
                crate::calib::noise::reweigh(&inputs.model, campaign, &inputs.identify, declared)
                    .map_err(|e| crate::load::locate(e, &inputs.merged))?;
            let list: Vec<String> = r
                .kinds
                .iter()
                .map(|k| {
                    format!(
                        "{} {:.3} {}",
                        k.name,
                        k.estimated.unwrap_or(k.assumed),
                        k.unit
                    )
                })
                .collect();
            progress.note(&format!(
                "noise per kind of observation ({} fits): {}",
                r.fits,
                list.join(", ")
            ));
            let c = &mut std::sync::Arc::make_mut(&mut inputs.merged).campaign;
            c.pose_sigma_um = r.campaign.pose_sigma_um;
            c.orientation_sigma_urad = r.campaign.orientation_sigma_urad;
            c.point_sigma_um = r.campaign.point_sigma_um;
            c.tilt_sigma_urad = r.campaign.tilt_sigma_urad;
            inputs.identify.sigma_um = r.options.sigma_um;
            c.reading_sigma_um = r.campaign.reading_sigma_um;
        }
        // Full tracker poses: pose or leg residuals, whichever predicts held-out poses better
        // (after the noise per kind, which weighs the pose residuals).
        if self.tracker_residuals == TrackerResiduals::Auto {
            let (model, merged) = (&inputs.model, &inputs.merged);
            if crate::calib::model::leg_space_applies(&merged.campaign) {
                progress.stage("choosing the tracker residuals (pose or legs) by cross-validation");
            }
            let choice = crate::calib::fit::formulation::choose_tracker_residuals(
                model,
                &merged.campaign,
                &inputs.identify,
                5,
            )
            .map_err(|e| crate::load::locate(e, merged))?;
            if let Some(c) = choice {
                inputs.identify.leg_space = c.leg_space;
                progress.note(&format!(
                    "tracker residuals: {} (cross-validated, {}: pose residuals {:.3}, leg residuals {:.3}, weighted RMS in um of the reference; the legs' gain in mean squared error {:.4e} +- {:.4e} um^2 is {} its standard error; --tracker-residuals chooses)",
                    if c.leg_space { "legs" } else { "pose" },
                    c.folds,
                    c.pose_cv_rms,
                    c.leg_cv_rms,
                    c.legs_gain_um2,
                    c.legs_gain_se_um2,
                    if c.leg_space { "beyond" } else { "not beyond" }
                ));
            }
        }
        Ok(inputs)
    }
}

/// Loads robot, effects and data for `calibrate` and `refine`.
fn load_inputs(args: &FitOptions, progress: &dyn Progress) -> anyhow::Result<Inputs> {
    let data = &args.data;
    progress.stage("reading the robot description");
    let robot = crate::load::load_robot(&args.robot, progress)?;
    let names = data.iter().map(|p| p.display().to_string()).collect();
    let read = |robot: &Robot, options: &io::ReadOptions, registration: &RegistrationOptions| {
        crate::load::load_data(data, robot, options, registration)
    };
    load_inputs_with(args, robot, read, data.clone(), names, &[], progress)
}

/// [`load_inputs`] with the robot given and the data read by `read` (with the read and
/// registration options of the model); `data_paths` are the files read (empty for data in
/// memory), `names` what the provenance calls the data, `instruments` one's own instruments
/// (the model's [`instruments`](MeasurementModel::instruments), whose measurements the data
/// hold).
pub(crate) fn load_inputs_with(
    args: &FitOptions,
    robot: Robot,
    read: impl FnOnce(&Robot, &io::ReadOptions, &RegistrationOptions) -> anyhow::Result<Merged>,
    data_paths: Vec<PathBuf>,
    names: Vec<String>,
    instruments: &[std::sync::Arc<dyn crate::calib::instruments::Instrument>],
    progress: &dyn Progress,
) -> anyhow::Result<Inputs> {
    // The tracker's noise: the options, else the description's `[calibration]`.
    let declared = robot.tracker_sigmas();
    let (pose_sigma_um, orientation_sigma_urad) = (
        args.pose_sigma_um.or(declared.0),
        args.orientation_sigma_urad.or(declared.1),
    );
    crate::load::require_six_links(&robot)?;
    let effects = crate::load::resolve_effects(args.effects.as_deref(), &robot)?;
    let model = robot.model(&effects);
    let sigma = crate::load::sigma(args.sigma_um, &robot)?;
    for (v, name) in [
        (pose_sigma_um, "--pose-sigma-um"),
        (orientation_sigma_urad, "--orientation-sigma-urad"),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                return Err(usage_error(format!("{name} must be > 0")));
            }
        }
    }
    progress.stage("reading the measurements");
    let mut merged = read(
        &robot,
        &crate::load::read_options(&model),
        &crate::load::registration_options(&model),
    )?;
    crate::load::warn_excluded(progress, &merged.excluded);
    if let Some(v) = pose_sigma_um {
        merged.campaign.pose_sigma_um = v;
        merged.campaign.point_sigma_um = v;
    }
    if let Some(v) = orientation_sigma_urad {
        merged.campaign.orientation_sigma_urad = v;
        merged.campaign.tilt_sigma_urad = v;
    }
    // The instruments' own declared noise, unless an option gave one.
    let (point, tilt) = robot.instrument_sigmas();
    if let (Some(v), None) = (point, args.pose_sigma_um) {
        merged.campaign.point_sigma_um = v;
    }
    if let (Some(v), None) = (tilt, args.orientation_sigma_urad) {
        merged.campaign.tilt_sigma_urad = v;
    }
    // The gauges keep their own noise (`--sigma-um`, `[calibration] sensor_noise_um`), never
    // the tracker's: undeclared, next to other instruments, cpm-calib's default.
    let c = &mut merged.campaign;
    let others = c.len() > c.readings.len();
    c.reading_sigma_um = match sigma {
        Some(s) => s,
        None if others && !c.readings.is_empty() => {
            crate::calib::campaign::DEFAULT_READING_SIGMA_UM
        }
        None => 0.0,
    };
    if merged.campaign.simulated {
        progress.note("the measurements are SIMULATED; every output says so");
    }
    // Tracker data: the session frame is refined in the fit by default (registered before it,
    // then held fixed, it would make the installation errors look better known than they
    // are); an explicit --effects list is taken as it is.
    let mut model = model;
    if !merged.campaign.pose_measurements.is_empty()
        && args.effects.is_none()
        && !model.effects.contains(&crate::calib::Effect::TrackerFrame)
    {
        let mut e = model.effects.clone();
        e.push(crate::calib::Effect::TrackerFrame);
        if !e.contains(&crate::calib::Effect::MarkerFrame) {
            e.push(crate::calib::Effect::MarkerFrame);
        }
        model = robot.model(&e);
        progress.note("tracker data: the tracker frame and the marker frame (the body the tracker measures, on the platform) are refined in the fit (tracker_frame, marker_frame added; their gauge freedoms with the base and platform joints are reported); give --effects to choose the effects yourself");
    }
    // Every tracker file is a session with its own set-up: one frame each.
    model.tracker_frame_sessions = tracker_sessions(&merged.campaign);
    // Point targets and inclinometers: their own unknowns (targets, mounts) and each
    // session's frame or levelling are always estimated with the machine.
    if let Some(m) = crate::load::with_instruments(&model, &merged.campaign) {
        model = m;
        progress.note(&crate::load::instruments_note(&model));
    }
    // One's own instruments: their own block each, always estimated with the machine.
    if instruments.is_empty() && !merged.campaign.instrument_measurements.is_empty() {
        return Err(usage_error(
            "measurements of one's own instruments are given without the instruments: give them to the job (memory::calibrate_with_instruments)",
        ));
    }
    if !instruments.is_empty() {
        // Named apart: reports and `[calibration.instruments]` know them by name.
        for (k, a) in instruments.iter().enumerate() {
            if instruments[..k].iter().any(|b| b.name() == a.name()) {
                return Err(usage_error(format!(
                    "two instruments are named `{}`: give each its own name",
                    a.name()
                )));
            }
        }
        model.instruments = instruments.to_vec();
        model.instrument_sessions = merged
            .campaign
            .instrument_measurements
            .iter()
            .map(|m| m.session + 1)
            .max()
            .unwrap_or(0);
    }
    // `thermal_drift` over time counts hours from one origin for the whole fit (every
    // subset refine tests, every file validate reads back): the description's, else the
    // earliest time of these data, written into calibrated.toml.
    if model.effect_settings.reference_time_s.is_none() {
        model.effect_settings.reference_time_s = merged.campaign.first_time_s();
    }
    // No hidden load: an effect whose direction comes from the link forces needs the load
    // the description declares.
    if robot.description.load.is_none() {
        if let Some(e) = model.effects.iter().find(|e| needs_load(**e)) {
            return Err(crate::error::input_error(format!(
                "{}: the effect `{}` needs the platform's load (the link forces give its direction), and the description declares none: add a [load] table (platform_mass_kg, platform_com_mm, optional payload and external wrench; docs/formats.md) or leave `{}` out",
                robot.file,
                e.name(),
                e.name()
            )));
        }
    }
    let tolerances = args.tolerances(&robot)?;
    check_description_groups(&robot, &model, &tolerances)?;
    crate::calib::prior::prior_std(&model, &tolerances).map_err(|e| {
        if args.tolerance.is_empty() && args.hold.is_empty() {
            // The options name no group: the description's [calibration] is at fault.
            anyhow::Error::new(crate::io::ReadError::from(crate::io::InputError {
                file: robot.file.clone(),
                line: None,
                field: Some("calibration".to_string()),
                message: format!("tolerances: {e}"),
            }))
        } else {
            usage_error(format!("tolerances: {e}"))
        }
    })?;
    let identify = IdentifyOptions {
        sigma_um: sigma,
        tolerances,
        leg_space: args.tracker_residuals == TrackerResiduals::Legs,
        cancel: progress.cancel_flag(),
        ..IdentifyOptions::default()
    };
    Ok(Inputs {
        data_paths,
        provenance: Provenance {
            robot: robot.file.clone(),
            data: names,
        },
        identify,
        robot,
        model,
        merged: std::sync::Arc::new(merged),
    })
}

/// The tolerances of a description's `[calibration]`, then the `--tolerance` and `--hold`
/// options on top, and `--no-prior`.
pub fn tolerances_of(
    robot: &Robot,
    tolerance: &[Tolerance],
    hold: &[Group],
    no_prior: bool,
) -> anyhow::Result<crate::calib::Tolerances> {
    let mut t = robot
        .tolerances()
        .map_err(|e| anyhow::Error::new(crate::io::ReadError::from(e)))?;
    // The description declares the machine's tolerances for every fit it takes part in: a
    // group this fit lacks is left aside ([`check_description_groups`]); one the options
    // name must be in the fit.
    t.optional = t.by_group.keys().chain(&t.hold).cloned().collect();
    for given in tolerance {
        t.set(given.group.as_str(), given.value)
            .map_err(|e| usage_error(format!("--tolerance {:?}: {e}", given.to_string())))?;
        t.optional.remove(given.group.as_str());
    }
    for h in hold {
        if !t.hold.iter().any(|g| g == h.as_str()) {
            t.hold.push(h.0.clone());
        }
        t.optional.remove(h.as_str());
    }
    t.off = no_prior;
    Ok(t)
}

/// The groups the description's `[calibration]` names (its tolerances and holds) that this
/// fit lacks are left aside, but each must be a group some fit can have: the installation
/// errors, an effect, or one of the model's instruments. Another name is an error of the
/// description (exit 3), naming the file and the field.
pub fn check_description_groups(
    robot: &Robot,
    model: &MeasurementModel,
    tolerances: &crate::calib::Tolerances,
) -> anyhow::Result<()> {
    let groups: Vec<String> = model
        .blocks()
        .iter()
        .map(|b| crate::calib::prior::group_name(model, b))
        .collect();
    for name in &tolerances.optional {
        let known = groups.contains(name)
            || name == crate::calib::prior::INSTALLATION_ERRORS
            || crate::calib::Effect::parse_among(name, &robot.user_effects).is_ok();
        if !known {
            let field = if tolerances.by_group.contains_key(name) {
                format!("calibration.tolerances.{name}")
            } else {
                "calibration.hold".to_string()
            };
            return Err(anyhow::Error::new(crate::io::ReadError::from(
                crate::io::InputError {
                    file: robot.file.clone(),
                    line: None,
                    field: Some(field),
                    message: format!(
                        "`{name}` is not a parameter group (installation_errors, an effect, or an instrument of the description; this fit's groups: {})",
                        groups.join(", ")
                    ),
                },
            )));
        }
    }
    Ok(())
}

/// True for the effects whose direction the link forces set, and so need a declared `[load]`:
/// compliance and the clearance correction.
pub fn needs_load(effect: crate::calib::Effect) -> bool {
    matches!(
        effect,
        crate::calib::Effect::Compliance | crate::calib::Effect::Clearance
    )
}

/// The sessions of a campaign that hold tracker pose measurements, when there are two or more
/// (each gets its own `tracker_frame`); none for one (the one shared frame).
pub fn tracker_sessions(campaign: &Campaign) -> Vec<usize> {
    let mut s: Vec<usize> = campaign
        .pose_measurements
        .iter()
        .map(|m| campaign.session_of(m.pose))
        .collect();
    s.dedup();
    s.sort_unstable();
    s.dedup();
    if s.len() > 1 {
        s
    } else {
        Vec::new()
    }
}

/// The warning of a tracker fit whose frame was not estimated.
pub const FRAME_HELD_FIXED: &str = "**Tracker frame held fixed**: the tracker frame was registered before the fit and held fixed (`tracker_frame` is not among the effects), so the standard deviations leave out its uncertainty and understate the errors' own; add `tracker_frame` to refine the frame in the fit.";

/// Adds to a fit's report what its sessions say: a tracker frame held fixed
/// ([`FRAME_HELD_FIXED`]) and estimates that move between sessions ([`session_warning`]).
pub fn add_session_warnings(
    fit: &mut FitReport,
    inputs: &Inputs,
    model: &MeasurementModel,
) -> anyhow::Result<()> {
    let held = (!inputs.merged.campaign.pose_measurements.is_empty()
        && !model.effects.contains(&crate::calib::Effect::TrackerFrame))
    .then(|| FRAME_HELD_FIXED.to_string());
    for w in held.into_iter().chain(session_warning(inputs)?) {
        fit.warnings.push(w.replace("**", ""));
        fit.text.warnings.push(w);
    }
    Ok(())
}

/// The start of the warning of a residual that is not white ([`whiteness_warning`]).
pub const NOT_WHITE: &str = "**The residual is not white**";

/// A warning when the residual of `cal` (its flagged outliers left out), in acquisition order,
/// fails the whiteness test `cpm refine` runs (the runs test on its signs and the Ljung-Box
/// test over lags 1 to 10, both at refine's default level 0.01): it follows the order of the
/// observations, structure the model lacks, and its RMS is then not the noise. Names the
/// residual against the declared noise when there is one (a weighted figure, in sigma, when
/// `weighted`: the residual mixes kinds weighed differently), and points to `cpm refine`.
pub fn whiteness_warning(cal: &Calibration, weighted: bool) -> Option<String> {
    whiteness_warning_of(cal, weighted, not_white(cal)?)
}

/// The test of [`whiteness_warning`]: the residual's diagnostics when it is not white.
fn not_white(cal: &Calibration) -> Option<crate::calib::diagnostics::ResidualDiagnostics> {
    let alpha = crate::calib::RefineOptions::default().alpha;
    let r: Vec<f64> = cal
        .residuals_um
        .iter()
        .enumerate()
        .filter(|(k, _)| !cal.outliers.contains(k))
        .map(|(_, r)| *r)
        .collect();
    let dof = r.len().saturating_sub(cal.identifiability.rank);
    if dof < 10 {
        return None;
    }
    let d = crate::calib::diagnostics::diagnose(&r, dof, None, &[], alpha);
    (!d.white).then_some(d)
}

/// The warning of [`whiteness_warning`] of the diagnostics `d` of a residual not white.
fn whiteness_warning_of(
    cal: &Calibration,
    weighted: bool,
    d: crate::calib::diagnostics::ResidualDiagnostics,
) -> Option<String> {
    use crate::report::format::{p_value, sig};
    let f = |x: f64| sig(x, 3);
    let noise = match (cal.sigma_estimated, cal.sigma_um) {
        _ if weighted => format!(
            "weighted residual RMS {} in sigma (each residual over its kind's noise at the fit's noise scale){}",
            f(d.rms_um / cal.sigma_um),
            if cal.sigma_estimated {
                ", which is then not the noise it is taken for"
            } else {
                ""
            }
        ),
        (false, s) if s > 0.0 => format!(
            "residual RMS {} um against the declared noise {} um",
            f(d.rms_um),
            f(s)
        ),
        _ => format!(
            "residual RMS {} um, which is then not the noise it is taken for",
            f(d.rms_um)
        ),
    };
    Some(format!(
        "{NOT_WHITE} (runs test p = {}, Ljung-Box p = {}, lag-1 autocorrelation {}; {noise}): it follows the order of the observations, an effect the model lacks. `cpm refine` tests the candidate effects (link offsets, backlash, ...) against it.",
        p_value(d.runs_p),
        p_value(d.ljung_box_p),
        sig(d.lag1_autocorrelation, 2)
    ))
}

/// A warning when the sessions (files) of the campaign, each fitted on its own, estimate the
/// machine differently by more than their standard deviations allow.
pub fn session_warning(inputs: &Inputs) -> anyhow::Result<Option<String>> {
    let c = crate::calib::session::consistency(
        &inputs.model,
        &inputs.merged.campaign,
        &inputs.identify,
    )
    .map_err(|e| crate::load::locate(e, &inputs.merged))?;
    let Some(c) = c.filter(|c| !c.consistent) else {
        return Ok(None);
    };
    let file = |s: usize| {
        inputs
            .provenance
            .data
            .get(s)
            .cloned()
            .unwrap_or_else(|| format!("session {}", s + 1))
    };
    let worst = c
        .pairs
        .iter()
        .max_by(|a, b| a.worst_z.abs().total_cmp(&b.worst_z.abs()))
        .expect("an inconsistent result has a pair");
    Ok(Some(format!(
        "**Estimates move between sessions**: fitted on its own, {} and {} differ in `{}` by {:.1} standard deviations of the difference ({} of {} parameters by more than 3). The machine or its set-up changed between the sessions, or the model lacks an effect they see differently: compare them with `cpm validate`, session by session.",
        file(worst.sessions[0]),
        file(worst.sessions[1]),
        worst.worst_parameter,
        worst.worst_z.abs(),
        worst.beyond_3sd,
        worst.compared
    )))
}

/// Sets the solver options of `--robust` and `--max-iterations` (usage errors when bad).
pub fn solver_options(
    identify: &mut IdentifyOptions,
    robust: Option<&Loss>,
    max_iterations: Option<usize>,
) -> anyhow::Result<()> {
    if let Some(loss) = robust {
        crate::options::check_loss(loss)?;
        identify.lm.loss = *loss;
    }
    if let Some(n) = max_iterations {
        if n == 0 {
            return Err(usage_error("--max-iterations must be >= 1"));
        }
        identify.lm.max_iterations = n;
        identify.lm.max_evaluations = identify.lm.max_evaluations.max(n.saturating_add(1));
    }
    Ok(())
}

/// A fit and its staged outputs (not yet written).
pub struct Fitted {
    /// The calibration.
    pub cal: Calibration,
    /// `calibration.json`, `report.md`, the figures and `calibrated.toml`, staged in `dir`.
    pub set: OutputSet,
    /// The report (`calibration.json`, report.md and report.html are renderings of it).
    pub report: crate::report::calibrate::CalibrateReport,
    /// The poses the fit left out because it could not start there (see [`leaving_out`]).
    pub excluded: Vec<crate::io::ExcludedPose>,
    /// Where the time went, s: the fit (the solver and the statistics of the calibration),
    /// then its outputs (report, figures, residuals, `calibrated.toml` and its read-back).
    pub seconds: FitSeconds,
}

/// The wall-clock time of the stages of [`fit_with`], s.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitSeconds {
    /// The fit: [`identify_with`](crate::formulation::identify_with) (solver, identifiability,
    /// noise), with the poses it had to leave out.
    pub fit_s: f64,
    /// The outputs staged from it (report, figures, residuals, `calibrated.toml` and its
    /// read-back check).
    pub outputs_s: f64,
}

/// Fits the inputs and stages every output of `cpm calibrate` in memory, for `dir`: nothing
/// is written (commit the set). Errors name the file and line of the pose they are about.
pub fn fit(inputs: &Inputs, dir: &Path, minimum_norm: bool) -> anyhow::Result<Fitted> {
    fit_with(
        inputs,
        dir,
        minimum_norm,
        crate::formulation::FormulationArg::Auto,
    )
}

/// [`fit`] with the formulation chosen by `formulation` (see [`crate::formulation`]).
pub fn fit_with(
    inputs: &Inputs,
    dir: &Path,
    minimum_norm: bool,
    formulation: crate::formulation::FormulationArg,
) -> anyhow::Result<Fitted> {
    let started = std::time::Instant::now();
    // A pose where the fit cannot start (forward kinematics does not converge there) is
    // left out, with its observations, and the fit run again (see `leaving_out`).
    let ((cal, formulation), excluded) = leaving_out(inputs, |merged| {
        let (model, campaign) = (&inputs.model, &merged.campaign);
        let f = crate::formulation::resolve(formulation, model, campaign, &inputs.identify);
        crate::formulation::identify_with(f, model, campaign, &inputs.identify).map(|c| (c, f))
    })?;
    let left_out;
    let inputs = if excluded.is_empty() {
        inputs
    } else {
        left_out = inputs.without_poses(&excluded);
        &left_out
    };
    let campaign = &inputs.merged.campaign;
    let model = &inputs.model;
    let fit_s = started.elapsed().as_secs_f64();
    let started = std::time::Instant::now();
    let mut set = OutputSet::new();
    // The report's figures and the whiteness test beside the fit report (each a pass of its
    // own over the residual, most of it on one core): the same results, in less time.
    let (fit, (white, figures)) = rayon::join(
        || -> anyhow::Result<FitReport> {
            let mut fit = FitReport::new(&inputs.report_inputs(), model, &cal, Some(formulation));
            add_session_warnings(&mut fit, inputs, model)?;
            Ok(fit)
        },
        || {
            rayon::join(
                || not_white(&cal),
                || {
                    let mut figures = OutputSet::new();
                    crate::staging::stage_figures(
                        &mut figures,
                        dir,
                        &inputs.robot,
                        model,
                        campaign,
                        &cal,
                    )
                    .map(|names| (figures, names))
                },
            )
        },
    );
    let mut fit = fit?;
    if let Some(w) = white.and_then(|d| whiteness_warning_of(&cal, fit.residual_weighted, d)) {
        fit.warnings.push(w.replace("**", ""));
        fit.text.warnings.push(w);
    }
    set.add(dir.join("calibration.json"), fit.to_json()?);
    crate::staging::stage_residuals(&mut set, dir, inputs, &cal);
    let (figure_files, figures) = figures?;
    set.append(figure_files);
    let notes = crate::staging::stage_calibrated(
        &mut set,
        dir,
        inputs,
        model,
        &cal,
        minimum_norm,
        None,
        "Calibrated",
        formulation == crate::formulation::Formulation::Nested,
    )?;
    let report = CalibrateReport {
        provenance: provenance_lines(&inputs.provenance, cal.simulated, "Calibrated"),
        calibrated: CalibratedFile {
            minimum_norm,
            undetermined: notes.undetermined.len(),
            known_effects: notes.known_effects.clone(),
        },
        figures: figures.iter().map(|f| f.to_string()).collect(),
        fit,
    };
    let markdown = report.markdown();
    set.add(dir.join("report.md"), markdown.as_str());
    crate::load::stage_report_html(&mut set, dir, "cpm calibration report", &markdown);
    Ok(Fitted {
        cal,
        set,
        report,
        excluded: excluded.into_iter().map(|(_, e)| e).collect(),
        seconds: FitSeconds {
            fit_s,
            outputs_s: started.elapsed().as_secs_f64(),
        },
    })
}

/// Runs `fit` (a fit of the merged data) on `inputs`' data; when it fails at one pose
/// (forward kinematics does not converge or the statics fail there,
/// [`error_pose`](crate::load::error_pose)), leaves that pose out with all its observations
/// and runs it again, for at most one pose in
/// [`POSES_PER_EXCLUDED_POSE`](crate::io::campaign::POSES_PER_EXCLUDED_POSE) of the campaign
/// (then the error, naming file and line, as before). Returns its result and the poses left
/// out (each with its index in the campaign as it was then, and what to record).
pub fn leaving_out<T>(
    inputs: &Inputs,
    mut fit: impl FnMut(&Merged) -> Result<T, crate::calib::CalibError>,
) -> anyhow::Result<(T, Vec<(usize, crate::io::ExcludedPose)>)> {
    let budget = crate::io::campaign::max_excluded_poses(inputs.merged.campaign.poses.len());
    let mut excluded: Vec<(usize, crate::io::ExcludedPose)> = Vec::new();
    let mut merged = std::borrow::Cow::Borrowed(&*inputs.merged);
    loop {
        let e = match fit(&merged) {
            Ok(r) => return Ok((r, excluded)),
            Err(e) => e,
        };
        let pose = crate::load::error_pose(&e)
            .filter(|_| excluded.len() < budget && merged.campaign.poses.len() > 1);
        let Some((pose, (file, line, label))) =
            pose.and_then(|p| merged.pose_origin.get(p).cloned().map(|o| (p, o)))
        else {
            return Err(crate::load::locate(e, &merged));
        };
        excluded.push((
            pose,
            crate::io::ExcludedPose {
                file,
                line,
                label,
                // The error's campaign index ("pose 16: ") says less than the label
                // beside it, and names a pose of the campaign as it was then.
                reason: format!(
                    "the fit cannot start there: {}",
                    e.to_string().replacen(&format!("pose {pose}: "), "", 1)
                ),
            },
        ));
        merged = std::borrow::Cow::Owned(merged.without_pose(pose));
    }
}

/// The options of `cpm calibrate`: the fit's, the formulation, and the write-back.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrateOptions {
    /// Robot, data, effects, noise, solver and output directory.
    #[serde(flatten)]
    pub fit: FitOptions,
    /// Kept for compatibility (calibrated.toml always holds the fit's complete point);
    /// default false.
    pub minimum_norm: bool,
    /// The formulation; default [`FormulationArg::Auto`](crate::formulation::FormulationArg).
    pub formulation: crate::formulation::FormulationArg,
}

impl CalibrateOptions {
    /// The options with every default, for `robot`, `data` and the output directory `out`.
    pub fn new(robot: impl Into<PathBuf>, data: Vec<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            fit: FitOptions::new(robot, data, out),
            minimum_norm: false,
            formulation: crate::formulation::FormulationArg::Auto,
        }
    }
}

/// What [`calibrate`] gives: the inputs as loaded, the calibration, its report and every
/// output staged for the output directory (commit it with
/// [`commit_dir`](crate::load::commit_dir), or read the files from it).
pub struct Calibrated {
    /// The inputs (robot, model, data, options) as the fit used them.
    pub inputs: Inputs,
    /// The fit, its staged outputs and its report.
    pub fitted: Fitted,
}

impl Calibrated {
    /// The trouble the fit reports with its outputs written (the command's exit code 1): a
    /// robust fit that failed, or a solver that did not converge; `None` when all is well.
    pub fn trouble(&self) -> Option<String> {
        let cal = &self.fitted.cal;
        if let Some(why) = cal.robust_failure() {
            Some(format!(
                "the fit failed: {why}; the outputs were written and say so"
            ))
        } else if cal.solver.was_successful() {
            None
        } else {
            Some(format!(
                "the solver did not converge ({}); the outputs were written and say so",
                cal.solver.termination
            ))
        }
    }

    /// The input files of the job (an output may not replace one).
    pub fn input_paths(&self) -> Vec<&Path> {
        std::iter::once(Path::new(&self.inputs.robot.file))
            .chain(self.inputs.data_paths.iter().map(PathBuf::as_path))
            .collect()
    }
}

/// `cpm calibrate` as a function: checks the options, loads the robot and the data, fits,
/// and stages every output for `options.fit.out` (nothing is written: commit the set). Stages
/// and notes go to `progress`; a cancelled job returns [`Cancelled`](crate::Cancelled).
pub fn calibrate(
    options: &CalibrateOptions,
    progress: &dyn Progress,
) -> anyhow::Result<Calibrated> {
    crate::progress::unless_cancelled(calibrate_job(options, progress), progress)
}

fn calibrate_job(
    options: &CalibrateOptions,
    progress: &dyn Progress,
) -> anyhow::Result<Calibrated> {
    options.fit.validate()?;
    check_cancelled(progress)?;
    let inputs = options.fit.load(progress)?;
    check_cancelled(progress)?;
    progress.stage(&format!(
        "fitting {} to {} observations",
        crate::load::describe_model(&inputs.model),
        inputs.merged.campaign.len()
    ));
    let fitted = fit_with(
        &inputs,
        &options.fit.out,
        options.minimum_norm,
        options.formulation,
    )?;
    crate::load::warn_excluded(progress, &fitted.excluded);
    check_cancelled(progress)?;
    Ok(Calibrated { inputs, fitted })
}

#[cfg(test)]
mod tests {
    use super::reproduces;

    /// The read-back may improve on a fit that stopped short of its frames' optimum (issue
    /// 33: 267.206037 fitted, 267.205535 read back), never do worse.
    #[test]
    fn a_read_back_may_improve_on_the_fit_never_worsen_it() {
        assert!(reproduces(267.206037, 267.205535));
        assert!(reproduces(238.132801, 238.127928));
        assert!(reproduces(1.0, 1.0));
        assert!(!reproduces(1.0, 1.0 + 1e-6));
        assert!(!reproduces(1.0, 0.99));
    }
}
