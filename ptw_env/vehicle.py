"""The reference scooter: one definition of the Sharp-type lateral model.

Every part of ptw-assist (environment, observers, controller design,
diagnosis) takes its matrices from a :class:`Vehicle` built here. Nothing
else in the code base writes a matrix entry of the model.

The model (``shared/spec/model.md``, the contract) is

.. math::

    E \\dot x = (A_0 + v_x A_1) x + B \\tau
    \\quad\\text{(+ sine terms in rows 5 and 6)}

with ``x = [phi, delta, vy, r, phi_dot, delta_dot, Fyf, Fyr]`` (rad, rad, m/s,
rad/s, rad/s, rad/s, N, N), the rider steering torque ``tau`` [N m] and the
forward speed ``vx`` [m/s] as a measured, time-varying scheduling parameter.

Provenance of the numbers
-------------------------
All entries are the "Scooter Big Baseline" (BikeSim) of Fouka, Nehaoua,
Arioui, *Motorcycle state estimation and tire cornering stiffness
identification ... using observer based identifiers*, Table IV, as
transcribed in ``model.md``. Three printed entries are resolved there:

* ``a71`` is printed ``-5319 vx``; it is ``+5319 vx`` (a positive front camber
  stiffness reproduces ``a72`` to 0.3 %, a negative one misses by 4.6 %).
* ``a84`` is printed ``79098 vx``; it is ``+79098`` with no ``vx`` factor
  (it is ``C_alpha_r l_r / sigma_r`` like its front twin ``a74``).
* ``a45`` is printed ``-3.665 vx``; it is ``+3.665 vx``: Table V gives
  ``a45 = +(i_fy/R_f + i_ry/R_r) vx`` and ``a54 = -(e35 + i_fy/R_f + i_ry/R_r) vx``,
  so the printed ``a54 = -175.048 vx`` gives ``+3.668``: the wheels' gyroscopic
  roll-yaw coupling is skew-symmetric (``a45 = -(a54 + e35 vx)``). The weave
  is unstable below 9.32 m/s (10.66 m/s with the printed sign).

The yaw-moment arms ``a47 = 0.856`` and ``a48 = -0.624`` are kept as printed
although the slip arms ``a74/a73 = 0.756`` and ``a84/a83 = 0.784`` differ.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

#: Gravity [m/s^2], the value model.md uses for the static loads.
G = 9.81

#: State names in order (model.md), used for logs, reports and labels.
STATE_NAMES: tuple[str, ...] = ("phi", "delta", "vy", "r", "phi_dot", "delta_dot", "Fyf", "Fyr")
#: Units of the states, same order.
STATE_UNITS: tuple[str, ...] = ("rad", "rad", "m/s", "rad/s", "rad/s", "rad/s", "N", "N")

PHI, DELTA, VY, R, PHI_DOT, DELTA_DOT, FYF, FYR = range(8)


def _entries(n: int, spec: Mapping[tuple[int, int], float]) -> np.ndarray:
    """Matrix from 1-based ``(row, col) -> value`` entries (as printed in model.md)."""
    m = np.zeros((n, n))
    for (i, j), v in spec.items():
        m[i - 1, j - 1] = v
    return m


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class TireParameters:
    """Tire data derived from the printed rows 7-8 (model.md, "Derived nominal tire parameters").

    Steady-state lateral force of axle ``k`` (model.md):
    ``F_ss,k = -C_alpha_k alpha_k + C_gamma_k gamma_k`` with
    ``alpha_f = (vy + lf_slip r - eta delta_dot)/vx - delta cos(eps)``,
    ``gamma_f = phi + delta sin(eps)``, ``alpha_r = (vy - lr_slip r)/vx``,
    ``gamma_r = phi``.
    """

    sigma_f: float  #: front relaxation length [m]
    sigma_r: float  #: rear relaxation length [m]
    C_alpha_f0: float  #: front cornering stiffness [N/rad]
    C_gamma_f0: float  #: front camber stiffness [N/rad]
    C_alpha_r0: float  #: rear cornering stiffness [N/rad]
    C_gamma_r0: float  #: rear camber stiffness [N/rad]
    caster: float  #: caster angle eps [rad]
    trail: float  #: mechanical trail eta [m]
    lf_slip: float  #: front slip arm [m]
    lr_slip: float  #: rear slip arm [m]
    Fzf: float  #: static front load [N]
    Fzr: float  #: static rear load [N]


#: The reference scooter's tires, derived from model.md's rows 7-8 (every field is a number of that one vehicle,
#: so none is a default of :class:`TireParameters`).
REFERENCE_TIRES = TireParameters(
    sigma_f=0.2,  # a77 = -vx/sigma_f = -5 vx
    sigma_r=0.2,  # a88 = -5 vx
    C_alpha_f0=22486.0,  # = -a73 sigma_f
    C_gamma_f0=1063.8,  # = a71/vx sigma_f
    C_alpha_r0=20178.0,  # = -a83 sigma_r
    C_gamma_r0=644.36,  # = a81/vx sigma_r
    caster=0.43631,  # = asin(a62/a52) = 25.0 deg
    trail=0.0894,  # = -a67
    lf_slip=0.756,  # = a74/a73
    lr_slip=0.784,  # = a84/a83
    Fzf=303.31 * G * 0.624 / (0.856 + 0.624),  # M g arms from a47, a48 (1254.5)
    Fzr=303.31 * G * 0.856 / (0.856 + 0.624),  # (1721.0)
)


def speed_array(speeds) -> np.ndarray:
    """``speeds`` [m/s] as a flat float array, or one ValueError naming ``speeds``: not numbers, none, or one
    that is not finite. The one check of the ``speeds=`` arguments (:meth:`Vehicle.fastest_rate`,
    :func:`ptw_env.integrate.speed_grid` and what takes speeds through them)."""
    try:
        v = np.atleast_1d(np.asarray(speeds, dtype=float)).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"speeds must be numbers of m/s, got {speeds!r}") from None
    if not v.size or not np.all(np.isfinite(v)):
        raise ValueError(f"speeds must be finite numbers of m/s, at least one, got {speeds!r}")
    return v


#: Speeds over a vehicle's range (ends included) at which its fastest mode is sought (:attr:`Vehicle.fastest_eigenvalue`);
#: a ride's own speeds are searched at the same spacing (:func:`ptw_env.integrate.speed_grid`).
RATE_GRID = 41


@dataclass(frozen=True, eq=False)
class Vehicle:
    """Linear part of a Sharp-type PTW lateral model, ``E x' = (A0 + vx A1) x + B tau``.

    Attributes
    ----------
    name : str
        Identifier used in logs and reports.
    E, A0, A1 : ndarray, shape (8, 8)
        Mass matrix and the speed-independent / speed-proportional parts of the
        state matrix (model.md). ``A0`` holds the *linear* gravity and trail
        entries a51, a52, a61, a62; the nonlinear plant replaces them by sines
        (:mod:`ptw_env.dynamics`).
    B : ndarray, shape (8,)
        Input vector (the torque enters row 6, the steering equation).
    mass : float
        Total mass M [kg] (e33), used for ``ay = (Fyf + Fyr)/M``.
    tires : TireParameters
        Derived tire data.
    vmin, vmax : float
        Valid forward-speed range [m/s] of the model (the environment ends an
        episode outside it). Required: a speed range is a number of one vehicle
        (the reference scooter's 3-40 m/s is model.md's), never a default.
    provenance : Mapping[str, str]
        Where each group of numbers comes from.
    steer_lock : float
        Largest steer angle |delta| [rad] the vehicle's steering stops allow, in
        ``(0, pi/2]``; a ride log steering beyond it is refused
        (:func:`ptw_env.logs.check_against_vehicle`). Default ``pi/2``: the geometric
        bound of any front wheel (beyond it the wheel would face backwards), not a
        number of any vehicle; a vehicle file gives its own in ``[limits] steer_lock``.
        Not part of the model (it changes no equation) nor of :meth:`identity`'s hash.
    design_range : tuple of float or None
        ``(vmin, vmax)`` [m/s] over which speed-scheduled designs (the TS
        controller's premise box, the HOSM structural analysis) are made by
        default: one common Lyapunov matrix rarely covers the whole valid range
        (the slow, unstable end is the hard one). ``None``: the valid range.
        The reference scooter's is 8-33 m/s (the controller issue's wide range);
        a vehicle file gives its own in ``[speed_range] design_vmin, design_vmax``.
        Not part of :meth:`identity`'s hash. See :attr:`control_range`.
    parameters : ptw_env.sharp.SharpParameters or None
        The physical parameters the matrices were built from (:func:`ptw_env.sharp.sharp_vehicle`), or
        ``None`` for a vehicle given as matrix entries (the reference scooter, model.md). Domain
        randomisation of a vehicle's masses, geometry and inertias (``randomize={"vehicle:M_r": ...}``)
        needs them. Not part of :meth:`identity`'s hash (the matrices are).
    """

    name: str
    E: np.ndarray
    A0: np.ndarray
    A1: np.ndarray
    B: np.ndarray
    mass: float
    tires: TireParameters
    vmin: float
    vmax: float
    provenance: Mapping[str, str] = field(default_factory=dict)
    steer_lock: float = math.pi / 2
    design_range: tuple[float, float] | None = None
    parameters: Any = None

    def __post_init__(self) -> None:
        for nm, shape in (("E", (8, 8)), ("A0", (8, 8)), ("A1", (8, 8)), ("B", (8,))):
            a = np.asarray(getattr(self, nm), dtype=float)
            if a.shape != shape:
                raise ValueError(f"Vehicle.{nm} must have shape {shape}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"Vehicle.{nm} has a non-finite entry")
            object.__setattr__(self, nm, _frozen(a))
        if not (0 < self.vmin < self.vmax):
            raise ValueError(f"Vehicle speed range must satisfy 0 < vmin < vmax, got [{self.vmin}, {self.vmax}]")
        if not (isinstance(self.steer_lock, (int, float)) and 0 < self.steer_lock <= math.pi / 2):
            raise ValueError(f"Vehicle.steer_lock must be an angle in (0, pi/2] rad, got {self.steer_lock!r}")
        if self.design_range is not None:
            lo, hi = (float(x) for x in self.design_range)
            if not (self.vmin <= lo < hi <= self.vmax):
                raise ValueError(f"Vehicle.design_range must satisfy vmin <= lo < hi <= vmax = [{self.vmin}, "
                                 f"{self.vmax}] m/s, got {self.design_range!r}")
            object.__setattr__(self, "design_range", (lo, hi))
        if np.linalg.cond(self.E) > 1e10:
            raise ValueError("Vehicle.E is singular (or nearly): the mass matrix must be invertible")
        object.__setattr__(self, "provenance", MappingProxyType(dict(self.provenance)))

    def __reduce__(self):
        # MappingProxyType does not pickle: rebuild from the fields
        return (
            Vehicle,
            (self.name, self.E, self.A0, self.A1, self.B, self.mass, self.tires, self.vmin, self.vmax,
             dict(self.provenance), self.steer_lock, self.design_range, self.parameters),
        )

    @property
    def control_range(self) -> tuple[float, float]:
        """Default speed range [m/s] of speed-scheduled designs: :attr:`design_range`, else ``(vmin, vmax)``."""
        return self.design_range if self.design_range is not None else (float(self.vmin), float(self.vmax))

    @functools.cached_property
    def fastest_eigenvalue(self) -> float:
        """``max |eig(E^-1 A(vx))|`` [1/s] over the speed range (:data:`RATE_GRID` speeds, ends included): the
        stiffest mode of the linearised vehicle, which sets the integration step
        (:func:`ptw_env.integrate.substeps_for`). Reference scooter: 186 at 40 m/s (the front tire lag,
        ~vx/sigma); robot bicycle: ~100 at every speed (its lateral-tire oscillation)."""
        return self.fastest_rate(self.rate_speeds())

    def rate_speeds(self) -> np.ndarray:
        """The :data:`RATE_GRID` speeds [m/s] from ``vmin`` to ``vmax`` at which the fastest mode over the
        range is sought (:attr:`fastest_eigenvalue`; the diagnosis's replay sizes its step on the same grid)."""
        return np.linspace(self.vmin, self.vmax, RATE_GRID)

    def mode_rates(self, speeds) -> np.ndarray:
        """``max |eig(E^-1 A(vx))|`` [1/s] at each of the given speeds [m/s]: the stiffest mode of the
        linearised vehicle there (the one definition; :meth:`fastest_rate` is its maximum)."""
        return np.array([np.abs(np.linalg.eigvals(self.state_matrix(float(x)))).max() for x in speed_array(speeds)])

    def fastest_rate(self, speeds) -> float:
        """``max |eig(E^-1 A(vx))|`` [1/s] over the given speeds [m/s]: the stiffest mode met at those
        speeds (:attr:`fastest_eigenvalue` is this over the whole range; an environment sizes its step
        for the speeds its rides reach, :func:`ptw_env.integrate.speed_grid`)."""
        return float(self.mode_rates(speeds).max())

    @property
    def steer_torque_scale(self) -> float:
        """``|a61|`` [N m/rad]: the steering torque that gravity and trail put on the steer at one
        radian of lean (Fouka et al. Table V: ``a61 = M_f e g - eta Z_f``), the vehicle's own unit of
        steering torque (164.3 N m/rad for the reference scooter, 8.7 for the robot bicycle)."""
        return abs(float(self.A0[DELTA_DOT, PHI]))

    @property
    def torque_ratio(self) -> float:
        """:attr:`steer_torque_scale` relative to the reference scooter's (exactly 1 for it): the
        factor that carries a torque chosen on the scooter (a rider's torque range, noise, the
        environment's actuator limit) to this vehicle."""
        return self.steer_torque_scale / REFERENCE_SCOOTER.steer_torque_scale

    def identity(self) -> dict[str, str]:
        """Which vehicle this is, for reports (cli.md: "its --json says which vehicle ran").

        ``name``; ``model_sha256``: SHA-256 of the model itself (E, A0, A1, B, mass, tire
        parameters, speed range; the same numbers give the same hash whatever file they came
        from); and, for a vehicle loaded from a parameter file, ``file`` and ``file_sha256``
        (SHA-256 of the file's bytes).
        """
        h = hashlib.sha256()
        for m in (self.E, self.A0, self.A1, self.B):
            h.update(np.ascontiguousarray(m, dtype=np.float64).tobytes())
        h.update(repr((float(self.mass), self.tires, float(self.vmin), float(self.vmax))).encode())
        out = {"name": self.name, "model_sha256": h.hexdigest()}
        f = self.provenance.get("file")
        if f:
            out["file"] = str(f)
            try:
                out["file_sha256"] = hashlib.sha256(Path(f).read_bytes()).hexdigest()
            except OSError:
                pass
        return out

    # -- the linear model -------------------------------------------------
    def A(self, vx: float) -> np.ndarray:
        """``A(vx) = A0 + vx A1`` (8 x 8)."""
        return self.A0 + float(vx) * self.A1

    def state_matrix(self, vx: float) -> np.ndarray:
        """``E^-1 A(vx)``: the state matrix of the model linearised at the upright (phi = 0)."""
        return np.linalg.solve(self.E, self.A(vx))

    def input_matrix(self) -> np.ndarray:
        """``E^-1 B`` as an (8, 1) column."""
        return np.linalg.solve(self.E, self.B)[:, None]

    @property
    def gravity(self) -> np.ndarray:
        """The gravity/trail coefficients ``[[a51, a52], [a61, a62]]`` that carry sines in the plant."""
        return self.A0[4:6, 0:2].copy()

    def ay_row(self) -> np.ndarray:
        """Output row of the lateral acceleration ``ay = (Fyf + Fyr)/M`` [m/s^2] (model.md)."""
        c = np.zeros(8)
        c[FYF] = c[FYR] = 1.0 / self.mass
        return c


_E = _entries(
    8,
    {
        (1, 1): 1.0, (2, 2): 1.0, (7, 7): 1.0, (8, 8): 1.0,
        (3, 3): 303.31, (3, 4): 6.32, (3, 5): 171.38, (3, 6): 0.187,
        (4, 4): 34.73, (4, 5): 1.97, (4, 6): 0.66,
        (5, 5): 118.02, (5, 6): 0.383,
        (6, 6): 0.614,
    },
)
# symmetric mass block on [vy, r, phi_dot, delta_dot]
_E = np.triu(_E) + np.triu(_E, 1).T

_A0 = _entries(
    8,
    {
        (1, 5): 1.0,
        (2, 6): 1.0,
        (3, 7): 1.0, (3, 8): 1.0,
        (4, 7): 0.856, (4, 8): -0.624,
        (5, 1): 1681.0, (5, 2): 164.34,
        (6, 1): 164.34, (6, 2): 69.45, (6, 6): -12.67, (6, 7): -0.0894,
        (7, 3): -112430.0, (7, 4): -84997.0, (7, 6): 10051.0,
        (8, 3): -100890.0, (8, 4): 79098.0,  # a84: resolved misprint (no vx factor)
    },
)

_A1 = _entries(
    8,
    {
        (3, 4): -303.31,
        (4, 4): -6.319, (4, 5): 3.665, (4, 6): 0.682,  # a45: resolved misprint (printed -3.665 vx)
        (5, 4): -175.048, (5, 6): -1.4622,
        (6, 4): -0.8685, (6, 5): 1.47,
        (7, 1): 5319.0,  # a71: resolved misprint (printed -5319 vx)
        (7, 2): 104503.0, (7, 7): -5.0,
        (8, 1): 3221.8, (8, 8): -5.0,
    },
)

_B = np.zeros(8)
_B[DELTA_DOT] = 1.0


def reference_scooter() -> Vehicle:
    """The reference scooter of ``shared/spec/model.md`` (BikeSim "Scooter Big Baseline").

    Examples
    --------
    >>> v = reference_scooter()
    >>> round(v.mass, 2), v.E.shape
    (303.31, (8, 8))
    """
    return Vehicle(
        name="reference-scooter",
        E=_E,
        A0=_A0,
        A1=_A1,
        B=_B,
        mass=303.31,
        tires=REFERENCE_TIRES,
        vmin=3.0,
        vmax=40.0,
        design_range=(8.0, 33.0),
        provenance={
            "E, A0, A1, B": "Fouka, Nehaoua, Arioui, Table IV (BikeSim Scooter Big Baseline), as in shared/spec/model.md",
            "a71": "printed -5319 vx, taken +5319 vx (model.md: positive camber stiffness reproduces a72 to 0.3 %)",
            "a84": "printed 79098 vx, taken +79098 (model.md: C_alpha_r l_r / sigma_r, like a74)",
            "a45": "printed -3.665 vx, taken +3.665 vx (model.md: Table V's +(i_fy/R_f + i_ry/R_r) vx; a54 + e35 vx = -3.668 vx, so the gyroscopic coupling is skew)",
            "tires": "derived from rows 7-8 with sigma = 0.2 m (model.md, derived nominal tire parameters)",
            "Fzf, Fzr": "M g arms from a47, a48 (model.md)",
            "vmin, vmax": "ptw-assist choice: 3-40 m/s (the tire modes reach |lambda| ~ 200 rad/s at 40 m/s)",
            "design_range": "8-33 m/s, the wide range of the TS controller issue (10-20 m/s in Dabladji et al.)",
        },
    )


REFERENCE_SCOOTER = reference_scooter()
