//! Sensor sockets: candidate places for the gauge's base and platform sockets, the sensors
//! (socket pairs) they make, and the gauge freedoms a socket layout leaves.
//!
//! A length gauge between one base socket `b` and one platform socket `p` cannot tell the
//! base joints apart from the same joints rotated rigidly about `b` (the gauge sees the base
//! only through distances from `b`), nor the platform joints from the same joints rotated
//! about `p`: 3 + 3 *gauge freedoms*, whatever the poses. A second base socket pins two of the
//! three base rotations (only the rotation about the line through both sockets is left); a
//! third socket off that line pins the last. So three non-collinear base sockets and three
//! non-collinear platform sockets, read in pairs, remove all six.
//!
//! [`gauge_freedoms`] counts them numerically: the dimension of the intersection of the
//! Jacobian's null space with the rigid motions of all base joints, and of all platform joints.
//!
//! ```
//! use cpm_calib::design::sockets::{pair_sensors, Socket};
//! let base = [Socket::new("b1", [0.0, 500.0, 500.0]), Socket::new("b2", [500.0, 0.0, 400.0])];
//! let platform = [Socket::new("p1", [0.0, 200.0, 0.0])];
//! let sensors = pair_sensors(&base, &platform);
//! assert_eq!(sensors.len(), 2);
//! assert_eq!(sensors[1].name, "b2p1");
//! ```
use cpm_geometry::{Pose, Sensor};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::analysis::identifiability::{analyze, physical_patterns, BlindDirection, RankOptions};
use crate::{identification_jacobian, CalibError, MeasurementModel, Plan};

/// A place to screw a socket: on the base (position in {B}) or the platform (in {P}).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Socket {
    /// Name, e.g. `b1` or `p3`.
    pub name: String,
    /// Socket centre, mm ({B} for base sockets, {P} for platform sockets).
    pub position_mm: Vector3<f64>,
}

impl Socket {
    /// A socket from a name and a position, mm.
    pub fn new(name: &str, position_mm: [f64; 3]) -> Self {
        Self {
            name: name.to_string(),
            position_mm: Vector3::from(position_mm),
        }
    }
}

/// The places a user could put sockets.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SocketCandidates {
    /// Candidate base sockets ({B}).
    pub base: Vec<Socket>,
    /// Candidate platform sockets ({P}).
    pub platform: Vec<Socket>,
}

impl SocketCandidates {
    /// Candidate sockets for the paper's cubic machine: the paper's pair (`b1`, `p1`), the
    /// sockets of [`crate::data::sensors::designed_sensors`] (`b1`..`b4`, `p1`..`p4`), and more
    /// places on a frame around the machine (`b5`..`b8`, radius about 500 mm, heights 100 to
    /// 550 mm) and on the platform body (`p5`..`p8`, its upper and lower corners).
    pub fn paper_cubic() -> Self {
        let base = [
            [-200.0, 500.0, 500.0],
            [350.0, -350.0, 450.0],
            [-400.0, -250.0, 250.0],
            [400.0, 300.0, 250.0],
            [500.0, 0.0, 550.0],
            [0.0, -500.0, 100.0],
            [-500.0, 0.0, 550.0],
            [0.0, 500.0, 100.0],
        ];
        let platform = [
            [-200.0, 205.0, -5.0],
            [150.0, -150.0, 0.0],
            [-150.0, -150.0, -150.0],
            [150.0, 150.0, -250.0],
            [200.0, 200.0, 0.0],
            [-200.0, -200.0, 0.0],
            [200.0, -200.0, -250.0],
            [-200.0, 200.0, -250.0],
        ];
        Self {
            base: base
                .iter()
                .enumerate()
                .map(|(i, p)| Socket::new(&format!("b{}", i + 1), *p))
                .collect(),
            platform: platform
                .iter()
                .enumerate()
                .map(|(i, p)| Socket::new(&format!("p{}", i + 1), *p))
                .collect(),
        }
    }

    /// Every base socket paired with every platform socket, base-major
    /// (sensor `i * platform.len() + j` joins base `i` and platform `j`).
    pub fn all_pairs(&self) -> Vec<Sensor> {
        pair_sensors(&self.base, &self.platform)
    }
}

/// Every base socket paired with every platform socket, base-major, named `{base}{platform}`.
pub fn pair_sensors(base: &[Socket], platform: &[Socket]) -> Vec<Sensor> {
    let mut out = Vec::with_capacity(base.len() * platform.len());
    for b in base {
        for p in platform {
            out.push(Sensor {
                name: format!("{}{}", b.name, p.name),
                base_mm: b.position_mm,
                platform_mm: p.position_mm,
            });
        }
    }
    out
}

