"""Training of the RL baseline (stable-baselines3, the ``[rl]`` extra): the episode distribution, the training
environment, :func:`train` and :func:`build_model`. See :mod:`assist.rl` for the method."""

from __future__ import annotations

import json
import math
import os
import platform
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ptw_env.env import PTWRollEnv
from ptw_env.rider import DEFAULT_TAU_MAX
from ptw_env.scenarios import make_scenario
from ptw_env.vehicle import G, REFERENCE_SCOOTER, Vehicle

from assist.rl.policy import ALGOS, ObsEncoder, PolicyError, RLPolicy, _algo_class, _MIRROR, require_sb3

@dataclass(frozen=True)
class TrainingDistribution:
    """Which rides the policy trains on (drawn per episode).

    Parameters
    ----------
    speed_kmh : (float, float) or None
        Range of cruise speeds [km/h] (uniform); the constant-radius,
        urban and handling rides stay inside it too. None (default): the
        vehicle's design range (:meth:`for_vehicle`; 28.8-118.8 km/h for the
        reference scooter; the shipped policy was trained on 30-90, its sidecar says so).
    noise_pct : (float, float)
        Sensor noise range, percent of each channel's range (uniform).
    weights : mapping scenario -> float
        Probability of each scenario (normalised).
    max_lean_deg : float
        Largest steady lean of the constant-radius turns [deg].
    mirror : bool
        Mirror half of the episodes left/right (the dynamics are odd).
    """

    speed_kmh: tuple[float, float] | None = None
    noise_pct: tuple[float, float] = (0.0, 6.0)
    weights: tuple[tuple[str, float], ...] = (
        ("double_lane_change", 0.3), ("slalom", 0.2), ("constant_radius", 0.2), ("urban", 0.15), ("handling", 0.15),
    )
    max_lean_deg: float = 35.0
    mirror: bool = True

    def for_vehicle(self, vehicle: Vehicle) -> "TrainingDistribution":
        """This distribution with its speeds resolved: ``speed_kmh`` as given (checked inside the vehicle's
        valid range), else the vehicle's :attr:`~ptw_env.vehicle.Vehicle.control_range` in km/h."""
        if self.speed_kmh is None:
            lo, hi = vehicle.control_range
            return replace(self, speed_kmh=(round(3.6 * lo, 6), round(3.6 * hi, 6)))
        lo, hi = (float(x) for x in self.speed_kmh)
        if not (3.6 * vehicle.vmin - 1e-9 <= lo < hi <= 3.6 * vehicle.vmax + 1e-9):
            raise PolicyError(f"training speeds {lo:g}-{hi:g} km/h: need lo < hi within the valid range of "
                              f"{vehicle.name}, {3.6 * vehicle.vmin:g}-{3.6 * vehicle.vmax:g} km/h")
        return self

    def draw(self, rng: np.random.Generator) -> dict[str, Any]:
        """One episode: ``{"scenario": Scenario, "noise_pct", "mirror", "scenario_seed", "label"}``."""
        if self.speed_kmh is None:
            raise PolicyError("TrainingDistribution.speed_kmh is unresolved: call for_vehicle(vehicle) first")
        names = [n for n, _ in self.weights]
        p = np.array([w for _, w in self.weights], dtype=float)
        name = names[int(rng.choice(len(names), p=p / p.sum()))]
        lo, hi = self.speed_kmh
        v = float(rng.uniform(lo, hi))
        seed = None
        if name == "double_lane_change":
            sc = make_scenario(name, speed_kmh=v, offset_m=float(rng.uniform(2.0, 4.5)))
        elif name == "slalom":
            vm = v / 3.6
            d = vm * float(rng.uniform(1.5, 2.5))  # half period 1.5-2.5 s
            acc = float(rng.uniform(1.5, 3.5))  # peak lateral acceleration [m/s^2]
            sc = make_scenario(name, speed_kmh=v, cone_spacing_m=d, amplitude_m=acc * d**2 / (vm**2 * math.pi**2),
                               n_cones=6)
        elif name == "constant_radius":
            v0 = float(rng.uniform(lo, 0.5 * (lo + hi)))
            v1 = float(rng.uniform(v0, hi))
            lean = math.radians(float(rng.uniform(10.0, self.max_lean_deg)))
            radius = (max(v0, v1) / 3.6) ** 2 / (G * math.tan(lean))
            sc = make_scenario(name, v_start_kmh=v0, v_end_kmh=v1, radius_m=radius)
        elif name == "urban":
            sc = make_scenario(name, v_min_kmh=lo, v_max_kmh=hi, duration_s=60.0)
            seed = int(rng.integers(2**31))
        elif name == "handling":
            sc = make_scenario(name, v_max_kmh=hi, lateral_g=float(rng.uniform(0.3, 0.5)), duration_s=45.0)
        else:  # pragma: no cover - weights are checked by the dataclass user
            raise PolicyError(f"unknown training scenario {name!r}")
        return {"scenario": sc, "noise_pct": float(rng.uniform(*self.noise_pct)),
                "mirror": bool(self.mirror and rng.random() < 0.5), "scenario_seed": seed, "label": name}

    def describe(self) -> dict[str, Any]:
        return {"speed_kmh": None if self.speed_kmh is None else list(self.speed_kmh), "noise_pct": list(self.noise_pct),
                "weights": dict(self.weights), "max_lean_deg": self.max_lean_deg, "mirror": self.mirror}


