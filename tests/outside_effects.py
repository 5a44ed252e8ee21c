"""Test-only plants with effects *outside* effects.md, for the diagnosis's "unexplained" answer (issue 7).

None of these is in the vocabulary of ``shared/spec/effects.md`` and none may be: they exist so that
the tests can hide in a ride log an effect the diagnosis has no name for. Each is built from the
project's own machinery: the compiled plant of :func:`ptw_env.dynamics.compile_plant`, its
right-hand side :func:`ptw_env.kernels.rhs_into`, the environment and rider of
:func:`ptw_env.ride.ride_scenario`, and the log's true-state columns.

Dynamic effects (:class:`OutsideStepper`), in the notation of model.md ``E x' = A(vx) x + B tau``
(+ the sine terms), rows 1-based as in effects.md:

* a steering torque ``T(x, vx)`` [N m] added to the rider's torque (row 6 through ``B``), which
  the log does not record: a torque-sensor offset ``T = T0``, Coulomb steering-head friction
  ``T = -Tc tanh(delta_dot / w)``, quadratic (turbulent) damping ``T = -c delta_dot |delta_dot|``;
* a lateral aerodynamic force growing with the square of the speed, ``F = c_y vx^2`` [N] (an
  asymmetric fairing, ``c_y = rho A C_y / 2``), at height ``h_a`` above the ground: ``F`` is added to
  the RHS of row 3 and the roll moment ``h_a F`` to row 5 (the sign convention of the bank's
  gravity component, whose force ``-M g sin(beta)`` at the centre of mass acts in rows 3 and 5
  the same way).

The extra terms are evaluated at every RK4 stage (not held over the sample), so they act on the
state continuously as physics does.

Sensor effect (:func:`yaw_gyro_scale`): a yaw-rate gyro with a scale-factor error ``k``,
``yaw_rate_meas = yaw_rate_meas_nominal + (k - 1) r`` with ``r`` the true yaw rate (the log's
``x_r`` column), so that the noise stays the sensor's.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

import numpy as np

import ptw_env.ride as ride_module
from ptw_env import kernels
from ptw_env.env import PTWRollEnv
from ptw_env.integrate import substeps_for
from ptw_env.logs import RideLog
from ptw_env.ride import ride_scenario
from ptw_env.scenarios import make_scenario

#: ``T(x, vx)`` [N m], ``F(x, vx)`` [N]: extra steering torque and lateral force of a test plant.
Term = Callable[[np.ndarray, float], float]


class OutsideStepper:
    """Drop-in for :class:`ptw_env.integrate.Stepper` with an extra steering torque and lateral force.

    RK4 with the same substeps as the environment's stepper; at each stage the compiled plant's
    right-hand side with the torque ``tau + torque(x, vx)``, plus ``E^-1 g`` in the mechanical rows
    for the generalised force ``g`` = (row 3: ``force(x, vx)``, row 5: ``height * force(x, vx)``).

    Parameters
    ----------
    plant : ptw_env.dynamics.Plant
        The true plant (unbatched).
    dt : float
        Control period [s].
    torque, force : callable, optional
        Extra steering torque [N m] and lateral force [N] as functions of the state and speed.
    height : float
        Height above the ground of the lateral force's line of action [m].
    """

    def __init__(self, plant, dt: float, torque: Term | None = None, force: Term | None = None,
                 height: float = 0.9, yaw_moment: Term | None = None) -> None:
        self.plant, self.dt = plant, float(dt)
        self.nsub = substeps_for(self.dt)
        self._flat = plant.flat()
        self.torque, self.force, self.yaw_moment = torque, force, yaw_moment
        g = np.zeros(8)
        g[2], g[4] = 1.0, height
        gen = np.linalg.solve(plant.vehicle.E, g)
        gen[6:] = 0.0  # the tire relaxation rows carry no body force
        self._gen = gen
        gy = np.zeros(8)
        gy[3] = 1.0  # row 4: a yaw moment [N m]
        self._gen_yaw = np.linalg.solve(plant.vehicle.E, gy)
        self._gen_yaw[6:] = 0.0
        self._x, self._t, self._v, self._out = np.empty((1, 8)), np.empty(1), np.empty(1), np.empty((1, 8))

    def _f(self, x: np.ndarray, tau: float, vx: float, d: float) -> np.ndarray:
        self._x[0] = x
        self._t[0] = tau + (self.torque(x, vx) if self.torque else 0.0)
        self._v[0] = vx
        kernels.rhs_into(self._x, self._t, self._v, *self._flat, self._out)
        f = self._out[0].copy()
        if self.force:
            f += self._gen * self.force(x, vx)
        if self.yaw_moment:
            f += self._gen_yaw * self.yaw_moment(x, vx)
        if d:
            raise NotImplementedError("roll-moment disturbances are not used with the test plants")
        return f

    def step(self, x: np.ndarray, tau: float, vx: float, roll_moment: float = 0.0) -> bool:
        """Advance ``x`` (modified in place) by one control period; False when it is no longer finite."""
        h = self.dt / self.nsub
        for _ in range(self.nsub):
            k1 = self._f(x, tau, vx, roll_moment)
            k2 = self._f(x + 0.5 * h * k1, tau, vx, roll_moment)
            k3 = self._f(x + 0.5 * h * k2, tau, vx, roll_moment)
            k4 = self._f(x + h * k3, tau, vx, roll_moment)
            x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return bool(np.all(np.isfinite(x)))


@contextlib.contextmanager
def _outside_env(**stepper_kw: Any):
    """While active, :func:`ptw_env.ride.ride_scenario` rides an environment whose true plant is an
    :class:`OutsideStepper` (the module's ``PTWRollEnv`` name is swapped, then restored)."""

    def make(*a: Any, **kw: Any) -> PTWRollEnv:
        env = PTWRollEnv(*a, **kw)
        env._stepper = OutsideStepper(env.plant, env.dt, **stepper_kw)
        return env

    saved = ride_module.PTWRollEnv
    ride_module.PTWRollEnv = make
    try:
        yield
    finally:
        ride_module.PTWRollEnv = saved


def ride_outside(scenario: str, seed: int, duration_s: float = 45.0, **stepper_kw: Any) -> RideLog:
    """A ride log (reference sensors, noise on) of a test plant (:class:`OutsideStepper` keywords)."""
    with _outside_env(**stepper_kw):
        log = ride_scenario(make_scenario(scenario, duration_s=duration_s), seed=seed).log
    log.meta["truth"] = {"causes": [], "outside_effects_md": stepper_kw_repr(stepper_kw)}
    return log


def stepper_kw_repr(kw: dict) -> str:
    """A short description of the test plant (for the sidecar)."""
    return ", ".join(f"{k}={getattr(v, '__doc__', None) or v!r}" for k, v in kw.items())


def sensor_error(log: RideLog, channel: str, offset: float = 0.0, scale: float = 0.0,
                 truth: np.ndarray | None = None) -> RideLog:
    """``log`` with ``channel`` read as ``y + offset + scale * truth`` (``truth`` the true signal of the
    channel, default the log's ``x_<channel>`` column), so that the noise stays the sensor's."""
    cols = dict(log.columns)
    if truth is None and scale:
        truth = cols[f"x_{channel}"]
    cols[channel] = cols[channel] + offset + (scale * np.asarray(truth) if scale else 0.0)
    meta = dict(log.meta, truth={"causes": [], "outside_effects_md": f"{channel}: offset {offset}, scale factor {1 + scale}"})
    return RideLog(t=log.t, columns=cols, meta=meta, path=None)


def yaw_gyro_scale(log: RideLog, k: float) -> RideLog:
    """``log`` with a yaw-rate gyro scale-factor error ``k`` (module docstring)."""
    return sensor_error(log, "yaw_rate", scale=k - 1.0, truth=log.columns["x_r"])


__all__ = ["OutsideStepper", "ride_outside", "sensor_error", "yaw_gyro_scale"]
