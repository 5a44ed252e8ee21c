"""Runtime of the LPV adaptive observer: states and tire stiffnesses from the scooter's own sensors.

Fouka, Nehaoua, Arioui [1]_, eqs. (17), (38), on the model of
:mod:`assist.estimation.lpv_model` with the certified gains of :mod:`assist.estimation.adaptive_design`:

.. math::

    \\dot{\\hat x} = f(\\hat x, \\tau, v_x) + D\\,\\chi(\\hat x, v_x)\\,\\hat\\Theta
        + L(v_x)\\,(y - C \\hat x), \\qquad L(v_x) = \\textstyle\\sum_i \\eta_i(v_x) L_i,

``f`` the nominal *nonlinear* plant's right-hand side (the one in
:mod:`ptw_env.kernels`: the paper's ``A(vx) x + B tau`` plus the sine terms),
``y = [delta, r, phi_dot, delta_dot, ay]`` (the roll angle is not used).
Two adaptive laws drive ``Theta_hat``; both keep every stiffness in the box
``[band_lo, band_hi] x C_0`` (default 0.2-2: positive, at most twice the
nominal) by projection.

The paper's law (``law="paper"``, [1]_ eqs. 18/30)
------------------------------------------------
``Theta_hat' = Proj(Gamma chi_f^T T eps_f)`` with ``eps_f = H(s) [y - C x_hat;
y_a - c_a x_hat]`` and ``chi_f = H(s) chi(x_hat, vx)``: one low-pass ``H(s) =
w^2/(s^2 + 2 zeta w s + w^2)`` (``zeta = 0.7071``, ``w = 2 pi filter_hz``)
on both factors keeps their relative phase. The virtual sensor ([1]_ eq. 15)
comes from the same filter, ``H y_a = m . (s H)[r, phi_dot, delta_dot] + H(n(vx)
. [r, phi_dot, delta_dot])`` (:meth:`assist.estimation.lpv_model.LPVModel.virtual_sensor_coefficients`):
a proper derivative, never a difference of noisy samples. With a diagonal
``Gamma`` the projection onto a box is the clipped update, which does not
increase ``Theta~^T Gamma^-1 Theta~`` (Ioannou and Sun, *Robust Adaptive
Control*, sec. 4.11). ``Gamma`` (:func:`adaptation_gain`): a slow parameter
error settles the state error at ``x~ = (L C - A)^-1 D chi Theta~``, so the
averaged law is ``Theta~' = -Gamma H_bar Theta~`` with ``H_bar = mean_k
chi_k^T T C_a (L(vx_k) C - A(vx_k))^-1 D chi_k`` over a reference ride (the
nominal urban ride, true states); ``Gamma = diag(1/(tau_a H_bar_jj))`` gives
each parameter alone the time constant ``tau_a`` (default 10 s).

**Why it is not the default.** For the reference scooter the eigenvalues of
``Gamma H_bar`` spread over four decades (e.g. 0.37, 0.033, 3.4e-4 and
-3e-5 1/s at ``tau_a`` = 10 s): the observer's output injection absorbs most
of a parameter error into the other states (``vy`` above all), so the fixed
weighting ``T C x~`` sees the common stiffness scale -- exactly what road
friction changes -- hardly at all, and the direction with a negative rate
(the equality ``D^T P = T C`` holds only to ~15 %) drifts. On the handling
track with friction 0.6 it ends at ``C/C_0 = (0.84, 0.84, 0.75, 0.67)``
after 87 s (``scripts/eval_adaptive.py`` has the numbers).

The sensitivity law (``law="sensitivity"``, default)
---------------------------------------------------
The same observer with the adaptive law of the adaptive-observer literature
that does not need ``D^T P = T C`` (Zhang, IEEE TAC 47(3), 2002; a two-stage
Kalman form): the sensitivity ``U = d x_hat / d s`` of the estimate to the
stiffness scales ``s_j = Theta_j / C_0j`` obeys

.. math::

    \\dot U = \\bigl(A(v_x) + D\\,\\partial_x(\\chi\\hat\\Theta) - L(v_x) C\\bigr) U
        + D\\,\\chi(\\hat x, v_x)\\operatorname{diag}(C_0),

and at each sample ``e = y - C x_hat``, ``H = C U``,
``K = Gamma H^T (H Gamma H^T + R_eff)^-1``, ``s += K e`` (then the
projection), ``x_hat += U Delta s``, ``Gamma <- (I - K H) Gamma + q^2 dt I``.
``Gamma`` is the covariance of the scale estimate: it starts at
``stiffness_std0^2 I`` (prior: the nominal tire within 50 %) and the
random-walk intensity ``q = stiffness_walk`` sets how fast a friction change
is followed -- the documented way to choose the adaptation gain.
``R_eff = R + C Sigma_x C^T`` (:func:`effective_noise`) adds the observer's
own steady error covariance to the sensor noise; without it the law fits the
stiffnesses to noise and sampling effects. ``Gamma`` is a time-varying
``Gamma(t)`` in [1]_'s law with the regressor ``chi`` replaced by its
effect on the outputs through the observer, ``C U``.

Which gains, which parameters (measured: ``scripts/eval_adaptive.py``, 5 % noise)
--------------------------------------------------------------------------------
* The certified Theorem-2 gains (:func:`assist.estimation.adaptive_design.design_adaptive_observer`)
  must dominate the Lipschitz bound of the sine terms and the stiffness band with one
  quadratic Lyapunov function, which takes ``||L_i|| ~ 1e5-1e6``: the observer then absorbs
  a stiffness error into its state correction and feeds its noise into ``chi(x_hat)``, and
  the four stiffnesses end 5-40 % off.
* Vertex Kalman gains (:func:`assist.estimation.adaptive_design.kalman_design`, ``||L_i|| ~ 1e4``,
  certified for the linear polytope only) keep the innovations informative: the four
  stiffnesses end within ~1-13 %; the camber stiffnesses are the weak ones, as the
  Cramér-Rao bound says they must be (:mod:`assist.estimation.identifiability`: 1-sigma of
  ``C_gamma_r`` after 15 s of riding is 4-8 % on the handling track and 23-32 % in town).
* Kalman gains with one scale per axle (``parametrisation="axle"``, camber and cornering
  stiffness of a tire scaled together, as road friction does) end within ~1 % and are within
  5 % after 15 s of riding in 9 of 10 evaluation rides.

Discretisation (what :meth:`AdaptiveObserver.update` does at sample ``k``)
------------------------------------------------------------------------
1. The state (and ``U``) is integrated from ``t_{k-1}`` to ``t_k`` by RK4
   (the plant's substeps) with ``tau_{k-1}`` and ``vx_{k-1}`` held (they are
   held over the period in the logs) and ``y`` interpolated linearly between
   ``y_{k-1}`` and ``y_k`` (first-order hold: no half-sample lag; holding
   ``y_{k-1}`` biases the force estimates by ``F' dt/2`` and, through them,
   the adaptation);
2. the filters take sample ``k`` (exact zero-order-hold discretisation);
3. the adaptive law updates ``Theta_hat`` (paper: one explicit Euler step).

Missing samples (NaN): a channel missing at either end of a period has no
innovation over it (pure prediction), its filters are fed the prediction and
the sensitivity law leaves it out. A missing speed keeps the last valid one.

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers" (``shared/papers/000_348caefc9b08ee38.txt``).
.. [2] Q. Zhang, "Adaptive observer for multiple-input-multiple-output (MIMO)
   linear time-varying systems", IEEE TAC 47(3), 525-529, 2002.

Length (about 820 lines): the compiled kernels, the three adaptive laws and the run-time class share
one state layout; a third is this docstring with the paper's corrections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg as sla
from numba import njit

from ptw_env.dynamics import compile_plant
from ptw_env.integrate import substeps_for
from ptw_env.kernels import deriv, fold_vx
from ptw_env.logs import held_speed, input_series
from ptw_env.vehicle import PHI_DOT, R, DELTA_DOT

from assist.estimation.adaptive_design import AdaptiveObserverDesign, default_design
from assist.estimation.identifiability import PARAMETRISATIONS
from assist.estimation.lpv_model import OUTPUT_NAMES, THETA_NAMES, LPVModel, bank_column, check_bank, chi_entry

# --------------------------------------------------------------------------- compiled kernels
# Filter bank of the paper's law (one H(s) per signal; f[k, 0] = H u, f[k, 1] = s H u):
#   0-2   measured r, phi_dot, delta_dot (their derivatives feed y_a)
#   3     n(vx) . [r, phi_dot, delta_dot] (the non-derivative part of y_a)
#   4     c_a . x_hat (the predicted virtual sensor)
#   5-9   innovations y - C x_hat of the five outputs
#   10-13 the four regressor entries chi_j(x_hat, vx)
NFILT = 14
NY = 5
LAW_NONE, LAW_PAPER, LAW_SENSITIVITY = 0, 1, 2


@njit(cache=True, inline="always")
def _obs_deriv(x, M, c, g, vxd, inv_sigma, fmax, bank, th, H0, H1, Lb, C, y0, y1, wm, a, out, e5):
    deriv(x, M, c, g, vxd, inv_sigma, fmax, bank, out)
    # D chi(x, vx) Theta
    for j in range(4):
        out[6 + j // 2] += chi_entry(x, vxd, H0, H1, j) * th[j]
    # L (y - C x), y interpolated linearly over the period (first-order hold)
    for r in range(NY):
        if wm[r]:
            acc = y0[r] + a * (y1[r] - y0[r])
            for i in range(8):
                acc -= C[r, i] * x[i]
            e5[r] = acc
        else:
            e5[r] = 0.0
    for i in range(8):
        acc = 0.0
        for r in range(NY):
            acc += Lb[i, r] * e5[r]
        out[i] += acc


@njit(cache=True, inline="always")
def _ups_deriv(U, Acl, x, vxd, H0, H1, c0, out):
    # U' = Acl U + D chi(x, vx) diag(C_0)
    for i in range(8):
        for j in range(4):
            acc = 0.0
            for l in range(8):
                acc += Acl[i, l] * U[l, j]
            out[i, j] = acc
    for j in range(4):
        out[6 + j // 2, j] += chi_entry(x, vxd, H0, H1, j) * c0[j]


@njit(cache=True, inline="always")
def _filt(f, k, u, Phi, G):
    a = Phi[0, 0] * f[k, 0] + Phi[0, 1] * f[k, 1] + G[0] * u
    b = Phi[1, 0] * f[k, 0] + Phi[1, 1] * f[k, 1] + G[1] * u
    f[k, 0] = a
    f[k, 1] = b


@njit(cache=True, inline="always")
def _gains(vx, Lv, vmin, vmax, Lb):
    vs = min(max(vx, vmin), vmax)
    w1 = (vmax - vs) / (vmax - vmin)
    for i in range(8):
        for r in range(NY):
            Lb[i, r] = w1 * Lv[0, i, r] + (1.0 - w1) * Lv[1, i, r]


@njit(cache=True)
def _observer_step(xh, th, f, mem, yprev, U, Gam, y_in, tau, vx_in, W, inv_sigma, fmax, bank, dt, nsub,
                   Lv, vmin, vmax, vlo, vhi, H0, H1, C, cvirt, T, gamma, th_lo, th_hi,
                   Phi, G, mvirt, n0, n1, A0, A1, c0, Reff, Qw, law, out_e):
    """One sample ``k`` of the adaptive observer (module docstring of :mod:`assist.estimation.adaptive_observer`).

    ``xh`` (8), ``th`` (4), ``f`` (NFILT, 2), ``mem`` (3: tau_{k-1}, vx_{k-1}, started),
    ``yprev`` (5), ``U`` (8, 4) and ``Gam`` (4, 4) are updated in place. ``out_e`` (6)
    receives the filtered innovations of the paper's law. Returns False when the state
    stopped being finite.
    """
    wm = np.empty(NY, dtype=np.bool_)
    for r in range(NY):
        wm[r] = np.isfinite(y_in[r]) and np.isfinite(yprev[r])
    Lb = np.empty((8, NY))
    if mem[2] > 0.5:
        vxd = min(max(mem[1], vlo), vhi)
        _gains(mem[1], Lv, vmin, vmax, Lb)
        M = np.empty((8, 8))
        c = np.empty(8)
        g = np.empty((8, 2))
        fold_vx(W, vxd, mem[0], 0.0, M, c, g)
        k1 = np.empty(8)
        k2 = np.empty(8)
        k3 = np.empty(8)
        k4 = np.empty(8)
        tmp = np.empty(8)
        e5 = np.empty(NY)
        sens = law == LAW_SENSITIVITY
        if sens:
            Acl = np.empty((8, 8))
            for i in range(8):
                for l in range(8):
                    acc = A0[i, l] + vxd * A1[i, l]
                    for r in range(NY):
                        acc -= Lb[i, r] * C[r, l]
                    Acl[i, l] = acc
            for j in range(4):
                for l in range(8):
                    Acl[6 + j // 2, l] += th[j] * (H0[j, l] + vxd * H1[j, l])
            u1 = np.empty((8, 4))
            u2 = np.empty((8, 4))
            u3 = np.empty((8, 4))
            u4 = np.empty((8, 4))
            Ut = np.empty((8, 4))
        h = 1.0 / nsub
        hd = dt / nsub
        for s in range(nsub):
            a0 = s * h
            if sens:  # sensitivity, forced by chi at the start of the substep
                _ups_deriv(U, Acl, xh, vxd, H0, H1, c0, u1)
                for i in range(8):
                    for j in range(4):
                        Ut[i, j] = U[i, j] + 0.5 * hd * u1[i, j]
                _ups_deriv(Ut, Acl, xh, vxd, H0, H1, c0, u2)
                for i in range(8):
                    for j in range(4):
                        Ut[i, j] = U[i, j] + 0.5 * hd * u2[i, j]
                _ups_deriv(Ut, Acl, xh, vxd, H0, H1, c0, u3)
                for i in range(8):
                    for j in range(4):
                        Ut[i, j] = U[i, j] + hd * u3[i, j]
                _ups_deriv(Ut, Acl, xh, vxd, H0, H1, c0, u4)
                for i in range(8):
                    for j in range(4):
                        U[i, j] += hd / 6.0 * (u1[i, j] + 2.0 * u2[i, j] + 2.0 * u3[i, j] + u4[i, j])
            _obs_deriv(xh, M, c, g, vxd, inv_sigma, fmax, bank, th, H0, H1, Lb, C, yprev, y_in, wm, a0, k1, e5)
            for i in range(8):
                tmp[i] = xh[i] + 0.5 * hd * k1[i]
            _obs_deriv(tmp, M, c, g, vxd, inv_sigma, fmax, bank, th, H0, H1, Lb, C, yprev, y_in, wm, a0 + 0.5 * h, k2, e5)
            for i in range(8):
                tmp[i] = xh[i] + 0.5 * hd * k2[i]
            _obs_deriv(tmp, M, c, g, vxd, inv_sigma, fmax, bank, th, H0, H1, Lb, C, yprev, y_in, wm, a0 + 0.5 * h, k3, e5)
            for i in range(8):
                tmp[i] = xh[i] + hd * k3[i]
            _obs_deriv(tmp, M, c, g, vxd, inv_sigma, fmax, bank, th, H0, H1, Lb, C, yprev, y_in, wm, a0 + h, k4, e5)
            for i in range(8):
                xh[i] += hd / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    for i in range(8):
        if not np.isfinite(xh[i]):
            return False

    # ---- sample k: filters (a missing channel is replaced by its prediction: zero innovation)
    vxd = min(max(vx_in, vlo), vhi)
    y = np.empty(NY)
    for r in range(NY):
        if np.isfinite(y_in[r]):
            y[r] = y_in[r]
        else:
            acc = 0.0
            for i in range(8):
                acc += C[r, i] * xh[i]
            y[r] = acc
    q = 0.0
    for k in range(3):
        _filt(f, k, y[1 + k], Phi, G)
        q += (n0[k] + vxd * n1[k]) * y[1 + k]
    _filt(f, 3, q, Phi, G)
    ya_hat = 0.0
    for i in range(8):
        ya_hat += cvirt[i] * xh[i]
    _filt(f, 4, ya_hat, Phi, G)
    for r in range(NY):
        acc = y[r]
        for i in range(8):
            acc -= C[r, i] * xh[i]
        _filt(f, 5 + r, acc, Phi, G)
    for j in range(4):
        acc = 0.0
        for i in range(8):
            acc += (H0[j, i] + vxd * H1[j, i]) * xh[i]
        _filt(f, 10 + j, acc, Phi, G)
    for r in range(NY):
        out_e[r] = f[5 + r, 0]
    ya_f = f[3, 0]
    for k in range(3):
        ya_f += mvirt[k] * f[k, 1]
    out_e[5] = ya_f - f[4, 0]

    if law == LAW_PAPER:
        # Theta' = Gamma chi_f^T T eps_f (explicit Euler), then the projection on the box
        for j in range(4):
            k = j // 2
            s_ = 0.0
            for r in range(6):
                s_ += T[k, r] * out_e[r]
            v = th[j] + dt * gamma[j] * f[10 + j, 0] * s_
            th[j] = min(max(v, th_lo[j]), th_hi[j])
    elif law == LAW_SENSITIVITY:
        # parameter update from the innovation through the sensitivity H = C U (scale units s = Theta / C_0)
        e = np.zeros(NY)
        Hm = np.zeros((NY, 4))
        S = np.zeros((NY, NY))
        for r in range(NY):
            if np.isfinite(y_in[r]):
                acc = y_in[r]
                for i in range(8):
                    acc -= C[r, i] * xh[i]
                e[r] = acc
                for j in range(4):
                    a_ = 0.0
                    for i in range(8):
                        a_ += C[r, i] * U[i, j]
                    Hm[r, j] = a_
        HG = Hm @ Gam
        for r in range(NY):
            for r2 in range(NY):
                if np.isfinite(y_in[r]) and np.isfinite(y_in[r2]):
                    acc = Reff[r, r2]
                    for j in range(4):
                        acc += HG[r, j] * Hm[r2, j]
                    S[r, r2] = acc
                elif r == r2:
                    S[r, r2] = 1.0
        Kg = HG.T @ np.linalg.inv(S)  # (4, NY)
        ds = Kg @ e
        dth = np.empty(4)
        for j in range(4):
            v = th[j] + ds[j] * c0[j]
            v = min(max(v, th_lo[j]), th_hi[j])
            dth[j] = (v - th[j]) / c0[j]
            th[j] = v
        for i in range(8):
            acc = 0.0
            for j in range(4):
                acc += U[i, j] * dth[j]
            xh[i] += acc
        IKH = np.eye(4) - Kg @ Hm
        Gn = IKH @ Gam
        for i in range(4):
            for j in range(4):
                Gam[i, j] = 0.5 * (Gn[i, j] + Gn[j, i]) + Qw[i, j] * dt
    for r in range(NY):
        yprev[r] = y_in[r]
    mem[0] = tau
    mem[1] = vx_in
    mem[2] = 1.0
    return True


@njit(cache=True)
def _observer_run(X, TH, E6, xh, th, f, mem, yprev, U, Gam, Y, TAU, VX, W, inv_sigma, fmax, bank, dt, nsub,
                  Lv, vmin, vmax, vlo, vhi, H0, H1, C, cvirt, T, gamma, th_lo, th_hi,
                  Phi, G, mvirt, n0, n1, A0, A1, c0, Reff, Qw, law):
    """Run :func:`_observer_step` over a log: ``X[k]``, ``TH[k]`` are the estimates at ``t_k``
    (after sample ``k``). Returns the number of samples processed (< K if it diverged)."""
    K = Y.shape[0]
    e6 = np.empty(6)
    for k in range(K):
        ok = _observer_step(xh, th, f, mem, yprev, U, Gam, Y[k], TAU[k], VX[k], W, inv_sigma, fmax, bank, dt, nsub,
                            Lv, vmin, vmax, vlo, vhi, H0, H1, C, cvirt, T, gamma, th_lo, th_hi,
                            Phi, G, mvirt, n0, n1, A0, A1, c0, Reff, Qw, law, e6)
        for i in range(8):
            X[k, i] = xh[i]
        for j in range(4):
            TH[k, j] = th[j]
        for r in range(6):
            E6[k, r] = e6[r]
        if not ok:
            return k + 1
    return K


# --------------------------------------------------------------------------- Python side
class ObserverInputError(ValueError):
    """A measurement, speed, torque or option that the adaptive observer cannot use."""


#: Default stiffness band of the projection (multiples of the nominal).
DEFAULT_BAND = (0.2, 2.0)


def svf_discrete(omega: float, dt: float, zeta: float = 1.0 / math.sqrt(2.0)) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation ``(Phi, G)`` of ``f' = [[0, 1], [-w^2, -2 zeta w]] f + [0, w^2] u``.

    ``f[0] = H(s) u`` and ``f[1] = s H(s) u`` with ``H = w^2/(s^2 + 2 zeta w s + w^2)``.
    """
    if not (omega > 0 and math.isfinite(omega)) or not (dt > 0 and math.isfinite(dt)):
        raise ObserverInputError(f"filter frequency and dt must be positive, got omega={omega!r}, dt={dt!r}")
    A = np.array([[0.0, 1.0], [-omega**2, -2.0 * zeta * omega]])
    B = np.array([[0.0], [omega**2]])
    M = sla.expm(np.block([[A, B], [np.zeros((1, 3))]]) * dt)
    return np.ascontiguousarray(M[:2, :2]), np.ascontiguousarray(M[:2, 2])


