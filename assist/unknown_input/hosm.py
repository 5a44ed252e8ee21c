"""Unknown-input high-order sliding-mode observer (UIHOSMO) of the roll angle and rider torque.

Nehaoua, Ichalal, Arioui, Davila, Mammar, Fridman [1]_, sec. III, on the
reference scooter, with the unknown inputs ``zeta`` (default ``[phi, tau]``,
``phi`` rearranged as an input, :mod:`assist.unknown_input.observability`) and the outputs
the structural analysis finds. Both work on the reference scooter with
model.md's corrected ``a45 = +3.665 vx`` (``ptw-assist observability``): the
paper's ``[delta, r]`` is strongly detectable at every speed (4 stable zeros,
the slowest -0.43 1/s at 5 m/s, -2.14 1/s at 100 km/h), as the paper says;
the default ``[delta, r, phi_dot]`` (the IMU's roll-rate gyro added) has no
invariant zero at all (strongly observable), converges faster and
differentiates ``delta`` once less for ``phi``, which matters with sensor
noise (``scripts/eval_hosm.py``, lane change at 100 km/h, errors after a 2 s
warm-up, reference-log noise: phi 0.74 deg / tau 2.84 N m RMSE with three
outputs, 1.36 deg / 5.10 N m with ``[delta, r]`` and Lipschitz constants
(30, 3) tuned on another seed; noise-free 0.08 / 1.76 and 0.45 / 2.06, the
pair's error still decaying with its -2.14 1/s zero). With Table IV's printed ``-3.665 vx`` the paper's pair had a real
unstable zero (+0.7 to +3.5 1/s) and could not be used. The model (design
speed ``v0``):

.. math::

    \\dot x = A x + B u + D \\zeta, \\qquad y = C x

(``x`` the 7 states without ``phi``; ``u`` the known inputs, none when
``tau`` is unknown).

Observer ([1]_ eqs. 6-7 and 11-12, general form)
-------------------------------------------------
1. **Luenberger part**: ``z' = A z + B u + L (y - C z)`` with ``eig(A - L C)``
   at the requested poles ([1]_: ``-15, -30, -45, -60, -150, -165, -180``,
   :data:`PAPER_POLES`). The error ``e = x - z`` obeys
   ``e' = Ã e + D zeta``, ``e_y = y - C z = C e``, ``Ã = A - L C``.
2. **Coordinate change** ``xi = T e``, ``T = [T1; T2]``. ``T1`` stacks
   ``C_i Ã^k`` for ``k = 0..r_i - 1`` (``r_i`` the relative degree of output
   ``i``), skipping rows dependent on earlier ones (lowest derivatives first):
   ``xi_1 = T1 e`` are the output errors and their derivatives, the *clean*
   coordinates. ``T2`` (``n - r_T`` rows) must satisfy ``T2 D = 0``, so that
   ``xi_2' = A21 xi_1 + A22 xi_2`` carries no unknown input ([1]_ eq. 11;
   **correction**: [1]_ writes the closed loop as ``A_p - C_p L_p``; it is
   ``A_p - L_p C_p``). [1]_ leaves ``T2`` open ("a possible choice ... can
   be found in [36]"); we take

   .. math::

       T_2 = P\\,(I - D \\bar D^{+} R), \\qquad R = [C_i \\tilde A^{r_i - 1}]_i,

   with ``P`` a constant selection of the physical states that completes
   ``T1`` (:func:`complement_selection`; ``[vy, Fyf, Fyr]`` for the default
   outputs) and ``Dbar^+`` the left inverse of step 4 (``T2 D = P D - P D = 0``).
   So ``xi_2`` is the error of the unmeasured physical states minus the
   unknown-input effect the reconstruction accounts for, which is what the
   scheduled variant integrates. For a square system (``p = q``)
   ``eig(A22)`` are the invariant zeros of ``(A, D, C)`` whatever ``T2``
   (stable by strong detectability). With redundant outputs (``p > q``)
   ``eig(A22)`` depend on the left inverse (``ui_weights``); optionally the
   UI-free combinations ``W`` (left null space of ``Dbar``) place them:
   ``T2 <- T2 - K W R`` keeps ``T2 D = 0`` and gives
   ``eig(A22 - K W Gamma Q2)`` (``Q2`` the last columns of ``T^-1``,
   ``Gamma = [C_i Ã^(r_i)]_i``), at the price of gains that grow when the
   pair is weakly observable.
3. **Differentiator injection**: a Levant differentiator of order
   ``r_i + k`` per output on ``e_y,i`` (:mod:`assist.unknown_input.differentiator`; [1]_
   eqs. 13-14 with ``k = 1``) gives ``theta_1 = T1 e`` in finite time and the
   ``r_i``-th derivatives ``v_r``; ``theta_2' = A21 theta_1 + A22 theta_2``
   integrates the rest, and ``x_hat = z + T^-1 theta``.
4. **Unknown-input reconstruction** ([1]_ eq. 15):
   ``zeta_hat = Dbar^+ (v_r - Gamma T^-1 theta)``, ``Dbar = [C_i Ã^(r_i-1) D]_i``
   (``Dbar^-1`` when square, a weighted left inverse otherwise).

**Corrections to [1]_** besides the above (each checked against the
structure the equations must have):

* eq. (5) lists ``x_p = [vy, r, phi_dot, delta_dot, Fyf, Fyr]``, six states,
  while ``n = 7`` and ``y_p = delta = C_p x_p``: ``delta`` belongs to ``x_p``;
* eq. (9) reconstructs ``phi`` from ``v_4`` (the third derivative of
  ``e_y``), but with ``r = 2`` the unknown input appears in the second,
  ``xi_12' = e_y''`` = ``v_3`` (eq. 15 uses ``v_{1,3}`` and ``v_{2,2}``,
  consistently with ``r = [2, 1]``); and it sums ``a_3 theta_21 ... a_7
  theta_27`` over seven ``theta_2`` entries where eq. (6) has ``n - r = 5``
  (``theta_21 .. theta_25``);
* eqs. (6) and (9) carry the known torque ``b_11 tau_r``, ``b_12 tau_r`` in
  the ``xi`` dynamics, i.e. they transform ``x``; the observer differentiates
  the error ``e = x - z`` whose ``z`` already integrates ``B_p tau_r``
  (eq. 7), so those terms cancel and are dropped here (keeping them would
  count the torque twice);
* the relative-degree conditions start at ``j = 0`` (:mod:`assist.unknown_input.structure`);
  the differentiator corrections are listed in :mod:`assist.unknown_input.differentiator`.

Discretisation (sampled at ``dt``; :meth:`UIHOSMO.update` receives ``y_k``)
--------------------------------------------------------------------------
``z`` and ``theta_2`` are propagated *exactly* over a period: ``u`` held
(zero-order hold, as the environment does) and ``y``, ``theta_1``
interpolated linearly between samples (first-order hold),
``z_k = Phi z_{k-1} + Gu u_{k-1} + G0 y_{k-1} + G1 (y_k - y_{k-1})`` from one
matrix exponential (the fast Luenberger poles, ``|lambda| dt`` up to 1.8,
rule out Euler). The differentiators are the Livne-Levant discretisation.

Gain-scheduled (LPV) variant, :class:`ScheduledUIHOSMO`
------------------------------------------------------
The paper's stated weakness is the fixed design speed. The scheduled observer
uses ``A(vx)``, ``D(vx)`` at the measured speed in every block but keeps one
constant ``L`` (checked Hurwitz over the speed range): then the clean rows
``C_i Ã^k`` (``k < r_i``) do not depend on ``vx`` for the scooter (its
``delta`` row is ``delta' = delta_dot``), so ``theta_1`` stays exact while
``vx`` varies. The unclean part is carried in *physical* coordinates ``P e``
(``P`` a constant selection of states completing ``T1``), which makes a
time-varying ``T2(vx)`` (and its neglected derivative) unnecessary:

.. math::

    \\dot{\\hat e}_2 = P \\tilde A(v_x) \\hat e + P D(v_x) \\hat\\zeta
        + G(v_x) W (v_r - \\Gamma \\hat e), \\qquad
    \\hat\\zeta = \\bar D^+(v_x) (v_r - \\Gamma(v_x) \\hat e),

with ``e_hat = Q(vx) [theta_1; e2_hat]``. For a constant speed this is the
fixed observer written in other coordinates (same eigenvalues), a test checks
it. Matrices are precomputed on a speed grid and interpolated linearly.

References
----------
.. [1] L. Nehaoua, D. Ichalal, H. Arioui, J. Davila, S. Mammar, L. Fridman,
   "An unknown input HOSM approach to estimate lean and steering motorcycle
   dynamics", IEEE Trans. Vehicular Technology 63(7), 3116-3127, 2014.
.. [2] L. Fridman, A. Levant, J. Davila, "Observation of linear systems with
   unknown inputs via high-order sliding-modes", Int. J. Systems Science
   38(10), 773-791, 2007.

Length (about 950 lines): one observer in two forms (fixed and speed-scheduled) sharing the design,
the coordinate change and the reconstruction; a third of it is this docstring, which records each
correction of the paper.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np
import scipy.linalg as sla
from scipy.optimize import linear_sum_assignment
from scipy.signal import place_poles

from ptw_env.vehicle import PHI, REFERENCE_SCOOTER, STATE_NAMES, Vehicle

from assist.unknown_input.differentiator import LevantDifferentiator
from assist.unknown_input.observability import UNKNOWN_INPUT_NAMES, ObservabilityError, PTWTriplet, analyse_triplet, ptw_triplet

#: Luenberger poles of [1]_ sec. IV-C [1/s].
PAPER_POLES: tuple[float, ...] = (-15.0, -30.0, -45.0, -60.0, -150.0, -165.0, -180.0)
#: Differentiator Lipschitz constant of [1]_ sec. IV-C (both channels).
PAPER_LIPSCHITZ = 5000.0
#: Default differentiator constants of the default outputs (orders 3, 2, 2 at 100 Hz): the coordinate-descent
#: tuning of ``scripts/eval_hosm.py`` on a training ride (double lane change at 100 km/h, seed 1, default
#: sensors) over 1, 3, 10, ..., 1000. Units output / s^(order+1): delta rad/s^4, r and phi_dot rad/s^3. The
#: rider torque is held over each sample, so |y^(order+1)| has no finite bound and the theory's L does not
#: exist; L trades sampling lag against noise.
DEFAULT_LIPSCHITZ: Mapping[str, float] = MappingProxyType({"delta": 30.0, "r": 10.0, "phi_dot": 10.0})
#: Slowest decay [1/s] accepted for the unclean part (an eigenvalue at 0 is an integrator, not an observer).
MIN_DECAY = 1e-3
#: Design speed of [1]_ (100 km/h) [m/s].
PAPER_SPEED = 100.0 / 3.6
#: Ride-log column of each output name (shared/spec/logs.md).
LOG_COLUMNS: Mapping[str, str] = {"delta": "delta", "delta_dot": "delta_rate", "r": "yaw_rate",
                                  "phi_dot": "roll_rate", "ay": "ay"}


class HOSMDesignError(ValueError):
    """An observer configuration that cannot be designed (not strongly detectable, bad poles, ...)."""


class HOSMInputError(ValueError):
    """A measurement, known input or speed given to an observer that is unusable."""


def _tuple_floats(name: str, v, allow_none: bool = False) -> tuple[float, ...] | None:
    if v is None and allow_none:
        return None
    try:
        out = tuple(float(a) for a in np.atleast_1d(np.asarray(v, dtype=float)))
    except (TypeError, ValueError):
        raise HOSMDesignError(f"{name} must be numbers, got {v!r}") from None
    if not all(math.isfinite(a) for a in out):
        raise HOSMDesignError(f"{name} must be finite, got {v!r}")
    return out


@dataclass(frozen=True)
class HOSMConfig:
    """Settings of the UIHOSMO (frozen; unknown fields are rejected by the constructor).

    Attributes
    ----------
    outputs : tuple of str
        Measured outputs (state names of model.md or ``"ay"``), default ``("delta", "r", "phi_dot")``.
    unknown_inputs : tuple of str
        ``"phi"`` (rearranged) and/or ``"tau"``.
    design_speed : float
        Speed [m/s] of the fixed design (default 100 km/h, [1]_).
    poles : tuple of float
        Eigenvalues of ``A - L C`` [1/s], one per state (default :data:`PAPER_POLES`).
    zero_dynamics_poles : tuple of float or None
        With redundant outputs (``p > q``) only: eigenvalues [1/s] to place
        ``eig(A22)`` at through the UI-free combinations (``n - r_T`` values).
        Default None: no such injection, ``eig(A22)`` follow from
        ``ui_weights`` (reported; the design fails if one is unstable). A
        square system's ``A22`` eigenvalues are its invariant zeros.
    extra_order : int
        ``k`` of [1]_: output ``i`` gets a differentiator of order ``r_i + k``.
    lipschitz : tuple of float or None
        Differentiator constant per output [output unit / s^(order+1)]; one
        value is used for every output. Default None: :data:`DEFAULT_LIPSCHITZ`
        by output name (tuned for ``extra_order = 1`` at 100 Hz; an output
        without an entry must be given explicitly). The paper's value,
        :data:`PAPER_LIPSCHITZ` = 5000 for every channel, is far too large at
        100 Hz: the sampling error ``L dt^(n+1-i)`` of the derivative used in
        the reconstruction is then ``0.5 mu_i`` rad/s^2.
    ui_weights : tuple of float or None
        Weights of the rows of ``Dbar`` in the unknown-input least squares
        (``p > q``); default equal.
    dt : float
        Sampling period [s].
    roll_from_sine : bool
        Report ``phi_hat = arcsin(zeta_phi)`` (default) instead of
        ``zeta_phi``. The reconstruction (step 4) uses only the mechanical rows
        of ``D`` (``Dbar = R D`` with ``R`` made of rows of ``delta_dot``,
        ``r``, ``phi_dot`` and outputs), where the roll angle enters through
        gravity, ``a51 sin(phi)``, ``a61 sin(phi)`` in the nonlinear plant
        (model.md); the camber terms ``a71 phi``, ``a81 phi`` act in the tire
        rows, i.e. only on the unclean part. So ``zeta_phi`` estimates
        ``sin(phi)``: at 38 deg of roll (a 100 m circle at 100 km/h) taking it
        as ``phi`` is 2.7 deg off.
    """

    outputs: tuple[str, ...] = ("delta", "r", "phi_dot")
    unknown_inputs: tuple[str, ...] = ("phi", "tau")
    design_speed: float = PAPER_SPEED
    poles: tuple[float, ...] = PAPER_POLES
    zero_dynamics_poles: tuple[float, ...] | None = None
    extra_order: int = 1
    lipschitz: tuple[float, ...] | None = None
    ui_weights: tuple[float, ...] | None = None
    dt: float = 0.01
    roll_from_sine: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "outputs", tuple(str(o) for o in self.outputs))
        object.__setattr__(self, "unknown_inputs", tuple(str(u) for u in self.unknown_inputs))
        for u in self.unknown_inputs:
            if u not in UNKNOWN_INPUT_NAMES:
                raise HOSMDesignError(f"unknown_inputs: {u!r} is not one of {UNKNOWN_INPUT_NAMES}")
        object.__setattr__(self, "poles", _tuple_floats("poles", self.poles))
        object.__setattr__(self, "zero_dynamics_poles", _tuple_floats("zero_dynamics_poles", self.zero_dynamics_poles, True))
        if self.lipschitz is None:
            missing = [o for o in self.outputs if o not in DEFAULT_LIPSCHITZ]
            if missing:
                raise HOSMDesignError(f"lipschitz: no default for output(s) {missing}; give one value per output")
            lip = tuple(DEFAULT_LIPSCHITZ[o] for o in self.outputs)
        else:
            lip = _tuple_floats("lipschitz", self.lipschitz)
        if len(lip) == 1:
            lip = lip * len(self.outputs)
        if len(lip) != len(self.outputs) or any(v <= 0 for v in lip):
            raise HOSMDesignError(f"lipschitz must be one positive value or one per output {self.outputs}, got {self.lipschitz!r}")
        object.__setattr__(self, "lipschitz", lip)
        w = _tuple_floats("ui_weights", self.ui_weights, True)
        if w is not None and (len(w) != len(self.outputs) or any(v <= 0 for v in w)):
            raise HOSMDesignError(f"ui_weights must be one positive weight per output {self.outputs}, got {self.ui_weights!r}")
        object.__setattr__(self, "ui_weights", w)
        if any(p >= 0 for p in self.poles):
            raise HOSMDesignError(f"poles must have negative real parts, got {self.poles}")
        if self.zero_dynamics_poles is not None and any(p >= 0 for p in self.zero_dynamics_poles):
            raise HOSMDesignError(f"zero_dynamics_poles must be negative, got {self.zero_dynamics_poles}")
        if not isinstance(self.roll_from_sine, bool):
            raise HOSMDesignError(f"roll_from_sine must be True or False, got {self.roll_from_sine!r}")
        if not isinstance(self.extra_order, int) or isinstance(self.extra_order, bool) or not 0 <= self.extra_order <= 3:
            raise HOSMDesignError(f"extra_order must be an integer in [0, 3], got {self.extra_order!r}")
        for nm in ("design_speed", "dt"):
            v = getattr(self, nm)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise HOSMDesignError(f"{nm} must be a positive number, got {v!r}")


# ---------------------------------------------------------------------------
# linear-algebra helpers
# ---------------------------------------------------------------------------
def _rank_tol(M: np.ndarray) -> float:
    return 1e-9 * max(1.0, float(np.linalg.norm(M, 2))) if M.size else 0.0


def _left_null(M: np.ndarray) -> np.ndarray:
    """Orthonormal rows spanning ``{w : w M = 0}``."""
    if M.shape[1] == 0:
        return np.eye(M.shape[0])
    U, s, _ = np.linalg.svd(M, full_matrices=True)
    rk = int(np.sum(s > _rank_tol(M)))
    return U[:, rk:].T


def _row_basis(M: np.ndarray) -> np.ndarray:
    if M.shape[0] == 0:
        return M.copy()
    _, s, Vt = np.linalg.svd(M, full_matrices=False)
    rk = int(np.sum(s > _rank_tol(M)))
    return Vt[:rk]


def _exact_discretisation(F: np.ndarray, Gzoh: np.ndarray, Gfoh: np.ndarray, dt: float):
    """``x_k = Phi x_{k-1} + Gz u_{k-1} + G0 w_{k-1} + G1 (w_k - w_{k-1})`` for
    ``x' = F x + Gzoh u + Gfoh w`` with ``u`` held and ``w`` linear over the period.

    Blocks of ``expm([[F, Gz, Gf, 0], [0, 0, 0, 0], [0, 0, 0, I/dt], [0, 0, 0, 0]] dt)``.
    """
    n = F.shape[0]
    mz, mf = Gzoh.shape[1], Gfoh.shape[1]
    N = n + mz + 2 * mf
    M = np.zeros((N, N))
    M[:n, :n] = F
    M[:n, n : n + mz] = Gzoh
    M[:n, n + mz : n + mz + mf] = Gfoh
    M[n + mz : n + mz + mf, n + mz + mf :] = np.eye(mf) / dt
    E = sla.expm(M * dt)
    return E[:n, :n], E[:n, n : n + mz], E[:n, n + mz : n + mz + mf], E[:n, n + mz + mf :]


def _place(F: np.ndarray, H: np.ndarray, poles: Sequence[float], what: str) -> np.ndarray:
    """``K`` with ``eig(F - K H) = poles`` (observer form), via scipy's place_poles on the dual."""
    try:
        with warnings.catch_warnings():  # YT iterations may stop early; the result is checked below
            warnings.simplefilter("ignore", UserWarning)
            res = place_poles(F.T, H.T, np.asarray(poles, dtype=float))
    except ValueError as exc:
        raise HOSMDesignError(f"{what}: pole placement failed ({exc})") from None
    K = res.gain_matrix.T
    got = np.linalg.eigvals(F - K @ H)
    want = np.asarray(poles, dtype=complex)
    cost = np.abs(got[:, None] - want[None, :])
    i, j = linear_sum_assignment(cost)
    if np.max(cost[i, j]) > 1e-3 * max(1.0, np.max(np.abs(want))):
        raise HOSMDesignError(f"{what}: requested poles {list(want.real)} not reached (got {got}); the pair is not observable")
    return K


