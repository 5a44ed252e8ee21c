"""The command-line toolkit of ``ptw-assist`` and the simulator's own commands (``shared/spec/cli.md``).

This module holds the command registry (:func:`command`), the option types
(:func:`number`, ...), the output checks and the error handling of
:func:`main`, plus the commands of the simulator (``simulate``, ``modes``).
It imports nothing of :mod:`assist`: the full ``ptw-assist`` program is
:func:`assist.cli.main` (the console script), which imports the assist
command modules so that they register here, then runs this :func:`main`.
Called directly, :func:`main` knows the simulator's commands only.

Each subcommand prints a short human summary and, with ``--json FILE``,
writes the machine-readable figures of cli.md. Bad input ends with one line
``ptw-assist <cmd>: error: <what and where>`` and exit status 2; existing
output files are never overwritten unless ``--overwrite`` is given.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from .outputs import atomic_path, atomic_write_text, check_writable

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


def check_outputs(args: argparse.Namespace, *names: str) -> None:
    """Check every output option before the work (:func:`ptw_env.outputs.check_writable`), and that no two
    outputs, and no output and the input log (``args.log`` when it is not an output) or its sidecar, are one file."""
    def label(n: str) -> str:
        return "the log's sidecar" if n == "sidecar" else f"--{n.replace('_', '-')}"

    seen: dict[str, str] = {}
    inputs: dict[str, str] = {}
    log_in = getattr(args, "log", None) if "log" not in names else None
    if isinstance(log_in, (str, os.PathLike)):
        inputs = {os.path.realpath(log_in): "the input log",
                  os.path.realpath(Path(log_in).with_suffix(".json")): "the input log's sidecar"}
    for n in names:
        p = getattr(args, n, None)
        if p is None:
            continue
        key = os.path.realpath(p)
        if key in inputs:
            raise CLIError(f"{label(n)}: {p} is {inputs[key]}; write the output elsewhere")
        if key in seen:
            raise CLIError(f"{label(n)} and {label(seen[key])} both name {p}: each output needs its own file")
        seen[key] = n
    for n in names:
        p = getattr(args, n, None)
        if p is not None:
            check_writable(p, f"--{n.replace('_', '-')}", overwrite=bool(getattr(args, "overwrite", False)))
            if n in ("plot", "locus"):
                _check_figure_format(p, f"--{n}")


def _check_figure_format(path: str | os.PathLike, option: str) -> None:
    from matplotlib.figure import Figure

    kinds = Figure().canvas.get_supported_filetypes()
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in kinds:
        raise CLIError(f"{option}: {path}: a figure needs one of the suffixes {', '.join('.' + k for k in sorted(kinds))}")


def write_json(path: str | None, obj: dict[str, Any], overwrite: bool) -> None:
    """Write a command's JSON (strict: no NaN or inf, cli.md) atomically."""
    if path is None:
        return
    p = Path(path)
    check_writable(p, "--json", overwrite=overwrite)
    try:
        text = json.dumps(obj, indent=2, allow_nan=False) + "\n"
    except ValueError as exc:  # a NaN/inf that a command let through: name it rather than write invalid JSON
        raise CLIError(f"--json: the result holds a value JSON cannot represent ({exc}); nothing written") from None
    atomic_write_text(p, text)


def load_vehicle_option(text: str) -> Any:
    """The vehicle of a ``--vehicle`` text: a preset name or the path of a TOML vehicle file
    (:func:`ptw_env.vehicle_files.load_vehicle`); a bad one is one :class:`CLIError` naming the option, file and key."""
    from .vehicle_files import load_vehicle

    try:
        return load_vehicle(text)
    except (ValueError, OSError) as exc:
        raise CLIError(f"--vehicle: {' '.join(str(exc).split())}") from None


def add_vehicle_option(p: argparse.ArgumentParser, *, from_log: bool = False) -> None:
    """Add ``--vehicle NAME_OR_FILE`` (cli.md: every subcommand); ``from_log``: the default is the log
    sidecar's vehicle (:func:`vehicle_for_log`)."""
    from .vehicle_files import vehicle_names

    default = "the log sidecar's vehicle, else reference-scooter" if from_log else "reference-scooter"
    p.add_argument("--vehicle", default=None, metavar="NAME_OR_FILE",
                   help=f"a vehicle preset ({', '.join(vehicle_names())}) or the path of a TOML vehicle file "
                        f"(ptw_env.vehicle_files); default {default}")


