"""How much a ride can tell about the tires: Fisher information and Cramér-Rao bounds of the stiffnesses.

For the outputs ``y_k = C x(t_k; x_0, s) + v_k`` of the nonlinear plant of
:mod:`assist.estimation.lpv_model` (``y = [delta, r, phi_dot, delta_dot, ay]``, the
adaptive observer's sensors), white Gaussian noise ``v_k ~ N(0, R)``, the known
inputs ``tau`` and ``vx`` of the ride, and the unknowns ``p = [x_0, s]`` (the
state at the start of the window, a nuisance, and the stiffness scales
``s_j = C_j / C_0j``), the Fisher information is

.. math::

    F = \\sum_k S_k^T R^{-1} S_k, \\qquad S_k = \\frac{\\partial y_k}{\\partial p},

and every unbiased estimator of ``s`` from the same samples has covariance at
least ``(F^{-1})_{ss}`` (the Cramér-Rao bound; Kay, *Fundamentals of Statistical
Signal Processing: Estimation Theory*, eq. 3.24, with the nuisance handled by
the Schur complement of the ``x_0`` block). ``S_k`` is computed at the true
trajectory by central differences through the batched simulator
(:func:`ptw_env.simulate`, the one plant of the project; the stiffness
perturbations use :meth:`assist.estimation.lpv_model.LPVModel.vehicle_with`).

There is no process noise in this model (the rider's torque is known
exactly), so the bound is the most optimistic one: a real estimator, which
must also allow for model error, does worse. The bound therefore answers
questions like the adaptive-observer issue's target ("every stiffness within
5 % of truth after 15 s"): if the bound's standard deviation of a stiffness
over those 15 s exceeds ~2.5 %, no unbiased estimator can meet the target
reliably (a 2-sigma interval wider than +-5 %).

Parametrisations (:data:`PARAMETRISATIONS`): ``"stiffness"`` the four scales
of [1]_ (``C_alpha_f, C_gamma_f, C_alpha_r, C_gamma_r``); ``"axle"`` one scale
per axle (effects.md ``tire_stiffness``: ``front_scale, rear_scale``);
``"friction"`` one scale for all four (road friction, [1]_ sec. II-C:
``Theta = mu Theta_0``).

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers" (``shared/papers/000_348caefc9b08ee38.txt``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ptw_env.integrate import simulate
from ptw_env.sensors import ENCODER_QUANTUM, SensorConfig

from assist.estimation.lpv_model import OUTPUT_NAMES, STATE_SCALE, THETA_NAMES, LPVModel, build_lpv_model

#: Maps from each parametrisation's scales to the four stiffness scales (columns: its parameters).
PARAMETRISATIONS: dict[str, tuple[tuple[str, ...], np.ndarray]] = {
    "stiffness": (THETA_NAMES, np.eye(4)),
    "axle": (("front_scale", "rear_scale"), np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]])),
    "friction": (("mu_scale",), np.ones((4, 1))),
}


class IdentifiabilityError(ValueError):
    """Inputs the Fisher-information computation cannot take (shapes, window, noise)."""


def output_noise_std(noise_pct: float, quantised_delta: bool = True) -> np.ndarray:
    """Per-sample noise std of ``[delta, yaw_rate, roll_rate, delta_rate, ay]`` at ``noise_pct`` % of range
    (:meth:`ptw_env.sensors.SensorConfig.from_percent`), plus the 10-bit encoder's ``q^2/12`` on delta."""
    cfg = SensorConfig.from_percent(noise_pct)
    s = np.array([cfg.noise_std[c] for c in OUTPUT_NAMES])
    if quantised_delta:
        s[0] = math.sqrt(s[0] ** 2 + ENCODER_QUANTUM**2 / 12.0)
    return s


