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

Every size that has a vehicle's unit is relative to the vehicle
(:func:`param_set`, :class:`VehicleScales`), so that a 37 kg bicycle and a
300 kg scooter are searched over the same *physical* hypotheses:

* ``payload``: fractions of the vehicle's mass ``M`` (-0.4 M to 1.3 M);
* ``roll_moment_offset``: fractions of the gravity roll stiffness ``a51``
  [N m/rad] (row 5 of model.md), i.e. the lean-angle offset the moment holds
  (up to 0.24 rad);
* ``steer_damping``: multiples of the critical damping of the steer about its
  trail stiffness, ``c_crit = 2 sqrt(e66 |a62|)`` [N m s/rad] (0 to 6.1
  c_crit), with the vehicle's own ``-a66`` as the nominal (a vehicle without a
  damper has 0);
* ``relaxation_length``: multiples of the vehicle's own ``sigma`` (nominal),
  0.1 to 7.5 sigma.

For the reference scooter these reproduce the ranges the diagnosis was built
with (payload -121..394 kg, moment +/-403 N m, damping 0-80 N m s/rad,
relaxation 0.02-1.5 m). The dimensionless causes (stiffness scales, friction,
bank, sensor offsets, frame gain, delay) keep their ranges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ptw_env.effects import DYNAMIC_CAUSES, SENSOR_CAUSES, VOCABULARY
from ptw_env.vehicle import DELTA, DELTA_DOT, FYF, FYR, PHI, PHI_DOT, REFERENCE_SCOOTER, Vehicle


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

    def value_std(self, z: float, std_z: float) -> float:
        """Standard deviation of the effects.md value from that of the internal coordinate (first order:
        ``std_z / z^2`` for an inverse coordinate); NaN when it is not finite."""
        if not math.isfinite(std_z):
            return math.nan
        if not self.inverse:
            return float(std_z)
        return float(std_z / z**2) if z > 0 else math.nan

    def report(self, z: float) -> float:
        """The value as written in the report, rounded to :attr:`digits` decimals (``inf`` kept)."""
        v = float(self.value(z))
        return v if not math.isfinite(v) else round(v, self.digits)


@dataclass(frozen=True)
class VehicleScales:
    """The vehicle's own sizes that the diagnosis's hypotheses are expressed in (module docstring).

    Attributes
    ----------
    mass : float
        ``M`` [kg] (model.md ``e33``).
    roll_stiffness : float
        Gravity roll stiffness ``a51`` [N m/rad] (``(M_f j + M_r h) g``, Fouka et al. Table V).
    steer_damping : float
        The vehicle's own steering damping ``-a66`` [N m s/rad] (the nominal of ``steer_damping``).
    steer_critical : float
        ``2 sqrt(e66 |a62|)`` [N m s/rad]: critical damping of the steer about its trail stiffness.
    sigma : float
        Tire relaxation length [m] (``-1/a77`` per unit speed; the shorter axle's).
    """

    mass: float
    roll_stiffness: float
    steer_damping: float
    steer_critical: float
    sigma: float

    @classmethod
    def of(cls, vehicle: Vehicle) -> "VehicleScales":
        """Read the scales off ``vehicle``'s matrices."""
        sigma = float(min(-1.0 / vehicle.A1[FYF, FYF], -1.0 / vehicle.A1[FYR, FYR]))
        c = 2.0 * math.sqrt(float(vehicle.E[DELTA_DOT, DELTA_DOT]) * abs(float(vehicle.A0[DELTA_DOT, DELTA])))
        return cls(float(vehicle.mass), abs(float(vehicle.A0[PHI_DOT, PHI])),
                   float(-vehicle.A0[DELTA_DOT, DELTA_DOT]), c, sigma)


def _spec(cause: str, name: str, lo: float, hi: float, scale: float, digits: int, inverse: bool = False,
          nominal: float | None = None) -> ParamSpec:
    _, _, plo, phi = VOCABULARY[cause][name]
    nom = VOCABULARY[cause][name][0] if nominal is None else nominal
    if not inverse:  # keep the search inside effects.md's physical range
        lo, hi = max(lo, plo), min(hi, phi)
    return ParamSpec(cause, name, 0.0 if inverse else float(nom), lo, hi, scale, digits, inverse)


def _digits(x: float, sig: int = 3) -> int:
    """Decimals that keep ``sig`` significant figures of a typical size ``x``."""
    return max(0, sig - 1 - int(math.floor(math.log10(abs(x))))) if x > 0 else 3


