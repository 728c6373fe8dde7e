"""``cpm.lm``: the cpm-lm Levenberg-Marquardt solver for any least-squares fit, with the
calling convention of ``scipy.optimize.least_squares``.

>>> import numpy as np, cpm.lm
>>> t = np.linspace(0, 4, 20); y = 3 * np.exp(-0.7 * t)
>>> r = cpm.lm.least_squares(lambda x: x[0] * np.exp(-x[1] * t) - y, [1.0, 0.1])
>>> bool(r.success), np.round(r.x, 6).tolist()
(True, [3.0, 0.7])

Differences from SciPy, all deliberate:

- ``method``: cpm-lm is a Levenberg-Marquardt solver; ``method="lm"`` (default) is accepted,
  ``"trf"``/``"dogbox"`` raise :class:`cpm.UsageError`. Unlike SciPy's ``lm``, bounds and
  robust losses work with it (an active set and a step that knows the box; Triggs'
  correction). A bounded solve reports ``success`` only at a first-order optimal point of
  the box; one that met a tolerance elsewhere ends ``"Stalled"`` (``status`` 0).
- ``ftol``, ``xtol``, ``gtol`` default to cpm-lm's (1e-15, i.e. to the rounding level), not
  SciPy's 1e-8; ``max_nfev`` is cpm-lm's ``max_evaluations`` (default 10,000).
- ``loss``: ``"linear"``, ``"huber"``, ``"cauchy"`` (SciPy's definitions with ``f_scale``)
  and ``"tukey"``; ``"soft_l1"`` and ``"arctan"`` are not in cpm-lm.
- ``x_scale``: ``"jac"`` (Marquardt's scaling, the default) or ``1.0`` (none).
- ``jac``: a callable (exact), or ``"2-point"``/``"3-point"`` (cpm-lm's finite
  differences, central by default; ``diff_step`` is the relative step).
- The result has SciPy's fields plus ``covariance`` (``sigma^2 (J^T J)^+``), ``std``,
  ``correlation``, ``rank``, ``singular_values``, ``termination`` (cpm-lm's reason),
  ``nit``, ``usable`` (the point can be used: Ceres' ``IsSolutionUsable``) and ``report``.
  ``optimality`` is the gradient's infinity norm, with bounds the projected gradient's,
  ``||x - clip(x - grad, lb, ub)||_inf``; ``active_mask`` marks the parameters on a bound
  (-1 lower, 1 upper). A bounded solve also gives cpm-lm's ``projected_gradient``,
  ``first_order_measure`` (scale-free: the cosine of MINPACK's gradient test in the
  interior) and ``first_order_optimal``. ``fun``, ``jac`` and ``grad`` are evaluated once more at the
  solution (not counted in ``nfev``); the evaluation at ``x0`` that sizes the problem is not
  counted either.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, Optional, Sequence, Tuple, Union

import numpy as np

from . import _cpm
from .errors import UsageError

__all__ = ["least_squares", "LeastSquaresResult"]

# SciPy's status codes from cpm-lm's termination reasons.
_STATUS = {
    "ConvergedGtol": 1,
    "ConvergedFtol": 2,
    "ConvergedXtol": 3,
    "ZeroResidual": 2,
    "MaxIterations": 0,
    "MaxEvaluations": 0,
    "NonFinite": -1,
    "SingularSystem": -1,
    "UserStop": -1,
    "Stalled": 0,
}


class LeastSquaresResult(dict):
    """The solution, with SciPy's ``OptimizeResult`` field names (attribute or key access)
    plus cpm-lm's statistics."""

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError as e:
            raise AttributeError(name) from e

    def __setattr__(self, name: str, value: Any) -> None:
        self[name] = value

    def __dir__(self):
        return list(self.keys())

    def __repr__(self) -> str:
        keys = ["message", "success", "status", "x", "cost", "nfev", "njev", "rank"]
        return "\n".join(f"{k:>12}: {self[k]!r}" for k in keys if k in self)


def _bounds(bounds: Any, n: int) -> Tuple[Optional[list], Optional[list]]:
    if hasattr(bounds, "lb") and hasattr(bounds, "ub"):  # scipy.optimize.Bounds
        lb, ub = bounds.lb, bounds.ub
    else:
        try:
            lb, ub = bounds
        except (TypeError, ValueError):
            raise UsageError("bounds must be (lb, ub)") from None
    lb = np.broadcast_to(np.asarray(lb, dtype=np.float64), (n,)).copy()
    ub = np.broadcast_to(np.asarray(ub, dtype=np.float64), (n,)).copy()
    if np.any(lb >= ub):
        raise UsageError("each lower bound must be below its upper bound")
    lower = None if np.all(np.isneginf(lb)) else lb.tolist()
    upper = None if np.all(np.isposinf(ub)) else ub.tolist()
    return lower, upper