@dataclass(frozen=True)
class StiffnessInformation:
    """Fisher information of ``[x_0 (8), s (4)]`` over one window of a ride (module docstring).

    Attributes
    ----------
    fisher : ndarray (12, 12)
        In the units ``x_0`` physical (rad, m/s, rad/s, N) and ``s`` dimensionless.
    t0, t1 : float
        The window [s].
    samples : int
    noise_std : ndarray (5,)
    scales : ndarray (4,)
        The true scales ``C/C_0`` the sensitivities were taken at.
    """

    fisher: np.ndarray
    t0: float
    t1: float
    samples: int
    noise_std: np.ndarray
    scales: np.ndarray

    def crb(self, parametrisation: str = "stiffness") -> np.ndarray:
        """Cramér-Rao covariance of the parametrisation's scales (``x_0`` a nuisance)."""
        if parametrisation not in PARAMETRISATIONS:
            raise IdentifiabilityError(f"parametrisation must be one of {sorted(PARAMETRISATIONS)}, "
                                       f"got {parametrisation!r}")
        _, G = PARAMETRISATIONS[parametrisation]
        T = np.zeros((12, 8 + G.shape[1]))
        T[:8, :8] = np.eye(8)
        T[8:, 8:] = G
        Fp = T.T @ self.fisher @ T
        # scale before inverting: the x_0 block spans ten decades of units
        d = np.sqrt(np.maximum(np.diag(Fp), 1e-300))
        cov = np.linalg.pinv(Fp / np.outer(d, d), rcond=1e-13) / np.outer(d, d)
        return cov[8:, 8:]

    def crb_relative_std(self, parametrisation: str = "stiffness") -> dict[str, float]:
        """Cramér-Rao standard deviation of each scale, relative to its true value (0.05 = 5 %)."""
        names, G = PARAMETRISATIONS[parametrisation] if parametrisation in PARAMETRISATIONS else ((), None)
        cov = self.crb(parametrisation)
        if parametrisation == "stiffness":
            truth = self.scales
        else:  # the scales of the coarser parametrisation, at the truth's mean per group
            truth = np.linalg.lstsq(G, self.scales, rcond=None)[0]
        return {n: float(math.sqrt(max(cov[j, j], 0.0)) / truth[j]) for j, n in enumerate(names)}


