"""Training throughput of the RL baseline: torch threads 1 vs 2, DummyVecEnv vs SubprocVecEnv.

Every configuration trains the same PPO (``assist.rl.build_model``, the
shipped policy's settings) for the same number of environment steps, in the
same run, interleaved over ``--repeats`` rounds so that the load of other
jobs on the machine falls on every configuration alike; the median
throughput (environment steps per second of ``model.learn``, collection and
updates together) is reported, with ratios against 1 thread + DummyVecEnv.
A second table times the two phases apart (rollout collection, gradient
updates) for each thread count.

Run: ``python scripts/bench_rl.py [--steps 16384] [--n-envs 4] [--repeats 3] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

from assist.rl import build_model
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)


def _run(threads: int, vec: str, n_envs: int, steps: int, seed: int = 0) -> dict[str, float]:
    model, venv, *_ = build_model("ppo", seed=seed, n_envs=n_envs, vec=vec, threads=threads)
    # split the time between rollout collection and the gradient updates
    timing = {"train": 0.0}
    train = model.train

    def timed_train():
        t = time.perf_counter()
        train()
        timing["train"] += time.perf_counter() - t

    model.train = timed_train
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    total = time.perf_counter() - t0
    venv.close()
    n = model.num_timesteps
    return {"steps": n, "seconds": total, "steps_per_s": n / total, "collect_s": total - timing["train"],
            "update_s": timing["train"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=16384, help="environment steps per configuration and round")
    ap.add_argument("--n-envs", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    add_overwrite(ap)
    a = ap.parse_args()
    output_file(ap, "--json", a.json, a.overwrite)
    configs = [(1, "dummy"), (2, "dummy"), (1, "subproc"), (2, "subproc")]
    runs: dict[tuple[int, str], list[dict[str, float]]] = {c: [] for c in configs}
    _run(1, "dummy", a.n_envs, 2048)  # warm-up: numba caches, imports
    for r in range(a.repeats):
        for c in configs:
            res = _run(c[0], c[1], a.n_envs, a.steps)
            runs[c].append(res)
            print(f"round {r + 1}: threads={c[0]} {c[1]:8s} {res['steps_per_s']:7.0f} steps/s "
                  f"(collect {res['collect_s']:.1f} s, update {res['update_s']:.1f} s)", flush=True)
    med = {c: statistics.median(x["steps_per_s"] for x in v) for c, v in runs.items()}
    base = med[(1, "dummy")]
    print(f"\nPPO, {a.n_envs} envs, {a.steps} steps per run, median of {a.repeats} interleaved rounds, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at the end")
    print("| torch threads | vec env | env steps/s | ratio to 1 thread + Dummy | collect s | update s |")
    print("|---|---|---|---|---|---|")
    for c in configs:
        cs = statistics.median(x["collect_s"] for x in runs[c])
        us = statistics.median(x["update_s"] for x in runs[c])
        print(f"| {c[0]} | {c[1]} | {med[c]:.0f} | {med[c] / base:.2f} | {cs:.1f} | {us:.1f} |")
    best = max(med, key=med.get)
    print(f"fastest: threads={best[0]}, {best[1]}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({f"{c[0]}_{c[1]}": {"median_steps_per_s": med[c], "runs": runs[c]} for c in configs}, f, indent=1)


if __name__ == "__main__":
    main()
