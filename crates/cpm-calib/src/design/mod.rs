//! Experiment design: where to put the sensor sockets and which poses to drive, chosen so that
//! every installation error is identified as well as the reading budget allows, and proved in
//! simulation before anyone touches the machine.
//!
//! - [`indices`]: observability indices O1..O4 of an identification Jacobian and the
//!   Cramér-Rao figures (worst direction, RMS, per parameter) for a sensor noise;
//! - [`candidates`]: candidate poses inside the workspace (random, grids, ballbar circles),
//!   filtered by link length limits, a tilt limit, J1's conditioning and forward kinematics;
//! - [`select`]: greedy and DETMAX-exchange selection of poses on the information matrix
//!   (D-, A- or E-optimal), incremental (Woodbury) so thousands of candidates take seconds;
//! - [`sockets`]: socket candidates, the socket pairs they make, and the gauge freedoms
//!   (rotations about the sockets) a layout leaves;
//! - [`monte_carlo`](mod@monte_carlo): many simulated campaigns and calibrations; RMS error, bias and
//!   efficiency against the Cramér-Rao bound;
//! - [`limits`]: the instrument and the machine's limits (gauge stroke and bars, gauge-link
//!   clearance, joint cone angles) and the exact distance between axes;
//! - [`setups`]: design under those limits: setups (socket pair + bar), the poses each drives,
//!   a setup sheet ([`design_setups`]);
//! - [`instruments`]: campaigns for a 6-D tracker, point targets, inclinometers or a mix: their
//!   bounds at each instrument's noise and the poses that identify most;
//! - [`design()`]: all of it together: sockets and poses jointly, for a reading budget, with the
//!   files a user drives the machine with ([`Design::poses_csv`], [`Design::sockets_csv`],
//!   [`Design::sensors_toml`]).
//!
//! Designs are made at the nominal geometry (installation errors are tens of micrometres, the
//! Jacobian barely changes with them) for the installation errors only: the model's extra
//! effects are left out.
//!
//! ```
//! use cpm_calib::design::{candidates, design, DesignOptions, sockets::SocketCandidates};
//! use cpm_calib::MeasurementModel;
//! use cpm_geometry::JointTable;
//! let model = MeasurementModel::new(JointTable::paper_cubic());
//! let ws = candidates::Workspace::default();
//! let (cands, _) = candidates::default_candidates(&model.nominal, &ws, 200, 100.0, 25.0, 1);
//! let opts = DesignOptions {
//!     max_readings: 360,
//!     base_sockets: 3,
//!     platform_sockets: 3,
//!     ..DesignOptions::default()
//! };
//! let d = design(&model, &SocketCandidates::paper_cubic(), &cands, &opts, &|_| {}).unwrap();
//! assert_eq!(d.poses.len(), 40); // 9 socket pairs x 40 poses = 360 readings
//! assert_eq!(d.indices.rank, 36);
//! assert!(d.poses_csv().starts_with("pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n1,"));
//! assert_eq!(d.gauge.first().unwrap().socket_freedoms(), 6); // one socket pair
//! assert_eq!(d.gauge.last().unwrap().socket_freedoms(), 0); // the design's layout
//! ```
pub mod candidates;
pub mod indices;
pub mod instruments;
pub mod limits;
pub mod monte_carlo;
pub mod select;
pub mod setups;
pub mod sockets;

use cpm_geometry::{Pose, Sensor};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

pub use indices::{observability_indices, Criterion, ObservabilityIndices};
pub use limits::{Clearance, Constraints, Gauge, GaugeKind, JointLimits};
pub use monte_carlo::{monte_carlo, monte_carlo_campaign, MonteCarloOptions, MonteCarloReport};
pub use select::{select_blocks, SelectOptions, Selection};
pub use setups::{design_setups, Setup, SetupDesign, SetupOptions};
pub use sockets::{gauge_freedoms, GaugeReport, Socket, SocketCandidates};

use crate::{identification_jacobian, CalibError, MeasurementModel, Plan};

/// Options of [`design`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DesignOptions {
    /// Most sensor readings (poses times socket pairs). Default 2000.
    pub max_readings: usize,
    /// Base sockets to use (every one paired with every platform socket). Default 4.
    pub base_sockets: usize,
    /// Platform sockets to use. Default 4.
    pub platform_sockets: usize,
    /// Poses to drive; default (`None`): as many as the budget allows,
    /// `max_readings / (base_sockets * platform_sockets)`.
    pub poses: Option<usize>,
    /// Pose selection (criterion, exchange). Default A-optimal with exchange.
    pub select: SelectOptions,
    /// Most alternations between choosing poses and choosing sockets. Default 4.
    pub socket_rounds: usize,
    /// Sensor noise standard deviation for the reported bounds, um. Default the paper's
    /// uniform +-10 um: 10 / sqrt(3).
    pub sigma_um: f64,
    /// Limits every chosen pose with every chosen sensor must honour (joint cones, link-link
    /// and gauge-link clearance). Default `None`: none beyond the candidates' own.
    pub limits: Option<DesignLimits>,
}

