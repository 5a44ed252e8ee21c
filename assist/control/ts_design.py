"""LMI design of the TS observer-based roll-tracking controller, with certificates.

Implements Theorems 1 and 2 of Dabladji et al. [1]_ on the TS model of
:mod:`assist.control.ts_model` (vertices ``A_i``, ``i = 1..4``), solved with cvxpy and
Clarabel, and checks every result again in plain numpy.

Theorem 1 (observer, [1]_ eqs. 10-11, corrected)
------------------------------------------------
Error ``e = x - x_hat``: ``e' = sum_i mu_hat_i (A_i - L_i C) e + Delta - L_i D w``
([1]_ eq. 9, ``Delta = sum_i (mu_i - mu_hat_i) A_i x``, ``w`` measurement
noise). The sensitivity signal ``h1 = 3 s/(s + 30 pi) e`` ([1]_ sec. III-B) is
realised as ``q' = -w1 q + e``, ``h1 = C11 [e; q]``, ``C11 = [3 I, -3 w1 I]``
(:func:`assist.control.ts_model.observer_sensitivity_filter`), so the LMI is written
for ``xi = [e; q]`` with ``P1 = diag(Pe, Pq)`` (block-diagonal so that
``L_i = Pe^-1 Z_i`` stays linear):

.. math::

    \\begin{bmatrix} \\Omega_i & P_1 G & -\\bar Z_i D & C_{11}^T \\\\
    \\star & -\\varepsilon_1 I & 0 & 0 \\\\
    \\star & 0 & -\\varepsilon_2 I & 0 \\\\
    \\star & 0 & 0 & -\\varepsilon_3 I \\end{bmatrix} \\prec 0,
    \\quad
    \\Omega_i = \\begin{bmatrix} A_i^T P_e + P_e A_i - Z_i C - C^T Z_i^T & P_q \\\\
                 P_q & -2 w_1 P_q \\end{bmatrix}

(``G = [I; 0]``, ``Z_bar = [Z_i; 0]``), minimising
``zeta1 eps1 + zeta2 eps2 + zeta3 eps3``. ``Delta`` enters through ``I`` as in
the paper (not only the rank-1 direction of the ``sin(phi)`` mismatch), so it
also covers ``sin(delta) ~ delta``, noise on the speed premise and unmodelled
effects. As in [1]_, ``Delta`` is treated as an exogenous input: it depends
on ``x`` and ``e`` (the premises are computed from the estimated roll), so the
ISS bound is a gain from ``Delta``, not a proof of closed-loop stability; no
small-gain closure is attempted (the closed loop is checked by simulation,
``scripts/eval_controller.py``). The filters are used as printed (``30 pi`` rad/s = 15 Hz and
``20 pi`` rad/s = 10 Hz, where the text says "20 Hz" and "8-10 Hz").
Corrections to the printed theorem:

* the third diagonal block is ``-eps2 I`` (printed ``-eps1 I``): the proof's
  inequality (15) weights ``w`` by ``eps2``;
* the decay rate under eq. (18) is printed ``eta1 = eps3^-1 ||C11||^2 /
  lambda_min(P1)``; from (15) it is at best ``sigma_min(C11)^2/(eps3
  lambda_max(P1))``, which is 0 here (``C11`` is 8 x 16). The rate reported
  (``eta``) is the tight one implied by the solved LMI (see ISS bounds below).

Theorem 2 (controller, [1]_ eqs. 22-23, corrected)
-------------------------------------------------
On ``x_a = [x, e_phi, s2]`` (:func:`assist.control.ts_model.augment`):

.. math::

    \\begin{bmatrix} \\Pi_i & I & B_1 & X_2 C_{12}^T \\\\
    \\star & -\\varepsilon_4 I & 0 & 0 \\\\
    \\star & 0 & -\\varepsilon_5 I & 0 \\\\
    \\star & 0 & 0 & -\\varepsilon_6 I \\end{bmatrix} \\prec 0,
    \\quad \\Pi_i = A_i X_2 + X_2 A_i^T - B_2 Y_i - Y_i^T B_2^T,
    \\quad K_i = Y_i X_2^{-1}

minimising ``zeta4 eps4 + zeta5 eps5 + zeta6 eps6``. Correction: the paper
prints ``Pi_i = A_i X2 + X2 A_i - ...`` (transpose missing; congruence of its
eq. (27) with ``diag(X2, I, I)`` gives ``A_i^T``) and ``-Y_i^T B2^T`` is needed
for symmetry.

Why more constraints than the paper (an attained optimum, implementable gains)
-----------------------------------------------------------------------------
Minimising the ``eps`` alone has no attained optimum: ``eps1 -> 0`` needs
``Omega_i ~ -Pe^2/eps1``, i.e. ever larger gains (a high-gain observer), and
likewise for ``eps4``. Both problems are therefore solved on a compact set:

* **pole region** (Chilali-Gahinet D-stability with the *same* Lyapunov
  matrix): ``Re(lambda) < -decay`` via ``Omega_e,i + 2 decay Pe < 0``
  (resp. ``Pi_i + 2 decay X2 < 0``) and ``|lambda| < radius`` via
  ``[[-radius Pe, Pe A_i - Z_i C], [*, -radius Pe]] < 0`` (resp. with
  ``A_i X2 - B2 Y_i``). This holds for every blend of the vertices, not only
  at the vertices. The default radius is ``0.8 pi/dt`` (80 % of the Nyquist
  frequency): no continuous pole can alias in the 100 Hz implementation;
  (The disk is imposed divided by ``radius``, ``[[-Pe, M_i/radius], [*, -Pe]] < 0``,
  so that all blocks have entries of the size of ``Pe``.)
* **Lyapunov conditioning**: ``I <= Pe <= cond_max I`` (resp. ``X2``).
  With the disk this bounds the gains: ``||Z_i C|| <= ||Pe A_i|| + radius
  ||Pe||`` so ``||L_i|| <= ||Z_i||`` is bounded, and ``||K_i|| <= ||Y_i||``.
  The feasible set is compact, the objective continuous: the optimum exists.
* **gain penalty**: the bound above is loose (the optimum sits on the disk
  boundary, ``|K| ~ 1e4`` N m/rad, and the sampled loop is then unstable), so
  the objective also carries ``gain_weight * gamma`` with
  ``[[Pe, Z_i], [Z_i^T, gamma I]] >= 0`` (``||L_i,s||^2 <= gamma`` since
  ``Pe >= I``), resp. ``[[X2, Y_i^T], [Y_i, gamma]] >= 0``
  (``||K_i,s||^2 <= gamma``), in the scaled coordinates: the observer no
  longer amplifies the sensor noise into the torque.

All LMIs are solved in *scaled* coordinates ``x = S x_s`` (nominal
magnitudes, :class:`Scaling`), then, if ``balance`` is set, rescaled by a
diagonal balancing from a preliminary minimum-condition-number problem
(Boyd et al., *LMIs in System and Control Theory*, sec. 3.1) so that the
Lyapunov matrices come out with comparable diagonal entries; a common
Lyapunov matrix for 8-33 m/s otherwise has condition number ~1e4-1e6.
The measurement scaling is the design noise level (``D = diag(noise)``).

Every strict inequality is imposed as ``<= -10 margin I`` and re-checked in numpy
(:class:`Certificate`: largest eigenvalue of every block ``< -margin``). The
sampled implementation (:mod:`assist.control.ts_controller`) is then checked on a grid
of frozen premises (:class:`DiscreteCheck`).

ISS bounds (in the scaled coordinates; corrected [1]_ eqs. 12, 20, 35-36)
-------------------------------------------------------------------------
From the LMI, ``V1 = xi^T P1 xi`` obeys ``V1' <= -eta1 V1 + eps1 |Delta|^2 +
eps2 |w|^2`` with ``eta1 = min_i lambda_min(-P1^-1/2 S_i P1^-1/2)``,
``S_i = Omega_i + eps1^-1 P1 G G^T P1 + eps2^-1 Z_i D D^T Z_i^T`` (convex in
the blend, so the vertices bound every blend), hence

.. math::

    |e(t)| \\le \\sqrt{\\kappa(P_e)} |e(0)| e^{-\\eta_1 t/2}
      + \\gamma_\\Delta \\|\\Delta\\|_\\infty + \\gamma_w \\|w\\|_\\infty,
    \\quad \\gamma_\\Delta = \\sqrt{\\varepsilon_1/(\\eta_1 \\lambda_{min}(P_e))},
    \\; \\gamma_w = \\sqrt{\\varepsilon_2/(\\eta_1 \\lambda_{min}(P_e))}

(``q(0) = 0``, ``V1 >= e^T Pe e``; ``|h1|`` has the L2 gains
``sqrt(eps1 eps3)``, ``sqrt(eps2 eps3)`` from ``Delta``, ``w``, [1]_ eq. 14).

For the controller, ``V2 = x_a^T X2^-1 x_a``, ``eta2 = min_i
lambda_min(-X2^-1/2 (Pi_i + eps4^-1 I + eps5^-1 B1 B1^T) X2^-1/2)``; the
estimation error enters through ``G_e,i = B2 K_i [I; 0] - [0; Bc] e_phi^T``
(the augmented states integrate ``phi_hat``) with ``g = max_i
||X2^-1/2 G_e,i||``; Young's inequality gives ``V2' <= -eta2/2 V2 + eps4
|Delta|^2 + eps5 |phi_r|^2 + (2 g^2/eta2) |e|^2`` and the bounds
``gamma = sqrt(2 eps/(eta2 lambda_min(X2^-1)))``, ``gamma_e = 2 g/(eta2
sqrt(lambda_min(X2^-1)))``. ``nominal_decay_rate`` is the rate of ``V`` with
no input (``>= 2 decay`` by the decay LMI). (The paper's (28) takes
``eta2 = eps6^-1 ||C12||^2``, not a decay rate since ``C12`` has rank 1.)

The ISS rate is imposed, not left to chance: minimising the ``eps`` pushes
the theorem LMI to its boundary, where ``-S_i`` is nearly singular and
``eta`` nearly 0 (the controller came out at ``eta2`` = 0.006 1/s, its gains
at 305 (``Delta``), 817 (reference), 5.2e5 (estimation error): true but
empty statements). ``TheoremOptions.iss_rate`` adds ``eta P1`` (resp.
``eta X2``) to the first diagonal block, which makes ``eta1 >= eta``
(``eta2 >= eta``) by construction; the default controller rate of 2 1/s
takes ``eta2`` to 2 1/s and the gains to 23, 58 and 1.7e3 with the same
closed loop (``K`` moves by 1 % of its largest entry; demo roll RMSE 0.160
and 0.183 deg at 0 and 5 % noise before, 0.160 and 0.182 after).

What the bounds say in physical units (``iss`` entries ``*_rad``, and
:func:`format_summary`): from the level sets of ``V``,
``|e_j| <= sx_j sqrt((Pe^-1)_jj V1)`` and ``|phi| <= sa_phi sqrt((X2)_phi,phi V2)``,
so at steady state

* roll-estimate error ``<= sx_phi sqrt((Pe^-1)_phi,phi eps2/eta1) |w_s|`` for
  noise at the design levels in every channel (``|w_s| = 2``); 12.8 deg for
  the default design, where the measured roll-estimate RMSE at 5 % noise
  (2.5 times the design levels) is 0.23 deg;
* roll ``<= sa_phi sqrt(2 (X2)_phi,phi eps5/eta2)/s_r`` per unit of
  ``||phi_r||``: 7.4 rad per rad, and ``sa_phi sqrt((X2)_phi,phi) 2 g/(eta2 sx_phi)``
  = 260 rad per rad of roll-estimate error.

They certify boundedness (the ISS property, every blend of the vertices,
every input), through one quadratic function of condition number 40-460;
as accuracy predictions they are one to three orders of magnitude loose.
The tracking accuracy is measured in closed loop (:mod:`assist.evaluate`).

Solver status: Clarabel returns ``optimal_inaccurate`` (its "AlmostSolved",
duality gap ~2e-6 relative against its 1e-8 target) on the controller
problem, with or without ``iss_rate``, after equivalent rescalings of the
torque and of ``gamma`` (same point, same status) and with its refinement
and equilibration settings changed: the objective is dominated by the gain
term and nearly flat in the ``eps``. The design does not rely on the
status: every block is re-checked in numpy at the returned point
(margins ~1e-4 against the required 1e-5).

References
----------
.. [1] H. Dabladji, D. Ichalal, H. Arioui, S. Mammar, "Observer based
   controller for single track vehicles", 52nd IEEE CDC, 2013, pp. 7420-7425.

Length (about 1350 lines, kept as one module): both theorems share the data scaling, the problem
builder, the quiet solve, the numpy certificate, the sampled-loop check and the disk cache, and one
:class:`TSDesign` carries them all; split by theorem, that plumbing would be written twice or passed
around as private state.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ptw_env.vehicle import PHI, REFERENCE_SCOOTER, STATE_NAMES, VY, Vehicle

from assist.control.ts_discrete import DiscreteTS, discretise, sampled_closed_loop
from assist.lmi import Certificate, CertificateEntry, max_eig, solve_quietly, symmetric
from assist.control.ts_model import (
    AUGMENTED_NAMES,
    MEASUREMENT_NAMES,
    PHI_MAX,
    AugmentedModel,
    TSModel,
    H1_CORNER,
    H1_GAIN,
    augment,
    build_ts_model,
    split_model,
)

#: Speed range of the reference scooter's default design [m/s] (the issue's wide range); another vehicle's
#: default is its own :attr:`ptw_env.vehicle.Vehicle.control_range`.
DEFAULT_SPEED_RANGE = REFERENCE_SCOOTER.control_range
#: Bump when the problem formulation changes (invalidates cached designs).
FORMULATION_VERSION = "ts-design-2"
SOLVERS = ("CLARABEL", "SCS")
#: The solve imposes ``block <= -SOLVE_MARGIN_FACTOR margin I``; the certificate requires ``< -margin``.
SOLVE_MARGIN_FACTOR = 10.0


class DesignError(ValueError):
    """An LMI design that failed: infeasible, inaccurate, badly conditioned or not certified.

    Attributes
    ----------
    theorem : str
        ``"observer (Theorem 1)"`` or ``"controller (Theorem 2)"``.
    lmi : str
        The inequality at fault (e.g. ``"decay"``, ``"disk"``, ``"theorem"``, ``"common Lyapunov matrix"``).
    vertex : int or None
        Vertex index (0-3) or None when no single vertex is at fault.
    cause : str
        The likely cause, in words.
    """

    def __init__(self, theorem: str, lmi: str, vertex: int | None, cause: str, where: str = "") -> None:
        self.theorem, self.lmi, self.vertex, self.cause = theorem, lmi, vertex, cause
        v = f", vertex {vertex}{where}" if vertex is not None else ""
        super().__init__(f"{theorem}: LMI '{lmi}'{v} failed: {cause}")


class DesignOptionError(ValueError):
    """A design option outside its meaningful range."""


# --------------------------------------------------------------------------- options
@dataclass(frozen=True)
class Scaling:
    """Nominal magnitudes used to scale the LMI problems (before balancing).

    Attributes
    ----------
    state : tuple of 8 floats
        phi [rad], delta [rad], vy [m/s], r [rad/s], phi_dot [rad/s], delta_dot [rad/s], Fyf [N], Fyr [N].
    e_phi : float
        Roll-error integral [rad s].
    s2 : float
        Low-pass sensitivity state [rad].
    torque : float
        Steering torque [N m].
    noise : tuple of 4 floats
        Design noise level of [yaw_rate, roll_rate, delta, delta_rate] (rad/s, rad/s, rad, rad/s):
        the noise matrix ``D`` of Theorem 1 (larger values give a slower observer).
    """

    state: tuple[float, ...] = (0.2, 0.02, 0.5, 0.2, 0.5, 0.2, 400.0, 400.0)
    e_phi: float = 0.05
    s2: float = 0.1
    torque: float = 10.0
    noise: tuple[float, ...] = (0.01, 0.02, 0.001, 0.02)

    def __post_init__(self) -> None:
        for name, n in (("state", 8), ("noise", 4)):
            v = tuple(float(a) for a in getattr(self, name))
            if len(v) != n or not all(math.isfinite(a) and a > 0 for a in v):
                raise DesignOptionError(f"Scaling.{name} must hold {n} positive finite numbers, got {v!r}")
            object.__setattr__(self, name, v)
        for name in ("e_phi", "s2", "torque"):
            a = getattr(self, name)
            if not (math.isfinite(a) and a > 0):
                raise DesignOptionError(f"Scaling.{name} must be a positive finite number, got {a!r}")


@dataclass(frozen=True)
class TheoremOptions:
    """Options of one LMI problem (Theorem 1 or Theorem 2).

    Attributes
    ----------
    zeta : tuple of 3 floats
        Weights of ``eps1..3`` (resp. ``eps4..6``) in the objective.
    decay : float
        Required decay rate: every pole of every blend has ``Re(lambda) < -decay`` [rad/s].
    radius : float or None
        Pole disk ``|lambda| < radius`` [rad/s]; None: ``0.8 pi/dt``.
    cond_max : float
        Bound on the condition number of the Lyapunov matrix (``I <= P <= cond_max I``).
    gain_weight : float
        Weight of the gain bound ``gamma`` in the objective, where
        ``[[Pe, Z_i], [Z_i^T, gamma I]] >= 0`` (resp. ``[[X2, Y_i^T], [Y_i, gamma]] >= 0``)
        gives ``||L_i||^2 <= gamma`` (resp. ``||K_i||^2 <= gamma``) in the scaled coordinates.
    iss_rate : float
        Decay rate ``eta`` [1/s] of the Lyapunov function *with* the ISS inputs, imposed by adding
        ``eta P1`` (resp. ``eta X2``) to the theorem's first diagonal block: ``V' <= -eta V +
        eps |input|^2``. 0 is the paper's theorem, whose minimised ``eps`` leave the inequality
        nearly tight and the rate small (reference scooter, 8-33 m/s: 0.24 1/s against the 2.0 1/s
        imposed by default, with an 8.6x larger gain from the estimation error; module docstring,
        ISS bounds).
    """

    zeta: tuple[float, float, float] = (1.0, 1.0, 1.0)
    decay: float = 1.0
    radius: float | None = None
    cond_max: float = 1e3
    gain_weight: float = 1e-3
    iss_rate: float = 0.0

    def __post_init__(self) -> None:
        z = tuple(float(a) for a in self.zeta)
        if len(z) != 3 or not all(math.isfinite(a) and a > 0 for a in z):
            raise DesignOptionError(f"zeta must hold 3 positive weights, got {self.zeta!r}")
        object.__setattr__(self, "zeta", z)
        if not (math.isfinite(self.decay) and self.decay >= 0):
            raise DesignOptionError(f"decay must be a non-negative rate in rad/s, got {self.decay!r}")
        if self.radius is not None and not (math.isfinite(self.radius) and self.radius > self.decay):
            raise DesignOptionError(f"radius must exceed decay ({self.decay} rad/s), got {self.radius!r}")
        if not (math.isfinite(self.cond_max) and self.cond_max > 1):
            raise DesignOptionError(f"cond_max must be a number > 1, got {self.cond_max!r}")
        if not (math.isfinite(self.gain_weight) and self.gain_weight >= 0):
            raise DesignOptionError(f"gain_weight must be a non-negative number, got {self.gain_weight!r}")
        if not (math.isfinite(self.iss_rate) and 0 <= self.iss_rate <= 2 * self.decay):
            raise DesignOptionError(f"iss_rate must lie in [0, 2 decay] = [0, {2 * self.decay:g}] 1/s (the decay LMI "
                                    f"gives V a rate of 2 decay without inputs), got {self.iss_rate!r}")


@dataclass(frozen=True)
class DesignOptions:
    """Options of the full design (both theorems).

    Attributes
    ----------
    observer, controller : TheoremOptions
        Defaults: observer decay 1 rad/s, gain_weight 1; controller decay 2 rad/s,
        gain_weight 0.1, iss_rate 2 1/s (the controller's ISS rate, half the rate of ``V2``
        the decay LMI gives without inputs; with 0 it came out at 0.006 1/s and the ISS
        gains at 3e2-5e5, with no measurable change of the closed loop either way). The
        observer keeps iss_rate 0 (its rate comes out at 0.37 1/s): imposing 1 1/s cost
        10 % of roll-estimation and roll-tracking RMSE on the demo. Chosen in closed loop on the nonlinear plant (8-33 m/s,
        lane changes, 5 % noise): roll RMSE ~0.2 deg with the sensor noise adding
        ~0.2 N m rms of torque. With gain_weight 1e-3 for both, |L| ~ 2e5 and the
        torque rms at 5 % noise nearly doubles (9.9 vs 5.5 N m); a controller
        decay of 4 rad/s then needed |K| ~ 7e4 and the 100 Hz loop was unstable.
    scaling : Scaling
    dt : float
        Sampling period of the implementation [s] (default radius, discrete checks).
    margin : float
        Strictness margin of every LMI (scaled units): imposed ``<= -10 margin``, certified ``< -margin``.
    balance : bool
        Diagonal balancing of the scaling by a preliminary minimum-condition solve.
    grid : int
        Speeds (>= 2) at which the sampled loop is checked, at both roll premises.
    """

    observer: TheoremOptions = field(default_factory=lambda: TheoremOptions(decay=1.0, gain_weight=1.0))
    controller: TheoremOptions = field(default_factory=lambda: TheoremOptions(decay=2.0, gain_weight=0.1, iss_rate=2.0))
    scaling: Scaling = field(default_factory=Scaling)
    dt: float = 0.01
    margin: float = 1e-5
    balance: bool = True
    grid: int = 5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.dt) and 0 < self.dt <= 0.1):
            raise DesignOptionError(f"dt must lie in (0, 0.1] s, got {self.dt!r}")
        if not (math.isfinite(self.margin) and 0 < self.margin < 1):
            raise DesignOptionError(f"margin must lie in (0, 1), got {self.margin!r}")
        if int(self.grid) != self.grid or self.grid < 2:
            raise DesignOptionError(f"grid must be an integer >= 2, got {self.grid!r}")
        for name in ("observer", "controller"):
            o = getattr(self, name)
            if not isinstance(o, TheoremOptions):
                raise DesignOptionError(f"{name} must be a TheoremOptions, got {type(o).__name__}")
            r = self.radius(o)
            if r * self.dt >= math.pi:
                raise DesignOptionError(
                    f"{name} radius {r} rad/s is beyond the Nyquist frequency pi/dt = {math.pi / self.dt:.1f} rad/s"
                )

    def radius(self, o: TheoremOptions) -> float:
        """Disk radius of ``o`` [rad/s] (``0.8 pi/dt`` by default)."""
        return float(o.radius) if o.radius is not None else 0.8 * math.pi / self.dt


OBSERVER = "observer (Theorem 1)"
CONTROLLER = "controller (Theorem 2)"
FAMILIES = ("theorem", "decay", "disk")  # strict inequalities
GAIN = "gain"  # non-strict: [[P, Z_i], [Z_i^T, gamma I]] >= 0 (resp. [[X, Y_i^T], [Y_i, gamma]])


# --------------------------------------------------------------------------- scaled data
@dataclass(frozen=True, eq=False)
class _Data:
    """One theorem's vertex data in scaled coordinates."""

    kind: str  # "observer" | "controller"
    A: np.ndarray  # (4, n, n)
    B: np.ndarray  # observer: C (ny, n); controller: B2 (n, 1)
    B1: np.ndarray | None  # controller: reference input (n, 1)
    C12: np.ndarray | None  # controller: sensitivity output (1, n)

    @property
    def n(self) -> int:
        return self.A.shape[-1]


