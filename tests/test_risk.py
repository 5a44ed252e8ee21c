"""Risk warning (assist.risk): friction mapping, excitation, formulas, hysteresis, wrapper, CLI.

Truth comes from the simulator wherever there is one: the friction schedule's
stiffness scaling, the constant-radius ride that loses grip at the safe speed,
the straight run of a ride, the true state the wrapper must not read.
"""

from __future__ import annotations

import dataclasses
import json
import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from assist.risk import (FrictionConfig, FrictionEstimate, PathAhead, RiskConfig, RiskMonitor, RiskPipeline,
                         RiskWarningWrapper, assess_log, safe_curve_speed, safe_lean_angle, stiffness_to_friction)
from assist.risk.evaluation import saturation_events, true_utilisation
from assist.risk.monitor import RiskInputError, WindowMax
from assist.risk.friction_estimate import NOMINAL_STIFFNESS as C0
from ptw_env.vehicle import REFERENCE_SCOOTER
from assist.risk.offline import replay
from assist.risk.pipeline import default_estimator
from ptw_env.env import PTWRollEnv
from ptw_env.friction import REFERENCE_FRICTION, FrictionSchedule
from ptw_env.logs import write_log
from ptw_env.ride import ride_scenario
from ptw_env.scenarios import make_scenario
from ptw_env.vehicle import G

SAT = "tire_saturation:mu_peak=0.9"


@pytest.fixture(scope="module")
def estimator():
    return default_estimator(5.0, tire="stiffness")


def _stiff() -> FrictionEstimate:
    """The friction reading of roads that scale the whole tire curve (stiffness tells the friction): the
    model these unit tests feed (their stiffness inputs stand for that road's)."""
    return FrictionEstimate(FrictionConfig(tire="stiffness"))


# ------------------------------------------------------------------ friction from stiffness
@pytest.mark.parametrize("mu", [0.3, 0.45, 0.9, 1.1])
def test_mu_hat_inverts_the_simulators_friction_scaling(mu):
    """The stiffness of the simulator's plant on a road of friction mu maps back to mu."""
    e = FrictionSchedule.constant(mu, scaling="stiffness_and_peak").effects_at(mu, SAT)
    stiff = C0 * np.array([e.value("tire_stiffness", "front_scale")] * 2 + [e.value("tire_stiffness", "rear_scale")] * 2)
    m, s = stiffness_to_friction(stiff, 0.1 * C0)
    assert m == pytest.approx(mu, rel=1e-12)
    assert s == pytest.approx(REFERENCE_FRICTION * 0.05, rel=1e-12)  # four equal, agreeing ratios: 0.1/sqrt(4)


def test_mu_hat_weights_by_precision_and_counts_disagreement():
    stiff = C0 * np.array([0.5, 1.0, 0.5, 1.0])
    std = C0 * np.array([0.01, 1.0, 0.01, 1.0])  # the alpha stiffnesses are far better known
    m, s = stiffness_to_friction(stiff, std)
    assert m == pytest.approx(0.9 * 0.5, abs=0.01)
    agree, s_agree = stiffness_to_friction(C0 * 0.5, std)
    assert s > s_agree  # disagreeing ratios widen the uncertainty


@pytest.mark.parametrize("bad", [np.ones(3), np.array([1.0, np.nan, 1.0, 1.0]), -C0])
def test_mu_hat_refuses_bad_stiffness(bad):
    with pytest.raises(ValueError, match="stiffness"):
        stiffness_to_friction(bad, C0)


def test_uncertainty_grows_while_not_excited_and_the_estimate_is_held():
    """The lateral gate, for an estimator that drifts when unexcited (excitation_min = 1 m/s^2)."""
    fe = FrictionEstimate(FrictionConfig(walk=0.05, excitation_min=1.0, tire="stiffness"))
    for k in range(100):  # informed cornering at scale 0.5
        st = fe.update(0.01 * k, 0.5 * C0, 0.05 * C0, ay=3.0)
    assert st.informed and st.mu_hat == pytest.approx(0.45)
    s0 = st.mu_std
    stds = []
    for k in range(100, 1100):  # straight: the estimator drifts to nominal but must not be believed
        drift = min(1.0, 0.5 + 0.5 * max(k - 150, 0) / 300)  # from 0.5 s on: the excitation filter has decayed
        st = fe.update(0.01 * k, drift * C0, 0.05 * C0, ay=0.0)
        if k >= 200:
            stds.append(st.mu_std)
    assert not st.informed and "not enough lateral excitation" in st.status
    assert st.mu_hat == pytest.approx(0.45) and st.mu_raw == pytest.approx(0.9)
    assert np.all(np.diff(stds) >= 0) and stds[-1] == pytest.approx(math.sqrt(s0**2 + 0.05**2 * st.since_informed_s))