def chosen_vehicle(args: argparse.Namespace) -> Any:
    """The vehicle of ``--vehicle`` (:func:`add_vehicle_option`), the reference scooter when absent."""
    from .vehicle import REFERENCE_SCOOTER

    text = getattr(args, "vehicle", None)
    return REFERENCE_SCOOTER if text is None else load_vehicle_option(text)


def vehicle_for_log(args: argparse.Namespace, log: Any) -> Any:
    """The vehicle a log is read with: ``--vehicle`` if given (refused when the sidecar names another one,
    both named), else the sidecar's ``vehicle``/``vehicle_file`` (:func:`ptw_env.vehicle_files.vehicle_of_log`),
    else the reference scooter. The log is then checked against it (:func:`ptw_env.logs.check_against_vehicle`)."""
    from .logs import check_against_vehicle
    from .vehicle import REFERENCE_SCOOTER
    from .vehicle_files import vehicle_of_log

    try:
        side = vehicle_of_log(log.meta, log.path)
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    given = None if getattr(args, "vehicle", None) is None else chosen_vehicle(args)
    if given is not None and side is not None and \
            given.identity()["model_sha256"] != side.identity()["model_sha256"]:
        raise CLIError(f"--vehicle {given.name!r} is not the vehicle of {log.path} (its sidecar says {side.name!r}); "
                       f"drop --vehicle or fix the sidecar")
    v = given if given is not None else side if side is not None else REFERENCE_SCOOTER
    try:
        check_against_vehicle(log, v)
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    return v


def check_speeds_in_vehicle(speeds: Sequence[float] | None, vehicle: Any, option: str = "--speeds") -> None:
    """Refuse speeds [m/s] outside the vehicle's valid range (one :class:`CLIError` naming them)."""
    bad = [s for s in (speeds or []) if not (vehicle.vmin <= s <= vehicle.vmax)]
    if bad:
        raise CLIError(f"{option}: {bad} m/s outside the valid range [{vehicle.vmin}, {vehicle.vmax}] m/s of "
                       f"{vehicle.name}")


def emit(args: argparse.Namespace, obj: dict[str, Any] | None,
         figures: Mapping[str, Callable[[Path], Any]] | None = None, what: str = "JSON") -> None:
    """The end of every command: each figure option that was given (``{"plot": draw, "locus": draw}``) drawn and
    written atomically (:func:`write_figure`), then ``obj`` as the ``--json`` file (:func:`write_json`), each
    with a line saying where (``what``: how that line names the JSON, e.g. "report")."""
    for option, draw in (figures or {}).items():
        path = getattr(args, option, None)
        if path:
            write_figure(path, draw)
            print(f"figure written to {path}")
    if obj is not None and getattr(args, "json", None):
        write_json(args.json, obj, bool(getattr(args, "overwrite", False)))
        print(f"{what} written to {args.json}")


def write_figure(path: str | os.PathLike, draw: Callable[[Path], Any]) -> None:
    """Draw a figure into a temporary file beside ``path`` and move it there when complete."""
    with atomic_path(path) as tmp:
        draw(tmp)


