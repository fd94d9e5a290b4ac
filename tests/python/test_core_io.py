"""SE2, Frame, logs and trajectory files from Python, and their bad input."""
import gzip
import math
import pickle

import numpy as np
import pytest

import lidar2d


def test_version_and_contract_names():
    assert isinstance(lidar2d.__version__, str) and lidar2d.__version__.count(".") == 2
    for name in ("read_log", "SE2", "Frame", "Slam", "run_slam", "evaluate_trajectory", "Error"):
        assert hasattr(lidar2d, name)


def test_se2_properties():
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.uniform(-5, 5, 2)
        th = rng.uniform(-math.pi, math.pi)
        T = lidar2d.SE2(x, y, th)
        assert (T.x, T.y, T.theta) == pytest.approx((x, y, th))
        assert (T * T.inverse()).is_approx(lidar2d.SE2(), 1e-12, 1e-12)
        assert lidar2d.SE2.exp(T.log()).is_approx(T, 1e-12, 1e-12)
        np.testing.assert_allclose(T.matrix() @ [1.0, 2.0, 1.0], [*(T * np.array([1.0, 2.0])), 1.0], atol=1e-12)
        assert pickle.loads(pickle.dumps(T)) == T
    # composition follows the frame names: T_a_c = T_a_b * T_b_c
    T_a_b, T_b_c = lidar2d.SE2(1, 0, math.pi / 2), lidar2d.SE2(1, 0, 0)
    assert (T_a_b * T_b_c).is_approx(lidar2d.SE2(1, 1, math.pi / 2), 1e-12, 1e-12)
    pts = np.array([[1.0, 0.0], [0.0, 1.0]])
    np.testing.assert_allclose(T_a_b * pts, [[1.0, 1.0], [0.0, 0.0]], atol=1e-12)
    assert lidar2d.SE2(0, 0, 3 * math.pi).theta == pytest.approx(math.pi)


@pytest.mark.parametrize("bad", [(math.nan, 0, 0), (0, math.inf, 0), (0, 0, -math.inf)])
def test_se2_refuses_non_finite(bad):
    with pytest.raises(ValueError, match="not finite"):
        lidar2d.SE2(*bad)


def test_frame_from_arrays_and_bad_arrays():
    ranges = np.full(181, 2.0)
    f = lidar2d.Frame(1.5, ranges, -math.pi / 2, math.pi / 180, 0.1, 10.0, odometry=lidar2d.SE2(1, 2, 0))
    assert f.stamp == 1.5 and len(f) == 181 and f.truth is None and f.odometry.y == 2
    assert f.angles[0] == pytest.approx(-math.pi / 2) and f.angles[-1] == pytest.approx(math.pi / 2)
    assert f.points("laser").shape == (181, 2)
    with pytest.raises(ValueError):  # the view is read-only
        f.ranges[0] = 1.0
    f2 = lidar2d.Frame(0.0, [1, 2, 3], 0.0, 0.1)  # integers are numbers too
    assert f2.ranges.dtype == np.float64
    with pytest.raises(TypeError, match="dtype"):
        lidar2d.Frame(0.0, np.array(["a", "b"]), 0.0, 0.1)
    with pytest.raises(TypeError):
        lidar2d.Frame(0.0, np.array([1 + 2j]), 0.0, 0.1)
    with pytest.raises(ValueError, match="shape"):
        lidar2d.Frame(0.0, np.ones((3, 2)), 0.0, 0.1)
    with pytest.raises(lidar2d.Error, match="angle_increment"):
        lidar2d.Frame(0.0, [1.0, 2.0], 0.0, 0.0)
    with pytest.raises(lidar2d.Error):
        lidar2d.Frame(0.0, [], 0.0, 0.1)
    with pytest.raises(ValueError, match="stamp"):
        lidar2d.Frame(math.nan, [1.0], 0.0, 0.1)


def test_read_log_frames(office_log, office_frames):
    reader = lidar2d.read_log(office_log)
    assert reader.format == "carmen"
    frames = list(reader)
    assert len(frames) == len(office_frames) == 120
    assert "TRUEPOS" in reader.notes()["truth_source"]
    for f, g in zip(frames, office_frames):
        assert isinstance(f.stamp, float) and f.stamp == pytest.approx(g.stamp, abs=1e-6)
        assert f.ranges.dtype == np.float64 and f.ranges.ndim == 1 and f.ranges.shape == f.angles.shape
        assert f.truth.is_approx(g.truth, 1e-5, 1e-5) and f.odometry.is_approx(g.odometry, 1e-5, 1e-5)
        valid = g.valid
        np.testing.assert_allclose(f.ranges[valid], g.ranges[valid], atol=1e-3)
    assert frames[5].index == 5


