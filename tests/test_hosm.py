"""The unknown-input HOSM observer (assist.unknown_input.hosm): design invariants, exact reconstruction on
smooth simulated data, bounds on rides with truth, the scheduled variant and input checking."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from assist.unknown_input.hosm import (
    PAPER_POLES,
    HOSMConfig,
    HOSMDesignError,
    HOSMInputError,
    ScheduledUIHOSMO,
    UIHOSMO,
    design_uihosmo,
    measurements_from_log,
    run_observer,
)
from assist.unknown_input.observability import ptw_triplet
from assist.unknown_input.structure import invariant_zeros
from ptw_env.integrate import simulate
from ptw_env.ride import ride_scenario
from ptw_env.sensors import SensorConfig
from ptw_env.vehicle import DELTA, PHI, PHI_DOT, R

V100 = 100 / 3.6
LIP = (30.0, 10.0, 10.0)
DT_FINE = 0.001


def same_set(a, b, tol=1e-6):
    a = np.asarray(a, dtype=complex).ravel()
    b = np.asarray(b, dtype=complex).ravel()
    if a.shape != b.shape:
        return False
    cost = np.abs(a[:, None] - b[None, :])
    i, j = linear_sum_assignment(cost)
    return bool(np.all(cost[i, j] <= tol * (1.0 + np.abs(b[j]))))


def smooth_ride(vx, T=6.0, amp=1.0, seed_phase=0.0):
    """Nonlinear plant driven by a smooth torque, simulated at 1 kHz and sampled at 100 Hz."""
    t = np.arange(0.0, T, DT_FINE)
    tau = amp * (1.5 * np.sin(2 * np.pi * 0.7 * t + seed_phase) + 0.8 * np.sin(2 * np.pi * 1.9 * t + 1.0))
    vxa = np.broadcast_to(np.asarray(vx(t) if callable(vx) else vx, dtype=float), t.shape)
    x = simulate(np.zeros(8), tau, vxa, dt=DT_FINE)[:-1]
    return t[::10], x[::10], tau[::10], vxa[::10]


@pytest.fixture(scope="module")
def design100():
    return design_uihosmo(HOSMConfig(lipschitz=LIP))


# ---------------------------------------------------------------------------
# design invariants
# ---------------------------------------------------------------------------
def test_luenberger_poles_as_in_the_paper(design100):
    assert same_set(design100.luenberger_eigs, PAPER_POLES)
    assert same_set(np.linalg.eigvals(design100.triplet.A - design100.L @ design100.triplet.C), PAPER_POLES)


def test_coordinate_change_separates_clean_states(design100):
    d = design100
    tr = d.triplet
    # relative degrees [2, 1, 1] and differentiator orders r_i + 1 ([1] eqs. 13-14 with k = 1)
    assert d.relative_degree == (2, 1, 1) and d.orders == (3, 2, 2)
    # T1 = [C_delta; C_r; C_phidot; C_delta Ã] spans exactly the clean physical states
    T1 = d.T[: d.r_total]
    names = tr.state_names
    clean = [names.index(s) for s in ("delta", "r", "phi_dot", "delta_dot")]
    assert np.linalg.matrix_rank(T1) == 4
    assert np.allclose(np.delete(T1, clean, axis=1) - np.delete(T1, clean, axis=1), 0)
    Tcl = np.zeros((4, tr.n))
    Tcl[np.arange(4), clean] = 1.0
    assert np.linalg.matrix_rank(np.vstack([T1, Tcl])) == 4
    # T2 annihilates D: the unclean coordinates carry no unknown input ([1] eq. 11)
    T2 = d.T[d.r_total :]
    assert np.abs(T2 @ tr.D).max() < 1e-8 * np.abs(T2).max() * np.abs(tr.D).max()
    # the normal form: T Ã T^-1 has the blocks used by the observer
    Ah = d.T @ d.Atil @ d.T_inv
    assert np.allclose(Ah[d.r_total :, d.r_total :], d.A22) and np.allclose(Ah[d.r_total :, : d.r_total], d.A21)
    assert np.max(d.zero_dynamics_eigs.real) < 0
    # the decoupling matrix has full column rank and Dbar^+ is a left inverse
    assert np.allclose(d.Dbar_pinv @ d.Dbar, np.eye(2))


def test_square_case_zero_dynamics_are_the_invariant_zeros():
    # phi and tau unknown, roll rate and lateral acceleration measured: square and strongly detectable
    cfg = HOSMConfig(outputs=("phi_dot", "ay"), lipschitz=(10.0, 100.0))
    d = design_uihosmo(cfg)
    z = invariant_zeros(d.triplet.A, d.triplet.D, d.triplet.C)
    assert z.size == 5 and np.all(z.real < 0)
    assert same_set(d.zero_dynamics_eigs, z, tol=1e-6)


def test_paper_case_5_with_known_torque_at_low_speed():
    # [1] eq. (5): phi unknown, tau known, delta measured; strongly detectable at 12 m/s on our scooter
    cfg = HOSMConfig(outputs=("delta",), unknown_inputs=("phi",), design_speed=12.0, lipschitz=(10.0,))
    d = design_uihosmo(cfg)
    assert d.triplet.known_inputs == ("tau",)
    assert d.relative_degree == (2,)
    assert same_set(d.zero_dynamics_eigs, invariant_zeros(d.triplet.A, d.triplet.D, d.triplet.C), tol=1e-6)
    # torque held over each 10 ms period: the known input enters the observer exactly (zero-order hold)
    t = np.arange(0.0, 4.0, 0.01)
    tau = 0.3 * (1.5 * np.sin(2 * np.pi * 0.7 * t) + 0.8 * np.sin(2 * np.pi * 1.9 * t + 1.0))
    X = simulate(np.zeros(8), tau, 12.0, dt=0.01)[:-1]
    run = run_observer(UIHOSMO(d), X[:, [DELTA]], vx=12.0, U=tau)
    late = t > 1.5
    err = np.abs(run.x_hat[late, PHI] - X[late, PHI]).max()
    assert np.degrees(err) < 0.06 and err < 0.1 * np.abs(X[:, PHI]).max()


def test_paper_case_designs_and_reconstructs_phi_and_tau_from_delta_and_r():
    """The paper's case (phi, tau unknown; delta, r measured): strongly detectable on the corrected
    scooter (a45 = +3.665 vx), so the observer is built as the paper builds it. The square system's
    zero dynamics (eig A22) are its invariant zeros, the slowest -2.14 1/s at 100 km/h; once that
    has decayed (4 s = 8.6 time constants from the paper's initial errors) phi and tau are exact up
    to the differentiators' sampling error, with the bounds of the three-output test (measured
    0.027 deg and 0.087 N m)."""
    d = design_uihosmo(HOSMConfig(outputs=("delta", "r"), lipschitz=(30.0, 10.0)))
    assert d.relative_degree == (2, 1)
    tr = ptw_triplet(V100, ("phi", "tau"), ("delta", "r"))
    assert same_set(d.zero_dynamics_eigs, invariant_zeros(tr.A, tr.D, tr.C), tol=1e-6)
    slowest = max(d.zero_dynamics_eigs.real)
    assert -2.5 < slowest < -2.0
    t, X, tau, vx = smooth_ride(V100)
    x0 = np.array([0.0, 0.0873, 0.1745, 0.1745, -0.3491, -0.0873, 50.0, 50.0])  # the paper's initial errors
    run = run_observer(UIHOSMO(d), X[:, [DELTA, R]], vx=vx, x0=x0)
    late = t > 4.0
    assert np.degrees(np.abs(run.x_hat[late, PHI] - X[late, PHI]).max()) < 0.05
    assert np.abs(run.unknown("tau")[late] - tau[late]).max() < 0.15


def test_zero_dynamics_poles_can_be_placed_with_redundant_outputs():
    cfg = HOSMConfig(lipschitz=LIP, zero_dynamics_poles=(-20.0, -25.0, -30.0))
    d = design_uihosmo(cfg)
    assert same_set(d.zero_dynamics_eigs, (-20.0, -25.0, -30.0), tol=1e-3)
    assert np.abs(d.T[d.r_total :] @ d.triplet.D).max() < 1e-6 * np.abs(d.T).max() * np.abs(d.triplet.D).max()
    with pytest.raises(HOSMDesignError, match="square system"):
        design_uihosmo(HOSMConfig(outputs=("phi_dot", "ay"), lipschitz=(10.0, 100.0), zero_dynamics_poles=(-1.0,) * 5))


# ---------------------------------------------------------------------------
# reconstruction
# ---------------------------------------------------------------------------
def test_exact_reconstruction_on_smooth_data_and_finite_time_convergence(design100):
    t, X, tau, vx = smooth_ride(V100)
    Y = X[:, [DELTA, R, PHI_DOT]]
    x0 = np.array([0.0, 0.0873, 0.1745, 0.1745, -0.3491, -0.0873, 50.0, 50.0])  # the paper's initial errors
    run = run_observer(UIHOSMO(design100), Y, vx=vx, x0=x0)
    late = t > 2.0
    # roll angle and torque: exact up to the sampling error of the differentiators
    assert np.degrees(np.abs(run.x_hat[late, PHI] - X[late, PHI]).max()) < 0.05
    assert np.abs(run.unknown("tau")[late] - tau[late]).max() < 0.15
    # the exactly estimated (clean) states: the measured ones (delta, r, phi_dot) are taken from the
    # first sample, the differentiated one (delta_dot) starts from the paper's large initial error
    # and converges in finite time (it last leaves the 2e-3 rad/s band at 1.16 s), then stays there
    clean = [DELTA, R, PHI_DOT, 5]
    err = np.abs(run.x_hat[:, clean] - X[:, clean])
    assert err[0, :3].max() < 1e-12 and err[0, 3] > 0.05
    settled = np.flatnonzero(err[:, 3] > 2e-3)[-1] + 1  # first sample after the last excursion
    assert t[settled] < 1.5, t[settled]
    assert err[t > 1.5].max(axis=0).max() < 2e-3
    # unknown-input-free coordinates converge too (asymptotically, at the A22 rate)
    assert np.abs(run.x_hat[late, 2] - X[late, 2]).max() < 1e-3  # vy


@pytest.fixture(scope="module")
def rides():
    return {
        "clean": ride_scenario("double_lane_change", speed_kmh=100, seed=0, sensors=SensorConfig.noiseless()),
        "noisy": ride_scenario("double_lane_change", speed_kmh=100, seed=0),
    }


# Regression bounds, ~25 % above what the observer reaches (clean: 0.075 deg, 1.79 N m; noisy, the
# reference logs' sensors: 0.805 deg, 2.83 N m, lane change at 100 km/h). The torque is the weak part:
# even noise-free it is 18 % of the torque RMS (9.9 N m), the sampling error of the second derivative
# of delta that the reconstruction needs at 100 Hz.
@pytest.mark.parametrize("which, phi_deg, tau_nm", [("clean", 0.1, 2.25), ("noisy", 1.0, 3.55)])
def test_reconstruction_bounds_on_rides_with_truth(design100, rides, which, phi_deg, tau_nm):
    r = rides[which]
    c = r.log.columns
    Y = measurements_from_log(c, design100.config.outputs)
    run = run_observer(UIHOSMO(design100), Y, vx=c["vx"])
    m = run.t > 2.0
    phi_rmse = np.degrees(np.sqrt(np.mean((run.x_hat[m, PHI] - r.states[m, PHI]) ** 2)))
    # y_k carries the torque of [t_{k-1}, t_k) only (zero-order hold): compare with that one
    tau_prev = np.r_[c["tau"][0], c["tau"][:-1]]
    tau_rmse = np.sqrt(np.mean((run.unknown("tau")[m] - tau_prev[m]) ** 2))
    assert phi_rmse < phi_deg
    assert tau_rmse < tau_nm
    # and far better than not estimating at all
    assert phi_rmse < 0.3 * np.degrees(np.sqrt(np.mean(r.states[m, PHI] ** 2)))


def test_paper_lipschitz_is_worse_at_100_hz(design100, rides):
    r = rides["clean"]
    Y = measurements_from_log(r.log.columns, design100.config.outputs)
    errs = []
    for lip in (LIP, (5000.0,) * 3):
        run = run_observer(UIHOSMO(design100, lipschitz=lip), Y, vx=r.log.columns["vx"])
        m = run.t > 2.0
        errs.append(np.sqrt(np.mean((run.x_hat[m, PHI] - r.states[m, PHI]) ** 2)))
    assert errs[1] > 3 * errs[0]


# ---------------------------------------------------------------------------
# gain-scheduled variant
# ---------------------------------------------------------------------------
def test_scheduled_equals_fixed_at_constant_speed():
    cfg = HOSMConfig(lipschitz=LIP)
    t, X, tau, vx = smooth_ride(V100)
    Y = X[:, [DELTA, R, PHI_DOT]]
    a = run_observer(UIHOSMO(design_uihosmo(cfg)), Y, vx=vx)
    lpv = ScheduledUIHOSMO(cfg, speed_range=(V100 - 2, V100 + 2), grid_step=0.5, luenberger_speed=V100)
    b = run_observer(lpv, Y, vx=vx)
    late = t > 1.0
    assert np.degrees(np.abs(a.x_hat[late, PHI] - b.x_hat[late, PHI]).max()) < 0.005
    assert np.abs(a.unknown("tau")[late] - b.unknown("tau")[late]).max() < 0.01


def test_scheduled_survives_time_varying_speed_where_fixed_does_not():
    cfg = HOSMConfig(lipschitz=LIP)
    t, X, tau, vx = smooth_ride(lambda tt: np.interp(tt, [0, 1, 7, 8], [30.0, 30.0, 15.0, 15.0]), T=8.0)
    Y = X[:, [DELTA, R, PHI_DOT]]
    late = t > 1.0
    fixed = run_observer(UIHOSMO(design_uihosmo(cfg)), Y, vx=vx)
    lpv = run_observer(ScheduledUIHOSMO(cfg, grid_step=1.0), Y, vx=vx)
    e_fixed = np.degrees(np.abs(fixed.x_hat[late, PHI] - X[late, PHI]).max())
    e_lpv = np.degrees(np.abs(lpv.x_hat[late, PHI] - X[late, PHI]).max())
    assert e_lpv < 0.1
    assert e_fixed > 10 * e_lpv
    assert np.abs(lpv.unknown("tau")[late] - tau[late]).max() < 0.2


def test_scheduled_constant_gain_is_checked_over_the_range():
    with pytest.raises(HOSMDesignError, match="does not stabilise"):
        ScheduledUIHOSMO(HOSMConfig(lipschitz=LIP), grid_step=5.0, luenberger_speed=V100)


# ---------------------------------------------------------------------------
# configuration and input checking
# ---------------------------------------------------------------------------
def test_config_rejects_bad_settings():
    with pytest.raises(TypeError):
        HOSMConfig(output=("delta",))  # unknown field
    with pytest.raises(HOSMDesignError, match="unknown_inputs"):
        HOSMConfig(unknown_inputs=("phi", "vx"))
    with pytest.raises(HOSMDesignError, match="negative"):
        HOSMConfig(poles=(1.0,) * 7)
    with pytest.raises(HOSMDesignError, match="lipschitz"):
        HOSMConfig(lipschitz=(1.0, 2.0))
    with pytest.raises(HOSMDesignError, match="no default"):
        HOSMConfig(outputs=("delta", "delta_dot"))
    with pytest.raises(HOSMDesignError, match="poles: 7 given, the model has 8 states"):
        design_uihosmo(HOSMConfig(outputs=("delta", "r"), unknown_inputs=("tau",)))


def test_observer_rejects_bad_samples(design100):
    obs = UIHOSMO(design100)
    with pytest.raises(HOSMInputError, match="y must be 3 finite values"):
        obs.update([0.0, 0.0])
    with pytest.raises(HOSMInputError, match="no known input"):
        obs.update([0.0, 0.0, 0.0], u=1.0)
    with pytest.raises(HOSMInputError, match="sample 0"):
        obs.update([0.0, np.nan, 0.0])
    with pytest.raises(HOSMInputError, match="x0"):
        obs.reset(np.zeros(5))
    d5 = design_uihosmo(HOSMConfig(outputs=("delta",), unknown_inputs=("phi",), design_speed=8.0, lipschitz=(30.0,)))
    with pytest.raises(HOSMInputError, match="known input"):
        UIHOSMO(d5).update([0.0])
    lpv = ScheduledUIHOSMO(HOSMConfig(lipschitz=LIP), speed_range=(V100 - 1, V100 + 1), luenberger_speed=V100)
    with pytest.raises(HOSMInputError, match="needs the measured speed"):
        lpv.update([0.0, 0.0, 0.0])
    with pytest.raises(HOSMInputError, match="no ride-log channel"):
        measurements_from_log({"delta": np.zeros(3)}, ("phi",))


def test_observer_is_deterministic_and_resettable(design100):
    t, X, tau, vx = smooth_ride(V100, T=1.0)
    Y = X[:, [DELTA, R, PHI_DOT]]
    obs = UIHOSMO(design100)
    a = run_observer(obs, Y)
    b = run_observer(obs, Y)  # run_observer resets
    assert np.array_equal(a.x_hat, b.x_hat) and np.array_equal(a.zeta_hat, b.zeta_hat)
    d2 = dataclasses.replace(design100.config, extra_order=0)
    assert design_uihosmo(d2).orders == (2, 1, 1)
