#!/bin/sh
# make demo: the most complete pipeline that exists, on the built-in simulator's office world:
# simulate -> summary -> occupancy maps from the true poses -> scan matching -> odometry drift
# against the truth -> full SLAM (map, trajectory, report) and its error against the truth.
set -eu
BIN=${1:-build/lidar2d}
OUT=${2:-out}
mkdir -p "$OUT"
echo "== simulate the office world (scans, noisy odometry, truth)"
"$BIN" simulate --world office --seed 1 -o "$OUT/office.log"
echo "== summary"
"$BIN" info "$OUT/office.log"
echo "== occupancy maps from the true poses (log-odds, TSDF)"
"$BIN" map "$OUT/office.log" --model logodds -o "$OUT/office-logodds" >/dev/null
"$BIN" map "$OUT/office.log" --model tsdf -o "$OUT/office-tsdf" >/dev/null
echo "== scan matching (point-to-line ICP, odometry guess) against the truth"
"$BIN" match "$OUT/office.log" --method p2l --eval -o "$OUT/office-pairs.txt" 2>&1 | grep -E 'success|median'
echo "== odometry against the truth"
"$BIN" eval "$OUT/office.log" --truth "$OUT/office.log" --estimate-from odometry -o "$OUT/odometry-eval.json" |
  grep -E '"(ate_rmse_m|rpe_trans_rmse_m|matched)"' || true
echo "== SLAM (front end, submaps, loop closure, pose graph) and its error against the truth"
"$BIN" slam "$OUT/office.log" -o "$OUT/slam" -q
"$BIN" eval "$OUT/slam/trajectory.txt" --truth "$OUT/office.log" -o "$OUT/slam-eval.json" |
  grep -E '"(ate_rmse_m|rpe_trans_rmse_m|matched)"' || true
echo
echo "SLAM map:    $OUT/slam/map.png (map_server: $OUT/slam/map.yaml)"
echo "SLAM report: $OUT/slam/report.html (open it in a browser)"
echo
echo "demo wrote:"
for f in "$OUT"/office.log "$OUT"/office-logodds.pgm "$OUT"/office-logodds.yaml "$OUT"/office-logodds.png \
  "$OUT"/office-tsdf.pgm "$OUT"/office-tsdf.yaml "$OUT"/office-tsdf.png "$OUT"/office-tsdf.surface.txt \
  "$OUT"/office-pairs.txt "$OUT"/odometry-eval.json "$OUT"/slam/trajectory.txt "$OUT"/slam/map.pgm \
  "$OUT"/slam/map.yaml "$OUT"/slam/map.png "$OUT"/slam/graph.txt "$OUT"/slam/report.html "$OUT"/slam/summary.json \
  "$OUT"/slam-eval.json; do
  echo "  $f"
done
