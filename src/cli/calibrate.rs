//! `cpm calibrate`: fit the installation errors and declared effects to measurements, and
//! write `calibration.json`, `report.md`, SVG figures and `calibrated.toml`.
use std::path::{Path, PathBuf};

use clap::Args;
use serde_json::json;

use super::common::{self, EffectsArg, RobotArg};
use super::{plots, Ctx, Outcome};
use crate::calib::{Calibration, Campaign, IdentifyOptions, MeasurementModel};
use crate::io::{self, Merged, Provenance, Robot};
use crate::output::OutputSet;

/// Arguments of `cpm calibrate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm calibrate --robot examples/hexapod_66.toml --data data.csv --out cal/\n  cpm calibrate --robot robot.toml --data lengths.csv --data tracker.csv --effects link_offset,link_scale,tracker_frame --out cal/ --json"
)]
pub struct CalibrateArgs {
    /// Robot, data, effects, noise, solver and output: as for `cpm refine`.
    #[command(flatten)]
    pub fit: FitArgs,
    /// Write the minimum-norm solution into calibrated.toml (blind directions at nominal)
    /// rather than only the components the data determine on their own.
    #[arg(long)]
    pub minimum_norm: bool,
    /// Formulation of the fit: `auto` (nested below 100,000 readings, implicit from there
    /// when the campaign has length readings only and the fit is plain least squares),
    /// `nested` or `implicit`. The report and calibration.json say which was used.
    #[arg(long, value_enum, default_value_t = super::formulation::FormulationArg::Auto)]
    pub formulation: super::formulation::FormulationArg,
}

/// The arguments every fit (`cpm calibrate`, `cpm refine`) takes.
#[derive(Debug, Clone, Args)]
pub struct FitArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Measurement files (length readings or tracker poses, docs/formats.md); repeatable.
    #[arg(long, value_name = "DATA.csv", required = true)]
    pub data: Vec<PathBuf>,
    /// The effects modelled.
    #[command(flatten)]
    pub effects: EffectsArg,
    /// Sensor noise standard deviation, um (default: `[calibration] sensor_noise_um` of the
    /// description, else estimated from the residual).
    #[arg(long, value_name = "UM")]
    pub sigma_um: Option<f64>,
    /// Tracker position noise, um (standard deviation per coordinate; default cpm-calib's).
    #[arg(long, value_name = "UM")]
    pub pose_sigma_um: Option<f64>,
    /// Tracker orientation noise, urad (default cpm-calib's).
    #[arg(long, value_name = "URAD")]
    pub orientation_sigma_urad: Option<f64>,
    /// Robust loss against outlier readings: huber:K, cauchy:K or tukey:K with K in um of
    /// reading (where the loss departs from the square; e.g. 3 x the noise), or none (least
    /// squares, the default). Readings more than 5 robust standard deviations off are
    /// flagged in report.md and calibration.json either way.
    #[arg(long, value_name = "LOSS:K")]
    pub robust: Option<String>,
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
}

impl FitArgs {
    /// Checks the options (usage errors before any file is read), then loads and checks the
    /// robot, the effects and the data.
    pub fn load(&self, ctx: &Ctx<'_>) -> anyhow::Result<Inputs> {
        common::check_out_dir(&self.out)?;
        solver_options(
            &mut IdentifyOptions::default(),
            self.robust.as_deref(),
            self.max_iterations,
        )?;
        let mut inputs = load_inputs(self, ctx)?;
        solver_options(
            &mut inputs.identify,
            self.robust.as_deref(),
            self.max_iterations,
        )?;
        Ok(inputs)
    }
}

/// The inputs of a fit, loaded and checked.
pub struct Inputs {
    /// The robot.
    pub robot: Robot,
    /// The model.
    pub model: MeasurementModel,
    /// The merged data.
    pub merged: Merged,
    /// Identification options.
    pub identify: IdentifyOptions,
    /// Where it all came from.
    pub provenance: Provenance,
}

