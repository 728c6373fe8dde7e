#!/usr/bin/env bash
# Runs the same commands with two `cpm` binaries and compares everything they write (files,
# stdout, stderr, exit codes), timings left out: a refactoring that moves code must not change
# an output. Usage: .ci/same_outputs.sh OLD_CPM NEW_CPM [WORK_DIR]
# (build the old one from a worktree of the previous commit: `cargo build --release --bin cpm`).
set -uo pipefail
work=${3:-$(mktemp -d)}
# Both run under the name `cpm` (usage messages name the program).
mkdir -p "$work/bin/old" "$work/bin/new"
cp "$1" "$work/bin/old/cpm" && cp "$2" "$work/bin/new/cpm"
old="$work/bin/old/cpm"; new="$work/bin/new/cpm"
root=$(cd "$(dirname "$0")/.." && pwd)
run_all() {
    local bin=$1 dir=$2
    rm -rf "$work/run" && mkdir -p "$work/run" && cd "$work/run" || exit 2
    cp -r "$root/examples" examples && cp -r "$root/tests/data/jugglebot" mocap && cp -r "$root/tests/data/jugglebot_tilt" tilt
    local n=0
    step() {
        n=$((n + 1))
        "$bin" "$@" >"out_$(printf %02d $n).txt" 2>"err_$(printf %02d $n).txt"
        echo "$?" >"rc_$(printf %02d $n).txt"
    }
    R=examples/hexapod_66.toml
    step simulate --robot $R --truth examples/hexapod_66_truth.toml --random 40 --seed 3 --out sim.csv
    step identifiability --robot $R --data sim.csv --json
    step calibrate --robot $R --data sim.csv --out cal --json
    step calibrate --robot $R --data sim.csv --out cal_text
    step validate --robot cal/calibrated.toml --data examples/hexapod_66_later.csv --out val --json
    step validate --robot cal/calibrated.toml --data examples/hexapod_66_later.csv
    step refine --robot $R --data sim.csv --max-steps 1 --out ref
    step compensate --robot cal/calibrated.toml --poses examples/targets.csv --out commands.csv
    step validate --reference $R --commands commands.csv --truth examples/hexapod_66_truth.toml --out comp
    step export --format linuxcnc --robot cal/calibrated.toml
    step design --robot $R --readings 60 --out design
    step design --robot $R --readings 60 --json --out design_json
    step design --robot $R --sockets design/sockets.csv --readings 60 --criterion d --out design_d
    step design --robot $R --stroke-mm 100 --readings 60 --setups 4 --candidates 200 --out design_limited
    step design --robot $R --instruments gauges,tracker --readings 120 --candidates 200 --out design_mix
    step design --robot $R --readings 60 --base-sockets 50 --out design_refused
    step calibrate --robot tilt/robot.toml --data tilt/session_1.csv --out tilt_cal
    step validate --robot tilt_cal/calibrated.toml --data tilt/session_1.csv --out tilt_val --json
    step calibrate --robot mocap/robot.toml --data mocap/session_108.csv --out mocap_cal
    step validate --robot mocap_cal/calibrated.toml --data mocap/session_108.csv --out mocap_val
    # Point targets (laser-tracker reflectors): three on the platform, a session in a frame
    # of its own (the ingest registers it roughly).
    for f in hexapod_66 hexapod_66_truth; do
        { cat examples/$f.toml; printf '\n[[target]]\nname = "a"\nplatform_mm = [90.0, 10.0, 30.0]\n\n[[target]]\nname = "b"\nplatform_mm = [-50.0, 80.0, 25.0]\n\n[[target]]\nname = "c"\nplatform_mm = [-40.0, -85.0, 35.0]\n'; } > pts_$f.toml
    done
    step simulate --robot pts_hexapod_66.toml --truth pts_hexapod_66_truth.toml --random 30 --seed 4 --measure points --noise gaussian:5 --tracker-frame 1200,-300,40,0,0,30 --out pts.csv
    step calibrate --robot pts_hexapod_66.toml --data pts.csv --out pts_cal --json
    step validate --robot pts_cal/calibrated.toml --data pts.csv --out pts_val --json
    step calibrate --robot $R --data sim.csv --sigma-um=-1 --out bad
    step validate --robot cal/calibrated.toml --data examples/targets.csv
    rm -rf examples mocap tilt
    cd "$work" && rm -rf "$dir" && mv run "$dir"
}
run_all "$old" old
run_all "$new" new
# Timings and the lock/manifest files differ run to run.
normalise() { grep -rIl . "$1" | while read -r f; do sed -i -E 's/[0-9]+(\.[0-9]+)?(ns|µs|us|ms|s)\b/DURATION/g; /"(elapsed|seconds|wall|run_id)[a-z_]*":/d' "$f"; done; }
normalise "$work/old"; normalise "$work/new"
if diff -r -x .cpm-result.json -x bin "$work/old" "$work/new"; then
    echo "same outputs: $(find "$work/new" -type f | wc -l) files compared ($work)"
else
    echo "outputs differ ($work)"; exit 1
fi