def _observer_data(ts: TSModel, sx: np.ndarray, sy: np.ndarray) -> _Data:
    As = ts.A / sx[None, :, None] * sx[None, None, :]
    Cs = ts.C / sy[:, None] * sx[None, :]
    return _Data("observer", As, Cs, None, None)


def _controller_data(aug: AugmentedModel, sa: np.ndarray, su: float, sr: float) -> _Data:
    As = aug.A / sa[None, :, None] * sa[None, None, :]
    B2 = aug.B2 / sa[:, None] * su
    B1 = aug.B1 / sa[:, None] * sr
    C12 = aug.C12 * sa[None, :] / sa[-1]
    return _Data("controller", As, B2, B1, C12)


# --------------------------------------------------------------------------- LMI blocks
def _cl_term(d: _Data, P: Any, G: Any, i: int) -> Any:
    """``Pe A_i - Z_i C`` (observer) or ``A_i X - B2 Y_i`` (controller)."""
    return P @ d.A[i] - G @ d.B if d.kind == "observer" else d.A[i] @ P - d.B @ G


def _blocks(d: _Data, P: Any, Pq: Any, G: Any, eps: Any, i: int, decay: float, radius: float,
            families: tuple[str, ...], bmat: Any, iss_rate: float = 0.0) -> dict[str, Any]:
    """The inequalities ``block < 0`` of vertex ``i``, written once for numpy (certificate) and cvxpy (solve).

    ``P``: ``Pe`` or ``X2``; ``G``: ``Z_i`` or ``Y_i``; ``eps``: 3 scalars; ``bmat``: ``np.block`` or ``cp.bmat``;
    ``iss_rate``: ``eta`` added to the theorem's first diagonal block (``+ eta P1``, resp. ``+ eta X2``).
    """
    n = d.n
    M = _cl_term(d, P, G, i)
    I, Z = np.eye, np.zeros
    out: dict[str, Any] = {}
    if "theorem" in families:
        if d.kind == "observer":
            ny = d.B.shape[0]
            Oa = bmat([[M + M.T + iss_rate * P, Pq], [Pq, (iss_rate - 2 * H1_CORNER) * Pq]])
            Gd = bmat([[P], [Z((n, n))]])  # Delta enters e only
            Nw = bmat([[-G], [Z((n, ny))]])  # -Z_i D w with D = I (scaled by the noise level)
            C11 = np.hstack([H1_GAIN * I(n), -H1_GAIN * H1_CORNER * I(n)])
            out["theorem"] = bmat(
                [
                    [Oa, Gd, Nw, C11.T],
                    [Gd.T, -eps[0] * I(n), Z((n, ny)), Z((n, n))],
                    [Nw.T, Z((ny, n)), -eps[1] * I(ny), Z((ny, n))],
                    [C11, Z((n, n)), Z((n, ny)), -eps[2] * I(n)],
                ]
            )
        else:
            out["theorem"] = bmat(
                [
                    [M + M.T + iss_rate * P, I(n), d.B1, P @ d.C12.T],
                    [I(n), -eps[0] * I(n), Z((n, 1)), Z((n, 1))],
                    [d.B1.T, Z((1, n)), -eps[1] * I(1), Z((1, 1))],
                    [d.C12 @ P, Z((1, n)), Z((1, 1)), -eps[2] * I(1)],
                ]
            )
    if "decay" in families:
        out["decay"] = M + M.T + 2 * decay * P
    if "disk" in families:  # divided by the radius: entries of the size of P
        out["disk"] = bmat([[-P, M / radius], [M.T / radius, -P]])
    if GAIN in families:
        if d.kind == "observer":
            ny = d.B.shape[0]
            out[GAIN] = -bmat([[P, G], [G.T, eps[3] * I(ny)]])
        else:
            out[GAIN] = -bmat([[P, G.T], [G, eps[3] * I(1)]])
    return out


