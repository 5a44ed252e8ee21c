"""Domain randomisation: a ``randomize=`` description sampled per environment at every reset.

A description maps a *key* to a *distribution*. Keys:

* ``"CAUSE:PARAM"``: a parameter of an effect of effects.md (:data:`ptw_env.effects.VOCABULARY`), e.g.
  ``"tire_stiffness:front_scale"``, ``"tire_saturation:mu_peak"`` (the tire's peak friction: the road),
  ``"payload:mass_kg"``, ``"road_bank:bank_rad"``, ``"steer_damping:damping_nms"``,
  ``"relaxation_length:sigma_m"``, ``"roll_moment_offset:moment_nm"``, ``"gyro_bias:yaw_rate_bias"``,
  ``"ay_frame:gravity_gain"``. The sample replaces the environment's own value of that parameter for
  the episode. (``sensor_delay`` changes the length of the sensors' history and is not randomised.)
* ``"tire_stiffness:scale"``: one factor for both axles' stiffness (front and rear together).
* ``"force:EQUATION:FEATURE"``: the coefficient ``c`` of a generalised force ``c * feature`` added to one
  equation of model.md (:func:`ptw_env.dynamics.add_generalised_forces`; EQUATION one of lateral, yaw, roll,
  steer, FEATURE one of :data:`ptw_env.dynamics.FORCE_FEATURES`), e.g. ``"force:steer:delta_dot"``
  (viscous steering friction [N m s/rad]) or ``"force:roll:vx^2"``: a model extension of the diagnosis
  (a digital twin, ``ptw-assist twin``).
* ``"vehicle:PARAM"``: a physical parameter of the vehicle (:data:`ptw_env.sharp.SPECS`, SI units: masses,
  mass-centre positions, wheelbase, caster, trail, inertias, wheel spin inertias, damper, tyre stiffness and
  relaxation lengths), e.g. ``"vehicle:M_r"`` [kg] (the rider's mass is in the rear frame), ``"vehicle:h"``
  [m], ``"vehicle:I_rx"`` [kg m^2]; ``"vehicle_scale:PARAM"``: a factor on the vehicle's own value (the same
  description then suits any vehicle, e.g. ``("uniform", 0.9, 1.1)``). The drawn vehicle is built from its
  parameters by Table V (:func:`ptw_env.sharp.parameter_batch`: ``E``, ``A0``, ``A1``, the mass, the axle
  loads; ``Z_f`` follows the statics), so the vehicle must have physical parameters (a vehicle file; not the
  reference scooter, given as matrix entries). The action scale, the observation bounds, the sensors' ranges
  and the speed range stay the nominal vehicle's (the spaces cannot change per episode). When the
  environment is made, the vehicles at the corners of the box of the supports are built and checked (all
  ``2^k`` corners for ``k <= 10`` keys, else all-low, all-high and each key at its other end): a rule of
  :data:`~ptw_env.sharp.SPECS` broken, a wheel without load (the combined mass centre outside the wheelbase)
  or a mass matrix that is not positive definite is an error then. For the rules and the axle loads
  (intervals and multilinear functions of the parameters) the corners decide for the whole box; the mass
  matrix is quadratic in the mass-centre positions, so a draw inside the box could in principle still fail
  its check: that reset then raises one :class:`RandomizationError` naming the keys. A normal on a vehicle
  key needs finite bounds (``("normal", mean, std, low, high)``). The environment's integration step is sized
  for the fastest linearised mode among those corners and the plants of :meth:`Randomization.stiffest_rate`.
* ``"sensor_noise_scale"``: a factor on every channel's noise standard deviation.
* ``"sensor_bias:CHANNEL"``: an offset [channel unit] added to that channel's bias
  (:data:`ptw_env.sensors.CHANNELS`).

The RK4 substeps of an environment with ``randomize=`` keep ``|lambda h|`` of the fastest drawable plant
inside :data:`ptw_env.integrate.MAX_LAMBDA_H` (:meth:`Randomization.stiffest_rate`) at the speeds of each
ride (:func:`ptw_env.integrate.speed_grid`; the vehicle's whole range with ``randomize_course``): a randomised
short relaxation length or Coulomb friction integrates with more substeps, for every episode of that ride;
so does a draw only slightly faster than the nominal vehicle when that one sits at the edge of a substep
count (the reference scooter's 185.6 1/s at 40 m/s takes 4 substeps, a tire stiffness drawn 0.8x makes
188.4 and 5; at 50 km/h the same draws keep the 2.5 ms step, 4 substeps).

Distributions: a number (fixed), ``("uniform", low, high)``, ``("loguniform", low, high)``,
``("normal", mean, std)`` or ``("normal", mean, std, low, high)`` (clipped to ``[low, high]``; ``None`` for
the physical bound), or
``("choice", [v1, v2, ...])``; also as JSON lists or ``{"dist": "uniform", "low": ..., "high": ...}``.
An effect parameter's draws must lie in its physical range of effects.md: a uniform range outside it is
an error, a normal's tails are clipped to it (stated in :attr:`Randomization.describe`).

Draws come from the environment's own generator, one call of ``random(number of keys)`` mapped through
each key's inverse distribution function in the sorted order of the keys, before the starting
roll angle and the sensor noise. A reset draws the *next* episode's values (the first reset, and a reset
with a seed, draw the episode's own first, then the next one's): the vector environment then compiles the
next episodes' plants many envs at a time, ahead of their resets. So ``reset(seed=s)`` gives the same
vehicle, road and readings in the single environment and in env ``i`` of the vector environment seeded
``s - i``, episode after episode.

>>> import numpy as np
>>> r = Randomization({"tire_saturation:mu_peak": ("uniform", 0.3, 1.0), "payload:mass_kg": ("normal", 0, 10)})
>>> s = r.sample(np.random.default_rng(0))
>>> sorted(s), 0.3 <= s["tire_saturation:mu_peak"] <= 1.0
(['payload:mass_kg', 'tire_saturation:mu_peak'], True)
>>> r.effects(Effects(), {k: np.array([v]) for k, v in s.items()}).batch_shape
(1,)
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.special import ndtri

from .dynamics import FORCE_FEATURES, FORCE_ROWS, Plant, add_generalised_forces, compile_plant
from .effects import DYNAMIC_CAUSES, VOCABULARY, Effects
from .integrate import linear_rate
from .sensors import CHANNELS
from .sharp import SPECS, SharpParameterError, parameter_batch, table_v

DISTRIBUTIONS = ("fixed", "uniform", "loguniform", "normal", "choice")
#: keys besides "CAUSE:PARAM"
EXTRA_KEYS = (("tire_stiffness:scale", "sensor_noise_scale", "force:EQUATION:FEATURE", "vehicle:PARAM",
               "vehicle_scale:PARAM") + tuple(f"sensor_bias:{c}" for c in CHANNELS))
#: the interval of each rule of :data:`ptw_env.sharp.SPECS` (ends are checked against the rule itself)
_RULE_BOUNDS = {"positive": (0.0, math.inf), "nonnegative": (0.0, math.inf), "negative": (-math.inf, 0.0),
                "any": (-math.inf, math.inf), "angle": (0.0, math.pi / 2)}
#: largest number of vehicle keys whose 2^k corners are all checked
MAX_CORNER_KEYS = 10


class RandomizationError(ValueError):
    """A bad ``randomize=`` description (names the key and the value)."""


def inverse_transform(kind: str, a: Any, b: Any, low: Any, high: Any, u: np.ndarray) -> np.ndarray:
    """Draws of a ``fixed`` (``a``), ``uniform`` (``a + (b - a) u``), ``loguniform`` (``exp`` of that in log
    space) or ``normal`` (``a + b Phi^-1(u)`` clipped to ``[low, high]``) distribution from uniform numbers ``u``
    in [0, 1); the parameters are numbers, or arrays broadcasting with ``u`` (several keys of one kind at once,
    :meth:`Randomization.sample_table`). The one copy of these formulas."""
    if kind == "fixed":
        return np.broadcast_to(np.asarray(a, dtype=float), np.shape(u)).copy()
    if kind == "uniform":
        return a + (b - a) * u
    if kind == "loguniform":
        la, lb = np.log(a), np.log(b)
        return np.exp(la + (lb - la) * u)
    if kind == "normal":
        return np.clip(a + b * ndtri(np.clip(u, 1e-300, None)), low, high)  # u = 0 would be -inf
    raise ValueError(f"no inverse transform for a {kind!r} distribution")


@dataclass(frozen=True)
class Distribution:
    """One seeded distribution (see the module docstring); ``low``/``high`` bound every draw."""

    kind: str
    a: float = 0.0
    b: float = 0.0
    low: float = -math.inf
    high: float = math.inf
    values: tuple[float, ...] = ()

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        """Draws by inverse transform of uniform numbers ``u`` in [0, 1) (any shape): :func:`inverse_transform`,
        or ``values[floor(n u)]`` for a choice."""
        u = np.asarray(u, dtype=float)
        if self.kind == "choice":
            return np.asarray(self.values)[np.minimum((u * len(self.values)).astype(np.int64), len(self.values) - 1)]
        return inverse_transform(self.kind, self.a, self.b, self.low, self.high, u)

    @property
    def tails(self) -> tuple[float, float]:
        """The ends of what is drawn in practice: :attr:`support`, a normal's cut at 5 standard deviations
        (inside its bounds, also when its mean lies outside them)."""
        lo, hi = self.support
        if self.kind == "normal":
            lo, hi = min(max(lo, self.a - 5.0 * self.b), hi), max(min(hi, self.a + 5.0 * self.b), lo)
        return lo, hi

    @property
    def support(self) -> tuple[float, float]:
        """Smallest and largest value a draw can take."""
        if self.kind == "fixed":
            return self.a, self.a
        if self.kind in ("uniform", "loguniform"):
            return self.a, self.b
        if self.kind == "normal":
            return self.low, self.high
        return min(self.values), max(self.values)

    def to_json(self) -> Any:
        if self.kind == "fixed":
            return self.a
        if self.kind == "choice":
            return ["choice", list(self.values)]
        if self.kind == "normal":  # an infinite bound is written null (strict JSON) and read as the physical one
            out: list[Any] = ["normal", self.a, self.b]
            if math.isfinite(self.low) or math.isfinite(self.high):
                out += [v if math.isfinite(v) else None for v in (self.low, self.high)]
            return out
        return [self.kind, self.a, self.b]


def _number(key: str, what: str, v: Any) -> float:
    if isinstance(v, bool):
        raise RandomizationError(f"randomize[{key!r}]: {what} must be a number, got {v!r}")
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise RandomizationError(f"randomize[{key!r}]: {what} must be a number, got {v!r}") from None
    if not math.isfinite(f):
        raise RandomizationError(f"randomize[{key!r}]: {what} must be finite, got {v!r}")
    return f


def _parse(key: str, spec: Any, bounds: tuple[float, float]) -> Distribution:
    lo_b, hi_b = bounds
    if isinstance(spec, Mapping):
        spec = dict(spec)
        kind = spec.pop("dist", None)
        order = {"uniform": ("low", "high"), "loguniform": ("low", "high"), "normal": ("mean", "std", "low", "high"),
                 "choice": ("values",)}
        if kind not in order:
            raise RandomizationError(f"randomize[{key!r}]: 'dist' must be one of {', '.join(order)}, got {kind!r}")
        extra = set(spec) - set(order[kind])
        if extra:
            raise RandomizationError(f"randomize[{key!r}]: unknown field(s) {sorted(extra)} of a {kind} distribution")
        spec = [kind] + [spec[f] for f in order[kind] if f in spec]
    if isinstance(spec, (int, float, np.number)) and not isinstance(spec, bool):
        v = _number(key, "the fixed value", spec)
        d = Distribution("fixed", v)
    elif isinstance(spec, (list, tuple)) and spec and isinstance(spec[0], str):
        kind, args = spec[0], list(spec[1:])
        if kind == "choice":
            if len(args) != 1 or not isinstance(args[0], (list, tuple)) or not args[0]:
                raise RandomizationError(f"randomize[{key!r}]: choice takes one non-empty list of values, got {spec!r}")
            d = Distribution("choice", values=tuple(_number(key, "a choice", v) for v in args[0]))
        elif kind in ("uniform", "loguniform"):
            if len(args) != 2:
                raise RandomizationError(f"randomize[{key!r}]: {kind} takes (low, high), got {spec!r}")
            a, b = (_number(key, n, v) for n, v in zip(("low", "high"), args))
            if not a <= b:
                raise RandomizationError(f"randomize[{key!r}]: {kind} needs low <= high, got {a} > {b}")
            if kind == "loguniform" and a <= 0:
                raise RandomizationError(f"randomize[{key!r}]: loguniform needs low > 0, got {a}")
            d = Distribution(kind, a, b)
        elif kind == "normal":
            if len(args) not in (2, 4):
                raise RandomizationError(f"randomize[{key!r}]: normal takes (mean, std) or (mean, std, low, high), got {spec!r}")
            default = (None, None, lo_b, hi_b)
            vals = [default[j] if (j >= 2 and v is None) else _number(key, n, v)
                    for j, (n, v) in enumerate(zip(("mean", "std", "low", "high"), args))]
            if vals[1] < 0:
                raise RandomizationError(f"randomize[{key!r}]: normal std must be >= 0, got {vals[1]}")
            lo, hi = (vals[2], vals[3]) if len(vals) == 4 else (lo_b, hi_b)
            if not lo <= hi:
                raise RandomizationError(f"randomize[{key!r}]: normal needs low <= high, got {lo} > {hi}")
            d = Distribution("normal", vals[0], vals[1], max(lo, lo_b), min(hi, hi_b))
        else:
            raise RandomizationError(f"randomize[{key!r}]: unknown distribution {kind!r}; known: {', '.join(DISTRIBUTIONS)}")
    else:
        raise RandomizationError(f"randomize[{key!r}]: expected a number or [kind, ...] e.g. ['uniform', 0.8, 1.2], got {spec!r}")
    lo, hi = d.support
    if lo < lo_b or hi > hi_b:
        raise RandomizationError(f"randomize[{key!r}]: draws in [{lo}, {hi}] leave the physical range [{lo_b}, {hi_b}]")
    return d


def _read_json(path: str, what: str) -> Any:
    """The JSON of ``path``; one :class:`RandomizationError` naming the file (and line, column) otherwise."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except OSError as exc:
        raise RandomizationError(f"{what}: cannot read {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise RandomizationError(f"{what}: {path} line {exc.lineno} column {exc.colno}: {exc.msg}") from None


class Randomization:
    """A parsed ``randomize=`` description (module docstring); immutable, picklable.

    Parameters
    ----------
    spec : mapping key -> distribution, or a JSON file's path (the same mapping, e.g. a digital twin)
    """

    def __init__(self, spec: Mapping[str, Any]) -> None:
        if not isinstance(spec, Mapping):
            raise RandomizationError(f"randomize must be a mapping key -> distribution, got {type(spec).__name__}")
        dists: dict[str, Distribution] = {}
        for key in sorted(spec):
            if not isinstance(key, str):
                raise RandomizationError(f"randomize: keys are strings, got {key!r}")
            if key in ("tire_stiffness:scale",):
                bounds = VOCABULARY["tire_stiffness"]["front_scale"][2:]
            elif key == "sensor_noise_scale":
                bounds = (0.0, math.inf)
            elif key.startswith("force:"):
                _, eq, feat = (key.split(":", 2) + ["", ""])[:3]
                if eq not in FORCE_ROWS or feat not in FORCE_FEATURES:
                    raise RandomizationError(f"randomize: {key!r} is not force:EQUATION:FEATURE with EQUATION one of "
                                             f"{', '.join(FORCE_ROWS)} and FEATURE one of {', '.join(FORCE_FEATURES)}")
                bounds = (-math.inf, math.inf)
            elif key.startswith(("vehicle:", "vehicle_scale:")):
                kind, _, param = key.partition(":")
                if param == "Z_f":
                    raise RandomizationError(f"randomize: {key!r}: Z_f follows the statics of the drawn geometry "
                                             "(Z_f' = Z_f Fzf'/Fzf); draw the masses or positions instead")
                if param not in SPECS:
                    raise RandomizationError(f"randomize: unknown vehicle parameter in {key!r}; parameters: "
                                             f"{', '.join(p for p in SPECS if p != 'Z_f')}")
                bounds = _RULE_BOUNDS[SPECS[param].rule] if kind == "vehicle" else (0.0, math.inf)
            elif key.startswith("sensor_bias:"):
                if key[len("sensor_bias:"):] not in CHANNELS:
                    raise RandomizationError(f"randomize: unknown channel in {key!r}; channels: {', '.join(CHANNELS)}")
                bounds = (-math.inf, math.inf)
            else:
                cause, _, param = key.partition(":")
                if cause not in VOCABULARY or param not in VOCABULARY[cause]:
                    raise RandomizationError(
                        f"randomize: unknown key {key!r}; keys are CAUSE:PARAM of effects.md "
                        f"({', '.join(f'{c}:{p}' for c in VOCABULARY for p in VOCABULARY[c])}) or {', '.join(EXTRA_KEYS)}")
                if cause == "sensor_delay":
                    raise RandomizationError("randomize: sensor_delay:delay_s cannot be randomised per episode "
                                             "(it sets the length of the sensors' history); set it in effects=")
                bounds = VOCABULARY[cause][param][2:]
            dists[key] = _parse(key, spec[key], bounds)
        if "tire_stiffness:scale" in dists and any(k in dists for k in ("tire_stiffness:front_scale", "tire_stiffness:rear_scale")):
            raise RandomizationError("randomize: give tire_stiffness:scale or the per-axle scales, not both")
        for key in dists:
            if key.startswith("vehicle:") and "vehicle_scale:" + key[len("vehicle:"):] in dists:
                raise RandomizationError(f"randomize: give {key} or vehicle_scale:{key[len('vehicle:'):]}, not both")
        self.dists: dict[str, Distribution] = dists
        # the keys of each kind of distribution with their numbers, for sample_table
        self._by_kind: dict[str, tuple[np.ndarray, ...]] = {}
        for kind in DISTRIBUTIONS:
            cols = [j for j, d in enumerate(dists.values()) if d.kind == kind]
            if cols:
                ds = [list(dists.values())[j] for j in cols]
                self._by_kind[kind] = (np.array(cols),) + tuple(np.array([getattr(d, f) for d in ds])
                                                                 for f in ("a", "b", "low", "high"))

    @classmethod
    def coerce(cls, spec: "Randomization | Mapping | str | None") -> "Randomization | None":
        """``None``, a :class:`Randomization`, a mapping, or the path of a JSON file holding one (under the key
        ``"randomize"`` or at the top level)."""
        if spec is None or isinstance(spec, Randomization):
            return spec
        if isinstance(spec, str):
            data = _read_json(spec, "randomize")
            if isinstance(data, Mapping) and "randomize" in data:
                data = data["randomize"]
            return cls(data)
        return cls(spec)

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(self.dists)

    @property
    def changes_plant(self) -> bool:
        """True when a key changes the dynamics (one plant per episode, compiled from the draws)."""
        return any(k.partition(":")[0] in DYNAMIC_CAUSES or k.startswith(("force:", "vehicle:", "vehicle_scale:"))
                   for k in self.dists)

    @property
    def vehicle_keys(self) -> tuple[str, ...]:
        """The keys that draw the vehicle's own parameters (``vehicle:`` and ``vehicle_scale:``)."""
        return tuple(k for k in self.dists if k.startswith(("vehicle:", "vehicle_scale:")))

    def vehicle_values(self, vehicle: Any, samples: Mapping[str, Any]) -> dict[str, Any]:
        """Parameter name -> drawn value [SI] of the vehicle keys in ``samples`` (a ``vehicle_scale:`` factor
        times the vehicle's own value)."""
        out = {}
        for k, v in samples.items():
            kind, _, param = k.partition(":")
            if kind in ("vehicle", "vehicle_scale") and getattr(vehicle, "parameters", None) is None:
                raise RandomizationError(f"randomize: {k} draws a physical parameter of the vehicle, but "
                                         f"{vehicle.name} has none (matrix entries only)")
            if kind == "vehicle":
                out[param] = v
            elif kind == "vehicle_scale":
                out[param] = np.asarray(v, dtype=float) * getattr(vehicle.parameters, param)
        return out

    def check_vehicle(self, vehicle: Any, speeds=None) -> float:
        """Check every vehicle the description can draw from ``vehicle`` (module docstring: the corners of
        the supports of the vehicle keys) and return their fastest linearised mode [1/s]
        (:func:`ptw_env.integrate.linear_rate` of the corner vehicles' plants, over the vehicle's range or
        at ``speeds`` [m/s], those a ride meets; 0 without vehicle keys).

        Raises
        ------
        RandomizationError
            Vehicle keys on a vehicle without physical parameters, a factor on a parameter that is 0, an
            unbounded normal, or a corner that is no vehicle (the message names the draw).
        """
        keys = self.vehicle_keys
        if not keys:
            return 0.0
        params = getattr(vehicle, "parameters", None)
        if params is None:
            raise RandomizationError(
                f"randomize: the keys {', '.join(keys)} draw the vehicle's physical parameters, but {vehicle.name} is given "
                "as matrix entries (the reference scooter, model.md): use a vehicle file (ptw_env.vehicle_files, "
                "e.g. 'sharp1971'), or randomise its tire_stiffness, payload and other effects instead")
        E0, A00, A10, _ = table_v(params)
        if not all(np.allclose(m, n, rtol=1e-9, atol=1e-9 * np.abs(n).max()) for m, n in
                   ((E0, vehicle.E), (A00, vehicle.A0), (A10, vehicle.A1))):
            raise RandomizationError(
                f"randomize: {vehicle.name}'s matrices are not those of its physical parameters (edited after it was "
                "built?), so drawing its parameters would discard the edit: build it again with sharp_vehicle")
        ends = []
        for k in keys:
            lo, hi = self.dists[k].support
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise RandomizationError(f"randomize[{k!r}]: a normal on a vehicle parameter needs finite bounds "
                                         f"(\"normal\", mean, std, low, high): every vehicle it can draw is checked")
            if k.startswith("vehicle_scale:") and getattr(params, k.partition(":")[2]) == 0:
                raise RandomizationError(f"randomize: {k}: {vehicle.name}'s {k.partition(':')[2]} is 0, so a factor "
                                         f"changes nothing; draw vehicle:{k.partition(':')[2]} instead")
            ends.append((lo, hi))
        if len(keys) <= MAX_CORNER_KEYS:
            corners = np.array(np.meshgrid(*ends, indexing="ij")).reshape(len(keys), -1)
        else:  # all low, all high, and each key at its other end
            lo, hi = np.array(ends).T
            flips = [np.where(np.arange(len(keys)) == j, hi, lo) for j in range(len(keys))]
            corners = np.array([lo, hi] + flips).T
        samples = dict(zip(keys, corners))
        try:
            model = parameter_batch(params, self.vehicle_values(vehicle, samples))
        except SharpParameterError as exc:
            raise RandomizationError(f"randomize: {', '.join(keys)} can draw a vehicle that is not one (at the "
                                     f"ends of their ranges): {exc}") from None
        return float(np.max(linear_rate(compile_plant(vehicle, model=model), speeds)))

    def forces(self, samples: Mapping[str, Any]) -> list[tuple[str, str, Any]]:
        """The sampled generalised forces ``(equation, feature, coefficient)``."""
        return [tuple(k.split(":", 2)[1:]) + (v,) for k, v in samples.items() if k.startswith("force:")]  # type: ignore[misc]

    def plant(self, vehicle: Any, base: Effects, samples: Mapping[str, Any], effects: Effects | None = None) -> Plant:
        """The episode's plant: ``vehicle`` (with the sampled physical parameters in place of its own, built by
        Table V) with ``base``'s dynamic effects, the sampled effect parameters in their place and the sampled
        generalised forces (arrays of samples: one plant each, a batch). ``effects``: :meth:`effects` of these
        samples when the caller has them already."""
        values = self.vehicle_values(vehicle, samples)
        model = None
        if values:
            try:
                model = parameter_batch(vehicle.parameters, values)
            except SharpParameterError as exc:
                raise RandomizationError(f"randomize: a draw of {', '.join(self.vehicle_keys)} is not a vehicle "
                                         f"(between the corners checked when the environment was made): {exc}") from None
        eff = self.effects(base, samples) if effects is None else effects
        plant = compile_plant(vehicle, eff.dynamic, model=model)
        forces = self.forces(samples)
        return add_generalised_forces(plant, forces) if forces else plant

    def extreme_samples(self) -> dict[str, float]:
        """Each key at the end of its range farthest from 0 (:attr:`Distribution.tails`): where
        :meth:`stiffest_rate` starts (it then moves each key to each of its ends)."""
        out = {}
        for k, d in self.dists.items():
            lo, hi = d.tails
            out[k] = hi if abs(hi) >= abs(lo) else lo
        return out

    def stiffest_rate(self, vehicle: Any, base: Effects, speeds=None) -> float:
        """Fastest rate [1/s] of the plants at the ends of the ranges, which the environment sizes its RK4
        substeps for: :meth:`extreme_samples`, and each key at each end of its support with the others there
        (which end is the stiffer depends on the key: a short relaxation length makes a fast tire lag, a
        large Coulomb friction a fast steer mode). Per plant, the largest ``|eig|`` of the plant linearised at
        the upright (:func:`ptw_env.dynamics.linearise`; Coulomb friction's slope ``Tc / w`` included) at the
        vehicle's lowest, middle and highest speed (or at ``speeds`` [m/s], those a ride meets:
        :func:`ptw_env.integrate.linear_rate`). These are 1 + 2k plants, not every combination of ends:
        two keys whose stiffer ends are both the ends nearer 0 are not combined (the vehicle keys' corners
        are, :meth:`check_vehicle`)."""
        extreme = self.extreme_samples()
        rows = [extreme]
        for k, d in self.dists.items():
            lo, hi = d.tails
            rows += [{**extreme, k: lo}, {**extreme, k: hi}]
        plant = self.plant(vehicle, base, {k: np.array([r[k] for r in rows]) for k in self.dists})
        return float(np.max(linear_rate(plant, speeds)))

    def sample(self, rng: np.random.Generator) -> dict[str, float]:
        """One episode's values: one call ``rng.random(len(keys))``, mapped by each key's inverse transform
        (:meth:`Distribution.from_uniform`) in key order."""
        return {k: float(v[0]) for k, v in self.sample_many([rng]).items()}

    def sample_many(self, rngs: "list[np.random.Generator]") -> dict[str, np.ndarray]:
        """One episode's values for each generator (one env each): key -> array of ``len(rngs)``; exactly
        :meth:`sample` of each generator (columns of :meth:`sample_table`)."""
        table = self.sample_table(rngs)
        return {k: table[:, j] for j, k in enumerate(self.dists)}

    def sample_table(self, rngs: "list[np.random.Generator]") -> np.ndarray:
        """:meth:`sample_many` as one array ``(len(rngs), len(keys))``, columns in key order: the inverse
        transforms (:func:`inverse_transform`) applied to all the keys of a kind at once."""
        return self.from_uniforms(self.uniforms(rngs))

    def uniforms(self, rngs: "list[np.random.Generator]") -> np.ndarray:
        """The draws of :meth:`sample_table` before their inverse transforms: one ``random(number of keys)`` per
        generator, shape ``(len(rngs), len(keys))`` (the vector env draws these at a reset and maps many envs'
        together, :meth:`from_uniforms`)."""
        out = np.empty((len(rngs), len(self.dists)))
        self.uniforms_into(rngs, range(len(rngs)), out)
        return out

    def uniforms_into(self, rngs: "list[np.random.Generator]", rows: "Sequence[int]", out: np.ndarray) -> None:
        """:meth:`uniforms` written into rows ``rows`` of ``out`` (float64, C-contiguous, ``len(keys)`` columns):
        generator ``rngs[j]`` fills ``out[rows[j]]`` (``random(out=...)``: the numbers of ``random(len(keys))``,
        without a temporary array per generator)."""
        if not (isinstance(out, np.ndarray) and out.dtype == np.float64 and out.ndim == 2
                and out.shape[1] == len(self.dists) and out.flags.c_contiguous):
            raise RandomizationError(f"out must be a C-contiguous float64 array of {len(self.dists)} columns, got "
                                     f"{getattr(out, 'dtype', type(out).__name__)} {getattr(out, 'shape', '')}")
        for rng, r in zip(rngs, rows):
            rng.random(out=out[r])

    def from_uniforms(self, u: np.ndarray) -> np.ndarray:
        """The values of :meth:`sample_table` from its uniform draws ``u`` (:meth:`uniforms`), columns in key
        order."""
        out = np.empty_like(u)
        for kind, (cols, a, b, lo, hi) in self._by_kind.items():
            if kind == "choice":
                for j in cols:
                    out[:, j] = self.dists[list(self.dists)[j]].from_uniform(u[:, j])
            else:
                out[:, cols] = inverse_transform(kind, a, b, lo, hi, u[:, cols])
        return out

    def effects(self, base: Effects, samples: Mapping[str, Any]) -> Effects:
        """``base`` with the sampled effect parameters in place of its own (arrays: one vehicle each)."""
        over: dict[str, dict[str, Any]] = {}
        for k, v in samples.items():
            cause, _, param = k.partition(":")
            if k.startswith("force:"):
                continue
            if k == "tire_stiffness:scale":
                over.setdefault("tire_stiffness", {}).update(front_scale=v, rear_scale=v)
            elif cause in VOCABULARY:
                over.setdefault(cause, {})[param] = v
        return base | Effects(over) if over else base

    def sensor_terms(self, samples: Mapping[str, Any]) -> tuple[Any, dict[str, Any]]:
        """``(noise_scale, {channel: extra bias})`` of the sampled sensor keys (1 and {} when none)."""
        scale = samples.get("sensor_noise_scale", 1.0)
        bias = {k[len("sensor_bias:"):]: v for k, v in samples.items() if k.startswith("sensor_bias:")}
        return scale, bias

    @staticmethod
    def env_kwargs(path: str) -> dict[str, Any]:
        """The keyword arguments of :class:`ptw_env.env.PTWRollEnv` (and the vector env) that a digital-twin
        file (``ptw-assist twin``) describes: ``vehicle`` (preset name or vehicle file), ``effects`` (what is
        fixed) and ``randomize`` (what was measured, with its uncertainty)."""
        data = _read_json(path, "twin")
        if not isinstance(data, Mapping) or "randomize" not in data:
            raise RandomizationError(f"twin: {path} has no 'randomize' mapping (not a ptw-assist twin file)")
        out: dict[str, Any] = {"randomize": Randomization(data["randomize"])}
        veh = data.get("vehicle") or {}
        if isinstance(veh, Mapping) and (veh.get("file") or veh.get("name")):
            out["vehicle"] = veh.get("file") or veh.get("name")
        if data.get("effects"):
            out["effects"] = Effects.from_causes(data["effects"])
        return out

    def to_json(self) -> dict[str, Any]:
        """The description as JSON-ready data (``Randomization(r.to_json())`` is ``r`` again)."""
        return {k: d.to_json() for k, d in self.dists.items()}

    def describe(self) -> str:
        return "; ".join(f"{k} ~ {d.to_json()}" for k, d in self.dists.items())

    def __repr__(self) -> str:
        return f"Randomization({self.to_json()!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Randomization) and self.dists == other.dists

    def __hash__(self) -> int:
        return hash(tuple(self.dists.items()))