def least_squares(
    fun: Callable[..., Any],
    x0: Union[Sequence[float], np.ndarray, float],
    jac: Union[Callable[..., Any], str, None] = None,
    bounds: Any = (-np.inf, np.inf),
    method: str = "lm",
    ftol: Optional[float] = None,
    xtol: Optional[float] = None,
    gtol: Optional[float] = None,
    x_scale: Union[str, float, None] = None,
    loss: str = "linear",
    f_scale: float = 1.0,
    diff_step: Optional[float] = None,
    max_nfev: Optional[int] = None,
    verbose: int = 0,
    args: Tuple[Any, ...] = (),
    kwargs: Optional[Dict[str, Any]] = None,
    *,
    damping: str = "trust-region",
    max_iterations: Optional[int] = None,
    acceleration: bool = False,
) -> LeastSquaresResult:
    """Minimises ``0.5 * sum(rho(fun(x)**2))`` with cpm-lm (see the module documentation for
    the differences from ``scipy.optimize.least_squares``).

    ``fun(x, *args, **kwargs)`` returns the ``m`` residuals, ``jac(x, *args, **kwargs)`` the
    ``(m, n)`` Jacobian. ``damping`` chooses cpm-lm's schedule (``"trust-region"``,
    ``"nielsen"``, ``"marquardt"``, ``"cubic"``), ``acceleration=True`` geodesic
    acceleration. The GIL is released between evaluations; Ctrl-C stops the solve at the next
    iteration (``KeyboardInterrupt``); an exception of ``fun`` or ``jac`` propagates."""
    if method not in (None, "lm"):
        raise UsageError(f"method={method!r}: cpm-lm is a Levenberg-Marquardt solver "
                         "(method='lm'); it takes bounds and robust losses itself")
    kwargs = kwargs or {}
    if np.iscomplexobj(x0):
        raise UsageError("x0: complex numbers; cpm-lm solves in real numbers (as SciPy's "
                         "least_squares, which refuses a complex x0)")
    x = np.atleast_1d(np.asarray(x0, dtype=np.float64)).copy()
    if x.ndim != 1:
        raise UsageError(f"x0 must be 1-D, got shape {x.shape}")
    n = x.size

    def f(v: np.ndarray) -> np.ndarray:
        r = np.asarray(fun(v, *args, **kwargs), dtype=np.float64)
        if r.ndim > 1:
            raise ValueError(f"fun must return a 1-D array, got shape {r.shape}")
        return np.atleast_1d(r)

    r0 = f(x.copy())
    m = r0.size
    if callable(jac):
        def j(v: np.ndarray) -> np.ndarray:
            a = jac(v, *args, **kwargs)
            if hasattr(a, "toarray"):  # a sparse matrix
                a = a.toarray()
            return np.atleast_2d(np.asarray(a, dtype=np.float64))
        jac_fn: Optional[Callable[[np.ndarray], np.ndarray]] = j
        diff = "3-point"
    elif jac in (None, "3-point", "2-point", "cs"):
        if jac == "cs":
            raise UsageError("jac='cs' (complex step) is not in cpm-lm: use '2-point' or "
                             "'3-point'")
        jac_fn, diff = None, (jac or "3-point")
    else:
        raise UsageError(f"jac={jac!r}: a callable, '2-point' or '3-point'")
    if x_scale is None or (isinstance(x_scale, str) and x_scale == "jac"):
        scale = "jac"
    elif np.all(np.asarray(x_scale) == 1.0):
        scale = "identity"
    else:
        raise UsageError("x_scale: 'jac' (Marquardt's scaling) or 1.0 (none); cpm-lm has no "
                         "per-parameter scale")
    lower, upper = _bounds(bounds, n)
    settings = dict(lower=lower, upper=upper, loss=loss, f_scale=float(f_scale), ftol=ftol,
                    xtol=xtol, gtol=gtol, max_nfev=max_nfev, max_iterations=max_iterations,
                    damping=damping, x_scale=scale, acceleration=bool(acceleration))
    d = _cpm.least_squares(f, x.tolist(), m, jac_fn, diff, diff_step, settings)
    res = LeastSquaresResult(d)
    xs = np.asarray(res["x"], dtype=np.float64)
    res["x"] = xs
    res["fun"] = f(xs.copy())
    if jac_fn is not None:
        res["jac"] = jac_fn(xs.copy())
    else:
        # Central differences at the solution, as the solver's own.
        h = (diff_step or np.finfo(float).eps ** (1 / 3)) * np.where(xs != 0, np.abs(xs), 1.0)
        cols = [(f(xs + h[k] * np.eye(n)[k]) - f(xs - h[k] * np.eye(n)[k])) / (2 * h[k])
                for k in range(n)]
        res["jac"] = np.stack(cols, axis=1) if cols else np.zeros((m, 0))
    # The gradient of the cost with the loss's weights rho'(f^2 / f_scale^2).
    z = (res["fun"] / f_scale) ** 2
    if loss == "huber":
        w = np.where(z <= 1, 1.0, 1.0 / np.sqrt(np.maximum(z, 1e-300)))
    elif loss == "cauchy":
        w = 1.0 / (1.0 + z)
    elif loss == "tukey":
        w = np.where(z <= 1, (1 - z) ** 2, 0.0)
    else:
        w = np.ones_like(z)
    res["grad"] = res["jac"].T @ (w * res["fun"])
    lb = np.asarray(lower, dtype=np.float64) if lower is not None else np.full(n, -np.inf)
    ub = np.asarray(upper, dtype=np.float64) if upper is not None else np.full(n, np.inf)
    # The projected gradient (the gradient itself without bounds), as SciPy's optimality.
    pg = xs - np.clip(xs - res["grad"], lb, ub)
    res["optimality"] = float(np.max(np.abs(pg))) if n else 0.0
    if "active_mask" in res:
        res["active_mask"] = np.asarray(res["active_mask"], dtype=int)
    else:
        active = np.zeros(n, dtype=int)
        active[xs <= lb] = -1
        active[xs >= ub] = 1
        res["active_mask"] = active
    res["status"] = _STATUS.get(res["termination"], -1)
    if verbose:
        print(res["report_full"] if verbose >= 2 else res["report"])
    return res
