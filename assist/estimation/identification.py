"""Tire-stiffness identification baselines on a ride log: direct (eq. 12), inversion (eq. 13), joint EKF.

The three methods the LPV adaptive observer (:mod:`assist.estimation.adaptive_observer`)
is compared with in Fouka, Nehaoua, Arioui [1]_ (Table I), plus the filter a
practitioner would reach for first. All return an :class:`EstimationResult`
with the stiffness history ``C(t) = [C_alpha_f, C_gamma_f, C_alpha_r,
C_gamma_r]`` [N/rad] (order of :data:`assist.estimation.lpv_model.THETA_NAMES`).

Derivatives: state-variable filters
-----------------------------------
Every derivative is taken by a *proper* filter, never by differencing noisy
samples: each signal ``u`` goes through the same Butterworth low-pass
``H(s)`` of order ``n`` (default 3, corner ``filter_hz``) realised in
companion form, whose states are ``H u, s H u, ..., s^{n-1} H u``
(:func:`state_variable_filter`, exact zero-order-hold discretisation). A
regression ``a(t) = phi(t)^T c`` with constant ``c`` holds unchanged for the
filtered signals ``H a = (H phi)^T c`` (classical state-variable-filter
identification, Young 1981), so derivatives of the measurements become
filter states and the noise is attenuated above the corner.

Least squares with forgetting
-----------------------------
Both regressions are solved by exponentially weighted least squares over
the whole log in information form, ``S_k = lambda S_{k-1} + Phi_k^T W
Phi_k``, ``b_k = lambda b_{k-1} + Phi_k^T W z_k``, ``c_k = (S_k + rho
I)^-1 (b_k + rho c_0)`` with ``lambda = exp(-dt/memory_s)``, each row
normalised by its RMS over the log, the unknowns in multiples of the nominal
``C_0``, and a small ridge ``rho`` pulling an unexcited direction to the
nominal instead of making it singular. Rows holding a missing sample are left out.

Direct method ([1]_ eq. 12, one-body model, eq. 11)
---------------------------------------------------
With ``vx F_ss,k = sigma_k sum_{j in k} C_j chi_j(x, vx)`` (``chi`` of
:mod:`assist.estimation.lpv_model`; ``-vx alpha_f = sigma_f chi_1`` etc.):

.. math::

    M a_y = \\sum_k \\tfrac{\\sigma_k}{v_x} \\textstyle\\sum_{j\\in k} C_j \\chi_j, \\quad
    I_z \\dot r = l_f \\tfrac{\\sigma_f}{v_x}(C_1\\chi_1 + C_2\\chi_2) - l_r \\tfrac{\\sigma_r}{v_x}(C_3\\chi_3 + C_4\\chi_4),

    \\sigma_k \\dot F_k + v_x F_k = \\sigma_k \\textstyle\\sum_{j\\in k} C_j \\chi_j, \\quad
    F_f = \\frac{l_r M a_y + I_z \\dot r}{l_f + l_r},\\ F_r = \\frac{l_f M a_y - I_z \\dot r}{l_f + l_r}.

``M`` = e33, ``I_z`` = e44, ``l_f`` = a47, ``l_r`` = -a48 (model.md; the
equivalent one body of [1]_ eq. 11, which ignores the roll/steer coupling of
E and the gyroscopic terms: the method's model error). By default
(:class:`DirectLS` ``split="full"``) the yaw row is the model's own, ``I_z r'``
replaced by ``E_4 x' - A_4(v_x) x`` over the first six states, the information
the adaptive observer has; ``split="one_body"`` is eq. 11 as printed. Corrections: [1]_
eq. (12) prints the yaw row with ``I_z psi`` (it is ``I_z psi_ddot = I_z r'``,
eq. 11) and divides by ``vx`` in the relaxation rows; here they are multiplied
by ``vx`` so that no signal is divided by a measured speed. In the filtered
relaxation rows ``H[vx u]`` is taken as ``vx H[u]`` (speed slowly varying
against the filter corner). The regressor states ``vy`` and ``phi`` are not
measured: they come from a state estimate ``x_hat`` (by default the adaptive
observer's), as in [1]_ ("the direct method ... assuming all states are measured").

Inversion method ([1]_ eq. 13)
------------------------------
``y' = C A x_hat + C B u + C D chi(x_hat) Theta`` for the outputs ``[ay, y_a]``,
the rows with ``rank(C D) = 2`` (the virtual sensor of [1]_ eq. 15 is
needed, as the paper says). Inverting ``C D`` gives, per axle,

.. math::

    \\dot F_k^{meas} + \\tfrac{v_x}{\\sigma_k} \\hat F_k = \\textstyle\\sum_{j\\in k} C_j \\chi_j(\\hat x, v_x),
    \\qquad
    \\begin{bmatrix} F_f \\\\ F_r \\end{bmatrix}^{meas} =
    \\begin{bmatrix} 1/M & 1/M \\\\ c_{67} & c_{68} \\end{bmatrix}^{-1}
    \\begin{bmatrix} a_y \\\\ y_a \\end{bmatrix},

with ``y_a = m . [r, phi_dot, delta_dot]' + n(vx) . [r, phi_dot, delta_dot]``
(:meth:`assist.estimation.lpv_model.LPVModel.virtual_sensor_coefficients`), so
``F'^meas`` needs second derivatives of the measured rates (third-order filter).
The nominal ``C A x_hat`` terms cancel against ``C D chi Theta_0``; what is
left is written with the full stiffness ``C = C_0 + Theta``.

Joint extended Kalman filter
----------------------------
State ``z = [x (8), s (4)]`` with ``s_j = C_j / C_0j - 1``; dynamics
``x' = f(x, tau, vx) + D chi(x, vx) diag(C_0) s`` (``f``: the nominal nonlinear
plant of :mod:`ptw_env.kernels`), ``s' = w_s`` (random walk); outputs ``y =
C x`` (five sensors, no roll angle). Prediction: RK4 of the mean (the
plant's substeps), covariance ``Phi P Phi^T + Q dt`` with ``Phi`` the
product of the substeps' fourth-order Taylor steps of the Jacobian (the
plant part by central differences of the one right-hand side, the parameter
part exact). Update: sequential scalar updates of the available channels
(NaN skipped), Joseph form. ``s`` is clipped to the stiffness band after
each step. cli.md names this method ``ukf``; the issue allows an unscented
or extended filter, and the model being bilinear in ``(x, s)`` with mild
sines, the extended one is used.

Sensor offsets as nuisance parameters (``offsets=``, issue 19): constant
offsets ``b_c`` of chosen channels (:data:`OFFSET_CHANNELS`) join the state,
``z = [x, s, b]``, ``b' = 0``, ``y_c = C_c x + b_c``. For a linear model a
constant output offset is observable whenever the plant matrix has no zero
eigenvalue (no equilibrium ``A x = 0`` with ``C x = b != 0``), which holds for
the model.md structure away from a capsize speed; the filter's covariance says
how well each is determined. The prior is zero with a standard deviation of
:data:`OFFSET_PRIOR_NOISE` of the channel's noise standard deviations (the
sensors' own scale, no vehicle number). :func:`estimate` runs this filter first
for the other methods and removes each offset that stands out of its standard
deviation by :data:`OFFSET_SIGNIFICANCE` before the method runs, provided the
filter with the offsets explains the log: each channel's mean normalised
innovation squared ``e^2 / S`` over the log's second half (1 for a consistent
filter) at most :data:`NIS_EXPLAINED`. Where it does not, the "offsets" are what
a model error leaves in the channels: they are reported, not removed.

Drifting offsets (``drift=True``): each offset also gets a constant rate,
``z = [x, s, b, d]``, ``b' = d``, ``d' = 0`` (a line over the log, the usual
model of a MEMS sensor's bias warming up over tens of seconds); the transition
of ``(b, d)`` over a step ``dt`` is ``[[1, dt], [0, 1]]`` exactly, and the
prior of ``d`` is the offset's prior divided by the log's duration (a drift
moving the offset by its prior over the log). :func:`correct_offsets` runs this
filter beside the constant one and uses it when a drift stands out by
:data:`OFFSET_SIGNIFICANCE` and it explains the log; the offsets removed are
then lines ``b(t) = b(T) + d (t - T)``.

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers" (``shared/papers/000_348caefc9b08ee38.txt``).
.. [2] P. Young, "Parameter estimation for continuous-time models - a
   survey", Automatica 17(1), 1981.

Length (about 1050 lines): three baselines (direct, inversion, joint EKF, with sensor offsets and drifts) behind one estimator
interface, sharing the weighted least squares and the log handling.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import scipy.linalg as sla
from numba import njit
from scipy.signal import butter, lfilter

from ptw_env.dynamics import compile_plant
from ptw_env.integrate import substeps_for
from ptw_env.kernels import deriv, fold_vx
from ptw_env.logs import input_series
from ptw_env.sensors import ENCODER_QUANTUM, SensorConfig
from ptw_env.vehicle import DELTA, DELTA_DOT, FYF, FYR, PHI_DOT, R, VY, Vehicle

from assist.estimation.adaptive_design import DEFAULT_PROCESS_STD, default_design
from assist.estimation.adaptive_observer import DEFAULT_BAND, AdaptiveObserver
from assist.estimation.lpv_model import (OUTPUT_NAMES, OUTPUT_UNITS, STATE_SCALE, THETA_NAMES, LPVModel, build_lpv_model,
                                         check_bank, chi_entry)

#: Methods of :func:`estimate` (cli.md ``--method``; ``ekf`` is an alias of ``ukf``).
METHODS = ("adaptive", "direct", "inversion", "ukf")
#: Channels whose constant offset the joint EKF can carry as a nuisance parameter (``offsets=``): the steering
#: encoder, both gyros and the lateral accelerometer (``delta_rate`` is the encoder's derivative: no offset).
OFFSET_CHANNELS = ("delta", "yaw_rate", "roll_rate", "ay")
#: Prior standard deviation of an offset, in standard deviations of its channel's noise (quantisation included).
OFFSET_PRIOR_NOISE = 5.0
#: An estimated offset is removed from the log before the other methods run when it exceeds this many of its
#: standard deviations (the filter's final covariance): the offsets the data say are there.
OFFSET_SIGNIFICANCE = 3.0


class IdentificationError(ValueError):
    """A log, option or state estimate that an identification method cannot use."""


class FilterDivergence(IdentificationError):
    """The joint EKF's state left the finite numbers (its model cannot follow the log)."""


