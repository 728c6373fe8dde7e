//! A fit in words: the model, the loss and the formulation described, the warnings of a fit
//! (failure, convergence, rank, noise, outliers, misfit), and where each observation came
//! from (file, line, what was observed).
use cpm_calib::{Calibration, Effect, MeasurementModel};
use cpm_io::{Merged, Robot};

/// The formulation of a fit (defined with the fit, in cpm-calib).
pub use cpm_calib::fit::formulation::Formulation;

/// The loss in words, e.g. `Huber, K = 3 um`.
pub fn describe_loss(loss: &cpm_lm::Loss) -> String {
    match loss {
        cpm_lm::Loss::Squared => "least squares".into(),
        cpm_lm::Loss::Huber(k) => format!("Huber, K = {k} um"),
        cpm_lm::Loss::Cauchy(k) => format!("Cauchy, K = {k} um"),
        cpm_lm::Loss::Tukey(k) => format!("Tukey, K = {k} um"),
    }
}

/// Effect names, comma-separated (`none` when empty).
pub fn effect_list(effects: &[Effect]) -> String {
    if effects.is_empty() {
        "none".into()
    } else {
        effects
            .iter()
            .map(|e| e.name())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The model's parameter count in words.
pub fn describe_model(model: &MeasurementModel) -> String {
    let known: Vec<Effect> = model.known_effects.iter().map(|k| k.effect).collect();
    format!(
        "{} parameters ({} installation errors{}){}",
        model.num_params(),
        model.num_installation_params(),
        if model.effects.is_empty() {
            String::new()
        } else {
            format!(" + {}", effect_list(&model.effects))
        },
        if known.is_empty() {
            String::new()
        } else {
            format!(", known {}", effect_list(&known))
        }
    )
}

/// The chi-square test of the fit against the declared noise (`None` when the noise was
/// estimated from the residual, or no degree of freedom is left).
pub fn misfit(cal: &Calibration) -> Option<cpm_calib::misfit::Misfit> {
    if cal.sigma_estimated {
        return None;
    }
    cpm_calib::misfit::chi_square(
        &cal.residuals_um,
        cal.sigma_um,
        cal.identifiability.rank,
        &cal.outliers,
    )
}

/// What a misfit says, in words; `weighted` when the residual mixes kinds of observation
/// weighed differently (`FitReport::residual_weighted`): its RMS is then said in sigma, each
/// residual over its kind's declared noise, never in um.
pub fn misfit_message(m: &cpm_calib::misfit::Misfit, weighted: bool) -> String {
    format!(
        "**The model does not fit the data to the declared noise**: chi2/dof = {:.2} on {} degrees of freedom (p {}), {}{}. The standard deviations assume the declared noise and are too small. An effect the model lacks (backlash, link offsets or scales, thermal drift, ...) or a noise larger than declared: `cpm refine` tests the effect library on these data.",
        m.chi2_per_dof,
        m.dof,
        if m.p_value < 1e-300 {
            "< 1e-300".to_string()
        } else {
            format!("= {:.1e}", m.p_value)
        },
        if weighted {
            format!(
                "weighted residual RMS {:.3} in sigma (each residual over its kind's declared noise) against 1",
                m.residual_rms_um / m.sigma_um
            )
        } else {
            format!(
                "residual RMS {:.3} um against the declared {} um",
                m.residual_rms_um, m.sigma_um
            )
        },
        if m.outliers_left_out > 0 {
            format!(", {} flagged outliers left out", m.outliers_left_out)
        } else {
            String::new()
        }
    )
}

/// What the data did not determine, how the fit ended, and whether the model fits the
/// declared noise, in a few lines for the top of a report (empty when all is well);
/// `weighted` as [`misfit_message`] takes it.
pub fn warnings(model: &MeasurementModel, cal: &Calibration, weighted: bool) -> Vec<String> {
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
        let n = super::DeterminationCounts::of(cal);
        let mut others = Vec::new();
        if n.held_by_tolerance > 0 {
            others.push(format!(
                "{} {} held by tolerance (fitted between the data and the tolerance, not measured)",
                n.held_by_tolerance,
                if n.held_by_tolerance == 1 {
                    "is"
                } else {
                    "are"
                }
            ));
        }
        if n.held_by_user > 0 {
            others.push(format!(
                "{} {} held by user",
                n.held_by_user,
                if n.held_by_user == 1 { "is" } else { "are" }
            ));
        }
        if n.blind > 0 {
            others.push(format!(
                "{} {} blind (no estimate, `n.d.`)",
                n.blind,
                if n.blind == 1 { "is" } else { "are" }
            ));
        }
        w.push(format!(
            "**Rank-deficient fit**: the data determine {} of {} parameters on their own (rank {} of {}){}; see \"What the data identify\" and \"Estimates\".",
            n.determined,
            model.num_params(),
            id.rank,
            id.num_params,
            if others.is_empty() {
                String::new()
            } else {
                format!("; of the others, {}", others.join(", "))
            }
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
            "**{} outlier observation{}** (more than 5 robust standard deviations off){}: listed under \"Outliers\".",
            cal.outliers.len(),
            if cal.outliers.len() == 1 { "" } else { "s" },
            match cal.set_aside.len() {
                0 => String::new(),
                n if n == cal.outliers.len() => {
                    ", set aside by the fit (`--keep-outliers` fits them)".to_string()
                }
                n => format!(", {n} set aside by the fit (`--keep-outliers` fits them)"),
            }
        ));
    }
    if let Some(m) = misfit(cal).filter(|m| m.inconsistent()) {
        w.push(misfit_message(&m, weighted));
    }
    if let Some(m) = misfit(cal).filter(|m| m.too_small()) {
        let rms = if weighted {
            format!(
                "the weighted residual RMS is {} in sigma (each residual over its kind's declared noise) against 1",
                crate::format::sig(m.residual_rms_um / m.sigma_um, 3)
            )
        } else {
            format!(
                "the residual RMS is {} um against the declared noise of {} um",
                crate::format::sig(m.residual_rms_um, 3),
                crate::format::sig(m.sigma_um, 3)
            )
        };
        w.push(format!(
            "**Noise smaller than declared**: {rms} (chi2/dof {} on {} degrees of freedom; a residual this small is improbable under the declared noise). The standard deviations use the declared noise and are about {} times too large; declare the noise the instrument shows, or leave it undeclared for the fit to estimate it.",
            crate::format::sig(m.chi2_per_dof, 3),
            m.dof,
            crate::format::sig(1.0 / m.chi2_per_dof.max(1e-300).sqrt(), 2)
        ));
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
    let mut what = String::new();
    let (file, line) = write_observation_origin(robot, merged, k, &mut what)?;
    Some(ObservationOrigin {
        file: file.to_string(),
        line,
        what,
    })
}

/// What a gauge reading observed, as [`write_observation_origin`] writes it: `sensor NAME at
/// pose "LABEL"` (the label as `{:?}` writes it), appended to `what`.
pub(crate) fn write_reading_what(what: &mut String, sensor: &str, label: &str) {
    use std::fmt::Write as _;
    // Writing into a String cannot fail.
    let _ = write!(what, "sensor {sensor} at pose {label:?}");
}

/// [`observation_origin`] without a string of its own: what was observed is written into
/// `what` (cleared first; a buffer reused from observation to observation), the file and the
/// line are returned (the file borrowed from `merged`). `None` when `k` has no origin
/// (`what` is then left empty).
pub fn write_observation_origin<'m>(
    robot: &Robot,
    merged: &'m Merged,
    k: usize,
    what: &mut String,
) -> Option<(&'m str, usize)> {
    use std::fmt::Write as _;
    what.clear();
    let c = &merged.campaign;
    let m = c.readings.len();
    // Writing into a String cannot fail.
    if k < m {
        let r = &c.readings[k];
        let (file, line) = merged.reading_origin.get(k)?;
        let label = merged.pose_origin.get(r.pose).map_or("?", |o| o.2.as_str());
        let sensor = robot
            .table
            .sensors
            .get(r.sensor)
            .map_or("?", |s| s.name.as_str());
        write_reading_what(what, sensor, label);
        Some((file, line))
    } else if k >= c.first_instrument_observation() && k < c.len() {
        // One's own instrument: named by its number (the campaign does not know its name).
        let cpm_calib::ObservationKind::Instrument(q, a) = c.observation_kind(k) else {
            return None;
        };
        let m = c.instrument_measurements.get(q)?;
        let (file, line, label) = merged.pose_origin.get(m.pose)?;
        let _ = write!(
            what,
            "instrument {} channel {} value {} at pose {label:?}",
            m.instrument + 1,
            m.channel + 1,
            a + 1
        );
        Some((file, *line))
    } else if k >= c.first_tilt_observation() {
        let q = k - c.first_tilt_observation();
        let t = c.tilt_measurements.get(q)?;
        let (file, line, label) = merged.pose_origin.get(t.pose)?;
        let line = merged.tilt_origin.get(q).map_or(*line, |o| o.1);
        let name = robot
            .description
            .inclinometers
            .get(t.inclinometer)
            .map_or("?", |c| c.name.as_str());
        let _ = write!(
            what,
            "inclinometer {name} angle_{}_deg at pose {label:?}",
            t.axis + 1
        );
        Some((file, line))
    } else if k >= c.first_point_observation() {
        let q = (k - c.first_point_observation()) / 3;
        let pm = c.point_measurements.get(q)?;
        let (file, line, label) = merged.pose_origin.get(pm.pose)?;
        let line = merged.point_origin.get(q).map_or(*line, |o| o.1);
        let target = robot
            .description
            .targets
            .get(pm.target)
            .map_or("?", |t| t.name.as_str());
        let comp = ["x", "y", "z"][(k - c.first_point_observation()) % 3];
        let _ = write!(what, "target {target} {comp} at pose {label:?}");
        Some((file, line))
    } else {
        let (q, a) = match c.observation_kind(k) {
            cpm_calib::ObservationKind::TrackerPosition(q, a) => (q, a),
            cpm_calib::ObservationKind::TrackerOrientation(q, a) => (q, 3 + a),
            _ => return None,
        };
        let pm = c.pose_measurements.get(q)?;
        let (file, line, label) = merged.pose_origin.get(pm.pose)?;
        let comp = ["x", "y", "z", "rotation x", "rotation y", "rotation z"][a];
        let _ = write!(what, "tracker {comp} of pose {label:?}");
        Some((file, *line))
    }
}
