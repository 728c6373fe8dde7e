//! Robot description files (TOML): joint table, sensors, home pose, clearance, load.
//!
//! A description is what a user writes to tell `cpm` about a robot: where the joints are
//! (nominally), which length sensors exist, the home pose, how link readings map to lengths,
//! and optionally the joint clearance, the load on the platform, calibration settings, a set
//! of installation errors, and the instruments and limits of an experiment (`[[gauge]]`,
//! `[[socket]]`, `[[socket_region]]`, `[limits]`; see [`GaugeSpec`], [`LimitsSpec`]).
//! `docs/robot-description.md` documents every key; the structs here mirror the file one to
//! one and every table rejects unknown keys.
//!
//! Units follow the file convention of `cpm`: millimetres (`_mm`), micrometres for
//! clearance and installation errors (`_um`), degrees for angles (`_deg`), kilograms, newtons.
//! Orientation is `R = Rz(yaw) Ry(pitch) Rx(roll)` from `rpy_deg = [roll, pitch, yaw]`.
//!
//! Loading ([`RobotDescription::from_toml_str`], [`RobotDescription::load`]) parses and then
//! checks the values; every failure is a [`GeometryError::Description`] whose message carries
//! the line and column and names the key (`link[3].mm_per_unit: ...`; links, sensors and rows
//! are numbered from 1 in messages, like the paper's links). Loading never panics.
//!
//! ```
//! use cpm_geometry::description::RobotDescription;
//! use cpm_geometry::JointTable;
//! let text = RobotDescription::paper_cubic().to_toml_string().unwrap();
//! let desc = RobotDescription::from_toml_str(&text, "<doc>").unwrap();
//! assert_eq!(desc.joint_table().unwrap(), JointTable::paper_cubic());
//!
//! let err = RobotDescription::from_toml_str(&text.replace("[home]", "[home]\nz_mm = 1.0"), "x.toml")
//!     .unwrap_err()
//!     .to_string();
//! assert!(err.contains("z_mm") && err.contains("line"));
//! ```
use std::collections::{BTreeMap, HashSet};
use std::path::Path;

use nalgebra::{Vector3, Vector6};
use serde::{Deserialize, Serialize};

use crate::{GeometryError, InstallationErrors, JointTable, Link, Pose, Sensor};

mod instruments;
pub use instruments::{
    GaugeKindSpec, GaugeSpec, LimitsSpec, SocketRegionSpec, SocketSide, SocketSpec,
    DEFAULT_BALLBAR_SHORTEST_MM, DEFAULT_CONE_DEG, DEFAULT_GAUGE_LINK_CLEARANCE_MM,
    DEFAULT_LONGEST_MM, DEFAULT_REGION_GRID, DEFAULT_TELESCOPING_SHORTEST_MM,
    MAX_DESCRIBED_SOCKETS,
};

/// Standard gravity, mm/s^2; the default gravity is `[0, 0, -STANDARD_GRAVITY_MM_S2]`.
pub const STANDARD_GRAVITY_MM_S2: f64 = 9806.65;

/// Minimum number of links of a description.
pub const MIN_LINKS: usize = 6;

/// A robot description: the contents of a robot TOML file.
///
/// The field names are the file's keys, except `links` (`[[link]]` tables) and `sensors`
/// (`[[sensor]]` tables).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDescription {
    /// Free-form name of the robot. Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The home pose: start of forward kinematics.
    pub home: HomeSpec,
    /// The actuated links (`[[link]]`), six or more.
    #[serde(rename = "link")]
    pub links: Vec<LinkSpec>,
    /// Length sensors (`[[sensor]]`), possibly none.
    #[serde(rename = "sensor", default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<SensorSpec>,
    /// Joint clearance (`[clearance]`). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clearance: Option<ClearanceSpec>,
    /// Static load on the platform (`[load]`), which sets the clearance direction. Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<LoadSpec>,
    /// Calibration settings (`[calibration]`). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationSpec>,
    /// A set of installation errors, e.g. a calibration result or a simulation's truth
    /// (`[installation_errors_um]`). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub installation_errors_um: Option<InstallationErrorsSpec>,
    /// The pose error map's settings and fitted range (`[pose_map]`). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_map: Option<PoseMapSpec>,
    /// Length gauges available for a campaign (`[[gauge]]`), possibly none
    /// (see [`instruments`](GaugeSpec)).
    #[serde(rename = "gauge", default, skip_serializing_if = "Vec::is_empty")]
    pub gauges: Vec<GaugeSpec>,
    /// Candidate socket places (`[[socket]]`), possibly none.
    #[serde(rename = "socket", default, skip_serializing_if = "Vec::is_empty")]
    pub sockets: Vec<SocketSpec>,
    /// Boxes of candidate socket places (`[[socket_region]]`), possibly none.
    #[serde(
        rename = "socket_region",
        default,
        skip_serializing_if = "Vec::is_empty"
    )]
    pub socket_regions: Vec<SocketRegionSpec>,
    /// What the machine allows a design (`[limits]`): joint cones, link radius, gauge-link
    /// clearance. Optional (defaults stated in [`LimitsSpec`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<LimitsSpec>,
    /// Point targets on the platform (`[[target]]`: laser-tracker reflectors in their nests),
    /// possibly none.
    #[serde(rename = "target", default, skip_serializing_if = "Vec::is_empty")]
    pub targets: Vec<TargetSpec>,
    /// Inclinometers on the platform (`[[inclinometer]]`), possibly none.
    #[serde(
        rename = "inclinometer",
        default,
        skip_serializing_if = "Vec::is_empty"
    )]
    pub inclinometers: Vec<InclinometerSpec>,
}

/// `[[inclinometer]]`: an inclinometer on the platform. Each measured angle is the elevation
/// above the horizontal of one instrument axis, `asin(up . a_k)` (what MEMS inclinometers such
/// as the SCL3300 report), with `a_k` the platform direction the axis nominally points along,
/// turned by the instrument's mount rotation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InclinometerSpec {
    /// Name used in the `inclinometer` column of tilt files; unique.
    pub name: String,
    /// The platform direction of each measured axis, in the order of the file's
    /// `angle_1_deg`, `angle_2_deg`, ... (e.g. `[[0, 1, 0], [-1, 0, 0]]`: the first angle along
    /// +y of the platform, the second along -x); non-zero, normalised when read; one to three.
    pub axes: Vec<[f64; 3]>,
    /// The mount rotation of the instrument on the platform, roll pitch yaw deg
    /// (`R = Rz Ry Rx`, applied to the axes in {P}): nominally zero; a calibrated
    /// description writes the fitted one.
    #[serde(default, skip_serializing_if = "is_zero3")]
    pub mount_rpy_deg: [f64; 3],
    /// Standard deviation of one measured angle, urad (> 0; every `[[inclinometer]]` that
    /// declares one declares the same). Default: `[calibration]
    /// tracker_orientation_sigma_urad`, else 20.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_urad: Option<f64>,
}