# --------------------------------------------------------------------------- cvxpy problems
@dataclass
class _Raw:
    """What a solve returns (scaled coordinates)."""

    P: np.ndarray
    Pq: np.ndarray | None
    G: np.ndarray  # (4, n, ny) Z_i or (4, 1, n) Y_i
    eps: np.ndarray  # (3,)
    status: str
    build_s: float
    solve_s: float


def _problem(d: _Data, o: TheoremOptions, radius: float, margin: float, families: tuple[str, ...],
             vertices: tuple[int, ...], objective: str):
    """cvxpy problem of one theorem; ``objective``: ``"eps"`` (the theorem) or ``"cond"`` (balancing)."""
    import cvxpy as cp

    n = d.n
    P = cp.Variable((n, n), symmetric=True)
    Pq = cp.Variable((n, n), symmetric=True) if (d.kind == "observer" and "theorem" in families) else None
    gshape = (n, d.B.shape[0]) if d.kind == "observer" else (1, n)
    G = [cp.Variable(gshape) for _ in range(4)]
    eps = cp.Variable(4) if "theorem" in families else None  # eps1..3 (resp. 4..6) and the gain bound gamma
    eye = np.eye(n)
    cons = [P >> eye]
    if objective == "cond":
        t = cp.Variable()
        cons.append(P << t * eye)
        obj = cp.Minimize(t)
    else:
        cons.append(P << o.cond_max * eye)
        obj = cp.Minimize(np.r_[o.zeta, o.gain_weight] @ eps) if eps is not None else cp.Minimize(0)
        families = families + (GAIN,) if eps is not None else families
    if Pq is not None:
        cons += [Pq >> 2 * margin * eye, Pq << o.cond_max * eye]
    if eps is not None:
        cons.append(eps >= margin)
    for i in vertices:
        for name, blk in _blocks(d, P, Pq, G[i], eps, i, o.decay, radius, families, cp.bmat, o.iss_rate).items():
            cons.append(blk << (0.0 if name == GAIN else -SOLVE_MARGIN_FACTOR * margin) * np.eye(blk.shape[0]))
    return cp.Problem(obj, cons), (P, Pq, G, eps)


