"""Scan matching, maps, degeneracy, global localization and evaluation through the bindings."""
import math
import os
import sys

import numpy as np
import pytest

import lidar2d


def relative_truth(a, b):
    return a.truth.inverse() * b.truth


@pytest.mark.parametrize("method", ["p2p", "p2l", "lf", "corr"])
def test_match_scans_every_method(office_frames, method):
    a, b = office_frames[40], office_frames[43]
    truth = relative_truth(a, b)
    init = a.odometry.inverse() * b.odometry
    r = lidar2d.match_scans(a.points(), b.points(), init, method=method)
    assert r.status == "converged" and r.converged and r.iterations >= 1 and r.num_inliers > 50
    assert r.pose.is_approx(truth, 0.03, math.radians(0.5)), (r.pose, truth)
    assert r.information.shape == (3, 3) and np.allclose(r.information, r.information.T)
    assert np.linalg.eigvalsh(r.information).min() > 0
    assert r.covariance.shape == (3, 3)


def test_match_scans_ceres_and_failures(office_frames):
    a, b = office_frames[10], office_frames[11]
    r = lidar2d.match_scans(a.points(), b.points(), method="p2l", solver="ceres")
    assert r.converged and r.pose.is_approx(relative_truth(a, b), 0.03, math.radians(0.5))
    few = lidar2d.match_scans(a.points()[:2], b.points()[:2])
    assert not few.converged and few.status == "too_few_points" and few.pose == lidar2d.SE2()
    with pytest.raises(ValueError, match="not finite"):
        lidar2d.match_scans(a.points(), b.points(), (math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match="shape"):
        lidar2d.match_scans(a.points()[:, 0], b.points())
    with pytest.raises(TypeError):
        lidar2d.match_scans(a.points().astype(str), b.points())
    with pytest.raises(ValueError, match="method"):
        lidar2d.match_scans(a.points(), b.points(), method="ndt")


@pytest.mark.parametrize("method", ["lf", "corr"])
def test_match_scan_to_map(office_frames, office_map, method):
    f = office_frames[60]
    init = f.truth * lidar2d.SE2(0.1, -0.08, math.radians(2))
    r = lidar2d.match_scan_to_map(office_map, f.points(), init, method=method)
    assert r.converged and r.pose.is_approx(f.truth, 0.05, math.radians(1)), (r.pose, f.truth)
    with pytest.raises(ValueError, match="lf"):
        lidar2d.match_scan_to_map(office_map, f.points(), init, method="p2l")


def test_occupancy_map_numpy_save_and_build_map(tmp_path, office_frames, office_map, office_log):
    cells = office_map.cells
    assert cells.dtype == np.int8 and cells.shape == (office_map.height, office_map.width)
    assert set(np.unique(cells)) <= {-1, 0, 100} and (cells == 100).sum() > 500 and (cells == 0).sum() > 5000
    office_map.save(tmp_path / "m.yaml")
    back = lidar2d.load_map(tmp_path / "m.yaml")
    assert np.array_equal(back.cells, cells) and back.resolution == pytest.approx(0.05)
    assert back.origin.is_approx(office_map.origin, 1e-6, 1e-6)
    # The log's map (read from the file, truth poses) is the in-memory map of the same frames.
    built = lidar2d.build_map(office_log)
    assert (built.width, built.height) == (office_map.width, office_map.height)
    assert (built.cells != cells).mean() < 0.001  # the log stores ranges to the millimetre
    counts = lidar2d.OccupancyMap(model="count", resolution=0.1)
    counts.insert(office_frames[0], pose=(0.0, 0.0, 0.0))
    assert counts.scans == 1 and counts.to_numpy().shape[0] > 10
    with pytest.raises(ValueError, match="model"):
        lidar2d.OccupancyMap(model="octomap")
    with pytest.raises(ValueError, match="resolution"):
        lidar2d.OccupancyMap(resolution=-1.0)
    with pytest.raises(ValueError, match="not finite"):
        counts.insert(office_frames[0], pose=(math.nan, 0.0, 0.0))
    with pytest.raises(lidar2d.Error, match="empty"):
        lidar2d.OccupancyMap().to_numpy()
    with pytest.raises(TypeError):
        lidar2d.MapImage(np.zeros((4, 4)), 0.05)
    with pytest.raises(lidar2d.IoError):
        lidar2d.load_map(tmp_path / "none.yaml")


def test_degeneracy(office_frames, corridor_frames):
    room = [lidar2d.analyze_degeneracy(f) for f in corridor_frames[0:150:10]]
    corridor = [lidar2d.analyze_degeneracy(f) for f in corridor_frames[170:200:2]]
    office = lidar2d.analyze_degeneracy(office_frames[5])
    assert not any(d["degenerate"] for d in room), [d["verdict"] for d in room]
    assert all(d["degenerate"] for d in corridor), [d["verdict"] for d in corridor]
    # the free direction is the corridor's axis in the robot frame (the robot drives along it)
    assert all(abs(d["direction_rad"]) < 0.2 for d in corridor), [d["direction_rad"] for d in corridor]
    assert office["verdict"] == "well_constrained" and office["information"].shape == (3, 3)
    few = lidar2d.analyze_degeneracy(np.zeros((3, 2)))
    assert few["verdict"] == "cannot_decide" and few["reason"]
    with pytest.raises(ValueError, match="shape"):
        lidar2d.analyze_degeneracy(np.zeros(10))


def test_global_localization(tmp_path, office_frames, office_map):
    db = lidar2d.build_localization_db(office_map)
    assert db.positions > 10 and db.pairs > 0
    db.save(tmp_path / "office.l2ddb")
    localizer = lidar2d.Localizer(office_map, tmp_path / "office.l2ddb")
    good = 0
    for f in office_frames[1::20]:
        r = localizer.localize(f)
        if not r["declined"]:
            err = r["pose"].inverse() * f.truth
            good += math.hypot(err.x, err.y) < 0.3 and abs(err.theta) < math.radians(5)
    assert good >= 4
    r = localizer.localize(office_frames[21])
    assert r["candidates"] and r["candidates"][0][0].is_approx(r["pose"]), r
    assert all(len(c) == 3 and 0.0 <= c[1] <= 1.0 for c in r["candidates"])
    # the command line's options reach the localizer: no pose explains every point perfectly
    strict = lidar2d.Localizer(office_map, tmp_path / "office.l2ddb", min_score=1.0, threads=1)
    assert all(strict.localize(f)["declined"] for f in office_frames[1::20])
    with pytest.raises(lidar2d.Error, match="min_score"):
        lidar2d.Localizer(office_map, db, min_score=1.5)
    with pytest.raises(lidar2d.Error, match="budget_ms"):
        lidar2d.Localizer(office_map, db, budget_ms=-1.0)
    assert db.positions > 10  # a bad option does not take the database
    taken = lidar2d.Localizer(office_map, db)  # takes the database over
    assert not taken.localize(office_frames[3])["declined"]
    with pytest.raises(ValueError, match="already"):
        db.save(tmp_path / "again.l2ddb")
    other = lidar2d.MapImage(office_map.cells[:-10, :], office_map.resolution, office_map.origin)
    with pytest.raises(lidar2d.Error, match="checksum"):
        lidar2d.Localizer(other, tmp_path / "office.l2ddb")
    (tmp_path / "junk.l2ddb").write_bytes(b"not a database")
    with pytest.raises(lidar2d.Error, match="junk.l2ddb"):
        lidar2d.load_localization_db(tmp_path / "junk.l2ddb")


def test_tracker(office_frames, office_map):
    tracker = lidar2d.Tracker(office_map)
    results = [tracker.add(f) for f in office_frames]
    statuses = [r["status"] for r in results]
    assert set(statuses) <= {"global", "tracking", "lost"}
    assert statuses[0] == "global", results[0]["reason"]  # a sure answer: no initial pose needed
    assert statuses.count("tracking") >= 0.9 * len(office_frames)
    for f, r in zip(office_frames, results):
        if r["status"] == "lost":
            assert r["pose"] is None and r["reason"]
        else:
            err = r["pose"].inverse() * f.truth
            assert math.hypot(err.x, err.y) < 0.5 and abs(err.theta) < math.radians(10), (f.index, r)
    tracker.reset()
    again = tracker.add(office_frames[50])
    assert again["status"] in ("global", "lost") and again["global_seconds"] > 0
    if again["status"] == "global":
        assert again["relocalized"]
    unsure = lidar2d.Tracker(office_map, sure_fix_score=2.0)
    assert [unsure.add(f)["status"] for f in office_frames[:3]] == ["lost", "lost", "global"]
    with pytest.raises(lidar2d.Error, match="min_track_score"):
        lidar2d.Tracker(office_map, min_track_score=1.5)
    with pytest.raises(lidar2d.Error, match="sure_fix_score"):
        lidar2d.Tracker(office_map, sure_fix_score=float("nan"))
    with pytest.raises(lidar2d.Error, match="confirm_fixes_against_odometry"):
        lidar2d.Tracker(office_map, confirm_fixes_against_odometry=0)
    with pytest.raises(lidar2d.Error, match="slide_score_margin"):
        lidar2d.Tracker(office_map, slide_score_margin=-0.1)
    with pytest.raises(lidar2d.Error, match="correction_score_slope"):
        lidar2d.Tracker(office_map, correction_score_slope=2.0)
    with pytest.raises(lidar2d.Error, match="max_beyond_map_m"):
        lidar2d.Tracker(office_map, max_beyond_map_m=0.0)
    with pytest.raises(lidar2d.Error, match="prior_score_margin"):
        lidar2d.Tracker(office_map, prior_score_margin=1.5)
    with pytest.raises(lidar2d.Error, match="max_degenerate_path_m"):
        lidar2d.Tracker(office_map, max_degenerate_path_m=float("nan"))
    # In the map of the whole run no scan needs the recent scans; with them off it tracks alike.
    assert not any(r["beyond_map"] for r in results)
    assert not any(r["odometry_frozen"] for r in results)
    off = lidar2d.Tracker(office_map, recent_scans=0)
    assert [off.add(f)["status"] for f in office_frames] == statuses
    # The odometry's distance scale: learnt from the pinned steps, or 1 as read.
    assert 0.9 <= tracker.odometry_scale <= 1.1
    as_read = lidar2d.Tracker(office_map, learn_odometry_scale=False)
    for f in office_frames[:100]:
        as_read.add(f)
    assert as_read.odometry_scale == 1.0
    with pytest.raises(TypeError):
        tracker.add(np.zeros((10, 2)))


def test_evaluation(tmp_path, office_frames):
    truth = np.array([[f.stamp, f.truth.x, f.truth.y, f.truth.theta] for f in office_frames])
    odom = [(f.stamp, f.odometry) for f in office_frames]
    same = lidar2d.evaluate_trajectory(truth, truth)
    assert same["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9) and same["matched"] == len(office_frames)
    shifted = truth.copy()
    shifted[:, 1] += 1.0
    assert lidar2d.evaluate_trajectory(shifted, truth)["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    unaligned = lidar2d.evaluate_trajectory(shifted, truth, align=False)
    assert unaligned["ate_rmse_m"] == pytest.approx(1.0, abs=1e-9)
    noisy = lidar2d.evaluate_trajectory(odom, truth)
    assert noisy["ate_rmse_m"] > 0.0 and noisy["rpe_pairs"] > 0
    path = tmp_path / "truth.txt"
    lidar2d.write_trajectory(path, truth)
    assert lidar2d.evaluate_trajectory(odom, path)["ate_rmse_m"] == pytest.approx(noisy["ate_rmse_m"])
    # relations of the truth itself: zero error
    rel = np.array([[truth[i, 0], truth[i + 5, 0], *(office_frames[i].truth.inverse() * office_frames[i + 5].truth).to_array()]
                    for i in range(0, 100, 10)])
    r = lidar2d.evaluate_relations(truth, rel)
    assert r["count"] == 10 and r["trans_mean_m"] == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="relations"):
        lidar2d.evaluate_relations(truth, np.zeros((3, 4)))
    with pytest.raises(lidar2d.IoError):
        lidar2d.evaluate_trajectory(tmp_path / "nope.txt", truth)
    with pytest.raises(ValueError, match="not finite"):
        lidar2d.evaluate_trajectory([(0.0, (math.nan, 0, 0))], truth)


def test_map_coverage_bench(office_log, office_frames, office_map):
    # python/bench/map_coverage.py: the share of scans a map explains at their truth poses.
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "python", "bench"))
    from map_coverage import explained_shares

    whole = explained_shares(office_map, office_log)
    assert whole.shape == (len(office_frames),)
    assert np.mean(whole >= 0.5) > 0.95
    # A map of the walls within 5 m of the first 20 scans lacks the rest of the route: the scans
    # that built it are explained, half the others are not.
    grid = lidar2d.OccupancyMap(resolution=0.05, max_range=5.0)
    for frame in office_frames[:20]:
        grid.insert(frame)
    part = explained_shares(grid.to_image(), office_log)
    assert np.all(part[:20] >= 0.5)
    assert np.mean(part >= 0.5) < 0.7