/// A declared instrument noise: positive and finite, and the same as the first one declared
/// (`first`): a fit weighs every point (every angle) of a campaign alike.
fn same_noise(
    value: Option<f64>,
    first: Option<f64>,
    what: &str,
    path: &[Seg],
) -> Result<(), Problem> {
    let Some(v) = value else { return Ok(()) };
    if !(v.is_finite() && v > 0.0) {
        return Err(Problem::new(path, format!("{v}: must be > 0")));
    }
    match first {
        Some(f) if f != v => Err(Problem::new(
            path,
            format!(
                "{v} differs from the {f} declared for {what} before: the fit weighs every one alike, declare one noise"
            ),
        )),
        _ => Ok(()),
    }
}

fn is_zero3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| *x == 0.0)
}

/// `[[target]]`: a point target on the platform (a laser tracker's reflector, SMR, in its
/// nest), whose position a tracker measures as a 3-D point. Its platform position is known only
/// from a drawing: a calibration from point measurements estimates it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetSpec {
    /// Name used in the `target` column of point measurement files; unique.
    pub name: String,
    /// The target's centre in {P}, mm (nominal, or calibrated in a calibrated description).
    #[serde(deserialize_with = "exact")]
    pub platform_mm: [f64; 3],
    /// Standard deviation of one measured coordinate of the target, um (> 0; every
    /// `[[target]]` that declares one declares the same). Default: `[calibration]
    /// tracker_position_sigma_um`, else 10.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_um: Option<f64>,
}

/// `[home]`: the home pose.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HomeSpec {
    /// Platform origin in {B}, mm.
    #[serde(deserialize_with = "exact")]
    pub position_mm: [f64; 3],
    /// Roll, pitch, yaw in degrees, `R = Rz(yaw) Ry(pitch) Rx(roll)`. Default zero.
    #[serde(default, deserialize_with = "exact")]
    pub rpy_deg: [f64; 3],
}

impl HomeSpec {
    /// The home pose.
    pub fn pose(&self) -> Pose {
        Pose::from_xyz_rpy_deg(self.position_mm, self.rpy_deg)
    }
}

/// `[[link]]`: one actuated link and how its reading maps to a length.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    /// Base joint centre in {B}, mm.
    #[serde(deserialize_with = "exact")]
    pub base_mm: [f64; 3],
    /// Platform joint centre in {P}, mm.
    #[serde(deserialize_with = "exact")]
    pub platform_mm: [f64; 3],
    /// Allowed length range `[min, max]`, mm. Optional.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "exact_opt"
    )]
    pub length_limits_mm: Option<[f64; 2]>,
    /// Length at a zero reading, mm. Default 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub length_at_zero_mm: f64,
    /// Millimetres per reading unit. Default 1 (readings are lengths in mm).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub mm_per_unit: f64,
}

impl LinkSpec {
    /// A link with the default reading model (readings are lengths) and no limits.
    pub fn new(base_mm: [f64; 3], platform_mm: [f64; 3]) -> Self {
        Self {
            base_mm,
            platform_mm,
            length_limits_mm: None,
            length_at_zero_mm: 0.0,
            mm_per_unit: 1.0,
        }
    }

    /// Link length for a reading: `length_at_zero_mm + mm_per_unit * reading`, mm.
    ///
    /// ```
    /// use cpm_geometry::description::LinkSpec;
    /// let l = LinkSpec { length_at_zero_mm: 300.0, mm_per_unit: 0.001, ..LinkSpec::new([0.0; 3], [0.0; 3]) };
    /// assert_eq!(l.length_mm(54_000.0), 354.0);
    /// assert_eq!(l.reading(354.0), 54_000.0);
    /// ```
    pub fn length_mm(&self, reading: f64) -> f64 {
        self.length_at_zero_mm + self.mm_per_unit * reading
    }

    /// The reading that corresponds to a link length (inverse of [`LinkSpec::length_mm`]).
    pub fn reading(&self, length_mm: f64) -> f64 {
        (length_mm - self.length_at_zero_mm) / self.mm_per_unit
    }

    /// The geometric part: a [`Link`] of a joint table.
    pub fn to_link(&self) -> Link {
        Link {
            base_mm: Vector3::from(self.base_mm),
            platform_mm: Vector3::from(self.platform_mm),
            length_limits_mm: self.length_limits_mm.map(|[lo, hi]| (lo, hi)),
        }
    }

    /// From a [`Link`], with the default reading model.
    pub fn from_link(link: &Link) -> Self {
        Self {
            length_limits_mm: link.length_limits_mm.map(|(lo, hi)| [lo, hi]),
            ..Self::new(link.base_mm.into(), link.platform_mm.into())
        }
    }
}

/// `[[sensor]]`: a length sensor between a base socket and a platform socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// Name used in measurement files; unique.
    pub name: String,
    /// Base socket centre in {B}, mm.
    #[serde(deserialize_with = "exact")]
    pub base_mm: [f64; 3],
    /// Platform socket centre in {P}, mm.
    #[serde(deserialize_with = "exact")]
    pub platform_mm: [f64; 3],
    /// The `[[gauge]]` this sensor is read with (a setup of that gauge). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gauge: Option<String>,
    /// The extension bar of this setup, mm: its readings lie in the gauge's window
    /// `[shortest + bar, shortest + bar + stroke]`. Optional (needs `gauge`; without it only
    /// the gauge's range and stroke are checked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bar_mm: Option<f64>,
}

impl SensorSpec {
    /// The [`Sensor`] of a joint table.
    pub fn to_sensor(&self) -> Sensor {
        Sensor::new(&self.name, self.base_mm, self.platform_mm)
    }

    /// From a [`Sensor`].
    pub fn from_sensor(sensor: &Sensor) -> Self {
        Self {
            name: sensor.name.clone(),
            base_mm: sensor.base_mm.into(),
            platform_mm: sensor.platform_mm.into(),
            gauge: None,
            bar_mm: None,
        }
    }
}

/// `[clearance]`: radial clearance of the joints.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClearanceSpec {
    /// Clearance radius of every joint, um.
    pub radius_um: f64,
    /// Width of the smooth sign rule for the clearance direction, N; 0 (the default) is the
    /// paper's hard rule.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub smooth_force_n: f64,
}