# ---------------------------------------------------------------------------
# design
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class HOSMDesign:
    """A designed UIHOSMO at one speed (see the module docstring for the symbols).

    Attributes
    ----------
    config : HOSMConfig
    triplet : PTWTriplet
        ``A, B, D, C`` at :attr:`vx`.
    L : ndarray (n, p)
        Luenberger gain.
    Atil : ndarray (n, n)
        ``Ã = A - L C``.
    T, T_inv : ndarray (n, n)
        ``xi = T e``; the first ``r_T`` rows are ``T1``.
    A11, A12, A21, A22 : ndarray
        Blocks of ``T Ã T^-1``.
    Dbar : ndarray (p, q)
        Decoupling matrix ``[C_i Ã^(r_i-1) D]_i``.
    Dbar_pinv : ndarray (q, p)
        Its (weighted) left inverse.
    Gamma : ndarray (p, n)
        ``[C_i Ã^(r_i)]_i``.
    W : ndarray (p - q, p)
        Left null space of ``Dbar`` (UI-free combinations; empty when square).
    theta1_index : tuple of (int, int)
        ``(output index i, derivative k)`` of each ``theta_1`` entry.
    relative_degree, orders : tuple of int
        Per output: ``r_i`` and differentiator order ``r_i + k``.
    zeros : ndarray
        Invariant zeros of ``(A, D, C)``.
    luenberger_eigs, zero_dynamics_eigs : ndarray
        ``eig(A - L C)`` and ``eig(A22)``.
    disc_z, disc_theta : tuple of ndarray
        Exact discretisations (``Phi, Gu, G0, G1``) of ``z`` and ``theta_2``.
    """

    config: HOSMConfig
    vx: float
    triplet: PTWTriplet
    L: np.ndarray
    Atil: np.ndarray
    T: np.ndarray
    T_inv: np.ndarray
    A11: np.ndarray
    A12: np.ndarray
    A21: np.ndarray
    A22: np.ndarray
    Dbar: np.ndarray
    Dbar_pinv: np.ndarray
    Gamma: np.ndarray
    W: np.ndarray
    theta1_index: tuple[tuple[int, int], ...]
    relative_degree: tuple[int, ...]
    orders: tuple[int, ...]
    zeros: np.ndarray
    luenberger_eigs: np.ndarray
    zero_dynamics_eigs: np.ndarray
    disc_z: tuple[np.ndarray, ...]
    disc_theta: tuple[np.ndarray, ...]

    @property
    def n(self) -> int:
        return self.triplet.n

    @property
    def r_total(self) -> int:
        return len(self.theta1_index)

    def summary(self) -> dict[str, Any]:
        """JSON-friendly description (outputs, relative degrees, orders, eigenvalues)."""
        cplx = lambda a: [[float(z.real), float(z.imag)] for z in np.sort_complex(np.asarray(a, dtype=complex))]  # noqa: E731
        return {
            "outputs": list(self.triplet.outputs),
            "unknown_inputs": list(self.triplet.unknown_inputs),
            "design_speed_mps": self.vx,
            "relative_degree": list(self.relative_degree),
            "differentiator_orders": list(self.orders),
            "lipschitz": list(self.config.lipschitz),
            "clean_coordinates": [f"d^{k} e_{self.triplet.outputs[i]}" for i, k in self.theta1_index],
            "invariant_zeros": cplx(self.zeros),
            "luenberger_eigs": cplx(self.luenberger_eigs),
            "zero_dynamics_eigs": cplx(self.zero_dynamics_eigs),
        }


