//! Implicit-loop calibration: the actual pose of every configuration is an unknown beside the
//! global parameters, so no forward kinematics runs inside the residuals.
//!
//! Unknowns: per configuration `j` a pose correction `(dt_j in um, dw_j in urad)` about the
//! commanded pose (`t = t_cmd + dt`, `R = exp(dw) R_cmd`), and the global parameters
//! (installation errors and declared link- or sensor-channel effects). Residuals, per
//! configuration: the six link closures `l_i(x_j, e) - L_ij - dL_ij(theta)`, weighted by
//! `sigma_sensor / sigma_encoder` (commanded lengths are measurements too), and every sensor
//! reading taken there. Each residual touches one pose block and a few globals, so the
//! Jacobian is block-sparse and `cpm-lm`'s Schur-complement solver eliminates the pose blocks;
//! cost and memory grow linearly with the number of configurations.
//!
//! As the encoder noise goes to zero the closures become hard constraints and the estimate
//! approaches the nested (forward kinematics in the loop) formulation of [`crate::identify()`].
use cpm_geometry::rotation::left_jacobian;
use cpm_geometry::Pose;
use cpm_lm::{LinearSolver, ModelError, Problem, SparseJacobian};
use nalgebra::{DMatrix, Vector3};

use crate::analysis::identifiability::{Identifiability, RankOptions};
use crate::model::effects::{is_link_effect, link_coefficient, sensor_coefficient, Effect};
use crate::model::Prepared;
use crate::{CalibError, Campaign, MeasurementModel};

mod stream;

/// Options of [`identify_implicit`].
#[derive(Debug, Clone)]
pub struct ImplicitOptions {
    /// Standard deviation of the commanded link lengths (encoder noise), um. Default 1.
    pub encoder_sigma_um: f64,
    /// Standard deviation of a sensor reading, um. Default 10/sqrt(3) (the paper's noise).
    pub sensor_sigma_um: f64,
    /// Solver options. Default: cpm-lm's options for a problem that forms its own normal
    /// equations ([`cpm_lm::Options::normal_equations`]: Gauss-Newton steps while they gain
    /// well, then Nielsen's rule; no statistics) with `ftol = xtol = gtol = 1e-10` (large
    /// problems need no more) and the linear solver named "Schur complement (streamed)".
    /// Streamed, an option the streamed system cannot serve (the trust-region or cubic
    /// damping, bounds, a robust loss, geodesic acceleration, statistics, another linear
    /// solver) is an error; with the stored Jacobian the linear solver is set to `cpm-lm`'s
    /// Schur complement.
    pub lm: cpm_lm::Options,
    /// Rank thresholds for the globals.
    pub rank: RankOptions,
    /// Accumulate the reduced (Schur) normal equations pose by pose, with no stored
    /// Jacobian (memory linear in the poses only, parallel over the poses), solved by
    /// `cpm-lm`'s engine as a [`cpm_lm::NormalEquations`] problem. `false` stores the sparse
    /// Jacobian and runs `cpm-lm`'s Schur-complement solver on it. Default `true`.
    pub streamed: bool,
}

impl Default for ImplicitOptions {
    fn default() -> Self {
        Self {
            encoder_sigma_um: 1.0,
            sensor_sigma_um: 10.0 / 3f64.sqrt(),
            lm: cpm_lm::Options {
                ftol: 1e-10,
                xtol: 1e-10,
                gtol: 1e-10,
                linear_solver: LinearSolver::Supplied {
                    name: "Schur complement (streamed)",
                },
                ..cpm_lm::Options::normal_equations()
            },
            rank: RankOptions::default(),
            streamed: true,
        }
    }
}

