"""Binding overhead: the same SLAM run through the program and through Python, interleaved.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/binding_overhead.py build/lidar2d LOG [RUNS]

Per run, three processes on LOG: `lidar2d slam LOG -o DIR --quiet` (its summary.json's slam_s: reading
+ SLAM + final optimisation), `lidar2d.run_slam(LOG, out_dir=DIR)` (the same work as the program but
the PNG, graph and HTML report), and a Python loop `for f in read_log(LOG): slam.add(f)` + finish()
timed like slam_s (every frame crosses into Python and back). Prints the median wall time of each
and the relative difference; checks that the three trajectories are identical.
"""
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

cli, log = sys.argv[1], sys.argv[2]
runs = int(sys.argv[3]) if len(sys.argv) > 3 else 3
work = tempfile.mkdtemp(prefix="lidar2d-overhead-")

LOOP = """
import sys, time, lidar2d
t0 = time.perf_counter()
slam = lidar2d.Slam()
for frame in lidar2d.read_log(sys.argv[1]):
    slam.add(frame)
slam.finish()
t1 = time.perf_counter()
lidar2d.write_trajectory(sys.argv[2], slam.trajectory())
print(t1 - t0)
"""
RUN = """
import sys, time, lidar2d
t0 = time.perf_counter()
lidar2d.run_slam(sys.argv[1], out_dir=sys.argv[2])
print(time.perf_counter() - t0)
"""


def wall(cmd):
    """Wall time [s], CPU time (user + sys) [s] and stdout of a process."""
    r0 = os.times()
    t0 = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    r1 = os.times()
    return time.perf_counter() - t0, (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system), out


res = {"cli": [], "cli_cpu": [], "cli_slam_s": [], "run_slam": [], "run_slam_cpu": [], "loop_slam_s": []}
for i in range(runs):
    d = os.path.join(work, f"cli{i}")
    t, cpu, _ = wall([cli, "slam", log, "-o", d, "--quiet"])
    res["cli"].append(t)
    res["cli_cpu"].append(cpu)
    res["cli_slam_s"].append(json.load(open(os.path.join(d, "summary.json")))["slam_s"])
    d = os.path.join(work, f"py{i}")
    os.makedirs(d)
    t, cpu, _ = wall([sys.executable, "-c", RUN, log, d])
    res["run_slam"].append(t)
    res["run_slam_cpu"].append(cpu)
    _, _, out = wall([sys.executable, "-c", LOOP, log, os.path.join(work, f"loop{i}.txt")])
    res["loop_slam_s"].append(float(out))
    same = open(os.path.join(work, f"cli{i}", "trajectory.txt")).read() == open(os.path.join(d, "trajectory.txt")).read()
    same_loop = open(os.path.join(work, f"cli{i}", "trajectory.txt")).read() == open(os.path.join(work, f"loop{i}.txt")).read()
    print(f"run {i}: " + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in res.items()) +
          f"; trajectories identical: run_slam {same}, loop {same_loop}", flush=True)
med = {k: statistics.median(v) for k, v in res.items()}
print(f"median whole process: lidar2d slam {med['cli']:.2f} s, run_slam {med['run_slam']:.2f} s "
      f"({100 * (med['run_slam'] / med['cli'] - 1):+.1f}%)")
print(f"median CPU time (user + sys): lidar2d slam {med['cli_cpu']:.2f} s, run_slam {med['run_slam_cpu']:.2f} s "
      f"({100 * (med['run_slam_cpu'] / med['cli_cpu'] - 1):+.1f}%)")
print(f"median SLAM time (slam_s): program {med['cli_slam_s']:.2f} s, Python loop {med['loop_slam_s']:.2f} s "
      f"({100 * (med['loop_slam_s'] / med['cli_slam_s'] - 1):+.1f}%)")