# --------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class EstimationResult:
    """Stiffness (and state) estimates of one method on one log.

    Attributes
    ----------
    method : str
    t : ndarray (K,)
        Time [s].
    stiffness : ndarray (K, 4)
        ``[C_alpha_f, C_gamma_f, C_alpha_r, C_gamma_r]`` [N/rad] after sample ``k``.
    x_hat : ndarray (K, 8) or None
        State estimate where the method has one.
    info : dict
        Method-specific figures.
    nominal : ndarray (4,) or None
        The nominal stiffnesses of the vehicle's model [N/rad] (every method's result carries them), for the
        ratios of :meth:`to_json`.
    """

    method: str
    t: np.ndarray
    stiffness: np.ndarray
    x_hat: np.ndarray | None
    info: dict
    nominal: np.ndarray | None = None

    def final_third_mean(self) -> np.ndarray:
        """Mean stiffness over the log's final third [N/rad] (cli.md, the paper's Table I figure)."""
        k = len(self.t)
        return self.stiffness[2 * k // 3:].mean(axis=0)

    def to_json(self) -> dict[str, Any]:
        """``{"method", "stiffness": {name: N/rad}}`` (cli.md) plus, with :attr:`nominal`, the ratio to the
        vehicle's nominal stiffness."""
        m = self.final_third_mean()
        out: dict[str, Any] = {"method": self.method, "stiffness": {n: float(v) for n, v in zip(THETA_NAMES, m)}}
        if self.nominal is not None:
            out["stiffness_ratio_to_nominal"] = {n: float(v / c) for n, v, c in zip(THETA_NAMES, m, self.nominal)}
        out.update(window="final third of the log",
                   duration_s=float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0)
        return out


# --------------------------------------------------------------------------- filters
def state_variable_filter(u: np.ndarray, dt: float, cutoff_hz: float, order: int = 3) -> np.ndarray:
    """``[H u, s H u, ..., s^{order-1} H u]`` for each column of ``u`` (module docstring).

    ``H`` is the Butterworth low-pass of ``order`` with corner ``cutoff_hz``,
    realised in companion form and discretised exactly for a zero-order-held
    input. Returns shape ``(order, K) + u.shape[1:]``. The filter starts at rest
    from the first sample's value (no start-up transient for a constant signal).
    """
    u = np.asarray(u, dtype=float)
    if not (cutoff_hz > 0 and math.isfinite(cutoff_hz)) or not (dt > 0 and cutoff_hz < 0.5 / dt):
        raise IdentificationError(f"cutoff_hz must lie in (0, {0.5 / dt:g}) Hz (Nyquist), got {cutoff_hz!r}")
    if int(order) != order or not 1 <= order <= 6:
        raise IdentificationError(f"filter order must be an integer in 1..6, got {order!r}")
    if not np.all(np.isfinite(u)):
        raise IdentificationError("state_variable_filter needs finite signals (fill dropouts first)")
    w = 2 * math.pi * cutoff_hz
    _, a = butter(order, w, analog=True)  # a[0] s^n + ... + a[n]
    a = a / a[0]
    n = order
    A = np.zeros((n, n))
    A[:-1, 1:] = np.eye(n - 1)
    A[-1, :] = -a[::-1][:n]
    B = np.zeros((n, 1))
    B[-1, 0] = a[-1]  # DC gain 1
    M = sla.expm(np.block([[A, B], [np.zeros((1, n + 1))]]) * dt)
    Ad, Bd = M[:n, :n], M[:n, n]
    # each state is an LTI filter of u: x_{k+1} = Ad x_k + Bd u_k -> transfer functions via lfilter
    shp = u.shape
    U = u.reshape(len(u), -1)
    out = np.empty((n, len(u), U.shape[1]))
    # steady state for u = u0: x = [u0, 0, ...]
    x = np.zeros((n, U.shape[1]))
    x[0] = U[0]
    for k in range(len(u)):
        out[:, k] = x
        x = Ad @ x + Bd[:, None] * U[k][None, :]
    return out.reshape((n,) + shp)


def _fill(x: np.ndarray) -> np.ndarray:
    """Linear interpolation across NaN (for the filters); returns a copy."""
    x = np.array(x, dtype=float)
    ok = np.isfinite(x)
    if not np.any(ok):
        raise IdentificationError("a channel has no finite sample")
    if not np.all(ok):
        idx = np.arange(len(x))
        x[~ok] = np.interp(idx[~ok], idx[ok], x[ok])
    return x


def _ewls(rows: np.ndarray, target: np.ndarray, valid: np.ndarray, lam: float, ridge: float,
          prior: np.ndarray) -> np.ndarray:
    """Exponentially weighted LS history (module docstring). ``rows`` (K, m, p), ``target`` (K, m),
    ``valid`` (K,) -> ``c`` (K, p)."""
    K, m, p = rows.shape
    Phi = np.where(valid[:, None, None], rows, 0.0)
    z = np.where(valid[:, None], target, 0.0)
    # row normalisation by RMS over the log
    scale = np.sqrt(np.mean(z**2, axis=0)) + 1e-300
    Phi = Phi / scale[None, :, None]
    z = z / scale[None, :]
    S_inc = np.einsum("kmi,kmj->kij", Phi, Phi).reshape(K, p * p)
    b_inc = np.einsum("kmi,km->ki", Phi, z)
    S = lfilter([1.0], [1.0, -lam], S_inc, axis=0).reshape(K, p, p)
    b = lfilter([1.0], [1.0, -lam], b_inc, axis=0)
    rho = ridge * np.mean(np.trace(S_inc.reshape(K, p, p), axis1=1, axis2=2)) / p / (1.0 - lam)
    S = S + rho * np.eye(p)[None]
    b = b + rho * prior[None, :]
    return np.linalg.solve(S, b[..., None])[..., 0]


@dataclass(frozen=True)
class LSOptions:
    """Options of the direct and inversion least squares.

    Attributes
    ----------
    filter_hz : float
        Corner of the state-variable filters [Hz].
    order : int
        Filter order (>= 3 for the inversion's second derivatives).
    memory_s : float
        Forgetting time constant [s] (``inf``: plain cumulative least squares).
    ridge : float
        Ridge toward the nominal, relative to the mean information per sample over ``memory_s``.
    """

    filter_hz: float = 3.0
    order: int = 3
    memory_s: float = 20.0
    ridge: float = 1e-6

    def __post_init__(self) -> None:
        if not (self.filter_hz > 0 and math.isfinite(self.filter_hz)):
            raise IdentificationError(f"filter_hz must be a positive frequency, got {self.filter_hz!r}")
        if int(self.order) != self.order or not 3 <= self.order <= 6:
            raise IdentificationError(f"order must be an integer in 3..6, got {self.order!r}")
        if not self.memory_s > 0:
            raise IdentificationError(f"memory_s must be > 0 s (inf allowed), got {self.memory_s!r}")
        if not (self.ridge >= 0 and math.isfinite(self.ridge)):
            raise IdentificationError(f"ridge must be >= 0, got {self.ridge!r}")

    def lam(self, dt: float) -> float:
        return 1.0 if math.isinf(self.memory_s) else math.exp(-dt / self.memory_s)


def _log_arrays(log) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    c = log.columns
    t = np.asarray(log.t, dtype=float)
    Y = np.column_stack([np.asarray(c[n], dtype=float) for n in OUTPUT_NAMES])
    try:  # ptw_env.logs: the one check of the inputs (torque at every sample, a positive held speed)
        tau, vx = input_series(t, c["tau"], c["vx"], str(getattr(log, "path", None) or "log"))
    except ValueError as exc:
        raise IdentificationError(str(exc)) from None
    dt = float(np.median(np.diff(t)))
    return t, Y, tau, vx, dt


def _states_for(log, x_hat: np.ndarray | None) -> np.ndarray:
    if x_hat is None:
        return AdaptiveObserver().run_log(log).x_hat
    x_hat = np.asarray(x_hat, dtype=float)
    if x_hat.shape != (len(log.t), 8) or not np.all(np.isfinite(x_hat)):
        raise IdentificationError(f"x_hat must be a finite array of shape ({len(log.t)}, 8), got {x_hat.shape}")
    return x_hat


class DirectLS:
    """The direct method of [1]_ eq. (12) (module docstring), scikit-learn style.

    ``fit(log, x_hat=None)`` sets ``stiffness_`` (K, 4) [N/rad], ``t_`` and returns self.

    ``split="full"`` (default) splits the axle forces with the model's own yaw row, the information the
    adaptive observer has: ``l_f F_f - l_r F_r = E_4 x' - A_4(v_x) x`` over the first six states (roll,
    steer and lateral inertia coupling ``e43, e45, e46`` and the gyroscopic and damping terms ``a44, a45,
    a46`` of model.md; the measured ``delta, r, phi', delta'`` where measured, ``x_hat`` for ``phi, vy``),
    so the comparison tests the method, not a handicap; ``split="one_body"`` is the paper's eq. (11),
    ``l_f F_f - l_r F_r = I_z r'``, which ignores those terms (the method's model error there).
    """

    name = "direct"
    SPLITS = ("full", "one_body")

    def __init__(self, options: LSOptions | None = None, model: LPVModel | None = None, split: str = "full") -> None:
        self.options = LSOptions() if options is None else options
        self.model = build_lpv_model() if model is None else model
        if split not in self.SPLITS:
            raise IdentificationError(f"split must be one of {self.SPLITS}, got {split!r}")
        self.split = split

    def fit(self, log, x_hat: np.ndarray | None = None) -> "DirectLS":
        o, m = self.options, self.model
        t, Y, tau, vx, dt = _log_arrays(log)
        X = _states_for(log, x_hat)
        v = m.vehicle
        M, Iz = v.E[VY, VY], v.E[R, R]
        lf, lr = v.A0[R, FYF], -v.A0[R, FYR]
        sig = 1.0 / np.array([-v.A1[FYF, FYF], -v.A1[FYR, FYR]])
        valid = np.all(np.isfinite(Y[:, [1, 4]]), axis=1)
        ay, r = _fill(Y[:, 4]), _fill(Y[:, 1])
        chi = m.regressor(X, vx)  # (K, 4)
        sigj = sig[[0, 0, 1, 1]]
        if self.split == "full":  # the yaw row's left side E_4 x' and its A_4(vx) x terms, from the best signals
            S = X[:, :6].copy()
            for j, col in ((DELTA, 0), (R, 1), (PHI_DOT, 2), (DELTA_DOT, 3)):
                S[:, j] = _fill(Y[:, col])
            e4 = v.E[R, :6]
            a4 = S @ v.A0[R, :6] + vx * (S @ v.A1[R, :6]) + v.B[R] * tau
            yaw_in = np.column_stack([S, a4])
        else:
            e4 = np.zeros(6)
            e4[R] = Iz
            yaw_in = np.column_stack([r[:, None] * np.eye(6)[R], np.zeros(len(t))])
        sv = state_variable_filter(np.column_stack([M * ay, chi * sigj / vx[:, None], chi * sigj, yaw_in]), dt,
                                   o.filter_hz, o.order)
        H_May, sH_May = sv[0, :, 0], sv[1, :, 0]
        Hchi_v = sv[0, :, 1:5]  # H[sigma chi / vx]
        Hchi_s = sv[0, :, 5:9]  # H[sigma chi]
        # H[lf Ff - lr Fr] = e4 . sH[S] - H[a4] and its derivative e4 . s2H[S] - sH[a4]
        H_yaw = sv[1, :, 9:15] @ e4 - sv[0, :, 15]
        sH_yaw = sv[2, :, 9:15] @ e4 - sv[1, :, 15]
        front, rear = np.array([1, 1, 0, 0.0]), np.array([0, 0, 1, 1.0])
        c0 = m.theta0
        rows = np.zeros((len(t), 4, 4))
        z = np.zeros((len(t), 4))
        rows[:, 0] = Hchi_v * c0
        z[:, 0] = H_May
        rows[:, 1] = (lf * front - lr * rear) * Hchi_v * c0
        z[:, 1] = H_yaw
        Ff = (lr * H_May + H_yaw) / (lf + lr)
        Fr = (lf * H_May - H_yaw) / (lf + lr)
        dFf = (lr * sH_May + sH_yaw) / (lf + lr)
        dFr = (lf * sH_May - sH_yaw) / (lf + lr)
        rows[:, 2] = front * Hchi_s * c0
        z[:, 2] = sig[0] * dFf + vx * Ff
        rows[:, 3] = rear * Hchi_s * c0
        z[:, 3] = sig[1] * dFr + vx * Fr
        scale = _ewls(rows, z, valid, o.lam(dt), o.ridge, np.ones(4))
        self.t_, self.stiffness_ = t, scale * c0
        return self

    def result(self) -> EstimationResult:
        return EstimationResult(self.name, self.t_, self.stiffness_, None,
                                {"options": self.options.__dict__, "split": self.split}, nominal=self.model.theta0)


class InversionLS:
    """The dynamic-inversion method of [1]_ eq. (13) (module docstring), scikit-learn style.

    ``fit(log, x_hat=None)`` sets ``stiffness_`` (K, 4) [N/rad], ``t_`` and returns self.
    """

    name = "inversion"

    def __init__(self, options: LSOptions | None = None, model: LPVModel | None = None) -> None:
        self.options = LSOptions() if options is None else options
        self.model = build_lpv_model() if model is None else model

    def fit(self, log, x_hat: np.ndarray | None = None) -> "InversionLS":
        o, m = self.options, self.model
        t, Y, tau, vx, dt = _log_arrays(log)
        X = _states_for(log, x_hat)
        v = m.vehicle
        sig = 1.0 / np.array([-v.A1[FYF, FYF], -v.A1[FYR, FYR]])
        valid = np.all(np.isfinite(Y[:, 1:5]), axis=1)
        ay = _fill(Y[:, 4])
        ym = np.column_stack([_fill(Y[:, j]) for j in (1, 2, 3)])  # r, phi_dot, delta_dot
        mv, _ = m.virtual_sensor_coefficients(0.0)
        n0 = m.virtual_sensor_coefficients(0.0)[1]
        n1 = m.virtual_sensor_coefficients(1.0)[1] - n0
        q = ym @ n0 + vx * (ym @ n1)
        chi = m.regressor(X, vx)
        relax = vx[:, None] / sig[None, :] * X[:, [FYF, FYR]]
        sv = state_variable_filter(np.column_stack([ay, ym, q, chi, relax]), dt, o.filter_hz, o.order)
        d_ay = sv[1, :, 0]
        d_ya = sv[2, :, 1:4] @ mv + sv[1, :, 4]
        G = np.array([[1.0 / v.mass, 1.0 / v.mass], m.c_virtual[[FYF, FYR]]])
        dF = np.column_stack([d_ay, d_ya]) @ np.linalg.inv(G).T  # (K, 2)
        Hchi = sv[0, :, 5:9]
        Hrel = sv[0, :, 9:11]
        c0 = m.theta0
        rows = np.zeros((len(t), 2, 4))
        rows[:, 0, 0:2] = Hchi[:, 0:2] * c0[0:2]
        rows[:, 1, 2:4] = Hchi[:, 2:4] * c0[2:4]
        z = dF + Hrel
        scale = _ewls(rows, z, valid, o.lam(dt), o.ridge, np.ones(4))
        self.t_, self.stiffness_ = t, scale * c0
        return self

    def result(self) -> EstimationResult:
        return EstimationResult(self.name, self.t_, self.stiffness_, None, {"options": self.options.__dict__},
                                nominal=self.model.theta0)


# --------------------------------------------------------------------------- joint EKF
@njit(cache=True, inline="always")
def _f_aug(x, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, out):
    deriv(x, M, c, g, vx, inv_sigma, fmax, bank, out)
    for j in range(4):
        out[6 + j // 2] += chi_entry(x, vx, H0, H1, j) * c0[j] * s[j]


@njit(cache=True)
def taylor_transition(F: np.ndarray, h: float, nsub: int) -> np.ndarray:
    """The covariance transition of an extended Kalman filter over ``nsub`` substeps of ``h`` [s] with the
    Jacobian ``F`` held: ``Phi = (I + F h + (F h)^2/2 + (F h)^3/6 + (F h)^4/24)^nsub``, the fourth-order Taylor
    step of ``exp(F h)`` (the order of the RK4 mean), used by the joint EKF and :mod:`assist.estimation.friction_imm`."""
    n = F.shape[0]
    Fh = F * h
    Fh2 = Fh @ Fh
    Fh3 = Fh2 @ Fh
    Phi1 = np.eye(n) + Fh + Fh2 / 2.0 + Fh3 / 6.0 + Fh3 @ Fh / 24.0
    Phi = Phi1.copy()
    for _ in range(nsub - 1):
        Phi = Phi1 @ Phi
    return Phi


@njit(cache=True)
def _ekf_run(Zout, Pdiag, Nis, z, P, Y, TAU, VX, W, inv_sigma, fmax, bank, dt, nsub, H0, H1, c0, C, rvar,
             Qc, fd_eps, s_lo, s_hi, nd):
    K = Y.shape[0]
    n = z.shape[0]  # 8 states, 4 stiffness scales, the sensor offsets b, then nd drift rates d (b' = d, d' = 0)
    nb = n - 12 - nd
    M = np.empty((8, 8))
    c = np.empty(8)
    g = np.empty((8, 2))
    k1 = np.empty(8)
    k2 = np.empty(8)
    k3 = np.empty(8)
    k4 = np.empty(8)
    tmp = np.empty(8)
    fp = np.empty(8)
    fm = np.empty(8)
    F = np.zeros((n, n))
    for k in range(K):
        # ---- measurement update at t_k (sequential scalar, Joseph form)
        for r in range(Y.shape[1]):
            yr = Y[k, r]
            if not np.isfinite(yr):
                continue
            h = C[r]
            e = yr
            for i in range(n):
                e -= h[i] * z[i]
            Ph = np.zeros(n)
            for i in range(n):
                acc = 0.0
                for j in range(n):
                    acc += P[i, j] * h[j]
                Ph[i] = acc
            S = rvar[r]
            for j in range(n):
                S += h[j] * Ph[j]
            Nis[k, r] = e * e / S  # normalised innovation squared: 1 on average when the model explains the data
            Kg = Ph / S
            for i in range(n):
                z[i] += Kg[i] * e
            # P = (I - K h) P (I - K h)^T + K R K^T
            A = np.eye(n)
            for i in range(n):
                for j in range(n):
                    A[i, j] -= Kg[i] * h[j]
            P[:, :] = A @ P @ A.T + rvar[r] * np.outer(Kg, Kg)
        for j in range(4):
            z[8 + j] = min(max(z[8 + j], s_lo[j]), s_hi[j])
        for i in range(n):
            Zout[k, i] = z[i]
            Pdiag[k, i] = P[i, i]
        # ---- prediction to t_{k+1}
        vx = VX[k]
        fold_vx(W, vx, TAU[k], 0.0, M, c, g)
        x = z[:8].copy()
        s = z[8:].copy()
        # Jacobian at the current estimate
        F[:, :] = 0.0
        for j in range(8):
            hj = fd_eps[j]
            for i in range(8):
                tmp[i] = x[i]
            tmp[j] = x[j] + hj
            _f_aug(tmp, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, fp)
            tmp[j] = x[j] - hj
            _f_aug(tmp, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, fm)
            for i in range(8):
                F[i, j] = (fp[i] - fm[i]) / (2.0 * hj)
        for jj in range(4):
            acc = 0.0
            for i in range(8):
                acc += (H0[jj, i] + vx * H1[jj, i]) * x[i]
            F[6 + jj // 2, 8 + jj] = acc * c0[jj]
        for j in range(nd):  # the first nd offsets drift: b_j' = d_j
            F[12 + j, 12 + nb + j] = 1.0
        hsub = dt / nsub
        Phi = taylor_transition(F, hsub, nsub)
        P[:, :] = Phi @ P @ Phi.T + Qc * dt
        for i in range(n):
            for j in range(i):
                a = 0.5 * (P[i, j] + P[j, i])
                P[i, j] = a
                P[j, i] = a
        # mean: RK4 substeps
        for _ in range(nsub):
            _f_aug(x, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, k1)
            for i in range(8):
                tmp[i] = x[i] + 0.5 * hsub * k1[i]
            _f_aug(tmp, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, k2)
            for i in range(8):
                tmp[i] = x[i] + 0.5 * hsub * k2[i]
            _f_aug(tmp, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, k3)
            for i in range(8):
                tmp[i] = x[i] + hsub * k3[i]
            _f_aug(tmp, s, M, c, g, vx, inv_sigma, fmax, bank, H0, H1, c0, k4)
            for i in range(8):
                x[i] += hsub / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        for i in range(8):
            if not np.isfinite(x[i]):
                return k + 1
            z[i] = x[i]
        for j in range(nd):
            z[12 + j] += dt * z[12 + nb + j]
    return K


class JointEKF:
    """Joint state and stiffness extended Kalman filter (module docstring), scikit-learn style.

    Parameters
    ----------
    sensors : SensorConfig, optional
        Measurement noise the filter assumes (default ``SensorConfig.from_percent(5)``;
        the encoder quantisation ``q^2/12`` is added to delta).
    process_std : 8 floats
        Model-error intensities of the states [unit/sqrt(s)].
    stiffness_walk : float
        Random-walk intensity of each ``s_j = C_j/C_0j - 1`` [1/sqrt(s)].
    stiffness_std0 : float
        Initial standard deviation of ``s`` (the prior is the nominal).
    band : (float, float)
        Stiffness band (multiples of ``C_0``) the estimate is clipped to.
    offsets : sequence of str
        Channels of :data:`OFFSET_CHANNELS` whose constant offset is estimated with the states (module
        docstring; default none).
    road_bank : float
        Known bank of the road [rad] (effects.md ``road_bank``) in the filter's plant (default level): a bank
        the plant lacks reads as offsets of ``ay`` and the gyros.
    drift : bool
        The offsets drift linearly over the log (module docstring: ``b' = d``, ``d' = 0``; default False:
        constant offsets).

    ``fit(log)`` sets ``stiffness_`` (K, 4), ``x_hat_`` (K, 8), ``stiffness_std_`` (K, 4), ``t_``, and
    ``offsets_``, ``offsets_std_`` (K, number of offsets; channel units: rad, rad/s, m/s^2); with ``drift``
    also ``drifts_``, ``drifts_std_`` (K, number of offsets; channel units per second).
    """

    name = "ukf"

    def __init__(self, sensors: SensorConfig | None = None, process_std=DEFAULT_PROCESS_STD,
                 stiffness_walk: float = 0.005, stiffness_std0: float = 0.5, band=DEFAULT_BAND,
                 model: LPVModel | None = None, offsets: Sequence[str] = (), road_bank: float = 0.0,
                 drift: bool = False) -> None:
        self.model = build_lpv_model() if model is None else model
        self.sensors = SensorConfig.from_percent(5, vehicle=self.model.vehicle) if sensors is None else sensors
        if not isinstance(self.sensors, SensorConfig):
            raise IdentificationError(f"sensors must be a SensorConfig, got {type(sensors).__name__}")
        q = np.asarray(process_std, dtype=float)
        if q.shape != (8,) or not np.all(np.isfinite(q)) or np.any(q <= 0):
            raise IdentificationError(f"process_std must hold 8 positive numbers, got {process_std!r}")
        for name, val in (("stiffness_walk", stiffness_walk), ("stiffness_std0", stiffness_std0)):
            if not (val > 0 and math.isfinite(val)):
                raise IdentificationError(f"{name} must be a positive number, got {val!r}")
        lo, hi = (float(b) for b in band)
        if not (0 < lo < 1 < hi) or not math.isfinite(hi):
            raise IdentificationError(f"band must be (lo, hi) with 0 < lo < 1 < hi, got {band!r}")
        self.process_std, self.stiffness_walk, self.stiffness_std0 = q, float(stiffness_walk), float(stiffness_std0)
        self.band = (lo, hi)
        self.offsets = offset_channels(offsets)
        self.road_bank = check_bank(road_bank, IdentificationError)  # effects.md's range, as the other designs
        if not isinstance(drift, bool):
            raise IdentificationError(f"drift must be True or False, got {drift!r}")
        if drift and not self.offsets:
            raise IdentificationError("drift=True needs offsets: the drift is that of the offsets' channels")
        self.drift = drift

    def fit(self, log) -> "JointEKF":
        m = self.model
        t, Y, tau, vx, dt = _log_arrays(log)
        vx = np.clip(vx, m.vehicle.vmin, m.vehicle.vmax)
        plant = compile_plant(m.vehicle, {"road_bank": {"bank_rad": self.road_bank}} if self.road_bank else None)
        W, isg, fmx, bk = plant.flat()
        rvar = np.array([self.sensors.noise_std[c] ** 2 for c in OUTPUT_NAMES])
        if self.sensors.delta_quantum:
            rvar[0] += self.sensors.delta_quantum**2 / 12.0
        else:
            rvar[0] += ENCODER_QUANTUM**2 / 12.0
        rvar = np.maximum(rvar, 1e-10)
        # the offsets: constant states b_c read by their channel's output row (y_c = C_c x + b_c)
        rows = [OUTPUT_NAMES.index(c) for c in self.offsets]
        nb = len(rows)
        nd = nb if self.drift else 0  # drift rates d_c (b_c' = d_c): a line over the log per offset
        n = 12 + nb + nd
        C = np.zeros((len(OUTPUT_NAMES), n))
        C[:, :8] = m.C
        for j, r in enumerate(rows):
            C[r, 12 + j] = 1.0
        b_std0 = OFFSET_PRIOR_NOISE * np.sqrt(rvar[rows])
        d_std0 = b_std0[:nd] / max(float(t[-1] - t[0]), dt)  # a drift moving the offset by its prior over the log
        Qc = np.diag(np.r_[self.process_std**2, np.full(4, self.stiffness_walk**2), np.zeros(nb + nd)])
        P0 = np.diag(np.r_[(STATE_SCALE * 0.1) ** 2, np.full(4, self.stiffness_std0**2), b_std0**2, d_std0**2])
        z = np.zeros(n)
        K = len(t)
        Z = np.zeros((K, n))
        Pd = np.zeros((K, n))
        nis = np.full((K, len(OUTPUT_NAMES)), np.nan)
        lo, hi = self.band
        k_end = _ekf_run(Z, Pd, nis, z, P0.copy(), np.ascontiguousarray(Y), np.ascontiguousarray(tau),
                         np.ascontiguousarray(vx), W[0], isg[0], fmx[0], float(bk[0]), dt, substeps_for(dt),
                         np.ascontiguousarray(m.H0), np.ascontiguousarray(m.H1), np.ascontiguousarray(m.theta0), C,
                         rvar, Qc, STATE_SCALE * 1e-4, np.full(4, lo - 1.0), np.full(4, hi - 1.0), nd)
        if k_end < K:
            raise FilterDivergence(f"the EKF diverged at t = {t[k_end - 1]:.2f} s (sample {k_end - 1})")
        self.t_ = t
        self.x_hat_ = Z[:, :8]
        self.stiffness_ = (1.0 + Z[:, 8:12]) * m.theta0
        self.stiffness_std_ = np.sqrt(np.maximum(Pd[:, 8:12], 0.0)) * m.theta0
        self.offsets_ = Z[:, 12:12 + nb]
        self.offsets_std_ = np.sqrt(np.maximum(Pd[:, 12:12 + nb], 0.0))
        if nd:
            self.drifts_ = Z[:, 12 + nb:]
            self.drifts_std_ = np.sqrt(np.maximum(Pd[:, 12 + nb:], 0.0))
        # mean normalised innovation squared per channel over the log's second half (the first holds the
        # filter's convergence from its prior): near 1 when the model (with its offsets) explains the channel
        half = nis[K // 2:]
        self.nis_ = {c: float(np.nanmean(half[:, j])) if np.isfinite(half[:, j]).any() else None
                     for j, c in enumerate(OUTPUT_NAMES)}
        return self

    @property
    def explains(self) -> bool:
        """True when the filter's model (with its offsets) explains every channel read: mean normalised
        innovation squared at most :data:`NIS_EXPLAINED` (:attr:`nis_`)."""
        return all(v is None or v <= NIS_EXPLAINED for v in self.nis_.values())

    def offset_table(self) -> dict[str, dict[str, Any]]:
        """``{channel: {"value", "std", "unit", "significant", "nis"}}`` at the log's end (channel units):
        ``significant`` when ``|value| > OFFSET_SIGNIFICANCE std``; ``nis`` the channel's mean normalised
        innovation squared over the log's second half (:attr:`nis_`): an offset can only be read as a sensor's
        when the model with it explains its channel (``nis`` up to :data:`NIS_EXPLAINED`); far above that the
        "offset" is what a model error leaves in the channel. With ``drift``, ``value`` is the offset at the
        log's end and ``drift`` gives its rate: ``{"value", "std", "unit", "significant", "t_ref_s"}``, the
        offset at time ``t`` being ``value + drift (t - t_ref_s)``."""
        out: dict[str, dict[str, Any]] = {}
        for j, c in enumerate(self.offsets):
            v, sd = float(self.offsets_[-1, j]), float(self.offsets_std_[-1, j])
            out[c] = {"value": v, "std": sd, "unit": OFFSET_UNITS[c], "significant": bool(abs(v) > OFFSET_SIGNIFICANCE * sd),
                      "nis": self.nis_[c]}
            if self.drift:
                d, dsd = float(self.drifts_[-1, j]), float(self.drifts_std_[-1, j])
                out[c]["drift"] = {"value": d, "std": dsd, "unit": f"({OFFSET_UNITS[c]})/s" if "/" in OFFSET_UNITS[c] else f"{OFFSET_UNITS[c]}/s",
                                   "significant": bool(abs(d) > OFFSET_SIGNIFICANCE * dsd), "t_ref_s": float(self.t_[-1])}
        return out

    @property
    def drifting(self) -> bool:
        """True when some offset's drift stands out of its standard deviation by :data:`OFFSET_SIGNIFICANCE`
        (always False for constant offsets)."""
        return self.drift and any(e["drift"]["significant"] for e in self.offset_table().values())

    def result(self) -> EstimationResult:
        info: dict[str, Any] = {"filter": "extended Kalman filter (joint states and stiffness scales"
                                          + (", sensor offsets)" if self.offsets else ")"),
                                "stiffness_std_final": [float(s) for s in self.stiffness_std_[-1]]}
        if self.offsets:
            info["offsets"] = self.offset_table()
            info["offset_filter_nis"] = dict(self.nis_)
        return EstimationResult("ukf", self.t_, self.stiffness_, self.x_hat_, info, nominal=self.model.theta0)


#: Mean normalised innovation squared of a channel up to which the filter's model explains it (1 for a
#: consistent filter; the filter's noise model is the sensors' white noise, so coloured noise and small model
#: errors raise it somewhat: see :meth:`JointEKF.offset_table`).
NIS_EXPLAINED = 3.0

#: Units of the offsets of :data:`OFFSET_CHANNELS` (their channels' units).
OFFSET_UNITS = {c: u for c, u in zip(OUTPUT_NAMES, OUTPUT_UNITS) if c in OFFSET_CHANNELS}


def offset_channels(offsets: Sequence[str] | str) -> tuple[str, ...]:
    """``offsets`` checked: channels of :data:`OFFSET_CHANNELS`, each once (``"all"``: every one of them;
    ``"none"``: none)."""
    if isinstance(offsets, str):
        offsets = {"all": OFFSET_CHANNELS, "none": ()}.get(offsets, (offsets,))
    if not isinstance(offsets, (tuple, list)) or not all(isinstance(c, str) for c in offsets):
        raise IdentificationError(f"offsets must be 'all', 'none' or a sequence of channel names of "
                                  f"{', '.join(OFFSET_CHANNELS)}, got {offsets!r}")
    out = tuple(offsets)
    bad = [c for c in out if c not in OFFSET_CHANNELS]
    if bad or len(set(out)) != len(out):
        raise IdentificationError(f"offsets must be distinct channels of {', '.join(OFFSET_CHANNELS)} (or 'all'), "
                                  f"got {list(out)!r}")
    return out


def drift_used(entry: dict[str, Any]) -> bool:
    """Whether an offset table entry's drift is part of its offset (a line, removed with it where the offset is
    removed): an entry of a drifting filter (:meth:`JointEKF.offset_table`), unless marked ``"used": False`` (a
    drift reported beside a constant offset)."""
    return "drift" in entry and entry["drift"].get("used", True)


def stands_out(entry: dict[str, Any]) -> bool:
    """Whether an offset table entry is one the data determine: the offset, or its drift where the drift is
    used, beyond :data:`OFFSET_SIGNIFICANCE` standard deviations."""
    return bool(entry["significant"] or (drift_used(entry) and entry["drift"]["significant"]))


def remove_offsets(log, table: dict[str, dict[str, Any]]):
    """``log`` with each offset of ``table`` (:meth:`JointEKF.offset_table`) marked ``removed`` subtracted from
    its channel, with its ``drift`` where the table holds one (the line ``value + drift (t - t_ref_s)``; a new
    :class:`ptw_env.logs.RideLog`; ``log`` itself when none is)."""
    from ptw_env.logs import RideLog

    t = np.asarray(log.t, dtype=float)
    drop = {c: e["value"] + (e["drift"]["value"] * (t - e["drift"]["t_ref_s"]) if drift_used(e) else 0.0)
            for c, e in table.items() if e.get("removed")}
    if not drop:
        return log
    cols = {k: (v - drop[k] if k in drop else v) for k, v in log.columns.items()}
    return RideLog(t=log.t, columns=cols, meta=log.meta, path=log.path, ignored_columns=log.ignored_columns,
                   lines=log.lines)


def _with_drift(ekf: JointEKF, log) -> tuple[JointEKF, dict[str, dict[str, Any]]]:
    """The offsets' filter to use and the drift estimates to report. The same filter with drifting offsets
    (``drift=True``) is run beside ``ekf``; it replaces ``ekf`` when a drift stands out
    (:attr:`JointEKF.drifting`) and that filter explains the log (:attr:`JointEKF.explains`); else ``ekf``
    stays, and the drifts (``{}`` if that filter diverged) are reported, not used."""
    d = copy.copy(ekf)  # the same settings (checked when ekf was made), with drifting offsets
    d.drift = True
    try:
        d.fit(log)
    except FilterDivergence:
        return ekf, {}
    if d.drifting and d.explains:
        return d, {}
    return ekf, {c: e["drift"] for c, e in d.offset_table().items()}


def _drift_reported(table: dict[str, dict[str, Any]], drifts: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """``table`` with the drifts of a filter that was not used, each marked ``"used": False`` (the offsets
    removed are then constant); the drifts of the filter used are marked ``"used": True``."""
    out = {}
    for c, e in table.items():
        if "drift" in e:
            out[c] = {**e, "drift": {**e["drift"], "used": True}}
        elif c in drifts:
            out[c] = {**e, "drift": {**drifts[c], "used": False}}
        else:
            out[c] = dict(e)
    return out


def _fit_offsets(ekf: JointEKF, log) -> tuple[JointEKF, dict[str, dict[str, Any]]]:
    """Fit ``ekf`` (constant offsets) and its drifting twin (:func:`_with_drift`); the filter used and its offset
    table, each entry marked ``removed`` where it (or its drift) stands out and the filter explains the log.
    Raises :class:`FilterDivergence` when ``ekf`` diverges."""
    ekf.fit(log)
    ekf, drifts = _with_drift(ekf, log)
    # an offset is removed only where the data determine it (or its drift) and the model with the offsets
    # explains the log: otherwise the "offsets" are what a model error leaves in the channels, and removing
    # them is a guess
    table = {c: {**e, "removed": stands_out(e) and ekf.explains}
             for c, e in _drift_reported(ekf.offset_table(), drifts).items()}
    return ekf, table


def correct_offsets(log, offsets: Sequence[str] | str = "all", *, sensors: SensorConfig | None = None,
                    model: LPVModel | None = None, road_bank: float = 0.0):
    """The offsets' correction every command that reads a log runs first (``estimate``, ``risk``; module
    docstring): the joint EKF with the ``offsets`` channels' constant offsets, and beside it the same filter with
    drifting ones (:func:`_with_drift`); each offset (or line) that stands out of its standard deviation by
    :data:`OFFSET_SIGNIFICANCE` is removed, **only where the filter used explains the log**
    (:attr:`JointEKF.explains`).

    Returns ``(log_corrected, table, nis, error)``: the log with the removed offsets taken off (``log`` itself
    when none is), the offset table (:meth:`JointEKF.offset_table`, each entry with ``removed`` and, where a
    drift was estimated, ``drift`` with ``used``), the filter's mean normalised innovations per channel
    (:attr:`JointEKF.nis_`), and ``None``; with no channel, ``(log, {}, {}, None)``; when the filter diverges,
    ``(log, None, None, why)``. Bad arguments and a log the filter cannot read raise :class:`IdentificationError`.
    """
    chans = offset_channels(offsets)
    ekf = JointEKF(sensors=sensors, model=model, offsets=chans, road_bank=road_bank)
    if not chans:
        return log, {}, {}, None
    try:
        ekf, table = _fit_offsets(ekf, log)
    except FilterDivergence as exc:
        return log, None, None, str(exc)
    return remove_offsets(log, table), table, dict(ekf.nis_), None


# --------------------------------------------------------------------------- one entry point
def _same_model(a: LPVModel, b: LPVModel) -> bool:
    return (a.vmin, a.vmax) == (b.vmin, b.vmax) and \
        a.vehicle.identity()["model_sha256"] == b.vehicle.identity()["model_sha256"]


def estimate(log, method: str, *, sensors: SensorConfig | None = None, observer: AdaptiveObserver | None = None,
             x_hat: np.ndarray | None = None, ls_options: LSOptions | None = None,
             model: LPVModel | None = None, offsets: Sequence[str] | str = ()) -> EstimationResult:
    """Run ``method`` (:data:`METHODS`, or ``"ekf"``) on a :class:`ptw_env.logs.RideLog`.

    ``offsets``: channels (:data:`OFFSET_CHANNELS`, or ``"all"``) whose constant sensor offsets are estimated as
    nuisance parameters (module docstring): by the joint EKF itself for ``ukf``; for the other methods by the
    joint EKF first, the significant ones (:data:`OFFSET_SIGNIFICANCE`) removed from the log before the method
    runs when that filter explains the log (:attr:`JointEKF.explains`). The result's ``info["offsets"]`` gives
    each with its standard deviation, its channel's normalised innovations and whether it was removed
    (``ukf``: never, they are estimated jointly); ``info["offset_filter_nis"]`` every channel's
    (:attr:`JointEKF.nis_`). A known bank (``observer.road_bank``) goes into the filter's plant. If that filter
    diverges, the method runs on the log as it is and ``info["offsets_error"]`` says why. A given ``x_hat``
    (estimated on the log before its offsets were removed) with an offset to remove is an error. Drifts: the
    same filter with linearly drifting offsets runs beside it and is used instead when a drift stands out and
    it explains the log (each offset removed is then a line over the log); each entry's ``drift`` gives the
    rate, its standard deviation and whether that filter was ``used`` (:func:`_with_drift`).

    ``model`` is the vehicle's LPV model (:func:`assist.estimation.lpv_model.build_lpv_model`; default the
    observer's, else the reference scooter's); ``observer`` must be designed on it. ``direct`` and
    ``inversion`` take their unmeasured regressor states from ``x_hat`` (default: the adaptive observer's
    estimate of the same log). The log's ``roll`` column is never used.
    """
    meth = "ukf" if method == "ekf" else method
    if meth not in METHODS:
        raise IdentificationError(f"unknown method {method!r}; known: {', '.join(METHODS)} (ekf = ukf)")
    if model is None:
        model = observer.design.model if observer is not None else build_lpv_model()
    elif observer is not None and not _same_model(observer.design.model, model):
        raise IdentificationError(f"observer= is designed on {observer.design.model.vehicle.name!r} at "
                                  f"[{observer.design.model.vmin}, {observer.design.model.vmax}] m/s, model= is "
                                  f"{model.vehicle.name!r} at [{model.vmin}, {model.vmax}] m/s")

    def default_observer() -> AdaptiveObserver:
        return AdaptiveObserver(default_design(model=model)) if observer is None else observer

    chans = offset_channels(offsets)
    bank = observer.road_bank if observer is not None else 0.0  # a known bank in the filter's plant too
    if meth == "ukf":
        ekf = JointEKF(sensors=sensors, model=model, offsets=chans, road_bank=bank)
        if not chans:
            return ekf.fit(log).result()
        ekf, table = _fit_offsets(ekf, log)
        res = ekf.result()
        table = {c: {**e, "removed": False} for c, e in table.items()}  # estimated jointly: nothing taken off
        return dataclasses.replace(res, info={**res.info, "offsets": table, "offset_filter_nis": dict(ekf.nis_)})
    if chans:
        fixed, table, nis, error = correct_offsets(log, chans, sensors=sensors, model=model, road_bank=bank)
        if error is not None:  # the filter diverged: no offsets, the method runs on the log as it is
            res = estimate(log, method, sensors=sensors, observer=observer, x_hat=x_hat, ls_options=ls_options,
                           model=model)
            return dataclasses.replace(res, info={**res.info, "offsets_error": error})
        if x_hat is not None and fixed is not log:
            raise IdentificationError("x_hat was estimated on the log before its sensor offsets were removed: "
                                      "pass offsets=() with it, or leave x_hat out (the observer then runs on the "
                                      "corrected log)")
        res = estimate(fixed, method, sensors=sensors, observer=observer, x_hat=x_hat, ls_options=ls_options,
                       model=model)
        return dataclasses.replace(res, info={**res.info, "offsets": table, "offset_filter_nis": nis})

    if meth == "adaptive":
        obs = default_observer()
        run = obs.run_log(log)
        if run.samples < len(run.t):
            raise IdentificationError(f"the adaptive observer diverged at t = {run.t[run.samples - 1]:.2f} s")
        info = {"law": obs.law, "equality_residual_rel": obs.design.residual_rel,
                "stiffness_std_final": [float(v) for v in obs.stiffness_std]}
        return EstimationResult("adaptive", run.t, run.stiffness, run.x_hat, info, nominal=model.theta0)
    if x_hat is None:
        x_hat = default_observer().run_log(log).x_hat
    est = DirectLS(ls_options, model=model) if meth == "direct" else InversionLS(ls_options, model=model)
    res = est.fit(log, x_hat=x_hat).result()
    return dataclasses.replace(res, x_hat=x_hat)


# --------------------------------------------------------------------------- a time-varying effect
def simulate_friction_drop(scenario: str = "urban", switch_s: float = 20.0, before: float = 1.0, after: float = 0.6,
                           noise_pct: float | None = 5.0, seed: int = 0, speed_kmh: float | None = None,
                           duration_s: float | None = None, rider_noise_nm: float | None = None,
                           vehicle: Vehicle | None = None, scenario_options: dict[str, Any] | None = None):
    """Ride ``scenario`` with a road-friction drop: both stiffness scales go from ``before`` to
    ``after`` at ``t = switch_s`` (effects.md ``tire_stiffness``: friction scales all four stiffnesses).

    ``vehicle`` (default the reference scooter) is ridden by its own LQR rider; ``rider_noise_nm``
    [N m] defaults to :data:`ptw_env.ride.RIDER_NOISE_NM` times the vehicle's ``torque_ratio``.

    :class:`ptw_env.env.PTWRollEnv` holds one plant per episode, so the loop is
    run here with the same parts the environment uses (the scenario's profile,
    :class:`ptw_env.rider.LQRRider` on the true state, :class:`ptw_env.sensors.SensorModel`,
    one :class:`ptw_env.integrate.Stepper` per plant) and the *stepper is swapped*
    at the switch; the true lateral acceleration ``(Fyf + Fyr)/M`` is continuous.

    Returns
    -------
    (RideLog, truth) : the log (with ``x_*`` truth columns and ``vx_true``) and the true
    stiffness history (K, 4) [N/rad].
    """
    from ptw_env.integrate import Stepper
    from ptw_env.logs import RideLog
    from ptw_env.ride import RIDER_NOISE_NM
    from ptw_env.rider import LQRRider
    from ptw_env.scenarios import make_scenario
    from ptw_env.sensors import CHANNELS, SensorModel
    from ptw_env.vehicle import REFERENCE_SCOOTER, STATE_NAMES
    from ptw_env.vehicle_files import sidecar_vehicle

    v = REFERENCE_SCOOTER if vehicle is None else vehicle
    if rider_noise_nm is None:
        rider_noise_nm = RIDER_NOISE_NM * v.torque_ratio
    for name, val in (("before", before), ("after", after)):
        if not (0.05 <= val <= 5.0):
            raise IdentificationError(f"{name} must be a stiffness scale in [0.05, 5], got {val!r}")
    over = {} if duration_s is None else {"duration_s": float(duration_s)}
    over.update(scenario_options or {})
    scen = make_scenario(scenario, speed_kmh=speed_kmh, **over)
    dt = 0.01
    prof = scen.profile(dt, seed=None)
    prof.check_vehicle(v)
    K = len(prof.t)
    k_sw = int(round(switch_s / dt))
    if not 0 < k_sw < K:
        raise IdentificationError(f"switch_s = {switch_s} s must lie inside the ride (0, {prof.t[-1]:.1f}) s")
    plants = [compile_plant(v, {"tire_stiffness": {"front_scale": b, "rear_scale": b}}) for b in (before, after)]
    steppers = [Stepper(p, dt) for p in plants]
    cfg = SensorConfig.from_percent(noise_pct, vehicle=v) if noise_pct is not None else SensorConfig()
    sens = SensorModel(cfg, None, dt=dt)
    root = np.random.SeedSequence(seed)
    s1, s2, s3 = root.spawn(3)
    sens.reset(np.random.default_rng(s1))
    rider = LQRRider(v, torque_noise_nm=rider_noise_nm, dt=dt)
    rider.reset(np.random.default_rng(s2))
    x = np.zeros(8)
    x[0] = np.random.default_rng(s3).uniform(-0.005, 0.005)
    rows_y, rows_x, taus = [], [], []
    for k in range(K):
        i = int(k >= k_sw)
        vx = float(prof.vx[k])
        rows_y.append(sens.measure(x, vx, float(plants[i].ay(x))))
        rows_x.append(x.copy())
        tau = rider.torque(x, vx, float(prof.phi_ref[k]))
        taus.append(tau)
        if not steppers[i].step(x, tau, vx) or abs(x[0]) > math.radians(45):
            raise IdentificationError(f"the rider fell at t = {prof.t[k]:.2f} s; pick a gentler scenario or seed")
    Yc, X = np.asarray(rows_y), np.asarray(rows_x)
    cols = {"t": np.asarray(prof.t, dtype=float), "tau": np.asarray(taus)}
    for j, ch in enumerate(CHANNELS):
        cols[ch] = Yc[:, j]
    cols["vx_true"] = np.asarray(prof.vx, dtype=float)
    for j, nm in enumerate(STATE_NAMES):
        cols[f"x_{nm}"] = X[:, j]
    meta = {**sidecar_vehicle(v), "sample_rate_hz": 100, "scenario": scen.name,
            "generator": "assist.estimation.identification.simulate_friction_drop", "noise_pct": noise_pct,
            "friction_drop": {"switch_s": switch_s, "before": before, "after": after}, "seeds": {"root": seed}}
    c0 = build_lpv_model(v).theta0
    truth = np.where((np.arange(K) >= k_sw)[:, None], after * c0, before * c0)
    return RideLog(t=cols["t"], columns=cols, meta=meta, path=None), truth


__all__ = [
    "DirectLS",
    "EstimationResult",
    "IdentificationError",
    "InversionLS",
    "JointEKF",
    "LSOptions",
    "METHODS",
    "estimate",
    "simulate_friction_drop",
    "state_variable_filter",
]