def _weighted_left_inverse(Dbar: np.ndarray, weights: Sequence[float] | None) -> np.ndarray:
    Wt = np.diag(np.ones(Dbar.shape[0]) if weights is None else np.asarray(weights, dtype=float) ** 2)
    return np.linalg.solve(Dbar.T @ Wt @ Dbar, Dbar.T @ Wt)


def complement_selection(T1: np.ndarray) -> np.ndarray:
    """Rows of the identity (a constant selection ``P`` of states) with ``[T1; P]`` best conditioned (greedy)."""
    n = T1.shape[1]
    chosen: list[int] = []
    for _ in range(n - T1.shape[0]):
        best, best_s = -1, -1.0
        for j in range(n):
            if j in chosen:
                continue
            M = np.vstack([T1, np.eye(n)[chosen + [j]]])
            sv = np.linalg.svd(M, compute_uv=False)[-1]
            if sv > best_s:
                best, best_s = j, sv
        chosen.append(best)
    return np.eye(n)[sorted(chosen)]


def _clean_rows(Atil: np.ndarray, C: np.ndarray, r: Sequence[int]) -> tuple[np.ndarray, tuple[tuple[int, int], ...]]:
    """``T1``: rows ``C_i Ã^k`` (``k < r_i``), lowest derivatives first, skipping dependent rows."""
    rows: list[np.ndarray] = []
    idx: list[tuple[int, int]] = []
    for k in range(max(r)):
        for i, ri in enumerate(r):
            if k >= ri:
                continue
            row = C[i] @ np.linalg.matrix_power(Atil, k)
            trial = np.vstack(rows + [row])
            if np.linalg.matrix_rank(trial, tol=1e-9 * max(1.0, np.linalg.norm(trial, 2))) == len(rows) + 1:
                rows.append(row)
                idx.append((i, k))
    return np.array(rows), tuple(idx)