/// The machine's limits a [`design`] honours (see [`limits`]): at every chosen pose the joint
/// cones and, when set, the link-link clearance; with every chosen sensor at every chosen
/// pose the gauge-link clearance. The link length limits of the joint table apply to the
/// candidates already ([`candidates::Workspace`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DesignLimits {
    /// Joint cone limits.
    pub joints: JointLimits,
    /// Gauge-link (and link-link) clearance.
    pub clearance: Clearance,
}

impl DesignLimits {
    /// As [`Constraints`] (with the default gauge, which a design without limits does not
    /// use).
    pub fn constraints(&self) -> Constraints {
        Constraints {
            joints: self.joints,
            clearance: self.clearance,
            ..Constraints::default()
        }
    }
}

impl Default for DesignOptions {
    fn default() -> Self {
        Self {
            max_readings: 2000,
            base_sockets: 4,
            platform_sockets: 4,
            poses: None,
            select: SelectOptions::default(),
            socket_rounds: 4,
            sigma_um: 10.0 / 3f64.sqrt(),
            limits: None,
        }
    }
}

/// A design: sockets, socket pairs and poses, with its figures of merit.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Design {
    /// Poses to drive, in the order chosen by the selection (ascending candidate index).
    pub poses: Vec<Pose>,
    /// Chosen base sockets.
    pub base_sockets: Vec<Socket>,
    /// Chosen platform sockets.
    pub platform_sockets: Vec<Socket>,
    /// The sensors: every chosen base socket with every chosen platform socket, base-major.
    pub sensors: Vec<Sensor>,
    /// Criterion used.
    pub criterion: Criterion,
    /// Admissible candidate poses the design chose from.
    pub candidates: usize,
    /// Indices and Cramér-Rao figures of the design (at the nominal geometry).
    pub indices: ObservabilityIndices,
    /// Per sensor, the shortest and longest socket distance over the poses, mm: the travel
    /// the gauge needs.
    pub sensor_lengths_mm: Vec<(f64, f64)>,
    /// Gauge freedoms with growing socket layouts on the chosen poses: one socket pair first,
    /// then 2 x 2, 3 x 3, ... sockets, the design's own layout last.
    pub gauge: Vec<GaugeReport>,
    /// The limits the design honours ([`DesignOptions::limits`]).
    pub limits: Option<DesignLimits>,
    /// Largest base and platform joint cone angles over the chosen poses, deg.
    pub max_cone_deg: (f64, f64),
    /// Smallest distance between a sensor's axis and a link axis over the chosen poses and
    /// sensors, mm.
    pub min_clearance_mm: f64,
    /// What each stage achieved, in words.
    pub log: Vec<String>,
}

impl Design {
    /// The plan: every sensor read at every pose (sensor indices into [`Design::sensors`]).
    pub fn plan(&self) -> Plan {
        Plan {
            poses: self.poses.clone(),
            sensors: (0..self.sensors.len()).collect(),
        }
    }

    /// `model` with the design's sensors (the model the plan is read through).
    pub fn model(&self, model: &MeasurementModel) -> MeasurementModel {
        model.with_sensors(self.sensors.clone())
    }

    /// Readings the plan takes.
    pub fn num_readings(&self) -> usize {
        self.poses.len() * self.sensors.len()
    }

    /// The poses as CSV: header `pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg`, poses
    /// numbered from 1, `R = Rz(yaw) Ry(pitch) Rx(roll)`.
    pub fn poses_csv(&self) -> String {
        poses_csv(&self.poses)
    }

    /// The sensors (socket pairs) as CSV: header
    /// `name,base_x_mm,base_y_mm,base_z_mm,platform_x_mm,platform_y_mm,platform_z_mm`.
    pub fn sockets_csv(&self) -> String {
        sockets_csv(&self.sensors)
    }

    /// The sensors as `[[sensor]]` tables for the robot description (TOML).
    pub fn sensors_toml(&self) -> String {
        sensors_toml(&self.sensors)
    }
}

/// Poses as CSV (see [`Design::poses_csv`]).
pub fn poses_csv(poses: &[Pose]) -> String {
    let mut s = String::from("pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n");
    for (i, p) in poses.iter().enumerate() {
        let [r, pi, y] = p.rpy_deg();
        let t = p.position_mm;
        s.push_str(&format!(
            "{},{:.6},{:.6},{:.6},{:.9},{:.9},{:.9}\n",
            i + 1,
            t.x,
            t.y,
            t.z,
            r,
            pi,
            y
        ));
    }
    s
}

