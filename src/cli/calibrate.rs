//! `cpm calibrate`: fit the installation errors and declared effects to measurements, and
//! write `calibration.json`, `report.md`, SVG figures and `calibrated.toml`.
use std::path::{Path, PathBuf};

use clap::Args;
use serde_json::json;

use super::common::{self, EffectsArg, RobotArg};
use super::{plots, Ctx, Outcome};
use crate::calib::{identify, Calibration, Campaign, IdentifyOptions, MeasurementModel};
use crate::io::{self, Merged, Provenance, Robot};
use crate::output::OutputSet;

/// Arguments of `cpm calibrate`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm calibrate --robot examples/hexapod_66.toml --data data.csv --out cal/\n  cpm calibrate --robot robot.toml --data lengths.csv --data tracker.csv --effects link_offset,link_scale,tracker_frame --out cal/ --json"
)]
pub struct CalibrateArgs {
    /// The robot description.
    #[command(flatten)]
    pub robot: RobotArg,
    /// Measurement files (length readings or tracker poses, docs/formats.md); repeatable.
    #[arg(long, value_name = "DATA.csv", required = true)]
    pub data: Vec<PathBuf>,
    /// The effects modelled.
    #[command(flatten)]
    pub effects: EffectsArg,
    /// Sensor noise standard deviation, um (default: [calibration] sensor_noise_um of the
    /// description, else estimated from the residual).
    #[arg(long, value_name = "UM")]
    pub sigma_um: Option<f64>,
    /// Tracker position noise, um (standard deviation per coordinate; default cpm-calib's).
    #[arg(long, value_name = "UM")]
    pub pose_sigma_um: Option<f64>,
    /// Tracker orientation noise, urad (default cpm-calib's).
    #[arg(long, value_name = "URAD")]
    pub orientation_sigma_urad: Option<f64>,
    /// Write the minimum-norm solution into calibrated.toml (blind directions at nominal)
    /// rather than only the components the data determine on their own.
    #[arg(long)]
    pub minimum_norm: bool,
    /// Output directory (created; existing files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
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
pub fn load_inputs(
    robot_path: &Path,
    data: &[PathBuf],
    effects: &EffectsArg,
    sigma_um: Option<f64>,
    pose_sigma_um: Option<f64>,
    orientation_sigma_urad: Option<f64>,
    ctx: &Ctx<'_>,
) -> anyhow::Result<Inputs> {
    ctx.stage("reading the robot description");
    let robot = common::load_robot(robot_path, ctx)?;
    common::require_six_links(&robot)?;
    let effects = effects.resolve(&robot)?;
    let model = robot.model(&effects);
    let sigma = common::sigma(sigma_um, &robot)?;
    ctx.stage("reading the measurements");
    let mut merged = common::load_data(data, &robot, &common::read_options(&effects))?;
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
    let (desc, notes) = io::calibrated_description(&inputs.robot, model, &params, declare);
    let mut header = provenance_lines(&inputs.provenance, cal.simulated, command);
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

/// Runs `cpm calibrate`.
pub fn run(args: &CalibrateArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    common::check_out_dir(&args.out)?;
    let inputs = load_inputs(
        &args.robot.robot,
        &args.data,
        &args.effects,
        args.sigma_um,
        args.pose_sigma_um,
        args.orientation_sigma_urad,
        ctx,
    )?;
    let campaign = &inputs.merged.campaign;
    let model = &inputs.model;
    ctx.stage(format!(
        "fitting {} to {} observations",
        common::describe_model(model),
        campaign.len()
    ));
    let cal = identify(model, campaign, &inputs.identify)
        .map_err(|e| common::locate(e, &inputs.merged))?;
    ctx.stage("writing the results");
    let dir = &args.out;
    let mut set = OutputSet::new();
    let value = io::calibration_json(model, campaign, &cal, &inputs.provenance);
    set.add(
        dir.join("calibration.json"),
        serde_json::to_string_pretty(&value)?,
    );
    let figures = stage_figures(&mut set, dir, &inputs.robot, model, campaign, &cal)?;
    let notes = stage_calibrated(
        &mut set,
        dir,
        &inputs,
        model,
        &cal,
        args.minimum_norm,
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
    r.push('\n');
    fit_report(&mut r, &inputs.robot, model, campaign, &cal);
    r.push_str("## Outputs\n\n- `calibration.json`: estimates, standard deviations, what is not determined, residual, solver report.\n");
    r.push_str(&format!(
        "- `calibrated.toml`: the robot description with the {} ({} installation-error components left at nominal); `link_offset`/`link_scale` folded into the link reading models.\n",
        if args.minimum_norm { "minimum-norm solution" } else { "determined installation errors" },
        notes.undetermined.len()
    ));
    for f in &figures {
        r.push_str(&format!("- `{f}`\n"));
    }
    set.add(dir.join("report.md"), r);
    let written = common::commit(set, &dir.display().to_string())?;
    ctx.finish();
    if args.json {
        let v = json!({
            "simulated": cal.simulated,
            "out": dir.display().to_string(),
            "files": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            "rank": cal.identifiability.rank,
            "parameters": cal.identifiability.num_params,
            "determined": cal.identifiability.num_determined(),
            "residual_rms_um": cal.residual_rms_um,
            "converged": cal.solver.was_successful(),
            "not_determined": value["not_determined"],
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
    if cal.solver.was_successful() {
        Ok(Outcome::Done)
    } else {
        Ok(Outcome::Trouble(format!(
            "the solver did not converge ({}); the outputs were written and say so",
            cal.solver.termination
        )))
    }
}
