//! Damping schedules: how the Levenberg-Marquardt parameter `mu` (or `lambda`) evolves.
//!
//! Every strategy solves `(J^T J + mu D^2) h = -J^T r` for the step `h` (with `D = I` under
//! [`Scaling::Identity`](crate::Scaling::Identity)). They differ in how `mu` reacts to the
//! gain ratio `rho = (actual reduction) / (reduction predicted by the linear model)`:
//!
//! * [`Damping::TrustRegion`] (default; MINPACK's `lmder`, Moré 1978): the damping is not
//!   updated directly but follows from a trust-region radius `delta` on the scaled step,
//!   `||D h|| <= delta`. Each trial finds `mu` by the Moré-Hebden iteration (MINPACK's
//!   `lmpar`): `mu = 0` (the Gauss-Newton step) when that step lies within `1.1 delta`,
//!   otherwise a safeguarded Newton iteration on `||D h(mu)|| - delta` until it is within
//!   10% of `delta` (a few extra solves of the damped system per trial, each cheap for the
//!   dense QR solver). The radius starts at `100 ||D x_0||` and is capped by the first
//!   step's length. When `x_0 = 0` (where MINPACK's fixed 100 depends on the units of the
//!   problem) it starts at `||D^-1 g|| / mu_0`, the bound on the length of the step damped
//!   with `mu_0 = tau max_j (J^T J)_jj / D_j^2`. After a trial with gain ratio `rho`:
//!   `rho <= 1/4` shrinks it, `delta <- t * min(delta, 10 ||D h||)` with `t = 1/2` (or the
//!   minimiser of the quadratic through the actual reduction when the cost rose, within
//!   `[1/10, 1/2]`); `rho >= 3/4` (or a Gauss-Newton step) sets `delta <- 2 ||D h||`.
//!   A step is accepted when `rho >= 1e-4`. Two refinements over MINPACK: after a
//!   Gauss-Newton step with `1/4 < rho < 3/4`, which overshoots
//!   (the cost's curvature along it is about `2 - rho` times the model's, as on
//!   large-residual problems), the next Gauss-Newton step that fits the region is
//!   shortened to `1 / (2 - rho)` of its length, the minimiser of the fitted quadratic,
//!   instead of converging only linearly with full steps; and after a rejected step the
//!   radius grows back only halfway towards the length that failed (that length relaxing
//!   by 25% per success) instead of doubling straight back to it, which made MINPACK
//!   alternate between a good and a rejected step along some valleys (NIST's MGH09 from its
//!   first start: 319 evaluations instead of 843 when measured, before the radius
//!   reduction after a rise of the cost was corrected to MINPACK's; 424 since). Because the radius, not `mu`, carries
//!   over, the damping drops to zero as soon as the Gauss-Newton step is trustworthy and
//!   the iteration follows a curved valley without crawling: from NIST's second starts,
//!   Lanczos1-3 take 9-14 evaluations instead of about 100 with Nielsen's rule.
//! * [`Damping::Nielsen`] (Nielsen 1999, Madsen-Nielsen-Tingleff 2004): on an
//!   accepted step `mu <- mu * max(1/3, 1 - (2 rho - 1)^3)`, `nu <- 2`; on a rejected step
//!   `mu <- mu * nu`, `nu <- 2 nu`. A step is accepted when `rho > 0`. One solve of the
//!   damped system per trial; it keeps `mu` nearly constant while `rho` stays near 1/2,
//!   which can make it crawl along curved valleys.
//! * [`Damping::GaussNewtonThenNielsen`]: Gauss-Newton steps (`mu = 0`) while each is
//!   accepted with a gain ratio of at least 1/4; the first that is not (rejected, accepted
//!   with `rho < 1/4`, or a singular undamped system) hands over to Nielsen's rule from
//!   `mu_0`. A nearly linear problem (the usual calibration) then converges in a few
//!   Gauss-Newton steps where Nielsen's rule, lowering `mu` by at most 3 per step, would
//!   crawl, and it needs one solve per trial (no trust-region search): the schedule of
//!   problems that form their own normal equations
//!   ([`NormalEquations`](crate::NormalEquations)), where each solve is a pass over the data.
//! * [`Damping::Marquardt`] (Marquardt 1963): `mu <- mu / 10` on acceptance,
//!   `mu <- mu * 10` on rejection.
//! * [`Damping::CubicInterpolation`]: the control of MATLAB's former `lsqnonlin`
//!   Levenberg-Marquardt (about 2000-2004). The direction is `d = -(J^T J + lambda D^2)^-1
//!   J^T f`, tried with a step length `alpha` (1 at first). `EstSum = ||J d + f||^2` is the
//!   linear model's sum of squares at unit step. A step is accepted when it lowers the sum
//!   of squares. After an accepted step of length `alpha`, the cubic through
//!   `(0, SS_old, slope_old)` and `(alpha, SS_new, slope_new)` (slopes of the sum of squares
//!   along `d`, the new one from the Jacobian at the new point) gives its minimiser and the
//!   value there, `fbest` (if it exceeds `SS_new`, or there is no minimiser, `fbest =
//!   0.9 SS_new`); then `lambda <- lambda / (1 + alpha)` if `EstSum > fbest`, else
//!   `lambda <- lambda + (fbest - EstSum) / (alpha + eps)`, and `alpha <- 1`. A failed step
//!   leaves `lambda` alone and shortens `alpha` by quadratic (first failure) or cubic
//!   (later failures) interpolation of the sum of squares along `d`, safeguarded to
//!   `[alpha/10, alpha/2]`, or `alpha / 8` when the interpolation is unusable. The original
//!   damped with the identity; combine it with [`Scaling::Identity`](crate::Scaling::Identity)
//!   to reproduce that, the default Marquardt scaling works as well.
//!
//! The damping strategies other than the trust region start from
//! `mu_0 = tau * max_j (J^T J)_jj / D_j^2` (`tau =` [`Options::tau`](crate::Options::tau)).

