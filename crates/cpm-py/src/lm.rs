//! `cpm.lm.least_squares`: the cpm-lm solver on Python callables.
//!
//! The residual function and the Jacobian are Python callables (the Python layer wraps the
//! user's so they return float64 numpy arrays of the declared shapes); without a Jacobian,
//! cpm-lm's finite differences ([`cpm_lm::NumericJacobian`]) are used. The solve runs with the
//! GIL released between evaluations (each evaluation takes it), and Ctrl-C stops it at the
//! next iteration: the iteration callback checks for signals. An exception raised by the
//! user's function stops the solve and is raised again as it was.
use std::ops::ControlFlow;
use std::sync::{Arc, Mutex};

use cpm_lm::{
    Damping, DenseJacobian, Difference, GeodesicAcceleration, Loss, ModelError, NumericJacobian,
    Options, Problem, Scaling, Solver,
};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The first Python error of a solve (raised again after it).
type Slot = Arc<Mutex<Option<PyErr>>>;

/// A least-squares problem whose residuals and Jacobian are Python callables.
struct PyProblem {
    fun: Py<PyAny>,
    jac: Option<Py<PyAny>>,
    m: usize,
    n: usize,
    error: Slot,
}

impl PyProblem {
    /// Keeps the first Python error and returns a model error that stops the solve.
    fn fail(&self, e: PyErr) -> ModelError {
        let msg = format!("the Python callback raised {e}");
        if let Ok(mut slot) = self.error.lock() {
            slot.get_or_insert(e);
        }
        msg.into()
    }
}

impl Problem for PyProblem {
    fn num_params(&self) -> usize {
        self.n
    }
    fn num_residuals(&self) -> usize {
        self.m
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        Python::with_gil(|py| -> PyResult<()> {
            let out = self.fun.call1(py, (PyArray1::from_slice(py, x),))?;
            let a: PyReadonlyArray1<'_, f64> = out.extract(py)?;
            let a = a.as_array();
            if a.len() != self.m {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "fun returned {} residuals, expected {} (as at x0)",
                    a.len(),
                    self.m
                )));
            }
            for (ri, v) in r.iter_mut().zip(a.iter()) {
                *ri = *v;
            }
            Ok(())
        })
        .map_err(|e| self.fail(e))
    }
}

impl DenseJacobian for PyProblem {
    fn jacobian(
        &mut self,
        x: &[f64],
        mut j: cpm_lm::faer::MatMut<'_, f64>,
    ) -> Result<(), ModelError> {
        let Some(jac) = &self.jac else {
            return Err("no Jacobian callable".into());
        };
        Python::with_gil(|py| -> PyResult<()> {
            let out = jac.call1(py, (PyArray1::from_slice(py, x),))?;
            let a: PyReadonlyArray2<'_, f64> = out.extract(py)?;
            let a = a.as_array();
            if a.shape() != [self.m, self.n] {
                return Err(pyo3::exceptions::PyValueError::new_err(format!(
                    "jac returned shape {:?}, expected ({}, {})",
                    a.shape(),
                    self.m,
                    self.n
                )));
            }
            for ((i, k), v) in a.indexed_iter() {
                j[(i, k)] = *v;
            }
            Ok(())
        })
        .map_err(|e| self.fail(e))
    }
}

/// The solver settings, normalised by the Python layer (`cpm/lm.py`), as a dict.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct Settings {
    lower: Option<Vec<f64>>,
    upper: Option<Vec<f64>>,
    loss: String,
    f_scale: f64,
    ftol: Option<f64>,
    xtol: Option<f64>,
    gtol: Option<f64>,
    max_nfev: Option<usize>,
    max_iterations: Option<usize>,
    damping: String,
    x_scale: String,
    acceleration: bool,
}

/// The solver options of the settings.
fn options(py: Python<'_>, s: Settings) -> PyResult<Options> {
    let Settings {
        lower,
        upper,
        f_scale,
        ftol,
        xtol,
        gtol,
        max_nfev,
        max_iterations,
        acceleration,
        ..
    } = s;
    let loss = match s.loss.as_str() {
        "linear" => Loss::Squared,
        "huber" => Loss::Huber(f_scale),
        "cauchy" => Loss::Cauchy(f_scale),
        "tukey" => Loss::Tukey(f_scale),
        other => {
            return Err(crate::errors::usage(
                py,
                format!("loss={other:?}: cpm-lm has 'linear', 'huber', 'cauchy', 'tukey'"),
            ))
        }
    };
    let damping = match s.damping.as_str() {
        "trust-region" => Damping::TrustRegion,
        "nielsen" => Damping::Nielsen,
        "marquardt" => Damping::Marquardt,
        "cubic" => Damping::CubicInterpolation,
        other => {
            return Err(crate::errors::usage(
                py,
                format!(
                    "damping={other:?}: one of 'trust-region', 'nielsen', 'marquardt', 'cubic'"
                ),
            ))
        }
    };
    let scaling = match s.x_scale.as_str() {
        "jac" => Scaling::Marquardt,
        "identity" => Scaling::Identity,
        other => {
            return Err(crate::errors::usage(
                py,
                format!("x_scale={other:?}: 'jac' (Marquardt's scaling) or 1.0 (none)"),
            ))
        }
    };
    let d = Options::default();
    let o = Options {
        loss,
        damping,
        scaling,
        ftol: ftol.unwrap_or(d.ftol),
        xtol: xtol.unwrap_or(d.xtol),
        gtol: gtol.unwrap_or(d.gtol),
        max_evaluations: max_nfev.unwrap_or(d.max_evaluations),
        max_iterations: max_iterations.unwrap_or(d.max_iterations),
        lower,
        upper,
        acceleration: acceleration.then(GeodesicAcceleration::default),
        ..d
    };
    o.validate()
        .map_err(|e| crate::errors::usage(py, e.to_string()))?;
    Ok(o)
}

