"""Gymnasium wrapper: the risk warning of :mod:`assist.risk` in ``info["risk"]``.

:class:`RiskWarningWrapper` runs the stiffness estimator and the risk monitor
on what the rider's scooter itself knows:

* the observation only (``delta, delta_rate, yaw_rate, roll_rate, ay, vx``
  of :class:`ptw_env.env.PTWRollEnv`) and the torque the agent applies
  (the action, clipped to the action space as the environment does); never
  ``info["state"]``, ``info["measurement"]`` or ``info["friction"]``;
* the road ahead from the scenario's curvature profile, as a navigation map
  would hold it: ``kappa(s)`` of the planned route, looked up at the
  distance travelled by odometry (the measured speed integrated,
  ``s_hat += vx_meas dt``), over the monitor's preview horizon. With
  ``use_map=False`` only the curvature being ridden, ``r_hat / vx``, is used.

Timing: :meth:`step` first updates the estimator with the observation the
action was chosen on (sample ``t_k``) and the action (held over
``[t_k, t_k+1)``), then steps the environment; ``info["risk"]`` is the
:class:`~assist.risk.monitor.RiskAssessment` of ``t_k`` (one control period
old), as a dict (:meth:`RiskAssessment.to_dict`); :attr:`last_assessment`
holds the object. ``reset`` returns no ``"risk"`` key (no action yet).

Examples
--------
>>> import numpy as np
>>> from ptw_env.env import PTWRollEnv
>>> env = RiskWarningWrapper(PTWRollEnv("double_lane_change"))
>>> obs, info = env.reset(seed=0)
>>> obs, r, term, trunc, info = env.step(np.zeros(1, dtype=np.float32))
>>> info["risk"]["level"], round(info["risk"]["mu_hat"], 2)
('safe', 0.9)
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from ptw_env.env import obs_index

from .monitor import PathAhead, RiskAssessment
from .pipeline import RiskPipeline, default_estimator

#: Observation indices of the estimator's outputs ``[delta, yaw_rate, roll_rate, delta_rate, ay]`` and of vx.
_OBS_Y = obs_index("delta", "yaw_rate", "roll_rate", "delta_rate", "ay")
(_OBS_VX,) = obs_index("vx")


class RiskWarningWrapper(gym.Wrapper):
    """Adds the risk assessment to ``info["risk"]`` (module docstring).

    Parameters
    ----------
    env : gymnasium.Env
        A :class:`ptw_env.env.PTWRollEnv` (possibly wrapped): its observation
        layout and, for the map, its ``profile`` (``s``, ``kappa``) and ``dt``.
    pipeline : RiskPipeline, optional
        Estimator and monitor (default: the friction filter designed for the
        environment's vehicle and noise level, see :func:`assist.risk.pipeline.default_estimator`).
    use_map : bool
        Preview the road ahead from the scenario's curvature profile (default True).
    info_key : str
        Key of the assessment in ``info`` (default ``"risk"``).
    """

    def __init__(self, env: gym.Env, pipeline: RiskPipeline | None = None, use_map: bool = True,
                 info_key: str = "risk") -> None:
        super().__init__(env)
        base = env.unwrapped
        self._dt = float(getattr(base, "dt", 0.01))
        if pipeline is None:
            noise = _noise_pct_of(base)
            v = getattr(base, "vehicle", None)
            pipeline = RiskPipeline(default_estimator(noise, self._dt, v), vehicle=v)
        self.pipeline = pipeline
        self.use_map = bool(use_map)
        self.info_key = str(info_key)
        self._obs: np.ndarray | None = None
        self._k = 0
        self._s_hat = 0.0
        self.last_assessment: RiskAssessment | None = None

    def _map(self) -> tuple[np.ndarray, np.ndarray] | None:
        prof = getattr(self.env.unwrapped, "profile", None)
        if not self.use_map or prof is None:
            return None
        return np.asarray(prof.s, dtype=float), np.asarray(prof.kappa, dtype=float)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.pipeline.reset()
        self._obs = np.asarray(obs, dtype=float)
        self._k = 0
        self._s_hat = 0.0
        self.last_assessment = None
        return obs, info

    def _torque(self, action) -> float:
        a = np.clip(np.asarray(action, dtype=float).ravel(), self.action_space.low, self.action_space.high)
        base = self.env.unwrapped
        scale = float(getattr(base, "tau_max", 1.0)) if getattr(base, "normalize_action", False) else 1.0
        return float(a[0]) * scale

    def step(self, action) -> tuple[Any, float, bool, bool, dict]:
        if self._obs is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        o = self._obs
        vx = float(o[_OBS_VX])
        path = None
        m = self._map()
        if m is not None:
            c = self.pipeline.monitor.config
            horizon = max(c.preview_min_m, max(vx, 0.0) * c.preview_s)
            path = PathAhead.from_map(self._s_hat, m[0], m[1], horizon)
        tau = self._torque(action)
        assessment = self.pipeline.update(self._k * self._dt, o[list(_OBS_Y)], tau, vx, path=path,
                                          yaw_rate_path=m is None)
        if math.isfinite(vx):
            self._s_hat += vx * self._dt
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._obs = np.asarray(obs, dtype=float)
        self._k += 1
        self.last_assessment = assessment
        info = dict(info)
        info[self.info_key] = assessment.to_dict()
        return obs, reward, terminated, truncated, info


def _noise_pct_of(env) -> float | None:
    """Sensor noise of ``env`` in percent of range, read off its ``ay`` channel
    (``SensorConfig.from_percent`` is linear in the percentage); None without a sensor config."""
    cfg = getattr(env, "sensor_config", None)
    if cfg is None:
        return None
    from ptw_env.sensors import SensorConfig

    return float(cfg.noise_std["ay"] / SensorConfig.from_percent(1.0, vehicle=getattr(env, "vehicle", None)).noise_std["ay"])


__all__ = ["RiskWarningWrapper"]
