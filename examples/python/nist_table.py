"""cpm.lm.least_squares against scipy.optimize.least_squares on the NIST StRD nonlinear
regression problems vendored in crates/cpm-lm/tests/data/nist: exact Jacobians, both starts,
the LRE of the worst parameter (capped at 11) and the time of each solve.

    python examples/python/nist_table.py [--repeat N] [--markdown]

cpm runs with cpm-lm's defaults; SciPy with method 'lm' and 'trf' and its tightest
tolerances (ftol = xtol = gtol = 1e-15, max_nfev 10000). Times are the median of N solves
(default 5), wall clock, Python callbacks included for both.
"""
import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.optimize as so

import cpm.lm

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "python" / "tests"))
import nist  # noqa: E402


def timed(f, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        try:
            out = f()
        except Exception as e:  # a solver failing on a start is its result
            out = e
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    rows = []
    for name, start, x0 in nist.runs():
        d = nist.load(name)
        f, j = nist.problem(d)
        r, tc = timed(lambda: cpm.lm.least_squares(f, x0, jac=j), a.repeat)
        row = [name, start, nist.min_lre(r.x, d.certified), tc]
        for method in ("lm", "trf"):
            s, ts = timed(lambda: so.least_squares(f, x0, jac=j, method=method, ftol=1e-15,
                                                   xtol=1e-15, gtol=1e-15, max_nfev=10000),
                          a.repeat)
            lre = 0.0 if isinstance(s, Exception) else nist.min_lre(s.x, d.certified)
            row += [lre, ts]
        rows.append(row)
    head = ["dataset", "start", "cpm LRE", "cpm ms", "scipy-lm LRE", "scipy-lm ms",
            "scipy-trf LRE", "scipy-trf ms"]
    if a.markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
    else:
        print("{:<9} {:>5} {:>8} {:>8} {:>12} {:>11} {:>13} {:>12}".format(*head))
    for n, s, l1, t1, l2, t2, l3, t3 in rows:
        cells = [n, s, f"{l1:.2f}", f"{1e3 * t1:.2f}", f"{l2:.2f}", f"{1e3 * t2:.2f}",
                 f"{l3:.2f}", f"{1e3 * t3:.2f}"]
        if a.markdown:
            print("| " + " | ".join(map(str, cells)) + " |")
        else:
            print("{:<9} {:>5} {:>8} {:>8} {:>12} {:>11} {:>13} {:>12}".format(*cells))
    arr = np.array([[r[2], r[3], r[4], r[5], r[6], r[7]] for r in rows])
    print(f"\nmin LRE: cpm {arr[:, 0].min():.2f}, scipy-lm {arr[:, 2].min():.2f}, "
          f"scipy-trf {arr[:, 4].min():.2f}; runs with LRE >= 6: cpm {(arr[:, 0] >= 6).sum()}, "
          f"scipy-lm {(arr[:, 2] >= 6).sum()}, scipy-trf {(arr[:, 4] >= 6).sum()} of {len(rows)}")
    print(f"total time: cpm {1e3 * arr[:, 1].sum():.1f} ms, scipy-lm {1e3 * arr[:, 3].sum():.1f}"
          f" ms, scipy-trf {1e3 * arr[:, 5].sum():.1f} ms")
    d = nist.load("BoxBOD")
    f, j = nist.problem(d)
    r, t = timed(lambda: cpm.lm.least_squares(f, d.start1, jac=j, acceleration=True), a.repeat)
    print(f"BoxBOD start 1 with cpm's geodesic acceleration (acceleration=True): LRE "
          f"{nist.min_lre(r.x, d.certified):.2f}, {1e3 * t:.2f} ms (the plain method stops on "
          "the plateau b2 -> infinity, as MINPACK does)")


if __name__ == "__main__":
    main()