def test_straight_riding_is_used_only_once_the_estimate_is_sure(estimator):
    """A ride's straight run-in on a road of friction 0.6 (truth): at first the estimate is too uncertain
    and the prior 0.9 is kept, saying so; on the straight the steering response to the rider's torque
    then informs it, and the status says it rests on little lateral acceleration; it is honest there
    (within 3 sigma of the truth at 95 % of the samples, not a guess); the lane change informs it by
    lateral acceleration, and it stays near the truth."""
    sc = make_scenario("double_lane_change", run_in_s=6.0, duration_s=20.0)
    ride = ride_scenario(sc, effects=SAT, noise_pct=5.0, seed=3, friction=FrictionSchedule.constant(0.6, scaling="stiffness_and_peak"))
    run = assess_log(ride.log, RiskPipeline(estimator, tire="stiffness"))
    t = run.t
    straight = t < 5.5
    true_ay = np.abs(ride.log.columns["x_Fyf"] + ride.log.columns["x_Fyr"]) / REFERENCE_SCOOTER.mass
    assert true_ay[straight].max() < 0.5  # truth: really straight (rider noise only)
    a0 = run.assessments[0]
    assert not a0.friction_informed and "not enough excitation" in a0.friction_status and a0.mu_hat == 0.9
    inf = run.series("friction_informed").astype(bool)
    on_straight = inf & straight
    assert on_straight.any()
    assert all("little lateral acceleration" in a.friction_status
               for a, s in zip(run.assessments, on_straight) if s)
    mu, sd = run.series("mu_hat"), run.series("mu_std")
    assert np.mean(np.abs(mu[on_straight] - 0.6) <= 3 * sd[on_straight]) >= 0.95
    turning = [a for a, s in zip(run.assessments, ~straight) if s and a.friction_status.startswith("informed (")]
    assert turning  # the lane change informs it by lateral acceleration
    assert abs(np.median(mu[inf]) - 0.6) < 0.05


# ------------------------------------------------------------------ formulas
def test_safe_lean_and_speed_formulas():
    assert safe_lean_angle(0.9) == pytest.approx(math.atan(0.9))
    assert safe_lean_angle(0.5, 0.8) == pytest.approx(math.atan(0.4))
    assert safe_curve_speed(0.45, 0.02) == pytest.approx(math.sqrt(0.45 * G / 0.02))
    assert safe_curve_speed(0.45, -0.02, margin=0.8) == pytest.approx(math.sqrt(0.8 * 0.45 * G / 0.02))
    assert safe_curve_speed(0.9, 0.0) == math.inf


def test_grip_runs_out_at_the_safe_speed_in_the_simulator():
    """Constant-radius turn, accelerating, road friction 0.5: the tires saturate (|F_ss| >= 0.95 Fmax)
    near sqrt(mu g / kappa), and at a lean of at least atan(mu) (the point-mass formula is on the safe
    side: this model's steady turn needs sin(phi) ~ a_y / (0.98 g) rather than tan(phi) = a_y / g)."""
    mu, R = 0.5, 100.0
    sc = make_scenario("constant_radius", radius_m=R, v_start_kmh=50, v_end_kmh=95, accel_mps2=1.0, duration_s=25)
    sched = FrictionSchedule.constant(mu)
    r = ride_scenario(sc, effects=SAT, noise_pct=0.0, seed=0, friction=sched, rider_noise_nm=0.0)
    c = r.log.columns
    ev = saturation_events(r.log.t, true_utilisation(r.states, c["vx_true"], c["mu_true"], sched))
    assert ev.size >= 1
    k = int(np.searchsorted(r.log.t, ev[0]))
    v_safe = safe_curve_speed(mu, 1.0 / R)
    assert 0.9 <= c["vx_true"][k] / v_safe <= 1.05
    assert abs(r.states[k, 0]) >= safe_lean_angle(mu) - math.radians(0.5)
    assert c["vx_true"][: k - 200].max() < v_safe  # no saturation while clearly below the safe speed


