"""Fixtures of the Python tests: small simulated logs (the office and corridor worlds), written once
per session. The whole suite is skipped, saying so, when the module is not built (LIDAR2D_BUILD_PYTHON
off, or PYTHONPATH not pointing at build/python)."""
import os

import pytest

lidar2d = pytest.importorskip("lidar2d", reason="the lidar2d module is not built (make python; PYTHONPATH=build/python)")

DATA_DIR = os.environ.get("LIDAR2D_DATA_DIR",
                          os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data"))


@pytest.fixture(scope="session")
def office_frames():
    # 120 scans at 10 Hz along the office route (about 10 m), seed 1.
    return lidar2d.simulate("office", scans=120, seed=1)


@pytest.fixture(scope="session")
def office_log(tmp_path_factory, office_frames):
    path = tmp_path_factory.mktemp("logs") / "office.log"
    lidar2d.write_log(path, office_frames, comment="office world, 120 scans, seed 1")
    return str(path)


@pytest.fixture(scope="session")
def corridor_frames():
    # 200 scans: the start room, then (from about scan 160) down the long corridor.
    return lidar2d.simulate("corridor", scans=200, seed=2)


@pytest.fixture(scope="session")
def office_map(office_frames):
    grid = lidar2d.OccupancyMap(resolution=0.05)
    for frame in office_frames:
        grid.insert(frame)
    return grid.to_image()


def data_path(*parts):
    """A path in the shared data set, or a skip when it is missing."""
    path = os.path.join(DATA_DIR, *parts)
    if not os.path.exists(path):
        pytest.skip(f"{path} missing (set LIDAR2D_DATA_DIR)")
    return path