@lru_cache(maxsize=1)
def reference_excitation() -> tuple[np.ndarray, np.ndarray]:
    """True states (every 10th sample) and speeds of the nominal, noise-free urban ride (seed 0):
    the reference excitation of :func:`adaptation_gain`."""
    from ptw_env.ride import ride_scenario
    from ptw_env.sensors import SensorConfig

    r = ride_scenario("urban", sensors=SensorConfig.noiseless(), seed=0)
    return r.states[::10].copy(), np.asarray(r.log.columns["vx_true"][::10], dtype=float)


@dataclass(frozen=True)
class AdaptationGain:
    """``Gamma`` of the adaptive law and the averaged matrix it was chosen from.

    Attributes
    ----------
    gamma : ndarray (4,)
        Diagonal of ``Gamma`` [(N/rad)^2 per unit of ``chi^T T eps``].
    H_bar : ndarray (4, 4)
        Averaged quasi-static matrix (module docstring).
    rates : ndarray (4,)
        Eigenvalues of ``Gamma H_bar`` [1/s] (real parts, descending): the averaged convergence rates.
    tau_a : float
    """

    gamma: np.ndarray
    H_bar: np.ndarray
    rates: np.ndarray
    tau_a: float


def adaptation_gain(design: AdaptiveObserverDesign, tau_a: float = 10.0,
                    reference: tuple[np.ndarray, np.ndarray] | None = None) -> AdaptationGain:
    """``Gamma = diag(1 / (tau_a H_bar_jj))`` (module docstring, "Choice of Gamma").

    Parameters
    ----------
    design : AdaptiveObserverDesign
    tau_a : float
        Time constant of each parameter's averaged adaptation [s].
    reference : (states (K, 8), speeds (K,)), optional
        Excitation to average over; default :func:`reference_excitation`.
    """
    if not (tau_a > 0 and math.isfinite(tau_a)):
        raise ObserverInputError(f"tau_a must be a positive time in seconds, got {tau_a!r}")
    X, V = reference_excitation() if reference is None else reference
    m = design.model
    H = np.zeros((4, 4))
    for x, v in zip(X, V):
        chi = m.chi(x, v)
        H += chi.T @ design.T @ m.C_aug() @ np.linalg.solve(design.gain(v) @ m.C - m.A(v), m.D @ chi)
    H /= len(X)
    d = np.diag(H)
    if np.any(d <= 0):
        bad = [THETA_NAMES[j] for j in range(4) if d[j] <= 0]
        raise ObserverInputError(f"the averaged adaptation gain of {bad} is not positive: the law cannot converge "
                                 "for this design (equality residual too large)")
    g = 1.0 / (tau_a * d)
    rates = np.sort(np.linalg.eigvals(g[:, None] * H).real)[::-1]
    return AdaptationGain(gamma=g, H_bar=H, rates=rates, tau_a=float(tau_a))


