"""Benchmark of the execution layer (:mod:`ptw_env.jobs`) on a fleet diagnosis: the same logs diagnosed
serially, in local processes and on a Dask LocalCluster, each time as a ratio of the serial run of
the same logs measured in the same run (the reference), and the verdicts compared (identical rows).

Usage::

    python scripts/bench_fleet.py [--data DIR] [--logs 6] [--workers 2]

Default data: the robot-bicycle rides of ``shared/data/robot_bicycle`` (the first ``--logs`` by
name). The Dask row needs the ``[cluster]`` extra and is skipped without it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from _outputs import local_executors, shared_data  # scripts/_outputs.py (python scripts/NAME.py puts scripts/ on sys.path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=None, help="folder of ride logs (default shared/data/robot_bicycle)")
    from ptw_env.cli import WORKERS, number

    ap.add_argument("--logs", type=number(1, 1e6, integer=True), default=6, help="how many logs (default 6)")
    ap.add_argument("--workers", type=WORKERS, default=2, help="processes / Dask workers (default 2)")
    a = ap.parse_args(argv)
    data = Path(a.data) if a.data else shared_data("robot_bicycle")
    paths = sorted(data.glob("*.csv"))[: a.logs]
    if not paths:
        ap.error(f"no .csv ride log in {data}")

    from assist.diagnose.fleet import diagnose_fleet

    runs = local_executors(a.workers)
    diagnose_fleet(paths[:1], tempfile.mkdtemp(), figures=False, progress=False)  # numba's cache, not timed
    ref = rows_ref = None
    print(f"{len(paths)} logs of {data} (diagnose, figures off)")
    for name, kw in runs:
        t0 = time.perf_counter()
        rows = diagnose_fleet(paths, tempfile.mkdtemp(), figures=False, progress=False, **kw)
        sec = time.perf_counter() - t0
        if ref is None:
            ref, rows_ref = sec, rows
        same = "identical verdicts" if rows == rows_ref else "DIFFERENT verdicts"
        print(f"  {name:<34} {sec:7.1f} s   {sec / ref:5.2f}x serial   {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