def _solve(d: _Data, o: TheoremOptions, radius: float, margin: float, solver: str,
           families: tuple[str, ...] = FAMILIES, vertices: tuple[int, ...] = (0, 1, 2, 3),
           objective: str = "eps", status: list[str] | None = None) -> _Raw | None:
    """Solve; None when the solver reports infeasibility or fails (its status appended to ``status`` if given)."""
    t0 = time.perf_counter()
    prob, (P, Pq, G, eps) = _problem(d, o, radius, margin, families, vertices, objective)
    st = solve_quietly(prob, solver)
    if st.startswith("solver_"):
        if status is not None:
            status.append(st.split(":", 1)[0])
        return None
    total = time.perf_counter() - t0
    if status is not None:
        status.append(st)
    stats = prob.solver_stats
    solve_s = float(stats.solve_time) if stats is not None and stats.solve_time is not None else total
    if prob.status not in ("optimal", "optimal_inaccurate") or P.value is None:
        return None
    nv = G[0].shape
    Gv = np.stack([g.value if g.value is not None else np.zeros(nv) for g in G])
    return _Raw(
        P=symmetric(P.value),
        Pq=symmetric(Pq.value) if Pq is not None else None,
        G=Gv,
        eps=np.asarray(eps.value, dtype=float) if eps is not None else np.full(4, np.nan),
        status=prob.status,
        build_s=max(total - solve_s, 0.0),
        solve_s=solve_s,
    )


def _balance(d: _Data, o: TheoremOptions, radius: float, margin: float, solver: str,
             vertices: tuple[int, ...] = (0, 1, 2, 3)) -> np.ndarray | None:
    """Diagonal rescaling factors from the minimum-condition Lyapunov matrix of the pole-region LMIs.

    Observer (``P`` form): ``factor = diag(P)^-1/2``; controller (``X = P^-1``
    form): ``factor = diag(X)^1/2``; normalised to a unit geometric mean.
    None when the region LMIs alone are infeasible (at ``vertices``).
    """
    raw = _solve(d, o, radius, margin, solver, families=("decay", "disk"), vertices=vertices, objective="cond")
    if raw is None:
        return None
    diag = np.clip(np.diag(raw.P), 1e-12, None)
    f = diag ** (-0.5 if d.kind == "observer" else 0.5)
    return f / np.exp(np.mean(np.log(f)))


def _where(ts: TSModel, i: int) -> str:
    z1, z2 = ts.vertices[i]
    return f" (vx = {z1:g} m/s, z2 = sin(phi)/phi = {z2:.4f})"


def _diagnose(theorem: str, d: _Data, o: TheoremOptions, radius: float, margin: float, solver: str,
              ts: TSModel, remake: Callable[[np.ndarray], _Data] | None = None) -> DesignError:
    """Find the vertex and the LMI family that make a design infeasible (only called on failure).

    ``remake(f)`` rebuilds the data with the nominal scaling times ``f``: a vertex that fails in the
    scaling shared by the whole box is solved again alone with its own balancing; if it passes
    there, the cause is the width of the speed range (one Lyapunov matrix, conditioned for all
    four vertices), not the vertex.
    """

    def ok(fams: tuple[str, ...], verts: tuple[int, ...], data: _Data = d) -> bool:
        return _solve(data, o, radius, margin, solver, fams, verts) is not None

    def alone_with_own_scaling(i: int) -> bool:
        if remake is None:
            return False
        f = _balance(remake(np.ones(d.n)), o, radius, margin, solver, vertices=(i,))
        return f is not None and ok(FAMILIES, (i,), remake(f))

    wide = (f"the speed range [{ts.vmin:g}, {ts.vmax:g}] m/s is likely too wide for one common Lyapunov matrix "
            f"(decay {o.decay:g} rad/s, cond_max {o.cond_max:g}); narrow it, or split it into two designs")

    fix = {
        "decay": f"lower the decay rate ({o.decay:g} rad/s) or raise cond_max ({o.cond_max:g})",
        "disk": f"narrow the speed range (vmax = {ts.vmax:g} m/s) or shorten dt",
        "theorem": f"raise cond_max ({o.cond_max:g}) or relax the pole region",
    }
    for i in range(4):
        if ok(FAMILIES, (i,)):
            continue
        openmax = float(np.max(np.abs(np.linalg.eigvals(d.A[i]))))
        own = alone_with_own_scaling(i)
        for fam in FAMILIES:
            if ok(tuple(f for f in FAMILIES if f != fam), (i,)):
                what = {
                    "decay": f"no gain puts every pole left of -{o.decay:g} rad/s inside |lambda| < {radius:.0f} rad/s "
                    f"with cond(P) <= {o.cond_max:g}",
                    "disk": f"the pole disk |lambda| < {radius:.0f} rad/s cannot hold this vertex "
                    f"(open-loop poles up to |lambda| = {openmax:.0f} rad/s)",
                    "theorem": "the ISS inequality has no solution inside the pole region",
                }[fam]
                if own:
                    return DesignError(theorem, fam, i, f"this vertex passes alone with its own scaling, but {what} "
                                       f"in the scaling the whole box needs: {wide}", _where(ts, i))
                return DesignError(theorem, fam, i, f"{what}; {fix[fam]}", _where(ts, i))
        if own:
            return DesignError(theorem, "theorem+decay+disk", i, "this vertex passes alone with its own scaling, "
                               f"but not in the scaling the whole box needs: {wide}", _where(ts, i))
        return DesignError(theorem, "theorem+decay+disk", i,
                           "infeasible even for this vertex alone: the vertex model is not "
                           + ("detectable from the measurements" if d.kind == "observer" else "stabilisable by the torque")
                           + " within the pole region and conditioning bound", _where(ts, i))
    for fam in FAMILIES:
        if ok(tuple(f for f in FAMILIES if f != fam), (0, 1, 2, 3)):
            return DesignError(
                theorem, f"{fam} (common Lyapunov matrix)", None,
                f"each vertex is feasible alone but no common Lyapunov matrix satisfies the {fam} LMI at all four: "
                f"the speed range [{ts.vmin:g}, {ts.vmax:g}] m/s is likely too wide; {fix[fam]}",
            )
    return DesignError(
        theorem, "common Lyapunov matrix", None,
        f"each vertex is feasible alone but not all four together: the speed range [{ts.vmin:g}, {ts.vmax:g}] m/s "
        f"is likely too wide for decay {o.decay:g} rad/s and cond_max {o.cond_max:g}",
    )


