"""Evaluation rides of the risk warning, with tire saturation on, and the simulator's truth.

Ride types (all with ``tire_saturation:mu_peak=0.9`` and a
:class:`~ptw_env.friction.FrictionSchedule`, so the true peak friction is the
schedule's ``mu``; by default friction scales the tire's *peak* only, its
small-slip stiffness stays (``scaling="peak"``, a wet road as measured tires
see it, :mod:`ptw_env.friction`); ``make_case(..., scaling="stiffness_and_peak")``
rides the earlier model; 5 % sensor noise; the scenario's LQR rider,
:func:`ptw_env.ride.ride_scenario`):

``dry``
    The urban scenario ridden at a brisk normal pace, ``lateral_g = 0.5``
    (cornering at about 56 % of the grip, 27 deg of lean) on dry asphalt,
    ``mu = 0.9`` throughout; 60 s. The route is drawn from the seed.
``wet``
    The same ride (same route and pace) onto a wet patch: ``mu`` drops from
    0.9 to 0.45 (over 2 m) at mid-ride distance and stays there.
``wet_straight``, ``wet_corner``
    The same patch, beginning on a straight (the first sample after mid-ride with no curvature in
    the second before and the :data:`STRAIGHT_AHEAD_S` after) or in a corner (the first sample
    after mid-ride (else after the first quarter, else from the start) where the route's demand ``v^2 |kappa| / g``
    reaches a level drawn from :data:`CORNER_DEMAND_G`, 0.25-0.45 g: the tires carry a fifth to a
    half of their load sideways).
``dry_long``, ``wet_long``
    The same with curve entries of 2.5 s instead of 1.2 s (``ramp_s``;
    rural-road clothoids instead of urban corners).
``dry_bank``, ``wet_bank``
    ``dry`` and ``wet`` on a road with a cross-fall (effects.md ``road_bank``), drawn from the
    seed: 0.015-0.04 rad, either sign (roads are built with 0.02-0.04 for drainage). The rider holds
    the line on it (:func:`ptw_env.ride.ride_scenario` ``hold_line``: leans by about the bank on a
    straight, instead of turning slowly downhill).
``dry_offsets``
    ``dry`` with a yaw-rate gyro bias of 0.01 rad/s and a lateral accelerometer offset of
    0.1 m/s^2 (:data:`OFFSETS`, signs drawn from the seed).
``too_fast``
    :class:`CurveTooFast`: a damp road (``mu`` 0.55-0.62 throughout, drawn
    from the seed), three warm-up curves at 0.3 g, a straight, then a curve
    entered without braking at ``overspeed`` (1.2-1.35) times the speed the
    friction allows; the preview of the curve comes from the ``kappa`` column
    (the route's curvature: the navigation map).

Saturation (the truth a warning must precede)
---------------------------------------------
An axle *saturates* when its steady-state force reaches 95 % of its peak,
``|F_ss,k| >= 0.95 Fmax_k`` with ``F_ss = Fmax tanh(F_lin / Fmax)``,
``Fmax_k = mu(t) Fz_k`` (effects.md; ``F_lin / Fmax >= atanh(0.95) = 1.83``:
the slip is 1.83 times the one at which a linear tire would reach the peak).
``F_ss`` is read from the true state (:meth:`ptw_env.dynamics.Plant.steady_tire_force`
of the plant at the friction of that instant). A saturation *event* starts
at the first saturated sample after at least ``gap_s`` = 2 s without one.

Lead time: ``t_event - t_warn`` where ``t_warn`` is the onset of the warning
episode (level >= caution, or >= danger, counted separately) that is active
at ``t_event``; an event without an active warning is *missed* (its
``late_s`` says how long after the event the first warning came, if any).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from assist.estimation.friction_imm import EVIDENCE_SWITCH_RATE
from ptw_env.effects import as_effects
from ptw_env.friction import MU_RANGE, REFERENCE_FRICTION, SCALINGS, FrictionPlants, FrictionSchedule
from ptw_env.sensors import SensorConfig
from ptw_env.scenarios import (Scenario, ScenarioError, require_positive, Segment, segments_to_grid, space_based,
                               speed_plan, make_scenario)
from ptw_env.vehicle import G, REFERENCE_SCOOTER, Vehicle
from ptw_env.vehicle_files import vehicle_of_log

#: Base effects of every evaluation ride: saturating tires whose peak friction is the road's.
EVAL_EFFECTS = "tire_saturation:mu_peak=0.9"
#: An axle saturates when |F_ss| reaches this fraction of Fmax.
SATURATION_FRACTION = 0.95
#: A friction drop that leaves less than this between its onset and the saturation it causes [s] cannot be
#: warned 0.5 s ahead by reading the tires: ~0.3-0.5 s of lateral force to see it, plus the 0.5 s lead.
WARNABLE_S = 1.0
#: Ride types of :func:`make_case`.
KINDS = ("dry", "wet", "dry_long", "wet_long", "too_fast", "dry_bank", "wet_bank", "dry_offsets", "wet_straight",
         "wet_corner")
#: The ride types of issue 20's evaluation (``scripts/eval_risk.py`` default).
EVAL_KINDS = ("dry", "dry_bank", "dry_offsets", "wet_straight", "wet_corner", "too_fast")
#: Sensor offsets of the ``dry_offsets`` rides: yaw-rate gyro bias [rad/s] and lateral accelerometer offset
#: [m/s^2] (issue 20), each with a sign drawn from the seed.
OFFSETS = {"yaw_rate": 0.01, "ay": 0.1}
#: A wet patch "in a corner" starts where the route's lateral demand ``v^2 |kappa| / g`` first reaches a level drawn
#: from this range [g] after mid-ride; "on a straight" where the route is straight for the next
#: :data:`STRAIGHT_AHEAD_S` of riding and was for the last second [-].
CORNER_DEMAND_G = (0.25, 0.45)
STRAIGHT_AHEAD_S = 2.0
#: The latency target applies when the more loaded axle uses at least this share of its load sideways at the drop
#: (issue 20: ``|F| / Fz >= 0.2``, when the tires carry information about the new friction).
LATENCY_LOAD = 0.2
#: A warning within this time of the drop meets the latency target [s].
LATENCY_S = 0.3
#: A warning at least this long before a loss of grip meets the lead target [s] (issue 20).
LEAD_S = 0.5
#: Friction of the wet patch of the ``wet*`` ride types (from 0.9), and the alternative of the sequential oracle.
WET_FRICTION = 0.45
#: The sequential oracle (:func:`sequential_evidence`) may warn on this share of the dry rides (issue 20: cautions
#: on at most 2 % of them); it is judged over this many noise draws per ride.
ORACLE_FALSE_SHARE = 0.02
ORACLE_DRAWS = 100
#: An oracle could where at least this share of its noise draws reach its threshold.
ORACLE_COULD_SHARE = 0.5
#: Noise draws of the observation oracle (:meth:`CaseResult.observation_oracle`): the ride's own, then rides of the
#: same case with other sensor and rider noise (each a ride and a two-model filter pass).
OBSERVATION_DRAWS = 5
#: Rate of switching between the observation oracle's two models [1/s] (:func:`observation_evidence`): as good as
#: none (1e-8 of a model's probability a sample at 0.01 s), which the filter needs to be positive; the friction
#: filter's evidence bank switches at the same rate.
OBSERVATION_SWITCH_RATE = EVIDENCE_SWITCH_RATE


@dataclass(frozen=True)
class CurveTooFast(Scenario):
    """Warm-up curves on a damp road, then a curve entered too fast (no braking).

    Parameters
    ----------
    speed_kmh : float
        Cruise speed [km/h] (default 70), kept into the critical curve.
    mu_road : float
        Road friction the critical curve's radius is computed from [-] (default 0.6).
    overspeed : float
        ``v^2 kappa / (mu_road g)`` of the critical curve [-] (default 1.25).
    warmup_g : float
        Lateral acceleration of the warm-up curves [g] (default 0.3).
    ramp_s : float
        Curvature ramps at the curves' entry and exit [s of travel] (default 1.2).
    seed : int
        Draws the warm-up route and the critical curve's direction.
    duration_s : float
        Default 45 s.

    Examples
    --------
    >>> p = CurveTooFast().profile()
    >>> round(float(np.max(np.abs(p.vx**2 * p.kappa)) / (0.6 * 9.81)), 2)
    1.25
    """

    name: ClassVar[str] = "curve_too_fast"
    duration_s: float = 45.0
    speed_kmh: float = 70.0
    mu_road: float = 0.6
    overspeed: float = 1.25
    warmup_g: float = 0.3
    ramp_s: float = 1.2
    seed: int = 0

    def _validate(self) -> None:
        require_positive(self, "speed_kmh", "mu_road", "overspeed", "warmup_g", "ramp_s")
        if self.overspeed * self.mu_road > math.tan(math.radians(40.0)):
            raise ScenarioError(f"{self.name}: overspeed * mu_road = {self.overspeed * self.mu_road:.3f} g needs more "
                                "than 40 deg of lean (the scenarios' limit)")

    def _segments(self, rng: np.random.Generator) -> tuple[list[Segment], float]:
        v = self.speed_kmh / 3.6
        segs = [Segment(length=60.0, vcap=v)]
        sign = 1.0 if rng.random() < 0.5 else -1.0
        for _ in range(3):
            R = rng.uniform(60.0, 150.0)
            vt = min(v, math.sqrt(self.warmup_g * G * R))
            segs += [Segment(length=rng.uniform(40.0, 80.0), vcap=v),
                     Segment(angle=sign * math.radians(rng.uniform(30.0, 60.0)), radius=R, ramp=vt * self.ramp_s, vcap=v)]
            sign = -sign
        segs.append(Segment(length=150.0, vcap=v))
        s_crit = sum(g.length if math.isinf(g.radius) else g.radius * abs(g.angle) + min(g.ramp, g.radius * abs(g.angle))
                     for g in segs)
        Rc = v * v / (self.overspeed * self.mu_road * G)
        segs += [Segment(angle=sign * math.radians(90.0), radius=Rc, ramp=v * self.ramp_s, vcap=v),
                 Segment(length=v * self.duration_s + 100.0, vcap=v)]
        return segs, s_crit

    def _trajectory(self, t, rng):
        segs, s_crit = self._segments(rng)
        s, k, cap = segments_to_grid(segs)
        k_plan = np.where(s < s_crit, k, 0.0)  # the rider does not slow down for the critical curve
        vplan = speed_plan(s, k_plan, cap, self.warmup_g, 2.0, 3.0, 10.0)
        return space_based(t, s, vplan, k, self.name)

    def profile(self, dt: float = 0.01, seed: int | None = None):
        """Sample the ride; ``seed`` (default: the field) draws the route."""
        return Scenario.profile(self, dt, self.seed if seed is None else seed)


@dataclass(frozen=True)
class RideCase:
    """One evaluation ride: scenario, friction schedule, effects, noise, sensor offsets and seed."""

    kind: str
    seed: int
    scenario: Scenario
    friction: FrictionSchedule
    effects: Any = EVAL_EFFECTS
    noise_pct: float = 5.0
    notes: dict = field(default_factory=dict)
    #: constant sensor offsets per channel (``SensorConfig.bias``), physical units
    bias: dict = field(default_factory=dict)


def _patch_start(prof, kind: str, rng: np.random.Generator) -> tuple[int, dict[str, Any]]:
    """Sample index where the wet patch of ``kind`` begins (after mid-ride), and its notes."""
    n = len(prof.t)
    dt = float(prof.t[1] - prof.t[0])
    demand = prof.vx**2 * np.abs(prof.kappa) / G
    mid = n // 2
    if kind == "wet_corner":
        level = float(rng.uniform(*CORNER_DEMAND_G))
        for start in (mid, n // 4, 0):  # after mid-ride; on a route whose later corners are gentler, earlier
            k = start + np.flatnonzero(demand[start:] >= level)
            if k.size:
                return int(k[0]), {"corner_demand_g": level}
        raise ScenarioError(f"wet_corner: no corner of the route reaches {level:.2f} g")
    if kind == "wet_straight":
        ahead, back = int(round(STRAIGHT_AHEAD_S / dt)), int(round(1.0 / dt))
        straight = np.abs(prof.kappa) < 1e-9
        for k in range(max(mid, back), n - ahead):
            if straight[k - back:k + ahead].all():
                return k, {}
        raise ScenarioError("wet_straight: no straight after mid-ride")
    return mid, {}


def make_case(kind: str, seed: int, scaling: str = "peak") -> RideCase:
    """The ride of type ``kind`` (one of :data:`KINDS`) for ``seed`` (module docstring), on tires whose
    friction ``scaling`` is ``"peak"`` (default) or ``"stiffness_and_peak"`` (:mod:`ptw_env.friction`)."""
    if kind not in KINDS:
        raise ValueError(f"unknown ride type {kind!r}; known: {', '.join(KINDS)}")
    if scaling not in SCALINGS:
        raise ValueError(f"unknown friction scaling {scaling!r}; known: {', '.join(SCALINGS)}")
    seed = int(seed)
    if kind == "too_fast":
        rng = np.random.default_rng(np.random.SeedSequence([seed, 77]))
        mu = float(rng.uniform(0.55, 0.62))
        sc = CurveTooFast(speed_kmh=float(rng.uniform(60.0, 80.0)), mu_road=mu,
                          overspeed=float(rng.uniform(1.2, 1.35)), seed=seed)
        prof = sc.profile(0.01)
        bend = (np.abs(prof.kappa) > 0).astype(int)
        crit = float(prof.t[int(np.flatnonzero(np.diff(bend) == 1)[-1]) + 1])  # the last curve's entry
        return RideCase(kind, seed, sc, FrictionSchedule.constant(mu, scaling=scaling), notes={"mu_road": mu,
                                                                               "overspeed": sc.overspeed,
                                                                               "curve_entry_s": crit})
    ramp = 2.5 if kind.endswith("_long") else 1.2
    sc = make_scenario("urban", lateral_g=0.5, duration_s=60.0, ramp_s=ramp, seed=seed)
    effects: Any = EVAL_EFFECTS
    notes: dict[str, Any] = {}
    bias: dict[str, float] = {}
    if kind.endswith("_bank"):
        rng = np.random.default_rng(np.random.SeedSequence([seed, 91]))
        bank = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.015, 0.04))
        effects, notes = [EVAL_EFFECTS, f"road_bank:bank_rad={bank!r}"], {"bank_rad": bank}
    if kind == "dry_offsets":
        rng = np.random.default_rng(np.random.SeedSequence([seed, 93]))
        bias = {c: float(rng.choice([-1.0, 1.0]) * v) for c, v in OFFSETS.items()}
        notes = {"bias": bias}
    if kind.startswith("dry"):
        return RideCase(kind, seed, sc, FrictionSchedule.constant(REFERENCE_FRICTION, scaling=scaling), effects=effects, notes=notes,
                        bias=bias)
    prof = sc.profile(0.01)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 95]))
    k, more = _patch_start(prof, kind, rng)
    s0 = float(prof.s[k])
    return RideCase(kind, seed, sc, FrictionSchedule.patch(start=s0, mu_before=REFERENCE_FRICTION, mu_patch=WET_FRICTION, ramp=2.0,
                                                           scaling=scaling),
                    effects=effects,
                    notes={**notes, **more, "patch_start_m": s0, "patch_start_s": float(prof.t[k])})


def true_utilisation(states: np.ndarray, vx: np.ndarray, mu: np.ndarray, friction: FrictionSchedule,
                     effects=EVAL_EFFECTS, vehicle=None) -> np.ndarray:
    """``|F_ss,k| / Fmax_k`` per sample and axle (K, 2) from the true states, speeds and friction
    (``Fmax = inf`` without tire_saturation: then ``|F_ss| / (mu Fz)``), on ``vehicle`` (default the
    reference scooter)."""
    plants = FrictionPlants(friction, vehicle, effects=as_effects(effects))
    X = np.asarray(states, dtype=float)
    out = np.empty((len(X), 2))
    mu = np.asarray(mu, dtype=float)
    for m in np.unique(np.round(mu, 3)):
        idx = np.flatnonzero(np.round(mu, 3) == m)
        p = plants.plant(float(m))
        fss = p.steady_tire_force(X[idx], np.asarray(vx, dtype=float)[idx])
        fz = np.array([p.vehicle.tires.Fzf, p.vehicle.tires.Fzr])
        fmax = np.where(np.isfinite(p.fmax), p.fmax, float(m) * fz)
        out[idx] = np.abs(fss) / fmax
    return out


def saturation_events(t: np.ndarray, util: np.ndarray, fraction: float = SATURATION_FRACTION,
                      gap_s: float = 2.0) -> np.ndarray:
    """Onset times [s] of saturation events (module docstring).

    >>> saturation_events(np.arange(6) * 1.0, np.array([0.5, 0.96, 0.97, 0.5, 0.5, 0.99]))
    array([1., 5.])
    """
    u = np.asarray(util, dtype=float)
    sat = (u.max(axis=1) if u.ndim == 2 else u) >= fraction
    out: list[float] = []
    last = -math.inf
    for k in np.flatnonzero(sat):
        if t[k] - last >= gap_s:
            out.append(float(t[k]))
        last = float(t[k])
    return np.array(out)


def friction_contrast(states: np.ndarray, vx: np.ndarray, mu, friction: FrictionSchedule,
                      effects=EVAL_EFFECTS, vehicle=None) -> np.ndarray:
    """``(sum_k F_ss,k(x; mu_ref) - sum_k F_ss,k(x; mu)) / M`` per sample [m/s^2], signed: the lateral
    acceleration by which the tires on a road of friction ``mu`` (one value, or one per sample) differ from the
    same tires at the same state on the reference road ``mu_ref`` (dry), from the true states (the
    accelerometer reads ``sum_k F_k / M``, sensors.py row 4)."""
    plants = FrictionPlants(friction, vehicle, effects=as_effects(effects))
    X = np.asarray(states, dtype=float)
    vx = np.asarray(vx, dtype=float)
    try:
        mu = np.broadcast_to(np.asarray(mu, dtype=float), (len(X),))
    except (TypeError, ValueError):
        raise ValueError(f"mu must be a friction or one per sample ({len(X)}), got {mu!r}") from None
    if not np.all((mu >= MU_RANGE[0]) & (mu <= MU_RANGE[1])):
        raise ValueError(f"mu must lie in {MU_RANGE}")
    ref = plants.plant(friction.mu_ref)
    f_ref = ref.steady_tire_force(X, vx).sum(axis=-1)
    out = np.zeros(len(X))
    for m in np.unique(np.round(mu, 3)):
        idx = np.flatnonzero(np.round(mu, 3) == m)
        out[idx] = f_ref[idx] - plants.plant(float(m)).steady_tire_force(X[idx], vx[idx]).sum(axis=-1)
    return out / ref.vehicle.mass


def dry_contrast(states: np.ndarray, vx: np.ndarray, mu: np.ndarray, friction: FrictionSchedule,
                 effects=EVAL_EFFECTS, vehicle=None) -> np.ndarray:
    """What the tires tell about the road, per sample [m/s^2]: ``|`` :func:`friction_contrast` ``|`` at the
    friction ridden, ``mu`` per sample. Zero on the reference road; on a wet road of :data:`ptw_env.friction`
    scaling ``"peak"`` it stays near zero while the tires use a small share of their grip (the curve's slope
    is the same), on ``"stiffness_and_peak"`` it is ``(1 - mu/mu_ref)`` times the axle forces at any
    slip. The accelerometer reads the sum of the axle forces over ``M``, so this is the signal
    any warning that reads the tires has to find the friction in."""
    return np.abs(friction_contrast(states, vx, mu, friction, effects, vehicle))


def sequential_evidence(contrast_alt: np.ndarray, contrast_true: np.ndarray, ay_std: float,
                        noise: np.ndarray) -> np.ndarray:
    """The sequential oracle: Page's CUSUM (Page 1954; Basseville and Nikiforov, *Detection of Abrupt
    Changes*, 1993, sec. 2.2.2) of a reader that knows the true state and the wet road's friction and reads the
    accelerometer: with ``s_k`` = ``contrast_alt`` (:func:`friction_contrast` to the wet friction: the dry road's
    force less the wet road's, over ``M``) and ``z_k`` the dry road's force over ``M`` less the reading, ``z_k =
    c_k + n_k`` (``c_k`` = ``contrast_true``, 0 on a dry road; ``n_k = ay_std noise_k`` white, its sign
    immaterial), the log-likelihood ratio of the wet road to the dry one per sample is
    ``(z_k s_k - s_k^2 / 2) / ay_std^2`` and ``g_k = max(0, g_{k-1} + that)``, ``g_{-1} = 0`` [nats]. The CUSUM
    is optimal for a change to a known alternative in Lorden's sense (the least worst-case delay at a given mean
    time between false alarms; Lorden, Ann. Math. Stat. 42, 1971; Moustakides, Ann. Stat. 14, 1986). With its
    threshold set on dry rides to the false-warning share the target allows it is a strong reference for what a
    warning reading the tires' force through the accelerometer can do (it knows the side slip and the friction),
    not a proven bound: that optimality is for independent samples of one signal and the worst-case delay, not a
    deadline met in half the draws at a share of false rides, and it reads no other sensor (the gyros also see
    the forces, through the yaw and roll moments). ``noise``: standard normal draws ``(K, draws)``; returns the
    paths ``(K, draws)``.

    >>> s = np.full(4, 0.2)
    >>> sequential_evidence(s, s, 0.25, np.zeros((4, 1)))[:, 0]  # noise-free: 0.02 / 0.0625 = 0.32 a sample
    array([0.32, 0.64, 0.96, 1.28])
    """
    try:
        s, c, n = (_real_array(v) for v in (contrast_alt, contrast_true, noise))
    except (TypeError, ValueError):
        raise ValueError("contrasts and noise must be arrays of real numbers") from None
    if not (s.ndim == c.ndim == 1 and s.shape == c.shape and n.ndim == 2 and n.shape[0] == s.size):
        raise ValueError(f"contrasts (K,) and noise (K, draws) needed, got {s.shape}, {c.shape}, {n.shape}")
    var = float(ay_std) ** 2 if (isinstance(ay_std, numbers.Real) and not isinstance(ay_std, bool)
                                 and 1e-100 < ay_std < 1e100) else math.nan
    if not math.isfinite(var):
        raise ValueError(f"ay_std must be a positive number [m/s^2] (1e-100 to 1e100), got {ay_std!r}")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(c)) and np.all(np.isfinite(n))):
        raise ValueError("contrasts and noise must be finite")
    return page_cusum(((c[:, None] + ay_std * n) * s[:, None] - 0.5 * s[:, None] ** 2) / var)


def page_cusum(increments: ArrayLike) -> np.ndarray:
    """Page's CUSUM ``g_k = max(0, g_{k-1} + l_k)``, ``g_{-1} = 0``, of log-likelihood-ratio increments ``l_k``
    along the first axis (one path per column) [nats] (E. S. Page, Biometrika 41, 1954; Basseville and Nikiforov,
    *Detection of Abrupt Changes*, 1993, eq. 2.2.10), the recursion itself (the unrolled form ``S_k - min S_j``
    loses the digits of a small sum after a large negative one).

    >>> page_cusum([1.0, -3.0, 2.0, 0.5]).tolist()
    [1.0, 0.0, 2.0, 2.5]
    """
    try:
        x = _real_array(increments)
    except (TypeError, ValueError):
        raise ValueError(f"the CUSUM's increments must be real numbers, got {increments!r}"[:200]) from None
    if x.ndim == 0 or x.shape[0] == 0 or not np.all(np.isfinite(x)):
        raise ValueError("the CUSUM's increments must be a finite, non-empty array")
    g = np.empty_like(x)
    last = np.zeros(x.shape[1:])
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(x.shape[0]):
            last = np.maximum(0.0, last + x[k])
            g[k] = last
    if not np.all(np.isfinite(g)):
        raise ValueError("the CUSUM's sum overflows: increments too large")
    return g


def observation_evidence(log: Any, mu_alt: float = WET_FRICTION, noise_pct: float = 5.0,
                         mu_ref: float = REFERENCE_FRICTION, vehicle: Vehicle | None = None) -> np.ndarray:
    """The observation oracle's evidence over a ride ``log`` [nats] (K,): a reader of the warning's own sensors that
    knows the two roads to tell apart, the reference road ``mu_ref`` and the wet road ``mu_alt``, but not the
    state. It is the friction filter (:class:`assist.estimation.friction_imm.FrictionIMM`: the saturating plant,
    its noise model for ``noise_pct`` % sensors, the speed tracker, the bank and yaw-gyro offset states) with those
    two models only, switching at :data:`OBSERVATION_SWITCH_RATE` (as good as none: its own bank is then its evidence
    bank), and that evidence (:attr:`FrictionIMM.evidence_own`), Page's CUSUM of its models' log-likelihood ratio
    ``ln Lambda_alt - ln Lambda_ref`` per sample (the
    likelihood of the sample's outputs given the past ones, from each model's extended Kalman filter; Blom and
    Bar-Shalom 1988, eq. 11). For two known hypotheses that is the CUSUM of :func:`sequential_evidence` on all
    channels, with the state estimated instead of known, approximately: the filter linearises, and its mixing
    (however small the switching) starts the unlikely model from the likely one's state at each sample, so each
    likelihood is a one-step comparison from the state the sensors make likelier, not that of a hypothesis
    tracked on its own from the start. A reference for what a warning reading these sensors could do if it knew
    what the wet road is, not a bound: a road whose friction lies between its two (the patch's ramp) it explains
    worse than a filter of more levels. As the filter's evidence, the sum is void (0) where the models do not
    explain the sensors (their normalised innovation squared, :attr:`FrictionIMM.nis`, above
    :data:`assist.estimation.identification.NIS_EXPLAINED`): there their comparison says nothing (on a real ride
    whose steer torque oscillates, robot bicycle run 04-009, the sum reached 206 nats without the gate, 2.2 with
    it). ``log``: a ride log (logs.md) with its ``tau`` and ``vx`` columns, read at its own sample time ``dt``;
    ``vehicle``: the filter's vehicle (default the reference scooter)."""
    from assist.estimation.friction_imm import FrictionIMM

    from .pipeline import output_matrix

    try:
        mu = [float(mu_ref), float(mu_alt)]
    except (TypeError, ValueError):
        raise ValueError(f"mu_ref and mu_alt must be frictions, got {mu_ref!r}, {mu_alt!r}") from None
    if not (MU_RANGE[0] <= mu[1] < mu[0] <= MU_RANGE[1]):
        raise ValueError(f"mu_alt must be below mu_ref, both in {MU_RANGE}, got {mu_alt!r}, {mu_ref!r}")
    try:
        Y = output_matrix(log.columns)
        tau, vx = (np.asarray(log.columns[n], dtype=float) for n in ("tau", "vx"))
        dt = float(log.dt)
    except (AttributeError, KeyError, TypeError, ValueError) as e:
        raise ValueError(f"a ride log with the outputs, tau and vx is needed ({e})") from None
    if not (len(Y) == tau.size == vx.size and tau.ndim == vx.ndim == 1):
        raise ValueError(f"a ride log's columns must be as long as one another: outputs {len(Y)}, tau {tau.shape}, "
                         f"vx {vx.shape}")
    imm = FrictionIMM(noise_pct=noise_pct, dt=dt, vehicle=vehicle, mu_ref=mu[0], grid=mu, lower=0.5 * (1.0 + mu[1] / mu[0]),
                      switch_rate=OBSERVATION_SWITCH_RATE)
    g = np.empty(len(Y))
    for k in range(len(Y)):
        imm.update(Y[k], tau[k], vx[k])
        g[k] = imm.evidence_own  # its CUSUM of ln Lambda_alt - ln Lambda_ref, void where nis > NIS_EXPLAINED
    return g


def filter_evidence(run: Any) -> np.ndarray | None:
    """The friction filter's own evidence per sample of a risk run [nats] (K,): its CUSUM ``g`` as the monitor
    was given it (:attr:`assist.estimation.friction_imm.FrictionReading.evidence`); None where the estimator gave
    no friction reading (a stiffness estimator) or the run kept no inputs."""
    inputs = getattr(run, "inputs", None)
    if inputs is None or len(inputs) == 0 or any(getattr(i.reading, "evidence", None) is None for i in inputs):
        return None
    return np.array([float(i.reading.evidence) for i in inputs])


def window_max(paths: list[dict], t0, t1) -> list[float] | None:
    """The largest value of each draw's path (``{"t", "g"}``, g >= 0) over ``t0 <= t <= t1`` [s] (one instant
    for all draws, or one per draw), rounded to 0.01; a draw with no sample there gathered nothing there (0); None
    where no draw has one (an empty window).

    >>> p = {"t": np.arange(5.0), "g": np.array([0.0, 1.0, 3.0, 2.0, 9.0])}
    >>> window_max([p, p], 1.0, [3.0, 0.5])
    [3.0, 0.0]
    """
    n = len(paths)
    try:
        a, b = (np.broadcast_to(_real_array(v), (n,)) for v in (t0, t1))
    except (TypeError, ValueError):
        raise ValueError(f"the window's ends must be instants [s], one or one per draw ({n}), got {t0!r}, "
                         f"{t1!r}"[:200]) from None
    out, seen = [], False
    for p, lo, hi in zip(paths, a, b):
        g = _real_array(p["g"])
        k = (p["t"] >= lo) & (p["t"] <= hi)
        if not np.all(np.isfinite(g[k])):
            raise ValueError("an oracle's path is not finite")
        seen = seen or bool(k.any())
        out.append(round(float(np.max(g[k])), 2) if k.any() else 0.0)
    return out if seen else None


def _real_array(v) -> np.ndarray:
    """``v`` as a float array; strings, booleans and complex numbers refused (TypeError)."""
    a = np.asarray(v)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"real numbers needed, got dtype {a.dtype}")
    return a.astype(float)