/// Damping schedule (see the [module documentation](self) for the update rules).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Damping {
    /// MINPACK's trust-region control of the damping (Moré 1978), the default.
    #[default]
    TrustRegion,
    /// Nielsen's smooth update driven by the gain ratio.
    Nielsen,
    /// Marquardt's classic divide / multiply by 10.
    Marquardt,
    /// Gauss-Newton steps while they gain well (`rho >= 1/4`), then Nielsen's rule.
    GaussNewtonThenNielsen,
    /// Cubic-interpolation control of MATLAB's former `lsqnonlin` LM (step length and
    /// damping adapted from a cubic model of the sum of squares along the step).
    CubicInterpolation,
}

impl Damping {
    /// Short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Damping::TrustRegion => "trust region",
            Damping::Nielsen => "Nielsen",
            Damping::Marquardt => "Marquardt",
            Damping::GaussNewtonThenNielsen => "Gauss-Newton, then Nielsen",
            Damping::CubicInterpolation => "cubic interpolation",
        }
    }
}

/// What the line along the direction looked like at a trial (sum-of-squares units,
/// i.e. `2 * cost`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct LineInfo {
    /// Sum of squares at the current point.
    pub f0: f64,
    /// Derivative of the sum of squares along the unit direction at the current point.
    pub slope0: f64,
    /// Step length used.
    pub alpha: f64,
    /// Sum of squares at the trial point.
    pub f_trial: f64,
    /// Linear model's sum of squares at unit step, `||J d + f||^2`.
    pub est_sum: f64,
    /// Scaled length `||D s||` of the step taken.
    pub scaled_step: f64,
    /// `g . s` for the step taken (derivative of the cost along it).
    pub gs: f64,
}

const MU_MIN: f64 = 1e-300;
/// Initial trust-region radius relative to `||D x_0||` (MINPACK's `factor`).
const TR_FACTOR: f64 = 100.0;

/// The evolving damping state of one solve.
#[derive(Clone, Debug)]
pub(crate) struct DampingState {
    kind: Damping,
    mu: f64,
    nu: f64,
    alpha: f64,
    /// Previous failed trial along the current direction, `(alpha, f)`.
    last_fail: Option<(f64, f64)>,
    /// Accepted cubic step waiting for the slope at the new point.
    pending: Option<LineInfo>,
    /// Trust-region radius on `||D h||`.
    delta: f64,
    /// Whether no trust-region trial has been made yet.
    tr_first: bool,
    /// Factor applied to the next Gauss-Newton step that fits the region.
    gn_scale: f64,
    /// Scaled length of the last rejected step, while no step that long has succeeded.
    failed: f64,
    /// Initial damping (where Nielsen's rule starts after the Gauss-Newton phase).
    mu0: f64,
    /// Whether the Gauss-Newton phase of [`Damping::GaussNewtonThenNielsen`] lasts.
    gauss_newton: bool,
}

