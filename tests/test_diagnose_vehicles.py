"""The diagnosis on vehicles other than the reference scooter (issue: any vehicle file).

Independent references: the vehicle's own matrices (mass, a51, e66, a62, a66, a77), its
eigenvalues computed here with numpy, the sidecars of the real robot-bicycle rides, and
hidden effects of known size in simulated bicycle rides.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from assist.diagnose import diagnose
from assist.diagnose.data import make_windows
from assist.diagnose.params import CAUSES, REFERENCE, param_set
from assist.diagnose.replay import EIG_STEP, Replay
from ptw_env.logs import read_log
from ptw_env.ride import ride_scenario
from ptw_env.scenarios import make_scenario
from ptw_env.sensors import DEFAULT_NOISE_STD
from ptw_env.vehicle import REFERENCE_SCOOTER
from ptw_env.vehicle_files import VehicleFileError, load_vehicle, vehicle_of_log, vehicle_names

from conftest import SHARED

BIKE_DIR = SHARED / "data" / "robot_bicycle"
REAL_RUNS = sorted(BIKE_DIR.glob("rb_*.csv"))


@pytest.fixture(scope="module")
def bike():
    return load_vehicle("robot-bicycle")


def test_robot_bicycle_is_a_preset_and_the_sidecar_spelling_works(bike):
    assert "robot-bicycle" in vehicle_names()
    assert load_vehicle("robot_bicycle").identity()["model_sha256"] == bike.identity()["model_sha256"]
    # the preset is the shared file's vehicle (same numbers, only the name is spelled as a preset)
    shared = load_vehicle(BIKE_DIR / "robot_bicycle.toml")
    assert shared.identity()["model_sha256"] != "" and np.array_equal(shared.A1, bike.A1)
    assert np.array_equal(shared.E, bike.E) and shared.mass == bike.mass == pytest.approx(37.0)


def test_hypotheses_are_sized_by_the_vehicle(bike):
    """Payload in fractions of M, roll moment of a51, damping of the steer's critical damping,
    relaxation length of sigma; the scooter keeps the ranges the diagnosis was built with."""
    for v, ps in ((REFERENCE_SCOOTER, REFERENCE), (bike, param_set(bike))):
        by = {(p.cause, p.name): p for p in ps.params}
        M, a51 = v.mass, v.A0[4, 0]
        c = 2 * math.sqrt(v.E[5, 5] * abs(v.A0[5, 1]))
        sigma = -1.0 / v.A1[6, 6]
        assert by["payload", "mass_kg"].hi == pytest.approx(1.3 * M)
        assert by["payload", "mass_kg"].lo == pytest.approx(-0.4 * M)
        assert by["roll_moment_offset", "moment_nm"].hi == pytest.approx(0.24 * a51)
        assert by["steer_damping", "damping_nms"].nominal == pytest.approx(-v.A0[5, 5])  # its own damper
        assert by["steer_damping", "damping_nms"].hi == pytest.approx(6.1 * c)
        assert by["relaxation_length", "sigma_m"].nominal == pytest.approx(sigma)
        for cause, axes in ps.grids.items():  # no grid point is the nominal model or out of bounds
            for i, axis in zip(CAUSES[cause], axes):
                assert all(ps.params[i].lo <= g <= ps.params[i].hi for g in axis), cause
    scooter = {(p.cause, p.name): p for p in REFERENCE.params}
    assert scooter["payload", "mass_kg"].hi == pytest.approx(394.3, abs=0.1)
    assert scooter["steer_damping", "damping_nms"].hi == pytest.approx(79.7, abs=0.1)
    assert param_set(bike).params[CAUSES["steer_damping"][0]].nominal == 0.0  # no damper fitted


@pytest.mark.parametrize("name", ["reference-scooter", "robot-bicycle", "sharp1971"])
def test_replay_substeps_resolve_the_fastest_eigenvalue(name):
    """|lambda h| <= EIG_STEP for the fastest eigenvalue of E^-1 A(vx) at every speed of the range
    (the bicycle's is its ~100 rad/s lateral-tire oscillation, not the tire lag vx/sigma)."""
    v = load_vehicle(name)
    kmh, rider_nm = (14.0, 0.2) if v.vmax < 13.0 else (50.0, 3.0)
    log = ride_scenario(make_scenario("double_lane_change", speed_kmh=kmh, duration_s=20.0), vehicle=v,
                        rider_noise_nm=rider_nm, seed=0).log
    win, _ = make_windows(log, 1.0, 0.1, v.vmin, v.vmax)
    rp = Replay(win, np.array([DEFAULT_NOISE_STD[c] for c in win.channels]), v)
    sigma = rp.params.vehicle_scales.sigma
    for vx in np.linspace(v.vmin, v.vmax, 23):
        lam = np.abs(np.linalg.eigvals(v.state_matrix(vx))).max()
        h = win.dt / rp.substeps(win.dt, vx, sigma, 0.0)
        assert lam * h <= EIG_STEP + 1e-9, (name, vx, lam)
        # a shorter relaxation length (tire modes ~ 1/sigma) gets proportionally more substeps
        assert rp.substeps(win.dt, vx, sigma / 4, 0.0) >= min(4, rp.substeps(win.dt, vx, sigma, 0.0) * 4 - 3)
    if name == "robot-bicycle":  # the tire lag alone would have said 1 substep with |lambda h| ~ 1
        assert np.abs(np.linalg.eigvals(v.state_matrix(v.vmin))).max() > 10 * v.vmin / sigma


def test_vehicle_of_log_reads_the_sidecar(tmp_path):
    meta = json.loads((BIKE_DIR / "rb_20130703_011.json").read_text())
    v = vehicle_of_log(meta, BIKE_DIR / "rb_20130703_011.csv")
    assert v is not None and v.mass == pytest.approx(37.0)
    assert vehicle_of_log({"vehicle": "sharp1971"}).name == load_vehicle("sharp1971").name
    assert vehicle_of_log({}) is None
    with pytest.raises(VehicleFileError, match="'vehicle' = 'no-such-bike'"):
        vehicle_of_log({"vehicle": "no-such-bike"}, tmp_path / "x.csv")
    with pytest.raises(VehicleFileError, match="must be a preset name"):
        vehicle_of_log({"vehicle": 3}, tmp_path / "x.csv")


@pytest.mark.skipif(not REAL_RUNS, reason="shared/data/robot_bicycle not found")
def test_every_real_robot_bicycle_run_gets_a_report():
    """No crash, no refusal of the speeds (1.4-5.1 m/s), the sidecar's vehicle, strict JSON."""
    assert len(REAL_RUNS) == 14
    for f in REAL_RUNS:
        rep = diagnose(f, progress=False, pairs=False)
        js = rep.to_json()
        assert js["vehicle"]["name"] == "robot_bicycle" and "file_sha256" in js["vehicle"], f.name
        json.dumps(js, allow_nan=False)  # strict JSON: no NaN or inf anywhere
        # the tool's verdict beats the nominal model on held-out data (it names what it found)
        assert js["verdict"]["causes"][0]["cause"] != "none" and js["verdict"]["gain"] > 0, (f.name, js["verdict"])
        assert read_log(f).vx.min() < 3.0  # speeds below the scooter's range were not refused


@pytest.fixture(scope="module")
def bike_ride(bike):
    def ride(effects, seed=2):
        sc = make_scenario("double_lane_change", speed_kmh=30, duration_s=40.0)
        return ride_scenario(sc, vehicle=bike, seed=seed, effects=effects).log
    return ride


@pytest.mark.parametrize("effects", [
    {"road_bank": {"bank_rad": 0.04}},
    {"payload": {"mass_kg": 10.0}},
    {"tire_stiffness": {"front_scale": 0.7, "rear_scale": 0.7}},
    {"gyro_bias": {"yaw_rate_bias": 0.01}},
    {},
], ids=["road_bank", "payload", "tire_stiffness", "gyro_bias", "none"])
def test_hidden_cause_is_named_on_a_bicycle_ride(bike, bike_ride, effects):
    """The bicycle's own hypotheses find an effect of effects.md hidden in a simulated bicycle ride
    (30 km/h lane change, LQR rider designed for the bicycle in its own torque units), size within
    25 %, and say none on a clean ride. At 14 km/h a bicycle's tires hardly slip and a 30 %
    stiffness change moves the held-out error by only 16-20 % (one seed of three missed): the
    ride must excite what is to be identified."""
    rep = diagnose(bike_ride(effects or None), vehicle=bike, progress=False)
    got = {c["cause"]: c["params"] for c in rep.causes}
    if not effects:
        assert set(got) == {"none"} and rep.explained and rep.gain == 0.0, rep.causes
        return
    (cause, truth), = effects.items()
    assert set(got) == {cause}, rep.causes
    big = max(abs(v - {"front_scale": 1.0, "rear_scale": 1.0}.get(p, 0.0)) for p, v in truth.items())
    for p, v in truth.items():
        nominal = {"front_scale": 1.0, "rear_scale": 1.0}.get(p, 0.0)
        assert abs(got[cause][p] - v) <= 0.25 * (abs(v - nominal) or big), (p, got[cause][p], v)
    for p in got[cause]:  # a parameter left at nominal (the roll-rate bias of a yaw-only bias) stays there
        if p not in truth:
            assert abs(got[cause][p]) <= 0.25 * big, (p, got[cause][p])
    assert rep.explained and rep.gain > 0.1
