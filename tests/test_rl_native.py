"""Native RL training on the vector env (issue 21): the batched encoder is the single one, the encoded
SB3 env keeps SB3's contract (terminal observations encoded, new episodes start a fresh history), and a
short native training run gives a policy the evaluation runs."""

from __future__ import annotations

import numpy as np
import pytest

from assist.rl.policy import ObsEncoder
from assist.rl.training import TrainingDistribution, native_training_env
from ptw_env.vehicle import REFERENCE_SCOOTER

pytestmark = pytest.mark.rl


def test_batched_encoder_is_the_single_encoder():
    enc = ObsEncoder.for_speeds(8.0, 33.0)
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(30, 3, 7)).astype(np.float32) * np.array([0.05, 0.2, 0.5, 1, 5, 10, 0.5], np.float32)
    acts = rng.uniform(-1.5, 1.5, size=(30, 3))
    buf = np.zeros((3, enc.dim), dtype=np.float32)
    enc.reset_into(obs[0], buf)
    singles = [ObsEncoder.for_speeds(8.0, 33.0) for _ in range(3)]
    want = [e.reset(obs[0, i]) for i, e in enumerate(singles)]
    np.testing.assert_array_equal(buf, np.array(want))
    for t in range(1, 30):
        enc.step_into(obs[t], acts[t], buf)
        want = [e.step(obs[t, i], acts[t, i]) for i, e in enumerate(singles)]
        np.testing.assert_array_equal(buf, np.array(want))


def test_encoded_native_env_keeps_the_sb3_contract():
    pytest.importorskip("stable_baselines3")
    dist = TrainingDistribution().for_vehicle(REFERENCE_SCOOTER)
    enc = ObsEncoder.for_speeds(*(v / 3.6 for v in dist.speed_kmh))
    venv = native_training_env(4, 0, dist, enc, 60.0, REFERENCE_SCOOTER, smooth_weight=0.1, pool=4)
    obs = venv.reset()
    assert obs.shape == (4, enc.dim)
    np.testing.assert_array_equal(obs[:, :7], obs[:, 7:14])  # a fresh history repeats the first frame
    a = np.ones((4, 1), dtype=np.float32)
    seen = False
    for _ in range(400):
        obs, rew, done, infos = venv.step(a)
        assert np.all(obs[:, -1] == np.where(done, 0.0, 1.0))  # previous action; 0 in a new episode
        if done.any():
            i = int(np.flatnonzero(done)[0])
            term = infos[i]["terminal_observation"]
            assert term.shape == (enc.dim,) and term[-1] == 1.0  # encoded with the last action
            np.testing.assert_array_equal(obs[i, :7], obs[i, 7:14])  # the next episode starts afresh
            assert "cost" in infos[i]
            seen = True
            break
    assert seen, "full torque should end an episode within 4 s"


def test_a_native_training_run_gives_a_policy_the_evaluation_runs(tmp_path):
    pytest.importorskip("stable_baselines3")
    from assist.evaluate import run_episode
    from assist.rl.training import train

    res = train("ppo", 4096, seed=0, out=tmp_path / "p.zip", n_envs=64, vec="native", progress=False,
                checkpoint_every=None, eval_episodes=1)
    assert res.steps >= 4096 and res.meta["native"]["pool"] == 64 and res.meta["hyper"]["n_steps"] == 256
    assert set(res.meta["native"]["randomize"]) >= {"sensor_noise_scale", "tire_saturation:mu_peak"}
    ep = run_episode("rl", "double_lane_change", speed_kmh=50, noise_pct=5.0, seed=0,
                     controller_options={"policy": str(res.path)})
    assert len(ep.t) > 10
