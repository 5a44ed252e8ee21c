"""Mutation sweep of the command line: bad ride logs, sidecars, paths and option values.

Builds valid ride logs (a simulated scooter ride and, when ``shared/data`` is
there, a real robot-bicycle ride), mutates them class by class, and runs
``ptw-assist diagnose | estimate | risk`` on each in this process; then
generates option values across and beyond every numeric option's documented
range (the ``.range`` of :func:`ptw_env.cli.number`), bad choices, bad paths
and impossible combinations for every subcommand. Each case declares what it
must give:

* ``refuse``: a non-zero exit, stderr ending in ONE line ``ptw-assist CMD: error: ...``
  (argparse may print its usage line before it) that names the place (file and
  line and column, or the option), no traceback, and no output created or
  changed (a sentinel file given as the output with ``--overwrite`` must survive);
* ``accept``: exit 0 and a strict JSON output (no NaN or inf), with a note on
  stdout where the input was trimmed or ignored.

Every case runs under a time limit; a refusal case that runs past it was
silently accepted. Prints the counts per class and every defect; exits 1 if
there is one.

Run: ``python scripts/fuzz_cli.py --logs 1000 --options 300 --seed 0 [--json out.json]``
(15 minutes on the 2-core machine for seed 1, 906 s, with another job beside it). ``tests/test_bad_input.py`` runs a small sweep
and the full one behind the ``slow`` marker.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.cli import build_parser, main  # noqa: E402
from ptw_env.logs import KNOWN_COLUMNS, REQUIRED_COLUMNS  # noqa: E402

LOG_COMMANDS = ("diagnose", "estimate", "risk")
#: Cells Python's float() takes or that look numeric, none of which is data (ptw_env.logs).
NOT_DATA = ("nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1_000", "\u0661\u0662", "\uff11", "1e999", "abc",
            "0x1A", "--1", "1e", ".", "+", "1.2.3", "true", "1 2", "\u00a0", "5\u20ac")
#: Values beyond what a two-wheeler's sensor can read, per column.
IMPOSSIBLE = {"vx": ("200", "-200", "1e6"), "delta": ("3.0", "-2.0"), "roll_rate": ("1e4", "-500"),
              "yaw_rate": ("250",), "delta_rate": ("-1e3",), "ay": ("5000", "-1e300"), "tau": ("1e6", "-2e5")}
#: Bad option texts for every numeric option, whatever its range.
BAD_NUMBERS = ("nan", "inf", "-inf", "abc", "", "1_0", "\u0661", "0x10", "1e308", "-1e308", "5,")


@dataclass
class Case:
    """One command line and what it must give."""

    cls: str
    argv: list[str]
    expect: str  # "refuse" | "accept"
    place: list[str] = field(default_factory=list)  # words the error line must hold
    watch: list[Path] = field(default_factory=list)  # outputs that must not be created/changed on a refusal
    stdout_has: list[str] = field(default_factory=list)  # words stdout must hold on acceptance
    json_out: Path | None = None


@dataclass
class Result:
    case: Case
    rc: Any
    stdout: str
    stderr: str
    seconds: float
    exception: str | None = None
    timed_out: bool = False


class _Timeout(Exception):
    pass


def _alarm(signum, frame):  # pragma: no cover - signal handler
    raise _Timeout()


def run_case(case: Case, timeout_s: float) -> Result:
    """Run ``ptw-assist`` in this process with the case's argv under a time limit."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    rc: Any = None
    exc = None
    timed_out = False
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main(case.argv)
    except SystemExit as e:
        rc = e.code
    except _Timeout:
        timed_out = True
    except BaseException as e:  # noqa: BLE001 - anything else is a traceback a user would see
        exc = f"{type(e).__name__}: {e}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return Result(case, rc, out.getvalue(), err.getvalue(), time.perf_counter() - t0, exc, timed_out)


def _snapshot(paths: list[Path]) -> dict[Path, bytes | None]:
    snap = {}
    for p in paths:
        try:
            snap[p] = p.read_bytes() if p.is_file() else None
        except OSError:
            snap[p] = None
    return snap


def _strict_json(path: Path) -> str | None:
    def bad(name: str):
        raise ValueError(f"non-JSON constant {name}")

    try:
        json.loads(path.read_text(), parse_constant=bad)
    except (OSError, ValueError) as e:
        return str(e)
    return None


