"""``ptw-assist diagnose LOG.csv [LOG2.csv ...] --json REPORT.json [--plot REPORT.png]`` (diagnose.md, cli.md).

One log: its report (``--json``) and figure (``--plot``). Many logs (files, folders of ``*.csv``
or glob patterns), or ``--out DIR``: one report and figure per log in ``DIR``, the fleet table
``DIR/fleet.csv``, the fleet's JSON (``--json``) and figure (``--plot``), run on the execution
layer (:mod:`ptw_env.jobs`: ``--workers N`` local processes, ``--scheduler ADDRESS`` a Dask
cluster; ``--resume`` skips the logs a previous run finished). Every log is read and checked
against its vehicle before any work. Registered into the one command line of :mod:`ptw_env.cli`
when it builds its parser (``import assist.cli.diagnose``). A bad log ends with one line naming
the file, the line and the column (:class:`ptw_env.logs.LogFormatError`) and exit status 2.
"""

from __future__ import annotations

import argparse
import glob
import os
from pathlib import Path

from ptw_env.cli import (
    CLIError,
    add_executor_options,
    add_vehicle_option,
    check_outputs,
    command,
    number,
    emit,
    vehicle_for_log,
)


#: ``--window``: replay window length [s].
_window = number(0.2, 20.0, unit="s")


def expand_logs(items: list[str]) -> list[str]:
    """The ride logs of the positional arguments: a file as given, a folder's ``*.csv`` (sorted), a glob
    pattern's matches (sorted); each log once. Nothing found for one item is one :class:`CLIError` naming it."""
    out: list[str] = []
    for it in items:
        if any(ch in it for ch in "*?["):
            found = sorted(glob.glob(it))
            if not found:
                raise CLIError(f"{it}: no file matches this pattern")
        elif Path(it).is_dir():
            found = sorted(str(p) for p in Path(it).glob("*.csv"))
            if not found:
                raise CLIError(f"{it}: a folder with no .csv ride log in it")
        elif not Path(it).exists():
            raise FileNotFoundError(f"{it}: no such file")
        else:
            found = [it]
        out += found
    seen: set[str] = set()
    unique = []
    for p in out:
        key = os.path.realpath(p)
        if key not in seen:
            seen.add(key)
            unique.append(p)
    return unique


@command(
    "diagnose",
    "replay the nominal model against a ride log, name the effect of effects.md that explains the "
    "difference, and measure the held-out gain",
    "ptw-assist diagnose ride.csv --json report.json --plot report.png",
)
def _build_diagnose(p: argparse.ArgumentParser):
    p.add_argument("logs", nargs="+", metavar="LOG.csv",
                   help="ride log(s) (logs.md, optional JSON sidecar): files, folders (their *.csv) or glob patterns")
    add_vehicle_option(p, from_log=True)
    p.add_argument("--json", default=None, metavar="REPORT.json",
                   help="write the report (diagnose.md); with many logs the fleet's JSON (one row per log)")
    p.add_argument("--plot", default=None, metavar="REPORT.png",
                   help="measured vs nominal vs extended model, residual before/after; with many logs the "
                        "fleet's figure (held-out gain per log)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="with many logs (required then): the folder of the per-log reports and figures and of "
                        "the fleet table fleet.csv")
    add_executor_options(p, "logs diagnosed",
                         "with --out: keep the logs a previous run finished (DIR/fleet_jobs.jsonl), diagnose the rest")
    p.add_argument("--window", type=_window, default=None, metavar="S",
                   help="replay window length [s] (default 2, shorter for short logs)")
    p.add_argument("--pairs", choices=("auto", "all", "none"), default="auto",
                   help="pairs of causes: auto (default) fits only pairs that forward selection "
                        "proposes (the best single cause with the next ones and those a score "
                        "test says add most; at most 9 of the 45 pairs), 'all' every pair (about "
                        "3.4x the simulation: over the 60 s target per 90 s log on 2 cores), "
                        "'none' no pairs. auto can miss a pair whose causes do not improve the "
                        "fit alone, or two weak causes neither of which is the best single one")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")

    def run(a: argparse.Namespace) -> int:
        from assist.diagnose import diagnose
        from ptw_env.logs import read_log

        logs = expand_logs(a.logs)
        pairs = {"auto": True, "all": "all", "none": False}[a.pairs]
        if len(logs) > 1 or a.out is not None:
            return _fleet(a, logs, pairs)
        if a.resume or a.workers != 1 or a.scheduler is not None:
            raise CLIError("--resume, --workers and --scheduler are for many logs (give --out DIR)")
        a.log = logs[0]
        check_outputs(a, "json", "plot")
        ride = read_log(a.log)
        v = vehicle_for_log(a, ride)  # --vehicle, else the sidecar's, else the reference scooter
        print(f"vehicle: {v.name}")
        rep = diagnose(ride, window_s=a.window, pairs=pairs, progress=False if a.no_progress else None, vehicle=v)
        print(rep.summary())
        print(f"diagnosed in {rep.seconds:.1f} s ({100 * rep.sim_seconds / rep.seconds:.0f} % in the simulator)")
        emit(a, rep.to_json() if a.json else None, {"plot": rep.plot}, what="report")
        return 0

    return run


