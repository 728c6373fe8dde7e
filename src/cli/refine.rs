//! `cpm refine`: calibrate, then add the effects that the residual asks for, one at a time,
//! each with an F-test, its BIC change and cross-validation (cpm_calib::refine), and write
//! `refine.json`, `report.md`, `calibration.json`, figures and `calibrated.toml`.
use clap::Args;
use serde_json::{json, Value};

use super::calibrate::{
    self, fit_report, provenance_lines, stage_calibrated, stage_figures, FitArgs,
};
use super::common;
use super::{plots, usage_error, Ctx, Outcome};
use crate::calib::{refine, Effect, RefineOptions, Refinement};
use crate::io::{self, parse_effects};
use crate::output::OutputSet;

/// Arguments of `cpm refine`.
#[derive(Debug, Clone, Args)]
#[command(
    after_help = "Examples:\n  cpm refine --robot examples/hexapod_66.toml --data data.csv --out refined/\n  cpm refine --robot robot.toml --data data.csv --candidates link_offset,link_scale,backlash --max-steps 2 --out refined/ --json"
)]
pub struct RefineArgs {
    /// Robot, data, effects, noise, solver and output: as for `cpm calibrate`.
    #[command(flatten)]
    pub fit: FitArgs,
    /// Candidate effects, comma-separated (default: the whole library).
    #[arg(long, value_name = "LIST")]
    pub candidates: Option<String>,
    /// Most effects added.
    #[arg(long, value_name = "N", default_value_t = 4)]
    pub max_steps: usize,
    /// Significance level of the F-test (before the Bonferroni correction).
    #[arg(long, value_name = "P", default_value_t = 0.01)]
    pub alpha: f64,
    /// Folds of the cross-validation over poses.
    #[arg(long, value_name = "K", default_value_t = 5)]
    pub folds: usize,
    /// Highest degree of the pose error map terms scanned and proposed (0: none, at most 3;
    /// default: `[pose_map] degree` of the description, else 2).
    #[arg(long, value_name = "D")]
    pub pose_map_degree: Option<u8>,
}

fn param_json(effect: Effect, params: &[(String, Option<f64>, Option<f64>)]) -> Value {
    Value::Array(
        params
            .iter()
            .enumerate()
            .map(|(k, (n, v, s))| {
                json!({
                    "name": n,
                    "value": v.filter(|x| x.is_finite()),
                    "std": s.filter(|x| x.is_finite()),
                    "unit": effect.param_unit(k),
                })
            })
            .collect(),
    )
}

/// The sentence about the candidates of a last round that added nothing: those left out as
/// confounded with the model (novelty below `min_novelty`), with their novelty, and those
/// not significant. `None` when the rounds ended otherwise.
pub fn last_round_message(r: &Refinement, min_novelty: f64) -> Option<String> {
    if r.last_round.is_empty() {
        return None;
    }
    let confounded: Vec<String> = r
        .last_round
        .iter()
        .filter(|c| c.novelty < min_novelty)
        .map(|c| format!("`{}` (novelty {:.4})", c.effect.name(), c.novelty))
        .collect();
    let weak: Vec<String> = r
        .last_round
        .iter()
        .filter(|c| c.novelty >= min_novelty)
        .map(|c| match c.p_value {
            Some(p) => format!("`{}` (p {p:.2e})", c.effect.name()),
            None => format!("`{}` (no fit)", c.effect.name()),
        })
        .collect();
    let mut s = String::new();
    if !confounded.is_empty() {
        s.push_str(&format!(
            "Left out as barely separable from the installation errors and effects already in the model on this design (novelty, the fraction of the effect's signature the model cannot already explain, below {min_novelty}): {}; the data cannot tell such an effect apart, so the residual says nothing about it: a design with more varied poses (`cpm design`) can. ",
            confounded.join(", ")
        ));
    }
    if !weak.is_empty() {
        s.push_str(&format!(
            "Not significant (after the Bonferroni correction, or no BIC gain): {}.",
            weak.join(", ")
        ));
    }
    Some(s.trim_end().to_string())
}