def check(res: Result, before: dict[Path, bytes | None], workdir: Path) -> list[str]:
    """The defects of one run (empty when it behaved as declared)."""
    c = res.case
    d = []
    if res.exception is not None:
        d.append(f"traceback: {res.exception}")
    if "Traceback" in res.stderr or "Traceback" in res.stdout:
        d.append("traceback text in the output")
    leftovers = [p.name for p in workdir.rglob(".*.tmp")]
    if leftovers:
        d.append(f"temporary files left: {leftovers[:3]}")
    if c.expect == "refuse":
        if res.timed_out:
            d.append("silent acceptance: still running at the time limit")
        elif res.exception is None:
            if res.rc in (0, None):
                d.append("silent acceptance: exit 0")
            lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
            msg = [ln for ln in lines if not ln.startswith("usage:") and not ln.startswith(" ")]
            if len(msg) != 1 or not msg[0].startswith("ptw-assist") or "error" not in msg[0]:
                d.append(f"not one error line: {lines[-3:]}")
            else:
                missing = [w for w in c.place if w not in msg[0]]
                if missing:
                    d.append(f"the message does not name {missing}: {msg[0][:200]}")
        after = _snapshot(c.watch)
        changed = [p.name for p in c.watch if after[p] != before[p]]
        if changed:
            d.append(f"output created or changed on a refusal: {changed}")
    else:
        if res.timed_out:
            d.append("too slow: past the time limit on a valid input")
        elif res.rc != 0:
            d.append(f"refused a valid input (exit {res.rc}): {res.stderr.strip()[-200:]}")
        else:
            if c.json_out is not None:
                bad = _strict_json(c.json_out)
                if bad:
                    d.append(f"JSON output not strict: {bad}")
            missing = [w for w in c.stdout_has if w not in res.stdout]
            if missing:
                d.append(f"no note of {missing} on stdout")
    return d


# --------------------------------------------------------------------------- base logs


@dataclass
class Base:
    name: str
    header: list[str]
    rows: list[list[str]]
    sidecar: dict
    commands: tuple[str, ...]
    extra_files: dict[str, bytes] = field(default_factory=dict)


def make_bases(workdir: Path, seed: int) -> list[Base]:
    """A 12 s simulated scooter lane change (5 % noise) and, if the shared data is there, 10 s of a real
    robot-bicycle ride with its vehicle file."""
    from ptw_env.ride import ride_scenario, save_ride

    res = ride_scenario("double_lane_change", noise_pct=5.0, seed=seed)
    p = workdir / "base_scooter.csv"
    save_ride(res, p, overwrite=True)
    lines = p.read_text().splitlines()
    n = 1200
    bases = [Base("scooter", lines[0].split(","), [ln.split(",") for ln in lines[1 : n + 1]],
                  json.loads(p.with_suffix(".json").read_text()), LOG_COMMANDS)]
    shared = [Path(os.environ.get("PTW_SHARED_DIR", "")), ROOT.parent / "shared", Path("/work/shared")]
    for s in shared:
        rb = s / "data" / "robot_bicycle"
        logs = sorted(rb.glob("rb_*.csv")) if rb.is_dir() else []
        if logs:
            lines = logs[0].read_text().splitlines()
            meta = json.loads(logs[0].with_suffix(".json").read_text())
            extra = {f.name: f.read_bytes() for f in rb.glob("*.toml")}
            bases.append(Base("bicycle", lines[0].split(","), [ln.split(",") for ln in lines[1:1001]], meta,
                              ("diagnose",), extra))
            break
    return bases


def _write(base: Base, d: Path, header: list[str] | None = None, rows: list[list[str]] | None = None,
           text: str | None = None, data: bytes | None = None, sidecar: Any = "same", name: str = "ride") -> Path:
    d.mkdir(parents=True, exist_ok=True)
    p = d / f"{name}.csv"
    if data is not None:
        p.write_bytes(data)
    else:
        if text is None:
            h = base.header if header is None else header
            r = base.rows if rows is None else rows
            text = ",".join(h) + "\n" + "".join(",".join(x) + "\n" for x in r)
        p.write_text(text, encoding="utf-8")
    for fname, content in base.extra_files.items():
        (d / fname).write_bytes(content)
    sc = p.with_suffix(".json")
    if sidecar == "same":
        sc.write_text(json.dumps(base.sidecar))
    elif sidecar == "dir":
        sc.mkdir()
    elif isinstance(sidecar, str):
        sc.write_text(sidecar)
    elif sidecar is not None:
        sc.write_text(json.dumps(sidecar))
    return p