impl DampingState {
    pub(crate) fn new(kind: Damping, mu0: f64) -> Self {
        Self {
            kind,
            mu: if matches!(kind, Damping::TrustRegion | Damping::GaussNewtonThenNielsen) {
                0.0
            } else {
                mu0.max(MU_MIN)
            },
            nu: 2.0,
            alpha: 1.0,
            last_fail: None,
            pending: None,
            delta: f64::INFINITY,
            tr_first: true,
            gn_scale: 1.0,
            failed: f64::INFINITY,
            mu0: mu0.max(MU_MIN),
            gauss_newton: kind == Damping::GaussNewtonThenNielsen,
        }
    }

    /// Ends the Gauss-Newton phase: Nielsen's rule from `mu_0`.
    fn leave_gauss_newton(&mut self) {
        self.gauss_newton = false;
        self.mu = self.mu0;
        self.nu = 2.0;
    }

    /// Whether `mu` follows a trust-region radius (see [`Self::radius`]).
    pub(crate) fn is_trust_region(&self) -> bool {
        self.kind == Damping::TrustRegion
    }

    /// Sets the initial trust-region radius: `100 ||D x_0||`, or, when `x_0 = 0` (where
    /// MINPACK's absolute 100 depends on the units), `fallback`, the bound
    /// `||D^-1 g|| / mu_0` on the scaled length of the step damped with `mu_0`.
    pub(crate) fn init_radius(&mut self, scaled_x_norm: f64, fallback: f64) {
        self.delta = if scaled_x_norm > 0.0 && scaled_x_norm.is_finite() {
            TR_FACTOR * scaled_x_norm
        } else if fallback > 0.0 && fallback.is_finite() {
            fallback
        } else {
            TR_FACTOR
        };
    }

    /// Trust-region radius on `||D h||`.
    pub(crate) fn radius(&self) -> f64 {
        self.delta
    }

    /// Factor for the next Gauss-Newton step.
    pub(crate) fn gn_scale(&self) -> f64 {
        self.gn_scale
    }

    /// Records the damping the trust-region search settled on for this trial.
    pub(crate) fn set_mu(&mut self, mu: f64) {
        self.mu = mu;
    }

    /// Whether the damping cannot grow any further (the solve should stop as singular).
    pub(crate) fn exhausted(&self) -> bool {
        if self.kind == Damping::TrustRegion {
            !(self.delta > MU_MIN)
        } else {
            self.mu.is_nan() || self.mu >= 1e300
        }
    }