/// The result of an implicit-loop identification.
#[derive(Debug, Clone)]
pub struct ImplicitCalibration {
    /// All global parameters (installation errors, then effects) at the solution.
    pub globals: Vec<f64>,
    /// Estimates of the determined globals; `None` where not determined.
    pub estimate_um: Vec<Option<f64>>,
    /// Standard deviations (marginal over the poses) of the determined globals.
    pub std_um: Vec<Option<f64>>,
    /// Identifiability of the globals from the reduced (Schur) information.
    pub identifiability: Identifiability,
    /// The estimated actual poses.
    pub poses: Vec<Pose>,
    /// RMS of the sensor residuals, um.
    pub reading_rms_um: f64,
    /// RMS of the closure residuals (unweighted), um.
    pub closure_rms_um: f64,
    /// Residual (predicted - measured) of every reading at the solution, um, in the order of
    /// the campaign's readings.
    pub reading_residuals_um: Vec<f64>,
    /// RMS of the reading residuals at the start (commanded poses, zero errors), um.
    pub initial_reading_rms_um: f64,
    /// The solver's report.
    pub solver: cpm_lm::Report,
}

struct Implicit<'a> {
    model: &'a MeasurementModel,
    campaign: &'a Campaign,
    /// Effective link lengths of every configuration, mm.
    lengths_mm: Vec<[f64; 6]>,
    /// Readings taken at configuration `j`: `reading_idx[reading_ptr[j]..reading_ptr[j + 1]]`
    /// (indices into the campaign's readings; one flat list rather than a vector per
    /// configuration).
    reading_ptr: Vec<usize>,
    reading_idx: Vec<usize>,
    /// First residual row of each configuration.
    row0: Vec<usize>,
    /// Link-channel coefficients (global index, mm per unit) of configuration `j`, link `i`:
    /// `link_coeff[link_ptr[6 j + i]..link_ptr[6 j + i + 1]]` (one flat list: a campaign
    /// of 10^5 configurations would otherwise hold 7 * 10^5 vectors, mostly empty).
    link_coeff: Vec<(usize, f64)>,
    link_ptr: Vec<usize>,
    /// Sensor-channel globals per sensor (they depend on the sensor only): (global index,
    /// effect, index within its block).
    sensor_params: Vec<Vec<(usize, Effect, usize)>>,
    num_poses: usize,
    num_globals: usize,
    rows: usize,
    w_enc: f64,
    sensor_corr: f64,
}

