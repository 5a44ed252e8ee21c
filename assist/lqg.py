"""Output-feedback LQG baseline: a gain-scheduled Kalman filter plus the full-state LQR.

What a practitioner would build first for the same measurement set as the
Takagi-Sugeno observer-based controller (yaw rate, roll rate, steering angle
and rate): a steady-state discrete Kalman filter on the model linearised at
the upright, scheduled on the measured speed, and certainty-equivalent
LQR feedback with integral roll action (:class:`ptw_env.rider.GainSchedule`,
the same gains as the full-state LQR bound).

Filter (predictor-corrector form, one step per sample ``dt``)::

    x-_k = Ad(vx) x_{k-1} + Bd(vx) tau_{k-1}
    x_k  = x-_k + L(vx) (y_k - C x-_k)

with ``(Ad, Bd)`` the zero-order-hold discretisation of
``(E^-1 A(vx), E^-1 B)`` (model.md) and ``L = P C^T (C P C^T + R)^-1`` from the
discrete Riccati equation ``P = Ad P Ad^T - Ad P C^T (C P C^T + R)^-1 C P Ad^T + Qw``.
``R`` holds the sensor variances (datasheet values: what the designer knows;
the steering angle adds the encoder's quantisation variance ``q^2/12``);
``Qw = s_tau^2 Bd Bd^T + Qm`` models an unknown torque disturbance of
``s_tau`` = 5 N m plus a small model-error term ``Qm`` on every state (the
plant is nonlinear, its linearisation is not). All matrices are precomputed on a 1 m/s
speed grid and interpolated linearly in ``vx``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ptw_env.rider import LQRRider
from ptw_env.sensors import SensorConfig
from ptw_env.vehicle import REFERENCE_SCOOTER, Vehicle

#: measured states, in the order of the measurement vector y: yaw rate, roll rate, delta, delta rate
MEASURED = (3, 4, 1, 5)
_CHANNEL_OF = {3: "yaw_rate", 4: "roll_rate", 1: "delta", 5: "delta_rate"}


class KalmanDesignError(ValueError):
    """The Kalman filter cannot be designed (bad noise levels, unobservable pair)."""


@dataclass(frozen=True)
class _Grid:
    speeds: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    L: np.ndarray


def kalman_grid(vehicle: Vehicle, sensors: SensorConfig, dt: float = 0.01, torque_std: float = 5.0,
                model_std: np.ndarray | None = None, step: float = 1.0) -> _Grid:
    """Discrete model and steady-state Kalman gain on a speed grid (see the module docstring)."""
    C = np.zeros((len(MEASURED), 8))
    for i, j in enumerate(MEASURED):
        C[i, j] = 1.0
    r = np.array([sensors.noise_std[_CHANNEL_OF[j]] ** 2 for j in MEASURED])
    if sensors.delta_quantum:
        r[MEASURED.index(1)] += sensors.delta_quantum**2 / 12.0
    r = np.maximum(r, 1e-10)  # noise-free sensors: keep R invertible (a very confident filter)
    R = np.diag(r)
    if model_std is None:
        # model error per state: rad, rad, m/s, rad/s, rad/s, rad/s, N, N per sample
        model_std = np.array([1e-4, 1e-4, 1e-3, 1e-3, 1e-3, 1e-3, 5.0, 5.0])
    Qm = np.diag(np.asarray(model_std, dtype=float) ** 2)
    speeds = np.arange(vehicle.vmin, vehicle.vmax + 0.5 * step, step)
    Ads, Bds, Ls = [], [], []
    B = vehicle.input_matrix()
    for v in speeds:
        A = vehicle.state_matrix(v)
        M = sla.expm(np.block([[A, B], [np.zeros((1, 9))]]) * dt)
        Ad, Bd = M[:8, :8], M[:8, 8:9]
        Q = torque_std**2 * (Bd @ Bd.T) + Qm
        try:
            P = sla.solve_discrete_are(Ad.T, C.T, Q, R)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise KalmanDesignError(f"Kalman filter at vx = {v:.1f} m/s: Riccati equation has no solution ({exc})") from None
        L = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        Ads.append(Ad)
        Bds.append(Bd[:, 0])
        Ls.append(L)
    return _Grid(speeds, np.array(Ads), np.array(Bds), np.array(Ls))


class LQGController:
    """Gain-scheduled Kalman filter + certainty-equivalent LQR with integral roll action.

    Parameters
    ----------
    vehicle : Vehicle
        Design model (the prior), default the reference scooter.
    sensors : SensorConfig
        The sensors' noise the filter is designed for.
    dt : float
        Sample period [s].

    Examples
    --------
    >>> import numpy as np
    >>> c = LQGController(sensors=SensorConfig.from_percent(5))
    >>> c.reset()
    >>> tau = c.update(np.zeros(4), 15.0, 0.0)
    >>> round(tau, 6)
    0.0
    """

    name = "lqg"

    def __init__(self, vehicle: Vehicle | None = None, sensors: SensorConfig | None = None, dt: float = 0.01,
                 tau_max: float = 60.0) -> None:
        self.vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
        self.sensors = SensorConfig() if sensors is None else sensors
        self.dt = float(dt)
        self._grid = kalman_grid(self.vehicle, self.sensors, self.dt)
        self._lqr = LQRRider(vehicle=self.vehicle, torque_noise_nm=0.0, tau_max=tau_max, dt=self.dt)
        self._C_idx = np.array(MEASURED)
        self.reset()

    def reset(self, x_hat0: np.ndarray | None = None) -> None:
        """Start from ``x_hat0`` (default the upright state)."""
        self._x = np.zeros(8) if x_hat0 is None else np.array(x_hat0, dtype=float)
        self._tau = 0.0
        self._first = True
        self._lqr.reset(None)

    @property
    def x_hat(self) -> np.ndarray:
        return self._x.copy()

    def _interp(self, vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g = self._grid
        u = (min(max(vx, g.speeds[0]), g.speeds[-1]) - g.speeds[0]) / (g.speeds[1] - g.speeds[0])
        i = min(int(u), len(g.speeds) - 2)
        w = u - i
        return (
            g.Ad[i] + w * (g.Ad[i + 1] - g.Ad[i]),
            g.Bd[i] + w * (g.Bd[i + 1] - g.Bd[i]),
            g.L[i] + w * (g.L[i + 1] - g.L[i]),
        )

    def update(self, y: np.ndarray, vx: float, phi_ref: float) -> float:
        """One sample: ``y`` = measured [yaw_rate, roll_rate, delta, delta_rate]; returns the torque [N m]
        to hold over the next period."""
        Ad, Bd, L = self._interp(vx)
        if self._first:
            xm = self._x
            self._first = False
        else:
            xm = Ad @ self._x + Bd * self._tau
        self._x = xm + L @ (np.asarray(y, dtype=float) - xm[self._C_idx])
        self._tau = self._lqr.torque(self._x, vx, phi_ref)
        return self._tau