# --------------------------------------------------------------------------- results
# Certificate and CertificateEntry: assist.lmi (shared with the adaptive observer's design). Here every
# inequality is strict (``max_eig < -margin``: the LMIs theorem, decay, disk of every vertex, and ``-P < 0``,
# ``-Pq < 0``, ``-eps < 0``) except the gain bound, whose ``max_eig`` is the violation relative to the block's
# size and must be ``<= NONSTRICT_TOL``. (``I <= P <= cond_max I`` only normalises the problem; the condition
# number is checked separately.) ``worst`` is taken over the LMI families (FAMILIES).


@dataclass(frozen=True, eq=False)
class ObserverDesign:
    """Theorem 1 result. ``L`` (4, 8, 4) physical gains; ``P``, ``Pq``, ``Z`` scaled; ``sx``, ``sy`` scales;
    ``eps = (eps1, eps2, eps3, gamma)`` (``gamma``: the gain bound); ``eta`` decay rate of ``V1`` [1/s]; ``iss`` bounds; ``poles`` (4, 8)
    eigenvalues of ``A_i - L_i C`` [rad/s]."""

    L: np.ndarray
    P: np.ndarray
    Pq: np.ndarray
    Z: np.ndarray
    eps: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    eta: float
    iss: dict
    poles: np.ndarray
    status: str
    build_s: float
    solve_s: float
    balance_s: float


@dataclass(frozen=True, eq=False)
class ControllerDesign:
    """Theorem 2 result. ``K`` (4, 10) physical gains on ``[x, e_phi, s2]``; ``X``, ``Y`` scaled;
    ``sa``, ``su``, ``sr`` scales; ``eps = (eps4, eps5, eps6, gamma)``; ``eta`` decay rate of ``V2`` [1/s];
    ``poles`` (4, 10) eigenvalues of ``A_a,i - B2 K_i`` [rad/s]."""

    K: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    eps: np.ndarray
    sa: np.ndarray
    su: float
    sr: float
    eta: float
    iss: dict
    poles: np.ndarray
    status: str
    build_s: float
    solve_s: float
    balance_s: float


@dataclass(frozen=True, eq=False)
class DiscreteCheck:
    """Spectral radii of the sampled implementation on a grid of frozen premises.

    ``speeds`` (grid,) [m/s]; ``observer_rho`` and ``closed_loop_rho`` have shape (grid, 2) (second
    axis: ``z2 = z2min``, ``z2 = 1``); ``required`` the largest radius allowed,
    ``exp(-min(decay) dt/2)`` (the sampled loop keeps half the designed decay rate);
    ``nyquist_ratio = max |lambda_continuous| dt / pi``.
    """

    dt: float
    speeds: np.ndarray
    observer_rho: np.ndarray
    closed_loop_rho: np.ndarray
    required: float
    nyquist_ratio: float

    @property
    def passed(self) -> bool:
        return bool(np.all(self.closed_loop_rho < self.required) and np.all(self.observer_rho < self.required)
                    and self.nyquist_ratio < 1.0)


def _gen_min_eig(S: np.ndarray, P: np.ndarray) -> float:
    """Smallest ``eta`` with ``-S - eta P`` singular: ``lambda_min(P^-1/2 (-S) P^-1/2)``."""
    import scipy.linalg as sla

    return float(sla.eigh(-symmetric(S), symmetric(P), eigvals_only=True)[0])


def _observer_result(raw: _Raw, d: _Data, sx: np.ndarray, sy: np.ndarray, balance_s: float) -> ObserverDesign:
    Ls = np.linalg.solve(raw.P[None], raw.G)  # Pe^-1 Z_i (scaled)
    L = sx[None, :, None] * Ls / sy[None, None, :]
    n, ny = d.n, d.B.shape[0]
    e1, e2, e3, _ = raw.eps
    P1 = np.block([[raw.P, np.zeros((n, n))], [np.zeros((n, n)), raw.Pq]])
    etas = []
    for i in range(4):
        M = _cl_term(d, raw.P, raw.G[i], i)
        Oa = np.block([[M + M.T, raw.Pq], [raw.Pq, -2 * H1_CORNER * raw.Pq]])
        Gd = np.vstack([raw.P, np.zeros((n, n))])
        Nw = np.vstack([raw.G[i], np.zeros((n, ny))])
        etas.append(_gen_min_eig(Oa + Gd @ Gd.T / e1 + Nw @ Nw.T / e2, P1))
    eta = min(etas)
    lam = np.linalg.eigvalsh(raw.P)
    nominal = min(_gen_min_eig(_cl_term(d, raw.P, raw.G[i], i) + _cl_term(d, raw.P, raw.G[i], i).T, raw.P)
                  for i in range(4))
    # physical units: |e_j| <= sx_j sqrt((Pe^-1)_jj V1), V1 <= eps2 |w_s|^2 / eta1, |w_s| = 2 at the design levels
    per_state = sx * np.sqrt(np.diag(np.linalg.inv(raw.P)) * e2 / eta) * 2.0 if eta > 0 else np.full(n, math.inf)
    iss = {
        "decay_rate": eta,
        "nominal_decay_rate": nominal,
        "overshoot": math.sqrt(lam[-1] / lam[0]),
        "gain_delta": math.sqrt(e1 / (eta * lam[0])) if eta > 0 else math.inf,
        "gain_noise": math.sqrt(e2 / (eta * lam[0])) if eta > 0 else math.inf,
        "l2_gain_delta_to_h1": math.sqrt(e1 * e3),
        "l2_gain_noise_to_h1": math.sqrt(e2 * e3),
        "phi_error_at_design_noise_rad": float(per_state[PHI]),
        "vy_error_at_design_noise_mps": float(per_state[VY]),
    }
    poles = np.array([np.linalg.eigvals(d.A[i] - Ls[i] @ d.B) for i in range(4)])
    return ObserverDesign(L=L, P=raw.P, Pq=raw.Pq, Z=raw.G, eps=raw.eps, sx=sx, sy=sy, eta=eta, iss=iss,
                          poles=poles, status=raw.status, build_s=raw.build_s, solve_s=raw.solve_s,
                          balance_s=balance_s)


def _controller_result(raw: _Raw, d: _Data, sa: np.ndarray, su: float, sr: float, aug: AugmentedModel,
                       sx_obs: np.ndarray, balance_s: float) -> ControllerDesign:
    X = raw.P
    Ks = np.linalg.solve(X[None], np.transpose(raw.G, (0, 2, 1)))[:, :, 0]  # (Y_i X^-1)^T = X^-1 Y_i^T
    K = su * Ks / sa[None, :]
    e4, e5, _, _ = raw.eps
    etas = [_gen_min_eig(_cl_term(d, X, raw.G[i], i) + _cl_term(d, X, raw.G[i], i).T
                         + np.eye(d.n) / e4 + d.B1 @ d.B1.T / e5, X) for i in range(4)]
    eta = min(etas)
    lamX = np.linalg.eigvalsh(X)
    lmin_P2 = 1.0 / lamX[-1]
    Xih = np.linalg.inv(np.linalg.cholesky(X))  # X^-1 = Xih^T Xih, so ||X^-1/2 G|| = ||Xih G||
    g = 0.0
    for i in range(4):
        Ge = aug.B2 @ K[i][None, :8]  # B2 K_i [I; 0]
        Ge[8:, 0] -= aug.Bc[:, 0]  # the augmented states integrate phi_hat = phi - e_phi
        g = max(g, float(np.linalg.norm(Xih @ (Ge / sa[:, None] * sx_obs[None, :]), 2)))
    nominal = min(_gen_min_eig(_cl_term(d, X, raw.G[i], i) + _cl_term(d, X, raw.G[i], i).T, X) for i in range(4))
    # physical units: |phi| <= sa_phi sqrt(X_phiphi V2) with V2 <= (2/eta2) eps5 |phi_r/sr|^2, resp. (2 g/eta2)^2 |e_s|^2
    roll = sa[PHI] * math.sqrt(X[PHI, PHI])
    iss = {
        "decay_rate": eta,
        "nominal_decay_rate": nominal,
        "overshoot": math.sqrt(lamX[-1] / lamX[0]),
        "gain_delta": math.sqrt(2 * e4 / (eta * lmin_P2)) if eta > 0 else math.inf,
        "gain_reference": math.sqrt(2 * e5 / (eta * lmin_P2)) if eta > 0 else math.inf,
        "gain_estimation_error": 2 * g / (eta * math.sqrt(lmin_P2)) if eta > 0 else math.inf,
        "coupling_g": g,
        "l2_gain_reference_to_h2": math.sqrt(e5 * raw.eps[2]),
        "roll_per_reference_rad": float(roll * math.sqrt(2 * e5 / eta) / sr) if eta > 0 else math.inf,
        "roll_per_roll_estimate_error_rad": float(roll * 2 * g / (eta * sx_obs[PHI])) if eta > 0 else math.inf,
    }
    poles = np.array([np.linalg.eigvals(d.A[i] - d.B @ Ks[i][None, :]) for i in range(4)])
    return ControllerDesign(K=K, X=X, Y=raw.G, eps=raw.eps, sa=sa, su=su, sr=sr, eta=eta, iss=iss, poles=poles,
                            status=raw.status, build_s=raw.build_s, solve_s=raw.solve_s, balance_s=balance_s)