# ------------------------------------------------------------------ hysteresis
def _levels(u: np.ndarray, cfg: RiskConfig) -> np.ndarray:
    """Levels for a front-tire utilisation ``u``; the riding-style caution is switched off (it would see
    the high lateral demand itself and hold a caution, which is not what these tests look at)."""
    mon = RiskMonitor(dataclasses.replace(cfg, style_enter=1e3, style_exit=1e3), friction=_stiff())
    fz = mon.fz
    out = []
    for k, uk in enumerate(u):  # informed, mu_hat = 0.45; front force sets the utilisation
        a = mon.update(0.01 * k, 0.5 * C0, 0.02 * C0, vx=15.0, ay=3.0, forces=(uk * 0.45 * fz[0], 0.0))
        out.append(a.level_code)
    return np.array(out)


def test_no_chattering_around_a_threshold():
    t = np.arange(2000) * 0.01
    rng = np.random.default_rng(0)
    c_in = RiskConfig().caution_enter
    u = c_in + 0.05 * np.sin(2 * np.pi * 3.0 * t) + 0.01 * rng.normal(size=t.size)  # around caution_enter
    u[:100] = 0.3  # starts safe
    lv = _levels(u, RiskConfig())
    assert np.count_nonzero(np.diff(lv)) == 1 and lv[-1] == 1  # enters once, stays (exit 0.1 lower)
    plain = _levels(u, RiskConfig(caution_exit=c_in, danger_exit=1.0, min_dwell_s=0.0))
    assert np.count_nonzero(np.diff(plain)) > 50  # without hysteresis it would chatter


def test_dwell_limits_changes_when_the_signal_crosses_both_thresholds():
    t = np.arange(3000) * 0.01
    c = RiskConfig(min_dwell_s=1.0)
    u = 0.5 * (c.caution_enter + c.caution_exit) + 0.15 * np.sign(np.sin(2 * np.pi * 4.0 * t))  # across both, 4 Hz
    lv = _levels(u, c)
    changes = np.flatnonzero(np.diff(lv))
    drops = [k for k in changes if lv[k + 1] < lv[k]]
    assert 10 <= len(drops) <= 30  # it does drop, at most once per second of the 30 s
    enter = np.flatnonzero(np.diff(lv) > 0)
    for k in drops:  # every drop comes at least the dwell time after the level was entered
        assert (k - enter[enter <= k].max()) * 0.01 >= 1.0 - 1e-9


def test_levels_and_reasons_follow_the_risk_index():
    mon = RiskMonitor(friction=_stiff())
    fz = mon.fz
    path = PathAhead(np.array([0.0, 30.0, 60.0]), np.array([0.0, 1 / 80, 1 / 80]))
    a = mon.update(0.0, 0.5 * C0, 0.02 * C0, vx=12.0, ay=2.0, forces=(0.2 * fz[0], 0.2 * fz[1]), path=path)
    assert a.level == "safe" and a.reason.startswith("safe:")
    # the rider has been cornering at 0.5 g on a dry road; the grip then drops to 0.45 on a straight: the
    # usual riding would need 111 % of it (> the 70 % margin): caution at once, no curve in sight yet
    style = RiskMonitor(friction=_stiff())
    for k in range(600):  # 3 s of cornering at 0.5 g, then 3 s straight, on the dry road
        style.update(0.01 * k, C0, 0.02 * C0, vx=15.0, ay=0.5 * G if k < 300 else 0.0, forces=None, path=None)
    assert style.last.level == "safe" and style.last.usual_demand == pytest.approx(0.5, rel=0.02)
    b = style.update(6.0, 0.5 * C0, 0.02 * C0, vx=15.0, ay=0.0, forces=None, path=None)
    assert b.level == "caution" and "low for your riding" in b.reason and "0.50 g" in b.reason
    assert b.utilisation_usual == pytest.approx(b.usual_demand / b.mu_hat)
    for k in range(1, 6001):  # 60 s of gentle riding later the old style is forgotten and the caution lifts
        b = style.update(6.0 + 0.01 * k, 0.5 * C0, 0.02 * C0, vx=15.0, ay=0.0, forces=None, path=None)
    assert b.level == "safe"
    a = mon.update(0.01, 0.5 * C0, 0.02 * C0, vx=12.0, ay=2.0, forces=(0.4 * fz[0], 0.2 * fz[1]), path=path)
    assert a.level == "caution" and "front tire uses 89 %" in a.reason
    fast = PathAhead(np.array([0.0, 5.0, 10.0]), np.array([0.0, 1 / 40, 1 / 40]))
    a = mon.update(0.02, 0.5 * C0, 0.02 * C0, vx=16.0, ay=2.0, forces=(0.1 * fz[0], 0.1 * fz[1]), path=fast)
    assert a.level == "danger" and "next curve (R 40 m" in a.reason and "safe speed" in a.reason
    assert a.safe_speed_next_curve == pytest.approx(safe_curve_speed(0.45, 1 / 40, RiskConfig().margin), rel=1e-3)


