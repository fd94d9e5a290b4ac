#!/bin/bash
# The SLAM benchmark of BENCHMARK.md: lidar2d slam with its default parameters on the raw Radish bags
# (Kuemmerle relation metric, with and without odometry), on a perturbed corrected log (ATE/RPE
# against its truth) and on the simulator's worlds (ATE against truth). Prints a markdown table.
#
#   tools/slam-benchmark.sh [BUILD_DIR] [OUT_DIR]
#
# LIDAR2D_SLAM_CONFIG=FILE.yaml passes `--config FILE.yaml` to every slam run (e.g. to compare with
# `descriptor_loops: false`).
#
# Data from ../shared/data (or $LIDAR2D_DATA_DIR). Wall time, CPU time and peak memory come from
# /usr/bin/time around the whole process (reading the bag, SLAM, writing map and report).
set -euo pipefail
BUILD=${1:-build}
OUT=${2:-bench-out/slam}
BIN=$BUILD/lidar2d
DATA=${LIDAR2D_DATA_DIR:-$(cd "$(dirname "$0")/.." && pwd)/../shared/data}
mkdir -p "$OUT"

row() {  # name log truth [slam args...]
  local name=$1 log=$2 truth=$3
  shift 3
  local dir=$OUT/$name
  local config=()
  if [ -n "${LIDAR2D_SLAM_CONFIG:-}" ]; then config=(--config "$LIDAR2D_SLAM_CONFIG"); fi
  /usr/bin/time -f "%e %U %M" -o "$dir.time" "$BIN" slam "$log" -o "$dir" -q "${config[@]}" "$@"
  "$BIN" eval "$dir/trajectory.txt" --truth "$truth" >"$dir.eval.json"
  python3 - "$dir" "$name" <<'PY'
import json, sys
d, name = sys.argv[1], sys.argv[2]
e = json.load(open(d + ".eval.json"))
wall, user, kb = open(d + ".time").read().split()
s = json.load(open(d + "/summary.json"))
if "relations" in e:
    r = e["relations"]
    acc = "%.4f +- %.4f | %.3f +- %.3f" % (r["trans_mean_m"], r["trans_std_m"], r["rot_mean_deg"], r["rot_std_deg"])
else:
    acc = "ATE %.4f m | ATE %.3f deg" % (e["ate_rmse_m"], e["ate_rot_rmse_deg"])
print("| %s | %s | %d | %s | %s | %d | %.2f | %d / %d |" % (name, acc, s["scans"], wall, user, int(kb) // 1024,
      s["ms_per_scan_mean"], s["loop_closures_accepted"], s["loop_closures_rejected"]))
PY
}

echo "| run | trans error [m] (mean +- std) | rot error [deg] (mean +- std) | scans | wall [s] | CPU [s] | peak MB | ms/scan | loops accepted / rejected |"
echo "|---|---|---|---|---|---|---|---|---|"
for d in intel fr079 mit-csail; do
  row "$d" "$DATA/raw/$d.orig.bag" "$DATA/raw/$d.relations"
done
# fr079's trajectory in the laser frame (its bag's tf_static puts the laser 4 cm ahead of base_link).
row "fr079-laser-frame" "$DATA/raw/fr079.orig.bag" "$DATA/raw/fr079.relations" --pose-frame laser
# The original CARMEN log has the laser 4 cm behind the robot's centre (robot_frontlaser_offset
# -0.04), the bag's tf_static 4 cm ahead of base_link; the relations measure the centre.
row "fr079-carmen-mount" "$DATA/raw/fr079.orig.bag" "$DATA/raw/fr079.relations" --laser-mount=-0.04,0,0
for d in intel fr079 mit-csail; do
  row "$d-no-odometry" "$DATA/raw/$d.orig.bag" "$DATA/raw/$d.relations" --no-odometry
done
# A corrected log with drifting odometry noise, against its truth.
"$BIN" perturb "$DATA/corrected/intel.log.gz" --odom-noise 0.01,0.005,0.005 --seed 1 -o "$OUT/intel-perturbed.log" >/dev/null
row "intel-corrected-perturbed" "$OUT/intel-perturbed.log" "$OUT/intel-perturbed.log"
for w in office corridor symmetric open; do
  "$BIN" simulate --world "$w" --seed 1 -o "$OUT/sim-$w.log" >/dev/null
  row "sim-$w" "$OUT/sim-$w.log" "$OUT/sim-$w.log"
done