def certify(ts: TSModel, aug: AugmentedModel, obs: ObserverDesign, ctl: ControllerDesign,
            options: DesignOptions) -> Certificate:
    """Re-check every inequality of both theorems in numpy from the solved variables.

    Rebuilds the scaled vertex data from the TS model and the stored scales,
    then evaluates the largest eigenvalue of each LMI block (theorem, decay,
    disk, gain bound) at each vertex, and of ``-P``, ``-Pq`` and ``-eps``.
    """
    out: list[CertificateEntry] = []
    for theorem, d, o, P, Pq, G, eps in (
        (OBSERVER, _observer_data(ts, obs.sx, obs.sy), options.observer, obs.P, obs.Pq, obs.Z, obs.eps),
        (CONTROLLER, _controller_data(aug, ctl.sa, ctl.su, ctl.sr), options.controller, ctl.X, None, ctl.Y, ctl.eps),
    ):
        radius = options.radius(o)
        for i in range(4):
            for name, blk in _blocks(d, P, Pq, G[i], eps, i, o.decay, radius, FAMILIES + (GAIN,), np.block,
                                     o.iss_rate).items():
                top = max_eig(blk)
                if name == GAIN:  # non-strict: relative violation
                    top /= max(1.0, float(np.linalg.norm(blk, 2)))
                out.append(CertificateEntry(name, i, top, strict=name != GAIN, theorem=theorem))
        out.append(CertificateEntry("P > 0", None, float(-np.linalg.eigvalsh(P)[0]), theorem=theorem))
        if Pq is not None:
            out.append(CertificateEntry("Pq > 0", None, float(-np.linalg.eigvalsh(Pq)[0]), theorem=theorem))
        out.append(CertificateEntry("eps > 0", None, float(-np.min(eps)), theorem=theorem))
    return Certificate(margin=options.margin, entries=tuple(out))


def check_discrete(ts: TSModel, aug: AugmentedModel, disc: DiscreteTS, options: DesignOptions,
                   continuous_poles: np.ndarray) -> DiscreteCheck:
    """Spectral radii of the sampled loop (plant ZOH-discretised, runtime as implemented) on a premise grid."""
    speeds = np.linspace(ts.vmin, ts.vmax, options.grid)
    orho = np.empty((options.grid, 2))
    crho = np.empty((options.grid, 2))
    for a, v in enumerate(speeds):
        for b, phi in enumerate((ts.phi_max, 0.0)):
            mu = ts.memberships(v, phi)
            orho[a, b] = np.max(np.abs(np.linalg.eigvals(np.einsum("i,ijk->jk", mu, disc.Phi)[:8, :8])))
            crho[a, b] = np.max(np.abs(np.linalg.eigvals(sampled_closed_loop(aug, disc, mu, mu))))
    dmin = min(options.observer.decay, options.controller.decay)
    required = math.exp(-0.5 * dmin * options.dt) if dmin > 0 else 1.0 - 1e-9
    ratio = float(np.max(np.abs(continuous_poles))) * options.dt / math.pi
    return DiscreteCheck(dt=options.dt, speeds=speeds, observer_rho=orho, closed_loop_rho=crho,
                         required=required, nyquist_ratio=ratio)


@dataclass(frozen=True, eq=False)
class TSDesign:
    """A certified TS observer-based controller design (what :func:`design` returns).

    Attributes
    ----------
    ts, aug : TSModel, AugmentedModel
    options : DesignOptions
    solver : str
    observer : ObserverDesign
    controller : ControllerDesign
    certificate : Certificate
        Passed (else :func:`design` raises).
    discrete : DiscreteCheck
        Passed (else :func:`design` raises).
    runtime : DiscreteTS
        The discretised vertex observer-controllers used by :class:`~assist.control.ts_controller.TSObserverController`.
    key : str
        Cache key (hash of the vertex matrices, options, solver and formulation version).
    cached : bool
        True when this object came from the cache instead of a solve.
    """

    ts: TSModel
    aug: AugmentedModel
    options: DesignOptions
    solver: str
    observer: ObserverDesign
    controller: ControllerDesign
    certificate: Certificate
    discrete: DiscreteCheck
    runtime: DiscreteTS
    key: str
    cached: bool = False

    @property
    def solve_s(self) -> float:
        """Wall time of the original design [s]: balancing, building and solving both theorems."""
        o, c = self.observer, self.controller
        return o.balance_s + o.build_s + o.solve_s + c.balance_s + c.build_s + c.solve_s

    def summary(self) -> dict[str, Any]:
        """What ``ptw-assist design`` prints and writes with ``--json`` (cli.md), JSON-serialisable."""
        return _summary(self)


def _finish(ts: TSModel, aug: AugmentedModel, options: DesignOptions, solver: str, key: str,
            raw_o: _Raw, sx: np.ndarray, sy: np.ndarray, bal_o: float,
            raw_c: _Raw, sa: np.ndarray, su: float, sr: float, bal_c: float) -> TSDesign:
    """Gains, certificate, ISS bounds and the sampled-loop check; raises :class:`DesignError` on any failure."""
    d_o = _observer_data(ts, sx, sy)
    d_c = _controller_data(aug, sa, su, sr)
    for theorem, raw in ((OBSERVER, raw_o), (CONTROLLER, raw_c)):
        c = np.linalg.cond(raw.P)
        cmax = (options.observer if theorem == OBSERVER else options.controller).cond_max
        if not np.all(np.isfinite(raw.G)) or not math.isfinite(c) or c > 1.01 * cmax:
            raise DesignError(theorem, "P >= I, P <= cond_max I", None,
                              f"badly conditioned solution (cond(P) = {c:.3g}, bound {cmax:g}, solver status "
                              f"{raw.status}); the problem is numerically ill-posed")
    obs = _observer_result(raw_o, d_o, sx, sy, bal_o)
    ctl = _controller_result(raw_c, d_c, sa, su, sr, aug, sx, bal_c)
    cert = certify(ts, aug, obs, ctl, options)
    if not cert.passed:
        bad = max(cert.failures(), key=lambda e: e.max_eig)
        status = raw_o.status if bad.theorem == OBSERVER else raw_c.status
        where = _where(ts, bad.vertex) if bad.vertex is not None else ""
        raise DesignError(
            bad.theorem, bad.lmi, bad.vertex,
            f"the solver {solver} reported '{status}' but the numpy check finds largest eigenvalue "
            f"{bad.max_eig:+.3e} (must be < {-options.margin:.1e}): the returned point violates the LMI"
            + (" (SCS at default tolerance returns such answers; use CLARABEL)" if solver == "SCS" else
               f"; the problem is badly conditioned: likely cause a speed range [{ts.vmin:g}, {ts.vmax:g}] m/s too "
               "wide for one common Lyapunov matrix (narrow or split it)"),
            where,
        )
    disc = discretise(aug, obs.L, ctl.K, options.dt)
    allpoles = np.concatenate([obs.poles.ravel(), ctl.poles.ravel()])
    dchk = check_discrete(ts, aug, disc, options, allpoles)
    if not dchk.passed:
        a, b = np.unravel_index(np.argmax(dchk.closed_loop_rho), dchk.closed_loop_rho.shape)
        raise DesignError(
            "sampled implementation", "discrete closed loop", None,
            f"spectral radius {dchk.closed_loop_rho[a, b]:.4f} (observer {dchk.observer_rho.max():.4f}) at "
            f"vx = {dchk.speeds[a]:g} m/s, z2 = {'z2min' if b == 0 else '1'} exceeds {dchk.required:.4f} for "
            f"dt = {options.dt} s (Nyquist ratio {dchk.nyquist_ratio:.2f}); lower the pole radius or shorten dt",
        )
    return TSDesign(ts=ts, aug=aug, options=options, solver=solver, observer=obs, controller=ctl,
                    certificate=cert, discrete=dchk, runtime=disc, key=key)


