"""Reading a log: every frame's time, ranges and angles as NumPy arrays, odometry and truth poses.

    python3 examples/python/read_log.py [OUT_DIR] [LOG]

Without LOG it simulates the office world and writes it as a CARMEN log in OUT_DIR first.
"""
import os
import sys
import tempfile

import numpy as np

import lidar2d

out = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp()
log = sys.argv[2] if len(sys.argv) > 2 else os.path.join(out, "office.log")
if len(sys.argv) <= 2:
    lidar2d.write_log(log, lidar2d.simulate("office", scans=50, seed=1))

reader = lidar2d.read_log(log)
stamps, beams, truth = [], [], []
for frame in reader:
    stamps.append(frame.stamp)
    beams.append(np.count_nonzero(frame.valid))
    if frame.truth is not None:
        truth.append((frame.stamp, frame.truth))
print(f"{log}: {len(stamps)} scans ({reader.format}), {stamps[-1] - stamps[0]:.1f} s, "
      f"{np.mean(beams):.0f} valid beams per scan, truth for {len(truth)} scans")
lidar2d.write_trajectory(os.path.join(out, "truth.txt"), truth)
print("wrote", os.path.join(out, "truth.txt"))