/// Sensors as CSV (see [`Design::sockets_csv`]).
pub fn sockets_csv(sensors: &[Sensor]) -> String {
    let mut s = String::from(
        "name,base_x_mm,base_y_mm,base_z_mm,platform_x_mm,platform_y_mm,platform_z_mm\n",
    );
    for x in sensors {
        let (b, p) = (x.base_mm, x.platform_mm);
        s.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            x.name, b.x, b.y, b.z, p.x, p.y, p.z
        ));
    }
    s
}

/// Sensors as `[[sensor]]` tables of the robot description (see `docs/robot-description.md`).
pub fn sensors_toml(sensors: &[Sensor]) -> String {
    let f = |v: f64| {
        let s = format!("{v}");
        if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
            s
        } else {
            format!("{s}.0")
        }
    };
    let mut s = String::new();
    for x in sensors {
        let (b, p) = (x.base_mm, x.platform_mm);
        s.push_str(&format!(
            "[[sensor]]\nname = \"{}\"\nbase_mm = [{}, {}, {}]\nplatform_mm = [{}, {}, {}]\n\n",
            x.name.replace('\\', "\\\\").replace('"', "\\\""),
            f(b.x),
            f(b.y),
            f(b.z),
            f(p.x),
            f(p.y),
            f(p.z)
        ));
    }
    s
}

/// k-subsets of `0..n` in lexicographic order.
fn subsets(n: usize, k: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    if k > n {
        return out;
    }
    let mut c: Vec<usize> = (0..k).collect();
    loop {
        out.push(c.clone());
        let mut i = k;
        loop {
            if i == 0 {
                return out;
            }
            i -= 1;
            if c[i] < n - k + i {
                break;
            }
            if i == 0 {
                return out;
            }
        }
        c[i] += 1;
        for j in i + 1..k {
            c[j] = c[j - 1] + 1;
        }
    }
}

/// Rows of the chosen socket pairs in an all-pairs block (base-major, `np` platform sockets).
fn pair_rows(base: &[usize], platform: &[usize], np: usize) -> Vec<usize> {
    let mut rows = Vec::with_capacity(base.len() * platform.len());
    for &b in base {
        for &p in platform {
            rows.push(b * np + p);
        }
    }
    rows
}

/// Most socket subsets ([base choices] x [platform choices]) searched exhaustively; beyond
/// this, sockets are improved by exchange.
const EXHAUSTIVE_SOCKETS: usize = 20_000;

/// Chooses sockets for fixed poses: the subsets maximising the criterion of the summed
/// per-pair information matrices, among those `feasible` allows (`start` must be feasible;
/// the result is, when any subset is).
#[allow(clippy::too_many_arguments)]
fn choose_sockets(
    pair_info: &[DMatrix<f64>],
    nb_all: usize,
    np_all: usize,
    nb: usize,
    np: usize,
    start: (&[usize], &[usize]),
    criterion: Criterion,
    feasible: &(dyn Fn(&[usize], &[usize]) -> bool + Sync),
) -> (Vec<usize>, Vec<usize>, f64) {
    let eval = |b: &[usize], p: &[usize]| {
        if !feasible(b, p) {
            return f64::NEG_INFINITY;
        }
        let n = pair_info[0].nrows();
        let mut m = DMatrix::zeros(n, n);
        for r in pair_rows(b, p, np_all) {
            m += &pair_info[r];
        }
        criterion.value(&m)
    };
    let bs = subsets(nb_all, nb);
    let ps = subsets(np_all, np);
    if bs.len() * ps.len() <= EXHAUSTIVE_SOCKETS {
        use rayon::prelude::*;
        let best = bs
            .par_iter()
            .flat_map(|b| ps.par_iter().map(move |p| (b, p)))
            .map(|(b, p)| (feasible(b, p), eval(b, p), b.clone(), p.clone()))
            .reduce_with(|x, y| {
                // Feasible first, then the larger criterion, then the first subsets.
                let better = (y.0, y.1) > (x.0, x.1)
                    || ((y.0, y.1) == (x.0, x.1) && (&y.2, &y.3) < (&x.2, &x.3));
                if better {
                    y
                } else {
                    x
                }
            })
            .map(|(_, v, b, p)| (v, b, p));
        if let Some((v, b, p)) = best {
            return (b, p, v);
        }
    }
    // Exchange: swap one socket for an unused one while that improves the criterion.
    let (mut b, mut p) = (start.0.to_vec(), start.1.to_vec());
    let mut v = eval(&b, &p);
    loop {
        let mut improved = false;
        for side in 0..2 {
            let (set, all) = if side == 0 {
                (b.clone(), nb_all)
            } else {
                (p.clone(), np_all)
            };
            for i in 0..set.len() {
                for c in 0..all {
                    if set.contains(&c) {
                        continue;
                    }
                    let mut trial = set.clone();
                    trial[i] = c;
                    trial.sort_unstable();
                    let tv = if side == 0 {
                        eval(&trial, &p)
                    } else {
                        eval(&b, &trial)
                    };
                    if tv > v {
                        v = tv;
                        if side == 0 {
                            b = trial;
                        } else {
                            p = trial;
                        }
                        improved = true;
                        break;
                    }
                }
                if improved {
                    break;
                }
            }
        }
        if !improved {
            return (b, p, v);
        }
    }
}

