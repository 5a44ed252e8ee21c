"""Constrained RL on the safety cost: PPO with a Lagrange multiplier (a PPO-Lagrangian loop on SB3).

The vector env reports ``info["cost"]`` per step (:class:`ptw_env.episode.CostConfig`: grip, roll and
torque-rate limits broken). The agent maximises ``reward - lambda cost``; after each rollout the multiplier
follows the constraint ``E[cost per step] <= budget`` by dual ascent,
``lambda <- max(0, lambda + lr (mean cost - budget))`` (Ray, Achiam & Amodei 2019, "Benchmarking Safe
Exploration in Deep RL", PPO-Lagrangian). Prints per rollout: mean reward, mean cost, lambda.

Run: ``python scripts/example_constrained_rl.py [--steps 200000] [--envs 256] [--budget 0.02] [--seed 0]``
(needs ``pip install "ptw-assist[rl]"``). A short run shows the loop working, not a trained policy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import ptw_env  # noqa: E402,F401
from assist.rl.vecenv import SB3VecEnv  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=200_000, help="total env-steps (default 200000)")
    ap.add_argument("--envs", type=int, default=256, help="vector env size (default 256)")
    ap.add_argument("--budget", type=float, default=0.02, help="allowed mean cost per step (default 0.02)")
    ap.add_argument("--lambda-lr", type=float, default=5.0, help="dual step size (default 5)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    for name in ("steps", "envs"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    if not (args.budget >= 0 and args.lambda_lr > 0):
        ap.error("--budget must be >= 0 and --lambda-lr > 0")
    try:
        from stable_baselines3 import PPO
        from stable_baselines3.common.callbacks import BaseCallback
        from stable_baselines3.common.vec_env import VecEnvWrapper
    except ImportError:
        raise SystemExit('this example needs stable-baselines3: pip install "ptw-assist[rl]"') from None

    class Lagrangian(VecEnvWrapper):
        """reward - lambda * cost, with the rollout's costs kept for the dual step."""

        def __init__(self, venv):
            super().__init__(venv)
            self.lam = 0.0
            self.costs: list[float] = []
            self.rewards: list[float] = []

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            obs, rew, done, infos = self.venv.step_wait()
            cost = np.array([i["cost"] for i in infos])
            self.costs.append(float(cost.mean()))
            self.rewards.append(float(rew.mean()))
            return obs, (rew - self.lam * cost).astype(np.float32), done, infos

    class DualAscent(BaseCallback):
        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            env = self.model.get_env()
            c, r = float(np.mean(env.costs)), float(np.mean(env.rewards))
            env.lam = max(0.0, env.lam + args.lambda_lr * (c - args.budget))
            print(f"steps {self.num_timesteps:8d}  reward/step {r:6.3f}  cost/step {c:6.4f}  lambda {env.lam:6.3f}")
            env.costs.clear()
            env.rewards.clear()

    venv = gym.make_vec("PTWRollNorm-v0", num_envs=args.envs, vectorization_mode="vector_entry_point")
    env = Lagrangian(SB3VecEnv(venv))
    env.seed(args.seed)
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=min(4096, 64 * args.envs), seed=args.seed, device="cpu",
                verbose=0)
    model.learn(args.steps, callback=DualAscent())


if __name__ == "__main__":
    main()