#: Training-only penalty on the action change (see :class:`TrainingEnv`); 0.1 chosen by a one-off measurement
#: (``train("ppo", 1_000_000, seed=0, env_kwargs={"smooth_weight": w})``, no script reruns it): at 1 M steps, 0.1 gave the best environment return (3962 vs 2436 with 0.3; 1.0 did not learn to
#: track) and 30 % less torque RMS than 0 on the lane change.
SMOOTH_WEIGHT = 0.1


class TrainingEnv(gym.Env):
    """Roll tracking on a ride drawn per episode, seen through :class:`ObsEncoder`.

    Each ``reset`` draws a ride from ``distribution`` with the environment's
    generator (seeded by ``reset(seed=...)``), builds the
    :class:`~ptw_env.env.PTWRollEnv` for it (action normalised to ``[-1, 1]``)
    and resets it with a seed from the same generator: same seed, same
    sequence of episodes. The reward is the environment's. ``info`` holds
    the ride's label and the end reason, not the state.

    Parameters
    ----------
    distribution : TrainingDistribution, optional
    encoder : dict, optional
        :meth:`ObsEncoder.config` (default encoder if omitted).
    fixed : dict, optional
        Instead of the distribution, always this ride:
        ``{"scenario": name, "speed_kmh": ..., "noise_pct": ...}``.
    tau_max : float, optional
        Steering torque of action 1 [N m] (default the environment's for the vehicle: 60 N m on the
        reference scooter, scaled by ``torque_ratio`` on another).
    vehicle : Vehicle, optional
        The vehicle ridden (default the reference scooter); the distribution's speeds and the default
        encoder's ``vx`` scaling follow its design range (:meth:`ObsEncoder.for_speeds`).
    smooth_weight : float
        Training-only shaping: ``smooth_weight (a_k - a_{k-1})^2`` is taken
        from the reward the agent learns from (the environment's own reward
        is ``info["env_reward"]``); it discourages a torque that chatters
        at 100 Hz, which the environment's effort term (0.01) hardly does
        (default :data:`SMOOTH_WEIGHT`).
    """

    metadata = {"render_modes": []}

    def __init__(self, distribution: TrainingDistribution | None = None, encoder: Mapping[str, Any] | None = None,
                 fixed: Mapping[str, Any] | None = None, tau_max: float | None = None,
                 smooth_weight: float = SMOOTH_WEIGHT, vehicle: Vehicle | None = None) -> None:
        super().__init__()
        if not (isinstance(smooth_weight, (int, float)) and math.isfinite(smooth_weight) and smooth_weight >= 0):
            raise PolicyError(f"smooth_weight must be a number >= 0, got {smooth_weight!r}")
        self.smooth_weight = float(smooth_weight)
        self._a_prev = 0.0
        self.vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
        if not isinstance(self.vehicle, Vehicle):
            raise PolicyError(f"vehicle must be a Vehicle (ptw_env.load_vehicle), got {type(vehicle).__name__}")
        self.distribution = (distribution or TrainingDistribution()).for_vehicle(self.vehicle)
        lo, hi = self.distribution.speed_kmh
        self.encoder = ObsEncoder.from_config(encoder) if encoder else ObsEncoder.for_speeds(lo / 3.6, hi / 3.6, self.vehicle)
        self.fixed = dict(fixed) if fixed else None
        self.tau_max = float(DEFAULT_TAU_MAX * self.vehicle.torque_ratio if tau_max is None else tau_max)
        c = self.encoder.clip
        self.observation_space = spaces.Box(-c, c, shape=(self.encoder.dim,), dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self._env: PTWRollEnv | None = None
        self._sign = 1.0
        self._label = ""
        self._act = np.zeros(1, dtype=np.float32)

    def _make(self) -> PTWRollEnv:
        if self.fixed is not None:
            f = self.fixed
            self._sign, self._label = 1.0, str(f["scenario"])
            return PTWRollEnv(f["scenario"], speed_kmh=f.get("speed_kmh"), noise_pct=f.get("noise_pct", 5.0),
                              normalize_action=True, tau_max=self.tau_max, vehicle=self.vehicle)
        ep = self.distribution.draw(self.np_random)
        self._sign = -1.0 if ep["mirror"] else 1.0
        self._label = ep["label"]
        return PTWRollEnv(ep["scenario"], noise_pct=ep["noise_pct"], normalize_action=True, tau_max=self.tau_max,
                          scenario_seed=ep["scenario_seed"], vehicle=self.vehicle)

    def _flip(self, obs: np.ndarray) -> np.ndarray:
        return obs * _MIRROR if self._sign < 0 else obs

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if self._env is not None:
            self._env.close()
        self._env = self._make()
        obs, _ = self._env.reset(seed=int(self.np_random.integers(2**31)))
        self._a_prev = 0.0
        return self.encoder.reset(self._flip(obs)), {"ride": self._label}

    def step(self, action):
        a = min(max(float(np.ravel(action)[0]), -1.0), 1.0)
        self._act[0] = self._sign * a
        obs, reward, term, trunc, info = self._env.step(self._act)
        out = {"ride": self._label, "env_reward": reward}
        if "reason" in info:
            out["reason"] = info["reason"]
        shaped = reward - self.smooth_weight * (a - self._a_prev) ** 2
        self._a_prev = a
        return self.encoder.step(self._flip(obs), a), shaped, term, trunc, out


# ----------------------------------------------------------------------------- policy
def _tqdm_callback(total: int):
    """A progress bar over environment steps with the mean training-episode return (tqdm only, no rich)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class TqdmCallback(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, unit="step", unit_scale=True, desc="train-rl", dynamic_ncols=True)

        def _on_step(self) -> bool:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            buf = self.model.ep_info_buffer
            if buf and self.n_calls % 50 == 0:
                self.bar.set_postfix(ep_return=f"{np.mean([e['r'] for e in buf]):.0f}",
                                     ep_len=f"{np.mean([e['l'] for e in buf]):.0f}", refresh=False)
            return True

        def _on_training_end(self) -> None:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            self.bar.close()

    return TqdmCallback()


#: PPO settings of ``train`` (the shipped policy's); overridable with ``hyper=``.
PPO_DEFAULTS: dict[str, Any] = {
    "n_steps": 1024, "batch_size": 256, "n_epochs": 10, "learning_rate": 3e-4, "lr_end": 3e-5, "gamma": 0.99,
    "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.0, "max_grad_norm": 0.5,
    "policy_kwargs": {"net_arch": {"pi": [64, 64], "vf": [64, 64]}, "log_std_init": -1.0},
}
SAC_DEFAULTS: dict[str, Any] = {
    "learning_rate": 3e-4, "buffer_size": 300_000, "learning_starts": 5_000, "batch_size": 256, "tau": 0.005,
    "gamma": 0.99, "train_freq": 1, "gradient_steps": 1,
    "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -1.0},
}


@dataclass
class TrainResult:
    """What :func:`train` did (the figures of ``train-rl --json``)."""

    path: Path
    algo: str
    steps: int
    seed: int
    seconds: float
    final_reward: float
    random_reward: float
    initial_reward: float
    meta: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        return {"steps": self.steps, "seconds": self.seconds, "final_reward": self.final_reward,
                "random_policy_reward": self.random_reward, "untrained_policy_reward": self.initial_reward,
                "algo": self.algo, "seed": self.seed, "policy": str(self.path), "meta": self.meta}


def _vec_env(n_envs: int, seed: int, vec: str, env_kwargs: dict[str, Any]):
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    cls = {"dummy": DummyVecEnv, "subproc": SubprocVecEnv}[vec]
    kw = {"start_method": "fork"} if vec == "subproc" and sys.platform.startswith("linux") else None
    return make_vec_env(TrainingEnv, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs, vec_env_cls=cls,
                        vec_env_kwargs=kw)


#: Vehicle and road randomisation of native training (``vec="native"``), per episode: tire stiffness
#: +-20 %, tire peak friction 0.6-1.1 (dry to damp), payload 0-20 % of the vehicle's mass, road bank
#: 0 +- 0.02 rad (clipped to 0.05); derived from the vehicle, nothing of one vehicle.
def training_randomization(vehicle: Vehicle) -> dict[str, Any]:
    """The ``randomize=`` of native training for ``vehicle`` (see the comment above)."""
    return {"tire_stiffness:scale": ("uniform", 0.8, 1.2), "tire_saturation:mu_peak": ("uniform", 0.6, 1.1),
            "payload:mass_kg": ("uniform", 0.0, round(0.2 * float(vehicle.mass), 3)),
            "road_bank:bank_rad": ("normal", 0.0, 0.02, -0.05, 0.05)}


def native_training_env(n_envs: int, seed: int, distribution: TrainingDistribution, encoder: ObsEncoder,
                        tau_max: float, vehicle: Vehicle, smooth_weight: float = SMOOTH_WEIGHT, pool: int = 64,
                        randomize_vehicle: bool = True) -> Any:
    """The SB3 ``VecEnv`` of native training: :class:`ptw_env.vector.PTWRollVectorEnv` with ``n_envs`` envs
    (seeded ``seed + i``), a pool of ``pool`` rides drawn once from ``distribution`` (with
    ``numpy.random.default_rng(seed)``), each episode one of them, mirrored with probability 1/2; the
    sensor noise drawn per episode as a factor in ``[lo/hi, 1]`` of ``hi`` percent of each channel's range
    (``distribution.noise_pct = (lo, hi)``; the GPS speed noise scales with it, unlike :class:`TrainingEnv`);
    :func:`training_randomization` when ``randomize_vehicle``; seen through ``encoder`` with the
    action-change penalty ``smooth_weight`` (:class:`EncodedVecEnv`). Its ``description`` (pool, mirror,
    noise, randomisation) goes into the policy's sidecar."""
    from ptw_env.vector import PTWRollVectorEnv

    from assist.rl.vecenv import SB3VecEnv

    rng = np.random.default_rng(seed)
    rides = []
    for _ in range(int(pool)):
        ep = distribution.draw(rng)
        sc = ep["scenario"]
        rides.append(replace(sc, seed=ep["scenario_seed"]) if ep["scenario_seed"] is not None else sc)
    lo, hi = distribution.noise_pct
    randomize: dict[str, Any] = {"sensor_noise_scale": ("uniform", lo / hi, 1.0)} if hi > 0 else {}
    if randomize_vehicle:
        randomize.update(training_randomization(vehicle))
    venv = PTWRollVectorEnv(num_envs=int(n_envs), scenario_pool=rides, mirror=distribution.mirror, noise_pct=hi,
                            normalize_action=True, tau_max=tau_max, vehicle=vehicle, randomize=randomize or None)
    sb3 = SB3VecEnv(venv)
    sb3.seed(int(seed))
    out = EncodedVecEnv(sb3, encoder, smooth_weight)
    out.description = {"pool": int(pool), "mirror": bool(distribution.mirror), "noise_pct_max": float(hi),
                       "randomize": randomize}
    return out


def _encoded_vec_env_class():
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class EncodedVecEnvImpl(VecEnvWrapper):
        """An SB3 ``VecEnv`` seen through :class:`ObsEncoder` (the policy's input, batched) with the training-only
        penalty ``smooth_weight (a_k - a_{k-1})^2`` on the action change, as :class:`TrainingEnv` does for one
        env; an ended episode's ``terminal_observation`` is encoded too (SB3 bootstraps truncated episodes
        from it)."""

        def __init__(self, venv, encoder: ObsEncoder, smooth_weight: float = SMOOTH_WEIGHT) -> None:
            c = encoder.clip
            super().__init__(venv, observation_space=spaces.Box(-c, c, shape=(encoder.dim,), dtype=np.float32),
                             action_space=spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32))
            self.encoder = encoder
            self.smooth_weight = float(smooth_weight)
            self._buf = np.zeros((venv.num_envs, encoder.dim), dtype=np.float32)
            self._a_prev = np.zeros(venv.num_envs)
            self._a = np.zeros(venv.num_envs)

        def reset(self):
            obs = self.venv.reset()
            self.encoder.reset_into(obs, self._buf)
            self._a_prev[:] = 0.0
            return self._buf.copy()

        def step_async(self, actions: np.ndarray) -> None:
            self._a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.num_envs), -1.0, 1.0)
            self.venv.step_async(self._a.reshape(-1, 1).astype(np.float32))

        def step_wait(self):
            obs, rew, done, infos = self.venv.step_wait()
            shaped = rew - self.smooth_weight * (self._a - self._a_prev) ** 2
            if done.any():
                idx = np.flatnonzero(done)
                last = self._buf[idx].copy()
                self.encoder.step_into(np.stack([infos[i]["terminal_observation"] for i in idx]), self._a[idx], last)
                for j, i in enumerate(idx):
                    infos[i]["terminal_observation"] = last[j]
            self.encoder.step_into(obs, self._a, self._buf)
            if done.any():  # the new episode's first observation (a masked row is a copy: write it back)
                fresh = self._buf[done]
                self.encoder.reset_into(obs[done], fresh)
                self._buf[done] = fresh
            self._a_prev[:] = np.where(done, 0.0, self._a)
            return self._buf.copy(), shaped.astype(np.float32), done, infos

    return EncodedVecEnvImpl