# --------------------------------------------------------------------------- log mutations


def log_cases(rng: np.random.Generator, bases: list[Base], workdir: Path, n: int) -> list[Case]:
    """``n`` mutated-log cases over the classes below, a command each."""
    classes: list[tuple[str, Callable[..., Case | None]]] = [
        ("cell_not_data", _cell_not_data), ("impossible_value", _impossible), ("nonpositive_speed", _nonpositive),
        ("extra_or_reordered_columns", _extra_columns), ("header", _header), ("row_fields", _row_fields),
        ("time", _time), ("encoding", _encoding), ("too_short", _too_short), ("sidecar", _sidecar),
        ("file_system_log", _fs_log), ("file_system_output", _fs_output),
    ]
    cases = []
    for i in range(n):
        cls, make = classes[i % len(classes)]
        base = bases[int(rng.integers(len(bases)))] if cls != "nonpositive_speed" else bases[0]
        cmd = str(rng.choice(base.commands))
        d = workdir / f"log{i:05d}"
        case = make(rng, base, d, cmd)
        case.cls = cls
        cases.append(case)
    return cases


def _outputs(d: Path, cmd: str, log: Path, sentinel: bool) -> tuple[list[str], list[Path], Path]:
    out = d / "out"
    out.mkdir(parents=True, exist_ok=True)
    j = out / "report.json"
    if sentinel:
        j.write_text("sentinel\n")
    return [cmd, str(log), "--json", str(j)] + (["--overwrite"] if sentinel else []), [j, out / "report.png"], j


def _refuse_on_log(d: Path, cmd: str, log: Path, place: list[str]) -> Case:
    argv, watch, _ = _outputs(d, cmd, log, sentinel=True)
    return Case("", argv, "refuse", place, watch)


def _accept_on_log(d: Path, cmd: str, log: Path, stdout_has: list[str] | None = None) -> Case:
    argv, watch, j = _outputs(d, cmd, log, sentinel=False)
    return Case("", argv, "accept", [], watch, stdout_has or [], j)


def _pick_row(rng, base: Base) -> int:
    return int(rng.integers(1, len(base.rows) - 1))


def _cell_not_data(rng, base: Base, d: Path, cmd: str) -> Case:
    rows = [r[:] for r in base.rows]
    i = _pick_row(rng, base)
    col = str(rng.choice([c for c in base.header if c in KNOWN_COLUMNS and c != "t"]))
    rows[i][base.header.index(col)] = str(rng.choice(NOT_DATA))
    log = _write(base, d, rows=rows)
    return _refuse_on_log(d, cmd, log, [log.name, f"line {i + 2}", f"'{col}'"])


def _impossible(rng, base: Base, d: Path, cmd: str) -> Case:
    rows = [r[:] for r in base.rows]
    i = _pick_row(rng, base)
    col = str(rng.choice([c for c in IMPOSSIBLE if c in base.header]))
    rows[i][base.header.index(col)] = str(rng.choice(IMPOSSIBLE[col]))
    log = _write(base, d, rows=rows)
    return _refuse_on_log(d, cmd, log, [log.name, f"line {i + 2}", f"'{col}'"])


def _nonpositive(rng, base: Base, d: Path, cmd: str) -> Case:
    rows = [r[:] for r in base.rows]
    i = _pick_row(rng, base)
    rows[i][base.header.index("vx")] = str(rng.choice(["0", "-1.5", "0.0", "-0"]))
    log = _write(base, d, rows=rows)
    if cmd == "diagnose":  # trims the windows around it and says so
        return _accept_on_log(d, cmd, log, ["speed outside the model's range", f"sample {i}"])
    # estimate, risk: run on the longest ridden stretch (ptw_env.logs.ridden_part) and say so
    return _accept_on_log(d, cmd, log, ["kept the longest ridden stretch", f"sample {i}"])


