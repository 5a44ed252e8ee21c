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
* ``"sensor_noise_scale"``: a factor on every channel's noise standard deviation.
* ``"sensor_bias:CHANNEL"``: an offset [channel unit] added to that channel's bias
  (:data:`ptw_env.sensors.CHANNELS`).

Distributions: a number (fixed), ``("uniform", low, high)``, ``("loguniform", low, high)``,
``("normal", mean, std)`` or ``("normal", mean, std, low, high)`` (clipped to ``[low, high]``; ``None`` for
the physical bound), or
``("choice", [v1, v2, ...])``; also as JSON lists or ``{"dist": "uniform", "low": ..., "high": ...}``.
An effect parameter's draws must lie in its physical range of effects.md: a uniform range outside it is
an error, a normal's tails are clipped to it (stated in :attr:`Randomization.describe`).

Draws come from the environment's own generator, one call of ``random(number of keys)`` mapped through
each key's inverse distribution function in the sorted order of the keys, before the starting
roll angle and the sensor noise, so ``reset(seed=s)`` gives the same vehicle, road and readings in the
single environment and in env ``i`` of the vector environment seeded ``s - i``.

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
from typing import Any, Mapping

import numpy as np
from scipy.special import ndtri

from .dynamics import FORCE_FEATURES, FORCE_ROWS, Plant, add_generalised_forces, compile_plant
from .effects import DYNAMIC_CAUSES, VOCABULARY, Effects
from .sensors import CHANNELS

DISTRIBUTIONS = ("fixed", "uniform", "loguniform", "normal", "choice")
#: keys besides "CAUSE:PARAM"
EXTRA_KEYS = (("tire_stiffness:scale", "sensor_noise_scale", "force:EQUATION:FEATURE")
              + tuple(f"sensor_bias:{c}" for c in CHANNELS))


class RandomizationError(ValueError):
    """A bad ``randomize=`` description (names the key and the value)."""


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
        """Draws by inverse transform of uniform numbers ``u`` in [0, 1) (any shape): ``low + (high - low) u``,
        ``exp`` of that in log space, ``mean + std Phi^-1(u)`` clipped, or ``values[floor(n u)]``."""
        u = np.asarray(u, dtype=float)
        if self.kind == "fixed":
            return np.full(u.shape, self.a)
        if self.kind == "uniform":
            return self.a + (self.b - self.a) * u
        if self.kind == "loguniform":
            return np.exp(math.log(self.a) + (math.log(self.b) - math.log(self.a)) * u)
        if self.kind == "normal":
            z = ndtri(np.clip(u, 1e-300, None))  # u = 0 would be -inf
            return np.clip(self.a + self.b * z, self.low, self.high)
        return np.asarray(self.values)[np.minimum((u * len(self.values)).astype(np.int64), len(self.values) - 1)]

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
        self.dists: dict[str, Distribution] = dists

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
        """True when a key changes the dynamics (the plant is compiled again at each reset)."""
        return any(k.partition(":")[0] in DYNAMIC_CAUSES or k.startswith("force:") for k in self.dists)

    def forces(self, samples: Mapping[str, Any]) -> list[tuple[str, str, Any]]:
        """The sampled generalised forces ``(equation, feature, coefficient)``."""
        return [tuple(k.split(":", 2)[1:]) + (v,) for k, v in samples.items() if k.startswith("force:")]  # type: ignore[misc]

    def plant(self, vehicle: Any, base: Effects, samples: Mapping[str, Any]) -> Plant:
        """The episode's plant: ``vehicle`` with ``base``'s dynamic effects, the sampled effect parameters in
        their place and the sampled generalised forces (arrays of samples: one plant each, a batch)."""
        plant = compile_plant(vehicle, self.effects(base, samples).dynamic)
        forces = self.forces(samples)
        return add_generalised_forces(plant, forces) if forces else plant

    def extreme_samples(self) -> dict[str, float]:
        """Each key at the end of its support farthest from 0 (a normal's unclipped tail at 5 standard
        deviations): the stiffest model it draws, which the environment sizes its RK4 substeps for (e.g.
        a Coulomb-friction force)."""
        out = {}
        for k, d in self.dists.items():
            lo, hi = d.support
            if d.kind == "normal":  # an unclipped tail: 5 standard deviations
                lo, hi = max(lo, d.a - 5.0 * d.b), min(hi, d.a + 5.0 * d.b)
            out[k] = hi if abs(hi) >= abs(lo) else lo
        return out

    def sample(self, rng: np.random.Generator) -> dict[str, float]:
        """One episode's values: one call ``rng.random(len(keys))``, mapped by each key's inverse transform
        (:meth:`Distribution.from_uniform`) in key order."""
        return {k: float(v[0]) for k, v in self.sample_many([rng]).items()}

    def sample_many(self, rngs: "list[np.random.Generator]") -> dict[str, np.ndarray]:
        """One episode's values for each generator (one env each): key -> array of ``len(rngs)``; exactly
        :meth:`sample` of each generator."""
        u = np.array([rng.random(len(self.dists)) for rng in rngs]).reshape(len(rngs), len(self.dists))
        return {k: d.from_uniform(u[:, j]) for j, (k, d) in enumerate(self.dists.items())}

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
