"""Sensor model (ptw_env.sensors) against hand-derived answers and the reference logs."""

from __future__ import annotations

import dataclasses
import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from ptw_env.effects import Effects
from ptw_env.sensors import (
    CHANNEL_RANGES,
    CHANNELS,
    DEFAULT_NOISE_STD,
    ENCODER_QUANTUM,
    SensorConfig,
    SensorConfigError,
    SensorModel,
    SensorResetError,
)
from ptw_env.vehicle import G

from conftest import DATA  # noqa: E402  (shared/data beside the repository)
Q = 2 * math.pi / 1024


def random_states(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    scale = np.array([0.3, 0.04, 1.0, 0.3, 0.5, 0.2, 500.0, 500.0])
    return rng.standard_normal((n, 8)) * scale


def truth(x: np.ndarray, vx: float, ay: float) -> np.ndarray:
    """The true channels written out by hand from the CHANNELS table."""
    return np.array([x[1], x[5], x[3], x[4], ay, x[0], vx])


def run(model: SensorModel, xs: np.ndarray, vx, ay, seed: int = 0) -> np.ndarray:
    model.reset(np.random.default_rng(seed))
    vx = np.broadcast_to(vx, (len(xs),))
    ay = np.broadcast_to(ay, (len(xs),))
    return np.array([model.measure(x, v, a) for x, v, a in zip(xs, vx, ay)])


# --------------------------------------------------------------------------- configuration


def test_defaults_equal_reference_sidecars():
    cfg = SensorConfig()
    assert dict(cfg.noise_std) == {
        "delta": 0.001, "delta_rate": 0.01, "yaw_rate": 0.005, "roll_rate": 0.005,
        "ay": 0.1, "roll": 0.005, "vx": 0.05,
    }  # fmt: skip
    assert cfg.delta_quantum == Q == ENCODER_QUANTUM
    assert cfg.gps_rate_hz == 10.0
    assert all(v == 0.0 for v in cfg.bias.values())
    assert set(cfg.bias) == set(CHANNELS)


def test_from_percent_scales_ranges_not_vx():
    cfg = SensorConfig.from_percent(5)
    for c in CHANNELS[:6]:
        assert cfg.noise_std[c] == pytest.approx(0.05 * CHANNEL_RANGES[c], rel=1e-15)
    assert cfg.noise_std["vx"] == DEFAULT_NOISE_STD["vx"]
    per = SensorConfig.from_percent({"ay": 10}, vx_std=0.2)
    assert per.noise_std["ay"] == pytest.approx(0.5)
    assert per.noise_std["yaw_rate"] == 0.0 and per.noise_std["vx"] == 0.2


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"noise_std": {"ay": -0.1}}, ["noise_std['ay']", ">= 0"]),
        ({"noise_std": {"yaw_rate": float("nan")}}, ["noise_std['yaw_rate']", "finite"]),
        ({"noise_std": {"yaw": 0.1}}, ["unknown channel 'yaw'"]),
        ({"bias": {"ay": float("inf")}}, ["bias['ay']", "finite"]),
        ({"bias": {"gyro": 0.1}}, ["bias", "unknown channel 'gyro'"]),
        ({"noise_std": {"ay": "abc"}}, ["noise_std['ay']", "number"]),
        ({"gps_rate_hz": 0.0}, ["gps_rate_hz"]),
        ({"gps_rate_hz": -10.0}, ["gps_rate_hz"]),
        ({"gps_rate_hz": float("nan")}, ["gps_rate_hz"]),
        ({"delta_quantum": 0.0}, ["delta_quantum"]),
        ({"delta_quantum": -Q}, ["delta_quantum"]),
    ],
)
def test_config_validation(kwargs, words):
    with pytest.raises(SensorConfigError) as info:
        SensorConfig(**kwargs)
    for w in words:
        assert w in str(info.value)


