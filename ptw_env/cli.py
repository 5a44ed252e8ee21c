"""The ``ptw-assist`` command line (``shared/spec/cli.md``).

Each subcommand prints a short human summary and, with ``--json FILE``,
writes the machine-readable figures of cli.md. Bad input ends with one line
``ptw-assist <cmd>: error: <what and where>`` and exit status 2; existing
output files are never overwritten unless ``--overwrite`` is given.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

#: subcommand name -> (parser builder returning the runner, help, example); each feature adds its own
_COMMANDS: dict[str, tuple[Callable[[argparse.ArgumentParser], Callable[[argparse.Namespace], int]], str, str]] = {}


class CLIError(ValueError):
    """A bad command-line argument (the message names it)."""


def command(name: str, help: str, example: str):
    """Register a subcommand: decorate its parser builder; the builder returns the runner."""

    def deco(build: Callable[[argparse.ArgumentParser], Callable[[argparse.Namespace], int]]):
        _COMMANDS[name] = (build, help, example)
        return build

    return deco


def _check_outputs(args: argparse.Namespace, *names: str) -> None:
    """Refuse to overwrite existing output files unless --overwrite."""
    for n in names:
        p = getattr(args, n, None)
        if p is None:
            continue
        p = Path(p)
        if p.exists() and not getattr(args, "overwrite", False):
            raise FileExistsError(f"{p} exists; pass --overwrite to replace it")
        if not p.parent.exists():
            raise CLIError(f"--{n.replace('_', '-')}: directory {p.parent} does not exist")


def _write_json(path: str | None, obj: dict[str, Any], overwrite: bool) -> None:
    if path is None:
        return
    p = Path(path)
    if p.exists() and not overwrite:
        raise FileExistsError(f"{p} exists; pass --overwrite to replace it")
    p.write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n")


def _speeds(text: str) -> list[float]:
    try:
        vals = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated speeds in m/s, e.g. 5,10,20,30; got {text!r}")
    if not vals or any(not math.isfinite(v) or v <= 0 for v in vals):
        raise argparse.ArgumentTypeError(f"speeds must be positive numbers in m/s, got {text!r}")
    return vals


def _seed(text: str) -> int:
    """A seed for numpy's generators: a whole number >= 0."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"a seed must be >= 0, got {text!r}")
    return v


def _nonneg(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}")
    if not math.isfinite(v) or v < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return v


def _bank_or_auto(text: str) -> float | str:
    """``--road-bank`` of the risk warning: an angle in rad, or ``auto`` (estimated on line)."""
    return "auto" if text.strip().lower() == "auto" else _bank(text)


