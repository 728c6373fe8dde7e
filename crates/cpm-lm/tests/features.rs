//! Behaviour tests: options validation, model errors, user stop, rank deficiency, robust
//! losses, other damping schedules, bounds, sparse/dense interplay, report contents.

use std::ops::ControlFlow;

use cpm_lm::stats::Statistics;
use cpm_lm::{
    check_jacobian, check_sparse_jacobian, minimize, minimize_sparse, Damping, DenseJacobian,
    EvalStage, LinearSolver, LmError, Loss, ModelError, Options, Problem, Scaling, Solver,
    SparseJacobian, TerminationReason,
};
use faer::MatMut;

/// y = a exp(-b t) + c on 30 points, optionally with outliers and failure injection.
#[derive(Clone)]
struct Decay {
    t: Vec<f64>,
    y: Vec<f64>,
    /// Fail the residual evaluation number `k` (1-based) when set.
    fail_residual_at: Option<usize>,
    fail_jacobian_at: Option<usize>,
    residual_calls: usize,
    jacobian_calls: usize,
}

impl Decay {
    fn new(outliers: &[(usize, f64)]) -> Self {
        let t: Vec<f64> = (0..30).map(|i| i as f64 * 0.2).collect();
        let mut y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, t)| 2.5 * (-1.3 * t).exp() + 0.5 + 1e-3 * (((i * 37) % 11) as f64 - 5.0))
            .collect();
        for &(i, d) in outliers {
            y[i] += d;
        }
        Self {
            t,
            y,
            fail_residual_at: None,
            fail_jacobian_at: None,
            residual_calls: 0,
            jacobian_calls: 0,
        }
    }
}

impl Problem for Decay {
    fn num_params(&self) -> usize {
        3
    }
    fn num_residuals(&self) -> usize {
        self.t.len()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.residual_calls += 1;
        if self.fail_residual_at == Some(self.residual_calls) {
            return Err(format!("sensor offline at call {}", self.residual_calls).into());
        }
        for i in 0..self.t.len() {
            r[i] = x[0] * (-x[1] * self.t[i]).exp() + x[2] - self.y[i];
        }
        Ok(())
    }
}

impl DenseJacobian for Decay {
    fn jacobian(&mut self, x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
        self.jacobian_calls += 1;
        if self.fail_jacobian_at == Some(self.jacobian_calls) {
            return Err("Jacobian unavailable".into());
        }
        for i in 0..self.t.len() {
            let e = (-x[1] * self.t[i]).exp();
            j[(i, 0)] = e;
            j[(i, 1)] = -x[0] * self.t[i] * e;
            j[(i, 2)] = 1.0;
        }
        Ok(())
    }
}

impl SparseJacobian for Decay {
    fn pattern(&self) -> Vec<(usize, usize)> {
        (0..self.t.len())
            .flat_map(|i| [(i, 0), (i, 1), (i, 2)])
            .collect()
    }
    fn jacobian_values(&mut self, x: &[f64], v: &mut [f64]) -> Result<(), ModelError> {
        for i in 0..self.t.len() {
            let e = (-x[1] * self.t[i]).exp();
            v[3 * i] = e;
            v[3 * i + 1] = -x[0] * self.t[i] * e;
            v[3 * i + 2] = 1.0;
        }
        Ok(())
    }
}

/// Rosenbrock as a least-squares problem.
struct Rosenbrock;
impl Problem for Rosenbrock {
    fn num_params(&self) -> usize {
        2
    }
    fn num_residuals(&self) -> usize {
        2
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        r[0] = 10.0 * (x[1] - x[0] * x[0]);
        r[1] = 1.0 - x[0];
        Ok(())
    }
}
impl DenseJacobian for Rosenbrock {
    fn jacobian(&mut self, x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
        j[(0, 0)] = -20.0 * x[0];
        j[(0, 1)] = 10.0;
        j[(1, 0)] = -1.0;
        j[(1, 1)] = 0.0;
        Ok(())
    }
}

#[test]
fn jacobians_of_the_test_problems_are_exact() {
    let mut d = Decay::new(&[]);
    assert!(check_jacobian(&mut d, &[2.0, 1.0, 0.3], 1e-6)
        .unwrap()
        .is_consistent(1e-7));
    assert!(check_sparse_jacobian(&mut d, &[2.0, 1.0, 0.3], 1e-6)
        .unwrap()
        .is_consistent(1e-7));
    assert!(check_jacobian(&mut Rosenbrock, &[-1.2, 1.0], 1e-6)
        .unwrap()
        .is_consistent(1e-7));
    assert!(check_jacobian(&mut Collinear, &[0.3, 0.2, 0.1], 1e-6)
        .unwrap()
        .is_consistent(1e-7));
}

