"""lidar2d: 2D LiDAR scan matching, occupancy mapping, degeneracy analysis, global localization,
SLAM and evaluation, from Python (the C++ library through pybind11).

    import lidar2d
    for frame in lidar2d.read_log("intel.log.gz"):
        frame.stamp, frame.ranges, frame.angles, frame.odometry, frame.truth

Errors of the library raise lidar2d.Error (a ValueError; lidar2d.IoError, also an OSError, when a
file cannot be read or written) with the C++ message naming the file, line and field. Long calls
release the GIL. `python3 -m lidar2d.batch` runs one task per log on Dask (see docs/python.md).
"""
from ._lidar2d import (  # noqa: F401
    __version__,
    Error,
    IoError,
    SE2,
    Frame,
    LogReader,
    read_log,
    read_trajectory,
    write_trajectory,
    read_relations,
    list_worlds,
    simulate,
    write_log,
    MatchResult,
    match_scans,
    match_scan_to_map,
    MapImage,
    load_map,
    OccupancyMap,
    build_map,
    analyze_degeneracy,
    LocalizationDatabase,
    build_localization_db,
    load_localization_db,
    Localizer,
    Tracker,
    Slam,
    run_slam,
    evaluate_trajectory,
    evaluate_relations,
)

__all__ = [
    "__version__", "Error", "IoError", "SE2", "Frame", "LogReader", "read_log", "read_trajectory",
    "write_trajectory", "read_relations", "list_worlds", "simulate", "write_log", "MatchResult",
    "match_scans", "match_scan_to_map", "MapImage", "load_map", "OccupancyMap", "build_map",
    "analyze_degeneracy", "LocalizationDatabase", "build_localization_db", "load_localization_db",
    "Localizer", "Tracker", "Slam", "run_slam", "evaluate_trajectory", "evaluate_relations",
]
