"""The effect parameters the diagnosis can fit, as one flat vector.

Every cause of ``shared/spec/effects.md`` contributes its parameters; a
hypothesis frees a subset and keeps the others at their nominal values, so
any mixture of hypotheses and candidate sizes is one parameter matrix and
one batched simulation (:class:`assist.diagnose.replay.Replay`).

The fit works in internal coordinates ``z``. All are the effects.md
parameter itself except ``tire_saturation``: ``z = 1 / mu_peak`` (0 =
linear tires, the nominal), so that "no saturation" is an ordinary point
at the edge of the search range (which stops at ``mu_peak = 1000``, no
saturation within any ride, so that a report never holds an infinity).
``lo, hi`` are the search ranges (inside the
physical ranges of :data:`ptw_env.effects.VOCABULARY`; ``sensor_delay`` is
capped by the replay lead); ``scale`` is a typical size, used for
finite-difference steps and for the optimiser's variable scaling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ptw_env.effects import DYNAMIC_CAUSES, SENSOR_CAUSES, VOCABULARY


@dataclass(frozen=True)
class ParamSpec:
    """One fitted parameter: ``cause:name`` of effects.md in internal coordinates (module docstring)."""

    cause: str
    name: str
    nominal: float  #: internal coordinate of the nominal value
    lo: float  #: search range, internal coordinates
    hi: float
    scale: float  #: typical size, internal coordinates
    digits: int  #: decimals kept in the report
    inverse: bool = False  #: internal coordinate is 1/value

    def value(self, z: np.ndarray | float) -> np.ndarray | float:
        """effects.md value from the internal coordinate."""
        if not self.inverse:
            return z
        z = np.asarray(z, dtype=float)
        with np.errstate(divide="ignore"):
            v = np.where(z > 0.0, 1.0 / np.maximum(z, 1e-300), math.inf)
        return float(v) if v.ndim == 0 else v

    def report(self, z: float) -> float:
        """The value as written in the report, rounded to :attr:`digits` decimals (``inf`` kept)."""
        v = float(self.value(z))
        return v if not math.isfinite(v) else round(v, self.digits)


def _spec(cause: str, name: str, lo: float, hi: float, scale: float, digits: int, inverse: bool = False) -> ParamSpec:
    nominal = VOCABULARY[cause][name][0]
    return ParamSpec(cause, name, 0.0 if inverse else float(nominal), lo, hi, scale, digits, inverse)


#: Every fitted parameter, in the order of the flat parameter vector.
PARAMS: tuple[ParamSpec, ...] = (
    _spec("tire_stiffness", "front_scale", 0.2, 3.0, 0.1, 3),
    _spec("tire_stiffness", "rear_scale", 0.2, 3.0, 0.1, 3),
    _spec("tire_saturation", "mu_peak", 1e-3, 4.0, 0.3, 3, inverse=True),
    _spec("road_bank", "bank_rad", -0.3, 0.3, 0.01, 4),
    _spec("roll_moment_offset", "moment_nm", -400.0, 400.0, 20.0, 1),
    _spec("payload", "mass_kg", -120.0, 400.0, 20.0, 1),
    _spec("steer_damping", "damping_nms", 0.0, 80.0, 2.0, 2),
    _spec("relaxation_length", "sigma_m", 0.02, 1.5, 0.05, 3),
    _spec("gyro_bias", "yaw_rate_bias", -0.3, 0.3, 0.005, 5),
    _spec("gyro_bias", "roll_rate_bias", -0.3, 0.3, 0.005, 5),
    _spec("ay_frame", "gravity_gain", -1.5, 1.5, 0.05, 3),
    _spec("sensor_delay", "delay_s", 0.0, 0.1, 0.01, 4),
)
#: Causes in effects.md order (the vocabulary's), each with the indices of its parameters in :data:`PARAMS`.
CAUSES: dict[str, tuple[int, ...]] = {
    c: tuple(i for i, p in enumerate(PARAMS) if p.cause == c) for c in VOCABULARY
}
assert set(CAUSES) == set(DYNAMIC_CAUSES) | set(SENSOR_CAUSES)
#: Internal coordinates of the nominal model.
NOMINAL = np.array([p.nominal for p in PARAMS])
LOWER = np.array([p.lo for p in PARAMS])
UPPER = np.array([p.hi for p in PARAMS])
SCALE = np.array([p.scale for p in PARAMS])


def to_causes(causes: tuple[str, ...], z: np.ndarray) -> list[dict]:
    """The report form ``[{"cause": ..., "params": {...}}]`` of a hypothesis at internal coordinates ``z``."""
    if not causes:
        return [{"cause": "none", "params": {}}]
    return [{"cause": c, "params": {PARAMS[i].name: PARAMS[i].report(z[i]) for i in CAUSES[c]}} for c in causes]


__all__ = ["ParamSpec", "PARAMS", "CAUSES", "NOMINAL", "LOWER", "UPPER", "SCALE", "to_causes"]
