"""Time/distance-varying road friction in the simulator (ptw_env.friction, env option ``friction=``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ptw_env.dynamics import compile_plant
from ptw_env.env import PTWRollEnv
from ptw_env.friction import (REFERENCE_FRICTION, FrictionPlants, FrictionSchedule, FrictionScheduleError)
from ptw_env.ride import ride_scenario
from ptw_env.sensors import SensorConfig

SAT = "tire_saturation:mu_peak=0.9"


def test_schedule_interpolates_and_holds_outside():
    f = FrictionSchedule(((10.0, 0.9), (20.0, 0.5), (30.0, 0.7)), by="time")
    assert f.mu(t=0.0) == 0.9 and f.mu(t=40.0) == 0.7
    assert f.mu(t=15.0) == pytest.approx(0.7)
    assert f.mu(t=25.0) == pytest.approx(0.6)
    np.testing.assert_allclose(f.along(np.array([5.0, 15.0, 35.0]), np.zeros(3)), [0.9, 0.7, 0.7])


def test_patch_with_length_returns_to_the_surrounding_friction():
    f = FrictionSchedule.patch(start=50.0, mu_before=0.9, mu_patch=0.3, length=20.0, ramp=2.0)
    assert [f.mu(s=x) for x in (0.0, 51.0, 60.0, 71.0, 200.0)] == pytest.approx([0.9, 0.6, 0.3, 0.6, 0.9])


@pytest.mark.parametrize("bad", [
    dict(points=()), dict(points=((0.0, 0.9), (0.0, 0.5))), dict(points=((0.0, 0.01),)),
    dict(points=((0.0, 0.9),), by="lap"), dict(points=((math.nan, 0.9),)), dict(points=(("a", 0.9),)),
])
def test_bad_schedules_are_refused_with_the_reason(bad):
    with pytest.raises(FrictionScheduleError):
        FrictionSchedule(**bad)


def test_schedule_asks_for_the_variable_it_is_indexed_by():
    with pytest.raises(FrictionScheduleError, match="distance"):
        FrictionSchedule.constant(0.9).mu(t=1.0)


def test_effects_scale_stiffness_and_mu_peak_together_in_the_earlier_model():
    f = FrictionSchedule.constant(0.45, scaling="stiffness_and_peak")
    e = f.effects_at(0.45, [SAT, "tire_stiffness:front_scale=0.8"])
    assert e.value("tire_stiffness", "front_scale") == pytest.approx(0.4)
    assert e.value("tire_stiffness", "rear_scale") == pytest.approx(0.5)
    assert e.value("tire_saturation", "mu_peak") == pytest.approx(0.45)
    # linear tires stay linear: only the stiffness follows the friction
    assert not f.effects_at(0.45).has("tire_saturation")


def test_peak_scaling_keeps_the_stiffness_and_gives_linear_tires_a_peak():
    f = FrictionSchedule.constant(0.45)
    assert f.scaling == "peak"
    e = f.effects_at(0.45, [SAT, "tire_stiffness:front_scale=0.8"])
    assert e.value("tire_stiffness", "front_scale") == pytest.approx(0.8)  # the tire's own, untouched
    assert e.value("tire_stiffness", "rear_scale") == pytest.approx(1.0)
    assert e.value("tire_saturation", "mu_peak") == pytest.approx(0.45)
    assert f.effects_at(0.45).value("tire_saturation", "mu_peak") == pytest.approx(0.45)
    with pytest.raises(FrictionScheduleError, match="scaling"):
        FrictionSchedule.constant(0.45, scaling="both")


def test_whole_tire_curve_scales_with_friction_in_the_earlier_model():
    """Stiffness and peak scaled together: F_ss at any slip is mu/mu_ref times the reference road's."""
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, [0.2, 0.05, 0.5, 0.3, 0.3, 0.5, 0.0, 0.0], size=(200, 8))
    fp = FrictionPlants(FrictionSchedule.constant(0.9, scaling="stiffness_and_peak"), effects=SAT)
    ref = fp.plant(REFERENCE_FRICTION).steady_tire_force(x, 15.0)
    for mu in (0.3, 0.45, 0.7):
        np.testing.assert_allclose(fp.plant(mu).steady_tire_force(x, 15.0), mu / REFERENCE_FRICTION * ref,
                                   rtol=1e-9, atol=1e-9)