impl Implicit<'_> {
    fn readings_of(&self, j: usize) -> &[usize] {
        &self.reading_idx[self.reading_ptr[j]..self.reading_ptr[j + 1]]
    }

    fn links(&self, j: usize, i: usize) -> &[(usize, f64)] {
        &self.link_coeff[self.link_ptr[6 * j + i]..self.link_ptr[6 * j + i + 1]]
    }

    fn pose(&self, x: &[f64], j: usize) -> (Pose, Vector3<f64>) {
        self.pose_from(&x[6 * j..6 * j + 6], j)
    }

    /// Pose of configuration `j` from its six corrections (um, urad).
    fn pose_from(&self, p: &[f64], j: usize) -> (Pose, Vector3<f64>) {
        let c = &self.campaign.poses[j];
        let dt = Vector3::new(p[0], p[1], p[2]) * 1e-3;
        let dw = Vector3::new(p[3], p[4], p[5]) * 1e-6;
        (
            Pose::new(
                c.position_mm + dt,
                nalgebra::Rotation3::new(dw) * c.rotation,
            ),
            dw,
        )
    }

    /// Residuals of configuration `j` (six closures, then its readings) for pose
    /// corrections `p` and globals `globals` (whose joint table is `table`).
    fn pose_residuals(
        &self,
        p: &[f64],
        globals: &[f64],
        table: &cpm_geometry::JointTable,
        j: usize,
        r: &mut [f64],
    ) {
        let (pose, _) = self.pose_from(p, j);
        let rm = pose.rotation.matrix();
        for (i, l) in table.links.iter().enumerate() {
            let q = pose.position_mm + rm * l.platform_mm - l.base_mm;
            let mut target = self.lengths_mm[j][i];
            for &(p, a) in self.links(j, i) {
                target += a * globals[p];
            }
            r[i] = (q.norm() - target) * 1e3 * self.w_enc;
        }
        for (t, &k) in self.readings_of(j).iter().enumerate() {
            let rd = &self.campaign.readings[k];
            let s = &table.sensors[rd.sensor];
            let geometric = s.length_mm(&pose);
            let mut y = geometric + self.sensor_corr;
            for &(p, e, q) in &self.sensor_params[rd.sensor] {
                y += sensor_coefficient(e, q, rd.sensor, geometric) * globals[p];
            }
            r[6 + t] = (y - rd.length_mm) * 1e3;
        }
    }

    /// Sums of squared closure (unweighted) and reading residuals at `x`, and the reading
    /// residuals in the campaign's order when `readings` is given.
    fn summary(&self, x: &[f64], readings: Option<&mut [f64]>) -> Result<(f64, f64), CalibError> {
        use rayon::prelude::*;
        let g0 = 6 * self.num_poses;
        let table = self.model.table_with(&x[g0..])?;
        let parts: Vec<(f64, f64, Vec<f64>)> = (0..self.num_poses)
            .collect::<Vec<_>>()
            .par_chunks(256)
            .map(|js| {
                let (mut sc, mut sr) = (0.0, 0.0);
                let mut out = Vec::new();
                let mut r = Vec::new();
                for &j in js {
                    r.clear();
                    r.resize(6 + self.readings_of(j).len(), 0.0);
                    self.pose_residuals(&x[6 * j..6 * j + 6], &x[g0..], &table, j, &mut r);
                    sc += r[..6].iter().map(|v| (v / self.w_enc).powi(2)).sum::<f64>();
                    sr += r[6..].iter().map(|v| v * v).sum::<f64>();
                    if readings.is_some() {
                        out.extend_from_slice(&r[6..]);
                    }
                }
                (sc, sr, out)
            })
            .collect();
        let (mut sc, mut sr) = (0.0, 0.0);
        let mut dst = readings;
        for (c, (a, b, out)) in parts.into_iter().enumerate() {
            sc += a;
            sr += b;
            if let Some(dst) = dst.as_deref_mut() {
                let mut t = 0;
                for j in 256 * c..(256 * (c + 1)).min(self.num_poses) {
                    for &k in self.readings_of(j) {
                        dst[k] = out[t];
                        t += 1;
                    }
                }
            }
        }
        Ok((sc, sr))
    }
}

impl Problem for Implicit<'_> {
    fn num_params(&self) -> usize {
        6 * self.num_poses + self.num_globals
    }
    fn num_residuals(&self) -> usize {
        self.rows
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        let g0 = 6 * self.num_poses;
        let globals = &x[g0..];
        let table = self.model.table_with(globals)?;
        for j in 0..self.num_poses {
            let o = self.row0[j];
            let n = 6 + self.readings_of(j).len();
            self.pose_residuals(&x[6 * j..6 * j + 6], globals, &table, j, &mut r[o..o + n]);
        }
        Ok(())
    }
}

