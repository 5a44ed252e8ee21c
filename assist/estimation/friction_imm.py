"""Road friction from the bend of the tire curve: an interacting-multiple-model filter over friction levels.

Why (issue 20): on a wet road a measured tire keeps its small-slip stiffness and loses its peak
(:mod:`ptw_env.friction` ``scaling="peak"``; Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., 2012,
sec. 3.2.2 and 4.3.2). A stiffness estimate linear in the state cannot see that until the tires slide
(README, "Risk warning"). The filter here carries the saturating tire itself: each model ``j`` of the
bank is the plant of :mod:`ptw_env.kernels` (model.md rows 1-8, the one right-hand side) with the steady
force ``F_ss,k = Fmax_k,j tanh(F_lin,k / Fmax_k,j)``, ``Fmax_k,j = mu_j Fz_k`` (effects.md
``tire_saturation``), for a grid of road frictions ``mu_j``. At the same slip the models differ by the
bend of the tanh curve, so the measured lateral acceleration and rates tell them apart as soon as the
tires carry load: at ``|F| = 0.3 Fz`` a drop from 0.9 to 0.45 takes 10 % off the force at that slip
(``0.45 tanh(atanh(1/3) 0.9/0.45) = 0.270`` for 0.3), which the filter reads within a few tenths of a second.

Interacting multiple models (Blom and Bar-Shalom, IEEE TAC 33(8), 1988, sec. III; Bar-Shalom, Li,
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, sec. 11.6.6)
-----------------------------------------------------------------------------------------
Models ``j = 1..J`` (one extended Kalman filter each on the 8 states of model.md), Markov switching
``P(m_k = j | m_{k-1} = i) = Pi_ij``. Per sample ``k``: each filter's measurement update with ``y_k``
(sequential scalar updates, Joseph form; a NaN channel is skipped) and its likelihood
``Lambda_j = prod_r N(e_r; 0, S_r)``; mode probabilities ``p_j <- Lambda_j c_j / sum``; then the mixing
``c_j = sum_i Pi_ij p_i``, ``x0_j = sum_i Pi_ij p_i x_i / c_j``, ``P0_j = sum_i (Pi_ij p_i / c_j) (P_i +
(x_i - x0_j)(x_i - x0_j)^T)`` and each filter's prediction to ``t_{k+1}`` with the torque and speed held
over the sample (RK4 of the mean over the plant's substeps, ``Phi P Phi^T + Q dt`` with ``Phi`` the
product of fourth-order Taylor steps of the central-difference Jacobian, as in
:class:`assist.estimation.identification.JointEKF`).

Switching: a road's friction can change at any moment: with ``p = 1 - exp(-switch_rate dt)``
(``switch_rate`` 0.3 /s by default), ``Pi_ij = p pi_j`` for ``i != j``, where ``pi`` is the stationary
distribution of the chain (detailed balance holds, ``pi_i Pi_ij = pi_j Pi_ji``): model ``i`` is left at the
rate ``switch_rate (1 - pi_i)`` (0.03 /s for the reference road, 0.29 /s for the others) and the
probabilities relax to ``pi`` at the rate ``switch_rate``. ``pi`` gives the reference road ``prior_ref`` (0.9)
and shares the rest evenly: with nothing to read (a straight) the probabilities return to ``pi`` within about
``1 / switch_rate`` s (3 s), so what a corner told is still held at the next one; and the switching moves
``p pi_ref`` of the lower models' probability back to the reference road per sample (0.27 %), so in the steady
state 0.999 on the lower side needs a likelihood ratio of about 3.7 per sample against the reference road, which
a few seconds of a light corner on a wet road can give. A faster switching forgets a model error sooner, and with
it the evidence: at 3 /s it moves 2.7 % per sample and 0.999 needs a ratio of about 28, which a drop under a
loaded tire gives and a steady light corner does not.

Friction grid: ``mu_j = mu_ref r^j``, ``j = 0..5``, ``r = 0.8`` (``grid_ratio``; 0.9 down to 0.29 for the
reference road of :data:`ptw_env.friction.REFERENCE_FRICTION`; no road of the evaluation is on it but the
reference).

The reading (:attr:`FrictionIMM.friction_reading`) has two sides, split at ``lower mu_ref`` (``lower`` = 0.7):
where the models below it hold ``decide`` (0.999) of the probability, or their evidence adds up to its bar
("Evidence", below), the road is *lower*, ``mu = E[mu | mu_j <= lower mu_ref]`` with its standard deviation; where the models above it do, the road is the reference one,
``mu = mu_ref``; otherwise nothing is read (the tires do not tell: a straight, a short light corner). The level
next to the reference (0.72) is on the reference's side: at the grip a dry urban ride uses (56 %) its
evidence against the reference is as large as what the sensors' noise and the filter's model error give (on
the calibration rides below, the lower side of ``lower`` 0.85 held 0.999 at some instant on 5 of 199 rides on
the reference road, 0.95 on 10), so a road above ``lower mu_ref`` (0.63) is not told from the reference.
``lower`` and ``decide`` were chosen on calibration rides (seeds 0-39 of the risk evaluation's ``dry``,
``dry_bank``, ``dry_offsets``, ``wet_corner`` and ``wet_straight``: 199 stretches of reference road, 120 distinct
rides on 40 routes (a wet ride before its patch is its seed's dry ride; a seed's dry, banked and offset rides share
its route), a seed whose route has no corner of the drawn demand
left out of ``wet_corner``; the evaluation uses 1000-1039), by the rule of the script's table 1b (the largest
``lower`` with no reference-road ride at 0.995): with ``lower`` 0.7, no lower reading on the reference road (the
dry rides, the wet ones before their patch) at any ``decide`` from 0.95 to 0.999, and 38 of the 39 patches that
begin in a corner read within 0.3 s at 0.999 (median 0.13 s; 39 at 0.995); ``scripts/eval_friction_filter.py``, stored in
``docs/results/risk/friction_filter/``. A reading follows the road within a few samples: the first one of a
patch can come while the patch's 2 m ramp is still going down and name the level above (tested on seeds 0 and 3
against the true friction at its instant).

Evidence: the switching that lets the probabilities follow a road that changes also hands back ``p pi_ref``
of the lower side per sample, so evidence that comes in small steps never brings them to ``decide``: on wet
straights 1008 and 1027 of the risk evaluation, where light corners on the wet patch told the road 16-19 s before
the loss of grip (the window oracle of the risk evaluation), P(lower) stopped at 0.9965 and 0.9977 and the warning
came 0.1 s ahead. The filter therefore also adds the evidence up, as Page's cumulative sum (CUSUM; E. S. Page,
"Continuous inspection schemes", Biometrika 41, 1954; Basseville and Nikiforov, *Detection of Abrupt Changes*,
1993, sec. 2.2.2): ``g_k = max(0, g_{k-1} + l_k)``, ``l_k = ln(sum_{j low} c_j Lambda_j / sum_{j low} c_j) -
ln(sum_{j ref} c_j Lambda_j / sum_{j ref} c_j)``, the log-ratio of the two sides' likelihoods of the sample (each
side its models' likelihoods weighted by their predicted probabilities ``c_j``), in two banks of the same models:

- the filter's own (:attr:`FrictionIMM.evidence_mixing`), whose mixing starts each unlikely model from the likely
  ones' states every sample, so that each likelihood compares one step from a blend of states; its ``g`` is void
  (0) while its probability reads the reference road;
- an evidence bank (:attr:`FrictionIMM.evidence_own`), the same models switching at :data:`EVIDENCE_SWITCH_RATE`
  (1e-6 /s, as good as never): each friction tracks the sensors on its own, as Page's test compares hypotheses,
  until its probability falls to the switching's floor (about 1e-8 of the likely ones' a sample), where the mixing
  restarts it from their states (the observation oracle of the risk evaluation is this bank with the dry and the
  wet friction only). Its probability is not read; the CUSUM's ``max(0, .)`` restarts its sum on the reference
  road.

Both are void where the models do not explain the sensors (``nis``, below). The evidence,
:attr:`FrictionIMM.evidence` (nats), is the larger of the two sums: where a drop comes under a loaded tire the
own bank gathers more (corner patch 3022 of the risk evaluation's fresh seeds: 13.1 nats within 0.3 s of the drop
in the filter's bank, 28.7 in the evidence bank), on a road between two levels the mixing explains it better
(too-fast seed 1, a damp road of 0.59: 26.5 and 10.6 before the critical curve; both rides looked at afterwards,
the banks' sums not stored; 3022's tested).

The road is read as *lower* where ``g >= h`` too, ``h`` = :data:`EVIDENCE_MARGIN` (2) times the evidence the
probability needs from the stationary prior, ``ln(decide / (1 - decide)) + ln(pi_ref_side / pi_lower_side)``, the
two sides' stationary masses (0.92 and 0.08: the level 0.72 is on the reference's side), 9.35 nats with the
defaults, so ``h`` = 18.7: unlike the probability, the sum does not forget, so it also adds up the model error, and
is given twice the bar. On the calibration rides' 199 reference-road stretches ``g`` reached at most 7.34 nats (0.39
``h``; the filter's own bank 7.31, the evidence bank 7.34); on the 13 real rides not held back 9.70 (run 13-014, the
filter's own bank; the evidence bank 7.88 there and at most 9.67, on 13-019); on the evaluation's wet straights 1008
and 1027 it reached 33 and 168 before the loss of grip (``scripts/eval_friction_filter.py`` table 7, stored; the
margin 2 was chosen after looking at those figures, so the fresh seeds 4000-4039, declared before the evidence's
first evaluation run, are its test; that run had the bar at 18.2, from the reference model's prior 0.9 instead of
its side's 0.92, corrected after it: a higher bar, which reads less, not more). The evidence bank was added after
looking at corner patch 3022 (seeds 3000-3039, where the held observation oracle could warn and the filter did not);
the fresh seeds 5000-5039, declared before its first evaluation run, are its test. What the margin costs, against a
reader of the same sensors that knows the wet road (the risk evaluation's observation oracle,
``assist.risk.evaluation.observation_evidence``: this filter with the dry and the wet friction only, switching as
good as never as the evidence bank does, its CUSUM's threshold set in the simulation at 2 % of dry rides, 7.1-8.4
nats): on the four wet straights of 200 evaluation seeds where it could warn and this filter did not (1006, 4003,
2006, 5022) this filter's evidence reached 5.8-15.3 nats. The oracle's threshold holds where the model is exact; on
the 14 measured robot-bicycle rides (dry floors) its own sum reaches 14.3 nats (run 13-019), and held to them (14.31
nats) it could warn none of those four (3-9 of 25 draws each) and no loss of grip this filter did not warn (README,
"Risk warning"). This filter's own sum reached 6.3-15.6 nats (the largest per run and dry ride type) on the
simulated dry rides of those seeds, 13.1-15.6 on one route (seed 5000: a 0.42 g corner under braking as the ride
ends; the filter's own bank 9.0-12.1 there, looked at afterwards, not stored).

Consistency: the comparison of the models means something only where one of them explains the sensors. The
filter low-passes (``NIS_TAU_S`` = 1 s) the probability-weighted normalised innovation squared per channel read,
:attr:`FrictionIMM.nis` (1 for a consistent filter; 0.88-0.98 median per ride, at most 1.19, on the simulated
calibration rides, whose noise is white), and reads nothing while it is above
:data:`assist.estimation.identification.NIS_EXPLAINED` (3, the joint EKF's rule). On the 14 real robot-bicycle
rides it is 0.08-0.59 (median per ride; the sensors are quieter than the 5 % the filter assumes) except run
04-009 (its 7-8 Hz steer-torque oscillation and brief saturation: 1.53 median, 10.5-16.1 where the lower frictions
took 0.999 of the probability), whose lower reading is therefore not used (same script). On the other 13 the
lower frictions held at most 0.994 (run 13-019; 0.07-0.82 on the rest), below the reading's 0.999 but with less
margin than with the previous defaults (0.966): these are dry floors, and the bicycle is the vehicle the filter
reads worst (the presets below).

History, said because it is how these numbers came: the first evaluation run of this filter (reading any
model but the reference at 0.95) gave false cautions on 2 of 40 banked and 3 of 40 offset dry rides of the
evaluation seeds (``docs/results/risk/first_imm_run/results.md``); the rule above was then chosen on the
calibration seeds.

Speed: the filter predicts the slip from the speed, and a 10 Hz GPS fix held between its refreshes lags the
true speed by up to 0.3 m/s when braking at 3 m/s^2 into a corner, at the entry, where the tires begin to carry
load. Taking that held reading as the speed, the lower frictions took more than 0.9 of the probability on 5 of
the 40 dry calibration rides (0.996 at most; at a braking entry of seed 11, tested); the filter therefore predicts
with the estimate of :class:`assist.estimation.speed.SpeedTracker` (``speed_jerk``; with it, at most 0.72 on the
40 rides; ``scripts/eval_friction_filter.py`` table 6). That lag, not the tire, was most of the "model error" that
had kept the process noise high and the switching fast in the previous version.

Process noise: ``Q`` holds the model error per state. Its shape was set during development by a coordinate search
over factors of the innovations' likelihood on one dry calibration ride of the risk evaluation (urban, seed 0, 5 %
noise, reference scooter; that search is not kept as a script): the steer rate 0.3 rad/s/sqrt(s), the axle forces
0.009 and 0.052 of their static loads per sqrt(s) (:data:`STATE_NOISE`, :data:`FORCE_NOISE`, scaled by the
vehicle's loads). Its level, ``noise_scale`` times that shape, and the switching rate are chosen on the
calibration rides (the same script, table 1a, eight pairs: ``noise_scale`` 1, 0.3, 0.1, 0.03 at ``switch_rate``
3 /s, 0.1 and 0.03 at 1 /s and at 0.3 /s), by a rule written before this sweep was run with the speed tracker
(it was written after a first exploration of an earlier sweep on the same seeds): among the filters whose
lower frictions held 0.995 on no reference-road ride, the most corner patches read within 0.3 s, then the most
wet straights read at least 0.5 s before their loss of grip, then the larger process noise. With the tracked
speed no filter of the sweep took 0.995 on the reference road (largest 0.70-0.92); all but the full shape read
38 of 39 corner patches within 0.3 s; the rule picks :data:`NOISE_SCALE` 0.1 at :data:`SWITCH_RATE` 0.3 /s:
14 of 40 wet straights read early (0.3 at 3 /s, the previous default: 7; 0.03 at 0.3 /s: 14), nis 0.92.

Bank and offsets: every model carries the road bank (prior :data:`BANK_PRIOR`, random walk :data:`BANK_WALK`)
and the yaw-rate gyro's offset as states. The bank changes the plant (row 3's ``g sin(beta)``, ``sin(phi -
beta)``), an offset only the reading, so loaded corners tell them apart. A lateral accelerometer offset ``o``
has no state: on straights and in corners it adds to ``a_y`` as ``g sin(beta)`` does, so it reads as a bank of
about ``o / g`` (0.1 m/s^2 as 0.010 rad).

Cost: two banks of six extended Kalman filters of 10 states per sample, the speed tracker and the evidence, 273 us
per :meth:`FrictionIMM.update` against 12.1 us for one environment step in the same run (22.6x; one bank: 12.2x)
(``scripts/bench_adaptive.py``, README's benchmark table).

Units: states as model.md (rad, rad/s, m/s, N), ``mu`` dimensionless, times in s.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
from numba import njit

from ptw_env.dynamics import compile_plant
from ptw_env.friction import MU_RANGE, REFERENCE_FRICTION
from ptw_env.integrate import substeps_for
from ptw_env.kernels import advance, deriv, fold_vx, scratch
from ptw_env.sensors import ENCODER_QUANTUM, SensorConfig
from ptw_env.vehicle import REFERENCE_SCOOTER, Vehicle

from assist.estimation.identification import NIS_EXPLAINED, OFFSET_PRIOR_NOISE, taylor_transition
from assist.estimation.lpv_model import (OUTPUT_NAMES, STATE_SCALE, bank_column, build_lpv_model, check_bank,
                                        check_real)
from assist.estimation.speed import JERK_INTENSITY, SpeedTracker

#: Process-noise intensities of the first six states (phi, delta, vy, r, phi_dot, delta_dot) [unit/sqrt(s)]
#: (module docstring: their shape by maximum likelihood on a dry ride; the filter scales them by ``noise_scale``).
STATE_NOISE = (1e-3, 1e-4, 3e-3, 1e-3, 1e-2, 0.3)
#: Process-noise intensities of the axle forces, in static axle loads per sqrt(s) (front, rear).
FORCE_NOISE = (0.009, 0.052)
#: Default rate of leaving a model [1/s] (module docstring, "Switching").
SWITCH_RATE = 0.3
#: Default factor on :data:`STATE_NOISE` and :data:`FORCE_NOISE` (module docstring, "Process noise": chosen on the
#: calibration rides by ``scripts/eval_friction_filter.py``).
NOISE_SCALE = 0.1
#: The lower side is read from the evidence (CUSUM) once it is this many times the evidence the probability
#: needs from the stationary prior, ``ln(decide / (1 - decide)) + ln(pi_ref_side / pi_lower_side)`` (module
#: docstring, "Evidence": 2 x 9.35 = 18.7 nats with the defaults).
EVIDENCE_MARGIN = 2.0
#: States of each model: model.md's 8, the road bank [rad] and the yaw-rate gyro offset [rad/s]. A lateral
#: accelerometer offset has no state of its own: it reads as the bank would (module docstring).
N_STATES = 10
#: Prior standard deviation of the road bank [rad] (roads are built with a cross-fall of 0.02-0.04).
BANK_PRIOR = 0.04
#: Random walk of the bank [rad/sqrt(s)] (the road changes along the ride: 0.02 rad in about 15 s).
BANK_WALK = 0.005
#: Sensor offsets the filter carries: the yaw-rate gyro's as a state, the lateral accelerometer's as the road bank
#: it reads the same way (:data:`N_STATES`).
CARRIED_OFFSETS = ("yaw_rate", "ay")
#: Rate of leaving a model in the evidence's own bank [1/s] (module docstring, "Evidence"): as good as none, each
#: friction's filter tracks the sensors on its own, as Page's CUSUM compares hypotheses (a rate of exactly zero would
#: leave a model whose probability underflowed with no mixing weight at all).
EVIDENCE_SWITCH_RATE = 1e-6
#: Time constant of the low-pass of the normalised innovations squared [s] (:attr:`FrictionIMM.nis`).
NIS_TAU_S = 1.0
#: Random walk of an offset, in its prior standard deviation per sqrt(s) (a sensor's offset barely moves).
OFFSET_WALK = 0.001


class FrictionFilterError(ValueError):
    """An option or input the friction filter cannot use."""


@dataclass(frozen=True)
class FrictionReading:
    """What the tires say about the road right now.

    Attributes
    ----------
    mu, std : float
        Friction and its 1-sigma [-] (the posterior over the grid; meaningful when ``informed``).
    informed : bool
        True when one side (the reference road, or a lower friction) holds ``decide`` of the probability.
    p_ref : float
        Probability of the reference road [-].
    status : str
        Why, in words.
    evidence : float or None
        The lower side's evidence against the reference road, the larger of the filter's two banks' Page's CUSUMs
        ``g`` [nats] (:attr:`FrictionIMM.evidence`; module docstring, "Evidence"); None: not given.
    """

    mu: float
    std: float
    informed: bool
    p_ref: float
    status: str
    evidence: float | None = None


@njit(cache=True)
def _imm_update(X, P, prob, y, C, rvar, loglik, nis):
    """Measurement update of each model and the mode probabilities (module docstring); ``nis[j]``: model
    ``j``'s normalised innovations squared, summed over the channels read."""
    J, n = X.shape
    for j in range(J):
        x = X[j].copy()
        Pj = P[j].copy()
        ll = 0.0
        nis[j] = 0.0
        for r in range(y.shape[0]):
            yr = y[r]
            if not np.isfinite(yr):
                continue
            h = C[r]
            e = yr - h @ x
            Ph = Pj @ h
            S = rvar[r] + h @ Ph
            ll += -0.5 * (e * e / S + math.log(2.0 * math.pi * S))
            nis[j] += e * e / S
            Kg = Ph / S
            x = x + Kg * e
            A = np.eye(n) - np.outer(Kg, h)
            Pj = A @ Pj @ A.T + rvar[r] * np.outer(Kg, Kg)
        X[j] = x
        P[j] = 0.5 * (Pj + Pj.T)
        loglik[j] = ll
    mx = loglik.max()
    s = 0.0
    for j in range(J):
        prob[j] = prob[j] * math.exp(loglik[j] - mx)
        s += prob[j]
    if not (s > 0.0 and np.isfinite(s)):
        return False
    for j in range(J):
        prob[j] /= s
    return True


