"""Exact Takagi-Sugeno form of the reference scooter, and its augmentation for roll tracking.

The nonlinear plant of ``shared/spec/model.md`` is

.. math::

    E \\dot x = \\bigl(A_0 + v_x A_1\\bigr) x + B\\tau
      + \\text{rows 5, 6: } a_{i1}(\\sin\\phi - \\phi) + a_{i2}(\\sin\\delta - \\delta).

With the premise variables of Dabladji et al. [1]_, eq. (7),

.. math::

    z_1 = v_x \\in [v_{min}, v_{max}], \\qquad
    z_2 = \\frac{\\sin\\phi}{\\phi} \\in \\Bigl[\\frac{\\sin\\phi_{max}}{\\phi_{max}}, 1\\Bigr]
    \\quad (\\phi_{max} = 45^\\circ),

``a51 sin(phi) = a51 z2 phi`` and ``a61 sin(phi) = a61 z2 phi``, so the
state matrix ``A~(z) = A0 + z1 A1`` with ``a51, a61`` multiplied by ``z2`` is
*bi-affine* in ``(z1, z2)``. The sector (convex) decomposition

.. math::

    \\dot x = \\sum_{i=1}^{4} \\mu_i(z) A_i x + B\\tau, \\qquad
    A_i = E^{-1}\\tilde A(z^{(i)}), \\quad B = E^{-1} \\tilde B,

with ``mu_i = w_{1,a}(z1) w_{2,b}(z2)``, ``w_{1,0} = (vmax - z1)/(vmax - vmin)``,
``w_{1,1} = 1 - w_{1,0}``, ``w_{2,0} = (1 - z2)/(1 - z2min)``,
``w_{2,1} = 1 - w_{2,0}``, is therefore *exact* on the box ([1]_, eqs. 6-7):
the only approximation is ``sin(delta) ~ delta`` (steering angles are a few
degrees). Vertex ``i = 2a + b`` sits at ``(z1, z2) = (vmin|vmax, z2min|1)``.

All vertex matrices are built from a :class:`~ptw_env.vehicle.Vehicle`
(default :data:`~ptw_env.vehicle.REFERENCE_SCOOTER`), or from a compiled
:class:`~ptw_env.dynamics.Plant` (e.g. an environment's prior,
``env.get_prior()``) whose dynamic effects keep that structure; nothing here
writes a model entry.

Effects the TS form can express (:data:`TS_EXPRESSIBLE_EFFECTS`): those of
effects.md that only change the linear matrices, ``tire_stiffness``,
``payload``, ``steer_damping``, ``relaxation_length``. The plant is then still
``x' = A_l(vx) x + g_phi (sin(phi) - phi) + g_delta (sin(delta) - delta) + B tau``
with ``A_l`` affine in ``vx``, and the vertex matrices are
``A_i = A_l(z1) + (z2 - 1) g_phi e_phi^T``, read off ``Plant.rhs`` (the physics
stays in :mod:`ptw_env.dynamics`). ``road_bank`` and ``roll_moment_offset``
add a constant term and ``tire_saturation`` a saturation of the tire forces,
none of which a sum of linear vertex models holds: they raise
:class:`UnsupportedEffectError` instead of being dropped silently.

Augmentation (the roll-tracking design model, [1]_ section III-B and eq. (1))
---------------------------------------------------------------------------
The controller works on ``x_a = [x, e_phi, s2]`` (10 states) with

.. math::

    \\dot e_\\phi = \\phi - \\phi_r, \\qquad
    \\dot s_2 = -\\omega_2 s_2 + k_2(\\phi - \\phi_r), \\qquad h_2 = s_2,

i.e. ``h2 = k2/(s + w2) (phi - phi_r)`` with ``k2 = 40 pi``, ``w2 = 20 pi``
rad/s (the paper's low-pass sensitivity signal), so that
``x_a' = sum mu_i A_a,i x_a + B1 phi_r + B2 tau`` and ``h2 = C12 x_a``
(paper's eq. 1). The observer's sensitivity signal
``h1 = 3 s/(s + 30 pi) e`` is a weight on the estimation error only; its
realisation ``q' = -w1 q + e``, ``h1 = k1 e - k1 w1 q`` (``k1 = 3``,
``w1 = 30 pi``) is used by :mod:`assist.control.ts_design` and given here as
:func:`observer_sensitivity_filter`.

Measurements (the order every function of the TS controller uses)
-----------------------------------------------------------------
``y = [yaw_rate r, roll_rate phi_dot, delta, delta_rate delta_dot]``
(rad/s, rad/s, rad, rad/s): IMU gyros and steering encoder, [1]_ section VI.

References
----------
.. [1] H. Dabladji, D. Ichalal, H. Arioui, S. Mammar, "Observer based
   controller for single track vehicles", 52nd IEEE CDC, 2013, pp. 7420-7425.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ptw_env.vehicle import DELTA, DELTA_DOT, PHI, PHI_DOT, R, REFERENCE_SCOOTER, Vehicle

#: Largest roll angle of the premise box [rad] (model.md: the model is valid to 45 deg).
PHI_MAX = math.pi / 4

#: Measured plant states, in the order of ``y``: yaw rate, roll rate, steering angle, steering rate.
MEASURED_STATES: tuple[int, ...] = (R, PHI_DOT, DELTA, DELTA_DOT)
#: Names of the measurement channels, same order (the ride-log column names of logs.md).
MEASUREMENT_NAMES: tuple[str, ...] = ("yaw_rate", "roll_rate", "delta", "delta_rate")
#: Units of the measurement channels.
MEASUREMENT_UNITS: tuple[str, ...] = ("rad/s", "rad/s", "rad", "rad/s")
#: Names of the augmented controller states appended to ``x``.
AUGMENTED_NAMES: tuple[str, ...] = ("e_phi", "s2")

#: Observer sensitivity filter h1 = K1 s/(s + W1) e: gain [-] and corner [rad/s] ([1]_, sec. III-B).
H1_GAIN, H1_CORNER = 3.0, 30.0 * math.pi
#: Controller sensitivity filter h2 = K2/(s + W2) (phi - phi_r): gain [1/s] and corner [rad/s].
H2_GAIN, H2_CORNER = 40.0 * math.pi, 20.0 * math.pi


#: Dynamic effects of effects.md that the TS form expresses exactly (they change the linear matrices only).
TS_EXPRESSIBLE_EFFECTS: tuple[str, ...] = ("tire_stiffness", "payload", "steer_damping", "relaxation_length")


class PremiseError(ValueError):
    """A premise-box definition that cannot hold (speed range outside the vehicle's, phi_max out of (0, pi/2))."""


class UnsupportedEffectError(ValueError):
    """A plant effect the TS model cannot express (a constant term or tire saturation)."""


def sinc_premise(phi: np.ndarray | float) -> np.ndarray:
    """``z2 = sin(phi)/phi`` with the removable singularity filled (``z2(0) = 1``) [-]."""
    return np.sinc(np.asarray(phi, dtype=float) / np.pi)


@dataclass(frozen=True, eq=False)
class TSModel:
    """Four-vertex Takagi-Sugeno model ``x' = sum_i mu_i(z) A_i x + B tau`` (exact up to sin(delta) ~ delta).

    Build it with :func:`build_ts_model`.

    Attributes
    ----------
    vehicle : Vehicle
        Source of every matrix entry (with ``effects`` on top).
    vmin, vmax : float
        Premise box on ``z1 = vx`` [m/s].
    phi_max : float
        Premise box on roll [rad]: ``z2 in [sin(phi_max)/phi_max, 1]``.
    z2min : float
        ``sin(phi_max)/phi_max`` [-].
    A : ndarray, shape (4, 8, 8)
        Vertex state matrices ``E^-1 A~(z^(i))`` [1/s and mixed SI].
    B : ndarray, shape (8, 1)
        ``E^-1 B~`` (torque input) [per N m].
    C : ndarray, shape (4, 8)
        Measurement matrix (rows: yaw rate, roll rate, steering angle, steering rate).
    vertices : ndarray, shape (4, 2)
        ``(z1, z2)`` of each vertex.
    effects : tuple of str
        Names of the dynamic effects folded into the matrices (empty: the vehicle alone).
    """

    vehicle: Vehicle
    vmin: float
    vmax: float
    phi_max: float
    z2min: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    vertices: np.ndarray
    effects: tuple[str, ...] = ()

    # -- premise and memberships -----------------------------------------
    def premises(self, vx: np.ndarray | float, phi: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """``(z1, z2)`` clipped to the premise box (``vx`` [m/s], ``phi`` [rad])."""
        z1 = np.clip(np.asarray(vx, dtype=float), self.vmin, self.vmax)
        z2 = np.clip(sinc_premise(phi), self.z2min, 1.0)
        return z1, z2

    def memberships(self, vx: np.ndarray | float, phi: np.ndarray | float) -> np.ndarray:
        """Sector membership functions ``mu_i``, shape ``broadcast(vx, phi) + (4,)``; they sum to 1.

        ``mu_{2a+b} = w_{1,a}(z1) w_{2,b}(z2)`` with the affine weights of the
        module docstring; premises outside the box are clipped onto it first.
        """
        z1, z2 = self.premises(vx, phi)
        w1_hi = (z1 - self.vmin) / (self.vmax - self.vmin)
        w2_hi = (z2 - self.z2min) / (1.0 - self.z2min)
        w1 = np.stack([1.0 - w1_hi, w1_hi], axis=-1)
        w2 = np.stack([1.0 - w2_hi, w2_hi], axis=-1)
        return (w1[..., :, None] * w2[..., None, :]).reshape(w1.shape[:-1] + (4,))

    def blend(self, mu: np.ndarray) -> np.ndarray:
        """``sum_i mu_i A_i``, shape ``mu.shape[:-1] + (8, 8)``."""
        return np.einsum("...i,ijk->...jk", np.asarray(mu, dtype=float), self.A)

    def state_matrix(self, vx: float, phi: float = 0.0) -> np.ndarray:
        """The TS state matrix ``A(z)`` at speed ``vx`` [m/s] and roll ``phi`` [rad] (8 x 8)."""
        return self.blend(self.memberships(vx, phi))

    def rhs(self, x: np.ndarray, tau: np.ndarray | float, vx: np.ndarray | float) -> np.ndarray:
        """``x' = sum_i mu_i(vx, phi) A_i x + B tau`` (premise from the state itself), batched over leading axes.

        Equals :meth:`ptw_env.dynamics.Plant.rhs` of the nominal plant except for
        ``sin(delta) ~ delta`` whenever ``vx`` and ``phi`` lie in the premise box.
        """
        x = np.asarray(x, dtype=float)
        Az = self.state_matrix(vx, x[..., PHI])
        return np.einsum("...jk,...k->...j", Az, x) + self.B[:, 0] * np.asarray(tau, dtype=float)[..., None]

    def measure(self, x: np.ndarray) -> np.ndarray:
        """Noise-free measurements ``y = C x`` = [yaw_rate, roll_rate, delta, delta_rate]."""
        return np.asarray(x, dtype=float) @ self.C.T


@dataclass(frozen=True, eq=False)
class AugmentedModel:
    """The TS model augmented with the roll-error integral and the low-pass sensitivity state.

    ``x_a = [x, e_phi, s2]``, ``x_a' = sum_i mu_i A_i x_a + B1 phi_r + B2 tau``,
    ``h2 = C12 x_a`` ([1]_, eq. 1; module docstring).

    Attributes
    ----------
    ts : TSModel
    A : ndarray, shape (4, 10, 10)
    B1 : ndarray, shape (10, 1)
        Reference input ``phi_r`` [rad].
    B2 : ndarray, shape (10, 1)
        Torque input [N m].
    C12 : ndarray, shape (1, 10)
        Sensitivity output ``h2 = s2``.
    Ac, Bc : ndarray, shapes (2, 2), (2, 1)
        The augmentation alone: ``[e_phi, s2]' = Ac [e_phi, s2] + Bc (phi - phi_r)``
        (what the runtime integrates with ``phi_hat``).
    """

    ts: TSModel
    A: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    C12: np.ndarray
    Ac: np.ndarray
    Bc: np.ndarray

    @property
    def n(self) -> int:
        return self.A.shape[-1]


def _plant_columns(plant, vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(A_l(vx), g_phi, B)`` of a plant ``x' = A_l x + g_phi (sin phi - phi) + g_delta (sin delta - delta) + B tau``.

    Read off :meth:`ptw_env.dynamics.Plant.rhs`: column ``j`` of ``A_l`` is
    ``f(e_j)`` for the states entering linearly; for ``phi`` and ``delta``,
    ``f(h e_j) = h A_l[:, j] + (sin h - h) g_j`` at ``h = 0.5`` and ``1`` rad
    gives both vectors (a 2 x 2 solve per row).
    """
    f = plant.rhs
    A = np.empty((8, 8))
    g_phi = np.zeros(8)
    for j in range(8):
        e = np.zeros(8)
        if j in (PHI, DELTA):
            hs = np.array([0.5, 1.0])
            M = np.column_stack([hs, np.sin(hs) - hs])
            F = np.stack([f(h * np.eye(8)[j], 0.0, vx) for h in hs])
            sol = np.linalg.solve(M, F)
            A[:, j] = sol[0]
            if j == PHI:
                g_phi = sol[1]
        else:
            e[j] = 1.0
            A[:, j] = f(e, 0.0, vx)
    B = (f(np.zeros(8), 1.0, vx) - f(np.zeros(8), 0.0, vx))[:, None]
    return A, g_phi, B


def split_model(model) -> tuple[Vehicle, object | None, tuple[str, ...]]:
    """``(vehicle, plant or None, effect names)`` of a design model: a Vehicle, None (the reference scooter),
    or a :class:`~ptw_env.dynamics.Plant` whose effects the TS form expresses (``plant`` is None when it
    has none); raises :class:`UnsupportedEffectError` otherwise."""
    from ptw_env.dynamics import Plant

    if model is None:
        return REFERENCE_SCOOTER, None, ()
    if isinstance(model, Vehicle):
        return model, None, ()
    if not isinstance(model, Plant):
        raise TypeError(f"vehicle must be a Vehicle or a ptw_env.dynamics.Plant, got {type(model).__name__}")
    if model.batch_shape:
        raise UnsupportedEffectError(f"the TS model takes one plant, got a batch of shape {model.batch_shape}")
    causes = tuple(model.effects.dynamic.params)
    bad = [c for c in causes if c not in TS_EXPRESSIBLE_EFFECTS]
    if bad:
        raise UnsupportedEffectError(
            f"the TS model cannot express the effect(s) {', '.join(bad)} of the plant (a constant term or tire "
            f"saturation is not a blend of linear vertex models); it can: {', '.join(TS_EXPRESSIBLE_EFFECTS)}")
    return model.vehicle, (model if causes else None), causes


def upright_matrices(model=None, vx: float = 15.0) -> tuple[np.ndarray, np.ndarray]:
    """``(A, B)`` of the model linearised at the upright at speed ``vx`` [m/s]: ``(E^-1 A(vx), E^-1 B)`` (model.md).

    ``model``: a Vehicle (default the reference scooter) or a plant with
    :data:`TS_EXPRESSIBLE_EFFECTS` only (read off its ``rhs``; the sines
    have unit slope at 0), so every controller designed on an environment's
    prior uses the same matrices as the TS model.

    Examples
    --------
    >>> A, B = upright_matrices(vx=20.0)
    >>> A.shape, B.shape
    ((8, 8), (8, 1))
    """
    v, plant, _ = split_model(model)
    if plant is None:
        return v.state_matrix(vx), v.input_matrix()
    A, _, B = _plant_columns(plant, float(vx))
    return A, B


def build_ts_model(
    vehicle=None,
    vmin: float | None = None,
    vmax: float | None = None,
    phi_max: float = PHI_MAX,
) -> TSModel:
    """Vertex matrices of the exact TS model on ``[vmin, vmax] x [sin(phi_max)/phi_max, 1]``.

    Parameters
    ----------
    vehicle : Vehicle or ptw_env.dynamics.Plant, optional
        Defaults to the reference scooter. A plant (e.g. ``env.get_prior()``)
        brings its dynamic effects; only :data:`TS_EXPRESSIBLE_EFFECTS` are
        accepted (module docstring).
    vmin, vmax : float, optional
        Speed range of the model [m/s]; default the vehicle's valid range
        (the LQR's feedforward table uses it so). Must lie inside it with
        ``vmin < vmax``. :func:`assist.control.ts_design.design` passes the vehicle's
        design range (:attr:`ptw_env.vehicle.Vehicle.control_range`).
    phi_max : float
        Roll bound of the premise box [rad], in (0, pi/2); default 45 deg.

    Raises
    ------
    PremiseError
        When the box is empty or leaves the vehicle's valid range.
    UnsupportedEffectError
        A plant with an effect the TS form cannot express (``road_bank``,
        ``roll_moment_offset``, ``tire_saturation``).
    """
    v, plant, causes = split_model(vehicle)
    lo = v.vmin if vmin is None else float(vmin)
    hi = v.vmax if vmax is None else float(vmax)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise PremiseError(f"speed range must satisfy vmin < vmax, got vmin={lo!r}, vmax={hi!r} m/s")
    if lo < v.vmin or hi > v.vmax:
        raise PremiseError(
            f"speed range [{lo}, {hi}] m/s leaves the vehicle's valid range [{v.vmin}, {v.vmax}] m/s ({v.name})"
        )
    if not (0.0 < phi_max < math.pi / 2):
        raise PremiseError(f"phi_max must lie in (0, pi/2) rad, got {phi_max!r}")
    z2min = float(math.sin(phi_max) / phi_max)
    verts = np.array([[z1, z2] for z1 in (lo, hi) for z2 in (z2min, 1.0)])
    A = np.empty((4, 8, 8))
    if plant is None:
        for i, (z1, z2) in enumerate(verts):
            At = v.A(z1).copy()
            At[PHI_DOT, PHI] *= z2  # a51 phi -> a51 z2 phi = a51 sin(phi)
            At[DELTA_DOT, PHI] *= z2  # a61 phi -> a61 sin(phi)
            A[i] = np.linalg.solve(v.E, At)
        B = v.input_matrix()
    else:
        for i, (z1, z2) in enumerate(verts):
            Al, g_phi, B = _plant_columns(plant, z1)
            Al[:, PHI] += (z2 - 1.0) * g_phi  # A_l phi + g_phi (sin(phi) - phi) with sin(phi) = z2 phi
            A[i] = Al
    C = np.zeros((4, 8))
    for row, col in enumerate(MEASURED_STATES):
        C[row, col] = 1.0
    for a in (A, B, C, verts):
        a.setflags(write=False)
    return TSModel(vehicle=v, vmin=lo, vmax=hi, phi_max=float(phi_max), z2min=z2min, A=A, B=B, C=C, vertices=verts,
                   effects=causes)


def augment(ts: TSModel) -> AugmentedModel:
    """Append ``e_phi`` (integral of ``phi - phi_r``) and ``s2`` (low-pass sensitivity state) to ``ts``.

    .. math::

        A_{a,i} = \\begin{bmatrix} A_i & 0 & 0 \\\\ e_\\phi^T & 0 & 0 \\\\
                   k_2 e_\\phi^T & 0 & -\\omega_2 \\end{bmatrix},\\;
        B_1 = \\begin{bmatrix} 0 \\\\ -1 \\\\ -k_2 \\end{bmatrix},\\;
        B_2 = \\begin{bmatrix} B \\\\ 0 \\\\ 0 \\end{bmatrix},\\;
        C_{12} = [0 \\; 0 \\; 1]

    (``k2 = 40 pi`` 1/s, ``w2 = 20 pi`` rad/s, [1]_ section III-B).
    """
    Ac = np.array([[0.0, 0.0], [0.0, -H2_CORNER]])
    Bc = np.array([[1.0], [H2_GAIN]])
    A = np.zeros((4, 10, 10))
    A[:, :8, :8] = ts.A
    A[:, 8:, 8:] = Ac
    A[:, 8:, PHI] = Bc[:, 0]
    B1 = np.zeros((10, 1))
    B1[8:, 0] = -Bc[:, 0]
    B2 = np.zeros((10, 1))
    B2[:8] = ts.B
    C12 = np.zeros((1, 10))
    C12[0, 9] = 1.0
    for a in (A, B1, B2, C12, Ac, Bc):
        a.setflags(write=False)
    return AugmentedModel(ts=ts, A=A, B1=B1, B2=B2, C12=C12, Ac=Ac, Bc=Bc)


def observer_sensitivity_filter(n: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """State-space ``(Aq, Bq, Cq, Dq)`` of ``h1 = 3 s/(s + 30 pi) e`` applied to each of ``n`` error channels.

    ``q' = -w1 q + e``, ``h1 = -k1 w1 q + k1 e`` (``3 s/(s+w1) = 3 - 3 w1/(s+w1)``).
    """
    eye = np.eye(n)
    return -H1_CORNER * eye, eye.copy(), -H1_GAIN * H1_CORNER * eye, H1_GAIN * eye


__all__ = [
    "AUGMENTED_NAMES",
    "AugmentedModel",
    "MEASUREMENT_NAMES",
    "MEASUREMENT_UNITS",
    "MEASURED_STATES",
    "PHI_MAX",
    "PremiseError",
    "TSModel",
    "TS_EXPRESSIBLE_EFFECTS",
    "UnsupportedEffectError",
    "augment",
    "build_ts_model",
    "observer_sensitivity_filter",
    "sinc_premise",
    "split_model",
    "upright_matrices",
]