def stiffness_information(x0, tau, vx, *, scales=(1.0, 1.0, 1.0, 1.0), noise_std=None, noise_pct: float = 5.0,
                          dt: float = 0.01, model: LPVModel | None = None, rel_step: float = 1e-4
                          ) -> StiffnessInformation:
    """Fisher information of the initial state and the four stiffness scales over one window.

    Parameters
    ----------
    x0 : array_like (8,)
        True state at the start of the window.
    tau, vx : array_like (K,)
        Rider torque [N m] and true speed [m/s] held over each of the ``K`` periods.
    scales : 4 floats
        True ``C/C_0`` of ``C_alpha_f, C_gamma_f, C_alpha_r, C_gamma_r``.
    noise_std : array_like (5,), optional
        Per-sample noise std of ``[delta, yaw_rate, roll_rate, delta_rate, ay]``;
        default :func:`output_noise_std` at ``noise_pct``.
    dt : float
        Sample period [s].
    model : LPVModel, optional
    rel_step : float
        Central-difference step, relative to :data:`assist.estimation.lpv_model.STATE_SCALE` for the
        states and absolute for the scales.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(300) * 0.01
    >>> info = stiffness_information(np.zeros(8), 8 * np.sin(2 * np.pi * 0.5 * t), np.full(300, 15.0))
    >>> {k: round(100 * v, 1) for k, v in info.crb_relative_std("axle").items()}  # 1-sigma, % (5 % noise)
    {'front_scale': 5.6, 'rear_scale': 3.9}
    """
    m = build_lpv_model() if model is None else model
    x0 = np.asarray(x0, dtype=float)
    tau = np.asarray(tau, dtype=float)
    vx = np.asarray(vx, dtype=float)
    if x0.shape != (8,) or not np.all(np.isfinite(x0)):
        raise IdentifiabilityError(f"x0 must hold 8 finite numbers, got shape {x0.shape}")
    if tau.ndim != 1 or vx.shape != tau.shape or len(tau) < 10:
        raise IdentifiabilityError(f"tau and vx must be 1-D of the same length >= 10, got {tau.shape}, {vx.shape}")
    sc = np.asarray(scales, dtype=float)
    if sc.shape != (4,) or np.any(~np.isfinite(sc)) or np.any(sc <= 0):
        raise IdentifiabilityError(f"scales must be 4 positive numbers, got {scales!r}")
    sig = output_noise_std(noise_pct) if noise_std is None else np.asarray(noise_std, dtype=float)
    if sig.shape != (5,) or np.any(~(sig > 0)):
        raise IdentifiabilityError(f"noise_std must hold 5 positive numbers, got {noise_std!r}")
    if not 0 < rel_step < 0.1:
        raise IdentifiabilityError(f"rel_step must lie in (0, 0.1), got {rel_step!r}")

    def outputs(xs: np.ndarray) -> np.ndarray:  # (..., K+1, 8) -> samples 1..K of y, (..., K, 5)
        return xs[..., 1:, :] @ m.C.T

    truth_theta = (sc - 1.0) * m.theta0
    veh = m.vehicle_with(truth_theta)
    K = len(tau)
    S = np.zeros((K, 5, 12))
    # initial state: one batched call, +- steps
    h = rel_step * STATE_SCALE
    X0 = np.concatenate([x0 + np.diag(h), x0 - np.diag(h)])
    Y = outputs(simulate(X0, np.broadcast_to(tau, (16, K)), np.broadcast_to(vx, (16, K)), dt=dt, vehicle=veh))
    S[:, :, :8] = np.moveaxis((Y[:8] - Y[8:]) / (2 * h)[:, None, None], 0, -1)
    for j in range(4):
        d = np.zeros(4)
        d[j] = rel_step * m.theta0[j]
        yp = outputs(simulate(x0, tau, vx, dt=dt, vehicle=m.vehicle_with(truth_theta + d)))
        ym = outputs(simulate(x0, tau, vx, dt=dt, vehicle=m.vehicle_with(truth_theta - d)))
        S[:, :, 8 + j] = (yp - ym) / (2 * rel_step)
    W = S / sig[None, :, None]
    F = np.einsum("kri,krj->ij", W, W)
    return StiffnessInformation(fisher=0.5 * (F + F.T), t0=0.0, t1=K * dt, samples=K, noise_std=sig, scales=sc)


def ride_information(states, tau, vx, t0: float, t1: float, *, scales=(1.0, 1.0, 1.0, 1.0), dt: float = 0.01,
                     **kwargs) -> StiffnessInformation:
    """:func:`stiffness_information` over ``[t0, t1)`` of a ride sampled at ``dt``: ``states`` (K, 8) the true
    states, ``tau`` and ``vx`` (K,) the torque and true speed held over each sample."""
    states = np.asarray(states, dtype=float)
    n = len(states)
    k0, k1 = int(round(t0 / dt)), int(round(t1 / dt))
    if not (0 <= k0 < k1 <= n):
        raise IdentifiabilityError(f"window [{t0}, {t1}] s leaves the ride (0 to {n * dt:.2f} s)")
    info = stiffness_information(states[k0], np.asarray(tau)[k0:k1], np.asarray(vx)[k0:k1], scales=scales, dt=dt,
                                 **kwargs)
    return StiffnessInformation(fisher=info.fisher, t0=k0 * dt, t1=k1 * dt, samples=info.samples,
                                noise_std=info.noise_std, scales=info.scales)


__all__ = [
    "IdentifiabilityError",
    "PARAMETRISATIONS",
    "StiffnessInformation",
    "output_noise_std",
    "ride_information",
    "stiffness_information",
]