/// Solves `min 0.5 sum rho(f(x)^2)` with cpm-lm. `fun(x) -> (m,)` and `jac(x) -> (m, n)`
/// must return float64 arrays (the Python layer wraps the user's callables); `jac=None` uses
/// finite differences (`diff` `"2-point"` forward, `"3-point"` central). `settings` is a dict
/// of the fields of [`Settings`]. Returns a dict of the solution and the solver's report.
#[pyfunction]
#[pyo3(signature = (fun, x0, m, jac, diff, diff_step, settings))]
pub fn least_squares<'py>(
    py: Python<'py>,
    fun: Py<PyAny>,
    x0: Vec<f64>,
    m: usize,
    jac: Option<Py<PyAny>>,
    diff: &str,
    diff_step: Option<f64>,
    settings: Settings,
) -> PyResult<Bound<'py, PyDict>> {
    let options = options(py, settings)?;
    let scheme = match diff {
        "2-point" => Difference::Forward,
        "3-point" => Difference::Central,
        other => {
            return Err(crate::errors::usage(
                py,
                format!("jac={other:?}: a callable, '2-point' or '3-point'"),
            ))
        }
    };
    let error: Slot = Arc::new(Mutex::new(None));
    let problem = PyProblem {
        fun,
        jac,
        m,
        n: x0.len(),
        error: error.clone(),
    };
    let mut x = x0;
    let stop = error.clone();
    let result = py.allow_threads(move || {
        let mut solver = Solver::new(options).with_callback(move |_| {
            match Python::with_gil(|py| py.check_signals()) {
                Ok(()) => ControlFlow::Continue(()),
                Err(e) => {
                    if let Ok(mut slot) = stop.lock() {
                        slot.get_or_insert(e);
                    }
                    ControlFlow::Break(())
                }
            }
        });
        let r = if problem.jac.is_some() {
            let mut p = problem;
            solver.minimize(&mut p, &mut x)
        } else {
            let mut p = NumericJacobian::new(problem, scheme);
            if let Some(h) = diff_step {
                p = p.with_step(h);
            }
            solver.minimize(&mut p, &mut x)
        };
        (r, x)
    });
    let (report, x) = result;
    if let Some(e) = error.lock().ok().and_then(|mut s| s.take()) {
        return Err(e);
    }
    let report = report.map_err(|e| match e {
        cpm_lm::LmError::InvalidOptions(_) | cpm_lm::LmError::DimensionMismatch { .. } => {
            crate::errors::usage(py, e.to_string())
        }
        other => crate::errors::solver(py, other.to_string()),
    })?;
    let d = PyDict::new(py);
    d.set_item("x", PyArray1::from_vec(py, x))?;
    d.set_item("cost", report.final_cost)?;
    d.set_item("initial_cost", report.initial_cost)?;
    d.set_item("termination", format!("{:?}", report.termination))?;
    d.set_item("message", report.termination.to_string())?;
    d.set_item("success", report.was_successful())?;
    d.set_item("nfev", report.residual_evaluations)?;
    d.set_item("njev", report.jacobian_evaluations)?;
    d.set_item("nit", report.num_iterations())?;
    d.set_item("usable", report.is_solution_usable())?;
    if let Some(o) = &report.optimality {
        // A bounded solve: SciPy's active_mask, and cpm-lm's first-order verdict in the box
        // (the Python layer computes `optimality` from the gradient at the solution).
        d.set_item(
            "active_mask",
            PyArray1::from_iter(py, o.active.iter().map(|a| i64::from(*a))),
        )?;
        d.set_item("projected_gradient", o.projected_gradient)?;
        d.set_item("first_order_measure", o.measure)?;
        d.set_item("first_order_optimal", o.optimal)?;
    }
    d.set_item("report", report.brief())?;
    d.set_item("report_full", report.full())?;
    if let Some(st) = report.statistics() {
        let n = st.num_params;
        d.set_item("rank", st.rank)?;
        d.set_item(
            "singular_values",
            PyArray1::from_slice(py, &st.singular_values),
        )?;
        d.set_item(
            "std",
            PyArray1::from_iter(py, st.std_dev.iter().map(|s| s.unwrap_or(f64::NAN))),
        )?;
        d.set_item("sigma2", st.sigma2)?;
        d.set_item("dof", st.dof)?;
        d.set_item("identifiable", st.identifiable.clone())?;
        let covariance = PyArray2::<f64>::zeros(py, [n, n], false);
        let correlation = PyArray2::<f64>::zeros(py, [n, n], false);
        {
            let mut c = covariance.readwrite();
            let mut r = correlation.readwrite();
            let (mut c, mut r) = (c.as_array_mut(), r.as_array_mut());
            for i in 0..n {
                for j in 0..n {
                    c[(i, j)] = st.covariance[(i, j)];
                    r[(i, j)] = st.correlation[(i, j)];
                }
            }
        }
        d.set_item("covariance", covariance)?;
        d.set_item("correlation", correlation)?;
    }
    Ok(d)
}
