"""The forward speed now, from a speed channel refreshed at a lower rate and held in between (a GPS).

Why: the friction filter (:mod:`assist.estimation.friction_imm`) predicts the tires' slip from the speed,
``alpha ~ vy / vx``. A 10 Hz GPS fix held for 0.1 s lags the true speed by up to ``0.1 a_x`` (0.3 m/s when
braking at 3 m/s^2 into a corner, 3 % at 11 m/s), and that lag is at the corner's entry, where the tires
start to carry load: taken as the speed, the held fix took the friction filter's lower frictions above 0.9
of the probability on 5 of the 40 dry calibration rides of the risk evaluation (0.996 at most, on a dry road),
this tracker's estimate to at most 0.72 (``scripts/eval_friction_filter.py``, table 6). An online reader cannot join the fixes as the offline
replays do (:func:`ptw_env.logs.held_speed`: it needs the next fix); it can extrapolate.

Model (a white-noise jerk, the constant-acceleration Kalman filter; Bar-Shalom, Li, Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, sec. 6.2.2, the continuous white-noise
acceleration model, eq. 6.2.2-12, one derivative up): state
``[v, a]`` [m/s, m/s^2], ``v' = a``, ``a' = w`` with ``E[w w] = q`` [m^2/s^5] (:data:`JERK_INTENSITY`);
over a sample ``dt``::

    F = [[1, dt], [0, 1]],   Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]

and a measurement update ``v_fix = v + n``, ``E[n n] = sigma^2`` (the GPS noise per fix, the sensor
model's ``noise_std["vx"]``) at each *new* fix: a sample whose reading differs from the one before (a held
reading repeats exactly; a reading refreshed every sample is a fix every sample), or a sample one fix period
(``fix_period``, the GPS's 0.1 s) and one sample after the last fix whatever its value (a standstill, a quantised channel, a
fix that repeats). A missing reading (NaN) is no fix; after :data:`HOLD_AFTER_S` without a fix the acceleration is
taken as zero (the speed held, not extrapolated through a long dropout). The estimate is never negative (the
filter rides forward: at a stop the speed is 0).

Units: m/s, m/s^2, s.
"""

from __future__ import annotations

import math

import numpy as np

from ptw_env.sensors import GPS_RATE_HZ

from assist.estimation.lpv_model import check_real

#: Intensity of the white-noise jerk [m^2/s^5] (module docstring): chosen on the dry calibration rides of the risk
#: evaluation (seeds 0-39) as the one of 1, 3, 10, 30, 100 with the smallest mean over the rides of the largest speed
#: error against the truth (``scripts/eval_friction_filter.py``, table 6: 0.280 m/s; its RMS error 0.064 m/s, the
#: held reading's 0.094; jerk 1 and 3 have a smaller RMS error, 0.057, and larger largest errors).
JERK_INTENSITY = 10.0
#: Prior standard deviation of the acceleration [m/s^2] before the second fix (a third of g: braking or
#: accelerating hard on a dry road).
ACCEL_PRIOR = 3.0
#: Time without a fix after which the acceleration is taken as zero [s] (module docstring).
HOLD_AFTER_S = 1.0
#: Smallest fix noise the filter assumes [m/s] (a noise-free channel still has its rounding).
MIN_FIX_STD = 1e-3


class SpeedTrackerError(ValueError):
    """An option or input the speed tracker cannot use."""


