"""The native vector environment (issue 21): the same episodes as the single env, gymnasium's vector
conventions, the actuator, the safety cost and domain randomisation, each against an independent
reference (the single env, a closed-form response, the state in ``info``)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import ptw_env  # noqa: F401  (registers the ids)
from ptw_env.env import EnvConfigError, PTWRollEnv
from ptw_env.episode import Actuator, CostConfig
from ptw_env.randomize import Randomization, RandomizationError
from ptw_env.scenarios import make_scenario
from ptw_env.vector import PTWRollVectorEnv


def replay_against_single(kwargs: dict, n: int, steps: int, seed: int, action_scale: float,
                          check: tuple[int, ...] | None = None) -> tuple[float, int, int]:
    """Step a vector env and single envs with the same random actions (single env i reset with seed
    seed + i, then without a seed at each episode end, as NEXT_STEP autoreset does), for the envs ``check``
    (default all n). Returns the largest difference of observation, reward, state and cost, the number of
    episode ends and the rides (pool indices) the checked envs stepped on."""
    venv = PTWRollVectorEnv(num_envs=n, **kwargs)
    check = tuple(range(n)) if check is None else check
    singles = {i: PTWRollEnv(**kwargs) for i in check}
    obs, info = venv.reset(seed=seed)
    diff = 0.0
    for i, e in singles.items():
        o, inf = e.reset(seed=seed + i)
        diff = max(diff, float(np.max(np.abs(o - obs[i]))), float(np.max(np.abs(inf["state"] - info["state"][i]))))
    rng = np.random.default_rng(seed)
    done = np.zeros(n, dtype=bool)
    ends = 0
    rides: set[int] = set()
    for _ in range(steps):
        a = (rng.uniform(0.0, 1.0, (n, 1)) * action_scale).astype(np.float32)  # leans one way: falls
        obs, rew, term, trunc, info = venv.step(a)
        for i, e in singles.items():
            if done[i]:
                o, inf = e.reset()
                r, te, tr, cost = 0.0, False, False, 0.0
            else:
                o, r, te, tr, inf = e.step(a[i])
                cost = inf["cost"]
                if te or tr:
                    ends += 1
                    assert info["reason"][i] == inf["reason"]
            assert (te, tr) == (term[i], trunc[i])
            rides.add(int(inf.get("ride", 0)))
            done[i] = te or tr
            diff = max(diff, float(np.max(np.abs(o - obs[i]))), abs(r - rew[i]),
                       float(np.max(np.abs(inf["state"] - info["state"][i]))), abs(cost - info["cost"][i]))
    return diff, ends, rides


@pytest.mark.parametrize("case", ["default", "effects_actuator", "randomized", "rides", "rides_substeps", "vehicle"])
def test_env_i_equals_single_env_through_resets(case):
    """Same seeds, same actions: env i of the vector env and a single env agree to round-off, including
    across episode ends (falls under random torques) and autoresets."""
    kwargs: dict = {"scenario": "slalom", "speed_kmh": 40}
    scale = 60.0
    if case == "effects_actuator":
        kwargs.update(effects={"sensor_delay": {"delay_s": 0.025}, "ay_frame": {"gravity_gain": 1.0},
                               "tire_saturation": {"mu_peak": 0.6}, "payload": {"mass_kg": 20.0}},
                      actuator=Actuator(delay_s=0.02, bandwidth_hz=8.0, rate_limit=400.0),
                      observe_roll=True, normalize_action=True)
        scale = 1.0
    elif case == "randomized":
        kwargs.update(randomize={"tire_saturation:mu_peak": ("uniform", 0.4, 1.0), "payload:mass_kg": ("normal", 0, 15),
                                 "sensor_noise_scale": ("uniform", 0.5, 2.0), "gyro_bias:yaw_rate_bias": ("normal", 0, 0.01),
                                 "sensor_bias:ay": ("uniform", -0.1, 0.1)})
    elif case == "rides":  # a ride drawn per episode from a pool, mirrored half of the time
        kwargs.update(scenario_pool=["slalom", "double_lane_change"], mirror=True)
    elif case == "rides_substeps":  # two rides at other speeds: each its own RK4 substeps (a randomised short
        # relaxation length's tire lag ~vx/sigma is fast at 120 km/h, not at 30)
        kwargs = {"scenario_pool": [make_scenario("double_lane_change", speed_kmh=30), make_scenario("double_lane_change", speed_kmh=120)],
                  "randomize": {"relaxation_length:sigma_m": ("uniform", 0.05, 0.2)}}
        subs = PTWRollEnv(**kwargs).ride_substeps
        assert subs[1] > subs[0], subs
        assert list(PTWRollVectorEnv(num_envs=2, **kwargs).nsub) == [subs[0], subs[0], subs[1], subs[1]]
    elif case == "vehicle":  # the vehicle's own masses, geometry and inertias drawn, on saturating tires
        kwargs.update(vehicle="sharp1971", effects={"tire_saturation": {"mu_peak": 0.7}},
                      randomize={"vehicle:M_r": ("uniform", 150.0, 300.0), "vehicle_scale:I_rx": ("uniform", 0.8, 1.2),
                                 "vehicle:h": ("normal", 0.6, 0.05, 0.5, 0.7), "vehicle_scale:C_f1": ("uniform", 0.7, 1.3)})
        scale = 1.2 * ptw_env.load_vehicle("sharp1971").torque_ratio * 60.0
    diff, ends, rides = replay_against_single(kwargs, n=3, steps=600, seed=11, action_scale=scale)
    assert ends >= 3, "the replay must cross episode ends to test the autoreset"
    if case in ("rides", "rides_substeps"):
        assert rides == {0, 1}, "the replay must step on both rides"
    # compiled batched plants (randomised) differ from one-by-one ones only by round-off
    assert diff <= (1e-9 if case in ("randomized", "rides_substeps", "vehicle") else 0.0)


def test_randomised_next_episodes_compiled_in_batches_keep_env_i_equal_to_a_single_env():
    """More envs than one compile batch (COMPILE_BATCH): each env's next episode is drawn at its reset and
    compiled later with other envs' (or at once when it is needed first); a few envs are replayed against
    single envs through their falls, and a seeded partial reset (reset_mask) starts those envs afresh."""
    from ptw_env.vector import COMPILE_BATCH

    n = COMPILE_BATCH + 44
    kwargs = {"scenario": "slalom", "speed_kmh": 40, "vehicle": "sharp1971",
              "randomize": {"tire_saturation:mu_peak": ("uniform", 0.5, 1.0), "vehicle_scale:M_r": ("uniform", 0.8, 1.3),
                            "sensor_noise_scale": ("uniform", 0.5, 2.0), "road_bank:bank_rad": ("normal", 0, 0.01)}}
    scale = 1.2 * ptw_env.load_vehicle("sharp1971").torque_ratio * 60.0
    diff, ends, _ = replay_against_single(kwargs, n=n, steps=500, seed=3, action_scale=scale, check=(0, 141, n - 1))
    assert ends >= 6, "each replayed env must cross several episode ends"
    assert diff <= 1e-9, diff
    # a seeded partial reset: the masked envs draw afresh from their new generators, the others go on
    venv = PTWRollVectorEnv(num_envs=n, **kwargs)
    venv.reset(seed=0)
    for _ in range(3):
        venv.step(np.zeros((n, 1), dtype=np.float32))
    mask = np.zeros(n, dtype=bool)
    mask[[5, n - 2]] = True
    seeds = [None] * n
    seeds[5], seeds[n - 2] = 1000, 1001
    obs, info = venv.reset(seed=seeds, options={"reset_mask": mask})
    for i, sd in ((5, 1000), (n - 2, 1001)):
        o, inf = PTWRollEnv(**kwargs).reset(seed=sd)
        assert np.array_equal(o, obs[i])
        assert inf["randomized"] == {k: v[i] for k, v in info["randomized"].items()}
    assert info["state"][6][0] != 0.0 and venv.step_index[6] == 3  # untouched


def test_a_mirrored_ride_is_the_mirror_image():
    """The model is odd in the lateral states: on the mirrored ride, with the torques negated, every lateral
    state is negated (noise-free sensors, no starting roll)."""
    kw = dict(scenario_pool=["slalom"], mirror=True, sensors=ptw_env.sensors.SensorConfig.noiseless(), init_roll_deg=0.0)
    runs = {}
    for seed in range(20):
        env = PTWRollEnv(**kw)
        _, info = env.reset(seed=seed)
        if info["mirrored"] in runs:
            continue
        sign = -1.0 if info["mirrored"] else 1.0
        rng = np.random.default_rng(0)
        xs = [env.step(np.array([sign * rng.normal(0, 5)], dtype=np.float32))[4]["state"] for _ in range(300)]
        runs[info["mirrored"]] = np.array(xs)
        if len(runs) == 2:
            break
    np.testing.assert_allclose(runs[True], -runs[False], rtol=0, atol=1e-12)
    assert np.max(np.abs(runs[False][:, 0])) > 0.01  # the ride leans (0.023 rad)


def test_make_vec_and_vector_conventions():
    envs = gym.make_vec("PTWRoll-Slalom-v0", num_envs=5, vectorization_mode="vector_entry_point")
    u = envs.unwrapped
    assert isinstance(u, PTWRollVectorEnv) and u.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.observation_space.shape == (5,) + envs.single_observation_space.shape
    assert envs.action_space.shape == (5, 1)
    obs, info = envs.reset(seed=3)
    assert obs in envs.observation_space and obs.dtype == np.float32
    assert u.np_random_seed == (3, 4, 5, 6, 7)
    assert set(info) >= {"state", "_state", "cost", "_cost"} and info["_state"].all()
    obs2, _ = envs.reset(seed=3)
    np.testing.assert_array_equal(obs, obs2)  # reset(seed) reproduces
    obs3, _ = envs.reset(seed=[3, 4, 5, 6, 8])
    np.testing.assert_array_equal(obs3[:4], obs[:4])
    assert not np.array_equal(obs3[4], obs[4])


def test_next_step_autoreset_and_reset_mask():
    """The step after an episode ends returns that env's first observation, reward 0 and no end; the
    action is ignored for it; a reset_mask resets only the masked envs."""
    venv = PTWRollVectorEnv(num_envs=2, scenario="slalom", speed_kmh=40, init_roll_deg=0.0)
    venv.reset(seed=0)
    a = np.array([[60.0], [0.0]], dtype=np.float32)  # full torque on env 0 throws it over
    for _ in range(400):
        obs, rew, term, trunc, info = venv.step(a)
        if term[0]:
            break
    assert term[0] and info["reason"][0] == "fell" and not info["_reason"][1]
    k1 = venv.step_index[1]
    obs, rew, term, trunc, info = venv.step(a)
    assert rew[0] == 0.0 and not term[0] and not trunc[0]
    assert info["t"][0] == 0.0 and np.all(info["state"][0, 1:] == 0.0)  # env 0 restarted upright
    assert venv.step_index[1] == k1 + 1  # env 1 went on
    mask = np.array([False, True])
    before = venv.state[0].copy()
    obs_before = obs[0].copy()
    obs, _ = venv.reset(options={"reset_mask": mask})
    assert venv.step_index.tolist() == [0, 0]  # env 0 (restarted on the step before) has not moved
    np.testing.assert_array_equal(venv.state[0], before)  # env 0 untouched by env 1's reset
    np.testing.assert_array_equal(obs[0], obs_before)
    with pytest.raises(EnvConfigError, match="reset_mask"):
        venv.reset(options={"reset_mask": np.array([1, 0])})


def test_bad_vector_arguments_are_named():
    with pytest.raises(EnvConfigError, match="num_envs"):
        PTWRollVectorEnv(num_envs=0)
    with pytest.raises(EnvConfigError, match="friction"):
        PTWRollVectorEnv(num_envs=2, friction=object())
    with pytest.raises(EnvConfigError, match="speed_kmh|vehicle|range"):
        PTWRollVectorEnv(num_envs=2, speed_kmh=500)
    venv = PTWRollVectorEnv(num_envs=2)
    with pytest.raises(EnvConfigError, match="before reset"):
        venv.step(np.zeros((2, 1)))
    venv.reset(seed=0)
    with pytest.raises(EnvConfigError, match="env 1 is not finite"):
        venv.step(np.array([[0.0], [np.nan]]))


def test_render_one_env():
    venv = PTWRollVectorEnv(num_envs=3, render_mode="rgb_array", render_env=2)
    venv.reset(seed=0)
    for _ in range(5):
        venv.step(np.zeros((3, 1), dtype=np.float32))
    single = PTWRollEnv(render_mode="rgb_array")
    single.reset(seed=2)
    for _ in range(5):
        single.step(np.zeros(1, dtype=np.float32))
    np.testing.assert_array_equal(venv.render(), single.render())


def test_single_env_passes_the_checkers():
    check_env(PTWRollEnv(actuator=Actuator(delay_s=0.02), randomize={"tire_stiffness:scale": ("uniform", 0.8, 1.2)}),
              skip_render_check=True)
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(PTWRollEnv(normalize_action=True), warn=False)


# ---------------------------------------------------------------- actuator
def _torques(actuator: Actuator, commands: np.ndarray) -> np.ndarray:
    env = PTWRollEnv(scenario="constant_radius", actuator=actuator, init_roll_deg=0.0)
    env.reset(seed=0)
    return np.array([env.step(np.array([c], dtype=np.float32))[4]["tau"] for c in commands])


def test_actuator_delay_lag_rate_and_saturation():
    dt = 0.01
    step = np.full(60, 10.0)
    # transport delay: the applied torque is the command D periods earlier
    np.testing.assert_array_equal(_torques(Actuator(delay_s=0.05), step)[:5], 0.0)
    np.testing.assert_array_equal(_torques(Actuator(delay_s=0.05), step)[5:], 10.0)
    # first-order lag: the step response 1 - exp(-2 pi f t) at the period ends
    f = 5.0
    t = dt * np.arange(1, 61)
    np.testing.assert_allclose(_torques(Actuator(bandwidth_hz=f), step), 10.0 * (1 - np.exp(-2 * math.pi * f * t)), rtol=1e-12)
    # rate limit: a ramp of rate * dt per period up to the command
    np.testing.assert_allclose(_torques(Actuator(rate_limit=100.0), step)[:12], np.minimum(1.0 * np.arange(1, 13), 10.0))
    # saturation
    assert np.max(np.abs(_torques(Actuator(torque_limit=4.0), np.full(5, -50.0)))) == 4.0
    with pytest.raises(EnvConfigError, match="whole number of control periods"):
        PTWRollEnv(actuator=Actuator(delay_s=0.015))


# ---------------------------------------------------------------- cost
def test_cost_counts_each_broken_limit():
    """Grip utilisation recomputed from the tire forces in info['state'] and the axle loads; roll and torque
    rate limits each add one."""
    env = PTWRollEnv(scenario="constant_radius", effects={"tire_saturation": {"mu_peak": 0.5}},
                     cost=CostConfig(grip_limit=0.3, roll_limit_deg=10.0, torque_rate_limit=1.0))
    env.reset(seed=0)
    fz = np.array([env.vehicle.tires.Fzf, env.vehicle.tires.Fzr])
    seen = set()
    prev = 0.0
    for k in range(600):
        _, _, term, trunc, info = env.step(np.array([2.0 if k % 50 < 25 else -2.0], dtype=np.float32))
        x = info["state"]
        util = np.max(np.abs(x[6:8]) / (0.5 * fz))
        assert info["grip_utilisation"] == pytest.approx(util, rel=1e-12)
        expect = (util > 0.3) + (abs(x[0]) > math.radians(10)) + (abs(info["tau"] - prev) > 1.0 * env.tau_max * env.dt)
        assert info["cost"] == expect
        seen.add(info["cost"])
        prev = info["tau"]
        if term or trunc:
            break
    assert len(seen) >= 2  # the ride both breaks and keeps limits


# ---------------------------------------------------------------- randomisation
def test_randomization_draws_and_plant():
    r = {"tire_saturation:mu_peak": ("uniform", 0.3, 0.9), "payload:mass_kg": ("normal", 10.0, 5.0, 0.0, 20.0),
         "road_bank:bank_rad": ("choice", [-0.02, 0.02])}
    venv = PTWRollVectorEnv(num_envs=400, randomize=r)
    _, info = venv.reset(seed=0)
    mu = info["randomized"]["tire_saturation:mu_peak"]
    m = info["randomized"]["payload:mass_kg"]
    assert 0.3 <= mu.min() and mu.max() <= 0.9 and abs(mu.mean() - 0.6) < 4 * 0.6 / math.sqrt(12 * 400)
    assert 0.0 <= m.min() and m.max() <= 20.0 and abs(np.median(m) - 10.0) < 1.0
    assert set(info["randomized"]["road_bank:bank_rad"]) == {-0.02, 0.02}
    # the plant of env i is the compiled plant of its draws
    i = 7
    p = ptw_env.compile_plant(venv.template.vehicle, {"tire_saturation": {"mu_peak": mu[i]}, "payload": {"mass_kg": m[i]},
                                                       "road_bank": {"bank_rad": info["randomized"]["road_bank:bank_rad"][i]}})
    W, _, fmax, bank = venv.plant_of(i)
    np.testing.assert_allclose(fmax, p.fmax, rtol=1e-15)
    np.testing.assert_allclose(W, p.W, rtol=1e-12, atol=1e-12)
    assert bank == p.bank
    # the same seed, the same draws; a single env seeded 7 draws env 7's values
    single = PTWRollEnv(randomize=r)
    _, sinfo = single.reset(seed=i)
    assert sinfo["randomized"]["tire_saturation:mu_peak"] == mu[i]


def test_vehicle_randomization_draws_the_vehicle_of_those_parameters():
    """``vehicle:PARAM`` / ``vehicle_scale:PARAM``: env i's plant is the plant of the vehicle file with the drawn
    parameters put in by hand (the scalar path: SharpParameters -> sharp_vehicle -> compile_plant), with Z_f
    following the statics; the draws lie in their ranges; axle loads (hence saturation forces) follow the masses."""
    from dataclasses import replace

    from ptw_env.sharp import sharp_vehicle, static_front_load
    from ptw_env.vehicle_files import load_parameters

    r = {"vehicle:M_r": ("uniform", 60.0, 120.0), "vehicle:k": ("uniform", 0.35, 0.55),
         "vehicle_scale:I_rz": ("loguniform", 0.5, 2.0), "vehicle:eps": ("normal", 0.45, 0.05, 0.35, 0.55)}
    eff = {"tire_saturation": {"mu_peak": 0.8}}
    venv = PTWRollVectorEnv(num_envs=64, vehicle="cossalter_sport_touring", effects=eff, randomize=r,
                            speed_kmh=60)
    _, info = venv.reset(seed=5)
    d = info["randomized"]
    assert 60.0 <= d["vehicle:M_r"].min() and d["vehicle:M_r"].max() <= 120.0
    assert 0.5 <= d["vehicle_scale:I_rz"].min() and d["vehicle_scale:I_rz"].max() <= 2.0
    p = load_parameters("cossalter_sport_touring")
    nominal = venv.template.vehicle
    for i in (0, 17, 63):
        new = dict(M_r=d["vehicle:M_r"][i], k=d["vehicle:k"][i], I_rz=p.I_rz * d["vehicle_scale:I_rz"][i],
                   eps=d["vehicle:eps"][i])
        fzf = static_front_load(p.M_f, new["M_r"], new["k"], p.l_f, p.l_r)
        q = replace(p, **new, Z_f=p.Z_f * fzf / p.static_loads()[0])
        v = sharp_vehicle(q, "by hand", nominal.vmin, nominal.vmax)
        ref = ptw_env.compile_plant(v, eff)
        W, s, fmax, bank = venv.plant_of(i)
        np.testing.assert_allclose(W, ref.W, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(fmax, 0.8 * np.array([v.tires.Fzf, v.tires.Fzr]), rtol=1e-12)
        assert q.static_loads()[0] == pytest.approx(-q.Z_f * p.static_loads()[0] / -p.Z_f, rel=1e-12)
    # the heaviest rider puts the most weight on the rear wheel
    heavy, light = int(np.argmax(d["vehicle:M_r"])), int(np.argmin(d["vehicle:M_r"]))
    assert venv.plant_of(heavy)[2][1] > venv.plant_of(light)[2][1]
    # a single env seeded 17 draws env 17's vehicle
    _, sinfo = PTWRollEnv(vehicle="cossalter_sport_touring", effects=eff, randomize=r, speed_kmh=60).reset(seed=5 + 17)
    assert sinfo["randomized"]["vehicle:M_r"] == d["vehicle:M_r"][17]


def test_vehicle_randomization_sizes_the_step_for_the_fastest_drawn_vehicle():
    """Short relaxation lengths make faster tire lags (vx/sigma): the substeps follow the fastest corner at
    the ride's speed, computed here from vehicles built by hand and their eigenvalues at that speed (the
    lane change is ridden at one speed), with the RK4 bounds (2.5 ms, |lambda h| <= MAX_LAMBDA_H) applied
    by hand."""
    from dataclasses import replace

    from ptw_env.integrate import DEFAULT_SUBSTEP, MAX_LAMBDA_H
    from ptw_env.sharp import sharp_vehicle
    from ptw_env.vehicle_files import load_parameters

    p = load_parameters("sharp1971")
    nominal = ptw_env.load_vehicle("sharp1971")
    r = {"vehicle:sigma_f": ("uniform", 0.05, 0.3), "vehicle_scale:sigma_r": ("uniform", 0.25, 1.0)}
    for kmh in (50, 120):
        env = PTWRollEnv(vehicle="sharp1971", randomize=r, speed_kmh=kmh)
        vx = float(env.profile.vx[0])
        assert np.all(env.profile.vx == vx)

        def lam(v) -> float:
            return float(np.abs(np.linalg.eigvals(v.state_matrix(vx))).max())

        rates = [lam(sharp_vehicle(replace(p, sigma_f=sf, sigma_r=p.sigma_r * sr), "x", nominal.vmin, nominal.vmax))
                 for sf in (0.05, 0.3) for sr in (0.25, 1.0)]
        assert max(rates) > 2 * lam(nominal)
        expected = int(np.ceil(env.dt / min(DEFAULT_SUBSTEP, MAX_LAMBDA_H / max(rates)) - 1e-9))
        assert env.substeps == expected > PTWRollEnv(vehicle="sharp1971", speed_kmh=kmh).substeps


def test_randomised_effects_size_the_step_for_the_stiffest_plant():
    """A short relaxation length makes a fast tire lag (vx / sigma): the env's substeps keep |lambda h| of the
    stiffest drawable plant (sigma = 0.02 m) at the ride's top speed inside the RK4 accuracy bound, computed
    here from that plant's own eigenvalues, and so do a fixed effect's; a slower ride takes fewer (the step
    is sized for the speeds ridden, not the vehicle's top speed); ``substeps=`` raises the count, never
    lowers it."""
    from ptw_env.integrate import DEFAULT_SUBSTEP, MAX_LAMBDA_H

    rnd = {"relaxation_length:sigma_m": ("uniform", 0.02, 0.2)}
    stiff = ptw_env.compile_plant(None, {"relaxation_length": {"sigma_m": 0.02}})
    counts = {}
    for kmh in (40, 140):
        env = PTWRollEnv(randomize=rnd, speed_kmh=kmh)
        A, _ = ptw_env.linearise(stiff, float(env.profile.vx.max()))
        lam = float(np.abs(np.linalg.eigvals(A)).max())
        assert lam > 5 * env.vehicle.fastest_rate(env.profile.vx)
        assert lam * env.dt / env.substeps <= MAX_LAMBDA_H < lam * env.dt / (env.substeps - 1)
        # the same plant as a fixed effect gets the same step (it used to keep the vehicle's 4 substeps)
        assert PTWRollEnv(effects={"relaxation_length": {"sigma_m": 0.02}}, speed_kmh=kmh).substeps == env.substeps
        counts[kmh] = env.substeps
    assert counts[40] < counts[140]
    # the top of the range: what every ride took before the step followed the ride's speeds
    A, _ = ptw_env.linearise(stiff, env.vehicle.vmax)
    assert float(np.abs(np.linalg.eigvals(A)).max()) * env.dt / counts[40] > MAX_LAMBDA_H
    # a fixed scooter at 50 km/h keeps the 2.5 ms accuracy step
    assert PTWRollEnv().substeps == round(PTWRollEnv().dt / DEFAULT_SUBSTEP)
    assert PTWRollEnv(substeps=9).substeps == 9 and PTWRollEnv(substeps=1).substeps == PTWRollEnv().substeps
    with pytest.raises(EnvConfigError, match="substeps must be a positive whole number"):
        PTWRollEnv(substeps=0)


def test_step_speeds_vehicle_keeps_the_step_of_the_whole_range():
    """A front tire of 0.8x stiffness makes the scooter's fastest mode 188 1/s at 40 m/s, just past the edge
    of 4 substeps: sized for the vehicle's whole range (``step_speeds="vehicle"``, what ride logs keep) it takes
    5 on a 50 km/h ride, sized for the ride (default) 4, each checked against that plant's own eigenvalues."""
    from ptw_env.integrate import MAX_LAMBDA_H

    eff = {"tire_stiffness": {"front_scale": 0.8, "rear_scale": 1.0}}
    plant = ptw_env.compile_plant(None, eff)
    ride, whole = PTWRollEnv(effects=eff), PTWRollEnv(effects=eff, step_speeds="vehicle")

    def lam(vx: float) -> float:
        return float(np.abs(np.linalg.eigvals(ptw_env.linearise(plant, vx)[0])).max())

    assert lam(whole.vehicle.vmax) * whole.dt / 4 > MAX_LAMBDA_H >= lam(whole.vehicle.vmax) * whole.dt / whole.substeps
    assert (ride.substeps, whole.substeps) == (4, 5)
    assert lam(float(ride.profile.vx.max())) * ride.dt / ride.substeps <= MAX_LAMBDA_H
    with pytest.raises(EnvConfigError, match="step_speeds must be 'ride' or 'vehicle'"):
        PTWRollEnv(step_speeds="fast")


def test_vehicle_randomization_errors_name_the_key_and_the_problem():
    cases = [
        (None, {"vehicle:M_r": ("uniform", 150, 300)}, "given as matrix entries"),
        ("sharp1971", {"vehicle:Z_f": -1000.0}, "Z_f follows the statics"),
        ("sharp1971", {"vehicle:M_x": 1.0}, "unknown vehicle parameter in 'vehicle:M_x'"),
        ("sharp1971", {"vehicle:M_r": ("normal", 200, 10)}, "needs finite bounds"),
        ("sharp1971", {"vehicle:M_r": ("uniform", 0.0, 10.0)}, "M_r .* must be > 0, got 0"),
        ("sharp1971", {"vehicle:k": ("uniform", -5.0, 1.0)}, "mass centre must lie between the contact points"),
        ("sharp1971", {"vehicle:C_rxz": ("uniform", -50.0, 50.0)}, "not positive definite"),
        ("sharp1971", {"vehicle:eps": ("uniform", 0.2, 1.6)}, "vehicle:eps.*physical range"),
        ("sharp1971", {"vehicle:M_r": 100.0, "vehicle_scale:M_r": 1.0}, "not both"),
        ("sharp1971", {"vehicle:k": ("uniform", 0.5, 20.0)}, "on the rear .*between the contact points"),
    ]
    for vehicle, r, msg in cases:
        with pytest.raises(EnvConfigError, match=msg):
            PTWRollEnv(vehicle=vehicle, randomize=r)
    # a vehicle whose matrices were edited after it was built from its parameters
    from dataclasses import replace

    v = ptw_env.load_vehicle("sharp1971")
    A0 = v.A0.copy()
    A0[5, 5] -= 3.0
    with pytest.raises(EnvConfigError, match="not those of its physical parameters"):
        PTWRollEnv(vehicle=replace(v, A0=A0), randomize={"vehicle_scale:M_r": ("uniform", 0.9, 1.1)})
    # the library call without an environment: one clear error, not an AttributeError
    from ptw_env.effects import Effects

    with pytest.raises(RandomizationError, match="vehicle_scale:M_r draws a physical parameter"):
        Randomization({"vehicle_scale:M_r": ("uniform", 0.9, 1.1)}).plant(ptw_env.REFERENCE_SCOOTER, Effects(),
                                                                           {"vehicle_scale:M_r": 1.0})


def test_randomization_errors_name_the_key():
    with pytest.raises(RandomizationError, match="tire_saturation:mu_peak.*physical range"):
        Randomization({"tire_saturation:mu_peak": ("uniform", 0.0, 1.0)})
    with pytest.raises(RandomizationError, match="unknown key 'tyre:mu'"):
        Randomization({"tyre:mu": 1.0})
    with pytest.raises(RandomizationError, match="sensor_delay"):
        Randomization({"sensor_delay:delay_s": ("uniform", 0.0, 0.02)})
    with pytest.raises(EnvConfigError, match="loguniform needs low > 0"):
        PTWRollEnv(randomize={"payload:mass_kg": ("loguniform", 0, 5)})
    r = Randomization({"payload:mass_kg": {"dist": "normal", "mean": 0, "std": 5}, "sensor_noise_scale": 2,
                       "tire_saturation:mu_peak": ("normal", 0.8, 0.2), "road_bank:bank_rad": ("choice", [0.0, 0.01])})
    import json

    assert Randomization(json.loads(json.dumps(r.to_json(), allow_nan=False))) == r  # strict JSON round trip


def test_sb3_adapter_keeps_each_env_equal_to_a_single_env():
    """Through SB3VecEnv (same-step resets by reset_mask) env i still rides exactly as a single env reset at
    each episode end: the other envs are not moved by a partial reset."""
    pytest.importorskip("stable_baselines3")
    from assist.rl.vecenv import SB3VecEnv

    kw = {"scenario": "slalom", "speed_kmh": 40}
    venv = SB3VecEnv(PTWRollVectorEnv(num_envs=3, **kw))
    venv.seed(5)
    obs = venv.reset()
    singles = [PTWRollEnv(**kw) for _ in range(3)]
    for i, e in enumerate(singles):
        np.testing.assert_array_equal(e.reset(seed=5 + i)[0], obs[i])
    rng = np.random.default_rng(1)
    ends = 0
    for _ in range(500):
        a = (rng.uniform(0.0, 1.0, (3, 1)) * 60.0).astype(np.float32)
        obs, rew, done, infos = venv.step(a)
        for i, e in enumerate(singles):
            o, r, te, tr, _ = e.step(a[i])
            assert r == rew[i] and (te or tr) == done[i]
            if done[i]:
                ends += 1
                np.testing.assert_array_equal(infos[i]["terminal_observation"], o)
                o, _ = e.reset()
            np.testing.assert_array_equal(o, obs[i])
    assert ends >= 3


def test_sb3_trains_on_the_vector_env():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from assist.rl.vecenv import SB3VecEnv

    venv = SB3VecEnv(gym.make_vec("PTWRollNorm-v0", num_envs=16, vectorization_mode="vector_entry_point"))
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=128, n_epochs=1, seed=0, device="cpu")
    model.learn(512)
    assert model.num_timesteps >= 512
    # terminal observations reach SB3 as its contract says
    venv.seed(0)
    venv.reset()
    for _ in range(300):
        obs, rew, done, infos = venv.step(np.ones((16, 1), dtype=np.float32))
        if done.any():
            i = int(np.flatnonzero(done)[0])
            assert "terminal_observation" in infos[i] and infos[i]["TimeLimit.truncated"] is False
            assert venv.venv.unwrapped.step_index[i] == 0
            break
    else:
        pytest.fail("full torque should throw a vehicle over within 3 s")


