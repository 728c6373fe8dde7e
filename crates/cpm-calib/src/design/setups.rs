//! Design under the limits: setups (socket pair + extension bar) and the poses each drives,
//! chosen so that every reading honours the gauge's stroke, the gauge-link clearance, the
//! joint cone angles and the link length limits ([`super::limits::Constraints`]).
//!
//! A reading is one setup at one pose. It is *admissible* when the pose is (workspace, cone
//! angles, link lengths), the gauge axis clears every link axis by the clearance, and the
//! socket distance lies in the setup's window `[shortest + bar, shortest + bar + stroke]`.
//! Only admissible readings are ever candidates, so no design can choose another.
//!
//! 1. **Pose sensitivities.** A reading's row of the identification Jacobian is
//!    `g^T S`: `g` the gradient of the socket distance with respect to the pose twist
//!    ([`cpm_kinematics::sensor_pose_gradient`]) and `S` (6 x 36) the sensitivity of the
//!    actual pose to the installation errors, the same for every gauge. `S` is computed once
//!    per pose from the links themselves read as sensors (`S = J1^-1 J_links`), so every
//!    socket pair's row costs a 6-vector product.
//! 2. **Candidate setups.** For every socket pair, windows over the lengths it spans (one per
//!    bar, or evenly spread when bars are free). A setup's candidate readings are the
//!    candidate poses whose length falls in its window, plus *projected* poses: candidate
//!    poses moved along the gauge axis until the length falls in the window (the platform
//!    socket slides along the gauge's line, so the length changes by exactly the shift; a
//!    ballbar's circles are poses of this kind). Projected poses are checked like any other.
//! 3. **Setups** are chosen greedily, then by exchange, on the criterion of the summed
//!    information of their readings, each setup's information scaled to its share of the
//!    budget (`max_readings / max_setups` readings).
//! 4. **Readings** are chosen among the chosen setups' candidates by greedy addition and
//!    DETMAX exchange ([`super::select::select_blocks`], one row per candidate).
//! 5. The setups are **ordered** to keep remounts few (consecutive setups share sockets where
//!    they can), and each setup's poses are ordered as a short path from home.
//!
//! [`check_reading`] re-checks a reading from scratch; the design's figures (gauge travel per
//! setup, smallest clearance, largest cone angle) are measured on the chosen readings.
use cpm_geometry::description::{RobotDescription, SensorSpec};
use cpm_geometry::{JointTable, Pose, Sensor};
use cpm_kinematics::sensor_pose_gradient;
use nalgebra::{DMatrix, Matrix6, RowDVector, Vector6};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::candidates::Workspace;
use super::indices::{observability_indices, Criterion, ObservabilityIndices};
use super::limits::{cone_angles_deg, gauge_clearance_mm, Constraints};
use super::select::{select_blocks, SelectOptions, Selection};
use super::sockets::{pose_blocks, Socket, SocketCandidates};
use crate::{identification_jacobian, CalibError, Campaign, MeasurementModel, Reading};

/// Options of [`design_setups`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SetupOptions {
    /// Most readings. Default 2000.
    pub max_readings: usize,
    /// Most setups (mounts of the gauge). Default 16.
    pub max_setups: usize,
    /// Windows tried per socket pair when the bars are free. Default 6.
    pub windows_per_pair: usize,
    /// Projected poses per candidate setup when screening setups. Default 24.
    pub screening_projections: usize,
    /// Projected poses per chosen setup offered to the reading selection. Default 300.
    pub projections: usize,
    /// Reading selection (criterion, exchange). Default A-optimal with at most 400 exchanges.
    pub select: SelectOptions,
    /// Workspace rules the projected poses must meet (candidates are assumed to meet them).
    /// Default [`Workspace::default`].
    pub workspace: Workspace,
    /// Seed of the projections. Default 1.
    pub seed: u64,
    /// Readings are planned at least this far inside their setup's window, mm (capped at a
    /// quarter of the stroke): the machine's unknown errors move the actual length by up to a
    /// few tenths of a millimetre from the nominal one. Default 1.
    pub edge_margin_mm: f64,
    /// Rounds of minimax reweighting after the reading selection: the parameters are
    /// weighted by their Cramér-Rao variance and the readings exchanged again on the
    /// weighted criterion; the selection with the lowest largest per-parameter bound is kept.
    /// Pulls the worst parameter towards the RMS. Default 4.
    pub minimax_rounds: usize,
    /// Exponent of the minimax reweighting: each round multiplies parameter `k`'s weight by
    /// `(v_k / mean v)^exponent` (weights accumulate over the rounds); larger pulls harder on
    /// the worst parameter. Default 2.
    pub minimax_exponent: f64,
}

impl Default for SetupOptions {
    fn default() -> Self {
        Self {
            max_readings: 2000,
            max_setups: 16,
            windows_per_pair: 6,
            screening_projections: 24,
            projections: 300,
            select: SelectOptions {
                max_exchanges: 400,
                ..SelectOptions::default()
            },
            workspace: Workspace::default(),
            seed: 1,
            edge_margin_mm: 1.0,
            minimax_rounds: 4,
            minimax_exponent: 2.0,
        }
    }
}

/// One setup: a socket pair with one bar, and the poses it drives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// Name (the sensor name in the readings file), e.g. `s01_b3p2`.
    pub name: String,
    /// Base socket ({B}).
    pub base: Socket,
    /// Platform socket ({P}).
    pub platform: Socket,
    /// Extension bar, mm (the window starts at the gauge's shortest length plus this).
    pub bar_mm: f64,
    /// The gauge's window in this setup `(lo, hi)`, mm.
    pub window_mm: (f64, f64),
    /// Poses to drive, in order.
    pub poses: Vec<Pose>,
    /// Socket distance at each pose (nominal), mm.
    pub lengths_mm: Vec<f64>,
    /// Smallest gauge-link distance at each pose, mm.
    pub clearances_mm: Vec<f64>,
}

impl Setup {
    /// The sensor this setup reads (named after the setup).
    pub fn sensor(&self) -> Sensor {
        Sensor {
            name: self.name.clone(),
            base_mm: self.base.position_mm,
            platform_mm: self.platform.position_mm,
        }
    }

    /// Shortest and longest socket distance over the setup's poses, mm.
    pub fn length_range_mm(&self) -> (f64, f64) {
        self.lengths_mm
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), l| {
                (a.min(*l), b.max(*l))
            })
    }

    /// Gauge travel used: longest minus shortest length, mm.
    pub fn travel_mm(&self) -> f64 {
        let (lo, hi) = self.length_range_mm();
        (hi - lo).max(0.0)
    }

    /// Smallest gauge-link clearance over the setup's poses, mm.
    pub fn min_clearance_mm(&self) -> f64 {
        self.clearances_mm
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }
}