impl Implicit<'_> {
    /// Visits the structural non-zeros of configuration `j`'s rows, in value order (row by
    /// row, columns ascending: the pose block, then the globals in block order).
    fn visit_pose_pattern(&self, j: usize, visit: &mut dyn FnMut(usize, usize)) {
        let g0 = 6 * self.num_poses;
        let o = self.row0[j];
        for i in 0..6 {
            for c in 0..6 {
                visit(o + i, 6 * j + c);
            }
            for c in 0..6 {
                visit(o + i, g0 + 6 * i + c);
            }
            for &(q, _) in self.links(j, i) {
                visit(o + i, g0 + q);
            }
        }
        for (t, &k) in self.readings_of(j).iter().enumerate() {
            for c in 0..6 {
                visit(o + 6 + t, 6 * j + c);
            }
            for &(q, _, _) in &self.sensor_params[self.campaign.readings[k].sensor] {
                visit(o + 6 + t, g0 + q);
            }
        }
    }

    /// Jacobian values of configuration `j`'s rows (order of [`Self::visit_pose_pattern`]);
    /// returns how many were written.
    fn pose_values(
        &self,
        x: &[f64],
        table: &cpm_geometry::JointTable,
        j: usize,
        values: &mut [f64],
    ) -> usize {
        let mut v = 0usize;
        let (pose, dw) = self.pose(x, j);
        let jl = left_jacobian(&dw);
        let rm = pose.rotation.matrix();
        let rt = rm.transpose();
        let w = self.w_enc;
        for (i, l) in table.links.iter().enumerate() {
            let s = rm * l.platform_mm;
            let q = pose.position_mm + s - l.base_mm;
            let z = q / q.norm();
            let m = jl.transpose() * s.cross(&z);
            for c in 0..3 {
                values[v + c] = z[c] * w;
                values[v + 3 + c] = m[c] * 1e-3 * w;
            }
            v += 6;
            let zp = rt * z;
            for c in 0..3 {
                values[v + c] = -z[c] * w;
                values[v + 3 + c] = zp[c] * w;
            }
            v += 6;
            for &(_, a) in self.links(j, i) {
                values[v] = -a * 1e3 * w;
                v += 1;
            }
        }
        for &k in self.readings_of(j) {
            let rd = &self.campaign.readings[k];
            let s = &table.sensors[rd.sensor];
            let sp = rm * s.platform_mm;
            let q = pose.position_mm + sp - s.base_mm;
            let geometric = q.norm();
            let u = q / geometric;
            let m = jl.transpose() * sp.cross(&u);
            for c in 0..3 {
                values[v + c] = u[c];
                values[v + 3 + c] = m[c] * 1e-3;
            }
            v += 6;
            for &(_, e, q) in &self.sensor_params[rd.sensor] {
                values[v] = sensor_coefficient(e, q, rd.sensor, geometric) * 1e3;
                v += 1;
            }
        }
        v
    }
}

impl SparseJacobian for Implicit<'_> {
    fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p = Vec::new();
        self.visit_pattern(&mut |r, c| p.push((r, c)));
        p
    }

    /// Streams the pattern in compressed-sparse-row order: the solver stores it as it
    /// arrives, with no list of the entries (at 10^6 readings the list alone was 270 MB).
    fn visit_pattern(&self, visit: &mut dyn FnMut(usize, usize)) {
        for j in 0..self.num_poses {
            self.visit_pose_pattern(j, visit);
        }
    }

    fn jacobian_values(&mut self, x: &[f64], values: &mut [f64]) -> Result<(), ModelError> {
        let table = self.model.table_with(&x[6 * self.num_poses..])?;
        let mut v = 0usize;
        for j in 0..self.num_poses {
            v += self.pose_values(x, &table, j, &mut values[v..]);
        }
        Ok(())
    }
}

/// Whether the implicit formulation can fit this model to this campaign: six links, length
/// readings only (no tracker poses), no socket or tracker-frame effects and no known effect
/// values. The error says what stands in the way.
pub fn supported(model: &MeasurementModel, campaign: &Campaign) -> Result<(), CalibError> {
    if model.nominal.num_links() != 6 {
        return Err(CalibError::invalid(
            "links",
            "the implicit formulation needs six links",
        ));
    }
    if !campaign.pose_measurements.is_empty()
        || !campaign.point_measurements.is_empty()
        || !campaign.tilt_measurements.is_empty()
        || !campaign.instrument_measurements.is_empty()
        || !model.instruments.is_empty()
    {
        return Err(CalibError::invalid(
            "pose_measurements",
            "the implicit formulation takes length readings only; use identify() for tracker data",
        ));
    }
    if let Some(e) = model.effects.iter().find(|e| {
        matches!(
            e,
            Effect::SocketError
                | Effect::TrackerFrame
                | Effect::MarkerFrame
                | Effect::TargetPosition
                | Effect::PointFrame
                | Effect::InclinometerMount
                | Effect::BaseTilt
                | Effect::PoseMap(_)
                | Effect::User(_)
        )
    }) {
        return Err(CalibError::invalid(
            "effects",
            format!("`{e}` is not supported by the implicit formulation"),
        ));
    }
    if let Some(k) = model.known_effects.first() {
        return Err(CalibError::invalid(
            "known_effects",
            format!(
                "the implicit formulation does not apply known effect values (`{}` is known); use identify()",
                k.effect
            ),
        ));
    }
    Ok(())
}

