"""Every vehicle preset through the toolchain (issue: any vehicle file, item 4).

Per preset, at a speed inside its own design range (:attr:`ptw_env.vehicle.Vehicle.control_range`): its LQR rider
rides the lane change without falling; the TS design certifies over its design range and the TS controller,
designed for it, tracks the lane change noise-free without falling or diverging; the diagnosis names a hidden
cause of effects.md (bank, payload, tire stiffness, gyro bias) of known size within 25 % and says
"none" on a clean ride (the robot bicycle's hidden-cause tests are in tests/test_diagnose_vehicles.py). Truth: the simulator's own effects.
"""

from __future__ import annotations

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