/// A design under the limits.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SetupDesign {
    /// The setups, in mounting order.
    pub setups: Vec<Setup>,
    /// The limits honoured.
    pub constraints: Constraints,
    /// Criterion used.
    pub criterion: Criterion,
    /// Candidate poses within the joint limits (of those given).
    pub candidate_poses: usize,
    /// Candidate setups screened (socket pairs x windows with readings).
    pub candidate_setups: usize,
    /// Candidate readings offered to the reading selection.
    pub candidate_readings: usize,
    /// Indices and Cramér-Rao figures at the nominal geometry (noise: the gauge's).
    pub indices: ObservabilityIndices,
    /// What each stage achieved, in words.
    pub log: Vec<String>,
}

impl SetupDesign {
    /// Writes the design into a robot description: one `[[sensor]]` per setup naming the
    /// gauge `gauge_name` and its bar, the gauge as a `[[gauge]]` (replacing one of that
    /// name) and the limits as `[limits]`, so `cpm calibrate` checks readings against each
    /// setup's window and `cpm design` can read the limits back.
    pub fn describe(&self, desc: &mut RobotDescription, gauge_name: &str) {
        let radius = desc.gauge(Some(gauge_name)).and_then(|g| g.radius_mm);
        let spec = self.constraints.gauge.to_spec(gauge_name, radius);
        match desc.gauges.iter_mut().find(|g| g.name == gauge_name) {
            Some(g) => *g = spec,
            None => desc.gauges.push(spec),
        }
        desc.limits = Some(self.constraints.to_limits_spec(desc.limits.as_ref()));
        desc.sensors = self
            .setups
            .iter()
            .map(|s| SensorSpec {
                gauge: Some(gauge_name.to_string()),
                bar_mm: Some(s.bar_mm),
                ..SensorSpec::from_sensor(&s.sensor())
            })
            .collect();
    }

    /// Readings: poses summed over the setups.
    pub fn num_readings(&self) -> usize {
        self.setups.iter().map(|s| s.poses.len()).sum()
    }

    /// One sensor per setup.
    pub fn sensors(&self) -> Vec<Sensor> {
        self.setups.iter().map(Setup::sensor).collect()
    }

    /// `model` with one sensor per setup.
    pub fn model(&self, model: &MeasurementModel) -> MeasurementModel {
        model.with_sensors(self.sensors())
    }

    /// The campaign skeleton (zero lengths, marked simulated): setup after setup, each pose
    /// of a setup a pose of its own, read by that setup's sensor only.
    pub fn campaign(&self) -> Campaign {
        let mut poses = Vec::with_capacity(self.num_readings());
        let mut readings = Vec::with_capacity(self.num_readings());
        for (k, s) in self.setups.iter().enumerate() {
            for p in &s.poses {
                readings.push(Reading {
                    pose: poses.len(),
                    sensor: k,
                    length_mm: 0.0,
                    time_s: crate::Logged::NONE,
                    temperature_c: crate::Logged::NONE,
                });
                poses.push(*p);
            }
        }
        Campaign {
            poses,
            readings,
            simulated: true,
            ..Campaign::default()
        }
    }

    /// Pose labels of [`SetupDesign::campaign`]'s poses: `<setup>.<k>`, k from 1.
    pub fn pose_labels(&self) -> Vec<String> {
        self.setups
            .iter()
            .flat_map(|s| (1..=s.poses.len()).map(move |k| format!("{}.{k}", s.name)))
            .collect()
    }

    /// Largest gauge travel over the setups, mm.
    pub fn max_travel_mm(&self) -> f64 {
        self.setups.iter().map(Setup::travel_mm).fold(0.0, f64::max)
    }

    /// Smallest gauge-link clearance over all readings, mm.
    pub fn min_clearance_mm(&self) -> f64 {
        self.setups
            .iter()
            .map(Setup::min_clearance_mm)
            .fold(f64::INFINITY, f64::min)
    }

    /// Largest base and platform joint cone angles over all readings, deg.
    pub fn max_cone_deg(&self, table: &JointTable) -> (f64, f64) {
        let mut m = (0.0f64, 0.0f64);
        for s in &self.setups {
            for p in &s.poses {
                for (b, q) in cone_angles_deg(table, p) {
                    m = (m.0.max(b), m.1.max(q));
                }
            }
        }
        m
    }

    /// Gauge mounts changed between consecutive setups: (socket moves, bar changes).
    pub fn remounts(&self) -> (usize, usize) {
        let mut r = (0, 0);
        for w in self.setups.windows(2) {
            r.0 += usize::from(w[0].base.name != w[1].base.name)
                + usize::from(w[0].platform.name != w[1].platform.name);
            r.1 += usize::from((w[0].bar_mm - w[1].bar_mm).abs() > 1e-9);
        }
        r
    }

    /// The setups as `[[sensor]]` tables (one per setup) for the robot description.
    pub fn sensors_toml(&self) -> String {
        super::sensors_toml(&self.sensors())
    }

    /// One setup's poses as a pose list (`pose,x_mm,...,yaw_deg`; `cpm simulate --plan`).
    pub fn setup_poses_csv(&self, setup: usize) -> String {
        self.setups
            .get(setup)
            .map_or_else(|| super::poses_csv(&[]), |s| super::poses_csv(&s.poses))
    }

    /// The setup sheet as CSV, one row per reading in driving order:
    /// `step,setup,base_socket,platform_socket,bar_mm,window_lo_mm,window_hi_mm,pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm,clearance_mm`.
    pub fn setup_sheet_csv(&self) -> String {
        let mut s = String::from("step,setup,base_socket,platform_socket,bar_mm,window_lo_mm,window_hi_mm,pose,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,length_mm,clearance_mm\n");
        let mut step = 0;
        for st in &self.setups {
            for (k, p) in st.poses.iter().enumerate() {
                step += 1;
                let [r, pi, y] = p.rpy_deg();
                let t = p.position_mm;
                s.push_str(&format!(
                    "{step},{},{},{},{:.3},{:.3},{:.3},{}.{},{:.6},{:.6},{:.6},{:.9},{:.9},{:.9},{:.3},{:.3}\n",
                    st.name,
                    st.base.name,
                    st.platform.name,
                    st.bar_mm,
                    st.window_mm.0,
                    st.window_mm.1,
                    st.name,
                    k + 1,
                    t.x,
                    t.y,
                    t.z,
                    r,
                    pi,
                    y,
                    st.lengths_mm[k],
                    st.clearances_mm[k]
                ));
            }
        }
        s
    }

