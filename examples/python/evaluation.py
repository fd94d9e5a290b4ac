"""Evaluation: ATE and RPE of a trajectory against the truth, and relation errors, as dicts.

    python3 examples/python/evaluation.py [OUT_DIR]
"""
import numpy as np

import lidar2d

frames = lidar2d.simulate("corridor", scans=80, seed=5)
truth = np.array([[f.stamp, f.truth.x, f.truth.y, f.truth.theta] for f in frames])
odometry = [(f.stamp, f.odometry) for f in frames]
r = lidar2d.evaluate_trajectory(odometry, truth)
print(f"odometry: ATE {r['ate_rmse_m']:.3f} m, RPE {r['rpe_trans_rmse_m']:.3f} m / {r['rpe_rot_rmse_deg']:.2f} deg")
relations = np.array([[truth[i, 0], truth[i + 10, 0], *(frames[i].truth.inverse() * frames[i + 10].truth).to_array()]
                      for i in range(0, 70, 5)])
print("relations:", lidar2d.evaluate_relations(odometry, relations))