def number(lo: float = -math.inf, hi: float = math.inf, *, unit: str = "", integer: bool = False,
           lo_open: bool = False, hi_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type`` for a numeric option with a documented valid range.

    The text must be a plain ASCII decimal (``ptw_env.logs.is_plain_number``: no ``nan``,
    ``inf``, ``1_000`` or non-ASCII digits) within ``[lo, hi]`` (open ends with
    ``lo_open``/``hi_open``); ``integer`` asks for a whole number. The checker carries
    its range in ``.range`` (read by the option sweep of ``scripts/fuzz_cli.py``) and
    states it in every refusal.

    >>> f = number(0, 100, unit="%")
    >>> f("5"), f.range
    (5.0, (0, 100, False, False))
    >>> f("nan")
    Traceback (most recent call last):
    argparse.ArgumentTypeError: expected a number in [0, 100] %, got 'nan'
    """
    from .logs import is_plain_number

    def fmt(x: float) -> str:
        return str(int(x)) if integer and math.isfinite(x) else f"{x:g}"

    span = f"{'(' if lo_open else '['}{fmt(lo)}, {fmt(hi)}{')' if hi_open else ']'}" + (f" {unit}" if unit else "")
    what = "a whole number" if integer else "a number"

    def parse(text: str) -> float:
        ok = is_plain_number(text)
        v = float(text) if ok else math.nan
        if ok and integer and not v.is_integer():
            ok = False
        if not ok or not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
            raise argparse.ArgumentTypeError(f"expected {what} in {span}, got {text!r}")
        return int(v) if integer else v

    parse.range = (lo, hi, lo_open, hi_open)  # type: ignore[attr-defined]
    parse.integer = integer  # type: ignore[attr-defined]
    parse.__name__ = f"number{span.replace(' ', '')}"
    return parse


#: Bounds of numeric options that hold for any two-wheeler (ptw_env.logs.PHYSICAL_BOUNDS); a vehicle's own
#: range is checked by the command that knows the vehicle.
SPEED_MS = number(0, 170, unit="m/s", lo_open=True)
SPEED_KMH = number(0, 612, unit="km/h", lo_open=True)


def number_list(check: Callable[[str], float], what: str, example: str) -> Callable[[str], list[float]]:
    """An argparse ``type`` for comma-separated numbers, each checked by ``check`` (a :func:`number`)."""
    def parse(text: str) -> list[float]:
        vals = []
        for s in text.split(","):
            if s.strip():
                try:
                    vals.append(check(s))
                except argparse.ArgumentTypeError:
                    raise argparse.ArgumentTypeError(f"expected comma-separated {what}, e.g. {example}; "
                                                     f"{s.strip()!r} of {text!r} is not one") from None
        if not vals:
            raise argparse.ArgumentTypeError(f"expected comma-separated {what}, e.g. {example}; got {text!r}")
        return vals

    return parse


#: ``--speeds V1,V2,...``: comma-separated forward speeds [m/s], each in (0, 170].
speed_list = number_list(SPEED_MS, "speeds in m/s in (0, 170]", "5,10,20,30")
#: ``--speeds KMH1,KMH2,...``: comma-separated cruise speeds [km/h], each in (0, 612].
kmh_list = number_list(SPEED_KMH, "speeds in km/h in (0, 612]", "30,60,90")


#: ``--workers``: local processes, or the size of a local Dask cluster (:mod:`ptw_env.jobs`).
WORKERS = number(1, 256, integer=True)


def add_executor_options(p: Any, what: str, resume: str) -> None:
    """``--workers``, ``--scheduler`` and ``--resume`` of a command that runs many jobs (cli.md; the
    execution layer :mod:`ptw_env.jobs`). ``what``: what runs at once; ``resume``: the help of ``--resume``."""
    p.add_argument("--workers", type=WORKERS, default=1, metavar="N",
                   help=f"{what} at once in local processes (default 1), or the size of a local Dask cluster "
                        "with --scheduler local")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a Dask scheduler, tcp://HOST:PORT, or 'local' (default: DASK_SCHEDULER_ADDRESS if set; "
                        "needs the [cluster] extra)")
    p.add_argument("--resume", action="store_true", help=resume)


#: ``--seed``: a whole number for numpy's generators, 0 .. 2**63 - 1.
SEED = number(0, 2**63 - 1, integer=True)
#: ``--noise``: sensor noise in percent of each channel's range.
NOISE_PCT = number(0, 100, unit="%")


def effect_arg(text: str) -> str:
    """``--effect CAUSE:PARAM=VALUE``: checked against effects.md when parsed (:meth:`ptw_env.effects.Effects.parse`)."""
    from .effects import Effects

    try:
        Effects.parse([text])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def road_bank_or_auto(text: str) -> float | str:
    """``--road-bank`` of the risk warning: an angle in rad, or ``auto`` (estimated on line)."""
    return "auto" if text.strip().lower() == "auto" else road_bank(text)


_bank_number = number(-0.5, 0.5, unit="rad", lo_open=True, hi_open=True)


def road_bank(text: str) -> float:
    """``--road-bank``: an angle in rad, |bank| < 0.5 (a value in degrees is refused)."""
    try:
        return _bank_number(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a road bank in rad (|bank| < 0.5; degrees? "
                                         "3 deg = 0.052 rad)") from None


road_bank.range = _bank_number.range  # type: ignore[attr-defined]


# ---------------------------------------------------------------------------- simulate
@command(
    "simulate",
    "ride a scenario with the scenario's rider and write a ride log",
    "ptw-assist simulate --scenario urban --noise 5 --seed 3 --effect road_bank:bank_rad=0.05 --log ride.csv --plot ride.png",
)
def _build_simulate(p: argparse.ArgumentParser):
    from .scenarios import scenario_names

    p.add_argument("--scenario", default="double_lane_change", choices=scenario_names(), help="scenario name")
    add_vehicle_option(p)
    p.add_argument("--speed", type=SPEED_KMH, default=None, metavar="KMH", help="cruise speed [km/h] where the scenario has one")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:PARAM=VALUE", type=effect_arg,
                   help="an effect of effects.md in the true plant (repeatable)")
    p.add_argument("--noise", type=NOISE_PCT, default=None, metavar="PCT",
                   help="sensor noise in percent of each channel's range (default: the reference logs' sensors)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the sensor noise, rider noise and initial state")
    p.add_argument("--rider-noise", type=number(0, 1e4, unit="N m"), default=None, metavar="NM",
                   help="rider random torque [N m] (default: the vehicle's, ptw_env.ride.RIDER_NOISE_NM scaled)")
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
        check_outputs(a, "log", "sidecar", "plot", "json")
        effects = Effects.parse(a.effect)
        v = chosen_vehicle(a)
        try:
            res = ride_scenario(a.scenario, speed_kmh=a.speed, effects=effects, noise_pct=a.noise, seed=a.seed,
                                rider_noise_nm=a.rider_noise, vehicle=v)
        except ValueError as exc:  # e.g. a scenario speed outside this vehicle's range
            raise CLIError(f"{v.name}: {exc} (--speed takes km/h within "
                           f"[{3.6 * v.vmin:.1f}, {3.6 * v.vmax:.1f}] for this vehicle)") from None
        save_ride(res, log_path, overwrite=a.overwrite)
        s = res.summary()
        print(f"{s['scenario']}: {s['duration_s']:.2f} s, {s['samples']} samples, "
              f"{'FELL' if s['fell'] else 'upright'}; roll RMSE vs reference {s['roll_rmse_deg']:.2f} deg, "
              f"max roll {s['roll_max_deg']:.1f} deg, torque RMS {s['torque_rms_nm']:.1f} N m; effects: {effects}")
        print(f"log written to {log_path} (+ {sidecar.name})")
        emit(a, {**s, "log": str(log_path), "effects": effects.to_causes(), "seed": a.seed, "vehicle": v.identity()},
             {"plot": lambda f: plot_ride(res, f)})
        return 0

    return run


# ---------------------------------------------------------------------------- modes
@command(
    "modes",
    "eigenvalues of the linearised vehicle per speed, labelled weave / wobble / capsize / tire / other",
    "ptw-assist modes --vehicle sharp1971 --speeds 5,10,20,30,40 --plot modes.png --locus locus.png --json modes.json",
)
def _build_modes(p: argparse.ArgumentParser):
    add_vehicle_option(p)
    p.add_argument("--speeds", type=speed_list, default=None, metavar="V1,V2,...",
                   help="speeds in m/s (default: 5 speeds evenly across the vehicle's valid range)")
    p.add_argument("--effect", action="append", default=[], metavar="CAUSE:PARAM=VALUE", type=effect_arg)
    p.add_argument("--plot", default=None, metavar="OUT.png")
    p.add_argument("--locus", default=None, metavar="OUT.png",
                   help="also write the classic root locus (Sharp 1971 style: real part vs frequency, speeds marked)")
    p.add_argument("--json", default=None, metavar="FILE")
    p.add_argument("--overwrite", action="store_true")

    def run(a: argparse.Namespace) -> int:
        from .effects import Effects
        from .modes import eigen_analysis, plot_modes
        v = chosen_vehicle(a)
        check_outputs(a, "plot", "locus", "json")
        if a.speeds is None:
            a.speeds = [round(v.vmin + (v.vmax - v.vmin) * k / 4, 3) for k in range(5)]
        check_speeds_in_vehicle(a.speeds, v)
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
        emit(a, js, {"plot": lambda f: plot_modes(res, f), "locus": lambda f: plot_modes(res, f, classic=True)})
        return 0

    return run


# ---------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    """The parser of every command registered so far (:func:`command`)."""
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
    """Parse ``argv`` and run the command: exit status 0, 2 for bad input (one line on stderr), 1 when the
    file system fails under the work, 130 when interrupted."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_usage(sys.stderr)
        print("ptw-assist: error: a command is required (ptw-assist --help lists them)", file=sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileExistsError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        print(f"ptw-assist {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:  # the file system failed under the work (disk full, device gone): say so, no traceback
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"ptw-assist {args.command}: error: {_describe_os(exc)}{where}; no output was left half-written",
              file=sys.stderr)
        return 1
    except MemoryError:
        print(f"ptw-assist {args.command}: error: out of memory; reduce the problem's size", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"ptw-assist {args.command}: interrupted", file=sys.stderr)
        return 130


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.strerror and exc.filename:  # FileNotFoundError and friends
        text = f"{exc.filename}: {exc.strerror}"
    return " ".join(text.split())


def _describe_os(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


if __name__ == "__main__":  # pragma: no cover
    # run as ``python -m ptw_env.cli``: use the imported module, whose registry the subcommands fill
    from ptw_env.cli import main as _main

    sys.exit(_main())