/// `[load]`: masses and external wrench, for the statics that set the clearance direction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// Platform mass, kg.
    pub platform_mass_kg: f64,
    /// Platform centre of mass in {P}, mm.
    #[serde(deserialize_with = "exact")]
    pub platform_com_mm: [f64; 3],
    /// Payload mass, kg. Default 0.
    #[serde(default)]
    pub payload_mass_kg: f64,
    /// Payload centre of mass in {P}, mm. Default origin.
    #[serde(default, deserialize_with = "exact")]
    pub payload_com_mm: [f64; 3],
    /// Gravity in {B}, mm/s^2. Default `[0, 0, -9806.65]`.
    #[serde(default = "default_gravity", deserialize_with = "exact")]
    pub gravity_mm_s2: [f64; 3],
    /// External force on the platform at its origin, {B}, N. Default zero.
    #[serde(default, deserialize_with = "exact")]
    pub external_force_n: [f64; 3],
    /// External moment on the platform about its origin, {B}, N mm. Default zero.
    #[serde(default, deserialize_with = "exact")]
    pub external_moment_nmm: [f64; 3],
}

impl LoadSpec {
    /// A platform of `mass_kg` with its centre of mass at `com_mm` in {P}, standard gravity
    /// along -z of {B}, no payload, no external wrench.
    pub fn platform(mass_kg: f64, com_mm: [f64; 3]) -> Self {
        Self {
            platform_mass_kg: mass_kg,
            platform_com_mm: com_mm,
            payload_mass_kg: 0.0,
            payload_com_mm: [0.0; 3],
            gravity_mm_s2: default_gravity(),
            external_force_n: [0.0; 3],
            external_moment_nmm: [0.0; 3],
        }
    }

    /// Platform plus payload mass, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.platform_mass_kg + self.payload_mass_kg
    }

    /// The wrench applied to the platform at `pose`: `[force (N); moment about the platform
    /// origin (N mm)]`, both in {B}. Weights (`m g`, with `g` in mm/s^2 so `1e-3 m g` is in
    /// newtons) act at the centres of mass `R c`; the external wrench is added as given.
    ///
    /// ```
    /// use cpm_geometry::{description::LoadSpec, Pose};
    /// let load = LoadSpec::platform(20.0, [0.0, 0.0, -100.0]);
    /// let w = load.wrench(&Pose::from_xyz_rpy(0.0, 0.0, 410.0, 0.0, 0.0, 0.0));
    /// assert!((w[2] + 20.0 * 9.80665).abs() < 1e-12); // 196 N down
    /// assert!(w.fixed_rows::<3>(3).norm() < 1e-12); // COM right below the origin: no moment
    /// ```
    pub fn wrench(&self, pose: &Pose) -> Vector6<f64> {
        let g = Vector3::from(self.gravity_mm_s2) * 1e-3;
        let weight_p = g * self.platform_mass_kg;
        let weight_l = g * self.payload_mass_kg;
        let cp = pose.rotation * Vector3::from(self.platform_com_mm);
        let cl = pose.rotation * Vector3::from(self.payload_com_mm);
        let f = weight_p + weight_l + Vector3::from(self.external_force_n);
        let m = cp.cross(&weight_p) + cl.cross(&weight_l) + Vector3::from(self.external_moment_nmm);
        Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z)
    }
}

/// `[calibration]`: settings for the calibration.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationSpec {
    /// Extra effects to identify besides the installation errors, e.g. `"link_offset"`,
    /// `"link_scale"`; interpreted by the calibration crate. Default none.
    #[serde(default)]
    pub effects: Vec<String>,
    /// Standard deviation of the sensor noise, um. Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_noise_um: Option<f64>,
    /// Standard deviation of a tracker position coordinate, um: the weight of tracker
    /// positions in a fit and in the registration of every session. `cpm calibrate` and
    /// `cpm refine` write the value they fitted with, so that `cpm validate` registers held-out
    /// sessions with the same weights. Default (when absent) cpm-calib's 10 um.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracker_position_sigma_um: Option<f64>,
    /// Standard deviation of a tracker orientation component, urad (as
    /// `tracker_position_sigma_um`). Default (when absent) cpm-calib's 20 urad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracker_orientation_sigma_urad: Option<f64>,
    /// Screw lead of the actuators, mm (the period of `screw_periodic`). Default 5.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screw_lead_mm: Option<f64>,
    /// Reference temperature of `thermal_drift`, deg C. Default 20.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_temperature_c: Option<f64>,
    /// Time origin of `thermal_drift` without temperatures, s (on the clock of the files'
    /// `time_s`): the drift is proportional to the hours since it. `cpm calibrate` and `cpm
    /// refine` write the origin they fitted with (the earliest time of their data) so that a
    /// prediction does not depend on which part of a file is given. Default (when absent) the
    /// earliest time of the data predicted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_time_s: Option<f64>,
    /// Length scale of `link_nonlinearity`'s polynomial variable, mm. Default 100.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nonlinearity_scale_mm: Option<f64>,
    /// `[calibration.known_effects]`: known values of effects (a calibration result), keyed
    /// by effect name, one value per parameter in the effect's units and parameter order
    /// (e.g. `backlash = [2.1, -0.4, ...]` um, one per link). Every prediction applies them;
    /// an effect also listed in `effects` is estimated as a correction on top. Interpreted
    /// by the calibration crate. Default none.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub known_effects: BTreeMap<String, Vec<f64>>,
    /// `[calibration.instruments]`: the fitted values of one's own instruments' parameters
    /// (instruments written in code, `cpm_calib::instruments::Instrument`: no description
    /// declares them), keyed by the instrument's name, its per-instrument parameters in their
    /// order and units. Written by a calibration with such instruments; a model with the same
    /// instruments predicts with them. Default none.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub instruments: BTreeMap<String, Vec<f64>>,
    /// `[calibration.tolerances]`: the a-priori tolerance (standard deviation) of each group of
    /// parameters, keyed by group (`installation_errors` in um, an effect's name in the
    /// effect's unit, e.g. `link_scale = 50000` ppm); interpreted by the calibration crate,
    /// which documents the defaults (scaled to the machine). A fit holds a direction that the
    /// data see less well than its tolerance near nominal. Default: the calibration crate's.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub tolerances: BTreeMap<String, f64>,
    /// How many tolerances a fitted parameter may reach: one the data pull further is held
    /// there (not measured, named in the report) and the fit repeated; `inf` for no limit.
    /// Interpreted by the calibration crate. Default (when absent) 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_limit: Option<f64>,
    /// Groups of parameters held at their nominal (or known) values and not fitted, e.g.
    /// `hold = ["installation_errors"]` to fit only the effects. Default none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hold: Vec<String>,
    /// The description this calibration started from (written by `cpm calibrate` and
    /// `cpm refine`: its path relative to the folder of the calibrated file, so that the two
    /// can move together; older files hold an absolute path), so that `cpm validate` can take
    /// it as the reference by default. Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated_from: Option<String>,
    /// The installation-error components and effect parameters the calibration's data did
    /// not determine on their own (written by `cpm calibrate` and `cpm refine` at the fit's
    /// minimum-norm point): `cpm compensate` warns that its commands cannot correct them.
    /// Default none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub undetermined: Vec<String>,
    /// What the calibration's data could not see, in words (its blind directions, e.g. "all
    /// base joints translated together": a base frame the instruments cannot fix). Default
    /// none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub blind_directions: Vec<String>,
    /// The FNV-1a (64-bit, hex) fingerprint of that description's bytes when the calibration
    /// was made: `cpm validate` says when the file found there is no longer the same.
    /// Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibrated_from_fnv1a64: Option<String>,
    /// True when the calibration was fitted to simulated data: every output made from this
    /// description (compensation commands, controller files) says so. Default false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub simulated: bool,
    /// `[calibration.covariance]`: the covariance of the calibrated machine's parameters
    /// (written by `cpm calibrate` and `cpm refine`): what `cpm compensate` turns into the
    /// pose error it predicts at each target. Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covariance: Option<CovarianceSpec>,
}