@njit(cache=True, inline="always")
def _f_bank(z, M, c, cb, g, vx, isg, fmx, c2, out):
    """``x'`` of model.md with the road bank ``z[8]`` a state (effects.md ``road_bank``: row 3's
    ``-(M+m) g sin(beta)``, folded into ``c`` by ``cb sin(beta)``, and ``sin(phi - beta)``)."""
    sb = np.sin(z[8])
    for i in range(8):
        c2[i] = c[i] + cb[i] * sb
    deriv(z, M, c2, g, vx, isg, fmx, z[8], out)


@njit(cache=True)
def _imm_predict(X, P, prob, tau, vx, W, dW, cb, isg, FM, dt, nsub, Qc, fd, Pi):
    """Mixing, then each model's prediction over ``dt`` (module docstring); False when a state is not finite.
    States ``[x (8), beta, b_r]``: the bank and the gyro offset are constant (their noise in ``Qc``)."""
    J, n = X.shape
    cbar = np.zeros(J)
    for j in range(J):
        for i in range(J):
            cbar[j] += Pi[i, j] * prob[i]
    X0 = np.zeros((J, n))
    P0 = np.zeros((J, n, n))
    for j in range(J):
        for i in range(J):
            X0[j] += (Pi[i, j] * prob[i] / cbar[j]) * X[i]
        for i in range(J):
            d = X[i] - X0[j]
            P0[j] += (Pi[i, j] * prob[i] / cbar[j]) * (P[i] + np.outer(d, d))
    for j in range(J):
        prob[j] = cbar[j]
    M, c, g, k = scratch()
    c2 = np.empty(8)
    tmp = np.empty(n)
    fp = np.empty(8)
    fm = np.empty(8)
    F = np.zeros((n, n))
    for j in range(J):
        x = X0[j].copy()
        fmx = FM[j]
        fold_vx(W, vx, tau, 0.0, M, c, g)  # the level road's fold; _f_bank adds the bank of the state given
        for jj in range(9):  # the 8 states and the bank (the offset does not enter the dynamics)
            for i in range(n):
                tmp[i] = x[i]
            tmp[jj] = x[jj] + fd[jj]
            _f_bank(tmp, M, c, cb, g, vx, isg, fmx, c2, fp)
            tmp[jj] = x[jj] - fd[jj]
            _f_bank(tmp, M, c, cb, g, vx, isg, fmx, c2, fm)
            for i in range(8):
                F[i, jj] = (fp[i] - fm[i]) / (2.0 * fd[jj])
        Phi = taylor_transition(F, dt / nsub, nsub)
        P[j] = Phi @ P0[j] @ Phi.T + Qc * dt
        Wb = W + dW * np.sin(x[8])  # the model's bank in its plant (effects.md road_bank, linear in sin(beta))
        x8 = x[:8].copy()  # the mean: the simulator's own step (ptw_env.kernels.advance)
        if not advance(x8, tau, vx, 0.0, Wb, isg, fmx, x[8], dt, nsub, M, c, g, k):
            return False
        x[:8] = x8
        for i in range(n):
            if not np.isfinite(x[i]):
                return False
        X[j] = x
    return True