def test_from_percent_validation_and_unknown_kwargs():
    with pytest.raises(SensorConfigError, match=r"pct\['ay'\]"):
        SensorConfig.from_percent({"ay": -1})
    with pytest.raises(SensorConfigError, match="vx"):
        SensorConfig.from_percent({"vx": 5})
    with pytest.raises(SensorConfigError, match="unknown channel 'yaw'"):
        SensorConfig.from_percent({"yaw": 5})
    with pytest.raises(TypeError):
        SensorConfig(nosie_std={})  # misspelt option
    with pytest.raises(TypeError):
        SensorConfig.from_percent(5, gps_rate=10)
    with pytest.raises(TypeError):
        SensorModel(SensorConfig(), delay=0.1)


def test_config_is_frozen_and_pickles():
    cfg = SensorConfig(bias={"ay": 0.2})
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.gps_rate_hz = 5.0
    assert pickle.loads(pickle.dumps(cfg)) == cfg


def test_model_validation():
    with pytest.raises(SensorConfigError, match="dt"):
        SensorModel(SensorConfig(), dt=0.0)
    with pytest.raises(SensorConfigError, match="dt"):
        SensorModel(SensorConfig(), dt=float("nan"))
    with pytest.raises(SensorConfigError, match="sensor_delay:delay_s"):
        SensorModel(SensorConfig(), Effects({"sensor_delay": {"delay_s": np.array([0.0, 0.1])}}))
    with pytest.raises(SensorConfigError, match="unknown effect"):
        SensorModel(SensorConfig(), {"gyro_drift": {}})
    model = SensorModel(SensorConfig())
    with pytest.raises(SensorResetError):
        model.measure(np.zeros(8), 10.0, 0.0)
    with pytest.raises(SensorConfigError, match="Generator"):
        model.reset(None)
    model.reset(0)
    with pytest.raises(SensorConfigError, match="8 states"):
        model.measure(np.zeros(7), 10.0, 0.0)


# --------------------------------------------------------------------------- noise-free readings


def test_noiseless_returns_exact_true_channels():
    xs = random_states(50)
    vx = np.linspace(5.0, 30.0, 50)
    ay = np.random.default_rng(1).standard_normal(50)
    model = SensorModel(SensorConfig.noiseless())
    y = run(model, xs, vx, ay)
    expected = np.array([truth(x, v, a) for x, v, a in zip(xs, vx, ay)])
    np.testing.assert_array_equal(y, expected)
    np.testing.assert_array_equal(model.true_channels, expected[-1])


def test_dynamic_effects_do_not_touch_readings():
    xs = random_states(20)
    plain = run(SensorModel(SensorConfig.noiseless()), xs, 12.0, 1.0)
    eff = Effects({"road_bank": {"bank_rad": 0.1}, "payload": {"mass_kg": 80}})
    np.testing.assert_array_equal(run(SensorModel(SensorConfig.noiseless(), eff), xs, 12.0, 1.0), plain)


def test_measure_series_on_a_simulated_ride_matches_states():
    from ptw_env.dynamics import compile_plant
    from ptw_env.integrate import simulate

    x0 = np.zeros(8)
    x0[0] = 0.05
    tau = 2.0 * np.sin(np.linspace(0, 6, 200))
    xs = simulate(x0, tau, 15.0, dt=0.01)
    plant = compile_plant(effects={"payload": {"mass_kg": 60}})
    ay = plant.ay(xs)
    model = SensorModel(SensorConfig.noiseless(), plant.effects)
    model.reset(0)
    y = model.measure_series(xs, 15.0, ay)
    np.testing.assert_array_equal(y[:, 0], xs[:, 1])
    np.testing.assert_array_equal(y[:, 2], xs[:, 3])
    np.testing.assert_array_equal(y[:, 5], xs[:, 0])
    np.testing.assert_allclose(y[:, 4], (xs[:, 6] + xs[:, 7]) / plant.mass, rtol=1e-15)