fn build<'a>(
    model: &'a MeasurementModel,
    campaign: &'a Campaign,
    options: &ImplicitOptions,
) -> Result<Implicit<'a>, CalibError> {
    if !(options.encoder_sigma_um > 0.0 && options.encoder_sigma_um.is_finite()) {
        return Err(CalibError::invalid(
            "encoder_sigma_um",
            "must be finite and > 0",
        ));
    }
    if !(options.sensor_sigma_um > 0.0 && options.sensor_sigma_um.is_finite()) {
        return Err(CalibError::invalid(
            "sensor_sigma_um",
            "must be finite and > 0",
        ));
    }
    supported(model, campaign)?;
    let prepared = Prepared::new(model, campaign)?;
    let np = campaign.poses.len();
    let ng = model.num_params();
    let blocks = model.blocks();
    let mut row0 = Vec::with_capacity(np);
    let mut rows = 0usize;
    for j in 0..np {
        row0.push(rows);
        rows += 6 + prepared.by_pose[j].len();
    }
    let mut link_coeff = Vec::new();
    let mut link_ptr = Vec::with_capacity(6 * np + 1);
    link_ptr.push(0);
    for j in 0..np {
        for i in 0..6 {
            for b in blocks
                .iter()
                .filter(|b| b.effect.is_some_and(is_link_effect))
            {
                for k in 0..b.len {
                    let a = link_coefficient(
                        b.effect.expect("effect"),
                        k,
                        i,
                        &prepared.contexts[j],
                        &model.effect_settings,
                        prepared.t0_s,
                    );
                    if a != 0.0 {
                        link_coeff.push((b.offset + k, a));
                    }
                }
            }
            link_ptr.push(link_coeff.len());
        }
    }
    // Only the lengths and the readings per configuration are kept, flat (the prepared
    // campaign's pose contexts served the link coefficients only; at 10^5 poses they hold
    // about 40 MB).
    // (The campaign's own lists are taken out and the rest, the contexts above all,
    // freed before the flat copies are made, each list freed as it is copied.)
    let mut prepared = prepared;
    let by_pose = std::mem::take(&mut prepared.by_pose);
    let lengths = std::mem::take(&mut prepared.lengths_mm);
    drop(prepared);
    let lengths_mm: Vec<[f64; 6]> = lengths
        .into_iter()
        .map(|l| std::array::from_fn(|i| l[i]))
        .collect();
    let mut reading_ptr = Vec::with_capacity(np + 1);
    let mut reading_idx = Vec::with_capacity(campaign.readings.len());
    reading_ptr.push(0);
    for b in by_pose {
        reading_idx.extend_from_slice(&b);
        reading_ptr.push(reading_idx.len());
    }
    let sensor_params: Vec<Vec<(usize, Effect, usize)>> = (0..model.nominal.sensors.len())
        .map(|sensor| {
            blocks
                .iter()
                .filter_map(|b| match b.effect {
                    Some(e @ (Effect::SensorOffset | Effect::SensorScale)) => {
                        Some((b.offset + sensor, e, sensor))
                    }
                    _ => None,
                })
                .collect()
        })
        .collect();
    Ok(Implicit {
        model,
        campaign,
        lengths_mm,
        reading_ptr,
        reading_idx,
        row0,
        link_coeff,
        link_ptr,
        sensor_params,
        num_poses: np,
        num_globals: ng,
        rows,
        w_enc: options.sensor_sigma_um / options.encoder_sigma_um,
        sensor_corr: model.sensor_correction_mm(),
    })
}

/// Checks the implicit formulation's analytic Jacobian against central differences at `x`
/// (pose corrections in um and urad, then the globals).
pub fn check_implicit_jacobian(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &ImplicitOptions,
    x: &[f64],
    step: f64,
) -> Result<cpm_lm::JacobianCheck, CalibError> {
    let mut problem = build(model, campaign, options)?;
    Ok(cpm_lm::check_sparse_jacobian(&mut problem, x, step)?)
}

