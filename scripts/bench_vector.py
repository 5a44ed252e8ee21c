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
  bank, noise scale, gyro bias: one plant per env, the next episodes' compiled in batches) against the same model
  fixed at the middle of the ranges (saturating tires, mu_peak 0.75: a saturating tire costs about a
  quarter more per step than the default linear tire, whether randomised or not, so that is the like-for-like
  reference; and at the substeps the randomised env uses, ``substeps=``: drawing a plant faster than the
  fixed one makes the env integrate with more RK4 substeps, a cost of the physics drawn, not of the reset,
  so both are printed; the env sizes its step for the ride's speeds, 50 km/h here, where the drawn plants
  need no extra substep), over 3 x 320 steps with 0, 1 or 10 envs reset before every step through
  ``reset(options={"reset_mask": ...})`` (the same schedule for both, whatever the episodes do; a 20 s
  episode at N = 1024 resets 0.5 env a step on average, 10 a step is a policy that falls every 2 s; each
  such reset also runs one kernel pass, in both; the three envs timed step by step in turn, so that a
  drift of the machine's speed falls on all alike, each round after a seeded reset and 5 untimed steps);
  the ends of episodes besides (falls) are printed; when the fixed model's substeps equal the randomised
  env's, "fixed" and "same" are one configuration measured twice and how far apart they came is printed
  as the noise of these figures;
  also whole 20 s episodes with random torques, with the resets each run had (not like for like: the
  randomised vehicles fall more often, and a fall is an early reset; each env timed on its own, best of 2,
  as the native figures are, so machine drift is not paired out there);
* what sizing the RK4 step for the ride's speeds buys: the same randomised env with ``step_speeds="vehicle"``
  (the step for the vehicle's whole speed range, as before 2026-11-26), timed in turn with the others;
* the same with the vehicle itself randomised too (``vehicle_scale:`` keys on the ``sharp1971`` vehicle file:
  rider mass, rear-frame height, roll inertia, caster, front cornering stiffness; the drawn vehicles'
  matrices built by Table V) besides the six keys, against that vehicle fixed (the substeps of both are
  printed: a randomisation that can draw a faster vehicle integrates with more);
* memory per env (bytes of the per-env arrays, :attr:`PTWRollVectorEnv.memory_bytes`).

Target (issue 21): >= 1,000,000 env-steps/s at N = 1024 on 2 cores; randomisation <= 10 % of it.

Run: ``python scripts/bench_vector.py [--quick] [--randomization-only] [--json OUT.json]`` (the second: only the
like-for-like randomisation runs, to repeat them).
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
#: Resets before every step in the like-for-like runs (a 20 s episode at N = 1024 averages 0.5 a step).
RESETS_PER_STEP = (0, 1, 10)
#: Rounds of the like-for-like runs (:func:`paired_rates`), all timed.
ROUNDS = 3
#: Timed steps of each round (5 rotations of the 64-step reset schedule), from the episodes' start.
LIKE_STEPS = 320
#: The vehicle's own parameters (Table V names, SI), drawn on top of :data:`RANDOMIZE` on a vehicle file.
VEHICLE_RANDOMIZE = {
    "vehicle_scale:M_r": ("uniform", 0.8, 1.3),
    "vehicle_scale:h": ("uniform", 0.9, 1.1),
    "vehicle_scale:I_rx": ("uniform", 0.8, 1.2),
    "vehicle_scale:eps": ("uniform", 0.9, 1.1),
    "vehicle_scale:C_f1": ("uniform", 0.8, 1.2),
}
VEHICLE = "sharp1971"


def schedule(envs, seed: int, scale: float, resets_per_step: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """64 steps' random actions for ``envs`` (uniform over the action box times ``scale``; a discrete space's
    actions uniform) and, with ``resets_per_step``, the 64 reset masks of a fixed rotation over the envs."""
    n = envs.num_envs
    rng = np.random.default_rng(seed)
    box = envs.single_action_space
    if isinstance(box, gym.spaces.Discrete):
        acts = rng.integers(0, box.n, (64, n))
    else:
        acts = (rng.uniform(box.low, box.high, (64, n, 1)) * scale).astype(box.dtype)
    masks = []
    for t in range(64 if resets_per_step else 0):
        m = np.zeros(n, dtype=bool)
        m[(t * resets_per_step + np.arange(resets_per_step)) % n] = True
        masks.append(m)
    return acts, masks


def rate(envs, steps: int, repeats: int, seed: int = 0, scale: float = 0.1,
         resets_per_step: int = 0) -> tuple[float, float]:
    """Best-of-``repeats`` env-steps/s over ``steps`` steps of random actions (after a warm-up), and the
    episode ends per step in that run (each an autoreset at the next step). ``resets_per_step``: that many
    envs (a fixed rotation, the same in every run) reset before each step through
    ``reset(options={"reset_mask": ...})``, a schedule that does not depend on the episodes."""
    n = envs.num_envs
    acts, masks = schedule(envs, seed, scale, resets_per_step)
    envs.reset(seed=seed)
    for t in range(5):
        envs.step(acts[t % 64])
    best, ends = 0.0, 0.0
    for _ in range(repeats):
        e = 0
        t0 = time.perf_counter()
        for t in range(steps):
            if masks:
                envs.reset(options={"reset_mask": masks[t % 64]})
            _, _, term, trunc, _ = envs.step(acts[t % 64])
            e += int(np.sum(term | trunc))
        r = n * steps / (time.perf_counter() - t0)
        if r > best:
            best, ends = r, e / steps
    return best, ends


def paired_rates(envs: dict, steps: int, rounds: int, resets_per_step: int, seed: int = 0,
                 scale: float = 0.1) -> dict[str, tuple[float, float]]:
    """env-steps/s and episode ends per step of each of ``envs`` (name -> vector env, all of one size), timed
    step by step in turn (the order rotating each step) over ``rounds`` x ``steps`` steps, with the reset
    schedule of :func:`rate`: a drift of the machine's speed (other processes, clock) then falls on all of them
    alike, which separate runs seconds apart do not ensure."""
    names = list(envs)
    n = envs[names[0]].num_envs
    acts, masks = schedule(envs[names[0]], seed, scale, resets_per_step)
    spent = dict.fromkeys(names, 0.0)
    ends = dict.fromkeys(names, 0)
    for _ in range(rounds):
        for e in envs.values():  # each round from the same episode starts (the first 320 steps: few falls)
            e.reset(seed=seed)
            for t in range(5):
                e.step(acts[t % 64])
        for t in range(steps):
            j = t % len(names)
            for name in names[j:] + names[:j]:
                e = envs[name]
                t0 = time.perf_counter()
                if masks:
                    e.reset(options={"reset_mask": masks[t % 64]})
                _, _, term, trunc, _ = e.step(acts[t % 64])
                spent[name] += time.perf_counter() - t0
                ends[name] += int(np.sum(term | trunc))
    return {name: (n * steps * rounds / spent[name], ends[name] / (steps * rounds)) for name in names}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer steps (a smoke run)")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    ap.add_argument("--randomization-only", action="store_true",
                    help="only the like-for-like randomisation runs (paired_rates; about a minute), to repeat them")
    add_overwrite(ap)
    args = ap.parse_args()
    out = output_file(ap, "--json", args.json, args.overwrite)
    # 2100 steps: past the 20 s lane change's end (1999 steps), so every env ends its episode and is reset
    # (autoreset) inside the timed window
    steps, repeats = (50, 1) if args.quick else (EPISODE_STEPS, 2)

    full = not args.randomization_only
    res: dict = {"native": {}, "memory_bytes_per_env": {}, "steps_timed": steps, "randomization_only": not full}
    for n in (1, 16, 256, 1024, 4096) if full else ():
        envs = gym.make_vec("PTWRoll-v0", num_envs=n, vectorization_mode="vector_entry_point")
        res["native"][n] = rate(envs, steps, repeats)[0]
        res["memory_bytes_per_env"][n] = envs.unwrapped.memory_bytes / n
        envs.close()
    if full:
        sync = gym.make_vec("PTWRoll-v0", num_envs=16, vectorization_mode="sync")
        res["sync_16"] = rate(sync, min(steps, 600), repeats)[0]
        cart = gym.make_vec("CartPole-v1", num_envs=1024, vectorization_mode="vector_entry_point")
        res["cartpole_native_1024"] = rate(cart, steps, repeats)[0]
    base = {"tire_saturation": {"mu_peak": 0.75}}
    both = {**RANDOMIZE, **VEHICLE_RANDOMIZE}
    for label, extra, rnd_spec in (("scooter", {}, RANDOMIZE), ("vehicle", {"vehicle": VEHICLE}, both)):
        rnd = gym.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point", effects=base,
                           randomize=rnd_spec, **extra)
        fixed = gym.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point", effects=base, **extra)
        same = gym.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point", effects=base,
                            substeps=int(rnd.unwrapped.nsub.max()), **extra)
        # the same randomised env with the step sized for the vehicle's whole speed range (before 2026-11-26)
        whole = gym.make_vec("PTWRoll-v0", num_envs=1024, vectorization_mode="vector_entry_point", effects=base,
                             randomize=rnd_spec, step_speeds="vehicle", **extra)
        res[f"substeps_whole_{label}"] = int(whole.unwrapped.nsub.max())
        res[f"substeps_{label}"] = [int(fixed.unwrapped.nsub.max()), int(rnd.unwrapped.nsub.max())]
        one_config = bool(np.array_equal(fixed.unwrapped.nsub, same.unwrapped.nsub))  # every ride's count
        res[f"one_config_{label}"] = one_config
        kinds = (("fixed", fixed), ("same", same), ("randomized", rnd))
        for kind, envs in kinds if full else ():
            res[f"{kind}_{label}_episodes"], res[f"{kind}_{label}_ends_per_step"] = rate(envs, steps, repeats)
        # the like-for-like runs timed step by step in turn (paired_rates): the machine's speed drifts by
        # several per cent between runs a few seconds apart
        for r in RESETS_PER_STEP:
            got = paired_rates({**dict(kinds), "whole": whole}, min(steps, LIKE_STEPS), 1 if args.quick else ROUNDS, r)
            res[f"whole_{label}_reset{r}"] = got["whole"][0]
            for kind, _ in kinds:
                res[f"{kind}_{label}_reset{r}"], res[f"{kind}_{label}_reset{r}_ends"] = got[kind]
    if full:
        n1024 = res["native"][1024]
        print("native vector env (PTWRoll-v0, sensors, reward, cost, autoreset):")
        for n, r in res["native"].items():
            print(f"  N = {n:5d}: {r:12,.0f} env-steps/s   {res['memory_bytes_per_env'][n]:8,.0f} bytes/env")
        print(f"same env, SyncVectorEnv N = 16:      {res['sync_16']:12,.0f} env-steps/s  "
              f"-> native at 1024 is {n1024 / res['sync_16']:.1f}x")
        print(f"CartPole-v1 native vector N = 1024:   {res['cartpole_native_1024']:12,.0f} env-steps/s  "
              f"-> native PTW at 1024 is {n1024 / res['cartpole_native_1024']:.3f}x of it")
    for label, what in (("scooter", "reference scooter, 6 effect/sensor keys"),
                        ("vehicle", f"{VEHICLE}, the 6 keys and 5 vehicle parameters")):
        nf, nr = res[f"substeps_{label}"]
        print(f"randomisation, N = 1024, {what}: {nr} RK4 substeps for the fastest plant it can draw, {nf} for the "
              f"fixed model")
        for r in RESETS_PER_STEP:
            rr = res[f"randomized_{label}_reset{r}"]
            f, fo = res[f"same_{label}_reset{r}"], res[f"fixed_{label}_reset{r}"]
            cost, total = 1.0 - rr / f, 1.0 - rr / fo
            res[f"randomization_cost_{label}_reset{r}"], res[f"randomization_total_{label}_reset{r}"] = cost, total
            print(f"  {r:2d} env(s) reset before every step (plus {res[f'randomized_{label}_reset{r}_ends']:.2f} vs "
                  f"{res[f'same_{label}_reset{r}_ends']:.2f} ends a step): {rr:,.0f} vs {f:,.0f} env-steps/s at the same "
                  f"substeps: costs {100 * cost:.1f} % (target <= 10 %); against the fixed model at its own "
                  f"{nf} substeps ({fo:,.0f}): {100 * total:.1f} %")
        if res[f"one_config_{label}"]:  # "fixed" and "same" are one configuration: how far apart they came is the noise
            gap = max(abs(1.0 - res[f"same_{label}_reset{r}"] / res[f"fixed_{label}_reset{r}"]) for r in RESETS_PER_STEP)
            res[f"noise_{label}"] = gap
            print(f"  (the fixed model at its own and at the same substeps is one configuration here, measured "
                  f"twice: up to {100 * gap:.1f} % apart, the noise of these figures)")
        gain = [res[f"randomized_{label}_reset{r}"] / res[f"whole_{label}_reset{r}"] - 1.0 for r in RESETS_PER_STEP]
        res[f"per_ride_gain_{label}"] = gain
        print(f"  the same randomised env with the step sized for the vehicle's whole range (step_speeds='vehicle', "
              f"{res[f'substeps_whole_{label}']} substeps), timed in turn with the others: per-ride sizing is "
              + " / ".join(f"{100 * x:+.1f} %" for x in gain) + f" faster at {' / '.join(map(str, RESETS_PER_STEP))} "
              "resets a step")
        if full:
            ef, er = res[f"fixed_{label}_ends_per_step"], res[f"randomized_{label}_ends_per_step"]
            print(f"  whole 20 s episodes, random torques (not like for like: {er:.2f} vs {ef:.2f} ends a step): "
                  f"{res[f'randomized_{label}_episodes']:,.0f} vs {res[f'fixed_{label}_episodes']:,.0f} env-steps/s")
    if full:
        print(f"target >= 1,000,000 env-steps/s at N = 1024: {'met' if n1024 >= 1e6 else 'NOT met'} ({n1024:,.0f})")
    if out is not None:
        out.write_text(json.dumps(res, indent=2) + "\n")


if __name__ == "__main__":
    main()
