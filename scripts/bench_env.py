"""Benchmark: environment step cost vs CartPole, and batched simulation throughput.

Prints, measured in one run on this machine:

* ``env.step`` of ``PTWRoll-v0`` vs ``CartPole-v1`` (both from ``gymnasium.make``,
  same wrappers, random actions): microseconds per step and the ratio
  (target: no more than 4x CartPole's);
* batched ``ptw_env.simulate`` throughput in vehicle-steps/s (100 Hz steps at
  the full internal accuracy, RK4 with 2.5 ms substeps) for N = 1, 64, 1024,
  with the ratio against a reference measured in the same run: the same RK4
  written as a numpy loop over ``Plant.rhs`` (target: >= 1,000,000
  vehicle-steps/s at N = 1024 on 2 cores).

Run: ``python scripts/bench_env.py [--quick]``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import ptw_env
from ptw_env.dynamics import compile_plant


def time_env_steps(env_id: str, n_steps: int, repeats: int, seed: int = 0) -> float:
    """Best-of-``repeats`` mean seconds per ``env.step`` with random actions."""
    env = gym.make(env_id)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(1000)]
    if env_id.startswith("PTWRoll"):
        # bounded torques that keep the scooter up most of the time: smaller than the full box
        actions = [np.clip(a * 0.05, env.action_space.low, env.action_space.high) for a in actions]
    best = np.inf
    for r in range(repeats):
        env.reset(seed=seed + r)
        t0 = time.perf_counter()
        for i in range(n_steps):
            _, _, term, trunc, _ = env.step(actions[i % 1000])
            if term or trunc:
                env.reset()
        best = min(best, (time.perf_counter() - t0) / n_steps)
    env.close()
    return best


def numpy_rk4_reference(plant, x0, tau, vx, dt, nsub):
    """The same RK4 (held inputs, ``nsub`` substeps) as a Python loop of numpy calls on ``Plant.rhs``."""
    x = x0.copy()
    h = dt / nsub
    for k in range(tau.shape[1]):
        u, v = tau[:, k], vx[:, k]
        for _ in range(nsub):
            k1 = plant.rhs(x, u, v)
            k2 = plant.rhs(x + 0.5 * h * k1, u, v)
            k3 = plant.rhs(x + 0.5 * h * k2, u, v)
            k4 = plant.rhs(x + h * k3, u, v)
            x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def throughput(N: int, T: int, repeats: int, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    tau = rng.normal(0.0, 2.0, size=(N, T))
    vx = np.broadcast_to(rng.uniform(15.0, 35.0, size=(N, 1)), (N, T)).copy()  # self-stable range: no falls
    x0 = np.zeros((N, 8))
    ptw_env.simulate(x0[:, :], tau[:, :2], vx[:, :2])  # compile / warm up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        ptw_env.simulate(x0, tau, vx)
        best = min(best, time.perf_counter() - t0)
    return N * T / best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer steps (noisier figures)")
    args = ap.parse_args()
    n_steps = 5_000 if args.quick else 20_000
    repeats = 3 if args.quick else 5

    time_env_steps("PTWRoll-v0", 200, 1)  # warm up (numba compile / cache load)
    t_ptw = time_env_steps("PTWRoll-v0", n_steps, repeats)
    t_cp = time_env_steps("CartPole-v1", n_steps, repeats)
    print("env.step (gymnasium.make, same wrappers, best of %d x %d steps)" % (repeats, n_steps))
    print(f"  PTWRoll-v0   {t_ptw * 1e6:7.2f} us/step")
    print(f"  CartPole-v1  {t_cp * 1e6:7.2f} us/step")
    print(f"  ratio PTWRoll / CartPole = {t_ptw / t_cp:.2f}  (target <= 4)")

    print("\nbatched simulate: vehicle-steps/s (100 Hz steps, RK4 2.5 ms substeps)")
    T = 500 if args.quick else 1000
    results = {}
    for N in (1, 64, 1024):
        results[N] = throughput(N, T if N > 1 else 10 * T, repeats)
        print(f"  N = {N:5d}: {results[N]:12,.0f} vehicle-steps/s")
    plant = compile_plant()
    Nr, Tr = 1024, 20
    rng = np.random.default_rng(1)
    tau, vx = rng.normal(0, 2.0, (Nr, Tr)), np.full((Nr, Tr), 20.0)
    t0 = time.perf_counter()
    numpy_rk4_reference(plant, np.zeros((Nr, 8)), tau, vx, 0.01, 4)
    ref = Nr * Tr / (time.perf_counter() - t0)
    print(f"  reference (numpy RK4 loop over Plant.rhs, N = 1024): {ref:12,.0f} vehicle-steps/s")
    print(f"  ratio compiled / numpy reference at N = 1024 = {results[1024] / ref:.1f}")
    print(f"  N = 1024 vs target 1,000,000: {results[1024] / 1e6:.2f}x")


if __name__ == "__main__":
    main()
