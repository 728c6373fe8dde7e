"""The time of ``cpm.gauge_readings`` alone (issue 36): 10^5 gauge readings (simulated,
examples/hexapod_66.toml: 33,334 random poses x 3 sensors, the campaign of ``split.py``)
made into measurements from numpy arrays and lists of names, ROUNDS times. Prints each
round's seconds and the median. Not a test: no time is asserted.

    python python/bench/gauge_readings.py [ROUNDS] [POSES]

Measure with the extension built in release (see ``split.py``). To compare two builds,
run this script with each in turn, several times, interleaved: the machine's speed drifts.
"""
from __future__ import annotations

import statistics
import sys
import time

import cpm
from _campaign import campaign


def main() -> None:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 15
    poses = int(sys.argv[2]) if len(sys.argv) > 2 else 33334
    robot, p, sensors, lengths, labels = campaign(poses)
    seconds = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        m = cpm.gauge_readings(robot, p, sensors, lengths, pose_labels=labels, simulated=True)
        seconds.append(time.perf_counter() - t0)
        assert m.num_readings == len(lengths)
    print(f"gauge_readings of {len(lengths)} SIMULATED readings at {poses} poses: median "
          f"{statistics.median(seconds):.4f} s, min {min(seconds):.4f} s, max "
          f"{max(seconds):.4f} s over {rounds} rounds")


if __name__ == "__main__":
    main()
