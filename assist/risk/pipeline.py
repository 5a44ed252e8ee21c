"""Sensors -> stiffness estimator -> :class:`~assist.risk.monitor.RiskMonitor`, one sample at a time.

The estimator is pluggable: any object with ``update(y, tau, vx)`` (``y`` =
``[delta, yaw_rate, roll_rate, delta_rate, ay]``, the torque and the speed
held until the next sample), ``reset()``, and the properties ``stiffness``
and ``stiffness_std`` ([N/rad], order ``C_alpha_f, C_gamma_f, C_alpha_r,
C_gamma_r``); if it also has ``x_hat`` (the 8 states of model.md) its axle
forces ``x_hat[6:8]`` give the per-axle utilisation; if it has ``friction_reading``
(:class:`assist.estimation.friction_imm.FrictionReading`), that reading is the
friction and the stiffness is not mapped. The default (:func:`default_estimator`)
is the friction filter of :mod:`assist.estimation.friction_imm` (tires that lose
their peak on a wet road), or for ``tire="stiffness"`` the LPV adaptive observer
of :mod:`assist.estimation.adaptive_observer` (sensitivity law); both designed for
the sensors' noise level.

Both online uses (:class:`assist.risk.wrapper.RiskWarningWrapper`) and the
offline one (:func:`assist.risk.offline.assess_log`) go through
:class:`RiskPipeline`, so they give the same assessments for the same samples.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from ptw_env.vehicle import G, REFERENCE_SCOOTER, Vehicle

from .friction_estimate import FrictionConfig, FrictionEstimate
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
    #: the estimator's own friction reading (``friction_reading``), if it has one
    reading: object = None


#: The estimator's output channels, in the order of ``y``.
OUTPUTS = ("delta", "yaw_rate", "roll_rate", "delta_rate", "ay")


def output_matrix(columns) -> np.ndarray:
    """The measured outputs of a log's ``columns`` (K, 5), in the order of :data:`OUTPUTS`."""
    return np.column_stack([np.asarray(columns[n], dtype=float) for n in OUTPUTS])


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


def default_estimator(noise_pct: float | None = 5.0, dt: float = 0.01, vehicle: Vehicle | None = None,
                      speeds: np.ndarray | None = None, tire: str = "peak"):
    """The estimator of the risk warning for tires whose friction scales ``tire`` (``"peak"``, the default:
    :func:`friction_estimator`; ``"stiffness"``: :func:`stiffness_estimator`), designed for ``noise_pct`` %
    sensor noise (``None``: the reference logs' sensors, as 0.5 %) at sample period ``dt`` [s] for
    ``vehicle`` (default the reference scooter); ``speeds``: a log's speeds [m/s] (the observer's range)."""
    if tire == "peak":
        return friction_estimator(noise_pct, dt, vehicle)
    if tire == "stiffness":
        return stiffness_estimator(noise_pct, dt, vehicle, speeds)
    raise ValueError(f"tire must be 'peak' or 'stiffness', got {tire!r}")


def friction_estimator(noise_pct: float | None = 5.0, dt: float = 0.01, vehicle: Vehicle | None = None):
    """The friction filter for tires that lose their peak on a wet road
    (:class:`assist.estimation.friction_imm.FrictionIMM`: models of the saturating tire over a grid of
    frictions; it reads the road from the bend of the tire curve as soon as the tires carry load, which
    a stiffness estimate linear in the state cannot). Noise as :func:`default_estimator`."""
    from assist.estimation.friction_imm import FrictionIMM

    pct = 0.5 if noise_pct is None else max(float(noise_pct), 0.5)
    return FrictionIMM(noise_pct=pct, dt=round(float(dt), 9), vehicle=vehicle)