# --------------------------------------------------------------------------- noise statistics


def test_noise_std_matches_config():
    n = 20000
    std = {
        "delta": 0.002, "delta_rate": 0.01, "yaw_rate": 0.005, "roll_rate": 0.02, "ay": 0.1, "roll": 0.005, "vx": 0.05,
    }  # fmt: skip
    cfg = SensorConfig(noise_std=std, delta_quantum=None)
    x = random_states(1)[0]
    model = SensorModel(cfg)
    y = run(model, np.broadcast_to(x, (n, 8)), 15.0, 2.0, seed=3)
    err = y - truth(x, 15.0, 2.0)
    for i, c in enumerate(CHANNELS):
        e = err[::10, i] if c == "vx" else err[:, i]  # one independent GPS fix per 10 samples
        m = len(e)
        sigma = std[c]
        # 5 standard errors of the sample std and the sample mean of Gaussian noise
        assert abs(e.std(ddof=1) - sigma) < 5 * sigma / math.sqrt(2 * (m - 1)), c
        assert abs(e.mean()) < 5 * sigma / math.sqrt(m), c
    # independent channels: all correlations within 5/sqrt(n) of zero
    corr = np.corrcoef(err[:, :6].T)
    assert np.max(np.abs(corr - np.eye(6))) < 5 / math.sqrt(n)


def test_percent_noise_std():
    n = 20000
    cfg = SensorConfig.from_percent(5, delta_quantum=None)
    x = random_states(1, seed=2)[0]
    err = run(SensorModel(cfg), np.broadcast_to(x, (n, 8)), 15.0, 0.0, seed=4) - truth(x, 15.0, 0.0)
    for i, c in enumerate(CHANNELS[:6]):
        sigma = 0.05 * CHANNEL_RANGES[c]
        assert abs(err[:, i].std(ddof=1) - sigma) < 5 * sigma / math.sqrt(2 * (n - 1)), c


def test_same_seed_same_numbers_different_seed_different():
    xs = random_states(1500)  # more than one noise block
    cfg = SensorConfig(bias={"ay": 0.1})
    a = run(SensorModel(cfg), xs, 14.0, 1.0, seed=7)
    b = run(SensorModel(cfg), xs, 14.0, 1.0, seed=7)
    c = run(SensorModel(cfg), xs, 14.0, 1.0, seed=8)
    np.testing.assert_array_equal(a, b)
    assert np.all(np.any(a != c, axis=0))
    # reset with the same seed restarts the identical stream on the same object
    model = SensorModel(cfg)
    np.testing.assert_array_equal(run(model, xs, 14.0, 1.0, seed=7), a)
    np.testing.assert_array_equal(run(model, xs, 14.0, 1.0, seed=7), a)


def test_randomness_only_from_the_given_generator():
    xs = random_states(30)
    np.random.seed(0)
    a = run(SensorModel(SensorConfig()), xs, 14.0, 1.0, seed=5)
    np.random.seed(1)
    b = run(SensorModel(SensorConfig()), xs, 14.0, 1.0, seed=5)
    np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------- encoder and GPS


def test_quantisation_step_is_exactly_2pi_over_1024():
    deltas = np.linspace(-0.2, 0.2, 4001)
    xs = np.zeros((deltas.size, 8))
    xs[:, 1] = deltas
    cfg = SensorConfig(noise_std={}, delta_quantum=Q)
    y = run(SensorModel(cfg), xs, 10.0, 0.0)[:, 0]
    counts = y / Q
    np.testing.assert_allclose(counts, np.round(counts), rtol=0, atol=1e-9)
    steps = np.unique(np.round(np.diff(y) / Q, 9))
    assert set(steps) == {0.0, 1.0}  # a slow sweep moves one count at a time
    assert np.max(np.abs(y - deltas)) <= Q / 2 + 1e-15
    assert np.unique(np.round(counts)).size == 2 * round(0.2 / Q) + 1