/// Designs a calibration experiment: chooses `options.base_sockets` base and
/// `options.platform_sockets` platform sockets from `sockets` and the poses from `candidates`
/// (admissible poses, e.g. from [`candidates::default_candidates`]) to optimise
/// `options.select.criterion`, within `options.max_readings` readings.
///
/// Sockets and poses are chosen jointly by alternation: poses for the current sockets (greedy,
/// then exchange), then the best sockets for those poses (exhaustively over the socket subsets
/// when there are few, else by exchange), until the sockets no longer change. The first
/// sockets are the best for all the candidate poses at once. `progress` is told each stage.
pub fn design(
    model: &MeasurementModel,
    sockets: &SocketCandidates,
    candidates: &[Pose],
    options: &DesignOptions,
    progress: &dyn Fn(&str),
) -> Result<Design, CalibError> {
    let (nb_all, np_all) = (sockets.base.len(), sockets.platform.len());
    let (nb, np) = (options.base_sockets, options.platform_sockets);
    let n_poses = check_design(nb_all, np_all, options)?;
    let mut log = Vec::new();
    // The joint limits: candidates beyond them are dropped.
    let constraints = options.limits.map(|l| l.constraints());
    if let Some(c) = &constraints {
        c.validate()?;
    }
    let table = &model.nominal;
    let candidates: Vec<Pose> = match &constraints {
        None => candidates.to_vec(),
        Some(c) => {
            let within = within_joint_limits(c, table, candidates, n_poses)?;
            log.push(format!(
                "{} of {} candidate poses within the joint limits (cones <= {} / {} deg{})",
                within.len(),
                candidates.len(),
                c.joints.base_cone_deg,
                c.joints.platform_cone_deg,
                c.clearance
                    .link_link_mm
                    .map_or(String::new(), |d| format!(", links >= {d} mm apart"))
            ));
            within
        }
    };
    progress(&format!(
        "design: Jacobian blocks of {} candidate poses x {} socket pairs",
        candidates.len(),
        nb_all * np_all
    ));
    let all_pairs = sockets.all_pairs();
    let (poses, blocks) = usable_blocks(model, &candidates, &all_pairs);
    if blocks.len() < n_poses {
        return Err(CalibError::invalid(
            "candidates",
            format!("{} usable candidate poses, {n_poses} needed", blocks.len()),
        ));
    }
    log.push(format!(
        "{} usable candidate poses of {}; {} x {} candidate sockets",
        blocks.len(),
        candidates.len(),
        nb_all,
        np_all
    ));
    // The gauge-link clearance: per socket pair, the candidates at which its axis clears
    // every link axis (bit sets); a layout may use only the poses all its pairs clear.
    let min_clear = constraints.as_ref().map(|c| c.clearance.gauge_link_mm);
    let clear_sets: Option<Vec<Vec<u64>>> = min_clear.map(|min| {
        use rayon::prelude::*;
        all_pairs
            .par_iter()
            .map(|s| {
                let mut bits = vec![0u64; poses.len().div_ceil(64)];
                for (c, p) in poses.iter().enumerate() {
                    if limits::gauge_clearance_mm(table, s, p) >= min {
                        bits[c / 64] |= 1 << (c % 64);
                    }
                }
                bits
            })
            .collect()
    });
    let layouts = Layouts {
        blocks: &blocks,
        clear_sets,
        min_clear,
        nb_all,
        np_all,
        nb,
        np,
        n_poses,
        options,
    };
    let (sb, sp) = layouts.first_sockets()?;
    let (sb, sp, chosen) = layouts.alternate(sb, sp, sockets, progress, &mut log)?;
    let base_sockets: Vec<Socket> = sb.iter().map(|&i| sockets.base[i].clone()).collect();
    let platform_sockets: Vec<Socket> = sp.iter().map(|&i| sockets.platform[i].clone()).collect();
    let sensors = sockets::pair_sensors(&base_sockets, &platform_sockets);
    let design_poses: Vec<Pose> = chosen.iter().map(|&c| poses[c]).collect();
    progress("design: indices and gauge freedoms of the chosen layout");
    let mut dm = model.with_sensors(sensors.clone());
    dm.effects.clear();
    let plan = Plan {
        poses: design_poses.clone(),
        sensors: (0..sensors.len()).collect(),
    };
    let j = identification_jacobian(&dm, &plan.skeleton(), &vec![0.0; dm.num_params()])?;
    let mut d = Design {
        poses: design_poses,
        base_sockets,
        platform_sockets,
        sensors,
        criterion: options.select.criterion,
        candidates: blocks.len(),
        indices: observability_indices(&j, options.sigma_um),
        sensor_lengths_mm: Vec::new(),
        gauge: Vec::new(),
        log,
        limits: options.limits,
        max_cone_deg: (0.0, 0.0),
        min_clearance_mm: f64::INFINITY,
    };
    d.measure_reach(table);
    // Gauge freedoms: one pair, then k x k sockets, then the layout itself.
    let mut layouts: Vec<(usize, usize)> = (1..nb.min(np)).map(|k| (k, k)).collect();
    layouts.push((nb, np));
    for (kb, kp) in layouts {
        let sensors: Vec<usize> = (0..kb)
            .flat_map(|b| (0..kp).map(move |p| b * np + p))
            .collect();
        let plan = Plan {
            poses: d.poses.clone(),
            sensors,
        };
        d.gauge.push(gauge_freedoms(&dm, &plan)?);
    }
    Ok(d)
}