/// `[calibration.covariance]`: the covariance of a calibration's machine parameters (the
/// installation errors, then the parameters of `effects`, in the calibration crate's order),
/// about the calibrated values; the session's own parameters (tracker frames, base tilts)
/// are left out.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CovarianceSpec {
    /// The effects whose parameters follow the installation errors, in order. Default none.
    #[serde(default)]
    pub effects: Vec<String>,
    /// The parameters' names, as the reports name them (each with its unit).
    pub parameters: Vec<String>,
    /// The standard deviation of each parameter, in its unit (um for an installation error).
    pub std: Vec<f64>,
    /// The correlation matrix, row by row (1 on the diagonal; the covariance of parameters `a`
    /// and `b` is `std[a] std[b] correlation[a][b]`).
    pub correlation: Vec<Vec<f64>>,
    /// What neither the data nor a tolerance bounded (blind directions, in words): the
    /// covariance says nothing of them. Default none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unbounded: Vec<String>,
}

/// `[installation_errors_um]`: joint displacements, um, one row `[dx, dy, dz]` per link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstallationErrorsSpec {
    /// Base joint displacements in {B}, um, one per link.
    #[serde(deserialize_with = "exact_list")]
    pub base: Vec<[f64; 3]>,
    /// Platform joint displacements in {P}, um, one per link.
    #[serde(deserialize_with = "exact_list")]
    pub platform: Vec<[f64; 3]>,
}

impl InstallationErrorsSpec {
    /// As [`InstallationErrors`].
    pub fn to_errors(&self) -> InstallationErrors {
        InstallationErrors {
            base_um: self.base.iter().map(|v| Vector3::from(*v)).collect(),
            platform_um: self.platform.iter().map(|v| Vector3::from(*v)).collect(),
        }
    }

    /// From [`InstallationErrors`].
    pub fn from_errors(errors: &InstallationErrors) -> Self {
        Self {
            base: errors.base_um.iter().map(|v| (*v).into()).collect(),
            platform: errors.platform_um.iter().map(|v| (*v).into()).collect(),
        }
    }
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

fn one() -> f64 {
    1.0
}

/// A fixed number of numbers: serde's own arrays would take the first `N` of a longer TOML
/// list and ignore the rest (`position_mm = [0, 0, 300, 999]`).
fn exact<'de, D: serde::Deserializer<'de>, const N: usize>(d: D) -> Result<[f64; N], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    exact_of(&v)
}

fn exact_of<E: serde::de::Error, const N: usize>(v: &[f64]) -> Result<[f64; N], E> {
    v.try_into().map_err(|_| {
        E::custom(format!(
            "expected {N} numbers, got {} (extra or missing values are not ignored)",
            v.len()
        ))
    })
}

fn exact_opt<'de, D: serde::Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Option<[f64; N]>, D::Error> {
    Option::<Vec<f64>>::deserialize(d)?
        .map(|v| exact_of(&v))
        .transpose()
}

fn exact_list<'de, D: serde::Deserializer<'de>, const N: usize>(
    d: D,
) -> Result<Vec<[f64; N]>, D::Error> {
    Vec::<Vec<f64>>::deserialize(d)?
        .iter()
        .map(|v| exact_of(v))
        .collect()
}

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -STANDARD_GRAVITY_MM_S2]
}

/// One step of a key path: a key, a key named by the file (a map entry) or a 0-based
/// array index.
#[derive(Debug, Clone)]
enum Seg {
    Key(&'static str),
    Name(String),
    Index(usize),
}

/// A semantic problem: where (key path) and what.
#[derive(Debug)]
struct Problem {
    path: Vec<Seg>,
    message: String,
}

impl Problem {
    fn new(path: &[Seg], message: impl Into<String>) -> Self {
        Self {
            path: path.to_vec(),
            message: message.into(),
        }
    }

    /// `link[3].mm_per_unit` (indices shown from 1).
    fn path_string(&self) -> String {
        let mut s = String::new();
        for seg in &self.path {
            match seg {
                Seg::Key(k) => {
                    if !s.is_empty() {
                        s.push('.');
                    }
                    s.push_str(k);
                }
                Seg::Name(k) => {
                    if !s.is_empty() {
                        s.push('.');
                    }
                    s.push_str(k);
                }
                Seg::Index(i) => s.push_str(&format!("[{}]", i + 1)),
            }
        }
        s
    }

    /// The message, with the line and column of the key in `source` when it can be found.
    fn render(&self, source: Option<&str>) -> String {
        let mut out = format!("{}: {}", self.path_string(), self.message);
        if let Some((line, col)) = source.and_then(|s| locate(s, &self.path)) {
            out.push_str(&format!(" (line {line}, column {col})"));
        }
        out
    }
}

/// Line and column (1-based) of the value at `path` in the TOML `source`, or of the deepest
/// part of the path that exists there.
fn locate(source: &str, path: &[Seg]) -> Option<(usize, usize)> {
    use toml::de::{DeTable, DeValue};
    let root = DeTable::parse(source).ok()?;
    let mut span = root.span();
    let root = DeValue::Table(root.into_inner());
    let mut cur = &root;
    for seg in path {
        let next = match seg {
            Seg::Key(k) => cur.get(*k),
            Seg::Name(k) => cur.get(k.as_str()),
            Seg::Index(i) => cur.get(*i),
        };
        match next {
            Some(v) => {
                span = v.span();
                cur = v.get_ref();
            }
            None => break,
        }
    }
    let before = source.get(..span.start.min(source.len()))?;
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Some((line, col))
}

fn finite3(v: &[f64; 3], path: &[Seg]) -> Result<(), Problem> {
    match v.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(k) => Err(Problem::new(
            path,
            format!(
                "must be finite, but its {} component is {}",
                ["x (1st)", "y (2nd)", "z (3rd)"][k],
                v[k]
            ),
        )),
    }
}