    /// The setup sheet in Markdown: per setup, what to mount and the poses to drive.
    pub fn setup_sheet_md(&self, table: &JointTable) -> String {
        let c = &self.constraints;
        let (mb, mp) = self.max_cone_deg(table);
        let (moves, bars) = self.remounts();
        let mut s = String::from("# Setup sheet\n\n");
        s.push_str(&format!(
            "Gauge: {} , stroke {} mm per setup, lengths {} to {} mm; clearance to the links at least {} mm; joint cones at most {} deg (base) and {} deg (platform).\n\n",
            c.gauge.kind.name(), c.gauge.stroke_mm, c.gauge.shortest_mm, c.gauge.longest_mm,
            c.clearance.gauge_link_mm, c.joints.base_cone_deg, c.joints.platform_cone_deg
        ));
        s.push_str(&format!(
            "{} setups, {} readings; largest gauge travel in a setup {:.1} mm; smallest gauge-link clearance {:.1} mm; largest cone angle {:.1} deg (base), {:.1} deg (platform); {} socket moves and {} bar changes between setups.\n\n",
            self.setups.len(), self.num_readings(), self.max_travel_mm(), self.min_clearance_mm(), mb, mp, moves, bars
        ));
        s.push_str("| setup | base socket (mm, {B}) | platform socket (mm, {P}) | bar (mm) | window (mm) | poses | lengths used (mm) | travel (mm) | min clearance (mm) |\n|---|---|---|---|---|---|---|---|---|\n");
        for st in &self.setups {
            let (lo, hi) = st.length_range_mm();
            let (b, p) = (st.base.position_mm, st.platform.position_mm);
            s.push_str(&format!(
                "| {} | {} ({:.1}, {:.1}, {:.1}) | {} ({:.1}, {:.1}, {:.1}) | {:.1} | {:.1} .. {:.1} | {} | {lo:.1} .. {hi:.1} | {:.1} | {:.1} |\n",
                st.name, st.base.name, b.x, b.y, b.z, st.platform.name, p.x, p.y, p.z, st.bar_mm,
                st.window_mm.0, st.window_mm.1, st.poses.len(), st.travel_mm(), st.min_clearance_mm()
            ));
        }
        s.push_str("\n## Steps\n\n");
        for (k, st) in self.setups.iter().enumerate() {
            s.push_str(&format!(
                "{}. Mount the gauge with a {:.1} mm bar between base socket {} and platform socket {} (sensor `{}`), then drive poses {}.1 to {}.{} (setup_sheet.csv lists them in order).\n",
                k + 1, st.bar_mm, st.base.name, st.platform.name, st.name, st.name, st.name, st.poses.len()
            ));
        }
        s
    }
}

/// Checks one reading from scratch: the pose within `workspace` and the joint limits, the
/// gauge axis at least the clearance from every link axis, the length in `window_mm`.
pub fn check_reading(
    table: &JointTable,
    constraints: &Constraints,
    workspace: &Workspace,
    sensor: &Sensor,
    window_mm: (f64, f64),
    pose: &Pose,
) -> Result<(f64, f64), String> {
    workspace
        .check(table, pose)
        .map_err(|r| format!("workspace: {r:?}"))?;
    constraints.check_pose(table, pose)?;
    let l = sensor.length_mm(pose);
    if !(l >= window_mm.0 && l <= window_mm.1) {
        return Err(format!(
            "length {l:.3} mm outside the window {:.3}..{:.3} mm",
            window_mm.0, window_mm.1
        ));
    }
    let c = gauge_clearance_mm(table, sensor, pose);
    if !(c >= constraints.clearance.gauge_link_mm) {
        return Err(format!(
            "gauge-link clearance {c:.3} mm < {} mm",
            constraints.clearance.gauge_link_mm
        ));
    }
    Ok((l, c))
}

/// Pose sensitivities `S` (6 x parameters, um of reading per um of error per unit gradient):
/// a sensor's row at the pose is `g^T S` (see the module doc). `None` where the model fails.
pub fn pose_sensitivities(model: &MeasurementModel, poses: &[Pose]) -> Vec<Option<DMatrix<f64>>> {
    let links: Vec<Sensor> = model
        .nominal
        .links
        .iter()
        .enumerate()
        .map(|(i, l)| Sensor {
            name: format!("link{}", i + 1),
            base_mm: l.base_mm,
            platform_mm: l.platform_mm,
        })
        .collect();
    if links.len() < 6 {
        return vec![None; poses.len()];
    }
    let blocks = pose_blocks(model, poses, &links[..6]);
    poses
        .par_iter()
        .zip(blocks)
        .map(|(p, b)| {
            let b = b?;
            let g = Matrix6::from_fn(|r, c| sensor_pose_gradient(&links[r], p)[c]);
            let lu = g.lu();
            let mut s = DMatrix::zeros(6, b.ncols());
            for c in 0..b.ncols() {
                let col = Vector6::from_fn(|r, _| b[(r, c)]);
                let x = lu.solve(&col)?;
                for r in 0..6 {
                    s[(r, c)] = x[r];
                }
            }
            s.iter().all(|v| v.is_finite()).then_some(s)
        })
        .collect()
}

fn row(sensor: &Sensor, pose: &Pose, s: &DMatrix<f64>) -> RowDVector<f64> {
    let g = sensor_pose_gradient(sensor, pose);
    let mut r = RowDVector::zeros(s.ncols());
    for k in 0..6 {
        r += s.row(k) * g[k];
    }
    r
}

/// A candidate reading.
#[derive(Clone)]
struct Cand {
    pose: Pose,
    length: f64,
    clearance: f64,
    row: RowDVector<f64>,
}

/// Moves `pose` along the gauge axis of `sensor` so that the socket distance becomes `target`.
fn project(sensor: &Sensor, pose: &Pose, target: f64) -> Pose {
    let q = pose.position_mm + pose.rotation * sensor.platform_mm;
    let d = q - sensor.base_mm;
    let l = d.norm();
    Pose::new(pose.position_mm + d * ((target - l) / l), pose.rotation)
}

struct Ctx<'a> {
    model: &'a MeasurementModel,
    constraints: &'a Constraints,
    options: &'a SetupOptions,
}

impl Ctx<'_> {
    /// Projected readings of `sensor` in `window` from the `poses` (checked; rows computed).
    fn projected(
        &self,
        sensor: &Sensor,
        window: (f64, f64),
        poses: &[Pose],
        seed: u64,
    ) -> Vec<Cand> {
        let table = &self.model.nominal;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let (lo, hi) = window;
        let margin = 0.01 * (hi - lo);
        let moved: Vec<Pose> = poses
            .iter()
            .map(|p| project(sensor, p, rng.random_range(lo + margin..=hi - margin)))
            .collect();
        let ok: Vec<Pose> = moved
            .into_par_iter()
            .filter(|p| {
                check_reading(
                    table,
                    self.constraints,
                    &self.options.workspace,
                    sensor,
                    window,
                    p,
                )
                .is_ok()
            })
            .collect();
        let sens = pose_sensitivities(self.model, &ok);
        ok.iter()
            .zip(sens)
            .filter_map(|(p, s)| {
                let s = s?;
                Some(Cand {
                    pose: *p,
                    length: sensor.length_mm(p),
                    clearance: gauge_clearance_mm(table, sensor, p),
                    row: row(sensor, p, &s),
                })
            })
            .collect()
    }
}

