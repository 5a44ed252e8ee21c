r"""Road friction that changes along a ride (a wet patch, a damp stretch), for the true plant.

A :class:`FrictionSchedule` gives the road friction ``mu(t)`` or ``mu(s)``
relative to the reference road on which the vehicle's nominal tires were
characterised, ``r = mu / mu_ref`` with ``mu_ref`` = :data:`REFERENCE_FRICTION`
= 0.9 (dry asphalt: the nominal stiffness of model.md *is* the stiffness on a
road of friction 0.9). How the tire follows the road is the schedule's
``scaling`` (:data:`SCALINGS`):

``"peak"`` (the default: a wet road as measured tires see it)
    Friction scales the **peak** force only; the small-slip stiffness stays:

    .. math::

        \mu_{peak} \to r\,\mu_{peak},\qquad C_k \to C_k,\qquad
        F_{ss} = r \mu_{peak} F_z \tanh\!\big(C\alpha / (r \mu_{peak} F_z)\big).

    Source: the brush model's cornering stiffness ``C_Fa = 2 c_p a^2`` (tread stiffness
    times the square of the contact half-length) has no friction in it, while its force
    saturates at ``mu Fz`` (Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., 2012, sec. 3.2.2,
    eqs. 3.26-3.31); in the Magic Formula the friction scaling factor ``lambda_muy``
    multiplies the peak ``D_y = mu_y Fz`` and not the cornering stiffness ``K_ya``
    (same book, sec. 4.3.2, eqs. 4.E13 and 4.E25). A wet road lowers the friction of the
    sliding part of the contact, not the elasticity of the tread. The curve's shape is
    effects.md's ``tanh``; its slope at zero slip is ``C`` whatever ``mu`` is, so at
    ``|F| = 0.2 Fz`` the force at a given slip is 1.7 % below the linear tire's on a road
    of 0.9 and 7.0 % below it on 0.45 (``tanh(x)/x``): that is all a tire-reading
    estimator has to see a wet patch with at that load. Without ``tire_saturation`` in
    the base effects the peak is added: ``tire_saturation:mu_peak = mu`` (the road's
    friction *is* the peak), so a linear tire does not ignore the friction.
``"stiffness_and_peak"`` (the earlier model, kept by name)
    effects.md's ``tire_stiffness`` ("Road friction (mu) scales both equally") and
    ``tire_saturation`` together: ``C_k -> r C_k`` (``front_scale``, ``rear_scale`` times
    ``r``) and ``mu_peak -> r mu_peak``. The whole tanh curve scales, ``F_ss(alpha) = r
    F_ss,ref(alpha)``, so a stiffness estimate tells the friction at any slip (the
    assumption of :mod:`assist.risk.friction_estimate`'s stiffness mapping). It makes a
    wet patch visible at small slip, which measured tires do not; without
    ``tire_saturation`` the tires stay linear and only the stiffness follows ``mu``.

Friction is piecewise linear between the schedule's points and constant
outside them, in time [s] or in travelled distance [m] (a patch is a place on
the road, so ``by="distance"`` is the default). :class:`FrictionPlants`
compiles one plant per distinct friction value (quantised to
:data:`MU_QUANTUM`) and caches it, so a step or a ramp costs a handful of
:func:`~ptw_env.dynamics.compile_plant` calls; :class:`ptw_env.env.PTWRollEnv`
takes a schedule as ``friction=`` and swaps the stepper at each control
period (the state, hence the tire forces, is continuous across a change).

Examples
--------
>>> f = FrictionSchedule.patch(start=100.0, mu_before=0.9, mu_patch=0.45, ramp=5.0)
>>> f.mu(s=0.0), f.mu(s=102.5), f.mu(s=200.0)
(0.9, 0.675, 0.45)
>>> e = f.effects_at(0.45, "tire_saturation:mu_peak=0.9")
>>> e.value("tire_stiffness", "front_scale"), e.value("tire_saturation", "mu_peak")
(1.0, 0.45)
>>> old = FrictionSchedule.patch(start=100.0, mu_before=0.9, mu_patch=0.45, scaling="stiffness_and_peak")
>>> old.effects_at(0.45, "tire_saturation:mu_peak=0.9").value("tire_stiffness", "front_scale")
0.5
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .dynamics import Plant, compile_plant
from .effects import Effects, as_effects
from .integrate import Stepper, speed_grid
from .vehicle import REFERENCE_SCOOTER, Vehicle, speed_array

#: Road friction that the nominal tire stiffness of model.md refers to (dry asphalt) [-].
REFERENCE_FRICTION = 0.9
#: Friction values are rounded to this before a plant is compiled (cache key) [-].
MU_QUANTUM = 1e-3
#: Friction values a schedule may take [-] (effects.md bounds: stiffness scale and mu_peak >= 0.05).
MU_RANGE = (0.05, 2.0)
#: How the tire follows the road's friction (module docstring): the peak only (default), or stiffness and peak.
SCALINGS = ("peak", "stiffness_and_peak")


class FrictionScheduleError(ValueError):
    """A friction schedule with a bad point, order or value (the message names it)."""


@dataclass(frozen=True)
class FrictionSchedule:
    """Road friction along a ride, piecewise linear between points.

    Parameters
    ----------
    points : sequence of (position, mu)
        Positions (seconds for ``by="time"``, metres for ``by="distance"``)
        strictly increasing; friction in :data:`MU_RANGE`. Before the first
        point and after the last the friction is constant.
    by : {"distance", "time"}
        What the positions measure (default: distance travelled, ``s = int vx dt``).
    mu_ref : float
        Friction of the road the nominal tires refer to (default :data:`REFERENCE_FRICTION`).
    scaling : {"peak", "stiffness_and_peak"}
        What the friction scales (module docstring): the tire's peak force only (default, a
        measured wet road), or its stiffness and peak together (the earlier model).

    Examples
    --------
    >>> FrictionSchedule([(0.0, 0.9), (10.0, 0.5)], by="time").mu(t=5.0)
    0.7
    """

    points: tuple[tuple[float, float], ...]
    by: str = "distance"
    mu_ref: float = REFERENCE_FRICTION
    scaling: str = "peak"

    def __post_init__(self) -> None:
        if self.scaling not in SCALINGS:
            raise FrictionScheduleError(f"scaling must be one of {', '.join(SCALINGS)}, got {self.scaling!r}")
        if self.by not in ("distance", "time"):
            raise FrictionScheduleError(f"by must be 'distance' or 'time', got {self.by!r}")
        try:
            pts = tuple((float(p), float(m)) for p, m in self.points)
        except (TypeError, ValueError):
            raise FrictionScheduleError(f"points must be (position, mu) pairs of numbers, got {self.points!r}") from None
        if not pts:
            raise FrictionScheduleError("a friction schedule needs at least one (position, mu) point")
        for i, (p, m) in enumerate(pts):
            if not math.isfinite(p):
                raise FrictionScheduleError(f"point {i}: position must be finite, got {p!r}")
            if not (MU_RANGE[0] <= m <= MU_RANGE[1]):
                raise FrictionScheduleError(f"point {i}: mu = {m!r} is outside [{MU_RANGE[0]}, {MU_RANGE[1]}]")
            if i and p <= pts[i - 1][0]:
                raise FrictionScheduleError(f"point {i}: positions must increase strictly ({pts[i - 1][0]} then {p})")
        if not (MU_RANGE[0] <= float(self.mu_ref) <= MU_RANGE[1]):
            raise FrictionScheduleError(f"mu_ref = {self.mu_ref!r} is outside [{MU_RANGE[0]}, {MU_RANGE[1]}]")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "mu_ref", float(self.mu_ref))

    # ------------------------------------------------------------------ construction
    @classmethod
    def constant(cls, mu: float, mu_ref: float = REFERENCE_FRICTION, scaling: str = "peak") -> "FrictionSchedule":
        """The same friction everywhere."""
        return cls(((0.0, mu),), mu_ref=mu_ref, scaling=scaling)

    @classmethod
    def patch(cls, start: float, mu_before: float, mu_patch: float, length: float = math.inf,
              ramp: float = 0.0, by: str = "distance", mu_ref: float = REFERENCE_FRICTION,
              scaling: str = "peak") -> "FrictionSchedule":
        """``mu_before`` up to ``start``, then ``mu_patch`` over ``length`` (default: to the end),
        with linear transitions of ``ramp`` (same unit as ``start``; 0: a step)."""
        for name, v in (("start", start), ("ramp", ramp)):
            if not (math.isfinite(v) and v >= 0):
                raise FrictionScheduleError(f"{name} must be a finite number >= 0, got {v!r}")
        if not (length > 0):
            raise FrictionScheduleError(f"length must be > 0, got {length!r}")
        eps = 1e-9
        r = max(ramp, eps)
        pts = [(start, mu_before), (start + r, mu_patch)]
        if math.isfinite(length):
            end = start + max(length, r + eps)
            pts += [(end, mu_patch), (end + r, mu_before)]
        return cls(tuple(pts), by=by, mu_ref=mu_ref, scaling=scaling)

    # ------------------------------------------------------------------ queries
    def mu(self, t: float | None = None, s: float | None = None) -> float:
        """Road friction at time ``t`` [s] or distance ``s`` [m] (the one this schedule is indexed by)."""
        x = s if self.by == "distance" else t
        if x is None:
            raise FrictionScheduleError(f"this schedule is indexed by {self.by}; pass {'s' if self.by == 'distance' else 't'}=")
        p = self.points
        if x <= p[0][0]:
            return p[0][1]
        if x >= p[-1][0]:
            return p[-1][1]
        xs = [q[0] for q in p]
        i = int(np.searchsorted(xs, x, side="right"))
        (x0, m0), (x1, m1) = p[i - 1], p[i]
        return m0 + (m1 - m0) * (x - x0) / (x1 - x0)

    def along(self, t: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Friction at each sample of a ride (arrays of time [s] and distance [m])."""
        x = np.asarray(s if self.by == "distance" else t, dtype=float)
        xs, ms = zip(*self.points)
        return np.interp(x, xs, ms)

    def effects_at(self, mu: float, base: Effects | Any = None) -> Effects:
        """The dynamic effects of the plant on a road of friction ``mu`` (module docstring):
        ``"peak"``: ``base`` with ``mu_peak`` times ``mu / mu_ref`` (``tire_saturation:mu_peak = mu``
        if ``base`` has none); ``"stiffness_and_peak"``: both stiffness scales and (if present)
        ``mu_peak`` times ``mu / mu_ref``."""
        base = as_effects(base)
        r = float(mu) / self.mu_ref
        extra: dict[str, dict[str, float]] = {}
        if self.scaling == "stiffness_and_peak":
            extra["tire_stiffness"] = {
                "front_scale": float(base.value("tire_stiffness", "front_scale")) * r,
                "rear_scale": float(base.value("tire_stiffness", "rear_scale")) * r,
            }
        if base.has("tire_saturation"):
            extra["tire_saturation"] = {"mu_peak": float(base.value("tire_saturation", "mu_peak")) * r}
        elif self.scaling == "peak":
            extra["tire_saturation"] = {"mu_peak": float(mu)}
        return base.dynamic | Effects(extra)

    def to_json(self) -> dict[str, Any]:
        """``{"by", "mu_ref", "scaling", "points": [[position, mu], ...]}``."""
        return {"by": self.by, "mu_ref": self.mu_ref, "scaling": self.scaling, "points": [list(p) for p in self.points]}

    @classmethod
    def from_json(cls, d: Any) -> "FrictionSchedule":
        """The schedule of :meth:`to_json` (a log's sidecar ``truth.friction``); a dict without
        ``scaling`` was written before the key existed, by the ``"stiffness_and_peak"`` model."""
        if not isinstance(d, dict) or "points" not in d:
            raise FrictionScheduleError(f"a friction schedule must be a dict with 'points', got {d!r}")
        try:
            pts = tuple(tuple(p) for p in d["points"])
        except TypeError:
            raise FrictionScheduleError(f"points must be (position, mu) pairs, got {d['points']!r}") from None
        return cls(pts, by=d.get("by", "distance"), mu_ref=d.get("mu_ref", REFERENCE_FRICTION),
                   scaling=d.get("scaling", "stiffness_and_peak"))


