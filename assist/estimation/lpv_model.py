"""LPV form of the reference scooter with the tire stiffnesses as unknown parameters.

Fouka, Nehaoua, Arioui [1]_, eqs. (6)-(10), (14)-(15), (35)-(36), built from
one :class:`~ptw_env.vehicle.Vehicle` (nothing here writes a model entry):

.. math::

    \\dot x = A(v_x)\\,x + B\\tau + \\varphi(x) + D\\,\\chi(x, v_x)\\,\\Theta,
    \\qquad y = C x,

* ``A(vx) = E^-1 (A0 + vx A1)`` and ``B = E^-1 B`` are the *nominal* printed
  matrices (model.md), tire rows included;
* ``phi(x)`` holds the sine terms of the nonlinear plant that the paper's
  linear model drops: ``E^-1 [0; 0; 0; 0; a51 (sin phi - phi) + a52 (sin
  delta - delta); a61 (...) + a62 (...); 0; 0]`` (model.md, "The nonlinear
  plant"). The runtime observer uses the plant's own right-hand side
  (:meth:`ptw_env.dynamics.Plant.rhs`), so ``phi`` is never written out; it
  enters the design only through its Lipschitz bound
  (:func:`nonlinearity_vertices`);
* ``D = E^-1 [0_{6x2}; I_2]`` ([1]_ eq. 9; equals ``[0; I_2]`` because ``E``
  is the identity on the tire rows);
* ``Theta = [C_alpha_f - C_alpha_f0, C_gamma_f - C_gamma_f0, C_alpha_r -
  C_alpha_r0, C_gamma_r - C_gamma_r0]`` [N/rad] ([1]_ eq. 8) and

  .. math::

      \\chi = \\begin{bmatrix} -v_x\\alpha_f/\\sigma_f & v_x\\gamma_f/\\sigma_f & 0 & 0 \\\\
                               0 & 0 & -v_x\\alpha_r/\\sigma_r & v_x\\gamma_r/\\sigma_r
              \\end{bmatrix}

  with ``alpha_f = (vy + lf r - eta delta_dot)/vx - delta cos(eps)``,
  ``gamma_f = phi + delta sin(eps)``, ``alpha_r = (vy - lr r)/vx``,
  ``gamma_r = phi`` (model.md; [1]_ eq. 5 with the trail term that Table V's
  ``a76`` carries).

Corrections and choices (recorded here, tested in ``tests/test_lpv_model.py``)
-----------------------------------------------------------------------------
* **chi is read off the printed rows 7-8**, not re-derived from the formula:
  every ``x``-coefficient of ``chi_j`` is the printed entry divided by the
  nominal stiffness that carries it, so ``chi(x, vx) Theta_0`` reproduces the
  printed rows *exactly* (``Theta_0 = [C_alpha_f0, ...]``). The one mixed
  entry, ``a72 = (C_alpha_f cos eps + C_gamma_f sin eps) vx / sigma_f``, is
  printed 0.34 % above the formula (model.md: 104503 vs 104145); it is split in
  the formula's proportion ``C_alpha_f0 cos eps : C_gamma_f0 sin eps`` and both
  parts carry the factor ``kappa = 104503/104145``. Consequence: a plant with
  ``tire_stiffness`` scales ``(s_f, s_r)`` (effects.md: the printed rows
  scaled) is *exactly* ``Theta = ((s_f - 1) C_alpha_f0, (s_f - 1) C_gamma_f0,
  (s_r - 1) C_alpha_r0, (s_r - 1) C_gamma_r0)``, so the truth of a simulated
  log is ``C = s C_0`` with no 0.4 % caveat. (Referenced to the formula
  instead, a front scale ``s`` would look like ``C_gamma_f`` off by
  ``(s - 1) 358 sigma_f / sin(eps)`` ~ 16 % of ``C_gamma_f0`` at ``s = 0.6``.)
* [1]_ eq. (1), row 3 prints ``e35 phi + e36 delta``; it is ``e35 phi'' +
  e36 delta''`` (the mass matrix multiplies accelerations; eq. 2).
* Virtual sensor ([1]_ eqs. 14-15): ``y_a = w^T E x' - w^T A~ x`` with the row
  combination ``w = e34 row3 - e33 row4`` that cancels ``vy'``. It equals
  ``(Mf k - M lf) Fyf + (Mf k + M lr) Fyr`` = ``(e34 - e33 a47) Fyf + (e34 -
  e33 a48) Fyr`` (-253.3 Fyf + 195.6 Fyr [kg m]) and is computable from the
  derivatives of the measured ``r, phi_dot, delta_dot``
  (:meth:`LPVModel.virtual_sensor_coefficients`). Its sign convention follows
  Table V's ``c67 = Mf k - M lf``, ``c68 = Mf k + M lr``.
* [1]_ sec. III-A says the measured set is "not observable/detectable". For
  the reference scooter the pair ``(A(vx), C)`` with
  ``y = [delta, r, phi_dot, delta_dot, ay]`` is observable at every speed of
  3-40 m/s (:func:`observability_table`, PBH test in scaled coordinates). What
  fails without the virtual sensor is the *identifiability* condition of the
  adaptive law: ``rank(C D) = 1 < rank(D) = 2`` (only ``Fyf + Fyr`` is
  measured), so ``D^T P = T C`` has no solution with ``P > 0``; with ``y_a``
  ``rank(C D) = 2``. Both ranks are reported.

Polytopic form ([1]_ eqs. 35-36)
--------------------------------
``A(vx)`` is affine in ``vx``, so on ``vx in [vmin, vmax]``
``A(vx) = eta_1(vx) A(vmin) + eta_2(vx) A(vmax)`` exactly, with the sector
weights ``eta_1 = (vmax - vx)/(vmax - vmin)``, ``eta_2 = 1 - eta_1``
(``vx`` clipped to the range first); ``r = 2`` vertices.

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers" (text in ``shared/papers/000_348caefc9b08ee38.txt``).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import numbers
from dataclasses import dataclass

import numpy as np
from numba import njit

from ptw_env.vehicle import (
    DELTA,
    DELTA_DOT,
    FYF,
    FYR,
    PHI,
    PHI_DOT,
    R,
    REFERENCE_SCOOTER,
    STATE_NAMES,
    VY,
    Vehicle,
)

#: Names of the unknown parameters, the order of ``Theta`` [N/rad].
THETA_NAMES: tuple[str, ...] = ("C_alpha_f", "C_gamma_f", "C_alpha_r", "C_gamma_r")
#: Physical outputs of the adaptive observer (log columns of logs.md), the order of ``y``.
OUTPUT_NAMES: tuple[str, ...] = ("delta", "yaw_rate", "roll_rate", "delta_rate", "ay")
#: Units of :data:`OUTPUT_NAMES`.
OUTPUT_UNITS: tuple[str, ...] = ("rad", "rad/s", "rad/s", "rad/s", "m/s^2")
#: Name of the virtual sensor appended as the sixth output ([1]_ eq. 15).
VIRTUAL_NAME = "y_a"
#: States whose derivatives the virtual sensor needs (all three measured).
VIRTUAL_STATES: tuple[int, ...] = (R, PHI_DOT, DELTA_DOT)
#: Roll bound of the Lipschitz box [rad] (model.md: the model is valid to 45 deg).
PHI_MAX = math.pi / 4
#: Steering bound of the Lipschitz box [rad] (steering angles are a few degrees; 20 deg is generous).
DELTA_MAX = math.radians(20.0)


class LPVModelError(ValueError):
    """A speed range, a parameter band or a state/speed array that the LPV model cannot take."""


@dataclass(frozen=True, eq=False)
class LPVModel:
    """The LPV model ``x' = A(vx) x + B tau + phi(x) + D chi(x, vx) Theta``, ``y = C x`` (module docstring).

    Build it with :func:`build_lpv_model`.

    Attributes
    ----------
    vehicle : Vehicle
        Source of every matrix entry.
    A0, A1 : ndarray, shape (8, 8)
        ``E^-1 A0`` and ``E^-1 A1``: ``A(vx) = A0 + vx A1`` (nominal tires, linear gravity terms).
    B : ndarray, shape (8,)
        ``E^-1 B`` [per N m].
    D : ndarray, shape (8, 2)
        ``E^-1 [0; I_2]``.
    N : ndarray, shape (8, 4)
        Where the nonlinearity enters: ``[D, E^-1 e5, E^-1 e6]`` (the tire rows and the
        roll and steer equations, whose sine terms the linear model drops).
    C : ndarray, shape (5, 8)
        Physical outputs ``[delta, r, phi_dot, delta_dot, ay]``.
    c_virtual : ndarray, shape (8,)
        Row of the virtual sensor ``y_a = c67 Fyf + c68 Fyr`` [kg m].
    H0, H1 : ndarray, shape (4, 8)
        ``chi_j(x, vx) = (H0[j] + vx H1[j]) . x`` is the non-zero entry of column
        ``j`` of ``chi`` (row ``j // 2``) [1/s per N/rad of ``Theta_j``].
    theta0 : ndarray, shape (4,)
        Nominal stiffnesses ``[C_alpha_f0, C_gamma_f0, C_alpha_r0, C_gamma_r0]`` [N/rad].
    gravity : ndarray, shape (2, 2)
        ``[[a51, a52], [a61, a62]]`` (the sine-carrying coefficients).
    kappa : float
        Printed/formula ratio of ``a72`` (module docstring).
    vmin, vmax : float
        Scheduling range [m/s].
    """

    vehicle: Vehicle
    A0: np.ndarray
    A1: np.ndarray
    B: np.ndarray
    D: np.ndarray
    N: np.ndarray
    C: np.ndarray
    c_virtual: np.ndarray
    H0: np.ndarray
    H1: np.ndarray
    theta0: np.ndarray
    gravity: np.ndarray
    kappa: float
    vmin: float
    vmax: float

    # ---------------------------------------------------------------- linear part
    def A(self, vx: float) -> np.ndarray:
        """``A(vx) = E^-1 (A0 + vx A1)`` (8 x 8) at ``vx`` [m/s] (not clipped)."""
        return self.A0 + float(vx) * self.A1

    @property
    def vertices(self) -> np.ndarray:
        """Vertex matrices ``A_1 = A(vmin)``, ``A_2 = A(vmax)``, shape (2, 8, 8) ([1]_ eq. 36)."""
        return np.stack([self.A(self.vmin), self.A(self.vmax)])

    def weights(self, vx: np.ndarray | float) -> np.ndarray:
        """Sector weights ``eta_i(vx)``, shape ``shape(vx) + (2,)``: ``eta_1 = (vmax - vx)/(vmax - vmin)``,
        ``eta_2 = 1 - eta_1``, with ``vx`` clipped to ``[vmin, vmax]`` ([1]_ eq. 35). They sum to 1."""
        v = np.clip(np.asarray(vx, dtype=float), self.vmin, self.vmax)
        e1 = (self.vmax - v) / (self.vmax - self.vmin)
        return np.stack([e1, 1.0 - e1], axis=-1)

    def C_aug(self) -> np.ndarray:
        """``[C; c_virtual]`` (6 x 8): the outputs with the virtual sensor."""
        return np.vstack([self.C, self.c_virtual])

    # ---------------------------------------------------------------- regressor
    def chi(self, x: np.ndarray, vx: np.ndarray | float) -> np.ndarray:
        """The regressor ``chi(x, vx)``, shape ``broadcast(x[..., 0], vx) + (2, 4)`` [1/s, per N/rad]."""
        x = np.asarray(x, dtype=float)
        if x.shape[-1:] != (8,):
            raise LPVModelError(f"x must have a trailing axis of length 8 (the states), got shape {x.shape}")
        vx = np.asarray(vx, dtype=float)
        c = x @ self.H0.T + vx[..., None] * (x @ self.H1.T)  # (..., 4)
        out = np.zeros(c.shape[:-1] + (2, 4))
        out[..., 0, 0:2] = c[..., 0:2]
        out[..., 1, 2:4] = c[..., 2:4]
        return out

    def regressor(self, x: np.ndarray, vx: np.ndarray | float) -> np.ndarray:
        """The four non-zero entries of ``chi`` (``chi[0, 0], chi[0, 1], chi[1, 2], chi[1, 3]``), shape (..., 4)."""
        x = np.asarray(x, dtype=float)
        vx = np.asarray(vx, dtype=float)
        return x @ self.H0.T + vx[..., None] * (x @ self.H1.T)

    def parameter_term(self, x: np.ndarray, vx: np.ndarray | float, theta: np.ndarray) -> np.ndarray:
        """``D chi(x, vx) Theta``, shape (..., 8)."""
        c = self.regressor(x, vx) * np.asarray(theta, dtype=float)
        out = np.zeros(c.shape[:-1] + (8,))
        out[..., FYF] = c[..., 0] + c[..., 1]
        out[..., FYR] = c[..., 2] + c[..., 3]
        return out

    def stiffness(self, theta: np.ndarray) -> np.ndarray:
        """``C = C_0 + Theta`` [N/rad]."""
        return self.theta0 + np.asarray(theta, dtype=float)

    def vehicle_with(self, theta: np.ndarray) -> Vehicle:
        """The vehicle whose tires have ``C = C_0 + Theta``: rows 7-8 of ``A0``, ``A1`` plus ``D chi Theta``.

        Exact for the model of this module (``E`` is the identity on the tire rows, so
        ``E^-1`` leaves rows 7-8 alone); with ``Theta = theta_of_scales(s_f, s_r)`` it is the
        plant of effects.md's ``tire_stiffness`` with those scales. Nothing else changes.
        """
        th = np.asarray(theta, dtype=float)
        if th.shape != (4,) or not np.all(np.isfinite(th)):
            raise LPVModelError(f"theta must hold 4 finite numbers [N/rad], got {theta!r}")
        v = self.vehicle
        A0, A1 = v.A0.copy(), v.A1.copy()
        for j in range(4):
            A0[FYF + j // 2] += th[j] * self.H0[j]
            A1[FYF + j // 2] += th[j] * self.H1[j]
        c = self.theta0 + th
        tires = dataclasses.replace(v.tires, C_alpha_f0=c[0], C_gamma_f0=c[1], C_alpha_r0=c[2], C_gamma_r0=c[3])
        s = c / self.theta0
        return Vehicle(name=f"{v.name} (C/C_0 = {', '.join(f'{x:.3g}' for x in s)})", E=v.E, A0=A0, A1=A1, B=v.B,
                       mass=v.mass, tires=tires, vmin=v.vmin, vmax=v.vmax,
                       provenance={**v.provenance, "tires": f"{v.name} with Theta = {th.tolist()} N/rad"})

    def theta_of_scales(self, front_scale: float, rear_scale: float) -> np.ndarray:
        """``Theta`` of a ``tire_stiffness`` effect with these scales (exact, module docstring)."""
        s = np.array([front_scale, front_scale, rear_scale, rear_scale], dtype=float)
        return (s - 1.0) * self.theta0

    # ---------------------------------------------------------------- outputs
    def output(self, x: np.ndarray) -> np.ndarray:
        """``y = C x`` = ``[delta, r, phi_dot, delta_dot, ay]``, shape (..., 5)."""
        return np.asarray(x, dtype=float) @ self.C.T

    def virtual_sensor_coefficients(self, vx: float) -> tuple[np.ndarray, np.ndarray]:
        """``(m, n)`` with ``y_a = m . d/dt[r, phi_dot, delta_dot] + n(vx) . [r, phi_dot, delta_dot]``.

        From ``w^T E x' = w^T A~(vx) x`` (rows 3 and 4 of the model have no sine,
        torque or ``vy`` term after the combination ``w``):
        ``m = (w^T E)[r, phi_dot, delta_dot]`` [kg m^2 ...] and
        ``n = -(w^T A~(vx))[r, phi_dot, delta_dot]``.
        """
        w = self._w()
        m = (w @ self.vehicle.E)[list(VIRTUAL_STATES)]
        n = -(w @ self.vehicle.A(vx))[list(VIRTUAL_STATES)]
        return m, n

    def _w(self) -> np.ndarray:
        E = self.vehicle.E
        w = np.zeros(8)
        w[VY], w[R] = E[VY, R], -E[VY, VY]  # e34 row3 - e33 row4: cancels vy'
        return w

    # ---------------------------------------------------------------- checks
    def check_speed(self, vx: np.ndarray | float, name: str = "vx") -> None:
        """Raise :class:`LPVModelError` if ``vx`` is not finite and positive."""
        v = np.asarray(vx, dtype=float)
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            idx = np.argwhere(~(np.isfinite(v) & (v > 0)))
            where = f" at index {tuple(int(i) for i in idx[0])}" if v.ndim and idx.size else ""
            raise LPVModelError(f"{name} must be finite and positive [m/s]{where}")


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def build_lpv_model(vehicle: Vehicle | None = None, vmin: float | None = None, vmax: float | None = None) -> LPVModel:
    """The LPV model of ``vehicle`` (default the reference scooter) scheduled on ``[vmin, vmax]`` [m/s].

    A bound left out is the vehicle's own (:attr:`ptw_env.vehicle.Vehicle.control_range`: the
    ``[speed_range] design_vmin/design_vmax`` of its file, else its valid range; 8-33 m/s for the
    reference scooter), never a number of one vehicle.

    Raises
    ------
    LPVModelError
        If the speed range is empty or leaves the vehicle's valid range, or if
        the vehicle's rows 3-4 do not give a virtual sensor on measured states
        only (a vehicle whose lateral/yaw rows differ in structure from model.md).
    """
    v = REFERENCE_SCOOTER if vehicle is None else vehicle
    lo = v.control_range[0] if vmin is None else float(vmin)
    hi = v.control_range[1] if vmax is None else float(vmax)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise LPVModelError(f"speed range must satisfy vmin < vmax, got vmin={lo!r}, vmax={hi!r} m/s")
    if lo < v.vmin or hi > v.vmax:
        raise LPVModelError(f"speed range [{lo}, {hi}] m/s leaves the vehicle's valid range [{v.vmin}, {v.vmax}] m/s")
    tp = v.tires
    Einv = np.linalg.inv(v.E)
    A0 = Einv @ v.A0
    A1 = Einv @ v.A1
    B = Einv @ v.B
    D = Einv[:, [FYF, FYR]]
    N = np.column_stack([D, Einv[:, PHI_DOT], Einv[:, DELTA_DOT]])
    C = np.zeros((5, 8))
    for i, j in enumerate((DELTA, R, PHI_DOT, DELTA_DOT)):
        C[i, j] = 1.0
    C[4] = v.ay_row()

    theta0 = np.array([tp.C_alpha_f0, tp.C_gamma_f0, tp.C_alpha_r0, tp.C_gamma_r0])
    # chi read off the printed rows 7-8 (module docstring)
    H0 = np.zeros((4, 8))
    H1 = np.zeros((4, 8))
    f0, f1 = v.A0[FYF].copy(), v.A1[FYF].copy()
    r0, r1 = v.A0[FYR].copy(), v.A1[FYR].copy()
    f0[FYF] = f1[FYF] = r0[FYR] = r1[FYR] = 0.0  # the -vx F/sigma relaxation term is not a stiffness
    ca, sa = tp.C_alpha_f0 * math.cos(tp.caster), tp.C_gamma_f0 * math.sin(tp.caster)
    a72 = f1[DELTA]
    kappa = a72 * tp.sigma_f / (ca + sa)
    # front cornering: vy, r, delta_dot (A0) and its share of a72; front camber: a71 and its share of a72
    for j in (VY, R, DELTA_DOT):
        H0[0, j] = f0[j] / tp.C_alpha_f0
    H1[0, DELTA] = a72 * ca / (ca + sa) / tp.C_alpha_f0
    H1[1, PHI] = f1[PHI] / tp.C_gamma_f0
    H1[1, DELTA] = a72 * sa / (ca + sa) / tp.C_gamma_f0
    for j in (VY, R):
        H0[2, j] = r0[j] / tp.C_alpha_r0
    H1[3, PHI] = r1[PHI] / tp.C_gamma_r0
    # every stiffness-carrying entry must be accounted for
    rest = [f0.copy(), f1.copy(), r0.copy(), r1.copy()]
    for arr, idx in ((rest[0], (VY, R, DELTA_DOT)), (rest[1], (PHI, DELTA)), (rest[2], (VY, R)), (rest[3], (PHI,))):
        arr[list(idx)] = 0.0
    if any(np.any(a != 0.0) for a in rest):
        raise LPVModelError(f"vehicle {v.name!r}: tire rows 7-8 have stiffness entries outside the model.md structure")

    model = LPVModel(
        vehicle=v, A0=_frozen(A0), A1=_frozen(A1), B=_frozen(B), D=_frozen(D), N=_frozen(N), C=_frozen(C),
        c_virtual=_frozen(np.zeros(8)), H0=_frozen(H0), H1=_frozen(H1), theta0=_frozen(theta0),
        gravity=_frozen(v.gravity), kappa=float(kappa), vmin=lo, vmax=hi,
    )
    w = model._w()
    comb0, comb1, combE = w @ v.A0, w @ v.A1, w @ v.E
    allowed = set(VIRTUAL_STATES)
    for name, row, extra in (("E", combE, set()), ("A0", comb0, {FYF, FYR}), ("A1", comb1, set())):
        tol = 1e-12 * max(1.0, float(np.abs(row).max()))
        bad = [STATE_NAMES[j] for j in range(8) if abs(row[j]) > tol and j not in allowed | extra]
        if bad:
            raise LPVModelError(f"vehicle {v.name!r}: the virtual-sensor row combination of {name} involves {bad}")
    cv = np.zeros(8)
    cv[[FYF, FYR]] = comb0[[FYF, FYR]]
    object.__setattr__(model, "c_virtual", _frozen(cv))
    return model


# ------------------------------------------------------------------------ observability
@dataclass(frozen=True)
class ObservabilityRow:
    """Observability of ``(A(vx), C)`` at one speed, with and without the virtual sensor.

    Attributes
    ----------
    vx : float
        Speed [m/s].
    rank, rank_virtual : int
        Numerical rank of the observability matrix (scaled coordinates, relative
        tolerance ``tol``) without / with ``y_a``; 8 = observable.
    pbh, pbh_virtual : float
        Smallest ``sigma_min([A - lambda I; C])/||A||`` over the eigenvalues
        (scaled PBH test; 0 = an unobservable mode).
    rank_CD, rank_CD_virtual : int
        ``rank(C D)`` without / with ``y_a`` (``rank(D) = 2`` is needed for ``D^T P = T C``).
    """

    vx: float
    rank: int
    rank_virtual: int
    pbh: float
    pbh_virtual: float
    rank_CD: int
    rank_CD_virtual: int


#: Nominal magnitudes of the states used to scale the observability tests (rad, rad, m/s, rad/s, rad/s, rad/s, N, N).
STATE_SCALE = np.array([0.2, 0.02, 0.5, 0.2, 0.5, 0.2, 400.0, 400.0])


def _obs_rank(A: np.ndarray, C: np.ndarray, tol: float) -> tuple[int, float]:
    n = A.shape[0]
    O = np.vstack([C @ np.linalg.matrix_power(A / np.linalg.norm(A, 2), k) for k in range(n)])
    s = np.linalg.svd(O, compute_uv=False)
    rank = int(np.sum(s > tol * s[0]))
    nA = np.linalg.norm(A, 2)
    pbh = min(np.linalg.svd(np.vstack([A - lam * np.eye(n), C]), compute_uv=False)[-1] for lam in np.linalg.eigvals(A))
    return rank, float(pbh / nA)


def observability_table(model: LPVModel | None = None, speeds=None, tol: float = 1e-9) -> list[ObservabilityRow]:
    """Observability of the measured set, without and with the virtual sensor, at each speed.

    Everything is computed in coordinates scaled by :data:`STATE_SCALE` (and
    each output by its row norm), where the observability matrix of the time
    grid ``A/||A||`` is numerically meaningful; the unscaled matrix spans 10
    orders of magnitude and its "rank" is an artefact of the tolerance.

    Parameters
    ----------
    model : LPVModel, optional
    speeds : sequence of float, optional
        Speeds [m/s]; default every 1 m/s over the vehicle's valid range.
    tol : float
        Relative singular-value tolerance of the rank.
    """
    model = build_lpv_model() if model is None else model
    v = model.vehicle
    sp = np.arange(v.vmin, v.vmax + 1e-9, 1.0) if speeds is None else np.asarray(speeds, dtype=float)
    model.check_speed(sp, "speeds")
    S = STATE_SCALE
    rows = []
    for vx in sp:
        As = model.A(vx) * S[None, :] / S[:, None]
        out = []
        for C in (model.C, model.C_aug()):
            Cs = C * S[None, :]
            Cs = Cs / np.linalg.norm(Cs, axis=1, keepdims=True)
            r, p = _obs_rank(As, Cs, tol)
            out.append((r, p, int(np.linalg.matrix_rank(C @ model.D))))
        rows.append(ObservabilityRow(float(vx), out[0][0], out[1][0], out[0][1], out[1][1], out[0][2], out[1][2]))
    return rows


# ------------------------------------------------------------------------ Lipschitz box
def theta_band(model: LPVModel, scale_lo: float, scale_hi: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Theta_lo, Theta_hi)`` of the stiffness band ``[scale_lo, scale_hi] x C_0``."""
    if not (0.0 < scale_lo < 1.0 < scale_hi) or not math.isfinite(scale_hi):
        raise LPVModelError(f"the stiffness band must satisfy 0 < scale_lo < 1 < scale_hi, got [{scale_lo}, {scale_hi}]")
    return (scale_lo - 1.0) * model.theta0, (scale_hi - 1.0) * model.theta0


