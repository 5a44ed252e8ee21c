"""Benchmark of the execution layer (:mod:`ptw_env.jobs`, issue 22): a 200-episode evaluation sweep
serially, in local processes and on a 2-worker Dask LocalCluster, each as a ratio of the serial run
measured in the same run; the per-job overhead of each executor (trivial jobs, with and without the
results file); and, from the measured per-episode cost, a *projection* of 1 M episodes on 100 workers.

Usage::

    python scripts/bench_jobs.py [--episodes 200] [--workers 2] [--trivial 2000]

The sweep: the TS and LQR controllers on the double lane change at 50 km/h, 5 % noise, seeds 0..
(episodes/2 - 1) each (:func:`assist.evaluate.run_sweep`); the rows are compared across executors.
The Dask rows need the ``[cluster]`` extra and are skipped without it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from _outputs import local_executors  # scripts/_outputs.py (python scripts/NAME.py puts scripts/ on sys.path)


def _timed(fn, *a, **kw):
    t0 = time.perf_counter()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    from ptw_env.cli import WORKERS, number

    ap.add_argument("--episodes", type=number(2, 1e6, integer=True), default=200,
                    help="episodes of the sweep (even; default 200)")
    ap.add_argument("--workers", type=WORKERS, default=2, help="processes / Dask workers (default 2)")
    ap.add_argument("--trivial", type=number(1, 1e7, integer=True), default=2000,
                    help="trivial jobs for the overhead (default 2000)")
    a = ap.parse_args(argv)

    from assist.evaluate import run_sweep, sweep_points
    from ptw_env.jobs import echo, run_jobs

    executors = local_executors(a.workers)
    points = sweep_points(["ts", "lqr"], ["double_lane_change"], [50.0], list(range(a.episodes // 2)))
    run_sweep(points[:1], progress=False)  # the TS design and numba's cache, not timed

    print(f"sweep of {len(points)} episodes (ts and lqr, double lane change at 50 km/h, 5 % noise)")
    ref = rows_ref = None
    for name, kw in executors:
        rows, sec = _timed(run_sweep, points, progress=False, **kw)
        if ref is None:
            ref, rows_ref = sec, rows
        same = "identical rows" if rows == rows_ref else "DIFFERENT rows"
        print(f"  {name:<30} {sec:7.1f} s  {sec / ref:5.2f}x serial  {1000 * sec / len(points):6.1f} ms/episode  {same}")
    per_episode = ref / len(points)
    dask_slope = None

    print(f"per-job overhead: trivial jobs, {a.trivial} and {3 * a.trivial}; the slope is the cost of one more job, "
          f"the intercept the executor's start-up")
    for name, kw in executors:
        for res in (None, "file"):
            secs = []
            for n in (a.trivial, 3 * a.trivial):
                with tempfile.TemporaryDirectory() as d:
                    path = None if res is None else str(Path(d) / "r.jsonl")
                    _, sec = _timed(run_jobs, echo, [(i, (i,)) for i in range(n)], results=path, progress=False, **kw)
                secs.append(sec)
            slope = (secs[1] - secs[0]) / (2 * a.trivial)
            start = secs[0] - slope * a.trivial
            label = "with the results file" if res else "no results file"
            print(f"  {name:<30} {label:<22} {1000 * slope:6.3f} ms/job, start-up {start:5.2f} s")
            if res and "scheduler" in kw:
                dask_slope = slope
    workers = 100
    hours = 1_000_000 * per_episode / workers / 3600
    print(f"projection (not measured): 1 M episodes at the measured {1000 * per_episode:.0f} ms each on {workers} "
          f"workers like these cores: {hours:.1f} h of computing")
    if dask_slope is not None:  # the per-job overhead is spent in one client and one scheduler: it does not divide
        print(f"  and at least 1 M x {1000 * dask_slope:.1f} ms = {1e6 * dask_slope / 3600:.1f} h in the Dask client "
              f"and scheduler with one episode per job ({1e5 * dask_slope / 3600:.2f} h with ten per job)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