def stiffness_estimator(noise_pct: float | None = 5.0, dt: float = 0.01, vehicle: Vehicle | None = None,
                        speeds: np.ndarray | None = None):
    """The LPV adaptive observer for the risk warning: Kalman vertex gains
    (:func:`assist.estimation.adaptive_design.kalman_design`) and one friction scale for all four stiffnesses
    (``parametrisation="friction"``, [1]_ sec. II-C ``Theta = mu Theta_0``), sensitivity law with the
    random walk :data:`FRICTION_WALK`; designed for ``noise_pct`` % sensor noise (``None``: the
    reference logs' sensors, designed as 0.5 %) at sample period ``dt`` [s], for ``vehicle`` (default the
    reference scooter) over its design range, else over ``speeds`` [m/s] (a log's; see
    :func:`assist.estimation.adaptive_design.design_for_vehicle`); its plant's road bank (``road_bank``,
    rad) is set by :class:`RiskPipeline`.

    The road's bank must be known: the model has no other place for it, so a bank's steady side force
    is read as a stiffness change (measured on a simulated urban ride at friction 0.9: ``mu_hat`` ends
    at 1.07 on a 0.02 rad bank, the usual cross-fall of a road, and swings between 0.4 and 1.4 on
    0.04 rad; with the bank given, 0.92 and 0.94). :class:`RiskPipeline` estimates it on line by
    default (:class:`BankEstimate`); ``ptw-assist diagnose`` names and sizes one on a log.

    Why this one: it sees a friction drop from the steering response to the rider's torque even on a
    straight (on the wet-patch rides of :mod:`assist.risk.evaluation` it reads 0.9 -> ~0.5 within a
    few seconds of straight riding), where the certified Theorem-2 observer, whose high gains absorb
    the stiffness error, drifts and has to be gated by lateral acceleration
    (:mod:`assist.estimation.adaptive_observer`, "Which gains, which parameters").

    .. [1] M. Fouka, L. Nehaoua, H. Arioui (``shared/papers/000_348caefc9b08ee38.txt``).
    """
    from assist.estimation.adaptive_design import AdaptiveDesignOptions, design_for_vehicle
    from assist.estimation.adaptive_observer import AdaptiveObserver

    pct = 0.5 if noise_pct is None else max(float(noise_pct), 0.5)
    design = design_for_vehicle(REFERENCE_SCOOTER if vehicle is None else vehicle,
                                AdaptiveDesignOptions(noise_pct=pct, dt=round(float(dt), 9)), "kalman", speeds)
    return AdaptiveObserver(design, parametrisation="friction", stiffness_walk=FRICTION_WALK)