/// Refuses a machine whose links cannot hold the platform at home: two links on the same
/// joints, or a link Jacobian of rank below 6 (six or more links).
fn singular_at_home(d: &RobotDescription, home: &Pose) -> Result<(), Problem> {
    use Seg::{Index, Key};
    let rows: Vec<(Vector3<f64>, Vector3<f64>)> = d
        .links
        .iter()
        .map(|l| {
            let b = Vector3::from(l.base_mm);
            let p = home.transform_point(&Vector3::from(l.platform_mm));
            let u = (p - b).normalize();
            (u, (p - home.transform_point(&Vector3::zeros())).cross(&u))
        })
        .collect();
    for (j, lj) in d.links.iter().enumerate() {
        for (i, li) in d.links.iter().enumerate().take(j) {
            let same =
                |a: &[f64; 3], b: &[f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
            if same(&li.base_mm, &lj.base_mm) && same(&li.platform_mm, &lj.platform_mm) {
                return Err(Problem::new(
                    &[Key("link"), Index(j)],
                    format!(
                        "has the same joints as link {} (it coincides with it): the machine is singular at its home pose",
                        i + 1
                    ),
                ));
            }
        }
    }
    if rows.len() >= 6 {
        let m = nalgebra::DMatrix::from_fn(rows.len(), 6, |r, c| {
            if c < 3 {
                rows[r].0[c]
            } else {
                rows[r].1[c - 3] * 1e-3 // per metre, to balance the columns
            }
        });
        let sv = m.singular_values();
        let (smax, smin) = (sv.max(), sv.min());
        if !(smin > 1e-9 * smax.max(f64::MIN_POSITIVE)) {
            return Err(Problem::new(
                &[Key("link")],
                format!(
                    "the links do not hold the platform at its home pose: their Jacobian is singular (smallest singular value {smin:.3e} of {smax:.3e})"
                ),
            ));
        }
    }
    Ok(())
}

/// The largest coordinate of a plausible description, mm (1 km).
pub const MAX_COORDINATE_MM: f64 = 1e6;
/// The shortest plausible link at the home pose, mm.
pub const MIN_LINK_LENGTH_MM: f64 = 1.0;
/// The largest plausible installation error, um (100 mm).
pub const MAX_INSTALLATION_ERROR_UM: f64 = 1e5;
/// The largest plausible joint clearance, um (10 mm).
pub const MAX_CLEARANCE_UM: f64 = 1e4;
/// The farthest plausible centre of mass of `[load]`, in multiples of the machine's size (the
/// largest joint distance from the base or platform origin).
pub const MAX_COM_SIZES: f64 = 100.0;

/// A finite position within [`MAX_COORDINATE_MM`] of the origin.
fn position3(v: &[f64; 3], path: &[Seg]) -> Result<(), Problem> {
    finite3(v, path)?;
    match v.iter().position(|x| x.abs() > MAX_COORDINATE_MM) {
        None => Ok(()),
        Some(k) => Err(Problem::new(
            path,
            format!(
                "its {} component is {:e} mm: implausibly far (over {} km; positions are in mm)",
                ["x (1st)", "y (2nd)", "z (3rd)"][k],
                v[k],
                MAX_COORDINATE_MM * 1e-6
            ),
        )),
    }
}

/// A name that can be a CSV value: not empty, no spaces at its ends, no comma, quote or
/// control character, not starting with '#'; `what` names its kind in the message (a
/// sensor's, a target's: a column value of the measurement files).
fn plain_name_of(name: &str, what: Option<&str>, path: &[Seg]) -> Result<(), Problem> {
    if name.trim().is_empty() {
        return Err(Problem::new(path, "must not be empty"));
    }
    if name.trim() != name
        || name.starts_with('#')
        || name.chars().any(|c| c.is_control() || c == ',' || c == '"')
    {
        let (kind, why) = match what {
            Some(w) => (
                format!("{w} "),
                " (it is a column value of the measurement files)",
            ),
            None => (String::new(), ""),
        };
        return Err(Problem::new(
            path,
            format!(
                "{name:?}: a {kind}name must not start with '#', have spaces at its ends or contain a comma, a quote or a control character{why}"
            ),
        ));
    }
    Ok(())
}

/// A sensor's or target's name ([`plain_name_of`]), unique among `seen`.
fn column_name<'a>(
    name: &'a str,
    what: &str,
    seen: &mut HashSet<&'a str>,
    path: &[Seg],
) -> Result<(), Problem> {
    plain_name_of(name, Some(what), path)?;
    if !seen.insert(name) {
        return Err(Problem::new(
            path,
            format!("duplicate {what} name `{name}`"),
        ));
    }
    Ok(())
}

fn non_negative(v: f64, path: &[Seg]) -> Result<(), Problem> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Problem::new(
            path,
            format!("must be finite and >= 0, got {v}"),
        ))
    }
}

fn desc_err(path: &str, message: String) -> GeometryError {
    GeometryError::Description {
        path: path.to_string(),
        message,
    }
}

impl RobotDescription {
    /// Parses and checks a description. `path` names the source in error messages (use e.g.
    /// `"<string>"` for text that is not a file).
    ///
    /// Errors ([`GeometryError::Description`]) for TOML syntax, unknown keys, missing keys and
    /// wrong types carry toml's message (line, column, the key); semantic errors (non-finite
    /// numbers, fewer than six links, duplicate sensor names, unordered limits, ...) name the
    /// key path and its line and column.
    pub fn from_toml_str(s: &str, path: &str) -> Result<Self, GeometryError> {
        let desc: Self = toml::from_str(s).map_err(|e| desc_err(path, e.to_string()))?;
        desc.check()
            .map_err(|p| desc_err(path, p.render(Some(s))))?;
        Ok(desc)
    }

    /// Reads, parses and checks a description file.
    ///
    /// ```
    /// use cpm_geometry::{JointTable, RobotDescription};
    /// // (Doctests run in the crate's folder.)
    /// let d = RobotDescription::load("../../examples/hexapod_66.toml").unwrap();
    /// assert_eq!(d.joint_table().unwrap(), JointTable::hexapod_66());
    /// let e = RobotDescription::load("no/such/file.toml").unwrap_err();
    /// assert!(e.to_string().starts_with("no/such/file.toml: cannot read the file"));
    /// ```
    pub fn load(path: impl AsRef<Path>) -> Result<Self, GeometryError> {
        let p = path.as_ref();
        let name = p.display().to_string();
        let text = std::fs::read_to_string(p)
            .map_err(|e| desc_err(&name, format!("cannot read the file: {e}")))?;
        Self::from_toml_str(&text, &name)
    }

