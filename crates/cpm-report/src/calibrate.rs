//! The report of `cpm calibrate`: `calibration.json` and report.md (hence report.html) from one
//! [`CalibrateReport`].
use super::fit::FitReport;

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

impl CalibrateReport {
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