#[test]
fn jacobian_checker_finds_a_wrong_entry() {
    struct Wrong;
    impl Problem for Wrong {
        fn num_params(&self) -> usize {
            2
        }
        fn num_residuals(&self) -> usize {
            2
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
            r[0] = x[0] * x[1];
            r[1] = x[1].sin();
            Ok(())
        }
    }
    impl DenseJacobian for Wrong {
        fn jacobian(&mut self, x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
            j[(0, 0)] = x[1];
            j[(0, 1)] = x[0];
            j[(1, 0)] = 0.0;
            j[(1, 1)] = -x[1].cos(); // wrong sign
            Ok(())
        }
    }
    let c = check_jacobian(&mut Wrong, &[1.0, 0.5], 1e-6).unwrap();
    assert!(!c.is_consistent(1e-3));
    assert_eq!(c.max_rel_entry, (1, 1));
    assert_eq!(c.max_abs_entry, (1, 1));
    assert!((c.max_abs_error - 2.0 * 0.5f64.cos()).abs() < 1e-6);
    assert!(c.to_string().contains("at (1, 1)"));
}

#[test]
fn options_validation_explains_the_problem() {
    let cases: Vec<(Options, &str)> = vec![
        (
            Options {
                ftol: f64::NAN,
                ..Options::default()
            },
            "ftol must be finite and >= 0, got NaN",
        ),
        (
            Options {
                gtol: -1e-3,
                ..Options::default()
            },
            "gtol must be finite and >= 0, got -0.001",
        ),
        (
            Options {
                max_iterations: 0,
                ..Options::default()
            },
            "max_iterations must be >= 1",
        ),
        (
            Options {
                max_evaluations: 1,
                ..Options::default()
            },
            "max_evaluations must be >= 2",
        ),
        (
            Options {
                tau: 0.0,
                ..Options::default()
            },
            "tau (initial damping factor) must be finite and > 0",
        ),
        (
            Options {
                loss: Loss::Huber(-1.0),
                ..Options::default()
            },
            "Huber loss scale must be finite and > 0, got -1",
        ),
        (
            Options {
                rank_tol: Some(-1.0),
                ..Options::default()
            },
            "rank_tol must be finite and >= 0",
        ),
        (
            Options {
                lower: Some(vec![0.0, 5.0]),
                upper: Some(vec![1.0, 4.0]),
                ..Options::default()
            },
            "lower[1] = 5 exceeds upper[1] = 4",
        ),
        (
            Options {
                lower: Some(vec![f64::NAN]),
                ..Options::default()
            },
            "lower[0] = NaN is not a usable lower bound",
        ),
        (
            Options {
                linear_solver: LinearSolver::Schur {
                    local_block_sizes: vec![2, 0],
                },
                ..Options::default()
            },
            "Schur local_block_sizes[1] is 0",
        ),
    ];
    for (o, want) in cases {
        let e = o.validate().unwrap_err();
        assert!(matches!(e, LmError::InvalidOptions(_)));
        assert!(
            e.to_string().contains(want),
            "{e} does not contain {want:?}"
        );
        // The same error comes back from a solve, before any evaluation.
        let mut p = Decay::new(&[]);
        let e2 = minimize(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap_err();
        assert_eq!(e2.to_string(), e.to_string());
        assert_eq!(p.residual_calls, 0);
    }
}

#[test]
fn size_errors_are_reported_before_evaluation() {
    let mut p = Decay::new(&[]);
    let e = minimize(&mut p, &mut [1.0, 1.0], &Options::default()).unwrap_err();
    assert!(
        matches!(
            e,
            LmError::DimensionMismatch {
                what: "x",
                expected: 3,
                found: 2
            }
        ),
        "{e}"
    );
    let o = Options {
        lower: Some(vec![0.0; 2]),
        ..Options::default()
    };
    let e = minimize(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap_err();
    assert!(
        e.to_string()
            .contains("options.lower has length 2, expected 3"),
        "{e}"
    );
    let o = Options {
        linear_solver: LinearSolver::Schur {
            local_block_sizes: vec![2, 2],
        },
        ..Options::default()
    };
    let e = minimize(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap_err();
    assert!(
        e.to_string()
            .contains("cover 4 parameters but the problem has only 3"),
        "{e}"
    );
    let e = minimize(&mut p, &mut [1.0, f64::INFINITY, 0.0], &Options::default()).unwrap_err();
    assert!(matches!(e, LmError::NonFiniteStart { index: 1, .. }), "{e}");
    assert_eq!(p.residual_calls, 0);
}

#[test]
fn model_error_stops_the_solve_with_that_error() {
    let mut p = Decay::new(&[]);
    p.fail_residual_at = Some(4);
    let e = minimize(&mut p, &mut [1.0, 1.0, 0.0], &Options::default()).unwrap_err();
    match &e {
        LmError::Model {
            iteration,
            stage,
            source,
        } => {
            assert_eq!(*iteration, 3);
            assert_eq!(*stage, EvalStage::Residuals);
            assert_eq!(source.to_string(), "sensor offline at call 4");
        }
        other => panic!("unexpected {other}"),
    }
    assert!(e
        .to_string()
        .contains("model error at iteration 3 while evaluating the residuals"));
    assert!(std::error::Error::source(&e).is_some());
    assert_eq!(p.residual_calls, 4, "no evaluation after the error");

    let mut p = Decay::new(&[]);
    p.fail_jacobian_at = Some(1);
    let e = minimize(&mut p, &mut [1.0, 1.0, 0.0], &Options::default()).unwrap_err();
    assert!(
        matches!(
            e,
            LmError::Model {
                iteration: 0,
                stage: EvalStage::Jacobian,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn callback_sees_every_iteration_and_can_stop() {
    let mut seen = Vec::new();
    let mut p = Decay::new(&[]);
    let report = {
        let mut solver = Solver::new(Options::default()).with_callback(|rec| {
            seen.push(rec.iteration);
            if rec.accepted && rec.iteration >= 2 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        });
        solver.minimize(&mut p, &mut [1.0, 1.0, 0.0]).unwrap()
    };
    assert_eq!(report.termination, TerminationReason::UserStop);
    assert!(!report.was_successful());
    assert_eq!(seen, (1..=report.iterations.len()).collect::<Vec<_>>());
    // Without the stop the same problem converges.
    let mut x = [1.0, 1.0, 0.0];
    let full = Solver::new(Options::default())
        .minimize(&mut p, &mut x)
        .unwrap();
    assert!(full.was_successful());
    assert!(full.iterations.len() > report.iterations.len());
}

/// y = (a + b) t + c: only a + b is identifiable.
struct Collinear;
impl Problem for Collinear {
    fn num_params(&self) -> usize {
        3
    }
    fn num_residuals(&self) -> usize {
        6
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        for i in 0..6 {
            let t = i as f64;
            r[i] = (x[0] + x[1]) * t + x[2] - (1.5 * t + 0.2 + 0.01 * ((i % 3) as f64 - 1.0));
        }
        Ok(())
    }
}
impl DenseJacobian for Collinear {
    fn jacobian(&mut self, _x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
        for i in 0..6 {
            j[(i, 0)] = i as f64;
            j[(i, 1)] = i as f64;
            j[(i, 2)] = 1.0;
        }
        Ok(())
    }
}

#[test]
fn rank_deficient_problem_reports_unidentifiable_parameters() {
    let mut x = [0.0, 0.0, 0.0];
    let report = minimize(&mut Collinear, &mut x, &Options::default()).unwrap();
    assert!(report.was_successful(), "{report:#}");
    assert!((x[0] + x[1] - 1.5).abs() < 1e-2);
    let st = report.statistics().unwrap();
    assert_eq!(st.rank, 2);
    assert!(st.is_rank_deficient());
    assert_eq!(st.null_space.ncols(), 1);
    // The null direction is (1, -1, 0) / sqrt(2).
    assert!((st.null_space[(0, 0)].abs() - 0.5f64.sqrt()).abs() < 1e-12);
    assert!(st.null_space[(2, 0)].abs() < 1e-12);
    assert_eq!(st.std_dev[0], None);
    assert_eq!(st.std_dev[1], None);
    assert!(st.std_dev[2].unwrap() > 0.0);
    assert_eq!(st.unidentifiable(), vec![0, 1]);
    assert!(st.correlation[(0, 2)].is_nan());
    assert_eq!(st.dof, 4);
    assert!(report.full().contains("unidentifiable parameters [0, 1]"));
    // Configurable rank threshold: a huge tolerance makes everything unidentifiable.
    let st = Statistics::from_jacobian(
        faer::Mat::<f64>::from_fn(6, 3, |i, j| if j < 2 { i as f64 } else { 1.0 }).as_ref(),
        &[0.0; 6],
        Some(1e6),
    );
    assert_eq!(st.rank, 0);
    assert!(st.std_dev.iter().all(Option::is_none));
}

#[test]
fn robust_losses_reduce_the_pull_of_outliers() {
    let outliers = [(3, 1.5), (17, -2.0), (25, 1.0)];
    let truth = [2.5, 1.3, 0.5];
    let err = |x: &[f64]| -> f64 { (0..3).map(|k| (x[k] - truth[k]).abs()).fold(0.0, f64::max) };
    let mut p = Decay::new(&outliers);
    let mut plain = [1.0, 1.0, 0.0];
    minimize(&mut p, &mut plain, &Options::default()).unwrap();
    for loss in [Loss::Huber(0.01), Loss::Cauchy(0.01), Loss::Tukey(0.05)] {
        let mut x = [1.0, 1.0, 0.0];
        // Tukey ignores large residuals entirely: start it from the least-squares fit.
        if matches!(loss, Loss::Tukey(_)) {
            x = plain;
        }
        let report = minimize(
            &mut p,
            &mut x,
            &Options {
                loss,
                ..Options::default()
            },
        )
        .unwrap();
        assert!(report.was_successful(), "{loss:?}: {report:#}");
        assert!(
            err(&x) < 0.1 * err(&plain),
            "{loss:?}: robust error {} vs plain {}",
            err(&x),
            err(&plain)
        );
        assert!(err(&x) < 0.02, "{loss:?}: {x:?}");
    }
}

#[test]
fn all_dampings_and_scalings_solve_rosenbrock() {
    for damping in [
        Damping::Nielsen,
        Damping::Marquardt,
        Damping::CubicInterpolation,
    ] {
        for scaling in [Scaling::Marquardt, Scaling::Identity] {
            for start in [[-1.2, 1.0], [-12.0, 10.0]] {
                let mut x = start;
                let o = Options {
                    damping,
                    scaling,
                    ..Options::default()
                };
                let report = minimize(&mut Rosenbrock, &mut x, &o).unwrap();
                assert!(
                    report.was_successful(),
                    "{damping:?}/{scaling:?}: {report:#}"
                );
                assert!(
                    (x[0] - 1.0).abs() < 1e-8 && (x[1] - 1.0).abs() < 1e-8,
                    "{damping:?}/{scaling:?} from {start:?}: {x:?}"
                );
                assert!(report.final_cost < 1e-20);
            }
        }
    }
}

#[test]
fn all_linear_solvers_agree_on_a_dense_problem() {
    let mut reference = [1.0, 1.0, 0.0];
    let mut p = Decay::new(&[]);
    minimize(&mut p, &mut reference, &Options::default()).unwrap();
    for solver in [
        LinearSolver::DenseCholesky,
        LinearSolver::SparseCholesky,
        LinearSolver::Schur {
            local_block_sizes: vec![2],
        },
        LinearSolver::Schur {
            local_block_sizes: vec![],
        },
    ] {
        let o = Options {
            linear_solver: solver.clone(),
            ..Options::default()
        };
        for sparse in [false, true] {
            let mut x = [1.0, 1.0, 0.0];
            let report = if sparse {
                minimize_sparse(&mut p, &mut x, &o).unwrap()
            } else {
                minimize(&mut p, &mut x, &o).unwrap()
            };
            assert!(report.was_successful(), "{solver:?}: {report:#}");
            for k in 0..3 {
                assert!(
                    (x[k] - reference[k]).abs() < 1e-8,
                    "{solver:?} sparse={sparse}: {x:?} vs {reference:?}"
                );
            }
        }
    }
    // Sparse problem through the dense QR.
    let mut x = [1.0, 1.0, 0.0];
    minimize_sparse(&mut p, &mut x, &Options::default()).unwrap();
    assert!((x[1] - reference[1]).abs() < 1e-10);
}

#[test]
fn schur_rejects_rows_spanning_two_blocks() {
    let mut p = Decay::new(&[]);
    let o = Options {
        linear_solver: LinearSolver::Schur {
            local_block_sizes: vec![1, 1],
        },
        ..Options::default()
    };
    let e = minimize_sparse(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap_err();
    assert!(
        matches!(
            e,
            LmError::SchurStructure {
                row: 0,
                first_block: 0,
                second_block: 1
            }
        ),
        "{e}"
    );
}

#[test]
fn sparse_pattern_out_of_bounds_is_an_error() {
    struct BadPattern;
    impl Problem for BadPattern {
        fn num_params(&self) -> usize {
            1
        }
        fn num_residuals(&self) -> usize {
            1
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
            r[0] = x[0];
            Ok(())
        }
    }
    impl SparseJacobian for BadPattern {
        fn pattern(&self) -> Vec<(usize, usize)> {
            vec![(0, 0), (0, 1)]
        }
        fn jacobian_values(&mut self, _x: &[f64], v: &mut [f64]) -> Result<(), ModelError> {
            v.fill(1.0);
            Ok(())
        }
    }
    let e = minimize_sparse(&mut BadPattern, &mut [1.0], &Options::default()).unwrap_err();
    assert!(
        e.to_string()
            .contains("entry #1 = (0, 1) lies outside the 1 x 1 Jacobian"),
        "{e}"
    );
}

#[test]
fn bounds_hold_and_active_bounds_are_respected() {
    let mut p = Decay::new(&[]);
    // The unconstrained optimum has b = 1.3; cap it at 1.0 and keep c >= 0.6.
    let o = Options {
        lower: Some(vec![f64::NEG_INFINITY, 0.0, 0.6]),
        upper: Some(vec![f64::INFINITY, 1.0, 10.0]),
        ..Options::default()
    };
    let mut x = [5.0, 3.0, -1.0]; // outside the box: projected first
    let report = minimize(&mut p, &mut x, &o).unwrap();
    assert!(report.was_successful(), "{report:#}");
    assert_eq!(x[1], 1.0);
    assert_eq!(x[2], 0.6);
    assert!(x[0] > 0.0);
}

#[test]
fn limits_and_non_finite_values_end_the_solve_cleanly() {
    let mut p = Decay::new(&[]);
    let o = Options {
        max_iterations: 2,
        ..Options::default()
    };
    let r = minimize(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap();
    assert_eq!(r.termination, TerminationReason::MaxIterations);
    assert_eq!(r.iterations.len(), 2);
    let o = Options {
        max_evaluations: 3,
        ..Options::default()
    };
    let r = minimize(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap();
    assert_eq!(r.termination, TerminationReason::MaxEvaluations);
    assert_eq!(r.residual_evaluations, 3);

    struct NanAt;
    impl Problem for NanAt {
        fn num_params(&self) -> usize {
            1
        }
        fn num_residuals(&self) -> usize {
            2
        }
        fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
            // Defined only for x < 2; the minimum of (x - 3)^2 + (x - 3)^2 lies outside.
            let v = if x[0] < 2.0 { x[0] - 3.0 } else { f64::NAN };
            r[0] = v;
            r[1] = v;
            Ok(())
        }
    }
    impl DenseJacobian for NanAt {
        fn jacobian(&mut self, _x: &[f64], mut j: MatMut<'_, f64>) -> Result<(), ModelError> {
            j[(0, 0)] = 1.0;
            j[(1, 0)] = 1.0;
            Ok(())
        }
    }
    // NaN trial points are rejected like bad steps; the solve creeps towards x = 2.
    let mut x = [0.0];
    let r = minimize(&mut NanAt, &mut x, &Options::default()).unwrap();
    assert!(x[0] < 2.0 && x[0] > 1.9, "{x:?} {r:#}");
    assert!(r.rejected_steps > 0);
    // A NaN at the start ends with NonFinite.
    let mut x = [5.0];
    let r = minimize(&mut NanAt, &mut x, &Options::default()).unwrap();
    assert_eq!(r.termination, TerminationReason::NonFinite);
    assert!(!r.was_successful());
    assert_eq!(x, [5.0]);
}

#[test]
fn report_counts_and_text() {
    let mut p = Decay::new(&[]);
    let mut x = [1.0, 1.0, 0.0];
    let r = minimize(&mut p, &mut x, &Options::default()).unwrap();
    assert!(r.was_successful());
    assert_eq!(r.accepted_steps + r.rejected_steps, r.iterations.len());
    assert_eq!(
        r.accepted_steps,
        r.iterations.iter().filter(|i| i.accepted).count()
    );
    assert_eq!(r.residual_evaluations, p.residual_calls);
    assert_eq!(r.jacobian_evaluations, p.jacobian_calls);
    assert_eq!(r.residual_evaluations, r.iterations.len() + 1);
    assert!(r.final_cost < r.initial_cost);
    assert_eq!(r.final_cost, r.iterations.last().unwrap().cost);
    assert!(r.elapsed >= r.timings.residuals);
    let brief = r.brief();
    assert!(!brief.contains('\n'));
    assert!(brief.starts_with("converged"), "{brief}");
    assert_eq!(format!("{r}"), brief);
    let full = format!("{r:#}");
    assert_eq!(full, r.full());
    assert!(
        full.contains("iter") && full.contains("gain") && full.contains("statistics: rank 3 of 3")
    );
    assert!(
        full.lines()
            .filter(|l| l.trim_start().starts_with(char::is_numeric))
            .count()
            >= r.iterations.len()
    );
    // Zero residual at the start.
    let mut exact = Decay::new(&[]);
    exact.y = exact.t.iter().map(|t| 2.0 * (-t).exp() + 0.1).collect();
    let mut x = [2.0, 1.0, 0.1];
    let r = minimize(&mut exact, &mut x, &Options::default()).unwrap();
    assert_eq!(r.termination, TerminationReason::ZeroResidual);
    assert!(r.was_successful());
    assert_eq!(r.iterations.len(), 0);
    let st = r.statistics().unwrap();
    assert_eq!(st.std_dev, vec![Some(0.0); 3]);
    // Statistics can be switched off.
    let o = Options {
        statistics: cpm_lm::StatisticsMode::Off,
        ..Options::default()
    };
    let off = minimize(&mut p, &mut [1.0, 1.0, 0.0], &o).unwrap();
    assert!(off.statistics().is_none() && off.jacobian().is_none());
    // On demand (the default) and at the end give the same numbers; only the eager one
    // spends time on them inside the solve.
    let mut xa = [1.0, 1.0, 0.0];
    let lazy = minimize(&mut p, &mut xa, &Options::default()).unwrap();
    let eager = Options {
        statistics: cpm_lm::StatisticsMode::AtEnd,
        ..Options::default()
    };
    let mut xb = [1.0, 1.0, 0.0];
    let at_end = minimize(&mut p, &mut xb, &eager).unwrap();
    assert_eq!(xa, xb);
    let (a, b) = (lazy.statistics().unwrap(), at_end.statistics().unwrap());
    assert_eq!(a.rank, b.rank);
    assert_eq!(a.std_dev, b.std_dev);
    assert_eq!(a.singular_values, b.singular_values);
}

/// [`Decay`] with a residual function that takes at least 50 us (a slow model).
struct SlowDecay(Decay);

impl Problem for SlowDecay {
    fn num_params(&self) -> usize {
        self.0.num_params()
    }
    fn num_residuals(&self) -> usize {
        self.0.num_residuals()
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        std::thread::sleep(std::time::Duration::from_micros(50));
        self.0.residuals(x, r)
    }
}

impl DenseJacobian for SlowDecay {
    fn jacobian(&mut self, x: &[f64], j: MatMut<'_, f64>) -> Result<(), ModelError> {
        self.0.jacobian(x, j)
    }
}

#[test]
fn phases_are_timed_or_said_not_to_be() {
    // A slow model: its phases are timed, and the residuals took at least 50 us a call.
    let mut p = SlowDecay(Decay::new(&[]));
    let mut x = [1.0, 1.0, 0.0];
    let r = minimize(&mut p, &mut x, &Options::default()).unwrap();
    assert!(r.timings.phases_timed);
    let calls = u32::try_from(r.residual_evaluations).unwrap();
    assert!(r.timings.residuals >= std::time::Duration::from_micros(50) * calls);
    assert!(r.full().contains(" residuals, "), "{}", r.full());
    // Whatever a solve's speed, untimed phases are zero and the summary says they were not
    // timed rather than printing zeros.
    let mut q = Decay::new(&[]);
    let mut y = [1.0, 1.0, 0.0];
    let r = minimize(&mut q, &mut y, &Options::default()).unwrap();
    if r.timings.phases_timed {
        assert!(r.full().contains(" residuals, "));
    } else {
        assert_eq!(
            r.timings.residuals + r.timings.jacobian,
            std::time::Duration::ZERO
        );
        assert!(r.full().contains("phases were not timed"), "{}", r.full());
    }
}
