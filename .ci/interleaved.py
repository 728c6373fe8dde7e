#!/usr/bin/env python3
"""Wall time and peak memory of commands run in turn, in a random order each round (this
machine's first touch of a page is slow and varies from minute to minute: run the old and the
new binary side by side, never one after the other's whole series).

    python3 .ci/interleaved.py ROUNDS 'name=command ...' 'name=command ...' ...

Prints per name the median, mean, min and max wall time (s) and the median peak resident size
(MB), from /usr/bin/time. Output directories /tmp/calx and /tmp/valx are removed before each
run (use them for --out). Not a test: nothing is asserted.
"""
import random
import shlex
import statistics
import subprocess
import sys


def main() -> None:
    rounds = int(sys.argv[1])
    commands = [a.split("=", 1) for a in sys.argv[2:]]
    wall = {name: [] for name, _ in commands}
    peak = {name: [] for name, _ in commands}
    random.seed(1)
    for _ in range(rounds):
        random.shuffle(commands)
        for name, command in commands:
            subprocess.run(["rm", "-rf", "/tmp/calx", "/tmp/valx"], check=True)
            done = subprocess.run(
                ["/usr/bin/time", "-f", "%e %M"] + shlex.split(command),
                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            seconds, kb = done.stderr.strip().splitlines()[-1].split()
            wall[name].append(float(seconds))
            peak[name].append(int(kb) / 1024)
    for name in sorted(wall):
        v = wall[name]
        print(f"{name}: median {statistics.median(v):.3f} s, mean {statistics.mean(v):.3f} s, "
              f"min {min(v):.3f} s, max {max(v):.3f} s; peak median "
              f"{statistics.median(peak[name]):.0f} MB ({' '.join(f'{x:.2f}' for x in v)})")


if __name__ == "__main__":
    main()
