//! `calibration.json`: what a calibration found, with its uncertainty and what it could not
//! determine (`docs/formats.md` lists every key).
use cpm_calib::{Calibration, Campaign, MeasurementModel};
use cpm_geometry::InstallationErrors;
use serde_json::{json, Value};

use super::robot::split_params;

fn opt(v: Option<f64>) -> Value {
    v.filter(|x| x.is_finite())
        .map(|x| json!(x))
        .unwrap_or(Value::Null)
}

/// `{ "base": [[dx, dy, dz], ...], "platform": [...] }` from installation-error values in
/// model order (`null` where unknown).
pub fn per_joint(values: &[Option<f64>]) -> Value {
    let links = values.len() / 6;
    let side = |s: usize| -> Value {
        Value::Array(
            (0..links)
                .map(|i| Value::Array((0..3).map(|a| opt(values[6 * i + 3 * s + a])).collect()))
                .collect(),
        )
    };
    json!({ "base": side(0), "platform": side(1) })
}

/// The `effects` array: per effect of the model its parameters with value, std and unit.
pub fn effects_json(
    model: &MeasurementModel,
    estimate: &[Option<f64>],
    std: &[Option<f64>],
) -> Value {
    let sensors: Vec<String> = model
        .nominal
        .sensors
        .iter()
        .map(|s| s.name.clone())
        .collect();
    let est = split_params(model, estimate);
    let sd = split_params(model, std);
    Value::Array(
        est.effects
            .iter()
            .zip(&sd.effects)
            .map(|((e, v), (_, s))| {
                json!({
                    "effect": e.name(),
                    "parameters": v.iter().zip(s).enumerate().map(|(k, (v, s))| json!({
                        "name": e.param_name(k, &sensors),
                        "value": opt(*v),
                        "std": opt(*s),
                        "unit": e.param_unit(k),
                    })).collect::<Vec<_>>(),
                })
            })
            .collect(),
    )
}

/// Where the inputs came from, for the record.
#[derive(Debug, Clone, Default)]
pub struct Provenance {
    /// The robot description file.
    pub robot: String,
    /// The measurement files.
    pub data: Vec<String>,
}

/// The identifiability part (rank, spectrum, blind directions).
pub fn identifiability_json(i: &cpm_calib::Identifiability, names: &[String]) -> Value {
    json!({
        "parameters": i.num_params,
        "observations": i.num_readings,
        "rank": i.rank,
        "rank_rtol": i.rank_rtol,
        "threshold": i.threshold,
        "determined": i.num_determined(),
        "singular_values": i.singular_values,
        "blind_directions": i.blind_directions.iter().map(|b| json!({"description": b.description, "dimensions": b.dimensions})).collect::<Vec<_>>(),
        "unexplained_null_dimensions": i.unexplained_null_dimensions,
        "sigma_um": i.sigma_um,
        "crlb_rms_um": opt(i.crlb_rms_um()),
        "crlb_max_um": opt(i.crlb_max_um()),
        "per_parameter": names.iter().enumerate().map(|(k, n)| json!({
            "name": n,
            "determined": i.determined[k],
            "null_fraction": i.null_fraction[k],
            "crlb_std": opt(i.crlb_std_um[k]),
        })).collect::<Vec<_>>(),
    })
}

/// The solver report.
pub fn solver_json(r: &cpm_lm::Report) -> Value {
    json!({
        "converged": r.was_successful(),
        "termination": r.termination.to_string(),
        "iterations": r.num_iterations(),
        "initial_cost": r.initial_cost,
        "final_cost": r.final_cost,
        "summary": r.brief(),
    })
}

/// The whole `calibration.json`.
pub fn calibration_json(
    model: &MeasurementModel,
    campaign: &Campaign,
    cal: &Calibration,
    provenance: &Provenance,
) -> Value {
    let ni = model.num_installation_params();
    let names = model.parameter_names();
    let not_determined: Vec<String> = (0..ni)
        .filter(|&k| cal.estimate_um[k].is_none())
        .map(InstallationErrors::component_name)
        .collect();
    let minimum_norm: Vec<Option<f64>> = cal.minimum_norm_um.iter().map(|v| Some(*v)).collect();
    json!({
        "cpm_version": env!("CARGO_PKG_VERSION"),
        "simulated": cal.simulated,
        "robot": provenance.robot,
        "data": provenance.data,
        "readings": campaign.readings.len(),
        "pose_measurements": campaign.pose_measurements.len(),
        "poses": campaign.poses.len(),
        "installation_errors_um": per_joint(&cal.estimate_um[..ni]),
        "std_um": per_joint(&cal.std_um[..ni]),
        "minimum_norm_um": per_joint(&minimum_norm[..ni]),
        "not_determined": not_determined,
        "effects": effects_json(model, &cal.estimate_um, &cal.std_um),
        // Known values applied in every prediction (the estimates above are on top of them).
        "known_effects": model
            .known_effects
            .iter()
            .map(|k| json!({"effect": k.effect.name(), "unit": k.effect.unit(), "values": k.values}))
            .collect::<Vec<_>>(),
        "residual_rms_um": cal.residual_rms_um,
        "initial_rms_um": cal.initial_rms_um,
        "sigma_um": cal.sigma_um,
        "sigma_estimated": cal.sigma_estimated,
        "sigma_excludes_outliers": cal.sigma_excludes_outliers,
        "identifiability": identifiability_json(&cal.identifiability, &names),
        "solver": solver_json(&cal.solver),
    })
}