def oracle_share(maxima: ArrayLike | None, h: float) -> float | None:
    """The share of an oracle's noise draws whose largest evidence ``maxima`` reaches its threshold ``h`` [nats]
    (None: no draw)."""
    if maxima is None or len(maxima) == 0:
        return None
    return float(np.mean(_real_array(maxima) >= h))


def oracle_could(maxima: ArrayLike | None, h: float | None) -> bool:
    """Whether an oracle could (at threshold ``h``): in at least :data:`ORACLE_COULD_SHARE` of its noise draws.

    >>> oracle_could([1.0, 3.0, 5.0, 7.0], 5.0), oracle_could([1.0, 3.0, 5.0], 5.0), oracle_could(None, 5.0)
    (True, False, False)
    """
    share = None if h is None else oracle_share(maxima, h)
    return share is not None and share >= ORACLE_COULD_SHARE


def oracle_threshold(dry_maxima) -> float:
    """An oracle's threshold [nats]: the ``1 - ORACLE_FALSE_SHARE`` quantile of the largest evidence of dry rides
    (pooled noise draws; :func:`sequential_evidence`, :func:`observation_evidence`), so that it warns on that
    share of them."""
    try:
        m = _real_array(dry_maxima).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"the dry rides' largest evidence must be numbers, got {dry_maxima!r}") from None
    if m.size == 0:
        raise ValueError("an oracle's threshold needs dry rides")
    if not np.all(np.isfinite(m)):
        raise ValueError("the dry rides' largest evidence must be finite")
    return float(np.quantile(m, 1.0 - ORACLE_FALSE_SHARE))


