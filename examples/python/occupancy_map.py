"""Occupancy maps: insert scans at their poses, get a NumPy array, save a map_server map.

    python3 examples/python/occupancy_map.py [OUT_DIR]
"""
import os
import sys
import tempfile

import numpy as np

import lidar2d

out = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp()
grid = lidar2d.OccupancyMap(model="logodds", resolution=0.05)
for frame in lidar2d.simulate("office", scans=80, seed=1):
    grid.insert(frame)  # at its truth pose
cells = grid.to_numpy()  # int8: -1 unknown, 0 free, 100 occupied; row 0 at the bottom
print(f"map {cells.shape[1]} x {cells.shape[0]} cells: {np.count_nonzero(cells == 100)} occupied, "
      f"{np.count_nonzero(cells == 0)} free")
grid.save(os.path.join(out, "office.yaml"))
print("wrote", os.path.join(out, "office.yaml"))