/// Loads robot, effects and data for `calibrate` and `refine`.
fn load_inputs(args: &FitArgs, ctx: &Ctx<'_>) -> anyhow::Result<Inputs> {
    let (data, effects) = (&args.data, &args.effects);
    let (pose_sigma_um, orientation_sigma_urad) = (args.pose_sigma_um, args.orientation_sigma_urad);
    ctx.stage("reading the robot description");
    let robot = common::load_robot(&args.robot.robot, ctx)?;
    common::require_six_links(&robot)?;
    let effects = effects.resolve(&robot)?;
    let model = robot.model(&effects);
    let sigma = common::sigma(args.sigma_um, &robot)?;
    for (v, name) in [
        (pose_sigma_um, "--pose-sigma-um"),
        (orientation_sigma_urad, "--orientation-sigma-urad"),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                return Err(super::usage_error(format!("{name} must be > 0")));
            }
        }
    }
    ctx.stage("reading the measurements");
    let mut merged = common::load_data(data, &robot, &common::read_options(&model))?;
    if let Some(v) = pose_sigma_um {
        merged.campaign.pose_sigma_um = v;
    }
    if let Some(v) = orientation_sigma_urad {
        merged.campaign.orientation_sigma_urad = v;
    }
    if merged.campaign.simulated {
        ctx.note("the measurements are SIMULATED; every output says so");
    }
    Ok(Inputs {
        provenance: Provenance {
            robot: robot.file.clone(),
            data: data.iter().map(|p| p.display().to_string()).collect(),
        },
        identify: IdentifyOptions {
            sigma_um: sigma,
            ..IdentifyOptions::default()
        },
        robot,
        model,
        merged,
    })
}

/// A header for generated files.
pub fn provenance_lines(p: &Provenance, simulated: bool, command: &str) -> Vec<String> {
    let mut v = vec![format!(
        "{command} by cpm {} from {} and {}",
        env!("CARGO_PKG_VERSION"),
        p.robot,
        p.data.join(", ")
    )];
    if simulated {
        v.push("SIMULATED data: this calibration is of a simulated machine.".into());
    }
    v
}

fn cell(v: Option<f64>, digits: usize) -> String {
    v.filter(|x| x.is_finite())
        .map_or("n.d.".to_string(), |x| format!("{x:.digits$}"))
}

/// The report's sections on a fit: data, fit, identifiability, estimates.
pub fn fit_report(
    s: &mut String,
    robot: &Robot,
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &Calibration,
    loss: &cpm_lm::Loss,
) {
    let names = model.parameter_names();
    s.push_str(&format!(
        "- Robot: `{}` ({} links, {} sensors); clearance {} um per joint.\n",
        robot.file,
        robot.num_links(),
        robot.table.sensors.len(),
        model.clearance.radius_um
    ));
    s.push_str(&format!(
        "- Data: {} length readings and {} tracker pose measurements at {} poses{}.\n",
        campaign.readings.len(),
        campaign.pose_measurements.len(),
        campaign.poses.len(),
        if campaign.simulated {
            " (**SIMULATED**)"
        } else {
            ""
        }
    ));
    s.push_str(&format!("- Model: {}.\n", common::describe_model(model)));
    s.push_str(&format!("- Loss: {}.\n", common::describe_loss(loss)));
    s.push_str(&format!(
        "- Residual RMS {:.3} um (at the start {:.3} um); noise {} {:.3} um.\n",
        cal.residual_rms_um,
        cal.initial_rms_um,
        if cal.sigma_estimated {
            "estimated from the residual:"
        } else {
            "declared:"
        },
        cal.sigma_um
    ));
    s.push_str(&format!(
        "- Solver: {}{}.\n\n",
        cal.solver.brief(),
        if cal.solver.was_successful() {
            ""
        } else {
            " — **did not converge: treat the estimates with suspicion**"
        }
    ));
    s.push_str("## What the data identify\n\n");
    s.push_str(&cal.identifiability.summary().replace("\n  - ", "\n- "));
    s.push_str(&format!(
        "\nCramér-Rao bounds: RMS {} um, worst {} um over the determined parameters.\n\n",
        cell(cal.identifiability.crlb_rms_um(), 3),
        cell(cal.identifiability.crlb_max_um(), 3)
    ));
    s.push_str("## Estimates\n\nn.d. = not determined by the data: no estimate exists, whatever a solver would print. The numbers `#` match `estimates.svg`.\n\n| # | parameter | estimate | std |\n|---|---|---|---|\n");
    let mut plotted = 0;
    for (k, n) in names.iter().enumerate() {
        let num = if cal.estimate_um[k].is_some() {
            plotted += 1;
            plotted.to_string()
        } else {
            String::new()
        };
        s.push_str(&format!(
            "| {num} | {n} | {} | {} |\n",
            cell(cal.estimate_um[k], 3),
            cell(cal.std_um[k], 3)
        ));
    }
    s.push('\n');
}