    /// The description as TOML text (loads back to an equal description).
    pub fn to_toml_string(&self) -> Result<String, GeometryError> {
        toml::to_string(self).map_err(|e| desc_err(&self.label(), e.to_string()))
    }

    /// Writes the description as TOML to `path`.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), GeometryError> {
        let p = path.as_ref();
        let text = self.to_toml_string()?;
        std::fs::write(p, text)
            .map_err(|e| desc_err(&p.display().to_string(), format!("cannot write: {e}")))
    }

    /// Checks every value (see [`RobotDescription::from_toml_str`]).
    pub fn validate(&self) -> Result<(), GeometryError> {
        self.check()
            .map_err(|p| desc_err(&self.label(), p.render(None)))
    }

    /// The joint table (links, sensors, home pose), after [`RobotDescription::validate`].
    pub fn joint_table(&self) -> Result<JointTable, GeometryError> {
        self.validate()?;
        Ok(JointTable {
            links: self.links.iter().map(LinkSpec::to_link).collect(),
            sensors: self.sensors.iter().map(SensorSpec::to_sensor).collect(),
            home: self.home.pose(),
        })
    }

    /// The installation errors of `[installation_errors_um]`, if present (checked).
    pub fn installation_errors(&self) -> Result<Option<InstallationErrors>, GeometryError> {
        self.validate()?;
        Ok(self
            .installation_errors_um
            .as_ref()
            .map(InstallationErrorsSpec::to_errors))
    }

    /// Link lengths (mm) from link readings, one per link, through each link's
    /// `length_at_zero_mm + mm_per_unit * reading`.
    pub fn lengths_from_readings(&self, readings: &[f64]) -> Result<Vec<f64>, GeometryError> {
        if readings.len() != self.links.len() {
            return Err(GeometryError::LinkCountMismatch {
                errors: readings.len(),
                links: self.links.len(),
            });
        }
        Ok(self
            .links
            .iter()
            .zip(readings)
            .map(|(l, r)| l.length_mm(*r))
            .collect())
    }

    /// A description of a joint table: links (readings are lengths), sensors and home pose;
    /// no name, clearance, load, calibration or installation errors.
    pub fn from_joint_table(table: &JointTable) -> Self {
        Self {
            name: None,
            home: HomeSpec {
                position_mm: table.home.position_mm.into(),
                // `+ 0.0` turns a -0.0 from atan2 into 0.0 for tidy files.
                rpy_deg: table.home.rpy_deg().map(|a| a + 0.0),
            },
            links: table.links.iter().map(LinkSpec::from_link).collect(),
            sensors: table.sensors.iter().map(SensorSpec::from_sensor).collect(),
            clearance: None,
            load: None,
            calibration: None,
            installation_errors_um: None,
            pose_map: None,
            gauges: Vec::new(),
            sockets: Vec::new(),
            socket_regions: Vec::new(),
            limits: None,
            targets: Vec::new(),
            inclinometers: Vec::new(),
        }
    }

    /// The paper's cubic manipulator as in `examples/paper_cubic.toml`:
    /// [`JointTable::paper_cubic`] plus a 10 um clearance (hard sign rule) and an assumed
    /// load (platform 20 kg with its centre of mass at (0, 0, -100) mm in {P}; the paper
    /// gives no mass).
    pub fn paper_cubic() -> Self {
        Self {
            name: Some("paper cubic".into()),
            clearance: Some(ClearanceSpec {
                radius_um: 10.0,
                smooth_force_n: 0.0,
            }),
            load: Some(LoadSpec::platform(20.0, [0.0, 0.0, -100.0])),
            ..Self::from_joint_table(&JointTable::paper_cubic())
        }
    }

    /// The general 6-6 Gough-Stewart platform of `examples/hexapod_66.toml`:
    /// [`JointTable::hexapod_66`] plus a 10 um clearance and a 10 kg platform with its
    /// centre of mass at (0, 0, -20) mm in {P}.
    pub fn hexapod_66() -> Self {
        Self {
            name: Some("hexapod 6-6".into()),
            clearance: Some(ClearanceSpec {
                radius_um: 10.0,
                smooth_force_n: 0.0,
            }),
            load: Some(LoadSpec::platform(10.0, [0.0, 0.0, -20.0])),
            ..Self::from_joint_table(&JointTable::hexapod_66())
        }
    }

    /// How error messages name a description that did not come from a file.
    fn label(&self) -> String {
        match &self.name {
            Some(n) => format!("robot description `{n}`"),
            None => "<robot description>".into(),
        }
    }

    /// Semantic checks; the first problem found.
    fn check(&self) -> Result<(), Problem> {
        use Seg::Key;
        if let Some(p) = &self.pose_map {
            p.check()?;
        }
        position3(&self.home.position_mm, &[Key("home"), Key("position_mm")])?;
        finite3(&self.home.rpy_deg, &[Key("home"), Key("rpy_deg")])?;
        let n = self.links.len();
        if n < MIN_LINKS {
            return Err(Problem::new(
                &[Key("link")],
                format!("need at least {MIN_LINKS} [[link]] tables, got {n}"),
            ));
        }
        let home = self.home.pose();
        self.check_links(&home)?;
        singular_at_home(self, &home)?;
        self.check_instrument_tables()?;
        self.check_clearance_and_load(&home)?;
        if let Some(c) = &self.calibration {
            check_calibration(c)?;
        }
        self.check_installation_errors(n)?;
        self.check_instruments()?;
        Ok(())
    }

    /// [[link]] tables: positions, length limits, reading scale, and a plausible length at
    /// the home pose.
    fn check_links(&self, home: &Pose) -> Result<(), Problem> {
        use Seg::{Index, Key};
        for (i, l) in self.links.iter().enumerate() {
            let at = |k: &'static str| [Key("link"), Index(i), Key(k)];
            position3(&l.base_mm, &at("base_mm"))?;
            position3(&l.platform_mm, &at("platform_mm"))?;
            if let Some([lo, hi]) = l.length_limits_mm {
                if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi) {
                    return Err(Problem::new(
                        &at("length_limits_mm"),
                        format!("need finite 0 < min < max, got [{lo}, {hi}]"),
                    ));
                }
            }
            if !l.length_at_zero_mm.is_finite() {
                return Err(Problem::new(
                    &at("length_at_zero_mm"),
                    format!("must be finite, got {}", l.length_at_zero_mm),
                ));
            }
            if !(l.mm_per_unit.is_finite() && l.mm_per_unit != 0.0) {
                return Err(Problem::new(
                    &at("mm_per_unit"),
                    format!("must be finite and non-zero, got {}", l.mm_per_unit),
                ));
            }
            if l.mm_per_unit < 0.0 {
                return Err(Problem::new(
                    &at("mm_per_unit"),
                    format!(
                        "must be > 0 (millimetres per reading unit: the link lengthens as its reading grows), got {}",
                        l.mm_per_unit
                    ),
                ));
            }
            let q = home.transform_point(&Vector3::from(l.platform_mm)) - Vector3::from(l.base_mm);
            let length = q.norm();
            if !(length > 1e-9) {
                return Err(Problem::new(
                    &[Key("link"), Index(i)],
                    "zero length at the home pose (its joints coincide)",
                ));
            }
            if length < MIN_LINK_LENGTH_MM {
                return Err(Problem::new(
                    &[Key("link"), Index(i)],
                    format!(
                        "only {length:.6} mm long at the home pose: implausibly short (positions are in mm: is the description in metres?)"
                    ),
                ));
            }
            if let Some([lo, hi]) = l.length_limits_mm {
                if length < lo || length > hi {
                    return Err(Problem::new(
                        &at("length_limits_mm"),
                        format!(
                            "the link is {length:.3} mm long at the home pose, outside [{lo}, {hi}] mm: the home pose must be within the limits"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// [[sensor]], [[target]] and [[inclinometer]] tables: unique names, positions, axes,
    /// one noise per kind.
    fn check_instrument_tables(&self) -> Result<(), Problem> {
        use Seg::{Index, Key};
        let mut names = HashSet::new();
        for (i, s) in self.sensors.iter().enumerate() {
            let at = |k: &'static str| [Key("sensor"), Index(i), Key(k)];
            column_name(&s.name, "sensor", &mut names, &at("name"))?;
            position3(&s.base_mm, &at("base_mm"))?;
            position3(&s.platform_mm, &at("platform_mm"))?;
        }
        let mut target_names = HashSet::new();
        for (i, t) in self.targets.iter().enumerate() {
            let at = |k: &'static str| [Key("target"), Index(i), Key(k)];
            column_name(&t.name, "target", &mut target_names, &at("name"))?;
            position3(&t.platform_mm, &at("platform_mm"))?;
            same_noise(
                t.sigma_um,
                self.targets.iter().find_map(|t| t.sigma_um),
                "a target",
                &at("sigma_um"),
            )?;
        }
        let mut inclinometer_names = HashSet::new();
        for (i, c) in self.inclinometers.iter().enumerate() {
            let at = |k: &'static str| [Key("inclinometer"), Index(i), Key(k)];
            column_name(
                &c.name,
                "inclinometer",
                &mut inclinometer_names,
                &at("name"),
            )?;
            if c.axes.is_empty() || c.axes.len() > 3 {
                return Err(Problem::new(
                    &at("axes"),
                    format!("needs one to three axes, got {}", c.axes.len()),
                ));
            }
            for (k, a) in c.axes.iter().enumerate() {
                let path = [Key("inclinometer"), Index(i), Key("axes"), Index(k)];
                finite3(a, &path)?;
                let norm = a.iter().map(|x| x * x).sum::<f64>().sqrt();
                if !(norm > 1e-9) {
                    return Err(Problem::new(&path, "a zero vector is no direction"));
                }
            }
            finite3(&c.mount_rpy_deg, &at("mount_rpy_deg"))?;
            same_noise(
                c.sigma_urad,
                self.inclinometers.iter().find_map(|c| c.sigma_urad),
                "an inclinometer",
                &at("sigma_urad"),
            )?;
        }
        Ok(())
    }

    /// [clearance] and [load]: non-negative sizes, a finite weight and wrench at home.
    fn check_clearance_and_load(&self, home: &Pose) -> Result<(), Problem> {
        use Seg::Key;
        if let Some(c) = &self.clearance {
            non_negative(c.radius_um, &[Key("clearance"), Key("radius_um")])?;
            if c.radius_um > MAX_CLEARANCE_UM {
                return Err(Problem::new(
                    &[Key("clearance"), Key("radius_um")],
                    format!(
                        "{:e} um: implausibly large (over {} mm; the clearance is in um)",
                        c.radius_um,
                        MAX_CLEARANCE_UM * 1e-3
                    ),
                ));
            }
            non_negative(c.smooth_force_n, &[Key("clearance"), Key("smooth_force_n")])?;
            if c.radius_um > 0.0 && self.load.is_none() {
                return Err(Problem::new(
                    &[Key("load")],
                    format!(
                        "missing: [clearance] (radius {} um) is applied along each link's force, which only a declared load gives; declare [load], or leave [clearance] out",
                        c.radius_um
                    ),
                ));
            }
        }
        if let Some(l) = &self.load {
            let at = |k: &'static str| [Key("load"), Key(k)];
            non_negative(l.platform_mass_kg, &at("platform_mass_kg"))?;
            non_negative(l.payload_mass_kg, &at("payload_mass_kg"))?;
            finite3(&l.platform_com_mm, &at("platform_com_mm"))?;
            finite3(&l.payload_com_mm, &at("payload_com_mm"))?;
            // A centre of mass far beyond the machine is a unit slip (m for mm, a typo).
            let size = self
                .links
                .iter()
                .flat_map(|k| [&k.base_mm, &k.platform_mm])
                .map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt())
                .fold(0.0, f64::max);
            for key in ["platform_com_mm", "payload_com_mm"] {
                let v = if key == "platform_com_mm" {
                    l.platform_com_mm
                } else {
                    l.payload_com_mm
                };
                let far = v.iter().map(|x| x * x).sum::<f64>().sqrt();
                if size > 0.0 && far > MAX_COM_SIZES * size {
                    return Err(Problem::new(
                        &at(key),
                        format!(
                            "implausibly far from the platform's origin: {far:.6e} mm, over {MAX_COM_SIZES} times the machine's size ({size:.1} mm; centres of mass are in mm in {{P}})"
                        ),
                    ));
                }
            }
            finite3(&l.gravity_mm_s2, &at("gravity_mm_s2"))?;
            finite3(&l.external_force_n, &at("external_force_n"))?;
            finite3(&l.external_moment_nmm, &at("external_moment_nmm"))?;
            // Derived quantities: the weight and the wrench at home must be finite too.
            let w = l.wrench(home);
            if !(l.total_mass_kg().is_finite() && w.iter().all(|x| x.is_finite())) {
                let key = if l.payload_mass_kg > l.platform_mass_kg {
                    "payload_mass_kg"
                } else {
                    "platform_mass_kg"
                };
                return Err(Problem::new(
                    &at(key),
                    format!(
                        "the load's weight or wrench at home is not a finite number (masses {:e} + {:e} kg): implausible",
                        l.platform_mass_kg, l.payload_mass_kg
                    ),
                ));
            }
        }
        Ok(())
    }

    /// [installation_errors_um]: one finite, plausible row per link (`n` links).
    fn check_installation_errors(&self, n: usize) -> Result<(), Problem> {
        use Seg::{Index, Key};
        if let Some(e) = &self.installation_errors_um {
            for (key, rows) in [("base", &e.base), ("platform", &e.platform)] {
                if rows.len() != n {
                    return Err(Problem::new(
                        &[Key("installation_errors_um"), Key(key)],
                        format!(
                            "has {} rows, need one [dx, dy, dz] per link ({n})",
                            rows.len()
                        ),
                    ));
                }
                for (i, r) in rows.iter().enumerate() {
                    let at = [Key("installation_errors_um"), Key(key), Index(i)];
                    finite3(r, &at)?;
                    if let Some(k) = r.iter().position(|v| v.abs() > MAX_INSTALLATION_ERROR_UM) {
                        return Err(Problem::new(
                            &at,
                            format!(
                                "its {} component is {:e} um: implausibly large (over {} mm; installation errors are in um)",
                                ["x (1st)", "y (2nd)", "z (3rd)"][k],
                                r[k],
                                MAX_INSTALLATION_ERROR_UM * 1e-3
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

/// [calibration]: positive noises and scales, unique non-empty effects, finite reference
/// time and temperature, finite known effects.
fn check_calibration(c: &CalibrationSpec) -> Result<(), Problem> {
    use Seg::{Index, Key, Name};
    for (v, key) in [
        (c.tracker_position_sigma_um, "tracker_position_sigma_um"),
        (
            c.tracker_orientation_sigma_urad,
            "tracker_orientation_sigma_urad",
        ),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                return Err(Problem::new(
                    &[Key("calibration"), Key(key)],
                    format!("must be > 0, got {v} (leave it out for the default)"),
                ));
            }
        }
    }
    if let Some(v) = c.sensor_noise_um {
        // Like `--sigma-um`: a declared noise must be > 0 (leave the key out to have
        // the noise estimated from the residual).
        if !(v.is_finite() && v > 0.0) {
            return Err(Problem::new(
                &[Key("calibration"), Key("sensor_noise_um")],
                format!(
                    "must be > 0, got {v} (leave it out to estimate the noise from the residual)"
                ),
            ));
        }
    }
    if let Some(v) = c.tolerance_limit {
        // A number of tolerances: > 0, `inf` for no limit.
        if !(v > 0.0) {
            return Err(Problem::new(
                &[Key("calibration"), Key("tolerance_limit")],
                format!("must be > 0 (a number of tolerances; inf for no limit), got {v}"),
            ));
        }
    }
    let mut seen = HashSet::new();
    for (i, e) in c.effects.iter().enumerate() {
        let at = [Key("calibration"), Key("effects"), Index(i)];
        if e.trim().is_empty() {
            return Err(Problem::new(&at, "must not be empty"));
        }
        if !seen.insert(e.as_str()) {
            return Err(Problem::new(&at, format!("duplicate effect `{e}`")));
        }
    }
    for (key, v) in [
        ("screw_lead_mm", c.screw_lead_mm),
        ("nonlinearity_scale_mm", c.nonlinearity_scale_mm),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && v > 0.0) {
                return Err(Problem::new(
                    &[Key("calibration"), Key(key)],
                    format!("must be finite and > 0, got {v}"),
                ));
            }
        }
    }
    if let Some(t) = c.reference_time_s {
        if !t.is_finite() {
            return Err(Problem::new(
                &[Key("calibration"), Key("reference_time_s")],
                format!("must be a finite time, s, got {t}"),
            ));
        }
    }
    if let Some(t) = c.reference_temperature_c {
        if !(t.is_finite() && (-273.15..=1000.0).contains(&t)) {
            return Err(Problem::new(
                &[Key("calibration"), Key("reference_temperature_c")],
                format!("must be a temperature between -273.15 and 1000 deg C, got {t}"),
            ));
        }
    }
    let known = c.known_effects.iter().map(|e| ("known_effects", e));
    for (table, (name, values)) in known.chain(c.instruments.iter().map(|e| ("instruments", e))) {
        let at = |i: usize| [Key("calibration"), Key(table), Name(name.clone()), Index(i)];
        if values.is_empty() {
            return Err(Problem::new(&at(0)[..3], "has no values"));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(Problem::new(
                &at(i),
                format!("must be finite, got {}", values[i]),
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// [pose_map]: the pose error map (a self-contained section).

/// `[pose_map]`: the pose error map's scan degree and the range of commanded poses its terms
/// were fitted on. The terms themselves are effects like any other (`pose_map_y2` in
/// `[calibration] effects` to estimate, in `[calibration.known_effects]` when known); a map
/// describes the fitted range only and does not extrapolate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseMapSpec {
    /// Highest degree of the terms `cpm refine` scans for (0 to 3). Default 2.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degree: Option<u8>,
    /// Smallest commanded x, y, z (mm), roll, pitch, yaw (deg) of the poses the known terms
    /// were fitted on. Written by `cpm calibrate` / `cpm refine`; optional.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "exact_opt"
    )]
    pub fitted_min: Option<[f64; 6]>,
    /// Largest commanded x, y, z (mm), roll, pitch, yaw (deg) of the fitted poses.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "exact_opt"
    )]
    pub fitted_max: Option<[f64; 6]>,
}

impl PoseMapSpec {
    fn check(&self) -> Result<(), Problem> {
        use Seg::{Index, Key};
        if let Some(d) = self.degree {
            if d > 3 {
                return Err(Problem::new(
                    &[Key("pose_map"), Key("degree")],
                    format!("must be 0 to 3, got {d}"),
                ));
            }
        }
        for (key, v) in [
            ("fitted_min", self.fitted_min),
            ("fitted_max", self.fitted_max),
        ] {
            if let Some(i) = v.and_then(|v| v.iter().position(|x| !x.is_finite())) {
                return Err(Problem::new(
                    &[Key("pose_map"), Key(key), Index(i)],
                    "must be finite",
                ));
            }
        }
        match (self.fitted_min, self.fitted_max) {
            (Some(lo), Some(hi)) => {
                if let Some(i) = (0..6).find(|&i| lo[i] > hi[i]) {
                    return Err(Problem::new(
                        &[Key("pose_map"), Key("fitted_min"), Index(i)],
                        format!("{} is above fitted_max {}", lo[i], hi[i]),
                    ));
                }
                Ok(())
            }
            (None, None) => Ok(()),
            _ => Err(Problem::new(
                &[Key("pose_map")],
                "give both fitted_min and fitted_max, or neither",
            )),
        }
    }
}