def _structure(tr: PTWTriplet):
    """Relative degrees, decoupling data and zeros of a triplet; raises if the observer cannot exist."""
    rep = analyse_triplet(tr)
    where = f"outputs {tr.outputs}, unknown inputs {tr.unknown_inputs}, vx = {tr.vx:g} m/s"
    if not rep.left_invertible:
        raise HOSMDesignError(f"{where}: the unknown inputs are not left-invertible from the outputs")
    if not rep.strongly_detectable:  # an unstable or marginal zero (ptw_env.spectrum)
        raise HOSMDesignError(f"{where}: not strongly detectable ({rep.reason}); "
                              "see `ptw-assist observability` for measurement sets that work")
    if any(r is None for r in rep.relative_degree):
        raise HOSMDesignError(f"{where}: an output has no relative degree (relative degrees {rep.relative_degree})")
    if rep.decoupling_rank != tr.D.shape[1]:
        raise HOSMDesignError(f"{where}: the decoupling matrix has rank {rep.decoupling_rank} < {tr.D.shape[1]} unknown "
                              "inputs: they cannot be reconstructed from the r_i-th output derivatives")
    return rep


def design_uihosmo(config: HOSMConfig | None = None, vehicle: Vehicle | None = None, vx: float | None = None) -> HOSMDesign:
    """Design the UIHOSMO of [1]_ at ``vx`` (default ``config.design_speed``) [m/s].

    Raises :class:`HOSMDesignError` when the case is not strongly detectable,
    the decoupling matrix lacks rank, or the poles cannot be placed.
    """
    cfg = HOSMConfig() if config is None else config
    v0 = float(cfg.design_speed if vx is None else vx)
    try:
        tr = ptw_triplet(v0, cfg.unknown_inputs, cfg.outputs, vehicle)
    except ObservabilityError as exc:
        raise HOSMDesignError(str(exc)) from None
    n = tr.n
    if len(cfg.poles) != n:
        raise HOSMDesignError(f"poles: {len(cfg.poles)} given, the model has {n} states {tr.state_names}")
    rep = _structure(tr)
    r = tuple(int(x) for x in rep.relative_degree)
    L = _place(tr.A, tr.C, cfg.poles, "Luenberger gain")
    Atil = tr.A - L @ tr.C
    T1, idx = _clean_rows(Atil, tr.C, r)
    rT = T1.shape[0]
    Rlast = np.array([tr.C[i] @ np.linalg.matrix_power(Atil, ri - 1) for i, ri in enumerate(r)])
    Dbar = Rlast @ tr.D
    Gamma = Rlast @ Atil
    Dpinv = _weighted_left_inverse(Dbar, cfg.ui_weights)
    # T2 = P (I - D Dbar^+ R_last): the unmeasured physical states P e minus the part of the unknown-input
    # effect that the reconstruction removes; T2 D = P D - P D Dbar^+ Dbar = 0 (module docstring)
    P = complement_selection(T1)
    T2 = P - P @ tr.D @ Dpinv @ Rlast
    T = np.vstack([T1, T2])
    if np.linalg.cond(T) > 1e12:
        raise HOSMDesignError("coordinate change T = [T1; T2] is singular")
    W = _left_null(Dbar)  # UI-free combinations of the r_i-th derivatives (empty when p == q)
    zpoles = cfg.zero_dynamics_poles
    if zpoles is not None:
        if W.shape[0] == 0:
            raise HOSMDesignError("zero_dynamics_poles given for a square system: its A22 eigenvalues are the invariant "
                                  f"zeros {rep.zeros} and cannot be moved")
        if len(zpoles) != n - rT:
            raise HOSMDesignError(f"zero_dynamics_poles: {len(zpoles)} given, the unclean part has {n - rT} states")
        Q2 = np.linalg.inv(T)[:, rT:]
        K = _place(T2 @ Atil @ Q2, W @ Gamma @ Q2, zpoles, "zero-dynamics injection")
        T2 = T2 - K @ W @ Rlast
        T = np.vstack([T1, T2])
    Tinv = np.linalg.inv(T)
    Ah = T @ Atil @ Tinv
    A11, A12, A21, A22 = Ah[:rT, :rT], Ah[:rT, rT:], Ah[rT:, :rT], Ah[rT:, rT:]
    if np.max(np.abs(T2 @ tr.D)) > 1e-8 * max(1.0, np.linalg.norm(T2) * np.linalg.norm(tr.D)):
        raise HOSMDesignError("internal: T2 D != 0")  # pragma: no cover
    zd = np.linalg.eigvals(A22) if A22.size else np.zeros(0, complex)
    if zd.size and np.max(zd.real) >= -MIN_DECAY:
        raise HOSMDesignError(f"unclean part not stable at {v0:g} m/s: eig(A22) = {zd}"
                              + ("" if W.shape[0] == 0 else "; change ui_weights or set zero_dynamics_poles"))
    disc_z = _exact_discretisation(Atil, tr.B, L, cfg.dt)
    disc_t = _exact_discretisation(A22, np.zeros((n - rT, 0)), A21, cfg.dt)
    orders = tuple(ri + cfg.extra_order for ri in r)
    return HOSMDesign(
        config=cfg, vx=v0, triplet=tr, L=L, Atil=Atil, T=T, T_inv=Tinv, A11=A11, A12=A12, A21=A21, A22=A22,
        Dbar=Dbar, Dbar_pinv=Dpinv, Gamma=Gamma, W=W, theta1_index=idx, relative_degree=r, orders=orders,
        zeros=rep.zeros, luenberger_eigs=np.linalg.eigvals(Atil), zero_dynamics_eigs=zd,
        disc_z=disc_z, disc_theta=disc_t,
    )


