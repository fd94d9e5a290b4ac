"""SLAM online (one frame at a time, a pose back for each) and offline (a whole log, with its map).

    python3 examples/python/slam.py [OUT_DIR]
"""
import os
import sys
import tempfile

import lidar2d

out = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp()
frames = lidar2d.simulate("office", scans=100, seed=3)

slam = lidar2d.Slam(submap_nodes=20)  # options as named by `lidar2d slam --dump-config`
for frame in frames:
    pose = slam.add(frame)
print(f"online: last pose {pose}")
slam.finish()
print("online:", {k: slam.stats()[k] for k in ("scans", "nodes", "loop_accepted")})

log = os.path.join(out, "office.log")
lidar2d.write_log(log, frames)
result = lidar2d.run_slam(log, out_dir=out)  # trajectory.txt and map.{yaml,pgm} in out
ate = lidar2d.evaluate_trajectory(result["trajectory"], log)["ate_rmse_m"]
print(f"offline: {result['map'].width} x {result['map'].height} map, ATE {100 * ate:.1f} cm -> {out}")
