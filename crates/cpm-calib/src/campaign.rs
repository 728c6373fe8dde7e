//! Measurement campaigns: commanded poses and the length-sensor readings taken at them.
use cpm_geometry::Pose;
use serde::{Deserialize, Serialize};

/// One length-sensor reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Index of the commanded pose in [`Campaign::poses`].
    pub pose: usize,
    /// Index of the sensor (socket pair) in the joint table's `sensors`.
    pub sensor: usize,
    /// The reading (average of its repeats), mm.
    pub length_mm: f64,
    /// Acquisition time, s, if logged.
    pub time_s: Option<f64>,
    /// Temperature, deg C, if logged.
    pub temperature_c: Option<f64>,
}

/// A platform pose measured by a tracker (laser tracker, motion capture) in the tracker's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseMeasurement {
    /// Index of the configuration in [`Campaign::poses`] (its commanded lengths drive it).
    pub pose: usize,
    /// The measured pose, tracker frame (mm, rotation).
    pub measured: Pose,
    /// Acquisition time, s, if logged.
    pub time_s: Option<f64>,
    /// Temperature, deg C, if logged (what `thermal_drift` reads at a pose without a
    /// temperature-logged reading).
    #[serde(default)]
    pub temperature_c: Option<f64>,
}

/// A measurement campaign: commanded poses and readings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Campaign {
    /// Commanded platform poses.
    pub poses: Vec<Pose>,
    /// Link lengths actually commanded per pose (mm), when the controller logged them;
    /// otherwise the nominal inverse kinematics of the commanded pose is used.
    pub commanded_lengths_mm: Option<Vec<Vec<f64>>>,
    /// Sensor readings.
    pub readings: Vec<Reading>,
    /// Tracker pose measurements (6 observations each), if any.
    #[serde(default)]
    pub pose_measurements: Vec<PoseMeasurement>,
    /// Standard deviation of a tracker position coordinate, um. Default (when 0) 10.
    #[serde(default)]
    pub pose_sigma_um: f64,
    /// Standard deviation of a tracker orientation component, urad. Default (when 0) 20.
    #[serde(default)]
    pub orientation_sigma_urad: f64,
    /// True when the readings were simulated, not measured. Carried into every output.
    pub simulated: bool,
    /// Poses (indices into [`poses`](Self::poses), increasing) at which a new session starts:
    /// a campaign merged from several files starts each file's motion history afresh there
    /// (a link's last motion direction, which `backlash` reads, is not carried across files),
    /// as a campaign of one file does at its first pose. Default none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub session_starts: Vec<usize>,
}

impl Campaign {
    /// True when pose `j` starts a session: the first pose, or one of
    /// [`session_starts`](Self::session_starts).
    pub fn starts_session(&self, j: usize) -> bool {
        j == 0 || self.session_starts.binary_search(&j).is_ok()
    }

    /// The session (0 for the first; one more at each of
    /// [`session_starts`](Self::session_starts)) that pose `j` belongs to.
    pub fn session_of(&self, j: usize) -> usize {
        self.session_starts.partition_point(|s| *s <= j)
    }

    /// Number of observations: length readings plus six per pose measurement.
    pub fn len(&self) -> usize {
        self.readings.len() + 6 * self.pose_measurements.len()
    }

    /// True when there are no observations.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The measured observations: every reading's length (mm), then per pose measurement its
    /// position (mm) and three zeros (orientation observations are the rotation from the
    /// measured to the predicted orientation, in mrad, measured as zero).
    pub fn observations(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self.readings.iter().map(|r| r.length_mm).collect();
        for pm in &self.pose_measurements {
            v.extend(pm.measured.position_mm.iter());
            v.extend([0.0; 3]);
        }
        v
    }

    /// The configuration (index into `poses`) behind observation `k`.
    pub fn observation_pose(&self, k: usize) -> usize {
        let m = self.readings.len();
        if k < m {
            self.readings[k].pose
        } else {
            self.pose_measurements[(k - m) / 6].pose
        }
    }

    /// Tracker position noise, um (10 when not set).
    pub fn pose_sigma(&self) -> f64 {
        if self.pose_sigma_um > 0.0 {
            self.pose_sigma_um
        } else {
            10.0
        }
    }

    /// Tracker orientation noise, urad (20 when not set).
    pub fn orientation_sigma(&self) -> f64 {
        if self.orientation_sigma_urad > 0.0 {
            self.orientation_sigma_urad
        } else {
            20.0
        }
    }

    /// Weight of each observation so that all residuals share the noise `sigma_ref_um` of a
    /// length reading: 1 for readings, `sigma_ref / pose_sigma` for tracker positions and
    /// `sigma_ref / orientation_sigma` (um per urad) for tracker orientations.
    pub fn observation_weights(&self, sigma_ref_um: f64) -> Vec<f64> {
        let mut w = vec![1.0; self.readings.len()];
        for _ in &self.pose_measurements {
            w.extend([sigma_ref_um / self.pose_sigma(); 3]);
            w.extend([sigma_ref_um / self.orientation_sigma(); 3]);
        }
        w
    }

    /// The campaign restricted to the configurations for which `keep(pose)` holds (readings
    /// and pose measurements; pose indices unchanged).
    pub fn filter_poses(&self, keep: impl Fn(usize) -> bool) -> Campaign {
        let mut c = self.clone();
        c.readings.retain(|r| keep(r.pose));
        c.pose_measurements.retain(|p| keep(p.pose));
        c
    }
}

/// A plan: poses to drive and sensors to read at each (every sensor at every pose).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Commanded poses.
    pub poses: Vec<Pose>,
    /// Sensor indices read at every pose.
    pub sensors: Vec<usize>,
}

impl Plan {
    /// A campaign skeleton for this plan: readings with zero length (for Jacobians and design).
    pub fn skeleton(&self) -> Campaign {
        let mut readings = Vec::with_capacity(self.poses.len() * self.sensors.len());
        for p in 0..self.poses.len() {
            for &s in &self.sensors {
                readings.push(Reading {
                    pose: p,
                    sensor: s,
                    length_mm: 0.0,
                    time_s: None,
                    temperature_c: None,
                });
            }
        }
        Campaign {
            poses: self.poses.clone(),
            commanded_lengths_mm: None,
            readings,
            simulated: true,
            ..Campaign::default()
        }
    }

    /// Number of readings the plan takes.
    pub fn num_readings(&self) -> usize {
        self.poses.len() * self.sensors.len()
    }
}

/// The paper's circle: radius 100 mm about `centre` in its xy plane, counter-clockwise,
/// constant orientation, a pose every 10 degrees from 0 to 350 (36 poses).
pub fn paper_circle(centre: &Pose) -> Vec<Pose> {
    circle(centre, 100.0, 36)
}

/// `n` poses on a circle of `radius_mm` about `centre` (xy plane, counter-clockwise,
/// orientation of `centre`), starting at angle 0.
pub fn circle(centre: &Pose, radius_mm: f64, n: usize) -> Vec<Pose> {
    (0..n)
        .map(|k| {
            let a = (k as f64) * std::f64::consts::TAU / n as f64;
            let mut p = *centre;
            p.position_mm.x += radius_mm * a.cos();
            p.position_mm.y += radius_mm * a.sin();
            p
        })
        .collect()
}
