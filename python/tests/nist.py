"""NIST StRD nonlinear regression problems for the Python tests: the parser, the models with
exact Jacobians and the LRE, ported from crates/cpm-lm/tests/common/nist.rs (the vendored
data files of crates/cpm-lm/tests/data/nist are read from the repository)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Tuple

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "crates" / "cpm-lm" / "tests" / "data" / "nist"

# The 23 vendored datasets, in NIST's order of difficulty (as nist.rs).
NAMES = [
    "Misra1a", "Chwirut2", "Chwirut1", "Lanczos3", "Gauss1", "Gauss2", "DanWood", "Misra1b",
    "Kirby2", "Nelson", "MGH17", "Lanczos1", "Lanczos2", "Gauss3", "Misra1c", "Misra1d",
    "Roszman1", "ENSO", "MGH09", "Thurber", "Rat42", "Rat43", "BoxBOD",
]


@dataclass
class Dataset:
    name: str
    start1: np.ndarray
    start2: np.ndarray
    certified: np.ndarray
    certified_sd: np.ndarray
    certified_rss: float
    x: np.ndarray  # (columns, n)
    y: np.ndarray


def load(name: str) -> Dataset:
    lines = (DATA / f"{name}.dat").read_text().splitlines()
    s1, s2, c, sd = [], [], [], []
    rss = math.nan
    data_line = None
    for k, line in enumerate(lines):
        t = line.strip()
        if t.startswith("b") and "=" in t:
            rest = t.split("=")[1].split()
            if len(rest) == 4:
                s1.append(float(rest[0]))
                s2.append(float(rest[1]))
                c.append(float(rest[2]))
                sd.append(float(rest[3]))
        elif t.startswith("Residual Sum of Squares:"):
            rss = float(t.split(":")[1].strip())
        elif line.startswith("Data:") and "y" in t:
            data_line = k
    assert data_line is not None, name
    rows = [list(map(float, ln.split())) for ln in lines[data_line + 1:] if ln.split()]
    a = np.array(rows)
    return Dataset(name, np.array(s1), np.array(s2), np.array(c), np.array(sd), rss,
                   a[:, 1:].T.copy(), a[:, 0].copy())


Model = Callable[[np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray]]


def _misra1a(b, x):
    t = x[0]
    e = np.exp(-b[1] * t)
    return b[0] * (1 - e), np.stack([1 - e, b[0] * t * e], 1)


def _misra1b(b, x):
    t = x[0]
    u = 1 + b[1] * t / 2
    return b[0] * (1 - u ** -2), np.stack([1 - u ** -2, b[0] * t * u ** -3], 1)


def _misra1c(b, x):
    t = x[0]
    u = 1 + 2 * b[1] * t
    return b[0] * (1 - u ** -0.5), np.stack([1 - u ** -0.5, b[0] * t * u ** -1.5], 1)


def _misra1d(b, x):
    t = x[0]
    u = 1 + b[1] * t
    return b[0] * b[1] * t / u, np.stack([b[1] * t / u, b[0] * t / u ** 2], 1)


def _chwirut(b, x):
    t = x[0]
    den = b[1] + b[2] * t
    f = np.exp(-b[0] * t) / den
    return f, np.stack([-t * f, -f / den, -t * f / den], 1)


def _danwood(b, x):
    t = x[0]
    p = t ** b[1]
    return b[0] * p, np.stack([p, b[0] * p * np.log(t)], 1)


def _lanczos(b, x):
    t = x[0]
    f = np.zeros_like(t)
    cols = []
    for k in range(3):
        e = np.exp(-b[2 * k + 1] * t)
        cols += [e, -b[2 * k] * t * e]
        f = f + b[2 * k] * e
    return f, np.stack(cols, 1)


def _gauss(b, x):
    t = x[0]
    e0 = np.exp(-b[1] * t)
    d1, d2 = t - b[3], t - b[6]
    e1 = np.exp(-d1 * d1 / b[4] ** 2)
    e2 = np.exp(-d2 * d2 / b[7] ** 2)
    j = np.stack([e0, -b[0] * t * e0, e1, b[2] * e1 * 2 * d1 / b[4] ** 2,
                  b[2] * e1 * 2 * d1 * d1 / b[4] ** 3, e2, b[5] * e2 * 2 * d2 / b[7] ** 2,
                  b[5] * e2 * 2 * d2 * d2 / b[7] ** 3], 1)
    return b[0] * e0 + b[2] * e1 + b[5] * e2, j


def _kirby2(b, x):
    t = x[0]
    nu = b[0] + b[1] * t + b[2] * t * t
    de = 1 + b[3] * t + b[4] * t * t
    return nu / de, np.stack([1 / de, t / de, t * t / de, -nu * t / de ** 2,
                              -nu * t * t / de ** 2], 1)


def _thurber(b, x):
    t = x[0]
    nu = b[0] + t * (b[1] + t * (b[2] + t * b[3]))
    de = 1 + t * (b[4] + t * (b[5] + t * b[6]))
    return nu / de, np.stack([1 / de, t / de, t ** 2 / de, t ** 3 / de, -nu * t / de ** 2,
                              -nu * t ** 2 / de ** 2, -nu * t ** 3 / de ** 2], 1)


def _mgh09(b, x):
    t = x[0]
    nu = t * t + t * b[1]
    de = t * t + t * b[2] + b[3]
    return b[0] * nu / de, np.stack([nu / de, b[0] * t / de, -b[0] * nu * t / de ** 2,
                                     -b[0] * nu / de ** 2], 1)


def _mgh17(b, x):
    t = x[0]
    e1, e2 = np.exp(-t * b[3]), np.exp(-t * b[4])
    return b[0] + b[1] * e1 + b[2] * e2, np.stack(
        [np.ones_like(t), e1, e2, -b[1] * t * e1, -b[2] * t * e2], 1)


def _nelson(b, x):
    x1, x2 = x[0], x[1]
    e = np.exp(-b[2] * x2)
    return b[0] - b[1] * x1 * e, np.stack([np.ones_like(x1), -x1 * e, b[1] * x1 * x2 * e], 1)


def _rat42(b, x):
    t = x[0]
    e = np.exp(b[1] - b[2] * t)
    u = 1 + e
    return b[0] / u, np.stack([1 / u, -b[0] * e / u ** 2, b[0] * t * e / u ** 2], 1)


def _rat43(b, x):
    t = x[0]
    e = np.exp(b[1] - b[2] * t)
    u = 1 + e
    p = u ** (-1 / b[3])
    return b[0] * p, np.stack([p, -b[0] * p * e / (b[3] * u), b[0] * p * e * t / (b[3] * u),
                               b[0] * p * np.log(u) / b[3] ** 2], 1)


def _roszman1(b, x):
    t = x[0]
    d = t - b[3]
    u = b[2] / d
    w = 1 / (math.pi * (1 + u * u))
    # NIST's arctan takes values in (0, pi) here: the branch of atan2(b3, x - b4).
    return b[0] - b[1] * t - np.arctan2(b[2], d) / math.pi, np.stack(
        [np.ones_like(t), -t, -w / d, -w * b[2] / d ** 2], 1)


def _enso(b, x):
    t = x[0]
    w = 2 * math.pi * t
    a0, s0 = np.cos(w / 12), np.sin(w / 12)
    a1, s1 = np.cos(w / b[3]), np.sin(w / b[3])
    a2, s2 = np.cos(w / b[6]), np.sin(w / b[6])
    g3 = (-b[4] * s1 + b[5] * a1) * (-w / b[3] ** 2)
    g6 = (-b[7] * s2 + b[8] * a2) * (-w / b[6] ** 2)
    f = b[0] + b[1] * a0 + b[2] * s0 + b[4] * a1 + b[5] * s1 + b[7] * a2 + b[8] * s2
    return f, np.stack([np.ones_like(t), a0, s0, g3, a1, s1, g6, a2, s2], 1)


MODELS: Dict[str, Model] = {
    "Misra1a": _misra1a, "BoxBOD": _misra1a, "Misra1b": _misra1b, "Misra1c": _misra1c,
    "Misra1d": _misra1d, "Chwirut1": _chwirut, "Chwirut2": _chwirut, "DanWood": _danwood,
    "Lanczos1": _lanczos, "Lanczos2": _lanczos, "Lanczos3": _lanczos, "Gauss1": _gauss,
    "Gauss2": _gauss, "Gauss3": _gauss, "Kirby2": _kirby2, "Thurber": _thurber,
    "MGH09": _mgh09, "MGH17": _mgh17, "Nelson": _nelson, "Rat42": _rat42, "Rat43": _rat43,
    "Roszman1": _roszman1, "ENSO": _enso,
}


def problem(d: Dataset) -> Tuple[Callable, Callable]:
    """Residuals ``f(b; x) - y`` (``log y`` for Nelson) and their exact Jacobian."""
    model = MODELS[d.name]
    y = np.log(d.y) if d.name == "Nelson" else d.y

    def fun(b):
        with np.errstate(all="ignore"):  # solvers try wild steps; inf/nan are their business
            return model(np.asarray(b), d.x)[0] - y

    def jac(b):
        with np.errstate(all="ignore"):
            return model(np.asarray(b), d.x)[1]

    return fun, jac


def lre(est: float, cert: float) -> float:
    """``-log10(|est - cert| / |cert|)`` capped at 11 (0 when not finite), as nist.rs."""
    if est == cert:
        return 11.0
    with np.errstate(all="ignore"):
        v = -math.log10(abs(est - cert) / abs(cert)) if abs(est - cert) > 0 else 11.0
    if not math.isfinite(v):
        return 0.0
    return min(max(v, 0.0), 11.0)


def min_lre(est, cert) -> float:
    return min(lre(float(e), float(c)) for e, c in zip(est, cert))


def runs() -> List[Tuple[str, int, np.ndarray]]:
    """Every (dataset, start number, start) of the table."""
    out = []
    for name in NAMES:
        d = load(name)
        out += [(name, 1, d.start1), (name, 2, d.start2)]
    return out
