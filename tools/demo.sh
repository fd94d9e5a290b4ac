#!/bin/sh
# make demo: the most complete pipeline that exists, on the built-in simulator's office world.
set -eu
BIN=${1:-build/lidar2d}
OUT=${2:-out}
mkdir -p "$OUT"
echo "== simulate the office world"
"$BIN" simulate --world office --seed 1 -o "$OUT/office.log"
echo "== summary"
"$BIN" info "$OUT/office.log"
echo "== odometry against truth"
"$BIN" eval "$OUT/office.log" --truth "$OUT/office.log" --estimate-from odometry -o "$OUT/odometry-eval.json"
echo
echo "demo wrote:"
for f in "$OUT"/office.log "$OUT"/odometry-eval.json; do echo "  $f"; done