def _extra_columns(rng, base: Base, d: Path, cmd: str) -> Case:
    kind = str(rng.choice(["text", "numeric", "empty", "shuffle"]))
    header, rows = base.header[:], [r[:] for r in base.rows]
    note: list[str] = []
    if kind == "text":
        header.append("comment")
        for k, r in enumerate(rows):
            r.append(f"lap {k // 100}")
        note = ["ignored"] if cmd == "diagnose" else []
    elif kind == "numeric":
        header.append("gps_quality")
        for r in rows:
            r.append(str(int(rng.integers(0, 9))))
    elif kind == "empty":
        header.append("spare")
        for r in rows:
            r.append("")
    else:
        order = rng.permutation(len(header))
        header = [header[j] for j in order]
        rows = [[r[j] for j in order] for r in rows]
    if cmd == "diagnose" and kind != "text":
        cmd = str(rng.choice(["estimate", "risk"])) if "estimate" in base.commands else cmd
    log = _write(base, d, header=header, rows=rows)
    return _accept_on_log(d, cmd, log, note)


def _header(rng, base: Base, d: Path, cmd: str) -> Case:
    header = base.header[:]
    kind = str(rng.choice(["drop", "duplicate", "empty", "rename"]))
    j = int(rng.choice([k for k, c in enumerate(header) if c in REQUIRED_COLUMNS]))
    rows = [r[:] for r in base.rows]
    col = header[j]
    if kind == "drop":
        del header[j]
        rows = [r[:j] + r[j + 1 :] for r in rows]
    elif kind == "duplicate":
        other = int(rng.choice([k for k in range(len(header)) if k != j]))
        col = header[j]
        header[other] = col
    elif kind == "empty":
        header[j] = ""
        col = str(j + 1)
    else:
        header[j] = header[j].upper() + "_x"
    log = _write(base, d, header=header, rows=rows)
    return _refuse_on_log(d, cmd, log, [log.name, "line 1", col])


def _row_fields(rng, base: Base, d: Path, cmd: str) -> Case:
    rows = [r[:] for r in base.rows]
    i = _pick_row(rng, base)
    if rng.random() < 0.5:
        rows[i] = rows[i][:-1]
    else:
        rows[i] = rows[i] + ["0.1"]
    log = _write(base, d, rows=rows)
    return _refuse_on_log(d, cmd, log, [log.name, f"line {i + 2}"])


def _time(rng, base: Base, d: Path, cmd: str) -> Case:
    rows = [r[:] for r in base.rows]
    i = _pick_row(rng, base)
    kind = str(rng.choice(["swap", "repeat", "drop_row", "empty_t", "drop_rows"]))
    line = i + 2
    if kind == "swap":
        rows[i], rows[i + 1] = rows[i + 1], rows[i]
        line = i + 3
    elif kind == "repeat":
        rows.insert(i, rows[i][:])
        line = i + 3
    elif kind == "drop_row":
        del rows[i]
        line = None
    elif kind == "drop_rows":
        del rows[i : i + 5]
        line = None
    else:
        rows[i][base.header.index("t")] = ""
    log = _write(base, d, rows=rows)
    return _refuse_on_log(d, cmd, log, [log.name, "'t'"] + ([f"line {line}"] if line else []))


def _encoding(rng, base: Base, d: Path, cmd: str) -> Case:
    text = ",".join(base.header) + "\n" + "".join(",".join(x) + "\n" for x in base.rows)
    kind = str(rng.choice(["utf16", "latin1", "nul", "bom", "crlf", "binary"]))
    if kind == "utf16":
        log = _write(base, d, data=text.encode("utf-16"))
        return _refuse_on_log(d, cmd, log, [log.name, "UTF-8"])
    if kind == "latin1":
        lines = text.splitlines()
        i = _pick_row(rng, base)
        lines[i + 1] = lines[i + 1] + "\u00e9"
        log = _write(base, d, data=("\n".join(lines) + "\n").encode("latin-1"))
        return _refuse_on_log(d, cmd, log, [log.name, f"line {i + 2}"])
    if kind == "nul":
        lines = text.splitlines()
        i = _pick_row(rng, base)
        lines[i + 1] = lines[i + 1].replace(",", ",\x00", 1)
        log = _write(base, d, text="\n".join(lines) + "\n")
        return _refuse_on_log(d, cmd, log, [log.name, f"line {i + 2}"])
    if kind == "binary":
        log = _write(base, d, data=bytes(rng.integers(0, 256, 4000, dtype=np.uint8)))
        return _refuse_on_log(d, cmd, log, [log.name])
    if kind == "bom":
        log = _write(base, d, data=b"\xef\xbb\xbf" + text.encode())
    else:
        log = _write(base, d, data=text.replace("\n", "\r\n").encode())
    if cmd == "diagnose" and "estimate" in base.commands:
        cmd = str(rng.choice(["estimate", "risk"]))
    return _accept_on_log(d, cmd, log)


