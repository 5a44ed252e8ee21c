"""Bad input end to end (issue 16): property tests of the ride-log reader, the sidecar and the
command-line options (hypothesis), and the mutation sweep of ``scripts/fuzz_cli.py``.

What must hold whatever the input: the reader either returns a log or raises
:class:`ptw_env.logs.LogFormatError` naming the file, the line and the column; an option value
is either inside its documented range or refused with one line naming the option; a command
refuses with exit 2 and ONE error line, no traceback, no output created or changed.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import math
import string
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from assist.cli import build_parser, main
from ptw_env.logs import PHYSICAL_BOUNDS, REQUIRED_COLUMNS, LogFormatError, is_plain_number, read_log

from conftest import ROOT

_spec = importlib.util.spec_from_file_location("fuzz_cli", ROOT / "scripts" / "fuzz_cli.py")
fuzz = importlib.util.module_from_spec(_spec)
sys.modules["fuzz_cli"] = fuzz
_spec.loader.exec_module(fuzz)

HEADER = list(REQUIRED_COLUMNS)
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _rows(n: int = 120) -> list[list[str]]:
    t = np.arange(n) * 0.01
    return [[f"{x:.2f}", f"{np.sin(x):.4f}", "12.5", "0.01", "0.02", "0.03", "-0.01", f"{0.3 * x:.3f}"] for x in t]


def _write(tmp_path, rows, header=HEADER, sidecar=None, name="ride") -> Path:
    d = tmp_path / f"case{np.random.default_rng().integers(1 << 40)}"
    d.mkdir()
    p = d / f"{name}.csv"
    p.write_text(",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in rows), encoding="utf-8")
    if sidecar is not None:
        p.with_suffix(".json").write_text(sidecar, encoding="utf-8")
    return p


def _cell_is_data(column: str, text: str) -> bool:
    s = text.strip(" \t")  # logs.md: blanks are ASCII space and tab; any other character is text
    if not s:
        return column != "t"  # an empty cell is a dropout, except for time
    if not is_plain_number(s):
        return False
    v = float(s)
    lo, hi = PHYSICAL_BOUNDS[column]
    return math.isfinite(v) and lo <= v <= hi


cells = st.one_of(
    st.text(max_size=12),
    st.text(alphabet=string.digits + "+-.eE_ ", max_size=10),
    st.sampled_from(["nan", "NaN", "inf", "-Infinity", "1_000", "\u0661", "\uff11", "1e999", "-1e300", "200", "0", ""]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
)


@SETTINGS
@given(col=st.sampled_from(HEADER[1:]), row=st.integers(1, 100), cell=cells)
def test_one_cell_of_any_text_is_data_or_named(tmp_path, col, row, cell):
    assume("," not in cell and "\n" not in cell and "\r" not in cell and '"' not in cell)
    rows = _rows()
    rows[row][HEADER.index(col)] = cell
    p = _write(tmp_path, rows)
    if _cell_is_data(col, cell):
        log = read_log(p)
        assert len(log) == len(rows)
    else:
        with pytest.raises(LogFormatError) as e:
            read_log(p)
        assert (e.value.line, e.value.column) == (row + 2, col), str(e.value)
        assert str(e.value).startswith(str(p))


@SETTINGS
@given(kind=st.sampled_from(["swap", "repeat", "drop", "drop_field", "add_field"]), row=st.integers(1, 100))
def test_row_mutations_are_named(tmp_path, kind, row):
    rows = _rows()
    if kind == "swap":
        rows[row], rows[row + 1] = rows[row + 1], rows[row]
    elif kind == "repeat":
        rows.insert(row, list(rows[row]))
    elif kind == "drop":
        del rows[row]
    elif kind == "drop_field":
        rows[row] = rows[row][:-1]
    else:
        rows[row] = rows[row] + ["1"]
    with pytest.raises(LogFormatError) as e:
        read_log(_write(tmp_path, rows))
    assert e.value.line is not None and e.value.line >= row + 1


json_values = st.recursive(st.none() | st.booleans() | st.floats(allow_nan=False, allow_infinity=False) | st.integers() | st.text(max_size=8),
                           lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=5), c, max_size=3),
                           max_leaves=6)


@SETTINGS
@given(key=st.sampled_from(["vehicle", "vehicle_file", "sample_rate_hz", "noise_pct", "truth", "notes"]),
       value=json_values)
def test_sidecar_values_of_any_type_are_accepted_or_named(tmp_path, key, value):
    meta = {"sample_rate_hz": 100.0, key: value}
    p = _write(tmp_path, _rows(), sidecar=json.dumps(meta))
    try:
        log = read_log(p)
    except LogFormatError as e:
        assert str(e).startswith(str(p.with_suffix(".json"))) and key in str(e)
        return
    v = log.meta[key]
    if key == "sample_rate_hz":
        assert v is None or (isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v - 100) <= 1)
    if key == "noise_pct":
        assert v is None or (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 100)
    if key in ("vehicle", "vehicle_file"):
        assert v is None or (isinstance(v, str) and v.strip())


def _numeric_options() -> list[tuple[str, str, tuple]]:
    p = build_parser()
    sub = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)][0]
    out = []
    for cmd, sp in sub.choices.items():
        for a in sp._actions:
            rg = getattr(a.type, "range", None)
            if a.option_strings and rg is not None:
                out.append((cmd, a.option_strings[-1], rg, getattr(a.type, "integer", False)))
    return out


NUMERIC_OPTIONS = _numeric_options()


def test_every_numeric_option_has_a_documented_range():
    p = build_parser()
    sub = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)][0]
    untyped = [(cmd, a.option_strings[-1]) for cmd, sp in sub.choices.items() for a in sp._actions
               if a.option_strings and a.type in (float, int)]
    assert not untyped, f"numeric options parsed by bare float/int (no range, take nan/1_000): {untyped}"
    assert len(NUMERIC_OPTIONS) >= 20


@settings(max_examples=300, deadline=None)
@given(opt=st.sampled_from(NUMERIC_OPTIONS),
       text=st.one_of(st.text(max_size=10), st.floats().map(repr), st.integers(-10**20, 10**20).map(str),
                      st.sampled_from(["nan", "inf", "1_0", "\u0661", "1e308", "-0", "0", "1", "0.5", "4096", "4097"])))
def test_option_values_are_in_range_or_refused_naming_the_option(opt, text):
    cmd, name, (lo, hi, lo_open, hi_open), integer = opt
    assume(not text.startswith("-") or is_plain_number(text))  # '-x' would parse as another option
    ok = is_plain_number(text) and math.isfinite(float(text))
    if ok:
        v = float(text)
        ok = (lo < v if lo_open else lo <= v) and (v < hi if hi_open else v <= hi) and (not integer or v.is_integer())
    sp = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)][0].choices[cmd]
    buf = io.StringIO()
    try:
        with contextlib.redirect_stderr(buf):
            ns = sp.parse_args(fuzz._needs(cmd, Path("ride.csv"), Path("."))[1:] + [f"{name}={text}"])
    except SystemExit as e:
        err = buf.getvalue().strip().splitlines()
        assert not ok, f"{name}={text!r} refused: {err[-1:]}"
        assert e.code == 2 and name in err[-1] and "error" in err[-1]
        return
    assert ok, f"{cmd} {name}={text!r} accepted as {getattr(ns, name.lstrip('-').replace('-', '_'))!r}"


def test_no_subcommand_prints_usage_on_stderr_exit_2(capsys):
    assert main([]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.startswith("usage: ptw-assist") and "error: a command is required" in cap.err


def test_an_unwritable_output_is_refused_before_the_work(tmp_path, capsys):
    """/dev/full as --json with --overwrite: refused as not a regular file (an atomic rename would replace the
    device node); the work never starts."""
    rc = main(["modes", "--speeds", "5,10", "--json", "/dev/full", "--overwrite"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--json: /dev/full is not a regular file" in err[0]


def test_the_mutation_sweep_finds_no_defect_small(tmp_path):
    """60 mutated logs (every class five times) and 40 option lines; the full sweep is the slow test below."""
    rep = fuzz.sweep(60, 40, seed=3, timeout_s=60, progress=False, workdir=tmp_path)
    assert rep["defects"] == [], json.dumps(rep["defects"][:5], indent=1)
    assert sum(c["cases"] for c in rep["counts"].values()) == 60 + 41
    assert all(c.get("defects", 0) == 0 for c in rep["counts"].values())


@pytest.mark.slow
def test_the_mutation_sweep_finds_no_defect_full(tmp_path):
    rep = fuzz.sweep(1000, 300, seed=0, timeout_s=60, progress=False, workdir=tmp_path)
    assert rep["defects"] == [], json.dumps(rep["defects"][:5], indent=1)


@pytest.mark.parametrize("content", [None, "t,delta\n0.0,x\n"])
def test_eval_risk_refuses_a_folder_of_measured_rides_it_cannot_read_before_the_rides(tmp_path, content):
    """``scripts/eval_risk.py --real``: a folder without a log, or with a log that is not one, is refused in one line
    naming the option (and the file), exit 2, before any ride and without creating the output folder."""
    import subprocess

    real = tmp_path / "real"
    real.mkdir()
    if content is not None:
        (real / "bad.csv").write_text(content, encoding="utf-8")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "eval_risk.py"), "--seeds", "1", "--real", str(real),
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert "--real" in last and (content is None or "bad.csv" in last), last
    assert not out.exists()


@pytest.mark.parametrize("content", ["{}", "not json", None])
def test_eval_risk_misses_refuses_a_file_that_is_not_a_stored_run_before_the_rides(tmp_path, content):
    """``scripts/eval_risk_misses.py``: a results file that is not one of ``scripts/eval_risk.py``'s with the
    observation oracle (or no file) is refused in one line naming it, exit 2, without creating the output folder."""
    import subprocess

    path = tmp_path / "results.json"
    if content is not None:
        path.write_text(content, encoding="utf-8")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "eval_risk_misses.py"), str(path), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert str(path) in r.stderr.strip().splitlines()[-1]
    assert not out.exists()