#: Screening grid of each cause in units of its vehicle scale (module docstring): payload in M,
#: roll moment in a51, damping in c_crit, relaxation length in sigma; the others as they are.
_UNIT_GRIDS: dict[str, tuple[tuple[float, ...], ...]] = {
    "tire_stiffness": ((0.5, 0.7, 1.0, 1.4, 2.0),) * 2,
    "tire_saturation": ((0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0),),  # 1/mu_peak
    "road_bank": ((-0.15, -0.08, -0.04, -0.02, 0.02, 0.04, 0.08, 0.15),),
    "roll_moment_offset": ((-0.12, -0.048, -0.018, -0.006, 0.006, 0.018, 0.048, 0.12),),
    "payload": ((-0.26, -0.13, 0.13, 0.26, 0.5, 0.82, 1.3),),
    "steer_damping": ((0.23, 0.46, 0.69, 1.22, 1.68, 2.3, 3.45, 5.36),),
    "relaxation_length": ((0.25, 0.5, 0.7, 1.4, 2.0, 3.0, 4.5, 6.5),),
    "gyro_bias": ((-0.02, 0.0, 0.02),) * 2,
    "ay_frame": ((-1.0, -0.5, -0.25, 0.25, 0.5, 1.0),),
    "sensor_delay": ((0.005, 0.01, 0.02, 0.03, 0.045, 0.06, 0.08, 0.1),),
}


@dataclass(frozen=True)
class ClosureTerm:
    """One term of the model-extension library (diagnose.md ``verdict.extension``), outside effects.md.

    A dynamic term is a generalised force ``c * feature`` added to one equation of model.md
    (:func:`ptw_env.dynamics.add_generalised_forces`); a sensor term changes one measured channel
    (``offset``: ``y + c``; ``scale``: ``y (1 + c)``; ``drift``: ``y + c (t - t_mid) / t_half``, a linear
    drift of the channel's offset about the middle ``t_mid`` of the span the log's replay windows cover,
    ``t_half`` half that span (:attr:`assist.diagnose.data.Windows.t_mid`): ``c`` is how far the offset moves
    from the middle of the log to its end, in the channel's unit, whatever the log's length).
    """

    name: str
    equation: str  #: "steer" | "roll" | "yaw" | "lateral" | "sensor:<channel>"
    feature: str  #: a key of ptw_env.dynamics.FORCE_FEATURES, or "offset" / "scale" / "drift" for a sensor
    term: str  #: the formula, in the state names of model.md
    unit: str  #: unit of the coefficient c


#: The library of closure terms (issue: extend the model beyond the table of effects). Steering:
#: viscous and Coulomb friction, a torque offset, a speed-dependent self-aligning term; roll: a
#: moment offset (rider lean, luggage) and a speed-squared aerodynamic moment; yaw and lateral:
#: aerodynamic moment and force in vx^2 and vx*vy; sensors: offsets, scale factors and the linear drifts of
#: the gyros' and the accelerometer's offsets (a warming MEMS sensor's; delays are effects.md's ``sensor_delay``,
#: constant gyro offsets its ``gyro_bias``).
CLOSURE_LIBRARY: tuple[ClosureTerm, ...] = (
    ClosureTerm("steer_viscous", "steer", "delta_dot", "c * delta_dot", "N m s/rad"),
    ClosureTerm("steer_coulomb", "steer", "tanh(delta_dot/w)", "c * tanh(delta_dot / 0.02)", "N m"),
    ClosureTerm("steer_offset", "steer", "1", "c", "N m"),
    ClosureTerm("steer_self_aligning", "steer", "vx*delta", "c * vx * delta", "N m s/(m rad)"),
    ClosureTerm("roll_offset", "roll", "1", "c", "N m"),
    ClosureTerm("roll_aero", "roll", "vx^2", "c * vx^2", "N m s^2/m^2"),
    ClosureTerm("yaw_aero", "yaw", "vx^2", "c * vx^2", "N m s^2/m^2"),
    ClosureTerm("yaw_vx_vy", "yaw", "vx*vy", "c * vx * vy", "N s^2/m"),
    ClosureTerm("lateral_aero", "lateral", "vx^2", "c * vx^2", "N s^2/m^2"),
    ClosureTerm("lateral_vx_vy", "lateral", "vx*vy", "c * vx * vy", "N s^2/m^2"),
    ClosureTerm("delta_offset", "sensor:delta", "offset", "delta + c", "rad"),
    ClosureTerm("ay_offset", "sensor:ay", "offset", "ay + c", "m/s^2"),
    ClosureTerm("yaw_rate_scale", "sensor:yaw_rate", "scale", "yaw_rate * (1 + c)", "-"),
    ClosureTerm("ay_scale", "sensor:ay", "scale", "ay * (1 + c)", "-"),
    ClosureTerm("yaw_rate_drift", "sensor:yaw_rate", "drift", "yaw_rate + c * (t - t_mid) / t_half", "rad/s"),
    ClosureTerm("roll_rate_drift", "sensor:roll_rate", "drift", "roll_rate + c * (t - t_mid) / t_half", "rad/s"),
    ClosureTerm("ay_drift", "sensor:ay", "drift", "ay + c * (t - t_mid) / t_half", "m/s^2"),
)
CLOSURES: dict[str, ClosureTerm] = {t.name: t for t in CLOSURE_LIBRARY}


