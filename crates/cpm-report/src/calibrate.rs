//! The report of `cpm calibrate`: `calibration.json` and report.md (hence report.html) from one
//! [`CalibrateReport`].
use serde::Serialize;

use super::fit::{FitReport, Outlier};

/// What `calibrated.toml` holds, for the outputs section.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CalibratedFile {
    /// The minimum-norm solution was written (rather than the determined components only).
    pub minimum_norm: bool,
    /// Installation-error components left at nominal.
    pub undetermined: usize,
    /// Effects whose values went to `[calibration.known_effects]`.
    pub known_effects: Vec<String>,
}

/// Everything `cpm calibrate` reports.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrateReport {
    /// The fit: calibration.json.
    pub fit: FitReport,
    /// The provenance lines atop the report.
    pub provenance: Vec<String>,
    /// What calibrated.toml holds.
    pub calibrated: CalibratedFile,
    /// The figure files written.
    pub figures: Vec<String>,
}

/// `cpm calibrate --json`: the summary printed on standard output.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CalibrateSummary {
    /// The data are simulated.
    pub simulated: bool,
    /// `nested` or `implicit`.
    pub formulation: Option<String>,
    /// The output directory.
    pub out: String,
    /// The files written.
    pub files: Vec<String>,
    /// Numerical rank.
    pub rank: usize,
    /// Parameters fitted.
    pub parameters: usize,
    /// Parameters determined on their own.
    pub determined: usize,
    /// Residual RMS, um; `null` when the residual is weighted (as calibration.json's).
    pub residual_rms_um: Option<f64>,
    /// The residual mixes kinds weighed differently (as calibration.json's).
    pub residual_weighted: bool,
    /// Weighted residual RMS in sigma (as calibration.json's).
    pub weighted_rms_in_sigma: f64,
    /// The solver converged.
    pub converged: bool,
    /// Share of observations the robust loss down-weighted.
    pub downweighted_share: f64,
    /// The robust fit failed.
    pub robust_failed: bool,
    /// Installation-error components not determined.
    pub not_determined: Vec<String>,
    /// Flagged outliers.
    pub outliers: Vec<Outlier>,
}

impl CalibrateSummary {
    /// Pretty-printed (keys sorted).
    pub fn to_json(&self) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&serde_json::to_value(self)?)
    }
}

impl CalibrateReport {
    /// The `--json` summary of the run that wrote `files` into `out`.
    pub fn summary(&self, out: String, files: Vec<String>) -> CalibrateSummary {
        let f = &self.fit;
        CalibrateSummary {
            simulated: f.simulated,
            formulation: f.formulation.clone(),
            out,
            files,
            rank: f.identifiability.rank,
            parameters: f.identifiability.parameters,
            determined: f.identifiability.determined,
            residual_rms_um: f.residual_rms_um,
            residual_weighted: f.residual_weighted,
            weighted_rms_in_sigma: f.weighted_rms_in_sigma,
            converged: f.solver.converged,
            downweighted_share: f.robust.as_ref().map_or(0.0, |r| r.downweighted_share),
            robust_failed: f.robust.as_ref().is_some_and(|r| r.failed),
            not_determined: f.not_determined.clone(),
            outliers: f.outliers.clone(),
        }
    }

    /// `calibration.json`.
    pub fn json(&self) -> serde_json::Result<String> {
        self.fit.to_json()
    }

    /// report.md.
    pub fn markdown(&self) -> String {
        let f = &self.fit;
        let mut r = String::from("# Calibration report\n\n");
        if f.simulated {
            r.push_str("**The measurements are SIMULATED.**\n\n");
        }
        for l in &self.provenance {
            r.push_str(&format!("{l}\n\n"));
        }
        if let Some(form) = &f.text.formulation {
            r.push_str(&format!("Formulation: {form}.\n"));
        }
        r.push('\n');
        f.markdown_warnings(&mut r);
        f.markdown_sections(&mut r);
        r.push_str("## Outputs\n\n- `calibration.json`: estimates, standard deviations, what is not determined, residual, solver report.\n");
        let c = &self.calibrated;
        r.push_str(&format!(
            "- `calibrated.toml`: the robot description with the fitted installation errors in `[installation_errors_um]` ({} components not determined on their own, written at the fit's minimum-norm point, which reproduces the fit); `link_offset`/`link_scale` folded into the link reading models, `socket_error` into the sensor sockets{}.\n",
            c.undetermined,
            if c.known_effects.is_empty() { String::new() } else { format!(", the values of {} in `[calibration.known_effects]`", c.known_effects.join(", ")) }
        ));
        for fig in &self.figures {
            r.push_str(&format!("- `{fig}`\n"));
        }
        r
    }
}