/// The `estimates.svg` figure: determined installation errors with error bars.
pub fn estimates_figure(model: &MeasurementModel, cal: &Calibration) -> anyhow::Result<String> {
    let names = model.parameter_names();
    let points: Vec<(String, f64, f64)> = (0..model.num_params())
        .filter_map(|k| {
            cal.estimate_um[k].map(|v| (names[k].clone(), v, cal.std_um[k].unwrap_or(0.0)))
        })
        .collect();
    Ok(plots::estimates(
        &format!(
            "Determined parameters, +-2 std{}",
            if cal.simulated {
                " (SIMULATED data)"
            } else {
                ""
            }
        ),
        "estimate (unit in report.md)",
        &points,
    )?)
}

/// Stages the figures of a fit.
pub fn stage_figures(
    set: &mut OutputSet,
    dir: &Path,
    robot: &Robot,
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &Calibration,
) -> anyhow::Result<Vec<&'static str>> {
    let sensors: Vec<String> = robot.table.sensors.iter().map(|s| s.name.clone()).collect();
    let sim = if campaign.simulated {
        " (SIMULATED)"
    } else {
        ""
    };
    let mut files = vec!["residuals_pose.svg", "estimates.svg"];
    set.add(
        dir.join("residuals_pose.svg"),
        plots::residuals_vs_pose(
            &format!("Residual after the fit against pose{sim}"),
            campaign,
            &sensors,
            &cal.residuals_um,
        )?,
    );
    if let Some(svg) = plots::residuals_vs_time(
        &format!("Residual after the fit against time{sim}"),
        campaign,
        &sensors,
        &cal.residuals_um,
    ) {
        set.add(dir.join("residuals_time.svg"), svg?);
        files.push("residuals_time.svg");
    }
    set.add(dir.join("estimates.svg"), estimates_figure(model, cal)?);
    Ok(files)
}

/// Stages `calibrated.toml`.
pub fn stage_calibrated(
    set: &mut OutputSet,
    dir: &Path,
    inputs: &Inputs,
    model: &MeasurementModel,
    cal: &Calibration,
    minimum_norm: bool,
    declare: Option<&[crate::calib::Effect]>,
    command: &str,
) -> anyhow::Result<io::robot::CalibratedNotes> {
    let params: Vec<Option<f64>> = if minimum_norm {
        cal.minimum_norm_um.iter().map(|v| Some(*v)).collect()
    } else {
        cal.estimate_um.clone()
    };
    let (mut desc, notes) = io::calibrated_description(&inputs.robot, model, &params, declare);
    // Reading offsets the registration applied to the data belong to the link reading models.
    if let Some(r) = inputs
        .merged
        .registration
        .as_ref()
        .filter(|r| r.offsets_applied)
    {
        for ((spec, orig), o) in desc
            .links
            .iter_mut()
            .zip(&inputs.robot.description.links)
            .zip(&r.link_offset_mm)
        {
            spec.length_at_zero_mm += o * spec.mm_per_unit / orig.mm_per_unit;
        }
    }
    // A pose error map describes the poses it was fitted on: their range goes with it.
    if model
        .effects
        .iter()
        .any(|e| matches!(e, crate::calib::Effect::PoseMap(_)))
    {
        let range = crate::calib::refine::PoseRange::of(&inputs.merged.campaign);
        let spec = desc
            .pose_map
            .get_or_insert(crate::geometry::description::PoseMapSpec {
                degree: None,
                fitted_min: None,
                fitted_max: None,
            });
        spec.fitted_min = Some(range.min);
        spec.fitted_max = Some(range.max);
    }
    let mut header = provenance_lines(&inputs.provenance, cal.simulated, command);
    if !cal.solver.was_successful() {
        header.push(format!(
            "WARNING: the solver did not converge ({}): these joints are where it stopped, not a calibration.",
            cal.solver.termination
        ));
    }
    if minimum_norm {
        header.push("Minimum-norm solution: components the data do not determine on their own are set from the identifiable combinations, blind directions at nominal.".into());
    }
    let text = io::calibrated_toml(&desc, &notes, &header).map_err(super::trouble)?;
    // The file must load back.
    io::Robot::from_toml(&text, "calibrated.toml").map_err(|e| {
        super::trouble(format!(
            "the calibrated description does not load back: {e}"
        ))
    })?;
    set.add(dir.join("calibrated.toml"), text);
    Ok(notes)
}