fn information(rows: &[&RowDVector<f64>], n: usize) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(n, n);
    for r in rows {
        m += r.transpose() * *r;
    }
    m
}

/// Designs a campaign under `constraints`: chooses setups (socket pair + bar, from the
/// socket candidates `sockets`) and the poses each drives (from `candidates`, admissible poses
/// e.g. from [`super::candidates::default_candidates`], and their projections) to optimise
/// `options.select.criterion` within `options.max_readings` readings and
/// `options.max_setups` setups. See the module doc.
pub fn design_setups(
    model: &MeasurementModel,
    sockets: &SocketCandidates,
    candidates: &[Pose],
    constraints: &Constraints,
    options: &SetupOptions,
    progress: &dyn Fn(&str),
) -> Result<SetupDesign, CalibError> {
    check_setup_options(sockets, constraints, options)?;
    let table = &model.nominal;
    let mut model = model.clone();
    model.effects.clear();
    let model = &model;
    let ctx = Ctx {
        model,
        constraints,
        options,
    };
    let mut log = Vec::new();
    progress("design under limits: candidate poses within the joint limits");
    let (poses, sens) = ctx.poses_within_limits(candidates)?;
    let n = model.num_params();
    let pairs = sockets.all_pairs();
    let np_all = sockets.platform.len();
    log.push(format!(
        "{} of {} candidate poses within the joint limits (cones <= {} / {} deg{}); {} x {} candidate sockets",
        poses.len(),
        candidates.len(),
        constraints.joints.base_cone_deg,
        constraints.joints.platform_cone_deg,
        if table.links.iter().any(|l| l.length_limits_mm.is_some()) { ", link length limits" } else { "" },
        sockets.base.len(),
        np_all
    ));
    progress(&format!(
        "design under limits: lengths and clearances of {} poses x {} socket pairs",
        poses.len(),
        pairs.len()
    ));
    let natural = ctx.natural_readings(&pairs, &poses);
    let cands = Readings {
        poses,
        sens,
        pairs,
        natural,
    };
    // Screening sample of poses for projections.
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed);
    let screen_poses = sample(&mut rng, &cands.poses, options.screening_projections);
    let setups = ctx.screen_setups(&cands, &screen_poses, n, progress)?;
    let criterion = options.select.criterion;
    let scale = setups.iter().map(|s| s.info.trace()).sum::<f64>() / (setups.len() * n) as f64;
    let info = SetupInformation {
        setups: &setups,
        ridge: DMatrix::<f64>::identity(n, n)
            * (options.select.ridge * scale.max(f64::MIN_POSITIVE)),
        criterion,
        n,
    };
    let choice = info.choose(options);
    let chosen = choice.chosen;
    if !choice.minimax.is_empty() {
        log.push(format!(
            "setup minimax rounds (worst parameter bound of the budget shares, per unit noise): {}",
            choice.minimax.join(", ")
        ));
    }
    log.push(format!(
        "{} candidate setups (socket pair x {} mm window); {} chosen: {}-criterion of their budget shares {:.4} greedy, {:.4} after {} swaps",
        setups.len(),
        constraints.gauge.stroke_mm,
        chosen.len(),
        criterion.name(),
        choice.greedy_value,
        choice.value,
        choice.swaps
    ));
    // Reading candidates of the chosen setups.
    progress(&format!(
        "design under limits: candidate readings of {} setups",
        chosen.len()
    ));
    let pool = ctx.reading_pool(&cands, &setups, &chosen, &mut rng);
    let sel = select_readings(&pool, n, constraints, options, progress, &mut log)?;
    let ordered = mounting_order(assemble_setups(
        &pool, &sel, &chosen, &setups, sockets, table,
    ));
    let mut d = SetupDesign {
        setups: ordered,
        constraints: constraints.clone(),
        criterion,
        candidate_poses: cands.poses.len(),
        candidate_setups: setups.len(),
        candidate_readings: pool.len(),
        indices: observability_indices(&DMatrix::zeros(0, n), constraints.gauge.sigma_um),
        log,
    };
    progress("design under limits: indices of the chosen readings");
    let dm = d.model(model);
    let j = identification_jacobian(&dm, &d.campaign(), &vec![0.0; n])?;
    d.indices = observability_indices(&j, constraints.gauge.sigma_um);
    let (moves, bars) = d.remounts();
    d.log.push(format!(
        "{} setups, {} readings: Cramér-Rao RMS {:.3} um, max {:.3} um (noise {:.2} um); largest travel {:.1} mm, smallest clearance {:.1} mm; {moves} socket moves and {bars} bar changes between setups",
        d.setups.len(),
        d.num_readings(),
        d.indices.crlb_rms_um,
        d.indices.crlb_max_um,
        constraints.gauge.sigma_um,
        d.max_travel_mm(),
        d.min_clearance_mm()
    ));
    Ok(d)
}

/// The checks of [`design_setups`]'s inputs.
fn check_setup_options(
    sockets: &SocketCandidates,
    constraints: &Constraints,
    options: &SetupOptions,
) -> Result<(), CalibError> {
    constraints.validate()?;
    if options.max_readings == 0 || options.max_setups == 0 {
        return Err(CalibError::invalid(
            "max_readings",
            "at least one reading and one setup are needed",
        ));
    }
    if sockets.base.is_empty() || sockets.platform.is_empty() {
        return Err(CalibError::invalid(
            "sockets",
            "at least one base and one platform socket candidate are needed",
        ));
    }
    if !(options.edge_margin_mm.is_finite() && options.edge_margin_mm >= 0.0) {
        return Err(CalibError::invalid(
            "edge_margin_mm",
            "must be finite and >= 0",
        ));
    }
    Ok(())
}

/// What the setups and readings of [`design_setups`] are chosen from: the candidate poses
/// within the joint limits with their sensitivities, the socket pairs, and per pair its
/// natural readings (pose index, length, clearance) that clear the links.
struct Readings {
    poses: Vec<Pose>,
    sens: Vec<DMatrix<f64>>,
    pairs: Vec<Sensor>,
    natural: Vec<Vec<(usize, f64, f64)>>,
}

/// A candidate setup: a socket pair, a bar, its window, and the information of its share of
/// the reading budget.
struct CandSetup {
    pair: usize,
    bar: f64,
    window: (f64, f64),
    info: DMatrix<f64>,
}

/// `k` of `poses` drawn at random (a partial shuffle of their indices).
fn sample(rng: &mut rand::rngs::StdRng, poses: &[Pose], k: usize) -> Vec<Pose> {
    let mut idx: Vec<usize> = (0..poses.len()).collect();
    let k = k.min(idx.len());
    for i in 0..k {
        let j = rng.random_range(i..idx.len());
        idx.swap(i, j);
    }
    idx[..k].iter().map(|&i| poses[i]).collect()
}

