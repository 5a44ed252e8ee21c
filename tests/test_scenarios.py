"""Scenario profiles: formulas, geometry, bounds, randomisation and errors (ptw_env.scenarios)."""

from __future__ import annotations

import dataclasses
import doctest
import math

import numpy as np
import pytest
from scipy.integrate import cumulative_simpson

import ptw_env.scenarios as sc
from ptw_env.scenarios import (
    SCENARIOS,
    ConstantRadius,
    DoubleLaneChange,
    ScenarioError,
    Slalom,
    UnknownScenarioError,
    Urban,
    make_scenario,
    scenario_names,
)
from ptw_env.vehicle import G

NAMES = ("double_lane_change", "constant_radius", "handling", "urban", "slalom")


@pytest.fixture(scope="module")
def profiles():
    return {n: make_scenario(n).profile() for n in NAMES}


def test_names_are_the_cli_contract():
    assert scenario_names() == NAMES
    assert set(SCENARIOS) == set(NAMES)
    for n, cls in SCENARIOS.items():
        assert cls.name == n and make_scenario(n) == cls()


@pytest.mark.parametrize("name", NAMES)
def test_profile_formulas_and_bounds(profiles, name):
    p = profiles[name]
    sc_obj = make_scenario(name)
    n = len(p)
    assert 20.0 <= sc_obj.duration_s <= 90.0
    assert p.t[-1] == pytest.approx(sc_obj.duration_s, abs=1e-9) and n == round(sc_obj.duration_s / 0.01) + 1
    np.testing.assert_allclose(np.diff(p.t), 0.01, rtol=0, atol=1e-12)
    for f in ("vx", "s", "kappa", "phi_ref", "X", "Y", "psi"):
        a = getattr(p, f)
        assert a.shape == (n,) and np.all(np.isfinite(a)) and not a.flags.writeable
    # the roll that balances a steady turn, exactly as documented
    np.testing.assert_array_equal(p.phi_ref, np.arctan(p.vx**2 * p.kappa / G))
    # sign: a turn toward +y (positive yaw rate vx kappa) leans toward +y
    turning = np.abs(p.kappa) > 1e-4
    assert np.all(np.sign(p.phi_ref[turning]) == np.sign(p.kappa[turning]))
    # valid speed range of the vehicle and the roll limit
    assert p.vx.min() >= 3.0 and p.vx.max() <= 40.0
    assert np.abs(p.phi_ref).max() <= math.radians(40.0) + 1e-12
    # starts straight and upright, so the vehicle starts in equilibrium
    assert p.kappa[0] == pytest.approx(0.0, abs=1e-12) and p.s[0] == 0.0


@pytest.mark.parametrize("name", NAMES)
def test_path_is_the_integral_of_curvature_and_speed(profiles, name):
    """psi' = vx kappa, X' = vx cos psi, Y' = vx sin psi, s' = vx, checked with Simpson's rule
    (an independent quadrature) on the same samples."""
    p = profiles[name]
    dt = p.dt
    psi = cumulative_simpson(p.vx * p.kappa, dx=dt, initial=0.0)
    np.testing.assert_allclose(p.psi, psi, rtol=0, atol=2e-5)
    np.testing.assert_allclose(p.X, cumulative_simpson(p.vx * np.cos(p.psi), dx=dt, initial=0.0), rtol=0, atol=5e-3)
    np.testing.assert_allclose(p.Y, cumulative_simpson(p.vx * np.sin(p.psi), dx=dt, initial=0.0), rtol=0, atol=5e-3)
    np.testing.assert_allclose(p.s, cumulative_simpson(p.vx, dx=dt, initial=0.0), rtol=0, atol=5e-3)
    # the planar speed of the path is vx
    speed = np.hypot(np.gradient(p.X, dt), np.gradient(p.Y, dt))
    np.testing.assert_allclose(speed[1:-1], p.vx[1:-1], rtol=1e-3)