/// Sets the solver options of `--robust` and `--max-iterations` (usage errors when bad).
pub fn solver_options(
    identify: &mut IdentifyOptions,
    robust: Option<&str>,
    max_iterations: Option<usize>,
) -> anyhow::Result<()> {
    if let Some(spec) = robust {
        identify.lm.loss =
            common::parse_loss(spec).map_err(|m| super::usage_error(format!("--robust {m}")))?;
    }
    if let Some(n) = max_iterations {
        if n == 0 {
            return Err(super::usage_error("--max-iterations must be >= 1"));
        }
        identify.lm.max_iterations = n;
        identify.lm.max_evaluations = identify.lm.max_evaluations.max(n.saturating_add(1));
    }
    Ok(())
}

/// The chi-square test of the fit against the declared noise (`None` when the noise was
/// estimated from the residual, or no degree of freedom is left).
pub fn misfit(cal: &Calibration) -> Option<crate::calib::misfit::Misfit> {
    if cal.sigma_estimated {
        return None;
    }
    crate::calib::misfit::chi_square(
        &cal.residuals_um,
        cal.sigma_um,
        cal.identifiability.rank,
        &cal.outliers,
    )
}

/// What a misfit says, in words.
pub fn misfit_message(m: &crate::calib::misfit::Misfit) -> String {
    format!(
        "**The model does not fit the data to the declared noise**: chi2/dof = {:.2} on {} degrees of freedom (p {}), residual RMS {:.3} um against the declared {} um{}. The standard deviations assume the declared noise and are too small. An effect the model lacks (backlash, link offsets or scales, thermal drift, ...) or a noise larger than declared: `cpm refine` tests the effect library on these data.",
        m.chi2_per_dof,
        m.dof,
        if m.p_value < 1e-300 {
            "< 1e-300".to_string()
        } else {
            format!("= {:.1e}", m.p_value)
        },
        m.residual_rms_um,
        m.sigma_um,
        if m.outliers_left_out > 0 {
            format!(", {} flagged outliers left out", m.outliers_left_out)
        } else {
            String::new()
        }
    )
}

/// `calibration.json`'s `misfit` object (null when the noise was estimated).
pub fn misfit_json(cal: &Calibration) -> serde_json::Value {
    match misfit(cal) {
        Some(m) => json!({
            "chi2": m.chi2,
            "dof": m.dof,
            "chi2_per_dof": m.chi2_per_dof,
            "p_value": m.p_value,
            "residual_rms_um": m.residual_rms_um,
            "sigma_um": m.sigma_um,
            "outliers_left_out": m.outliers_left_out,
            "inconsistent": m.inconsistent(),
            "rule": format!("inconsistent when p < {} and chi2/dof > {}", crate::calib::misfit::MISFIT_P, crate::calib::misfit::MISFIT_CHI2_PER_DOF),
            "message": if m.inconsistent() { Some(misfit_message(&m).replace("**", "")) } else { None },
        }),
        None => serde_json::Value::Null,
    }
}

/// What the data did not determine, how the fit ended, and whether the model fits the
/// declared noise, in a few lines for the top of a report (empty when all is well).
pub fn warnings(model: &MeasurementModel, cal: &Calibration) -> Vec<String> {
    let mut w = Vec::new();
    if let Some(why) = cal.robust_failure() {
        w.push(format!(
            "**The fit failed**: {why}. Use a larger K (about 3 x the noise) or least squares."
        ));
    }
    if !cal.solver.was_successful() {
        w.push(format!(
            "**The solver did not converge** ({}): the estimates are where it stopped; treat them with suspicion.",
            cal.solver.termination
        ));
    }
    let id = &cal.identifiability;
    if id.rank < id.num_params {
        w.push(format!(
            "**Rank-deficient fit**: the data determine {} of {} parameters on their own (rank {} of {}); the others have no estimate (`n.d.`, see \"What the data identify\").",
            id.num_determined(),
            model.num_params(),
            id.rank,
            id.num_params
        ));
    }
    if cal.sigma_estimated && cal.residuals_um.len() <= id.rank {
        w.push(format!(
            "**The noise cannot be estimated**: {} observations for {} identifiable combinations leave no residual degrees of freedom; the standard deviations are meaningless. Give the noise with `--sigma-um`.",
            cal.residuals_um.len(),
            id.rank
        ));
    }
    if !cal.outliers.is_empty() {
        w.push(format!(
            "**{} outlier observation{}** (more than 5 robust standard deviations off): listed under \"Outliers\".",
            cal.outliers.len(),
            if cal.outliers.len() == 1 { "" } else { "s" }
        ));
    }
    if let Some(m) = misfit(cal).filter(|m| m.inconsistent()) {
        w.push(misfit_message(&m));
    }
    w
}