def test_quantisation_order():
    """Default: quantised angle plus noise (as the reference logs); option: noise then quantise."""
    n = 5000
    xs = np.zeros((n, 8))
    xs[:, 1] = 0.0123
    after = run(SensorModel(SensorConfig(noise_std={"delta": 0.001})), xs, 10.0, 0.0, seed=1)[:, 0]
    resid = after - Q * round(0.0123 / Q)
    assert abs(resid.std() - 0.001) < 5 * 0.001 / math.sqrt(2 * n)
    before = run(
        SensorModel(SensorConfig(noise_std={"delta": 0.001}, noise_before_quantisation=True)), xs, 10.0, 0.0, seed=1
    )[:, 0]
    np.testing.assert_allclose(before / Q, np.round(before / Q), rtol=0, atol=1e-9)


def test_default_noise_reproduces_reference_log_statistics():
    """Driving the model with the noise-free twin's true states gives residuals like nominal_urban.csv."""
    twin = np.genfromtxt(DATA / "nominal_urban_noiseless.csv", delimiter=",", names=True)
    ref = np.genfromtxt(DATA / "nominal_urban.csv", delimiter=",", names=True)
    xs = np.column_stack([twin["x_" + s] for s in ("phi", "delta", "vy", "r", "phi_dot", "delta_dot", "Fyf", "Fyr")])
    model = SensorModel(SensorConfig())
    model.reset(np.random.default_rng(11))
    y = model.measure_series(xs, twin["vx"], twin["ay"])
    n = len(xs)
    for i, c in enumerate(CHANNELS[1:6], start=1):
        ours = np.std(y[:, i] - twin[c])
        theirs = np.std(ref[c] - twin[c])
        assert abs(ours - theirs) < 6 * DEFAULT_NOISE_STD[c] / math.sqrt(2 * n) + 2e-6, c  # + file rounding
    ours = np.std(y[:, 0] - Q * np.round(twin["delta"] / Q))
    theirs = np.std(ref["delta"] - Q * np.round(twin["delta"] / Q))
    assert abs(ours - theirs) < 6 * 0.001 / math.sqrt(2 * n) + 2e-6
    # GPS speed changes on the same samples as the reference log's
    np.testing.assert_array_equal(np.flatnonzero(np.diff(y[:, 6])), np.flatnonzero(np.diff(ref["vx"])))