def test_read_log_bad_input(tmp_path, office_log):
    with pytest.raises(lidar2d.IoError) as e:
        lidar2d.read_log(tmp_path / "missing.log")
    assert "missing.log" in str(e.value) and isinstance(e.value, OSError) and e.value.kind == "io"
    bad = tmp_path / "bad.log"
    lines = open(office_log).read().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("ROBOTLASER1"))
    fields = lines[k].split()
    fields[12] = "abc"  # a range
    lines[k] = " ".join(fields)
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(lidar2d.Error) as e:
        list(lidar2d.read_log(bad))
    assert e.value.file.endswith("bad.log") and e.value.line == k + 1 and str(k + 1) in str(e.value)
    truncated = tmp_path / "truncated.log.gz"
    data = gzip.compress(open(office_log, "rb").read())
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(lidar2d.Error, match="truncated.log.gz"):
        list(lidar2d.read_log(truncated))


def test_trajectory_round_trip_and_bad_input(tmp_path):
    traj = np.array([[0.0, 1.0, 2.0, 0.5], [0.1, 1.5, 2.5, -3.0]])
    path = tmp_path / "t.txt"
    lidar2d.write_trajectory(path, traj)
    np.testing.assert_allclose(lidar2d.read_trajectory(path), traj, atol=1e-9)
    lidar2d.write_trajectory(path, [(0.0, lidar2d.SE2(1, 2, 0.5))], format="tum")
    np.testing.assert_allclose(lidar2d.read_trajectory(path), [[0.0, 1.0, 2.0, 0.5]], atol=1e-9)
    with pytest.raises(ValueError, match="not finite"):
        lidar2d.write_trajectory(path, np.array([[0.0, math.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="shape"):
        lidar2d.write_trajectory(path, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="format"):
        lidar2d.write_trajectory(path, traj, format="csv")
    with pytest.raises(lidar2d.IoError):
        lidar2d.write_trajectory(tmp_path / "no" / "such" / "dir" / "t.txt", traj)
    (tmp_path / "bad.txt").write_text("0 1 2 3\n1 1 x 3\n")
    with pytest.raises(lidar2d.Error, match=r"bad.txt:2"):
        lidar2d.read_trajectory(tmp_path / "bad.txt")


def test_simulate_and_worlds():
    assert {"office", "corridor"} <= set(lidar2d.list_worlds())
    a = lidar2d.simulate("corridor", scans=5, seed=4)
    b = lidar2d.simulate("corridor", scans=5, seed=4)
    assert len(a) == 5 and all(np.array_equal(x.ranges, y.ranges) for x, y in zip(a, b))
    with pytest.raises(lidar2d.Error, match="office"):
        lidar2d.simulate("nowhere")
    # People only shorten beams; the odometry does not see them.
    c = lidar2d.simulate("corridor", scans=50, seed=4, people=8)
    d = lidar2d.simulate("corridor", scans=50, seed=4)
    assert all((x.ranges <= y.ranges).all() for x, y in zip(c, d))
    assert sum(int((x.ranges < y.ranges).sum()) for x, y in zip(c, d)) > 100
    assert all(x.odometry.x == y.odometry.x for x, y in zip(c, d))
    with pytest.raises(lidar2d.Error, match="people"):
        lidar2d.simulate("corridor", people=5000)


def test_read_log_laser_range_max(tmp_path):
    # A declared range max of 10 m below what the laser read (edmonton's log): the readings prove
    # it wrong (returns up to 25 m under the no-return code 51.15), so the reader takes 99% of the
    # code and says so; laser_range_max replaces either, the no-return code above it no return.
    log = tmp_path / "declared.log"
    log.write_text("PARAM robot_front_laser_max 10 nohost 0\n"
                   "FLASER 5 2 12.5 25 51.15 51.15 0 0 0 0 0 0 1 host 1\n")
    reader = lidar2d.read_log(log)
    (frame,) = list(reader)
    assert list(frame.valid) == [True, True, True, False, False]
    assert any("the log's range max (10.00 m) is below what its laser measured" in w
               for w in reader.notes()["warnings"])
    (frame,) = list(lidar2d.read_log(log, laser_range_max=50.0))
    assert list(frame.valid) == [True, True, True, False, False]
    # Kept at 10 m, the reader warns, as `lidar2d info` does: beyond 10 m, 12.5 and 25 m are
    # returns, 51.15 (the most frequent reading there) the no-return code: 2 of 5 beams.
    reader = lidar2d.read_log(log, laser_range_max=10.0)
    (frame,) = list(reader)
    assert list(frame.valid) == [True, False, False, False, False]
    assert reader.notes()["beams_beyond_range_max"] == 2
    assert any("40.0% of the beams read beyond the range max" in w for w in reader.notes()["warnings"])
    reader = lidar2d.read_log(log, laser_range_max=50.0)
    list(reader)
    assert reader.notes()["beams_beyond_range_max"] == 0
    with pytest.raises(lidar2d.Error, match="laser_range_max"):
        lidar2d.read_log(log, laser_range_max=-1.0)