# ---------------------------------------------------------------------------
# runtime
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class HOSMEstimate:
    """One observer output at a sample instant.

    ``x_hat``: the 8 states of model.md (``phi`` from the unknown-input
    reconstruction when ``phi`` is unknown); ``zeta_hat``: the unknown inputs
    in ``unknown_inputs`` order (rad, N m; the roll angle after the
    ``roll_from_sine`` inversion); ``theta1``: the clean coordinates.
    """

    x_hat: np.ndarray
    zeta_hat: np.ndarray
    theta1: np.ndarray


class _UIObserverBase:
    """Shared bookkeeping: validation of each sample, differentiators, mapping to the 8 states (hook ``_step``)."""

    def __init__(self, tr0: PTWTriplet, cfg: HOSMConfig, orders: Sequence[int], lipschitz: Sequence[float] | None) -> None:
        self.config = cfg
        self.outputs = tr0.outputs
        self.unknown_inputs = tr0.unknown_inputs
        self.known_inputs = tr0.known_inputs
        self.state_names = tr0.state_names
        self._n = tr0.n
        self._p = len(tr0.outputs)
        self._keep = [STATE_NAMES.index(s) for s in tr0.state_names]
        lip = cfg.lipschitz if lipschitz is None else tuple(float(v) for v in lipschitz)
        if len(lip) != self._p:
            raise HOSMDesignError(f"lipschitz: {len(lip)} values for {self._p} outputs")
        self.lipschitz = lip
        self._diffs = [LevantDifferentiator(o, lv, cfg.dt) for o, lv in zip(orders, lip)]
        self._x0: np.ndarray | None = None
        self._k = 0

    def reset(self, x0=None) -> None:
        """Restart; ``x0`` is the initial estimate (8 states of model.md, or the model's
        ``n`` states without ``phi``); default zero."""
        if x0 is None:
            self._x0 = np.zeros(self._n)
        else:
            x0 = np.asarray(x0, dtype=float)
            if x0.shape == (8,):
                x0 = x0[self._keep]
            if x0.shape != (self._n,) or not np.all(np.isfinite(x0)):
                raise HOSMInputError(f"x0 must be 8 finite states or {self._n} states {self.state_names}, got {x0!r}")
            self._x0 = x0.copy()
        for d in self._diffs:
            d.reset()
        self._k = 0
        self._reset_hook()

    def _reset_hook(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _step(self, y: np.ndarray, u: np.ndarray, vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError  # pragma: no cover

    def update(self, y, u=None, vx: float | None = None) -> HOSMEstimate:
        """Process the sample ``y_k`` (outputs in :attr:`outputs` order); ``u`` the known inputs held over
        ``[t_k, t_{k+1})`` (``tau`` [N m] when it is not unknown); ``vx`` the measured speed [m/s]."""
        if self._x0 is None:
            self.reset()
        y = np.asarray(y, dtype=float)
        if y.shape != (self._p,) or not np.all(np.isfinite(y)):
            raise HOSMInputError(f"sample {self._k}: y must be {self._p} finite values {self.outputs}, got {y!r}")
        nu = len(self.known_inputs)
        if nu:
            if u is None:
                raise HOSMInputError(f"sample {self._k}: the known input(s) {self.known_inputs} must be given as u")
            u = np.atleast_1d(np.asarray(u, dtype=float))
            if u.shape != (nu,) or not np.all(np.isfinite(u)):
                raise HOSMInputError(f"sample {self._k}: u must be {nu} finite values {self.known_inputs}, got {u!r}")
        elif u is not None and np.size(u) != 0:
            raise HOSMInputError(f"sample {self._k}: this observer has no known input (all of {UNKNOWN_INPUT_NAMES} "
                                 "that are inputs are unknown); do not pass u")
        else:
            u = np.zeros(0)
        if vx is not None:
            vx = float(vx)
            if not math.isfinite(vx) or vx <= 0:
                raise HOSMInputError(f"sample {self._k}: vx must be a positive speed in m/s, got {vx!r}")
        xr, zeta, th1 = self._step(y, u, vx)
        self._k += 1
        x8 = np.zeros(8)
        x8[self._keep] = xr
        if "phi" in self.unknown_inputs:
            j = self.unknown_inputs.index("phi")
            if self.config.roll_from_sine:
                zeta = zeta.copy()
                zeta[j] = math.asin(min(1.0, max(-1.0, float(zeta[j]))))
            x8[PHI] = zeta[j]
        return HOSMEstimate(x_hat=x8, zeta_hat=zeta, theta1=th1)

    def _differentiate(self, ey: np.ndarray) -> list[np.ndarray]:
        return [d.update(ey[i]) for i, d in enumerate(self._diffs)]


class UIHOSMO(_UIObserverBase):
    """The fixed-speed UIHOSMO of [1]_ (module docstring), run at the sampling rate of its design.

    Parameters
    ----------
    design : HOSMDesign
        From :func:`design_uihosmo`.
    lipschitz : sequence of float, optional
        Overrides ``design.config.lipschitz``.

    The measured speed passed to :meth:`update` is ignored: the design speed
    is used throughout (the paper's observer; see :class:`ScheduledUIHOSMO`).
    """

    def __init__(self, design: HOSMDesign, lipschitz: Sequence[float] | None = None) -> None:
        if not isinstance(design, HOSMDesign):
            raise HOSMDesignError(f"design must be a HOSMDesign, got {type(design).__name__}")
        super().__init__(design.triplet, design.config, design.orders, lipschitz)
        self.design = design
        self.reset()

    def _reset_hook(self) -> None:
        d = self.design
        self._z = self._x0.copy()
        self._theta2 = np.zeros(d.n - d.r_total)
        self._prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def _step(self, y, u, vx):
        d = self.design
        if self._prev is not None:
            y0, u0, th0 = self._prev
            Phi, Gu, G0, G1 = d.disc_z
            self._z = Phi @ self._z + Gu @ u0 + G0 @ y0 + G1 @ (y - y0)
        ey = y - d.triplet.C @ self._z
        V = self._differentiate(ey)
        th1 = np.array([V[i][k] for i, k in d.theta1_index])
        if self._prev is not None:
            Ph, _, H0, H1 = d.disc_theta
            self._theta2 = Ph @ self._theta2 + H0 @ th0 + H1 @ (th1 - th0)
        e_hat = d.T_inv @ np.concatenate([th1, self._theta2])
        vr = np.array([V[i][ri] for i, ri in enumerate(d.relative_degree)])
        zeta = d.Dbar_pinv @ (vr - d.Gamma @ e_hat)
        self._prev = (y, u, th1)
        return self._z + e_hat, zeta, th1


# ---------------------------------------------------------------------------
# gain-scheduled (LPV) variant
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _LPVPoint:
    vx: float
    Q: np.ndarray  # inv([T1; P])
    Dbar_pinv: np.ndarray
    Gamma: np.ndarray
    disc_z: tuple[np.ndarray, ...]
    disc_e2: tuple[np.ndarray, ...]  # Phi, G(theta1, v_r) zoh, -, -
    e2_eigs: np.ndarray


class ScheduledUIHOSMO(_UIObserverBase):
    """Gain-scheduled (LPV) UIHOSMO: the model follows the measured speed (module docstring).

    Parameters
    ----------
    config : HOSMConfig
        As for the fixed observer; ``design_speed`` is where ``L`` is placed.
    vehicle : Vehicle, optional
    speed_range : (float, float), optional
        Scheduling range [m/s] (the speed is clipped to it; :attr:`clipped`
        counts the samples where that happened); default the vehicle's design
        range (:attr:`ptw_env.vehicle.Vehicle.control_range`, 8-33 m/s for the
        reference scooter).
    grid_step : float
        Spacing of the precomputed designs [m/s] (linear interpolation between).
    luenberger_speed : float, optional
        Speed [m/s] at which the constant ``L`` places ``config.poles``.
        Default: the grid speed closest to ``config.design_speed`` whose ``L``
        keeps every mode of ``A(vx) - L C`` decaying faster than ``min_decay``
        over the whole grid (reference scooter, paper's poles, 8-33 m/s:
        21 m/s; ``L`` placed at 100 km/h leaves ``A - L C`` unstable below
        about 22 m/s). The gain closest to the design speed keeps the noise
        propagation of the fixed design; the most robust one (about 13 m/s)
        costs 40 % more roll-angle error with the default sensors.
    min_decay : float
        Required decay rate [1/s] of ``A(vx) - L C`` over the range (default 2).
    lipschitz : sequence of float, optional
        Overrides ``config.lipschitz``.
    """

    def __init__(self, config: HOSMConfig | None = None, vehicle: Vehicle | None = None,
                 speed_range: tuple[float, float] | None = None, grid_step: float = 0.5,
                 luenberger_speed: float | None = None, min_decay: float = 2.0,
                 lipschitz: Sequence[float] | None = None) -> None:
        cfg = HOSMConfig() if config is None else config
        veh = REFERENCE_SCOOTER if vehicle is None else vehicle
        lo, hi = (float(s) for s in (veh.control_range if speed_range is None else speed_range))
        if not (veh.vmin <= lo < hi <= veh.vmax):
            raise HOSMDesignError(f"speed_range must satisfy {veh.vmin} <= lo < hi <= {veh.vmax} m/s, got {speed_range!r}")
        if not (isinstance(grid_step, (int, float)) and 0 < grid_step <= hi - lo):
            raise HOSMDesignError(f"grid_step must be in (0, {hi - lo}] m/s, got {grid_step!r}")
        self.grid = np.linspace(lo, hi, int(round((hi - lo) / grid_step)) + 1)
        if luenberger_speed is None:
            luenberger_speed = self._best_luenberger_speed(cfg, veh, self.grid, float(min_decay))
        base = design_uihosmo(cfg, veh, vx=luenberger_speed)  # L, relative degrees, clean rows
        super().__init__(base.triplet, cfg, base.orders, lipschitz)
        self.base = base
        self.vehicle = veh
        self.speed_range = (lo, hi)
        T1 = base.T[: base.r_total]
        self._T1 = T1
        self._P = complement_selection(T1)
        self.points = [self._point(v) for v in self.grid]
        self.clipped = 0
        self.reset()

    @staticmethod
    def _best_luenberger_speed(cfg: HOSMConfig, veh: Vehicle, grid: np.ndarray, min_decay: float) -> float:
        """Grid speed closest to ``cfg.design_speed`` whose ``L`` keeps every mode of ``A(vx) - L C``
        decaying faster than ``min_decay`` over the grid."""
        As = [ptw_triplet(v, cfg.unknown_inputs, cfg.outputs, veh) for v in grid]
        ok: list[tuple[float, float]] = []
        worst_all = math.inf
        for tr0 in As:
            try:
                L = _place(tr0.A, tr0.C, cfg.poles, "Luenberger gain")
            except HOSMDesignError:
                continue
            worst = max(float(np.max(np.linalg.eigvals(tr.A - L @ tr.C).real)) for tr in As)
            worst_all = min(worst_all, worst)
            if worst <= -min_decay:
                ok.append((abs(tr0.vx - cfg.design_speed), tr0.vx))
        if not ok:
            raise HOSMDesignError(f"no constant Luenberger gain placed on the grid keeps A(vx) - L C decaying faster "
                                  f"than {min_decay} 1/s over {grid[0]:g}-{grid[-1]:g} m/s (best: {-worst_all:.3g} 1/s); "
                                  "narrow speed_range or lower min_decay")
        return min(ok)[1]

    def _point(self, v: float) -> _LPVPoint:
        b, cfg = self.base, self.config
        tr = ptw_triplet(v, cfg.unknown_inputs, cfg.outputs, self.vehicle)
        Atil = tr.A - b.L @ tr.C
        if np.max(np.linalg.eigvals(Atil).real) >= 0:
            raise HOSMDesignError(f"the constant Luenberger gain (placed at {b.vx:g} m/s) does not stabilise A - L C at "
                                  f"{v:g} m/s; narrow speed_range")
        T1, idx = _clean_rows(Atil, tr.C, b.relative_degree)
        if idx != b.theta1_index or np.max(np.abs(T1 - self._T1)) > 1e-8 * max(1.0, np.abs(self._T1).max()):
            raise HOSMDesignError(f"at {v:g} m/s the clean rows C_i (A - L C)^k depend on the speed: the scheduled "
                                  "observer would need their time derivative; use the fixed design")
        rep = _structure(tr)
        r = b.relative_degree
        if tuple(int(x) for x in rep.relative_degree) != r:
            raise HOSMDesignError(f"relative degree changes with speed ({rep.relative_degree} at {v:g} m/s vs {r})")
        Rlast = np.array([tr.C[i] @ np.linalg.matrix_power(Atil, ri - 1) for i, ri in enumerate(r)])
        Dbar, Gamma = Rlast @ tr.D, Rlast @ Atil
        Dp = _weighted_left_inverse(Dbar, cfg.ui_weights)
        W = _left_null(Dbar)
        P = self._P
        Q = np.linalg.inv(np.vstack([T1, P]))
        rT = T1.shape[0]
        Q1, Q2 = Q[:, :rT], Q[:, rT:]
        Mproj = Atil - tr.D @ Dp @ Gamma  # e' with zeta replaced by its reconstruction
        F = P @ Mproj @ Q2
        H1 = P @ Mproj @ Q1
        H2 = P @ tr.D @ Dp
        if cfg.zero_dynamics_poles is not None and W.shape[0] and F.size:
            K = _place(F, W @ Gamma @ Q2, cfg.zero_dynamics_poles, f"zero-dynamics injection at {v:g} m/s")
            F = F - K @ W @ Gamma @ Q2
            H1 = H1 - K @ W @ Gamma @ Q1
            H2 = H2 + K @ W
        eig = np.linalg.eigvals(F) if F.size else np.zeros(0, complex)
        if eig.size and np.max(eig.real) >= -MIN_DECAY:
            raise HOSMDesignError(f"unclean part unstable at {v:g} m/s: eigenvalues {eig}")
        disc_z = _exact_discretisation(Atil, tr.B, b.L, cfg.dt)
        disc_e2 = _exact_discretisation(F, np.zeros((F.shape[0], 0)), np.hstack([H1, H2]), cfg.dt)
        return _LPVPoint(vx=v, Q=Q, Dbar_pinv=Dp, Gamma=Gamma, disc_z=disc_z, disc_e2=disc_e2, e2_eigs=eig)

    def _reset_hook(self) -> None:
        self._z = self._x0.copy()
        self._e2 = self._P @ np.zeros(self._n)
        self._prev = None
        self._last_vx = self.base.vx

    def _interp(self, vx: float):
        lo, hi = self.speed_range
        if vx < lo or vx > hi:
            self.clipped += 1
        v = min(max(vx, lo), hi)
        g = self.grid
        j = int(min(max(np.searchsorted(g, v) - 1, 0), len(g) - 2))
        w = (v - g[j]) / (g[j + 1] - g[j])
        a, b = self.points[j], self.points[j + 1]
        mix = lambda x, y: (1 - w) * x + w * y  # noqa: E731
        return a, b, w, mix

    def _step(self, y, u, vx):
        if vx is None:
            raise HOSMInputError(f"sample {self._k}: the scheduled observer needs the measured speed vx")
        C = self.base.triplet.C
        if self._prev is not None:
            y0, u0, w0, vx0 = self._prev
            a, b, w, mix = self._interp(vx0)
            Phi = mix(a.disc_z[0], b.disc_z[0])
            Gu, G0, G1 = (mix(a.disc_z[i], b.disc_z[i]) for i in (1, 2, 3))
            self._z = Phi @ self._z + Gu @ u0 + G0 @ y0 + G1 @ (y - y0)
        ey = y - C @ self._z
        V = self._differentiate(ey)
        th1 = np.array([V[i][k] for i, k in self.base.theta1_index])
        vr = np.array([V[i][ri] for i, ri in enumerate(self.base.relative_degree)])
        wvec = np.concatenate([th1, vr])
        if self._prev is not None:
            a, b, w, mix = self._interp(vx0)
            Ph = mix(a.disc_e2[0], b.disc_e2[0])
            H0, H1 = mix(a.disc_e2[2], b.disc_e2[2]), mix(a.disc_e2[3], b.disc_e2[3])
            self._e2 = Ph @ self._e2 + H0 @ w0 + H1 @ (wvec - w0)
        a, b, w, mix = self._interp(vx)
        e_hat = mix(a.Q, b.Q) @ np.concatenate([th1, self._e2])
        zeta = mix(a.Dbar_pinv, b.Dbar_pinv) @ (vr - mix(a.Gamma, b.Gamma) @ e_hat)
        self._prev = (y, u, wvec, vx)
        return self._z + e_hat, zeta, th1


# ---------------------------------------------------------------------------
# running on arrays / ride logs
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ObserverRun:
    """Estimates over a ride: ``x_hat`` (K, 8), ``zeta_hat`` (K, q), ``theta1`` (K, r_T), ``t`` (K,)."""

    t: np.ndarray
    x_hat: np.ndarray
    zeta_hat: np.ndarray
    theta1: np.ndarray
    unknown_inputs: tuple[str, ...]

    def unknown(self, name: str) -> np.ndarray:
        """Reconstructed unknown input ``name`` ('phi' [rad] or 'tau' [N m])."""
        if name not in self.unknown_inputs:
            raise HOSMInputError(f"{name!r} is not an unknown input of this run ({self.unknown_inputs})")
        return self.zeta_hat[:, self.unknown_inputs.index(name)]


def measurements_from_log(columns: Mapping[str, np.ndarray], outputs: Sequence[str]) -> np.ndarray:
    """Stack the log columns of ``outputs`` (:data:`LOG_COLUMNS`) into (K, p)."""
    cols = []
    for o in outputs:
        if o not in LOG_COLUMNS:
            raise HOSMInputError(f"output {o!r} has no ride-log channel; channels: {dict(LOG_COLUMNS)}")
        c = LOG_COLUMNS[o]
        if c not in columns:
            raise HOSMInputError(f"the log has no column {c!r} (needed for output {o!r})")
        cols.append(np.asarray(columns[c], dtype=float))
    return np.stack(cols, axis=1)


def run_observer(observer: _UIObserverBase, Y: np.ndarray, vx=None, U=None, t=None, x0=None) -> ObserverRun:
    """Run ``observer`` over samples ``Y`` (K, p) with speeds ``vx`` (K,) and known inputs ``U`` (K, m)."""
    Y = np.asarray(Y, dtype=float)
    if Y.ndim != 2:
        raise HOSMInputError(f"Y must have shape (K, p), got {Y.shape}")
    K = Y.shape[0]
    vxa = None if vx is None else np.broadcast_to(np.asarray(vx, dtype=float), (K,))
    Ua = None if U is None else np.asarray(U, dtype=float).reshape(K, -1)
    observer.reset(x0)
    xs = np.empty((K, 8))
    zs = np.empty((K, len(observer.unknown_inputs)))
    ths: list[np.ndarray] = []
    for k in range(K):
        est = observer.update(Y[k], None if Ua is None else Ua[k], None if vxa is None else vxa[k])
        xs[k] = est.x_hat
        zs[k] = est.zeta_hat
        ths.append(est.theta1)
    tt = np.arange(K) * observer.config.dt if t is None else np.asarray(t, dtype=float)
    return ObserverRun(t=tt, x_hat=xs, zeta_hat=zs, theta1=np.array(ths), unknown_inputs=observer.unknown_inputs)


__all__ = [
    "DEFAULT_LIPSCHITZ",
    "HOSMConfig",
    "HOSMDesign",
    "HOSMDesignError",
    "HOSMEstimate",
    "HOSMInputError",
    "LOG_COLUMNS",
    "ObserverRun",
    "PAPER_LIPSCHITZ",
    "PAPER_POLES",
    "PAPER_SPEED",
    "ScheduledUIHOSMO",
    "UIHOSMO",
    "design_uihosmo",
    "measurements_from_log",
    "run_observer",
]
