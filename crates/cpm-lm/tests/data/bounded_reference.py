#!/usr/bin/env python3
"""SciPy references for cpm-lm's bound-constrained test set (`tests/bounded.rs`).

Defines the cases (problem, start, box) and solves each with
`scipy.optimize.least_squares`, methods trf (x_scale 1 and 'jac') and dogbox, exact
Jacobians, ftol = xtol = gtol = 1e-15, and writes `bounded_reference.tsv` beside this
script: one line per case with the box, the best cost of the three runs (the reference),
each run's cost and evaluations, the best point, and whether the box cuts the first
Gauss-Newton step. The Rust test reads the cases from that file, so they are defined here
only.

Problems: Moré-Garbow-Hillstrom (ported here from `tests/common/mgh.rs`) and NIST StRD
datasets (`tests/data/nist`, read with `python/tests/nist.py`; residual = model - y).

Run: python3 crates/cpm-lm/tests/data/bounded_reference.py  (numpy, scipy)
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np
import scipy
from scipy.optimize import least_squares

HERE = os.path.dirname(os.path.abspath(__file__))
INF = math.inf
sys.path.insert(0, os.path.join(HERE, "..", "..", "..", "..", "python", "tests"))
import nist as nist_tests  # noqa: E402  (python/tests/nist.py)

# ---------------------------------------------------------------- Moré-Garbow-Hillstrom

BARD_Y = [0.14, 0.18, 0.22, 0.25, 0.29, 0.32, 0.35, 0.39, 0.37, 0.58, 0.73, 0.96, 1.34, 2.10,
          4.39]
KO_Y = [0.1957, 0.1947, 0.1735, 0.1600, 0.0844, 0.0627, 0.0456, 0.0342, 0.0323, 0.0235,
        0.0246]
KO_U = [4.0, 2.0, 1.0, 0.5, 0.25, 0.167, 0.125, 0.1, 0.0833, 0.0714, 0.0625]
OSB1_Y = [0.844, 0.908, 0.932, 0.936, 0.925, 0.908, 0.881, 0.850, 0.818, 0.784, 0.751, 0.718,
          0.685, 0.658, 0.628, 0.603, 0.580, 0.558, 0.538, 0.522, 0.506, 0.490, 0.478, 0.467,
          0.457, 0.448, 0.438, 0.431, 0.424, 0.420, 0.414, 0.411, 0.406]


def mgh(kind: str, n: int, m: int):
    """Residuals and Jacobian of an MGH problem, as `tests/common/mgh.rs`."""

    def f(x):
        r = np.zeros(m)
        j = np.zeros((m, n))
        if kind == "Rosenbrock":
            r[0] = 10 * (x[1] - x[0] ** 2)
            r[1] = 1 - x[0]
            j[0] = [-20 * x[0], 10]
            j[1] = [-1, 0]
        elif kind == "HelicalValley":
            if x[0] > 0:
                th = math.atan(x[1] / x[0]) / (2 * math.pi)
            elif x[0] < 0:
                th = math.atan(x[1] / x[0]) / (2 * math.pi) + 0.5
            else:
                th = math.copysign(0.25, x[1])
            rr = math.hypot(x[0], x[1])
            r[:] = [10 * (x[2] - 10 * th), 10 * (rr - 1), x[2]]
            q = 2 * math.pi * rr * rr
            j[0] = [100 * x[1] / q, -100 * x[0] / q, 10]
            j[1] = [10 * x[0] / rr, 10 * x[1] / rr, 0]
            j[2] = [0, 0, 1]
        elif kind == "PowellSingular":
            s5, s10 = math.sqrt(5), math.sqrt(10)
            r[:] = [x[0] + 10 * x[1], s5 * (x[2] - x[3]), (x[1] - 2 * x[2]) ** 2,
                    s10 * (x[0] - x[3]) ** 2]
            j[0] = [1, 10, 0, 0]
            j[1] = [0, 0, s5, -s5]
            j[2] = [0, 2 * (x[1] - 2 * x[2]), -4 * (x[1] - 2 * x[2]), 0]
            j[3] = [2 * s10 * (x[0] - x[3]), 0, 0, -2 * s10 * (x[0] - x[3])]
        elif kind == "FreudensteinRoth":
            r[0] = -13 + x[0] + ((5 - x[1]) * x[1] - 2) * x[1]
            r[1] = -29 + x[0] + ((x[1] + 1) * x[1] - 14) * x[1]
            j[0] = [1, x[1] * (10 - 3 * x[1]) - 2]
            j[1] = [1, x[1] * (2 + 3 * x[1]) - 14]
        elif kind == "Bard":
            for i in range(15):
                u, v = i + 1.0, 15.0 - i
                w = min(u, v)
                den = v * x[1] + w * x[2]
                r[i] = BARD_Y[i] - (x[0] + u / den)
                j[i] = [-1, u * v / den ** 2, u * w / den ** 2]
        elif kind == "KowalikOsborne":
            for i in range(11):
                u = KO_U[i]
                nu = u * (u + x[1])
                de = u * (u + x[2]) + x[3]
                r[i] = KO_Y[i] - x[0] * nu / de
                j[i] = [-nu / de, -u * x[0] / de, x[0] * nu * u / de ** 2, x[0] * nu / de ** 2]
        elif kind == "Box3d":
            for i in range(m):
                t = (i + 1) / 10.0
                c = math.exp(-t) - math.exp(-10 * t)
                r[i] = math.exp(-t * x[0]) - math.exp(-t * x[1]) - x[2] * c
                j[i] = [-t * math.exp(-t * x[0]), t * math.exp(-t * x[1]), -c]
        elif kind == "JennrichSampson":
            for i in range(m):
                k = i + 1.0
                r[i] = 2 + 2 * k - math.exp(k * x[0]) - math.exp(k * x[1])
                j[i] = [-k * math.exp(k * x[0]), -k * math.exp(k * x[1])]
        elif kind == "BrownDennis":
            for i in range(m):
                t = (i + 1) / 5.0
                a = x[0] + t * x[1] - math.exp(t)
                b = x[2] + math.sin(t) * x[3] - math.cos(t)
                r[i] = a * a + b * b
                j[i] = [2 * a, 2 * a * t, 2 * b, 2 * b * math.sin(t)]
        elif kind == "Osborne1":
            for i in range(33):
                t = 10.0 * i
                e1, e2 = math.exp(-x[3] * t), math.exp(-x[4] * t)
                r[i] = OSB1_Y[i] - (x[0] + x[1] * e1 + x[2] * e2)
                j[i] = [-1, -e1, -e2, t * x[1] * e1, t * x[2] * e2]
        else:
            raise ValueError(kind)
        return r, j

    return f


# ---------------------------------------------------------------------------- NIST StRD


def nist(name: str):
    """Residuals (model - y) and Jacobian of a NIST dataset, from `python/tests/nist.py`
    (the port of `tests/common/nist.rs`)."""
    fun, jac = nist_tests.problem(nist_tests.load(name))
    return lambda b: (fun(b), jac(b))


# --------------------------------------------------------------------------------- cases


def cases():
    """(name, problem, x0, lower, upper)."""
    c = []
    ros = "mgh:Rosenbrock:2:2"
    x = [-1.2, 1.0]
    c += [
        ("rosenbrock-box2", ros, x, [-2, -2], [2, 2]),
        ("rosenbrock-x0-le-0.5", ros, x, [-2, -2], [0.5, 2]),
        ("rosenbrock-x1-le-0.5", ros, [-1.2, 0.5], [-INF, -INF], [INF, 0.5]),
        ("rosenbrock-x0-ge-1.5", ros, [1.8, 1.0], [1.5, -INF], [INF, INF]),
        ("rosenbrock-corner", ros, [-1.2, 0.2], [-2, -2], [0.5, 0.2]),
        ("rosenbrock-start-on-lower", ros, [-2.0, 1.0], [-2, -2], [2, 2]),
        ("rosenbrock-start-on-upper", ros, [-1.2, 1.5], [-2, -2], [2, 1.5]),
        ("rosenbrock-start-on-corner", ros, [0.5, 2.0], [-2, -2], [0.5, 2]),
    ]
    hel = "mgh:HelicalValley:3:3"
    x = [-1.0, 0.0, 0.0]
    c += [
        ("helical-inactive", hel, x, [-10] * 3, [10] * 3),
        ("helical-x0-le-0.5", hel, x, [-INF] * 3, [0.5, INF, INF]),
        ("helical-x2-ge-0.5", hel, [-1.0, 0.0, 0.6], [-INF, -INF, 0.5], [INF] * 3),
    ]
    pow_ = "mgh:PowellSingular:4:4"
    x = [3.0, -1.0, 0.0, 1.0]
    c += [
        ("powell-inactive", pow_, x, [-5] * 4, [5] * 4),
        ("powell-x0-ge-0.1", pow_, x, [0.1, -INF, -INF, -INF], [INF] * 4),
        ("powell-start-on-bound", pow_, x, [3.0, -INF, -INF, -INF], [INF] * 4),
    ]
    fr = "mgh:FreudensteinRoth:2:2"
    x = [0.5, -2.0]
    c += [
        ("freudenstein-roth-box", fr, x, [0, -3], [20, 5]),
        ("freudenstein-roth-x1-le-3.5", fr, x, [-INF, -INF], [INF, 3.5]),
    ]
    bard = "mgh:Bard:3:15"
    x = [1.0, 1.0, 1.0]
    c += [
        ("bard-inactive", bard, x, [0] * 3, [10] * 3),
        ("bard-x2-le-2", bard, x, [-INF] * 3, [INF, INF, 2.0]),
    ]
    ko = "mgh:KowalikOsborne:4:11"
    x = [0.25, 0.39, 0.415, 0.39]
    c += [
        ("kowalik-osborne-inactive", ko, x, [0] * 4, [1] * 4),
        ("kowalik-osborne-x0-le-0.18", ko, [0.15, 0.39, 0.415, 0.39], [-INF] * 4,
         [0.18, INF, INF, INF]),
    ]
    b3 = "mgh:Box3d:3:10"
    x = [0.0, 10.0, 20.0]
    c += [
        ("box3d-start-on-bounds", b3, x, [0, 0, 0], [2, 20, 20]),
        ("box3d-x2-ge-1.5", b3, x, [-INF, -INF, 1.5], [INF] * 3),
    ]
    js = "mgh:JennrichSampson:2:10"
    c += [
        ("jennrich-sampson-inactive", js, [0.3, 0.4], [0, 0], [1, 1]),
        ("jennrich-sampson-x0-ge-0.28", js, [0.3, 0.4], [0.28, -INF], [INF, INF]),
    ]
    bd = "mgh:BrownDennis:4:20"
    x = [25.0, 5.0, -5.0, -1.0]
    c += [
        ("brown-dennis-inactive", bd, x, [-20] * 4, [30] * 4),
        ("brown-dennis-x0-ge-minus-10", bd, x, [-10, -INF, -INF, -INF], [INF] * 4),
    ]
    o1 = "mgh:Osborne1:5:33"
    x = [0.5, 1.5, -1.0, 0.01, 0.02]
    c += [
        ("osborne1-positive-rates", o1, x, [-INF, -INF, -INF, 0, 0], [INF] * 5),
        ("osborne1-x1-le-1.8", o1, x, [-INF] * 5, [INF, 1.8, INF, INF, INF]),
    ]
    # NIST fits with positivity bounds (and a few with an upper bound cutting the solution).
    for name, start, extra_upper in [
        ("Misra1a", 1, None), ("Misra1a", 1, (0, 200.0)),
        ("BoxBOD", 1, None), ("BoxBOD", 2, None), ("BoxBOD", 1, (1, 0.3)),
        ("MGH09", 1, None), ("MGH09", 2, None), ("MGH09", 2, (0, 0.15)),
        ("Rat43", 1, None), ("Rat43", 2, (3, 0.5)),
        ("DanWood", 1, None),
    ]:
        d = nist_tests.load(name)
        x0 = [float(v) for v in (d.start1 if start == 1 else d.start2)]
        n = len(x0)
        upper = [INF] * n
        label = f"{name.lower()}-s{start}-positive"
        if extra_upper is not None:
            k, v = extra_upper
            upper[k] = v
            x0[k] = min(x0[k], v)
            label += f"-b{k + 1}-le-{v:g}"
        c.append((label, f"nist:{name}", x0, [0.0] * n, upper))
    return c


def problem(spec: str):
    parts = spec.split(":")
    if parts[0] == "mgh":
        return mgh(parts[1], int(parts[2]), int(parts[3]))
    return nist(parts[1])


def solve(f, x0, lo, up, method, x_scale):
    t0 = time.perf_counter()
    res = least_squares(lambda x: f(x)[0], x0, jac=lambda x: f(x)[1], bounds=(lo, up),
                        method=method, x_scale=x_scale, ftol=1e-15, xtol=1e-15, gtol=1e-15,
                        max_nfev=20000)
    res.seconds = time.perf_counter() - t0
    return res


def cuts_first_gn_step(f, x0, lo, up):
    r, j = f(np.asarray(x0, float))
    h = np.linalg.lstsq(j, -r, rcond=None)[0]
    t = np.asarray(x0) + h
    return bool(np.any(t < lo) or np.any(t > up))


def fmt(v):
    return ",".join(repr(float(a)) for a in v)


def main():
    np.seterr(all="ignore")  # Rat43's dogbox runs overflow on the way; the costs are kept
    out = os.path.join(HERE, "bounded_reference.tsv")
    rows = []
    for name, spec, x0, lo, up in cases():
        f = problem(spec)
        lo, up, x0 = np.asarray(lo, float), np.asarray(up, float), np.asarray(x0, float)
        runs = {
            "trf": solve(f, x0, lo, up, "trf", 1.0),
            "trf-jac": solve(f, x0, lo, up, "trf", "jac"),
            "dogbox": solve(f, x0, lo, up, "dogbox", 1.0),
        }
        best = min(runs.values(), key=lambda r: r.cost)
        cut = cuts_first_gn_step(f, x0, lo, up)
        rows.append("\t".join([
            name, spec, fmt(x0), fmt(lo), fmt(up), repr(float(best.cost)),
            *(f"{repr(float(r.cost))}\t{r.nfev}" for r in runs.values()),
            fmt(best.x), "cut" if cut else "-",
        ]))
        # Wall times go to stderr only (the data file stays the same from run to run).
        print(f"{name}\tbest {best.cost:.10e}\t" + "\t".join(
            f"{k} {r.cost:.6e} ({r.nfev}, {1e3 * r.seconds:.2f} ms)" for k, r in runs.items()),
            file=sys.stderr)
    header = ("# generated by bounded_reference.py with scipy " + scipy.__version__
              + " numpy " + np.__version__ + "\n"
              + "# name\tproblem\tx0\tlower\tupper\tbest_cost\ttrf_cost\ttrf_nfev"
              + "\ttrf_jac_cost\ttrf_jac_nfev\tdogbox_cost\tdogbox_nfev\tbest_x\tcuts_gn\n")
    with open(out, "w") as fh:
        fh.write(header + "\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
