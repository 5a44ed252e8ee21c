"""Cramér-Rao bounds of the tire stiffnesses (assist.estimation.identifiability) against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from assist.estimation.identifiability import IdentifiabilityError, output_noise_std, ride_information, stiffness_information
from assist.estimation.lpv_model import STATE_SCALE, build_lpv_model
from ptw_env import simulate
from ptw_env.dynamics import compile_plant

M = build_lpv_model()
K = 300
T = np.arange(K) * 0.01
TAU = 8 * np.sin(2 * np.pi * 0.5 * T) + 4 * np.sin(2 * np.pi * 1.3 * T)
VX = np.full(K, 15.0)


def test_vehicle_with_theta_is_the_tire_stiffness_effect():
    """The perturbed vehicle of the bound is exactly effects.md's tire_stiffness plant."""
    v = M.vehicle_with(M.theta_of_scales(0.6, 1.3))
    ref = compile_plant(effects={"tire_stiffness": {"front_scale": 0.6, "rear_scale": 1.3}})
    x = np.random.default_rng(1).normal(size=(20, 8)) * STATE_SCALE
    np.testing.assert_allclose(compile_plant(v).rhs(x, 2.0, 17.0), ref.rhs(x, 2.0, 17.0), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(build_lpv_model(v).theta0, M.theta0 * [0.6, 0.6, 1.3, 1.3])


def test_bound_matches_monte_carlo_of_the_maximum_likelihood_fit():
    """The bound is what an efficient estimator reaches: the spread of output-error ML fits
    (scipy least_squares on the simulator, Gaussian noise, 25 realisations) equals the bound
    to within the sampling error of a 25-sample standard deviation (+-14 % at 1 sigma)."""
    sig = output_noise_std(5.0)
    info = stiffness_information(np.zeros(8), TAU, VX, noise_std=sig)
    crb = np.sqrt(np.diag(info.crb("axle")))
    G = np.array([[1.0, 0], [1, 0], [0, 1], [0, 1]])
    y_true = simulate(np.zeros(8), TAU, VX)[1:] @ M.C.T

    def y_of(p):
        return simulate(p[:8] * STATE_SCALE, TAU, VX, vehicle=M.vehicle_with((G @ p[8:] - 1) * M.theta0))[1:] @ M.C.T

    rng = np.random.default_rng(7)
    est = []
    for _ in range(25):
        y = y_true + rng.normal(size=y_true.shape) * sig
        fit = least_squares(lambda p: ((y_of(p) - y) / sig).ravel(), np.r_[np.zeros(8), 1.0, 1.0],
                            x_scale=np.full(10, 0.01), diff_step=1e-6)
        est.append(fit.x[8:])
    sd = np.std(est, axis=0, ddof=1)
    assert np.all(np.abs(np.mean(est, axis=0) - 1) < 3 * crb / np.sqrt(25) + 1e-3)
    assert np.all(sd / crb > 0.7) and np.all(sd / crb < 1.4), (sd, crb)


def test_coarser_parametrisations_are_better_determined():
    info = stiffness_information(np.zeros(8), TAU, VX)
    four, axle, mu = (info.crb_relative_std(p) for p in ("stiffness", "axle", "friction"))
    assert axle["front_scale"] < min(four["C_alpha_f"], four["C_gamma_f"])
    assert axle["rear_scale"] < min(four["C_alpha_r"], four["C_gamma_r"])
    assert mu["mu_scale"] <= min(axle.values()) * 1.0001
    # the camber stiffnesses are the poorly determined ones (their force is small next to the slip force)
    assert four["C_gamma_r"] > four["C_alpha_r"] and four["C_gamma_f"] > four["C_alpha_f"]


def test_bound_scales_with_noise_and_time():
    """Information is linear in 1/sigma^2 (bound ~ sigma) and grows with the record."""
    a = stiffness_information(np.zeros(8), TAU, VX, noise_pct=5.0).crb_relative_std("axle")
    b = stiffness_information(np.zeros(8), TAU, VX, noise_std=2 * output_noise_std(5.0)).crb_relative_std("axle")
    for k in a:
        assert b[k] / a[k] == pytest.approx(2.0, rel=1e-6)
    half = stiffness_information(np.zeros(8), TAU[:150], VX[:150]).crb_relative_std("axle")
    assert all(half[k] > a[k] for k in a)


def test_ride_window_and_bad_input():
    X = simulate(np.zeros(8), TAU, VX)
    info = ride_information(X[:-1], TAU, VX, 1.0, 2.5)
    assert (info.t0, info.t1, info.samples) == (1.0, 2.5, 150)
    with pytest.raises(IdentifiabilityError, match="leaves the ride"):
        ride_information(X[:-1], TAU, VX, 2.0, 9.0)
    with pytest.raises(IdentifiabilityError, match="parametrisation"):
        info.crb("wheel")
    with pytest.raises(IdentifiabilityError, match="scales"):
        stiffness_information(np.zeros(8), TAU, VX, scales=(1, 1, -1, 1))
    with pytest.raises(IdentifiabilityError, match="x0"):
        stiffness_information(np.zeros(7), TAU, VX)
