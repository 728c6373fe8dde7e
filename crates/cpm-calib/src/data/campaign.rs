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
    pub time_s: Logged,
    /// Temperature, deg C, if logged.
    pub temperature_c: Logged,
}

/// A value a log may or may not hold (a reading's time or temperature): an `Option<f64>` in
/// 8 bytes, not 16 (10^6 readings: 16 MB less), NaN standing for "not logged" (the readers
/// refuse a number that is not finite, so no logged value is NaN; [`Logged::new`] of
/// `Some(NaN)` is not logged). Serialised as the `Option<f64>` it stands for.
///
/// ```
/// use cpm_calib::campaign::Logged;
/// let t = Logged::new(Some(12.5));
/// assert_eq!(t.get(), Some(12.5));
/// assert_eq!(Logged::NONE.get(), None);
/// assert_eq!(Logged::new(None), Logged::NONE);
/// assert_eq!(std::mem::size_of::<Logged>(), 8);
/// ```
#[derive(Clone, Copy)]
pub struct Logged(f64);

impl Logged {
    /// Not logged.
    pub const NONE: Logged = Logged(f64::NAN);

    /// Of an optional value.
    pub fn new(v: Option<f64>) -> Self {
        Logged(v.unwrap_or(f64::NAN))
    }

    /// The value, `None` when not logged.
    pub fn get(self) -> Option<f64> {
        (!self.0.is_nan()).then_some(self.0)
    }

    /// True when logged.
    pub fn is_some(self) -> bool {
        !self.0.is_nan()
    }
}

impl Default for Logged {
    fn default() -> Self {
        Logged::NONE
    }
}

impl From<Option<f64>> for Logged {
    fn from(v: Option<f64>) -> Self {
        Logged::new(v)
    }
}

impl From<Logged> for Option<f64> {
    fn from(v: Logged) -> Self {
        v.get()
    }
}

impl PartialEq for Logged {
    fn eq(&self, other: &Self) -> bool {
        self.get() == other.get()
    }
}

impl std::fmt::Debug for Logged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.get().fmt(f)
    }
}

impl Serialize for Logged {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.get().serialize(s)
    }
}

impl<'de> Deserialize<'de> for Logged {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Option::<f64>::deserialize(d).map(Logged::new)
    }
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

/// A point target (a laser tracker's reflector on the platform, `[[target]]`) measured as a
/// 3-D point in the tracker's frame, for one session.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PointMeasurement {
    /// Index of the configuration in [`Campaign::poses`].
    pub pose: usize,
    /// Index of the target in the model's targets ([`crate::MeasurementModel::targets`]).
    pub target: usize,
    /// The session (tracker set-up) it was measured in, from 0: each session has its own
    /// frame (a file is a session).
    pub session: usize,
    /// The measured position, tracker frame, mm.
    pub measured_mm: nalgebra::Vector3<f64>,
    /// Acquisition time, s, if logged.
    pub time_s: Option<f64>,
}

/// One angle of an inclinometer on the platform (`[[inclinometer]]`): the elevation of one of
/// its axes above the horizontal, for one session (the base levelled once).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TiltMeasurement {
    /// Index of the configuration in [`Campaign::poses`].
    pub pose: usize,
    /// Index of the inclinometer in the model's
    /// [`inclinometers`](crate::MeasurementModel::inclinometers).
    pub inclinometer: usize,
    /// Index of the instrument's axis (the file's `angle_{axis+1}_deg`).
    pub axis: usize,
    /// The session (levelling of the base) it was measured in, from 0 (a file is a session).
    pub session: usize,
    /// The measured angle, mrad.
    pub angle_mrad: f64,
    /// Acquisition time, s, if logged.
    pub time_s: Option<f64>,
}

/// A measurement of one's own instrument ([`crate::model::instruments::Instrument`], in the model's
/// [`instruments`](crate::MeasurementModel::instruments)): its values at one pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentMeasurement {
    /// Index of the configuration in [`Campaign::poses`].
    pub pose: usize,
    /// Index of the instrument in the model's
    /// [`instruments`](crate::MeasurementModel::instruments).
    pub instrument: usize,
    /// The instrument's channel (target, axis, beam) it is of, from 0.
    pub channel: usize,
    /// The session it was measured in, from 0 (each brings the instrument's per-session
    /// nuisance parameters).
    pub session: usize,
    /// The measured values (the instrument's `num_values`), in the instrument's unit.
    pub values: Vec<f64>,
    /// Standard deviation of each value, in the instrument's unit (sets its weight).
    pub sigma: f64,
}