/// Where observation `k` of a merged campaign came from and what it is.
pub struct ObservationOrigin {
    /// The file.
    pub file: String,
    /// Its line.
    pub line: usize,
    /// What was observed: `sensor s1 at pose "3"`, `tracker x of pose "7"`.
    pub what: String,
}

/// The origin of observation `k` (readings first, then 6 per pose measurement).
pub fn observation_origin(robot: &Robot, merged: &Merged, k: usize) -> Option<ObservationOrigin> {
    let c = &merged.campaign;
    let m = c.readings.len();
    if k < m {
        let r = &c.readings[k];
        let (file, line) = merged.reading_origin.get(k)?.clone();
        let label = merged.pose_origin.get(r.pose).map_or("?", |o| o.2.as_str());
        let sensor = robot
            .table
            .sensors
            .get(r.sensor)
            .map_or("?", |s| s.name.as_str());
        Some(ObservationOrigin {
            file,
            line,
            what: format!("sensor {sensor} at pose {label:?}"),
        })
    } else {
        let pm = c.pose_measurements.get((k - m) / 6)?;
        let (file, line, label) = merged.pose_origin.get(pm.pose)?.clone();
        let comp = ["x", "y", "z", "rotation x", "rotation y", "rotation z"][(k - m) % 6];
        Some(ObservationOrigin {
            file,
            line,
            what: format!("tracker {comp} of pose {label:?}"),
        })
    }
}

/// The `outliers` array of `calibration.json`: per flagged observation its file, line, what
/// it is and its residual.
pub fn outliers_json(robot: &Robot, merged: &Merged, cal: &Calibration) -> serde_json::Value {
    serde_json::Value::Array(
        cal.outliers
            .iter()
            .map(|&k| {
                let o = observation_origin(robot, merged, k);
                json!({
                    "observation": k + 1,
                    "file": o.as_ref().map(|o| o.file.clone()),
                    "line": o.as_ref().map(|o| o.line),
                    "what": o.as_ref().map(|o| o.what.clone()),
                    "residual_um": cal.residuals_um.get(k).copied().filter(|v| v.is_finite()),
                })
            })
            .collect(),
    )
}

