"""Every vehicle preset through the toolchain (issue: any vehicle file, item 4).

Per preset, at a speed inside its own design range (:attr:`ptw_env.vehicle.Vehicle.control_range`): its LQR rider
rides the lane change without falling; the TS design certifies over its design range and the TS controller,
designed for it, tracks the lane change noise-free without falling or diverging; the diagnosis names a hidden
cause of effects.md (bank, payload, tire stiffness, gyro bias) of known size within 25 % and says
"none" on a clean ride (the robot bicycle's hidden-cause tests are in tests/test_diagnose_vehicles.py). Truth: the simulator's own effects.
"""

from __future__ import annotations

import math

import pytest

from assist.control.ts_design import design
from assist.diagnose import diagnose
from assist.evaluate import run_episode
from ptw_env.ride import ride_scenario
from ptw_env.vehicle_files import load_vehicle, vehicle_names


def _speed_kmh(v) -> float:
    lo, hi = v.control_range
    return round(3.6 * (lo + hi) / 2.0, 1)


@pytest.mark.parametrize("name", vehicle_names())
def test_each_preset_rides_designs_and_tracks(name):
    v = load_vehicle(name)
    kmh = _speed_kmh(v)
    ride = ride_scenario("double_lane_change", speed_kmh=kmh, noise_pct=0.0, seed=0, vehicle=v)
    assert not ride.fell, (name, kmh, ride.reason)
    d = design(v)
    assert d.certificate.passed and (d.ts.vmin, d.ts.vmax) == v.control_range
    ep = run_episode("ts", "double_lane_change", speed_kmh=kmh, noise_pct=0.0, seed=0, vehicle=v)
    m = ep.metrics()
    assert not m["fell"] and not m["diverged"], (name, m["end_reason"])
    assert m["roll_rmse_deg"] < 1.0, (name, m["roll_rmse_deg"])  # the controller issue's target, noise-free


EFFECTS = {
    "road_bank": lambda v: {"bank_rad": 0.04},
    "payload": lambda v: {"mass_kg": round(0.25 * v.mass, 1)},  # a quarter of the vehicle's own mass
    "tire_stiffness": lambda v: {"front_scale": 0.7, "rear_scale": 0.7},
    "gyro_bias": lambda v: {"yaw_rate_bias": 0.01},
    "none": None,
}


@pytest.mark.parametrize("cause", list(EFFECTS))
@pytest.mark.parametrize("name", ["sharp1971", "cossalter-sport-touring"])
def test_diagnose_names_the_hidden_cause_and_nothing_on_a_clean_ride(name, cause):
    """The vehicle's own hypotheses (sized by its mass, a51, steer damping, sigma) find an effect of effects.md
    hidden in a lane change ridden by that vehicle's LQR rider at mid design speed, 2 % sensor noise: the one
    cause, each parameter within 25 % of the injected change, a parameter left at nominal stays within 25 % of
    it; "none" on a clean ride. The robot bicycle's matrix is in tests/test_diagnose_vehicles.py, the
    scooter's in tests/test_diagnose.py."""
    v = load_vehicle(name)
    kmh = _speed_kmh(v)
    truth = EFFECTS[cause](v) if EFFECTS[cause] else None
    effects = {cause: truth} if truth else None
    ride = ride_scenario("double_lane_change", speed_kmh=kmh, noise_pct=2.0, seed=1, vehicle=v, effects=effects)
    assert not ride.fell
    rep = diagnose(ride.log, vehicle=v, progress=False)
    got = {c["cause"]: c["params"] for c in rep.to_json()["verdict"]["causes"]}
    if truth is None:
        assert list(got) == ["none"] and rep.explained, rep.summary()
        return
    assert list(got) == [cause], got
    nominal = {"front_scale": 1.0, "rear_scale": 1.0}
    big = max(abs(x - nominal.get(p, 0.0)) for p, x in truth.items())
    for p, x in truth.items():
        assert abs(got[cause][p] - x) <= 0.25 * (abs(x - nominal.get(p, 0.0)) or big), (p, got[cause][p], x)
    for p in got[cause]:
        if p not in truth:
            assert abs(got[cause][p] - nominal.get(p, 0.0)) <= 0.25 * big, (p, got[cause][p])
    # beats the nominal model on held-out data (a 0.01 rad/s yaw bias sits at the 2 % noise level, 0.01 rad/s:
    # its held-out gain is small, so no size is asserted for the gain, only its sign)
    assert rep.explained and rep.gain > 0.0, rep.summary()