@pytest.mark.parametrize("name", NAMES)
def test_roll_reference_is_continuous(name):
    """A jump would not shrink with the sample period; a continuous signal's steps halve with dt.
    The reference roll rate stays below 1.2 rad/s (the reference ride logs peak at 1.07 rad/s)."""
    s = make_scenario(name)
    p1, p2 = s.profile(dt=0.01), s.profile(dt=0.005)
    j1, j2 = np.abs(np.diff(p1.phi_ref)).max(), np.abs(np.diff(p2.phi_ref)).max()
    assert j1 / j2 == pytest.approx(2.0, rel=0.05)
    assert j1 / 0.01 < 1.2
    # the speed is continuous too, with the acceleration within the scenario's limits
    # [m/s^2] (to 0.1 %: the speed plan is interpolated from a 5 cm path grid)
    limit = max(getattr(s, "accel_mps2", 0.0), getattr(s, "brake_mps2", 0.0)) * 1.001
    if name == "constant_radius":
        limit = s.accel_mps2 * math.pi / 2 * 1.001  # cosine blend: peak = pi/2 x mean
    assert np.abs(np.diff(p1.vx)).max() / 0.01 <= limit


@pytest.mark.parametrize("speed", [50.0, 100.0])
def test_double_lane_change_geometry(speed):
    s = DoubleLaneChange(speed_kmh=speed)
    p = s.profile()
    v = speed / 3.6
    np.testing.assert_allclose(p.vx, v, rtol=0, atol=1e-12)
    # in the middle of the hold: in the offset lane, heading straight
    k_hold = int(round((s.run_in_s + s.transition_s + s.hold_s / 2) / p.dt))
    assert p.Y[k_hold] == pytest.approx(s.offset_m, abs=2e-3)
    assert p.psi[k_hold] == pytest.approx(0.0, abs=1e-4)
    assert p.Y.max() == pytest.approx(s.offset_m, abs=2e-3)
    # back in the original lane, heading straight, at the end
    assert p.Y[-1] == pytest.approx(0.0, abs=2e-3) and p.psi[-1] == pytest.approx(0.0, abs=1e-4)
    # straight run-in: nothing happens before the first move
    k_in = int(s.run_in_s / p.dt)
    assert np.all(p.phi_ref[:k_in] == 0.0)
    # time-scaled moves: same peak roll at any speed; 7.51 offset / T^2 lateral acceleration
    ay_peak = 7.513 * s.offset_m / s.transition_s**2
    assert np.abs(p.phi_ref).max() == pytest.approx(math.atan(ay_peak / G), rel=0.02)


def test_constant_radius_speeds_and_radius():
    s = ConstantRadius()
    p = s.profile()
    assert p.vx[0] * 3.6 == pytest.approx(50.0, abs=1e-9)
    assert p.vx[-1] * 3.6 == pytest.approx(100.0, abs=1e-9)
    assert np.all(np.diff(p.vx) >= -1e-12)
    # mean acceleration over the speed change as set
    acc = np.diff(p.vx) / p.dt
    moving = acc > 1e-9
    assert acc[moving].mean() == pytest.approx(s.accel_mps2, rel=0.02)
    # on the circle: radius from the curvature, and from a least-squares circle fit of X, Y
    on = p.t >= s.run_in_s + s.entry_s + 0.1
    np.testing.assert_allclose(1.0 / p.kappa[on], 100.0, rtol=1e-9)
    X, Y = p.X[on], p.Y[on]
    A = np.column_stack([2 * X, 2 * Y, np.ones_like(X)])
    cx, cy, c = np.linalg.lstsq(A, X**2 + Y**2, rcond=None)[0]
    assert math.sqrt(c + cx**2 + cy**2) == pytest.approx(100.0, abs=0.05)
    assert p.phi_ref[-1] == pytest.approx(math.atan((100 / 3.6) ** 2 / (100.0 * G)), rel=1e-9)
    # a different radius is recovered too
    p2 = make_scenario("constant_radius", radius_m=150.0, v_end_kmh=90.0).profile()
    assert 1.0 / p2.kappa[-1] == pytest.approx(150.0, rel=1e-9)


