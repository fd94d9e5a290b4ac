"""Scan matching: align each scan to the previous one with every method, and one scan to a map.

    python3 examples/python/scan_matching.py [OUT_DIR]
"""
import math

import lidar2d

frames = lidar2d.simulate("office", scans=30, seed=2)
for method in ("p2p", "p2l", "lf", "corr"):
    errors = []
    for prev, cur in zip(frames, frames[1:]):
        guess = prev.odometry.inverse() * cur.odometry  # T_prev_cur from odometry
        r = lidar2d.match_scans(prev.points(), cur.points(), guess, method=method)
        err = (prev.truth.inverse() * cur.truth).inverse() * r.pose
        errors.append(math.hypot(err.x, err.y))
    print(f"{method:5s} mean translation error {1000 * sum(errors) / len(errors):.1f} mm over {len(errors)} pairs")

grid = lidar2d.OccupancyMap()
for f in frames:
    grid.insert(f)
f = frames[15]
r = lidar2d.match_scan_to_map(grid.to_image(), f.points(), f.truth * lidar2d.SE2(0.2, 0.1, 0.05))
print(f"scan to map: {r.status} after {r.iterations} iterations, information diagonal {r.information.diagonal()}")