def _bank(text: str) -> float:
    """``--road-bank``: an angle in rad, |bank| < 0.5 (a value in degrees is refused)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(v) or abs(v) >= 0.5:
        raise argparse.ArgumentTypeError(f"{text} is not a road bank in rad (|bank| < 0.5; degrees? 3 deg = 0.052 rad)")
    return v


# ---------------------------------------------------------------------------- simulate
@command(
    "simulate",
    "ride a scenario with the scenario's rider and write a ride log",
    "ptw-assist simulate --scenario urban --noise 5 --seed 3 --effect road_bank:bank_rad=0.05 --log ride.csv --plot ride.png",
)
def _build_simulate(p: argparse.ArgumentParser):
    from .scenarios import scenario_names

    p.add_argument("--scenario", default="double_lane_change", choices=scenario_names(), help="scenario name")
    p.add_argument("--speed", type=float, default=None, metavar="KMH", help="cruise speed [km/h] where the scenario has one")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:PARAM=VALUE",
                   help="an effect of effects.md in the true plant (repeatable)")
    p.add_argument("--noise", type=_nonneg, default=None, metavar="PCT",
                   help="sensor noise in percent of each channel's range (default: the reference logs' sensors)")
    p.add_argument("--seed", type=_seed, default=0, help="seed of the sensor noise, rider noise and initial state")
    p.add_argument("--rider-noise", type=_nonneg, default=3.0, metavar="NM", help="rider random torque [N m] (default 3)")
    p.add_argument("--log", required=True, metavar="OUT.csv", help="ride log to write (logs.md), with a JSON sidecar")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")

    def run(a: argparse.Namespace) -> int:
        from .effects import Effects
        from .ride import plot_ride, ride_scenario, save_ride

        log_path = Path(a.log)
        sidecar = log_path.with_suffix(".json")
        a.sidecar = str(sidecar)
        _check_outputs(a, "log", "sidecar", "plot", "json")
        effects = Effects.parse(a.effect)
        res = ride_scenario(a.scenario, speed_kmh=a.speed, effects=effects, noise_pct=a.noise, seed=a.seed,
                            rider_noise_nm=a.rider_noise)
        save_ride(res, log_path, overwrite=a.overwrite)
        s = res.summary()
        print(f"{s['scenario']}: {s['duration_s']:.2f} s, {s['samples']} samples, "
              f"{'FELL' if s['fell'] else 'upright'}; roll RMSE vs reference {s['roll_rmse_deg']:.2f} deg, "
              f"max roll {s['roll_max_deg']:.1f} deg, torque RMS {s['torque_rms_nm']:.1f} N m; effects: {effects}")
        print(f"log written to {log_path} (+ {sidecar.name})")
        if a.plot:
            plot_ride(res, a.plot)
            print(f"figure written to {a.plot}")
        _write_json(a.json, {**s, "log": str(log_path), "effects": effects.to_causes(), "seed": a.seed}, a.overwrite)
        return 0

    return run


# ---------------------------------------------------------------------------- modes
@command(
    "modes",
    "eigenvalues of the linearised vehicle per speed, labelled weave / wobble / capsize / tire / other",
    "ptw-assist modes --vehicle sharp1971 --speeds 5,10,20,30,40 --plot modes.png --locus locus.png --json modes.json",
)
def _build_modes(p: argparse.ArgumentParser):
    p.add_argument("--vehicle", default="reference-scooter", metavar="NAME_OR_FILE",
                   help="a vehicle preset (reference-scooter, sharp1971, cossalter-sport-touring) or the path of a "
                        "TOML parameter file (ptw_env.vehicle_files); default reference-scooter")
    p.add_argument("--speeds", type=_speeds, default=[5.0, 10.0, 20.0, 30.0], metavar="V1,V2,...",
                   help="speeds in m/s (default 5,10,20,30)")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:PARAM=VALUE")
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--locus", default=None, metavar="OUT.png",
                   help="also write the classic root locus (Sharp 1971 style: real part vs frequency, speeds marked)")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")

    def run(a: argparse.Namespace) -> int:
        from .effects import Effects
        from .modes import eigen_analysis, plot_modes
        from .vehicle_files import load_vehicle

        try:
            v = load_vehicle(a.vehicle)
        except ValueError as exc:
            raise CLIError(f"--vehicle: {exc}") from None
        _check_outputs(a, "plot", "locus", "json")
        bad = [s for s in a.speeds if not (v.vmin <= s <= v.vmax)]
        if bad:
            raise CLIError(f"--speeds: {bad} m/s outside the valid range [{v.vmin}, {v.vmax}] m/s of {v.name}")
        effects = Effects.parse(a.effect)
        res = eigen_analysis(v, speeds=a.speeds, effects=effects or None)
        js = res.to_json()
        for s, evs, labs in zip(js["speeds"], js["eigenvalues"], js["labels"]):
            parts = []
            for (re, im), lab in zip(evs, labs):
                if im < 0:
                    continue
                parts.append(f"{lab} {re:+.2f}{'' if im == 0 else f'±{im:.2f}j'}")
            print(f"vx = {s:5.1f} m/s: " + ", ".join(parts))
        print(f"{v.name}: weave stability speed {res.stability_speed():.2f} m/s")
        if a.plot:
            plot_modes(res, a.plot)
            print(f"figure written to {a.plot}")
        if a.locus:
            plot_modes(res, a.locus, classic=True)
            print(f"root locus written to {a.locus}")
        _write_json(a.json, js, a.overwrite)
        return 0

    return run


# ---------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    import assist.commands  # noqa: F401  (registers design, evaluate, demo, observability)
    import assist.diagnose_cli  # noqa: F401  (registers diagnose)
    import assist.estimate_cli  # noqa: F401  (registers estimate)
    import assist.risk_cli  # noqa: F401  (registers risk)
    import assist.rl_cli  # noqa: F401  (registers train-rl)

    parser = argparse.ArgumentParser(
        prog="ptw-assist",
        description="Powered two-wheeler lateral dynamics, estimation and rider assistance.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Run 'ptw-assist <command> --help' for a command's options and an example.",
    )
    parser.add_argument("--version", action="version", version="ptw-assist 0.1.0")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    for name, (build, help_, example) in _COMMANDS.items():
        p = sub.add_parser(name, help=help_.replace("%", "%%"), description=help_[0].upper() + help_[1:] + ".",
                           epilog=f"example:\n  {example}", formatter_class=argparse.RawDescriptionHelpFormatter)
        p.set_defaults(_run=build(p))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileExistsError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"ptw-assist {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    # run as ``python -m ptw_env.cli``: use the imported module, whose registry the subcommands fill
    from ptw_env.cli import main as _main

    sys.exit(_main())