/// Per-pose Jacobian blocks of the installation errors: for each pose, one row per sensor
/// (um of reading per um of error, at the nominal geometry, through the model's clearance).
/// The model's effects are left out (the design is for the installation errors). `None` where
/// the model fails at a pose (forward kinematics, statics).
pub fn pose_blocks(
    model: &MeasurementModel,
    poses: &[Pose],
    sensors: &[Sensor],
) -> Vec<Option<DMatrix<f64>>> {
    let mut m = model.with_sensors(sensors.to_vec());
    m.effects.clear();
    let zeros = vec![0.0; m.num_params()];
    let all: Vec<usize> = (0..sensors.len()).collect();
    poses
        .par_iter()
        .map(|p| {
            let plan = Plan {
                poses: vec![*p],
                sensors: all.clone(),
            };
            identification_jacobian(&m, &plan.skeleton(), &zeros).ok()
        })
        .collect()
}

/// Orthonormal basis (parameters x 6) of the rigid motions of all base joints (`side` 0) or
/// all platform joints (`side` 1): three translations and three small rotations about the
/// origin of the side's frame.
pub fn rigid_motions(model: &MeasurementModel, side: usize) -> DMatrix<f64> {
    let n = model.nominal.num_links();
    let np = 6 * n;
    let mut cols = Vec::with_capacity(6);
    for a in 0..6 {
        let mut v = DVector::zeros(np);
        for (i, l) in model.nominal.links.iter().enumerate() {
            let p = if side == 0 { l.base_mm } else { l.platform_mm };
            let d = if a < 3 {
                let mut t = Vector3::zeros();
                t[a] = 1.0;
                t
            } else {
                let mut w = Vector3::zeros();
                w[a - 3] = 1.0;
                w.cross(&p)
            };
            for b in 0..3 {
                v[6 * i + 3 * side + b] = d[b];
            }
        }
        cols.push(v);
    }
    let q = DMatrix::from_columns(&cols).qr().q();
    q.columns(0, 6).into_owned()
}

/// The gauge freedoms a plan leaves (see the module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GaugeReport {
    /// Distinct base sockets read.
    pub base_sockets: usize,
    /// Distinct platform sockets read.
    pub platform_sockets: usize,
    /// Sensors (socket pairs) read.
    pub pairs: usize,
    /// Readings.
    pub readings: usize,
    /// Rank of the identification Jacobian (of `num_params`).
    pub rank: usize,
    /// Number of installation-error parameters.
    pub num_params: usize,
    /// Rigid motions of the base joints the readings cannot see (0 to 3: rotations about the
    /// base sockets).
    pub base_freedoms: usize,
    /// Rigid motions of the platform joints the readings cannot see (0 to 3).
    pub platform_freedoms: usize,
    /// Null-space dimensions beyond the socket freedoms.
    pub other_null_dimensions: usize,
    /// The blind directions in words (the identifiability analysis's names).
    pub blind_directions: Vec<BlindDirection>,
}

impl GaugeReport {
    /// Base plus platform freedoms.
    pub fn socket_freedoms(&self) -> usize {
        self.base_freedoms + self.platform_freedoms
    }
}

/// Counts the gauge freedoms of `plan` read through `model` (its sensors), at the nominal
/// geometry, with the default rank threshold.
pub fn gauge_freedoms(model: &MeasurementModel, plan: &Plan) -> Result<GaugeReport, CalibError> {
    let mut m = model.clone();
    m.effects.clear();
    let campaign = plan.skeleton();
    let j = identification_jacobian(&m, &campaign, &vec![0.0; m.num_params()])?;
    let opts = RankOptions::default();
    let ident = analyze(&j, 1.0, &opts, &physical_patterns(&m, &campaign));
    let count = |side: usize| {
        let q = rigid_motions(&m, side);
        (&j * q)
            .singular_values()
            .iter()
            .filter(|s| **s <= ident.threshold)
            .count()
    };
    let (bf, pf) = (count(0), count(1));
    let mut bases: Vec<[u64; 3]> = Vec::new();
    let mut plats: Vec<[u64; 3]> = Vec::new();
    for &s in &plan.sensors {
        let sensor = &m.nominal.sensors[s];
        let key = |v: &Vector3<f64>| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
        if !bases.contains(&key(&sensor.base_mm)) {
            bases.push(key(&sensor.base_mm));
        }
        if !plats.contains(&key(&sensor.platform_mm)) {
            plats.push(key(&sensor.platform_mm));
        }
    }
    Ok(GaugeReport {
        base_sockets: bases.len(),
        platform_sockets: plats.len(),
        pairs: plan.sensors.len(),
        readings: plan.num_readings(),
        rank: ident.rank,
        num_params: ident.num_params,
        base_freedoms: bf,
        platform_freedoms: pf,
        other_null_dimensions: (ident.num_params - ident.rank).saturating_sub(bf + pf),
        blind_directions: ident.blind_directions,
    })
}
