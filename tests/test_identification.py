"""Identification baselines (direct eq. 12, inversion eq. 13, joint EKF) and ``ptw-assist estimate``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

import assist.cli.estimate  # noqa: F401  (registers the subcommand)
from assist.estimation.identification import (
    DirectLS,
    IdentificationError,
    InversionLS,
    JointEKF,
    LSOptions,
    estimate,
    state_variable_filter,
)
from assist.estimation.lpv_model import build_lpv_model
from assist.cli import main
from ptw_env.logs import RideLog
from ptw_env.ride import ride_scenario
from ptw_env.sensors import SensorConfig

from conftest import DATA  # noqa: E402  (shared/data beside the repository)

C0 = build_lpv_model().theta0
TRUTH_FRICTION_URBAN = 0.6 * C0  # sidecar: tire_stiffness front_scale = rear_scale = 0.6


@pytest.fixture(scope="module")
def noiseless_07():
    r = ride_scenario("handling", effects={"tire_stiffness": {"front_scale": 0.7, "rear_scale": 0.7}},
                      sensors=SensorConfig.noiseless(), seed=2)
    return r


@pytest.fixture(scope="module")
def noisy_06():
    return ride_scenario("handling", effects={"tire_stiffness": {"front_scale": 0.6, "rear_scale": 0.6}},
                         noise_pct=5, seed=1)


# ---------------------------------------------------------------- filters
def test_state_variable_filter_matches_scipy_and_is_a_derivative_chain():
    dt = 0.01
    t = np.arange(2000) * dt
    u = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sign(np.sin(2 * np.pi * 0.13 * t))
    out = state_variable_filter(u, dt, 3.0, order=3)
    b, a = signal.butter(3, 2 * np.pi * 3.0, analog=True)
    for k in range(3):  # s^k H(s): numerator shifted by k
        num = np.r_[b[-1], np.zeros(k)]
        _, yk, _ = signal.lsim((num, a), u - u[0], t, interp=False)
        ref = yk + (u[0] if k == 0 else 0.0)
        np.testing.assert_allclose(out[k], ref, atol=1e-8 * max(1.0, np.abs(ref).max()))
    # a constant signal passes unchanged with zero derivatives (the filter starts at rest on it)
    c = state_variable_filter(np.full(100, 2.5), dt, 3.0)
    np.testing.assert_allclose(c[0], 2.5, rtol=1e-12)
    np.testing.assert_allclose(c[1:], 0.0, atol=1e-12)


@pytest.mark.parametrize("kw, words", [({"cutoff_hz": 60.0}, "Nyquist"), ({"order": 0}, "order"),
                                       ({"cutoff_hz": -1.0}, "cutoff_hz")])
def test_state_variable_filter_rejects_bad_settings(kw, words):
    args = {"cutoff_hz": 3.0, "order": 3, **kw}
    with pytest.raises(IdentificationError, match=words):
        state_variable_filter(np.zeros(10), 0.01, args["cutoff_hz"], args["order"])


# ---------------------------------------------------------------- least squares
def test_inversion_recovers_the_truth_from_true_states(noiseless_07):
    """Eq. (13) is exact for the model: with the true states and noise-free sensors the final-third
    mean is within 1 % of 0.7 C_0 for all four stiffnesses."""
    r = noiseless_07
    res = InversionLS().fit(r.log, x_hat=r.states).result()
    np.testing.assert_allclose(res.final_third_mean() / (0.7 * C0), 1.0, atol=0.01)


def test_direct_one_body_model_is_biased(noiseless_07):
    """The paper's eq. (12) with its one-body model (11): on the same exact data it misses by far more than
    inversion."""
    r = noiseless_07
    d = DirectLS(split="one_body").fit(r.log, x_hat=r.states).result().final_third_mean() / (0.7 * C0) - 1
    i = InversionLS().fit(r.log, x_hat=r.states).result().final_third_mean() / (0.7 * C0) - 1
    assert np.abs(d).max() > 10 * np.abs(i).max()


def test_direct_with_the_models_yaw_row_is_the_method_without_its_handicap(noiseless_07):
    """The same direct least squares, the axle forces split by the model's own yaw row (the observer's
    information): on exact data within 5 % of the truth 0.7 C_0 on every stiffness (the one-body split
    misses by tens of percent), the front axle within 1 %."""
    r = noiseless_07
    res = DirectLS().fit(r.log, x_hat=r.states).result()
    assert res.info["split"] == "full"
    err = res.final_third_mean() / (0.7 * C0) - 1
    assert np.abs(err).max() < 0.05 and np.abs(err[:2]).max() < 0.01, err
    with pytest.raises(IdentificationError, match="split"):
        DirectLS(split="two_body")


def test_least_squares_options_are_checked(noiseless_07):
    with pytest.raises(IdentificationError, match="order"):
        LSOptions(order=2)
    with pytest.raises(IdentificationError, match="x_hat"):
        DirectLS().fit(noiseless_07.log, x_hat=np.zeros((5, 8)))


# ---------------------------------------------------------------- joint EKF
def test_joint_ekf_on_a_noisy_friction_ride(noisy_06):
    """5 % noise, handling track, friction 0.6: cornering stiffnesses within 3 % of the truth 15 s in,
    all four within 10 % over the final third; the states are estimated too."""
    r = noisy_06
    ekf = JointEKF(sensors=SensorConfig.from_percent(5)).fit(r.log)
    truth = 0.6 * C0
    at15 = ekf.stiffness_[1500:2000].mean(axis=0) / truth
    assert np.all(np.abs(at15[[0, 2]] - 1) < 0.03), at15
    final = ekf.result().final_third_mean() / truth
    assert np.all(np.abs(final - 1) < 0.10), final
    phi_err = np.sqrt(np.mean((ekf.x_hat_[:, 0] - r.states[:, 0]) ** 2))
    assert phi_err < 0.01  # rad, against a roll RMS of ~0.3 rad


def test_joint_ekf_survives_dropouts_and_is_deterministic(noisy_06):
    c = {k: np.array(v, dtype=float) for k, v in noisy_06.log.columns.items()}
    c["ay"][500:700] = np.nan
    c["yaw_rate"][1000:1100] = np.nan
    c["vx"][2000:2030] = np.nan
    log = RideLog(t=c["t"], columns=c, meta={}, path=None)
    a = JointEKF().fit(log)
    b = JointEKF().fit(log)
    assert np.all(np.isfinite(a.stiffness_)) and np.all(np.isfinite(a.x_hat_))
    np.testing.assert_array_equal(a.stiffness_, b.stiffness_)
    assert np.all(a.stiffness_ >= 0.2 * C0 - 1e-9) and np.all(a.stiffness_ <= 2.0 * C0 + 1e-9)


def test_estimate_dispatch():
    with pytest.raises(IdentificationError, match="unknown method"):
        estimate(None, "kalman")


# ---------------------------------------------------------------- command line
def test_cli_estimate_on_the_cross_check_log(tmp_path, capsys):
    """friction_urban.csv (independent simulator, truth 0.6 C_0 in the sidecar): cli.md's JSON, the
    final-third mean, and the cornering stiffnesses within 5 % for the EKF."""
    js = tmp_path / "est.json"
    png = tmp_path / "est.png"
    rc = main(["estimate", str(DATA / "friction_urban.csv"), "--method", "ukf", "--json", str(js), "--plot", str(png)])
    assert rc == 0
    out = json.loads(js.read_text())
    assert out["method"] == "ukf"
    assert set(out["stiffness"]) == {"C_alpha_f", "C_gamma_f", "C_alpha_r", "C_gamma_r"}
    est = np.array([out["stiffness"][k] for k in ("C_alpha_f", "C_gamma_f", "C_alpha_r", "C_gamma_r")])
    np.testing.assert_allclose([out["truth_stiffness"]["C_alpha_f"]], [TRUTH_FRICTION_URBAN[0]])
    assert np.all(np.abs(est[[0, 2]] / TRUTH_FRICTION_URBAN[[0, 2]] - 1) < 0.05)
    assert png.stat().st_size > 10_000
    text = capsys.readouterr().out
    assert "C_alpha_f" in text and "truth" in text


def test_cli_refuses_to_overwrite_and_rejects_bad_options(tmp_path, capsys):
    js = tmp_path / "est.json"
    js.write_text("keep\n")
    rc = main(["estimate", str(DATA / "friction_urban.csv"), "--method", "direct", "--json", str(js)])
    assert rc == 2 and "exists" in capsys.readouterr().err and js.read_text() == "keep\n"
    rc = main(["estimate", str(DATA / "friction_urban.csv"), "--tau-a", "5"])
    err = capsys.readouterr().err
    assert rc == 2 and "--tau-a" in err and err.count("\n") == 1
    with pytest.raises(SystemExit) as e:
        main(["estimate", str(DATA / "friction_urban.csv"), "--method", "magic"])
    assert e.value.code == 2
    rc = main(["estimate", str(tmp_path / "missing.csv")])
    assert rc == 2 and "missing.csv" in capsys.readouterr().err


def test_cli_adaptive_kalman_axle_on_the_cross_check_log(tmp_path):
    """The independently simulated friction_urban.csv (truth 0.6 C_0): the adaptive observer with Kalman
    gains and axle scales lands every stiffness within 2 % of the truth (final third); the options
    are echoed in the JSON and --law paper refuses them with one line."""
    js = tmp_path / "est.json"
    rc = main(["estimate", str(DATA / "friction_urban.csv"), "--gains", "kalman", "--parametrisation", "axle",
               "--json", str(js)])
    assert rc == 0
    out = json.loads(js.read_text())
    assert (out["gains"], out["parametrisation"]) == ("kalman", "axle")
    est = np.array([out["stiffness"][k] for k in ("C_alpha_f", "C_gamma_f", "C_alpha_r", "C_gamma_r")])
    assert np.all(np.abs(est / TRUTH_FRICTION_URBAN - 1) < 0.02), est / TRUTH_FRICTION_URBAN
    assert main(["estimate", str(DATA / "friction_urban.csv"), "--law", "paper", "--gains", "kalman"]) == 2
