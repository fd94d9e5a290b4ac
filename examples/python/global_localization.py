"""Global localization: build a map's database once, save it, localize single scans without a guess.

    python3 examples/python/global_localization.py [OUT_DIR]
"""
import math
import os
import sys
import tempfile

import lidar2d

out = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp()
frames = lidar2d.simulate("office", scans=120, seed=1)
grid = lidar2d.OccupancyMap()
for f in frames[0::2]:  # the map from the even scans
    grid.insert(f)
image = grid.to_image()
db = lidar2d.build_localization_db(image)
db.save(os.path.join(out, "office.l2ddb"))
localizer = lidar2d.Localizer(image, os.path.join(out, "office.l2ddb"))
for f in frames[1::30]:  # a few odd scans, each on its own
    r = localizer.localize(f)
    if r["declined"]:
        print(f"scan {f.index}: declined ({r['reason']})")
        continue
    err = r["pose"].inverse() * f.truth
    print(f"scan {f.index}: {r['pose']} score {r['score']:.2f}, "
          f"error {100 * math.hypot(err.x, err.y):.1f} cm {math.degrees(abs(err.theta)):.2f} deg")
