//! Criterion benchmarks of cpm-calib: prediction with the analytic Jacobian, and whole
//! identifications (the paper's design and a designed campaign), the nested and implicit
//! formulations side by side, and the identification's fit solved by cpm-lm and by the
//! `levenberg-marquardt` crate on the same problem code (`peer/...`).
use std::cell::RefCell;
use std::hint::black_box;

use cpm_calib::campaign::paper_circle;
use cpm_calib::model::{predict, Prepared};
use cpm_calib::paper::{designed_sensors, random_workspace_poses};
use cpm_calib::*;
use cpm_geometry::{InstallationErrors, JointTable};
use criterion::{criterion_group, criterion_main, Criterion};

fn designed(poses: usize) -> (MeasurementModel, Campaign) {
    let mut model = MeasurementModel::new(JointTable::paper_cubic());
    model.nominal.sensors = designed_sensors();
    let plan = Plan {
        poses: random_workspace_poses(&model.nominal, poses, 100.0, 25.0, 3.0, 1),
        sensors: (0..16).collect(),
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    (model, data)
}

/// The paper's design: the circle of poses read by sensor 0 (36 readings).
fn paper() -> (MeasurementModel, Campaign) {
    let model = MeasurementModel::new(JointTable::paper_cubic());
    let plan = Plan {
        poses: paper_circle(&model.nominal.home),
        sensors: vec![0],
    };
    let truth = InstallationErrors::paper_table2().to_vec_um();
    let data = simulate(&model, &truth, &plan, &SimulationOptions::default()).expect("simulate");
    (model, data)
}

fn prediction(c: &mut Criterion) {
    let (model, data) = designed(125);
    let prepared = Prepared::new(&model, &data).expect("prepare");
    let e = InstallationErrors::paper_table2().to_vec_um();
    let mut j = nalgebra::DMatrix::zeros(data.len(), 36);
    c.bench_function("predict/2000_readings", |b| {
        b.iter(|| predict(&model, &prepared, &data, black_box(&e), None))
    });
    c.bench_function("predict_with_jacobian/2000_readings", |b| {
        b.iter(|| predict(&model, &prepared, &data, black_box(&e), Some(&mut j)))
    });
}

/// The solver's Jacobian of the measurement model ([`cpm_lm::DenseJacobian`] for
/// [`Predictions`](cpm_calib::model::Predictions)): the rows written into the solver's faer
/// storage, at the designed campaign (2000 readings x 36 parameters).
fn solver_jacobian(c: &mut Criterion) {
    use cpm_lm::DenseJacobian;
    let (model, data) = designed(125);
    let mut problem = cpm_calib::model::Predictions::new(&model, &data).expect("prepare");
    let e = InstallationErrors::paper_table2().to_vec_um();
    let mut jac = cpm_lm::faer::Mat::<f64>::zeros(data.len(), model.num_params());
    c.bench_function("solver_jacobian/2000_readings", |b| {
        b.iter(|| {
            problem
                .jacobian(black_box(&e), jac.as_mut())
                .expect("jacobian")
        })
    });
}

fn identification(c: &mut Criterion) {
    let (model, data) = paper();
    let opts = IdentifyOptions::default();
    c.bench_function("identify/paper_design_36_readings", |b| {
        b.iter(|| identify(&model, black_box(&data), &opts))
    });
    let (dmodel, ddata) = designed(125);
    let mut group = c.benchmark_group("identify");
    group.sample_size(10);
    group.bench_function("designed_2000_readings", |b| {
        b.iter(|| identify(&dmodel, black_box(&ddata), &opts))
    });
    group.finish();
}

/// The two formulations side by side on the same designed campaign (125 poses x 16 sensors):
/// nested (forward kinematics in the loop, dense Jacobian) and implicit (poses as unknowns,
/// Schur complement), both returning a `Calibration`.
fn formulations(c: &mut Criterion) {
    let (model, data) = designed(125);
    let opts = IdentifyOptions::default();
    let mut group = c.benchmark_group("formulation/designed_2000_readings");
    group.sample_size(10);
    group.bench_function("nested", |b| {
        b.iter(|| identify(&model, black_box(&data), &opts))
    });
    group.bench_function("implicit", |b| {
        b.iter(|| {
            cpm_calib::implicit::identify_implicit_calibration(&model, black_box(&data), &opts)
        })
    });
    group.finish();
}

/// The least-squares fit of [`identify`] at a parameter vector, for both solvers: the
/// identifiable subspace of the weighted Jacobian at the nominal geometry (the start), the
/// errors `e = V_r theta`, the weighted residuals (predicted - measured) in um and their
/// Jacobian, from cpm-calib's measurement model ([`predict`]). Predictions and the
/// Jacobian are computed together and kept for the point last evaluated (identify's
/// problem does the same): both solvers ask for the Jacobian at the point whose residuals
/// they have just accepted.
struct Fit<'a> {
    model: &'a MeasurementModel,
    prepared: Prepared,
    campaign: &'a Campaign,
    /// `V_r`: parameters x identifiable directions.
    basis: nalgebra::DMatrix<f64>,
    measured_mm: Vec<f64>,
    weights: Vec<f64>,
    /// The point last evaluated, its predictions (mm) and full Jacobian.
    at: RefCell<(Vec<f64>, Vec<f64>, nalgebra::DMatrix<f64>)>,
}

