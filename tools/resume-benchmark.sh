#!/usr/bin/env bash
# The resume benchmark of issue 30, on the raw bags with their Kuemmerle relations: for each bag,
# `lidar2d slam` over the whole bag, and `slam --to HALF` (the first half of its duration) saved, then
# `slam --from HALF --resume first/state.l2d` (the second half as a new session, placed by global
# localization); the two sessions' trajectories together are scored with the relations like the
# single run. Also the state file's size, save and load times (summary.json).
# Usage: tools/resume-benchmark.sh [BUILD_DIR [OUT_DIR]]  (default build, bench-out/resume)
set -euo pipefail
BUILD=${1:-build}
OUT=${2:-bench-out/resume}
BIN=$BUILD/lidar2d
DATA=${LIDAR2D_DATA_DIR:-$(cd "$(dirname "$0")/.." && pwd)/../shared/data}
[ -x "$BIN" ] || { echo "no lidar2d binary at $BIN (build the lidar2d_cli target)" >&2; exit 2; }
mkdir -p "$OUT"
echo "| bag | whole bag [m, deg] | halves, resumed [m, deg] | ratio (m) | second half placed | state.l2d (first half) | save / load [s] |"
echo "|---|---|---|---|---|---|---|"
for d in ${BAGS:-intel fr079 mit-csail}; do
  bag=$DATA/raw/$d.orig.bag
  rel=$DATA/raw/$d.relations
  o=$OUT/$d
  mkdir -p "$o"
  half=$("$BIN" info --json "$bag" | python3 -c 'import json,sys; print(json.load(sys.stdin)["duration_s"] / 2)')
  "$BIN" slam "$bag" -o "$o/whole" -q
  "$BIN" slam "$bag" --to "$half" -o "$o/first" -q
  "$BIN" slam "$bag" --from "$half" --resume "$o/first/state.l2d" -o "$o/resumed" -q
  cat "$o/resumed/trajectory_session1.txt" "$o/resumed/trajectory.txt" >"$o/resumed/both.txt"
  "$BIN" eval "$o/whole/trajectory.txt" --truth "$rel" >"$o/whole.json"
  "$BIN" eval "$o/resumed/both.txt" --truth "$rel" >"$o/resumed.json"
  python3 - "$o" "$d" <<'PY'
import json, os, sys
o, name = sys.argv[1], sys.argv[2]
load = lambda f: json.load(open(os.path.join(o, f)))
w, r = load("whole.json")["relations"], load("resumed.json")["relations"]
f, s = load("first/summary.json"), load("resumed/summary.json")
fmt = lambda e: "%.3f +- %.3f, %.2f +- %.2f" % (e["trans_mean_m"], e["trans_std_m"], e["rot_mean_deg"], e["rot_std_deg"])
placed = "yes (%d relocalization(s))" % s["relocalizations"] if s["fragments"] == 1 else "no: %d fragments" % s["fragments"]
print("| %s | %s | %s | %.2f | %s | %.1f MB | %.2f / %.2f |" % (
    name, fmt(w), fmt(r), r["trans_mean_m"] / w["trans_mean_m"], placed, f["state_bytes"] / 1e6, f["state_save_s"],
    s["state_load_s"]))
PY
done