/// The checks of [`design`]'s options against `nb_all` base and `np_all` platform socket
/// candidates; the number of poses to choose.
fn check_design(
    nb_all: usize,
    np_all: usize,
    options: &DesignOptions,
) -> Result<usize, CalibError> {
    let (nb, np) = (options.base_sockets, options.platform_sockets);
    if nb == 0 || np == 0 || nb > nb_all || np > np_all {
        return Err(CalibError::invalid(
            "sockets",
            format!(
                "{nb} base and {np} platform sockets asked for, {nb_all} and {np_all} candidates given (at least one each)"
            ),
        ));
    }
    let pairs = nb * np;
    let n_poses = options.poses.unwrap_or(options.max_readings / pairs);
    if n_poses == 0 || n_poses * pairs > options.max_readings {
        return Err(CalibError::invalid(
            "poses",
            format!(
                "{n_poses} poses x {pairs} socket pairs does not fit {} readings (and at least one pose is needed)",
                options.max_readings
            ),
        ));
    }
    if !(options.sigma_um.is_finite() && options.sigma_um > 0.0) {
        return Err(CalibError::invalid("sigma_um", "must be finite and > 0"));
    }
    Ok(n_poses)
}

/// The candidates whose Jacobian block (one row per pair of `all_pairs`) is finite, and
/// their blocks.
fn usable_blocks(
    model: &MeasurementModel,
    candidates: &[Pose],
    all_pairs: &[Sensor],
) -> (Vec<Pose>, Vec<DMatrix<f64>>) {
    let raw = sockets::pose_blocks(model, candidates, all_pairs);
    let mut poses = Vec::with_capacity(candidates.len());
    let mut blocks = Vec::with_capacity(candidates.len());
    for (p, b) in candidates.iter().zip(raw) {
        if let Some(b) = b {
            if b.iter().all(|v| v.is_finite()) {
                poses.push(*p);
                blocks.push(b);
            }
        }
    }
    (poses, blocks)
}

/// What the alternation of [`design`] chooses from: the usable candidates' Jacobian blocks
/// (a row per socket pair, pair `r` = base `r / np_all`, platform `r % np_all`) and which
/// pairs clear which candidates.
struct Layouts<'a> {
    blocks: &'a [DMatrix<f64>],
    /// Per socket pair, the candidates at which its axis clears every link axis (bit sets);
    /// `None` without limits (every pair clears every candidate).
    clear_sets: Option<Vec<Vec<u64>>>,
    /// The gauge-link clearance asked for, mm.
    min_clear: Option<f64>,
    nb_all: usize,
    np_all: usize,
    /// Base and platform sockets to choose, and poses.
    nb: usize,
    np: usize,
    n_poses: usize,
    options: &'a DesignOptions,
}