impl<'a> Fit<'a> {
    fn new(model: &'a MeasurementModel, campaign: &'a Campaign) -> Self {
        let np = model.num_params();
        let j0 = identification_jacobian(model, campaign, &vec![0.0; np]).expect("jacobian");
        let patterns = identifiability::physical_patterns(model, campaign);
        let id = identifiability::try_analyze(&j0, 1.0, &RankOptions::default(), &patterns)
            .expect("identifiability");
        Self {
            model,
            prepared: Prepared::new(model, campaign).expect("prepare"),
            campaign,
            basis: id.row_space(),
            measured_mm: campaign.observations(),
            weights: campaign.observation_weights(campaign.pose_sigma()),
            at: RefCell::new((Vec::new(), Vec::new(), nalgebra::DMatrix::zeros(0, 0))),
        }
    }

    fn rank(&self) -> usize {
        self.basis.ncols()
    }

    /// Forgets the point last evaluated (each timed solve starts from the same state).
    fn reset(&self) {
        self.at.borrow_mut().0.clear();
    }

    /// Predictions and full Jacobian at `theta` into the cache (unless there already).
    fn evaluate(&self, theta: &[f64]) {
        let mut at = self.at.borrow_mut();
        if at.0 == theta {
            return;
        }
        let e = &self.basis * nalgebra::DVector::from_column_slice(theta);
        let mut full = nalgebra::DMatrix::zeros(self.campaign.len(), self.model.num_params());
        let y = predict(
            self.model,
            &self.prepared,
            self.campaign,
            e.as_slice(),
            Some(&mut full),
        )
        .expect("predict");
        *at = (theta.to_vec(), y, full);
    }

    /// Weighted residuals at `theta`, um.
    fn residuals(&self, theta: &[f64], r: &mut [f64]) {
        self.evaluate(theta);
        let at = self.at.borrow();
        for (i, ri) in r.iter_mut().enumerate() {
            *ri = (at.1[i] - self.measured_mm[i]) * 1e3 * self.weights[i];
        }
    }

    /// Their Jacobian at `theta`, entry by entry.
    fn jacobian(&self, theta: &[f64], mut set: impl FnMut(usize, usize, f64)) {
        self.evaluate(theta);
        let reduced = &self.at.borrow().2 * &self.basis;
        for c in 0..reduced.ncols() {
            for (i, v) in reduced.column(c).iter().enumerate() {
                set(i, c, v * 1e3 * self.weights[i]);
            }
        }
    }
}

impl cpm_lm::Problem for Fit<'_> {
    fn num_params(&self) -> usize {
        self.rank()
    }
    fn num_residuals(&self) -> usize {
        self.measured_mm.len()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), cpm_lm::ModelError> {
        Fit::residuals(self, x, r);
        Ok(())
    }
}

impl cpm_lm::DenseJacobian for Fit<'_> {
    fn jacobian(
        &mut self,
        x: &[f64],
        mut jac: cpm_lm::faer::MatMut<'_, f64>,
    ) -> Result<(), cpm_lm::ModelError> {
        Fit::jacobian(self, x, |i, c, v| jac[(i, c)] = v);
        Ok(())
    }
}

