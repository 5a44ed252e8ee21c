"""Risk warning from the estimated road friction: utilisation, safe lean, safe curve speed, levels.

:class:`RiskMonitor` is a plain object fed, once per sample, with a tire
stiffness estimate or an estimator's own friction reading (by default the friction filter
:class:`assist.estimation.friction_imm.FrictionIMM`, see :mod:`assist.risk.pipeline`), the estimated axle forces, the
speed, the measured lateral acceleration and the path ahead. It returns a
:class:`RiskAssessment`. The aim is the one of Fouka, Nehaoua, Arioui [1]_
(introduction): "the rider should be aware at each instant about the
available road friction and the optimal turn speed".

Quantities (``g`` = 9.81 m/s^2, ``mu_hat`` and its 1-sigma from
:class:`assist.risk.friction_estimate.FrictionEstimate`)
-------------------------------------------------------------------------
* Friction utilisation per axle, now: ``u_k = |F_k| / (mu_hat Fz_k)`` with the
  estimated lateral force ``F_k`` (the observer's ``x_hat[6:8]``) and the
  static loads ``Fzf`` = 1254.5 N, ``Fzr`` = 1721.0 N of model.md (without
  force estimates: ``u = |a_y| / (mu_hat g)`` on both axles).
* Utilisation of the path ahead (a navigation map's curvature ``kappa(d)`` at
  distance ``d`` ahead, over ``max(preview_min_m, v preview_s)``), at the speed
  the rider can still reach there with comfortable braking ``a_c`` (3 m/s^2),
  ``v(d)^2 = max(v^2 - 2 a_c d, 0)``, ``u_ahead = max_d v(d)^2 |kappa(d)| / (mu_hat g)``.
* The rider's style: the usual cornering demand ``a_u`` = the largest 0.3 s
  low-passed lateral acceleration of the last ``style_window_s`` (60 s), in g,
  and its share of the estimated grip ``u_u = a_u / mu_hat``. A rider who
  keeps the pace onto a wet patch will corner at ``a_u`` again: when ``u_u``
  exceeds the margin the grip has dropped below the riding, which the
  warning says as soon as the estimate knows it (on a straight too), before
  the next curve is in the preview.
* The grip the rider has been riding on: ``mu_before`` = the largest
  ``mu_hat`` of the same ``style_window_s`` (the prior until a first reading),
  and the drop index ``delta = m mu_before / (mu_hat + k_d sigma)``. At
  ``delta >= 1`` a turn that used the margin's share of the earlier grip now
  needs all of the grip read: the rider's habits were formed on a road that is
  no longer there. This warns of a read drop whatever the tires use at that
  moment (a wet patch read under a gentle corner, where ``rho`` and ``pi`` stay
  below their thresholds). The drop must be confirmed: ``k_d`` =
  ``drop_sigmas`` (2) for a friction mapped from a stiffness estimate, which
  moves with the estimate's noise sample by sample (on a dry ride it dips far
  enough now and then); 0 for an estimator's own reading (``reading``), which
  is itself a decision (the friction filter reads a lower friction only at
  0.999 of its probability or 18.7 nats of evidence).
* Maximum safe lean ``phi_safe = atan(m mu_hat)`` and safe speed for the next
  curve ``v_safe = sqrt(m mu_hat g / kappa_max)`` (``kappa_max``: the largest
  ``|kappa|`` ahead), with the margin ``m`` = ``margin`` (0.7: a steady turn may
  use at most 70 % of the estimated grip; the lean-in needs the rest: on the
  wet-patch rides of :mod:`assist.risk.evaluation` a curve whose steady demand
  is 75-80 % of the grip already saturates the front tire while the rider
  leans in, and the estimate itself is good to a few %). ``phi_safe =
  atan(mu)`` is the steady-turn balance ``tan(phi) = a_y / g`` at the friction limit.
* Risk index ``rho = max(u_f, u_r, u_ahead)`` with ``mu_hat``; the same with the
  *confirmed* friction ``mu_low = max(mu_hat - k sigma, mu_floor)`` (``k`` =
  ``confirm_sigmas`` = 2) is ``rho_low = rho mu_hat / mu_low``; the style index
  ``pi = u_u / m`` (>= 1: the usual cornering needs more than ``m`` of the grip).

Levels, with hysteresis and a minimum dwell
------------------------------------------
==========  ===========================================  ==========================
level       enter when                                   leave when (and dwell met)
==========  ===========================================  ==========================
danger      ``rho >= 1.0`` (demand exceeds estimated     ``rho < 0.9``
            grip now, or in the next curve even with
            comfortable braking)
caution     ``rho >= 0.7`` (the margin: 70 % of the       ``rho < 0.6``,
            estimated grip),
            or ``pi >= 1`` (the rider's usual cornering    ``pi < 0.875``,
            needs more than ``m`` of the grip: slow       ``delta < 0.875`` and
            down), or ``delta >= 1`` (the grip read       ``rho_low < 0.9``
            dropped below ``m`` of the grip of the
            last ``style_window_s``), or ``rho_low >= 1.0``
            (grip not confirmed at 2 sigma)
safe        otherwise
==========  ===========================================  ==========================

A higher level is taken at once; a lower one only after the current level has
lasted ``min_dwell_s`` (1 s) *and* the index is below the exit threshold, also
with the lowest ``mu_hat`` of the last ``min_dwell_s`` (an estimate that jitters
up while the tires near their limit does not lift a warning), so a signal
oscillating around a threshold gives at most one change per dwell time and
none inside the hysteresis band. Every assessment carries a
human-readable reason naming what governs it.

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers" (``shared/papers/000_348caefc9b08ee38.txt``).

Examples
--------
>>> import math, numpy as np
>>> from assist.risk.friction_estimate import NOMINAL_STIFFNESS as c0, FrictionConfig
>>> mon = RiskMonitor(friction=FrictionEstimate(FrictionConfig(tire="stiffness")))  # stiffness tells the friction
>>> path = PathAhead(distance=np.array([0.0, 20.0, 40.0]), kappa=np.array([0.0, 0.02, 0.02]))
>>> a = mon.update(0.0, 0.5 * c0, 0.05 * c0, vx=20.0, ay=3.0, forces=(400.0, 550.0), path=path)
>>> a.level, round(a.mu_hat, 2), round(math.degrees(a.max_safe_lean), 1), round(a.safe_speed_next_curve, 1)
('danger', 0.45, 17.5, 12.4)
>>> print(a.reason)
danger: next curve (R 50 m, 20 m ahead) needs 0.57 g at 16.7 m/s (60 km/h); estimated grip 0.45 +- 0.02: safe speed 12.4 m/s (45 km/h)
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

from ptw_env.vehicle import G, REFERENCE_SCOOTER, Vehicle

from .friction_estimate import FrictionEstimate, FrictionState

#: Warning levels, in increasing severity (``RiskAssessment.level_code`` indexes this).
LEVELS: tuple[str, ...] = ("safe", "caution", "danger")
SAFE, CAUTION, DANGER = 0, 1, 2


class RiskInputError(ValueError):
    """A speed, force, path or option the risk monitor cannot use (the message names it)."""


def _pos(name: str, v, allow_zero: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise RiskInputError(f"{name} must be a finite number, got {v!r}")
    if v < 0 or (v == 0 and not allow_zero):
        raise RiskInputError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class RiskConfig:
    """Thresholds and margins of :class:`RiskMonitor` (module docstring for their meaning).

    Attributes
    ----------
    caution_enter, caution_exit, danger_enter, danger_exit : float
        Risk-index thresholds [-] (0.7, 0.6, 1.0, 0.9): caution at the margin's share of the grip.
    style_enter, style_exit : float
        Thresholds of the riding-style index ``pi`` and of the grip-drop index ``delta`` [-] (1.0, 0.875).
    drop_sigmas : float
        ``k_d`` of the grip-drop index for a friction mapped from a stiffness estimate (2; an estimator's own
        reading is a decision already and takes 0).
    confirm_sigmas : float
        ``k`` of ``mu_low = mu_hat - k sigma`` (2). :class:`RiskMonitor` without a config takes 0 when its
        friction estimate reads a peak-scaling tire (``FrictionConfig.tire="peak"``, the default): such tires
        confirm the grip only near their limit, so a caution on unconfirmed grip would come in every corner.
    mu_floor : float
        Lower bound of ``mu_low`` [-] (0.1).
    min_dwell_s : float
        Shortest time a level is held before a lower one is taken [s] (1.0).
    margin : float
        Fraction of ``mu_hat`` a steady turn may use: the safe lean, the safe speed, and the
        riding-style caution [-] (0.7).
    comfort_decel : float
        Braking the rider can still do before a curve [m/s^2] (3.0, the urban scenario's).
    style_window_s : float
        Window of the rider's usual cornering demand and of the grip ridden before a drop [s] (60).
    preview_s, preview_min_m : float
        Path-ahead horizon: ``max(preview_min_m, v preview_s)`` [s, m] (6 s, 30 m).
    kappa_straight : float
        Curvature below which the road ahead counts as straight [1/m] (1e-3, R > 1 km).
    """

    caution_enter: float = 0.7
    caution_exit: float = 0.6
    danger_enter: float = 1.0
    danger_exit: float = 0.9
    style_enter: float = 1.0
    style_exit: float = 0.875
    confirm_sigmas: float = 2.0
    drop_sigmas: float = 2.0
    mu_floor: float = 0.1
    min_dwell_s: float = 1.0
    margin: float = 0.7
    comfort_decel: float = 3.0
    style_window_s: float = 60.0
    preview_s: float = 6.0
    preview_min_m: float = 30.0
    kappa_straight: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("caution_enter", "caution_exit", "danger_enter", "danger_exit", "style_enter", "style_exit",
                     "mu_floor", "margin", "style_window_s",
                     "preview_s", "preview_min_m", "kappa_straight"):
            _pos(f"RiskConfig.{name}", getattr(self, name))
        for name in ("confirm_sigmas", "drop_sigmas", "min_dwell_s", "comfort_decel"):
            _pos(f"RiskConfig.{name}", getattr(self, name), allow_zero=True)
        if self.style_exit > self.style_enter:
            raise RiskInputError(f"RiskConfig needs style_exit <= style_enter, got {self.style_exit}, {self.style_enter}")
        if not (self.caution_exit <= self.caution_enter <= self.danger_enter and self.danger_exit <= self.danger_enter):
            raise RiskInputError("RiskConfig thresholds must satisfy caution_exit <= caution_enter <= danger_enter "
                                 f"and danger_exit <= danger_enter, got {self.caution_exit}, {self.caution_enter}, "
                                 f"{self.danger_enter}, {self.danger_exit}")
        if self.margin > 1:
            raise RiskInputError(f"RiskConfig.margin is a fraction of the grip, at most 1, got {self.margin}")


@dataclass(frozen=True)
class PathAhead:
    """Curvature of the road ahead: ``kappa[i]`` [1/m] at ``distance[i]`` [m] ahead of the vehicle.

    ``distance`` starts at 0 (here) and increases. A navigation map gives it
    (:meth:`from_map`); without one, :meth:`current` holds only the curvature
    being ridden (e.g. ``yaw_rate / vx``).

    Examples
    --------
    >>> p = PathAhead.from_map(10.0, np.array([0.0, 50.0, 100.0]), np.array([0.0, 0.0, 0.02]), horizon_m=60.0)
    >>> float(p.distance[-1]), round(float(p.kappa[-1]), 4)
    (60.0, 0.008)
    """

    distance: np.ndarray
    kappa: np.ndarray

    def __post_init__(self) -> None:
        d = np.asarray(self.distance, dtype=float).ravel()
        k = np.asarray(self.kappa, dtype=float).ravel()
        if d.shape != k.shape or d.size == 0:
            raise RiskInputError(f"PathAhead needs distance and kappa of equal, non-zero length, got {d.shape}, {k.shape}")
        if not (np.all(np.isfinite(d)) and np.all(np.isfinite(k))):
            raise RiskInputError("PathAhead distance and kappa must be finite")
        if d[0] < 0 or np.any(np.diff(d) <= 0):
            raise RiskInputError("PathAhead distance must start at >= 0 m and increase strictly")
        object.__setattr__(self, "distance", d)
        object.__setattr__(self, "kappa", k)

    @classmethod
    def current(cls, kappa: float) -> "PathAhead":
        """Only the curvature being ridden now (no preview)."""
        return cls(np.zeros(1), np.array([float(kappa)]))

    @classmethod
    def from_map(cls, s_now: float, s_map: np.ndarray, kappa_map: np.ndarray, horizon_m: float,
                 step_m: float = 1.0) -> "PathAhead":
        """Sample a map ``kappa(s)`` (``s_map`` increasing, metres along the route) from ``s_now``
        over ``horizon_m`` every ``step_m`` metres (beyond the map's end: its last value)."""
        n = max(2, int(math.ceil(horizon_m / step_m)) + 1)
        d = np.linspace(0.0, float(horizon_m), n)
        return cls(d, np.interp(s_now + d, s_map, kappa_map))


@dataclass(frozen=True)
class RiskAssessment:
    """What :meth:`RiskMonitor.update` says about one sample.

    Attributes
    ----------
    t : float
        Time [s].
    level : str
        ``"safe"``, ``"caution"`` or ``"danger"`` (after hysteresis and dwell).
    level_code : int
        0, 1, 2.
    reason : str
        Human-readable: what governs the level, with numbers.
    mu_hat, mu_std, mu_low : float
        Estimated available friction, its 1-sigma, and the confirmed friction ``mu_hat - k sigma`` [-].
    friction_informed : bool
        Whether this sample's stiffness estimate was used (enough lateral excitation).
    friction_status : str
        The friction estimate's own status (e.g. "not enough lateral excitation ...").
    excitation : float
        ``|LP(a_y)|`` [m/s^2].
    utilisation_front, utilisation_rear : float
        ``|F_k| / (mu_hat Fz_k)`` now [-].
    utilisation_ahead : float
        Largest utilisation of the path ahead at reachable speed [-] (0 without a path).
    usual_demand : float
        The rider's cornering demand: the largest low-passed lateral acceleration of the last
        ``style_window_s``, in g [-].
    utilisation_usual : float
        ``usual_demand / mu_hat`` [-]: what the rider's style would use of the estimated grip.
    grip_before : float
        ``mu_before``: the largest ``mu_hat`` of the last ``style_window_s`` [-].
    grip_drop_index : float
        ``delta = margin mu_before / (mu_hat + k_d mu_std)`` [-] (>= 1: the grip read dropped below the margin's
        share of it; ``k_d``: :class:`RiskConfig`).
    risk_index, risk_index_low : float
        ``rho`` with ``mu_hat`` and with ``mu_low`` [-].
    max_safe_lean : float
        ``atan(margin mu_hat)`` [rad].
    safe_speed_next_curve : float
        ``sqrt(margin mu_hat g / kappa_max)`` [m/s] (``inf``: straight ahead).
    next_curve_distance, next_curve_kappa : float
        Where the path ahead is most demanding [m] and its curvature [1/m] (NaN without a path).
    """

    t: float
    level: str
    level_code: int
    reason: str
    mu_hat: float
    mu_std: float
    mu_low: float
    friction_informed: bool
    friction_status: str
    excitation: float
    utilisation_front: float
    utilisation_rear: float
    utilisation_ahead: float
    usual_demand: float
    utilisation_usual: float
    grip_before: float
    grip_drop_index: float
    risk_index: float
    risk_index_low: float
    max_safe_lean: float
    safe_speed_next_curve: float
    next_curve_distance: float
    next_curve_kappa: float

    @property
    def utilisation(self) -> float:
        """``max(u_f, u_r)`` now [-]."""
        return max(self.utilisation_front, self.utilisation_rear)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (``inf``/NaN become None)."""
        out = asdict(self)
        for k, v in out.items():
            if isinstance(v, float) and not math.isfinite(v):
                out[k] = None
        return out


def safe_lean_angle(mu: float, margin: float = 1.0) -> float:
    """``atan(margin mu)`` [rad]: the steady-turn lean ``tan(phi) = a_y / g`` at ``a_y = margin mu g``.

    >>> round(math.degrees(safe_lean_angle(0.9)), 2), round(math.degrees(safe_lean_angle(0.9, 0.8)), 2)
    (41.99, 35.75)
    """
    return math.atan(margin * mu)


def safe_curve_speed(mu: float, kappa: float, margin: float = 1.0, g: float = G) -> float:
    """``sqrt(margin mu g / |kappa|)`` [m/s] (``inf`` for ``kappa = 0``).

    >>> round(safe_curve_speed(0.45, 1 / 50.0), 2), safe_curve_speed(0.9, 0.0)
    (14.86, inf)
    """
    k = abs(float(kappa))
    return math.inf if k == 0 else math.sqrt(margin * mu * g / k)


class WindowMax:
    """The largest value pushed in the last ``window`` seconds (the last push included), in O(1) amortised per
    push: a deque kept decreasing in value (each value leaves once, when a later one at least as large arrives
    or when it is older than the window).

    >>> w = WindowMax(1.0)
    >>> [w.push(t, v) for t, v in [(0.0, 3.0), (0.5, 1.0), (1.2, 2.0), (1.6, 0.5)]]
    [3.0, 3.0, 2.0, 2.0]
    """

    def __init__(self, window: float) -> None:
        self.window = _pos("WindowMax window [s]", window, allow_zero=True)
        self._q: deque[tuple[float, float]] = deque()

    def push(self, t: float, v: float) -> float:
        """Add ``v`` at time ``t`` (non-decreasing) and return the largest value of ``[t - window, t]``."""
        q = self._q
        while q and q[-1][1] <= v:
            q.pop()
        q.append((float(t), float(v)))
        while q[0][0] < t - self.window:
            q.popleft()
        return q[0][1]


class RiskMonitor:
    """Friction utilisation, safe lean and curve speed, and warning levels (module docstring).

    Parameters
    ----------
    config : RiskConfig, optional
    friction : FrictionEstimate, optional
        The stiffness-to-friction stage (default: :class:`FrictionEstimate` with its defaults, on ``vehicle``).
    vehicle : Vehicle, optional
        For the static axle loads and the nominal stiffnesses (default: the reference scooter).
    """

    def __init__(self, config: RiskConfig | None = None, friction: FrictionEstimate | None = None,
                 vehicle: Vehicle | None = None) -> None:
        v = REFERENCE_SCOOTER if vehicle is None else vehicle
        self.friction = FrictionEstimate(vehicle=v) if friction is None else friction
        if config is None:  # RiskConfig.confirm_sigmas: nothing to confirm on a peak-scaling tire
            config = RiskConfig(confirm_sigmas=0.0) if self.friction.config.tire == "peak" else RiskConfig()
        self.config = config
        if not isinstance(self.config, RiskConfig):
            raise RiskInputError(f"config must be a RiskConfig, got {type(config).__name__}")
        self.fz = np.array([v.tires.Fzf, v.tires.Fzr])
        self.reset()

    def reset(self) -> None:
        """Start over: level safe, friction back to its prior."""
        self.friction.reset()
        self._level = SAFE
        self._t_enter = -math.inf
        self._mu_low = WindowMax(self.config.min_dwell_s)  # of -mu_hat
        self._demand = WindowMax(self.config.style_window_s)
        self._grip = WindowMax(self.config.style_window_s)
        self._reason = ""
        self.last: RiskAssessment | None = None

    # ------------------------------------------------------------------
    def _preview(self, vx: float, mu: float, path: PathAhead | None):
        """``(u_ahead, where, v_reach, kappa_max)`` over the horizon (zeros without a path);
        ``where = (distance, kappa, demand [g])`` of the most demanding point."""
        if path is None:
            return 0.0, None, vx, 0.0
        c = self.config
        horizon = max(c.preview_min_m, vx * c.preview_s)
        m = path.distance <= horizon
        d, k = path.distance[m], np.abs(path.kappa[m])
        if d.size == 0:
            return 0.0, None, vx, 0.0
        v2 = np.maximum(vx * vx - 2.0 * c.comfort_decel * d, 0.0)
        dem = v2 * k / G
        i = int(np.argmax(dem))
        return float(dem[i] / mu), (float(d[i]), float(k[i]), float(dem[i])), math.sqrt(v2[i]), float(k.max())

    def update(self, t: float, stiffness, stiffness_std, vx: float, ay: float, forces=None,
               path: PathAhead | None = None, reading=None) -> RiskAssessment:
        """Assess one sample.

        Parameters
        ----------
        t : float
            Time [s], increasing.
        stiffness, stiffness_std : array_like (4,)
            Estimated ``[C_alpha_f, C_gamma_f, C_alpha_r, C_gamma_r]`` and 1-sigma [N/rad].
        vx : float
            Forward speed [m/s].
        ay : float
            Measured lateral acceleration [m/s^2] (NaN: a dropout).
        forces : (float, float), optional
            Estimated lateral forces ``(Fyf, Fyr)`` [N].
        path : PathAhead, optional
            Curvature of the road ahead.
        reading : FrictionReading, optional
            The estimator's own friction reading (:meth:`FrictionEstimate.update`), instead of the
            stiffness mapping.
        """
        c = self.config
        vx = _pos("vx", vx)
        if forces is not None:
            Fs = np.asarray(forces, dtype=float).ravel()
            if Fs.shape != (2,) or not np.all(np.isfinite(Fs)):
                raise RiskInputError(f"forces must be two finite numbers (Fyf, Fyr) [N], got {forces!r}")
        fr: FrictionState = self.friction.update(t, stiffness, stiffness_std, ay,
                                                 None if forces is None else G * Fs / self.fz, reading)
        mu, sd = fr.mu_hat, fr.mu_std
        mu_low = max(mu - c.confirm_sigmas * sd, c.mu_floor)
        F = np.abs(Fs) if forces is not None else self.fz * fr.excitation / G
        u_axle = F / (mu * self.fz)
        u_now = float(u_axle.max())
        u_ahead, where, v_reach, kmax = self._preview(vx, mu, path)
        rho = max(u_now, u_ahead)
        rho_low = rho * mu / mu_low
        # the rider's style: the largest (0.3 s low-passed) lateral demand of the last style_window_s
        usual = self._demand.push(t, fr.excitation / G)
        u_style = usual / mu
        pace = u_style / c.margin
        # the grip ridden on: the largest estimate of the same window, and how far the estimate fell below it
        mu_before = self._grip.push(t, mu)
        drop = c.margin * mu_before / (mu + (0.0 if reading is not None else c.drop_sigmas) * sd)
        v_safe = safe_curve_speed(mu, kmax, c.margin) if kmax > c.kappa_straight else math.inf
        lean = safe_lean_angle(mu, c.margin)

        # target level with the enter/exit thresholds of the current level
        cur = self._level
        d_th = c.danger_exit if cur == DANGER else c.danger_enter
        c_th = c.caution_exit if cur >= CAUTION else c.caution_enter
        p_th = c.style_exit if cur >= CAUTION else c.style_enter
        grip = f"estimated grip {mu:.2f} +- {sd:.2f}"
        if where is not None and u_ahead >= u_now:
            d_i, k_i, dem = where
            if k_i <= c.kappa_straight:
                what = f"road ahead needs {dem:.2f} g"
            else:
                what = (f"{'curve' if d_i < 1.0 else 'next curve'} (R {1 / k_i:.0f} m, {d_i:.0f} m ahead) needs "
                        f"{dem:.2f} g at {v_reach:.1f} m/s ({v_reach * 3.6:.0f} km/h)")
        else:
            ax = "front" if u_axle[0] >= u_axle[1] else "rear"
            what = f"{ax} tire uses {100 * u_now:.0f} % of the estimated grip"
        advice = (f"safe speed {v_safe:.1f} m/s ({v_safe * 3.6:.0f} km/h)" if math.isfinite(v_safe)
                  else f"max safe lean {math.degrees(lean):.0f} deg")
        if rho >= d_th:
            target, reason = DANGER, f"danger: {what}; {grip}: {advice}"
        elif rho >= c_th:
            target, reason = CAUTION, f"caution: {what}; {grip}: {advice}"
        elif pace >= p_th:
            target, reason = CAUTION, (f"caution: {grip} is low for your riding: you have been cornering at "
                                       f"{usual:.2f} g ({100 * u_style:.0f} % of it) in the last "
                                       f"{c.style_window_s:g} s; take the next curves slower: {advice}")
        elif drop >= p_th:
            target, reason = CAUTION, (f"caution: the grip dropped: {grip}, down from {mu_before:.2f} in the last "
                                       f"{c.style_window_s:g} s; {what}; ride as on a low-grip road: {advice}")
        elif rho_low >= d_th:
            why = fr.status if not fr.informed else "the estimate is still uncertain"
            target, reason = CAUTION, (f"caution: grip not confirmed ({why}); {what}, "
                                       f"confirmed grip only {mu_low:.2f} ({grip})")
        else:
            target, reason = SAFE, (f"safe: {what}; {grip} ({fr.status})")
        # a lower level also needs the grip to have stayed up: the indices with the lowest mu_hat of the
        # last min_dwell_s must allow it too (the estimate jitters while the tires near their limit)
        mu_min = -self._mu_low.push(t, -mu)  # the lowest mu_hat of the last min_dwell_s
        if target < cur:
            f = mu / mu_min
            lo_c = c.caution_exit if cur >= CAUTION else c.caution_enter
            held = (DANGER if rho * f >= d_th else
                    CAUTION if (rho * f >= lo_c or pace * f >= p_th or drop * f >= p_th) else SAFE)
            if held > target:
                target = min(held, cur)
                if target == cur:  # the warning stays as it is, and so does its reason
                    reason = self._reason.split(" [held")[0]
                else:  # down one level only (danger -> caution): say why caution stays
                    reason = (f"{LEVELS[target]}: {what}; the estimated grip was as low as {mu_min:.2f} in the "
                              f"last {c.min_dwell_s:g} s ({grip}): {advice}")
        if target > cur or (target < cur and t - self._t_enter >= c.min_dwell_s):
            self._level, self._t_enter = target, t
            self._reason = reason
        elif target == cur:
            self._reason = reason
        else:  # a lower level is due but the dwell time has not passed
            self._reason = self._reason.split(" [held")[0] + f" [held {c.min_dwell_s:g} s minimum]"
        a = RiskAssessment(
            t=float(t), level=LEVELS[self._level], level_code=self._level, reason=self._reason, mu_hat=mu,
            mu_std=sd, mu_low=mu_low, friction_informed=fr.informed, friction_status=fr.status,
            excitation=fr.excitation, utilisation_front=float(u_axle[0]), utilisation_rear=float(u_axle[1]),
            utilisation_ahead=u_ahead, usual_demand=usual, utilisation_usual=u_style,
            grip_before=mu_before, grip_drop_index=drop, risk_index=rho, risk_index_low=rho_low, max_safe_lean=lean,
            safe_speed_next_curve=v_safe, next_curve_distance=math.nan if where is None else where[0],
            next_curve_kappa=math.nan if where is None else where[1],
        )
        self.last = a
        return a


__all__ = [
    "CAUTION",
    "DANGER",
    "LEVELS",
    "PathAhead",
    "RiskAssessment",
    "RiskConfig",
    "RiskInputError",
    "RiskMonitor",
    "SAFE",
    "WindowMax",
    "safe_curve_speed",
    "safe_lean_angle",
]
