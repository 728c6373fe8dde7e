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
/// per-pair information matrices.
fn choose_sockets(
    pair_info: &[DMatrix<f64>],
    nb_all: usize,
    np_all: usize,
    nb: usize,
    np: usize,
    start: (&[usize], &[usize]),
    criterion: Criterion,
) -> (Vec<usize>, Vec<usize>, f64) {
    let eval = |b: &[usize], p: &[usize]| {
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
            .map(|(b, p)| (eval(b, p), b.clone(), p.clone()))
            .reduce_with(|x, y| {
                if y.0 > x.0 || (y.0 == x.0 && (&y.1, &y.2) < (&x.1, &x.2)) {
                    y
                } else {
                    x
                }
            });
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
    let mut log = Vec::new();
    progress(&format!(
        "design: Jacobian blocks of {} candidate poses x {} socket pairs",
        candidates.len(),
        nb_all * np_all
    ));
    let all_pairs = sockets.all_pairs();
    let raw = sockets::pose_blocks(model, candidates, &all_pairs);
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
    let criterion = options.select.criterion;
    let info_per_pair = |chosen: Option<&[usize]>| -> Vec<DMatrix<f64>> {
        let n = blocks[0].ncols();
        let idx: Vec<usize> = match chosen {
            Some(c) => c.to_vec(),
            None => (0..blocks.len()).collect(),
        };
        use rayon::prelude::*;
        (0..nb_all * np_all)
            .into_par_iter()
            .map(|r| {
                let a = DMatrix::from_fn(idx.len(), n, |i, c| blocks[idx[i]][(r, c)]);
                a.tr_mul(&a)
            })
            .collect()
    };
    let first: Vec<usize> = (0..nb).collect();
    let firstp: Vec<usize> = (0..np).collect();
    let (mut sb, mut sp, _) = choose_sockets(
        &info_per_pair(None),
        nb_all,
        np_all,
        nb,
        np,
        (&first, &firstp),
        criterion,
    );
    let mut chosen: Option<Vec<usize>> = None;
    for round in 0..options.socket_rounds.max(1) {
        let rows = pair_rows(&sb, &sp, np_all);
        let sub: Vec<DMatrix<f64>> = blocks.iter().map(|b| b.select_rows(&rows)).collect();
        progress(&format!(
            "design round {}: {}-optimal selection of {n_poses} poses for sockets {} / {}",
            round + 1,
            criterion.name(),
            names(&sockets.base, &sb),
            names(&sockets.platform, &sp)
        ));
        let sel = select_blocks(&sub, n_poses, None, chosen.as_deref(), &options.select)?;
        let info = select::information(&sub, &sel.chosen);
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
        let (nb2, np2, _) = choose_sockets(
            &info_per_pair(Some(&sel.chosen)),
            nb_all,
            np_all,
            nb,
            np,
            (&sb, &sp),
            criterion,
        );
        chosen = Some(sel.chosen);
        if nb2 == sb && np2 == sp {
            break;
        }
        sb = nb2;
        sp = np2;
        if round + 1 == options.socket_rounds.max(1) {
            // Sockets changed on the last round: choose the poses for them once more.
            let rows = pair_rows(&sb, &sp, np_all);
            let sub: Vec<DMatrix<f64>> = blocks.iter().map(|b| b.select_rows(&rows)).collect();
            let sel = select_blocks(&sub, n_poses, None, chosen.as_deref(), &options.select)?;
            log.push(format!(
                "final: sockets {} / {}; poses re-chosen for them, {}-criterion {:.4} after {} exchanges",
                names(&sockets.base, &sb),
                names(&sockets.platform, &sp),
                criterion.name(),
                sel.value,
                sel.exchanges
            ));
            chosen = Some(sel.chosen);
        }
    }
    let chosen = chosen.unwrap_or_default();
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
        criterion,
        candidates: blocks.len(),
        indices: observability_indices(&j, options.sigma_um),
        sensor_lengths_mm: Vec::new(),
        gauge: Vec::new(),
        log,
    };
    d.sensor_lengths_mm = d
        .sensors
        .iter()
        .map(|s| {
            d.poses.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
                let l = s.length_mm(p);
                (lo.min(l), hi.max(l))
            })
        })
        .collect();
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
