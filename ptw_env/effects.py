"""The named model effects of ``shared/spec/effects.md``, as data.

An :class:`Effects` object says which effects are switched on and at what
size; the physics that uses them lives in :mod:`ptw_env.dynamics` (dynamic
effects) and :mod:`ptw_env.sensors` (sensor effects). Parameter values may be
numpy arrays: the batched simulator then runs one vehicle per value, which is
what the discrepancy tool uses to fit effect sizes.

Vocabulary (cause -> parameters with their nominal values, effects.md):

=====================  ======================================  ===========
cause                  parameters (unit)                       kind
=====================  ======================================  ===========
tire_stiffness         front_scale, rear_scale (-)             dynamics
tire_saturation        mu_peak (-)                             dynamics
road_bank              bank_rad (rad)                          dynamics
roll_moment_offset     moment_nm (N m)                         dynamics
payload                mass_kg (kg)                            dynamics
steer_damping          damping_nms (N m s/rad)                 dynamics
relaxation_length      sigma_m (m)                             dynamics
gyro_bias              yaw_rate_bias, roll_rate_bias (rad/s)   sensors
ay_frame               gravity_gain (-)                        sensors
sensor_delay           delay_s (s)                             sensors
=====================  ======================================  ===========

Examples
--------
>>> e = Effects.parse(["road_bank:bank_rad=0.05", "tire_stiffness:front_scale=0.7"])
>>> e.value("tire_stiffness", "rear_scale"), e.value("road_bank", "bank_rad")
(1.0, 0.05)
>>> e.to_causes()[0]
{'cause': 'road_bank', 'params': {'bank_rad': 0.05}}
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Iterable, Mapping

import numpy as np


class EffectError(ValueError):
    """An unknown effect, an unknown parameter or a value outside its physical range."""


#: cause -> {parameter: (nominal, unit, lower bound, upper bound)}; bounds inclusive.
#: The nominal values of steer_damping and relaxation_length are the reference
#: scooter's; for another vehicle the nominal is read from its matrices.
VOCABULARY: Mapping[str, Mapping[str, tuple[float, str, float, float]]] = MappingProxyType(
    {
        "tire_stiffness": {"front_scale": (1.0, "-", 0.05, 5.0), "rear_scale": (1.0, "-", 0.05, 5.0)},
        "tire_saturation": {"mu_peak": (math.inf, "-", 0.05, math.inf)},
        "road_bank": {"bank_rad": (0.0, "rad", -0.5, 0.5)},
        "roll_moment_offset": {"moment_nm": (0.0, "N m", -2000.0, 2000.0)},
        "payload": {"mass_kg": (0.0, "kg", -150.0, 500.0)},
        "steer_damping": {"damping_nms": (12.67, "N m s/rad", 0.0, 200.0)},
        "relaxation_length": {"sigma_m": (0.2, "m", 0.01, 2.0)},
        "gyro_bias": {"yaw_rate_bias": (0.0, "rad/s", -1.0, 1.0), "roll_rate_bias": (0.0, "rad/s", -1.0, 1.0)},
        "ay_frame": {"gravity_gain": (0.0, "-", -2.0, 2.0)},
        "sensor_delay": {"delay_s": (0.0, "s", 0.0, 1.0)},
    }
)

DYNAMIC_CAUSES = (
    "tire_stiffness",
    "tire_saturation",
    "road_bank",
    "roll_moment_offset",
    "payload",
    "steer_damping",
    "relaxation_length",
)
SENSOR_CAUSES = ("gyro_bias", "ay_frame", "sensor_delay")

#: Height of the payload point mass above the ground [m] (effects.md, payload).
PAYLOAD_HEIGHT = 0.6


def _check_value(cause: str, param: str, value: Any) -> float | np.ndarray:
    _, unit, lo, hi = VOCABULARY[cause][param]
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise EffectError(f"effect {cause}: parameter {param} must be a number, got {value!r}") from None
    # the smallest and the largest element decide every check (NaN propagates through min and max)
    if arr.size == 0:
        return arr
    mn, mx = (float(arr), float(arr)) if arr.ndim == 0 else (float(arr.min()), float(arr.max()))
    if math.isnan(mn) or math.isnan(mx) or ((math.isinf(mn) or math.isinf(mx)) and not (cause == "tire_saturation")):
        raise EffectError(f"effect {cause}: parameter {param} must be finite, got {value!r}")
    if mn < lo or mx > hi:
        raise EffectError(
            f"effect {cause}: parameter {param} = {value!r} {unit} is outside its physical range [{lo}, {hi}]"
        )
    return float(arr) if arr.ndim == 0 else arr


@dataclass(frozen=True)
class Effects:
    """A set of effects of effects.md with their sizes (immutable).

    Parameters
    ----------
    params : mapping
        ``{cause: {parameter: value}}``. A parameter left out takes its nominal
        value. Values are floats or arrays (one vehicle per element in the
        batched simulator; arrays of different effects must broadcast).
    """

    params: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        clean: dict[str, dict[str, Any]] = {}
        for cause, ps in dict(self.params).items():
            if cause == "none":
                if ps:
                    raise EffectError("effect none takes no parameters")
                continue
            if cause not in VOCABULARY:
                raise EffectError(f"unknown effect {cause!r}; known: none, {', '.join(VOCABULARY)}")
            if not isinstance(ps, Mapping):
                raise EffectError(f"effect {cause}: parameters must be a mapping, got {ps!r}")
            clean[cause] = {}
            for p, v in ps.items():
                if p not in VOCABULARY[cause]:
                    raise EffectError(
                        f"effect {cause}: unknown parameter {p!r}; known: {', '.join(VOCABULARY[cause])}"
                    )
                clean[cause][p] = _check_value(cause, p, v)
        object.__setattr__(self, "params", MappingProxyType({c: MappingProxyType(p) for c, p in clean.items()}))

    # -- construction -------------------------------------------------------
    @classmethod
    def parse(cls, specs: Iterable[str] | str | None) -> "Effects":
        """From command-line strings ``CAUSE:PARAM=VALUE[,PARAM=VALUE...]`` (cli.md)."""
        if specs is None:
            return cls()
        if isinstance(specs, str):
            specs = [specs]
        out: dict[str, dict[str, float]] = {}
        for spec in specs:
            cause, sep, rest = spec.partition(":")
            cause = cause.strip()
            if cause == "none" and not rest.strip():
                continue
            if not sep or not rest.strip():
                raise EffectError(f"effect {spec!r}: expected CAUSE:PARAM=VALUE, e.g. road_bank:bank_rad=0.05")
            out.setdefault(cause, {})
            for item in rest.split(","):
                name, eq, val = item.partition("=")
                if not eq:
                    raise EffectError(f"effect {spec!r}: {item!r} is not PARAM=VALUE")
                from .logs import is_plain_number

                if not is_plain_number(val):
                    raise EffectError(f"effect {spec!r}: value {val!r} of {name.strip()} is not a number (plain ASCII decimal expected)")
                out[cause][name.strip()] = float(val)
        return cls(out)

    @classmethod
    def from_causes(cls, causes: Iterable[Mapping[str, Any]]) -> "Effects":
        """From the report form ``[{"cause": ..., "params": {...}}, ...]`` (diagnose.md)."""
        out: dict[str, dict[str, Any]] = {}
        for c in causes:
            if "cause" not in c:
                raise EffectError(f"cause entry {c!r} has no 'cause' key")
            if c["cause"] == "none":
                continue
            out.setdefault(c["cause"], {}).update(dict(c.get("params", {})))
        return cls(out)

    def to_causes(self) -> list[dict[str, Any]]:
        """The report form; ``[{"cause": "none", "params": {}}]`` when empty."""
        if not self.params:
            return [{"cause": "none", "params": {}}]
        return [
            {"cause": c, "params": {p: (v.tolist() if isinstance(v, np.ndarray) else v) for p, v in ps.items()}}
            for c, ps in self.params.items()
        ]

    @classmethod
    def _checked(cls, params: Mapping[str, Mapping[str, Any]]) -> "Effects":
        """An :class:`Effects` of parameters taken from other :class:`Effects` (already checked: not again)."""
        out = object.__new__(cls)
        object.__setattr__(out, "params", MappingProxyType({c: MappingProxyType(dict(p)) for c, p in params.items()}))
        return out

    def __or__(self, other: "Effects") -> "Effects":
        if not isinstance(other, Effects):
            return NotImplemented
        merged: dict[str, dict[str, Any]] = {c: dict(p) for c, p in self.params.items()}
        for c, p in other.params.items():
            merged.setdefault(c, {}).update(p)
        return Effects._checked(merged)

    # -- queries --------------------------------------------------------------
    def has(self, cause: str) -> bool:
        return cause in self.params

    def value(self, cause: str, param: str, nominal: float | None = None) -> Any:
        """The parameter's value, or its nominal (``nominal`` overrides the table's) when unset."""
        if cause not in VOCABULARY or param not in VOCABULARY[cause]:
            raise EffectError(f"unknown effect parameter {cause}:{param}")
        if cause in self.params and param in self.params[cause]:
            return self.params[cause][param]
        return VOCABULARY[cause][param][0] if nominal is None else nominal

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Broadcast shape of all array-valued parameters (``()`` when all are scalars)."""
        shapes = [np.shape(v) for ps in self.params.values() for v in ps.values()]
        try:
            return tuple(np.broadcast_shapes(*shapes)) if shapes else ()
        except ValueError:
            raise EffectError(f"effect parameter arrays do not broadcast: shapes {shapes}") from None

    @property
    def dynamic(self) -> "Effects":
        """Only the effects that change the vehicle dynamics."""
        return Effects._checked({c: p for c, p in self.params.items() if c in DYNAMIC_CAUSES})

    @property
    def sensor(self) -> "Effects":
        """Only the effects that change the sensor readings."""
        return Effects._checked({c: p for c, p in self.params.items() if c in SENSOR_CAUSES})

    def __bool__(self) -> bool:
        return bool(self.params)

    def __repr__(self) -> str:
        inner = "; ".join(f"{c}: " + ", ".join(f"{p}={v}" for p, v in ps.items()) for c, ps in self.params.items())
        return f"Effects({inner or 'none'})"

    # frozen dataclass with MappingProxyType fields: make pickling explicit
    def __reduce__(self):
        return (Effects, ({c: dict(p) for c, p in self.params.items()},))


def as_effects(effects: "Effects | Mapping | Iterable[str] | str | None") -> Effects:
    """Coerce what a user passes (``None``, an Effects, a dict, CLI strings) into :class:`Effects`."""
    if effects is None:
        return Effects()
    if isinstance(effects, Effects):
        return effects
    if isinstance(effects, Mapping):
        return Effects(effects)
    if isinstance(effects, (str, list, tuple)):
        if isinstance(effects, (list, tuple)) and effects and isinstance(effects[0], Mapping):
            return Effects.from_causes(effects)
        return Effects.parse(effects)
    raise EffectError(f"cannot interpret {effects!r} as effects")