def _too_short(rng, base: Base, d: Path, cmd: str) -> Case:
    kind = str(rng.choice(["empty", "header_only", "five_rows", "blank_lines"]))
    if kind == "empty":
        log = _write(base, d, text="")
    elif kind == "header_only":
        log = _write(base, d, rows=[])
    elif kind == "five_rows":
        log = _write(base, d, rows=base.rows[:5])
    else:
        log = _write(base, d, text="\n\n\n")
    return _refuse_on_log(d, cmd, log, [log.name])


def _sidecar(rng, base: Base, d: Path, cmd: str) -> Case:
    meta = dict(base.sidecar)
    kinds = {
        "dir": ("dir", None), "unknown_vehicle": ({**meta, "vehicle": "no-such-bike"}, "vehicle"),
        "vehicle_number": ({**meta, "vehicle": 5}, "vehicle"), "noise_text": ({**meta, "noise_pct": "abc"}, "noise_pct"),
        "noise_negative": ({**meta, "noise_pct": -1}, "noise_pct"), "noise_big": ({**meta, "noise_pct": 1e3}, "noise_pct"),
        "noise_nan": (json.dumps({**meta, "noise_pct": 0.0}).replace('"noise_pct": 0.0', '"noise_pct": NaN'), "NaN"),
        "rate_text": ({**meta, "sample_rate_hz": "100"}, "sample_rate_hz"),
        "rate_list": ({**meta, "sample_rate_hz": [100]}, "sample_rate_hz"),
        "rate_bool": ({**meta, "sample_rate_hz": True}, "sample_rate_hz"),
        "rate_wrong": ({**meta, "sample_rate_hz": 37.0}, "sample_rate_hz"),
        "list": ("[1, 2, 3]", "object"), "truncated": (json.dumps(meta)[: len(json.dumps(meta)) // 2], "JSON"),
        "truth_type": ({**meta, "truth": "wet"}, "truth"), "not_utf8": (None, "UTF-8"),
    }
    kind = str(rng.choice(list(kinds)))
    sc, word = kinds[kind]
    if kind == "not_utf8":
        log = _write(base, d, sidecar=None)
        log.with_suffix(".json").write_bytes(json.dumps(meta).encode("utf-16"))
    else:
        log = _write(base, d, sidecar=sc)
    return _refuse_on_log(d, cmd, log, [log.with_suffix(".json").name] + ([word] if word else []))


def _fs_log(rng, base: Base, d: Path, cmd: str) -> Case:
    d.mkdir(parents=True, exist_ok=True)
    kind = str(rng.choice(["directory", "missing", "too_long", "sidecar_given"]))
    if kind == "directory":
        p = d / "ride.csv"
        p.mkdir()
    elif kind == "missing":
        p = d / "no_such_ride.csv"
    elif kind == "too_long":
        p = d / ("r" * 300 + ".csv")
    else:
        p = _write(base, d).with_suffix(".json")
    return _refuse_on_log(d, cmd, p, [p.name[:40]])


def _fs_output(rng, base: Base, d: Path, cmd: str) -> Case:
    log = _write(base, d)
    out = d / "out"
    out.mkdir(parents=True, exist_ok=True)
    kind = str(rng.choice(["no_dir", "is_dir", "dev_full", "too_long", "exists", "plot_suffix", "parent_is_file"]))
    watch: list[Path] = []
    extra: list[str] = []
    if kind == "no_dir":
        opt, target = "--json", out / "missing" / "r.json"
    elif kind == "is_dir":
        opt, target = "--json", out / "adir"
        target.mkdir()
    elif kind == "dev_full":
        opt, target = "--json", Path("/dev/full")
        extra = ["--overwrite"]
    elif kind == "too_long":
        opt, target = str(rng.choice(["--json", "--plot"])), out / ("x" * 300 + ".png")
    elif kind == "exists":
        opt, target = str(rng.choice(["--json", "--plot"])), out / "r.png"
        target.write_text("sentinel\n")
        watch = [target]
    elif kind == "plot_suffix":
        opt, target = "--plot", out / "r.xyz"
        extra = ["--overwrite"]
    else:
        (out / "f").write_text("x")
        opt, target = "--json", out / "f" / "r.json"
    place = [opt]
    return Case("", [cmd, str(log), opt, str(target)] + extra, "refuse", place, watch)


# --------------------------------------------------------------------------- option sweep


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    p = build_parser()
    sub = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)][0]
    return dict(sub.choices)


