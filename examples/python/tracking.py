"""Tracking in a known map without an initial pose: the first scan is placed by global localization,
then each scan is tracked from the odometry; a robot carried elsewhere is found again.

    python3 examples/python/tracking.py   (writes nothing: the tracker keeps nothing per scan)
"""
import collections
import math

import lidar2d

frames = lidar2d.simulate("office", scans=300, seed=1)
grid = lidar2d.OccupancyMap()
for f in frames[:150]:  # the map from the first half of the run
    grid.insert(f)
tracker = lidar2d.Tracker(grid.to_image())
counts = collections.Counter()
worst = 0.0
for f in frames:  # the whole run: its second half leaves the mapped part now and then
    r = tracker.add(f)
    counts[r["status"]] += 1
    if r["status"] == "tracking":
        err = r["pose"].inverse() * f.truth
        worst = max(worst, math.hypot(err.x, err.y))
    if r["status"] == "global":
        print(f"scan {f.index}: global fix at {r['pose']} (score {r['score']:.2f})")
print(f"{len(frames)} scans: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) +
      f"; largest error while tracking {100 * worst:.1f} cm")
