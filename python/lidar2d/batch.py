"""Batch runs: one task per log, as Dask tasks, and one results table.

    python3 -m lidar2d.batch LOG... -o DIR [--task slam|map|localize|eval] [--scheduler ADDRESS]

Runs on a LocalCluster (one single-threaded worker process per --workers) unless --scheduler names
an existing Dask scheduler (`dask scheduler` on one machine, `dask worker ADDRESS` on each of the
others; the logs and DIR must then be on a path every worker sees). --sequential runs the tasks one
after the other in this process, without Dask (the reference for the parallel run's results).

SLAM solves its pose graph on one Ceres thread in every mode: its estimate depends on the count of
Ceres threads (floating-point sums in another order), and a batch's results must not depend on
where it ran. Under Dask a task also runs SLAM without its back-end thread: the workers fill the
cores. That thread changes nothing in the results; --sequential keeps it (--sequential --one-thread
runs the tasks as under Dask, one after the other: the reference for the parallel run's speed).

Writes DIR/results.csv and DIR/results.json, one row per log: log, task, ok, error, seconds, and the
task's figures; each log's outputs go to DIR/<log name>/. A log whose task fails gets ok=False and
its error in the table; the other logs go on. Progress goes to stderr as tasks finish. Exit code 0
when every log succeeded, 1 when one failed, 2 for a usage error.

Tasks (figures in the table):
  map       the map of the log's truth poses (else odometry): DIR/<name>/map.{yaml,pgm};
            scans, width, height, occupied, free, map_sha1
  slam      full SLAM with the defaults: DIR/<name>/trajectory.txt, map.{yaml,pgm};
            scans, nodes, loops, fragments, trajectory_sha1 (+ ate_rmse_m when the log has truth)
  localize  the evaluation protocol of global localization: a map from the even scans at their
            truth poses, then every odd scan localized on its own; localized, declined, success_rate
            (within 0.3 m and 5 deg of the truth), seconds_per_scan
  eval      the log's odometry against its truth: ate_rmse_m, rpe_trans_rmse_m, rpe_rot_rmse_deg
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import sys
import tempfile
import time
import traceback

TASKS = ("slam", "map", "localize", "eval")
BASE_COLUMNS = ["log", "task", "ok", "error", "seconds"]


def _log_name(path: str) -> str:
    name = os.path.basename(os.path.normpath(path))
    for ext in (".gz", ".log", ".clf", ".bag", ".db3", ".mcap"):
        if name.endswith(ext):
            name = name[: -len(ext)]
    return name or "log"


def _out_dirs(logs: list[str], out: str) -> list[str]:
    """One output folder per log, named after it (a suffix keeps equal names apart)."""
    seen: dict[str, int] = {}
    dirs = []
    for log in logs:
        name = _log_name(log)
        k = seen.get(name, 0)
        seen[name] = k + 1
        dirs.append(os.path.join(out, name if k == 0 else f"{name}-{k + 1}"))
    return dirs


def _size(path: str) -> int:
    """Bytes of a log file or folder (0 when it cannot be read: the task reports that)."""
    try:
        if os.path.isdir(path):
            return sum(e.stat().st_size for e in os.scandir(path) if e.is_file())
        return os.path.getsize(path)
    except OSError:
        return 0


def _sha1(data: bytes) -> str:
    return hashlib.sha1(data).hexdigest()[:16]


def _map_figures(image) -> dict:
    cells = image.cells
    return {
        "width": image.width,
        "height": image.height,
        "occupied": int((cells == 100).sum()),
        "free": int((cells == 0).sum()),
        "map_sha1": _sha1(cells.tobytes()),
    }


def _has_truth(log: str) -> bool:
    import lidar2d

    for frame in lidar2d.read_log(log, read_ahead=False):
        return frame.truth is not None
    return False


def _task_map(log: str, out_dir: str, single_thread: bool) -> dict:
    import lidar2d

    image = lidar2d.build_map(log)
    image.save(os.path.join(out_dir, "map.yaml"))
    scans = sum(1 for _ in lidar2d.read_log(log))
    return {"scans": scans, **_map_figures(image)}


def _task_slam(log: str, out_dir: str, single_thread: bool) -> dict:
    import lidar2d

    threads = {"back_end_thread": False, "graph_threads": 1} if single_thread else {"graph_threads": 1}
    result = lidar2d.run_slam(log, out_dir=out_dir, **threads)
    stats = result["stats"]
    trajectory = result["trajectory"]
    figures = {
        "scans": stats["scans"],
        "nodes": stats["nodes"],
        "loops": stats["loop_accepted"],
        "fragments": stats["fragments"],
        "trajectory_sha1": _sha1(trajectory.tobytes()),
    }
    if _has_truth(log):
        figures["ate_rmse_m"] = lidar2d.evaluate_trajectory(trajectory, log)["ate_rmse_m"]
    return figures


def _task_localize(log: str, out_dir: str, single_thread: bool) -> dict:
    import lidar2d

    frames = list(lidar2d.read_log(log))
    if not frames or frames[0].truth is None:
        raise ValueError(f"{log}: the localize task needs truth poses")
    grid = lidar2d.OccupancyMap()
    for frame in frames[0::2]:
        grid.insert(frame)
    image = grid.to_image()
    image.save(os.path.join(out_dir, "map-even.yaml"))
    localizer = lidar2d.Localizer(image)
    localized = declined = successes = 0
    start = time.perf_counter()
    odd = frames[1::2]
    for frame in odd:
        r = localizer.localize(frame)
        if r["declined"]:
            declined += 1
            continue
        localized += 1
        err = r["pose"].inverse() * frame.truth
        if math.hypot(err.x, err.y) <= 0.3 and abs(err.theta) <= math.radians(5.0):
            successes += 1
    elapsed = time.perf_counter() - start
    return {
        "scans": len(odd),
        "localized": localized,
        "declined": declined,
        "success_rate": successes / len(odd) if odd else float("nan"),
        "seconds_per_scan": elapsed / len(odd) if odd else float("nan"),
    }


def _task_eval(log: str, out_dir: str, single_thread: bool) -> dict:
    import lidar2d

    odometry, truth = [], []
    for frame in lidar2d.read_log(log):
        if frame.odometry is None or frame.truth is None:
            raise ValueError(f"{log}: scan {frame.index} lacks odometry or truth (the eval task needs both)")
        odometry.append((frame.stamp, frame.odometry))
        truth.append((frame.stamp, frame.truth))
    lidar2d.write_trajectory(os.path.join(out_dir, "odometry.txt"), odometry)
    r = lidar2d.evaluate_trajectory(odometry, truth)
    return {k: r[k] for k in ("matched", "ate_rmse_m", "rpe_trans_rmse_m", "rpe_rot_rmse_deg")}


_RUNNERS = {"map": _task_map, "slam": _task_slam, "localize": _task_localize, "eval": _task_eval}


def run_task(log: str, task: str, out_dir: str, single_thread: bool = False) -> dict:
    """Runs `task` on one log, writing its outputs under out_dir, on one thread when single_thread;
    never raises: a failure is a row with ok=False and the error's message."""
    start = time.perf_counter()
    row = {"log": log, "task": task, "ok": True, "error": ""}
    try:
        os.makedirs(out_dir, exist_ok=True)
        row.update(_RUNNERS[task](log, out_dir, single_thread))
    except Exception as e:  # noqa: BLE001 - every failure becomes the log's row
        row["ok"] = False
        row["error"] = f"{type(e).__name__}: {e}" if str(e) else traceback.format_exc(limit=1).strip()
    row["seconds"] = round(time.perf_counter() - start, 3)
    return row


