//! The `--json` summaries of the commands that write data rather than a report: `simulate`
//! (a measurement file) and `compensate` (a command file). Fields are in alphabetical order,
//! the order of the keys in the printed JSON.
use serde::Serialize;

/// `cpm simulate --json`: what was simulated, and where it went.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SimulateSummary {
    /// Effects of the simulated machine, by name.
    pub effects: Vec<String>,
    /// What was measured: `lengths`, `poses`, `points` or `tilts`.
    pub measure: String,
    /// The noise in words (um, or urad for inclinometer angles).
    pub noise: String,
    /// The file written.
    pub out: String,
    /// Point measurements simulated.
    pub point_measurements: usize,
    /// Tracker pose measurements simulated.
    pub pose_measurements: usize,
    /// Poses of the plan.
    pub poses: usize,
    /// Length readings simulated.
    pub readings: usize,
    /// The random seed.
    pub seed: u64,
    /// Always true: the data are simulated.
    pub simulated: bool,
    /// Inclinometer angles simulated.
    pub tilt_measurements: usize,
    /// The truth in words.
    pub truth: String,
}

/// `cpm compensate --json`: the command file written.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CompensateSummary {
    /// What the calibration's data could not see, in words (`[calibration]
    /// blind_directions`).
    pub blind_directions: Vec<String>,
    /// Joint clearance of the model, um.
    pub clearance_um: f64,
    /// Effects with known values applied, by name.
    pub known_effects: Vec<String>,
    /// The file written.
    pub out: String,
    /// Labels of the targets outside the pose range a pose map was fitted on.
    pub outside_pose_map_range: Vec<String>,
    /// The pose error predicted after compensation, from the calibration's
    /// `[calibration.covariance]`; `null` when the description carries none (no accuracy is
    /// promised).
    pub predicted_error: Option<PredictedError>,
    /// The robot description file.
    pub robot: String,
    /// Targets compensated.
    pub targets: usize,
    /// What the calibration left undetermined (installation-error components and effect
    /// parameters, `[calibration] undetermined` of the description): the commands cannot
    /// correct it.
    pub undetermined: Vec<String>,
}

impl SimulateSummary {
    /// The pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a summary serialises")
    }
}

/// The pose error a compensation is predicted to leave (the twist from target to reached pose
/// for the true machine, whose parameters differ from the calibrated ones within their
/// covariance; first order), with 95 % bands.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PredictedError {
    /// The probability of the bands: 0.95.
    pub level: f64,
    /// Per target, in file order.
    pub targets: Vec<TargetError>,
    /// What neither the data nor a tolerance bounded (parameter names): the bands do not hold
    /// the error along them.
    pub unbounded: Vec<String>,
    /// ISO 9283's accuracy terms over the targets, predicted: the worst target's 95 % band
    /// of each (AP_x, AP_y, AP_z and AP_a, AP_b, AP_c: 1.96 standard deviations; AP_p: the
    /// radius of a sphere holding the position's 95 % ellipsoid).
    pub worst_target: Iso9283Bands,
}

/// The predicted pose error at one target.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TargetError {
    /// Standard deviation about base x, y and z, urad.
    pub orientation_std_urad: [f64; 3],
    /// The orientation's 95 % band (largest semi-axis of its ellipsoid), urad.
    pub orientation_95_urad: f64,
    /// The target's label.
    pub pose: String,
    /// Standard deviation along base x, y and z, um.
    pub position_std_um: [f64; 3],
    /// The position's 95 % band (largest semi-axis of its ellipsoid), um.
    pub position_95_um: f64,
}

/// ISO 9283 pose accuracy terms, as predicted 95 % bands.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Iso9283Bands {
    /// AP_a, about base x, urad.
    pub ap_a_urad: f64,
    /// AP_b, about base y, urad.
    pub ap_b_urad: f64,
    /// AP_c, about base z, urad.
    pub ap_c_urad: f64,
    /// AP_p, the position, um.
    pub ap_p_um: f64,
    /// AP_x, um.
    pub ap_x_um: f64,
    /// AP_y, um.
    pub ap_y_um: f64,
    /// AP_z, um.
    pub ap_z_um: f64,
}

