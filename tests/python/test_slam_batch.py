"""SLAM online and offline, the batch runner (sequential and on a Dask LocalCluster) and the
Python run against the CLI's."""
import csv
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import lidar2d
from lidar2d import batch


def test_slam_online_matches_offline(office_frames, office_log):
    slam = lidar2d.Slam()
    poses = [slam.add(f) for f in office_frames]
    assert all(isinstance(p, lidar2d.SE2) for p in poses)
    slam.finish()
    online = slam.trajectory()
    assert online.shape == (120, 4) and slam.stats()["scans"] == 120
    truth = np.array([[f.stamp, f.truth.x, f.truth.y, f.truth.theta] for f in office_frames])
    assert lidar2d.evaluate_trajectory(online, truth)["ate_rmse_m"] < 0.05
    with pytest.raises(lidar2d.Error, match="finish"):
        slam.add(office_frames[0])
    # Offline on the log is online on the log's frames (the log rounds ranges to 1 mm: other frames).
    offline = lidar2d.Slam().run(office_log)
    again = lidar2d.Slam()
    for f in lidar2d.read_log(office_log):
        again.add(f)
    again.finish()
    np.testing.assert_array_equal(offline, again.trajectory())


def test_slam_options():
    s = lidar2d.Slam(use_odometry=False, submap_nodes=20, node_min_rotation_deg=5)
    o = s.options()
    assert o["use_odometry"] is False and o["submap_nodes"] == 20 and o["node_min_rotation_deg"] == 5
    with pytest.raises(ValueError, match="unknown"):
        lidar2d.Slam(no_such_option=1)
    with pytest.raises(TypeError, match="int"):
        lidar2d.Slam(submap_nodes=2.5)
    with pytest.raises(TypeError, match="bool"):
        lidar2d.Slam(use_odometry=1)
    with pytest.raises(ValueError, match="submap_nodes"):
        lidar2d.Slam(submap_nodes=-3)
    with pytest.raises(ValueError, match="node_min_translation_m"):
        lidar2d.Slam(node_min_translation_m=math.nan)


def test_run_slam_writes_outputs_like_the_cli(tmp_path, office_log):
    out = tmp_path / "py"
    out.mkdir()
    r = lidar2d.run_slam(office_log, out_dir=out)
    assert r["trajectory"].shape == (120, 4) and r["map"].width > 50 and r["stats"]["nodes"] > 5
    assert (out / "trajectory.txt").exists() and (out / "map.yaml").exists() and (out / "map.pgm").exists()
    cli = os.environ.get("LIDAR2D_CLI")
    if not cli:
        pytest.skip("LIDAR2D_CLI not set: no comparison with the program")
    subprocess.run([cli, "slam", office_log, "-o", str(tmp_path / "cli"), "--quiet"], check=True)
    np.testing.assert_array_equal(lidar2d.read_trajectory(tmp_path / "cli" / "trajectory.txt"),
                                  lidar2d.read_trajectory(out / "trajectory.txt"))
    assert (tmp_path / "cli" / "map.pgm").read_bytes() == (out / "map.pgm").read_bytes()


def test_run_slam_bad_input(tmp_path):
    empty = tmp_path / "empty.log"
    empty.write_text("# nothing\n")
    with pytest.raises(lidar2d.Error, match="empty.log"):
        lidar2d.run_slam(empty)
    with pytest.raises(lidar2d.IoError):
        lidar2d.run_slam(tmp_path / "missing.log")


def read_rows(out):
    rows = json.loads((out / "results.json").read_text())
    with open(out / "results.csv") as f:
        csv_rows = list(csv.DictReader(f))
    assert [r["log"] for r in rows] == [r["log"] for r in csv_rows]
    for key in ("log", "task", "ok", "error", "seconds"):
        assert all(key in r for r in rows) and key in csv_rows[0]
    return rows


@pytest.fixture(scope="module")
def batch_logs(tmp_path_factory, office_log):
    d = tmp_path_factory.mktemp("batch")
    corridor = d / "corridor.log"
    lidar2d.write_log(corridor, lidar2d.simulate("corridor", scans=40, seed=3))
    bad = d / "broken.log"
    bad.write_text("FLASER 3 1.0 2.0 x\n")
    return [office_log, str(corridor), str(bad)]


@pytest.mark.parametrize("task,figure", [("map", "map_sha1"), ("slam", "trajectory_sha1")])
def test_batch_sequential_and_dask_agree(tmp_path, batch_logs, task, figure):
    seq = batch.run_batch(batch_logs, str(tmp_path / "seq"), task=task, sequential=True, stream=sys.stdout)
    par = batch.run_batch(batch_logs, str(tmp_path / "par"), task=task, workers=2, stream=sys.stdout)
    for rows in (seq, par):
        assert [r["ok"] for r in rows] == [True, True, False]
        assert "broken.log" in rows[2]["error"] and figure not in rows[2]
    strip = lambda r: {k: v for k, v in r.items() if k != "seconds"}  # noqa: E731
    assert [strip(r) for r in seq] == [strip(r) for r in par]
    assert read_rows(tmp_path / "par")[0][figure] == seq[0][figure]
    assert (tmp_path / "par" / "office" / "map.yaml").exists()


@pytest.mark.parametrize("task", ["slam", "localize", "eval"])
def test_batch_tasks(tmp_path, batch_logs, task):
    rows = batch.run_batch(batch_logs[:1], str(tmp_path), task=task, sequential=True, stream=sys.stdout)
    assert rows[0]["ok"], rows[0]["error"]
    figures = {"slam": "trajectory_sha1", "localize": "success_rate", "eval": "ate_rmse_m"}[task]
    assert figures in rows[0]
    if task == "localize":
        assert rows[0]["success_rate"] > 0.8


def test_batch_command_line(tmp_path, batch_logs):
    env = dict(os.environ)
    r = subprocess.run([sys.executable, "-m", "lidar2d.batch", *batch_logs[1:], "-o", str(tmp_path), "--task", "map",
                        "--sequential"], capture_output=True, text=True, env=env)
    assert r.returncode == 1, r.stderr  # one log failed
    assert "[2/2]" in r.stderr and "1/2 logs ok" in r.stderr
    assert [row["ok"] for row in read_rows(tmp_path)] == [True, False]
    r = subprocess.run([sys.executable, "-m", "lidar2d.batch", "x.log", "-o", str(tmp_path), "--task", "dance"],
                       capture_output=True, text=True, env=env)
    assert r.returncode == 2 and "invalid choice" in r.stderr
    r = subprocess.run([sys.executable, "-m", "lidar2d.batch", "x.log", "-o", str(tmp_path), "--one-thread"],
                       capture_output=True, text=True, env=env)
    assert r.returncode == 2 and "--one-thread needs --sequential" in r.stderr


def test_batch_one_thread_changes_nothing_but_the_threads(tmp_path, batch_logs):
    threads = batch.run_batch(batch_logs[:2], str(tmp_path / "a"), task="slam", sequential=True, stream=sys.stdout)
    one = batch.run_batch(batch_logs[:2], str(tmp_path / "b"), task="slam", sequential=True, stream=sys.stdout,
                          one_thread=True)
    assert [r["trajectory_sha1"] for r in threads] == [r["trajectory_sha1"] for r in one]


EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "python")


@pytest.mark.parametrize("script", sorted(f for f in os.listdir(EXAMPLES) if f.endswith(".py")))
def test_example_runs(tmp_path, script):
    r = subprocess.run([sys.executable, os.path.join(EXAMPLES, script), str(tmp_path)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.strip()
