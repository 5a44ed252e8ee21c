"""``ptw-assist train-rl``: train the RL baseline (cli.md), registered into :mod:`ptw_env.cli`.

Imports nothing of stable-baselines3 until the command runs, so ``--help``
works without the ``[rl]`` extra.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

from ptw_env.cli import SEED, CLIError, add_vehicle_option, check_outputs, chosen_vehicle, command, emit, number

#: Settings of the shipped policy (``assist/policies/ppo_roll.json``).
DEFAULT_STEPS = 6_000_000


def _int_at_least(lo: int, hi: int = 10**12):
    """argparse type: a whole number in ``[lo, hi]``."""
    return number(lo, hi, integer=True)


@command(
    "train-rl",
    "train the RL baseline (PPO or SAC, stable-baselines3) on roll tracking from the noisy sensors",
    "ptw-assist train-rl --algo ppo --steps 200000 --seed 0 --out my_policy.zip --json train.json",
)
def _build_train_rl(p: argparse.ArgumentParser):
    p.add_argument("--algo", choices=("ppo", "sac"), default="ppo")
    add_vehicle_option(p)
    p.add_argument("--steps", type=_int_at_least(1), default=DEFAULT_STEPS, metavar="N",
                   help=f"environment steps of 10 ms over all copies (default {DEFAULT_STEPS}, the shipped policy's)")
    p.add_argument("--seed", type=SEED, default=0, metavar="N",
                   help="seed of torch, numpy and the environments (default 0)")
    p.add_argument("--speeds", default=None, metavar="LO,HI",
                   help="cruise speeds of the training rides [km/h] (default: the vehicle's design range; "
                        "the shipped policy: 30,90)")
    p.add_argument("--n-envs", type=_int_at_least(1, 4096), default=4, metavar="N", help="environment copies (default 4)")
    p.add_argument("--vec", choices=("dummy", "subproc", "native"), default="dummy",
                   help="copies in this process, one process each, or native: the compiled vector env with a pool "
                        "of 64 rides, mirrored rides and randomised vehicles (assist.rl.training.native_training_env; "
                        "use many --n-envs, e.g. 256) (default dummy)")
    p.add_argument("--threads", type=_int_at_least(1, 1024), default=1, metavar="N",
                   help="torch threads (default 1: faster on 2 cores, scripts/bench_rl.py)")
    p.add_argument("--checkpoint-every", type=_int_at_least(0), default=500_000, metavar="N",
                   help="save a checkpoint every N steps into <out stem>_checkpoints/ (0: none; default 500000)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--out", required=True, metavar="POLICY.zip",
                   help="policy file to write (with its provenance in POLICY.json beside it)")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")

    def run(a: argparse.Namespace) -> int:
        from assist.rl import train

        from assist.rl import PolicyError, TrainingDistribution

        v = chosen_vehicle(a)
        speeds = None
        if a.speeds is not None:
            parts = a.speeds.split(",")
            try:
                speeds = tuple(number(0, 1e4, unit="km/h", lo_open=True)(x.strip()) for x in parts)
            except argparse.ArgumentTypeError as exc:
                raise CLIError(f"--speeds {a.speeds!r}: {exc}") from None
            if len(speeds) != 2:
                raise CLIError(f"--speeds {a.speeds!r}: expected two speeds LO,HI in km/h")
        try:
            dist = TrainingDistribution(speed_kmh=speeds).for_vehicle(v)
        except PolicyError as exc:
            raise CLIError(f"--speeds: {exc}") from None
        out = Path(a.out)
        if out.suffix != ".zip":
            raise CLIError(f"--out: the policy file must end in .zip, got {out.name!r}")
        a.sidecar = str(out.with_suffix(".json"))
        if a.json is not None and Path(a.json).resolve() == Path(a.sidecar).resolve():
            raise CLIError(f"--json: {a.json} is the policy's provenance file; choose another name")
        check_outputs(a, "out", "sidecar", "json")
        for opt, f in (("--out", out), ("--json", None if a.json is None else Path(a.json))):
            # before training, not after: a run may take an hour
            if f is not None and not (f.parent.is_dir() and os.access(f.parent, os.W_OK)):
                raise CLIError(f"{opt}: cannot write into {f.parent} (not a writable folder)")
        ck = out.parent / f"{out.stem}_checkpoints"
        if a.checkpoint_every and ck.exists() and not a.overwrite:
            raise FileExistsError(f"{ck} exists; pass --overwrite to write checkpoints into it")
        cmd = "ptw-assist " + " ".join(shlex.quote(x) for x in sys.argv[1:]) if sys.argv else None
        res = train(a.algo, a.steps, a.seed, out, n_envs=a.n_envs, vec=a.vec, threads=a.threads,
                    checkpoint_every=a.checkpoint_every or None, progress=not a.no_progress, command=cmd,
                    env_kwargs={"vehicle": v, "distribution": dist})
        print(f"{a.algo} trained {res.steps} steps (seed {a.seed}) in {res.seconds:.0f} s; mean return over "
              f"{res.meta['eval_rides']['episodes']} evaluation rides: trained {res.final_reward:.0f}, untrained "
              f"{res.initial_reward:.0f}, random actions {res.random_reward:.0f} (1 per 10 ms step of perfect tracking)")
        print(f"policy written to {res.path} (+ {Path(a.sidecar).name})")
        emit(a, res.to_json())
        return 0

    return run
