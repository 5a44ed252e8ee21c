"""What one step of a roll-tracking episode does besides the dynamics: the steer actuator, the reward,
the end of the episode and the safety cost; one implementation for the single environment
(:class:`ptw_env.env.PTWRollEnv`) and the vector environment (:class:`ptw_env.vector.PTWRollVectorEnv`).

The compiled functions here are called per vehicle: by the single environment with scalars, by the
vector environment inside its batched kernel, so the two step the same way by construction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: ``info["reason"]`` by end code (0: the episode goes on).
REASONS: tuple[str, ...] = ("", "fell", "diverged", "speed_out_of_range", "scenario_end")
FELL, DIVERGED, SPEED_OUT_OF_RANGE, SCENARIO_END = 1, 2, 3, 4


class EpisodeConfigError(ValueError):
    """A bad actuator or cost setting (names the field)."""


def _positive(owner: str, name: str, v: float, *, allow_zero: bool = False, allow_inf: bool = False) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise EpisodeConfigError(f"{owner}.{name} must be a number, got {v!r}") from None
    if math.isnan(f) or (math.isinf(f) and not allow_inf) or f < 0 or (f == 0 and not allow_zero):
        raise EpisodeConfigError(f"{owner}.{name} must be {'>= 0' if allow_zero else '> 0'}"
                                 f"{' (inf: none)' if allow_inf else ' and finite'}, got {v!r}")
    return f


@dataclass(frozen=True)
class Actuator:
    """The steer actuator between the action (the commanded torque) and the steering torque on the plant.

    Per control period ``k`` (``dt``), in this order:

    1. transport delay: ``c_k = u_{k - D}`` with ``D = delay_s / dt`` periods (0 before the first command
       arrives: the actuator starts at rest);
    2. bandwidth: first-order lag of corner frequency ``f_c`` (``T tau' = c - tau``, ``T = 1/(2 pi f_c)``),
       discretised exactly for a held input: ``a_k = a_{k-1} + (1 - exp(-2 pi f_c dt)) (c_k - a_{k-1})``;
    3. rate limit: ``|a_k - a_{k-1}| <= rate_limit dt``;
    4. saturation: ``|a_k| <= torque_limit``.

    ``a_k`` [N m] is held over the period (zero-order hold, as the action always was). The default is the
    ideal actuator (no delay, infinite bandwidth and rate, the action box as the only limit), which
    reproduces the environment without this option exactly.

    Parameters
    ----------
    delay_s : float
        Transport delay [s], a whole number of control periods.
    bandwidth_hz : float
        Corner frequency [Hz]; ``inf``: none.
    rate_limit : float
        Largest torque rate [N m/s]; ``inf``: none.
    torque_limit : float or None
        Largest torque [N m]; ``None``: the environment's ``tau_max`` (the action box).
    """

    delay_s: float = 0.0
    bandwidth_hz: float = math.inf
    rate_limit: float = math.inf
    torque_limit: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "delay_s", _positive("Actuator", "delay_s", self.delay_s, allow_zero=True))
        object.__setattr__(self, "bandwidth_hz", _positive("Actuator", "bandwidth_hz", self.bandwidth_hz, allow_inf=True))
        object.__setattr__(self, "rate_limit", _positive("Actuator", "rate_limit", self.rate_limit, allow_inf=True))
        if self.torque_limit is not None:
            object.__setattr__(self, "torque_limit", _positive("Actuator", "torque_limit", self.torque_limit))

    @property
    def ideal(self) -> bool:
        return (self.delay_s == 0 and math.isinf(self.bandwidth_hz) and math.isinf(self.rate_limit)
                and self.torque_limit is None)

    def discrete(self, dt: float, tau_max: float) -> tuple[int, float, float, float]:
        """``(D, alpha, rate_step, limit)`` of :func:`actuate` for control period ``dt`` [s] and action
        range ``tau_max`` [N m]; the delay must be a whole number of periods."""
        d = self.delay_s / dt
        if abs(d - round(d)) > 1e-9:
            raise EpisodeConfigError(f"Actuator.delay_s must be a whole number of control periods "
                                     f"(dt = {dt} s), got {self.delay_s} s = {d:.4g} periods")
        alpha = 1.0 if math.isinf(self.bandwidth_hz) else 1.0 - math.exp(-2.0 * math.pi * self.bandwidth_hz * dt)
        limit = tau_max if self.torque_limit is None else min(self.torque_limit, tau_max)
        return int(round(d)), alpha, self.rate_limit * dt, limit


#: Where the observation's channels sit (``ptw_env.env.OBS_NAMES``): the five IMU and encoder channels first,
#: then the GPS speed, the reference, and the roll angle with ``observe_roll``.
OBS_VX, OBS_REF, OBS_ROLL = 5, 6, 7


@njit(cache=True)
def command(u, lim, tau_max, normalize):
    """``(tau [N m], clipped)`` of an action ``u``: clipped to ``[-lim, lim]`` (the action box; the rider's
    strength), times ``tau_max`` [N m] when actions are normalised."""
    clipped = u > lim or u < -lim
    if clipped:
        u = lim if u > 0 else -lim
    return (u * tau_max if normalize else u), clipped


@njit(cache=True)
def observe_into(meas, phi_ref, observe_roll, obs_hi, obs):
    """The observation (float32) from a measured row ``meas`` (:data:`ptw_env.sensors.CHANNELS` order) and the
    reference roll ``phi_ref`` [rad]: ``[delta, delta_rate, yaw_rate, roll_rate, ay, vx, phi_ref(, roll)]``,
    each clipped to ``+-obs_hi`` (the sensors' full scale)."""
    for j in range(5):
        obs[j] = meas[j]
    obs[OBS_VX] = meas[6]
    obs[OBS_REF] = phi_ref
    if observe_roll:
        obs[OBS_ROLL] = meas[5]
    for j in range(obs.shape[0]):
        if obs[j] > obs_hi[j]:
            obs[j] = obs_hi[j]
        elif obs[j] < -obs_hi[j]:
            obs[j] = -obs_hi[j]


@njit(cache=True)
def actuate(cmd, buf, k, prev, alpha, rate_step, limit):
    """Torque [N m] the actuator applies over period ``k`` (:class:`Actuator`, steps 1-4) for the command
    ``cmd`` [N m]; ``buf`` (D + 1,) is the ring of past commands (written at ``k``), ``prev`` the torque
    applied over period ``k - 1``."""
    n = buf.shape[0]
    buf[k % n] = cmd
    j = k - (n - 1)
    c = buf[j % n] if j >= 0 else 0.0
    if alpha == 1.0:
        a = c
    else:
        a = prev + alpha * (c - prev)
    if a - prev > rate_step:
        a = prev + rate_step
    elif prev - a > rate_step:
        a = prev - rate_step
    if a > limit:
        a = limit
    elif a < -limit:
        a = -limit
    return a


@dataclass(frozen=True)
class CostConfig:
    """The safety cost ``info["cost"]`` of a step (for safe / constrained RL): the number of these limits
    the step breaks, so a cost of 0 is a safe step and the episode's cost the number of unsafe
    (limit, step) pairs:

    * grip: the tire utilisation ``max_k |F_k| / (mu Fz_k)`` (front, rear; ``mu`` the tire's peak
      friction, ``road_mu`` for a linear tire without ``tire_saturation``) above ``grip_limit``;
    * roll: ``|phi|`` above ``roll_limit_deg``;
    * torque rate: the applied steering torque's change over the period above ``torque_rate_limit``
      ``tau_max`` per second (a rate relative to the vehicle's actuator range, so the same setting suits
      a scooter and a bicycle).

    All dimensionless or angles: nothing of a particular vehicle.
    """

    grip_limit: float = 0.8
    roll_limit_deg: float = 35.0
    torque_rate_limit: float = 20.0
    road_mu: float = 1.0

    def __post_init__(self) -> None:
        for name in ("grip_limit", "roll_limit_deg", "torque_rate_limit", "road_mu"):
            object.__setattr__(self, name, _positive("CostConfig", name, getattr(self, name), allow_inf=True))


@njit(cache=True)
def grip_utilisation(x, fmax, fz, road_mu):
    """``max_k |F_k| / Fmax_k`` of the two axles (``x[6:8]`` the tire forces [N], ``fmax`` the saturation
    forces, ``road_mu fz`` where they are infinite)."""
    u = 0.0
    for i in range(2):
        cap = fmax[i] if np.isfinite(fmax[i]) else road_mu * fz[i]
        v = abs(x[6 + i]) / cap
        if v > u:
            u = v
    return u


@njit(cache=True)
def step_cost(util, phi, dtau, grip_limit, roll_limit, dtau_limit):
    """:class:`CostConfig`'s cost of a step: how many of grip, roll and torque-rate limits it breaks."""
    c = 0.0
    if util > grip_limit:
        c += 1.0
    if abs(phi) > roll_limit:
        c += 1.0
    if abs(dtau) > dtau_limit:
        c += 1.0
    return c


@njit(cache=True)
def roll_reward(phi, phi_ref, tau_frac, roll_scale, effort_w):
    """``r = exp(-(phi - phi_ref)^2 / (2 s^2)) - w (tau / tau_max)^2`` (:class:`ptw_env.env.PTWRollEnv`,
    Reward); 0 when ``phi`` is not finite (the model diverged)."""
    if not np.isfinite(phi):
        return 0.0
    e = (phi - phi_ref) / roll_scale
    return np.exp(-0.5 * e * e) - effort_w * tau_frac * tau_frac


@njit(cache=True)
def end_code(finite, phi, fall_angle, vx_next, vmin, vmax, k_next, max_steps):
    """Why the episode ends after a step (:data:`REASONS`): ``DIVERGED`` (state not finite), ``FELL``
    (``|phi| > fall_angle``), ``SPEED_OUT_OF_RANGE`` (next speed outside ``[vmin, vmax]``), ``SCENARIO_END``
    (step ``k_next`` reaches ``max_steps``; truncation), 0 otherwise. The first three terminate."""
    if not finite:
        return DIVERGED
    if abs(phi) > fall_angle:
        return FELL
    if not (vmin <= vx_next <= vmax):
        return SPEED_OUT_OF_RANGE
    if k_next >= max_steps:
        return SCENARIO_END
    return 0
