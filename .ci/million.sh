#!/usr/bin/env bash
# Issue 34's end-to-end figures, reproducible from the repository alone: 10^6 SIMULATED gauge
# readings (62,500 random poses x 16 gauges on the paper's cube,
# tests/data/cube_16_gauges.toml), then `cpm calibrate`, `cpm validate --json` and
# `cpm validate --out` timed in a random order each round by .ci/interleaved.py (median wall
# time and peak memory).
#
#     .ci/million.sh [ROUNDS] [WORK_DIR]          (defaults: 15, target/million)
#     OLD=/path/to/old/cpm .ci/million.sh         (the old binary timed beside the new one)
#
# Not a test and not part of .ci/run: nothing is asserted. Run it with nothing else busy (the
# machine's speed varies from day to day by tens of percent: compare binaries side by side).
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-15}
work=${2:-target/million}
cargo build --release --bin cpm --quiet
root=$(pwd)
cpm=$root/target/release/cpm
mkdir -p "$work"
cp tests/data/cube_16_gauges.toml "$work/cube16.toml"
cd "$work"
if [ ! -f m.csv ]; then
    "$cpm" simulate --robot cube16.toml --random 62500 --seed 5 --noise uniform:10 --out m.csv
fi
rm -rf cal && "$cpm" calibrate --robot cube16.toml --data m.csv --out cal >/dev/null
commands=(
    "calibrate=$cpm calibrate --robot cube16.toml --data m.csv --out /tmp/calx"
    "validate_json=$cpm validate --robot cal/calibrated.toml --data m.csv --json"
    "validate_out=$cpm validate --robot cal/calibrated.toml --data m.csv --out /tmp/valx"
)
if [ -n "${OLD:-}" ]; then
    commands+=(
        "old_calibrate=$OLD calibrate --robot cube16.toml --data m.csv --out /tmp/calx"
        "old_validate_json=$OLD validate --robot cal/calibrated.toml --data m.csv --json"
        "old_validate_out=$OLD validate --robot cal/calibrated.toml --data m.csv --out /tmp/valx"
    )
fi
python3 "$root/.ci/interleaved.py" "$rounds" "${commands[@]}"
