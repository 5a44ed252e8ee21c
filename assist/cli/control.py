"""``ptw-assist`` subcommands of the rider-assist side: design, evaluate, demo (cli.md).

Registered into the one command line of :mod:`ptw_env.cli` when it builds its parser.
"""

from __future__ import annotations

import argparse
import math

from ptw_env.cli import (
    NOISE_PCT,
    SEED,
    SPEED_KMH,
    SPEED_MS,
    CLIError,
    add_executor_options,
    add_vehicle_option,
    check_outputs,
    check_speeds_in_vehicle,
    chosen_vehicle,
    command,
    effect_arg,
    emit,
    kmh_list,
    number,
)

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
    add_vehicle_option(p)
    p.add_argument("--vmin", type=SPEED_MS, default=None,
                   help="lower end of the speed premise [m/s] (default: the vehicle's design range, 8 for the "
                        "reference scooter)")
    p.add_argument("--vmax", type=SPEED_MS, default=None,
                   help="upper end of the speed premise [m/s] (default: the vehicle's design range, 33 for the "
                        "reference scooter)")
    p.add_argument("--solver", choices=("CLARABEL", "SCS"), default="CLARABEL")
    p.add_argument("--no-cache", action="store_true", help="solve again even if an identical design is cached")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")

    def run(a: argparse.Namespace) -> int:
        from assist.control.ts_design import design_report, format_summary

        check_outputs(a, "json")
        v = chosen_vehicle(a)
        _check_range_in_vehicle(a, v)
        rep = design_report(v, solver=a.solver, cache=not a.no_cache, **_speed_range(a))
        rep["vehicle"] = v.identity()
        print(f"vehicle: {v.name}")
        print(format_summary(rep))
        if not rep.get("feasible"):
            print(f"  (speed range tried: {_speed_range(a) or 'the design range of ' + v.name}; narrow it with "
                  f"--vmin/--vmax, or set [speed_range] design_vmin/design_vmax in the vehicle file)")
        emit(a, rep)
        return 0 if rep.get("feasible") else 1

    return run


def _check_range_in_vehicle(a: argparse.Namespace, v) -> None:
    """``--vmin``/``--vmax`` inside the vehicle's valid speed range (one clear error otherwise)."""
    for name in ("vmin", "vmax"):
        x = getattr(a, name, None)
        if x is not None and not (v.vmin <= x <= v.vmax):
            raise CLIError(f"--{name} {x:g} m/s is outside the valid range [{v.vmin:g}, {v.vmax:g}] m/s of {v.name}")


def _add_episode_args(p: argparse.ArgumentParser, controller: bool = True) -> None:
    from ptw_env.scenarios import scenario_names

    from assist.evaluate import CONTROLLERS

    if controller:
        p.add_argument("--controller", choices=CONTROLLERS, default="ts")
        p.add_argument("--policy", default=None, metavar="POLICY.zip",
                       help="rl: a policy file from 'ptw-assist train-rl' (default: the shipped policy)")
    p.add_argument("--scenario", choices=scenario_names(), default=DEFAULT_DEMO["scenario"])
    add_vehicle_option(p)
    p.add_argument("--speed", type=SPEED_KMH, default=None, metavar="KMH", help="cruise speed [km/h] where the scenario has one")
    p.add_argument("--noise", type=NOISE_PCT, default=DEFAULT_DEMO["noise"], metavar="PCT",
                   help="sensor noise in percent of each channel's range (default 5, the paper's)")
    p.add_argument("--seed", type=SEED, default=DEFAULT_DEMO["seed"], help="seed of the sensor noise (>= 0)")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:PARAM=VALUE", type=effect_arg,
                   help="an effect of effects.md in the true plant (the controller is designed on the nominal model)")
    p.add_argument("--vmin", type=SPEED_MS, default=None,
                   help="TS design: lower end of the speed premise [m/s] (default: the vehicle's design range)")
    p.add_argument("--vmax", type=SPEED_MS, default=None,
                   help="TS design: upper end of the speed premise [m/s] (default: the vehicle's design range)")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")


def _episode(a: argparse.Namespace, controller: str):
    from ptw_env.effects import Effects

    from assist.evaluate import run_episode

    v = chosen_vehicle(a)
    _check_range_in_vehicle(a, v)
    opts = _speed_range(a) if controller in ("ts", "ts_state") else {}
    if getattr(a, "policy", None) is not None:
        if controller != "rl":
            raise CLIError(f"--policy applies to --controller rl, not {controller}")
        opts["policy"] = a.policy
    try:
        return run_episode(controller, a.scenario, speed_kmh=a.speed, noise_pct=a.noise, seed=a.seed,
                           effects=Effects.parse(a.effect), controller_options=opts, vehicle=v)
    except ValueError as exc:  # a design the vehicle cannot certify, a speed outside its range, ...
        raise CLIError(f"{v.name}, controller {controller}: {exc}") from None