impl Ctx<'_> {
    /// The window in which readings are admitted: `w` shrunk by the edge margin.
    fn inner(&self, w: (f64, f64)) -> (f64, f64) {
        let edge = self
            .options
            .edge_margin_mm
            .min(0.25 * self.constraints.gauge.stroke_mm);
        (w.0 + edge, w.1 - edge)
    }

    /// The candidates within the joint limits whose sensitivities could be computed, with
    /// them; `Err` when none is.
    fn poses_within_limits(
        &self,
        candidates: &[Pose],
    ) -> Result<(Vec<Pose>, Vec<DMatrix<f64>>), CalibError> {
        let table = &self.model.nominal;
        let within: Vec<Pose> = candidates
            .par_iter()
            .filter(|p| self.constraints.check_pose(table, p).is_ok())
            .copied()
            .collect();
        let sens = pose_sensitivities(self.model, &within);
        let (poses, sens): (Vec<Pose>, Vec<DMatrix<f64>>) = within
            .iter()
            .zip(sens)
            .filter_map(|(p, s)| s.map(|s| (*p, s)))
            .unzip();
        if poses.is_empty() {
            return Err(CalibError::invalid(
                "candidates",
                format!(
                    "none of the {} candidate poses is within the joint limits",
                    candidates.len()
                ),
            ));
        }
        Ok((poses, sens))
    }

    /// Per pair: the natural readings (pose index, length, clearance) that clear the links.
    fn natural_readings(&self, pairs: &[Sensor], poses: &[Pose]) -> Vec<Vec<(usize, f64, f64)>> {
        let table = &self.model.nominal;
        pairs
            .par_iter()
            .map(|s| {
                poses
                    .iter()
                    .enumerate()
                    .filter_map(|(c, p)| {
                        let cl = gauge_clearance_mm(table, s, p);
                        (cl >= self.constraints.clearance.gauge_link_mm)
                            .then(|| (c, s.length_mm(p), cl))
                    })
                    .collect()
            })
            .collect()
    }

    /// The candidate setups (per pair, the gauge's windows over its lengths), each screened
    /// on its natural readings and projections of `screen_poses`: those with any admissible
    /// reading, with the information of their share of the budget (`n` parameters).
    fn screen_setups(
        &self,
        cands: &Readings,
        screen_poses: &[Pose],
        n: usize,
        progress: &dyn Fn(&str),
    ) -> Result<Vec<CandSetup>, CalibError> {
        let (options, constraints) = (self.options, self.constraints);
        let (poses, pairs, natural) = (&cands.poses, &cands.pairs, &cands.natural);
        let share = (options.max_readings as f64 / options.max_setups as f64).max(1.0);
        let mut specs = Vec::new();
        for (r, nat) in natural.iter().enumerate() {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for (_, l, _) in nat {
                lo = lo.min(*l);
                hi = hi.max(*l);
            }
            if !lo.is_finite() {
                // No admissible natural reading: use the lengths over all poses.
                for p in poses {
                    let l = pairs[r].length_mm(p);
                    lo = lo.min(l);
                    hi = hi.max(l);
                }
            }
            for (bar, wlo, whi) in
                constraints
                    .gauge
                    .windows(lo, hi, options.windows_per_pair.max(1))
            {
                specs.push((r, bar, (wlo, whi)));
            }
        }
        progress(&format!(
            "design under limits: screening {} candidate setups",
            specs.len()
        ));
        let setups: Vec<CandSetup> = specs
            .par_iter()
            .enumerate()
            .filter_map(|(k, &(r, bar, window))| {
                let s = &pairs[r];
                let w = self.inner(window);
                let mut rows: Vec<RowDVector<f64>> = natural[r]
                    .iter()
                    .filter(|(_, l, _)| *l >= w.0 && *l <= w.1)
                    .map(|(c, _, _)| row(s, &poses[*c], &cands.sens[*c]))
                    .collect();
                rows.extend(
                    self.projected(s, w, screen_poses, options.seed ^ (k as u64 + 1))
                        .into_iter()
                        .map(|c| c.row),
                );
                if rows.is_empty() {
                    return None;
                }
                let refs: Vec<&RowDVector<f64>> = rows.iter().collect();
                let scale = (share / rows.len() as f64).min(1.0);
                Some(CandSetup {
                    pair: r,
                    bar,
                    window,
                    info: information(&refs, n) * scale,
                })
            })
            .collect();
        if setups.is_empty() {
            return Err(CalibError::NoInformation(
                "no socket pair has an admissible reading under the limits: allow more sockets, a longer stroke or less clearance".into(),
            ));
        }
        Ok(setups)
    }

    /// The candidate readings of the `chosen` setups (with the index of their setup among
    /// the chosen): the natural readings in each window, then projections of poses drawn
    /// from `rng`.
    fn reading_pool(
        &self,
        cands: &Readings,
        setups: &[CandSetup],
        chosen: &[usize],
        rng: &mut rand::rngs::StdRng,
    ) -> Vec<(usize, Cand)> {
        let (options, poses) = (self.options, &cands.poses);
        let mut pool: Vec<(usize, Cand)> = Vec::new();
        for (k, &c) in chosen.iter().enumerate() {
            let cs = &setups[c];
            let s = &cands.pairs[cs.pair];
            let w = self.inner(cs.window);
            for (pi, l, cl) in &cands.natural[cs.pair] {
                if *l >= w.0 && *l <= w.1 {
                    pool.push((
                        k,
                        Cand {
                            pose: poses[*pi],
                            length: *l,
                            clearance: *cl,
                            row: row(s, &poses[*pi], &cands.sens[*pi]),
                        },
                    ));
                }
            }
            let extra = sample(rng, poses, options.projections);
            for cand in self.projected(s, w, &extra, options.seed.wrapping_mul(31) ^ (c as u64 + 7))
            {
                pool.push((k, cand));
            }
        }
        pool
    }
}

/// The setups chosen: their indices among the candidates, the criterion after the greedy
/// choice and after the swaps, and the setup-level minimax rounds (worst bound before ->
/// after).
struct SetupChoice {
    chosen: Vec<usize>,
    greedy_value: f64,
    value: f64,
    swaps: usize,
    minimax: Vec<String>,
}

/// The candidate setups' information and the ridge that regularises its sums (`n`
/// parameters).
struct SetupInformation<'a> {
    setups: &'a [CandSetup],
    ridge: DMatrix<f64>,
    criterion: Criterion,
    n: usize,
}