def test_a_read_drop_of_the_grip_is_a_caution_whatever_the_tires_use():
    """The rider rides gently (0.1 g, light tire forces) on a road read at 0.9; the grip read then drops. Below
    the margin's share of the grip ridden on (0.7 x 0.9 = 0.63) it is a caution at once, in its own words, though
    neither the utilisation nor the rider's usual cornering reach a threshold; a drop to 0.7 is not. After
    style_window_s on the lower road the earlier grip is forgotten and the caution lifts."""
    cfg = RiskConfig()
    for mu_new, level in ((0.45, "caution"), (0.7, "safe")):
        mon = RiskMonitor(friction=_stiff())
        fz = mon.fz
        for k in range(300):  # 3 s on the dry road
            a = mon.update(0.01 * k, C0, 0.02 * C0, vx=15.0, ay=0.1 * G, forces=(0.1 * fz[0], 0.1 * fz[1]))
        assert a.level == "safe" and a.grip_before == pytest.approx(0.9)
        b = mon.update(3.0, mu_new / 0.9 * C0, 0.02 * C0, vx=15.0, ay=0.1 * G, forces=(0.1 * fz[0], 0.1 * fz[1]))
        assert b.level == level and b.risk_index < cfg.caution_enter and b.utilisation_usual < cfg.margin
        assert b.grip_drop_index == pytest.approx(cfg.margin * 0.9 / (b.mu_hat + cfg.drop_sigmas * b.mu_std))
        assert ("the grip dropped" in b.reason and "down from 0.90" in b.reason) == (level == "caution")
    for k in range(1, round(cfg.style_window_s / 0.01) + 2):
        b = mon.update(3.0 + 0.01 * k, 0.45 / 0.9 * C0, 0.02 * C0, vx=15.0, ay=0.1 * G, forces=None)
    assert b.level == "safe" and b.grip_before == pytest.approx(b.mu_hat) and b.grip_drop_index < 1.0


@given(st.lists(st.tuples(st.floats(0.0, 2.0), st.floats(-10.0, 10.0)), min_size=1, max_size=60),
       st.floats(0.0, 3.0))
def test_window_max_is_the_largest_value_of_its_window(steps, window):
    """WindowMax against the brute force over all pushes of ``[t - window, t]``."""
    w, t, seen = WindowMax(window), 0.0, []
    for dt, v in steps:
        t += dt
        seen.append((t, v))
        assert w.push(t, v) == max(x for s_, x in seen if s_ >= t - window)


@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf, "60", True])
def test_window_max_refuses_a_window_that_is_not_a_duration(bad):
    with pytest.raises(RiskInputError, match="WindowMax window"):
        WindowMax(bad)


def test_a_warning_held_down_one_level_says_why_in_its_own_words():
    """danger -> caution because the grip was low a moment ago: the level and its reason agree."""
    mon = RiskMonitor(friction=_stiff())
    kappa = 1.1 * 0.45 * G / 20.0**2  # the curve now needs 110 % of a 0.45 grip at 20 m/s
    path = PathAhead(np.array([0.0, 40.0]), np.array([kappa, kappa]))
    levels = []
    for k in range(25):  # grip estimate 0.45, then 0.6, then 0.9; light tire forces, no style caution
        s = 0.5 if k == 0 else (2 / 3 if k <= 6 else 1.0)
        a = mon.update(0.1 * k, s * C0, 0.02 * C0, vx=20.0, ay=0.5, forces=(50.0, 50.0), path=path)
        levels.append(a.level)
        assert a.reason.startswith(a.level + ":"), (0.1 * k, a.level, a.reason)
    assert levels[0] == "danger" and "caution" in levels and levels[-1] == "safe"
    assert levels.index("caution") > levels.index("danger")


