"""Where the time of a calibration from numpy arrays goes (issue 36): 10^5 gauge readings
(simulated, examples/hexapod_66.toml: 33,334 random poses x 3 sensors) made into
measurements, then calibrated in memory. Prints the seconds of each part: inside the fit
(the least-squares solve) and outside it (reading the arrays, loading, the outputs, the
results for Python). Not a test: no time is asserted.

    python python/bench/split.py [POSES] [--effects a,b]

Measure with the extension built in release, as the wheel is (`pip install` of the wheel, or
`cargo build --release -p cpm-py --features cli` copied into a copy of python/cpm): a dev
build (opt-level 2 with debug assertions) makes the fit slower and the split misleading.
"""
from __future__ import annotations

import sys
import time

import cpm
from _campaign import campaign


def main() -> None:
    args = sys.argv[1:]
    effects = None
    if "--effects" in args:
        i = args.index("--effects")
        effects = args[i + 1].split(",")
        del args[i:i + 2]
    poses = int(args[0]) if args else 33334
    robot, p, sensors, lengths, labels = campaign(poses)
    print(f"{len(lengths)} readings at {poses} poses, effects {effects or 'declared'}")
    for run in range(3):
        t0 = time.perf_counter()
        m = cpm.gauge_readings(robot, p, sensors, lengths, pose_labels=labels, simulated=True)
        t1 = time.perf_counter()
        r = cpm.calibrate(robot, m, effects=effects)
        t2 = time.perf_counter()
        t = r.timings
        nan = float("nan")
        job, fit, outputs = t.get("job", nan), t.get("fit", nan), t.get("outputs", nan)
        solver = t.get("solver", nan)
        load = job - fit - outputs
        python = (t2 - t1) - job
        total = t2 - t0
        print(f"run {run + 1}: total {total:.3f} s = arrays->measurements (read and checked: "
              f"reachability, units) {t1 - t0:.3f} s + load {load:.3f} s + fit {fit:.3f} s "
              f"(solver {solver:.3f} s) + outputs (report, figures, residuals, "
              f"calibrated.toml and its read-back) {outputs:.3f} s + results for Python "
              f"{python:.3f} s")
        print(f"    outside the fit: {100 * (total - fit) / total:.0f} % of the total: "
              f"arrays->measurements {100 * (t1 - t0) / total:.0f} % (mostly the reader's "
              f"checks), outputs {100 * outputs / total:.0f} %, results for Python "
              f"{100 * python / total:.1f} %; {r.solver}")


if __name__ == "__main__":
    main()
