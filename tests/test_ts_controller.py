"""Runtime TS observer-controller: discretisation, the sampled loop, closed loop on the nonlinear plant."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.integrate import solve_ivp

from assist.control.ts_controller import (
    MeasurementError,
    ReferenceFilter,
    TSObserverController,
    TSStateFeedback,
    foh_discretise,
    reference_series,
    run_closed_loop,
    sampled_closed_loop,
)
from assist.control.ts_design import design
from assist.control.ts_model import MEASURED_STATES
from ptw_env.dynamics import compile_plant
from ptw_env.sensors import SensorConfig
from ptw_env.vehicle import DELTA, PHI, VY

DT = 0.01


@pytest.fixture(scope="module")
def dz():
    return design()


def lane_change_roll(t: np.ndarray, amp_deg: float = 12.0, starts=(2.0, 6.0), period: float = 2.5) -> np.ndarray:
    """Double-lane-change-like roll reference [rad]: out and back, each a smooth full cycle
    ``(sin(2 pi u) - sin(4 pi u)/2) / 1.299`` (zero value, slope and curvature at both ends)."""

    def cycle(u):
        inside = (u >= 0) & (u <= 1)
        return np.where(inside, (np.sin(2 * np.pi * u) - 0.5 * np.sin(4 * np.pi * u)) / 1.299038105676658, 0.0)

    return math.radians(amp_deg) * (cycle((t - starts[0]) / period) - cycle((t - starts[1]) / period))


def speed_ramp(t: np.ndarray, v0: float, v1: float) -> np.ndarray:
    return v0 + (v1 - v0) * 0.5 * (1 - np.cos(np.pi * t / t[-1]))


# --------------------------------------------------------------------------- discretisation
def test_foh_discretisation_matches_an_ode_solver():
    rng = np.random.default_rng(3)
    F = rng.standard_normal((5, 5)) - 3 * np.eye(5)
    G = rng.standard_normal((5, 2))
    z0, v0, v1 = rng.standard_normal(5), rng.standard_normal(2), rng.standard_normal(2)
    h = 0.05
    Phi, G0, G1 = foh_discretise(F, G, h)
    sol = solve_ivp(lambda t, z: F @ z + G @ (v0 + (v1 - v0) * t / h), (0, h), z0, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(Phi @ z0 + G0 @ v0 + G1 @ (v1 - v0), sol.y[:, -1], rtol=1e-9, atol=1e-12)


def test_runtime_matches_the_sampled_loop_matrix(dz):
    # Linear TS plant frozen at an upright vertex, stepped exactly (ZOH torque); tiny states keep the
    # controller's premise z2 = sin(phi_hat)/phi_hat at 1 to ~1e-12. The runtime must reproduce T^k s0.
    ts = dz.ts
    for vertex, vx in ((1, ts.vmin), (3, ts.vmax)):
        mu = np.eye(4)[vertex]
        T = sampled_closed_loop(dz.aug, dz.runtime, mu, mu)
        M = np.zeros((9, 9))
        M[:8, :8], M[:8, 8:] = ts.A[vertex], ts.B
        Ed = sla.expm(M * DT)
        Ad, Bd = Ed[:8, :8], Ed[:8, 8:]
        ctrl = TSObserverController(dz, feedforward=None)
        x = np.zeros(8)
        x[PHI], x[VY] = 1e-6, 2e-6
        s = np.r_[x, np.zeros(10)]
        for _ in range(60):
            tau = ctrl.update(ts.C @ x, vx, 0.0)  # integrates the observer to this sample, then the torque
            np.testing.assert_allclose(np.r_[x, ctrl.z], s, rtol=1e-7, atol=1e-13)
            assert tau == pytest.approx(-(dz.runtime.K[vertex] @ s[8:]), rel=1e-9, abs=1e-15)
            x = Ad @ x + Bd[:, 0] * tau
            s = T @ s
        assert np.abs(np.linalg.eigvals(T)).max() < dz.discrete.required  # the loop the design certified


def test_update_costs_no_solver_call(dz, monkeypatch):
    # The per-sample path must not call expm, solve or cvxpy (precomputed matrices only).
    ctrl = TSObserverController(dz)
    ctrl.update(np.zeros(4), 15.0, 0.0)

    def boom(*a, **k):
        raise AssertionError("solver call inside update")

    monkeypatch.setattr(sla, "expm", boom)
    monkeypatch.setattr(np.linalg, "solve", boom)
    for k in range(5):
        ctrl.update(np.full(4, 0.01 * k), 15.0, 0.01 * k)


# --------------------------------------------------------------------------- feedforward
def test_reference_series_is_the_low_frequency_inverse(dz):
    ts = dz.ts
    mu = ts.memberships(17.0, 0.0)
    A = np.einsum("i,ijk->jk", mu, ts.A)
    S = reference_series(ts, 17.0, 1.0, order=2)
    np.testing.assert_allclose(A @ S[0, :8] + ts.B[:, 0] * S[0, 8], 0.0, atol=1e-9 * np.abs(S[0]).max())
    for j in (1, 2):
        np.testing.assert_allclose(A @ S[j, :8] + ts.B[:, 0] * S[j, 8], S[j - 1, :8], atol=1e-9 * np.abs(S).max())
    assert S[0, PHI] == pytest.approx(1.0) and S[1, PHI] == pytest.approx(0.0, abs=1e-12)


def test_steady_turn_is_an_equilibrium_of_the_nonlinear_plant(dz):
    # At roll phi_r the TS steady turn (premise z2 = sin(phi_r)/phi_r) is the plant's equilibrium except
    # for sin(delta) ~ delta: the plant's derivative there is exactly E^-1 [.. a52, a62 ..] (sin(delta) - delta).
    v = dz.ts.vehicle
    plant = compile_plant()
    col = np.zeros(8)
    col[4], col[5] = v.gravity[0, 1], v.gravity[1, 1]
    for vx, phi_r in ((10.0, 0.3), (25.0, -0.6)):
        S = reference_series(dz.ts, vx, math.sin(phi_r) / phi_r, order=0)[0]
        x, tau = phi_r * S[:8], phi_r * S[8]
        expected = np.linalg.solve(v.E, col) * (math.sin(x[DELTA]) - x[DELTA])
        np.testing.assert_allclose(plant.rhs(x, tau, vx), expected, rtol=1e-6, atol=1e-9)


# --------------------------------------------------------------------------- reference filter
def test_reference_filter_is_the_stated_transfer_functions():
    # Independent reference: scipy's lsim of F(s), s F(s), s^2 F(s), F = (1 + 3s/w)/(1 + s/w)^3, with the
    # input linear between samples (lsim's interpolation = the filter's first-order hold).
    from scipy import signal

    w = 30.0
    t = np.arange(801) * DT
    r = lane_change_roll(t, starts=(1.0, 4.0), period=2.0) + 0.05 * np.sin(3.0 * t) ** 2
    f = ReferenceFilter(w, DT)
    got = np.array([f.update(v) for v in r])
    num = np.array([3.0 / w, 1.0])
    den = np.array([1.0, 3 * w, 3 * w**2, w**3]) / w**3
    for j in range(3):
        _, ref, _ = signal.lsim((np.polymul(num, [1.0] + [0.0] * j), den), r, t)
        np.testing.assert_allclose(got[:, j], ref, rtol=0, atol=1e-7 * max(1.0, np.abs(ref).max()))


def test_reference_filter_follows_a_parabola_with_the_stated_error():
    # F - 1 = -3 (s/w)^2 + O(s^3): for phi_r = a t^2/2 the outputs settle at phi_r - 3a/w^2, phi_r' and a
    # (plus a dt^2/12 on phi_f: the filter sees the chords between samples, above the parabola by that on average;
    # the chords' kinks make a ripple at the sample instants: ~1e-7 rad, ~1e-5 rad/s and, since w dt = 0.3 is not
    # small, 2.2 % low on phi_f'', hence the tolerances; test_reference_filter_is_the_stated_transfer_functions
    # checks the realisation exactly).
    w, a = 30.0, 3.5
    f = ReferenceFilter(w, DT)
    t = np.arange(400) * DT
    out = np.array([f.update(0.5 * a * tk**2) for tk in t])
    assert out[-1, 0] - 0.5 * a * t[-1] ** 2 == pytest.approx(-3 * a / w**2 + a * DT**2 / 12, rel=1e-4)
    assert out[-1, 1] == pytest.approx(a * t[-1], rel=1e-5)
    assert out[-1, 2] == pytest.approx(a, rel=0.03)


def test_reference_filter_second_derivative_is_continuous_where_the_reference_is_only_c1():
    # phi_r = a (t - t0)^2 / 2 after t0: phi_r'' jumps by a. Two backward differences jump by ~a in one sample
    # whatever the sampling; the filter's phi_f'' is continuous: its largest one-sample change shrinks with dt.
    a, t0 = 3.5, 0.5

    def largest_step(dt: float) -> float:
        f = ReferenceFilter(30.0, dt)
        t = np.arange(int(round(1.5 / dt))) * dt
        d2 = np.array([f.update(0.5 * a * max(tk - t0, 0.0) ** 2)[2] for tk in t])
        return float(np.abs(np.diff(d2)).max())

    coarse, fine = largest_step(0.01), largest_step(0.001)
    assert coarse < 0.5 * a
    assert fine < 0.2 * coarse


def test_reference_filter_rejects_bad_settings():
    for bw in (0.0, -3.0, float("nan"), 400.0):  # 400 rad/s is beyond pi/dt = 314 rad/s
        with pytest.raises(ValueError, match="bandwidth"):
            ReferenceFilter(bw, DT)
    with pytest.raises(MeasurementError, match="finite"):
        ReferenceFilter().update(float("nan"))


def test_state_feedback_is_the_ts_gain_on_the_true_state(dz):
    # Observer bypassed: tau = -sum mu_i(vx, phi) K_i [x; e_phi; s2] with zero reference, the memberships of the
    # true roll and speed, and e_phi the exact integral of phi.
    sf = TSStateFeedback(dz)
    x = np.array([0.01, 0.002, 0.1, 0.02, 0.0, 0.0, 50.0, 40.0])
    mu = dz.ts.memberships(17.0, x[PHI])
    for k in range(5):
        tau = sf.update(x, 17.0, 0.0)
        e_phi = x[PHI] * k * DT
        assert sf.augmented[0] == pytest.approx(e_phi, rel=1e-9, abs=1e-15)
        assert tau == pytest.approx(-(mu @ dz.controller.K) @ np.r_[x, sf.augmented], rel=1e-9)
    with pytest.raises(MeasurementError):
        sf.update(np.zeros(7), 17.0, 0.0)


# --------------------------------------------------------------------------- closed loop on the nonlinear plant
CASES = [(10.0, 20.0), (20.0, 10.0), (8.0, 33.0), (33.0, 8.0)]


@pytest.mark.parametrize("v0, v1", CASES)
@pytest.mark.parametrize("seed", [0, 1])
def test_roll_tracking_at_5_percent_noise(dz, v0, v1, seed):
    t = np.arange(1201) * DT
    vx = speed_ramp(t, v0, v1)
    ref = lane_change_roll(t)
    run = run_closed_loop(TSObserverController(dz), vx, ref, sensors=SensorConfig.from_percent(5.0), seed=seed)
    assert not run.fell
    assert run.roll_rmse_deg() < 1.0
    err = run.x - run.x_hat
    assert np.degrees(np.abs(err[100:, PHI]).max()) < 2.0  # roll estimate within 2 deg after 1 s
    assert np.abs(err[:, VY]).max() < 0.2  # lateral velocity estimate bounded (m/s)
    assert np.abs(run.tau).max() < 60.0  # within the rider's strength (the env's tau_max)


def test_noise_free_tracking_is_tight_and_estimation_converges(dz):
    t = np.arange(1201) * DT
    x0 = np.zeros(8)
    x0[PHI] = math.radians(3.0)  # the observer starts from 0: initial estimation error of 3 deg
    run = run_closed_loop(TSObserverController(dz), speed_ramp(t, 10.0, 20.0), lane_change_roll(t), x0=x0)
    assert not run.fell
    assert run.roll_rmse_deg(skip_s=1.0) < 0.5
    err = np.degrees(np.abs(run.x[:, PHI] - run.x_hat[:, PHI]))
    assert err[0] > 2.9
    assert err[150:200].max() < 0.05  # converged before the manoeuvre starts (t = 2 s)
    assert err.max() < 3.1  # ISS: no peaking beyond the initial error, model mismatch included


def test_feedforward_is_what_makes_the_roll_follow_the_reference(dz):
    t = np.arange(1201) * DT
    vx, ref = speed_ramp(t, 10.0, 20.0), lane_change_roll(t)
    with_ff = run_closed_loop(TSObserverController(dz), vx, ref).roll_rmse_deg()
    paper = run_closed_loop(TSObserverController(dz, feedforward=None), vx, ref).roll_rmse_deg()
    assert with_ff < 0.5 < 1.0 < paper  # the paper's pure law lags the reference by degrees


def test_same_seed_same_run(dz):
    t = np.arange(301) * DT
    a = run_closed_loop(TSObserverController(dz), np.full(301, 15.0), lane_change_roll(t, starts=(0.5, 1.5)),
                        sensors=SensorConfig.from_percent(5.0), seed=42)
    b = run_closed_loop(TSObserverController(dz), np.full(301, 15.0), lane_change_roll(t, starts=(0.5, 1.5)),
                        sensors=SensorConfig.from_percent(5.0), seed=42)
    np.testing.assert_array_equal(a.tau, b.tau)


def test_env_episode_through_env_step(dz):
    env_mod = pytest.importorskip("ptw_env.env")
    env = env_mod.PTWRollEnv(scenario="double_lane_change", noise_pct=5.0)
    ctrl = TSObserverController(dz)
    obs, info = env.reset(seed=3)
    err = []
    while True:
        tau = ctrl.act(obs)
        err.append(info["state"][PHI] - info["phi_ref"])
        obs, _, terminated, truncated, info = env.step(np.array([tau], dtype=np.float32))
        if terminated or truncated:
            break
    assert not terminated, info.get("reason")
    assert math.degrees(math.sqrt(np.mean(np.square(err)))) < 1.0


# --------------------------------------------------------------------------- API
def test_bad_inputs_are_rejected_and_leave_the_state_alone(dz):
    ctrl = TSObserverController(dz)
    ctrl.update([0.01, 0.02, 0.001, 0.0], 15.0, 0.0)
    z = ctrl.z.copy()
    with pytest.raises(MeasurementError, match="4 measurements"):
        ctrl.update([0.0, 0.0, 0.0], 15.0, 0.0)
    with pytest.raises(MeasurementError, match="finite"):
        ctrl.update([0.0, np.nan, 0.0, 0.0], 15.0, 0.0)
    with pytest.raises(MeasurementError, match="finite"):
        ctrl.update([0.0, 0.0, 0.0, 0.0], float("inf"), 0.0)
    np.testing.assert_array_equal(ctrl.z, z)
    with pytest.raises(ValueError, match="feedforward"):
        TSObserverController(dz, feedforward=3)
    with pytest.raises(TypeError):
        TSObserverController(dz, feed_forward=2)
    with pytest.raises(TypeError, match="TSDesign"):
        TSObserverController(object())
    with pytest.raises(MeasurementError, match="x_hat0"):
        ctrl.reset(np.zeros(7))


def test_reset_and_state_views(dz):
    ctrl = TSObserverController(dz)
    x0 = np.arange(8.0) * 0.01
    ctrl.reset(x0)
    np.testing.assert_array_equal(ctrl.x_hat, x0)
    np.testing.assert_array_equal(ctrl.augmented, [0.0, 0.0])
    ctrl.x_hat[0] = 5.0  # a copy: the controller is not modified
    assert ctrl.z[0] == 0.0
    tau = ctrl.update(ts_measure := dz.ts.C @ x0, 50.0, 0.0)  # vx beyond the box: clipped, not an error
    assert math.isfinite(tau) and ctrl.tau == tau and ts_measure.shape == (4,)
    assert ctrl.mu.sum() == pytest.approx(1.0) and ctrl.mu[2] + ctrl.mu[3] == pytest.approx(1.0)


def test_measurement_order_is_yaw_rate_roll_rate_delta_delta_rate():
    assert MEASURED_STATES == (3, 4, 1, 5)