impl SetupInformation<'_> {
    /// The ridge plus the information of the `chosen` setups.
    fn sum(&self, chosen: &[usize]) -> DMatrix<f64> {
        let mut m = self.ridge.clone();
        for &c in chosen {
            m += &self.setups[c].info;
        }
        m
    }

    /// The criterion of the `chosen` setups.
    fn value(&self, chosen: &[usize]) -> f64 {
        self.criterion.value(&self.sum(chosen))
    }

    /// The parameters' variances under the `chosen` setups.
    fn variances(&self, chosen: &[usize]) -> Option<Vec<f64>> {
        let inv = self.sum(chosen).cholesky()?.inverse();
        Some((0..self.n).map(|k| inv[(k, k)]).collect())
    }

    /// Minus the variances under the `chosen` setups weighted by `w`.
    fn weighted(&self, chosen: &[usize], w: &[f64]) -> f64 {
        self.variances(chosen).map_or(f64::NEG_INFINITY, |v| {
            -v.iter().zip(w).map(|(a, b)| a * b).sum::<f64>()
        })
    }

    /// The best setup not in `taken` by `score` (largest, ties to the lower index).
    fn best(
        &self,
        taken: &[usize],
        score: impl Fn(usize) -> f64 + Sync + Send,
    ) -> Option<(f64, usize)> {
        (0..self.setups.len())
            .into_par_iter()
            .filter(|c| !taken.contains(c))
            .map(|c| (score(c), c))
            .reduce_with(|a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            })
    }

    /// Exchange passes (at most three) on `chosen` from the objective `current`: each place
    /// takes the setup that raises `objective` most when it does by more than the
    /// tolerance. Returns the objective reached and the swaps made.
    fn exchange(
        &self,
        chosen: &mut [usize],
        mut current: f64,
        tolerance: f64,
        objective: &(dyn Fn(&[usize]) -> f64 + Sync),
    ) -> (f64, usize) {
        let mut swaps = 0;
        for _pass in 0..3 {
            let mut improved = false;
            for i in 0..chosen.len() {
                let best = self.best(chosen, |c| {
                    let mut t = chosen.to_vec();
                    t[i] = c;
                    objective(&t)
                });
                if let Some((v, c)) = best {
                    if v > current + tolerance * current.abs() {
                        chosen[i] = c;
                        current = v;
                        swaps += 1;
                        improved = true;
                    }
                }
            }
            if !improved {
                break;
            }
        }
        (current, swaps)
    }

    /// The setups: greedy up to `options.max_setups`, exchanges, then minimax at the setup
    /// level (the parameters weighted by their variance under the chosen setups and chosen
    /// again; kept when the largest variance falls).
    fn choose(&self, options: &SetupOptions) -> SetupChoice {
        let (n, tolerance) = (self.n, options.select.tolerance);
        let k_setups = options.max_setups.min(self.setups.len());
        let mut chosen: Vec<usize> = Vec::with_capacity(k_setups);
        for _ in 0..k_setups {
            let best = self.best(&chosen, |c| {
                let mut t = chosen.clone();
                t.push(c);
                self.value(&t)
            });
            match best {
                Some((_, c)) => chosen.push(c),
                None => break,
            }
        }
        let greedy_value = self.value(&chosen);
        let (mut current, swaps) =
            self.exchange(&mut chosen, greedy_value, tolerance, &|t| self.value(t));
        let mut minimax = Vec::new();
        for _ in 0..options.minimax_rounds {
            let Some(v) = self.variances(&chosen) else {
                break;
            };
            let worst = v.iter().copied().fold(0.0, f64::max);
            let mean = v.iter().sum::<f64>() / n as f64;
            let w: Vec<f64> = v.iter().map(|x| x / mean).collect();
            let mut trial = chosen.clone();
            let cur = self.weighted(&trial, &w);
            self.exchange(&mut trial, cur, tolerance, &|t| self.weighted(t, &w));
            let Some(v2) = self.variances(&trial) else {
                break;
            };
            let worst2 = v2.iter().copied().fold(0.0, f64::max);
            minimax.push(format!("{:.3} -> {:.3}", worst.sqrt(), worst2.sqrt()));
            if worst2 < worst {
                chosen = trial;
                current = self.value(&chosen);
            } else {
                break;
            }
        }
        SetupChoice {
            chosen,
            greedy_value,
            value: current,
            swaps,
            minimax,
        }
    }
}

/// The readings: the criterion-optimal selection of at most `options.max_readings` from
/// `pool` (`n` parameters), then minimax reweighting rounds (each parameter weighted by its
/// variance, exchanged again; the selection of the smallest worst variance kept).
fn select_readings(
    pool: &[(usize, Cand)],
    n: usize,
    constraints: &Constraints,
    options: &SetupOptions,
    progress: &dyn Fn(&str),
    log: &mut Vec<String>,
) -> Result<Selection, CalibError> {
    let criterion = options.select.criterion;
    let n_read = options.max_readings.min(pool.len());
    progress(&format!(
        "design under limits: {}-optimal selection of {n_read} of {} candidate readings",
        criterion.name(),
        pool.len()
    ));
    let blocks: Vec<DMatrix<f64>> = pool
        .iter()
        .map(|(_, c)| DMatrix::from_row_slice(1, n, c.row.as_slice()))
        .collect();
    let mut sel = select_blocks(&blocks, n_read, None, None, &options.select)?;
    log.push(format!(
        "{} of {} candidate readings chosen ({}-criterion {:.4} after greedy, {:.4} after {} exchanges)",
        sel.chosen.len(),
        pool.len(),
        criterion.name(),
        sel.greedy_value,
        sel.value,
        sel.exchanges
    ));
    // Minimax reweighting: weight each parameter by its variance, exchange again.
    let variances = |chosen: &[usize]| -> Option<Vec<f64>> {
        let m = super::select::information(&blocks, chosen);
        let inv = m.cholesky()?.inverse();
        Some((0..n).map(|k| inv[(k, k)]).collect())
    };
    // Weights accumulate over the rounds (w_k <- w_k (v_k / mean)^exponent, normalised):
    // a multiplicative-weights approach to the minimax of the variances; each round starts
    // from the best selection so far and the best is kept.
    let mut weights = vec![1.0; n];
    let mut best_worst =
        variances(&sel.chosen).map_or(f64::INFINITY, |v| v.iter().copied().fold(0.0, f64::max));
    let mut current = sel.clone();
    for round in 0..options.minimax_rounds {
        let Some(v) = variances(&current.chosen) else {
            break;
        };
        let worst = v.iter().copied().fold(0.0, f64::max);
        let mean = v.iter().sum::<f64>() / n as f64;
        for (w, vk) in weights.iter_mut().zip(&v) {
            *w *= (vk / mean).powf(options.minimax_exponent);
        }
        let wmean = weights.iter().sum::<f64>() / n as f64;
        weights.iter_mut().for_each(|w| *w /= wmean);
        // Column k scaled by 1 / sqrt(w_k): the scaled problem's variances are w_k v_k, so
        // its A-optimality is sum_k w_k v_k.
        let d: Vec<f64> = weights.iter().map(|w| 1.0 / w.max(1e-300).sqrt()).collect();
        let scaled: Vec<DMatrix<f64>> = blocks
            .iter()
            .map(|b| DMatrix::from_fn(1, n, |_, c| b[(0, c)] * d[c]))
            .collect();
        let quick = SelectOptions {
            max_exchanges: options.select.max_exchanges.min(40),
            ..options.select
        };
        let next = select_blocks(&scaled, n_read, None, Some(&current.chosen), &quick)?;
        let Some(v2) = variances(&next.chosen) else {
            break;
        };
        let worst2 = v2.iter().copied().fold(0.0, f64::max);
        let sigma = constraints.gauge.sigma_um;
        let kept = worst2 < best_worst;
        log.push(format!(
            "minimax round {}: {} exchanges on the variance-weighted criterion; worst parameter bound {:.3} -> {:.3} um, RMS {:.3} -> {:.3} um{}",
            round + 1,
            next.exchanges,
            sigma * worst.sqrt(),
            sigma * worst2.sqrt(),
            sigma * mean.sqrt(),
            sigma * (v2.iter().sum::<f64>() / n as f64).sqrt(),
            if kept { "" } else { " (not the best so far)" }
        ));
        if kept {
            best_worst = worst2;
            sel = next.clone();
        }
        if next.exchanges == 0 {
            break;
        }
        current = next;
    }
    Ok(sel)
}