/// The same fit in the `levenberg-marquardt` crate's interface (dynamic sizes).
struct PeerFit<'f, 'a> {
    fit: &'f Fit<'a>,
    theta: nalgebra::DVector<f64>,
}

impl levenberg_marquardt::LeastSquaresProblem<f64, nalgebra::Dyn, nalgebra::Dyn>
    for PeerFit<'_, '_>
{
    type ResidualStorage = nalgebra::storage::Owned<f64, nalgebra::Dyn>;
    type JacobianStorage = nalgebra::storage::Owned<f64, nalgebra::Dyn, nalgebra::Dyn>;
    type ParameterStorage = nalgebra::storage::Owned<f64, nalgebra::Dyn>;

    fn set_params(&mut self, x: &nalgebra::DVector<f64>) {
        self.theta.copy_from(x);
    }
    fn params(&self) -> nalgebra::DVector<f64> {
        self.theta.clone()
    }
    fn residuals(&self) -> Option<nalgebra::DVector<f64>> {
        let mut r = nalgebra::DVector::zeros(self.fit.measured_mm.len());
        self.fit.residuals(self.theta.as_slice(), r.as_mut_slice());
        Some(r)
    }
    fn jacobian(&self) -> Option<nalgebra::DMatrix<f64>> {
        let mut j = nalgebra::DMatrix::zeros(self.fit.measured_mm.len(), self.fit.rank());
        self.fit
            .jacobian(self.theta.as_slice(), |i, c, v| j[(i, c)] = v);
        Some(j)
    }
}

/// The identification's fit (from the nominal geometry) solved by cpm-lm and by the
/// `levenberg-marquardt` crate (default options each), on the same residual and Jacobian
/// code ([`Fit`]): the paper's 36 readings and the designed campaign's 2000. Both solvers
/// must reach the same cost (relative 1e-6). [`identify`]'s cost is printed beside them, not
/// compared: its fit weighs a prior and sets outliers aside, which this bare fit does not.
fn peers(c: &mut Criterion) {
    use levenberg_marquardt::LevenbergMarquardt;
    let (paper_model, paper_data) = paper();
    let (designed_model, designed_data) = designed(125);
    let opts = IdentifyOptions::default();
    for (label, model, data, samples) in [
        ("paper_36_readings", &paper_model, &paper_data, 50),
        (
            "designed_2000_readings",
            &designed_model,
            &designed_data,
            10,
        ),
    ] {
        // The solves only: the subspace and the prepared campaign are built once.
        let mut fit = Fit::new(model, data);
        let cpm = |fit: &mut Fit| {
            fit.reset();
            let mut theta = vec![0.0; fit.rank()];
            let report =
                cpm_lm::minimize(fit, &mut theta, &cpm_lm::Options::default()).expect("cpm-lm");
            (theta, report)
        };
        let peer = |fit: &Fit| {
            fit.reset();
            let theta = nalgebra::DVector::zeros(fit.rank());
            let (solved, report) = LevenbergMarquardt::new().minimize(PeerFit { fit, theta });
            (solved.theta, report)
        };
        let (_, ours) = cpm(&mut fit);
        let (_, theirs) = peer(&fit);
        let reference = identify(model, data, &opts).expect("identify").solver;
        println!(
            "peer/{label}: cost cpm-lm {:.10e} ({} residual / {} Jacobian evaluations), \
             levenberg-marquardt {:.10e} ({} evaluations), identify {:.10e}",
            ours.final_cost,
            ours.residual_evaluations,
            ours.jacobian_evaluations,
            theirs.objective_function,
            theirs.number_of_evaluations,
            reference.final_cost
        );
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * a.abs().max(b.abs());
        assert!(
            close(ours.final_cost, theirs.objective_function),
            "{label}: cpm-lm {} vs levenberg-marquardt {}",
            ours.final_cost,
            theirs.objective_function
        );
        let mut group = c.benchmark_group(format!("peer/{label}"));
        group.sample_size(samples);
        group.bench_function("cpm-lm", |b| b.iter(|| black_box(cpm(&mut fit))));
        group.bench_function("levenberg-marquardt", |b| b.iter(|| black_box(peer(&fit))));
        group.finish();
    }
}

criterion_group!(
    benches,
    prediction,
    solver_jacobian,
    identification,
    formulations,
    peers
);
criterion_main!(benches);
