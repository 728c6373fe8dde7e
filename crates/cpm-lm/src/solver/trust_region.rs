//! The Levenberg-Marquardt parameter for a trust-region radius (MINPACK's `lmpar`,
//! Moré 1978), on top of any [`LinearSystem`].
//!
//! Given the radius `delta`, find `par >= 0` with `||D p(par)|| ~ delta` where
//! `(J^T J + par D^2) p = -g`: `par = 0` when the Gauss-Newton step lies within
//! `1.1 delta`, otherwise the Moré-Hebden iteration, a safeguarded Newton iteration on
//! `phi(par) = ||D p(par)|| - delta` inside the bracket `[parl, paru]`, stopping when
//! `|phi| <= 0.1 delta` (at most 10 solves). The Newton correction is
//! `(phi / delta) / q` with `q = ||D p||^-2 (D^2 p)^T (J^T J + par D^2)^-1 (D^2 p)`
//! (from [`LinearSystem::inverse_quadratic`]).

use crate::solver::jacobian::Jacobian;
use crate::solver::LinearSystem;

const P1: f64 = 0.1;
const P001: f64 = 1e-3;
const MAX_SOLVES: usize = 10;

fn scaled_norm(d: &[f64], h: &[f64]) -> f64 {
    d.iter()
        .zip(h)
        .map(|(a, b)| (a * b) * (a * b))
        .sum::<f64>()
        .sqrt()
}

/// `wa = D^2 h / ||D h||`.
fn newton_vector(d: &[f64], h: &[f64], dxnorm: f64, wa: &mut [f64]) {
    for ((w, &dj), &hj) in wa.iter_mut().zip(d).zip(h) {
        *w = dj * (dj * hj / dxnorm);
    }
}

/// Solves for the step `h` with the damping that fits the radius `delta`, starting the
/// search from `par0`. Returns the damping used, or `None` when no damped system could be
/// solved. `wa` is scratch of length `n`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn lmpar(
    linear: &mut dyn LinearSystem,
    jac: &Jacobian,
    mut delta: f64,
    gn_scale: f64,
    par0: f64,
    d: &[f64],
    g: &[f64],
    h: &mut [f64],
    wa: &mut [f64],
) -> Option<f64> {
    let dwarf = f64::MIN_POSITIVE;
    // The Gauss-Newton step: accepted when it lies within the region (up to 10%).
    let mut parl = 0.0;
    let mut fp = f64::INFINITY;
    let mut dxnorm = 0.0;
    if linear.solve(jac, 0.0, d, g, h) {
        dxnorm = scaled_norm(d, h);
        fp = dxnorm - delta;
        if fp <= P1 * delta {
            if gn_scale >= 1.0 || dxnorm == 0.0 {
                return Some(0.0);
            }
            delta = gn_scale * dxnorm;
            fp = dxnorm - delta;
        }
        // With J of full rank, the Newton step at par = 0 bounds par from below.
        newton_vector(d, h, dxnorm, wa);
        if let Some(q) = linear.inverse_quadratic(jac, wa) {
            if q > 0.0 {
                parl = fp / delta / q;
            }
        }
    }
    // Upper bound ||D^-1 g|| / delta.
    let gnorm = d
        .iter()
        .zip(g)
        .map(|(a, b)| (b / a) * (b / a))
        .sum::<f64>()
        .sqrt();
    let mut paru = gnorm / delta;
    if paru == 0.0 {
        paru = dwarf / delta.min(P1);
    }
    let mut par = par0.max(parl).min(paru);
    if par == 0.0 && dxnorm > 0.0 && fp.is_finite() {
        par = gnorm / dxnorm;
    }
    for iter in 1..=MAX_SOLVES {
        if par == 0.0 {
            par = dwarf.max(P001 * paru);
        }
        if !linear.solve(jac, par, d, g, h) {
            // Not numerically positive definite at this damping: raise it.
            if iter == MAX_SOLVES {
                return None;
            }
            parl = parl.max(par);
            par *= 10.0;
            paru = paru.max(par);
            continue;
        }
        let previous = fp;
        dxnorm = scaled_norm(d, h);
        fp = dxnorm - delta;
        if fp.abs() <= P1 * delta
            || (parl == 0.0 && fp <= previous && previous < 0.0)
            || iter == MAX_SOLVES
            || dxnorm == 0.0
        {
            return Some(par);
        }
        newton_vector(d, h, dxnorm, wa);
        let Some(q) = linear.inverse_quadratic(jac, wa) else {
            return Some(par);
        };
        let parc = fp / delta / q;
        if fp > 0.0 {
            parl = parl.max(par);
        } else if fp < 0.0 {
            paru = paru.min(par);
        }
        let next = parl.max(par + parc);
        if !next.is_finite() {
            return Some(par);
        }
        par = next;
    }
    Some(par)
}
