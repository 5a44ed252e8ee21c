"""Honest replay of a ride log: multi-step prediction over short windows.

Why not replay the whole log open loop
--------------------------------------
The reference scooter is open-loop unstable below ~11 m/s (weave, real part
up to +2.8 1/s at 3 m/s) and only lightly damped above, and the rider closes
the loop in the log. A whole-log open-loop simulation driven by the logged
torque drifts away from any real ride within seconds, whatever the model,
so its error measures the drift, not the model. A Kalman filter's
innovations are honest but only one step deep: over 10 ms most effects of
effects.md are far below the sensor noise, and every hypothesis would need
its own filter tuning.

What is done instead
--------------------
The log is cut into windows of ~2 s (:mod:`assist.diagnose.data`). In each
window the model (nominal, or with a hypothesised effect) is simulated by the
batched nonlinear simulator :func:`ptw_env.integrate.simulate` from an
initial state ``x0_w`` estimated *for that window and that model* by
weighted least squares on the window's measured channels (an output-error
"multiple shooting" fit: the 8 initial states per window are nuisance
parameters that every hypothesis gets equally):

.. math::

    \\hat x_{0,w}(\\theta) = \\arg\\min_{x_0} \\sum_{k, c}
       \\left(\\frac{y_{c}(t_k) - h_c(x(t_k; x_0, \\theta), \\theta)}{\\sigma_c}\\right)^2 .

``h`` is the sensor map (:func:`assist.diagnose.measurement.sensor_outputs`)
and ``sigma_c`` the noise level of channel ``c``. The window is short enough
that the unstable weave amplifies an initial-state error at most ~e^5, so the
fit stays well conditioned; long enough that an effect has time to act
(the reference logs' ``detectability_replay_2s``).

Besides its initial state, each window gets a small correction of the
logged speed, an offset and a ramp over the window (:data:`NX` nuisance
parameters in all). The speed is a measured input (a 10 Hz GPS with noise,
reconstructed in :mod:`assist.diagnose.data`); its remaining error of a few
cm/s is amplified by the lightly damped weave at low speed and would
otherwise leave a residual of several % of the noise at 0.5-2 Hz even for the
right model. Typical sizes (:data:`STATE_SCALE`, 5 cm/s for the speed)
weigh a weak pull towards the measured start state (:attr:`Replay.x_guess`,
speed correction 0), so that directions the scored outputs cannot see (tire
forces that decay during the lead) stay put:

.. math::

    \\min_{p_w} \\|r_w(p_w)\\|^2 + \\lambda^2 \\|D^{-1}(p_w - p_{w,\\text{guess}})\\|^2 ,
    \\qquad \\lambda = \\text{DAMPING},\\; D = \\operatorname{diag}(\\text{STATE\\_SCALE}).

The minimisation is Gauss-Newton with the sensitivity ``J_w = d y / d p_w``
computed by finite differences for each model evaluated (``NX`` extra
trajectories per window in the same batched call); each step costs one
batched simulation. Starting from the measured start state,
:data:`STATE_STEPS` steps converge (the map from ``p_w`` to the outputs is
nearly linear: the nonlinearity is ``sin(phi)`` and tire saturation).

Integration: :func:`ptw_env.integrate.simulate` (RK4, inputs held over each
sample) with as many substeps as keep ``|lambda h| <= TIRE_STEP`` for the
fastest tire-relaxation mode ``lambda = -vx/sigma`` of the batch: 2 substeps
(5 ms) for the reference scooter up to 40 m/s instead of the simulator's
default 4, the same model at half the cost. On the noise-free reference log
the replay residual does not change (checked down to 1 substep).
"""

from __future__ import annotations

import time

import numpy as np

from ptw_env.effects import DYNAMIC_CAUSES, Effects
from ptw_env.integrate import simulate
from ptw_env.vehicle import FYF, FYR, G, REFERENCE_SCOOTER, Vehicle

from .data import Windows
from .measurement import sensor_outputs
from .params import CAUSES, PARAMS