def EncodedVecEnv(venv: Any, encoder: ObsEncoder, smooth_weight: float = SMOOTH_WEIGHT) -> Any:
    """:class:`EncodedVecEnvImpl` over ``venv`` (an SB3 ``VecEnv``; needs the ``[rl]`` extra)."""
    require_sb3()
    return _encoded_vec_env_class()(venv, encoder, smooth_weight)


def mean_episode_reward(act: Callable[[np.ndarray], float] | str, episodes: int = 4, seed: int = 12345,
                        env_kwargs: Mapping[str, Any] | None = None, max_steps: int | None = None) -> float:
    """Mean return of ``episodes`` episodes of :class:`TrainingEnv` under a policy.

    Parameters
    ----------
    act : callable or "random"
        Encoded observation -> normalised action; ``"random"`` draws
        uniform actions in ``[-1, 1]`` (seeded from ``seed``).
    episodes : int
        Episode ``i`` is the ride of ``reset(seed=seed + i)``: the same rides
        for every policy compared.
    env_kwargs : dict, optional
        Arguments of :class:`TrainingEnv`.
    max_steps : int, optional
        Cut each episode after this many steps.

    Returns
    -------
    float
        Mean undiscounted return of the environment's reward (a step of
        perfect tracking earns 1; no training shaping).
    """
    env = TrainingEnv(**dict(env_kwargs or {}))
    rng = np.random.default_rng(seed)
    total = 0.0
    for i in range(episodes):
        x, _ = env.reset(seed=seed + i)
        k = 0
        while True:
            a = float(rng.uniform(-1, 1)) if isinstance(act, str) else float(act(x))
            x, _, term, trunc, info = env.step(np.array([a], dtype=np.float32))
            total += info["env_reward"]
            k += 1
            if term or trunc or (max_steps is not None and k >= max_steps):
                break
    return total / episodes


