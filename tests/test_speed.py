"""The speed tracker (assist.estimation.speed): the speed now from a GPS fix held between its refreshes.

Truth: the simulator's true speed (``vx_true``) of a seeded dry ride of the risk evaluation (calibration seed 11,
urban route: braking at 3 m/s^2 into its corners), and exact profiles built here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from assist.estimation.speed import SpeedTracker, SpeedTrackerError
from assist.risk.evaluation import make_case, ride_case
from ptw_env.sensors import GPS_RATE_HZ, SensorConfig


def test_the_held_fixs_lag_is_removed_while_braking_and_accelerating():
    """Where the true speed changes at 2 m/s^2 or more (the ride's braking and accelerating), the held 10 Hz
    reading lags by half a GPS period on average (0.05 s x |a|); the tracker's mean signed lag there is under a
    fifth of the held one's, and its RMS error over the ride is smaller."""
    r = ride_case(make_case("dry", 11))
    c = r.log.columns
    t, v, held = np.asarray(r.log.t), np.asarray(c["vx_true"], float), np.asarray(c["vx"], float)
    tr = SpeedTracker(float(r.log.dt), SensorConfig.from_percent(5.0).noise_std["vx"])
    est = np.array([tr.update(x) for x in held])
    a = np.gradient(v, t)
    steady = (np.abs(a) >= 2.0) & (t >= 1.0)
    steady &= np.convolve(steady, np.ones(50), mode="same") >= 50  # in the middle of 0.5 s of steady acceleration
    assert steady.sum() > 100
    lag_held = np.mean((held - v)[steady] * -np.sign(a[steady]))  # > 0: behind the true speed
    lag_est = np.mean((est - v)[steady] * -np.sign(a[steady]))
    assert lag_held == pytest.approx(0.5 / GPS_RATE_HZ * np.mean(np.abs(a[steady])), rel=0.3)  # half a period
    assert abs(lag_est) < 0.2 * lag_held
    m = t >= 1.0
    assert np.sqrt(np.mean((est - v)[m] ** 2)) < np.sqrt(np.mean((held - v)[m] ** 2))


def test_a_constant_speed_is_exact_and_a_missing_reading_is_predicted():
    tr = SpeedTracker(0.01, 0.05)
    assert math.isnan(tr.update(math.nan))  # no fix yet
    assert tr.update(12.0) == 12.0
    for _ in range(30):
        assert tr.update(12.0) == 12.0  # held (a repeat counts as a fix every 11 samples): no acceleration
    ramp = SpeedTracker(0.01, 0.0)
    for k in range(200):  # 10 Hz fixes of 15 - 2 t, noise-free
        ramp.update(15.0 - 2.0 * 0.01 * (k - k % 10))
    x = ramp.update(math.nan)  # a dropout: the prediction at t = 2.00 s
    assert x == pytest.approx(15.0 - 2.0 * 2.0, abs=0.02)
    ramp.reset()
    assert math.isnan(ramp.update(math.nan))


def test_a_stop_a_frozen_reading_and_a_long_dropout_are_held_not_extrapolated():
    """Noise-free 10 Hz fixes. Braking at 3 m/s^2 from 6 m/s to a stop, then standing (the reading repeats 0): the
    estimate never goes below 0 and is 0 within 0.5 s of the stop. Braking from 15 m/s for 1 s, then the reading
    frozen at 12.3 m/s for 3 s (a repeated fix counts once a fix period and a sample have passed): the estimate
    comes back to 12.3 instead of braking on. Accelerating at 2 m/s^2 to a last fix of 9.8 m/s, then no reading
    for 10 s: the speed is extrapolated for HOLD_AFTER_S after the last fix and held from then on."""
    from assist.estimation.speed import HOLD_AFTER_S

    dt = 0.01
    tr = SpeedTracker(dt, 0.0)
    t = np.arange(600) * dt
    fix_t = t - np.mod(t, 0.1)
    est = np.array([tr.update(max(6.0 - 3.0 * ft, 0.0)) for ft in fix_t])
    assert est.min() >= 0.0
    assert np.all(est[t >= 2.5] < 1e-3)
    tr = SpeedTracker(dt, 0.0)
    for k in range(100):
        tr.update(15.0 - 3.0 * 0.01 * (k - k % 10))  # last fix 12.3 m/s at k = 90
    frozen = [tr.update(12.3) for _ in range(300)]
    assert frozen[-1] == pytest.approx(12.3, abs=0.01)
    tr = SpeedTracker(dt, 0.0)
    for k in range(100):
        tr.update(8.0 + 2.0 * 0.01 * (k - k % 10))  # last fix 9.8 m/s at k = 90
    lost = np.array([tr.update(math.nan) for _ in range(1000)])
    j = int(np.flatnonzero(lost == lost[-1])[0])  # held from here on
    assert np.all(np.diff(lost[:j]) > 0)  # extrapolated before
    assert abs((10 + j) * dt - HOLD_AFTER_S) <= dt  # j samples after the 10th one since the last fix


def test_bad_options_are_refused():
    for args, match in (((0.0, 0.05), "dt"), ((0.01, -1.0), "fix_std"), ((0.01, 0.05, math.nan), "jerk"),
                        ((True, 0.05), "dt"), ((0.01, "0.05"), "fix_std"), ((0.01, 0.05, 0.0), "jerk")):
        with pytest.raises(SpeedTrackerError, match=match):
            SpeedTracker(*args)
    for args in ((10**400, 0.05), (0.01, 1e200), (1e120, 0.05), (0.01, 0.05, 10.0, 10**400)):
        with pytest.raises(SpeedTrackerError, match="SpeedTracker"):
            SpeedTracker(*args)
    tr = SpeedTracker(0.01, 0.05)
    for bad in (None, "12", 1j, True, np.True_, math.inf, -math.inf, 10**400):
        with pytest.raises(SpeedTrackerError, match="speed reading"):
            tr.update(bad)
    for bad in (None, (1.0, 2.0), "x", (1.0, (None, None, None, None)), (1.0, (None, np.eye(2), "0", 0))):
        with pytest.raises(SpeedTrackerError, match="what peek returned"):
            tr.commit(bad)