def information_onset(t: np.ndarray, contrast: np.ndarray, t0: float, ay_std: float,
                      window_s: float = LATENCY_S) -> float | None:
    """First instant ``>= t0`` [s] at which the tires have told the road from the reference road to a
    reader that knows the true state: the mean of :func:`dry_contrast` over the trailing ``window_s``
    reaches twice the standard error of the mean of ``window_s`` of accelerometer noise
    (``2 ay_std / sqrt(n)``, ``n`` samples in the window). An oracle bound, generous to any real
    warning (which must also estimate the state): no warning that reads the tires can be sure of the
    new friction before it. None: never.

    >>> t = np.arange(100) * 0.01
    >>> information_onset(t, np.where(t >= 0.5, 0.2, 0.0), 0.0, ay_std=0.25)  # 2 x 0.25 / sqrt(30) = 0.091
    0.63
    """
    t = np.asarray(t, dtype=float)
    c = np.asarray(contrast, dtype=float)
    dt = float(np.median(np.diff(t)))
    n = max(1, int(round(window_s / dt)))
    mean = np.convolve(c, np.ones(n) / n, mode="full")[: len(c)]  # trailing mean (shorter at the start)
    mean[: n - 1] *= n / np.arange(1, n)
    thr = 2.0 * ay_std / math.sqrt(n)
    k = np.flatnonzero((t >= t0) & (mean >= thr))
    return float(t[k[0]]) if k.size else None