def _closure_specs(vehicle: Vehicle, s: "VehicleScales") -> tuple[ParamSpec, ...]:
    """Search ranges of the closure coefficients in the vehicle's units (module docstring): steering
    torques up to 0.1 |a61| x 1 rad, roll and yaw moments up to 0.24 a51 x 1 rad (the roll-moment
    offset's range, also at the top speed for the speed-dependent ones), lateral forces up to
    0.1 M g at the top speed; sensor offsets and drifts in the sensors' own units (no vehicle number): a
    drift up to 0.1 rad/s (gyros) or 1 m/s^2 (accelerometer) from the middle of the log to its end."""
    tq = abs(float(vehicle.A0[DELTA_DOT, PHI]))  # |a61| [N m/rad]
    K, Mg, v, c = s.roll_stiffness, s.mass * 9.81, float(vehicle.vmax), s.steer_critical
    a62 = abs(float(vehicle.A0[DELTA_DOT, DELTA]))
    hi = {
        "steer_viscous": 6.1 * c, "steer_coulomb": 0.1 * tq, "steer_offset": 0.1 * tq,
        "steer_self_aligning": a62 / v, "roll_offset": 0.24 * K, "roll_aero": 0.24 * K / v**2,
        "yaw_aero": 0.24 * K / v**2, "yaw_vx_vy": 0.24 * K / v, "lateral_aero": 0.1 * Mg / v**2,
        "lateral_vx_vy": 0.1 * Mg / v, "delta_offset": 0.05, "ay_offset": 1.0,
        "yaw_rate_scale": 0.3, "ay_scale": 0.3,
        # a drift's change from the middle to the end: a third of gyro_bias's range (its screening grid then
        # starts at gyro_bias's typical size, 0.005 rad/s), ay_offset's range
        "yaw_rate_drift": 0.1, "roll_rate_drift": 0.1, "ay_drift": 1.0,
    }
    out = []
    for t in CLOSURE_LIBRARY:
        h = hi[t.name]
        out.append(ParamSpec(t.name, "c", 0.0, -h, h, h / 20.0, _digits(h / 200.0)))
    return tuple(out)


@dataclass(frozen=True)
class ParamSet:
    """The fitted parameters of one vehicle (:func:`param_set`): specs, bounds, scales and grids."""

    vehicle_scales: VehicleScales
    params: tuple[ParamSpec, ...]
    grids: dict[str, tuple[tuple[float, ...], ...]]

    @property
    def nominal(self) -> np.ndarray:
        return np.array([p.nominal for p in self.params])

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lo for p in self.params])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.hi for p in self.params])

    @property
    def scale(self) -> np.ndarray:
        return np.array([p.scale for p in self.params])

    def to_causes(self, causes: tuple[str, ...], z: np.ndarray) -> list[dict]:
        """The report form ``[{"cause": ..., "params": {...}}]`` of a hypothesis at internal coordinates ``z``."""
        if not causes:
            return [{"cause": "none", "params": {}}]
        return [{"cause": c, "params": {self.params[i].name: self.params[i].report(z[i]) for i in CAUSES[c]}}
                for c in causes]


    def stds(self, causes: tuple[str, ...], z: np.ndarray, std_z: np.ndarray) -> dict[str, dict[str, float | None]]:
        """``{cause: {param: std}}`` in effects.md units (3 significant digits; ``None`` where unknown) for a
        hypothesis at ``z`` whose parameters (in the hypothesis's order) have internal standard deviations
        ``std_z`` (:meth:`assist.diagnose.hypotheses.Fit.std`)."""
        out: dict[str, dict[str, float | None]] = {}
        j = 0
        for c in causes:
            out[c] = {}
            for i in CAUSES[c]:
                v = self.params[i].value_std(float(z[i]), float(std_z[j]) if j < len(std_z) else math.nan)
                out[c][self.params[i].name] = float(f"{v:.3g}") if math.isfinite(v) else None
                j += 1
        return out