class FrictionPlants:
    """Compiled plants and steppers of one vehicle for the friction values a schedule visits (cached).

    Parameters
    ----------
    schedule : FrictionSchedule
    vehicle : Vehicle, optional
    effects : Effects or anything :func:`~ptw_env.effects.as_effects` takes
        The base dynamic effects (on the reference road).
    dt : float
        Control period of the steppers [s].
    speeds : array, optional
        Speeds [m/s] the steppers' substeps are sized for (:class:`ptw_env.integrate.Stepper`; default the
        vehicle's whole range).

    Examples
    --------
    >>> fp = FrictionPlants(FrictionSchedule.constant(0.45), effects="tire_saturation:mu_peak=0.9")
    >>> [round(float(v), 2) for v in fp.plant(0.45).fmax]
    [564.54, 774.43]
    """

    def __init__(self, schedule: FrictionSchedule, vehicle: Vehicle | None = None, effects=None,
                 dt: float = 0.01, speeds=None) -> None:
        if not isinstance(schedule, FrictionSchedule):
            raise FrictionScheduleError(f"friction must be a FrictionSchedule, got {type(schedule).__name__}")
        self.schedule = schedule
        self.vehicle = vehicle
        self.effects = as_effects(effects).dynamic
        self.dt = float(dt)
        if speeds is not None:  # the Stepper's check (speed_grid), made here rather than at the first new friction
            speed_grid(REFERENCE_SCOOTER if vehicle is None else vehicle, speeds)
        self.speeds = None if speeds is None else speed_array(speeds)
        self._cache: dict[float, tuple[Plant, Stepper]] = {}

    def _entry(self, mu: float) -> tuple[Plant, Stepper]:
        key = round(round(float(mu) / MU_QUANTUM) * MU_QUANTUM, 6)
        hit = self._cache.get(key)
        if hit is None:
            plant = compile_plant(self.vehicle, self.schedule.effects_at(key, self.effects))
            hit = (plant, Stepper(plant, self.dt, speeds=self.speeds))
            self._cache[key] = hit
        return hit

    def plant(self, mu: float) -> Plant:
        """The plant on a road of friction ``mu``."""
        return self._entry(mu)[0]

    def stepper(self, mu: float) -> Stepper:
        """The stepper of :meth:`plant` ``(mu)``."""
        return self._entry(mu)[1]


__all__ = [
    "FrictionPlants",
    "FrictionSchedule",
    "FrictionScheduleError",
    "MU_QUANTUM",
    "MU_RANGE",
    "REFERENCE_FRICTION",
    "SCALINGS",
]