impl PredictedError {
    /// The bands of `targets` (labels and predictions): each target's, and the worst of
    /// each ISO 9283 term.
    pub fn of(targets: Vec<TargetError>, unbounded: Vec<String>, z: f64) -> Self {
        let worst = |f: &dyn Fn(&TargetError) -> f64| targets.iter().map(f).fold(0.0, f64::max);
        let worst_target = Iso9283Bands {
            ap_a_urad: worst(&|t| z * t.orientation_std_urad[0]),
            ap_b_urad: worst(&|t| z * t.orientation_std_urad[1]),
            ap_c_urad: worst(&|t| z * t.orientation_std_urad[2]),
            ap_p_um: worst(&|t| t.position_95_um),
            ap_x_um: worst(&|t| z * t.position_std_um[0]),
            ap_y_um: worst(&|t| z * t.position_std_um[1]),
            ap_z_um: worst(&|t| z * t.position_std_um[2]),
        };
        Self {
            level: 0.95,
            targets,
            unbounded,
            worst_target,
        }
    }

    /// The worst target's orientation band (largest semi-axis of its 95 % ellipsoid), urad.
    pub fn worst_orientation_95_urad(&self) -> f64 {
        self.targets
            .iter()
            .map(|t| t.orientation_95_urad)
            .fold(0.0, f64::max)
    }

    /// The one line a user reads: the worst target's position and orientation bands.
    pub fn line(&self) -> String {
        let w = &self.worst_target;
        let mut s = format!(
            "predicted pose error after compensation, worst of {} targets (95 %, from the calibration's covariance): position {:.3} um (ISO 9283 AP_p), orientation {:.3} urad (AP_a {:.3}, AP_b {:.3}, AP_c {:.3} urad)",
            self.targets.len(),
            w.ap_p_um,
            self.worst_orientation_95_urad(),
            w.ap_a_urad,
            w.ap_b_urad,
            w.ap_c_urad
        );
        if !self.unbounded.is_empty() {
            s.push_str(&format!(
                "; not bounded by the data or a tolerance, so outside these bands: {}",
                self.unbounded.join(", ")
            ));
        }
        s
    }
}

impl CompensateSummary {
    /// The pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a summary serialises")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The keys come out sorted, as the untyped summaries printed them.
    fn keys_sorted(json: &str) -> bool {
        let v: serde_json::Value = serde_json::from_str(json).unwrap();
        let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
        let fields: Vec<String> = json
            .lines()
            .filter_map(|l| l.strip_prefix("  \"")?.split('"').next().map(String::from))
            .collect();
        let mut sorted = fields.clone();
        sorted.sort();
        keys.len() == fields.len() && fields == sorted
    }

    #[test]
    fn summaries_print_their_keys_in_order() {
        let s = SimulateSummary {
            effects: vec!["backlash".into()],
            measure: "lengths".into(),
            noise: "1 um".into(),
            out: "d.csv".into(),
            point_measurements: 0,
            pose_measurements: 0,
            poses: 3,
            readings: 9,
            seed: 7,
            simulated: true,
            tilt_measurements: 0,
            truth: "the paper's table 2".into(),
        };
        assert!(keys_sorted(&s.to_json()), "{}", s.to_json());
        let c = CompensateSummary {
            clearance_um: 10.0,
            known_effects: vec![],
            out: "c.csv".into(),
            outside_pose_map_range: vec!["p1".into()],
            predicted_error: Some(PredictedError::of(
                vec![TargetError {
                    orientation_std_urad: [1.0, 2.0, 3.0],
                    orientation_95_urad: 9.0,
                    pose: "p1".into(),
                    position_std_um: [1.0, 2.0, 0.5],
                    position_95_um: 6.0,
                }],
                vec![],
                2.0,
            )),
            robot: "r.toml".into(),
            targets: 1,
            undetermined: vec!["base 1 x".into()],
            blind_directions: vec![],
        };
        assert!(keys_sorted(&c.to_json()), "{}", c.to_json());
        let v: serde_json::Value = serde_json::from_str(&c.to_json()).unwrap();
        for inner in [
            &v["predicted_error"],
            &v["predicted_error"]["worst_target"],
            &v["predicted_error"]["targets"][0],
        ] {
            let keys: Vec<&String> = inner.as_object().unwrap().keys().collect();
            assert!(keys.windows(2).all(|w| w[0] < w[1]), "{keys:?}");
        }
        // The worst of each term: z times the deviation, the position's band as given.
        assert_eq!(v["predicted_error"]["worst_target"]["ap_y_um"], 4.0);
        assert_eq!(v["predicted_error"]["worst_target"]["ap_p_um"], 6.0);
        assert!(!keys_sorted("{\n  \"b\": 1,\n  \"a\": 2\n}"));
    }
}