/// What observation `k` of [`Campaign::observations`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObservationKind {
    /// Reading `index` of [`Campaign::readings`].
    Reading(usize),
    /// Position axis `axis` (0..3) of pose measurement `index`.
    TrackerPosition(usize, usize),
    /// Orientation axis `axis` (0..3) of pose measurement `index`.
    TrackerOrientation(usize, usize),
    /// Axis `axis` (0..3) of point measurement `index`.
    Point(usize, usize),
    /// Tilt measurement `index`.
    Tilt(usize),
    /// Value `value` of instrument measurement `index`.
    Instrument(usize, usize),
}

/// The gauges' noise a command-line fit assumes when a campaign mixes gauge readings with
/// other instruments and the gauges' noise is not declared, um (the tracker's default: a
/// campaign of defaults weighs as before); `--noise-per-kind` estimates it instead.
pub const DEFAULT_READING_SIGMA_UM: f64 = 10.0;

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
    /// Standard deviation of a length (gauge) reading, um: the gauges' own noise, whatever
    /// the other instruments' (`[calibration] sensor_noise_um`, `--sigma-um`). Default
    /// (when 0) the reference noise of the weights (a reading weighs 1).
    #[serde(default)]
    pub reading_sigma_um: f64,
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
    /// Point target measurements (3 observations each, after the pose measurements'), if
    /// any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub point_measurements: Vec<PointMeasurement>,
    /// Standard deviation of a point coordinate, um. Default (when 0) 10.
    #[serde(default)]
    pub point_sigma_um: f64,
    /// Components of pose measurements that were not measured (a lost marker, an orientation
    /// not solved): `(q, a)` = component `a` (0..3 position x y z, 3..6 orientation) of pose
    /// measurement `q`, sorted. They are not observations: the fit uses the rest. Default
    /// none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unmeasured: Vec<(usize, usize)>,
    /// Inclinometer angles (one observation each, after the point measurements'), if any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tilt_measurements: Vec<TiltMeasurement>,
    /// Standard deviation of an inclinometer angle, urad. Default (when 0) 20.
    #[serde(default)]
    pub tilt_sigma_urad: f64,
    /// Measurements of one's own instruments (their values each, after the tilt
    /// measurements'), if any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub instrument_measurements: Vec<InstrumentMeasurement>,
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

    /// Number of observations: length readings, six per pose measurement (less its
    /// [`unmeasured`](Self::unmeasured) components), three per point measurement, one per
    /// tilt measurement, the values of each instrument measurement.
    pub fn len(&self) -> usize {
        self.first_instrument_observation()
            + self
                .instrument_measurements
                .iter()
                .map(|m| m.values.len())
                .sum::<usize>()
    }

    /// Index of the first instrument observation in [`observations`](Self::observations).
    pub fn first_instrument_observation(&self) -> usize {
        self.first_tilt_observation() + self.tilt_measurements.len()
    }

    /// The observation index of the first value of each instrument measurement.
    pub fn instrument_observation_rows(&self) -> Vec<usize> {
        let mut k = self.first_instrument_observation();
        self.instrument_measurements
            .iter()
            .map(|m| {
                k += m.values.len();
                k - m.values.len()
            })
            .collect()
    }

    /// Number of sessions of the instrument measurements: the largest session index plus
    /// one, 0 without instrument measurements.
    pub fn instrument_sessions(&self) -> usize {
        self.instrument_measurements
            .iter()
            .map(|m| m.session + 1)
            .max()
            .unwrap_or(0)
    }

    /// Index of the first inclinometer observation in [`observations`](Self::observations).
    pub fn first_tilt_observation(&self) -> usize {
        self.first_point_observation() + 3 * self.point_measurements.len()
    }

    /// Number of inclinometer sessions (one base levelling each): the largest session index
    /// plus one, 0 without tilt measurements.
    pub fn tilt_sessions(&self) -> usize {
        self.tilt_measurements
            .iter()
            .map(|t| t.session + 1)
            .max()
            .unwrap_or(0)
    }

    /// Inclinometer angle noise, urad (20 when not set).
    pub fn tilt_sigma(&self) -> f64 {
        if self.tilt_sigma_urad > 0.0 {
            self.tilt_sigma_urad
        } else {
            20.0
        }
    }

    /// Index of the first point observation in [`observations`](Self::observations).
    pub fn first_point_observation(&self) -> usize {
        self.readings.len() + 6 * self.pose_measurements.len() - self.unmeasured.len()
    }

    /// True when component `a` of pose measurement `q` was measured.
    pub fn is_measured(&self, q: usize, a: usize) -> bool {
        self.unmeasured.binary_search(&(q, a)).is_err()
    }

    /// The observation index of each component of each pose measurement (`None`: not
    /// measured).
    pub fn pose_observation_rows(&self) -> Vec<[Option<usize>; 6]> {
        let mut k = self.readings.len();
        let mut u = self.unmeasured.iter().peekable();
        (0..self.pose_measurements.len())
            .map(|q| {
                let mut rows = [None; 6];
                for (a, r) in rows.iter_mut().enumerate() {
                    if u.peek() == Some(&&(q, a)) {
                        u.next();
                    } else {
                        *r = Some(k);
                        k += 1;
                    }
                }
                rows
            })
            .collect()
    }

    /// The group of every observation for a rank that does not depend on weights
    /// ([`RankScaling::row_groups`](crate::RankScaling::row_groups)): its kind (gauge
    /// readings, tracker positions, tracker orientations, points, angles, each of one's own
    /// instruments), every gauge reading one group (readings share a unit); empty for gauge
    /// readings alone, which are scaled by nothing.
    pub fn kind_groups(&self) -> Vec<usize> {
        if self.len() == self.readings.len() {
            return Vec::new();
        }
        let mut kinds: Vec<(u8, usize)> = Vec::new();
        self.observation_kinds()
            .into_iter()
            .map(|o| {
                let kind = match o {
                    ObservationKind::Reading(_) => (0, 0),
                    ObservationKind::TrackerPosition(..) => (1, 0),
                    ObservationKind::TrackerOrientation(..) => (2, 0),
                    ObservationKind::Point(..) => (3, 0),
                    ObservationKind::Tilt(_) => (4, 0),
                    ObservationKind::Instrument(q, _) => {
                        (5, self.instrument_measurements[q].instrument)
                    }
                };
                match kinds.iter().position(|k| *k == kind) {
                    Some(g) => g,
                    None => {
                        kinds.push(kind);
                        kinds.len() - 1
                    }
                }
            })
            .collect()
    }

    /// What each observation is, in order ([`observation_kind`](Self::observation_kind) of
    /// every one, in one pass).
    pub fn observation_kinds(&self) -> Vec<ObservationKind> {
        let mut out: Vec<ObservationKind> = (0..self.readings.len())
            .map(ObservationKind::Reading)
            .collect();
        for (q, rows) in self.pose_observation_rows().iter().enumerate() {
            for (a, r) in rows.iter().enumerate() {
                if r.is_some() {
                    out.push(if a < 3 {
                        ObservationKind::TrackerPosition(q, a)
                    } else {
                        ObservationKind::TrackerOrientation(q, a - 3)
                    });
                }
            }
        }
        for q in 0..self.point_measurements.len() {
            out.extend((0..3).map(|a| ObservationKind::Point(q, a)));
        }
        out.extend((0..self.tilt_measurements.len()).map(ObservationKind::Tilt));
        for (q, m) in self.instrument_measurements.iter().enumerate() {
            out.extend((0..m.values.len()).map(|a| ObservationKind::Instrument(q, a)));
        }
        out
    }

    /// Number of point-measurement sessions (one frame each): the largest session index
    /// plus one, 0 without point measurements.
    pub fn point_sessions(&self) -> usize {
        self.point_measurements
            .iter()
            .map(|p| p.session + 1)
            .max()
            .unwrap_or(0)
    }

    /// Point position noise, um (10 when not set).
    pub fn point_sigma(&self) -> f64 {
        if self.point_sigma_um > 0.0 {
            self.point_sigma_um
        } else {
            10.0
        }
    }

    /// What observation `k` is (`k < len()`).
    pub fn observation_kind(&self, k: usize) -> ObservationKind {
        let m = self.readings.len();
        let p = self.first_point_observation();
        if !self.unmeasured.is_empty() && (m..p).contains(&k) {
            return self.observation_kinds()[k];
        }
        if k < m {
            ObservationKind::Reading(k)
        } else if k < p {
            let (q, a) = ((k - m) / 6, (k - m) % 6);
            if a < 3 {
                ObservationKind::TrackerPosition(q, a)
            } else {
                ObservationKind::TrackerOrientation(q, a - 3)
            }
        } else if k < self.first_tilt_observation() {
            ObservationKind::Point((k - p) / 3, (k - p) % 3)
        } else if k < self.first_instrument_observation() {
            ObservationKind::Tilt(k - self.first_tilt_observation())
        } else {
            let rows = self.instrument_observation_rows();
            let q = rows.partition_point(|r| *r <= k) - 1;
            ObservationKind::Instrument(q, k - rows[q])
        }
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
        for (q, pm) in self.pose_measurements.iter().enumerate() {
            for a in 0..6 {
                if self.is_measured(q, a) {
                    v.push(if a < 3 {
                        pm.measured.position_mm[a]
                    } else {
                        0.0
                    });
                }
            }
        }
        for pm in &self.point_measurements {
            v.extend(pm.measured_mm.iter());
        }
        v.extend(self.tilt_measurements.iter().map(|t| t.angle_mrad));
        for m in &self.instrument_measurements {
            v.extend(&m.values);
        }
        v
    }

    /// The configuration (index into `poses`) behind observation `k`.
    pub fn observation_pose(&self, k: usize) -> usize {
        match self.observation_kind(k) {
            ObservationKind::Reading(i) => self.readings[i].pose,
            ObservationKind::TrackerPosition(q, _) | ObservationKind::TrackerOrientation(q, _) => {
                self.pose_measurements[q].pose
            }
            ObservationKind::Point(q, _) => self.point_measurements[q].pose,
            ObservationKind::Tilt(q) => self.tilt_measurements[q].pose,
            ObservationKind::Instrument(q, _) => self.instrument_measurements[q].pose,
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

    /// The earliest logged time of the length readings, s (`None` when none is logged): the
    /// clock origin of `thermal_drift` when the model declares none
    /// ([`EffectSettings::reference_time_s`](crate::EffectSettings::reference_time_s)).
    pub fn first_time_s(&self) -> Option<f64> {
        self.readings
            .iter()
            .filter_map(|r| r.time_s.get())
            .reduce(f64::min)
    }

    /// The gauges' noise, um, when declared ([`reading_sigma_um`](Self::reading_sigma_um)
    /// set): `None` when the readings are the reference of the weights.
    pub fn reading_sigma(&self) -> Option<f64> {
        (self.reading_sigma_um > 0.0).then_some(self.reading_sigma_um)
    }

    /// The reference noise of the weights, um, for a fit given the gauge noise `sigma_um`
    /// (`IdentifyOptions::sigma_um`): that, else the gauges' declared noise, else the tracker
    /// position noise. Weighed with it (see [`observation_weights`](Self::observation_weights))
    /// every kind of observation keeps its own noise.
    pub fn reference_sigma(&self, sigma_um: Option<f64>) -> f64 {
        sigma_um
            .or(self.reading_sigma())
            .unwrap_or(self.pose_sigma())
    }

    /// Weight of each observation so that all residuals share the noise `sigma_ref_um`:
    /// `sigma_ref / reading_sigma` for readings (1 when the readings' noise is not declared:
    /// they are the reference), `sigma_ref / pose_sigma` for tracker positions and
    /// `sigma_ref / orientation_sigma` (um per urad) for tracker orientations, and so on for
    /// points, tilts and one's own instruments. Every kind is weighed by its own noise: the
    /// gauges never take the tracker's.
    pub fn observation_weights(&self, sigma_ref_um: f64) -> Vec<f64> {
        let reading = self.reading_sigma().map_or(1.0, |s| sigma_ref_um / s);
        let mut w = vec![reading; self.readings.len()];
        for q in 0..self.pose_measurements.len() {
            for a in 0..6 {
                if self.is_measured(q, a) {
                    w.push(if a < 3 {
                        sigma_ref_um / self.pose_sigma()
                    } else {
                        sigma_ref_um / self.orientation_sigma()
                    });
                }
            }
        }
        for _ in &self.point_measurements {
            w.extend([sigma_ref_um / self.point_sigma(); 3]);
        }
        // Angles in mrad, as the tracker orientations: um of the reference per urad.
        w.extend(
            self.tilt_measurements
                .iter()
                .map(|_| sigma_ref_um / self.tilt_sigma()),
        );
        // Values in their instrument's unit, sigma too: um of the reference per
        // thousandth of the unit, as for the other kinds.
        for m in &self.instrument_measurements {
            w.extend(std::iter::repeat_n(
                sigma_ref_um * 1e-3 / m.sigma,
                m.values.len(),
            ));
        }
        w
    }

    /// Keeps the pose measurements `q` with `kept[q]` (and their unmeasured components,
    /// renumbered).
    pub fn retain_pose_measurements(&mut self, kept: &[bool]) {
        let mut new_index = Vec::with_capacity(kept.len());
        let mut n = 0;
        for &k in kept {
            new_index.push(n);
            n += usize::from(k);
        }
        let mut q = 0;
        self.pose_measurements.retain(|_| {
            q += 1;
            kept[q - 1]
        });
        self.unmeasured = self
            .unmeasured
            .iter()
            .filter(|(q, _)| kept[*q])
            .map(|(q, a)| (new_index[*q], *a))
            .collect();
    }

    /// The campaign restricted to the configurations for which `keep(pose)` holds (readings
    /// and pose measurements; pose indices unchanged).
    pub fn filter_poses(&self, keep: impl Fn(usize) -> bool) -> Campaign {
        let mut c = self.clone();
        c.readings.retain(|r| keep(r.pose));
        let kept: Vec<bool> = self
            .pose_measurements
            .iter()
            .map(|p| keep(p.pose))
            .collect();
        c.retain_pose_measurements(&kept);
        c.point_measurements.retain(|p| keep(p.pose));
        c.tilt_measurements.retain(|p| keep(p.pose));
        c.instrument_measurements.retain(|p| keep(p.pose));
        c
    }

    /// The campaign without the configurations for which `drop(pose)` holds, and without
    /// every observation taken at them; unlike [`filter_poses`](Self::filter_poses) the
    /// poses left are renumbered (in order), so the campaign is the one the files would give
    /// without those poses' rows: commanded lengths, session starts and the sessions of the
    /// point, tilt and instrument measurements (renumbered in order when one is left empty)
    /// follow.
    pub fn without_poses(&self, drop: impl Fn(usize) -> bool) -> Campaign {
        let mut new_index = Vec::with_capacity(self.poses.len());
        let mut kept = 0;
        for j in 0..self.poses.len() {
            if drop(j) {
                new_index.push(None);
            } else {
                new_index.push(Some(kept));
                kept += 1;
            }
        }
        let map = |j: usize| new_index.get(j).copied().flatten();
        // The sessions left, renumbered in order.
        fn renumber(mut used: Vec<usize>) -> impl Fn(usize) -> usize {
            used.sort_unstable();
            used.dedup();
            move |s| used.partition_point(|u| *u < s)
        }
        let mut c = self.clone();
        c.poses = self
            .poses
            .iter()
            .enumerate()
            .filter(|(j, _)| map(*j).is_some())
            .map(|(_, p)| *p)
            .collect();
        c.commanded_lengths_mm = self.commanded_lengths_mm.as_ref().map(|l| {
            l.iter()
                .enumerate()
                .filter(|(j, _)| map(*j).is_some())
                .map(|(_, l)| l.clone())
                .collect()
        });
        c.readings = self
            .readings
            .iter()
            .filter_map(|r| map(r.pose).map(|pose| Reading { pose, ..*r }))
            .collect();
        let measured: Vec<bool> = self
            .pose_measurements
            .iter()
            .map(|m| map(m.pose).is_some())
            .collect();
        c.retain_pose_measurements(&measured);
        c.pose_measurements = c
            .pose_measurements
            .iter()
            .filter_map(|m| map(m.pose).map(|pose| PoseMeasurement { pose, ..*m }))
            .collect();
        let points: Vec<PointMeasurement> = self
            .point_measurements
            .iter()
            .filter_map(|m| map(m.pose).map(|pose| PointMeasurement { pose, ..*m }))
            .collect();
        let session = renumber(points.iter().map(|m| m.session).collect());
        c.point_measurements = points
            .into_iter()
            .map(|m| PointMeasurement {
                session: session(m.session),
                ..m
            })
            .collect();
        let tilts: Vec<TiltMeasurement> = self
            .tilt_measurements
            .iter()
            .filter_map(|m| map(m.pose).map(|pose| TiltMeasurement { pose, ..*m }))
            .collect();
        let session = renumber(tilts.iter().map(|m| m.session).collect());
        c.tilt_measurements = tilts
            .into_iter()
            .map(|m| TiltMeasurement {
                session: session(m.session),
                ..m
            })
            .collect();
        let instruments: Vec<InstrumentMeasurement> = self
            .instrument_measurements
            .iter()
            .filter_map(|m| map(m.pose).map(|pose| InstrumentMeasurement { pose, ..m.clone() }))
            .collect();
        let session = renumber(instruments.iter().map(|m| m.session).collect());
        c.instrument_measurements = instruments
            .into_iter()
            .map(|m| InstrumentMeasurement {
                session: session(m.session),
                ..m
            })
            .collect();
        // A session starts at its first pose left (none when it has none left); the first
        // pose starts one anyway.
        c.session_starts = Vec::new();
        for &s in &self.session_starts {
            let start = new_index[..s.min(new_index.len())]
                .iter()
                .filter(|k| k.is_some())
                .count();
            if start > 0 && start < kept && c.session_starts.last() != Some(&start) {
                c.session_starts.push(start);
            }
        }
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
                    time_s: Logged::NONE,
                    temperature_c: Logged::NONE,
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

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(pose: usize) -> Reading {
        Reading {
            pose,
            sensor: 0,
            length_mm: pose as f64,
            time_s: Logged::NONE,
            temperature_c: Logged::NONE,
        }
    }

    /// Dropping a pose renumbers the poses after it, takes its observations along, and
    /// keeps session starts and sessions in order.
    #[test]
    fn without_poses_renumbers_what_is_left() {
        let poses: Vec<Pose> = (0..5)
            .map(|k| Pose::from_xyz_rpy_deg([k as f64, 0.0, 0.0], [0.0; 3]))
            .collect();
        let c = Campaign {
            poses: poses.clone(),
            commanded_lengths_mm: Some((0..5).map(|k| vec![k as f64]).collect()),
            readings: (0..5).flat_map(|j| [reading(j), reading(j)]).collect(),
            session_starts: vec![2, 3],
            tilt_measurements: (0..5)
                .map(|j| TiltMeasurement {
                    pose: j,
                    inclinometer: 0,
                    axis: 0,
                    session: usize::from(j >= 2) + usize::from(j >= 3),
                    angle_mrad: j as f64,
                    time_s: None,
                })
                .collect(),
            ..Campaign::default()
        };
        let d = c.without_poses(|j| j == 2);
        assert_eq!(d.poses, [poses[0], poses[1], poses[3], poses[4]]);
        assert_eq!(
            d.commanded_lengths_mm,
            Some(vec![vec![0.0], vec![1.0], vec![3.0], vec![4.0]])
        );
        let left: Vec<(usize, f64)> = d.readings.iter().map(|r| (r.pose, r.length_mm)).collect();
        assert_eq!(
            left,
            [
                (0, 0.0),
                (0, 0.0),
                (1, 1.0),
                (1, 1.0),
                (2, 3.0),
                (2, 3.0),
                (3, 4.0),
                (3, 4.0)
            ]
        );
        // The session of pose 2 is gone: the next starts where it started.
        assert_eq!(d.session_starts, [2]);
        let tilts: Vec<(usize, usize)> = d
            .tilt_measurements
            .iter()
            .map(|t| (t.pose, t.session))
            .collect();
        assert_eq!(tilts, [(0, 0), (1, 0), (2, 1), (3, 1)]);
        assert_eq!(c.without_poses(|_| false), c);
    }
}