def _needs(cmd: str, log: Path, d: Path) -> list[str]:
    """The required arguments of ``cmd`` with valid values (outputs in ``d``)."""
    if cmd in LOG_COMMANDS:
        return [cmd, str(log)]
    if cmd == "simulate":
        return [cmd, "--log", str(d / "sim.csv")]
    if cmd == "train-rl":
        return [cmd, "--out", str(d / "policy.zip"), "--steps", "64"]
    if cmd == "twin":
        return [cmd, str(log), "--out", str(d / "twin.json")]
    return [cmd]


def _out_of_range(rng, rg: tuple, integer: bool) -> list[str]:
    lo, hi, lo_open, hi_open = rg
    vals = []
    if math.isfinite(lo):
        vals += [repr(lo) if lo_open else repr(lo - max(1.0, abs(lo)) if integer else lo - 1e-3 * max(1.0, abs(lo)))]
    if math.isfinite(hi):
        vals += [repr(hi) if hi_open else repr(hi + max(1.0, abs(hi)))]
    if integer:
        vals += ["1.5"]
    return vals


def option_cases(rng: np.random.Generator, log: Path, workdir: Path, n: int) -> list[Case]:
    """``n`` command lines, each with at least one bad option value (or combination)."""
    subs = _subparsers()
    workdir.mkdir(parents=True, exist_ok=True)
    pool: list[tuple[str, list[str], list[str]]] = []  # (cmd, bad args, words)
    for cmd, sp in subs.items():
        for a in sp._actions:
            if not a.option_strings or isinstance(a, (argparse._HelpAction, argparse._StoreTrueAction)):
                continue
            opt = a.option_strings[-1]
            rg = getattr(a.type, "range", None)
            if rg is not None:
                for v in _out_of_range(rng, rg, getattr(a.type, "integer", False)) + list(BAD_NUMBERS):
                    pool.append((cmd, [f"{opt}={v}"], [opt]))
            elif a.choices:
                pool.append((cmd, [opt, "bogus-choice"], [opt]))
            if opt in ("--json", "--plot", "--locus", "--log", "--out"):
                pool.append((cmd, [opt, str(workdir / "no_dir" / "x.png")], [opt]))
                pool.append((cmd, [opt, "/dev/full", "--overwrite"], [opt]))
            if opt == "--speeds":
                for v in ("5,nan", "5,,x", "-5", "0", "1e9", "5;10"):
                    pool.append((cmd, [f"{opt}={v}"], [opt]))
            if opt == "--effect":
                for v in ("road_bank:bank_rad=nan", "nosuch:x=1", "road_bank", "road_bank:bank_rad=1e308",
                          "tire_stiffness:front_scale=-1", "road_bank:nosuch=0.1"):
                    pool.append((cmd, [f"{opt}={v}"], [opt]))
            if opt == "--vehicle":
                for v in ("no-such-vehicle", str(workdir), str(workdir / "bad.toml")):
                    pool.append((cmd, [opt, v], [opt]))
        if any(a.option_strings and a.option_strings[-1] == "--vmin" for a in sp._actions):
            pool.append((cmd, ["--vmin", "20", "--vmax", "10"], ["--vmin"]))
            pool.append((cmd, ["--vmin", "15", "--vmax", "15"], ["--vmin"]))
        pool.append((cmd, ["--no-such-option", "1"], ["--no-such-option"]))
    (workdir / "bad.toml").write_text("[vehicle\nname = 3\n")
    cases = []
    order = rng.permutation(len(pool))
    for k in range(n):
        cmd, bad, words = pool[int(order[k % len(pool)])]
        d = workdir / f"opt{k:05d}"
        d.mkdir(parents=True, exist_ok=True)
        sentinel = d / "sentinel.json"
        sentinel.write_text("sentinel\n")
        argv = _needs(cmd, log, d) + bad
        if "--json" not in " ".join(bad) and any(a.option_strings and a.option_strings[-1] == "--json"
                                                 for a in subs[cmd]._actions):
            argv += ["--json", str(sentinel)] + ([] if "--overwrite" in bad else ["--overwrite"])
        cases.append(Case("options", argv, "refuse", words, [sentinel, d / "sim.csv", d / "policy.zip"]))
    cases.append(Case("options", [], "refuse", ["command"], []))  # no subcommand: usage, exit 2
    return cases


