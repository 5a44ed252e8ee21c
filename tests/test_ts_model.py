"""The exact TS form of the reference scooter against the one model (ptw_env.dynamics)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from assist.control.ts_model import (
    H1_CORNER,
    H1_GAIN,
    H2_CORNER,
    H2_GAIN,
    MEASURED_STATES,
    PremiseError,
    UnsupportedEffectError,
    augment,
    build_ts_model,
    observer_sensitivity_filter,
    sinc_premise,
    upright_matrices,
)
from ptw_env.dynamics import compile_plant, linearise
from ptw_env.effects import Effects
from ptw_env.vehicle import DELTA, DELTA_DOT, PHI, PHI_DOT, REFERENCE_SCOOTER, STATE_NAMES

RNG = np.random.default_rng(20240501)


def _random_states(n: int, rng: np.random.Generator, phi_max: float = math.pi / 4) -> np.ndarray:
    scale = np.array([0.3, 0.05, 1.0, 0.5, 1.0, 1.0, 1500.0, 1500.0])
    x = rng.standard_normal((n, 8)) * scale
    x[:, PHI] = rng.uniform(-phi_max, phi_max, n)
    return x


def _tolerance(ts, x, tau, vx):
    """Machine-precision tolerance per component: eps times the sum of |terms| of the product."""
    Az = np.abs(ts.state_matrix(vx, x[:, PHI]))
    mags = np.einsum("nij,nj->ni", Az, np.abs(x)) + np.abs(ts.B[:, 0]) * np.abs(tau)[:, None]
    return 64 * np.finfo(float).eps * (mags + 1.0)


def test_memberships_are_a_partition_of_unity_and_hit_the_vertices():
    ts = build_ts_model(vmin=8.0, vmax=33.0)
    vx = RNG.uniform(0.0, 50.0, 500)  # also outside the box: clipped
    phi = RNG.uniform(-1.2, 1.2, 500)
    mu = ts.memberships(vx, phi)
    assert mu.shape == (500, 4)
    assert np.all(mu >= 0.0)
    np.testing.assert_allclose(mu.sum(axis=-1), 1.0, rtol=0, atol=1e-14)
    for i, (z1, z2) in enumerate(ts.vertices):
        phi_i = 0.0 if z2 == 1.0 else ts.phi_max
        np.testing.assert_allclose(ts.memberships(z1, phi_i), np.eye(4)[i], atol=1e-12)


def test_premise_z2_is_sin_phi_over_phi_with_the_limit_at_zero():
    phi = np.array([0.0, 1e-9, 0.3, -0.3, math.pi / 4])
    np.testing.assert_allclose(sinc_premise(phi), [1.0, 1.0, math.sin(0.3) / 0.3, math.sin(0.3) / 0.3,
                                                   math.sin(math.pi / 4) / (math.pi / 4)], rtol=1e-15)
    ts = build_ts_model()
    assert ts.z2min == pytest.approx(math.sin(math.pi / 4) / (math.pi / 4), rel=1e-15)


def test_ts_rhs_equals_the_nonlinear_plant_to_machine_precision_when_delta_is_zero():
    # With delta = 0 exactly, sin(delta) = delta = 0: the TS form is exact (phi, vx in the box).
    ts = build_ts_model(vmin=8.0, vmax=33.0)
    plant = compile_plant()
    x = _random_states(400, RNG)
    x[:, DELTA] = 0.0
    vx = RNG.uniform(8.0, 33.0, 400)
    tau = RNG.normal(0.0, 20.0, 400)
    got = ts.rhs(x, tau, vx)
    ref = plant.rhs(x, tau, vx)
    assert np.all(np.abs(got - ref) <= _tolerance(ts, x, tau, vx))


def test_ts_rhs_plus_the_known_sin_delta_term_equals_the_nonlinear_plant_for_any_delta():
    # The only approximation is sin(delta) ~ delta in rows 5, 6 of E x' (coefficients a52, a62):
    # f_plant - f_TS = E^-1 [0 0 0 0 a52 a62 0 0]^T (sin(delta) - delta), from the vehicle data alone.
    v = REFERENCE_SCOOTER
    ts = build_ts_model(vmin=8.0, vmax=33.0)
    plant = compile_plant()
    x = _random_states(400, RNG)
    x[:, DELTA] = RNG.uniform(-0.2, 0.2, 400)
    vx = RNG.uniform(8.0, 33.0, 400)
    tau = RNG.normal(0.0, 20.0, 400)
    col = np.zeros(8)
    col[PHI_DOT], col[DELTA_DOT] = v.gravity[0, 1], v.gravity[1, 1]
    corr = np.outer(np.sin(x[:, DELTA]) - x[:, DELTA], np.linalg.solve(v.E, col))
    got = ts.rhs(x, tau, vx) + corr
    assert np.all(np.abs(got - plant.rhs(x, tau, vx)) <= _tolerance(ts, x, tau, vx) + 1e-12 * np.abs(corr))
    # and the difference is not negligible: the correction is what closes the gap
    assert np.max(np.abs(corr)) > 1e3 * np.max(_tolerance(ts, x, tau, vx))


PRIOR_EFFECTS = ["tire_stiffness:front_scale=0.8,rear_scale=1.1", "payload:mass_kg=80",
                 "steer_damping:damping_nms=20", "relaxation_length:sigma_m=0.3"]


def test_ts_model_of_a_plant_with_linear_effects_is_exact():
    # An environment's prior may carry the effects that only change the linear matrices: the TS model
    # of that plant matches its right-hand side to machine precision (delta = 0), and differs from the
    # nominal one (the effects are not dropped).
    plant = compile_plant(None, Effects.parse(PRIOR_EFFECTS))
    ts = build_ts_model(plant, vmin=8.0, vmax=33.0)
    assert set(ts.effects) == {"tire_stiffness", "payload", "steer_damping", "relaxation_length"}
    x = _random_states(400, RNG)
    x[:, DELTA] = 0.0
    vx = RNG.uniform(8.0, 33.0, 400)
    tau = RNG.normal(0.0, 20.0, 400)
    assert np.all(np.abs(ts.rhs(x, tau, vx) - plant.rhs(x, tau, vx)) <= _tolerance(ts, x, tau, vx))
    nominal = build_ts_model(vmin=8.0, vmax=33.0)
    assert np.abs(ts.A - nominal.A).max() > 0.05 * np.abs(nominal.A).max()
    A, B = upright_matrices(plant, 20.0)
    A_fd, B_fd = linearise(plant, 20.0)  # independent: central differences
    np.testing.assert_allclose(A, A_fd, rtol=1e-6, atol=1e-6 * np.abs(A).max())
    np.testing.assert_allclose(B, B_fd, rtol=1e-6)


@pytest.mark.parametrize("effect", ["road_bank:bank_rad=0.05", "roll_moment_offset:moment_nm=20",
                                    "tire_saturation:mu_peak=0.9"])
def test_effects_the_ts_form_cannot_hold_are_refused_not_dropped(effect):
    plant = compile_plant(None, Effects.parse([effect]))
    with pytest.raises(UnsupportedEffectError, match=effect.split(":")[0]):
        build_ts_model(plant)
    with pytest.raises(UnsupportedEffectError):
        upright_matrices(plant, 15.0)


def test_upright_ts_matrix_is_the_linearisation_of_the_plant():
    ts = build_ts_model(vmin=8.0, vmax=33.0)
    plant = compile_plant()
    for vx in (8.0, 14.3, 33.0):
        A_ts = ts.state_matrix(vx, 0.0)
        np.testing.assert_allclose(A_ts, REFERENCE_SCOOTER.state_matrix(vx), rtol=1e-13, atol=1e-9)
        A_fd, B_fd = linearise(plant, vx)
        np.testing.assert_allclose(A_ts, A_fd, rtol=1e-5, atol=1e-3)
        np.testing.assert_allclose(ts.B, B_fd, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("vx, weave", [(10.0, complex(-0.411, 6.16)), (20.0, complex(-4.43, 15.8))])
def test_upright_vertex_reproduces_the_weave_of_model_md(vx, weave):
    """model.md's eigenvalue table (a45 = +3.665 vx), to its printed digits."""
    ts = build_ts_model(vmin=vx, vmax=35.0)
    ev = np.linalg.eigvals(ts.A[1])  # vertex (vmin, z2 = 1): the upright linear model at vx
    assert np.min(np.abs(ev - weave)) < 0.06


