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
nearly linear: the nonlinearity is ``sin(phi)`` and tire saturation). The one
state no sensor reads is the lateral velocity (0 in the measured start); near the
friction limit a saturating model's replay from ``vy = 0`` diverges, so where the
measured lateral force asks a saturating model for a sideslip (its force misses at
``vy = 0`` and also at the sideslip the scan finds for the same model with a linear
tire), the fit is made again from that sideslip and the better fit kept
(:meth:`Replay.fit_from_starts`); on a saturated plateau, where the first sample's force cannot
tell the candidate sideslips apart, the start is the candidate whose replay of the window fits it
best (:meth:`Replay.start`); linear-tire models keep the one start.

Integration: :func:`ptw_env.integrate.simulate` (RK4, inputs held over each
sample) with as many substeps as keep ``|lambda h| <= EIG_STEP`` for the
fastest eigenvalue of the batch: the vehicle's spectral radius
``max |eig(E^-1 A(vx))|`` up to the batch's highest speed (computed once on a
grid of the vehicle's speed range), raised for a shorter relaxation length
(the tire modes scale with ``1/sigma``) and for a steering damping larger than
the vehicle's (the steer mode ``-c/e66``). For the reference scooter this is
the tire lag ``-vx/sigma`` at speed (2 substeps, 5 ms, up to 40 m/s instead of
the simulator's default 4) and the wobble at low speed (1 substep); for a
bicycle on 0.15 m relaxation it is the lateral-tire oscillation near 100
rad/s at every speed, which the tire lag alone (``vx/sigma`` = 7-33 1/s at
1-5 m/s) would miss. On the noise-free reference log the replay residual does
not change (checked down to 1 substep).

Nuisance-parameter scales in the vehicle's units: the tire-force corrections
(:data:`STATE_SCALE`, finite-difference :data:`STATE_STEP`) are fractions
:data:`FORCE_SCALE` and :data:`FORCE_STEP` of the weight ``M g`` (200 N and
5 N on the reference scooter).

A candidate model whose replay leaves the numbers (NaN or inf: diverged) gets a
huge but finite misfit, and no information about the initial states from that
window (its sensitivity is zero), so it loses every comparison; it is never
an error.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from ptw_env.effects import DYNAMIC_CAUSES, Effects
from ptw_env.dynamics import Plant, add_generalised_forces, compile_plant
from ptw_env.integrate import plant_rate, simulate
from ptw_env.vehicle import FYF, FYR, G, REFERENCE_SCOOTER, VY, Vehicle

from .data import Windows
from .measurement import sensor_outputs
from .params import CAUSES, CLOSURES, ClosureTerm, param_set

#: Gauss-Newton steps on the initial states per evaluation of a hypothesis.
STATE_STEPS = 2
#: Largest ``|lambda h|`` of the fastest eigenvalue of the replayed batch per RK4 substep ``h``
#: (module docstring).
EIG_STEP = 1.0
#: Typical size of a tire-force correction of the initial state, as a fraction of the weight ``M g``.
FORCE_SCALE = 0.067
#: Finite-difference step on a tire-force initial state, as a fraction of the weight ``M g``.
FORCE_STEP = FORCE_SCALE / 40.0
#: Nuisance parameters per window: the 8 initial states and the speed correction (offset, ramp).
NX = 10
#: Finite-difference steps on the nuisance parameters (rad, rad, m/s, rad/s, rad/s, rad/s, N, N, m/s, m/s)
#: of the reference scooter (the forces are :data:`FORCE_STEP` of each vehicle's weight: :meth:`Replay.scales`).
STATE_STEP = np.array([1e-3, 1e-3, 1e-2, 1e-3, 1e-3, 1e-3, 5.0, 5.0, 0.01, 0.01])
#: Typical size of each correction (same units): the scale of the damping and of the prior (forces:
#: :data:`FORCE_SCALE` of the weight).
STATE_SCALE = np.array([0.02, 0.005, 0.1, 0.02, 0.02, 0.05, 200.0, 200.0, 0.05, 0.05])
#: Damping of the initial-state fit (Levenberg-Marquardt / Tikhonov): a correction of one typical
#: size (:data:`STATE_SCALE`) in a direction that changes the weighted residual norm by much less
#: than this is not made (an initial state the scored outputs cannot see).
DAMPING = 0.1

#: Sideslip angles [rad] scanned for the start of each window's lateral velocity (:meth:`Replay.start`):
#: a coarse grid over the range of tire slip angles (beyond the force peak of any tire), then a fine
#: one around its best point.
SLIP_SCAN = np.linspace(-0.2, 0.2, 41)
SLIP_FINE = np.linspace(-0.01, 0.01, 21)
_ZERO_SLIP = int(np.flatnonzero(SLIP_SCAN == 0.0)[0])
#: The start's sideslip moves from 0 only where the measured force asks for it by more than this many
#: standard deviations of its noise (:meth:`Replay.start`).
SLIP_SIGNIFICANCE = 3.0

#: Output magnitude taken as a diverged replay (any channel, physical units); such outputs are clipped
#: to it, a finite misfit far beyond any real one.
_DIVERGED = 1e6


@njit(cache=True)
def _below(Y, bound):
    """``(Y.shape[1], Y.shape[2])`` flags of a 4-D array: every ``|Y[k, a, b, c]| < bound`` (NaN is not), without
    the temporaries of ``np.all(np.abs(Y) < bound, axis=(0, 3))``."""
    K, A, B, C = Y.shape
    out = np.ones((A, B), dtype=np.bool_)
    for k in range(K):
        for a in range(A):
            for b in range(B):
                if out[a, b]:
                    for c in range(C):
                        if not abs(Y[k, a, b, c]) < bound:
                            out[a, b] = False
                            break
    return out

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
        The measured start states (:meth:`_initial_guess`): the start of every initial-state fit, with a
        second, sideslip start for a saturating tire where its saturation asks for one (:meth:`fit_from_starts`).
    sim_seconds : float
        Wall time spent in :func:`ptw_env.integrate.simulate` so far [s].
    sim_steps : int
        Vehicle-steps simulated so far.
    """

    def __init__(self, windows: Windows, sigma: np.ndarray, vehicle: Vehicle | None = None) -> None:
        self.win = windows
        self.vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
        self.params = param_set(self.vehicle)  # the vehicle's hypotheses: nominal, bounds, grids
        self.state_step, self.state_scale = self.scales(self.vehicle)
        v = self.vehicle
        self._rho_v = v.rate_speeds()
        self._rho = np.maximum.accumulate(v.mode_rates(self._rho_v))  # fastest eigenvalue up to each speed
        self._sigma0 = self.params.vehicle_scales.sigma
        self._damping0 = max(self.params.vehicle_scales.steer_damping, 0.0)
        self.sim_seconds = 0.0
        self.sim_steps = 0
        self.set_sigma(sigma)
        self.x_guess = self._initial_guess()

    @staticmethod
    def scales(vehicle: Vehicle) -> tuple[np.ndarray, np.ndarray]:
        """Finite-difference steps and typical sizes of the nuisance parameters of ``vehicle``
        (:data:`STATE_STEP`, :data:`STATE_SCALE` with the tire forces in fractions of ``M g``)."""
        step, scale = STATE_STEP.copy(), STATE_SCALE.copy()
        weight = vehicle.mass * G
        step[[FYF, FYR]] = FORCE_STEP * weight
        scale[[FYF, FYR]] = FORCE_SCALE * weight
        return step, scale

    def substeps(self, dt: float, vmax: float, sigma_min: float, damping_max: float) -> int:
        """RK4 substeps per sample for a batch up to speed ``vmax`` (module docstring)."""
        rho = float(np.interp(vmax, self._rho_v, self._rho))
        rho *= max(1.0, self._sigma0 / sigma_min)
        if damping_max > self._damping0:
            rho = max(rho, damping_max / float(self.vehicle.E[5, 5]))
        if not math.isfinite(rho):
            return 1
        return max(1, int(math.ceil(dt * rho / EIG_STEP - 1e-9)))

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
        w = self.win
        X, rows, dyn, sens, chan_terms = self._simulate(Z, widx, x0, w.n)
        mass = self.vehicle.mass + (rows[:, CAUSES["payload"][0]] if "payload" in dyn else 0.0)
        Y = sensor_outputs(X, mass, w.dt, channels=w.channels, **sens)
        for term, col in chan_terms:
            ch = term.equation.split(":", 1)[1]
            if ch in w.channels:
                j = w.channels.index(ch)
                if term.feature == "offset":
                    Y[..., j] += col[:, None]
                elif term.feature == "drift":  # y + c (t - t_mid) / t_half, t the log time of each sample
                    t = (w.t0[widx][:, None] + w.dt * np.arange(w.n)[None, :] - w.t_mid) / w.t_half
                    Y[..., j] += col[:, None] * np.tile(t, (m, 1))
                else:
                    Y[..., j] *= 1.0 + col[:, None]
        if not _below(Y.reshape(1, 1, 1, -1), _DIVERGED)[0, 0]:  # a candidate that diverges: a huge but finite misfit
            Y = np.clip(np.nan_to_num(Y, nan=_DIVERGED, posinf=_DIVERGED, neginf=-_DIVERGED), -_DIVERGED, _DIVERGED)
        return Y.reshape(m, Ws, w.n, len(w.channels))

    def _simulate(self, Z: np.ndarray, widx: np.ndarray, x0: np.ndarray, samples: int) -> tuple:
        """The states of the first ``samples`` samples of windows ``widx`` for each row of ``Z``
        (shape (m Ws, samples, 8)), with what :meth:`outputs` needs to read the channels: each
        simulated vehicle's parameter row, the dynamic effects, the sensor arguments and the
        closure terms of the channels."""
        m, Ws = Z.shape[0], len(widx)
        N = m * Ws
        rows = np.repeat(Z, Ws, axis=0)  # (N, P): parameter row of each simulated vehicle
        dyn: dict[str, dict[str, np.ndarray]] = {}
        sens: dict[str, np.ndarray] = {}
        forces: list[tuple[str, str, np.ndarray]] = []  # closure terms: generalised forces
        chan_terms: list[tuple[ClosureTerm, np.ndarray]] = []  # closure terms: sensor offsets, scales
        for i, p in enumerate(self.params.params):
            col = rows[:, i]
            if np.all(col == p.nominal):
                continue
            if p.cause in DYNAMIC_CAUSES:
                dyn.setdefault(p.cause, {})[p.name] = np.asarray(p.value(col), dtype=float)
            elif p.cause in CLOSURES:
                term = CLOSURES[p.cause]
                if term.equation.startswith("sensor:"):
                    chan_terms.append((term, col))
                else:
                    forces.append((term.equation, term.feature, col))
            else:
                sens[_SENSOR_ARGS[(p.cause, p.name)]] = col
        w = self.win
        k = samples - 1
        tau = np.broadcast_to(w.tau[widx][None, :, :k], (m, Ws, k)).reshape(N, k)
        x0 = np.reshape(x0, (N, NX))
        ramp = np.linspace(-0.5, 0.5, w.n - 1)[None, :k]
        vx = np.broadcast_to(w.vx[widx][None, :, :k], (m, Ws, k)).reshape(N, k)
        vx = np.clip(vx + x0[:, 8:9] + x0[:, 9:10] * ramp, self.vehicle.vmin, self.vehicle.vmax)
        eff = Effects(dyn)
        sigma = float(np.min(dyn["relaxation_length"]["sigma_m"])) if "relaxation_length" in dyn else self._sigma0
        damping = float(np.max(dyn["steer_damping"]["damping_nms"])) if "steer_damping" in dyn else 0.0
        nsub = self.substeps(w.dt, float(np.max(vx)), sigma, damping)
        model: Vehicle | Plant = self.vehicle
        if forces:  # a model extension: its generalised forces in the one right-hand side
            model = add_generalised_forces(compile_plant(self.vehicle, eff), forces)
            eff = None
            nsub = max(nsub, int(math.ceil(w.dt * plant_rate(model) / EIG_STEP - 1e-9)))
        t = time.perf_counter()
        X = simulate(np.ascontiguousarray(x0[:, :8]), tau, vx, dt=w.dt, effects=eff, vehicle=model,
                     substeps=nsub)
        self.sim_seconds += time.perf_counter() - t
        self.sim_steps += N * k
        return X, rows, dyn, sens, chan_terms

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

    def saturating(self, Z: np.ndarray) -> np.ndarray:
        """Rows of ``Z`` (shape (m, P)) whose tire saturates (``tire_saturation`` away from its nominal,
        the linear tire), shape (m,): the rows that may get the sideslip start (:meth:`start`)."""
        isat = CAUSES["tire_saturation"][0]
        return np.atleast_2d(Z)[:, isat] != self.params.nominal[isat]

    def _slip_scan(self, Z: np.ndarray, widx: np.ndarray) -> tuple[np.ndarray, ...]:
        """The sideslip scan of :meth:`start` for each row of ``Z`` (shape (m, P)) and window ``widx``.
        Returns ``beta`` (m, Ws) [rad], ``ask`` (m, Ws): ``vy = 0`` misses the coarse scan's least
        force change by more than :data:`SLIP_SIGNIFICANCE` noise levels, ``least`` (m, Ws) [N], the
        fine scan's least change (at ``beta``), and ``tol`` (Ws,) [N], the noise level of a force
        change over one sample; then the fine scan's candidates (m, K, Ws) [rad] and which of them are
        within ``tol`` of ``least`` (m, K, Ws)."""
        m, Ws = Z.shape[0], len(widx)
        v0 = self.win.vx[widx, 0]
        beta = np.zeros((m, Ws))
        # what the measured force can tell: the ay noise as a force, as far as it relaxes in one sample
        tol = (self.sigma[self.win.channels.index("ay")] * self.vehicle.mass
               * (1.0 - np.exp(-self.win.dt * v0 / self._sigma0)))
        for grid in (SLIP_SCAN, SLIP_FINE):
            b = beta[:, None, :] + grid[None, :, None]  # (m, K, Ws)
            miss = self._force_miss(Z, widx, b)
            least = miss.min(axis=1, keepdims=True)
            if grid is SLIP_SCAN:  # does the measured force ask for a sideslip at all?
                ask = miss[:, _ZERO_SLIP] > least[:, 0] + SLIP_SIGNIFICANCE * tol[None]  # (m, Ws)
            near = miss <= least + tol[None, None]  # within the noise: the smallest |beta|
            pick = np.argmin(np.where(near, np.abs(b), np.inf), axis=1)  # (m, Ws)
            beta = np.take_along_axis(b, pick[:, None, :], axis=1)[:, 0]
        return beta, ask, least[:, 0], tol, b, near

    def _replay_pick(self, Z: np.ndarray, widx: np.ndarray, beta: np.ndarray, b: np.ndarray,
                     near: np.ndarray) -> np.ndarray:
        """Of the sideslip candidates ``b`` (m, K, Ws) flagged ``near`` (the first sample's force cannot
        tell them apart), the one whose replay of the window from :attr:`x_guess` (``vy = vx tan(b)``)
        fits the window best (weighted residual); ``beta`` (m, Ws) where one candidate or none is
        flagged. One simulated window per flagged candidate."""
        beta = beta.copy()
        v0 = self.win.vx[widx, 0]
        for i in range(Z.shape[0]):
            J = np.flatnonzero(near[i].sum(axis=0) > 1)
            if J.size == 0:
                continue
            K = int(near[i][:, J].sum(axis=0).max())
            order = np.argsort(~near[i][:, J], axis=0, kind="stable")[:K]  # the flagged ones first
            cand = np.take_along_axis(b[i][:, J], order, axis=0)  # (K, |J|)
            ok = np.take_along_axis(near[i][:, J], order, axis=0)
            x = np.repeat(self.x_guess[widx[J]][None], K, axis=0)
            x[..., VY] = v0[J][None] * np.tan(cand)
            cost = window_costs(self.residual(np.repeat(Z[i:i + 1], K, axis=0), widx[J], x))
            k = np.argmin(np.where(ok, cost, np.inf), axis=0)
            beta[i, J] = cand[k, np.arange(J.size)]
        return beta

    def _force_miss(self, Z: np.ndarray, widx: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``|F(dt) - F(0)|`` [N], the change of the total tire force over the first sample, from
        :attr:`x_guess` with ``vy = vx tan(b)``; ``b`` of shape (m, K, Ws), one simulated sample
        per candidate; a diverged one is ``inf``."""
        m, K, Ws = b.shape
        x0 = np.repeat(self.x_guess[widx][None, None], m, axis=0).repeat(K, axis=1)  # (m, K, Ws, NX)
        x0[..., VY] = self.win.vx[widx, 0] * np.tan(b)
        X = self._simulate(np.repeat(Z, K, axis=0), widx, x0.reshape(m * K, Ws, NX), 2)[0]
        F = X[:, :, FYF] + X[:, :, FYR]
        miss = np.abs(F[:, 1] - F[:, 0]).reshape(m, K, Ws)
        return np.where(np.isfinite(miss), miss, np.inf)

    def start(self, Z: np.ndarray, widx: np.ndarray) -> np.ndarray:
        """Start of the initial-state fit of windows ``widx`` for each parameter row of ``Z``, shape
        (m, Ws, NX): :attr:`x_guess` with the lateral velocity, the one state no sensor reads, set
        for each model (the second start of :meth:`fit_from_starts`).

        The tire forces settle on their steady-state value within a relaxation time ``sigma / vx``
        (tens of ms), so at a window's start the model's steady-state lateral force should carry
        the measured one (``M ay``, the guess's total force). ``vy = vx tan(beta)`` with the
        sideslip ``beta`` that makes the total tire force change least over the first sample (one
        simulated sample per candidate): a scan of :data:`SLIP_SCAN`, then :data:`SLIP_FINE` around
        the point it chose. The candidates within the measurement's own resolution of the least
        change (the ay noise times the mass, times the share of a force step that relaxes in one
        sample, ``1 - exp(-dt vx / sigma)``, ``sigma`` the vehicle's relaxation length) are what
        the force can tell; of them, the fine scan's smallest ``|beta|`` (for the gate below), and
        for the start the one whose replay of the whole window fits it best
        (:meth:`_replay_pick`): on a saturated plateau, where the first sample's force cannot
        tell, the window's own channels do (measured: the window of ``constant_radius`` at
        mu_peak 0.6, seed 64, that holds the slide: from the plateau's smallest ``|beta|`` the
        true model's state fit stopped at 948763, 1.6e3 times the noise; from the candidate that
        replays best, 553, its cost from the true state being 537). Where ``vy = 0`` is within :data:`SLIP_SIGNIFICANCE` such noise
        levels of the least change, the measured force does not ask for a sideslip and ``vy``
        stays that of :attr:`x_guess`.

        A row with a saturating tire (``tire_saturation`` active) moves only where the saturation
        itself asks: where, at the sideslip the same row with a linear tire would start from, its
        own force change is more than :data:`SLIP_SIGNIFICANCE` noise levels above its least. Where
        the linear tire asks as much (a model error every hypothesis shares, such as on the real
        rides, or a saturation so weak that the tire is linear), the row keeps ``vy`` of
        :attr:`x_guess`, as the linear rows of :meth:`fit_from_starts` do, so that the second start
        favours no hypothesis.

        Why: near the friction limit the replay is so sensitive to ``vy`` (a 2 s window of a steady
        turn at 28 m/s with ``mu_peak`` 0.8 diverges unless ``vy`` starts within ~0.1 m/s of its
        true -1.03 m/s) that the Gauss-Newton steps from ``vy = 0`` never reach it, and a correct
        saturating tire scored worse than a wrong stiffness.
        """
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        widx = np.asarray(widx)
        xg = self.x_guess[widx]
        beta, ask, least, tol, b, near = self._slip_scan(Z, widx)
        sat = self.saturating(Z)
        if sat.any():
            isat = CAUSES["tire_saturation"][0]
            Zl = Z[sat].copy()
            Zl[:, isat] = self.params.nominal[isat]  # the same rows with a linear tire
            beta_l, ask_l = self._slip_scan(Zl, widx)[:2]
            beta_l = np.where(ask_l, beta_l, 0.0)  # where the linear tire starts from
            miss_l = self._force_miss(Z[sat], widx, beta_l[:, None, :])[:, 0]
            ask[sat] &= miss_l > least[sat] + SLIP_SIGNIFICANCE * tol[None]
        # where the force cannot tell the candidates apart (a saturated plateau), the window's replay does
        beta = self._replay_pick(Z, widx, beta, b, near & ask[:, None, :])
        x = np.repeat(xg[None], Z.shape[0], axis=0)
        x[..., VY] = np.where(ask, self.win.vx[widx, 0] * np.tan(beta), xg[None, :, VY])
        return x

    def fit_from_starts(self, Z: np.ndarray, widx: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray, tuple]:
        """``steps`` Gauss-Newton steps on the initial states of windows ``widx`` for each row of ``Z``
        from :attr:`x_guess` (``vy = 0``) and, for a row with a saturating tire wherever its own
        sideslip start (:meth:`start`: only where the saturation, not a model error a linear tire
        shares, asks for one) differs from ``vy = 0``, from that start too; per (row, window) the
        fit of lower weighted residual is kept (as :meth:`fit_states_from`). Rows with a linear tire
        get the first fit only. Returns the residual (m, Ws, n, C), the states (m, Ws, NX) and the
        pseudo-inverses of :meth:`linearise` at the kept start.

        Not only where the first fit's sideslip stayed away from the start's: a fit from ``vy = 0`` can
        reach the right sideslip with the other states trapped (measured: a held-out window of the
        ``handling`` ride at mu_peak 0.6, seed 61: the true model's fit from ``vy = 0`` ended at vy 0.58
        m/s, 0.005 rad of sideslip from its start's 0.48, at a cost of 2.4e6, 2000 times the noise;
        from the start, 1110)."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        widx = np.asarray(widx)
        x = np.repeat(self.x_guess[widx][None], Z.shape[0], axis=0)
        r0, (P, prior) = self.linearise(Z, widx, x)
        r, x = self.gauss_newton(Z, widx, x, r0, (P, prior), steps)
        # only a tire force nonlinear in the slip (a saturating tire) needs it: for a linear tire the
        # fit is linear in vy (apart from sin phi) and the steps from vy = 0 reach it; and a saturating
        # row only where its saturation asks (start()), so that no hypothesis is favoured elsewhere
        sat = self.saturating(Z)
        if not sat.any():
            return r, x, (P, prior)
        xs = np.repeat(self.x_guess[widx][None], Z.shape[0], axis=0)
        xs[sat] = self.start(Z[sat], widx)
        # a second fit wherever the start asks for a sideslip
        moved = xs[..., VY] != self.x_guess[widx][None, :, VY]
        if moved.any():
            rows, wins = np.flatnonzero(moved.any(axis=1)), np.flatnonzero(moved.any(axis=0))
            blk = np.ix_(rows, wins)
            x1 = xs[blk]
            r1, (P1, prior1) = self.linearise(Z[rows], widx[wins], x1)
            r1, x1 = self.gauss_newton(Z[rows], widx[wins], x1, r1, (P1, prior1), steps)
            better = moved[blk] & (window_costs(r1) < window_costs(r[blk]))
            i, j = np.nonzero(better)
            I, J = rows[i], wins[j]
            r[I, J], x[I, J], P[I, J], prior[I, J] = r1[i, j], x1[i, j], P1[i, j], prior1[i, j]
        return r, x, (P, prior)

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
        step, scale = self.state_step, self.state_scale
        X0 = np.repeat(np.asarray(x0, dtype=float)[None], NX + 1, axis=0)  # (NX + 1, m, Ws, NX)
        for j in range(NX):
            X0[j + 1, :, :, j] += step[j]
        Y = self.outputs(np.tile(Z, (NX + 1, 1)), widx, X0.reshape((NX + 1) * m, Ws, NX)).reshape(NX + 1, m, Ws, -1)
        wt = self.weight[widx].reshape(1, Ws, -1)
        r0 = (self.win.Y[widx].reshape(1, Ws, -1) - Y[0]) * wt
        # a diverged replay (outputs clipped to a huge misfit) tells nothing about the initial state
        diverged = ~_below(Y, _DIVERGED)  # (m, Ws)
        # weighted sensitivity per typical-size correction, laid out (m, Ws, NX, nC) for batched matmul
        Yt = Y.transpose(1, 2, 0, 3)
        J = Yt[:, :, 1:] - Yt[:, :, :1]
        J *= wt[:, :, None, :] * (scale / step)[None, None, :, None]
        if diverged.any():
            J[diverged] = 0.0
        Ainv = np.linalg.inv(J @ J.swapaxes(-1, -2) + DAMPING**2 * np.eye(NX))
        pinv = scale[None, None, :, None] * (Ainv @ J)
        # prior pull towards the measured start state: - lambda^2 D A^-1 D^-1 (x - x_guess)
        prior = DAMPING**2 * scale[:, None] * Ainv / scale[None, :]
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
                    + DAMPING**2 * np.sum(((x - xg) / self.state_scale) ** 2, axis=-1))

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
            Starting states (default: from the measured channels, :meth:`fit_from_starts`).
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
        x = None if x0 is None else np.array(x0, dtype=float)
        rs, xs = [], []
        step = max(1, chunk // Ws)
        for i in range(0, m, step):
            sl = slice(i, i + step)
            if x is None:
                r, xx, _ = self.fit_from_starts(Z[sl], widx, steps)
            else:
                r0, P = self.linearise(Z[sl], widx, x[sl])
                r, xx = self.gauss_newton(Z[sl], widx, x[sl], r0, P, steps)
            rs.append(r)
            xs.append(xx)
        return np.concatenate(rs), np.concatenate(xs)

    def fit_states_from(self, Z: np.ndarray, widx: np.ndarray, x_alt: np.ndarray,
                        steps: int = STATE_STEPS, cross: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`fit_states` from two starts, the better kept per (row, window).

        The initial state is a nuisance parameter and its least-squares problem is not convex: with a
        sharp nonlinearity (Coulomb friction ``tanh(delta_dot / w)``) the Gauss-Newton steps from
        :attr:`x_guess` can stop in a local minimum of one window, which then scores a correct model
        as worse than a wrong one (measured: one held-out window of the urban ride with hidden
        Coulomb friction, 21258 with the true model from ``x_guess``, 1446 from the states a viscous
        model fitted). ``x_alt`` (shape ``(Ws, NX)``, e.g. the states another model fitted) is the
        second start; each window keeps the start with the lower weighted residual. ``cross``: a
        third start per window, the states of the row of ``Z`` that fits that window best (models
        compared on the same windows then differ by their dynamics, not by where their state fits
        stopped).
        """
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        r, x = self.fit_states(Z, widx, steps=steps)
        xa = np.broadcast_to(np.asarray(x_alt, dtype=float), x.shape).copy()
        r, x, _ = keep_better((r, x), self.fit_states(Z, widx, x0=xa, steps=steps))
        if cross and len(Z) > 1:  # a third start per window: the states of the row that fits it best
            x_best = x[np.argmin(window_costs(r), axis=0), np.arange(len(widx))]
            r, x, _ = keep_better((r, x), self.fit_states(Z, widx, x0=np.broadcast_to(x_best, x.shape).copy(),
                                                          steps=steps))
        return r, x


def window_costs(r: np.ndarray) -> np.ndarray:
    """Weighted sum of squares per (row, window) of a residual of shape (m, Ws, n, C)."""
    return np.einsum("mwkc,mwkc->mw", r, r)


def keep_better(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...]) -> tuple:
    """Per (row, window), the fit of lower weighted residual of two initial-state fits ``a`` and ``b``
    (tuples whose first item is the residual (m, Ws, n, C), the rest arrays with the same two leading
    axes: states, pseudo-inverses, ...). Returns ``a``'s items with ``b``'s where ``b`` is better,
    then the mask (m, Ws)."""
    better = window_costs(b[0]) < window_costs(a[0])
    out = tuple(np.where(better.reshape(better.shape + (1,) * (u.ndim - 2)), v, u) for u, v in zip(a, b))
    return out + (better,)


__all__ = ["Replay", "STATE_STEPS", "keep_better", "window_costs"]