def test_gps_hold_every_ten_samples_at_100_hz():
    n = 95
    vx = 10.0 + 0.1 * np.arange(n)  # a ramp: the true speed changes every sample
    xs = np.zeros((n, 8))
    y = run(SensorModel(SensorConfig.noiseless(gps_rate_hz=10.0)), xs, vx, 0.0)[:, 6]
    np.testing.assert_array_equal(y, vx[(np.arange(n) // 10) * 10])
    noisy = run(SensorModel(SensorConfig()), xs, vx, 0.0, seed=2)[:, 6]
    np.testing.assert_array_equal(np.flatnonzero(np.diff(noisy)) + 1, np.arange(10, n, 10))


def test_gps_rate_not_dividing_the_sample_rate():
    n = 120
    vx = 10.0 + 0.1 * np.arange(n)
    y = run(SensorModel(SensorConfig.noiseless(gps_rate_hz=3.0)), np.zeros((n, 8)), vx, 0.0)[:, 6]
    # fix m is taken at the first sample at or after m/3 s: k = ceil(100 m / 3)
    updates = [0, 34, 67, 100]
    assert list(np.flatnonzero(np.diff(y)) + 1) == updates[1:]
    assert [y[k] for k in updates] == [vx[k] for k in updates]


# --------------------------------------------------------------------------- sensor effects


def test_bias_offsets_exactly():
    xs = random_states(40)
    eff = Effects({"gyro_bias": {"yaw_rate_bias": 0.02, "roll_rate_bias": -0.03}})
    cfg = dataclasses.replace(SensorConfig.noiseless(), bias={"ay": 0.25, "roll_rate": 0.5, "vx": -0.5})
    y = run(SensorModel(cfg, eff), xs, 12.0, 1.0)
    exact = np.array([truth(x, 12.0, 1.0) for x in xs])
    offset = np.array([0.0, 0.0, 0.02, 0.5 - 0.03, 0.25, 0.0, -0.5])
    np.testing.assert_array_equal(y, exact + offset)
    np.testing.assert_array_equal(y[:, [0, 1, 5]], exact[:, [0, 1, 5]])


@pytest.mark.parametrize("gain", [1.0, 0.5, -0.3])
def test_ay_frame(gain):
    xs = random_states(40)
    ay = np.random.default_rng(3).standard_normal(40) * 3
    y = run(SensorModel(SensorConfig.noiseless(), Effects({"ay_frame": {"gravity_gain": gain}})), xs, 12.0, ay)
    phi = xs[:, 0]
    body = ay * np.cos(phi) - G * np.sin(phi)  # an unrotated body-frame accelerometer
    np.testing.assert_allclose(y[:, 4], (1 - gain) * ay + gain * body, rtol=1e-13, atol=1e-13)
    others = np.column_stack([xs[:, [1, 5, 3, 4, 0]], np.full(40, 12.0)])
    np.testing.assert_array_equal(y[:, [0, 1, 2, 3, 5, 6]], others)


def test_delay_of_whole_samples():
    n = 30
    xs = random_states(n)
    vx = 10.0 + np.arange(n)
    ay = np.arange(n) * 0.1
    y = run(SensorModel(SensorConfig.noiseless(), Effects({"sensor_delay": {"delay_s": 0.05}}), dt=0.01), xs, vx, ay)
    exact = np.array([truth(x, v, a) for x, v, a in zip(xs, vx, ay)])
    np.testing.assert_array_equal(y[5:, :6], exact[:-5, :6])  # 5 samples earlier
    np.testing.assert_array_equal(y[:5, :6], np.broadcast_to(exact[0, :6], (5, 6)))  # oldest stands in
    np.testing.assert_array_equal(y[:, 6], vx)  # vx is an input: not delayed


def test_fractional_delay_interpolates():
    n = 30
    xs = random_states(n)
    y = run(SensorModel(SensorConfig.noiseless(), {"sensor_delay": {"delay_s": 0.025}}, dt=0.01), xs, 12.0, 0.0)
    exact = np.array([truth(x, 12.0, 0.0) for x in xs])[:, :6]
    np.testing.assert_allclose(y[3:, :6], 0.5 * exact[1:-2] + 0.5 * exact[:-3], rtol=1e-14, atol=1e-15)
    y = run(SensorModel(SensorConfig.noiseless(), {"sensor_delay": {"delay_s": 0.013}}, dt=0.01), xs, 12.0, 0.0)
    np.testing.assert_allclose(y[2:, :6], 0.7 * exact[1:-1] + 0.3 * exact[:-2], rtol=1e-13, atol=1e-15)
    # a linear ramp delayed by 2.5 samples is the ramp shifted by 2.5 samples
    ramp = np.zeros((n, 8))
    ramp[:, 3] = np.arange(n) * 0.01
    y = run(SensorModel(SensorConfig.noiseless(), Effects({"sensor_delay": {"delay_s": 0.025}})), ramp, 12.0, 0.0)
    np.testing.assert_allclose(y[3:, 2], (np.arange(3, n) - 2.5) * 0.01, rtol=0, atol=1e-15)


def test_delay_applies_to_the_ay_frame_reading_and_reset_clears_history():
    n = 20
    xs = random_states(n)
    ay = np.random.default_rng(4).standard_normal(n)
    eff = Effects({"sensor_delay": {"delay_s": 0.03}, "ay_frame": {"gravity_gain": 1.0}})
    model = SensorModel(SensorConfig.noiseless(), eff)
    y = run(model, xs, 12.0, ay)
    body = ay * np.cos(xs[:, 0]) - G * np.sin(xs[:, 0])
    np.testing.assert_allclose(y[3:, 4], body[:-3], rtol=1e-13, atol=1e-13)
    y2 = run(model, xs[::-1], 12.0, ay[::-1])  # reset: no memory of the previous run
    np.testing.assert_allclose(y2[:4, 4], body[-1], rtol=1e-13)


# ------------------------------------------------------------------ channel ranges per vehicle
def test_channel_ranges_of_the_reference_are_the_table_and_scale_with_the_vehicle():
    """channel_ranges: the reference scooter's are CHANNEL_RANGES exactly (so every scooter result is
    unchanged); another vehicle's follow the steady-turn kinematics the docstring derives, checked here
    against the linear model's own steady turn: r / a_y = 1 / v and phi / a_y = 1 / g (within 4 %)."""
    import numpy as np

    from ptw_env.sensors import CHANNEL_RANGES, SensorConfig, channel_ranges
    from ptw_env.vehicle import FYF, FYR, PHI, R, REFERENCE_SCOOTER, G
    from ptw_env.vehicle_files import load_vehicle, vehicle_names

    assert channel_ranges(REFERENCE_SCOOTER) == dict(CHANNEL_RANGES) == dict(channel_ranges(None))
    assert SensorConfig.from_percent(5.0, vehicle=REFERENCE_SCOOTER).noise_std == SensorConfig.from_percent(5.0).noise_std
    v0 = 0.5 * sum(REFERENCE_SCOOTER.control_range)
    for name in vehicle_names():
        v = load_vehicle(name)
        vm = 0.5 * sum(v.control_range)
        x = np.linalg.lstsq(v.A(vm), -v.B, rcond=None)[0]  # steady turn under a constant torque
        ay = (x[FYF] + x[FYR]) / v.mass
        assert x[R] / ay == pytest.approx(1.0 / vm, rel=1e-6)
        assert x[PHI] / ay == pytest.approx(1.0 / G, rel=0.04)
        r = channel_ranges(v)
        assert r["yaw_rate"] == pytest.approx(CHANNEL_RANGES["yaw_rate"] * v0 / vm)
        assert (r["ay"], r["roll"], r["roll_rate"]) == (CHANNEL_RANGES["ay"], CHANNEL_RANGES["roll"],
                                                        CHANNEL_RANGES["roll_rate"])
        cfg = SensorConfig.from_percent(5.0, vehicle=v)
        for c in ("delta", "delta_rate", "yaw_rate", "roll_rate", "ay"):
            assert cfg.noise_std[c] == pytest.approx(0.05 * r[c])


def test_the_robot_bicycles_ranges_are_of_the_order_of_its_measured_rides():
    """The 14 measured robot-bicycle rides (shared/data/robot_bicycle): the largest |signal| of each channel
    over all runs lies within the derived range and above a quarter of it (those rides are gentle: a_y up to
    3.5 m/s^2), as the scooter's table lies just above its urban ride."""
    import numpy as np

    from ptw_env.logs import read_log
    from ptw_env.sensors import channel_ranges
    from ptw_env.vehicle_files import load_vehicle

    from conftest import SHARED

    runs = sorted((SHARED / "data" / "robot_bicycle").glob("rb_*.csv"))
    assert len(runs) == 14
    r = channel_ranges(load_vehicle("robot-bicycle"))
    for c in ("delta", "delta_rate", "yaw_rate", "roll_rate", "ay"):
        peak = max(float(np.nanmax(np.abs(read_log(f).columns[c]))) for f in runs)
        assert 0.25 * r[c] <= peak <= r[c], (c, peak, r[c])