def _logit(p: float) -> float:
    return math.log(p / (1.0 - p))


def _side_log_ratio(loglik: np.ndarray, c: np.ndarray, low: np.ndarray) -> float:
    """``ln`` of the lower side's likelihood over the reference side's for one sample, each side the
    mixture of its models' likelihoods ``Lambda_j`` weighted by their predicted probabilities ``c_j``
    (module docstring, "Evidence"); a :class:`FrictionFilterError` where it is not finite (a side whose predicted
    probabilities all underflowed, a likelihood that vanished)."""
    def side(mask):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            w = c[mask] / c[mask].sum()
            m = float(loglik[mask].max())
            return m + float(np.log(w @ np.exp(loglik[mask] - m)))
    out = side(low) - side(~low)
    if not math.isfinite(out):
        raise FrictionFilterError("the sides' likelihood ratio is not finite: the outputs are far outside the model")
    return out


def friction_grid(mu_ref: float = REFERENCE_FRICTION, ratio: float = 0.8, levels: int = 6) -> np.ndarray:
    """``mu_ref ratio^j``, ``j = 0..levels-1`` (module docstring), kept inside :data:`ptw_env.friction.MU_RANGE`.

    >>> friction_grid().round(3).tolist()
    [0.9, 0.72, 0.576, 0.461, 0.369, 0.295]
    """
    def real(v) -> bool:
        try:
            check_real(v, "")
        except ValueError:
            return False
        return True

    if not (real(mu_ref) and MU_RANGE[0] <= mu_ref <= MU_RANGE[1]) or not (real(ratio) and 0.0 < ratio < 1.0) \
            or not (isinstance(levels, numbers.Integral) and not isinstance(levels, bool) and levels >= 2):
        raise FrictionFilterError(f"friction grid needs mu_ref in {MU_RANGE}, a ratio in (0, 1) and an integer number "
                                  f"of levels >= 2, got {mu_ref!r}, {ratio!r}, {levels!r}")
    g = float(mu_ref) * ratio ** np.arange(int(levels))
    return g[g >= MU_RANGE[0]]