def test_slalom_passes_the_cones():
    s = Slalom()
    p = s.profile()
    np.testing.assert_allclose(p.vx, s.speed_kmh / 3.6, atol=1e-12)
    assert np.abs(p.Y).max() == pytest.approx(s.amplitude_m, abs=5e-3)
    # the path crosses the cone line midway between passes: crossings every cone spacing
    x0 = s.speed_kmh / 3.6 * s.run_in_s
    full = (p.X > x0 + 2 * s.cone_spacing_m) & (p.X < x0 + (s.n_cones + 2) * s.cone_spacing_m)
    X, Y = p.X[full], p.Y[full]
    k = np.flatnonzero(np.sign(Y[1:]) != np.sign(Y[:-1]))
    Xc = X[k] - Y[k] * (X[k + 1] - X[k]) / (Y[k + 1] - Y[k])  # linear interpolation of the crossing
    assert len(Xc) == s.n_cones - 1
    np.testing.assert_allclose(np.diff(Xc), s.cone_spacing_m, atol=0.01)
    # the heading has no drift and the path ends on the centre line
    assert p.Y[-1] == pytest.approx(0.0, abs=2e-3) and p.psi[-1] == pytest.approx(0.0, abs=1e-4)


def test_handling_track_closes_and_spans_40_to_120_kmh():
    p = make_scenario("handling", duration_s=120.0).profile()
    assert p.vx.min() * 3.6 == pytest.approx(40.0, abs=2.0)
    assert p.vx.max() * 3.6 == pytest.approx(120.0, abs=1e-6)
    # one lap: the path comes back through the start point with the heading turned by 2 pi
    later = p.t > 40.0
    k = int(np.flatnonzero(later)[np.argmin(np.hypot(p.X[later], p.Y[later]))])
    assert math.hypot(p.X[k], p.Y[k]) < 0.5 and p.psi[k] == pytest.approx(2 * math.pi, abs=1e-5)
    # turns of both signs and of several radii
    curv = p.kappa[np.abs(p.kappa) > 1e-3]
    radii = np.unique(np.round(1.0 / np.abs(curv[np.abs(np.diff(curv, prepend=0)) < 1e-9])))
    assert np.any(curv > 0) and np.any(curv < 0) and len(radii) >= 5
    # lap time: the default duration is about one lap
    assert 75.0 < p.t[k] < 95.0


def test_urban_seeded_and_realistic():
    a = Urban().profile()
    b = Urban().profile(seed=0)
    c = Urban().profile(seed=1)
    np.testing.assert_array_equal(a.vx, b.vx)
    np.testing.assert_array_equal(a.kappa, b.kappa)
    assert not np.array_equal(a.kappa, c.kappa)
    np.testing.assert_array_equal(Urban(seed=1).profile().kappa, c.kappa)
    assert a.duration_s == pytest.approx(90.0)
    for p in (a, c):
        kmh = p.vx * 3.6
        assert kmh.min() >= 30.0 - 1e-6 and kmh.max() <= 90.0 + 1e-6
        assert kmh.max() - kmh.min() > 30.0  # accelerations and braking, not a cruise
        acc = np.diff(p.vx) / p.dt
        assert acc.min() < -1.0 and acc.max() > 1.0
        assert np.any(p.kappa > 1e-3) and np.any(p.kappa < -1e-3)
        assert np.abs(p.kappa).max() > 1 / 40.0  # narrow turns
        assert np.any((np.abs(p.kappa) > 1 / 220) & (np.abs(p.kappa) < 1 / 55))  # wide turns


def test_dataclass_replace_and_frozen():
    s = make_scenario("slalom")
    s2 = dataclasses.replace(s, amplitude_m=0.8)
    assert s2.amplitude_m == 0.8 and s.amplitude_m == 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.speed_kmh = 60.0  # type: ignore[misc]
    with pytest.raises(ScenarioError, match="amplitude_m"):
        dataclasses.replace(s, amplitude_m=-1.0)


