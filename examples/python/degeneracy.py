"""Degeneracy: which scans leave the position free along a direction (a corridor)?

    python3 examples/python/degeneracy.py [OUT_DIR]
"""
import math

import lidar2d

for world in ("corridor", "office"):
    results = [lidar2d.analyze_degeneracy(f) for f in lidar2d.simulate(world, scans=40, seed=1)]
    degenerate = [r for r in results if r["degenerate"]]
    directions = ", ".join(f"{math.degrees(r['direction_rad']):.0f}" for r in degenerate[:5])
    print(f"{world}: {len(degenerate)}/{len(results)} scans degenerate (directions in deg: {directions or '-'})")
