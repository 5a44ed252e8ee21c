"""Named riding scenarios: speed, path and roll reference over time.

A scenario is a frozen dataclass (copy it and change fields with
:func:`dataclasses.replace`) whose :meth:`Scenario.profile` samples, every
``dt``, what the rider is asked to do: the forward speed ``vx`` (the measured
scheduling parameter of ``shared/spec/model.md``), the path curvature and the
roll angle that balances the turn. Names are a contract
(``shared/spec/cli.md``): ``double_lane_change``, ``constant_radius``,
``handling``, ``urban``, ``slalom``.

Conventions (all scenarios)
---------------------------
* ``s(t) = int_0^t vx dt`` is the distance travelled [m].
* ``kappa(s)`` [1/m] is the path curvature at ``s``; positive turns toward
  ``+y``, i.e. a positive yaw rate ``r = vx kappa``.
* ``phi_ref = atan(vx^2 kappa / g)`` [rad] is the roll angle of a point-mass
  rider balancing a steady turn (``tan phi = a_y / g``); ``phi > 0`` leans
  toward ``+y`` (model.md), so a left (``+y``) turn has ``phi_ref > 0``.
  The nonlinear model, whose gravity moment goes with ``sin(phi)`` and whose
  centrifugal moment has no ``cos(phi)``, holds a steady turn of curvature
  ``~ 0.98 g sin(phi) / vx^2`` rather than ``g tan(phi) / vx^2``: holding
  30 deg at 15 m/s the vehicle turns with 15 % less curvature than planned
  (measured with :class:`ptw_env.rider.LQRRider`). The scenarios are
  roll-tracking tasks; the path is the plan, not a constraint.
* The planar path integrates the curvature (no side slip):
  ``psi' = vx kappa``, ``X' = vx cos psi``, ``Y' = vx sin psi`` (trapezoidal
  rule on the output grid).
* Curvature is C1 in ``s`` (cosine, quintic or septic blends; "clothoid-like" entries)
  and speed is continuous, so ``phi_ref`` is continuous; every profile is
  checked to keep ``vx`` in the vehicle's valid range [3, 40] m/s and
  ``|phi_ref| <= 40 deg``.

Examples
--------
>>> p = make_scenario("double_lane_change", speed_kmh=100).profile(dt=0.01)
>>> round(float(p.vx[0] * 3.6), 1), round(float(p.Y[-1]), 3)
(100.0, 0.0)

Length (about 850 lines): every scenario of the environment and the path toolkit they are built from
(segments, speed plan, space-based resampling), so that a scenario's definition reads in one place.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .vehicle import G, Vehicle
#: Largest roll reference a scenario may ask for [rad] (the model is valid to 45 deg).
PHI_REF_MAX = math.radians(40.0)
#: Resolution of the internal path grid [m].
_DS = 0.05


class ScenarioError(ValueError):
    """A scenario parameter outside its valid range, or a path the vehicle cannot ride."""


class UnknownScenarioError(ScenarioError):
    """A scenario name that is not in :data:`SCENARIOS`."""


# ----------------------------------------------------------------------------- profile
@dataclass(frozen=True, eq=False)
class Profile:
    """A scenario sampled every ``dt`` over its duration (arrays of equal length ``n``).

    Attributes
    ----------
    scenario : str
        Name of the scenario that produced it.
    dt : float
        Sample period [s].
    t : ndarray
        Time [s], ``t[k] = k dt``.
    vx : ndarray
        Forward speed [m/s].
    s : ndarray
        Distance travelled [m], ``s' = vx``.
    kappa : ndarray
        Path curvature at ``s(t)`` [1/m]; positive turns toward ``+y``.
    phi_ref : ndarray
        Roll reference [rad], ``atan(vx^2 kappa / g)``; positive leans toward ``+y``.
    X, Y, psi : ndarray
        Planned planar path [m, m] and heading [rad]: ``psi' = vx kappa``,
        ``X' = vx cos psi``, ``Y' = vx sin psi``, starting at 0.
    """

    scenario: str
    dt: float
    t: np.ndarray
    vx: np.ndarray
    s: np.ndarray
    kappa: np.ndarray
    phi_ref: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    psi: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.t)
        for f in ("vx", "s", "kappa", "phi_ref", "X", "Y", "psi"):
            a = np.array(getattr(self, f), dtype=float)
            if a.shape != (n,):
                raise ScenarioError(f"Profile.{f} has shape {a.shape}, expected ({n},) like t")
            a.setflags(write=False)
            object.__setattr__(self, f, a)
        t = np.array(self.t, dtype=float)
        t.setflags(write=False)
        object.__setattr__(self, "t", t)

    def __len__(self) -> int:
        return len(self.t)

    def mirrored(self) -> "Profile":
        """The same ride mirrored left/right: curvature, roll reference, ``Y`` and heading negated (the
        model is odd in the lateral states, so a mirrored ride is the other half of a symmetric training set)."""
        return dataclasses.replace(self, kappa=-self.kappa, phi_ref=-self.phi_ref, Y=-self.Y, psi=-self.psi)

    def check_vehicle(self, vehicle: Vehicle) -> None:
        """Raise :class:`ScenarioError` if the speed ever leaves ``vehicle``'s valid range ``[vmin, vmax]`` [m/s]
        (a scenario is defined without a vehicle; the vehicle that rides it decides which speeds are valid).
        The message names the scenario, the first time and speed outside, and the range in km/h."""
        bad = np.flatnonzero((self.vx < vehicle.vmin - 1e-9) | (self.vx > vehicle.vmax + 1e-9))
        if bad.size:
            k = bad[0]
            raise ScenarioError(
                f"scenario {self.scenario!r}: speed {self.vx[k]:.3g} m/s ({3.6 * self.vx[k]:.3g} km/h) at "
                f"t = {self.t[k]:.2f} s leaves the valid range of {vehicle.name}, [{vehicle.vmin:g}, "
                f"{vehicle.vmax:g}] m/s ([{3.6 * vehicle.vmin:g}, {3.6 * vehicle.vmax:g}] km/h); change the "
                f"scenario's speed parameters")

    @property
    def duration_s(self) -> float:
        """``t[-1]`` [s]."""
        return float(self.t[-1])


def _cumtrapz(y: np.ndarray, x: np.ndarray | float) -> np.ndarray:
    """Cumulative trapezoidal integral starting at 0 (``x`` an array or a constant step)."""
    dx = np.diff(x) if np.ndim(x) else float(x)
    return np.concatenate(([0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * dx)))


def _assemble(name: str, dt: float, t: np.ndarray, vx: np.ndarray, s: np.ndarray, kappa: np.ndarray) -> Profile:
    """Roll reference and planar path from speed and curvature; checks that the speed stays positive and the
    roll bound (the vehicle's speed range is checked by whoever rides it: :meth:`Profile.check_vehicle`)."""
    bad = np.flatnonzero(~(vx > 0))
    if bad.size:
        k = bad[0]
        raise ScenarioError(f"{name}: speed {vx[k]:.3g} m/s at t = {t[k]:.2f} s; the model needs a forward speed > 0 "
                            f"(change the scenario's speed parameters)")
    phi_ref = np.arctan(vx**2 * kappa / G)
    k = int(np.argmax(np.abs(phi_ref)))
    if abs(phi_ref[k]) > PHI_REF_MAX + 1e-9:
        raise ScenarioError(
            f"{name}: the path asks for a roll angle of {math.degrees(phi_ref[k]):.1f} deg at t = {t[k]:.2f} s "
            f"(limit {math.degrees(PHI_REF_MAX):.0f} deg); lower the speed or widen the path"
        )
    psi = _cumtrapz(vx * kappa, dt)
    X = _cumtrapz(vx * np.cos(psi), dt)
    Y = _cumtrapz(vx * np.sin(psi), dt)
    return Profile(name, float(dt), t, vx, s, kappa, phi_ref, X, Y, psi)


# ----------------------------------------------------------------------------- path helpers
def _cos_blend(u: np.ndarray) -> np.ndarray:
    """``(1 - cos(pi u))/2`` on ``u`` clipped to [0, 1]: a C1 step from 0 to 1."""
    return 0.5 * (1.0 - np.cos(np.pi * np.clip(u, 0.0, 1.0)))


def _quintic(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic smoothstep ``S = 6u^5 - 15u^4 + 10u^3`` (``S' = S'' = 0`` at both ends) and its
    first two derivatives with respect to ``u``, on ``u`` clipped to [0, 1]."""
    inside = (u > 0) & (u < 1)
    u = np.clip(u, 0.0, 1.0)
    S = u**3 * (10 - 15 * u + 6 * u**2)
    dS = np.where(inside, 30 * u**2 * (1 - u) ** 2, 0.0)
    d2S = np.where(inside, 60 * u * (1 - u) * (1 - 2 * u), 0.0)
    return S, dS, d2S


def _septic(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Septic smoothstep ``S = 35u^4 - 84u^5 + 70u^6 - 20u^7`` and its first two derivatives.

    ``S'``, ``S''`` and ``S'''`` vanish at both ends, so a path ``y = S`` has a curvature and a
    curvature slope that start and end at zero: the roll reference starts and ends without a
    jump in roll rate.
    """
    inside = (u > 0) & (u < 1)
    u = np.clip(u, 0.0, 1.0)
    S = u**4 * (35 - 84 * u + 70 * u**2 - 20 * u**3)
    dS = np.where(inside, 140 * u**3 * (1 - u) ** 3, 0.0)
    d2S = np.where(inside, 420 * u**2 * (1 - u) ** 2 * (1 - 2 * u), 0.0)
    return S, dS, d2S


def _graph_path(x: np.ndarray, y: np.ndarray, dy: np.ndarray, d2y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length and curvature of the graph ``Y = y(X)``: ``s = int sqrt(1 + y'^2) dX``,
    ``kappa = y'' / (1 + y'^2)^(3/2)``."""
    return _cumtrapz(np.sqrt(1.0 + dy**2), x), d2y / (1.0 + dy**2) ** 1.5


@dataclass(frozen=True)
class Segment:
    """Path segment: a straight (``radius = inf``) or a turn by ``angle`` [rad] (signed, + toward +y)
    on ``radius`` [m] with cosine curvature ramps of ``ramp`` [m] at entry and exit; ``vcap`` [m/s]
    caps the speed on the segment."""

    length: float = 0.0
    angle: float = 0.0
    radius: float = math.inf
    ramp: float = 0.0
    vcap: float = math.inf


def segments_to_grid(segs: list[Segment]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Path grid ``(s, kappa, vcap)`` every :data:`_DS` metres.

    A turn's curvature rises as a cosine blend over ``ramp``, holds ``1/R``, falls back over
    ``ramp``; its heading change is ``(arc + ramp)/R = angle`` with ``arc = R|angle| - ramp``.
    """
    ss, ks, vs = [], [], []
    s0 = 0.0
    for g in segs:
        if math.isinf(g.radius):
            L = g.length
            shape = lambda u: np.zeros_like(u)  # noqa: E731
        else:
            ramp = min(g.ramp, g.radius * abs(g.angle))
            arc = g.radius * abs(g.angle) - ramp
            L = arc + 2 * ramp
            k = math.copysign(1.0 / g.radius, g.angle)

            def shape(sl, k=k, ramp=ramp, L=L):
                if ramp <= 0:
                    return np.full_like(sl, k)
                return k * (_cos_blend(sl / ramp) - _cos_blend((sl - (L - ramp)) / ramp))

        n = max(1, int(round(L / _DS)))
        sl = np.arange(n) * (L / n)
        ss.append(s0 + sl)
        ks.append(shape(sl))
        vs.append(np.full(n, g.vcap))
        s0 += L
    return np.concatenate(ss), np.concatenate(ks), np.concatenate(vs)


def speed_plan(s: np.ndarray, kappa: np.ndarray, vcap: np.ndarray, lateral_g: float, accel: float,
                brake: float, smooth_m: float) -> np.ndarray:
    """Speed along the path [m/s]: the fastest ride within ``|vx^2 kappa| <= lateral_g g``,
    the caps, acceleration ``<= accel`` and deceleration ``<= brake`` [m/s^2].

    The limits are a forward then a backward pass in ``v^2`` (``(v^2)' = 2 a`` in ``s``),
    written as running minima: ``v_f^2(s) = min_{s' <= s} (v_lim^2(s') + 2 accel (s - s'))``.
    A Hann moving average over ``smooth_m`` metres then makes the acceleration continuous.
    """
    with np.errstate(divide="ignore"):
        vlim2 = np.minimum(vcap**2, lateral_g * G / np.abs(kappa))
    fwd = 2 * accel * s + np.minimum.accumulate(vlim2 - 2 * accel * s)
    bwd = -2 * brake * s + np.minimum.accumulate((fwd + 2 * brake * s)[::-1])[::-1]
    w = max(3, int(round(smooth_m / _DS)) | 1)
    win = np.hanning(w + 2)[1:-1]
    win /= win.sum()
    padded = np.concatenate((np.full(w // 2, bwd[0]), bwd, np.full(w // 2, bwd[-1])))
    return np.sqrt(np.convolve(padded, win, mode="valid"))


def space_based(t: np.ndarray, s_grid: np.ndarray, v_grid: np.ndarray, k_grid: np.ndarray,
                 name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(vx, s, kappa)`` at times ``t`` for a speed given along the path: ``t(s) = int ds / v``."""
    t_grid = _cumtrapz(1.0 / v_grid, s_grid)
    if t_grid[-1] < t[-1]:
        raise ScenarioError(f"{name}: internal path too short ({t_grid[-1]:.1f} s for {t[-1]:.1f} s)")
    s = np.interp(t, t_grid, s_grid)
    return np.interp(s, s_grid, v_grid), s, np.interp(s, s_grid, k_grid)


def _kmh(v: float) -> float:
    return v / 3.6


# ----------------------------------------------------------------------------- validation
def _num(obj: Any, field: str) -> float:
    v = getattr(obj, field)
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
        raise ScenarioError(f"{obj.name}: {field} must be a finite number, got {v!r}")
    return float(v)


def require_positive(obj: Any, *fields: str) -> None:
    """Raise :class:`ScenarioError` naming ``obj.name`` and the field unless each of ``fields`` of ``obj`` is > 0."""
    for f in fields:
        if _num(obj, f) <= 0:
            raise ScenarioError(f"{obj.name}: {f} must be > 0, got {getattr(obj, f)!r}")


def _speed_kmh(obj: Any, *fields: str) -> None:
    """A speed parameter [km/h] must be a positive number; which speeds a vehicle can ride is checked against
    that vehicle (:meth:`Profile.check_vehicle`), not here."""
    for f in fields:
        v = _num(obj, f)
        if not v > 0:
            raise ScenarioError(f"{obj.name}: {f} = {v:g} km/h; a speed must be > 0")


def _lateral_g(obj: Any) -> None:
    lim = math.tan(PHI_REF_MAX)
    v = _num(obj, "lateral_g")
    if not (0 < v <= lim):
        raise ScenarioError(f"{obj.name}: lateral_g must be in (0, {lim:.3f}] (roll <= 40 deg), got {v!r}")


# ----------------------------------------------------------------------------- scenarios
@dataclass(frozen=True)
class Scenario:
    """Base class: a named ride of ``duration_s`` seconds.

    Subclasses set the class attribute ``name``, add their parameters as
    fields (validated in :meth:`_validate`, which raises
    :class:`ScenarioError` naming the parameter) and implement
    :meth:`_trajectory`, returning ``(vx, s, kappa)`` at the sample times.
    """

    name: ClassVar[str] = "scenario"
    duration_s: float = 30.0

    def __post_init__(self) -> None:
        require_positive(self, "duration_s")
        self._validate()
        need = self._min_duration()
        if self.duration_s < need - 1e-9:
            raise ScenarioError(
                f"{self.name}: duration_s = {self.duration_s:g} s is shorter than the manoeuvre ({need:.1f} s)"
            )

    def _validate(self) -> None:
        """Check the subclass's parameters."""

    def _min_duration(self) -> float:
        """Shortest ``duration_s`` that holds the whole manoeuvre [s]."""
        return 0.0

    def _trajectory(self, t: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def profile(self, dt: float = 0.01, seed: int | None = None) -> Profile:
        """Sample the scenario every ``dt`` [s] over ``[0, duration_s]``.

        ``seed`` matters only for randomised scenarios (:class:`Urban`); the
        others are deterministic and ignore it.
        """
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not (0 < dt <= self.duration_s / 2):
            raise ScenarioError(f"{self.name}: dt must be in (0, duration_s/2] seconds, got {dt!r}")
        n = int(math.floor(self.duration_s / dt + 1e-9)) + 1
        t = np.arange(n) * float(dt)
        vx, s, kappa = self._trajectory(t, np.random.default_rng(seed))
        return _assemble(self.name, float(dt), t, vx, s, kappa)


def _time_based(t: np.ndarray, vx: np.ndarray, s_grid: np.ndarray, k_grid: np.ndarray):
    s = _cumtrapz(vx, t)
    return vx, s, np.interp(s, s_grid, k_grid)


@dataclass(frozen=True)
class DoubleLaneChange(Scenario):
    """Double lane change at constant speed (ISO 3888-1-like).

    A straight run-in (the vehicle settles), a lateral move of ``offset_m``
    toward ``+y``, a hold in the offset lane, the move back, and a straight
    until the end. Each move is the graph ``y(x) = offset S(x / L)`` with the
    septic smoothstep ``S`` (curvature and its slope zero at both ends, so the
    roll reference starts each move without a jump in roll rate) over
    ``L = v transition_s``. The moves are time-scaled with speed so the peak
    lateral acceleration, ``7.51 offset / transition_s^2`` (2.9 m/s^2,
    16.4 deg of roll at the defaults), and the peak reference roll rate
    (0.7 rad/s) are the same at 50 and at 100 km/h. At 50 km/h the
    geometry is like ISO 3888-1 (3.5 m offset; 42 m transitions where the
    ISO car test has 30 m; 28 m in the offset lane).

    Parameters
    ----------
    speed_kmh : float
        Constant speed [km/h] (default 50; also used at 100).
    offset_m : float
        Lateral offset of the second lane [m] (default 3.5; negative moves toward ``-y``).
    run_in_s, transition_s, hold_s : float
        Straight run-in, duration of each lateral move, time in the offset lane [s].
    duration_s : float
        Total duration [s] (default 20).

    Examples
    --------
    >>> p = DoubleLaneChange(speed_kmh=50).profile()
    >>> round(float(p.Y.max()), 2), round(float(np.degrees(p.phi_ref).max()), 1)
    (3.5, 16.4)
    """

    name: ClassVar[str] = "double_lane_change"
    duration_s: float = 20.0
    speed_kmh: float = 50.0
    offset_m: float = 3.5
    run_in_s: float = 3.0
    transition_s: float = 3.0
    hold_s: float = 2.0

    def _validate(self) -> None:
        _speed_kmh(self, "speed_kmh")
        _num(self, "offset_m")
        require_positive(self, "run_in_s", "transition_s", "hold_s")

    def _min_duration(self) -> float:
        return self.run_in_s + 2 * self.transition_s + self.hold_s

    def _phases_x(self) -> tuple[float, float, float]:
        """Start of the first move, start of the return move and its length, along X [m]."""
        v = _kmh(self.speed_kmh)
        x0 = v * self.run_in_s
        L = v * self.transition_s
        return x0, x0 + L + v * self.hold_s, L

    def _trajectory(self, t, rng):
        v = _kmh(self.speed_kmh)
        x0, x1, L = self._phases_x()
        x = np.arange(0.0, v * t[-1] + 10.0, _DS)
        S1, dS1, d2S1 = _septic((x - x0) / L)
        S2, dS2, d2S2 = _septic((x - x1) / L)
        a = self.offset_m
        s_grid, k_grid = _graph_path(x, a * (S1 - S2), a * (dS1 - dS2) / L, a * (d2S1 - d2S2) / L**2)
        return _time_based(t, np.full_like(t, v), s_grid, k_grid)


@dataclass(frozen=True)
class ConstantRadius(Scenario):
    """Constant-radius turn while accelerating (a steady-state cornering test).

    A straight run-in at ``v_start_kmh``, a clothoid-like entry (curvature
    rises to ``1/radius_m`` as a cosine blend over ``entry_s`` of travel),
    ``settle_s`` on the circle, then the speed follows a cosine blend from
    ``v_start_kmh`` to ``v_end_kmh`` with mean acceleration ``accel_mps2``
    (peak ``pi/2`` times that), then holds. The roll reference grows with
    speed: ``atan(v^2 / (R g))`` = 10.9 deg at 50 km/h and 38.2 deg at
    100 km/h for R = 100 m.

    Parameters
    ----------
    radius_m : float
        Turn radius [m] (default 100; positive, the turn is toward ``+y``).
    v_start_kmh, v_end_kmh : float
        Speed at entry and at the end [km/h] (defaults 50 and 100).
    accel_mps2 : float
        Mean longitudinal acceleration of the speed change [m/s^2] (default 1).
    run_in_s, entry_s, settle_s : float
        Straight run-in, entry transition, time on the circle before the speed changes [s].
    duration_s : float
        Total duration [s] (default 30).

    Examples
    --------
    >>> p = ConstantRadius().profile()
    >>> round(float(p.vx[0] * 3.6)), round(float(p.vx[-1] * 3.6)), round(float(1 / p.kappa[-1]), 1)
    (50, 100, 100.0)
    """

    name: ClassVar[str] = "constant_radius"
    duration_s: float = 30.0
    radius_m: float = 100.0
    v_start_kmh: float = 50.0
    v_end_kmh: float = 100.0
    accel_mps2: float = 1.0
    run_in_s: float = 2.0
    entry_s: float = 2.0
    settle_s: float = 2.0

    def _validate(self) -> None:
        require_positive(self, "radius_m", "accel_mps2", "run_in_s", "entry_s", "settle_s")
        _speed_kmh(self, "v_start_kmh", "v_end_kmh")
        vmax = _kmh(max(self.v_start_kmh, self.v_end_kmh))
        phi = math.atan(vmax**2 / (self.radius_m * G))
        if phi > PHI_REF_MAX:
            raise ScenarioError(
                f"{self.name}: radius_m = {self.radius_m:g} m at {vmax * 3.6:g} km/h needs "
                f"{math.degrees(phi):.1f} deg of roll (limit 40 deg); increase radius_m or lower the speeds"
            )

    def _accel_time(self) -> float:
        return abs(_kmh(self.v_end_kmh - self.v_start_kmh)) / self.accel_mps2

    def _min_duration(self) -> float:
        return self.run_in_s + self.entry_s + self.settle_s + self._accel_time()

    def _trajectory(self, t, rng):
        v0, v1 = _kmh(self.v_start_kmh), _kmh(self.v_end_kmh)
        t_acc = self.run_in_s + self.entry_s + self.settle_s
        T = self._accel_time()
        vx = v0 + (v1 - v0) * (_cos_blend((t - t_acc) / T) if T > 0 else 0.0)
        s_run, L = v0 * self.run_in_s, v0 * self.entry_s
        s_grid = np.arange(0.0, max(v0, v1) * t[-1] + 10.0, _DS)
        k_grid = _cos_blend((s_grid - s_run) / L) / self.radius_m
        return _time_based(t, vx, s_grid, k_grid)


@dataclass(frozen=True)
class Slalom(Scenario):
    """Slalom through a row of cones at constant speed.

    Cones stand every ``cone_spacing_m`` on the straight line ``y = 0``; the
    path passes them alternately at ``+-amplitude_m``:
    ``y(x) = amplitude E(x) sin(pi (x - x0)/d)`` where the envelope ``E``
    rises (quintic smoothstep) over two spacings after a straight run-in
    (``n_cones`` cones at full amplitude follow) and falls over two spacings.
    Lateral acceleration ``v^2 amplitude (pi/d)^2`` at full amplitude
    (3.0 m/s^2, 17.3 deg of roll at the defaults; the envelope's ramps add up
    to 11 %); the rider is excited at ``v / (2 d)`` Hz (0.28 Hz at the
    defaults), near the weave mode at low speed.

    Parameters
    ----------
    speed_kmh : float
        Constant speed [km/h] (default 50).
    cone_spacing_m : float
        Distance between cones ``d`` [m] (default 25).
    amplitude_m : float
        Lateral excursion of the path at the cones [m] (default 1.0).
    n_cones : int
        Number of cones passed at full amplitude (default 8).
    run_in_s : float
        Straight run-in [s] (default 3).
    duration_s : float
        Total duration [s] (default 30).

    Examples
    --------
    >>> p = Slalom().profile()
    >>> round(float(np.abs(p.Y).max()), 2), round(float(np.degrees(p.phi_ref).max()), 1)
    (1.0, 19.0)
    """

    name: ClassVar[str] = "slalom"
    duration_s: float = 30.0
    speed_kmh: float = 50.0
    cone_spacing_m: float = 25.0
    amplitude_m: float = 1.0
    n_cones: int = 8
    run_in_s: float = 3.0

    def _validate(self) -> None:
        _speed_kmh(self, "speed_kmh")
        require_positive(self, "cone_spacing_m", "amplitude_m", "run_in_s")
        if isinstance(self.n_cones, bool) or not isinstance(self.n_cones, (int, np.integer)) or self.n_cones < 1:
            raise ScenarioError(f"{self.name}: n_cones must be an integer >= 1, got {self.n_cones!r}")

    def _min_duration(self) -> float:
        return self.run_in_s + (self.n_cones + 4) * self.cone_spacing_m / _kmh(self.speed_kmh)

    def _trajectory(self, t, rng):
        v, d, a = _kmh(self.speed_kmh), self.cone_spacing_m, self.amplitude_m
        x0 = v * self.run_in_s
        x1 = x0 + (self.n_cones + 2) * d  # the envelope rises over [x0, x0 + 2d], falls over [x1, x1 + 2d]
        x = np.arange(0.0, v * t[-1] + 10.0, _DS)
        Su, dSu, d2Su = _quintic((x - x0) / (2 * d))
        Sd, dSd, d2Sd = _quintic((x - x1) / (2 * d))
        E, dE, d2E = Su - Sd, (dSu - dSd) / (2 * d), (d2Su - d2Sd) / (2 * d) ** 2
        w = math.pi / d
        sn, cs = np.sin(w * (x - x0)), np.cos(w * (x - x0))
        y = a * E * sn
        dy = a * (dE * sn + E * w * cs)
        d2y = a * (d2E * sn + 2 * dE * w * cs - E * w**2 * sn)
        s_grid, k_grid = _graph_path(x, y, dy, d2y)
        return _time_based(t, np.full_like(t, v), s_grid, k_grid)


#: Handling track, counter-clockwise: (kind, length [m] or (angle [deg], radius [m])).
#: The two straights marked None are solved so that the lap closes.
_TRACK: tuple[tuple[str, Any], ...] = (
    ("straight", None),  # main straight (start/finish)
    ("turn", (120.0, 28.0)),
    ("straight", 80.0),
    ("turn", (-60.0, 90.0)),
    ("straight", 60.0),
    ("turn", (110.0, 150.0)),
    ("straight", None),  # back straight
    ("turn", (100.0, 26.0)),
    ("straight", 90.0),
    ("turn", (-70.0, 55.0)),
    ("straight", 40.0),
    ("turn", (70.0, 40.0)),
    ("straight", 180.0),
    ("turn", (90.0, 120.0)),
)


@dataclass(frozen=True)
class Handling(Scenario):
    """A closed handling track ridden briskly (like Fig. 2 of Fouka, Nehaoua, Arioui).

    Fourteen segments, counter-clockwise: a main and a back straight, a
    hairpin (R 26 m, 150 deg), tight (R 28-40 m), medium (R 55-90 m) and fast
    (R 120-160 m) turns, left and right; the two straights are sized so the
    lap closes exactly (lap 1.99 km, 87 s at the defaults). Turn entries are clothoid-like
    (cosine curvature ramps over ``ramp_s`` of travel at the turn speed).
    The speed is the fastest ride with lateral acceleration
    ``<= lateral_g g``, speed ``<= v_max_kmh``, acceleration
    ``<= accel_mps2`` and braking ``<= brake_mps2``, smoothed over 15 m; at
    the defaults it varies between ~40 km/h (hairpin) and 120 km/h (main
    straight), roll up to ``atan(lateral_g)`` (26.6 deg; 27.8 deg where the
    smoothing carries some speed into a turn entry). The ride starts on the
    main straight after a lap's worth of run-up (so the speed is that of a
    rider on the track) and continues onto further laps if ``duration_s``
    exceeds a lap.

    Parameters
    ----------
    v_max_kmh : float
        Top speed on the straights [km/h] (default 120).
    lateral_g : float
        Cornering lateral acceleration in g (default 0.5, i.e. 26.6 deg of roll).
    accel_mps2, brake_mps2 : float
        Acceleration and braking limits [m/s^2] (defaults 2.5 and 4).
    ramp_s : float
        Duration of the turn-entry/exit curvature ramps [s] (default 1.2).
    duration_s : float
        Total duration [s] (default 87, one lap).

    Examples
    --------
    >>> p = Handling().profile()
    >>> round(float(p.vx.min() * 3.6)), round(float(p.vx.max() * 3.6))
    (41, 120)
    """

    name: ClassVar[str] = "handling"
    duration_s: float = 87.0
    v_max_kmh: float = 120.0
    lateral_g: float = 0.5
    accel_mps2: float = 2.5
    brake_mps2: float = 4.0
    ramp_s: float = 1.2

    def _validate(self) -> None:
        _speed_kmh(self, "v_max_kmh")
        _lateral_g(self)
        require_positive(self, "accel_mps2", "brake_mps2", "ramp_s")

    def _lap(self) -> list[Segment]:
        """One closed lap; the two free straights solve ``end = start`` (a 2 x 2 linear system)."""
        vmax = _kmh(self.v_max_kmh)

        def segs(l1: float, l2: float) -> list[Segment]:
            free = iter((l1, l2))
            out = []
            for kind, val in _TRACK:
                if kind == "straight":
                    out.append(Segment(length=next(free) if val is None else val, vcap=vmax))
                else:
                    ang, R = val
                    vt = min(vmax, math.sqrt(self.lateral_g * G * R))
                    out.append(Segment(angle=math.radians(ang), radius=R, ramp=vt * self.ramp_s, vcap=vmax))
            return out

        def end(l1: float, l2: float) -> np.ndarray:
            s, k, _ = segments_to_grid(segs(l1, l2) + [Segment(length=_DS)])
            psi = _cumtrapz(k, s)
            return np.array([_cumtrapz(np.cos(psi), s)[-1], _cumtrapz(np.sin(psi), s)[-1]])

        # end(l1, l2) = end(0, 0) + l1 u1 + l2 u2 with u the unit vectors of the free straights
        e0 = end(0.0, 0.0)
        J = np.column_stack([end(1.0, 0.0) - e0, end(0.0, 1.0) - e0])
        l1, l2 = np.linalg.solve(J, -e0)
        if min(l1, l2) < 50.0:
            raise ScenarioError(f"{self.name}: the track does not close with positive straights ({l1:.0f}, {l2:.0f} m)")
        return segs(float(l1), float(l2))

    def _trajectory(self, t, rng):
        lap = self._lap()
        s1, k1, c1 = segments_to_grid(lap)
        lap_len = s1[-1] + _DS
        laps = int(math.ceil(_kmh(self.v_max_kmh) * t[-1] / lap_len)) + 2
        s = np.concatenate([s1 + i * lap_len for i in range(laps)])
        k, c = np.tile(k1, laps), np.tile(c1, laps)
        v = speed_plan(s, k, c, self.lateral_g, self.accel_mps2, self.brake_mps2, smooth_m=15.0)
        keep = s >= lap_len  # drop the run-up lap
        return space_based(t, s[keep] - lap_len, v[keep], k[keep], self.name)


@dataclass(frozen=True)
class Urban(Scenario):
    """Urban ride: straights, narrow and wide turns, speeds ~30-90 km/h (randomised, seeded).

    Segments drawn from ``np.random.default_rng(seed)``: straights of
    60-250 m with a cruise speed uniform in ``[max(50, v_min), v_max]`` km/h,
    30 % of them with a slow-down (traffic) to ``v_min``-50 km/h; each
    straight is followed by a turn, left with probability
    ``1 / (1 + exp(psi / (pi/2)))`` given the heading ``psi`` so far (even
    odds when heading as at the start; the route meanders, it does not
    spiral): narrow (R 18-35 m, 70-100 deg; intersections) with probability 0.4, or
    wide (R 60-200 m, 20-70 deg). The speed is the fastest ride with
    lateral acceleration ``<= lateral_g g`` (never below ``v_min_kmh``),
    acceleration ``<= accel_mps2``, braking ``<= brake_mps2``, smoothed
    over 10 m. The ride starts on a 60 m straight. Same seed, same ride.

    Parameters
    ----------
    v_min_kmh, v_max_kmh : float
        Slowest and fastest speeds [km/h] (defaults 30, 90).
    lateral_g : float
        Cornering lateral acceleration in g (default 0.35, 19 deg of roll).
    accel_mps2, brake_mps2 : float
        Acceleration and braking limits [m/s^2] (defaults 2 and 3).
    ramp_s : float
        Duration of the curvature ramps at turn entry and exit [s] (default 1.2).
    seed : int
        Default seed of the randomisation (``profile(seed=...)`` overrides it).
    duration_s : float
        Total duration [s] (default 90).

    Examples
    --------
    >>> p = Urban().profile()
    >>> bool(np.array_equal(p.vx, Urban().profile(seed=0).vx)), bool(20 < p.vx.max() * 3.6 <= 90)
    (True, True)
    """

    name: ClassVar[str] = "urban"
    duration_s: float = 90.0
    v_min_kmh: float = 30.0
    v_max_kmh: float = 90.0
    lateral_g: float = 0.35
    accel_mps2: float = 2.0
    brake_mps2: float = 3.0
    ramp_s: float = 1.2
    seed: int = 0

    def _validate(self) -> None:
        _speed_kmh(self, "v_min_kmh", "v_max_kmh")
        if self.v_min_kmh >= self.v_max_kmh:
            raise ScenarioError(
                f"{self.name}: v_min_kmh ({self.v_min_kmh:g}) must be below v_max_kmh ({self.v_max_kmh:g})"
            )
        _lateral_g(self)
        require_positive(self, "accel_mps2", "brake_mps2", "ramp_s")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ScenarioError(f"{self.name}: seed must be a non-negative integer, got {self.seed!r}")

    def _segments(self, rng: np.random.Generator, length: float) -> list[Segment]:
        vmin, vmax = _kmh(self.v_min_kmh), _kmh(self.v_max_kmh)
        # cruise in the upper two thirds of the speed range, slow down for traffic in the lower third
        # (50 km/h for the default 30-90 km/h; a fraction, so that a bicycle's 5-25 km/h works alike)
        split = _kmh(self.v_min_kmh + (self.v_max_kmh - self.v_min_kmh) / 3.0)
        segs = [Segment(length=60.0, vcap=vmax)]
        total, heading = 60.0, 0.0
        while total < length:
            L = rng.uniform(60.0, 250.0)
            cruise = rng.uniform(split, vmax)
            if rng.random() < 0.3:  # slow down for traffic in the middle of the straight
                slow = rng.uniform(vmin, split)
                segs += [Segment(length=L / 2, vcap=cruise), Segment(length=10.0, vcap=slow), Segment(length=L / 2, vcap=cruise)]
                L += 10.0
            else:
                segs.append(Segment(length=L, vcap=cruise))
            if rng.random() < 0.4:
                R, ang = rng.uniform(18.0, 35.0), rng.uniform(70.0, 100.0)
            else:
                R, ang = rng.uniform(60.0, 200.0), rng.uniform(20.0, 70.0)
            # left with probability 1/(1 + exp(heading / (pi/2))): the route does not spiral
            ang *= 1.0 if rng.random() < 1.0 / (1.0 + math.exp(heading / (math.pi / 2))) else -1.0
            heading += math.radians(ang)
            vt = min(cruise, max(vmin, math.sqrt(self.lateral_g * G * R)))
            segs.append(Segment(angle=math.radians(ang), radius=R, ramp=vt * self.ramp_s, vcap=cruise))
            total += L + R * math.radians(abs(ang))
        return segs

    def _trajectory(self, t, rng):
        s, k, c = segments_to_grid(self._segments(rng, _kmh(self.v_max_kmh) * t[-1] + 100.0))
        # never slower than v_min: lift the lateral limit where a turn is too tight for v_min
        with np.errstate(divide="ignore"):
            lat = np.maximum(self.lateral_g, _kmh(self.v_min_kmh) ** 2 * np.abs(k) / G)
        v = speed_plan(s, k / lat * self.lateral_g, c, self.lateral_g, self.accel_mps2, self.brake_mps2, 10.0)
        return space_based(t, s, v, k, self.name)

    def profile(self, dt: float = 0.01, seed: int | None = None) -> Profile:
        """Sample the ride every ``dt`` [s]; ``seed`` (default: the field ``seed``) draws the segments."""
        return Scenario.profile(self, dt, self.seed if seed is None else seed)


#: Scenario classes by their contract name (cli.md).
SCENARIOS: dict[str, type[Scenario]] = {
    c.name: c for c in (DoubleLaneChange, ConstantRadius, Handling, Urban, Slalom)
}


def scenario_names() -> tuple[str, ...]:
    """The known scenario names, in the order of ``shared/spec/cli.md``."""
    return tuple(SCENARIOS)


def make_scenario(name: str, speed_kmh: float | None = None, **overrides: Any) -> Scenario:
    """Build a scenario by name with its defaults, changed by ``speed_kmh`` and ``overrides``.

    Parameters
    ----------
    name : str
        One of :func:`scenario_names`.
    speed_kmh : float, optional
        Cruise speed [km/h] (the CLI's ``--speed``); only for scenarios that
        have one (``double_lane_change``, ``slalom``).
    **overrides
        Other fields of the scenario class (e.g. ``radius_m=80``, ``duration_s=40``).

    Raises
    ------
    UnknownScenarioError
        ``name`` is not a known scenario (the message lists the known names).
    ScenarioError
        An unknown field, or a value out of range (the message names the field).

    Examples
    --------
    >>> make_scenario("constant_radius", radius_m=120).radius_m
    120
    >>> make_scenario("slalom", speed_kmh=40).speed_kmh
    40
    """
    if name not in SCENARIOS:
        raise UnknownScenarioError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}")
    cls = SCENARIOS[name]
    fields = [f.name for f in dataclasses.fields(cls)]
    if speed_kmh is not None:
        if "speed_kmh" not in fields:
            speeds = [f for f in fields if f.endswith("_kmh")]
            raise ScenarioError(
                f"scenario {name!r} has no cruise speed (speed_kmh); its speed parameters are {', '.join(speeds)}"
            )
        overrides["speed_kmh"] = speed_kmh
    unknown = [k for k in overrides if k not in fields]
    if unknown:
        raise ScenarioError(f"scenario {name!r} has no parameter {unknown[0]!r}; its parameters: {', '.join(fields)}")
    return cls(**overrides)


__all__ = [
    "Profile",
    "Scenario",
    "DoubleLaneChange",
    "ConstantRadius",
    "Handling",
    "Urban",
    "Slalom",
    "SCENARIOS",
    "ScenarioError",
    "UnknownScenarioError",
    "make_scenario",
    "scenario_names",
    # the path toolkit (used by assist.risk.evaluation to build its curve scenario)
    "Segment",
    "require_positive",
    "segments_to_grid",
    "space_based",
    "speed_plan",
]