class BankEstimate:
    """The road bank from the IMU, on line: ``beta_hat = asin(LP(a_y - v_x (r - b_hat)) / g)``, with the
    yaw-rate gyro bias ``b_hat`` estimated on the same straights.

    Row 3 of model.md with effects.md's ``road_bank`` reads ``M (vy' + vx r) + e34 r' + e35 phi'' +
    e36 delta'' = Fyf + Fyr - M g sin(beta)``, and the lateral accelerometer gives ``a_y = (Fyf +
    Fyr) / M`` (:meth:`ptw_env.vehicle.Vehicle.ay_row`), so

    .. math::

        a_y - v_x r = \\dot v_y + (e_{34} \\dot r + e_{35} \\ddot\\phi + e_{36} \\ddot\\delta) / M
                    + g \\sin\\beta .

    Every term but the last is a derivative of a bounded signal, large in curves (a curve entry's
    ``vy'`` and ``r'``): the estimate takes only samples ridden straight (the bias-corrected yaw rate
    low-passed over ``straight_tau_s`` = 0.5 s below ``straight_yaw_rate`` = 0.05 rad/s), averages
    them until ``tau_s`` (10 s) of straight riding have been seen, then low-passes them with that
    time constant; it says 0 (level) until ``warmup_s`` (3 s) of straight riding, and holds in curves.

    Gyro bias (issue 20): a yaw-rate gyro bias ``b`` enters as ``-v_x b``: 0.01 rad/s at 15 m/s
    would read as a bank of 0.015 rad. On a straight road a rider holds the line, the heading is
    constant, so the true yaw rate averages to zero there and the measured one to ``b``: ``b_hat``
    is the average of the measured yaw rate over the straight samples (a low-pass of ``bias_tau_s``
    = 60 s once that many have been seen: a sensor's bias does not wander, and a slow manoeuvre's
    yaw rate, below the straight threshold at low speed, only averages out over its whole length),
    used once ``bias_warmup_s`` = 3 s of straights have been seen and only while it stands out of
    its own noise (``|b_hat| > 3 sigma_r / sqrt(n_eff)``: on the robot bicycle, whose yaw-rate noise
    at 5 % is 0.14 rad/s, an unchecked average wanders by 0.008 rad/s), and subtracted from ``r`` (here and, by :class:`RiskPipeline`, in the yaw-rate channel the
    estimator reads). It needs that rider: one who keeps the road-relative roll at zero on a banked
    straight turns slowly downhill, a real yaw rate this estimate would take for a bias
    (:func:`ptw_env.ride.ride_scenario` ``hold_line``; the risk evaluation's rider holds the line). What stays indistinguishable
    from a bank: a lateral accelerometer offset ``o`` (it adds ``o`` to ``a_y - v_x r`` on straights
    and in corners alike, at every speed, as ``g sin(beta)`` does; 0.1 m/s^2 reads as 0.010 rad),
    and a bank that changes faster than ``tau_s`` of straight riding. Read as a bank, the offset is
    at least explained the way the estimator's model sees it: a steady ``a_y`` with no turn.

    Measured: ``scripts/eval_risk.py`` (README, "Risk warning").

    >>> be = BankEstimate(tau_s=1.0)
    >>> for _ in range(1000):
    ...     b = be.update(ay=9.81 * math.sin(0.03), yaw_rate=0.01, vx=15.0)  # straight, gyro bias 0.01 rad/s
    >>> round(b, 4), round(be.yaw_rate_bias, 4)
    (0.03, 0.01)
    """

    def __init__(self, tau_s: float = 10.0, dt: float = 0.01, limit: float = 0.3, record: bool = False,
                 straight_yaw_rate: float = 0.05, straight_tau_s: float = 0.5, warmup_s: float = 3.0,
                 bias_tau_s: float = 60.0, bias_warmup_s: float = 3.0) -> None:
        for name, v in (("tau_s", tau_s), ("dt", dt), ("limit", limit), ("straight_yaw_rate", straight_yaw_rate),
                        ("straight_tau_s", straight_tau_s), ("warmup_s", warmup_s), ("bias_tau_s", bias_tau_s),
                        ("bias_warmup_s", bias_warmup_s)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"BankEstimate {name} must be a positive number, got {v!r}")
        self.tau_s, self.dt, self.limit = float(tau_s), float(dt), float(limit)
        self.straight_yaw_rate, self.straight_tau_s = float(straight_yaw_rate), float(straight_tau_s)
        self.warmup_s = float(warmup_s)
        self.bias_tau_s, self.bias_warmup_s = float(bias_tau_s), float(bias_warmup_s)
        #: keep every estimate since the last reset in :attr:`history`
        self.record = bool(record)
        self.reset()

    def reset(self) -> None:
        self._f = 0.0
        self._n = 0
        self._r = math.nan
        self._b = 0.0
        self._b2 = 0.0
        self._v = 0.0
        self.bank = 0.0
        #: the yaw-rate gyro bias estimate [rad/s] (0 until ``warmup_s`` of straight riding)
        self.yaw_rate_bias = 0.0
        self.history: list[float] | None = [] if self.record else None

    def update(self, ay: float, yaw_rate: float, vx: float) -> float:
        """Take one sample (``a_y`` [m/s^2], ``r`` [rad/s], ``v_x`` [m/s]; NaN: skipped); the bank [rad]."""
        r = float(yaw_rate)
        if math.isfinite(r):  # |low-passed, bias-corrected yaw rate| below straight_yaw_rate: riding straight
            ar = 1.0 - math.exp(-self.dt / self.straight_tau_s)
            rc = r - self.yaw_rate_bias
            self._r = rc if math.isnan(self._r) else self._r + ar * (rc - self._r)
        z = float(ay) - float(vx) * r
        if math.isfinite(z) and abs(self._r) < self.straight_yaw_rate:
            # the mean of the straight samples so far, then a low-pass of time constant tau_s
            self._n += 1
            a = max(1.0 - math.exp(-self.dt / self.tau_s), 1.0 / self._n)
            self._f += a * (z - self._f)
            self._v += a * (float(vx) - self._v)
            # the bias is a property of the sensor: averaged longer, and used once bias_warmup_s of straights
            # have been seen (a manoeuvre's yaw rate averages out over its whole length, not over seconds)
            ab = max(1.0 - math.exp(-self.dt / self.bias_tau_s), 1.0 / self._n)
            self._b += ab * (r - self._b)
            self._b2 += ab * (r * r - self._b2)
            # used once bias_warmup_s of straights are in and only where it stands out of its own noise:
            # |b_hat| above 3 standard errors, sigma_r^2 / n_eff (n_eff: the samples the average holds)
            n_eff = min(self._n, 2.0 * self.bias_tau_s / self.dt)
            se = math.sqrt(max(self._b2 - self._b * self._b, 0.0) / n_eff)
            if self._n * self.dt >= self.bias_warmup_s:
                self.yaw_rate_bias = self._b if abs(self._b) > 3.0 * se else 0.0
            if self._n * self.dt >= self.warmup_s:  # before: too few samples, the level road stands
                zc = self._f + self._v * self.yaw_rate_bias  # the same average of v_x b as z holds
                self.bank = math.asin(max(-math.sin(self.limit), min(math.sin(self.limit), zc / G)))
        if self.history is not None:
            self.history.append(self.bank)
        return self.bank

    def summary(self) -> dict[str, float] | None:
        """The recorded estimates [rad] (``record=True``): ``{"median", "p5", "p95", "final"}``; None without any."""
        if not self.history:
            return None
        b = np.asarray(self.history, dtype=float)
        return {"median": float(np.median(b)), "p5": float(np.percentile(b, 5)), "p95": float(np.percentile(b, 95)),
                "final": float(b[-1])}