impl Layouts<'_> {
    /// Whether pair `r` clears candidate `c`.
    fn clear(&self, r: usize, c: usize) -> bool {
        self.clear_sets
            .as_ref()
            .is_none_or(|sets| sets[r][c / 64] >> (c % 64) & 1 == 1)
    }

    /// Candidates every pair of a layout clears.
    fn eligible(&self, b: &[usize], p: &[usize]) -> Vec<usize> {
        let rows = pair_rows(b, p, self.np_all);
        (0..self.blocks.len())
            .filter(|&c| rows.iter().all(|&r| self.clear(r, c)))
            .collect()
    }

    /// How many candidates every pair of a layout clears.
    fn eligible_count(&self, b: &[usize], p: &[usize]) -> usize {
        match &self.clear_sets {
            None => self.blocks.len(),
            Some(sets) => {
                let rows = pair_rows(b, p, self.np_all);
                (0..sets[0].len())
                    .map(|w| {
                        rows.iter()
                            .fold(u64::MAX, |acc, &r| acc & sets[r][w])
                            .count_ones() as usize
                    })
                    .sum()
            }
        }
    }

    /// Per socket pair, the information of the candidates it clears (`None`) or of the
    /// chosen poses (all of them: the layouts that do not clear them are not feasible).
    fn info_per_pair(&self, chosen: Option<&[usize]>) -> Vec<DMatrix<f64>> {
        let blocks = self.blocks;
        let n = blocks[0].ncols();
        use rayon::prelude::*;
        (0..self.nb_all * self.np_all)
            .into_par_iter()
            .map(|r| {
                let idx: Vec<usize> = match chosen {
                    Some(c) => c.to_vec(),
                    None => (0..blocks.len()).filter(|&c| self.clear(r, c)).collect(),
                };
                let a = DMatrix::from_fn(idx.len(), n, |i, c| blocks[idx[i]][(r, c)]);
                a.tr_mul(&a)
            })
            .collect()
    }

    /// The error when no layout clears enough candidates.
    fn no_layout(&self) -> CalibError {
        let (nb, np, n_poses) = (self.nb, self.np, self.n_poses);
        CalibError::invalid(
            "limits.gauge_link_mm",
            format!(
                "no layout of {nb} base and {np} platform sockets keeps every gauge axis {} mm from the link axes at {n_poses} poses (of {} candidates)",
                self.min_clear.unwrap_or(0.0),
                self.blocks.len()
            ),
        )
    }

    /// The first sockets: the best for all the candidate poses they clear at once, among
    /// the layouts that clear enough of them.
    fn first_sockets(&self) -> Result<(Vec<usize>, Vec<usize>), CalibError> {
        let first: Vec<usize> = (0..self.nb).collect();
        let firstp: Vec<usize> = (0..self.np).collect();
        let enough = |b: &[usize], p: &[usize]| self.eligible_count(b, p) >= self.n_poses;
        let (sb, sp, _) = choose_sockets(
            &self.info_per_pair(None),
            self.nb_all,
            self.np_all,
            self.nb,
            self.np,
            (&first, &firstp),
            self.options.select.criterion,
            &enough,
        );
        if !enough(&sb, &sp) {
            return Err(self.no_layout());
        }
        Ok((sb, sp))
    }

    /// Poses for sockets `b / p`: among the candidates they clear, from `start` when given
    /// (candidate indices); the chosen candidate indices, the selection and its information.
    fn select_for(
        &self,
        b: &[usize],
        p: &[usize],
        start: Option<&[usize]>,
    ) -> Result<(Vec<usize>, Selection, DMatrix<f64>), CalibError> {
        let rows = pair_rows(b, p, self.np_all);
        let el = self.eligible(b, p);
        if el.len() < self.n_poses {
            return Err(self.no_layout());
        }
        let sub: Vec<DMatrix<f64>> = el
            .iter()
            .map(|&c| self.blocks[c].select_rows(&rows))
            .collect();
        let start: Option<Vec<usize>> =
            start.and_then(|s| s.iter().map(|c| el.binary_search(c).ok()).collect());
        let sel = select_blocks(
            &sub,
            self.n_poses,
            None,
            start.as_deref(),
            &self.options.select,
        )?;
        let info = select::information(&sub, &sel.chosen);
        let chosen: Vec<usize> = sel.chosen.iter().map(|&i| el[i]).collect();
        Ok((chosen, sel, info))
    }

    /// The alternation from sockets `sb / sp`: poses for the current sockets, then the best
    /// sockets for those poses, until the sockets no longer change (at most
    /// `options.socket_rounds` rounds; poses chosen once more when the last round changed
    /// them). Returns the sockets and the chosen candidate indices.
    #[allow(clippy::type_complexity)]
    fn alternate(
        &self,
        mut sb: Vec<usize>,
        mut sp: Vec<usize>,
        sockets: &SocketCandidates,
        progress: &dyn Fn(&str),
        log: &mut Vec<String>,
    ) -> Result<(Vec<usize>, Vec<usize>, Vec<usize>), CalibError> {
        let (options, n_poses, np_all) = (self.options, self.n_poses, self.np_all);
        let criterion = options.select.criterion;
        let pairs = self.nb * self.np;
        let mut chosen: Option<Vec<usize>> = None;
        for round in 0..options.socket_rounds.max(1) {
            progress(&format!(
                "design round {}: {}-optimal selection of {n_poses} poses for sockets {} / {}",
                round + 1,
                criterion.name(),
                names(&sockets.base, &sb),
                names(&sockets.platform, &sp)
            ));
            let (now, sel, info) = self.select_for(&sb, &sp, chosen.as_deref())?;
            let ix = indices::indices_from_information(&info, n_poses * pairs, options.sigma_um);
            log.push(format!(
                "round {}: sockets {} / {}; {n_poses} poses, {}-criterion {:.4} after greedy, {:.4} after {} exchanges: Cramér-Rao RMS {:.3} um, max {:.3} um",
                round + 1,
                names(&sockets.base, &sb),
                names(&sockets.platform, &sp),
                criterion.name(),
                sel.greedy_value,
                sel.value,
                sel.exchanges,
                ix.crlb_rms_um,
                ix.crlb_max_um
            ));
            // Layouts whose pairs all clear the chosen poses.
            let clears_chosen = |b: &[usize], p: &[usize]| {
                let rows = pair_rows(b, p, np_all);
                now.iter().all(|&c| rows.iter().all(|&r| self.clear(r, c)))
            };
            let (nb2, np2, _) = choose_sockets(
                &self.info_per_pair(Some(&now)),
                self.nb_all,
                np_all,
                self.nb,
                self.np,
                (&sb, &sp),
                criterion,
                &clears_chosen,
            );
            chosen = Some(now);
            if nb2 == sb && np2 == sp {
                break;
            }
            sb = nb2;
            sp = np2;
            if round + 1 == options.socket_rounds.max(1) {
                // Sockets changed on the last round: choose the poses for them once more.
                let (now, sel, _) = self.select_for(&sb, &sp, chosen.as_deref())?;
                log.push(format!(
                    "final: sockets {} / {}; poses re-chosen for them, {}-criterion {:.4} after {} exchanges",
                    names(&sockets.base, &sb),
                    names(&sockets.platform, &sp),
                    criterion.name(),
                    sel.value,
                    sel.exchanges
                ));
                chosen = Some(now);
            }
        }
        Ok((sb, sp, chosen.unwrap_or_default()))
    }
}