def _slalom(v, duration_s: float, n_cones: int):
    """A slalom at mid design speed ``vm`` that asks about 0.3 g: cones ``4 vm`` apart (one every 4 s), path
    curvature amplitude ``A (pi / L)^2 = 0.3 g / vm^2`` (a sine path through the cones)."""
    from ptw_env.scenarios import make_scenario
    from ptw_env.vehicle import G

    lo, hi = v.control_range
    vm = 0.5 * (lo + hi)
    L = 4.0 * vm
    A = 0.3 * G / vm**2 / (math.pi / L) ** 2
    return make_scenario("slalom", speed_kmh=3.6 * vm, cone_spacing_m=round(L, 2), amplitude_m=round(A, 3),
                         n_cones=n_cones, run_in_s=2.0, duration_s=duration_s)


@pytest.mark.parametrize("name", [
    "reference-scooter", "sharp1971", "cossalter-sport-touring",
    pytest.param("robot-bicycle", marks=pytest.mark.xfail(strict=True, reason=(
        "measured (scripts/eval_vehicle_estimation.py, seeds 0-2): 21-30 % mean error after the drop at 5 % "
        "noise (the motorcycles: 1.5-3.4 %), 8-18 % at 1 %, 30-43 % at 2 %; noise-free it follows the drop (4-11 % "
        "on 0.1-0.3 g slaloms at 3.75 and 5.5 m/s): with noise it converges too slowly (scales 0.65-0.76 for 0.6 "
        "40 s after the drop), the bicycle's small tire forces carrying little information"))),
])
def test_estimate_recovers_a_friction_drop_on_each_preset(name):
    """The adaptive observer (Kalman vertex gains, one scale per axle) designed for the vehicle
    (:func:`assist.estimation.adaptive_design.design_for_vehicle`) follows a friction drop 1 -> 0.6 at 20 s
    on a 0.3 g slalom at mid design speed, 5 % noise, the vehicle's own LQR rider: from 15 s after the drop
    every stiffness within 3 % on average (the scooter's tolerance on its handling track, tests/test_adaptive.py)
    and never more than 12 % off (8 % there; on this slalom the scooter itself reaches 11 % over seeds 0-2),
    10 s after the drop within 10 % (as there). Truth: the simulator's stiffness history."""
    import numpy as np

    from assist.estimation.adaptive_design import AdaptiveDesignOptions, design_for_vehicle
    from assist.estimation.adaptive_observer import AdaptiveObserver
    from assist.estimation.identification import simulate_friction_drop

    v = load_vehicle(name)
    sc = _slalom(v, 60.0, 10)
    log, truth = simulate_friction_drop(sc.name, switch_s=20.0, after=0.6, noise_pct=5.0, seed=0, duration_s=60.0,
                                        speed_kmh=sc.speed_kmh, vehicle=v,
                                        scenario_options={k: getattr(sc, k) for k in
                                                          ("cone_spacing_m", "amplitude_m", "n_cones", "run_in_s")})
    assert log.meta["vehicle"] == v.name
    d = design_for_vehicle(v, AdaptiveDesignOptions(noise_pct=5.0), "kalman", log.columns["vx"])
    assert d.certificate.passed and d.model.vehicle is v
    run = AdaptiveObserver(d, parametrisation="axle").run_log(log)
    err = np.abs(run.stiffness / truth - 1.0)
    assert np.all(err[3500:].mean(axis=0) < 0.03), err[3500:].mean(axis=0)
    assert np.all(err[3500:].max(axis=0) < 0.12), err[3500:].max(axis=0)
    assert np.all(err[3000] < 0.10), err[3000]