@command(
    "evaluate",
    "a closed-loop roll-tracking episode through env.step with a controller",
    "ptw-assist evaluate --controller ts --scenario double_lane_change --speed 100 --noise 5 --seed 1 --plot ts.png",
)
def _build_evaluate(p: argparse.ArgumentParser):
    _add_episode_args(p)
    g = p.add_argument_group("sweep form (any of these: many episodes on the execution layer, one table)")
    g.add_argument("--sweep", default=None, metavar="SWEEP.json",
                   help="a sweep file: JSON with controllers, scenarios, speeds_kmh, seeds, effects (a list of "
                        "effect sets), noise_pct; a key left out takes the options' value")
    g.add_argument("--controllers", type=_name_list, default=None, metavar="C1,C2", help="controllers to sweep")
    g.add_argument("--scenarios", type=_name_list, default=None, metavar="S1,S2", help="scenarios to sweep")
    g.add_argument("--speeds", type=kmh_list, default=None, metavar="KMH,...", help="cruise speeds to sweep [km/h]")
    g.add_argument("--seeds", type=_SEEDS, default=None, metavar="N", help="N seeds from --seed on")
    g.add_argument("--table", default=None, metavar="OUT.csv", help="the sweep's table, one row per episode (required)")
    add_executor_options(g, "episodes", "keep the episodes a previous run of this --table finished (OUT.csv.jobs.jsonl)")

    def run(a: argparse.Namespace) -> int:
        from assist.evaluate import metrics_table, plot_episode

        if any(getattr(a, k) is not None for k in ("sweep", "controllers", "scenarios", "speeds", "seeds")):
            return _sweep(a)
        if a.table or a.resume or a.workers != 1 or a.scheduler:
            raise CLIError("--table, --resume, --workers and --scheduler belong to the sweep form "
                           "(give --sweep, --controllers, --scenarios, --speeds or --seeds)")
        check_outputs(a, "plot", "json")
        ep = _episode(a, a.controller)
        m = ep.metrics()
        m["vehicle"] = chosen_vehicle(a).identity()
        print(f"vehicle: {chosen_vehicle(a).name}")
        print(metrics_table([m]))
        if m["diverged"] or m["fell"]:
            print(f"the episode ended early: {m['end_reason']}")
        emit(a, m, {"plot": lambda f: plot_episode(ep, f)})
        return 0

    return run


_SEEDS = number(1, 1_000_000, integer=True)


def _name_list(text: str) -> list[str]:
    out = [t.strip() for t in text.split(",") if t.strip()]
    if not out:
        raise argparse.ArgumentTypeError(f"expected comma-separated names, got {text!r}")
    return out