def lead_time(t: np.ndarray, level: np.ndarray, t_event: float, min_level: int) -> dict[str, Any]:
    """``{"lead_s", "late_s"}`` of the warning (level >= ``min_level``) for an event at ``t_event``.

    >>> t = np.arange(10) * 0.5
    >>> lead_time(t, np.array([0, 0, 1, 1, 2, 2, 2, 0, 0, 0]), 2.5, 1)
    {'lead_s': 1.5, 'late_s': None}
    >>> lead_time(t, np.array([0, 0, 1, 1, 2, 2, 2, 0, 0, 0]), 1.0, 2)
    {'lead_s': None, 'late_s': 1.0}
    """
    on = np.asarray(level) >= min_level
    k = int(np.searchsorted(t, t_event))
    k = min(k, len(t) - 1)
    if on[k]:
        j = k
        while j > 0 and on[j - 1]:
            j -= 1
        return {"lead_s": float(t_event - t[j]), "late_s": None}
    after = np.flatnonzero(on[k:])
    return {"lead_s": None, "late_s": float(t[k + after[0]] - t_event) if after.size else None}


def episodes(level: np.ndarray, min_level: int) -> int:
    """Number of warning episodes at level >= ``min_level`` (rises from below).

    >>> episodes(np.array([0, 1, 1, 0, 2, 1, 0]), 1), episodes(np.array([0, 1, 1, 0, 2, 1, 0]), 2)
    (2, 1)
    """
    on = (np.asarray(level) >= min_level).astype(int)
    return int(np.sum(np.diff(np.concatenate(([0], on))) == 1))