def nonlinearity_vertices(model: LPVModel, theta_lo: np.ndarray, theta_hi: np.ndarray,
                          phi_max: float = PHI_MAX, delta_max: float = DELTA_MAX) -> np.ndarray:
    """Vertices ``J_v`` (4 x 8 each) of the set that holds every increment of the nonlinearity.

    For ``Lambda(x) = phi(x) + D chi(x, vx) Theta`` and any ``x, x_hat`` in the box,
    the mean-value theorem gives ``Lambda(x) - Lambda(x_hat) = N J x_tilde`` with

    .. math::

        J = \\begin{bmatrix} \\Theta_1 (h_0^1 + v_x h_1^1) + \\Theta_2 (h_0^2 + v_x h_1^2) \\\\
                             \\Theta_3 (h_0^3 + v_x h_1^3) + \\Theta_4 (h_0^4 + v_x h_1^4) \\\\
                             a_{51} c_1 e_\\phi^T + a_{52} c_2 e_\\delta^T \\\\
                             a_{61} c_1 e_\\phi^T + a_{62} c_2 e_\\delta^T \\end{bmatrix},

    ``c_1 = cos(xi_1) - 1 in [cos(phi_max) - 1, 0]``, ``c_2 in [cos(delta_max)
    - 1, 0]`` (``xi`` between the true and estimated angles), ``vx in [vmin,
    vmax]``, ``Theta in [theta_lo, theta_hi]``. ``J`` is multi-affine in these
    seven numbers, so every ``J`` lies in the convex hull of the ``2^7``
    returned vertices (fewer when a bound is degenerate), and a matrix
    inequality affine in ``J`` that holds at the vertices holds everywhere.
    """
    tl, th = np.asarray(theta_lo, float), np.asarray(theta_hi, float)
    if tl.shape != (4,) or th.shape != (4,) or np.any(tl > th):
        raise LPVModelError("theta_lo, theta_hi must be 4-vectors with theta_lo <= theta_hi")
    if not (0 < phi_max < math.pi / 2) or not (0 < delta_max < math.pi / 2):
        raise LPVModelError(f"phi_max and delta_max must lie in (0, pi/2) rad, got {phi_max}, {delta_max}")
    axes = [(model.vmin, model.vmax)] + [(tl[j], th[j]) for j in range(4)]
    axes += [(math.cos(phi_max) - 1.0, 0.0), (math.cos(delta_max) - 1.0, 0.0)]
    axes = [tuple(sorted(set(a))) for a in axes]
    g = model.gravity
    out = []
    for vx, t1, t2, t3, t4, c1, c2 in itertools.product(*axes):
        J = np.zeros((4, 8))
        th_ = (t1, t2, t3, t4)
        for j in range(4):
            J[j // 2] += th_[j] * (model.H0[j] + vx * model.H1[j])
        J[2, PHI], J[2, DELTA] = g[0, 0] * c1, g[0, 1] * c2
        J[3, PHI], J[3, DELTA] = g[1, 0] * c1, g[1, 1] * c2
        out.append(J)
    return np.array(out)


@njit(cache=True, inline="always")
def chi_entry(x, vx, H0, H1, j):
    """``chi_j(x, vx) = (H0[j] + vx H1[j]) . x`` (:class:`LPVModel`), the regressor of stiffness ``j`` in row
    ``FYF + j // 2``: the one compiled form of the LPV stiffness term, used by the adaptive observer's and the
    joint EKF's kernels (units: those of ``C_j chi_j / C_j0`` per N/rad, as :attr:`LPVModel.H0`)."""
    acc = 0.0
    for i in range(8):
        acc += (H0[j, i] + vx * H1[j, i]) * x[i]
    return acc


#: Bank at which :func:`bank_column` samples the plant [rad] (exact at any value: the column is linear in sin(beta)).
BANK_SAMPLE_RAD = 0.1


def bank_column(vehicle) -> tuple[np.ndarray, np.ndarray]:
    """``(W0, dW)``: the plant's flat coefficients on a level road and their change per unit ``sin(beta)`` of the
    road bank (effects.md ``road_bank``: the bank enters the constant column, row 3's ``-M g sin(beta)`` through
    ``E^-1``, linearly in ``sin(beta)``), so ``W(beta) = W0 + sin(beta) dW``; sampled at :data:`BANK_SAMPLE_RAD`."""
    from ptw_env.dynamics import compile_plant
    from ptw_env.vehicle import Vehicle

    if not isinstance(vehicle, Vehicle):
        raise LPVModelError(f"bank_column needs a Vehicle (ptw_env.vehicle_files.load_vehicle), got "
                            f"{type(vehicle).__name__}")
    w0 = compile_plant(vehicle).flat()[0][0]
    w1 = compile_plant(vehicle, {"road_bank": {"bank_rad": BANK_SAMPLE_RAD}}).flat()[0][0]
    return w0.copy(), np.ascontiguousarray((w1 - w0) / math.sin(BANK_SAMPLE_RAD))


def check_real(value, name: str, error: type[Exception] = ValueError, *, positive: bool = False,
               missing_ok: bool = False) -> float:
    """``value`` as a float, or ``error`` naming ``name`` and the value: a real number (not a bool, a numpy bool or
    a string), finite (``missing_ok``: NaN, a missing reading, passes), and > 0 when ``positive``.

    >>> check_real(2, "dt", positive=True)
    2.0
    >>> check_real(True, "dt")
    Traceback (most recent call last):
    ...
    ValueError: dt must be a finite number, got True
    """
    kind = "a positive number" if positive else "a finite number"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise error(f"{name} must be {kind}, got {value!r}")
    try:
        v = float(value)
    except (OverflowError, TypeError, ValueError):
        raise error(f"{name} must be {kind}, got {value!r}") from None
    if missing_ok and math.isnan(v):
        return v
    if not math.isfinite(v) or (positive and v <= 0.0):
        raise error(f"{name} must be {kind}{' (NaN: missing)' if missing_ok else ''}, got {value!r}")
    return v


def check_bank(value, error: type[Exception] = ValueError) -> float:
    """A road bank [rad] as a float, or ``error`` naming the value: a real number (not a bool or a string) inside
    the open range effects.md gives ``road_bank:bank_rad`` (``ptw_env.effects.VOCABULARY``, |bank| < 0.5).

    >>> check_bank(0.05)
    0.05
    >>> check_bank("0.05")
    Traceback (most recent call last):
    ...
    ValueError: road_bank must be a bank angle in rad, |road_bank| < 0.5, got '0.05'
    """
    from ptw_env.effects import VOCABULARY

    _, _, lo, hi = VOCABULARY["road_bank"]["bank_rad"]
    msg = f"road_bank must be a bank angle in rad, |road_bank| < {hi:g}, got {value!r}"
    try:
        v = check_real(value, "road_bank", error)
    except error:
        raise error(msg) from None
    if not lo < v < hi:
        raise error(msg)
    return v


__all__ = [
    "BANK_SAMPLE_RAD",
    "bank_column",
    "check_bank",
    "check_real",
    "DELTA_MAX",
    "LPVModel",
    "LPVModelError",
    "ObservabilityRow",
    "OUTPUT_NAMES",
    "OUTPUT_UNITS",
    "PHI_MAX",
    "STATE_SCALE",
    "THETA_NAMES",
    "VIRTUAL_NAME",
    "VIRTUAL_STATES",
    "build_lpv_model",
    "chi_entry",
    "nonlinearity_vertices",
    "observability_table",
    "theta_band",
]
