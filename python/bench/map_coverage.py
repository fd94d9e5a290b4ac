"""How much of a log a map can place: the share of its scans that the map explains at their truth poses.

    PYTHONPATH=build/python /usr/bin/python3 python/bench/map_coverage.py MAP.yaml LOG [--min-share S ...]

For every scan of LOG (which needs truth poses), the share of its returns under 30 m that land within
0.1 m of an occupied cell of MAP at the scan's truth pose; prints, per threshold S (default 0.3, 0.5,
0.6, 0.7), the share of scans at or above it. `lidar2d track` needs a map match scoring at least
0.5 (`min_track_score`: this share minus the beams through walls), so the share of scans at 0.5 is
an upper bound on what a map alone can track, whatever the tracker: the rest see mostly ground the
map lacks (a map from half a log). The returns are placed from the laser's pose (the truth pose and
the log's laser mounting).
"""
import argparse
import sys

import numpy as np

import lidar2d


def explained_shares(image: lidar2d.MapImage, log: str, max_range: float = 30.0, near_m: float = 0.1) -> np.ndarray:
    """Per scan of `log`, the share of its returns under `max_range` within `near_m` of an occupied cell.

    The hit term of the localizer's score alone (Localizer::score, not bound to Python, also counts
    beams through walls against a pose): an upper bound on that score."""
    cells = np.asarray(image.cells)  # row 0 at the map's lowest y
    occupied = cells == 100
    reach = int(round(near_m / image.resolution))
    near = np.zeros_like(occupied)
    padded = np.pad(occupied, reach)
    h, w = occupied.shape
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            if dx * dx + dy * dy <= reach * reach:
                near |= padded[reach + dy : reach + dy + h, reach + dx : reach + dx + w]
    shares = []
    for frame in lidar2d.read_log(log):
        if frame.truth is None:
            raise ValueError(f"{log}: scan {frame.index} has no truth pose")
        t = frame.truth * frame.laser_pose
        ok = np.isfinite(frame.ranges) & (frame.ranges > 0) & (frame.ranges < max_range)
        r, a = frame.ranges[ok], frame.angles[ok]
        if r.size == 0:
            shares.append(0.0)
            continue
        ix = np.floor((t.x + r * np.cos(t.theta + a) - image.origin.x) / image.resolution).astype(int)
        iy = np.floor((t.y + r * np.sin(t.theta + a) - image.origin.y) / image.resolution).astype(int)
        inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        shares.append(float(near[iy[inside], ix[inside]].sum()) / r.size)
    return np.array(shares)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("map", help="map_server YAML")
    parser.add_argument("log", help="a log with truth poses")
    parser.add_argument("--min-share", type=float, nargs="+", default=[0.3, 0.5, 0.6, 0.7])
    args = parser.parse_args()
    shares = explained_shares(lidar2d.load_map(args.map), args.log)
    for s in args.min_share:
        print(f"explained at least {s:.2f} at the truth pose: {100.0 * np.mean(shares >= s):.1f}% of {shares.size} scans")
    return 0


if __name__ == "__main__":
    sys.exit(main())
