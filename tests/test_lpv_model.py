"""The LPV form of the reference scooter (assist.estimation.lpv_model): regressor, virtual sensor, polytope, observability."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from assist.estimation.lpv_model import (
    LPVModelError,
    build_lpv_model,
    nonlinearity_vertices,
    observability_table,
    theta_band,
)
from ptw_env.dynamics import compile_plant
from ptw_env.vehicle import DELTA, FYF, FYR, PHI, REFERENCE_SCOOTER as V

M = build_lpv_model()
RNG_SCALE = np.array([0.3, 0.03, 0.5, 0.3, 0.5, 0.3, 800.0, 800.0])


def _states(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, 8)) * RNG_SCALE


def test_chi_times_nominal_stiffness_is_the_printed_tire_rows():
    """chi(x, vx) C_0 - (vx/sigma) F reproduces rows 7-8 of E^-1 A(vx) x exactly (model.md's printed entries)."""
    X = _states(50, 0)
    for vx in (3.0, 11.0, 27.5, 40.0):
        printed = X @ V.state_matrix(vx).T
        rows = M.parameter_term(X, vx, M.theta0)
        rows[:, FYF] += V.A(vx)[FYF, FYF] * X[:, FYF]  # the relaxation term -vx F / sigma
        rows[:, FYR] += V.A(vx)[FYR, FYR] * X[:, FYR]
        np.testing.assert_allclose(rows[:, [FYF, FYR]], printed[:, [FYF, FYR]], rtol=1e-12, atol=1e-6)


@pytest.mark.parametrize("front, rear", [(0.6, 0.6), (0.5, 1.5), (1.5, 0.8)])
def test_tire_stiffness_effect_is_exactly_the_parameter_term(front, rear):
    """effects.md's tire_stiffness (printed rows scaled) = D chi Theta with Theta = (s - 1) C_0: no 0.4 % caveat."""
    X = _states(40, 1)
    vx = np.linspace(4.0, 39.0, 40)
    plant = compile_plant(effects={"tire_stiffness": {"front_scale": front, "rear_scale": rear}})
    d = plant.rhs(X, 0.0, vx) - compile_plant().rhs(X, 0.0, vx)
    np.testing.assert_allclose(d, M.parameter_term(X, vx, M.theta_of_scales(front, rear)), rtol=1e-10, atol=1e-6)


def test_kappa_is_the_printed_over_formula_ratio_of_a72():
    tp = V.tires
    formula = (tp.C_alpha_f0 * math.cos(tp.caster) + tp.C_gamma_f0 * math.sin(tp.caster)) / tp.sigma_f
    assert M.kappa == pytest.approx(V.A1[FYF, DELTA] / formula, rel=1e-12)
    assert M.kappa == pytest.approx(104503 / 104145, rel=2e-4)  # model.md's two numbers


def test_D_is_the_tire_rows_and_the_virtual_row_is_table_V():
    np.testing.assert_array_equal(M.D[:6], 0.0)
    np.testing.assert_allclose(M.D[6:], np.eye(2), atol=1e-15)
    e34, e33 = V.E[2, 3], V.E[2, 2]
    lf, lr = V.A0[3, FYF], -V.A0[3, FYR]
    np.testing.assert_allclose(M.c_virtual[[FYF, FYR]], [e34 - e33 * lf, e34 + e33 * lr], rtol=1e-12)
    assert np.count_nonzero(M.c_virtual) == 2


def test_virtual_sensor_from_derivatives_equals_its_force_combination():
    """y_a = m . d/dt[r, phi_dot, delta_dot] + n(vx) . [...] = c67 Fyf + c68 Fyr along the nonlinear plant."""
    plant = compile_plant()
    X = _states(30, 2)
    for vx in (5.0, 17.0, 33.0):
        xdot = plant.rhs(X, 7.0, vx)  # torque and sines must cancel out of the combination
        m, n = M.virtual_sensor_coefficients(vx)
        ya = xdot[:, [3, 4, 5]] @ m + X[:, [3, 4, 5]] @ n
        np.testing.assert_allclose(ya, X @ M.c_virtual, rtol=1e-9, atol=1e-6 * np.abs(X @ M.c_virtual).max())


def test_polytope_is_exact_and_weights_are_convex():
    for vx in np.linspace(M.vmin, M.vmax, 9):
        w = M.weights(vx)
        assert w.sum() == pytest.approx(1.0) and np.all(w >= 0)
        np.testing.assert_allclose(np.einsum("i,ijk->jk", w, M.vertices), V.state_matrix(vx), rtol=1e-11, atol=1e-9)
    np.testing.assert_array_equal(M.weights([1.0, 100.0]), [[1.0, 0.0], [0.0, 1.0]])  # clipped


def test_observability_before_and_after_the_virtual_sensor():
    """Every speed 3-40 m/s: (A, C) observable with and without y_a; rank(C D) goes 1 -> 2 (what D^T P = T C needs)."""
    rows = observability_table()
    assert [r.vx for r in rows] == list(np.arange(3.0, 40.5, 1.0))
    assert all(r.rank == 8 and r.rank_virtual == 8 for r in rows)
    assert all(r.rank_CD == 1 and r.rank_CD_virtual == 2 for r in rows)
    assert all(r.pbh > 1e-4 for r in rows)
    # independent check of the PBH test at one speed: no eigenvector of A is in the kernel of C
    A = V.state_matrix(20.0)
    lam, vecs = np.linalg.eig(A)
    assert min(np.linalg.norm(M.C @ v) / np.linalg.norm(v) for v in vecs.T) > 1e-6


def test_nonlinearity_vertices_bound_the_real_increments():
    """Lambda(x) - Lambda(x_hat) = N J x~ with J in the hull: the increment lies in range(N) and its size is
    within the largest vertex gain (Lambda from the plant itself, not from the vertex formula)."""
    lo, hi = theta_band(M, 0.5, 1.5)
    J = nonlinearity_vertices(M, lo, hi)
    assert J.shape == (2**7, 4, 8)
    gmax = max(np.linalg.norm(M.N @ Jv, 2) for Jv in J)
    rng = np.random.default_rng(3)
    for k in range(40):
        s = rng.uniform(0.5, 1.5, 2)
        plant = compile_plant(effects={"tire_stiffness": {"front_scale": s[0], "rear_scale": s[1]}})
        vx = rng.uniform(M.vmin, M.vmax)
        x, xh = _states(2, 10 + k)
        x[PHI], xh[PHI] = rng.uniform(-0.7, 0.7, 2)
        x[DELTA], xh[DELTA] = rng.uniform(-0.3, 0.3, 2)
        lam = (plant.rhs(x, 0.0, vx) - plant.rhs(xh, 0.0, vx)) - M.A(vx) @ (x - xh)
        w, *_ = np.linalg.lstsq(M.N, lam, rcond=None)
        np.testing.assert_allclose(M.N @ w, lam, atol=1e-8 * max(1.0, np.abs(lam).max()))
        assert np.linalg.norm(lam) <= gmax * np.linalg.norm(x - xh) * (1 + 1e-9)


@pytest.mark.parametrize("kw", [{"vmin": 10.0, "vmax": 5.0}, {"vmin": 1.0}, {"vmax": 45.0}])
def test_bad_speed_range_is_rejected(kw):
    with pytest.raises(LPVModelError, match="speed range"):
        build_lpv_model(**kw)


def test_bad_inputs_are_rejected():
    with pytest.raises(LPVModelError, match="trailing axis of length 8"):
        M.chi(np.zeros(7), 10.0)
    with pytest.raises(LPVModelError, match="band"):
        theta_band(M, 1.2, 1.5)
    with pytest.raises(LPVModelError, match="speeds"):
        observability_table(speeds=[10.0, -1.0])


def test_every_vertex_combination_is_present():
    lo, hi = theta_band(M, 0.8, 1.2)
    J = nonlinearity_vertices(M, lo, hi)
    # the front cornering entry on vy takes exactly the four products of its band ends with the two speeds
    vals = sorted({round(float(Jv[0, 2]), 6) for Jv in J})
    expect = sorted({round(t * M.H0[0, 2], 6) for t, _ in itertools.product((lo[0], hi[0]), (0, 1))})
    assert vals == expect