def test_measurement_matrix_picks_yaw_rate_roll_rate_delta_delta_rate():
    ts = build_ts_model()
    assert [STATE_NAMES[i] for i in MEASURED_STATES] == ["r", "phi_dot", "delta", "delta_dot"]
    x = np.arange(8.0)
    np.testing.assert_array_equal(ts.measure(x), [3.0, 4.0, 1.0, 5.0])


def test_augmentation_integrates_the_roll_error_and_low_passes_it():
    ts = build_ts_model(vmin=10.0, vmax=20.0)
    aug = augment(ts)
    assert aug.A.shape == (4, 10, 10) and aug.n == 10
    np.testing.assert_array_equal(aug.A[:, :8, :8], ts.A)
    np.testing.assert_array_equal(aug.B2[:8], ts.B)
    x = RNG.standard_normal(10)
    r = 0.1
    for i in range(4):
        d = aug.A[i] @ x + aug.B1[:, 0] * r
        assert d[8] == pytest.approx(x[PHI] - r, abs=1e-15)  # e_phi' = phi - phi_r
        assert d[9] == pytest.approx(-H2_CORNER * x[9] + H2_GAIN * (x[PHI] - r), rel=1e-14)
    # h2 = s2: transfer from (phi - phi_r) to h2 is 40 pi/(s + 20 pi)
    for w in (0.5, 10.0, 300.0):
        s = 1j * w
        h = aug.C12[0, 8:] @ np.linalg.solve(s * np.eye(2) - aug.Ac, aug.Bc[:, 0])
        assert h == pytest.approx(40 * math.pi / (s + 20 * math.pi), rel=1e-12)


def test_observer_sensitivity_filter_is_3s_over_s_plus_30pi():
    Aq, Bq, Cq, Dq = observer_sensitivity_filter(3)
    for w in (0.1, 30.0, 1000.0):
        s = 1j * w
        H = Cq @ np.linalg.solve(s * np.eye(3) - Aq, Bq) + Dq
        np.testing.assert_allclose(H, np.eye(3) * H1_GAIN * s / (s + H1_CORNER), rtol=1e-12)


def test_vertex_matrices_are_read_only():
    ts = build_ts_model()
    with pytest.raises(ValueError):
        ts.A[0, 0, 0] = 1.0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"vmin": 20.0, "vmax": 10.0}, "vmin < vmax"),
        ({"vmin": 1.0, "vmax": 10.0}, "valid range"),
        ({"vmin": 10.0, "vmax": 45.0}, "valid range"),
        ({"phi_max": 2.0}, "phi_max"),
        ({"vmin": float("nan"), "vmax": 10.0}, "vmin < vmax"),
    ],
)
def test_bad_premise_box_is_rejected(kwargs, match):
    with pytest.raises(PremiseError, match=match):
        build_ts_model(**kwargs)
    assert issubclass(PremiseError, ValueError)


def test_unknown_keyword_is_rejected():
    with pytest.raises(TypeError):
        build_ts_model(v_min=3.0)
