"""Exact sampled-data form of the TS observer-controller (the runtime's discretisation).

Per vertex the 10-state system ``z' = F_i z + G_i v`` (``z = [x_hat, e_phi, s2]``,
``v = [tau, y, phi_r]``, Dabladji et al., CDC 2013, eqs. 8 and 21) is discretised
exactly over one period ``dt`` with the torque held (zero-order hold) and the
measurements and the reference interpolated linearly between samples
(first-order hold)::

    z_k = Phi_i z_{k-1} + Gamma0_i v_{k-1} + Gamma1_i (v_k - v_{k-1})

``[Phi, Gamma0, Gamma1]`` are blocks of ``expm([[F, G, 0], [0, 0, I], [0, 0, 0]] dt)``.
Used by the design (:mod:`assist.control.ts_design`, which checks the sampled loop's
stability on a grid of frozen premises with :func:`sampled_closed_loop`) and by
the runtime (:mod:`assist.control.ts_controller`); it sits below both, so neither
imports the other for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from assist.control.ts_model import PHI, AugmentedModel

#: number of runtime states z = [x_hat (8), e_phi, s2]
NZ = 10
#: inputs v = [tau, y (4), phi_r]
NV = 6


@dataclass(frozen=True, eq=False)
class DiscreteTS:
    """Exact FOH/ZOH discretisation of the four vertex observer-controllers (see module docstring).

    Attributes
    ----------
    dt : float
        Sampling period [s].
    Phi : ndarray, shape (4, 10, 10)
    Gamma0 : ndarray, shape (4, 10, 6)
        Effect of ``v_{k-1} = [tau, y, phi_r]``.
    Gamma1 : ndarray, shape (4, 10, 6)
        Effect of ``v_k - v_{k-1}`` (its torque column is zero: the torque is held).
    K : ndarray, shape (4, 10)
        Vertex feedback gains ``tau = -K_i z`` [N m per unit state].
    stacked : ndarray, shape (40, 22)
        ``[Phi | Gamma0 | Gamma1]`` of the vertices stacked for one matrix-vector product.
    """

    dt: float
    Phi: np.ndarray
    Gamma0: np.ndarray
    Gamma1: np.ndarray
    K: np.ndarray
    stacked: np.ndarray


def vertex_systems(aug: AugmentedModel, L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Continuous vertex systems ``(F, G)`` of the runtime, shapes (4, 10, 10), (4, 10, 6).

    ``F_i = [[A_i - L_i C, 0], [Bc e_phi^T, Ac]]``, ``G_i = [[B, L_i, 0], [0, 0, -Bc]]``
    (module docstring; ``L`` has shape (4, 8, 4)).
    """
    ts = aug.ts
    F = np.zeros((4, NZ, NZ))
    G = np.zeros((4, NZ, NV))
    for i in range(4):
        F[i, :8, :8] = ts.A[i] - L[i] @ ts.C
        F[i, 8:, PHI] = aug.Bc[:, 0]
        F[i, 8:, 8:] = aug.Ac
        G[i, :8, 0] = ts.B[:, 0]
        G[i, :8, 1:5] = L[i]
        G[i, 8:, 5] = -aug.Bc[:, 0]
    return F, G


def foh_discretise(F: np.ndarray, G: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Phi, Gamma0, Gamma1)`` of ``z' = F z + G v`` with ``v`` linear over ``[0, dt]``.

    ``z(dt) = Phi z(0) + Gamma0 v(0) + Gamma1 (v(dt) - v(0))``, from
    ``expm([[F, G, 0], [0, 0, I/dt], [0, 0, 0]] dt)`` (exact for linear ``v``).
    """
    n, m = G.shape
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n] = F
    M[:n, n : n + m] = G
    M[n : n + m, n + m :] = np.eye(m) / dt
    E = sla.expm(M * dt)
    return E[:n, :n], E[:n, n : n + m], E[:n, n + m :]


def discretise(aug: AugmentedModel, L: np.ndarray, K: np.ndarray, dt: float) -> DiscreteTS:
    """Discretise the vertex observer-controllers for a ``dt``-periodic implementation.

    Parameters
    ----------
    aug : AugmentedModel
    L : ndarray, shape (4, 8, 4)
        Observer gains (physical units).
    K : ndarray, shape (4, 10)
        Controller gains (physical units).
    dt : float
        Sampling period [s].
    """
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    F, G = vertex_systems(aug, L)
    Phi = np.empty((4, NZ, NZ))
    G0 = np.empty((4, NZ, NV))
    G1 = np.empty((4, NZ, NV))
    for i in range(4):
        Phi[i], G0[i], G1[i] = foh_discretise(F[i], G[i], dt)
    G1[:, :, 0] = 0.0  # the torque is held: v_k - v_{k-1} has no torque part inside a period
    stacked = np.concatenate([Phi, G0, G1], axis=2).reshape(4 * NZ, NZ + 2 * NV)
    K = np.asarray(K, dtype=float).reshape(4, NZ)
    for a in (Phi, G0, G1, K, stacked):
        a.setflags(write=False)
    return DiscreteTS(dt=float(dt), Phi=Phi, Gamma0=G0, Gamma1=G1, K=K, stacked=np.ascontiguousarray(stacked))


def sampled_closed_loop(aug: AugmentedModel, disc: DiscreteTS, mu_plant: np.ndarray, mu_ctrl: np.ndarray) -> np.ndarray:
    """Transition matrix of the sampled loop: frozen TS plant + discretised observer-controller.

    The plant ``x' = A(mu_plant) x + B tau`` is discretised exactly with the
    torque held (``Ad, Bd``); the runtime uses the blend ``mu_ctrl`` of the
    discrete vertex matrices. With ``s_k = [x_k, z_k]``, ``tau_k = -K z_k``,
    ``y = C x`` and ``phi_r = 0``::

        x_k = Ad x_{k-1} + Bd tau_{k-1}
        z_k = Phi z_{k-1} + Gamma0 [tau_{k-1}, C x_{k-1}, 0] + Gamma1 [0, C (x_k - x_{k-1}), 0]

    Returns the (18, 18) matrix ``s_k = T s_{k-1}``; the loop is stable for these
    frozen premises iff its spectral radius is below 1.
    """
    ts = aug.ts
    mu_p = np.asarray(mu_plant, dtype=float)
    mu_c = np.asarray(mu_ctrl, dtype=float)
    A = np.einsum("i,ijk->jk", mu_p, ts.A)
    n = 8
    M = np.zeros((n + 1, n + 1))
    M[:n, :n] = A
    M[:n, n:] = ts.B
    Ed = sla.expm(M * disc.dt)
    Ad, Bd = Ed[:n, :n], Ed[:n, n:]
    Phi = np.einsum("i,ijk->jk", mu_c, disc.Phi)
    G0 = np.einsum("i,ijk->jk", mu_c, disc.Gamma0)
    G1 = np.einsum("i,ijk->jk", mu_c, disc.Gamma1)
    K = (mu_c @ disc.K)[None, :]
    C = ts.C
    G0u, G0y = G0[:, :1], G0[:, 1:5]
    G1y = G1[:, 1:5]
    T = np.zeros((n + NZ, n + NZ))
    T[:n, :n] = Ad
    T[:n, n:] = -Bd @ K
    T[n:, :n] = G0y @ C + G1y @ C @ (Ad - np.eye(n))
    T[n:, n:] = Phi - G0u @ K - G1y @ C @ Bd @ K
    return T


__all__ = ["NV", "NZ", "DiscreteTS", "discretise", "foh_discretise", "sampled_closed_loop", "vertex_systems"]