# --------------------------------------------------------------------------- cache
_MEMORY: dict[str, TSDesign] = {}


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/ptw-assist/ts-design`` (``~/.cache/...`` when unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ptw-assist" / "ts-design"


def clear_cache(cache_dir: str | Path | None = None) -> None:
    """Forget the in-memory designs (and delete the cached files in ``cache_dir`` when given)."""
    _MEMORY.clear()
    if cache_dir is not None:
        for p in Path(cache_dir).glob("*.npz"):
            p.unlink()


def _options_dict(options: DesignOptions) -> dict[str, Any]:
    return json.loads(json.dumps(asdict(options)))


def cache_key(ts: TSModel, options: DesignOptions, solver: str) -> str:
    """Hash of everything that determines a design: vertex matrices, premise box, options, solver, formulation."""
    h = hashlib.sha256()
    h.update(FORMULATION_VERSION.encode())
    h.update(solver.encode())
    h.update(json.dumps(_options_dict(options), sort_keys=True).encode())
    for a in (ts.A, ts.B, ts.C, ts.vertices):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()[:32]


def _save(path: Path, raw_o: _Raw, sx, sy, bal_o, raw_c: _Raw, sa, su, sr, bal_c) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp.npz")
    np.savez(
        tmp,
        o_P=raw_o.P, o_Pq=raw_o.Pq, o_G=raw_o.G, o_eps=raw_o.eps, o_sx=sx, o_sy=sy,
        o_t=np.array([raw_o.build_s, raw_o.solve_s, bal_o]), o_status=np.array(raw_o.status),
        c_P=raw_c.P, c_G=raw_c.G, c_eps=raw_c.eps, c_sa=sa, c_su=np.array(su), c_sr=np.array(sr),
        c_t=np.array([raw_c.build_s, raw_c.solve_s, bal_c]), c_status=np.array(raw_c.status),
    )
    os.replace(tmp, path)


def _load(path: Path, ts, aug, options, solver, key) -> TSDesign | None:
    """A design from disk, re-certified; None when the file is missing, unreadable or fails the checks."""
    try:
        with np.load(path) as f:
            raw_o = _Raw(f["o_P"], f["o_Pq"], f["o_G"], f["o_eps"], str(f["o_status"]), *map(float, f["o_t"][:2]))
            raw_c = _Raw(f["c_P"], None, f["c_G"], f["c_eps"], str(f["c_status"]), *map(float, f["c_t"][:2]))
            args = (f["o_sx"], f["o_sy"], float(f["o_t"][2]), raw_c, f["c_sa"], float(f["c_su"]),
                    float(f["c_sr"]), float(f["c_t"][2]))
        return _finish(ts, aug, options, solver, key, raw_o, *args)
    except (OSError, KeyError, ValueError):
        return None


# --------------------------------------------------------------------------- the design
def design(
    vehicle: Vehicle | None = None,
    *,
    vmin: float | None = None,
    vmax: float | None = None,
    phi_max: float = PHI_MAX,
    options: DesignOptions | None = None,
    solver: str = "CLARABEL",
    cache: bool = True,
    cache_dir: str | Path | None = None,
) -> TSDesign:
    """Design, certify and discretise the TS observer (Theorem 1) and controller (Theorem 2).

    Parameters
    ----------
    vehicle : Vehicle, optional
        Defaults to the reference scooter.
    vmin, vmax : float, optional
        Speed range of the premise box [m/s]; default the vehicle's design range
        (:attr:`ptw_env.vehicle.Vehicle.control_range`; :data:`DEFAULT_SPEED_RANGE` for the reference scooter).
    phi_max : float
        Roll bound of the premise box [rad] (default 45 deg).
    options : DesignOptions, optional
    solver : {"CLARABEL", "SCS"}
        SDP solver. SCS is offered for comparison only: at its default
        tolerance its "optimal" points usually fail the certificate.
    cache : bool
        Reuse a design of the same key solved earlier in this process.
    cache_dir : str or Path, optional
        Also keep designs on disk there (e.g. :func:`default_cache_dir`); a file
        is re-certified when loaded.

    Returns
    -------
    TSDesign

    Raises
    ------
    DesignError
        Infeasible, inaccurate, badly conditioned, uncertified, or a sampled
        loop that is not stable enough; the message names the theorem, the LMI,
        the vertex and the likely cause.
    DesignOptionError, assist.control.ts_model.PremiseError
        Bad options or premise box.
    """
    options = DesignOptions() if options is None else options
    if not isinstance(options, DesignOptions):
        raise DesignOptionError(f"options must be a DesignOptions, got {type(options).__name__}")
    if solver not in SOLVERS:
        raise DesignOptionError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    v_design = split_model(vehicle)[0].control_range  # default: the vehicle's design range
    ts = build_ts_model(vehicle, v_design[0] if vmin is None else vmin, v_design[1] if vmax is None else vmax, phi_max)
    aug = augment(ts)
    key = cache_key(ts, options, solver)
    if cache and key in _MEMORY:
        from dataclasses import replace

        return replace(_MEMORY[key], cached=True)
    path = Path(cache_dir) / f"{key}.npz" if cache_dir is not None else None
    if path is not None and path.exists():
        got = _load(path, ts, aug, options, solver, key)
        if got is not None:
            from dataclasses import replace

            got = replace(got, cached=True)
            if cache:
                _MEMORY[key] = got
            return got

    sc = options.scaling
    margin = options.margin
    # Theorem 1
    sx = np.array(sc.state)
    sy = np.array(sc.noise)
    sx0, sa0 = sx.copy(), np.r_[sc.state, sc.e_phi, sc.s2]

    def remake_o(f: np.ndarray) -> _Data:
        return _observer_data(ts, sx0 * f, sy)

    def remake_c(f: np.ndarray) -> _Data:
        return _controller_data(aug, sa0 * f, sc.torque, sc.state[0])

    o = options.observer
    t0 = time.perf_counter()
    if options.balance:
        f = _balance(_observer_data(ts, sx, sy), o, options.radius(o), margin, solver)
        if f is None:
            raise _diagnose(OBSERVER, _observer_data(ts, sx, sy), o, options.radius(o), margin, solver, ts, remake_o)
        sx = sx * f
    bal_o = time.perf_counter() - t0
    d_o = _observer_data(ts, sx, sy)
    raw_o = _solve(d_o, o, options.radius(o), margin, solver)
    if raw_o is None:
        raise _diagnose(OBSERVER, d_o, o, options.radius(o), margin, solver, ts, remake_o)
    # Theorem 2
    sa = np.r_[sc.state, sc.e_phi, sc.s2]
    su, sr = sc.torque, sc.state[0]
    c = options.controller
    t0 = time.perf_counter()
    if options.balance:
        f = _balance(_controller_data(aug, sa, su, sr), c, options.radius(c), margin, solver)
        if f is None:
            raise _diagnose(CONTROLLER, _controller_data(aug, sa, su, sr), c, options.radius(c), margin, solver, ts,
                            remake_c)
        sa = sa * f
    bal_c = time.perf_counter() - t0
    d_c = _controller_data(aug, sa, su, sr)
    raw_c = _solve(d_c, c, options.radius(c), margin, solver)
    if raw_c is None:
        raise _diagnose(CONTROLLER, d_c, c, options.radius(c), margin, solver, ts, remake_c)

    out = _finish(ts, aug, options, solver, key, raw_o, sx, sy, bal_o, raw_c, sa, su, sr, bal_c)
    if cache:
        _MEMORY[key] = out
    if path is not None:
        _save(path, raw_o, sx, sy, bal_o, raw_c, sa, su, sr, bal_c)
    return out


def _cplx(a: np.ndarray) -> list[list[float]]:
    a = np.asarray(a).ravel()
    a = a[np.lexsort((a.imag, a.real))]
    return [[float(z.real), float(z.imag)] for z in a]


def _summary(dz: TSDesign) -> dict[str, Any]:
    o, c, ts = dz.observer, dz.controller, dz.ts
    cert = dz.certificate
    dchk = dz.discrete
    return {
        "feasible": True,
        "solve_s": dz.solve_s,
        "cached": dz.cached,
        "solver": dz.solver,
        "speed_range": [ts.vmin, ts.vmax],
        "phi_max_deg": math.degrees(ts.phi_max),
        "vertices": [
            {"index": i, "vx": float(ts.vertices[i, 0]), "z2": float(ts.vertices[i, 1]),
             "open_loop_poles": _cplx(np.linalg.eigvals(ts.A[i])),
             "observer_poles": _cplx(o.poles[i]), "closed_loop_poles": _cplx(c.poles[i])}
            for i in range(4)
        ],
        "gains": {
            "L": o.L.tolist(),
            "K": c.K.tolist(),
            "L_rows": list(STATE_NAMES),
            "L_columns": list(MEASUREMENT_NAMES),
            "K_columns": list(STATE_NAMES) + list(AUGMENTED_NAMES),
            "max_norm_L": float(max(np.linalg.norm(a, 2) for a in o.L)),
            "max_norm_K": float(np.max(np.linalg.norm(c.K, axis=1))),
        },
        "eps": {**{f"eps{k + 1}": float(o.eps[k]) for k in range(3)},
                **{f"eps{k + 4}": float(c.eps[k]) for k in range(3)}},
        "iss": {"observer": {k: float(v) for k, v in o.iss.items()},
                "controller": {k: float(v) for k, v in c.iss.items()},
                "units": "scaled coordinates (see scaling), except the entries ending in _rad, _mps: physical"},
        "margins": {
            "observer_lmi": -cert.worst(OBSERVER, FAMILIES).max_eig,
            "controller_lmi": -cert.worst(CONTROLLER, FAMILIES).max_eig,
            "required_lmi": cert.margin,
            "discrete_observer_rho": float(dchk.observer_rho.max()),
            "discrete_closed_loop_rho": float(dchk.closed_loop_rho.max()),
            "discrete_required_rho": dchk.required,
            "nyquist_ratio": dchk.nyquist_ratio,
        },
        "timing": {
            "observer": {"balance_s": o.balance_s, "build_s": o.build_s, "solve_s": o.solve_s, "status": o.status},
            "controller": {"balance_s": c.balance_s, "build_s": c.build_s, "solve_s": c.solve_s, "status": c.status},
        },
        "scaling": {"state": o.sx.tolist(), "noise": o.sy.tolist(), "augmented": c.sa.tolist(),
                    "torque": c.su, "reference": c.sr},
        "options": _options_dict(dz.options),
        "key": dz.key,
    }


def compare_solver(dz: TSDesign, solver: str = "SCS") -> dict[str, Any]:
    """Solve the two theorem problems of ``dz`` again with ``solver``, same scaled data and options, and certify.

    The issue's warning made measurable: SCS at its default tolerance reports
    "optimal" points that violate the LMIs. Per theorem: wall time [s] (build
    and solve), the solver's status, and the numpy certificate of the
    returned point (largest eigenvalue of every block of that theorem,
    required ``< -margin``); ``certified`` for the pair, which is what
    :func:`design` would require before using the gains.

    Returns
    -------
    dict
        ``{"solver", "observer": {...}, "controller": {...}, "wall_s", "certified"}``; each theorem entry
        holds ``wall_s``, ``status``, ``worst_lmi`` (name, vertex, max eigenvalue) or None when no point came back.
    """
    if solver not in SOLVERS:
        raise DesignOptionError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    opts = dz.options
    o, c = dz.observer, dz.controller
    data = {OBSERVER: _observer_data(dz.ts, o.sx, o.sy), CONTROLLER: _controller_data(dz.aug, c.sa, c.su, c.sr)}
    raws: dict[str, _Raw | None] = {}
    out: dict[str, Any] = {"solver": solver}
    for theorem, key, th in ((OBSERVER, "observer", opts.observer), (CONTROLLER, "controller", opts.controller)):
        status: list[str] = []
        t0 = time.perf_counter()
        raws[theorem] = _solve(data[theorem], th, opts.radius(th), opts.margin, solver, status=status)
        out[key] = {"wall_s": time.perf_counter() - t0, "status": status[-1] if status else "unknown",
                    "worst_lmi": None}
    out["wall_s"] = out["observer"]["wall_s"] + out["controller"]["wall_s"]
    out["certified"] = False
    if raws[OBSERVER] is None or raws[CONTROLLER] is None:
        return out
    obs = _observer_result(raws[OBSERVER], data[OBSERVER], o.sx, o.sy, 0.0)
    ctl = _controller_result(raws[CONTROLLER], data[CONTROLLER], c.sa, c.su, c.sr, dz.aug, o.sx, 0.0)
    cert = certify(dz.ts, dz.aug, obs, ctl, opts)
    for theorem, key in ((OBSERVER, "observer"), (CONTROLLER, "controller")):
        w = cert.worst(theorem, FAMILIES)
        out[key]["worst_lmi"] = {"lmi": w.lmi, "vertex": w.vertex, "max_eig": w.max_eig}
        out[key]["certified"] = not any(f.theorem == theorem for f in cert.failures())
    out["certified"] = cert.passed
    return out


def design_report(vehicle: Vehicle | None = None, **kwargs: Any) -> dict[str, Any]:
    """:func:`design` (same arguments) as the ``ptw-assist design --json`` dictionary.

    A :class:`DesignError` becomes ``{"feasible": false, "error": {...}}`` with
    the theorem, LMI, vertex and cause; other errors propagate.
    """
    try:
        return design(vehicle, **kwargs).summary()
    except DesignError as err:
        return {"feasible": False, "solve_s": None, "gains": {}, "margins": {},
                "error": {"message": str(err), "theorem": err.theorem, "lmi": err.lmi,
                          "vertex": err.vertex, "cause": err.cause}}


def format_summary(s: dict[str, Any]) -> str:
    """Short human-readable text of a :func:`design_report` / :meth:`TSDesign.summary` dictionary."""
    if not s.get("feasible"):
        return f"TS design: INFEASIBLE\n  {s['error']['message']}"
    m, e = s["margins"], s["eps"]
    io, ic = s["iss"]["observer"], s["iss"]["controller"]
    lines = [
        f"TS observer-based controller design ({s['solver']}, {s['solve_s']:.2f} s"
        + (", from cache" if s.get("cached") else "") + ")",
        f"  premise box: vx in [{s['speed_range'][0]:g}, {s['speed_range'][1]:g}] m/s, |phi| <= {s['phi_max_deg']:.0f} deg",
    ]
    for v in s["vertices"]:
        slow_o = max(p[0] for p in v["observer_poles"])
        slow_c = max(p[0] for p in v["closed_loop_poles"])
        lines.append(f"  vertex {v['index']}: vx = {v['vx']:5.1f} m/s, z2 = {v['z2']:.4f}; slowest pole "
                     f"observer {slow_o:6.2f}, controller {slow_c:6.2f} rad/s")
    lines += [
        "  eps: " + ", ".join(f"{k} = {val:.4g}" for k, val in e.items()),
        f"  |L| <= {s['gains']['max_norm_L']:.4g}, |K| <= {s['gains']['max_norm_K']:.4g}",
        *_format_gains(s["gains"]),
        f"  ISS observer: decay {io['decay_rate']:.3g} 1/s, overshoot {io['overshoot']:.3g}, "
        f"gain(Delta) {io['gain_delta']:.3g}, gain(noise) {io['gain_noise']:.3g} (scaled units)",
        f"  ISS controller: decay {ic['decay_rate']:.3g} 1/s, overshoot {ic['overshoot']:.3g}, "
        f"gain(Delta) {ic['gain_delta']:.3g}, gain(ref) {ic['gain_reference']:.3g}, "
        f"gain(e) {ic['gain_estimation_error']:.3g} (scaled units)",
        "  ISS in physical units (worst case at steady state; they certify boundedness, as accuracy they are "
        "loose by orders of magnitude):",
        f"    roll-estimate error <= {math.degrees(io['phi_error_at_design_noise_rad']):.3g} deg, vy error <= "
        f"{io['vy_error_at_design_noise_mps']:.3g} m/s, with noise at the design level in every channel",
        f"    |phi| <= {ic['roll_per_reference_rad']:.3g} deg per deg of reference, "
        f"{ic['roll_per_roll_estimate_error_rad']:.3g} deg per deg of roll-estimate error",
        f"  LMI margins: observer {m['observer_lmi']:.3g}, controller {m['controller_lmi']:.3g} "
        f"(required {m['required_lmi']:.1g}); certificate checked in numpy",
        f"  100 Hz loop: spectral radius {m['discrete_closed_loop_rho']:.4f} (observer {m['discrete_observer_rho']:.4f}) "
        f"< {m['discrete_required_rho']:.4f}; max |pole| dt/pi = {m['nyquist_ratio']:.2f}",
    ]
    for th, part in s["timing"].items():
        lines.append(f"  {th} solve: balance {part['balance_s']:.2f} s, build {part['build_s']:.2f} s, "
                     f"solve {part['solve_s']:.2f} s, status {part['status']}"
                     + (" (solver short of full accuracy; the numpy certificate above is what counts)"
                        if part["status"] != "optimal" else ""))
    return "\n".join(lines)


def _format_gains(g: dict[str, Any]) -> list[str]:
    """The gain matrices of a summary, one line per vertex (K) and per state row (L, vertices side by side)."""
    w = 10
    K = np.asarray(g["K"])
    out = ["  controller gains K_i, tau = -sum_i mu_i K_i [x; e_phi; s2] (N m per rad, m/s, rad/s, N, rad s):",
           "        " + "".join(f"{n:>{w}}" for n in g["K_columns"])]
    out += [f"    K_{i} " + "".join(f"{v:>{w}.3g}" for v in row) for i, row in enumerate(K)]
    L = np.asarray(g["L"])
    w = 11
    head = "".join(f"{c:>{w}}" for c in g["L_columns"])
    out.append("  observer gains L_i, x_hat' = ... + L_i (y - C x_hat) (rows: states; columns: measurements):")
    for pair in ((0, 1), (2, 3)):
        out.append(f"    {'':9}" + "  ".join(f"{'L_' + str(i):>{w}}" + " " * (3 * w) for i in pair).rstrip())
        out.append(f"    {'':9}" + "  ".join(head for _ in pair))
        for r, name in enumerate(g["L_rows"]):
            out.append(f"    {name:9}" + "  ".join("".join(f"{v:>{w}.3g}" for v in L[i, r]) for i in pair))
    return out


__all__ = [
    "Certificate",
    "CertificateEntry",
    "ControllerDesign",
    "DEFAULT_SPEED_RANGE",
    "DesignError",
    "DesignOptionError",
    "DesignOptions",
    "DiscreteCheck",
    "ObserverDesign",
    "Scaling",
    "TSDesign",
    "TheoremOptions",
    "cache_key",
    "certify",
    "check_discrete",
    "clear_cache",
    "compare_solver",
    "default_cache_dir",
    "design",
    "design_report",
    "format_summary",
]