def test_monitor_refuses_bad_input_with_a_clear_message():
    mon = RiskMonitor(friction=_stiff())
    with pytest.raises(ValueError, match="vx"):
        mon.update(0.0, C0, C0 * 0.1, vx=-3.0, ay=0.0)
    with pytest.raises(ValueError, match="forces"):
        mon.update(0.0, C0, C0 * 0.1, vx=10.0, ay=0.0, forces=(1.0, np.nan))
    with pytest.raises(ValueError, match="thresholds"):
        RiskConfig(caution_enter=1.2)
    with pytest.raises(ValueError, match="distance"):
        PathAhead(np.array([5.0, 1.0]), np.zeros(2))


# ------------------------------------------------------------------ wrapper
class _Corrupt(gym.Wrapper):
    """Replaces every piece of truth in info by garbage: the risk wrapper must not notice."""

    def _bad(self, info):
        info = dict(info)
        info["state"] = np.full(8, 1e9)
        info["measurement"] = np.full(7, -1e9)
        info["friction"] = 5.0
        return info

    def reset(self, **kw):
        obs, info = self.env.reset(**kw)
        return obs, self._bad(info)

    def step(self, a):
        obs, r, te, tr, info = self.env.step(a)
        return obs, r, te, tr, self._bad(info)


def _wrapped(estimator, corrupt: bool):
    base = PTWRollEnv("double_lane_change", noise_pct=5.0, effects=SAT, friction=FrictionSchedule.constant(0.6))
    return RiskWarningWrapper(_Corrupt(base) if corrupt else base, RiskPipeline(estimator))


def test_wrapper_uses_the_observation_only(estimator):
    runs = []
    for corrupt in (False, True):
        env = _wrapped(estimator, corrupt)
        env.reset(seed=4)
        rng = np.random.default_rng(1)
        seq = []
        for k in range(300):
            obs, _, te, tr, info = env.step(np.array([3.0 * math.sin(k / 15) + rng.normal()], dtype=np.float32))
            seq.append((info["risk"]["mu_hat"], info["risk"]["utilisation_front"], info["risk"]["level"]))
        runs.append(seq)
    assert runs[0] == runs[1]


def test_wrapper_adds_the_assessment_and_passes_check_env(estimator):
    from gymnasium.utils.env_checker import check_env

    env = _wrapped(estimator, False)
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert "risk" not in info
    obs2, r, te, tr, info = env.step(np.zeros(1, dtype=np.float32))
    keys = {"level", "reason", "mu_hat", "mu_std", "utilisation_front", "utilisation_rear", "utilisation_ahead",
            "max_safe_lean", "safe_speed_next_curve", "friction_status"}
    assert keys <= set(info["risk"]) and info["risk"]["level"] in ("safe", "caution", "danger")
    json.dumps(info["risk"], allow_nan=False)
    assert info["risk"]["t"] == 0.0 and env.last_assessment.t == 0.0


# ------------------------------------------------------------------ offline + CLI
@pytest.fixture(scope="module")
def wet_log(tmp_path_factory):
    """A short simulated ride onto a wet patch, with the route's curvature as the map."""
    sc = make_scenario("slalom", duration_s=16.0, n_cones=3)
    sched = FrictionSchedule.patch(start=60.0, mu_before=0.9, mu_patch=0.45, ramp=2.0, scaling="stiffness_and_peak")
    r = ride_scenario(sc, effects=SAT, noise_pct=5.0, seed=2, friction=sched)
    r.log.columns["kappa"] = np.asarray(sc.profile(0.01).kappa[: len(r.log.t)])
    p = tmp_path_factory.mktemp("risk") / "wet.csv"
    write_log(p, r.log, meta=r.log.meta)
    return p


