"""Available road friction ``mu_hat`` from a tire-stiffness estimate, with an honest uncertainty.

Mapping (effects.md: "Road friction (mu) scales both [stiffnesses] equally")
-------------------------------------------------------------------------
The nominal stiffnesses ``C_0`` of model.md are those of the reference road,
dry asphalt of friction ``mu_ref`` = :data:`ptw_env.friction.REFERENCE_FRICTION`
= 0.9 (the simulator's :class:`~ptw_env.friction.FrictionSchedule` scales the
stiffness and ``mu_peak`` by ``mu / mu_ref`` with the same constant, so the
tanh tire curve as a whole scales with ``mu``). With the four stiffness
ratios ``r_j = C_hat_j / C_0j`` and their standard deviations ``s_j =
std(C_hat_j) / C_0j`` (1 sigma, from the estimator):

.. math::

    \\hat r = \\frac{\\sum_j w_j r_j}{\\sum_j w_j},\\quad w_j = s_j^{-2},\\qquad
    \\sigma_r^2 = \\frac{1}{\\sum_j w_j} + \\frac{\\sum_j w_j (r_j - \\hat r)^2}{\\sum_j w_j},\\qquad
    \\hat\\mu_{raw} = \\mu_{ref}\\,\\hat r,\\ \\sigma_{raw} = \\mu_{ref}\\,\\sigma_r.

The second term of ``sigma_r^2`` is the disagreement between the four
ratios, which a pure friction change would make equal: it carries the
estimator's bias into the uncertainty instead of hiding it.

Excitation (not enough: say so, do not guess)
---------------------------------------------
Stiffness is only observable while the tires carry lateral force -- from the
rider's steering torque on a straight (the steer and roll response to a known
torque depends on the front tire: the stiffness estimator of
:mod:`assist.risk.pipeline` reads a friction drop there within seconds, on roads that scale the whole tire
curve) or,
far more, in a turn. An estimator whose reported standard deviation follows
its information (the sensitivity law's ``Gamma`` grows by the random walk
when nothing excites the tires, and shrinks when something does) needs no
other gate: the estimate is used while ``sigma_r <= max_informed_std``
(0.25) and the status says how little lateral acceleration it rests on. For
an estimator whose std does not tell (it drifts unexcited), a lateral gate
can be added: ``excitation_min`` (0 by default; 1.0 m/s^2, about 0.1 g, for
such an estimator). The excitation is ``E = max(|LP(a_y)|, |LP(g F_f / Fz_f)|, |LP(g F_r / Fz_r)|)``:
the measured lateral acceleration and, when the estimator gives them, the
estimated axle forces over the static axle loads (the front force of a
counter-steer comes before the net ``a_y``), each through a first-order
low-pass of time constant ``excitation_tau_s`` (0.3 s; it takes the
sensor noise, 0.25 m/s^2 at 5 %, down to ~0.05 m/s^2). The raw estimate is
*used* only while ``E >= excitation_min`` and ``sigma_r <= max_informed_std``;
then ``mu_hat = mu_raw``, ``sigma = sigma_raw``. Otherwise the status says
"not enough ... excitation", ``mu_hat`` keeps the last informed value (the prior
``prior_mu`` = 0.9 +- ``prior_std`` before any) and its uncertainty grows as a
random walk, ``sigma^2 = sigma_last^2 + q^2 (t - t_last)`` (road friction can
change while nothing is measured; ``q`` = ``walk`` = 0.02 /sqrt(s), the
adaptive observer's own stiffness random walk times ``mu_ref``).

A stiffness estimate also falls when the tires approach saturation (the
linear model sees the secant of the tanh curve, ``tanh(a)/a``: -11 % at 56 %
of the grip): ``mu_hat`` is then low, which errs on the safe side.

Which tire (``FrictionConfig.tire``)
------------------------------------
The mapping above (``tire="stiffness"``) holds on roads that scale the whole tire curve
(:mod:`ptw_env.friction` ``scaling="stiffness_and_peak"``). Measured tires on a wet road keep their
small-slip stiffness and lose peak force (``scaling="peak"``, the simulator's default): there a
stiffness estimate does not tell the friction at small slip at all, only the *curvature* of the
tire curve does. ``tire="peak"`` (the default) reads it: the estimated stiffness ratio ``theta =
r_hat`` is taken as the secant ``F / F_lin`` of the tanh curve, ``theta = w / atanh(w)`` with the
utilisation ``w = |F| / Fmax``, so

.. math::

    w = g^{-1}(\\theta),\\ g(w) = \\frac{w}{\\operatorname{atanh} w},\\qquad
    \\hat\\mu_{raw} = \\frac{\\ell}{w},\\quad \\ell = \\frac{|F_f| + |F_r|}{F_{zf} + F_{zr}}

(``ell``: the estimated lateral force over the static load, ``|a_y| / g`` without force estimates).
Its spread comes from ``theta +- s_theta`` with ``s_theta^2 = sigma_r^2 + model_std^2``:
``model_std`` (0.3) is the error
of the linear stiffness estimate away from saturation that is not noise (the observer's model is
linear in the lean and the speed; sensor offsets add to it): measured with the stiffness estimator on
the reference scooter's evaluation rides of calibration seeds 0-7 (the evaluation uses seeds
1000-1039), while the tires used 10-70 % of their grip ``theta`` went down to 0.76 on clean sensors
(``dry``, ``dry_bank``; its median 0.94-0.98, the tanh secant 0.81-1.0) and to 0.63 with the yaw-gyro
bias of 0.01 rad/s and accelerometer offset of 0.1 m/s^2 of ``dry_offsets``; at 95 % and more of
the grip (``wet_corner``, ``wet_straight``, ``too_fast``) its median was 0.29. With 0.3 a reading is used only below ``theta`` ~0.54 (at any load:
the relative spread of ``ell / w`` does not depend on it), under both. The estimate is used when ``sigma_raw <=
max_informed_std mu_raw`` (relative: a small load over a curve that only looks bent gives a small
``mu_raw`` with a small absolute, but a large relative, spread) and ``mu_raw`` is a road's friction
(:data:`ptw_env.friction.MU_RANGE`, from 0.05), and not in the first ``settle_s`` (1 s) after a
reset: the observer starts from a zero state while the vehicle already rides (on a bank, leaning),
and its reading falls to 0.2-0.6 for the first 0.1 s of a ride. So it is *informed* only where the curve is bent far beyond
that, within reach of the grip (a secant of 0.54 is 94 % of it): a wet road is seen when the tires
near their limit, not before. A tire-reading warning on such tires cannot see a wet patch at small
slip; README, "Risk warning", measures what that costs.

An estimator's own reading
--------------------------
An estimator that reads the friction itself (:class:`assist.estimation.friction_imm.FrictionIMM`, the risk
warning's default for peak-scaling tires: models of the saturating tire over a grid of frictions) gives
``reading`` to :meth:`FrictionEstimate.update`: its ``mu`` and ``std`` replace the mapping above and it is
used where it says ``informed`` (after ``settle_s``); between readings the same hold and random walk apply.

Examples
--------
>>> import numpy as np
>>> fe = FrictionEstimate(FrictionConfig(tire="stiffness"))      # a road that scales the whole curve
>>> c0 = np.array([22486.0, 1063.8, 20178.0, 644.36])
>>> st = fe.update(0.0, 0.9 * c0, 0.8 * c0, ay=0.0)         # nothing known yet: the prior
>>> st.informed, st.mu_hat, st.status
(False, 0.9, 'not enough excitation: the stiffness estimate is too uncertain (+-0.36 in mu)')
>>> st = fe.update(0.01, 0.5 * c0, 0.05 * c0, ay=0.0)       # straight, but the steering response told
>>> st.informed, round(st.mu_hat, 3), st.status
(True, 0.45, 'informed by the steering response (little lateral acceleration, |a_y| 0.00 m/s^2)')
>>> for k in range(100):
...     st = fe.update(0.02 + 0.01 * k, 0.5 * c0, 0.05 * c0, ay=3.0)  # cornering
>>> st.informed, round(st.mu_hat, 3), round(st.mu_std, 4), st.status
(True, 0.45, 0.0225, 'informed (|a_y| 2.89 m/s^2)')
>>> fe = FrictionEstimate()                                  # tire="peak": the bend of the curve tells
>>> st = fe.update(0.0, 0.95 * c0, 0.02 * c0, ay=2.0)       # 5 % below the slope: could be model error
>>> st.informed, st.mu_hat
(False, 0.9)
>>> st = fe.update(1.5, 0.4 * c0, 0.02 * c0, ay=4.4)        # 40 % of the slope at 0.45 g, after the start-up
>>> st.informed, round(st.mu_hat, 2)                        # w = 0.975 of the grip: 0.449 / 0.975
(True, 0.46)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ptw_env.friction import MU_RANGE, REFERENCE_FRICTION
from ptw_env.vehicle import G, REFERENCE_SCOOTER, Vehicle


def nominal_stiffness(vehicle: Vehicle) -> np.ndarray:
    """The vehicle's nominal stiffnesses ``C_0`` [N/rad] (its tire parameters), order C_alpha_f, C_gamma_f,
    C_alpha_r, C_gamma_r: what ``mu_ref`` friction gives."""
    tp = vehicle.tires
    return np.array([tp.C_alpha_f0, tp.C_gamma_f0, tp.C_alpha_r0, tp.C_gamma_r0])


#: The reference scooter's nominal stiffnesses ``C_0`` [N/rad] (model.md, derived tire parameters).
NOMINAL_STIFFNESS = nominal_stiffness(REFERENCE_SCOOTER)


#: What road friction changes in the tires (:class:`FrictionConfig` ``tire``).
TIRES = ("peak", "stiffness")
def utilisation_of_secant(theta: float) -> float:
    """``w`` with ``w / atanh(w) = theta`` (module docstring): 0 for ``theta >= 1`` (a linear tire), ->1 as
    ``theta`` -> 0.

    >>> round(utilisation_of_secant(0.9837), 3), round(utilisation_of_secant(0.5), 3), utilisation_of_secant(1.2)
    (0.22, 0.958, 0.0)
    """
    th = float(theta)
    if not th < 1.0:
        return 0.0
    hi = 1.0 - 1e-15
    if th <= hi / math.atanh(hi):  # beyond any slip the tanh curve reaches in double precision
        return hi
    return float(brentq(lambda w: w / math.atanh(w) - th, 1e-12, hi, xtol=1e-13))


def peak_friction(theta: float, theta_std: float, load: float) -> tuple[float, float]:
    """``(mu_raw, sigma_raw)`` on a peak-scaling tire (module docstring): ``load / w(theta)`` and half the
    spread of ``load / w`` over ``theta +- theta_std`` (``inf`` where the tire looks linear).

    >>> mu, s = peak_friction(0.5, 0.05, 0.43)
    >>> round(mu, 3), round(s, 3)
    (0.449, 0.009)
    >>> peak_friction(0.98, 0.1, 0.2)
    (inf, inf)
    """
    w = utilisation_of_secant(theta)
    w_lo, w_hi = utilisation_of_secant(theta + theta_std), utilisation_of_secant(theta - theta_std)
    if w <= 0.0 or w_lo <= 0.0 or load <= 0.0:
        return math.inf, math.inf
    return load / w, 0.5 * (load / w_lo - load / w_hi)


#: Lateral acceleration [m/s^2] above which a turn, not only the steering response, informs the estimate
#: (about 0.1 g, a fifth of normal-pace cornering); below it the status says so.
LATERAL_EXCITATION = 1.0


class FrictionEstimateError(ValueError):
    """A stiffness, standard deviation or option the friction estimate cannot use."""


@dataclass(frozen=True)
class FrictionConfig:
    """Options of :class:`FrictionEstimate` (module docstring for the equations).

    Attributes
    ----------
    mu_ref : float
        Friction of the road the nominal stiffness refers to (default 0.9, dry asphalt).
    prior_mu, prior_std : float
        Friction assumed before the first informed estimate, and its 1-sigma (default 0.9 +- 0.2).
    excitation_min : float
        Lateral excitation ``E`` (module docstring) above which the estimate is used [m/s^2] (default 0:
        the estimator's own std decides; 1.0 for an estimator that drifts unexcited).
    excitation_tau_s : float
        Time constant of the excitation low-pass [s] (default 0.3).
    max_informed_std : float
        An estimate whose relative 1-sigma ``sigma_r`` is above this [-] is not used (default 0.25).
    walk : float
        Random-walk intensity of the friction while uninformed [1/sqrt(s)] (default 0.02).
    fallback_std : float
        Relative stiffness std used when the estimator reports none (NaN) [-] (default 0.15).
    tire : {"peak", "stiffness"}
        What the road friction changes in the tires (module docstring): the peak only (default; the
        friction is read from the bend of the tire curve) or stiffness and peak (the stiffness tells it).
    model_std : float
        ``tire="peak"``: relative error of the stiffness estimate that is not noise [-] (default 0.3).
    settle_s : float
        ``tire="peak"``: no reading in the first ``settle_s`` after :meth:`FrictionEstimate.reset` [s]
        (default 1.0; module docstring).
    """

    mu_ref: float = REFERENCE_FRICTION
    prior_mu: float = REFERENCE_FRICTION
    prior_std: float = 0.2
    excitation_min: float = 0.0
    excitation_tau_s: float = 0.3
    max_informed_std: float = 0.25
    walk: float = 0.02
    fallback_std: float = 0.15
    tire: str = "peak"
    model_std: float = 0.3
    settle_s: float = 1.0

    def __post_init__(self) -> None:
        if self.tire not in TIRES:
            raise FrictionEstimateError(f"FrictionConfig.tire must be one of {', '.join(TIRES)}, got {self.tire!r}")
        for name in ("mu_ref", "prior_mu", "prior_std", "excitation_tau_s", "max_informed_std", "fallback_std"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise FrictionEstimateError(f"FrictionConfig.{name} must be a positive number, got {v!r}")
        for name in ("excitation_min", "walk", "model_std", "settle_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise FrictionEstimateError(f"FrictionConfig.{name} must be a number >= 0, got {v!r}")


@dataclass(frozen=True)
class FrictionState:
    """The friction estimate after one sample.

    Attributes
    ----------
    t : float
        Time [s].
    mu_hat, mu_std : float
        Available friction and its 1-sigma [-].
    mu_raw, raw_std : float
        What the stiffness estimate says right now (used or not) [-].
    informed : bool
        True when this sample's stiffness estimate was used.
    excitation : float
        ``|LP(a_y)|`` [m/s^2].
    since_informed_s : float
        Time since the last informed sample [s] (``inf`` before any).
    status : str
        Why the estimate is (not) used, for the warning's reason.
    """

    t: float
    mu_hat: float
    mu_std: float
    mu_raw: float
    raw_std: float
    informed: bool
    excitation: float
    since_informed_s: float
    status: str


def stiffness_to_friction(stiffness, stiffness_std, mu_ref: float = REFERENCE_FRICTION,
                          nominal=NOMINAL_STIFFNESS, fallback_std: float = 0.15) -> tuple[float, float]:
    """``(mu_raw, sigma_raw)`` from a stiffness estimate [N/rad] and its 1-sigma [N/rad] (module docstring).

    Examples
    --------
    >>> c0 = NOMINAL_STIFFNESS
    >>> mu, s = stiffness_to_friction(0.5 * c0, 0.1 * c0)
    >>> round(mu, 3), round(s, 4)
    (0.45, 0.045)
    """
    c = np.asarray(stiffness, dtype=float)
    sd = np.asarray(stiffness_std, dtype=float)
    c0 = np.asarray(nominal, dtype=float)
    if c.shape != c0.shape or sd.shape != c0.shape:
        raise FrictionEstimateError(f"stiffness and stiffness_std must hold {c0.size} values "
                                    f"(C_alpha_f, C_gamma_f, C_alpha_r, C_gamma_r), got shapes {c.shape}, {sd.shape}")
    if not np.all(np.isfinite(c)) or np.any(c <= 0):
        raise FrictionEstimateError(f"stiffness must be positive and finite [N/rad], got {c.tolist()}")
    r = c / c0
    s = np.where(np.isfinite(sd) & (sd > 0), sd / c0, fallback_std)
    w = 1.0 / s**2
    W = float(w.sum())
    rhat = float((w * r).sum() / W)
    var = 1.0 / W + float((w * (r - rhat) ** 2).sum() / W)
    return mu_ref * rhat, mu_ref * math.sqrt(var)


class FrictionEstimate:
    """Available friction from a stream of stiffness estimates, gated by lateral excitation.

    Parameters
    ----------
    config : FrictionConfig, optional
    vehicle : Vehicle, optional
        Whose nominal stiffnesses the estimates are divided by (:func:`nominal_stiffness`; default the
        reference scooter).

    Notes
    -----
    Feed :meth:`update` once per sample; :meth:`reset` starts again from the prior.
    """

    def __init__(self, config: FrictionConfig | None = None, vehicle: Vehicle | None = None) -> None:
        self.config = FrictionConfig() if config is None else config
        if not isinstance(self.config, FrictionConfig):
            raise FrictionEstimateError(f"config must be a FrictionConfig, got {type(config).__name__}")
        v = REFERENCE_SCOOTER if vehicle is None else vehicle
        self.nominal = nominal_stiffness(v)
        #: static axle loads [N] (the load share of ``tire="peak"``)
        self.fz = np.array([v.tires.Fzf, v.tires.Fzr])
        self.reset()

    def reset(self) -> None:
        """Back to the prior, no excitation history."""
        c = self.config
        self._mu = c.prior_mu
        self._var_last = c.prior_std**2
        self._t_last: float | None = None
        self._ay_f = np.zeros(3)
        self._t_prev: float | None = None
        self._t0: float | None = None
        self.state: FrictionState | None = None

    def update(self, t: float, stiffness, stiffness_std, ay: float, axle_accel=None, reading=None) -> FrictionState:
        """Take one sample: time [s], stiffness estimate and its 1-sigma [N/rad], measured ``a_y`` [m/s^2]
        (NaN: a dropout, the excitation filter holds) and optionally the axle forces over the axle
        loads, ``g F_k / Fz_k`` [m/s^2] (the excitation is then the largest of the three, filtered).

        ``reading``: an estimator's own friction reading (an object with ``mu``, ``std``, ``informed`` and
        ``status``, as :class:`assist.estimation.friction_imm.FrictionReading`): it replaces the stiffness
        mapping; it is used where it says ``informed``, after the first ``settle_s`` (the filter's start-up)."""
        c = self.config
        t = float(t)
        if not math.isfinite(t):
            raise FrictionEstimateError(f"t must be a finite time in seconds, got {t!r}")
        if self._t_prev is not None and t < self._t_prev:
            raise FrictionEstimateError(f"time went backwards: {t} s after {self._t_prev} s")
        dt = 0.0 if self._t_prev is None else t - self._t_prev
        self._t_prev = t
        sig = np.array([float(ay), math.nan, math.nan])
        if axle_accel is not None:
            sig[1:] = np.asarray(axle_accel, dtype=float).ravel()[:2]
        a = 1.0 if self.state is None else 1.0 - math.exp(-dt / c.excitation_tau_s)
        ok = np.isfinite(sig)
        self._ay_f[ok] += a * (sig[ok] - self._ay_f[ok])
        exc = float(np.max(np.abs(self._ay_f)))
        if reading is not None:  # the estimator reads the friction itself
            if self._t0 is None:
                self._t0 = t
            mu_raw, raw_std = float(reading.mu), float(reading.std)
            settling = t - self._t0 < c.settle_s
            use = bool(reading.informed) and not settling and MU_RANGE[0] <= mu_raw <= MU_RANGE[1]
            if use:
                self._mu, self._var_last, self._t_last = mu_raw, raw_std**2, t
                informed, since, std = True, 0.0, raw_std
            else:
                informed = False
                since = math.inf if self._t_last is None else t - self._t_last
                std = math.sqrt(self._var_last + (0.0 if self._t_last is None else c.walk**2 * since))
            status = (f"estimator starting up (the first {c.settle_s:g} s are not read)" if settling else
                      str(reading.status))
            self.state = FrictionState(t=t, mu_hat=float(self._mu), mu_std=float(std), mu_raw=mu_raw,
                                       raw_std=raw_std, informed=informed, excitation=float(exc),
                                       since_informed_s=float(since), status=status)
            return self.state
        mu_raw, raw_std = stiffness_to_friction(stiffness, stiffness_std, c.mu_ref, self.nominal, c.fallback_std)
        if c.tire == "peak":  # the bend of the tire curve, not its slope, tells the friction
            theta, s_theta = mu_raw / c.mu_ref, math.hypot(raw_std / c.mu_ref, c.model_std)
            if axle_accel is not None and np.all(np.isfinite(sig[1:])):
                load = float(np.abs(sig[1:]) @ self.fz / self.fz.sum() / G)
            else:
                load = abs(float(ay)) / G if math.isfinite(float(ay)) else 0.0
            mu_raw, raw_std = peak_friction(theta, s_theta, load)
            mu_raw = min(mu_raw, MU_RANGE[1])  # the largest friction a road may have
        # informed: sigma within max_informed_std of mu_ref (stiffness), of the estimate itself (peak: a small
        # load over a wrongly bent curve gives a small mu with a small absolute, but a large relative, spread)
        limit = c.max_informed_std * (mu_raw if c.tire == "peak" else c.mu_ref)
        if c.tire == "peak":
            if self._t0 is None:
                self._t0 = t
            # below any road's friction, or the estimator's start-up: not a reading of the road
            if mu_raw < MU_RANGE[0] or t - self._t0 < c.settle_s:
                limit = -1.0
        if exc >= c.excitation_min and raw_std <= limit:
            self._mu, self._var_last, self._t_last = mu_raw, raw_std**2, t
            informed, since, std = True, 0.0, raw_std
            status = (f"informed (|a_y| {exc:.2f} m/s^2)" if exc >= LATERAL_EXCITATION else
                      f"informed by the steering response (little lateral acceleration, |a_y| {exc:.2f} m/s^2)")
        else:
            informed = False
            if self._t_last is None:  # the prior, until the first informed sample
                since, std = math.inf, math.sqrt(self._var_last)
            else:
                since = t - self._t_last
                std = math.sqrt(self._var_last + c.walk**2 * since)
            if exc < c.excitation_min:
                status = f"not enough lateral excitation (|a_y| {exc:.2f} m/s^2 < {c.excitation_min:.2f})"
            elif c.tire == "peak" and self._t0 is not None and t - self._t0 < c.settle_s:
                status = f"estimator starting up (the first {c.settle_s:g} s are not read)"
            elif c.tire == "peak":
                status = ("not read: the tires are not near their limit (the stiffness estimate is within its "
                          "model-error band)" if not math.isfinite(raw_std) else
                          f"not read: the tire curve's bend is uncertain (+-{raw_std:.2f} in mu)")
            else:
                status = f"not enough excitation: the stiffness estimate is too uncertain (+-{raw_std:.2f} in mu)"
        self.state = FrictionState(t=t, mu_hat=float(self._mu), mu_std=float(std), mu_raw=float(mu_raw),
                                   raw_std=float(raw_std), informed=informed, excitation=float(exc),
                                   since_informed_s=float(since), status=status)
        return self.state


__all__ = [
    "FrictionConfig",
    "FrictionEstimate",
    "FrictionEstimateError",
    "FrictionState",
    "NOMINAL_STIFFNESS",
    "TIRES",
    "peak_friction",
    "utilisation_of_secant",
    "nominal_stiffness",
    "stiffness_to_friction",
]
