"""What the sensors of a ride log read, for a batch of simulated trajectories.

The diagnosis compares predicted and measured channels many thousand times
while it fits effect sizes, so it needs the measurement map of
:mod:`ptw_env.sensors` applied to whole batches of trajectories at once.
:class:`ptw_env.sensors.SensorModel` is a streaming, one-vehicle model (a
Python loop per sample); :func:`sensor_outputs` is the same definitions
applied to arrays, without noise, quantisation or GPS hold (which the
diagnosis treats as measurement noise). ``tests/test_diagnose.py`` proves the
two paths agree to rounding for every sensor effect.

Definitions (``shared/spec/effects.md``, order as in
:mod:`ptw_env.sensors`, "Order of operations"):

1. true channels at ``t_k``: ``delta = x[1]``, ``delta_rate = x[5]``,
   ``yaw_rate = x[3]``, ``roll_rate = x[4]``,
   ``ay = (Fyf + Fyr)/(M + m)`` (model frame), ``roll = x[0]``;
2. ``ay_frame``: ``ay_meas = ay + k (ay cos(phi) - g sin(phi) - ay)``;
3. ``sensor_delay``: every channel above is read ``delay_s`` in the past,
   ``y(t_k - d)`` linearly interpolated between samples
   (``d/dt = n + f``: ``(1 - f) y[k - n] + f y[k - n - 1]``); before the
   history exists the first sample stands in;
4. ``gyro_bias``: ``yaw_rate_bias`` and ``roll_rate_bias`` added.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ptw_env.vehicle import DELTA, DELTA_DOT, FYF, FYR, G, PHI, PHI_DOT, R

#: Channels the diagnosis compares, in this order (log columns of logs.md); ``roll`` only when logged.
CHANNELS: tuple[str, ...] = ("delta", "delta_rate", "yaw_rate", "roll_rate", "ay", "roll")
#: Units of :data:`CHANNELS`.
UNITS: dict[str, str] = {
    "delta": "rad", "delta_rate": "rad/s", "yaw_rate": "rad/s", "roll_rate": "rad/s", "ay": "m/s^2", "roll": "rad",
}  # fmt: skip


#: state index of each channel; -1: ay
_CODE = {"delta": DELTA, "delta_rate": DELTA_DOT, "yaw_rate": R, "roll_rate": PHI_DOT, "ay": -1, "roll": PHI}


@njit(cache=True)
def _channel(X, i, t, c, mass, k):  # steps 1-2 of the module docstring, one reading
    if c >= 0:
        return X[i, t, c]
    ay = (X[i, t, FYF] + X[i, t, FYR]) / mass
    if k != 0.0:
        phi = X[i, t, PHI]
        ay = ay + k * (ay * np.cos(phi) - G * np.sin(phi) - ay)
    return ay


@njit(cache=True, parallel=True)
def _read(X, mass, gain, codes, n, f, bias, Y):
    """Steps 1-4 of the module docstring in one pass: ``Y[i, t, j] = y_j(t - n_i) + f_i (y_j(t - n_i - 1) -
    y_j(t - n_i)) + bias[i, j]``, a time before the first sample read as the first sample."""
    N, T = X.shape[0], X.shape[1]
    for i in prange(N):
        for t in range(T):
            t0 = max(t - n[i], 0)
            t1 = max(t - n[i] - 1, 0)
            for j in range(codes.shape[0]):
                v = _channel(X, i, t0, codes[j], mass[i], gain[i])
                if f[i] != 0.0:
                    v = v + f[i] * (_channel(X, i, t1, codes[j], mass[i], gain[i]) - v)
                Y[i, t, j] = v + bias[i, j]


def sensor_outputs(
    X: np.ndarray,
    mass: np.ndarray | float,
    dt: float,
    *,
    yaw_rate_bias: np.ndarray | float = 0.0,
    roll_rate_bias: np.ndarray | float = 0.0,
    gravity_gain: np.ndarray | float = 0.0,
    delay_s: np.ndarray | float = 0.0,
    channels: tuple[str, ...] = CHANNELS,
) -> np.ndarray:
    """Noise-free sensor readings of a batch of trajectories (module docstring, steps 1-4).

    Parameters
    ----------
    X : ndarray, shape (N, T, 8)
        True states at the sample instants ``t_k = k dt`` (model.md order).
    mass : float or ndarray, shape (N,)
        Total mass ``M + m`` [kg] of each vehicle (``Plant.mass``), for ``ay``.
    dt : float
        Sample period [s].
    yaw_rate_bias, roll_rate_bias : float or ndarray (N,)
        ``gyro_bias`` [rad/s].
    gravity_gain : float or ndarray (N,)
        ``ay_frame`` gain [-].
    delay_s : float or ndarray (N,)
        ``sensor_delay`` [s], ``>= 0``.
    channels : tuple of str
        Which channels to return, a subset of :data:`CHANNELS` in that order.

    Returns
    -------
    ndarray, shape (N, T, len(channels))
    """
    X = np.asarray(X, dtype=float)
    N, T = X.shape[:2]

    def col(v) -> np.ndarray:
        return np.broadcast_to(np.asarray(v, dtype=float), (N,))[:, None]

    codes = np.array([_CODE[c] for c in channels], dtype=np.int64)
    d = np.broadcast_to(np.asarray(delay_s, dtype=float), (N,)) / dt
    d = np.where(np.abs(d - np.round(d)) < 1e-9, np.round(d), d)
    if not np.all(d >= 0.0):
        raise ValueError(f"delay_s must be >= 0 seconds, got {delay_s!r}")
    n = np.floor(d).astype(np.int64)
    f = np.ascontiguousarray(d - n)
    bias = np.zeros((N, len(channels)))
    for name, b in (("yaw_rate", yaw_rate_bias), ("roll_rate", roll_rate_bias)):
        if name in channels:
            bias[:, channels.index(name)] = col(b)[:, 0]
    Y = np.empty((N, T, len(channels)))
    _read(X, np.ascontiguousarray(col(mass)[:, 0]), np.ascontiguousarray(col(gravity_gain)[:, 0]), codes,
          np.ascontiguousarray(n), f, bias, Y)
    return Y


__all__ = ["CHANNELS", "UNITS", "sensor_outputs"]