@dataclass(frozen=True, eq=False)
class ObserverRun:
    """Estimates of a whole log (:meth:`AdaptiveObserver.run`).

    Attributes
    ----------
    t : ndarray (K,)
        Time [s].
    x_hat : ndarray (K, 8)
        State estimate at ``t_k`` (after sample ``k``).
    theta : ndarray (K, 4)
        ``Theta_hat = C_hat - C_0`` [N/rad].
    stiffness : ndarray (K, 4)
        ``C_hat`` [N/rad], order of :data:`assist.estimation.lpv_model.THETA_NAMES`.
    innovations : ndarray (K, 6)
        Filtered innovations ``eps_f`` (five outputs and ``y_a``).
    samples : int
        Samples processed (``< K`` only if the estimate diverged).
    """

    t: np.ndarray
    x_hat: np.ndarray
    theta: np.ndarray
    stiffness: np.ndarray
    innovations: np.ndarray
    samples: int

    def final_third_mean(self) -> np.ndarray:
        """Mean stiffness over the last third of the log [N/rad] (the paper's Table I figure)."""
        k = len(self.t)
        return self.stiffness[2 * k // 3:].mean(axis=0)


def gps_interpolate(t: np.ndarray, vx: np.ndarray) -> np.ndarray:
    """Offline reconstruction of a sample-and-hold speed: linear interpolation between the
    instants where the held value changes (and across NaN); a channel refreshed every sample is
    returned unchanged (only NaN filled). For whole logs; :meth:`AdaptiveObserver.update` uses
    the speed as given."""
    try:
        return held_speed(t, vx)  # ptw_env.logs: the one reconstruction of the held speed
    except ValueError:
        raise ObserverInputError("vx has no finite sample") from None


class AdaptiveObserver:
    """The LPV adaptive observer (module docstring), one vehicle, at the design's sample period.

    Parameters
    ----------
    design : AdaptiveObserverDesign, optional
        Gains ``L_i``, ``T`` (default: :func:`assist.estimation.adaptive_design.default_design`).
    law : {"sensitivity", "paper", "none"}
        The adaptive law: ``"sensitivity"`` (default; the parameter filter on the
        observer's sensitivity), ``"paper"`` ([1]_ eq. 18 with ``T`` and the filtered
        signals), or ``"none"`` (``Theta_hat`` frozen: a plain LPV observer).
    band : (float, float)
        Projection band of every stiffness, multiples of the nominal ``C_0``.
    tau_a : float
        ``"paper"``: time constant of :func:`adaptation_gain` [s].
    gamma : array_like (4,), optional
        ``"paper"``: the diagonal of ``Gamma`` instead of the rule.
    filter_hz : float
        ``"paper"``: corner of the law's filter ``H(s)`` [Hz].
    stiffness_std0 : float
        ``"sensitivity"``: prior standard deviation of ``C/C_0`` (``Gamma_0 = std0^2 I``).
    stiffness_walk : float
        ``"sensitivity"``: random-walk intensity of ``C/C_0`` [1/sqrt(s)] (how fast a change
        of road friction is followed; default 0.02, i.e. 2 % per sqrt(s)).
    parametrisation : {"stiffness", "axle", "friction"}
        ``"sensitivity"``: what is adapted (:data:`assist.estimation.identifiability.PARAMETRISATIONS`):
        the four stiffnesses independently ([1]_), one scale per axle (effects.md's
        ``tire_stiffness``: camber and cornering stiffness of a tire scale together), or one
        scale for all four (road friction, [1]_ sec. II-C ``Theta = mu Theta_0``). With
        ``Theta = (s - 1) C_0`` and ``s = G p``, ``Gamma = G Gamma_p G^T``: the update stays in
        the range of ``G``. The coarser ones are far better determined from short rides
        (:mod:`assist.estimation.identifiability`: on 15 s of the handling track at 5 % noise the
        Cramér-Rao 1-sigma of ``C_gamma_r`` is 4-8 %, of the rear axle scale 0.2-0.7 %).
    road_bank : float
        Known bank (cross-fall) of the road [rad], effects.md ``road_bank`` in the observer's plant
        (default 0: level). The model has no other place for a bank: an unknown one's steady side
        force is read as a stiffness change (a 0.02 rad bank, a road's usual cross-fall, puts the
        axle scales 3 % and 13 % off on a simulated urban ride; given, 0.1 %).

    Examples
    --------
    >>> import numpy as np
    >>> obs = AdaptiveObserver()
    >>> x, th = obs.update(np.zeros(5), 0.0, 15.0)
    >>> x.shape, th.shape
    ((8,), (4,))
    """

    LAWS = {"none": LAW_NONE, "paper": LAW_PAPER, "sensitivity": LAW_SENSITIVITY}

    def __init__(self, design: AdaptiveObserverDesign | None = None, law: str = "sensitivity",
                 band: tuple[float, float] = DEFAULT_BAND, tau_a: float = 10.0, gamma=None, filter_hz: float = 4.0,
                 stiffness_std0: float = 0.5, stiffness_walk: float = 0.02,
                 parametrisation: str = "stiffness", road_bank: float = 0.0) -> None:
        self.design = default_design() if design is None else design
        if not isinstance(self.design, AdaptiveObserverDesign):
            raise ObserverInputError(f"design must be an AdaptiveObserverDesign, got {type(design).__name__}")
        if law not in self.LAWS:
            raise ObserverInputError(f"law must be one of {sorted(self.LAWS)}, got {law!r}")
        if parametrisation not in PARAMETRISATIONS:
            raise ObserverInputError(f"parametrisation must be one of {sorted(PARAMETRISATIONS)}, "
                                     f"got {parametrisation!r}")
        if law == "paper" and parametrisation != "stiffness":
            raise ObserverInputError("the paper's law adapts the four stiffnesses: use parametrisation='stiffness'")
        if law == "paper" and self.design.kind != "theorem2":
            raise ObserverInputError(f"the paper's law needs the weight T of a Theorem-2 design; this design is "
                                     f"{self.design.kind!r} (use law='sensitivity')")
        self.law = law
        self.parametrisation = parametrisation
        Gp = PARAMETRISATIONS[parametrisation][1]
        self._GG = Gp @ Gp.T
        m: LPVModel = self.design.model
        self.model = m
        try:
            lo, hi = (float(b) for b in band)
        except (TypeError, ValueError):
            raise ObserverInputError(f"band must be two numbers (lo, hi), got {band!r}") from None
        if not (0 < lo < 1 < hi) or not math.isfinite(hi):
            raise ObserverInputError(f"band must be (lo, hi) with 0 < lo < 1 < hi, got {band!r}")
        self.band = (lo, hi)
        for name, val in (("filter_hz", filter_hz), ("stiffness_std0", stiffness_std0)):
            if not (val > 0 and math.isfinite(val)):
                raise ObserverInputError(f"{name} must be a positive number, got {val!r}")
        if not (stiffness_walk >= 0 and math.isfinite(stiffness_walk)):
            raise ObserverInputError(f"stiffness_walk must be a number >= 0, got {stiffness_walk!r}")
        self.filter_hz = float(filter_hz)
        self.stiffness_std0 = float(stiffness_std0)
        self.stiffness_walk = float(stiffness_walk)
        self.dt = float(self.design.options.dt)
        self.gain: AdaptationGain | None = None
        if gamma is not None:
            g = np.asarray(gamma, dtype=float)
            if g.shape != (4,) or not np.all(np.isfinite(g)) or np.any(g < 0):
                raise ObserverInputError(f"gamma must hold 4 finite numbers >= 0 (diagonal of Gamma), got {gamma!r}")
        elif law == "paper":
            self.gain = adaptation_gain(self.design, tau_a)
            g = self.gain.gamma
        else:
            g = np.zeros(4)
        check_bank(road_bank, ObserverInputError)
        # a known road bank (effects.md road_bank) enters the plant's constant column (row 3's
        # -M g sin(beta), through E^-1) linearly in sin(beta), and the sine terms as the angle
        plant = compile_plant(m.vehicle)
        W, s, f, b = plant.flat()
        self._W0, self._dW = bank_column(m.vehicle)
        w = m._w()
        v = m.vehicle
        idx = list((R, PHI_DOT, DELTA_DOT))
        Phi, G = svf_discrete(2 * math.pi * self.filter_hz, self.dt)
        self.R_eff = effective_noise(self.design)
        self._p = dict(
            W=W[0], inv_sigma=s[0], fmax=f[0], bank=float(b[0]), dt=self.dt, nsub=substeps_for(self.dt),
            Lv=np.ascontiguousarray(self.design.L), vmin=m.vmin, vmax=m.vmax, vlo=v.vmin, vhi=v.vmax,
            H0=np.ascontiguousarray(m.H0), H1=np.ascontiguousarray(m.H1), C=np.ascontiguousarray(m.C),
            cvirt=np.ascontiguousarray(m.c_virtual), T=np.ascontiguousarray(self.design.T),
            gamma=np.ascontiguousarray(g), th_lo=(lo - 1.0) * m.theta0, th_hi=(hi - 1.0) * m.theta0,
            Phi=Phi, G=G, mvirt=np.ascontiguousarray((w @ v.E)[idx]),
            n0=np.ascontiguousarray(-(w @ v.A0)[idx]), n1=np.ascontiguousarray(-(w @ v.A1)[idx]),
            A0=np.ascontiguousarray(m.A0), A1=np.ascontiguousarray(m.A1), c0=np.ascontiguousarray(m.theta0),
            Reff=np.ascontiguousarray(self.R_eff), Qw=np.ascontiguousarray(self.stiffness_walk**2 * self._GG),
            law=self.LAWS[law],
        )
        self._args = tuple(self._p.values())
        self.road_bank = road_bank
        self.reset()

    @property
    def road_bank(self) -> float:
        """The road bank [rad] the observer's plant assumes (settable between samples)."""
        return self._p["bank"]

    @road_bank.setter
    def road_bank(self, value: float) -> None:
        check_bank(value, ObserverInputError)
        self._p["W"] = self._W0 + math.sin(value) * self._dW
        self._p["bank"] = float(value)
        self._args = tuple(self._p.values())

    # ------------------------------------------------------------------
    def reset(self, x0=None, theta0=None) -> None:
        """Start from ``x0`` (default upright, zero forces) and ``Theta_0`` (default 0: the nominal stiffness)."""
        self._x = np.zeros(8) if x0 is None else self._vec(x0, 8, "x0")
        th = np.zeros(4) if theta0 is None else self._vec(theta0, 4, "theta0")
        self._th = np.clip(th, self._p["th_lo"], self._p["th_hi"])
        self._f = np.zeros((NFILT, 2))
        self._mem = np.zeros(3)
        self._yprev = np.zeros(NY)
        self._U = np.zeros((8, 4))
        self._Gam = self._GG * self.stiffness_std0**2
        self._e = np.zeros(6)
        self._vx_last = math.nan

    @staticmethod
    def _vec(a, n: int, name: str) -> np.ndarray:
        a = np.array(a, dtype=float)
        if a.shape != (n,) or not np.all(np.isfinite(a)):
            raise ObserverInputError(f"{name} must hold {n} finite numbers, got {a!r}")
        return a

    @property
    def x_hat(self) -> np.ndarray:
        """State estimate [phi, delta, vy, r, phi_dot, delta_dot, Fyf, Fyr] (copy)."""
        return self._x.copy()

    @property
    def theta_hat(self) -> np.ndarray:
        """``Theta_hat`` [N/rad] (copy)."""
        return self._th.copy()

    @property
    def stiffness(self) -> np.ndarray:
        """``C_hat = C_0 + Theta_hat`` [N/rad], order of THETA_NAMES."""
        return self.model.theta0 + self._th

    @property
    def stiffness_std(self) -> np.ndarray:
        """``"sensitivity"`` law: standard deviation of ``C_hat`` [N/rad] from ``Gamma`` (NaN for the others)."""
        if self.law != "sensitivity":
            return np.full(4, np.nan)
        return np.sqrt(np.maximum(np.diag(self._Gam), 0.0)) * self.model.theta0

    def _speed(self, vx: float) -> float:
        v = float(vx)
        if math.isfinite(v):
            if v <= 0:
                raise ObserverInputError(f"vx must be a positive speed in m/s, got {v!r}")
            self._vx_last = v
        elif math.isnan(self._vx_last):
            raise ObserverInputError("vx is missing and no earlier speed is known")
        return self._vx_last

    def update(self, y, tau: float, vx: float) -> tuple[np.ndarray, np.ndarray]:
        """Take sample ``k``: ``y`` = [delta, yaw_rate, roll_rate, delta_rate, ay] (NaN = dropout),
        ``tau`` [N m] and ``vx`` [m/s] to be held until the next sample.
        Returns ``(x_hat(t_k), Theta_hat)`` (copies)."""
        y = np.asarray(y, dtype=float)
        if y.shape != (NY,):
            raise ObserverInputError(f"y must hold the {NY} outputs {OUTPUT_NAMES}, got shape {y.shape}")
        tau = float(tau)
        if not math.isfinite(tau):
            raise ObserverInputError(f"tau must be finite (the rider torque is known), got {tau!r}")
        v = self._speed(vx)
        ok = _observer_step(self._x, self._th, self._f, self._mem, self._yprev, self._U, self._Gam, y, tau, v,
                            *self._args, self._e)
        if not ok:
            raise ObserverInputError("the state estimate diverged (not finite); check the inputs' units")
        return self._x.copy(), self._th.copy()

    def run(self, t, y, tau, vx, interpolate_speed: bool = True) -> ObserverRun:
        """Run over a whole record from the current state: ``y`` (K, 5), ``tau`` (K,), ``vx`` (K,) at times ``t`` (K,).

        ``interpolate_speed``: reconstruct a sample-and-hold GPS speed first (:func:`gps_interpolate`).
        Gives the same numbers as calling :meth:`update` sample by sample.
        """
        t = np.asarray(t, dtype=float)
        Y = np.ascontiguousarray(np.asarray(y, dtype=float))
        tau = np.ascontiguousarray(np.asarray(tau, dtype=float))
        K = len(t)
        if Y.shape != (K, NY) or tau.shape != (K,) or np.shape(vx) != (K,):
            raise ObserverInputError(f"shapes must be t (K,), y (K, {NY}), tau (K,), vx (K,); got "
                                     f"{t.shape}, {Y.shape}, {tau.shape}, {np.shape(vx)}")
        try:  # ptw_env.logs: the one check of the inputs (torque at every sample, a positive held speed)
            tau, v_held = input_series(t, tau, vx)
        except ValueError as exc:
            raise ObserverInputError(str(exc)) from None
        v = v_held if interpolate_speed else np.asarray(vx, dtype=float)
        if not np.all(np.isfinite(v)):
            k = int(np.flatnonzero(~np.isfinite(v))[0])
            raise ObserverInputError(f"vx is missing at sample {k} (t = {t[k]:g} s): a held speed needs "
                                     f"interpolate_speed=True")
        tau = np.ascontiguousarray(tau)
        X = np.zeros((K, 8))
        TH = np.zeros((K, 4))
        E6 = np.zeros((K, 6))
        n = _observer_run(X, TH, E6, self._x, self._th, self._f, self._mem, self._yprev, self._U, self._Gam, Y, tau,
                          np.ascontiguousarray(v), *self._args)
        return ObserverRun(t=t, x_hat=X, theta=TH, stiffness=TH + self.model.theta0, innovations=E6, samples=int(n))

    def run_log(self, log, interpolate_speed: bool = True) -> ObserverRun:
        """:meth:`reset` then :meth:`run` on a :class:`ptw_env.logs.RideLog` (its ``roll`` column is not used)."""
        self.reset()
        c = log.columns
        Y = np.column_stack([c[name] for name in OUTPUT_NAMES])
        return self.run(log.t, Y, c["tau"], c["vx"], interpolate_speed=interpolate_speed)


def effective_noise(design: AdaptiveObserverDesign, vx: float | None = None) -> np.ndarray:
    """``R_eff = R + C Sigma_x C^T`` (5 x 5): covariance of the innovation of the LPV observer.

    ``R`` holds the per-sample variances the design assumed
    (:meth:`AdaptiveDesignOptions.noise_std`); ``Sigma_x`` solves the observer's
    error Lyapunov equation ``(A - L C) Sigma + Sigma (A - L C)^T + B_w B_w^T +
    L V L^T = 0`` at ``vx`` (default mid-range), ``V = R dt`` the noise
    intensity. Used by the sensitivity law: without the state-error part it
    trusts each innovation as if the state were exact and fits the parameters to
    noise and sampling effects.
    """
    m, o = design.model, design.options
    v = 0.5 * (m.vmin + m.vmax) if vx is None else float(vx)
    sig2 = o.noise_std(m.vehicle) ** 2
    L = design.gain(v)
    Acl = m.A(v) - L @ m.C
    Bw = np.diag(np.asarray(o.process_std))
    Q = Bw @ Bw.T + L @ np.diag(sig2 * o.dt) @ L.T
    Sx = sla.solve_continuous_lyapunov(Acl, -Q)
    Sx = 0.5 * (Sx + Sx.T)
    return np.diag(sig2) + m.C @ Sx @ m.C.T


__all__ = [
    "AdaptationGain",
    "AdaptiveObserver",
    "DEFAULT_BAND",
    "effective_noise",
    "ObserverInputError",
    "ObserverRun",
    "adaptation_gain",
    "gps_interpolate",
    "reference_excitation",
    "svf_discrete",
]