    /// MINPACK's radius update after a trial with gain ratio `rho`.
    fn update_radius(&mut self, rho: f64, line: &LineInfo) {
        let pnorm = line.scaled_step;
        // A Gauss-Newton step with a fair gain ratio overshoots: along it, the cost's
        // curvature exceeds the model's by about 2 - rho, so the next Gauss-Newton step is
        // shortened by 1 / (2 - rho) (the minimiser of the quadratic fitted through the
        // actual reduction). MINPACK would take full steps and converge only linearly.
        if self.mu == 0.0 && rho > 0.25 && rho < 0.75 {
            self.gn_scale = 1.0 / (2.0 - rho);
        } else {
            self.gn_scale = 1.0;
        }
        if self.tr_first {
            self.delta = self.delta.min(pnorm);
            self.tr_first = false;
        }
        if !(rho > 0.25) {
            // Relative actual reduction and directional derivative, in MINPACK's units
            // (sums of squares relative to the current one): MINPACK's `dirder` is
            // `-(||J p||^2 + par ||D p||^2) / ||f||^2 = (g . p) / f0` with `g = J^T f`, so
            // that `temp` below is the minimiser of the quadratic through the sum of
            // squares, its slope `2 g . p` and the trial value. (Twice that, as this port
            // had it, shrank the radius less than MINPACK after a rise of the cost: 45
            // evaluations instead of 30 for Freudenstein-Roth from 100x its start.)
            let big_increase = !(line.f_trial < 100.0 * line.f0);
            let actred = if big_increase {
                -1.0
            } else {
                1.0 - line.f_trial / line.f0
            };
            let dirder = line.gs / line.f0;
            let mut temp = if actred >= 0.0 {
                0.5
            } else {
                0.5 * dirder / (dirder + 0.5 * actred)
            };
            if big_increase || !(temp >= 0.1) {
                temp = 0.1;
            }
            temp = temp.min(0.5);
            // MINPACK's bound: the new radius at most 10 |Dh| (t times). (Bounding it by
            // |Dh| after a Gauss-Newton step, as this port once did, cost Rosenbrock from 10x
            // its start 30 evaluations instead of 9 once the reduction above was MINPACK's.)
            self.delta = temp * self.delta.min(10.0 * pnorm);
            self.mu /= temp;
            if rho < 1e-4 {
                self.failed = pnorm;
            }
        } else if self.mu == 0.0 || rho >= 0.75 {
            self.delta = 2.0 * pnorm;
            self.mu *= 0.5;
            if pnorm >= self.failed {
                self.failed = f64::INFINITY;
            } else if self.delta >= self.failed {
                // Doubling would retry the length that just failed (and then halve again,
                // every other trial wasted): grow halfway towards it instead.
                self.delta = pnorm.max(0.5 * (pnorm + self.failed));
                self.failed *= 1.25;
            }
        }
    }

    /// Current damping parameter.
    pub(crate) fn mu(&self) -> f64 {
        self.mu
    }

    /// Step length to apply to the solved direction (1 except for the cubic control).
    pub(crate) fn step_length(&self) -> f64 {
        self.alpha
    }

    /// Whether a step with gain ratio `rho` and trial cost below the current one is accepted.
    pub(crate) fn accepts(&self, rho: f64, decreased: bool) -> bool {
        match self.kind {
            Damping::CubicInterpolation => decreased,
            Damping::TrustRegion => decreased && rho >= 1e-4,
            Damping::Nielsen | Damping::Marquardt | Damping::GaussNewtonThenNielsen => {
                decreased && rho > 0.0
            }
        }
    }

    /// Updates after an accepted step.
    pub(crate) fn accepted(&mut self, rho: f64, line: LineInfo) {
        match self.kind {
            Damping::TrustRegion => {
                self.update_radius(rho, &line);
                return;
            }
            Damping::GaussNewtonThenNielsen if self.gauss_newton => {
                if !(rho >= 0.25) {
                    self.leave_gauss_newton();
                }
                return;
            }
            Damping::Nielsen | Damping::GaussNewtonThenNielsen => {
                let t = 2.0 * rho - 1.0;
                self.mu *= (1.0 / 3.0f64).max(1.0 - t * t * t);
                self.nu = 2.0;
            }
            Damping::Marquardt => self.mu /= 10.0,
            Damping::CubicInterpolation => {
                self.pending = Some(line);
                self.last_fail = None;
                self.alpha = 1.0;
            }
        }
        self.mu = self.mu.max(MU_MIN);
    }

    /// Whether the state waits for the slope at the new point ([`Self::new_slope`]).
    pub(crate) fn needs_slope(&self) -> bool {
        self.pending.is_some()
    }

    /// Completes the cubic update with the derivative of the sum of squares along the
    /// accepted direction at the new point.
    pub(crate) fn new_slope(&mut self, slope_new: f64) {
        let Some(p) = self.pending.take() else {
            return;
        };
        let a = p.alpha;
        let f1 = p.f_trial;
        let mut fbest = 0.9 * f1;
        if let Some(t) = cubic_minimiser(p.f0, p.slope0, a, f1, slope_new) {
            let v = cubic_value(p.f0, p.slope0, a, f1, slope_new, t);
            if v.is_finite() && v <= f1 {
                fbest = v;
            }
        }
        if p.est_sum > fbest {
            self.mu /= 1.0 + a;
        } else {
            self.mu += (fbest - p.est_sum) / (a + f64::EPSILON);
        }
        if !self.mu.is_finite() || self.mu <= 0.0 {
            self.mu = MU_MIN;
        }
        self.mu = self.mu.max(MU_MIN);
    }

