#!/bin/bash
# Writes the outputs that a behaviour-preserving change must leave byte-identical: `lidar2d slam`,
# `map` and `match` on the three raw Radish bags and on the demo's simulated office.
#
#   tools/reference-outputs.sh BIN OUT_DIR            # run BIN, write its outputs under OUT_DIR
#   tools/reference-outputs.sh --compare DIR_A DIR_B  # cmp every output of A with B's
#
# Timings (summary.json, report.html) are not compared; everything else is, byte for byte.
# Data from ../shared/data (or $LIDAR2D_DATA_DIR). Takes a few minutes on two cores.
set -euo pipefail
if [ "${1:-}" = "--compare" ]; then
  a=$2 b=$3 bad=0 n=0
  while IFS= read -r f; do
    n=$((n + 1))
    if ! cmp -s "$a/$f" "$b/$f"; then
      echo "differs: $f"
      bad=1
    fi
  done < <(cd "$a" && find . -type f ! -name summary.json ! -name report.html ! -name '*.time' | sort)
  if [ "$bad" = 0 ]; then echo "reference-outputs: $n files identical"; fi
  exit $bad
fi
BIN=$1
OUT=$2
DATA=${LIDAR2D_DATA_DIR:-$(cd "$(dirname "$0")/.." && pwd)/../shared/data}
mkdir -p "$OUT"
"$BIN" simulate --world office --seed 1 -o "$OUT/office.log" >/dev/null
logs=("office:$OUT/office.log")
for d in intel fr079 mit-csail; do logs+=("$d:$DATA/raw/$d.orig.bag"); done
for entry in "${logs[@]}"; do
  name=${entry%%:*} log=${entry#*:}
  echo "== $name" >&2
  /usr/bin/time -f "%e s %M KB" -o "$OUT/$name-slam.time" "$BIN" slam "$log" -o "$OUT/$name-slam" -q
  "$BIN" slam "$log" -o "$OUT/$name-slam-noodom" -q --no-odometry
  "$BIN" map "$log" --model logodds -o "$OUT/$name-logodds" >/dev/null
  "$BIN" map "$log" --model tsdf -o "$OUT/$name-tsdf" >/dev/null
  "$BIN" map "$log" --model count --poses "$OUT/$name-slam/trajectory.txt" -o "$OUT/$name-count-slam" >/dev/null
  "$BIN" match "$log" --method p2l -o "$OUT/$name-p2l.txt" >/dev/null 2>&1
  "$BIN" match "$log" --method corr --then p2l --init identity -o "$OUT/$name-corr-p2l.txt" >/dev/null 2>&1
  "$BIN" match "$log" --method lf -o "$OUT/$name-lf.txt" >/dev/null 2>&1
done
echo "reference-outputs: wrote $OUT" >&2
