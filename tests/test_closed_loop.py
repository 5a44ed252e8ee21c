"""Issue-3 episode tests: full closed-loop episodes through env.step, from noisy sensors only.

Bounds (stated, not tuned): the issue's targets — no fall, roll RMSE under 1 deg, and
within 2x of the full-state LQR bound on the double lane change at 5 % noise — and a
bounded estimation error: |phi_hat - phi| < 2 deg and |vy_hat - vy| < 0.2 m/s at every
sample (the roll error bound is twice the 1 deg tracking target; 0.2 m/s is 10 % of
the lateral velocity a 45 deg lean at 33 m/s would need). The full-state bound is
:class:`assist.control.lqg.TrackingLQR` on the true state (with the TS controller's reference
feedforward), and on the double lane change at 50 km/h no output-feedback controller may
beat it, or the TS design's own state feedback on the true state, by more than 10 %. (They
bound their own feedback laws, not every law: at 100 km/h, noise-free, the TS loop beats
its state feedback by 12 % and the LQR by 7 %, the observer's dynamics happening to help
on that reference; with noise both bounds win clearly.)
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from assist.evaluate import EvaluationError, make_controller, run_episode
from assist.control.lqg import MEASURED, LQGController, TrackingLQR, tracking_weights
from assist.cli import main
from ptw_env.dynamics import compile_plant, linearise
from ptw_env.env import PTWRollEnv
from ptw_env.integrate import Stepper
from ptw_env.sensors import SensorConfig
from ptw_env.vehicle import PHI


@pytest.mark.parametrize(
    "scenario, speed, seed",
    [("double_lane_change", 50.0, 0), ("double_lane_change", 50.0, 1), ("double_lane_change", 100.0, 2),
     ("constant_radius", None, 0), ("urban", None, 3)],
)
def test_ts_episode_no_fall_tracks_and_estimates(scenario, speed, seed):
    ep = run_episode("ts", scenario, speed_kmh=speed, noise_pct=5.0, seed=seed)
    m = ep.metrics()
    assert not m["fell"] and m["end_reason"] == "scenario_end"
    assert m["roll_rmse_deg"] < 1.0
    err = ep.x_hat - ep.x
    assert np.degrees(np.abs(err[:, 0]).max()) < 2.0
    assert np.abs(err[:, 2]).max() < 0.2
    assert np.all(np.isfinite(ep.x_hat))


def test_ts_within_2x_of_full_state_lqr_on_lane_change():
    # The bound is the tracking LQR on the true state with the TS feedforward, not the rider's gentle LQR.
    assert isinstance(make_controller("lqr", PTWRollEnv()).ctrl, TrackingLQR)
    ts = run_episode("ts", "double_lane_change", noise_pct=5.0, seed=4).metrics()
    lqr = run_episode("lqr", "double_lane_change", noise_pct=5.0, seed=4).metrics()
    assert ts["roll_rmse_deg"] < 1.0
    assert ts["roll_rmse_deg"] <= 2.0 * lqr["roll_rmse_deg"]


@pytest.mark.parametrize("noise", [0.0, 5.0])
def test_no_output_feedback_controller_beats_the_full_state_bounds(noise):
    # A bound an output-feedback design beats by more than 10 % is no bound (the rider's LQR, the former
    # "bound", lost to the TS controller by a factor 2 here: 0.37 vs 0.18 deg).
    m = {c: np.mean([run_episode(c, "double_lane_change", noise_pct=noise, seed=s).metrics()["roll_rmse_deg"]
                     for s in (0, 1)]) for c in ("ts", "ts_state", "lqg", "lqr")}
    for output_feedback in ("ts", "lqg"):
        assert m[output_feedback] >= 0.9 * m["lqr"], m
    assert m["ts"] >= 0.9 * m["ts_state"], m


def test_reference_filter_leaves_no_torque_spike_on_the_c1_lane_change():
    # phi_ref of the lane change is only C1 (phi_ref'' jumps at each move's ends). Noise-free, the TS torque
    # peaks no higher than 25 % above the full-state bound's on the same ride (both use the filtered
    # feedforward); with two backward differences of phi_ref instead it spiked to twice that.
    from assist.evaluate import TSAdapter
    from assist.control.ts_controller import TSObserverController

    def ts_with(bandwidth):
        def make(env):
            a = TSAdapter(env)
            a.ctrl = TSObserverController(a.design, reference_bandwidth=bandwidth)
            return a
        return make

    lqr = run_episode("lqr", "double_lane_change", noise_pct=0.0, seed=0)
    ts = run_episode(ts_with(30.0), "double_lane_change", noise_pct=0.0, seed=0)
    diff = run_episode(ts_with(None), "double_lane_change", noise_pct=0.0, seed=0)
    peak = {k: float(np.abs(e.tau).max()) for k, e in (("lqr", lqr), ("ts", ts), ("diff", diff))}
    assert peak["ts"] <= 1.25 * peak["lqr"], peak
    assert peak["diff"] > 2.0 * peak["lqr"], peak  # the spike this guards against
    assert ts.metrics()["roll_rmse_deg"] < 1.0


def test_tracking_lqr_gain_solves_the_discrete_riccati_equation():
    # Independent reference: the finite-difference linearisation, scipy's cont2discrete, and the Riccati
    # difference equation iterated to convergence (value iteration), at two speeds.
    from scipy.signal import cont2discrete

    lqr = TrackingLQR()
    Q, R = tracking_weights()
    for vx in (9.0, 27.0):
        A, B = linearise(compile_plant(), vx)
        Aa = np.zeros((9, 9))
        Aa[:8, :8], Aa[8, PHI] = A, 1.0
        Ad, Bd, *_ = cont2discrete((Aa, np.vstack([B, [[0.0]]]), np.eye(9), np.zeros((9, 1))), 0.01)
        P = Q.copy()
        for _ in range(20000):
            K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
            P = Q + Ad.T @ P @ (Ad - Bd @ K)
        np.testing.assert_allclose(lqr.gain(vx), K[0], rtol=1e-4, atol=1e-6 * np.abs(K).max())
        assert np.abs(np.linalg.eigvals(Ad - Bd @ K)).max() < 1.0


def test_tracking_lqr_holds_a_steady_turn_on_the_nonlinear_plant():
    # Feedforward (model inverse, nonlinear steady turn) plus integral action: at 15 m/s, 20 deg held after a
    # 2 s ramp, the roll error after 8 s is below 0.01 deg.
    lqr, step = TrackingLQR(), Stepper(compile_plant(), 0.01)
    x = np.zeros(8)
    for k in range(800):
        ref = np.radians(20.0) * min(k * 0.01 / 2.0, 1.0)
        step.step(x, lqr.update(x, 15.0, ref), 15.0)
    assert abs(np.degrees(x[PHI]) - 20.0) < 0.01


def test_controllers_design_on_the_prior_with_its_effects():
    # The prior's tire stiffness is 20 % low: the TS design's vertex matrices are the prior's Jacobian
    # (independent: finite differences), not the nominal scooter's.
    env = PTWRollEnv(prior_effects={"tire_stiffness": {"front_scale": 0.8}},
                     effects={"tire_stiffness": {"front_scale": 0.8}})
    ts = make_controller("ts", env).design.ts
    assert ts.effects == ("tire_stiffness",)
    A_fd, _ = linearise(env.get_prior(), ts.vmin)
    np.testing.assert_allclose(ts.A[1], A_fd, rtol=1e-6, atol=1e-6 * np.abs(A_fd).max())  # vertex 1: vmin, z2 = 1
    A_nominal, _ = linearise(compile_plant(), ts.vmin)
    assert np.abs(ts.A[1] - A_nominal).max() > 0.05 * np.abs(A_nominal).max()
    m = run_episode("ts", "double_lane_change", noise_pct=5.0, seed=0,
                    prior_effects={"tire_stiffness": {"front_scale": 0.8}},
                    effects={"tire_stiffness": {"front_scale": 0.8}}).metrics()
    assert not m["fell"] and m["roll_rmse_deg"] < 1.0


@pytest.mark.parametrize("controller", ["ts", "lqg", "lqr", "ts_state"])
def test_prior_effects_a_controller_cannot_model_are_an_error(controller):
    with pytest.raises(EvaluationError, match="road_bank"):
        make_controller(controller, PTWRollEnv(prior_effects={"road_bank": {"bank_rad": 0.05}}))
    env = PTWRollEnv(prior_effects={"gyro_bias": {"roll_rate_bias": 0.01}})
    if controller in ("ts", "lqg"):  # observers without a sensor-effect model
        with pytest.raises(EvaluationError, match="gyro_bias"):
            make_controller(controller, env)
    else:
        assert make_controller(controller, env).x_hat is None


@pytest.mark.parametrize("noise", [0.0, 10.0])
def test_ts_other_noise_levels_no_fall(noise):
    m = run_episode("ts", "double_lane_change", noise_pct=noise, seed=5).metrics()
    assert not m["fell"] and m["roll_rmse_deg"] < 1.0


def test_lqg_episode_and_filter_stability():
    m = run_episode("lqg", "urban", noise_pct=5.0, seed=0).metrics()
    assert not m["fell"] and m["roll_rmse_deg"] < 1.5
    c = LQGController(sensors=SensorConfig.from_percent(5))
    C = np.zeros((4, 8))
    for i, j in enumerate(MEASURED):
        C[i, j] = 1.0
    for Ad, L in zip(c._grid.Ad, c._grid.L):
        rho = max(abs(np.linalg.eigvals((np.eye(8) - L @ C) @ Ad)))
        assert rho < 1.0  # the estimation error of the corrected filter decays at every grid speed


def test_unknown_controller():
    with pytest.raises(EvaluationError, match="unknown controller"):
        run_episode("pid")


def test_evaluate_cli_json(tmp_path):
    js = tmp_path / "e.json"
    assert main(["evaluate", "--controller", "lqg", "--scenario", "slalom", "--noise", "5", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert {"roll_rmse_deg", "roll_max_deg", "torque_rms_nm", "torque_max_nm", "fell", "estimation_rmse"} <= set(d)
    assert set(d["estimation_rmse"]) >= {"phi", "vy"} and math.isfinite(d["roll_rmse_deg"])


def test_metrics_table_reports_every_estimated_state_and_the_torque_peak(tmp_path):
    from assist.evaluate import metrics_table, plot_episode

    lqg = run_episode("lqg", "slalom", noise_pct=5.0, seed=0)
    lqr = run_episode("lqr", "slalom", noise_pct=5.0, seed=0)
    rows = metrics_table([lqg.metrics(), lqr.metrics()]).splitlines()
    head = [c.strip() for c in rows[0].strip("|").split("|")]
    assert "torque peak N m" in head
    assert [h.split()[0] for h in head if " est " in h] == ["phi", "delta", "vy", "r", "phi_dot", "delta_dot",
                                                            "Fyf", "Fyr"]
    cells = dict(zip(head, (c.strip() for c in rows[2].strip("|").split("|"))))
    est = lqg.metrics()["estimation_rmse"]
    assert float(cells["phi est deg"]) == pytest.approx(math.degrees(est["phi"]), rel=2e-3)
    assert float(cells["Fyr est N"]) == pytest.approx(est["Fyr"], rel=2e-3)
    assert float(cells["torque peak N m"]) == pytest.approx(np.abs(lqg.tau).max(), abs=0.06)
    assert [c.strip() for c in rows[3].strip("|").split("|")][-8:] == ["-"] * 8  # the bound has no estimate
    fig = plot_episode(lqg, tmp_path / "lqg.png", compare=[lqr])
    assert (tmp_path / "lqg.png").stat().st_size > 0 and len(fig.axes) == 10


def test_design_cli_json(tmp_path):
    js = tmp_path / "d.json"
    assert main(["design", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    assert d["feasible"] is True and {"solve_s", "gains", "margins"} <= set(d)


def test_observability_cli_json(tmp_path):
    js = tmp_path / "o.json"
    assert main(["observability", "--speeds", "8,20,33", "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    for case in d["cases"]:
        assert {"name", "unknown_inputs", "outputs", "speeds", "relative_degree", "invariant_zeros",
                "strongly_detectable"} <= set(case)
    paper = next(c for c in d["cases"] if c["name"].startswith("c_"))
    # issue 15: with model.md's corrected a45 the paper's case is strongly detectable at every speed
    assert paper["outputs"] == ["delta", "r"] and paper["unknown_inputs"] == ["phi", "tau"]
    assert paper["strongly_detectable"] == [True, True, True]
    assert all(max(z[0] for z in zs) < 0 for zs in paper["invariant_zeros"])