/// The report's outlier section (nothing when none were flagged).
pub fn outliers_report(s: &mut String, robot: &Robot, merged: &Merged, cal: &Calibration) {
    if cal.outliers.is_empty() {
        return;
    }
    s.push_str("## Outliers

Observations whose residual is more than 5 robust standard deviations (1.4826 x MAD) from the median. With `--robust` their influence on the fit is limited; without it they pull on every estimate. Check the instrument log at these lines.

| file:line | observation | residual (um) |
|---|---|---|
");
    for &k in &cal.outliers {
        let r = cal.residuals_um.get(k).copied().unwrap_or(f64::NAN);
        match observation_origin(robot, merged, k) {
            Some(o) => s.push_str(&format!(
                "| {}:{} | {} | {r:.3} |
",
                o.file, o.line, o.what
            )),
            None => s.push_str(&format!(
                "| ? | observation {} | {r:.3} |
",
                k + 1
            )),
        }
    }
    s.push('\n');
}

/// A fit and its staged outputs (not yet written).
pub struct Fitted {
    /// The calibration.
    pub cal: Calibration,
    /// `calibration.json`, `report.md`, the figures and `calibrated.toml`, staged in `dir`.
    pub set: OutputSet,
    /// The contents of `calibration.json`.
    pub value: serde_json::Value,
}

/// A parameter's name, estimate and standard deviation (`None` when not determined).
type NamedValue = (String, Option<f64>, Option<f64>);

/// The fitted values of one effect block: (name, estimate, standard deviation).
fn block_values(
    model: &MeasurementModel,
    cal: &Calibration,
    effect: crate::calib::Effect,
) -> Option<Vec<NamedValue>> {
    let names = model.parameter_names();
    let b = model
        .blocks()
        .into_iter()
        .find(|b| b.effect == Some(effect))?;
    Some(
        (b.offset..b.offset + b.len)
            .map(|k| {
                (
                    names[k].clone(),
                    cal.estimate_um.get(k).copied().flatten(),
                    cal.std_um.get(k).copied().flatten(),
                )
            })
            .collect(),
    )
}

/// `calibration.json`'s `registration` object: the automatic registration of the tracker
/// files (per file: translation mm, rotation deg, RMS before and after; reading offsets mm per
/// link), the fit's refinements of it (`tracker_frame`, `link_offset`) and their gauge
/// freedoms; null without tracker files.
pub fn registration_json(
    merged: &Merged,
    model: &MeasurementModel,
    cal: &Calibration,
) -> serde_json::Value {
    let Some(r) = &merged.registration else {
        return serde_json::Value::Null;
    };
    let vals = |e| {
        block_values(model, cal, e).map(|v| {
            v.into_iter()
                .map(|(n, v, s)| json!({"name": n, "value": v, "std": s}))
                .collect::<Vec<_>>()
        })
    };
    let gauge: Vec<String> = cal
        .identifiability
        .blind_directions
        .iter()
        .filter(|b| b.description.contains("tracker"))
        .map(|b| b.description.clone())
        .collect();
    json!({
        "apply_threshold_mm": io::REGISTRATION_APPLY_MM,
        "failure": r.failure,
        "sessions": r.sessions.iter().map(|s| {
            let f = &s.frame;
            let [ro, pi, ya] = f.as_pose().rpy_deg();
            json!({
                "file": s.file,
                "poses": f.poses,
                "applied": s.applied,
                "largest_move_mm": s.largest_move_mm,
                "translation_mm": [f.translation_mm.x, f.translation_mm.y, f.translation_mm.z],
                "translation_sd_mm": f.translation_sd_mm,
                "rotation_vector_deg": f.rotation_vector_deg(),
                "rotation_sd_deg": f.rotation_sd_deg,
                "rotation_angle_deg": f.rotation_angle_deg(),
                "roll_pitch_yaw_deg": [ro, pi, ya],
                "rms_before_mm": f.rms_before_mm,
                "rms_after_mm": f.rms_after_mm,
                "orientation_rms_before_deg": f.orientation_rms_before_deg,
                "orientation_rms_after_deg": f.orientation_rms_after_deg,
            })
        }).collect::<Vec<_>>(),
        "link_reading_offset_mm": r.link_offset_mm,
        "link_reading_offset_sd_mm": r.link_offset_sd_mm,
        "offsets_estimated": r.offsets_estimated,
        "offsets_applied": r.offsets_applied,
        "variance_factor": r.variance_factor,
        "refined_by_fit": {
            "tracker_frame": vals(crate::calib::Effect::TrackerFrame),
            "link_offset": vals(crate::calib::Effect::LinkOffset),
            "gauge_freedoms": gauge,
        },
    })
}

/// The registration section of report.md (nothing without tracker files).
pub fn registration_report(
    s: &mut String,
    merged: &Merged,
    model: &MeasurementModel,
    cal: &Calibration,
) {
    let Some(r) = &merged.registration else {
        return;
    };
    s.push_str("## Tracker registration\n\n");
    if let Some(why) = &r.failure {
        s.push_str(&format!("The automatic registration of the tracker frames failed ({why}); the measured poses were used as logged.\n\n"));
        return;
    }
    s.push_str(&format!("Each tracker file (session) gets its own frame, found from the data against the nominal forward kinematics of its readings (closed form, then Gauss-Newton with one reading offset per link shared by the files); a frame that moves a measured position by more than {} mm, or offsets larger than that, are applied to the data before the fit, smaller ones are left to the fit. Standard deviations are scaled by the registration's variance factor ({:.3}).\n\n", io::REGISTRATION_APPLY_MM, r.variance_factor));
    s.push_str("| file | poses | translation, mm (sd) | rotation vector, deg (sd) | angle, deg | RMS before, mm | RMS after, mm | applied |\n|---|---|---|---|---|---|---|---|\n");
    for x in &r.sessions {
        let f = &x.frame;
        let t = f.translation_mm;
        let w = f.rotation_vector_deg();
        s.push_str(&format!(
            "| {} | {} | {:.3} ({:.3}), {:.3} ({:.3}), {:.3} ({:.3}) | {:.4} ({:.4}), {:.4} ({:.4}), {:.4} ({:.4}) | {:.4} | {:.3} | {:.4} | {} |\n",
            x.file, f.poses,
            t.x, f.translation_sd_mm[0], t.y, f.translation_sd_mm[1], t.z, f.translation_sd_mm[2],
            w[0], f.rotation_sd_deg[0], w[1], f.rotation_sd_deg[1], w[2], f.rotation_sd_deg[2],
            f.rotation_angle_deg(), f.rms_before_mm, f.rms_after_mm,
            if x.applied { "yes" } else { "no (small)" }
        ));
    }
    s.push('\n');
    if r.offsets_estimated {
        s.push_str(&format!(
            "Link reading offsets (true length = logged length + offset), mm: {}; {}.\n\n",
            r.link_offset_mm
                .iter()
                .zip(&r.link_offset_sd_mm)
                .enumerate()
                .map(|(i, (o, sd))| format!("link {} {o:.3} +- {sd:.3}", i + 1))
                .collect::<Vec<_>>()
                .join(", "),
            if r.offsets_applied {
                "applied to the commanded lengths before the fit and folded into `calibrated.toml`"
            } else {
                "not applied (small: left to `link_offset`)"
            }
        ));
    } else {
        s.push_str("Link reading offsets were not estimated (the poses cannot tell them from the frames).\n\n");
    }
    for e in [
        crate::calib::Effect::TrackerFrame,
        crate::calib::Effect::LinkOffset,
    ] {
        if let Some(v) = block_values(model, cal, e) {
            s.push_str(&format!(
                "Refined by the fit, `{}` (on top of the registration): {}.\n\n",
                e.name(),
                v.iter()
                    .map(|(n, v, sd)| match (v, sd) {
                        (Some(v), Some(sd)) => format!("{n} {v:.2} +- {sd:.2}"),
                        _ => format!("{n} not determined"),
                    })
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
    }
    let gauge: Vec<&str> = cal
        .identifiability
        .blind_directions
        .iter()
        .filter(|b| b.description.contains("tracker"))
        .map(|b| b.description.as_str())
        .collect();
    if !gauge.is_empty() {
        s.push_str(&format!("Gauge freedoms of the refinement: {} (the fit determines the tracker frame only together with the installation errors; these directions are not determined).\n\n", gauge.join("; ")));
    }
}

/// Fits the inputs and stages every output of `cpm calibrate` in memory, for `dir`: nothing
/// is written (commit the set). Errors name the file and line of the pose they are about.
pub fn fit(inputs: &Inputs, dir: &Path, minimum_norm: bool) -> anyhow::Result<Fitted> {
    fit_with(
        inputs,
        dir,
        minimum_norm,
        super::formulation::FormulationArg::Auto,
    )
}

/// [`fit`] with the formulation chosen by `formulation` (see [`super::formulation`]).
pub fn fit_with(
    inputs: &Inputs,
    dir: &Path,
    minimum_norm: bool,
    formulation: super::formulation::FormulationArg,
) -> anyhow::Result<Fitted> {
    let campaign = &inputs.merged.campaign;
    let model = &inputs.model;
    let formulation = super::formulation::resolve(formulation, model, campaign, &inputs.identify);
    let cal = super::formulation::identify_with(formulation, model, campaign, &inputs.identify)
        .map_err(|e| common::locate(e, &inputs.merged))?;
    let mut set = OutputSet::new();
    let mut value = io::calibration_json(model, campaign, &cal, &inputs.provenance);
    value["formulation"] = json!(formulation.key());
    value["robust_loss"] = json!(common::describe_loss(&inputs.identify.lm.loss));
    value["robust"] = json!({
        "downweighted_share": cal.downweighted_share,
        "downweight_level": crate::calib::DOWNWEIGHT_LEVEL,
        "max_downweighted_share": crate::calib::MAX_DOWNWEIGHTED_SHARE,
        "failed": cal.robust_failed,
    });
    value["outliers"] = outliers_json(&inputs.robot, &inputs.merged, &cal);
    value["registration"] = registration_json(&inputs.merged, model, &cal);
    value["misfit"] = misfit_json(&cal);
    value["warnings"] = json!(warnings(model, &cal)
        .iter()
        .map(|w| w.replace("**", ""))
        .collect::<Vec<_>>());
    set.add(
        dir.join("calibration.json"),
        serde_json::to_string_pretty(&value)?,
    );
    let figures = stage_figures(&mut set, dir, &inputs.robot, model, campaign, &cal)?;
    let notes = stage_calibrated(
        &mut set,
        dir,
        inputs,
        model,
        &cal,
        minimum_norm,
        None,
        "Calibrated",
    )?;
    let mut r = String::new();
    r.push_str("# Calibration report\n\n");
    if cal.simulated {
        r.push_str("**The measurements are SIMULATED.**\n\n");
    }
    for l in provenance_lines(&inputs.provenance, cal.simulated, "Calibrated") {
        r.push_str(&format!("{l}\n"));
    }
    r.push_str(&format!("Formulation: {}.\n", formulation.describe()));
    r.push('\n');
    for w in warnings(model, &cal) {
        r.push_str(&format!("- {w}\n"));
    }
    if cal.sigma_excludes_outliers {
        r.push_str("- The noise was estimated from the residuals without the flagged outliers (robust fit); the standard deviations use it.\n");
    }
    r.push('\n');
    fit_report(
        &mut r,
        &inputs.robot,
        model,
        campaign,
        &cal,
        &inputs.identify.lm.loss,
    );
    outliers_report(&mut r, &inputs.robot, &inputs.merged, &cal);
    registration_report(&mut r, &inputs.merged, model, &cal);
    r.push_str("## Outputs\n\n- `calibration.json`: estimates, standard deviations, what is not determined, residual, solver report.\n");
    r.push_str(&format!(
        "- `calibrated.toml`: the robot description with the {} ({} installation-error components left at nominal); `link_offset`/`link_scale` folded into the link reading models, `socket_error` into the sensor sockets{}.\n",
        if minimum_norm { "minimum-norm solution" } else { "determined installation errors" },
        notes.undetermined.len(),
        if notes.known_effects.is_empty() { String::new() } else { format!(", the values of {} in `[calibration.known_effects]`", notes.known_effects.join(", ")) }
    ));
    for f in &figures {
        r.push_str(&format!("- `{f}`\n"));
    }
    set.add(dir.join("report.md"), r);
    crate::html::stage_report_html(&mut set, dir, "cpm calibration report");
    Ok(Fitted { cal, set, value })
}

/// Runs `cpm calibrate`.
pub fn run(args: &CalibrateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    let inputs = args.fit.load(ctx)?;
    let model = &inputs.model;
    ctx.stage(format!(
        "fitting {} to {} observations",
        common::describe_model(model),
        inputs.merged.campaign.len()
    ));
    let Fitted { cal, set, value } =
        fit_with(&inputs, &args.fit.out, args.minimum_norm, args.formulation)?;
    ctx.stage("writing the results");
    let dir = &args.fit.out;
    let inputs_paths: Vec<&Path> = std::iter::once(args.fit.robot.robot.as_path())
        .chain(args.fit.data.iter().map(PathBuf::as_path))
        .collect();
    let written = common::commit_dir(set, dir, &inputs_paths, "calibrate", ctx)?;
    ctx.finish();
    for w in warnings(model, &cal)
        .iter()
        .skip(usize::from(!cal.succeeded()))
    {
        ctx.note(w.replace("**", ""));
    }
    if args.fit.json {
        let v = json!({
            "simulated": cal.simulated,
            "formulation": value["formulation"],
            "out": dir.display().to_string(),
            "files": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "rank": cal.identifiability.rank,
            "parameters": cal.identifiability.num_params,
            "determined": cal.identifiability.num_determined(),
            "residual_rms_um": cal.residual_rms_um,
            "converged": cal.solver.was_successful(),
            "downweighted_share": cal.downweighted_share,
            "robust_failed": cal.robust_failed,
            "not_determined": value["not_determined"],
            "outliers": value["outliers"],
        });
        writeln!(ctx.out, "{}", serde_json::to_string_pretty(&v)?)?;
    } else {
        writeln!(
            ctx.out,
            "{}rank {} of {}, {} parameters determined, residual RMS {:.3} um; solver: {}",
            if cal.simulated {
                "SIMULATED data: "
            } else {
                ""
            },
            cal.identifiability.rank,
            cal.identifiability.num_params,
            cal.identifiability.num_determined(),
            cal.residual_rms_um,
            cal.solver.termination
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    if let Some(why) = cal.robust_failure() {
        Ok(Outcome::Trouble(format!(
            "the fit failed: {why}; the outputs were written and say so"
        )))
    } else if cal.solver.was_successful() {
        Ok(Outcome::Done)
    } else {
        Ok(Outcome::Trouble(format!(
            "the solver did not converge ({}); the outputs were written and say so",
            cal.solver.termination
        )))
    }
}
