//! What the fits (`cpm calibrate`, `cpm refine`) stage beside their reports: the figures,
//! `residuals.csv` and `calibrated.toml` (checked by reading it back). Shared by both jobs, so
//! that neither imports the other's staging.
use std::path::Path;

use crate::calib::{Calibration, Campaign, MeasurementModel};
use crate::error::trouble;
use crate::io::{self, Provenance, Robot};
use crate::load::Inputs;
use crate::output::OutputSet;

/// Stages the figures of a fit.
pub fn stage_figures(
    set: &mut OutputSet,
    dir: &Path,
    robot: &Robot,
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &Calibration,
) -> anyhow::Result<Vec<&'static str>> {
    let names = crate::report::figures::fit::ResidualNames::new(
        robot.table.sensors.iter().map(|s| s.name.clone()).collect(),
        model,
    );
    // As residuals.csv: measured minus predicted, each kind in its own unit.
    let native = crate::calib::noise::measured_minus_predicted(
        campaign,
        cal.sigma_ref_um,
        &cal.residuals_um,
    );
    let sim = if campaign.simulated {
        " (SIMULATED)"
    } else {
        ""
    };
    let mut files = vec!["residuals_pose.svg", "estimates.svg"];
    set.add(
        dir.join("residuals_pose.svg"),
        crate::report::figures::fit::residuals_vs_pose(
            &format!("Residual after the fit against pose{sim}"),
            campaign,
            &names,
            &native,
        )?,
    );
    if let Some(svg) = crate::report::figures::fit::residuals_vs_time(
        &format!("Residual after the fit against time{sim}"),
        campaign,
        &names,
        &native,
    ) {
        set.add(dir.join("residuals_time.svg"), svg?);
        files.push("residuals_time.svg");
    }
    set.add(
        dir.join("estimates.svg"),
        crate::report::figures::fit::estimates_figure(model, cal)?,
    );
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
    check: bool,
) -> anyhow::Result<io::robot::CalibratedNotes> {
    // The point the fit ended at, complete: a rank-deficient fit writes its point of the
    // solution set (the minimum-norm one), never a mix of fitted and nominal components.
    let _ = minimum_norm;
    let (mut desc, notes) = io::calibrated_description(
        &inputs.robot,
        model,
        &cal.minimum_norm_um,
        &(0..cal.estimate_um.len())
            .map(|k| cal.determination(k))
            .collect::<Vec<_>>(),
        declare,
    );
    // Where it came from (validate's default reference) and whether the data were simulated.
    {
        let c = desc.calibration.get_or_insert_with(Default::default);
        let from = std::path::Path::new(&inputs.robot.file);
        c.calibrated_from = Some(crate::load::calibrated_from(from, dir));
        c.calibrated_from_fnv1a64 = std::fs::read(from)
            .ok()
            .map(|b| format!("{:016x}", crate::output::fingerprint(&b)));
        c.simulated = cal.simulated;
        // What the data left undetermined, for every command that uses the file (compensate
        // warns that its commands cannot correct it).
        c.undetermined = notes
            .undetermined
            .iter()
            .chain(&notes.undetermined_effects)
            .cloned()
            .collect();
        c.blind_directions = if c.undetermined.is_empty() {
            Vec::new()
        } else {
            cal.identifiability
                .blind_directions
                .iter()
                .map(|b| b.description.clone())
                .collect()
        };
        // The time origin of a drift over time, so that its predictions do not depend on
        // which part of a log is given.
        let drift = crate::calib::Effect::ThermalDrift;
        if model.effects.contains(&drift) || model.known_effects.iter().any(|k| k.effect == drift) {
            c.reference_time_s = model.effect_settings.reference_time_s;
        }
        // The covariance of the machine's parameters: what compensate promises from.
        c.covariance = covariance_spec(model, cal);
        // The tracker noise the fit weighed its sessions with: held-out sessions are
        // registered with the same weights.
        if !inputs.merged.campaign.pose_measurements.is_empty() {
            c.tracker_position_sigma_um = Some(inputs.merged.campaign.pose_sigma());
            c.tracker_orientation_sigma_urad = Some(inputs.merged.campaign.orientation_sigma());
        }
    }
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
    let text = io::calibrated_toml(&desc, &notes, &header).map_err(trouble)?;
    // The file must load back.
    // (The user effects the fit modelled are the reader's too: nothing global knows them.)
    let user = crate::load::user_effects_of(&inputs.robot, model);
    let back = io::Robot::from_toml_among(&text, "calibrated.toml", &user).map_err(|e| {
        trouble(format!(
            "the calibrated description does not load back: {e}"
        ))
    })?;
    if check && !inputs.merged.campaign.instrument_measurements.is_empty() {
        instruments_read_back(&back, model, &inputs.merged.campaign, cal)?;
    }
    // What every reader of the file will predict is what the fit predicted: checked on the
    // fit's own data before anything is written.
    // Gauge readings are predicted from the campaign in memory (read from files or given in
    // memory alike); other kinds are read again from their files, and inputs held in memory
    // without files (or a caller's scratch files removed, as Python's binding does when it
    // is interrupted) are not checked for those.
    if check && inputs.data_paths.iter().all(|p| p.exists()) {
        let data = &inputs.data_paths;
        if let Some((fit, file)) = crate::validate::file_reproduces_fit(
            &text,
            &inputs.robot,
            data,
            model,
            &inputs.merged.campaign,
            cal,
            inputs.identify.sigma_um,
            &inputs.merged.excluded,
        )? {
            if !reproduces(fit, file) {
                return Err(trouble(format!(
                    "the calibrated description does not reproduce the fit: weighted residual RMS {fit:.6} fitted, {file:.6} read back from calibrated.toml (in um of the reference noise); nothing was written (please report this)"
                )));
            }
        }
    }
    set.add(dir.join("calibrated.toml"), text);
    Ok(notes)
}