impl Design {
    /// The largest cone angles, the smallest sensor-link clearance and each sensor's length
    /// range over the design's poses, on the nominal `table`.
    fn measure_reach(&mut self, table: &cpm_geometry::JointTable) {
        for p in &self.poses {
            for (b, q) in limits::cone_angles_deg(table, p) {
                self.max_cone_deg = (self.max_cone_deg.0.max(b), self.max_cone_deg.1.max(q));
            }
            for s in &self.sensors {
                self.min_clearance_mm = self
                    .min_clearance_mm
                    .min(limits::gauge_clearance_mm(table, s, p));
            }
        }
        self.sensor_lengths_mm = self
            .sensors
            .iter()
            .map(|s| {
                self.poses
                    .iter()
                    .fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
                        let l = s.length_mm(p);
                        (lo.min(l), hi.max(l))
                    })
            })
            .collect();
    }
}

/// The candidates within the joint limits of `c` (cones, link-link clearance); `Err` naming
/// the limits that rejected them when fewer than `needed` are.
fn within_joint_limits(
    c: &Constraints,
    table: &cpm_geometry::JointTable,
    candidates: &[Pose],
    needed: usize,
) -> Result<Vec<Pose>, CalibError> {
    use rayon::prelude::*;
    // Per candidate: beyond the base cone, the platform cone, the link-link clearance.
    let verdicts: Vec<(bool, bool, bool)> = candidates
        .par_iter()
        .map(|p| {
            let cones = limits::cone_angles_deg(table, p);
            let base = cones.iter().any(|(b, _)| !(*b <= c.joints.base_cone_deg));
            let plat = cones
                .iter()
                .any(|(_, q)| !(*q <= c.joints.platform_cone_deg));
            let links = c.clearance.link_link_mm.is_some_and(|min| {
                let axes = limits::link_axes(table, p);
                (0..axes.len()).any(|i| {
                    (i + 1..axes.len()).any(|j| {
                        !(limits::segment_distance_mm(
                            &axes[i].0, &axes[i].1, &axes[j].0, &axes[j].1,
                        ) >= min)
                    })
                })
            });
            (base, plat, links)
        })
        .collect();
    let within: Vec<Pose> = candidates
        .iter()
        .zip(&verdicts)
        .filter(|(_, v)| !(v.0 || v.1 || v.2))
        .map(|(p, _)| *p)
        .collect();
    if within.len() >= needed {
        return Ok(within);
    }
    let count = |f: fn(&(bool, bool, bool)) -> bool| verdicts.iter().filter(|v| f(v)).count();
    let mut why = vec![
        format!(
            "{} beyond the base joint cone of {} deg",
            count(|v| v.0),
            c.joints.base_cone_deg
        ),
        format!(
            "{} beyond the platform joint cone of {} deg",
            count(|v| v.1),
            c.joints.platform_cone_deg
        ),
    ];
    if let Some(d) = c.clearance.link_link_mm {
        why.push(format!(
            "{} with two link axes closer than {d} mm",
            count(|v| v.2)
        ));
    }
    Err(CalibError::invalid(
        "limits",
        format!(
            "{} of {} candidate poses within the joint limits ({}), {needed} needed",
            within.len(),
            candidates.len(),
            why.join(", ")
        ),
    ))
}