# --------------------------------------------------------------------------- the sweep


def sweep(n_logs: int, n_options: int, seed: int, timeout_s: float = 60.0, progress: bool = True,
          workdir: Path | None = None) -> dict[str, Any]:
    """Run the sweep; return counts per class and the defects."""
    rng = np.random.default_rng(seed)
    tmp = Path(tempfile.mkdtemp(prefix="ptw-fuzz-")) if workdir is None else workdir
    try:
        bases = make_bases(tmp, seed)
        cases = log_cases(rng, bases, tmp / "logs", n_logs)
        valid = _write(bases[0], tmp / "valid")
        cases += option_cases(rng, valid, tmp / "opts", n_options)
        counts: dict[str, Counter] = defaultdict(Counter)
        defects: list[dict[str, Any]] = []
        t0 = time.perf_counter()
        it = cases
        if progress:
            from tqdm import tqdm

            it = tqdm(cases, desc="fuzz", unit="case", file=sys.stderr)
        for case in it:
            before = _snapshot(case.watch)
            res = run_case(case, timeout_s)
            bad = check(res, before, tmp)
            counts[case.cls]["cases"] += 1
            counts[case.cls][case.expect] += 1
            if bad:
                counts[case.cls]["defects"] += 1
                defects.append({"class": case.cls, "argv": case.argv, "expect": case.expect, "defects": bad,
                                "stderr": res.stderr.strip()[-300:]})
        return {"seed": seed, "cases": len(cases), "seconds": round(time.perf_counter() - t0, 1),
                "counts": {k: dict(v) for k, v in sorted(counts.items())}, "defects": defects}
    finally:
        if workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)


def main_cli(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", type=int, default=1000, help="mutated-log cases (default 1000)")
    ap.add_argument("--options", type=int, default=300, help="option cases (default 300)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per case (default 60)")
    ap.add_argument("--json", default=None, help="write the counts and defects here")
    ap.add_argument("--overwrite", action="store_true")
    a = ap.parse_args(argv)
    if a.json and Path(a.json).exists() and not a.overwrite:
        ap.error(f"{a.json} exists; pass --overwrite")
    rep = sweep(a.logs, a.options, a.seed, a.timeout)
    print(f"{rep['cases']} cases in {rep['seconds']} s (seed {a.seed})")
    print(f"{'class':<28} {'cases':>6} {'refuse':>7} {'accept':>7} {'defects':>8}")
    for k, c in rep["counts"].items():
        print(f"{k:<28} {c.get('cases', 0):6d} {c.get('refuse', 0):7d} {c.get('accept', 0):7d} {c.get('defects', 0):8d}")
    for d in rep["defects"][:40]:
        print(f"DEFECT [{d['class']}] {' '.join(d['argv'])[:160]}\n    {d['defects']}\n    stderr: {d['stderr'][-160:]}")
    if a.json:
        from ptw_env.outputs import atomic_write_text

        atomic_write_text(Path(a.json), json.dumps(rep, indent=1) + "\n")
    return 1 if rep["defects"] else 0


if __name__ == "__main__":
    sys.exit(main_cli())