/// The chosen setups with their selected readings (those with any), each's poses ordered as
/// a short path from home (nearest neighbour, position mm + 5 mm per deg).
fn assemble_setups(
    pool: &[(usize, Cand)],
    sel: &Selection,
    chosen: &[usize],
    setups: &[CandSetup],
    sockets: &SocketCandidates,
    table: &JointTable,
) -> Vec<Setup> {
    let np_all = sockets.platform.len();
    let mut groups: Vec<Vec<&Cand>> = vec![Vec::new(); chosen.len()];
    for &i in &sel.chosen {
        groups[pool[i].0].push(&pool[i].1);
    }
    let mut built: Vec<Setup> = Vec::new();
    for (k, g) in groups.iter().enumerate() {
        if g.is_empty() {
            continue;
        }
        let cs = &setups[chosen[k]];
        let (bi, pi) = (cs.pair / np_all, cs.pair % np_all);
        // Poses as a short path from home (nearest neighbour, position mm + 5 mm per deg).
        let dist = |a: &Pose, b: &Pose| {
            let d = a.difference(b);
            d.fixed_rows::<3>(0).norm() + 5.0 * d.fixed_rows::<3>(3).norm().to_degrees()
        };
        let mut left: Vec<&Cand> = g.clone();
        let mut order: Vec<&Cand> = Vec::with_capacity(left.len());
        let mut at = table.home;
        while !left.is_empty() {
            let (j, _) = left
                .iter()
                .enumerate()
                .map(|(j, c)| (j, dist(&at, &c.pose)))
                .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
            let c = left.swap_remove(j);
            at = c.pose;
            order.push(c);
        }
        built.push(Setup {
            name: String::new(),
            base: sockets.base[bi].clone(),
            platform: sockets.platform[pi].clone(),
            bar_mm: cs.bar,
            window_mm: cs.window,
            poses: order.iter().map(|c| c.pose).collect(),
            lengths_mm: order.iter().map(|c| c.length).collect(),
            clearances_mm: order.iter().map(|c| c.clearance).collect(),
        });
    }
    built
}