class RiskPipeline:
    """One estimator and one monitor, fed sample by sample.

    Parameters
    ----------
    estimator : StiffnessEstimator, optional
        Default: :func:`default_estimator` for ``vehicle`` and ``tire``.
    monitor : RiskMonitor, optional
        Default: :class:`RiskMonitor` with its defaults for ``vehicle`` (its axle loads and nominal stiffnesses).
    road_bank : "auto", float or None
        ``"auto"`` (default): an estimator that carries the bank as a state (``estimates_bank`` true, as
        :class:`~assist.estimation.friction_imm.FrictionIMM`, the default for ``tire="peak"``) estimates it
        itself; for one with a settable ``road_bank`` only (as
        :class:`~assist.estimation.adaptive_observer.AdaptiveObserver`) the bank is estimated on line by
        :class:`BankEstimate` and given to it before every sample; others are left as they are. A
        number [rad]: that bank, fixed (the estimator must take it). ``None``: leave the estimator as
        it is (the friction filter estimates the bank; the adaptive observer rides a level road). Why on line by default: roads are built
        with a cross-fall of 0.02-0.04 rad, and a level-road estimator reads it as grip
        (an earlier evaluation with the stiffness reading, 20 dry rides on such banks: friction
        over-estimated by up to 45 % and a false danger in 9 of them with a level-road estimator;
        ``scripts/eval_risk.py`` now: no false warning on 40 banked dry rides, bank estimated on line).
    vehicle : Vehicle, optional
        The vehicle of the default estimator and monitor (default the reference scooter).
    tire : {"peak", "stiffness"}
        How the default monitor reads friction from the stiffness estimate
        (:class:`~assist.risk.friction_estimate.FrictionConfig` ``tire``): from the bend of the tire curve
        (default; wet roads that lower the peak) or from its slope (roads that scale the whole curve).
    """

    def __init__(self, estimator=None, monitor: RiskMonitor | None = None,
                 road_bank: float | str | None = "auto", vehicle: Vehicle | None = None, tire: str = "peak") -> None:
        self.estimator = default_estimator(vehicle=vehicle, tire=tire) if estimator is None else estimator
        if not isinstance(self.estimator, StiffnessEstimator):
            raise TypeError("estimator must have update(y, tau, vx), reset(), stiffness and stiffness_std; "
                            f"got {type(self.estimator).__name__}")
        if monitor is None:
            monitor = RiskMonitor(friction=FrictionEstimate(FrictionConfig(tire=tire), vehicle=vehicle), vehicle=vehicle)
        self.monitor = monitor
        self.bank_estimate: BankEstimate | None = None
        settable = hasattr(self.estimator, "road_bank")
        if road_bank == "auto":
            # an estimator that carries the bank (and the sensor offsets) as states needs no BankEstimate
            if settable and not getattr(self.estimator, "estimates_bank", False):
                self.bank_estimate = BankEstimate(dt=float(getattr(self.estimator, "dt", 0.01)))
        elif isinstance(road_bank, str):
            raise ValueError(f"road_bank must be 'auto', a number [rad] or None, got {road_bank!r}")
        elif road_bank is not None:
            if not settable:
                raise TypeError(f"road_bank needs an estimator with a settable road_bank; "
                                f"{type(self.estimator).__name__} has none")
            self.estimator.road_bank = road_bank
        self._vx = math.nan
        self.last_inputs: MonitorInputs | None = None

    def reset(self) -> None:
        """Reset the estimator, the bank estimate and the monitor."""
        self.estimator.reset()
        self.monitor.reset()
        if self.bank_estimate is not None:
            self.bank_estimate.reset()
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
        if self.bank_estimate is not None:
            self.estimator.road_bank = self.bank_estimate.update(y[4], y[1], self._vx)
            y = y.copy()
            y[1] -= self.bank_estimate.yaw_rate_bias  # the gyro bias found on the straights (BankEstimate)
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
                                         None if forces is None else forces.copy(), path,
                                         getattr(est, "friction_reading", None))
        return self.monitor.update(*self.last_inputs)


__all__ = ["BankEstimate", "MonitorInputs", "OUTPUTS", "output_matrix", "RiskPipeline", "StiffnessEstimator", "default_estimator",
           "friction_estimator", "stiffness_estimator"]