/// Identifies the global parameters of `model` from a length-sensor campaign with the
/// implicit-loop formulation (Schur complement over the pose blocks).
pub fn identify_implicit(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &ImplicitOptions,
) -> Result<ImplicitCalibration, CalibError> {
    let mut problem = build(model, campaign, options)?;
    let (np, ng) = (problem.num_poses, problem.num_globals);
    let g0 = 6 * np;
    let mut x = vec![0.0; g0 + ng];
    let (_, initial_ss) = problem.summary(&x, None)?;
    let initial_reading_rms_um = (initial_ss / campaign.readings.len().max(1) as f64).sqrt();
    let solver = if options.streamed {
        cpm_lm::minimize_normal(&mut stream::Streamed::new(&problem), &mut x, &options.lm)?
    } else {
        let mut lm = options.lm.clone();
        lm.linear_solver = LinearSolver::Schur {
            local_block_sizes: vec![6; np],
        };
        cpm_lm::minimize_sparse(&mut problem, &mut x, &lm)?
    };
    // Reduced information of the globals: S = sum_j (G_j^T G_j - G_j^T L_j (L_j^T L_j)^-1
    // L_j^T G_j), accumulated pose by pose (no damping; a singular pose block is left out
    // of the elimination).
    let table = model.table_with(&x[g0..])?;
    let mut no_scale = vec![0.0; g0];
    let red = stream::reduce(&problem, &x, &table, 0.0, &mut no_scale, None, true);
    drop(no_scale);
    let s = red.symmetric(ng, |_| 0.0);
    let eig = nalgebra::SymmetricEigen::new(s);
    let mut pseudo = DMatrix::<f64>::zeros(ng, ng);
    for c in 0..ng {
        let l = eig.eigenvalues[c].max(0.0).sqrt();
        for rr in 0..ng {
            pseudo[(c, rr)] = l * eig.eigenvectors[(rr, c)];
        }
    }
    // Gauge readings only: the columns are scaled by unit, the rows not at all.
    let columns = model.rank_groups();
    let scaling = crate::RankScaling {
        column_groups: Some(&columns),
        row_groups: None,
    };
    let mut ident = crate::analyze_scaled(
        &pseudo,
        options.sensor_sigma_um,
        &options.rank,
        &crate::analysis::identifiability::physical_patterns(model, campaign),
        &scaling,
    );
    ident.num_readings = campaign.readings.len();
    let globals = x[g0..].to_vec();
    let estimate_um = (0..ng)
        .map(|k| ident.determined[k].then_some(globals[k]))
        .collect();
    let poses = (0..np).map(|j| problem.pose(&x, j).0).collect();
    let mut reading_residuals_um = vec![0.0; campaign.readings.len()];
    let (sc, sr) = problem.summary(&x, Some(&mut reading_residuals_um))?;
    let nr = campaign.readings.len();
    Ok(ImplicitCalibration {
        std_um: ident.crlb_std_um.clone(),
        estimate_um,
        identifiability: ident,
        globals,
        poses,
        reading_rms_um: (sr / nr.max(1) as f64).sqrt(),
        closure_rms_um: (sc / (6 * np).max(1) as f64).sqrt(),
        reading_residuals_um,
        initial_reading_rms_um,
        solver,
    })
}