    /// Updates after a rejected step.
    pub(crate) fn rejected(&mut self, rho: f64, line: LineInfo) {
        match self.kind {
            Damping::TrustRegion => self.update_radius(rho, &line),
            Damping::GaussNewtonThenNielsen if self.gauss_newton => self.leave_gauss_newton(),
            Damping::Nielsen | Damping::GaussNewtonThenNielsen => {
                self.mu *= self.nu;
                self.nu *= 2.0;
            }
            Damping::Marquardt => self.mu *= 10.0,
            Damping::CubicInterpolation => {
                let a = line.alpha;
                let next = shorten(line.f0, line.slope0, a, line.f_trial, self.last_fail);
                self.last_fail = Some((a, line.f_trial));
                self.alpha = next;
            }
        }
    }

    /// Updates after the damped system could not be solved (not positive definite).
    pub(crate) fn singular(&mut self) {
        match self.kind {
            Damping::TrustRegion => {
                self.delta *= 0.1;
                self.mu = (10.0 * self.mu).max(MU_MIN);
                return;
            }
            Damping::GaussNewtonThenNielsen if self.gauss_newton => {
                self.leave_gauss_newton();
                return;
            }
            Damping::Nielsen | Damping::GaussNewtonThenNielsen => {
                self.mu *= self.nu;
                self.nu *= 2.0;
            }
            Damping::Marquardt | Damping::CubicInterpolation => self.mu *= 10.0,
        }
        if self.mu == 0.0 {
            self.mu = 1.0;
        }
    }
}

/// Positive minimiser of the cubic Hermite interpolant `p` with `p(0) = f0`, `p'(0) = s0`,
/// `p(a) = f1`, `p'(a) = s1`, if any.
fn cubic_minimiser(f0: f64, s0: f64, a: f64, f1: f64, s1: f64) -> Option<f64> {
    let (c2, c3) = cubic_coefficients(f0, s0, a, f1, s1);
    // p'(t) = s0 + 2 c2 t + 3 c3 t^2; the root with p'' > 0 written stably.
    let disc = c2 * c2 - 3.0 * c3 * s0;
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    let den = c2 + disc.sqrt();
    if den <= 0.0 {
        return None;
    }
    let t = -s0 / den;
    (t.is_finite() && t > 0.0).then_some(t)
}

fn cubic_coefficients(f0: f64, s0: f64, a: f64, f1: f64, s1: f64) -> (f64, f64) {
    let big_a = f1 - f0 - s0 * a;
    let big_b = s1 - s0;
    let c3 = (big_b * a - 2.0 * big_a) / (a * a * a);
    let c2 = (3.0 * big_a - big_b * a) / (a * a);
    (c2, c3)
}

fn cubic_value(f0: f64, s0: f64, a: f64, f1: f64, s1: f64, t: f64) -> f64 {
    let (c2, c3) = cubic_coefficients(f0, s0, a, f1, s1);
    f0 + t * (s0 + t * (c2 + t * c3))
}