/// The read-back check of a fit with one's own instruments, whose measurements no file holds:
/// the calibrated description `back`, read back with the same instruments
/// ([`calibrated_model`](crate::sources::calibrated_model)), predicts every observation of the
/// fit's own campaign as the fit did, within 1e-6 of its noise (at the commands the fit
/// assumed).
fn instruments_read_back(
    back: &Robot,
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &Calibration,
) -> anyhow::Result<()> {
    use crate::calib::model::{predict, Prepared};
    let (read, params) = crate::sources::calibrated_model(back, &model.instruments)?;
    let mut c = campaign.clone();
    model.log_commands(&mut c);
    let fail = |e: crate::calib::CalibError| trouble(format!("predicting the read-back: {e}"));
    let fitted = predict(
        model,
        &Prepared::new(model, &c).map_err(fail)?,
        &c,
        &cal.minimum_norm_um,
        None,
    )
    .map_err(fail)?;
    let again = predict(
        &read,
        &Prepared::new(&read, &c).map_err(fail)?,
        &c,
        &params,
        None,
    )
    .map_err(fail)?;
    let weights = c.observation_weights(cal.sigma_ref_um);
    let worst = fitted
        .iter()
        .zip(&again)
        .zip(&weights)
        .map(|((a, b), w)| (a - b).abs() * w / cal.sigma_ref_um)
        .fold(0.0, f64::max);
    if !(worst <= 1e-6) {
        return Err(trouble(format!(
            "the calibrated description does not reproduce the fit: read back with the same instruments, it predicts an observation {worst:.3e} of its noise away from the fit; nothing was written (please report this)"
        )));
    }
    Ok(())
}

/// Whether the weighted residual RMS `file` of the fit's own data predicted from the
/// calibrated description (each session's frame or levelling registered afresh, as `cpm
/// validate` does) reproduces the fit's `fit`.
///
/// The read-back holds the machine as written and fits only the session frames, to rounding:
/// a file that holds the fit's machine can never do worse than the fit (beyond 1e-7), and
/// does slightly better when the fit stopped short of the frames' own optimum (it solves in
/// the directions the data determine at the start, which a campaign weighed very unevenly,
/// e.g. inclinometer angles at 2 urad beside points at 50 um, leaves a few 1e-5 above it). A
/// file better than the fit by more than 1e-3 is as suspect as a worse one.
pub fn reproduces(fit: f64, file: f64) -> bool {
    let scale = fit.max(1e-3);
    file - fit <= 1e-7 * scale && fit - file <= 1e-3 * scale
}

