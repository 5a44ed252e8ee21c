"""Job functions for tests/test_jobs.py: module-level, so that process pools and Dask workers import them."""

from __future__ import annotations

import time

import numpy as np

from ptw_env.ride import ride_scenario
from ptw_env.scenarios import make_scenario


def short_ride(seed: int, speed_kmh: float) -> dict:
    """A 12 s lane change with the LQR rider: the roll RMS [rad] and the last true state."""
    r = ride_scenario(make_scenario("double_lane_change", duration_s=12.0, speed_kmh=speed_kmh), seed=seed)
    return {"phi_rms": float(np.sqrt(np.mean(r.states[:, 0] ** 2))), "last": [float(v) for v in r.states[-1]]}


def slow_square(x: int, delay_s: float) -> int:
    """``x * x`` after ``delay_s`` seconds (a job long enough to kill a worker under it)."""
    time.sleep(delay_s)
    return x * x


def fail_on(x: int, bad: int, delay_s: float = 0.0) -> int:
    """``x`` itself, except that ``x == bad`` raises ``ValueError`` after ``delay_s`` seconds (a job that
    fails on a worker, last when the others are fast)."""
    if x == bad:
        import time

        time.sleep(delay_s)
        raise ValueError(f"job {x} failed")
    return x