/// New step length after a failed trial at `a` (value `fa`), from `f(0) = f0`,
/// `f'(0) = s0` and, when present, the previous failed trial `(a_prev, f_prev)`.
fn shorten(f0: f64, s0: f64, a: f64, fa: f64, prev: Option<(f64, f64)>) -> f64 {
    let fallback = a / 8.0;
    if !(fa.is_finite() && s0 < 0.0) {
        return fallback;
    }
    let candidate = match prev {
        Some((ap, fp)) if fp.is_finite() && ap > a => {
            // Cubic through f(0), f'(0), f(a), f(ap) (Nocedal & Wright, eq. 3.58).
            let r1 = fa - f0 - s0 * a;
            let r0 = fp - f0 - s0 * ap;
            let den = a * a * ap * ap * (a - ap);
            let ca = (ap * ap * r1 - a * a * r0) / den;
            let cb = (-ap * ap * ap * r1 + a * a * a * r0) / den;
            if ca.abs() < f64::MIN_POSITIVE {
                -s0 / (2.0 * cb)
            } else {
                let disc = cb * cb - 3.0 * ca * s0;
                if disc < 0.0 {
                    f64::NAN
                } else {
                    (-cb + disc.sqrt()) / (3.0 * ca)
                }
            }
        }
        _ => -s0 * a * a / (2.0 * (fa - f0 - s0 * a)),
    };
    if candidate.is_finite() && candidate > 0.0 {
        candidate.clamp(a / 10.0, a / 2.0)
    } else {
        fallback
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(rho_f: f64) -> LineInfo {
        LineInfo {
            f0: 1.0,
            slope0: -1.0,
            alpha: 1.0,
            f_trial: rho_f,
            est_sum: 0.5,
            scaled_step: 1.0,
            gs: -0.5,
        }
    }

    #[test]
    fn nielsen_updates() {
        let mut d = DampingState::new(Damping::Nielsen, 1.0);
        d.accepted(1.0, line(0.5));
        assert!((d.mu() - 1.0 / 3.0).abs() < 1e-15);
        d.accepted(0.5, line(0.5));
        assert!((d.mu() - 1.0 / 3.0).abs() < 1e-15); // 1 - 0^3 = 1
        d.rejected(-1.0, line(2.0));
        assert!((d.mu() - 2.0 / 3.0).abs() < 1e-15);
        d.rejected(-1.0, line(2.0));
        assert!((d.mu() - 8.0 / 3.0).abs() < 1e-15);
        d.accepted(0.75, line(0.5));
        // nu reset to 2, mu scaled by max(1/3, 1 - 0.125)
        assert!((d.mu() - 8.0 / 3.0 * 0.875).abs() < 1e-14);
        d.rejected(-1.0, line(2.0));
        assert!((d.mu() - 8.0 / 3.0 * 0.875 * 2.0).abs() < 1e-14);
    }

    #[test]
    fn gauss_newton_then_nielsen() {
        let mut d = DampingState::new(Damping::GaussNewtonThenNielsen, 1e-3);
        assert_eq!(d.mu(), 0.0);
        // Good steps keep mu = 0.
        d.accepted(0.9, line(0.5));
        d.accepted(0.25, line(0.5));
        assert_eq!(d.mu(), 0.0);
        assert!(d.accepts(0.1, true) && !d.accepts(0.0, true) && !d.accepts(0.5, false));
        // A poor accepted step hands over to Nielsen from mu0 (no Nielsen update on it).
        d.accepted(0.2, line(0.5));
        assert_eq!(d.mu(), 1e-3);
        d.rejected(-1.0, line(2.0));
        assert_eq!(d.mu(), 2e-3);
        d.accepted(1.0, line(0.5));
        assert!((d.mu() - 2e-3 / 3.0).abs() < 1e-18);
        // A rejected or singular Gauss-Newton step hands over too.
        let mut r = DampingState::new(Damping::GaussNewtonThenNielsen, 0.5);
        r.rejected(-1.0, line(2.0));
        assert_eq!(r.mu(), 0.5);
        let mut s = DampingState::new(Damping::GaussNewtonThenNielsen, 0.5);
        s.singular();
        assert_eq!(s.mu(), 0.5);
        s.singular();
        assert_eq!(s.mu(), 1.0);
        assert!(!s.exhausted());
    }

    #[test]
    fn trust_region_radius_updates() {
        let mut d = DampingState::new(Damping::TrustRegion, 1.0);
        assert_eq!(d.mu(), 0.0);
        d.init_radius(2.0, 5.0);
        assert_eq!(d.radius(), 200.0);
        let mut z = DampingState::new(Damping::TrustRegion, 1.0);
        z.init_radius(0.0, 5.0);
        assert_eq!(z.radius(), 5.0);
        // First trial: the radius is capped by the step (1), then a very good step with
        // mu = 0 doubles it.
        d.accepted(1.0, line(0.5));
        assert_eq!(d.radius(), 2.0);
        // A fair step (rho = 0.5) with mu > 0 leaves radius and mu alone.
        d.set_mu(1.0);
        d.accepted(0.5, line(0.5));
        assert_eq!((d.radius(), d.mu()), (2.0, 1.0));
        // A poor step that still lowered the cost halves min(delta, 10 |Dh|).
        d.accepted(0.1, line(0.5));
        assert_eq!((d.radius(), d.mu()), (1.0, 2.0));
        // A step that raised the cost: t from the quadratic, clamped to [0.1, 0.5].
        // f0 = 1, f_trial = 2: actred = -1, dirder = gs / f0 = -0.5 -> t = 0.5 * -0.5 / -1,
        // the minimiser of 1 - t + 2 t^2 (sum of squares 1 at 0, slope 2 gs = -1, 2 at 1).
        d.rejected(-1.0, line(2.0));
        assert!((d.radius() - 0.25).abs() < 1e-15);
        assert!((d.mu() - 8.0).abs() < 1e-12);
        // A huge increase: t = 0.1.
        d.rejected(-1.0, line(1e3));
        assert!((d.radius() - 0.025).abs() < 1e-15);
        // A rejected step of length 1 was the last: a very good shorter step (0.5) grows
        // the radius halfway to the failed length, not to 2 * 0.5 = 1.
        let short = LineInfo {
            scaled_step: 0.5,
            ..line(0.5)
        };
        d.accepted(1.0, short);
        assert!((d.radius() - 0.75).abs() < 1e-15);
        // A success at the failed length (1.25 after relaxing) clears the memory.
        let long = LineInfo {
            scaled_step: 1.25,
            ..line(0.5)
        };
        d.accepted(1.0, long);
        assert_eq!(d.radius(), 2.5);
        assert!(d.accepts(1e-3, true) && !d.accepts(1e-5, true) && !d.accepts(0.5, false));
    }

    #[test]
    fn cubic_minimiser_of_a_quadratic() {
        // f(t) = (t - 2)^2 + 1: f(0) = 5, f'(0) = -4, f(1) = 2, f'(1) = -2 -> t* = 2, f* = 1.
        let t = cubic_minimiser(5.0, -4.0, 1.0, 2.0, -2.0).unwrap();
        assert!((t - 2.0).abs() < 1e-12);
        assert!((cubic_value(5.0, -4.0, 1.0, 2.0, -2.0, t) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn cubic_lambda_rule() {
        let mut d = DampingState::new(Damping::CubicInterpolation, 1.0);
        // Model too pessimistic (EstSum above the cubic's best) -> lambda / (1 + alpha).
        d.accepted(
            1.0,
            LineInfo {
                f0: 5.0,
                slope0: -4.0,
                alpha: 1.0,
                f_trial: 2.0,
                est_sum: 3.0,
                scaled_step: 1.0,
                gs: -2.0,
            },
        );
        assert!(d.needs_slope());
        d.new_slope(-2.0);
        assert!((d.mu() - 0.5).abs() < 1e-15);
        // Model too optimistic -> lambda grows by (fbest - EstSum) / alpha.
        d.accepted(
            1.0,
            LineInfo {
                f0: 5.0,
                slope0: -4.0,
                alpha: 1.0,
                f_trial: 2.0,
                est_sum: 0.5,
                scaled_step: 1.0,
                gs: -2.0,
            },
        );
        d.new_slope(-2.0);
        assert!((d.mu() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn failed_cubic_step_shortens_alpha_only() {
        let mut d = DampingState::new(Damping::CubicInterpolation, 1.0);
        d.rejected(
            -1.0,
            LineInfo {
                f0: 1.0,
                slope0: -1.0,
                alpha: 1.0,
                f_trial: 3.0,
                est_sum: 0.0,
                scaled_step: 1.0,
                gs: -0.5,
            },
        );
        assert_eq!(d.mu(), 1.0);
        // Quadratic: -s0 a^2 / (2 (fa - f0 - s0 a)) = 1 / 6, within [0.1, 0.5].
        assert!((d.step_length() - 1.0 / 6.0).abs() < 1e-15);
        d.rejected(
            -1.0,
            LineInfo {
                f0: 1.0,
                slope0: -1.0,
                alpha: 1.0 / 6.0,
                f_trial: f64::NAN,
                est_sum: 0.0,
                scaled_step: 1.0,
                gs: -0.5,
            },
        );
        assert!((d.step_length() - 1.0 / 48.0).abs() < 1e-15);
    }
}