class FrictionIMM:
    """States and road friction by interacting multiple models (module docstring), one sample at a time.

    The interface of :class:`assist.risk.pipeline.StiffnessEstimator` (``update(y, tau, vx)``, ``reset()``,
    ``stiffness``, ``stiffness_std``, ``x_hat``, a settable ``road_bank``), plus :attr:`friction_reading`
    and :attr:`probabilities`.

    Parameters
    ----------
    noise_pct : float
        Sensor noise the filter assumes, percent of the vehicle's channel ranges (default 5).
    dt : float
        Sample period [s] (default 0.01).
    vehicle : Vehicle, optional
        Default: the reference scooter.
    mu_ref : float
        Friction of the road the vehicle's tires refer to (default 0.9).
    grid : sequence of float, optional
        The frictions of the models, the first the reference road (default :func:`friction_grid`).
    switch_rate : float
        Rate of leaving a model [1/s] (default :data:`SWITCH_RATE`, 0.3).
    noise_scale : float
        Factor on the process-noise intensities of the plant's states, :data:`STATE_NOISE` and :data:`FORCE_NOISE`
        (default :data:`NOISE_SCALE`).
    prior_ref : float
        Stationary probability of the reference road (default 0.9).
    decide : float
        Probability one side must hold for a reading (default 0.999).
    lower : float
        Frictions at or below ``lower mu_ref`` are the *lower* side of the reading (default 0.7).
    speed_jerk : float or None
        The speed given to :meth:`update` is a reading refreshed at a lower rate and held (a GPS): the filter
        predicts with :class:`assist.estimation.speed.SpeedTracker`'s estimate, of this jerk intensity
        [m^2/s^5] (default :data:`assist.estimation.speed.JERK_INTENSITY`), its fix period the sensor model's
        GPS period (``ptw_env.sensors.SensorConfig.gps_rate_hz``, 10 Hz). None: the speed is taken as given
        (a speed exact at every sample).
    evidence : float or None
        The evidence [nats] that reads the lower side when its probability does not (module docstring,
        "Evidence"; :attr:`evidence_needed`). Default: :data:`EVIDENCE_MARGIN` times the evidence the probability
        needs from the stationary prior, ``ln(decide / (1 - decide)) + ln(pi_ref_side / pi_lower_side)`` (18.7
        with the defaults); it must come out positive.

    Examples
    --------
    >>> imm = FrictionIMM()
    >>> imm.update([0.0, 0.0, 0.0, 0.0, 0.0], 0.0, 15.0)   # riding straight: nothing to read
    >>> r = imm.friction_reading
    >>> r.informed, round(r.p_ref, 2)
    (False, 0.9)
    """

    def __init__(self, noise_pct: float = 5.0, dt: float = 0.01, vehicle: Vehicle | None = None,
                 mu_ref: float = REFERENCE_FRICTION, grid=None, switch_rate: float = SWITCH_RATE, prior_ref: float = 0.9,
                 decide: float = 0.999, lower: float = 0.7, noise_scale: float = NOISE_SCALE,
                 speed_jerk: float | None = JERK_INTENSITY, evidence: float | None = None) -> None:
        for name, v in (("noise_pct", noise_pct), ("dt", dt), ("mu_ref", mu_ref), ("switch_rate", switch_rate),
                        ("noise_scale", noise_scale)) + ((("speed_jerk", speed_jerk),) if speed_jerk is not None else ()):
            check_real(v, f"FrictionIMM {name}", FrictionFilterError, positive=True)
        if dt > 0.1:  # the EKF linearises over one sample; the other designs take (0, 0.1] s too
            raise FrictionFilterError(f"FrictionIMM dt must lie in (0, 0.1] s, got {dt!r}")
        for name, v, lo in (("prior_ref", prior_ref, 0.0), ("decide", decide, 0.5), ("lower", lower, 0.0)):
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not (lo < v < 1.0):
                raise FrictionFilterError(f"FrictionIMM {name} must be a number in ({lo:g}, 1), got {v!r}")
        if evidence is not None:
            check_real(evidence, "FrictionIMM evidence [nats]", FrictionFilterError, positive=True)
        if vehicle is not None and not isinstance(vehicle, Vehicle):
            raise FrictionFilterError(f"vehicle must be a Vehicle (ptw_env.vehicle_files.load_vehicle), got "
                                      f"{type(vehicle).__name__}")
        self.vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
        self.model = build_lpv_model(self.vehicle)
        self.mu_ref = float(mu_ref)
        try:
            g = friction_grid(self.mu_ref) if grid is None else np.asarray(grid, dtype=float).ravel()
        except (TypeError, ValueError):
            raise FrictionFilterError(f"grid must be a sequence of frictions, got {grid!r}") from None
        if (g.size < 2 or not np.all(np.isfinite(g)) or np.any(g < MU_RANGE[0]) or np.any(g > MU_RANGE[1])
                or g[0] != self.mu_ref or np.any(np.diff(g) >= 0)):
            raise FrictionFilterError(f"grid must hold at least two decreasing frictions in {MU_RANGE}, the first "
                                      f"mu_ref {self.mu_ref}, got {g.tolist()}")
        self.grid = g
        gaps = -np.diff(g)
        self._band = np.r_[gaps[0], 0.5 * (gaps[:-1] + gaps[1:]), gaps[-1]] / math.sqrt(12.0)
        self.dt = float(dt)
        self.nsub = substeps_for(self.dt)
        self.FM = np.array([compile_plant(self.vehicle, {"tire_saturation": {"mu_peak": float(m)}}).flat()[2][0]
                            for m in g])
        self.isg = compile_plant(self.vehicle).flat()[1][0]
        self.W, self.dW = bank_column(self.vehicle)
        self.cb = np.empty(8)  # its constant part per unit sin(beta)
        fold_vx(self.dW, 1.0, 0.0, 0.0, np.empty((8, 8)), self.cb, np.empty((8, 2)))
        sens = SensorConfig.from_percent(float(noise_pct), vehicle=self.vehicle)
        self.speed = None if speed_jerk is None else SpeedTracker(  # the sensor model's GPS noise and period
            self.dt, sens.noise_std["vx"], float(speed_jerk), fix_period=1.0 / sens.gps_rate_hz)
        rvar = np.array([sens.noise_std[c] ** 2 for c in OUTPUT_NAMES])
        rvar[0] += (sens.delta_quantum or ENCODER_QUANTUM) ** 2 / 12.0
        self.rvar = np.maximum(rvar, 1e-10)
        C = np.zeros((len(OUTPUT_NAMES), N_STATES))
        C[:, :8] = self.model.C
        C[OUTPUT_NAMES.index("yaw_rate"), 9] = 1.0  # y_r = r + b_r: the offset's row
        self.C = C
        off0 = OFFSET_PRIOR_NOISE * math.sqrt(self.rvar[OUTPUT_NAMES.index("yaw_rate")])
        fz = np.array([self.vehicle.tires.Fzf, self.vehicle.tires.Fzr])
        self.noise_scale = float(noise_scale)
        self._q = np.r_[self.noise_scale * np.r_[STATE_NOISE, np.asarray(FORCE_NOISE) * fz], BANK_WALK, off0 * OFFSET_WALK]
        self._p0 = np.r_[STATE_SCALE * 0.1, BANK_PRIOR, off0]
        self.fd = np.r_[STATE_SCALE * 1e-4, 1e-5, 1e-5]
        J = g.size
        self.pi = np.r_[prior_ref, np.full(J - 1, (1.0 - prior_ref) / (J - 1))]
        p = -math.expm1(-float(switch_rate) * self.dt)
        if not p > 0.0:
            raise FrictionFilterError(f"FrictionIMM switch_rate {switch_rate!r} /s is too small to switch in a sample "
                                      f"of {dt!r} s")
        self.Pi = self._transitions(p)
        self.Pi_evidence = self._transitions(-math.expm1(-EVIDENCE_SWITCH_RATE * self.dt))
        #: the filter's own bank is the evidence bank (it switches at EVIDENCE_SWITCH_RATE): one bank is run
        self._one_bank = bool(np.array_equal(self.Pi, self.Pi_evidence))
        self.decide = float(decide)
        self.lower = float(lower)
        self.low = self.grid <= float(lower) * self.mu_ref  # the lower side of the reading
        #: the evidence [nats] that reads the lower side when its probability does not (module docstring)
        if not self.low.any():
            raise FrictionFilterError(f"no friction of the grid {g.tolist()} is at or below lower x mu_ref = "
                                      f"{lower * self.mu_ref:g}")
        prior_odds = float(self.pi[~self.low].sum() / self.pi[self.low].sum())
        self.evidence_needed = (EVIDENCE_MARGIN * (_logit(self.decide) + math.log(prior_odds)) if evidence is None
                                else float(evidence))
        if not self.evidence_needed > 0.0:
            raise FrictionFilterError(f"the evidence the lower side needs, {EVIDENCE_MARGIN:g} x (ln(decide / (1 - "
                                      f"decide)) + ln({prior_odds:.3g})), is not positive with prior_ref {prior_ref!r} "
                                      f"and decide {decide!r}: a larger prior_ref or decide, or an evidence option")
        self.stiffness = self.model.theta0.copy()
        self.stiffness_std = np.full(4, math.nan)
        self._known_bank: float | None = None
        self.reset()

    def _transitions(self, p: float) -> np.ndarray:
        """``Pi_ij = p pi_j`` for ``i != j``, the rest on the diagonal (module docstring, "Switching")."""
        J = self.pi.size
        Pi = p * np.tile(self.pi, (J, 1))
        Pi[np.diag_indices(J)] = 0.0
        Pi[np.diag_indices(J)] = 1.0 - Pi.sum(axis=1)
        return Pi

    @property
    def estimates_bank(self) -> bool:
        """True while the bank is a state of the filter (no known bank was set)."""
        return self._known_bank is None

    @property
    def road_bank(self) -> float:
        """The road's bank [rad]: the known one, else the filter's estimate (effects.md ``road_bank``).
        Setting it makes the bank known (fixed in every model); ``None`` estimates it again."""
        return float(self._known_bank) if self._known_bank is not None else self._bank_hat

    @road_bank.setter
    def road_bank(self, value) -> None:
        if value is None:  # estimated again, from its prior (a level road, BANK_PRIOR)
            if self._known_bank is not None:
                self._known_bank = None
                self._bank_hat = 0.0
                for X, P in ((self._X, self._P), (self._Xe, self._Pe)):
                    X[:, 8] = 0.0
                    P[:, 8, :] = 0.0
                    P[:, :, 8] = 0.0
                    P[:, 8, 8] = BANK_PRIOR**2
            return
        b = check_bank(value, FrictionFilterError)
        self._known_bank = b
        self._bank_hat = b
        for X, P in ((self._X, self._P), (self._Xe, self._Pe)):
            X[:, 8] = b
            P[:, 8, :] = 0.0
            P[:, :, 8] = 0.0

    @property
    def yaw_rate_offset(self) -> float:
        """The estimated offset of the yaw-rate gyro [rad/s] (after the last update)."""
        return self._offset_hat

    def reset(self) -> None:
        """Zero states and offsets, the known bank (else zero), the stationary probabilities."""
        J = self.grid.size
        self._X = np.zeros((J, N_STATES))
        self._P = np.tile(np.diag(self._p0**2), (J, 1, 1))
        # the evidence's own bank (module docstring, "Evidence"): the same models, switching at EVIDENCE_SWITCH_RATE
        self._Xe, self._Pe, self._probe = self._X.copy(), self._P.copy(), self.pi.copy()
        self._lle = np.zeros(J)
        self._nise = np.zeros(J)
        self._bank_hat, self._offset_hat = 0.0, 0.0
        self._vx: float | None = None
        if self.speed is not None:
            self.speed.reset()
        if self._known_bank is not None:
            self.road_bank = self._known_bank
        self._prob = self.pi.copy()  # the predicted mode probabilities (the mixing's c_j)
        #: the mode probabilities after the last update (order of :attr:`grid`)
        self.probabilities = self.pi.copy()
        self._ll = np.zeros(J)
        self._nis = np.zeros(J)
        #: each model's log-likelihood ``ln Lambda_j`` of the last sample's outputs (order of :attr:`grid`; zeros
        #: before the first update) [nats]
        self.log_likelihoods = np.zeros(J)
        #: the lower side's evidence against the reference road, in nats: the larger of the two banks' CUSUMs
        #: (module docstring, "Evidence"), read as lower at :attr:`evidence_needed`
        self.evidence = 0.0
        #: the CUSUM of the filter's own bank (its models mix at ``switch_rate``) [nats]
        self.evidence_mixing = 0.0
        #: the CUSUM of the evidence bank (its models track the sensors on their own, :data:`EVIDENCE_SWITCH_RATE`)
        #: [nats]
        self.evidence_own = 0.0
        #: normalised innovation squared per channel, probability-weighted, low-passed over ``NIS_TAU_S`` (1 when
        #: the models explain the sensors)
        self.nis = 1.0
        self.x_hat = np.zeros(8)

    def update(self, y, tau: float, vx: float) -> None:
        """Take the outputs ``y`` at this sample (``[delta, yaw_rate, roll_rate, delta_rate, ay]``, NaN: a
        dropout), then predict to the next one with the torque ``tau`` [N m] and speed ``vx`` [m/s] held. With
        ``speed_jerk`` (the default) ``vx`` is the speed reading and the speed is its tracked estimate (a missing
        reading, NaN, is predicted, and held after :data:`assist.estimation.speed.HOLD_AFTER_S`); without, a
        missing speed holds the last one. On an error the filter is left as it was before the call."""
        try:
            yv = np.asarray(y, dtype=float).ravel()
        except (TypeError, ValueError):
            raise FrictionFilterError(f"y must hold {len(OUTPUT_NAMES)} numbers {OUTPUT_NAMES}, got {y!r}") from None
        if yv.shape != (len(OUTPUT_NAMES),):
            raise FrictionFilterError(f"y must hold {len(OUTPUT_NAMES)} outputs {OUTPUT_NAMES}, got {yv.shape}")
        tau = check_real(tau, "tau [N m]", FrictionFilterError)
        v = check_real(vx, "vx [m/s]", FrictionFilterError, missing_ok=True)
        tracked = None
        if self.speed is not None:
            tracked = self.speed.peek(v)
            v = tracked[0]
        if not math.isfinite(v):
            if self._vx is None:
                raise FrictionFilterError(f"vx is missing ({vx!r}) and no earlier speed is known")
            v = self._vx
        X, P, prob = self._X.copy(), self._P.copy(), self._prob.copy()  # committed only when every step succeeds
        Xe, Pe, probe = self._Xe.copy(), self._Pe.copy(), self._probe.copy()
        c, ce = prob.copy(), probe.copy()  # each bank's predicted mode probabilities of this sample
        if not (_imm_update(X, P, prob, yv, self.C, self.rvar, self._ll, self._nis)
                and (self._one_bank or _imm_update(Xe, Pe, probe, yv, self.C, self.rvar, self._lle, self._nise))):
            raise FrictionFilterError("every model's likelihood vanished: the outputs are far outside the model")
        step = _side_log_ratio(self._ll, c, self.low)
        step_own = step if self._one_bank else _side_log_ratio(self._lle, ce, self.low)
        post = prob.copy()
        post_X = X.copy()
        q = self._q.copy()
        if self._known_bank is not None:
            q[8] = 0.0
        vc = min(max(v, self.vehicle.vmin), self.vehicle.vmax)
        Q = np.diag(q**2)
        banks = ((X, P, prob, self.Pi),) + (() if self._one_bank else ((Xe, Pe, probe, self.Pi_evidence),))
        for Xb, Pb, pb, Pi in banks:
            if not _imm_predict(Xb, Pb, pb, tau, vc, self.W, self.dW, self.cb, self.isg, self.FM, self.dt, self.nsub,
                                Q, self.fd, Pi):
                raise FrictionFilterError("the friction filter diverged (a state is not finite)")
        self._X, self._P, self._prob, self._vx = X, P, prob, v
        self._Xe, self._Pe, self._probe = Xe, Pe, probe
        if tracked is not None:
            self.speed.commit(tracked)
        self.probabilities = post
        self.log_likelihoods = self._ll.copy()
        self.x_hat = post @ post_X[:, :8]
        self._bank_hat = float(post @ post_X[:, 8]) if self._known_bank is None else self._known_bank
        self._offset_hat = float(post @ post_X[:, 9])
        n_read = int(np.isfinite(yv).sum())
        if n_read:  # the model's consistency: NIS per channel read, probability-weighted, low-passed
            a = 1.0 - math.exp(-self.dt / NIS_TAU_S)
            self.nis += a * (float(post @ self._nis) / n_read - self.nis)
        # the evidence adds up (Page's CUSUM), in each bank; void where the models do not explain the sensors, the
        # mixing bank's also where its probability reads the reference road
        unexplained = self.nis > NIS_EXPLAINED
        void = unexplained or 1.0 - float(post[self.low].sum()) >= self.decide
        self.evidence_mixing = 0.0 if void else max(0.0, self.evidence_mixing + step)
        self.evidence_own = 0.0 if unexplained else max(0.0, self.evidence_own + step_own)
        self.evidence = max(self.evidence_mixing, self.evidence_own)

    @property
    def friction_reading(self) -> FrictionReading:
        """The reading after the last :meth:`update` (module docstring). Its ``std`` is the spread of the
        posterior over the side read, each level standing for a uniform band around it as wide as the mean of
        its gaps to its neighbours (std ``width / sqrt(12)``), so a level that takes all the probability still
        says the grid's resolution."""
        p = self.probabilities
        p_ref = float(p[0])
        low = float(p[self.low].sum())

        def side(mask):
            q = p[mask] / p[mask].sum()
            mu = self.grid[mask]
            m = float(q @ mu)
            return m, float(math.sqrt(max(q @ (mu**2 + self._band[mask] ** 2) - m * m, 0.0)))

        def reading(m: float, s: float, informed: bool, status: str) -> FrictionReading:
            return FrictionReading(m, s, informed, p_ref, status, self.evidence)

        if self.nis > NIS_EXPLAINED:  # the models do not explain the sensors: their comparison says nothing
            return reading(*side(np.ones_like(self.low)), False, f"not read: the model does not explain the sensors "
                           f"(normalised innovation squared {self.nis:.1f} per channel, above {NIS_EXPLAINED:g})")
        if 1.0 - low >= self.decide:  # the std about mu_ref: the levels of this side are not told from it
            q, mu = p[~self.low] / (1.0 - low), self.grid[~self.low]
            s = float(math.sqrt(q @ ((mu - self.mu_ref) ** 2 + self._band[~self.low] ** 2)))
            return reading(self.mu_ref, s, True, f"the tires read the reference road (friction above "
                           f"{self.lower * self.mu_ref:.2f}: {1.0 - low:.3f})")
        if low >= self.decide:
            return reading(*side(self.low), True, f"the tires read a lower friction ({low:.3f})")
        if self.evidence >= self.evidence_needed:
            return reading(*side(self.low), True, f"the tires read a lower friction (evidence {self.evidence:.1f} "
                           f"nats, P(lower) {low:.3f})")
        return reading(*side(np.ones_like(self.low)), False, f"not read: the tires do not tell the road (P(lower) "
                       f"{low:.3f})")


__all__ = ["CARRIED_OFFSETS", "EVIDENCE_MARGIN", "EVIDENCE_SWITCH_RATE", "FORCE_NOISE", "NOISE_SCALE", "STATE_NOISE", "SWITCH_RATE", "FrictionFilterError", "FrictionIMM", "FrictionReading", "friction_grid"]