#: Samples per PPO rollout with ``vec="native"`` (``n_steps = NATIVE_ROLLOUT // n_envs``), taken in minibatches of 2048:
#: with hundreds of envs, the default 1024 steps per env would update the policy a hundred times less often.
NATIVE_ROLLOUT = 16384
#: How the training envs are stepped: ``dummy`` (SB3 DummyVecEnv of :class:`TrainingEnv`), ``subproc`` (one process
#: each) or ``native`` (:func:`native_training_env`: the compiled vector env, a ride pool and randomised vehicles).
VECS = ("dummy", "subproc", "native")


def _check_train_args(algo: str, steps: int, seed: int, n_envs: int, vec: str, threads: int) -> None:
    if algo not in ALGOS:
        raise PolicyError(f"unknown algorithm {algo!r}; known: {', '.join(ALGOS)}")
    for name, v, lo in (("steps", steps, 1), ("n_envs", n_envs, 1), ("threads", threads, 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise PolicyError(f"{name} must be a positive integer, got {v!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise PolicyError(f"seed must be an integer >= 0, got {seed!r}")
    if vec not in VECS:
        raise PolicyError(f"vec must be one of {', '.join(VECS)}, got {vec!r}")


def versions() -> dict[str, str]:
    """Versions of the packages that make a trained policy (for its provenance)."""
    import gymnasium

    sb3, torch = require_sb3()
    return {"python": platform.python_version(), "stable_baselines3": sb3.__version__, "torch": torch.__version__,
            "gymnasium": gymnasium.__version__, "numpy": np.__version__}


def build_model(algo: str = "ppo", seed: int = 0, n_envs: int = 4, vec: str = "dummy", threads: int = 1,
                hyper: Mapping[str, Any] | None = None, env_kwargs: Mapping[str, Any] | None = None):
    """The untrained SB3 model on ``n_envs`` copies of :class:`TrainingEnv` (see :func:`train`).

    Sets ``torch.set_num_threads(threads)``. Returns ``(model, vec_env,
    encoder, algorithm arguments, environment arguments)``.
    """
    _check_train_args(algo, 1, seed, n_envs, vec, threads)
    _, torch = require_sb3()
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(int(threads))
    env_kwargs = dict(env_kwargs or {})
    probe = TrainingEnv(**env_kwargs)  # resolves the vehicle's speeds, encoder and torque once, checked
    encoder = probe.encoder
    env_kwargs.update(encoder=encoder.config(), distribution=probe.distribution, tau_max=probe.tau_max)
    if vec == "native":
        if probe.fixed is not None:
            raise PolicyError("vec='native' trains on a pool of rides drawn from the distribution; 'fixed' is "
                              "for the dummy/subproc envs")
        venv = native_training_env(n_envs, seed, probe.distribution, encoder, probe.tau_max, probe.vehicle,
                                   probe.smooth_weight)
    else:
        venv = _vec_env(n_envs, seed, vec, env_kwargs)
    params = dict(PPO_DEFAULTS if algo == "ppo" else SAC_DEFAULTS)
    if vec == "native" and algo == "ppo":  # many envs: the same 16384-sample rollout, minibatches of 2048
        params.update(n_steps=max(8, NATIVE_ROLLOUT // n_envs), batch_size=2048)
    params.update(hyper or {})
    args = dict(params)
    lr_end = args.pop("lr_end", None)
    if lr_end is not None:  # linear decay over the run
        from stable_baselines3.common.utils import LinearSchedule

        args["learning_rate"] = LinearSchedule(float(args["learning_rate"]), float(lr_end), 1.0)
    if algo == "ppo":
        # reward scaling for the value function only: the policy never sees it, nothing to ship
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=params["gamma"])
    model = _algo_class(algo)("MlpPolicy", venv, seed=seed, device="cpu", tensorboard_log=None, verbose=0, **args)
    return model, venv, encoder, params, env_kwargs


def train(
    algo: str = "ppo",
    steps: int = 100_000,
    seed: int = 0,
    out: str | os.PathLike = "policy.zip",
    n_envs: int = 4,
    vec: str = "dummy",
    threads: int = 1,
    checkpoint_every: int | None = 250_000,
    progress: bool = True,
    hyper: Mapping[str, Any] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    eval_episodes: int = 5,
    command: str | None = None,
) -> TrainResult:
    """Train PPO or SAC on :class:`TrainingEnv` and save the policy to ``out``.

    Parameters
    ----------
    algo : {"ppo", "sac"}
    steps : int
        Environment steps (10 ms each), summed over the ``n_envs`` copies.
    seed : int
        Seeds torch, numpy, the action space and the environments (copy
        ``i`` gets ``seed + i``): same seed and settings, same policy on the
        same machine and package versions.
    out : path
        Policy file (``.zip``); checkpoints go to ``<out stem>_checkpoints/``
        beside it and the provenance to ``<out stem>.json``.
    n_envs : int
        Environment copies stepped together.
    vec : {"dummy", "subproc"}
        Same process, or one worker process per copy (``SubprocVecEnv``).
    threads : int
        ``torch.set_num_threads`` during training (1 is fastest on the 2-core
        machines: ``scripts/bench_rl.py``).
    checkpoint_every : int or None
        Save a checkpoint every this many steps (None or 0: none).
    progress : bool
        Show a tqdm progress bar.
    hyper : dict, optional
        Algorithm arguments over :data:`PPO_DEFAULTS` / :data:`SAC_DEFAULTS`.
    env_kwargs : dict, optional
        Arguments of :class:`TrainingEnv` (e.g. ``fixed=`` for one ride).
    eval_episodes : int
        Episodes of the final evaluation (deterministic policy) and of the
        random-policy and untrained-policy references, on the same rides.
    command : str, optional
        The command line, recorded in the provenance.

    Returns
    -------
    TrainResult
        ``final_reward`` is the mean return of the trained deterministic
        policy over ``eval_episodes`` rides; ``random_reward`` and
        ``initial_reward`` are those of uniform random actions and of the
        untrained network on the same rides. No TensorBoard log is written.
    """
    _check_train_args(algo, steps, seed, n_envs, vec, threads)
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    out = Path(out)
    model, venv, encoder, params, env_kwargs = build_model(algo, seed, n_envs, vec, threads, hyper, env_kwargs)

    eval_kwargs = {k: v for k, v in env_kwargs.items()}
    policy0 = RLPolicy(model, encoder, {})
    initial = mean_episode_reward(policy0.normalized_action, eval_episodes, seed=10_000 + seed, env_kwargs=eval_kwargs)
    rand = mean_episode_reward("random", eval_episodes, seed=10_000 + seed, env_kwargs=eval_kwargs)

    callbacks = []
    if checkpoint_every:
        ck = out.parent / f"{out.stem}_checkpoints"
        callbacks.append(CheckpointCallback(save_freq=max(int(checkpoint_every) // n_envs, 1), save_path=str(ck),
                                            name_prefix=algo))
    if progress:
        callbacks.append(_tqdm_callback(int(steps)))
    meta = {
        "algo": algo, "encoder": encoder.config(), "tau_max": float(env_kwargs["tau_max"]), "dt": 0.01,
        "vehicle": (env_kwargs.get("vehicle") or REFERENCE_SCOOTER).identity(),
        "seed": int(seed),
        "steps": int(steps), "n_envs": int(n_envs), "vec": vec, "threads": int(threads),
        "distribution": env_kwargs["distribution"].describe()
        if not env_kwargs.get("fixed") else {"fixed": dict(env_kwargs["fixed"])},
        "smooth_weight": float(env_kwargs.get("smooth_weight", SMOOTH_WEIGHT)),
        **({"native": getattr(getattr(venv, "venv", venv), "description", None)} if vec == "native" else {}),
        "hyper": json.loads(json.dumps(params, default=str)), "versions": versions(), "command": command,
    }
    model.ptw_rl = meta  # saved with the model (BaseAlgorithm.save stores the instance's attributes)
    t0 = time.perf_counter()
    model.learn(total_timesteps=int(steps), callback=CallbackList(callbacks), progress_bar=False)
    seconds = time.perf_counter() - t0
    venv.close()
    meta["seconds"] = round(seconds, 1)
    meta["steps_done"] = int(model.num_timesteps)
    trained = RLPolicy(model, encoder, meta)  # the numpy actor is a snapshot: take it after training
    final = mean_episode_reward(trained.normalized_action, eval_episodes, seed=10_000 + seed, env_kwargs=eval_kwargs)
    meta["eval_rides"] = {"episodes": int(eval_episodes), "reset_seeds": f"{10_000 + seed}..{10_000 + seed + eval_episodes - 1}"}
    meta["final_reward"] = final
    meta["random_policy_reward"] = rand
    meta["untrained_policy_reward"] = initial
    meta["machine"] = {"cpus": os.cpu_count(), "platform": platform.platform()}
    model.ptw_rl = meta
    out.parent.mkdir(parents=True, exist_ok=True)
    model.save(out)
    if out.suffix != ".zip":  # SB3 appends .zip
        out = out.with_name(out.name + ".zip")
    sidecar = out.with_suffix(".json")
    sidecar.write_text(json.dumps(meta, indent=2, default=str) + "\n")
    return TrainResult(path=out, algo=algo, steps=int(model.num_timesteps), seed=int(seed), seconds=seconds,
                       final_reward=final, random_reward=rand, initial_reward=initial, meta=meta)



__all__ = ["SMOOTH_WEIGHT", "VECS", "EncodedVecEnv", "native_training_env", "training_randomization", "PPO_DEFAULTS", "SAC_DEFAULTS", "TrainResult", "TrainingDistribution", "TrainingEnv",
           "build_model", "mean_episode_reward", "train", "versions"]
