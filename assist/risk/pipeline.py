"""Sensors -> stiffness estimator -> :class:`~assist.risk.monitor.RiskMonitor`, one sample at a time.

The estimator is pluggable: any object with ``update(y, tau, vx)`` (``y`` =
``[delta, yaw_rate, roll_rate, delta_rate, ay]``, the torque and the speed
held until the next sample), ``reset()``, and the properties ``stiffness``
and ``stiffness_std`` ([N/rad], order ``C_alpha_f, C_gamma_f, C_alpha_r,
C_gamma_r``); if it also has ``x_hat`` (the 8 states of model.md) its axle
forces ``x_hat[6:8]`` give the per-axle utilisation. The default is the LPV
adaptive observer of :mod:`assist.adaptive_observer` (sensitivity law),
designed for the sensors' noise level (:func:`default_estimator`).

Both online uses (:class:`assist.risk.wrapper.RiskWarningWrapper`) and the
offline one (:func:`assist.risk.offline.assess_log`) go through
:class:`RiskPipeline`, so they give the same assessments for the same samples.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from .monitor import PathAhead, RiskAssessment, RiskMonitor

class MonitorInputs(NamedTuple):
    """The arguments of one :meth:`RiskMonitor.update` call, in its order."""

    t: float
    stiffness: np.ndarray
    stiffness_std: np.ndarray
    vx: float
    ay: float
    forces: np.ndarray | None
    path: PathAhead | None


#: The estimator's output channels, in the order of ``y``.
OUTPUTS = ("delta", "yaw_rate", "roll_rate", "delta_rate", "ay")


@runtime_checkable
class StiffnessEstimator(Protocol):
    """What :class:`RiskPipeline` needs from a tire-stiffness estimator."""

    def update(self, y, tau: float, vx: float): ...

    def reset(self) -> None: ...

    @property
    def stiffness(self) -> np.ndarray: ...

    @property
    def stiffness_std(self) -> np.ndarray: ...


#: Random-walk intensity of the friction scale in the default estimator [1/sqrt(s)]: road friction can
#: change at any moment (a wet patch), so the estimate must be able to move by ~0.15 in 10 s.
FRICTION_WALK = 0.05


def default_estimator(noise_pct: float | None = 5.0, dt: float = 0.01, road_bank: float = 0.0):
    """The LPV adaptive observer for the risk warning: Kalman vertex gains
    (:func:`assist.adaptive_design.kalman_design`) and one friction scale for all four stiffnesses
    (``parametrisation="friction"``, [1]_ sec. II-C ``Theta = mu Theta_0``), sensitivity law with the
    random walk :data:`FRICTION_WALK`; designed for ``noise_pct`` % sensor noise (``None``: the
    reference logs' sensors, designed as 0.5 %) at sample period ``dt`` [s], on a road of known bank
    ``road_bank`` [rad] (effects.md ``road_bank``; default level).

    The road must be known: the model has no bank, so a bank's steady side force is read as a
    stiffness change (measured on a simulated urban ride at friction 0.9: ``mu_hat`` ends at 1.07 on a
    0.02 rad bank, the usual cross-fall of a road, and swings between 0.4 and 1.4 on 0.04 rad; with
    the bank given, 0.92 and 0.94). ``ptw-assist diagnose`` names and sizes a bank on a log.

    Why this one: it sees a friction drop from the steering response to the rider's torque even on a
    straight (on the wet-patch rides of :mod:`assist.risk.evaluation` it reads 0.9 -> ~0.5 within a
    few seconds of straight riding), where the certified Theorem-2 observer, whose high gains absorb
    the stiffness error, drifts and has to be gated by lateral acceleration
    (:mod:`assist.adaptive_observer`, "Which gains, which parameters").

    .. [1] M. Fouka, L. Nehaoua, H. Arioui (``shared/papers/000_348caefc9b08ee38.txt``).
    """
    from assist.adaptive_design import AdaptiveDesignOptions, default_kalman_design
    from assist.adaptive_observer import AdaptiveObserver

    pct = 0.5 if noise_pct is None else max(float(noise_pct), 0.5)
    design = default_kalman_design(AdaptiveDesignOptions(noise_pct=pct, dt=round(float(dt), 9)))
    return AdaptiveObserver(design, parametrisation="friction", stiffness_walk=FRICTION_WALK, road_bank=road_bank)


class RiskPipeline:
    """One estimator and one monitor, fed sample by sample.

    Parameters
    ----------
    estimator : StiffnessEstimator, optional
        Default: :func:`default_estimator` ().
    monitor : RiskMonitor, optional
        Default: :class:`RiskMonitor` with its defaults.
    """

    def __init__(self, estimator=None, monitor: RiskMonitor | None = None) -> None:
        self.estimator = default_estimator() if estimator is None else estimator
        if not isinstance(self.estimator, StiffnessEstimator):
            raise TypeError("estimator must have update(y, tau, vx), reset(), stiffness and stiffness_std; "
                            f"got {type(self.estimator).__name__}")
        self.monitor = RiskMonitor() if monitor is None else monitor
        self._vx = math.nan
        self.last_inputs: MonitorInputs | None = None

    def reset(self) -> None:
        """Reset the estimator and the monitor."""
        self.estimator.reset()
        self.monitor.reset()
        self._vx = math.nan

    def update(self, t: float, y, tau: float, vx: float, path: PathAhead | None = None,
               yaw_rate_path: bool = False) -> RiskAssessment:
        """Take sample ``t`` [s]: ``y`` (5, order :data:`OUTPUTS`), ``tau`` [N m] and ``vx`` [m/s]
        (held until the next sample). ``path``: the road ahead; with ``yaw_rate_path`` and no
        ``path`` the curvature being ridden, ``r_hat / vx`` (the estimated yaw rate, else the
        measured one), stands in (no preview). A missing ``vx`` (NaN) keeps the last one."""
        y = np.asarray(y, dtype=float)
        if y.shape != (len(OUTPUTS),):
            raise ValueError(f"y must hold the {len(OUTPUTS)} outputs {OUTPUTS}, got shape {y.shape}")
        vx = float(vx)
        if math.isfinite(vx):
            self._vx = vx
        elif not math.isfinite(self._vx):
            raise ValueError(f"vx is missing at t = {t} s and no earlier speed is known")
        self.estimator.update(y, tau, vx)
        est = self.estimator
        xh = getattr(est, "x_hat", None)
        forces = None
        if xh is not None:
            xh = np.asarray(xh, dtype=float)
            if xh.shape == (8,) and np.all(np.isfinite(xh[6:8])):
                forces = xh[6:8]
        if path is None and yaw_rate_path:
            r = float(xh[3]) if xh is not None and xh.shape == (8,) and math.isfinite(xh[3]) else float(y[1])
            if math.isfinite(r):
                path = PathAhead.current(r / self._vx)
        #: what the monitor was fed (for :func:`assist.risk.offline.replay`)
        self.last_inputs = MonitorInputs(float(t), np.asarray(est.stiffness, dtype=float).copy(),
                                         np.asarray(est.stiffness_std, dtype=float).copy(), self._vx, float(y[4]),
                                         None if forces is None else forces.copy(), path)
        return self.monitor.update(*self.last_inputs)


__all__ = ["MonitorInputs", "OUTPUTS", "RiskPipeline", "StiffnessEstimator", "default_estimator"]
