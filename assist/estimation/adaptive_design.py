"""LMI design of the LPV adaptive observer (Fouka, Nehaoua, Arioui [1]_, Theorem 2), with certificates.

Problem ([1]_ eqs. 19-20, 33-34, 38) on the polytopic model of
:mod:`assist.estimation.lpv_model` (vertices ``A_1 = A(vmin)``, ``A_2 = A(vmax)``):

.. math::

    \\begin{bmatrix} A_i^T P + P A_i - C^T K_i^T - K_i C + R & P N \\\\
                     N^T P & -Q \\end{bmatrix} \\prec 0, \\quad i = 1, 2,
    \\qquad
    \\min\\ s \\ \\text{s.t.}\\
    \\begin{bmatrix} s I & D^T P - T C_a \\\\ \\star & s I \\end{bmatrix} \\succeq 0,

``L_i = P^-1 K_i``, ``L(vx) = sum_i eta_i(vx) L_i``. ``C`` holds the five
physical outputs (the gains use only real sensors); ``C_a = [C; c_a]`` adds
the virtual sensor ``y_a`` ([1]_ eq. 15), which only the adaptive law uses
(the equality needs ``rank(C_a D) = 2``).

The Lipschitz bound (computed, [1]_ Lemma 1, eq. 25)
----------------------------------------------------
The nonlinearity ``Lambda(x) = phi(x) + D chi(x, vx) Theta`` (sine terms and
the stiffness deviation) has increments ``Lambda(x) - Lambda(x_hat) = N J
x_tilde`` with ``J`` in the convex hull of the vertices of
:func:`assist.estimation.lpv_model.nonlinearity_vertices` (speed range, the certified
stiffness band, ``|phi| <= 45 deg``, ``|delta| <= 20 deg``). With ``Q = I``
(in the scaled coordinates of ``w = J x_tilde``), ``R`` is the solution of

.. math::

    \\min_R \\operatorname{tr} R \\quad \\text{s.t.}\\quad
    \\begin{bmatrix} R & J_v^T \\\\ J_v & Q^{-1} \\end{bmatrix} \\succeq 0\\ \\forall v,

which gives ``Lambda~^T Q Lambda~ <= x~^T R x~`` on the whole box (the
constraint is affine in ``J``, ``J`` multi-affine in the box coordinates).
The scale of ``Q`` is immaterial (it is absorbed by ``P``).

Corrections to the printed theorem, and what is added
------------------------------------------------------
* The inequality is written with ``P N`` (``Lambda`` lies in the range of
  ``N = [D, E^-1 e5, E^-1 e6]``) instead of ``P``; with ``N = I`` it is
  [1]_ eq. (34) verbatim, and the Young step (26) is the same. It is tighter,
  and the ``Q`` block is 4 x 4.
* [1]_ eq. (32) prints the adaptive law as ``Theta' = sigma_max Theta~^T D^T P
  x~`` (a scalar, using the unknown ``Theta~``); the law is eq. (18)/(30),
  ``Theta' = Gamma chi^T(x_hat) T C x~`` (:mod:`assist.estimation.adaptive_observer`).
* [1]_ eq. (33) writes ``min_{i=1..r} s``; there is one ``s`` (one ``P``, one ``T``).
* The paper's problem has no noise term: its gains are as large as the
  Lipschitz margin allows, which amplifies 5 % sensor noise (and the 10-bit
  encoder's quantisation) into the state estimate and biases the adaptation.
  The design therefore adds, as a strict superset of (34),

  .. math::

      \\begin{bmatrix} \\Psi_i + R & P N & P B_w & -K_i \\\\
        \\star & -Q & 0 & 0 \\\\ \\star & 0 & -I & 0 \\\\ \\star & 0 & 0 & -I \\end{bmatrix} \\prec 0,
      \\quad \\begin{bmatrix} Z & I \\\\ I & P \\end{bmatrix} \\succeq 0,

  (its upper-left 2 x 2 block is (34)), so that ``tr Z`` bounds the
  steady-state error covariance (scaled) for model-error intensity ``B_w
  B_w^T`` and measurement-noise intensity ``V`` (the sensors' variances times
  ``dt``): an LMI Kalman filter with the Lipschitz dissipation kept. Stage 1
  minimises ``tr Z``; stage 2 minimises ``s`` subject to ``tr Z <= (1 +
  slack) tr Z*``. A pole disk ``|lambda(A_i - L_i C)| < radius`` (Chilali-
  Gahinet, same ``P``) keeps every blend implementable at ``dt``.

Every strict inequality is imposed with a margin and re-checked in numpy
(:class:`Certificate`). The residual of ``D^T P = T C_a`` is reported
absolute and relative to ``||D^T P||``, together with the quasi-static
adaptation check: the symmetric part of ``T C_a (L(vx) C - A(vx))^-1 D``
(what the law sees of a slow parameter error) should be positive definite
for the adaptation to converge by averaging; with an exact equality it is
(``P F^-1`` has a positive-definite symmetric part when ``F^T P + P F > 0``).

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers" (``shared/papers/000_348caefc9b08ee38.txt``).
.. [2] M. Chilali, P. Gahinet, "H-infinity design with pole placement
   constraints: an LMI approach", IEEE TAC 41(3), 1996.

Length (about 730 lines): the two designs of the observer's gains (Theorem 2 and Kalman vertex gains) share
the options, the data scaling, the pole disk and the certificate, and :func:`design_for_vehicle` chooses
between their speed ranges; split, each half would import the other's private scaling.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ptw_env.sensors import ENCODER_QUANTUM, SensorConfig
from ptw_env.vehicle import Vehicle

from assist.lmi import Certificate, CertificateEntry, max_eig, solve_quietly, symmetric
from assist.estimation.lpv_model import (
    DELTA_MAX,
    OUTPUT_NAMES,
    PHI_MAX,
    STATE_SCALE,
    LPVModel,
    build_lpv_model,
    nonlinearity_vertices,
    theta_band,
)

#: Default model-error intensities per state (phi..Fyr, units per sqrt(s)): small on the kinematic
#: rows, 30 N/sqrt(s) on the tire forces (the relaxation model is trusted, the stiffness is not).
DEFAULT_PROCESS_STD = (1e-4, 1e-4, 1e-2, 1e-3, 1e-2, 1e-2, 30.0, 30.0)
#: Scale of the tire-force columns of D in the scaled problem [N].
_D_SCALE = 400.0
#: Scale of the virtual sensor in the equality [kg m N].
_YA_SCALE = 300.0
SOLVERS = ("CLARABEL", "SCS")


class AdaptiveDesignError(ValueError):
    """The adaptive-observer LMIs are infeasible, the solver failed, or a certificate does not hold.

    Attributes
    ----------
    stage : str
        ``"lipschitz"``, ``"noise (stage 1)"``, ``"equality (stage 2)"`` or ``"certificate"``.
    cause : str
    """

    def __init__(self, stage: str, cause: str) -> None:
        self.stage, self.cause = stage, cause
        super().__init__(f"adaptive observer design, {stage}: {cause}")


class AdaptiveDesignOptionError(ValueError):
    """A design option outside its meaningful range."""


@dataclass(frozen=True)
class AdaptiveDesignOptions:
    """Options of :func:`design_adaptive_observer` (all physical units).

    Attributes
    ----------
    vmin, vmax : float or None
        Scheduling range [m/s]; None (default): the model's, i.e. the vehicle's
        :attr:`ptw_env.vehicle.Vehicle.control_range` (8-33 m/s for the reference scooter).
    lipschitz_band : tuple of 2 floats
        Stiffness band ``[lo, hi] x C_0`` over which the Lipschitz bound (hence
        the certificate) holds (default 0.9-1.1: wider bands drive the equality
        residual up, see ``scripts/eval_adaptive.py``).
    phi_max, delta_max : float
        Roll and steer bounds of the Lipschitz box [rad].
    noise_pct : float
        Sensor noise the gains are designed for, percent of each channel's range
        (``SensorConfig.from_percent``; the encoder quantisation ``q^2/12`` is added to delta).
    process_std : tuple of 8 floats
        Model-error intensities per state [unit/sqrt(s)].
    slack : float
        Stage 2 may raise the noise bound ``tr Z`` by this fraction to lower the residual.
    radius : float or None
        Pole disk [rad/s]; None: ``0.8 pi/dt``.
    dt : float
        Sample period of the implementation [s].
    margin : float
        Strict inequalities are imposed ``<= -10 margin`` and certified ``< -margin`` (scaled units).
    solver : str
        ``"CLARABEL"`` (default) or ``"SCS"``.
    """

    vmin: float | None = None
    vmax: float | None = None
    lipschitz_band: tuple[float, float] = (0.9, 1.1)
    phi_max: float = PHI_MAX
    delta_max: float = DELTA_MAX
    noise_pct: float = 5.0
    process_std: tuple[float, ...] = DEFAULT_PROCESS_STD
    slack: float = 0.1
    radius: float | None = None
    dt: float = 0.01
    margin: float = 1e-8
    solver: str = "CLARABEL"

    def __post_init__(self) -> None:
        def num(name: str) -> float:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise AdaptiveDesignOptionError(f"{name} must be a finite number, got {v!r}")
            return float(v)

        lo = None if self.vmin is None else num("vmin")
        hi = None if self.vmax is None else num("vmax")
        if (lo is not None and lo <= 0) or (hi is not None and hi <= 0) or (None not in (lo, hi) and not lo < hi):
            raise AdaptiveDesignOptionError(f"need 0 < vmin < vmax [m/s], got vmin={self.vmin}, vmax={self.vmax}")
        band = tuple(float(b) for b in self.lipschitz_band)
        if len(band) != 2 or not (0 < band[0] < 1 < band[1]):
            raise AdaptiveDesignOptionError(f"lipschitz_band must be (lo, hi) with 0 < lo < 1 < hi, got {self.lipschitz_band!r}")
        object.__setattr__(self, "lipschitz_band", band)
        for name in ("phi_max", "delta_max"):
            if not 0 < num(name) < math.pi / 2:
                raise AdaptiveDesignOptionError(f"{name} must lie in (0, pi/2) rad, got {getattr(self, name)!r}")
        if num("noise_pct") < 0:
            raise AdaptiveDesignOptionError(f"noise_pct must be >= 0, got {self.noise_pct!r}")
        q = tuple(float(a) for a in self.process_std)
        if len(q) != 8 or not all(math.isfinite(a) and a > 0 for a in q):
            raise AdaptiveDesignOptionError(f"process_std must hold 8 positive numbers, got {self.process_std!r}")
        object.__setattr__(self, "process_std", q)
        if num("slack") < 0:
            raise AdaptiveDesignOptionError(f"slack must be >= 0, got {self.slack!r}")
        if not 0 < num("dt") <= 0.1:
            raise AdaptiveDesignOptionError(f"dt must lie in (0, 0.1] s, got {self.dt!r}")
        if self.radius is not None and not (0 < num("radius") < math.pi / self.dt):
            raise AdaptiveDesignOptionError(f"radius must lie in (0, pi/dt) rad/s, got {self.radius!r}")
        if not 0 < num("margin") < 1e-2:
            raise AdaptiveDesignOptionError(f"margin must lie in (0, 0.01), got {self.margin!r}")
        if self.solver not in SOLVERS:
            raise AdaptiveDesignOptionError(f"solver must be one of {SOLVERS}, got {self.solver!r}")

    @property
    def disk(self) -> float:
        """Pole-disk radius [rad/s]."""
        return float(self.radius) if self.radius is not None else 0.8 * math.pi / self.dt

    def noise_std(self, vehicle: Vehicle | None = None) -> np.ndarray:
        """Per-sample noise std of the five outputs (delta with quantisation), physical units, in percent of
        ``vehicle``'s channel ranges (:func:`ptw_env.sensors.channel_ranges`; default the reference scooter's)."""
        cfg = SensorConfig.from_percent(max(self.noise_pct, 0.1), vehicle=vehicle)
        s = np.array([cfg.noise_std[c] for c in OUTPUT_NAMES])
        s[0] = math.sqrt(s[0] ** 2 + ENCODER_QUANTUM**2 / 12.0)
        return s


# --------------------------------------------------------------------------- scaled data
@dataclass(frozen=True, eq=False)
class _Scaled:
    A: np.ndarray  # (2, 8, 8)
    C: np.ndarray  # (5, 8)
    Ca: np.ndarray  # (6, 8)
    D: np.ndarray  # (8, 2)
    N: np.ndarray  # (8, 4)
    Bw: np.ndarray  # (8, 8)
    J: np.ndarray  # (nv, 4, 8)
    sx: np.ndarray
    sy: np.ndarray  # measurement-noise intensity scale (5,)
    sya: np.ndarray  # equality output scale (6,)
    sw: np.ndarray  # (4,)


def _scaled(model: LPVModel, o: AdaptiveDesignOptions) -> _Scaled:
    sx = STATE_SCALE
    ns = o.noise_std(model.vehicle)
    sy = ns * math.sqrt(o.dt)  # white noise of per-sample std s at rate 1/dt has intensity s^2 dt
    sya = np.r_[ns, _YA_SCALE]
    A = np.stack([a / sx[:, None] * sx[None, :] for a in model.vertices])
    C = model.C * sx[None, :] / sy[:, None]
    Ca = model.C_aug() * sx[None, :] / sya[:, None]
    D = model.D / sx[:, None] * _D_SCALE
    Nraw = model.N / sx[:, None]
    sw = 1.0 / np.linalg.norm(Nraw, axis=0)
    N = Nraw * sw[None, :]
    Bw = np.diag(np.asarray(o.process_std) / sx)
    J = nonlinearity_vertices(model, *theta_band(model, *o.lipschitz_band), o.phi_max, o.delta_max)
    Js = J / sw[None, :, None] * sx[None, None, :]
    return _Scaled(A, C, Ca, D, N, Bw, Js, sx, sy, sya, sw)


def _solve(prob, solver: str, stage: str) -> None:
    st = solve_quietly(prob, solver)
    if st.startswith("solver_error"):
        raise AdaptiveDesignError(stage, f"solver {solver} failed ({st.split(': ', 1)[1]})")
    if st.startswith("solver_crash"):
        raise AdaptiveDesignError(stage, f"solver {solver} crashed ({st.split(': ', 1)[1]})")
    if st not in ("optimal", "optimal_inaccurate"):
        raise AdaptiveDesignError(stage, f"the LMIs are {st}")


# --------------------------------------------------------------------------- Lipschitz bound
def _lipschitz_violation(Rs: np.ndarray, J: np.ndarray) -> float:
    """``max_v -lambda_min(R - J_v^T J_v)`` (scaled, ``Q = I``): <= 0 when the bound holds at every vertex
    (the Schur complement of ``[[R, J^T], [J, Q^-1]] >= 0``)."""
    return float(max(-np.linalg.eigvalsh(Rs - Jv.T @ Jv)[0] for Jv in J))


@dataclass(frozen=True, eq=False)
class LipschitzBound:
    """``Lambda~^T Q Lambda~ <= x~^T R x~`` with ``Lambda~ = N w``.

    Attributes
    ----------
    R : ndarray (8, 8)
        Physical coordinates (``x~`` in SI units).
    Q : ndarray (4, 4)
        Weight on ``w`` in physical units (``Q = diag(1/sw^2)``: identity in the scaled problem).
    R_scaled : ndarray (8, 8)
    vertices : int
        Number of vertices ``J_v`` it was computed on.
    band : tuple
        Stiffness band (multiples of ``C_0``).
    gamma : float
        Lipschitz constant of ``Lambda`` in the scaled coordinates, ``max_v ||J_v||`` (for reference).
    """

    R: np.ndarray
    Q: np.ndarray
    R_scaled: np.ndarray
    vertices: int
    band: tuple[float, float]
    gamma: float


def model_for(options: AdaptiveDesignOptions, model: LPVModel | None = None) -> LPVModel:
    """The LPV model a design is made on: ``model`` (its speed range must match the options' bounds that are
    set), else the reference scooter's on the options' range (bounds left at None: the vehicle's
    :attr:`~ptw_env.vehicle.Vehicle.control_range`)."""
    if model is None:
        return build_lpv_model(vmin=options.vmin, vmax=options.vmax)
    for name, mine in (("vmin", model.vmin), ("vmax", model.vmax)):
        want = getattr(options, name)
        if want is not None and float(want) != float(mine):
            raise AdaptiveDesignOptionError(
                f"model speed range [{model.vmin}, {model.vmax}] m/s differs from the options' {name} = {want} m/s")
    return model


def lipschitz_bound(model: LPVModel | None = None, options: AdaptiveDesignOptions | None = None) -> LipschitzBound:
    """Compute ``R`` (module docstring, SDP ``min tr R``) on the box of ``options``."""
    import cvxpy as cp

    o = AdaptiveDesignOptions() if options is None else options
    model = model_for(o, model)
    d = _scaled(model, o)
    R = cp.Variable((8, 8), symmetric=True)
    I4 = np.eye(4)
    cons = [cp.bmat([[R, Jv.T], [Jv, I4]]) >> 0 for Jv in d.J]
    prob = cp.Problem(cp.Minimize(cp.trace(R)), cons)
    _solve(prob, o.solver, "lipschitz")
    Rs = symmetric(R.value)
    # make it exactly feasible: lift by the worst violation
    worst = _lipschitz_violation(Rs, d.J)
    if worst > 0:
        Rs = Rs + (worst * 1.01 + 1e-12) * np.eye(8)
    sx = d.sx
    Rp = Rs / sx[:, None] / sx[None, :]
    Qp = np.diag(1.0 / d.sw**2)
    return LipschitzBound(R=Rp, Q=Qp, R_scaled=Rs, vertices=len(d.J), band=o.lipschitz_band,
                          gamma=float(max(np.linalg.norm(Jv, 2) for Jv in d.J)))


# --------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class AdaptiveObserverDesign:
    """Result of :func:`design_adaptive_observer`.

    Attributes
    ----------
    model : LPVModel
    options : AdaptiveDesignOptions
    L : ndarray (2, 8, 5)
        Vertex gains, physical units (``x' += L (y - C x_hat)``, outputs of OUTPUT_NAMES).
    T : ndarray (2, 6)
        Adaptive-law output weight (physical; columns: the five outputs and ``y_a``).
    P : ndarray (8, 8)
        Lyapunov matrix, physical coordinates.
    residual, residual_rel : float
        ``s = ||D^T P - T C_a||`` (scaled) and ``s / ||D^T P||``.
    noise_bound : float
        ``tr P^-1`` (scaled): the bound on the steady-state error covariance that the certified
        inequality implies (stage 1 minimises ``tr Z >= tr P^-1``).
    lipschitz : LipschitzBound
    certificate : Certificate
    poles : ndarray (2, 8)
        Eigenvalues of ``A_i - L_i C`` [rad/s].
    quasi_static_min_eig : float
        Smallest eigenvalue of the symmetric part of ``T C_a (L C - A)^-1 D`` over a speed
        grid (normalised by its largest; > 0: slow parameter errors are corrected).
    solve_s : float
        Wall time of the whole design [s].
    status : str
        Solver status of stage 2.
    kind : str
        ``"theorem2"`` (:func:`design_adaptive_observer`: certified against the Lipschitz bound)
        or ``"kalman"`` (:func:`kalman_design`: certified for the linear polytope only; ``T``,
        the equality residual and the Lipschitz bound do not apply and are NaN / None).
    """

    model: LPVModel
    options: AdaptiveDesignOptions
    L: np.ndarray
    T: np.ndarray
    P: np.ndarray
    residual: float
    residual_rel: float
    noise_bound: float
    lipschitz: LipschitzBound
    certificate: Certificate
    poles: np.ndarray
    quasi_static_min_eig: float
    solve_s: float
    status: str
    kind: str = "theorem2"
    _scaled: dict = field(default_factory=dict, repr=False)

    def gain(self, vx: float) -> np.ndarray:
        """``L(vx) = sum_i eta_i(vx) L_i`` (8 x 5)."""
        w = self.model.weights(vx)
        return w[0] * self.L[0] + w[1] * self.L[1]

    def quasi_static_gain(self, vx: float) -> np.ndarray:
        """``T C_a (L(vx) C - A(vx))^-1 D`` (2 x 2): the adaptation signal per unit slow ``D chi Theta~``."""
        F = self.gain(vx) @ self.model.C - self.model.A(vx)
        return self.T @ self.model.C_aug() @ np.linalg.solve(F, self.model.D)

    def summary(self) -> dict[str, Any]:
        """JSON-friendly figures of the design."""
        if self.kind == "kalman":
            return {
                "kind": self.kind, "feasible": bool(self.certificate.passed), "solve_s": round(self.solve_s, 3),
                "speed_range": [self.model.vmin, self.model.vmax], "lipschitz_certified": False,
                "worst_lmi_eig": float(self.certificate.worst().max_eig),
                "slowest_pole": float(np.max(self.poles.real)), "fastest_pole_abs": float(np.max(np.abs(self.poles))),
                "L_norm": [float(np.linalg.norm(l, 2)) for l in self.L], "status": self.status,
            }
        return {
            "kind": self.kind,
            "feasible": bool(self.certificate.passed),
            "solve_s": round(self.solve_s, 3),
            "speed_range": [self.model.vmin, self.model.vmax],
            "lipschitz_band": list(self.options.lipschitz_band),
            "lipschitz_gamma_scaled": round(self.lipschitz.gamma, 4),
            "equality_residual": float(self.residual),
            "equality_residual_rel": float(self.residual_rel),
            "noise_bound_trPinv": float(self.noise_bound),
            "quasi_static_min_eig": float(self.quasi_static_min_eig),
            "worst_lmi_eig": float(self.certificate.worst().max_eig),
            "slowest_pole": float(np.max(self.poles.real)),
            "fastest_pole_abs": float(np.max(np.abs(self.poles))),
            "L_norm": [float(np.linalg.norm(l, 2)) for l in self.L],
            "status": self.status,
        }


# --------------------------------------------------------------------------- the LMIs
def _main_block(d: _Scaled, P, K, R, i: int, bmat):
    M = P @ d.A[i] - K @ d.C
    n, nw, ny = 8, d.N.shape[1], d.C.shape[0]
    Z = np.zeros
    return bmat([
        [M + M.T + R, P @ d.N, P @ d.Bw, -K],
        [(P @ d.N).T, -np.eye(nw), Z((nw, n)), Z((nw, ny))],
        [(P @ d.Bw).T, Z((n, nw)), -np.eye(n), Z((n, ny))],
        [-K.T, Z((ny, nw)), Z((ny, n)), -np.eye(ny)],
    ])


def _paper_block(d: _Scaled, P, K, R, i: int) -> np.ndarray:
    """[1]_ eq. (34) with ``P N`` and ``Q = I``: the upper-left part of :func:`_main_block`."""
    M = P @ d.A[i] - K @ d.C
    return np.block([[M + M.T + R, P @ d.N], [(P @ d.N).T, -np.eye(d.N.shape[1])]])


def _disk_block(d: _Scaled, P, K, i: int, radius: float, bmat):
    M = P @ d.A[i] - K @ d.C
    return bmat([[-P, M / radius], [M.T / radius, -P]])


def design_adaptive_observer(model: LPVModel | None = None, options: AdaptiveDesignOptions | None = None,
                             **kwargs: Any) -> AdaptiveObserverDesign:
    """Solve the adaptive-observer LMIs (module docstring) and certify the result in numpy.

    Parameters
    ----------
    model : LPVModel, optional
        Default: :func:`assist.estimation.lpv_model.build_lpv_model` on the options' speed range.
    options : AdaptiveDesignOptions, optional
    **kwargs
        Fields of :class:`AdaptiveDesignOptions` (only when ``options`` is not given);
        unknown names are rejected.

    Raises
    ------
    AdaptiveDesignError
        Infeasible LMIs, a failed solver, or a certificate that does not hold.
    AdaptiveDesignOptionError
        Bad options.
    """
    import cvxpy as cp

    if options is not None and kwargs:
        raise AdaptiveDesignOptionError("give either options= or keyword options, not both")
    if kwargs:
        known = set(AdaptiveDesignOptions.__dataclass_fields__)
        bad = sorted(set(kwargs) - known)
        if bad:
            raise AdaptiveDesignOptionError(f"unknown design option(s) {bad}; known: {sorted(known)}")
        options = AdaptiveDesignOptions(**kwargs)
    o = AdaptiveDesignOptions() if options is None else options
    model = model_for(o, model)
    t0 = time.perf_counter()
    lip = lipschitz_bound(model, o)
    d = _scaled(model, o)
    Rs = lip.R_scaled
    m10 = 10 * o.margin
    P = cp.Variable((8, 8), symmetric=True)
    K = [cp.Variable((8, 5)) for _ in range(2)]
    T = cp.Variable((2, 6))
    s = cp.Variable(nonneg=True)
    Z = cp.Variable((8, 8), symmetric=True)
    cons = [P >> m10 * np.eye(8)]
    for i in range(2):
        blk = _main_block(d, P, K[i], Rs, i, cp.bmat)
        cons.append(blk << -m10 * np.eye(blk.shape[0]))
        dk = _disk_block(d, P, K[i], i, o.disk, cp.bmat)
        cons.append(dk << -m10 * np.eye(16))
    cons.append(cp.bmat([[Z, np.eye(8)], [np.eye(8), P]]) >> 0)
    E = d.D.T @ P - T @ d.Ca
    cons.append(cp.bmat([[s * np.eye(2), E], [E.T, s * np.eye(8)]]) >> 0)
    stage1 = cp.Problem(cp.Minimize(cp.trace(Z)), cons)
    _solve(stage1, o.solver, "noise (stage 1)")
    z_opt = float(stage1.value)
    stage2 = cp.Problem(cp.Minimize(s), cons + [cp.trace(Z) <= (1.0 + o.slack) * z_opt])
    _solve(stage2, o.solver, "equality (stage 2)")
    Pv, Kv, Tv = symmetric(P.value), np.stack([k.value for k in K]), T.value
    Zv = symmetric(Z.value)
    if Pv is None or not np.all(np.isfinite(Pv)):
        raise AdaptiveDesignError("equality (stage 2)", "the solver returned no Lyapunov matrix")

    # ---- certificate (numpy)
    entries = [CertificateEntry("P > 0", None, float(-np.linalg.eigvalsh(Pv)[0]))]
    for i in range(2):
        entries.append(CertificateEntry("theorem 2 (34) + noise", i, max_eig(_main_block(d, Pv, Kv[i], Rs, i, np.block))))
        entries.append(CertificateEntry("theorem 2 (34)", i, max_eig(_paper_block(d, Pv, Kv[i], Rs, i))))
        entries.append(CertificateEntry("pole disk", i, max_eig(_disk_block(d, Pv, Kv[i], i, o.disk, np.block))))
    entries.append(CertificateEntry("lipschitz R - J^T Q J >= 0", None, _lipschitz_violation(Rs, d.J), strict=False))
    cert = Certificate(margin=o.margin, entries=tuple(entries))
    if not cert.passed:
        f = cert.failures()[0]
        where = f", vertex {f.vertex} (vx = {(model.vmin, model.vmax)[f.vertex]:g} m/s)" if f.vertex is not None else ""
        raise AdaptiveDesignError("certificate", f"LMI '{f.lmi}'{where} has eigenvalue {f.max_eig:.3g} "
                                  f"(needs < -{o.margin:g}); the solver's answer is not accurate enough "
                                  f"(status {stage2.status}); try solver='SCS' or a narrower lipschitz_band")

    # ---- physical quantities
    sx, sy, sya = d.sx, d.sy, d.sya
    Ls = np.linalg.solve(Pv[None], Kv)
    L = sx[None, :, None] * Ls / sy[None, None, :]
    Tp = Tv / sya[None, :] / _D_SCALE
    Pp = Pv / sx[:, None] / sx[None, :]
    res = float(np.linalg.norm(d.D.T @ Pv - Tv @ d.Ca, 2))
    rel = res / float(np.linalg.norm(d.D.T @ Pv, 2))
    poles = np.stack([np.linalg.eigvals(d.A[i] - Ls[i] @ d.C) for i in range(2)])
    design = AdaptiveObserverDesign(
        model=model, options=o, L=L, T=Tp, P=Pp, residual=res, residual_rel=rel, noise_bound=float(np.trace(np.linalg.inv(Pv))),
        lipschitz=lip, certificate=cert, poles=poles, quasi_static_min_eig=0.0,
        solve_s=time.perf_counter() - t0, status=stage2.status,
        _scaled={"P": Pv, "K": Kv, "T": Tv, "Z": Zv, "s": res},
    )
    qs = []
    for v in np.linspace(model.vmin, model.vmax, 14):
        G = design.quasi_static_gain(v)
        ev = np.linalg.eigvalsh(symmetric(G))
        qs.append(ev[0] / max(abs(ev[-1]), 1e-300))
    object.__setattr__(design, "quasi_static_min_eig", float(min(qs)))
    for a in (L, Tp, Pp, poles):
        a.setflags(write=False)
    return design


def kalman_design(model: LPVModel | None = None, options: AdaptiveDesignOptions | None = None,
                  grid: int = 27) -> AdaptiveObserverDesign:
    """Vertex Kalman gains for the adaptive observer, certified for the linear LPV error dynamics only.

    ``L_i = Sigma_i C^T V^-1`` with ``Sigma_i`` the stabilising solution of the filter Riccati
    equation ``A_i Sigma + Sigma A_i^T - Sigma C^T V^-1 C Sigma + B_w B_w^T = 0`` at the vertex
    speeds (``B_w`` = ``options.process_std``, ``V`` = the sensors' variances times ``dt``,
    as in :func:`design_adaptive_observer`), blended with the same sector weights.

    Why: the certified gains of Theorem 2 must dominate the Lipschitz bound of the sine terms
    and of the stiffness band with one quadratic Lyapunov function; for the reference scooter
    that forces gains ~100x the Kalman gains (``||L|| ~ 1e5-1e6`` against ``~1e4``), and such an
    observer absorbs a stiffness error into its state correction: the innovations the adaptive
    law learns from nearly vanish and the regressor ``chi(x_hat)`` carries the injected noise
    (errors in variables), so the stiffness estimates are slow and biased
    (``scripts/eval_adaptive.py``). These gains keep the innovations informative.

    What is certified (re-checked in numpy, :class:`Certificate`): a common Lyapunov matrix
    ``P > 0`` with ``(A_i - L_i C)^T P + P (A_i - L_i C) < 0`` at both vertices (so every frozen
    and every time-varying blend of the *linear* model is stable), the pole disk at ``dt``,
    and frozen-speed Hurwitz on a ``grid`` of speeds. What is not: Theorem 2 with the
    Lipschitz bound (its LMI is infeasible for these gains: the sine terms up to 45 deg of
    roll and the stiffness band are not dominated) -- ``summary()["lipschitz_certified"]`` is
    False.
    """
    import cvxpy as cp
    import scipy.linalg as sla

    o = AdaptiveDesignOptions() if options is None else options
    model = model_for(o, model)
    t0 = time.perf_counter()
    Bw = np.diag(np.asarray(o.process_std))
    V = np.diag(o.noise_std(model.vehicle) ** 2 * o.dt)
    L = []
    for v in (model.vmin, model.vmax):
        try:
            S = sla.solve_continuous_are(model.A(v).T, model.C.T, Bw @ Bw.T, V)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise AdaptiveDesignError("kalman", f"the filter Riccati equation at vx = {v:g} m/s has no "
                                      f"stabilising solution ({exc})") from None
        L.append(S @ model.C.T @ np.linalg.inv(V))
    L = np.stack(L)
    d = _scaled(model, o)
    Ls = L / d.sx[None, :, None] * d.sy[None, None, :]
    # homogeneous in P: with P >= I a margin of 1e-3 loses nothing and survives the solver's accuracy
    eps = 1e-3
    P = cp.Variable((8, 8), symmetric=True)
    cons = [P >> np.eye(8)]
    for i in range(2):
        M = P @ (d.A[i] - Ls[i] @ d.C)
        cons.append(M + M.T << -eps * np.eye(8))
        cons.append(_disk_block(d, P, P @ Ls[i], i, o.disk, cp.bmat) << -eps * np.eye(16))
    prob = cp.Problem(cp.Minimize(cp.trace(P)), cons)
    _solve(prob, o.solver, "kalman (common Lyapunov matrix)")
    Pv = symmetric(P.value)
    entries = [CertificateEntry("P > 0", None, float(-np.linalg.eigvalsh(Pv)[0]))]
    for i in range(2):
        Acl = d.A[i] - Ls[i] @ d.C
        entries.append(CertificateEntry("linear polytope (common P)", i,
                                        max_eig(Pv @ Acl + Acl.T @ Pv)))
        entries.append(CertificateEntry("pole disk", i, max_eig(_disk_block(d, Pv, Pv @ Ls[i], i, o.disk, np.block))))
    for v in np.linspace(model.vmin, model.vmax, grid):
        w = model.weights(v)
        ev = np.linalg.eigvals(model.A(v) - (w[0] * L[0] + w[1] * L[1]) @ model.C)
        entries.append(CertificateEntry(f"frozen speed {v:.2f} m/s Hurwitz", None, float(np.max(ev.real))))
    cert = Certificate(margin=o.margin, entries=tuple(entries))
    if not cert.passed:
        f = cert.failures()[0]
        raise AdaptiveDesignError("certificate", f"'{f.lmi}' has eigenvalue {f.max_eig:.3g} (needs < -{o.margin:g})")
    poles = np.stack([np.linalg.eigvals(model.A(v) - L[i] @ model.C) for i, v in enumerate((model.vmin, model.vmax))])
    nan = float("nan")
    for a in (L, poles):
        a.setflags(write=False)
    return AdaptiveObserverDesign(
        model=model, options=o, L=L, T=np.full((2, 6), nan), P=Pv / d.sx[:, None] / d.sx[None, :],
        residual=nan, residual_rel=nan, noise_bound=nan, lipschitz=None, certificate=cert, poles=poles,
        quasi_static_min_eig=nan, solve_s=time.perf_counter() - t0, status=prob.status, kind="kalman")


_DESIGNS: dict[tuple, AdaptiveObserverDesign] = {}


def _memo(kind: str, options: AdaptiveDesignOptions | None, model: LPVModel | None, make) -> AdaptiveObserverDesign:
    """One design per (kind, options, vehicle model, speed range, sensor noise) and process; at most 8 kept.

    The noise is part of the key because it follows the vehicle's channel ranges, which follow its design range
    (:func:`ptw_env.sensors.channel_ranges`), not only its model: two files of one model with different design
    ranges (the robot bicycle's preset and its data folder's file) shared a design, so ``estimate`` on one ride
    gave front scales 0.2 or 1.9 depending on which vehicle a process had designed for first."""
    o = AdaptiveDesignOptions() if options is None else options
    m = model_for(o, model)
    key = (kind, o, m.vehicle.identity()["model_sha256"], m.vmin, m.vmax, tuple(o.noise_std(m.vehicle).tolist()))
    if key not in _DESIGNS:
        if len(_DESIGNS) >= 8:
            _DESIGNS.pop(next(iter(_DESIGNS)))
        _DESIGNS[key] = make(model=m, options=o)
    return _DESIGNS[key]


def default_design(options: AdaptiveDesignOptions | None = None, model: LPVModel | None = None) -> AdaptiveObserverDesign:
    """:func:`design_adaptive_observer` for ``options`` on ``model`` (defaults: default options, the reference
    scooter's model), solved once per process and reused."""
    return _memo("theorem2", options, model, design_adaptive_observer)


def default_kalman_design(options: AdaptiveDesignOptions | None = None,
                          model: LPVModel | None = None) -> AdaptiveObserverDesign:
    """:func:`kalman_design` for ``options`` on ``model`` (defaults as :func:`default_design`), computed once per
    process and reused."""
    return _memo("kalman", options, model, kalman_design)


def design_for_vehicle(vehicle: Vehicle, options: AdaptiveDesignOptions | None = None, kind: str = "kalman",
                       speeds: np.ndarray | None = None) -> AdaptiveObserverDesign:
    """The observer design for ``vehicle``: over its :attr:`~ptw_env.vehicle.Vehicle.control_range`, else, when
    that has no common Lyapunov matrix (one P for both vertices of a wide range, e.g. sharp1971's Kalman gains
    over 6-30 m/s) and ``speeds`` [m/s] are given (a log's measured speeds), over their span
    ``[min, max]`` (within the vehicle's valid range): the certificate only has to cover the speeds ridden.

    ``kind``: ``"kalman"`` (:func:`default_kalman_design`) or ``"theorem2"`` (:func:`default_design`). The
    options' ``vmin``/``vmax`` must be None (the range is chosen here).

    Raises
    ------
    AdaptiveDesignError
        Infeasible over both ranges; the message names both.
    LPVModelError
        The vehicle's rows do not have the structure of model.md.
    """
    o = AdaptiveDesignOptions() if options is None else options
    if o.vmin is not None or o.vmax is not None:
        raise AdaptiveDesignOptionError("design_for_vehicle chooses the speed range: leave vmin, vmax at None")
    make = {"kalman": default_kalman_design, "theorem2": default_design}.get(kind)
    if make is None:
        raise AdaptiveDesignOptionError(f"kind must be 'kalman' or 'theorem2', got {kind!r}")
    try:
        return make(o, build_lpv_model(vehicle))
    except AdaptiveDesignError as exc:
        first = exc
    sp = None if speeds is None else np.asarray(speeds, dtype=float)
    sp = None if sp is None or not np.any(np.isfinite(sp)) else sp[np.isfinite(sp)]
    if sp is None:
        raise first
    lo = max(float(vehicle.vmin), math.floor(2.0 * float(sp.min())) / 2.0)
    hi = min(float(vehicle.vmax), math.ceil(2.0 * float(sp.max())) / 2.0)
    if hi - lo < 0.5:  # a constant speed: a half-metre-per-second band around it
        lo, hi = max(float(vehicle.vmin), lo - 0.25), min(float(vehicle.vmax), hi + 0.25)
    try:
        return make(o, build_lpv_model(vehicle, lo, hi))
    except AdaptiveDesignError as exc:
        raise AdaptiveDesignError(exc.stage, f"over {vehicle.name}'s design range {vehicle.control_range} m/s "
                                  f"({first.cause}) and over the log's speeds [{lo:g}, {hi:g}] m/s ({exc.cause})") from None


__all__ = [
    "AdaptiveDesignError",
    "AdaptiveDesignOptionError",
    "AdaptiveDesignOptions",
    "AdaptiveObserverDesign",
    "Certificate",
    "CertificateEntry",
    "DEFAULT_PROCESS_STD",
    "LipschitzBound",
    "default_design",
    "default_kalman_design",
    "design_for_vehicle",
    "design_adaptive_observer",
    "kalman_design",
    "lipschitz_bound",
    "model_for",
]
