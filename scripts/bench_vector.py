"""Benchmark: the native vector environment (issue 21) against the same env under SyncVectorEnv and
gymnasium's own native vector CartPole, all measured in this run.

Prints:

* env-steps/s of ``gymnasium.make_vec("PTWRoll-v0", N, vectorization_mode="vector_entry_point")``
  (sensors with noise, reward, cost, autoreset, ``info`` built every step) for N = 1, 16, 256, 1024,
  4096, timed over 2100 steps so that every env ends its 20 s episode and is reset inside the window, with random torques (uniform over the action box, a tenth of it so that most episodes run to
  their end as a tracking policy's do) and the ratio against the references:
  - the same env through ``gymnasium.vector.SyncVectorEnv`` at N = 16 (gymnasium's generic batching);
  - ``CartPole-v1``'s native vector env at N = 1024;
* the cost of domain randomisation: N = 1024 with ``randomize=`` (tire peak friction, stiffness, payload,
  bank, noise scale, gyro bias: one plant per env, compiled again at each reset) against the same model
  fixed at the middle of the ranges (saturating tires, mu_peak 0.75: a saturating tire costs about a
  quarter more per step than the default linear tire, whether randomised or not, so that is the like-for-like
  reference), over 2100 steps of full 20 s episodes (each env reset once) and on episodes cut to 100
  steps (about 10 resets per step, the worst case);
* memory per env (bytes of the per-env arrays, :attr:`PTWRollVectorEnv.memory_bytes`).

Target (issue 21): >= 1,000,000 env-steps/s at N = 1024 on 2 cores; randomisation <= 10 % of it.

Run: ``python scripts/bench_vector.py [--quick] [--json OUT.json]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import ptw_env  # noqa: E402,F401
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)

#: Timed steps per run: beyond one episode of PTWRoll-v0 (1999 steps), so every env's autoreset is in the window.
EPISODE_STEPS = 2100

RANDOMIZE = {
    "tire_saturation:mu_peak": ("uniform", 0.4, 1.1),
    "tire_stiffness:scale": ("uniform", 0.8, 1.2),
    "payload:mass_kg": ("normal", 0.0, 10.0, -20.0, 40.0),
    "road_bank:bank_rad": ("normal", 0.0, 0.02),
    "sensor_noise_scale": ("uniform", 0.5, 2.0),
    "gyro_bias:yaw_rate_bias": ("normal", 0.0, 0.005),
}


def rate(envs, steps: int, repeats: int, seed: int = 0, scale: float = 0.1) -> float:
    """Best-of-``repeats`` env-steps/s over ``steps`` steps of random actions (after a warm-up)."""
    n = envs.num_envs
    rng = np.random.default_rng(seed)
    box = envs.single_action_space
    if isinstance(box, gym.spaces.Discrete):
        acts = rng.integers(0, box.n, (64, n))
    else:
        acts = (rng.uniform(box.low, box.high, (64, n, 1)) * scale).astype(box.dtype)
    envs.reset(seed=seed)
    for t in range(5):
        envs.step(acts[t % 64])
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        for t in range(steps):
            envs.step(acts[t % 64])
        best = max(best, n * steps / (time.perf_counter() - t0))
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer steps (a smoke run)")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    add_overwrite(ap)
    args = ap.parse_args()
    out = output_file(ap, "--json", args.json, args.overwrite)
    # 2100 steps: past the 20 s lane change's end (1999 steps), so every env ends its episode and is reset
    # (autoreset) inside the timed window
    steps, repeats = (50, 1) if args.quick else (EPISODE_STEPS, 2)

    res: dict = {"native": {}, "memory_bytes_per_env": {}, "steps_timed": steps}
    for n in (1, 16, 256, 1024, 4096):
        envs = gym.make_vec("PTWRoll-v0", num_envs=n, vectorization_mode="vector_entry_point")
        res["native"][n] = rate(envs, steps, repeats)
        res["memory_bytes_per_env"][n] = envs.unwrapped.memory_bytes / n
        envs.close()
    sync = gym.make_vec("PTWRoll-v0", num_envs=16, vectorization_mode="sync")
    res["sync_16"] = rate(sync, min(steps, 600), repeats)
    cart = gym.make_vec("CartPole-v1", num_envs=1024, vectorization_mode="vector_entry_point")
    res["cartpole_native_1024"] = rate(cart, steps, repeats)
    base = {"tire_saturation": {"mu_peak": 0.75}}
    for label, extra in (("full", {}), ("short", {"max_episode_steps": 100})):
        fixed = gym.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point", effects=base, **extra)
        rnd = gym.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point", effects=base,
                           randomize=RANDOMIZE, **extra)
        res[f"fixed_{label}_1024"] = rate(fixed, steps, repeats)
        res[f"randomized_{label}_1024"] = rate(rnd, steps, repeats)
    n1024 = res["native"][1024]
    print("native vector env (PTWRoll-v0, sensors, reward, cost, autoreset):")
    for n, r in res["native"].items():
        print(f"  N = {n:5d}: {r:12,.0f} env-steps/s   {res['memory_bytes_per_env'][n]:8,.0f} bytes/env")
    print(f"same env, SyncVectorEnv N = 16:      {res['sync_16']:12,.0f} env-steps/s  "
          f"-> native at 1024 is {n1024 / res['sync_16']:.1f}x")
    print(f"CartPole-v1 native vector N = 1024:   {res['cartpole_native_1024']:12,.0f} env-steps/s  "
          f"-> native PTW at 1024 is {n1024 / res['cartpole_native_1024']:.3f}x of it")
    for label, what in (("full", "20 s episodes"), ("short", "100-step episodes")):
        cost = 1.0 - res[f"randomized_{label}_1024"] / res[f"fixed_{label}_1024"]
        res[f"randomization_cost_{label}"] = cost
        print(f"randomisation, N = 1024, {what}: {res[f'randomized_{label}_1024']:,.0f} vs {res[f'fixed_{label}_1024']:,.0f} "
              f"env-steps/s with the model fixed: costs {100 * cost:.1f} % (target <= 10 %)")
    print(f"target >= 1,000,000 env-steps/s at N = 1024: {'met' if n1024 >= 1e6 else 'NOT met'} ({n1024:,.0f})")
    if out is not None:
        out.write_text(json.dumps(res, indent=2) + "\n")


if __name__ == "__main__":
    main()