def test_cli_json_holds_the_cli_md_keys(wet_log, tmp_path, capsys):
    from assist.cli import main

    out = tmp_path / "risk.json"
    fig = tmp_path / "risk.png"
    assert main(["risk", str(wet_log), "--json", str(out), "--plot", str(fig)]) == 0
    js = json.loads(out.read_text())
    assert isinstance(js["mu_hat_final"], float) and isinstance(js["warnings"], list)
    for w in js["warnings"]:
        assert {"t", "level", "reason"} <= set(w) and w["level"] in ("caution", "danger") and w["reason"]
    assert js["path_source"] == "kappa column"
    assert js["truth"]["mu_final"] == pytest.approx(0.45)
    assert fig.stat().st_size > 10_000
    text = capsys.readouterr().out
    assert "mu_hat" in text and "warning(s)" in text
    # refuses to overwrite
    assert main(["risk", str(wet_log), "--json", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err


@pytest.mark.parametrize("content, where", [
    ("t,tau,vx,delta,delta_rate,yaw_rate,roll_rate\n0,0,10,0,0,0,0\n", "ay"),
    ("t,tau,vx,delta,delta_rate,yaw_rate,roll_rate,ay\n" + "".join(
        f"{k / 100},0,10,0,0,{'x' if k == 7 else 0},0,0\n" for k in range(200)), "line 9"),
])
def test_cli_bad_log_one_line_exit_2(tmp_path, capsys, content, where):
    from assist.cli import main

    p = tmp_path / "bad.csv"
    p.write_text(content)
    assert main(["risk", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ptw-assist risk: error:") and where in err[0]


def test_offline_replay_gives_the_same_assessments(wet_log, estimator):
    from ptw_env.logs import read_log

    run = assess_log(read_log(wet_log), RiskPipeline(estimator, tire="stiffness"))
    again = replay(run, RiskMonitor(friction=_stiff()))
    assert [a.level for a in again.assessments] == [a.level for a in run.assessments]
    np.testing.assert_array_equal(again.series("risk_index"), run.series("risk_index"))
    assert run.level_code.max() > 0
    deaf = replay(run, RiskMonitor(friction=_stiff(), config=RiskConfig(
        caution_enter=1e3, caution_exit=1e3, danger_enter=1e3, danger_exit=1e3, style_enter=1e3, style_exit=1e3,
        confirm_sigmas=0.0)))
    assert deaf.level_code.max() == 0  # the replay really uses the other monitor


@pytest.mark.parametrize("value, words", [("3", "degrees?"), ("nan", "not a road bank"), ("x", "not a road bank")])
def test_cli_road_bank_must_be_an_angle_in_rad(tmp_path, capsys, value, words):
    from assist.cli import main

    with pytest.raises(SystemExit) as e:
        main(["risk", str(tmp_path / "any.csv"), "--road-bank", value])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "--road-bank" in err[-1] and words in err[-1], err


@pytest.fixture(scope="module")
def banked_log():
    """A 90 s urban ride, dry (friction 0.9), 5 % noise, on a 0.03 rad road bank; the rider holds the line
    (on straights the yaw rate is zero, which the gyro-bias estimate relies on)."""
    return ride_scenario("urban", effects={"road_bank": {"bank_rad": 0.03}}, noise_pct=5.0, seed=2,
                         hold_line=True).log


def test_road_bank_estimated_on_line_keeps_the_friction_estimate(banked_log):
    """``road_bank="auto"`` (default): the IMU's bank estimate (:class:`BankEstimate`) settles at the true bank,
    and the friction estimate stays near 0.9, where the level-road model is biased by the bank."""
    from assist.risk.pipeline import default_estimator

    level = assess_log(banked_log, RiskPipeline(default_estimator(5.0, tire="stiffness"), road_bank=None,
                                                tire="stiffness"))
    pipe = RiskPipeline(default_estimator(5.0, tire="stiffness"), tire="stiffness")  # road_bank="auto", the default
    pipe.bank_estimate.record = True
    auto = assess_log(banked_log, pipe)
    b = np.asarray(pipe.bank_estimate.history)
    assert np.median(b[3000:]) == pytest.approx(0.03, abs=0.004)
    half = len(banked_log.t) // 2
    mu_level, mu_auto = (np.median(r.series("mu_hat")[half:]) for r in (level, auto))
    assert abs(mu_auto - 0.9) < 0.05, mu_auto
    assert abs(mu_level - 0.9) > abs(mu_auto - 0.9) + 0.03, (mu_level, mu_auto)


def test_road_bank_needs_a_settable_estimator():
    class Plain:
        stiffness = C0
        stiffness_std = 0.01 * C0

        def update(self, y, tau, vx):
            pass

        def reset(self):
            pass

    assert RiskPipeline(Plain()).bank_estimate is None  # the default "auto" leaves it as it is
    with pytest.raises(TypeError, match="settable road_bank"):
        RiskPipeline(Plain(), road_bank=0.02)
    with pytest.raises(ValueError, match="'auto'"):
        RiskPipeline(road_bank="automatic")