def test_peak_scaling_keeps_the_small_slip_slope_and_lowers_the_peak_to_mu_fz():
    """The wet road of Pacejka's brush model / Magic Formula (friction.py): same slope at zero slip on
    every road, force bounded by mu Fz, and at |F| = 0.2 Fz the secant is tanh(x)/x of the road's peak."""
    fp = FrictionPlants(FrictionSchedule.constant(0.9), effects=SAT)
    tires = fp.plant(0.9).vehicle.tires
    fz = np.array([tires.Fzf, tires.Fzr])
    x = np.zeros((3, 8))
    x[:, 2] = [1e-4, 1.0, 10.0]  # lateral velocity only: the same side slip on both axles [m/s at 15 m/s]
    lin_f = compile_plant(None, None).steady_tire_force(x, 15.0)  # the linear tire
    for mu in (0.9, 0.45, 0.2):
        f = fp.plant(mu).steady_tire_force(x, 15.0)
        np.testing.assert_allclose(f[0], lin_f[0], rtol=1e-6)  # small slip: the linear tire's force
        assert np.all(np.abs(f[2]) <= mu * fz + 1e-9) and np.all(np.abs(f[2]) >= 0.99 * mu * fz)
    # the secant at |F| = 0.2 Fz: 1 - tanh(x)/x for x = atanh(0.2/mu)
    for mu, want in ((0.9, 0.0167), (0.45, 0.0697)):
        xx = np.arctanh(0.2 / mu)
        assert 1.0 - 0.2 / mu / xx == pytest.approx(want, abs=5e-4)


def test_schedule_json_round_trip_and_old_sidecars():
    f = FrictionSchedule.patch(start=10.0, mu_before=0.9, mu_patch=0.45, ramp=2.0)
    assert FrictionSchedule.from_json(f.to_json()) == f
    old = {"by": "distance", "mu_ref": 0.9, "points": [[10.0, 0.9], [12.0, 0.45]]}  # written before 'scaling'
    assert FrictionSchedule.from_json(old).scaling == "stiffness_and_peak"
    with pytest.raises(FrictionScheduleError):
        FrictionSchedule.from_json({"by": "distance"})


def test_plants_are_cached_per_quantised_value():
    fp = FrictionPlants(FrictionSchedule.constant(0.9), effects=SAT)
    assert fp.stepper(0.45) is fp.stepper(0.4502)
    assert fp.stepper(0.45) is not fp.stepper(0.46)


def _states(env, steps, tau=2.0):
    env.reset(seed=0, options={"x0": np.zeros(8)})
    out, mus = [], []
    for _ in range(steps):
        _, _, term, trunc, info = env.step(np.array([tau], dtype=np.float32))
        out.append(info["state"])
        mus.append(info.get("friction"))
        if term or trunc:
            break
    return np.array(out), mus


def test_env_with_a_time_step_in_friction_matches_the_plants_swapped_by_hand():
    """Truth of the env option: before the switch the nominal plant, after it the wet plant."""
    quiet = SensorConfig.noiseless()
    sched = FrictionSchedule(((0.995, 0.9), (1.0, 0.45)), by="time",
                             scaling="stiffness_and_peak")  # a step at t = 1 s
    env = PTWRollEnv("double_lane_change", sensors=quiet, effects=SAT, friction=sched, init_roll_deg=0.0)
    X, mus = _states(env, 200)
    assert mus[0] == 0.9 and mus[-1] == 0.45
    dry = PTWRollEnv("double_lane_change", sensors=quiet, effects=SAT, init_roll_deg=0.0)
    Xd, _ = _states(dry, 200)
    np.testing.assert_array_equal(X[:100], Xd[:100])  # identical until the switch
    assert np.max(np.abs(X[150:, 7] - Xd[150:, 7])) > 1.0  # then the rear force differs (halved stiffness)
    wet = PTWRollEnv("double_lane_change", sensors=quiet,
                     effects=[SAT.replace("0.9", "0.45"), "tire_stiffness:front_scale=0.5,rear_scale=0.5"],
                     init_roll_deg=0.0)
    wet.reset(seed=0, options={"x0": X[99]})
    x = X[99].copy()
    for k in range(100, 150):
        _, _, _, _, info = wet.step(np.array([2.0], dtype=np.float32))
        x = info["state"]
    np.testing.assert_allclose(x, X[149], rtol=1e-12, atol=1e-12)


def test_ride_log_records_true_friction_and_the_schedule():
    sched = FrictionSchedule.patch(start=100.0, mu_before=0.9, mu_patch=0.5, ramp=5.0)
    r = ride_scenario("double_lane_change", effects=SAT, seed=1, friction=sched, noise_pct=5.0)
    mu = r.log.columns["mu_true"]
    s = np.concatenate(([0.0], np.cumsum(r.log.columns["vx_true"][:-1] * 0.01)))
    np.testing.assert_allclose(mu, sched.along(r.log.t, s), atol=2e-3)
    assert r.log.meta["truth"]["friction"]["points"][0] == [100.0, 0.9]
    plain = ride_scenario("double_lane_change", seed=1, noise_pct=5.0)
    assert "mu_true" not in plain.log.columns and "friction" not in plain.log.meta["truth"]


def test_env_refuses_a_friction_that_is_not_a_schedule():
    with pytest.raises(ValueError, match="FrictionSchedule"):
        PTWRollEnv("double_lane_change", friction=0.5)


def test_compile_plant_matches_effects_at():
    f = FrictionSchedule.constant(0.6)
    p = FrictionPlants(f, effects=SAT).plant(0.6)
    q = compile_plant(None, f.effects_at(0.6, SAT))
    np.testing.assert_array_equal(p.W, q.W)
    np.testing.assert_allclose(p.fmax, 0.6 * np.array([p.vehicle.tires.Fzf, p.vehicle.tires.Fzr]))
