"""The SLAM state from Python: save_state, then Slam.resume continues the map with a new session."""
import numpy as np
import pytest

import lidar2d


def test_save_state_and_resume(tmp_path, office_frames, office_log):
    slam = lidar2d.Slam()
    for frame in office_frames[:80]:
        slam.add(frame)
    slam.finish()
    path = tmp_path / "state.l2d"
    slam.save_state(path)
    # The office log again as a second session: placed into the saved map, in its frame.
    resumed = lidar2d.Slam.resume(path, session="again")
    assert resumed.options() == slam.options()
    traj = resumed.run(office_log)
    assert traj.shape == (80 + len(office_frames), 4)
    assert resumed.stats()["fragments"] == 1
    first = slam.trajectory()
    # The resumed recording's poses agree with the saved one's where they overlap.
    second = traj[80:160]
    assert np.max(np.hypot(second[:, 1] - first[:, 1], second[:, 2] - first[:, 2])) < 0.1
    resumed.save_state(tmp_path / "both.l2d")
    assert lidar2d.Slam.resume(tmp_path / "both.l2d").trajectory().shape[0] == traj.shape[0]


def test_resume_bad_state(tmp_path, office_log):
    bad = tmp_path / "bad.l2d"
    bad.write_bytes(b"L2DSLAMS\x07\x00\x00\x00")
    with pytest.raises(Exception, match="version 7 is not supported"):
        lidar2d.Slam.resume(bad)
    with pytest.raises(Exception, match="not a lidar2d SLAM state file"):
        lidar2d.Slam.resume(office_log)