def _write_atomic(path: str, text: str) -> None:
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=os.path.basename(path))
    try:
        with os.fdopen(fd, "w", newline="") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def write_results(rows: list[dict], out: str) -> None:
    """DIR/results.csv and DIR/results.json (a list of rows), in the order of the logs given."""
    columns = list(BASE_COLUMNS)
    for row in rows:
        columns += [k for k in row if k not in columns]
    import io

    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow(row)
    _write_atomic(os.path.join(out, "results.csv"), buf.getvalue())
    _write_atomic(os.path.join(out, "results.json"), json.dumps(rows, indent=2) + "\n")


def _progress(done: int, total: int, row: dict, stream) -> None:
    verdict = "ok" if row["ok"] else f"FAILED: {row['error']}"
    print(f"[{done}/{total}] {row['log']} ({row['task']}): {verdict} ({row['seconds']:.1f} s)", file=stream, flush=True)


def run_batch(logs: list[str], out: str, task: str = "slam", scheduler: str | None = None, workers: int = 2,
              sequential: bool = False, stream=sys.stderr, one_thread: bool = False) -> list[dict]:
    """Runs `task` on every log (see the module's doc) and writes the results table; returns its rows."""
    if task not in TASKS:
        raise ValueError(f"task: unknown '{task}' ({', '.join(TASKS)})")
    os.makedirs(out, exist_ok=True)
    dirs = _out_dirs(logs, out)
    rows: list[dict | None] = [None] * len(logs)
    if sequential:
        for i, (log, d) in enumerate(zip(logs, dirs)):
            rows[i] = run_task(log, task, d, one_thread)
            _progress(i + 1, len(logs), rows[i], stream)
    else:
        import dask
        from dask.distributed import Client, LocalCluster, as_completed

        cluster = None
        if scheduler:
            client = Client(scheduler)
        else:
            # Dask's workers default to MALLOC_TRIM_THRESHOLD_=65536, which returns freed memory to the
            # system eagerly; SLAM frees and reallocates scan-sized buffers all the time, and ran 45%
            # slower with it (freiburg-079, single runs). The local workers keep glibc's default.
            environ = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ", {}).items()
                       if k != "MALLOC_TRIM_THRESHOLD_"}
            with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
            client = Client(cluster)
        try:
            # Largest logs first (by bytes on disk, a proxy for their work): a long task started last
            # would leave the other workers idle at the end (longest-processing-time-first scheduling).
            order = sorted(range(len(logs)), key=lambda i: -_size(logs[i]))
            futures = {client.submit(run_task, logs[i], task, dirs[i], True, pure=False, priority=len(logs) - rank,
                                     key=f"lidar2d-{task}-{i}-{os.getpid()}"): i
                       for rank, i in enumerate(order)}
            for done, future in enumerate(as_completed(futures), start=1):
                i = futures[future]
                try:
                    rows[i] = future.result()
                except Exception as e:  # noqa: BLE001 - a worker that died: the log's row says so
                    rows[i] = {"log": logs[i], "task": task, "ok": False, "error": f"{type(e).__name__}: {e}",
                               "seconds": float("nan")}
                _progress(done, len(logs), rows[i], stream)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    write_results(rows, out)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m lidar2d.batch", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("logs", nargs="+", metavar="LOG", help="logs (any format lidar2d reads)")
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="results table and per-log outputs")
    parser.add_argument("--task", default="slam", choices=TASKS, help="what to run on each log (default slam)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (tcp://host:8786)")
    parser.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default 2)")
    parser.add_argument("--sequential", action="store_true", help="no Dask: one log after the other here")
    parser.add_argument("--one-thread", action="store_true",
                        help="with --sequential: each task on one thread, as under Dask (same results)")
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error("--workers must be >= 1")
    if args.sequential and args.scheduler:
        parser.error("--sequential and --scheduler exclude each other")
    if args.one_thread and not args.sequential:
        parser.error("--one-thread needs --sequential (under Dask every task runs on one thread)")
    start = time.perf_counter()
    rows = run_batch(args.logs, args.output, args.task, args.scheduler, args.workers, args.sequential,
                     one_thread=args.one_thread)
    failed = sum(1 for r in rows if not r["ok"])
    print(f"lidar2d.batch: {len(rows) - failed}/{len(rows)} logs ok in {time.perf_counter() - start:.1f} s -> "
          f"{os.path.join(args.output, 'results.csv')}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
