"""Batch runs on Dask: one task per log, a results table (CSV, JSON), failures isolated.

    python3 examples/python/batch.py [OUT_DIR]

The same as `python3 -m lidar2d.batch LOG... -o OUT_DIR --task map` on a 2-worker LocalCluster;
give scheduler="tcp://host:8786" to run on an existing cluster.
"""
import os
import sys
import tempfile

import lidar2d
from lidar2d.batch import run_batch


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp()
    logs = []
    for world in ("office", "corridor"):
        logs.append(os.path.join(out, f"{world}.log"))
        lidar2d.write_log(logs[-1], lidar2d.simulate(world, scans=40, seed=1))
    logs.append(os.path.join(out, "missing.log"))  # fails, and the others go on

    rows = run_batch(logs, os.path.join(out, "results"), task="map", workers=2)
    for row in rows:
        print(row["log"], "ok" if row["ok"] else row["error"], row.get("occupied", ""))


if __name__ == "__main__":  # Dask's worker processes import this file again
    main()