class SpeedTracker:
    """Causal speed estimate from a held speed channel (module docstring).

    Parameters
    ----------
    dt : float
        Sample period [s].
    fix_std : float
        Noise of one fix [m/s] (0: noise-free, :data:`MIN_FIX_STD` is used).
    jerk : float
        White-noise jerk intensity [m^2/s^5] (default :data:`JERK_INTENSITY`).
    fix_period : float
        Period of the fixes [s] (default the sensor model's GPS period, ``1 / ptw_env.sensors.GPS_RATE_HZ``,
        0.1 s): a sample more than this after the last fix is a fix even when its reading repeats.

    Examples
    --------
    A GPS at 10 Hz held over 100 Hz samples while braking at 3 m/s^2: the held reading lags by up to
    0.3 m/s, the tracker's estimate by far less once it has seen a few fixes.

    >>> t = np.arange(300) * 0.01
    >>> v = 15.0 - 3.0 * t
    >>> held = v[(np.arange(300) // 10) * 10]
    >>> tr = SpeedTracker(0.01, fix_std=0.0)
    >>> est = np.array([tr.update(h) for h in held])
    >>> bool(np.max(np.abs(held - v)[100:]) > 0.25), bool(np.max(np.abs(est - v)[100:]) < 0.05)
    (True, True)
    """

    def __init__(self, dt: float, fix_std: float, jerk: float = JERK_INTENSITY,
                 fix_period: float = 1.0 / GPS_RATE_HZ) -> None:
        h = check_real(dt, "SpeedTracker dt", SpeedTrackerError, positive=True)
        std = check_real(fix_std, "SpeedTracker fix_std", SpeedTrackerError)
        q = check_real(jerk, "SpeedTracker jerk", SpeedTrackerError, positive=True)
        period = check_real(fix_period, "SpeedTracker fix_period", SpeedTrackerError, positive=True)
        if std < 0.0:
            raise SpeedTrackerError(f"SpeedTracker fix_std must be a non-negative number, got {fix_std!r}")
        self.dt = h
        try:
            self.r = max(std, MIN_FIX_STD) ** 2
            self.Q = q * np.array([[h**3 / 3.0, h**2 / 2.0], [h**2 / 2.0, h]])
        except OverflowError:
            self.r = math.inf
        self.F = np.array([[1.0, h], [0.0, 1.0]])
        if not (math.isfinite(self.r) and np.all(np.isfinite(self.Q)) and period / h < 1e9):
            raise SpeedTrackerError(f"SpeedTracker options out of range: dt {dt!r} s, fix_std {fix_std!r} m/s, "
                                    f"jerk {jerk!r}, fix_period {fix_period!r} s")
        self.fix_samples = max(1, int(round(period / self.dt)))
        self.hold_samples = max(self.fix_samples, int(round(HOLD_AFTER_S / self.dt)))
        self.reset()

    def reset(self) -> None:
        """Forget every fix."""
        self.x: np.ndarray | None = None  # [v, a] at the current sample, None before the first fix
        self.P = np.diag([self.r, ACCEL_PRIOR**2])
        self._last = math.nan
        self._since = 0  # samples since the last fix

    def peek(self, vx: float) -> tuple:
        """``(estimate, state)`` after taking ``vx`` at this sample, without keeping it (:meth:`commit`
        keeps it)."""
        v = check_real(vx, "a speed reading [m/s]", SpeedTrackerError, missing_ok=True)
        x, P, last, since = (None if self.x is None else self.x.copy()), self.P.copy(), self._last, self._since + 1
        if x is not None:  # predict from the previous sample to this one
            if since > self.hold_samples:  # a long dropout: hold the speed
                x[1] = 0.0
            x = self.F @ x
            P = self.F @ P @ self.F.T + self.Q
        if math.isfinite(v) and (v != last or since > self.fix_samples):  # a fix
            if x is None:
                x = np.array([v, 0.0])
            else:
                s = P[0, 0] + self.r
                k = P[:, 0] / s
                x = x + k * (v - x[0])
                P = P - np.outer(k, P[0, :])
            last, since = v, 0
        if x is not None and x[0] < 0.0:  # forward riding: at a stop the speed is 0
            x[0], x[1] = 0.0, max(x[1], 0.0)
        return (math.nan if x is None else float(x[0])), (x, P, last, since)

    def commit(self, peeked: tuple) -> float:
        """Keep a state from :meth:`peek`; returns its estimate [m/s]."""
        ok = isinstance(peeked, tuple) and len(peeked) == 2 and isinstance(peeked[1], tuple) and len(peeked[1]) == 4
        if ok:
            x, P, last, since = peeked[1]
            ok = ((x is None or (isinstance(x, np.ndarray) and x.shape == (2,)))
                  and isinstance(P, np.ndarray) and P.shape == (2, 2) and isinstance(last, float)
                  and isinstance(since, int) and not isinstance(since, bool))
        if not ok:
            raise SpeedTrackerError(f"commit takes what peek returned, got {peeked!r}")
        est, (self.x, self.P, self._last, self._since) = peeked
        return est

    def update(self, vx: float) -> float:
        """Take this sample's reading ``vx`` [m/s] (NaN: none; infinite: refused) and return the speed estimate at this
        sample [m/s] (NaN before the first fix)."""
        return self.commit(self.peek(vx))


__all__ = ["ACCEL_PRIOR", "HOLD_AFTER_S", "JERK_INTENSITY", "MIN_FIX_STD", "SpeedTracker", "SpeedTrackerError"]
