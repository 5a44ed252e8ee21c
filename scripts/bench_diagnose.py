"""Benchmark of ``ptw-assist diagnose``: seconds to diagnose a 90 s, 100 Hz ride log, and the share
spent in the batched simulator (issue 7 target: under 60 s per log on 2 cores).

Usage::

    python scripts/bench_diagnose.py                 # the disclosed 90 s reference log, then a 90 s
                                                     # simulated urban ride with a hidden bank
    python scripts/bench_diagnose.py --log ride.csv  # any log
    python scripts/bench_diagnose.py --repeat 3

The first diagnosis of a fresh interpreter also pays numba's cache load; the
script warms it up on a short ride first (not timed).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _shared_data() -> Path:
    for c in (os.environ.get("PTW_SHARED_DIR"), ROOT.parent / "shared", Path("/work/shared")):
        if c and (Path(c) / "data").is_dir():
            return Path(c) / "data"
    raise SystemExit("shared/data not found; set PTW_SHARED_DIR")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", action="append", default=None, help="ride log(s) to diagnose (default: see above)")
    ap.add_argument("--repeat", type=int, default=1, help="diagnoses per log (the best time is reported)")
    a = ap.parse_args(argv)

    from assist.diagnose import diagnose
    from ptw_env.ride import ride_scenario
    from ptw_env.scenarios import make_scenario

    diagnose(ride_scenario(make_scenario("double_lane_change", duration_s=24.0), seed=0).log, pairs=False,
             progress=False)  # warm-up: numba caches, imports
    logs: list[tuple[str, object]] = []
    if a.log:
        logs = [(p, p) for p in a.log]
    else:
        logs.append(("nominal_urban.csv (reference, 90 s)", _shared_data() / "nominal_urban.csv"))
        ride = ride_scenario("urban", effects={"road_bank": {"bank_rad": 0.04}}, seed=1)
        logs.append(("simulated urban ride, 90 s, hidden road_bank 0.04", ride.log))
    print(f"{'log':55s} {'seconds':>8s} {'sim share':>9s} {'vehicle-steps':>14s}  verdict")
    worst = 0.0
    for name, src in logs:
        best = None
        for _ in range(max(1, a.repeat)):
            t = time.perf_counter()
            rep = diagnose(src, progress=False)
            dt = time.perf_counter() - t
            if best is None or dt < best[0]:
                best = (dt, rep)
        dt, rep = best
        worst = max(worst, dt)
        verdict = ", ".join(c["cause"] for c in rep.causes)
        print(f"{name:55s} {dt:8.1f} {100 * rep.sim_seconds / dt:8.0f} % {rep.sim_steps:14,d}  {verdict}")
    print(f"target: < 60 s per 90 s log on 2 cores; slowest here {worst:.1f} s "
          f"({os.cpu_count()} CPUs visible; other processes share them)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
