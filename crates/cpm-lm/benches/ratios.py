#!/usr/bin/env python3
"""Time ratios of a criterion group's cpm-lm runs to the levenberg-marquardt crate's.

Reads criterion's estimates under target/criterion/<group>/<solver>/<case>/new/estimates.json
(the mean point estimate, or the median with --median: steadier on a shared machine) and
prints, per case, both times and cpm-lm's ratio, then the geometric mean of the ratios and
the largest one. With --min: the fastest sample's time per iteration (from sample.json), the
least disturbed by other processes on a loaded machine (they only ever add time).

    cargo bench -p cpm-lm --bench lib -- minpack --warm-up-time 1 --measurement-time 3
    python3 crates/cpm-lm/benches/ratios.py target/criterion/minpack [--median]
"""
import json
import math
import os
import sys

args = [a for a in sys.argv[1:] if not a.startswith("--")]
flags = sys.argv[1:]
statistic = "min" if "--min" in flags else "median" if "--median" in flags else "mean"
root = args[0] if args else "target/criterion/minpack"
ours, theirs = "cpm-lm", "levenberg-marquardt"


def read(path):
    """The statistic of one benchmark, ns."""
    if statistic == "min":
        sample = json.load(open(os.path.join(os.path.dirname(path), "sample.json")))
        return min(t / n for t, n in zip(sample["times"], sample["iters"]))
    return json.load(open(path))[statistic]["point_estimate"]


rows = []
for case in sorted(os.listdir(os.path.join(root, ours))):
    paths = [os.path.join(root, s, case, "new", "estimates.json") for s in (ours, theirs)]
    if not all(os.path.exists(p) for p in paths):
        continue
    a, b = (read(p) for p in paths)
    rows.append((case, a, b, a / b))
print(f"{'case':<36} {'cpm-lm':>12} {'lm crate':>12} {'ratio':>7}")
for case, a, b, r in rows:
    print(f"{case:<36} {a / 1e3:>10.2f}us {b / 1e3:>10.2f}us {r:>7.2f}")
if rows:
    g = math.exp(sum(math.log(r[3]) for r in rows) / len(rows))
    worst = max(rows, key=lambda r: r[3])
    print(
        f"{len(rows)} cases ({statistic}s): geometric mean ratio {g:.3f}, "
        f"largest {worst[3]:.2f} ({worst[0]})"
    )