@pytest.mark.parametrize("kw, words", [
    (dict(seed=[None, None, None, -1]), "seeds must be integers >= 0"),
    (dict(seed=-3), "seeds must be integers >= 0"),
    (dict(options="abc"), "reset options must be a dict"),
    (dict(options={"x0": "abc"}), "x0 must be 8 finite numbers"),
    (dict(options={"x0": {}}), "x0 must be 8 finite numbers"),
])
def test_a_bad_reset_is_one_error_and_changes_nothing(kw, words):
    """A refused reset leaves every env as it was: a bad seed in the list is found before any generator is
    replaced (a first reset that failed half-way left an env on a placeholder generator, randomisation off)."""
    r = {"payload:mass_kg": ("normal", 0.0, 10.0)}
    venv = PTWRollVectorEnv(num_envs=4, randomize=r)
    with pytest.raises(EnvConfigError, match=words):
        venv.reset(**kw)
    _, info = venv.reset(seed=7)
    assert venv.np_random_seed == (7, 8, 9, 10)
    _, ref = PTWRollVectorEnv(num_envs=4, randomize=r).reset(seed=7)
    np.testing.assert_array_equal(info["randomized"]["payload:mass_kg"], ref["randomized"]["payload:mass_kg"])
    with pytest.raises(EnvConfigError, match="step_speeds"):
        PTWRollEnv(step_speeds=np.array([1, 2]))
