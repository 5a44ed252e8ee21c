"""Compiled kernels: the one implementation of the right-hand side and of RK4.

Everything that evaluates the nonlinear model (the environment, the batched
simulator, :meth:`ptw_env.dynamics.Plant.rhs`, hence linearisation and the
scipy reference integration in the tests) goes through :func:`rhs_into`. The
matrices it reads are built by :func:`ptw_env.dynamics.compile_plant` from
the one vehicle definition; see there for the equations.

Layout of a compiled plant row ``W[i]`` (i = 0..5: ``x'_i``; i = 6, 7:
``F_lin`` front/rear): ``W[i] . [x, vx x, x/vx, sin(phi-beta), sin(delta), tau, 1, d, vx^2,
tanh(delta_dot / COULOMB_WIDTH)]`` where ``d`` is an external roll moment [N m] (a disturbance
input, 0 unless the environment injects one). The last two features are zero in the vehicle
model of model.md; they carry generalised forces a model extension adds
(:func:`ptw_env.dynamics.add_generalised_forces`: aerodynamic terms in ``vx^2``, Coulomb steering
friction). The ``vx^2`` column is folded with the held speed; the Coulomb column, the only one
evaluated at every RK4 stage besides the sines, is skipped for plants that do not use it.

Over one control period ``vx`` and ``tau`` are held (zero-order hold, as in
the reference ride logs), so each period first folds them into an 8 x 8
matrix ``M`` and a vector ``c`` (:func:`fold_vx`) and the substeps only pay for
``M x``, two sines and the tire saturation.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


#: Width [rad/s] of the smooth sign ``tanh(delta_dot / w)`` of Coulomb steering friction.
COULOMB_WIDTH = 0.02


@njit(cache=True, inline="always")
def fold_vx(W, vx, tau, d, M, c, g):
    """Fold the held speed ``vx`` [m/s], torque ``tau`` [N m] and roll moment ``d`` [N m] into one period's
    ``M`` (8 x 8, ``M_ij = W_ij + vx W_i,8+j + W_i,16+j / vx``), ``c`` (constant part) and ``g`` (coefficients of
    ``sin(phi - bank)`` and ``sin(delta)``), written in place (module docstring: layout of ``W``)."""
    for i in range(8):
        for j in range(8):
            M[i, j] = W[i, j] + vx * W[i, 8 + j] + W[i, 16 + j] / vx
        g[i, 0] = W[i, 24]
        g[i, 1] = W[i, 25]
        c[i] = W[i, 26] * tau + W[i, 27] + W[i, 28] * d + W[i, 29] * vx * vx


@njit(cache=True, inline="always")
def _has_coulomb(W):
    for i in range(6):
        if W[i, 30] != 0.0:
            return True
    return False


@njit(cache=True, inline="always")
def _add_coulomb(x, W, out):
    s = np.tanh(x[5] / COULOMB_WIDTH)
    for i in range(6):
        out[i] += W[i, 30] * s


@njit(cache=True, inline="always")
def deriv(x, M, c, g, vx, inv_sigma, fmax, bank, out):
    """``out = x'`` of one vehicle for a folded period (:func:`fold_vx`): ``M x + c + g [sin(phi - bank),
    sin(delta)]``, then the relaxation rows ``F_k' = vx / sigma_k (F_ss,k - F_k)`` with the saturated steady
    force ``F_ss = fmax tanh(F_lin / fmax)`` (``F_lin`` when ``fmax`` is infinite); model.md rows 7-8."""
    s1 = np.sin(x[0] - bank)
    s2 = np.sin(x[1])
    for i in range(8):
        acc = c[i] + g[i, 0] * s1 + g[i, 1] * s2
        for j in range(8):
            acc += M[i, j] * x[j]
        out[i] = acc
    for k in range(2):
        flin = out[6 + k]
        fm = fmax[k]
        if np.isfinite(fm):
            fss = fm * np.tanh(flin / fm)
        else:
            fss = flin
        out[6 + k] = vx * inv_sigma[k] * (fss - x[6 + k])


@njit(cache=True)
def rhs_into(x, tau, vx, W, inv_sigma, fmax, bank, out):
    """``out[n] = f(x[n], tau[n], vx[n])`` for a batch; ``W`` etc. have a leading
    axis of length 1 (shared) or N (one plant per vehicle)."""
    M = np.empty((8, 8))
    c = np.empty(8)
    g = np.empty((8, 2))
    K = W.shape[0]
    for n in range(x.shape[0]):
        k = n if K > 1 else n - n
        fold_vx(W[k], vx[n], tau[n], 0.0, M, c, g)
        deriv(x[n], M, c, g, vx[n], inv_sigma[k], fmax[k], bank[k], out[n])
        _add_coulomb(x[n], W[k], out[n])


@njit(cache=True, inline="always")
def _rk4_period(x, M, c, g, vx, inv_sigma, fmax, bank, h, nsub, k1, k2, k3, k4, tmp):
    for _ in range(nsub):
        deriv(x, M, c, g, vx, inv_sigma, fmax, bank, k1)
        for i in range(8):
            tmp[i] = x[i] + 0.5 * h * k1[i]
        deriv(tmp, M, c, g, vx, inv_sigma, fmax, bank, k2)
        for i in range(8):
            tmp[i] = x[i] + 0.5 * h * k2[i]
        deriv(tmp, M, c, g, vx, inv_sigma, fmax, bank, k3)
        for i in range(8):
            tmp[i] = x[i] + h * k3[i]
        deriv(tmp, M, c, g, vx, inv_sigma, fmax, bank, k4)
        for i in range(8):
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True, inline="always")
def _rk4_period_c(x, M, c, g, W, vx, inv_sigma, fmax, bank, h, nsub, k1, k2, k3, k4, tmp):
    """:func:`_rk4_period` with the Coulomb column of ``W`` evaluated at every stage."""
    for _ in range(nsub):
        deriv(x, M, c, g, vx, inv_sigma, fmax, bank, k1)
        _add_coulomb(x, W, k1)
        for i in range(8):
            tmp[i] = x[i] + 0.5 * h * k1[i]
        deriv(tmp, M, c, g, vx, inv_sigma, fmax, bank, k2)
        _add_coulomb(tmp, W, k2)
        for i in range(8):
            tmp[i] = x[i] + 0.5 * h * k2[i]
        deriv(tmp, M, c, g, vx, inv_sigma, fmax, bank, k3)
        _add_coulomb(tmp, W, k3)
        for i in range(8):
            tmp[i] = x[i] + h * k3[i]
        deriv(tmp, M, c, g, vx, inv_sigma, fmax, bank, k4)
        _add_coulomb(tmp, W, k4)
        for i in range(8):
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def scratch():
    """Work arrays of :func:`advance` ``(M, c, g, k)``: ``M`` (8, 8), ``c`` (8,), ``g`` (8, 2) and ``k`` (5, 8)
    (the four RK4 stages and a temporary); allocate once per thread, not per step."""
    return np.empty((8, 8)), np.empty(8), np.empty((8, 2)), np.empty((5, 8))


@njit(cache=True)
def advance(x, tau, vx, d, W, inv_sigma, fmax, bank, dt, nsub, M, c, g, k):
    """Advance one vehicle (``x`` shape (8,), modified in place) by one control
    period ``dt`` with ``tau``, ``vx`` and the roll-moment disturbance ``d`` held;
    ``nsub`` RK4 substeps; ``M, c, g, k`` from :func:`scratch`. Returns True when the new state is finite."""
    fold_vx(W, vx, tau, d, M, c, g)
    if _has_coulomb(W):
        _rk4_period_c(x, M, c, g, W, vx, inv_sigma, fmax, bank, dt / nsub, nsub, k[0], k[1], k[2], k[3], k[4])
    else:
        _rk4_period(x, M, c, g, vx, inv_sigma, fmax, bank, dt / nsub, nsub, k[0], k[1], k[2], k[3], k[4])
    for i in range(8):
        if not np.isfinite(x[i]):
            return False
    return True


@njit(cache=True)
def step_one(x, tau, vx, d, W, inv_sigma, fmax, bank, dt, nsub):
    """:func:`advance` with its own work arrays (one vehicle, one period)."""
    M, c, g, k = scratch()
    return advance(x, tau, vx, d, W, inv_sigma, fmax, bank, dt, nsub, M, c, g, k)


@njit(cache=True, parallel=True)
def simulate_batch(x0, tau, vx, W, inv_sigma, fmax, bank, dt, nsub, out):
    """``out[n, t]`` = state at ``t dt`` (``out[n, 0] = x0[n]``) for ``tau[n, t]``,
    ``vx[n, t]`` held over ``[t dt, (t+1) dt)``. Vehicles run in parallel."""
    N = x0.shape[0]
    T = tau.shape[1]
    K = W.shape[0]
    for n in prange(N):
        k = n if K > 1 else n - n
        M = np.empty((8, 8))
        c = np.empty(8)
        g = np.empty((8, 2))
        k1 = np.empty(8)
        k2 = np.empty(8)
        k3 = np.empty(8)
        k4 = np.empty(8)
        tmp = np.empty(8)
        x = x0[n].copy()
        out[n, 0] = x
        coul = _has_coulomb(W[k])
        for t in range(T):
            fold_vx(W[k], vx[n, t], tau[n, t], 0.0, M, c, g)
            if coul:
                _rk4_period_c(x, M, c, g, W[k], vx[n, t], inv_sigma[k], fmax[k], bank[k], dt / nsub, nsub,
                              k1, k2, k3, k4, tmp)
            else:
                _rk4_period(x, M, c, g, vx[n, t], inv_sigma[k], fmax[k], bank[k], dt / nsub, nsub,
                            k1, k2, k3, k4, tmp)
            out[n, t + 1] = x