fn names(all: &[Socket], idx: &[usize]) -> String {
    idx.iter()
        .map(|&i| all[i].name.as_str())
        .collect::<Vec<_>>()
        .join(",")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_design_under_limits_keeps_them_at_every_pose_and_sensor() {
        let model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
        let ws = candidates::Workspace::default();
        let (cands, _) = candidates::default_candidates(&model.nominal, &ws, 300, 100.0, 25.0, 1);
        let sockets = SocketCandidates::paper_cubic();
        let free = DesignOptions {
            max_readings: 180,
            base_sockets: 3,
            platform_sockets: 3,
            ..DesignOptions::default()
        };
        let d = design(&model, &sockets, &cands, &free, &|_| {}).unwrap();
        assert!(d.limits.is_none());
        // The free design goes beyond the limits below (else the test proves nothing).
        assert!(
            d.max_cone_deg.0 > 20.0 && d.max_cone_deg.1 > 25.0 && d.min_clearance_mm < 25.0,
            "{:?}",
            (d.max_cone_deg, d.min_clearance_mm)
        );
        let limits = DesignLimits {
            joints: JointLimits {
                base_cone_deg: 20.0,
                platform_cone_deg: 25.0,
            },
            clearance: Clearance {
                gauge_link_mm: 25.0,
                link_link_mm: Some(10.0),
            },
        };
        let bounded = DesignOptions {
            limits: Some(limits),
            ..free
        };
        let d = design(&model, &sockets, &cands, &bounded, &|_| {}).unwrap();
        assert_eq!(d.poses.len(), 20);
        let t = &model.nominal;
        for p in &d.poses {
            assert!(limits.constraints().check_pose(t, p).is_ok());
            for s in &d.sensors {
                assert!(limits::gauge_clearance_mm(t, s, p) >= 25.0);
            }
        }
        assert!(d.max_cone_deg.0 <= 20.0 && d.max_cone_deg.1 <= 25.0);
        assert!(d.min_clearance_mm >= 25.0);
        // Limits nothing keeps: errors naming them.
        let impossible = |l: DesignLimits| {
            let o = DesignOptions {
                limits: Some(l),
                ..free
            };
            match design(&model, &sockets, &cands, &o, &|_| {}) {
                Err(CalibError::Invalid { field, why }) => format!("{field}: {why}"),
                other => panic!("{:?}", other.map(|d| d.poses.len())),
            }
        };
        let far_links = DesignLimits {
            clearance: Clearance {
                gauge_link_mm: 0.0,
                link_link_mm: Some(5000.0),
            },
            ..limits
        };
        let e = impossible(far_links);
        assert!(
            e.starts_with("limits: 0 of") && e.contains("closer than 5000 mm"),
            "{e}"
        );
        let far_gauge = DesignLimits {
            clearance: Clearance {
                gauge_link_mm: 5000.0,
                link_link_mm: None,
            },
            ..limits
        };
        assert!(impossible(far_gauge).starts_with("limits.gauge_link_mm: no layout"));
    }

    #[test]
    fn subsets_enumerate_all_combinations() {
        assert_eq!(subsets(4, 2).len(), 6);
        assert_eq!(subsets(8, 4).len(), 70);
        assert_eq!(subsets(3, 3), vec![vec![0, 1, 2]]);
        assert_eq!(subsets(3, 1), vec![vec![0], vec![1], vec![2]]);
        assert!(subsets(2, 3).is_empty());
    }

    #[test]
    fn csv_and_toml_outputs() {
        let sensors = vec![Sensor::new("b1p1", [1.0, 2.0, 3.5], [-1.0, 0.0, 2.0])];
        assert_eq!(
            sockets_csv(&sensors),
            "name,base_x_mm,base_y_mm,base_z_mm,platform_x_mm,platform_y_mm,platform_z_mm\nb1p1,1,2,3.5,-1,0,2\n"
        );
        let toml = sensors_toml(&sensors);
        assert!(toml.contains("base_mm = [1.0, 2.0, 3.5]"), "{toml}");
        let p = Pose::from_xyz_rpy_deg([1.0, 2.0, 410.0], [10.0, -5.0, 3.0]);
        let csv = poses_csv(&[p]);
        let line = csv.lines().nth(1).unwrap();
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        assert_eq!(v[0], 1.0);
        assert!(
            (v[4] - 10.0).abs() < 1e-6 && (v[5] + 5.0).abs() < 1e-6 && (v[6] - 3.0).abs() < 1e-6
        );
    }
}