@pytest.mark.parametrize("name", vehicle_names())
def test_risk_reads_the_friction_of_each_preset(name):
    """The risk warning's friction estimate (its default pipeline for the vehicle: Kalman observer with one
    friction scale, the vehicle's axle loads and nominal stiffnesses) on a lane change at mid design speed on a
    road of friction 0.6 (5 % noise, saturating tires, seed 3 as tests/test_risk.py): the median over the
    informed samples within 0.05 of the truth, the scooter's tolerance there, and a caution is raised."""
    import numpy as np

    from assist.risk.offline import assess_log
    from ptw_env.friction import FrictionSchedule
    from ptw_env.scenarios import make_scenario

    v = load_vehicle(name)
    sc = make_scenario("double_lane_change", speed_kmh=_speed_kmh(v), run_in_s=6.0, duration_s=20.0)
    ride = ride_scenario(sc, vehicle=v, effects="tire_saturation:mu_peak=0.9", noise_pct=5.0, seed=3,
                         friction=FrictionSchedule.constant(0.6, scaling="stiffness_and_peak"))
    assert not ride.fell
    run = assess_log(ride.log, tire="stiffness")  # the sidecar names the vehicle; the road scales the curve
    mu, inf = run.series("mu_hat"), run.series("friction_informed").astype(bool)
    assert inf.any() and abs(np.median(mu[inf]) - 0.6) < 0.05, np.median(mu[inf])
    assert "caution" in {a.level for a in run.assessments}


@pytest.mark.parametrize("name", [
    "reference-scooter", "sharp1971", "cossalter-sport-touring",
    pytest.param("robot-bicycle", marks=pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
        "measured (docs/results/risk/friction_filter/results.md): on the bicycle's lane change the lower "
        "frictions take about as much of the probability on the wet road as on the dry one: its forces tell "
        "the bend of the curve too little against its sensors' noise")))])
def test_friction_filter_tells_a_wet_road_on_each_preset(name):
    """The friction filter for the vehicle (assist.estimation.friction_imm: its plant, loads and noise) on a lane
    change at mid design speed (5 % noise, seed 3), on a road whose friction scales the tire's peak: on 0.45 the
    frictions at or below 0.7 x 0.9 take at least 0.99 of the probability, on the dry road 0.9 at most 0.3
    (docs/results/risk/friction_filter/results.md, scripts/eval_friction_filter.py). Truth: the simulator's
    friction schedule."""
    from assist.estimation.friction_imm import FrictionIMM
    from assist.risk.pipeline import output_matrix
    from ptw_env.friction import FrictionSchedule
    from ptw_env.scenarios import make_scenario

    v = load_vehicle(name)
    top = {}
    for mu in (0.9, 0.45):
        sc = make_scenario("double_lane_change", speed_kmh=_speed_kmh(v), run_in_s=6.0, duration_s=20.0)
        ride = ride_scenario(sc, vehicle=v, effects="tire_saturation:mu_peak=0.9", noise_pct=5.0, seed=3,
                             friction=FrictionSchedule.constant(mu))
        c = ride.log.columns
        Y = output_matrix(c)
        imm = FrictionIMM(vehicle=v, dt=float(ride.log.dt))
        p = []
        for k in range(len(ride.log.t)):
            imm.update(Y[k], float(c["tau"][k]), float(c["vx"][k]))
            p.append(float(imm.probabilities[imm.low].sum()))
        top[mu] = max(p[int(1.0 / ride.log.dt):])
    assert top[0.9] <= 0.3 and top[0.45] >= 0.99, top