#: ``--spread``: factor on the fitted standard deviations
_spread = number(0.0, 1000.0, lo_open=True)


@command(
    "twin",
    "a digital twin of a ride log: diagnose it and write what was measured (vehicle, causes, closure terms, "
    "their uncertainty) as a randomize= description for the environments",
    "ptw-assist twin ride.csv --out twin.json",
)
def _build_twin(p: argparse.ArgumentParser):
    p.add_argument("log", metavar="LOG.csv", help="ride log (logs.md, optional JSON sidecar)")
    add_vehicle_option(p, from_log=True)
    p.add_argument("--out", required=True, metavar="TWIN.json",
                   help="the twin (assist.diagnose.twin): use it with Randomization.env_kwargs('TWIN.json')")
    p.add_argument("--spread", type=_spread, default=1.0, metavar="K",
                   help="widen every fitted distribution K times its standard deviation (default 1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")

    def run(a: argparse.Namespace) -> int:
        from assist.diagnose import diagnose
        from assist.diagnose.twin import twin
        from ptw_env.cli import write_json
        from ptw_env.logs import read_log

        check_outputs(a, "out")
        ride = read_log(a.log)
        v = vehicle_for_log(a, ride)
        print(f"vehicle: {v.name}")
        rep = diagnose(ride, progress=False if a.no_progress else None, vehicle=v)
        print(rep.summary())
        t = twin(rep, spread=a.spread)
        for key, d in t["randomize"].items():
            print(f"  {key} ~ {d}")
        for e in t["effects"]:
            print(f"  fixed: {e['cause']} {e['params']}")
        for line in t["not_reproduced"] + t["notes"]:
            print(f"  note: {line}")
        write_json(a.out, t, a.overwrite)
        print(f"twin written to {a.out}")
        return 0

    return run


def _fleet(a: argparse.Namespace, logs: list[str], pairs) -> int:
    """Many logs: check them all, then diagnose them on the execution layer (module docstring)."""
    from assist.diagnose.diagnosis import replay_windows
    from assist.diagnose.fleet import diagnose_fleet, plot_fleet
    from ptw_env.jobs import JobsError, executor_name
    from ptw_env.logs import read_log

    if a.out is None:
        raise CLIError(f"{len(logs)} logs: give --out DIR for their reports and the fleet table")
    out = Path(a.out)
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out: {out} is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (a.overwrite or a.resume):
        raise CLIError(f"--out: {out} is not empty; pass --resume to continue a run there or --overwrite to replace it")
    if a.resume and not (out / "fleet_jobs.jsonl").exists():
        raise CLIError(f"--resume: {out} holds no previous run (fleet_jobs.jsonl)")
    try:
        where = executor_name(a.workers, a.scheduler)
    except JobsError as exc:
        raise CLIError(f"--scheduler/--workers: {exc}") from None
    check_outputs(a, "json", "plot")
    reports = {os.path.realpath(out / f"{Path(p).stem}{suffix}") for p in logs for suffix in (".json", ".png")}
    reports |= {os.path.realpath(out / n) for n in ("fleet.csv", "fleet_jobs.jsonl")}
    for opt in ("json", "plot"):
        path = getattr(a, opt)
        if path is not None and os.path.realpath(path) in reports:
            raise CLIError(f"--{opt}: {path} is one of the files written in --out; name it otherwise")
    vehicles = []
    for p in logs:  # every log read, checked against its vehicle and cut into windows before any work
        ride = read_log(p)
        vehicles.append(vehicle_for_log(a, ride))
        replay_windows(ride, vehicles[-1], a.window, source=p)
    print(f"{len(logs)} logs; executor: {where}; reports in {out}/")
    try:
        rows = diagnose_fleet(logs, out, vehicles=vehicles, window_s=a.window, pairs=pairs, workers=a.workers,
                              scheduler=a.scheduler, resume=a.resume, progress=not a.no_progress)
    except JobsError as exc:
        raise CLIError(str(exc)) from None
    for r in rows:
        causes = ", ".join(c["cause"] for c in r["causes"])
        ext = "" if r["extension"] is None else "; extended: " + ", ".join(t["name"] for t in r["extension"])
        print(f"  {r['log_name']}: {causes} (gain {r['gain']:.3f}, {'explained' if r['explained'] else 'not explained'}){ext}")
    print(f"fleet table written to {out / 'fleet.csv'}")
    obj = {"logs": rows, "executor": where,
           "vehicles": {v.name: v.identity() for v in vehicles}} if a.json else None
    emit(a, obj, {"plot": lambda path: plot_fleet(rows, path)}, what="fleet JSON")
    return 0
