"""Every vehicle preset through the toolchain (issue: any vehicle file, item 4).

Per preset, at a speed inside its own design range (:attr:`ptw_env.vehicle.Vehicle.control_range`): its LQR rider
rides the lane change without falling; the TS design certifies over its design range and the TS controller,
designed for it, tracks the lane change noise-free without falling or diverging; the diagnosis names a hidden
road bank of known size within 25 % and says "none" on a clean ride (the robot bicycle's hidden-cause tests are in
tests/test_diagnose_vehicles.py). Truth: the simulator's own effects.
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


@pytest.mark.parametrize("name", ["sharp1971", "cossalter-sport-touring"])
def test_diagnose_names_a_hidden_bank_and_nothing_on_a_clean_ride(name):
    v = load_vehicle(name)
    kmh = _speed_kmh(v)
    bank = 0.04
    hidden = ride_scenario("double_lane_change", speed_kmh=kmh, noise_pct=2.0, seed=1, vehicle=v,
                           effects={"road_bank": {"bank_rad": bank}})
    rep = diagnose(hidden.log, vehicle=v, progress=False)
    causes = {c["cause"]: c["params"] for c in rep.to_json()["verdict"]["causes"]}
    assert "road_bank" in causes, causes
    assert abs(causes["road_bank"]["bank_rad"] / bank - 1.0) <= 0.25, causes
    clean = ride_scenario("double_lane_change", speed_kmh=kmh, noise_pct=2.0, seed=2, vehicle=v)
    rep = diagnose(clean.log, vehicle=v, progress=False)
    assert [c["cause"] for c in rep.to_json()["verdict"]["causes"]] == ["none"], rep.summary()