def _sweep(a: argparse.Namespace) -> int:
    """``evaluate``'s sweep form: controllers x scenarios x speeds x effect sets x seeds on the execution layer."""
    import os
    from pathlib import Path

    from ptw_env.jobs import JobsError, executor_name
    from ptw_env.outputs import atomic_write_text, check_writable
    from ptw_env.scenarios import make_scenario, scenario_names

    from assist.evaluate import (EvaluationError, load_sweep_file, plot_sweep, run_sweep, sweep_points,
                                 sweep_summary, sweep_table)

    if a.table is None:
        raise CLIError("the sweep form writes its table: give --table OUT.csv")
    if getattr(a, "policy", None) is not None:
        raise CLIError("--policy is for one episode; a sweep of rl uses the shipped policy")
    try:
        spec = load_sweep_file(a.sweep) if a.sweep else {}
    except EvaluationError as exc:
        raise CLIError(f"--sweep: {exc}") from None
    controllers = spec.get("controllers", a.controllers or [a.controller])
    scenarios = spec.get("scenarios", a.scenarios or [a.scenario])
    speeds = spec.get("speeds_kmh", a.speeds or [a.speed])
    seeds = spec.get("seeds", list(range(a.seed, a.seed + (a.seeds or 1))))
    effects = spec.get("effects", [list(a.effect)])
    noise = spec.get("noise_pct", a.noise)
    if spec:  # a file's numbers within the command line's own ranges (NOISE_PCT, SEED, SPEED_KMH)
        try:
            if "noise_pct" in spec:
                noise = NOISE_PCT(str(noise))
            if "seeds" in spec:
                seeds = [int(SEED(str(x))) for x in seeds]
            if "speeds_kmh" in spec:
                speeds = [None if x is None else float(SPEED_KMH(str(x))) for x in speeds]
        except argparse.ArgumentTypeError as exc:
            raise CLIError(f"--sweep: {a.sweep}: {exc}") from None
    known = set(scenario_names())
    for name in scenarios:
        if name not in known:
            raise CLIError(f"scenario {name!r} is not one of {sorted(known)}")
        for sp in speeds:  # a speed the scenario cannot take is refused here, not in a worker
            try:
                make_scenario(name, speed_kmh=sp)
            except ValueError as exc:
                raise CLIError(f"--speeds: {exc}") from None
    for ef in effects:
        for t in ef:
            try:
                effect_arg(t)  # checked against effects.md here, not in a worker
            except argparse.ArgumentTypeError as exc:
                raise CLIError(f"--sweep: effects {ef}: {exc}") from None
    try:
        points = sweep_points(controllers, scenarios, speeds, seeds, effects, noise)
        where = executor_name(a.workers, a.scheduler)
    except (EvaluationError, JobsError) as exc:
        raise CLIError(str(exc)) from None
    v = chosen_vehicle(a)
    for sp in speeds:
        if sp is not None:
            check_speeds_in_vehicle([sp / 3.6], v, "--speeds")
    jobs_file = Path(str(a.table) + ".jobs.jsonl")
    if a.resume and not jobs_file.exists():
        raise CLIError(f"--resume: no previous run of {a.table} ({jobs_file} is missing)")
    if not a.resume and jobs_file.exists() and not a.overwrite:
        raise CLIError(f"--table: {jobs_file} holds a previous run; pass --resume to continue it or --overwrite")
    check_outputs(a, "plot", "json")
    for opt in ("plot", "json"):
        if getattr(a, opt) is not None and os.path.realpath(getattr(a, opt)) == os.path.realpath(a.table):
            raise CLIError(f"--{opt} and --table both name {a.table}: each output needs its own file")
    check_writable(a.table, "--table", overwrite=a.overwrite or a.resume)  # --resume completes that table
    if not a.resume and jobs_file.exists():
        jobs_file.unlink()
    print(f"vehicle: {v.name}; {len(points)} episodes ({len(controllers)} controllers x {len(scenarios)} scenarios "
          f"x {len(speeds)} speeds x {len(effects)} effect sets x {len(seeds)} seeds); executor: {where}")
    try:
        rows = run_sweep(points, vehicle=v, workers=a.workers, scheduler=a.scheduler, results=str(jobs_file))
    except JobsError as exc:
        raise CLIError(str(exc)) from None
    atomic_write_text(a.table, sweep_table(rows))
    summ = sweep_summary(rows)
    for r in summ:
        sp = "-" if r["speed_kmh"] is None else f"{r['speed_kmh']:g} km/h"
        print(f"  {r['controller']:>8} {r['scenario']:<20} {sp:>10} {r['effects'] or 'nominal':<28} "
              f"roll RMSE {r['roll_rmse_deg_mean']:.3f} deg (max {r['roll_rmse_deg_max']:.3f}) over "
              f"{r['episodes']} episodes, falls {r['falls']}")
    print(f"table written to {a.table}")
    obj = {"summary": summ, "rows": rows, "executor": where, "vehicle": v.identity()} if a.json else None
    emit(a, obj, {"plot": lambda f: plot_sweep(rows, f)})
    return 0


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
        from assist.evaluate import metrics_table, plot_episode

        check_outputs(a, "plot", "json")
        eps = {c: _episode(a, c) for c in ("ts", "lqg", "lqr", "ts_state")}
        ms = {c: e.metrics() for c, e in eps.items()}
        print(f"closed-loop roll tracking, {chosen_vehicle(a).name}, {a.scenario}, noise {a.noise} % of range, "
              f"seed {a.seed} "
              f"(ts and lqg see only the noisy sensors; the full-state bounds lqr (tracking LQR) and ts_state "
              f"(the TS gains, observer bypassed) get the true state)")
        print(metrics_table(list(ms.values())))
        out = dict(ms["ts"])
        out["baselines"] = {"lqg": ms["lqg"], "lqr": ms["lqr"], "ts_state": ms["ts_state"]}
        out["vehicle"] = chosen_vehicle(a).identity()
        emit(a, out, {"plot": lambda f: plot_episode(eps["ts"], f, compare=[eps["lqg"], eps["lqr"]])})
        return 0

    return run


@command(
    "observability",
    "strong observability / detectability of the HOSM cases (invariant zeros, relative degrees) per speed",
    "ptw-assist observability --speeds 8,15,25,33 --json obs.json --plot obs.png",
)
def _build_observability(p: argparse.ArgumentParser):
    from ptw_env.cli import speed_list

    add_vehicle_option(p)
    p.add_argument("--speeds", type=speed_list, default=None, metavar="V1,V2,...",
                   help="speeds in m/s (default: 26 speeds across the vehicle's design range, 8 to 33 m/s for the "
                        "reference scooter)")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")

    def run(a: argparse.Namespace) -> int:
        from assist.unknown_input.observability import format_report, observability_report, plot_report

        check_outputs(a, "plot", "json")
        v = chosen_vehicle(a)
        check_speeds_in_vehicle(a.speeds, v)
        rep = observability_report(a.speeds, vehicle=v)
        rep["vehicle"] = v.identity()
        print(format_report(rep))
        emit(a, rep, {"plot": lambda f: plot_report(rep, f)})
        return 0

    return run