def test_unknown_name_lists_the_known_ones():
    with pytest.raises(UnknownScenarioError) as e:
        make_scenario("lane_change")
    for n in NAMES:
        assert n in str(e.value)
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize(
    "name, speed, overrides, match",
    [
        ("slalom", None, {"cone_spaceing_m": 20.0}, "cone_spaceing_m"),
        ("double_lane_change", -50.0, {}, "speed_kmh"),
        ("slalom", 0.0, {}, "speed_kmh"),
        ("urban", None, {"duration_s": 0.0}, "duration_s"),
        ("handling", None, {"duration_s": -3.0}, "duration_s"),
        ("constant_radius", None, {"radius_m": 0.0}, "radius_m"),
        ("constant_radius", None, {"radius_m": -100.0}, "radius_m"),
        ("constant_radius", None, {"radius_m": 50.0}, "radius_m"),  # 100 km/h on 50 m: 57 deg of roll
        ("constant_radius", None, {"v_end_kmh": 150.0}, "150 km/h needs 60.5 deg of roll"),
        ("constant_radius", 80.0, {}, "v_start_kmh"),  # no cruise speed: names its speed parameters
        ("constant_radius", None, {"duration_s": 10.0}, "duration_s"),
        ("urban", None, {"v_min_kmh": 95.0}, "v_min_kmh"),
        ("urban", None, {"seed": -1}, "seed"),
        ("handling", None, {"lateral_g": 1.5}, "lateral_g"),
        ("handling", None, {"v_max_kmh": float("nan")}, "v_max_kmh"),
        ("slalom", None, {"n_cones": 2.5}, "n_cones"),
        ("slalom", None, {"amplitude_m": True}, "amplitude_m"),
    ],
)
def test_bad_parameters_raise_named_errors(name, speed, overrides, match):
    with pytest.raises(ScenarioError, match=match):
        make_scenario(name, speed_kmh=speed, **overrides)


@pytest.mark.parametrize("name, speed, overrides, rider", [
    ("double_lane_change", 200.0, {}, "cossalter-sport-touring"),  # 55.6 m/s: its valid range is 3-60 m/s
    ("double_lane_change", 8.0, {}, "robot-bicycle"),              # 2.2 m/s
    ("urban", None, {"v_min_kmh": 5.0, "v_max_kmh": 30.0}, "robot-bicycle"),
])
def test_the_vehicle_that_rides_a_scenario_decides_its_speeds(name, speed, overrides, rider):
    """A scenario has no vehicle: its speeds are checked against the one that rides it (Profile.check_vehicle),
    so the robot bicycle rides at 2.2 m/s what the scooter (3-40 m/s) cannot, and no scooter bound hides in a
    scenario; the environment refuses the scooter with the scenario, time, speed and range named."""
    from ptw_env.env import EnvConfigError, PTWRollEnv
    from ptw_env.vehicle import REFERENCE_SCOOTER
    from ptw_env.vehicle_files import load_vehicle

    sc = make_scenario(name, speed_kmh=speed, **overrides)
    prof = sc.profile()
    with pytest.raises(ScenarioError, match=r"leaves the valid range of reference.scooter, \[3, 40\] m/s"):
        prof.check_vehicle(REFERENCE_SCOOTER)
    with pytest.raises(EnvConfigError, match=rf"scenario '{name}': speed .* at t = .* valid range"):
        PTWRollEnv(scenario=sc)
    v = load_vehicle(rider)
    prof.check_vehicle(v)
    env = PTWRollEnv(scenario=sc, vehicle=v)
    env.reset(seed=0)
    assert env.step([0.0])[0].shape == env.observation_space.shape


def test_infeasible_path_and_bad_dt():
    # a fast slalom through close cones needs more roll than 40 deg
    with pytest.raises(ScenarioError, match="roll angle"):
        make_scenario("slalom", speed_kmh=100, cone_spacing_m=20.0).profile()
    with pytest.raises(ScenarioError, match="dt"):
        make_scenario("urban").profile(dt=0.0)


def test_docstring_examples_run():
    res = doctest.testmod(sc, optionflags=doctest.ELLIPSIS)
    assert res.attempted >= 8 and res.failed == 0