def param_set(vehicle: Vehicle) -> ParamSet:
    """Every fitted parameter of ``vehicle``, in the order of the flat parameter vector (module docstring)."""
    s = VehicleScales.of(vehicle)
    M, K, c, sg = s.mass, s.roll_stiffness, s.steer_critical, s.sigma
    params = (
        _spec("tire_stiffness", "front_scale", 0.2, 3.0, 0.1, 3),
        _spec("tire_stiffness", "rear_scale", 0.2, 3.0, 0.1, 3),
        _spec("tire_saturation", "mu_peak", 1e-3, 4.0, 0.3, 3, inverse=True),
        _spec("road_bank", "bank_rad", -0.3, 0.3, 0.01, 4),
        _spec("roll_moment_offset", "moment_nm", -0.24 * K, 0.24 * K, 0.012 * K, _digits(0.012 * K)),
        _spec("payload", "mass_kg", -0.4 * M, 1.3 * M, 0.066 * M, _digits(0.066 * M)),
        _spec("steer_damping", "damping_nms", 0.0, 6.1 * c, 0.15 * c, _digits(0.15 * c), nominal=s.steer_damping),
        _spec("relaxation_length", "sigma_m", 0.1 * sg, 7.5 * sg, 0.25 * sg, _digits(0.25 * sg, 2), nominal=sg),
        _spec("gyro_bias", "yaw_rate_bias", -0.3, 0.3, 0.005, 5),
        _spec("gyro_bias", "roll_rate_bias", -0.3, 0.3, 0.005, 5),
        _spec("ay_frame", "gravity_gain", -1.5, 1.5, 0.05, 3),
        _spec("sensor_delay", "delay_s", 0.0, 0.1, 0.01, 4),
    )
    unit = {"roll_moment_offset": K, "payload": M, "steer_damping": c, "relaxation_length": sg}
    grids = {cause: tuple(tuple(float(unit.get(cause, 1.0) * g) for g in axis) for axis in axes)
             for cause, axes in _UNIT_GRIDS.items()}
    return ParamSet(s, params + _closure_specs(vehicle, s), grids)


#: The reference scooter's parameter set (the defaults of the module-level names below).
REFERENCE = param_set(REFERENCE_SCOOTER)
#: Every fitted parameter of the reference scooter, in the order of the flat parameter vector.
PARAMS: tuple[ParamSpec, ...] = REFERENCE.params
#: Causes in effects.md order (the vocabulary's), each with the indices of its parameters in :data:`PARAMS`
#: (the same for every vehicle).
CAUSES: dict[str, tuple[int, ...]] = {
    c: tuple(i for i, p in enumerate(PARAMS) if p.cause == c) for c in VOCABULARY
}
assert set(CAUSES) == set(DYNAMIC_CAUSES) | set(SENSOR_CAUSES)
#: Index of each closure term's coefficient in the flat parameter vector (after the table's).
CLOSURE_INDEX: dict[str, int] = {p.cause: i for i, p in enumerate(PARAMS) if p.cause in CLOSURES}
#: Number of parameters of the table causes (the closure coefficients follow them).
N_TABLE = min(CLOSURE_INDEX.values())


def cause_indices(cause: str) -> tuple[int, ...]:
    """Indices of a table cause's parameters, or of a closure term's coefficient."""
    return CAUSES[cause] if cause in CAUSES else (CLOSURE_INDEX[cause],)
#: Internal coordinates of the reference scooter's nominal model, and its search bounds and scales.
NOMINAL = REFERENCE.nominal
LOWER = REFERENCE.lower
UPPER = REFERENCE.upper
SCALE = REFERENCE.scale
#: Screening grids of the reference scooter, internal coordinates.
GRIDS = REFERENCE.grids


def to_causes(causes: tuple[str, ...], z: np.ndarray) -> list[dict]:
    """The report form of a hypothesis of the reference scooter (:meth:`ParamSet.to_causes`)."""
    return REFERENCE.to_causes(causes, z)


__all__ = ["ParamSpec", "ParamSet", "VehicleScales", "param_set", "REFERENCE", "PARAMS", "CAUSES", "NOMINAL",
           "LOWER", "UPPER", "SCALE", "GRIDS", "to_causes", "ClosureTerm", "CLOSURE_LIBRARY", "CLOSURES",
           "CLOSURE_INDEX", "N_TABLE", "cause_indices"]