/// The `refine.json` document.
pub fn refine_json(r: &Refinement, simulated: bool) -> Value {
    let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
    json!({
        "cpm_version": env!("CARGO_PKG_VERSION"),
        "simulated": simulated,
        "initial": {
            "rms_um": r.initial_diagnostics.rms_um,
            "residual_white": r.initial_diagnostics.white,
            "significant": r.initial_diagnostics.significant,
        },
        "steps": r.steps.iter().map(|s| json!({
            "effect": s.effect.name(),
            "p_value": finite(s.p_value),
            "delta_bic": finite(s.delta_bic),
            "rms_before_um": s.rms_before_um,
            "rms_after_um": s.rms_after_um,
            "cv_rms_before_um": s.cv_rms_before_um,
            "cv_rms_after_um": s.cv_rms_after_um,
            "parameters": param_json(s.effect, &s.parameters),
            "candidates": s.candidates.iter().map(|c| json!({
                "effect": c.effect.name(),
                "novelty": c.novelty,
                "p_value": c.p_value,
                "delta_bic": c.delta_bic,
                "rms_um": c.rms_um,
                "cv_rms_um": c.cv_rms_um,
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "last_round": r.last_round.iter().map(|c| json!({
            "effect": c.effect.name(),
            "novelty": c.novelty,
            "confounded": c.novelty < RefineOptions::default().min_novelty,
            "p_value": c.p_value,
            "delta_bic": c.delta_bic,
            "rms_um": c.rms_um,
        })).collect::<Vec<_>>(),
        "min_novelty": RefineOptions::default().min_novelty,
        "pose_structure": r.initial_pose_structure.iter().take(5).map(|p| json!({
            "effect": p.effect.name(),
            "dimensions": p.dimensions,
            "explained_share": p.explained_share,
            "p_value": p.p_value,
        })).collect::<Vec<_>>(),
        "pose_range": {
            "min_xyz_mm_rpy_deg": r.pose_range.min,
            "max_xyz_mm_rpy_deg": r.pose_range.max,
            "note": "pose map terms describe these commanded poses only; they do not extrapolate",
        },
        "final": {
            "effects": r.model.effects.iter().map(|e| e.name()).collect::<Vec<_>>(),
            "rms_um": r.calibration.residual_rms_um,
            "cv_rms_um": r.final_cv_rms_um,
            "residual_white": r.final_diagnostics.white,
            "consistent_with_noise": r.final_diagnostics.consistent_with_noise,
            "unexplained_structure": r.unexplained_structure,
            "converged": r.calibration.solver.was_successful(),
            "downweighted_share": r.calibration.downweighted_share,
            "robust_failed": r.calibration.robust_failed,
        },
        "outliers_before": r.outliers_before.len(),
        "rejected_by_cross_validation": r.rejected_by_cv.iter().map(|(e, before, after)| json!({
            "effect": e.name(),
            "cv_rms_before_um": before,
            "cv_rms_with_um": after,
        })).collect::<Vec<_>>(),
    })
}

/// Runs `cpm refine`.
pub fn run(args: &RefineArgs, ctx: &mut Ctx<'_>) -> anyhow::Result<Outcome> {
    common::check_out_dir(&args.fit.out)?;
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(usage_error("--alpha must be in (0, 1)"));
    }
    if args.folds < 2 || args.folds > 1000 {
        return Err(usage_error("--folds must be between 2 and 1000"));
    }
    let candidates = match &args.candidates {
        Some(list) => parse_effects(list).map_err(|m| usage_error(format!("--candidates: {m}")))?,
        None => Effect::ALL.to_vec(),
    };
    let inputs = args.fit.load(ctx)?;
    let campaign = &inputs.merged.campaign;
    let pose_map_degree = args
        .pose_map_degree
        .or(inputs.robot.description.pose_map.and_then(|p| p.degree))
        .unwrap_or(2);
    if pose_map_degree > 3 {
        return Err(usage_error("--pose-map-degree must be 0 to 3"));
    }
    ctx.stage(format!(
        "refining: {} to {} observations, up to {} effects from {} candidates (each round fits every candidate)",
        common::describe_model(&inputs.model),
        campaign.len(),
        args.max_steps,
        candidates.len()
    ));
    let options = RefineOptions {
        candidates,
        alpha: args.alpha,
        max_steps: args.max_steps,
        folds: args.folds,
        pose_map_degree,
        identify: inputs.identify.clone(),
        ..RefineOptions::default()
    };
    let r =
        refine(&inputs.model, campaign, &options).map_err(|e| common::locate(e, &inputs.merged))?;
    ctx.stage("writing the results");
    let dir = &args.fit.out;
    let cal = &r.calibration;
    let mut set = OutputSet::new();
    let doc = refine_json(&r, campaign.simulated);
    set.add(dir.join("refine.json"), serde_json::to_string_pretty(&doc)?);
    let mut value = io::calibration_json(&r.model, campaign, cal, &inputs.provenance);
    value["robust_loss"] = json!(common::describe_loss(&inputs.identify.lm.loss));
    value["outliers"] = calibrate::outliers_json(&inputs.robot, &inputs.merged, cal);
    value["registration"] = calibrate::registration_json(&inputs.merged, &r.model, cal);
    value["misfit"] = calibrate::misfit_json(cal);
    value["warnings"] = json!(calibrate::warnings(&r.model, cal)
        .iter()
        .map(|w| w.replace("**", ""))
        .collect::<Vec<_>>());
    set.add(
        dir.join("calibration.json"),
        serde_json::to_string_pretty(&value)?,
    );
    let mut figures = stage_figures(&mut set, dir, &inputs.robot, &r.model, campaign, cal)?;
    set.add(
        dir.join("residuals_before_after.svg"),
        plots::residuals_before_after(
            &format!(
                "Residual before and after refinement{}",
                if campaign.simulated {
                    " (SIMULATED)"
                } else {
                    ""
                }
            ),
            campaign,
            &r.initial_residuals_um,
            &cal.residuals_um,
        )?,
    );
    figures.push("residuals_before_after.svg");
    let notes = stage_calibrated(
        &mut set,
        dir,
        &inputs,
        &r.model,
        cal,
        false,
        Some(&r.model.effects),
        "Refined",
    )?;
    let mut s = String::from("# Refinement report\n\n");
    if campaign.simulated {
        s.push_str("**The measurements are SIMULATED.**\n\n");
    }
    for l in provenance_lines(&inputs.provenance, campaign.simulated, "Refined") {
        s.push_str(&format!("{l}\n"));
    }
    s.push('\n');
    for w in calibrate::warnings(&r.model, cal) {
        s.push_str(&format!("- {w}\n"));
    }
    s.push_str(&format!(
        "\nStarting model: {}. Residual RMS {:.3} um, white: {}.\n\n## Steps\n\n",
        common::describe_model(&inputs.model),
        r.initial_diagnostics.rms_um,
        r.initial_diagnostics.white
    ));
    let alpha_scan = options.alpha / r.initial_pose_structure.len().max(1) as f64;
    let pose_structure: Vec<String> = r
        .initial_pose_structure
        .iter()
        .filter(|p| p.p_value < alpha_scan)
        .take(3)
        .map(|p| {
            format!(
                "`{}` ({:.1} % of the residual sum of squares, p {:.1e})",
                p.effect.name(),
                100.0 * p.explained_share,
                p.p_value
            )
        })
        .collect();
    if !pose_structure.is_empty() {
        s.push_str(&format!(
            "Pose-correlated structure in the first residual (pose map scan): {}.\n\n",
            pose_structure.join(", ")
        ));
    }
    if !r.outliers_before.is_empty() {
        s.push_str(&format!(
            "The first fit flagged {} outlier observation(s) (listed under \"Outliers\") before any effect was chosen: the effects were chosen without them (an effect is also added only when it lowers the cross-validated RMS), and the final model was fitted to all observations.\n\n",
            r.outliers_before.len()
        ));
    }
    for (e, before, after) in &r.rejected_by_cv {
        s.push_str(&format!(
            "- `{}` passed the F-test and BIC but was not added: cross-validated RMS {before:.3} -> {after:.3} um (no better).\n",
            e.name()
        ));
    }
    if !r.rejected_by_cv.is_empty() {
        s.push('\n');
    }
    let last = last_round_message(&r, options.min_novelty);
    if r.steps.is_empty() {
        match &last {
            Some(m) => s.push_str(&format!("No effect was added. {m}\n\n")),
            None => s.push_str("No effect was added: the residual was already white and consistent with the noise (or no candidate was left).\n\n"),
        }
    }
    for (i, st) in r.steps.iter().enumerate() {
        s.push_str(&format!(
            "### {}. `{}`\n\n- F-test p-value {:.3e}, BIC change {:.2}\n- RMS {:.3} -> {:.3} um; cross-validated {:.3} -> {:.3} um\n\n| parameter | estimate | std |\n|---|---|---|\n",
            i + 1, st.effect.name(), st.p_value, st.delta_bic, st.rms_before_um, st.rms_after_um, st.cv_rms_before_um, st.cv_rms_after_um
        ));
        for (n, v, sd) in &st.parameters {
            s.push_str(&format!(
                "| {n} | {} | {} |\n",
                v.map_or("n.d.".into(), |x| format!("{x:.4}")),
                sd.map_or("n.d.".into(), |x| format!("{x:.4}"))
            ));
        }
        s.push('\n');
    }
    if let (false, Some(m)) = (r.steps.is_empty(), &last) {
        s.push_str(&format!("The last round added nothing. {m}\n\n"));
    }
    s.push_str(&format!(
        "## Final\n\n- Effects: {}\n- RMS {:.3} um, cross-validated {:.3} um, residual white: {}\n- Unexplained structure: {}\n\n",
        common::effect_list(&r.model.effects),
        cal.residual_rms_um,
        r.final_cv_rms_um,
        r.final_diagnostics.white,
        if r.unexplained_structure.is_empty() { "none".to_string() } else { r.unexplained_structure.join(", ") }
    ));
    if r.model
        .effects
        .iter()
        .any(|e| matches!(e, Effect::PoseMap(_)))
    {
        let (lo, hi) = (r.pose_range.min, r.pose_range.max);
        s.push_str(&format!(
            "The pose error map describes the poses it was fitted on and does not extrapolate: x {:.1} to {:.1} mm, y {:.1} to {:.1} mm, z {:.1} to {:.1} mm, roll {:.2} to {:.2} deg, pitch {:.2} to {:.2} deg, yaw {:.2} to {:.2} deg (written to `calibrated.toml` `[pose_map]`; `cpm compensate` flags targets outside).\n\n",
            lo[0], hi[0], lo[1], hi[1], lo[2], hi[2], lo[3], hi[3], lo[4], hi[4], lo[5], hi[5]
        ));
    }
    fit_report(
        &mut s,
        &inputs.robot,
        &r.model,
        campaign,
        cal,
        &inputs.identify.lm.loss,
    );
    calibrate::outliers_report(&mut s, &inputs.robot, &inputs.merged, cal);
    calibrate::registration_report(&mut s, &inputs.merged, &r.model, cal);
    s.push_str(&format!(
        "## Outputs\n\n- `refine.json`, `calibration.json` (final model)\n- `calibrated.toml`: determined installation errors ({} components left at nominal), effects declared; link_offset/link_scale folded into the link reading models, socket_error into the sensor sockets{}\n",
        notes.undetermined.len(),
        if notes.known_effects.is_empty() { String::new() } else { format!("; values of {} in `[calibration.known_effects]`", notes.known_effects.join(", ")) }
    ));
    for f in &figures {
        s.push_str(&format!("- `{f}`\n"));
    }
    set.add(dir.join("report.md"), s);
    crate::html::stage_report_html(&mut set, dir, "cpm refinement report");
    let inputs_paths: Vec<&std::path::Path> = std::iter::once(args.fit.robot.robot.as_path())
        .chain(args.fit.data.iter().map(std::path::PathBuf::as_path))
        .collect();
    let written = common::commit_dir(set, dir, &inputs_paths, "refine", ctx)?;
    ctx.finish();
    for w in calibrate::warnings(&r.model, cal)
        .iter()
        .skip(usize::from(!cal.solver.was_successful()))
    {
        ctx.note(w.replace("**", ""));
    }
    if let Some(m) = &last {
        ctx.note(m.replace('`', ""));
    }
    if args.fit.json {
        writeln!(ctx.out, "{}", serde_json::to_string_pretty(&doc)?)?;
    } else {
        writeln!(
            ctx.out,
            "{}added {} effect(s): {}; RMS {:.3} -> {:.3} um, cross-validated {:.3} um; unexplained structure: {}",
            if campaign.simulated { "SIMULATED data: " } else { "" },
            r.steps.len(),
            if r.steps.is_empty() { "none".to_string() } else { r.steps.iter().map(|s| s.effect.name()).collect::<Vec<_>>().join(", ") },
            r.initial_diagnostics.rms_um,
            cal.residual_rms_um,
            r.final_cv_rms_um,
            if r.unexplained_structure.is_empty() { "none".to_string() } else { r.unexplained_structure.join(", ") }
        )?;
        for w in &written {
            writeln!(ctx.out, "wrote {}", w.display())?;
        }
    }
    if let Some(why) = cal.robust_failure() {
        Ok(Outcome::Trouble(format!(
            "the final fit failed: {why}; the outputs were written and say so"
        )))
    } else if cal.solver.was_successful() {
        Ok(Outcome::Done)
    } else {
        Ok(Outcome::Trouble(format!(
            "the final fit did not converge ({})",
            cal.solver.termination
        )))
    }
}