/// Mounting order: start with the setup of most readings, then always the setup that
/// changes least (socket moves count 2, a bar change 1), ties to more readings; each named
/// after its place and sockets.
fn mounting_order(mut built: Vec<Setup>) -> Vec<Setup> {
    let mut ordered: Vec<Setup> = Vec::with_capacity(built.len());
    if !built.is_empty() {
        let first = (0..built.len())
            .max_by_key(|&i| (built[i].poses.len(), usize::MAX - i))
            .unwrap_or(0);
        ordered.push(built.swap_remove(first));
        while !built.is_empty() {
            let Some(last) = ordered.last() else { break };
            let cost = |s: &Setup| {
                2 * (usize::from(s.base.name != last.base.name)
                    + usize::from(s.platform.name != last.platform.name))
                    + usize::from((s.bar_mm - last.bar_mm).abs() > 1e-9)
            };
            let j = (0..built.len())
                .min_by_key(|&i| (cost(&built[i]), usize::MAX - built[i].poses.len()))
                .unwrap_or(0);
            ordered.push(built.swap_remove(j));
        }
    }
    for (k, s) in ordered.iter_mut().enumerate() {
        s.name = format!("s{:02}_{}{}", k + 1, s.base.name, s.platform.name);
    }
    ordered
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::candidates::default_candidates;
    use crate::design::limits::Gauge;
    use nalgebra::Vector3;

    /// Distance from a point to a segment (closed form).
    fn point_segment(x: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
        let d = b - a;
        let t = if d.norm_squared() > 0.0 {
            ((x - a).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (x - (a + d * t)).norm()
    }

    /// Segment distance by ternary search on the first segment's parameter (the distance to
    /// a convex set along a line is convex): independent of `segment_distance_mm`.
    fn segment_distance_ternary(
        p0: &Vector3<f64>,
        p1: &Vector3<f64>,
        q0: &Vector3<f64>,
        q1: &Vector3<f64>,
    ) -> f64 {
        let f = |s: f64| point_segment(&(p0 + (p1 - p0) * s), q0, q1);
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..200 {
            let m1 = lo + (hi - lo) / 3.0;
            let m2 = hi - (hi - lo) / 3.0;
            if f(m1) <= f(m2) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        f(0.5 * (lo + hi)).min(f(0.0)).min(f(1.0))
    }

    /// Independent check of one reading: returns (travel-relevant length, clearance, max
    /// cone) or why it breaks a limit.
    fn independent_check(
        table: &JointTable,
        c: &Constraints,
        setup: &Setup,
        pose: &Pose,
    ) -> Result<(f64, f64, f64), String> {
        let q = |p: &Vector3<f64>| pose.position_mm + pose.rotation * p;
        let len = (q(&setup.platform.position_mm) - setup.base.position_mm).norm();
        let (g0, g1) = (setup.base.position_mm, q(&setup.platform.position_mm));
        let mut clear = f64::INFINITY;
        let mut cone = 0.0f64;
        for l in &table.links {
            let (a, b) = (l.base_mm, q(&l.platform_mm));
            clear = clear.min(segment_distance_ternary(&g0, &g1, &a, &b));
            let h = table.home.position_mm + table.home.rotation * l.platform_mm;
            let (d0, d1) = ((h - a).normalize(), (b - a).normalize());
            let base = d0.dot(&d1).clamp(-1.0, 1.0).acos().to_degrees();
            let plat = (table.home.rotation.transpose() * d0)
                .dot(&(pose.rotation.transpose() * d1))
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            if base > c.joints.base_cone_deg + 1e-6 || plat > c.joints.platform_cone_deg + 1e-6 {
                return Err(format!("cone {base} / {plat}"));
            }
            cone = cone.max(base).max(plat);
            if let Some((lo, hi)) = l.length_limits_mm {
                let ll = (b - a).norm();
                if ll < lo || ll > hi {
                    return Err(format!("link length {ll}"));
                }
            }
        }
        if clear < c.clearance.gauge_link_mm - 1e-6 {
            return Err(format!("clearance {clear}"));
        }
        if len < setup.window_mm.0 - 1e-9 || len > setup.window_mm.1 + 1e-9 {
            return Err(format!("length {len} outside {:?}", setup.window_mm));
        }
        if setup.window_mm.1 - setup.window_mm.0 > c.gauge.stroke_mm + 1e-9 {
            return Err("window wider than the stroke".into());
        }
        Ok((len, clear, cone))
    }

    #[test]
    fn rows_from_pose_sensitivities_match_the_identification_jacobian() {
        let model = MeasurementModel::new(JointTable::paper_cubic());
        let ws = Workspace::default();
        let (poses, _) = default_candidates(&model.nominal, &ws, 20, 80.0, 15.0, 3);
        let sockets = SocketCandidates::paper_cubic();
        let pairs = sockets.all_pairs();
        let sens = pose_sensitivities(&model, &poses[..10]);
        let direct = pose_blocks(&model, &poses[..10], &pairs);
        let mut worst = 0.0f64;
        for ((p, s), d) in poses.iter().zip(sens).zip(direct) {
            let (s, d) = (s.unwrap(), d.unwrap());
            for (r, pair) in pairs.iter().enumerate() {
                let a = row(pair, p, &s);
                let b = d.row(r);
                let rel = (&a - b).norm() / b.norm();
                worst = worst.max(rel);
                // Equal to first order (terms of the model beyond the pose's sensitivity,
                // e.g. the gauge's own socket clearance, are left out).
                assert!(rel <= 1e-2, "pair {r}: relative difference {rel}");
            }
        }
        eprintln!("largest relative difference of a row: {worst:.2e}");
    }

    #[test]
    fn every_chosen_reading_honours_the_limits() {
        let model = MeasurementModel::new(JointTable::paper_cubic());
        let ws = Workspace::default();
        let (cands, _) = default_candidates(&model.nominal, &ws, 400, 100.0, 25.0, 5);
        let constraints = Constraints {
            gauge: Gauge {
                stroke_mm: 60.0,
                ..Gauge::default()
            },
            ..Constraints::default()
        };
        let opts = SetupOptions {
            max_readings: 400,
            max_setups: 10,
            windows_per_pair: 4,
            screening_projections: 8,
            projections: 60,
            ..SetupOptions::default()
        };
        let d = design_setups(
            &model,
            &SocketCandidates::paper_cubic(),
            &cands,
            &constraints,
            &opts,
            &|_| {},
        )
        .unwrap();
        assert!(d.num_readings() <= 400 && d.num_readings() > 300);
        assert!(d.setups.len() <= 10);
        assert_eq!(d.indices.rank, 36, "{:?}", d.log);
        let table = &model.nominal;
        let mut min_clear = f64::INFINITY;
        for s in &d.setups {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in &s.poses {
                let (l, c, _) = independent_check(table, &constraints, s, p)
                    .unwrap_or_else(|e| panic!("{}: {e}", s.name));
                lo = lo.min(l);
                hi = hi.max(l);
                min_clear = min_clear.min(c);
                // Planned at least the edge margin (1 mm) inside the window.
                assert!(l >= s.window_mm.0 + 1.0 - 1e-9 && l <= s.window_mm.1 - 1.0 + 1e-9);
                // And the library's own check agrees.
                check_reading(table, &constraints, &ws, &s.sensor(), s.window_mm, p).unwrap();
            }
            assert!(hi - lo <= constraints.gauge.stroke_mm + 1e-9);
            assert!((s.travel_mm() - (hi - lo)).abs() < 1e-6);
        }
        assert!((d.min_clearance_mm() - min_clear).abs() < 1e-6);
        // The campaign reads each setup's sensor at its own poses only.
        let c = d.campaign();
        assert_eq!(c.readings.len(), d.num_readings());
        assert_eq!(d.pose_labels().len(), c.poses.len());
        assert!(d
            .setup_sheet_csv()
            .starts_with("step,setup,base_socket,platform_socket,bar_mm"));
        assert!(d.setup_sheet_md(table).contains("| setup |"));
    }

    /// The minimax rounds lower the largest per-parameter bound (against the same search
    /// without them), at a small cost in RMS; the design still honours the limits.
    #[test]
    fn minimax_rounds_lower_the_worst_parameter_bound() {
        let model = MeasurementModel::new(JointTable::paper_cubic());
        let (cands, _) =
            default_candidates(&model.nominal, &Workspace::default(), 300, 100.0, 25.0, 9);
        let constraints = Constraints::default();
        let run = |rounds: usize| {
            let opts = SetupOptions {
                max_readings: 400,
                max_setups: 8,
                windows_per_pair: 3,
                screening_projections: 6,
                projections: 60,
                minimax_rounds: rounds,
                ..SetupOptions::default()
            };
            design_setups(
                &model,
                &SocketCandidates::paper_cubic(),
                &cands,
                &constraints,
                &opts,
                &|_| {},
            )
            .unwrap()
        };
        let plain = run(0);
        let minimax = run(4);
        let (a, b) = (&plain.indices, &minimax.indices);
        assert_eq!((a.rank, b.rank), (36, 36));
        assert!(
            b.crlb_max_um < 0.97 * a.crlb_max_um,
            "worst bound {} -> {} um; {:?}",
            a.crlb_max_um,
            b.crlb_max_um,
            minimax.log
        );
        assert!(
            b.crlb_rms_um < 1.1 * a.crlb_rms_um,
            "{} -> {}",
            a.crlb_rms_um,
            b.crlb_rms_um
        );
        assert!(minimax.max_travel_mm() <= constraints.gauge.stroke_mm + 1e-9);
        assert!(minimax.min_clearance_mm() >= constraints.clearance.gauge_link_mm);
        assert!(minimax.log.iter().any(|l| l.starts_with("minimax round 1")));
    }

    #[test]
    fn impossible_limits_are_an_error_not_a_design() {
        let model = MeasurementModel::new(JointTable::paper_cubic());
        let (cands, _) =
            default_candidates(&model.nominal, &Workspace::default(), 50, 50.0, 10.0, 1);
        let c = Constraints {
            clearance: crate::design::limits::Clearance {
                gauge_link_mm: 5000.0,
                link_link_mm: None,
            },
            ..Constraints::default()
        };
        let opts = SetupOptions {
            max_readings: 50,
            screening_projections: 2,
            projections: 4,
            ..SetupOptions::default()
        };
        let e = design_setups(
            &model,
            &SocketCandidates::paper_cubic(),
            &cands,
            &c,
            &opts,
            &|_| {},
        );
        assert!(e.is_err());
    }
}