@dataclass(eq=False)
class CaseResult:
    """A ridden and assessed evaluation case."""

    case: RideCase
    ride: Any  #: ptw_env.ride.RideResult (log with a ``kappa`` column added)
    run: Any  #: assist.risk.offline.RiskRun
    mu_true: np.ndarray
    utilisation: np.ndarray  #: true |F_ss|/Fmax (K, 2)
    events: np.ndarray  #: saturation onsets [s]
    contrast: np.ndarray | None = None  #: :func:`dry_contrast` [m/s^2] (K,)
    #: :func:`friction_contrast` at the friction ridden and at :data:`WET_FRICTION` (the sequential oracle's
    #: alternative; None for the too-fast rides, whose road is damp throughout) [m/s^2] (K,)
    contrast_true: np.ndarray | None = None
    contrast_alt: np.ndarray | None = None
    _oracle: Any = field(default=None, init=False, repr=False)
    _observation: Any = field(default=None, init=False, repr=False)

    def drop_time(self) -> float | None:
        """First instant the true friction is below the ride's starting friction [s] (None: no drop)."""
        return _drop_time(self.run.t, self.mu_true)

    def reference_time(self) -> float | None:
        """The instant the lead is counted from [s]: the friction drop (wet), the critical curve's entry
        (too fast); None on a dry ride."""
        if "curve_entry_s" in self.case.notes:
            return float(self.case.notes["curve_entry_s"])
        return self.drop_time()

    def load_at(self, t0: float) -> float:
        """True ``|F_k| / Fz_k`` of the more loaded axle at ``t0`` [-]."""
        tires = REFERENCE_SCOOTER.tires
        k = min(int(np.searchsorted(self.run.t, t0)), len(self.ride.states) - 1)
        return float(np.max(np.abs(self.ride.states[k, 6:8]) / np.array([tires.Fzf, tires.Fzr])))

    def summary(self, run=None, observation: bool = False, draws: int = OBSERVATION_DRAWS) -> dict[str, Any]:
        """Figures of the ride: events with lead times (caution, danger) and the time from the drop
        (or curve entry) to them, the tires' information onset (:func:`information_onset`) and the lead it
        leaves, the latency of the first caution after a drop and the load then, false-alarm
        episodes, peak true utilisation, friction estimate at the end and its truth (``run``: another
        assessment of the same ride, e.g. :func:`assist.risk.offline.replay`); with ``observation`` also the
        observation oracle's largest values (:meth:`observation_oracle` with ``draws`` draws, which rides the case
        ``draws - 1`` times again); where the estimator reads the friction itself, the filter's own
        evidence (:func:`filter_evidence`): its largest between the drop and ``LEAD_S`` before each loss of grip
        (``filter_evidence_max``), over a dry ride (``filter_evidence_dry_max``) [nats]."""
        run = self.run if run is None else run
        t = run.t
        lv = run.level_code
        t_ref = self.reference_time()
        seq = self.sequential_oracle()
        obs = self.observation_oracle(draws) if observation else None
        gf = filter_evidence(run)
        t_info = None
        if t_ref is not None and self.contrast is not None:
            ay_std = SensorConfig.from_percent(self.case.noise_pct).noise_std["ay"]
            t_drop = self.drop_time()  # the road of the event since its drop, or since the start (damp throughout)
            t_info = information_onset(t, self.contrast, float(t[0]) if t_drop is None else t_drop, ay_std)
        ev = []
        for te in self.events:
            e = {"t": float(te), "caution": lead_time(t, lv, te, 1), "danger": lead_time(t, lv, te, 2)}
            if t_ref is not None:
                e["after_reference_s"] = float(te - t_ref)
                e["information_lead_bound_s"] = None if t_info is None or t_info > te else float(te - t_info)
            if gf is not None and self.drop_time() is not None:  # the filter's own, LEAD_S or more ahead
                k = (t >= self.drop_time()) & (t <= te - LEAD_S)
                e["filter_evidence_max"] = round(float(gf[k].max()), 3) if k.any() else None
            if seq is not None and self.drop_time() is not None:  # the largest evidence LEAD_S or more ahead
                k = (seq["t"] >= self.drop_time()) & (seq["t"] <= te - LEAD_S)
                e["sequential_max"] = _rounded(seq["paths"][k].max(axis=0)) if k.any() else None
                if obs is not None:  # each draw between its own drop and LEAD_S before its own loss
                    drops, losses = self._draw_instants(obs, te)
                    e["observation_max"] = window_max(obs, drops, losses - LEAD_S)
            ev.append(e)
        latency = None
        if t_ref is not None:
            on = np.flatnonzero((t >= t_ref) & (lv >= 1))
            latency = {"load_at_reference": self.load_at(t_ref),
                       "caution_after_s": float(t[on[0]] - t_ref) if on.size else None,
                       "information_after_s": None if t_info is None else float(max(t_info - t_ref, 0.0))}
            if seq is not None and self.drop_time() is not None:
                k = (seq["t"] >= t_ref) & (seq["t"] <= t_ref + LATENCY_S)
                latency["sequential_max"] = _rounded(seq["paths"][k].max(axis=0))
                if obs is not None:  # each draw from its own drop (the reference instant of a wet ride)
                    drops = self._draw_instants(obs, None)[0]
                    latency["observation_max"] = window_max(obs, drops, drops + LATENCY_S)
        return {
            "kind": self.case.kind,
            "seed": self.case.seed,
            "notes": self.case.notes,
            "duration_s": float(t[-1]),
            "fell": bool(self.ride.fell),
            "max_true_utilisation": [float(v) for v in self.utilisation.max(axis=0)],
            "events": ev,
            "caution_episodes": episodes(lv, 1),
            "danger_episodes": episodes(lv, 2),
            "mu_hat_final": float(run.assessments[-1].mu_hat),
            "mu_true_final": float(self.mu_true[-1]),
            "reference_s": t_ref,
            "latency": latency,
            **({"oracle_dry_max": _rounded(seq["paths"].max(axis=0))} if seq is not None and self.drop_time() is None
               else {}),
            **({"observation_dry_max": window_max(obs, -math.inf, math.inf)}
               if obs is not None and self.drop_time() is None else {}),
            **({"filter_evidence_dry_max": round(float(gf.max()), 3)} if gf is not None and t_ref is None else {}),
        }

    def sequential_oracle(self) -> dict | None:
        """The sequential oracle's paths (:func:`sequential_evidence`, :data:`ORACLE_DRAWS` noise draws seeded by
        the ride) from the ride's start (on a wet ride it has run on the dry road before the drop, as a reader
        riding along would: a sum that started earlier is never lower): ``{"t": (K,), "paths": (K, draws)}``;
        None without an alternative (too fast)."""
        if self.contrast_alt is None or self.contrast_true is None:
            return None
        if self._oracle is None:
            t = np.asarray(self.run.t, dtype=float)
            rng = np.random.default_rng(np.random.SeedSequence([self.case.seed, KINDS.index(self.case.kind), 71]))
            ay_std = SensorConfig.from_percent(self.case.noise_pct).noise_std["ay"]
            noise = rng.standard_normal((len(t), ORACLE_DRAWS))
            self._oracle = {"t": t, "paths": sequential_evidence(self.contrast_alt, self.contrast_true, ay_std, noise)}
        return self._oracle

    def observation_oracle(self, draws: int = OBSERVATION_DRAWS) -> list[dict] | None:
        """The observation oracle's paths (:func:`observation_evidence`, :data:`WET_FRICTION` against the reference
        road), one per noise draw: the ride's own log, then ``draws`` - 1 (default :data:`OBSERVATION_DRAWS` - 1)
        rides of the same case with other sensor and rider noise (seeded by the ride: the first draws are the same
        whatever ``draws``), from the ride's start: ``[{"t": (K,), "g": (K,)}]``; None without an alternative
        (too fast)."""
        if isinstance(draws, bool) or not isinstance(draws, numbers.Integral) or not 1 <= draws <= 10_000:
            raise ValueError(f"draws must be a whole number in [1, 10000], got {draws!r}")
        if self.contrast_alt is None:
            return None
        if self._observation is None:
            self._observation = [{"t": np.asarray(self.run.t, dtype=float), "g": observation_evidence(
                self.ride.log, noise_pct=self.case.noise_pct), "drop": self.drop_time(), "events": self.events}]
        if len(self._observation) < draws:
            out = self._observation
            ss = np.random.SeedSequence([self.case.seed, KINDS.index(self.case.kind), 73])
            for seed in ss.generate_state(draws - 1)[len(out) - 1:]:
                ride = ride_case(self.case, noise_seed=int(seed))
                t = np.asarray(ride.log.t, dtype=float)
                mu, util = _ride_truth(self.case, ride)
                out.append({"t": t, "g": observation_evidence(ride.log, noise_pct=self.case.noise_pct),
                            "drop": _drop_time(t, mu), "events": saturation_events(t, util)})
        return self._observation[:draws]

    @staticmethod
    def _draw_instants(obs: list[dict], te: float | None) -> tuple[np.ndarray, np.ndarray]:
        """Each observation draw's (``obs``) drop and its loss of grip matching the ride's loss at ``te`` (its own
        event nearest ``te``, within :data:`LEAD_S`; else, a draw that did not lose its grip there, ``te`` itself)
        [s]."""
        drops, losses = [], []
        for d in obs:
            drops.append(math.nan if d["drop"] is None else d["drop"])
            ev = np.asarray(d["events"], dtype=float)
            j = int(np.argmin(np.abs(ev - te))) if te is not None and ev.size else -1
            losses.append(float(ev[j]) if j >= 0 and abs(ev[j] - te) <= LEAD_S else te)
        return np.array(drops), np.array(losses, dtype=float)