#: Gauss-Newton steps on the initial states per evaluation of a hypothesis.
STATE_STEPS = 2
#: Largest ``|lambda h|`` of the fastest tire-relaxation mode (``lambda = -vx / sigma``) per RK4
#: substep ``h``; sets the substeps of the replay (:meth:`Replay.substeps`).
TIRE_STEP = 1.0
#: Nuisance parameters per window: the 8 initial states and the speed correction (offset, ramp).
NX = 10
#: Finite-difference steps on the nuisance parameters (rad, rad, m/s, rad/s, rad/s, rad/s, N, N, m/s, m/s).
STATE_STEP = np.array([1e-3, 1e-3, 1e-2, 1e-3, 1e-3, 1e-3, 5.0, 5.0, 0.01, 0.01])
#: Typical size of each correction (same units): the scale of the damping and of the prior.
STATE_SCALE = np.array([0.02, 0.005, 0.1, 0.02, 0.02, 0.05, 200.0, 200.0, 0.05, 0.05])
#: Damping of the initial-state fit (Levenberg-Marquardt / Tikhonov): a correction of one typical
#: size (:data:`STATE_SCALE`) in a direction that changes the weighted residual norm by much less
#: than this is not made (an initial state the scored outputs cannot see).
DAMPING = 0.1

_SENSOR_ARGS = {
    ("gyro_bias", "yaw_rate_bias"): "yaw_rate_bias",
    ("gyro_bias", "roll_rate_bias"): "roll_rate_bias",
    ("ay_frame", "gravity_gain"): "gravity_gain",
    ("sensor_delay", "delay_s"): "delay_s",
}


