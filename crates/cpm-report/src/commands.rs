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
            robot: "r.toml".into(),
            targets: 1,
            undetermined: vec!["base 1 x".into()],
            blind_directions: vec![],
        };
        assert!(keys_sorted(&c.to_json()), "{}", c.to_json());
        assert!(!keys_sorted("{\n  \"b\": 1,\n  \"a\": 2\n}"));
    }
}