def truth_from_log(log, vehicle=None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(mu_true, true_utilisation, saturation_events)`` of a simulated log, or None.

    ``vehicle``: the vehicle that rode it (default: the sidecar's, else the reference scooter).

    Needs the truth columns ``x_phi`` ... ``x_Fyr`` and ``vx_true`` (written by
    :func:`ptw_env.ride.ride_scenario`); the friction comes from a ``mu_true``
    column, else from the sidecar's ``truth.friction`` schedule, else it is the
    reference 0.9; the dynamic effects from the sidecar's ``truth.causes``.
    """
    from ptw_env.vehicle import STATE_NAMES

    c = log.columns
    names = [f"x_{n}" for n in STATE_NAMES]
    if not all(n in c for n in names) or "vx_true" not in c:
        return None
    X = np.column_stack([np.asarray(c[n], dtype=float) for n in names])
    vx = np.asarray(c["vx_true"], dtype=float)
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(vx)) and np.all(vx > 0)):
        return None
    truth = (log.meta or {}).get("truth", {}) if isinstance(log.meta, dict) else {}
    try:
        effects = as_effects(truth.get("causes")) if truth.get("causes") else as_effects(None)
        fj = truth.get("friction")
        sched = FrictionSchedule.from_json(fj) if isinstance(fj, dict) else None
    except (ValueError, KeyError, TypeError):
        return None
    t = np.asarray(log.t, dtype=float)
    if "mu_true" in c and np.all(np.isfinite(c["mu_true"])):
        mu = np.asarray(c["mu_true"], dtype=float)
    elif sched is not None:
        s = np.concatenate(([0.0], np.cumsum(vx[:-1] * np.diff(t))))
        mu = sched.along(t, s)
    else:
        mu = np.full(len(t), 0.9)
    sched = sched or FrictionSchedule.constant(0.9)
    if vehicle is None:
        try:
            vehicle = vehicle_of_log(log.meta or {}, getattr(log, "path", None))
        except ValueError:
            return None
    util = true_utilisation(X, vx, mu, sched, effects, vehicle)
    return mu, util, saturation_events(t, util) if effects.has("tire_saturation") else np.array([])


def estimator_figures(res: CaseResult, rel_tol: float = 0.2, excitation_g: float = 0.1) -> dict[str, Any]:
    """How the friction estimate behaves against the truth on one ride.

    * ``rel_error``: ``mu_hat / mu_true - 1`` over the *informed* samples at least 3 s after any
      change of the true friction (median, 5th and 95th percentiles);
    * ``within_2sigma``: fraction of those samples with ``|mu_hat - mu_true| <= 2 mu_std``;
    * for a friction drop (wet patch): ``excitation_s``, the time from the drop to the first true
      axle force ``|F_k| >= excitation_g Fz_k`` on the new surface; ``detect_s``, from that instant
      to ``mu_hat`` within ``rel_tol`` of the new friction; ``before_saturation_s``, from detection
      to the next saturation event (NaN if none); ``onset_to_saturation_s``, from the drop to the first
      saturation after it (under :data:`WARNABLE_S` little time is left for any warning: when the
      patch begins under tires loaded in a corner, none that reads the tires' response can lead by
      0.5 s); ``load_at_drop``, the true ``|F_k| / Fz_k`` of the more loaded axle at the drop (near 0
      on a straight, ~0.3 and more in a corner).
    """
    t = res.run.t
    mu_hat = res.run.series("mu_hat")
    sd = res.run.series("mu_std")
    informed = res.run.series("friction_informed").astype(bool)
    mu = res.mu_true
    change = np.flatnonzero(np.abs(np.diff(mu)) > 1e-9)
    settled = np.ones(len(t), dtype=bool)
    for k in change:
        settled &= ~((t >= t[k]) & (t < t[k] + 3.0))
    m = informed & settled
    out: dict[str, Any] = {"informed_fraction": float(informed.mean())}
    if m.any():
        e = mu_hat[m] / mu[m] - 1.0
        out["rel_error"] = {"median": float(np.median(e)), "p5": float(np.percentile(e, 5)),
                            "p95": float(np.percentile(e, 95))}
        out["within_2sigma"] = float(np.mean(np.abs(mu_hat[m] - mu[m]) <= 2 * sd[m]))
    if change.size and mu[-1] < mu[0]:
        k0 = int(change[0]) + 1
        after = res.events[res.events >= t[k0]]
        out["onset_to_saturation_s"] = float(after[0] - t[k0]) if after.size else None
        fz = np.array([REFERENCE_SCOOTER.tires.Fzf, REFERENCE_SCOOTER.tires.Fzr])
        load = np.max(np.abs(res.ride.states[:, 6:8]) / fz, axis=1)
        out["load_at_drop"] = float(load[k0])  # |F|/Fz of the more loaded axle as the friction drops
        exc = np.flatnonzero((np.arange(len(t)) >= k0) & (load >= excitation_g))
        out["excitation_s"] = float(t[exc[0]] - t[k0]) if exc.size else None
        if exc.size:
            det = np.flatnonzero((np.arange(len(t)) >= exc[0]) & (mu_hat <= mu[-1] * (1 + rel_tol)))
            out["detect_s"] = float(t[det[0]] - t[exc[0]]) if det.size else None
            nxt = res.events[res.events >= t[exc[0]]]
            out["before_saturation_s"] = (float(nxt[0] - t[det[0]]) if det.size and nxt.size else None)
    return out


def ride_case(case: RideCase, noise_seed: int | None = None):
    """Ride ``case``: :func:`ptw_env.ride.ride_scenario` with its friction schedule, effects, sensor noise and
    offsets, the rider holding the line; the route's curvature added to the log as ``kappa`` (the map).
    ``noise_seed``: the seed of the sensors' and the rider's noise (default the case's seed, which also draws
    the route)."""
    from ptw_env.ride import ride_scenario

    if noise_seed is not None and (isinstance(noise_seed, bool) or not isinstance(noise_seed, numbers.Integral)
                                   or not 0 <= noise_seed < 2**63):
        raise ValueError(f"noise_seed must be a whole number in [0, 2**63), got {noise_seed!r}")
    sensors = {"sensors": SensorConfig.from_percent(case.noise_pct, bias=case.bias)} if case.bias else \
        {"noise_pct": case.noise_pct}
    ride = ride_scenario(case.scenario, effects=case.effects, seed=case.seed if noise_seed is None else int(noise_seed),
                         friction=case.friction,
                         scenario_seed=case.seed, hold_line=True, **sensors)
    prof = case.scenario.profile(0.01, seed=case.seed)
    ride.log.columns["kappa"] = np.asarray(prof.kappa[: len(ride.log.t)], dtype=float)
    return ride


def run_case(case: RideCase, pipeline=None) -> CaseResult:
    """Ride ``case`` (:func:`ride_case`), assess it (:func:`assist.risk.offline.assess_log`) and compute the
    truth."""
    from .offline import assess_log

    ride = ride_case(case)
    c = ride.log.columns
    run = assess_log(ride.log, pipeline=pipeline, noise_pct=case.noise_pct)
    mu, util = _ride_truth(case, ride)
    signed = friction_contrast(ride.states, c["vx_true"], mu, case.friction, case.effects)
    alt = None if case.kind == "too_fast" else friction_contrast(ride.states, c["vx_true"], WET_FRICTION,
                                                                  case.friction, case.effects)
    return CaseResult(case=case, ride=ride, run=run, mu_true=mu, utilisation=util,
                      events=saturation_events(ride.log.t, util), contrast=np.abs(signed), contrast_true=signed,
                      contrast_alt=alt)


def _ride_truth(case: RideCase, ride) -> tuple[np.ndarray, np.ndarray]:
    """The true friction per sample and the true utilisation (:func:`true_utilisation`) of a ride of ``case``."""
    c = ride.log.columns
    mu = np.asarray(c["mu_true"], dtype=float)
    return mu, true_utilisation(ride.states, c["vx_true"], mu, case.friction, case.effects)


def _drop_time(t: np.ndarray, mu: np.ndarray) -> float | None:
    """First instant ``t`` at which ``mu`` is below its first value [s] (None: no drop)."""
    k = np.flatnonzero(np.asarray(mu) < mu[0] - 1e-9)
    return float(t[k[0]]) if k.size else None


def _rounded(x: np.ndarray) -> list[float]:
    return [round(float(v), 2) for v in x]


__all__ = [
    "CaseResult",
    "CurveTooFast",
    "EVAL_EFFECTS",
    "dry_contrast",
    "friction_contrast",
    "oracle_threshold",
    "oracle_could",
    "oracle_share",
    "ORACLE_COULD_SHARE",
    "observation_evidence",
    "filter_evidence",
    "OBSERVATION_DRAWS",
    "OBSERVATION_SWITCH_RATE",
    "page_cusum",
    "sequential_evidence",
    "window_max",
    "ORACLE_DRAWS",
    "ORACLE_FALSE_SHARE",
    "WET_FRICTION",
    "information_onset",
    "EVAL_KINDS",
    "KINDS",
    "LATENCY_LOAD",
    "LATENCY_S",
    "LEAD_S",
    "OFFSETS",
    "RideCase",
    "SATURATION_FRACTION",
    "episodes",
    "estimator_figures",
    "lead_time",
    "make_case",
    "ride_case",
    "run_case",
    "truth_from_log",
    "saturation_events",
    "true_utilisation",
]