class Replay:
    """Multi-step prediction of one log's windows under any batch of effect sizes (module docstring).

    Parameters
    ----------
    windows : Windows
        The log, cut by :func:`assist.diagnose.data.make_windows`.
    sigma : ndarray, shape (C,)
        Noise level per channel (physical units), the weights of the fit.
    vehicle : Vehicle, optional
        The nominal vehicle (default the reference scooter).

    Attributes
    ----------
    x_guess : ndarray, shape (W, NX)
        Start of every initial-state fit: the measured start states (:meth:`_initial_guess`).
    sim_seconds : float
        Wall time spent in :func:`ptw_env.integrate.simulate` so far [s].
    sim_steps : int
        Vehicle-steps simulated so far.
    """

    def __init__(self, windows: Windows, sigma: np.ndarray, vehicle: Vehicle | None = None) -> None:
        self.win = windows
        self.vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
        self._sigma0 = float(min(-1.0 / self.vehicle.A1[FYF, FYF], -1.0 / self.vehicle.A1[FYR, FYR]))
        self.sim_seconds = 0.0
        self.sim_steps = 0
        self.set_sigma(sigma)
        self.x_guess = self._initial_guess()

    # -- weights --------------------------------------------------------------
    def set_sigma(self, sigma: np.ndarray) -> None:
        """Set the noise levels (weights) per channel."""
        sigma = np.asarray(sigma, dtype=float)
        self.sigma = sigma
        self.weight = self.win.score / sigma[None, None, :]

    # -- simulation -------------------------------------------------------------
    def outputs(self, Z: np.ndarray, widx: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Predicted channels of windows ``widx`` for each parameter row of ``Z``.

        Parameters
        ----------
        Z : ndarray, shape (m, P)
            Internal parameter vectors (:data:`assist.diagnose.params.PARAMS`).
        widx : ndarray of int, shape (Ws,)
            Window indices.
        x0 : ndarray, shape (m, Ws, NX)
            Initial state and speed correction of each window for each parameter row.

        Returns
        -------
        ndarray, shape (m, Ws, n, C)
        """
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        m, Ws = Z.shape[0], len(widx)
        N = m * Ws
        rows = np.repeat(Z, Ws, axis=0)  # (N, P): parameter row of each simulated vehicle
        dyn: dict[str, dict[str, np.ndarray]] = {}
        sens: dict[str, np.ndarray] = {}
        for i, p in enumerate(PARAMS):
            col = rows[:, i]
            if np.all(col == p.nominal):
                continue
            if p.cause in DYNAMIC_CAUSES:
                dyn.setdefault(p.cause, {})[p.name] = np.asarray(p.value(col), dtype=float)
            else:
                sens[_SENSOR_ARGS[(p.cause, p.name)]] = col
        w = self.win
        tau = np.broadcast_to(w.tau[widx][None], (m, Ws, w.n - 1)).reshape(N, w.n - 1)
        x0 = np.reshape(x0, (N, NX))
        ramp = np.linspace(-0.5, 0.5, w.n - 1)[None, :]
        vx = np.broadcast_to(w.vx[widx][None], (m, Ws, w.n - 1)).reshape(N, w.n - 1)
        vx = np.clip(vx + x0[:, 8:9] + x0[:, 9:10] * ramp, self.vehicle.vmin, self.vehicle.vmax)
        eff = Effects(dyn)
        sigma = float(np.min(dyn["relaxation_length"]["sigma_m"])) if "relaxation_length" in dyn else self._sigma0
        nsub = max(1, int(np.ceil(w.dt * float(vx.max()) / (TIRE_STEP * sigma) - 1e-9)))
        t = time.perf_counter()
        X = simulate(np.ascontiguousarray(x0[:, :8]), tau, vx, dt=w.dt, effects=eff, vehicle=self.vehicle,
                     substeps=nsub)
        self.sim_seconds += time.perf_counter() - t
        self.sim_steps += N * (w.n - 1)
        mass = self.vehicle.mass + (rows[:, CAUSES["payload"][0]] if "payload" in dyn else 0.0)
        Y = sensor_outputs(X, mass, w.dt, channels=w.channels, **sens)
        if not np.all(np.isfinite(Y)):  # a candidate that diverges: a huge but finite misfit
            Y = np.nan_to_num(Y, nan=1e6, posinf=1e6, neginf=-1e6)
        return Y.reshape(m, Ws, w.n, len(w.channels))

    def residual(self, Z: np.ndarray, widx: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Weighted residual ``(y - y_hat)/sigma`` on the scored samples, shape (m, Ws, n, C)."""
        Yh = self.outputs(Z, widx, x0)
        return (self.win.Y[widx][None] - Yh) * self.weight[widx][None]

    # -- initial states -----------------------------------------------------------
    def _initial_guess(self) -> np.ndarray:
        """Start states from the measured channels at each window's first sample (model-independent):
        ``phi`` the logged roll (else the steady-turn lean ``atan(vx r / g)``), ``delta``, ``r``,
        ``phi_dot``, ``delta_dot`` as measured (the first reading that is not a dropout), ``vy = 0``,
        and the total tire force ``M ay``
        split between the axles as their static loads."""
        w = self.win
        first = np.argmax(w.valid, axis=1)  # (W, C): first reading that is not a dropout
        ch = {c: np.take_along_axis(w.Y[:, :, i], first[:, i:i + 1], axis=1)[:, 0] for i, c in enumerate(w.channels)}
        x0 = np.zeros((len(w), NX))  # the speed correction starts at 0
        x0[:, 0] = ch["roll"] if "roll" in ch else np.arctan(w.speed[:, 0] * ch["yaw_rate"] / G)
        x0[:, 1] = ch["delta"]
        x0[:, 3] = ch["yaw_rate"]
        x0[:, 4] = ch["roll_rate"]
        x0[:, 5] = ch["delta_rate"]
        t = self.vehicle.tires
        F = ch["ay"] * self.vehicle.mass
        x0[:, FYF] = F * t.Fzf / (t.Fzf + t.Fzr)
        x0[:, FYR] = F * t.Fzr / (t.Fzf + t.Fzr)
        return x0

    def linearise(self, Z: np.ndarray, widx: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual at ``x0`` and the damped pseudo-inverse of the sensitivity to the initial state.

        Both for each parameter row of ``Z`` (shape (m, P)) and window ``widx`` (shape (Ws,)),
        from one batched simulation of ``(NX + 1) m Ws`` vehicles (each window, and each window
        with one nuisance parameter perturbed by :data:`STATE_STEP`).

        Returns
        -------
        residual : ndarray, shape (m, Ws, n, C)
            Weighted residual at ``x0`` (shape (m, Ws, NX)).
        pinv : tuple of ndarray, shapes (m, Ws, NX, n C) and (m, Ws, NX, NX)
            ``D (J^T J + lambda^2 I)^-1 J^T`` with ``J`` the weighted sensitivity per
            typical-size correction ``D = diag(STATE_SCALE)`` and ``lambda`` = :data:`DAMPING`,
            and the matrix of the pull towards :attr:`x_guess`.
        """
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        m, Ws = Z.shape[0], len(widx)
        X0 = np.repeat(np.asarray(x0, dtype=float)[None], NX + 1, axis=0)  # (NX + 1, m, Ws, NX)
        for j in range(NX):
            X0[j + 1, :, :, j] += STATE_STEP[j]
        Y = self.outputs(np.tile(Z, (NX + 1, 1)), widx, X0.reshape((NX + 1) * m, Ws, NX)).reshape(NX + 1, m, Ws, -1)
        wt = self.weight[widx].reshape(1, Ws, -1)
        r0 = (self.win.Y[widx].reshape(1, Ws, -1) - Y[0]) * wt
        # weighted sensitivity per typical-size correction
        J = (Y[1:] - Y[0][None]) * wt[None] * (STATE_SCALE / STATE_STEP)[:, None, None, None]  # (NX, m, Ws, nC)
        JtJ = np.einsum("imwk,jmwk->mwij", J, J)
        Ainv = np.linalg.inv(JtJ + DAMPING**2 * np.eye(NX))
        pinv = STATE_SCALE[None, None, :, None] * np.einsum("mwij,jmwk->mwik", Ainv, J)
        # prior pull towards the measured start state: - lambda^2 D A^-1 D^-1 (x - x_guess)
        prior = DAMPING**2 * STATE_SCALE[:, None] * Ainv / STATE_SCALE[None, :]
        return r0.reshape(m, Ws, self.win.n, -1), (pinv, prior)

    def gauss_newton(self, Z: np.ndarray, widx: np.ndarray, x0: np.ndarray, r0: np.ndarray, pinv: tuple,
                     steps: int, safeguard: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``steps`` Gauss-Newton steps on the initial states with a fixed ``pinv`` (:meth:`linearise`).

        Safeguarded per window: a step that raises the window's objective (weighted residual plus
        the pull towards :attr:`x_guess`, module docstring) is rejected and the window's next
        step is a quarter as long; an accepted step doubles it back (up to a full step). A model
        far from the log (the nominal one on a log with a large effect, say) would otherwise make
        the linearised steps overshoot in the odd window. ``safeguard=False``: plain steps (a smooth
        function of ``Z``, for finite differences). Returns the weighted residual at the returned
        states (one simulation per step) and the states.
        """
        m, Ws = x0.shape[:2]
        P, prior = pinv
        xg = self.x_guess[widx][None]

        def objective(x: np.ndarray, r: np.ndarray) -> np.ndarray:
            return (np.einsum("mwkc,mwkc->mw", r, r)
                    + DAMPING**2 * np.sum(((x - xg) / STATE_SCALE) ** 2, axis=-1))

        x, r = np.array(x0, dtype=float), np.array(r0, dtype=float)
        f = objective(x, r)
        alpha = np.ones((m, Ws, 1))
        for _ in range(steps):
            dx = np.einsum("mwjk,mwk->mwj", P, r.reshape(m, Ws, -1)) - np.einsum("mwjk,mwk->mwj", prior, x - xg)
            xn = x + alpha * dx
            rn = self.residual(Z, widx, xn)
            fn = objective(xn, rn)
            ok = fn <= f if safeguard else np.ones_like(f, dtype=bool)
            x = np.where(ok[..., None], xn, x)
            r = np.where(ok[..., None, None], rn, r)
            f = np.where(ok, fn, f)
            alpha = np.where(ok[..., None], np.minimum(1.0, 2.0 * alpha), 0.25 * alpha)
        return r, x

    def fit_states(self, Z: np.ndarray, widx: np.ndarray, x0: np.ndarray | None = None,
                   steps: int = STATE_STEPS, chunk: int = 512) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares initial states of windows ``widx`` for each parameter row (Gauss-Newton).

        The sensitivity is computed once, at the starting states, *for each parameter row*
        (a model far from nominal has other unstable modes), then ``steps`` steps follow.

        Parameters
        ----------
        Z : ndarray, shape (m, P)
        widx : ndarray of int, shape (Ws,)
        x0 : ndarray, shape (m, Ws, NX), optional
            Starting states (default: :attr:`x_guess`, from the measured channels).
        steps : int
            Gauss-Newton steps.
        chunk : int
            Largest number of (row, window) pairs linearised at once (memory).

        Returns
        -------
        residual : ndarray, shape (m, Ws, n, C)
            Weighted residual at the returned states.
        x0 : ndarray, shape (m, Ws, NX)
        """
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        widx = np.asarray(widx)
        m, Ws = Z.shape[0], len(widx)
        x = np.repeat(self.x_guess[widx][None], m, axis=0) if x0 is None else np.array(x0, dtype=float)
        rs, xs = [], []
        step = max(1, chunk // Ws)
        for i in range(0, m, step):
            sl = slice(i, i + step)
            r0, P = self.linearise(Z[sl], widx, x[sl])
            r, xx = self.gauss_newton(Z[sl], widx, x[sl], r0, P, steps)
            rs.append(r)
            xs.append(xx)
        return np.concatenate(rs), np.concatenate(xs)


__all__ = ["Replay", "STATE_STEPS"]