/// Stages `residuals.csv` of a fit (its weighted residuals brought back to each
/// observation's own unit).
pub fn stage_residuals(set: &mut OutputSet, dir: &Path, inputs: &Inputs, cal: &Calibration) {
    let native = crate::calib::noise::measured_minus_predicted(
        &inputs.merged.campaign,
        cal.sigma_ref_um,
        &cal.residuals_um,
    );
    // Written as the file is (10^6 rows are 80 MB of text), from the numbers.
    let (robot, merged) = (inputs.robot.clone(), inputs.merged.clone());
    // One's own instruments' rows in their units.
    let units: Vec<String> = inputs
        .model
        .instruments
        .iter()
        .map(|i| i.unit().to_string())
        .collect();
    set.add_streamed(
        dir.join("residuals.csv"),
        Box::new(move |mut out| {
            out.write_all(crate::report::residuals::RESIDUALS_HEADER.as_bytes())?;
            crate::report::residuals::write_residual_rows_with(
                &mut out, &robot, &merged, &native, 1, &units,
            )
        }),
    );
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

/// `[calibration.covariance]` of a fit: the covariance of the machine's parameters (the
/// installation errors and every effect's but the sessions' and instruments' own: tracker,
/// marker and point frames, targets, inclinometer mounts, base tilts) as standard deviations
/// (six significant digits) and correlations (six decimals); `None` when the fit formed none (the implicit formulation).
pub fn covariance_spec(
    model: &MeasurementModel,
    cal: &Calibration,
) -> Option<crate::geometry::description::CovarianceSpec> {
    use crate::calib::Effect;
    let np = model.num_params();
    if cal.covariance.shape() != (np, np) {
        return None;
    }
    let mut keep: Vec<usize> = (0..model.num_installation_params()).collect();
    let mut effects = Vec::new();
    for b in model.blocks().into_iter().skip(1) {
        let Some(e) = b.effect else { continue };
        let session_or_instrument = matches!(
            e,
            Effect::TrackerFrame
                | Effect::MarkerFrame
                | Effect::TargetPosition
                | Effect::PointFrame
                | Effect::InclinometerMount
                | Effect::BaseTilt
        );
        if !session_or_instrument && b.len > 0 {
            effects.push(e.name().to_string());
            keep.extend(b.offset..b.offset + b.len);
        }
    }
    let names = model.parameter_names();
    let c = &cal.covariance;
    let std: Vec<f64> = keep.iter().map(|&k| c[(k, k)].max(0.0).sqrt()).collect();
    // Six significant digits for a deviation, six decimals for a correlation.
    let six = |v: f64| format!("{v:.5e}").parse::<f64>().unwrap_or(v);
    let correlation: Vec<Vec<f64>> = keep
        .iter()
        .enumerate()
        .map(|(a, &ka)| {
            keep.iter()
                .enumerate()
                .map(|(b, &kb)| {
                    if a == b {
                        1.0
                    } else if std[a] > 0.0 && std[b] > 0.0 {
                        let r = (c[(ka, kb)] / (std[a] * std[b])).clamp(-1.0, 1.0);
                        (r * 1e6).round() / 1e6
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    // What nothing bounds: the blind parameters (neither the data nor a tolerance determine
    // them; the covariance holds only their determined part).
    let unbounded = keep
        .iter()
        .filter(|&&k| cal.determination(k) == crate::calib::Determination::Blind)
        .map(|&k| names[k].clone())
        .collect();
    Some(crate::geometry::description::CovarianceSpec {
        effects,
        parameters: keep.iter().map(|&k| names[k].clone()).collect(),
        std: std.iter().map(|v| six(*v)).collect(),
        correlation,
        unbounded,
    })
}