/// Identifies `model` from `campaign` with the implicit formulation and returns the result
/// in the form of the nested formulation's [`identify()`](crate::identify()), so that either
/// can feed the same reports.
///
/// The commanded lengths are treated as exact, as the nested formulation does (encoder
/// standard deviation `1e-4` of the reading one), so both give the same estimates to a small
/// fraction of a standard deviation. The noise is `options.sigma_um` when declared, otherwise
/// estimated from the reading residuals (`m - rank` degrees of freedom); the standard
/// deviations are the Cramér-Rao bounds of the reduced (Schur) information at that noise.
/// `minimum_norm_um` is the estimate projected on the identified directions (the start is
/// zero). Length readings only, plain least squares, no start (see [`supported`]).
pub fn identify_implicit_calibration(
    model: &MeasurementModel,
    campaign: &Campaign,
    options: &crate::IdentifyOptions,
) -> Result<crate::Calibration, CalibError> {
    supported(model, campaign)?;
    if !options.lm.loss.is_squared() {
        return Err(CalibError::invalid(
            "loss",
            "the implicit formulation fits plain least squares; use identify() for a robust loss",
        ));
    }
    if options.start_um.is_some() {
        return Err(CalibError::invalid(
            "start_um",
            "the implicit formulation starts from zero errors; use identify() for a start",
        ));
    }
    let reference = options.sigma_um.unwrap_or(1.0);
    let mut lm = ImplicitOptions::default().lm;
    lm.max_iterations = options.lm.max_iterations;
    lm.max_evaluations = options.lm.max_evaluations;
    let imp = identify_implicit(
        model,
        campaign,
        &ImplicitOptions {
            encoder_sigma_um: 1e-4 * reference,
            sensor_sigma_um: reference,
            lm,
            rank: options.rank,
            streamed: true,
        },
    )?;
    let m = imp.reading_residuals_um.len();
    let rank = imp.identifiability.rank;
    let (sigma_um, sigma_estimated) = match options.sigma_um {
        Some(s) => (s, false),
        None => {
            let ssr: f64 = imp.reading_residuals_um.iter().map(|r| r * r).sum();
            ((ssr / m.saturating_sub(rank).max(1) as f64).sqrt(), true)
        }
    };
    // The reduced information depends on the ratio of the two noises only (fixed above), so
    // the bounds at the estimated noise are those at the reference one rescaled.
    let mut ident = imp.identifiability.clone();
    let scale = sigma_um / reference;
    for s in ident.crlb_std_um.iter_mut().flatten() {
        *s *= scale;
    }
    for s in ident.combination_std_um.iter_mut() {
        *s *= scale;
    }
    ident.sigma_um = sigma_um;
    let e_hat = &imp.globals;
    let np = e_hat.len();
    let estimate_um = (0..np)
        .map(|k| ident.determined[k].then_some(e_hat[k]))
        .collect();
    let mut minimum_norm_um = vec![0.0; np];
    let combinations = (0..ident.rank)
        .map(|c| {
            let v = ident.v.column(c);
            let proj: f64 = v.iter().zip(e_hat).map(|(a, b)| a * b).sum();
            for (mn, a) in minimum_norm_um.iter_mut().zip(v.iter()) {
                *mn += a * proj;
            }
            let mut load: Vec<(usize, f64)> = v.iter().copied().enumerate().collect();
            load.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            load.truncate(4);
            crate::fit::identify::Combination {
                singular_value: ident.singular_values[c],
                estimate_um: proj,
                std_um: ident.combination_std_um[c],
                loadings: load,
            }
        })
        .collect();
    let outliers = crate::analysis::diagnostics::outliers(&imp.reading_residuals_um);
    Ok(crate::Calibration {
        simulated: campaign.simulated,
        estimate_um,
        std_um: ident.crlb_std_um.clone(),
        minimum_norm_um,
        combinations,
        identifiability: ident,
        sigma_um,
        sigma_estimated,
        sigma_excludes_outliers: false,
        // The implicit formulation is least squares only (no robust loss).
        downweighted_share: 0.0,
        robust_failed: false,
        outliers,
        set_aside: Vec::new(),
        initial_rms_um: imp.initial_reading_rms_um,
        residual_rms_um: imp.reading_rms_um,
        residuals_um: imp.reading_residuals_um,
        solver: imp.solver,
        // Readings only, weighted by 1: their own noise.
        sigma_ref_um: sigma_um,
        leverages: Vec::new(),
        // The implicit formulation fits length readings at scale, least squares without a
        // prior (its campaigns determine every parameter they fit far below any tolerance).
        prior: None,
        prior_std: vec![f64::INFINITY; np],
        held_at_limit: Vec::new(),
        tolerance_limit: f64::INFINITY,
        leg_space: false,
        // Not formed at scale: a compensation from it promises no band.
        covariance: nalgebra::DMatrix::zeros(0, 0),
    })
}
