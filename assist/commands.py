"""``ptw-assist`` subcommands of the rider-assist side: design, evaluate, demo (cli.md).

Registered into the one command line of :mod:`ptw_env.cli` when it builds its parser.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ptw_env.cli import SPEED_KMH, SPEED_MS, CLIError, check_outputs, NOISE_PCT, SEED, write_json, command, effect_arg, write_figure

DEFAULT_DEMO = {"scenario": "double_lane_change", "noise": 5.0, "seed": 0}


def _speed_range(a: argparse.Namespace) -> dict[str, float]:
    out = {}
    for name in ("vmin", "vmax"):
        v = getattr(a, name, None)
        if v is not None:
            if not math.isfinite(v) or v <= 0:
                raise CLIError(f"--{name}: expected a positive speed in m/s, got {v}")
            out[name] = v
    if "vmin" in out and "vmax" in out and out["vmin"] >= out["vmax"]:
        raise CLIError(f"--vmin {out['vmin']} must be below --vmax {out['vmax']}")
    return out


@command(
    "design",
    "the TS observer and controller LMI design (Theorems 1-2), certificates checked in numpy",
    "ptw-assist design --vmin 8 --vmax 33 --json design.json",
)
def _build_design(p: argparse.ArgumentParser):
    p.add_argument("--vmin", type=SPEED_MS, default=None, help="lower end of the speed premise [m/s] (default 8)")
    p.add_argument("--vmax", type=SPEED_MS, default=None, help="upper end of the speed premise [m/s] (default 33)")
    p.add_argument("--solver", choices=("CLARABEL", "SCS"), default="CLARABEL")
    p.add_argument("--no-cache", action="store_true", help="solve again even if an identical design is cached")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")

    def run(a: argparse.Namespace) -> int:
        from .ts_design import design_report, format_summary

        check_outputs(a, "json")
        rep = design_report(solver=a.solver, cache=not a.no_cache, **_speed_range(a))
        print(format_summary(rep))
        write_json(a.json, rep, a.overwrite)
        return 0 if rep.get("feasible") else 1

    return run


def _add_episode_args(p: argparse.ArgumentParser, controller: bool = True) -> None:
    from ptw_env.scenarios import scenario_names

    from .evaluate import CONTROLLERS

    if controller:
        p.add_argument("--controller", choices=CONTROLLERS, default="ts")
        p.add_argument("--policy", default=None, metavar="POLICY.zip",
                       help="rl: a policy file from 'ptw-assist train-rl' (default: the shipped policy)")
    p.add_argument("--scenario", choices=scenario_names(), default=DEFAULT_DEMO["scenario"])
    p.add_argument("--speed", type=SPEED_KMH, default=None, metavar="KMH", help="cruise speed [km/h] where the scenario has one")
    p.add_argument("--noise", type=NOISE_PCT, default=DEFAULT_DEMO["noise"], metavar="PCT",
                   help="sensor noise in percent of each channel's range (default 5, the paper's)")
    p.add_argument("--seed", type=SEED, default=DEFAULT_DEMO["seed"], help="seed of the sensor noise (>= 0)")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:PARAM=VALUE", type=effect_arg,
                   help="an effect of effects.md in the true plant (the controller is designed on the nominal model)")
    p.add_argument("--vmin", type=SPEED_MS, default=None, help="TS design: lower end of the speed premise [m/s]")
    p.add_argument("--vmax", type=SPEED_MS, default=None, help="TS design: upper end of the speed premise [m/s]")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")


def _episode(a: argparse.Namespace, controller: str):
    from ptw_env.effects import Effects

    from .evaluate import run_episode

    opts = _speed_range(a) if controller in ("ts", "ts_state") else {}
    if getattr(a, "policy", None) is not None:
        if controller != "rl":
            raise CLIError(f"--policy applies to --controller rl, not {controller}")
        opts["policy"] = a.policy
    return run_episode(controller, a.scenario, speed_kmh=a.speed, noise_pct=a.noise, seed=a.seed,
                       effects=Effects.parse(a.effect), controller_options=opts)


@command(
    "evaluate",
    "a closed-loop roll-tracking episode through env.step with a controller",
    "ptw-assist evaluate --controller ts --scenario double_lane_change --speed 100 --noise 5 --seed 1 --plot ts.png",
)
def _build_evaluate(p: argparse.ArgumentParser):
    _add_episode_args(p)

    def run(a: argparse.Namespace) -> int:
        from .evaluate import metrics_table, plot_episode

        check_outputs(a, "plot", "json")
        ep = _episode(a, a.controller)
        m = ep.metrics()
        print(metrics_table([m]))
        if a.plot:
            write_figure(a.plot, lambda f: plot_episode(ep, f))
            print(f"figure written to {a.plot}")
        write_json(a.json, m, a.overwrite)
        return 0

    return run


@command(
    "demo",
    "the main job: TS observer-based roll tracking on the default scenario with 5 % sensor noise, "
    "against the LQG and the full-state bounds (tracking LQR, TS gains on the true state)",
    "ptw-assist demo --plot demo.png",
)
def _build_demo(p: argparse.ArgumentParser):
    _add_episode_args(p, controller=False)
    p.set_defaults(plot="demo.png")

    def run(a: argparse.Namespace) -> int:
        from .evaluate import metrics_table, plot_episode

        check_outputs(a, "plot", "json")
        eps = {c: _episode(a, c) for c in ("ts", "lqg", "lqr", "ts_state")}
        ms = {c: e.metrics() for c, e in eps.items()}
        print(f"closed-loop roll tracking, {a.scenario}, noise {a.noise} % of range, seed {a.seed} "
              f"(ts and lqg see only the noisy sensors; the full-state bounds lqr (tracking LQR) and ts_state "
              f"(the TS gains, observer bypassed) get the true state)")
        print(metrics_table(list(ms.values())))
        write_figure(a.plot, lambda f: plot_episode(eps["ts"], f, compare=[eps["lqg"], eps["lqr"]]))
        print(f"figure written to {Path(a.plot)}")
        out = dict(ms["ts"])
        out["baselines"] = {"lqg": ms["lqg"], "lqr": ms["lqr"], "ts_state": ms["ts_state"]}
        write_json(a.json, out, a.overwrite)
        return 0

    return run


@command(
    "observability",
    "strong observability / detectability of the HOSM cases (invariant zeros, relative degrees) per speed",
    "ptw-assist observability --speeds 8,15,25,33 --json obs.json --plot obs.png",
)
def _build_observability(p: argparse.ArgumentParser):
    from ptw_env.cli import speed_list

    p.add_argument("--speeds", type=speed_list, default=None, metavar="V1,V2,...",
                   help="speeds in m/s (default: 8 to 33 m/s)")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")

    def run(a: argparse.Namespace) -> int:
        from .observability import format_report, observability_report, plot_report

        check_outputs(a, "plot", "json")
        rep = observability_report(a.speeds)
        print(format_report(rep))
        if a.plot:
            write_figure(a.plot, lambda f: plot_report(rep, f))
            print(f"figure written to {a.plot}")
        write_json(a.json, rep, a.overwrite)
        return 0

    return run
