"""Ride logs: read and write the measured-data format of ``shared/spec/logs.md``.

A ride log is a UTF-8 CSV file, one header line then one row per sample at a
fixed rate (nominally 100 Hz), with an optional JSON sidecar ``<name>.json``
beside ``<name>.csv``. Columns (SI units, radians; any order; extra columns
are kept):

==========  =========================================  =======  ========
column      meaning                                    unit     required
==========  =========================================  =======  ========
t           time since start, strictly increasing      s        yes
tau         rider steering torque (the known input)    N m      yes
vx          forward speed, measured                    m/s      yes
delta       steering angle, encoder                    rad      yes
delta_rate  steering rate, encoder                     rad/s    yes
yaw_rate    yaw rate, IMU gyro                         rad/s    yes
roll_rate   roll rate, IMU gyro                        rad/s    yes
ay          lateral acceleration, model (road) frame   m/s^2    yes
roll        roll angle, IMU attitude filter            rad      no
==========  =========================================  =======  ========

What the reader accepts and rejects
-----------------------------------
Accepted: column order is free; extra columns (numeric ones are kept, one that
holds text anywhere is ignored as a whole and named in
:attr:`RideLog.ignored_columns`, as logs.md says extra columns are ignored);
surrounding spaces in cells and header names; a UTF-8 byte-order mark; ``\\n``
or ``\\r\\n`` line ends; blank lines at the end of the file; a missing sidecar.
An **empty cell is a dropout** and reads as NaN (logs.md: only an empty cell).

Rejected with :class:`LogFormatError` (one message naming the file, the line,
1-based with the header on line 1, and the column): an empty file; a header
with an empty, duplicated or missing required column name; a row with the
wrong number of fields; a cell of a known column that is not a plain ASCII
decimal number (``1_000`` and non-ASCII digits, which Python's ``float``
would take, are refused); ``nan`` or ``inf`` in a known column (a sensor
never reads them; a dropout is an empty cell); a value outside the
:data:`PHYSICAL_BOUNDS` of its channel (no two-wheeler's sensor can read it:
``vx = 200`` m/s, ``-1e300``; a speed that must be positive is the commands' check); an empty time ``t`` (time
cannot be missing); time that does not strictly increase (both lines named);
non-uniform sampling, a step differing from the median step by more than
:data:`SAMPLING_TOLERANCE` (1 %) of it (e.g. dropped rows; a dropout must be a
row of empty cells, not a missing row); a log shorter than
:data:`MIN_SAMPLES` samples or ``min_duration_s``; a sidecar that is not a
JSON object (named with its line and character column), or whose
``sample_rate_hz`` disagrees with the CSV's time column by more than 1 %.
Bounds that depend on the vehicle (its speed range, its steering lock) are
checked by the commands against the vehicle that runs
(:func:`check_against_vehicle`).

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> t = np.arange(200) * 0.01
>>> cols = {c: np.zeros_like(t) for c in REQUIRED_COLUMNS}
>>> cols["t"] = t
>>> p = pathlib.Path(tempfile.mkdtemp()) / "ride.csv"
>>> _ = write_log(p, cols, meta={"vehicle": "reference-scooter", "sample_rate_hz": 100})
>>> log = read_log(p)
>>> len(log), round(log.sample_rate_hz, 6), round(log.duration_s, 6), log.meta["vehicle"]
(200, 100.0, 2.0, 'reference-scooter')

Length (about 1000 lines): the ride-log format of logs.md end to end, one reader of one format:
reading with located errors, sidecar checks, writing, and the held-speed reconstruction every
consumer uses.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .outputs import atomic_write_text

#: Columns every ride log has (logs.md).
REQUIRED_COLUMNS: tuple[str, ...] = ("t", "tau", "vx", "delta", "delta_rate", "yaw_rate", "roll_rate", "ay")
#: Columns a ride log may have that the project knows (logs.md).
OPTIONAL_COLUMNS: tuple[str, ...] = ("roll",)
#: Column order in written files: logs.md order, then extras in their given order.
KNOWN_COLUMNS: tuple[str, ...] = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
#: Units of the known columns (logs.md).
COLUMN_UNITS: Mapping[str, str] = {
    "t": "s", "tau": "N m", "vx": "m/s", "delta": "rad", "delta_rate": "rad/s",
    "yaw_rate": "rad/s", "roll_rate": "rad/s", "ay": "m/s^2", "roll": "rad",
}  # fmt: skip

#: Readings no two-wheeler's sensor can produce, per known column: ``(low, high)``
#: in the column's unit. They catch broken exports (``-1e300``, a speed in km/h
#: written as m/s far beyond any PTW), not vehicle limits: |vx| <= 170 m/s (the
#: motorcycle land-speed record is 605 km/h = 168 m/s), steer and roll angles
#: within +/-pi/2 (the model's geometry ends at a right angle), angular rates
#: within +/-100 rad/s (MEMS gyros saturate at 35-70 rad/s), ay within
#: +/-1000 m/s^2 (100 g; PTW accelerometers range 2-16 g), torque within
#: +/-10 kN m.
PHYSICAL_BOUNDS: Mapping[str, tuple[float, float]] = {
    "t": (-1e9, 1e9), "tau": (-1e4, 1e4), "vx": (-170.0, 170.0), "delta": (-math.pi / 2, math.pi / 2),
    "delta_rate": (-100.0, 100.0), "yaw_rate": (-100.0, 100.0), "roll_rate": (-100.0, 100.0),
    "ay": (-1000.0, 1000.0), "roll": (-math.pi / 2, math.pi / 2),
}  # fmt: skip

#: Fewest samples a log may have (two give a rate; ten make it a signal).
MIN_SAMPLES = 10
#: Shortest log [s] that :func:`read_log` accepts by default, and the shortest ridden stretch :func:`ridden_part` keeps.
MIN_DURATION_S = 1.0
#: Largest allowed deviation of one time step from the median step, relative [-].
SAMPLING_TOLERANCE = 0.01


class LogFormatError(ValueError):
    """A ride-log file (or its sidecar) that breaks logs.md.

    Attributes
    ----------
    path : pathlib.Path
        The offending file (the CSV, or the ``.json`` sidecar).
    line : int or None
        1-based line number (the CSV header is line 1); ``None`` when the
        problem is not on one line.
    column : str, int or None
        The CSV column name; for a sidecar, the 1-based character column of
        the JSON error; ``None`` when not tied to one column.
    reason : str
        What is wrong, without the location.
    """

    def __init__(self, path: str | os.PathLike, line: int | None, column: str | int | None, reason: str) -> None:
        self.path = Path(path)
        self.line = line
        self.column = column
        self.reason = reason
        where = [str(path)]
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column!r}" if isinstance(column, str) else f"column {column}")
        super().__init__(f"{', '.join(where)}: {reason}")

    def __reduce__(self):
        return (type(self), (self.path, self.line, self.column, self.reason))


class LogDataError(ValueError):
    """In-memory log data that cannot make a valid ride log (writer and :class:`RideLog` checks).

    Attributes
    ----------
    column : str or None
        The offending column.
    index : int or None
        0-based sample index of the offending value, when there is one.
    """

    def __init__(self, message: str, column: str | None = None, index: int | None = None) -> None:
        self.column = column
        self.index = index
        super().__init__(message)


# --------------------------------------------------------------------------- checks on numbers


def _first_true(mask: np.ndarray) -> int | None:
    idx = np.flatnonzero(mask)
    return int(idx[0]) if idx.size else None


def _time_problem(t: np.ndarray, where: Callable[[int], str] = lambda i: "") -> tuple[str, int] | None:
    """``(reason, index)`` for the first problem of a time column, else None.

    Checks: finite, strictly increasing, uniform within SAMPLING_TOLERANCE.
    ``where(i)`` locates the other sample involved (e.g. " on line 41").
    """
    i = _first_true(~np.isfinite(t))
    if i is not None:
        return ("t cannot be missing or infinite; every row needs its time", i)
    if t.size < 2:
        return None
    d = np.diff(t)
    i = _first_true(d <= 0.0)
    if i is not None:
        return (f"t = {float(t[i + 1])!r} s does not increase from t = {float(t[i])!r} s{where(i)}", i + 1)
    h = float(np.median(d))
    i = _first_true(np.abs(d - h) > SAMPLING_TOLERANCE * h)
    if i is not None:
        return (
            f"non-uniform sampling: the step from t = {float(t[i])!r} s{where(i)} to t = {float(t[i + 1])!r} s "
            f"is {d[i]:.6g} s, "
            f"the log's median step is {h:.6g} s (tolerance {SAMPLING_TOLERANCE:.0%}); "
            "rows missing? a dropout must be a row of empty cells",
            i + 1,
        )
    return None


def _length_problem(t: np.ndarray, min_duration_s: float) -> str | None:
    n = t.size
    dur = n * float(np.median(np.diff(t))) if n > 1 else 0.0
    if n < MIN_SAMPLES or dur < min_duration_s:
        return (
            f"the log is too short to analyse: {n} samples, {dur:.6g} s; "
            f"at least {MIN_SAMPLES} samples and {min_duration_s:g} s are needed"
        )
    return None


def _rate_problem(meta: Mapping[str, Any], t: np.ndarray) -> str | None:
    if "sample_rate_hz" not in meta or t.size < 2:
        return None
    r = meta["sample_rate_hz"]
    if isinstance(r, bool) or not isinstance(r, (int, float)) or not (math.isfinite(r) and r > 0):
        return f"sample_rate_hz must be a positive number, got {r!r}"
    rate = 1.0 / float(np.median(np.diff(t)))
    if abs(rate - r) > SAMPLING_TOLERANCE * r:
        return f"sample_rate_hz = {r!r} disagrees with the log's time column ({rate:.6g} Hz)"
    return None


def _check_name(name: Any) -> str:
    if not isinstance(name, str) or not name or name != name.strip() or any(ch in name for ch in ',"\r\n'):
        raise LogDataError(
            f"column name {name!r} cannot be written: it must be a non-empty string without commas, "
            "quotes, line breaks or surrounding spaces",
            column=name if isinstance(name, str) else None,
        )
    return name


# --------------------------------------------------------------------------- the log object


@dataclass
class RideLog:
    """A ride log in memory (logs.md).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Time [s], finite, strictly increasing, uniformly sampled.
    columns : dict str -> ndarray (N,)
        Every numeric column of the log in file order, ``t`` included (it is
        put first when left out), extras kept. NaN marks a dropout.
    meta : dict
        Sidecar content (``{}`` when there is none).
    path : Path or None
        Where the log was read from.
    ignored_columns : tuple of str
        Extra columns of the file that hold text and were ignored (logs.md).
    lines : tuple of int
        The file line of each sample (the header is line 1), for messages
        (:meth:`where`); empty when the log was not read from a file.

    Raises
    ------
    LogDataError
        Missing required column, columns of different lengths, a non-numeric
        or infinite value, or a bad time column.
    """

    t: np.ndarray
    columns: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)
    path: Path | None = None
    ignored_columns: tuple[str, ...] = ()
    lines: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        t = self._as_column("t", self.t)
        if not isinstance(self.columns, Mapping):
            raise LogDataError(f"columns must be a mapping name -> array, got {type(self.columns).__name__}")
        if "t" in self.columns:
            tc = self._as_column("t", self.columns["t"])
            if tc.shape != t.shape or not np.array_equal(tc, t, equal_nan=True):
                raise LogDataError("columns['t'] differs from t", column="t")
        cols: dict[str, np.ndarray] = {} if "t" in self.columns else {"t": t}  # file order kept
        for name, values in self.columns.items():
            cols[_check_name(name)] = t if name == "t" else self._as_column(name, values)
        missing = [c for c in REQUIRED_COLUMNS if c not in cols]
        if missing:
            raise LogDataError(
                f"missing required column(s) {', '.join(missing)}; found {', '.join(cols)}", column=missing[0]
            )
        n = t.size
        for name, v in cols.items():
            if v.size != n:
                raise LogDataError(f"column {name!r} has {v.size} samples, t has {n}", column=name)
            i = _first_true(np.isinf(v))
            if i is not None:
                raise LogDataError(f"column {name!r} is infinite at sample {i}", column=name, index=i)
        problem = _time_problem(t, lambda i: f" (sample {i})")
        if problem is not None:
            raise LogDataError(f"column 't' at sample {problem[1]}: {problem[0]}", column="t", index=problem[1])
        if not isinstance(self.meta, dict):
            raise LogDataError(f"meta must be a dict, got {type(self.meta).__name__}")
        rate = _rate_problem(self.meta, t)
        if rate is not None:
            raise LogDataError(f"meta: {rate}")
        self.t = t
        self.columns = cols
        if self.path is not None:
            self.path = Path(self.path)

    @staticmethod
    def _as_column(name: str, values: Any) -> np.ndarray:
        try:
            v = np.array(values, dtype=float)
        except (TypeError, ValueError):
            raise LogDataError(f"column {name!r} is not numeric", column=name) from None
        if v.ndim != 1:
            raise LogDataError(f"column {name!r} must be one-dimensional, got shape {v.shape}", column=name)
        return v

    def where(self, i: int) -> str:
        """Where sample ``i`` is, for a message: ``"<file> line L (sample i, t = ... s)"``."""
        i = int(i)
        at = f"sample {i}, t = {self.t[i]:.3f} s"
        if self.path is not None and len(self.lines) == len(self.t):
            return f"{self.path} line {self.lines[i]} ({at})"
        return f"{self.path or 'log'} ({at})"

    # -- channels -----------------------------------------------------------------
    def __getitem__(self, column: str) -> np.ndarray:
        if column not in self.columns:
            raise LogDataError(f"the log has no column {column!r}; it has {', '.join(self.columns)}", column=column)
        return self.columns[column]

    @property
    def tau(self) -> np.ndarray:
        """Rider steering torque [N m]."""
        return self.columns["tau"]

    @property
    def vx(self) -> np.ndarray:
        """Measured forward speed [m/s]."""
        return self.columns["vx"]

    @property
    def delta(self) -> np.ndarray:
        """Steering angle [rad]."""
        return self.columns["delta"]

    @property
    def delta_rate(self) -> np.ndarray:
        """Steering rate [rad/s]."""
        return self.columns["delta_rate"]

    @property
    def yaw_rate(self) -> np.ndarray:
        """Yaw rate [rad/s]."""
        return self.columns["yaw_rate"]

    @property
    def roll_rate(self) -> np.ndarray:
        """Roll rate [rad/s]."""
        return self.columns["roll_rate"]

    @property
    def ay(self) -> np.ndarray:
        """Lateral acceleration in the model (road-plane) frame [m/s^2]."""
        return self.columns["ay"]

    @property
    def roll(self) -> np.ndarray | None:
        """Roll angle [rad] (optional column; ``None`` when the log has none)."""
        return self.columns.get("roll")

    # -- timing -------------------------------------------------------------------
    @property
    def dt(self) -> float:
        """Sample period [s] (median time step)."""
        return float(np.median(np.diff(self.t))) if self.t.size > 1 else math.nan

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate [Hz], ``1 / dt``."""
        return 1.0 / self.dt

    @property
    def duration_s(self) -> float:
        """Time covered by the samples [s], ``N dt = t[-1] - t[0] + dt`` (each sample
        holds over one period; the sidecars' ``duration_s`` convention)."""
        return len(self) * self.dt if len(self) > 1 else 0.0

    def __len__(self) -> int:
        return int(self.t.size)

    def has(self, column: str) -> bool:
        """Whether the log has ``column``."""
        return column in self.columns

    def to_array(self, columns: Sequence[str]) -> np.ndarray:
        """The named columns side by side, shape ``(N, len(columns))``."""
        if isinstance(columns, str):
            columns = [columns]
        return np.column_stack([self[c] for c in columns]) if columns else np.empty((len(self), 0))


# --------------------------------------------------------------------------- reader


def _sidecar_path(path: Path) -> Path:
    return path.with_suffix(".json")


def _line_of_key(text: str, key: str) -> int | None:
    pos = text.find(f'"{key}"')
    return text.count("\n", 0, pos) + 1 if pos >= 0 else None


def _read_sidecar(sidecar: Path) -> tuple[dict, str]:
    raw = sidecar.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise LogFormatError(sidecar, raw.count(b"\n", 0, e.start) + 1, None, "not UTF-8 text") from None
    def constant(name: str) -> Any:  # Python's json takes NaN and Infinity; strict JSON does not
        raise ValueError(name)

    try:
        meta = json.loads(text, parse_constant=constant)
    except json.JSONDecodeError as e:
        raise LogFormatError(sidecar, e.lineno, e.colno, f"not valid JSON: {e.msg}") from None
    except ValueError as e:
        raise LogFormatError(sidecar, text.count("\n", 0, max(text.find(str(e)), 0)) + 1, None,
                             f"not valid JSON: {e} is not a JSON number (use null for a missing value)") from None
    if not isinstance(meta, dict):
        raise LogFormatError(sidecar, 1, None, f"the sidecar must be a JSON object {{...}}, got {type(meta).__name__}")
    for key, problem in _sidecar_problems(meta):
        raise LogFormatError(sidecar, _line_of_key(text, key), key, problem)
    return meta, text


#: Sidecar keys the project reads, with what each must be (logs.md; ``truth`` as the simulators write it).
SIDECAR_KEYS: Mapping[str, str] = {
    "vehicle": "a vehicle preset name or a vehicle file (a non-empty string)",
    "vehicle_file": "the path of a vehicle file (a non-empty string)",
    "sample_rate_hz": "a positive number [Hz]",
    "noise_pct": "a number in [0, 100] (sensor noise in percent of each channel's range)",
    "truth": 'an object {"causes": [{"cause": NAME, "params": {NAME: NUMBER}}]}',
}


def _is_number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _sidecar_problems(meta: Mapping[str, Any]) -> list[tuple[str, str]]:
    """``(key, what is wrong)`` for each known sidecar key of the wrong type or out of range."""
    out = []
    for key in ("vehicle", "vehicle_file"):
        if key in meta and meta[key] is not None and not (isinstance(meta[key], str) and meta[key].strip()):
            out.append((key, f"must be {SIDECAR_KEYS[key]}, got {meta[key]!r}"))
    r = meta.get("sample_rate_hz")
    if r is not None and not (_is_number(r) and r > 0):
        out.append(("sample_rate_hz", f"must be {SIDECAR_KEYS['sample_rate_hz']}, got {r!r}"))
    n = meta.get("noise_pct")
    if n is not None and not (_is_number(n) and 0 <= n <= 100):
        out.append(("noise_pct", f"must be {SIDECAR_KEYS['noise_pct']}, got {n!r}"))
    if "truth" in meta and meta["truth"] is not None:
        tr = meta["truth"]
        causes = tr.get("causes") if isinstance(tr, dict) else None
        ok = isinstance(causes, list) and all(
            isinstance(c, dict) and isinstance(c.get("cause"), str)
            and isinstance(c.get("params", {}), dict) and all(_is_number(v) for v in c.get("params", {}).values())
            for c in causes)
        if not ok:
            out.append(("truth", f"must be {SIDECAR_KEYS['truth']}, got {json.dumps(tr)[:80]}"))
    return out


_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
#: The only blanks a cell may carry around its number (or be made of, for a dropout): ASCII space
#: and tab. A non-breaking space or a form feed is not blank; it is text.
_BLANKS = " \t"
#: A row holding any other character needs the cell-by-cell check.
_NOT_PLAIN = re.compile(r"[^0-9eE+\-. \t]")


def is_plain_number(text: str) -> bool:
    """True if ``text`` (spaces around allowed) is a plain ASCII decimal number: ``-1.5e3``, ``.5``, ``7``.

    Python's ``float`` also takes ``1_000``, non-ASCII digits (``'\\u0661'``), ``nan`` and
    ``infinity``; none of them is data in a ride log or on a command line.

    >>> [is_plain_number(s) for s in ("-1.5e3", " .5 ", "1_000", "\\u0661", "nan", "1e", "")]
    [True, True, False, False, False, False, False]
    """
    return _NUMBER.fullmatch(text.strip(_BLANKS)) is not None


def _cell_error(path: Path, line: int, name: str, cell: str) -> LogFormatError | None:
    """The error for one cell, or None if it is a plain number or a dropout (an empty cell)."""
    s = cell.strip(_BLANKS)
    if not s:
        return LogFormatError(path, line, name, "t is missing; time cannot be missing") if name == "t" else None
    if not is_plain_number(s):
        if s.lower() in ("nan", "+nan", "-nan"):
            return LogFormatError(path, line, name, f"{cell!r} is not a number (a dropout is an empty cell)")
        if s.lower().lstrip("+-") in ("inf", "infinity"):
            return LogFormatError(path, line, name, f"{cell!r} is not finite (a dropout is an empty cell)")
        return LogFormatError(path, line, name, f"{cell!r} is not a number (plain ASCII decimal expected)")
    v = float(s)
    if math.isinf(v):
        return LogFormatError(path, line, name, f"{cell!r} overflows to infinity (not finite)")
    lo, hi = PHYSICAL_BOUNDS.get(name, (-math.inf, math.inf))
    if not (lo <= v <= hi):
        unit = COLUMN_UNITS.get(name, "")
        return LogFormatError(path, line, name, f"{s} {unit} is outside what a two-wheeler's sensor can read "
                                                f"[{lo:g}, {hi:g}] {unit} (ptw_env.logs.PHYSICAL_BOUNDS)")
    return None


def read_log(path: str | os.PathLike, min_duration_s: float = MIN_DURATION_S) -> RideLog:
    """Read a ride log (logs.md) and its sidecar, or say exactly what is wrong.

    Parameters
    ----------
    path : path-like
        The CSV file. Its sidecar is the same name with ``.json``.
    min_duration_s : float
        Shortest accepted log, :attr:`RideLog.duration_s` ``= N dt`` [s]; a log also needs
        :data:`MIN_SAMPLES` samples.

    Returns
    -------
    RideLog
        All columns as float arrays (NaN = dropout), the sidecar as ``meta``.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    LogFormatError
        The file or its sidecar breaks logs.md; see the module docstring for
        the cases. The message names the file, the 1-based line and the column.
    """
    try:
        min_dur = float(min_duration_s)
    except (TypeError, ValueError):
        raise LogDataError(f"min_duration_s must be a number of seconds, got {min_duration_s!r}") from None
    if not (math.isfinite(min_dur) and min_dur >= 0.0):
        raise LogDataError(f"min_duration_s must be finite and >= 0, got {min_duration_s!r}")
    path = Path(path)
    if path.suffix.lower() == ".json":
        raise LogFormatError(path, None, None, "this is a sidecar; pass the .csv log beside it")
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise LogFormatError(path, raw.count(b"\n", 0, e.start) + 1, None, "not UTF-8 text") from None
    if not text.strip():
        raise LogFormatError(path, 1, None, f"the file is empty; expected a header line {','.join(REQUIRED_COLUMNS)}")

    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader)
        while not header:  # leading blank lines
            header = next(reader)
        hline = reader.line_num
        names = [h.strip() for h in header]
        seen: dict[str, int] = {}
        for j, name in enumerate(names, 1):
            if not name:
                raise LogFormatError(path, hline, j, f"the header's field {j} is empty; every column needs a name")
            if name in seen:
                raise LogFormatError(path, hline, name, f"duplicate column name (fields {seen[name]} and {j})")
            seen[name] = j
        missing = [c for c in REQUIRED_COLUMNS if c not in seen]
        if missing:
            raise LogFormatError(
                path, hline, missing[0],
                f"missing required column(s) {', '.join(missing)}; the header has {', '.join(names)}",
            )  # fmt: skip

        ncol = len(names)
        known = [n in KNOWN_COLUMNS for n in names]
        lo = np.array([PHYSICAL_BOUNDS.get(n, (-math.inf, math.inf))[0] for n in names])
        hi = np.array([PHYSICAL_BOUNDS.get(n, (-math.inf, math.inf))[1] for n in names])
        text_cols: set[int] = set()  # extra columns holding text: ignored (logs.md)
        rows: list[list[float]] = []
        lines: list[int] = []
        blank: int | None = None  # first blank line after the last data row
        nan = math.nan
        for rec in reader:
            line = reader.line_num
            if not rec or (len(rec) == 1 and not rec[0].strip(_BLANKS) and ncol > 1):
                blank = line if blank is None else blank
                continue
            if blank is not None:
                raise LogFormatError(path, blank, None, f"blank line inside the data; expected {ncol} fields")
            if len(rec) != ncol:
                col = names[len(rec)] if len(rec) < ncol else None
                raise LogFormatError(path, line, col, f"the row has {len(rec)} fields, the header has {ncol}")
            try:  # fast path: plain ASCII numbers everywhere, no dropout, within bounds
                vals = [float(c) for c in rec]
                bad = (text_cols or _NOT_PLAIN.search("".join(rec)) is not None
                       or not all(lo[j] <= v <= hi[j] for j, v in enumerate(vals)))  # NaN fails too
            except (ValueError, OverflowError):
                vals, bad = [], True
            if bad:  # cell by cell: the first offending cell of a known column, left to right
                vals = []
                for j, (name, cell) in enumerate(zip(names, rec)):
                    err = _cell_error(path, line, name, cell)
                    if err is not None and not known[j]:
                        text_cols.add(j)
                        err = None
                    if err is not None:
                        raise err
                    s = cell.strip(_BLANKS)
                    vals.append(nan if (not s or j in text_cols) else float(s))
            rows.append(vals)
            lines.append(line)
    except csv.Error as e:
        raise LogFormatError(path, reader.line_num, None, f"not valid CSV: {e}") from None
    except StopIteration:  # pragma: no cover - guarded by the empty-file check
        raise LogFormatError(path, 1, None, "no header line") from None

    data = np.array(rows, dtype=float).reshape(len(rows), ncol)
    t = data[:, names.index("t")]
    problem = _time_problem(t, lambda i: f" on line {lines[i]}")
    if problem is not None:
        raise LogFormatError(path, lines[problem[1]], "t", problem[0])
    problem = _length_problem(t, min_dur)
    if problem is not None:
        raise LogFormatError(path, lines[-1] if lines else hline, "t", problem)

    meta: dict = {}
    sidecar = _sidecar_path(path)
    if sidecar.exists() and not sidecar.is_file():
        raise LogFormatError(sidecar, None, None, "the sidecar is not a regular file (a directory?); "
                                                  "it must be the log's JSON metadata or absent")
    if sidecar.is_file():
        meta, mtext = _read_sidecar(sidecar)
        rate = _rate_problem(meta, t)
        if rate is not None:
            raise LogFormatError(sidecar, _line_of_key(mtext, "sample_rate_hz"), "sample_rate_hz", rate)
    columns = {name: np.ascontiguousarray(data[:, j]) for j, name in enumerate(names) if j not in text_cols}
    return RideLog(t=columns["t"], columns=columns, meta=meta, path=path,
                   ignored_columns=tuple(names[j] for j in sorted(text_cols)), lines=tuple(lines))


def sidecar_noise_pct(meta: Mapping[str, Any] | None) -> float | None:
    """The sidecar's ``noise_pct`` (percent of each channel's range, logs.md) when it is a finite number >= 0,
    else None (absent: the caller's default applies; :func:`read_log` has already refused a bad value)."""
    v = meta.get("noise_pct") if isinstance(meta, Mapping) else None
    if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0:
        return float(v)
    return None


def speed_fixes(t: np.ndarray, vx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The instants [s] and values [m/s] of a sample-and-hold speed channel's fixes (logs.md: ``vx`` is the
    GPS speed held between 10 Hz fixes): the first reading and every reading that differs from the one before,
    dropouts (NaN) skipped. A channel refreshed every sample gives every sample. ValueError without a reading."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(vx, dtype=float)
    ok = np.isfinite(v)
    if not ok.any():
        raise ValueError("column 'vx': no speed reading at all")
    ti, vi = t[ok], v[ok]
    fix = np.r_[True, vi[1:] != vi[:-1]]  # a held reading repeats; a new fix changes it
    return ti[fix], vi[fix]


def held_speed(t: np.ndarray, vx: np.ndarray) -> np.ndarray:
    """Speed [m/s] at every sample ``t`` [s] from a sample-and-hold channel: linear interpolation between its
    fixes (:func:`speed_fixes`), across dropouts; constant before the first and after the last fix. The one
    reconstruction of the held GPS speed (estimation, risk and diagnosis use it)."""
    tf, vf = speed_fixes(t, vx)
    return np.interp(np.asarray(t, dtype=float), tf, vf)


def ridden_part(log: RideLog) -> tuple[RideLog, list[str]]:
    """The longest stretch of ``log`` a sequential estimator can run through, and notes saying what was left out
    and why (the estimators and the risk warning: ``ptw-assist estimate`` and ``risk``).

    A sample is usable when the rider torque ``tau`` is read (the model is driven by it: a dropout there
    cannot be bridged) and the speed, where read, is positive: a standstill, a vehicle pushed or carried,
    a speed sensor reading 0 or less is not riding, and the model divides by ``vx``. A speed dropout is usable
    (the held speed bridges it, :func:`held_speed`). The longest run of usable samples is kept; what lies
    before and after it, and any shorter usable run, is left out and said in the notes (samples, times and
    file lines). ``log`` is returned itself, with no note, when every sample is usable.

    Raises
    ------
    LogDataError
        No usable stretch of at least :data:`MIN_SAMPLES` samples and :data:`MIN_DURATION_S` (the longest named).
    """
    bad_tau, stand = unusable_samples(log["tau"], log["vx"])
    good = ~(bad_tau | stand)
    if good.all():
        return log, []
    starts, ends = _runs(good)  # usable runs [start, end)
    lengths = ends - starts
    why = []
    if stand.any():
        k = int(np.flatnonzero(stand)[0])
        why.append(f"{int(stand.sum())} sample(s) with vx <= 0 (not ridden; the first at {log.where(k)})")
    if bad_tau.any():
        k = int(np.flatnonzero(bad_tau)[0])
        why.append(f"{int(bad_tau.sum())} dropout(s) in tau (the first at {log.where(k)})")
    i = int(np.argmax(lengths)) if lengths.size else -1
    s, e = (int(starts[i]), int(ends[i])) if lengths.size else (0, 0)
    short = _length_problem(log.t[s:e], MIN_DURATION_S)  # the rule read_log applies to a whole log
    if short is not None:
        raise LogDataError(f"{log.path or 'log'}: no ridden stretch of at least {MIN_DURATION_S:g} s and {MIN_SAMPLES} "
                           f"samples (longest: {(e - s) * log.dt:.2f} s, {e - s} samples); {'; '.join(why)}",
                           column="vx" if stand.any() else "tau")
    notes = [f"kept the longest ridden stretch, t = {log.t[s]:.2f}-{log.t[e - 1]:.2f} s ({e - s} of {len(log)} samples, "
             f"from {log.where(s)}): the log has {'; '.join(why)}"]
    others = [j for j in range(lengths.size) if j != i]
    if others:
        notes.append(f"left out {len(others)} shorter ridden stretch(es), {lengths[others].sum() * log.dt:.2f} s in all "
                     f"(a sequential estimator cannot bridge the gaps): "
                     + ", ".join(f"t = {log.t[starts[j]]:.2f}-{log.t[ends[j] - 1]:.2f} s" for j in others[:5])
                     + (" ..." if len(others) > 5 else ""))
    part = RideLog(t=log.t[s:e], columns={k: c[s:e] for k, c in log.columns.items()}, meta=log.meta, path=log.path,
                   ignored_columns=log.ignored_columns, lines=log.lines[s:e] if len(log.lines) == len(log) else ())
    return part, notes


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and ends (exclusive) of the runs of True in a boolean array."""
    edges = np.flatnonzero(np.diff(np.r_[0, np.asarray(mask).astype(np.int8), 0]))
    return edges[::2], edges[1::2]


def unusable_samples(tau: np.ndarray, vx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples a model replay cannot use, as masks ``(tau_missing, vx_not_positive)``: the rider torque not
    read (NaN) and a speed read at 0 or below (a missing speed fix is usable: the held speed bridges it). The
    one rule of :func:`input_series` (which refuses such samples) and :func:`ridden_part` (which cuts them out)."""
    tau = np.asarray(tau, dtype=float)
    v = np.asarray(vx, dtype=float)
    return ~np.isfinite(tau), np.isfinite(v) & (v <= 0.0)


def input_series(t: np.ndarray, tau: np.ndarray, vx: np.ndarray, where: str = "") -> tuple[np.ndarray, np.ndarray]:
    """The inputs of a model replay, checked once: ``(tau, vx_held)`` [N m, m/s] from the ``tau`` and ``vx``
    columns at times ``t`` [s].

    The rider torque must be present at every sample (the model is driven by it); the speed is a
    sample-and-hold channel (NaN where a fix is missing) that must have a reading and be positive
    wherever present (the model divides by it), and is returned reconstructed at every sample
    (:func:`held_speed`). A violation is one ValueError naming the first sample, its time and its line in a
    file with one header line, and how many samples are affected (prefixed by ``where``, e.g. the file, when
    given). The one check shared by the
    estimators, the adaptive observer and the risk warning.
    """
    t = np.asarray(t, dtype=float)
    tau = np.asarray(tau, dtype=float)
    v = np.asarray(vx, dtype=float)
    where = f"{where}: " if where else ""

    def at(idx: np.ndarray) -> str:
        k = int(idx[0])
        return f"at sample {k} (t = {t[k]:.3f} s, line {k + 2} of a file with one header line), {idx.size} such sample(s)"

    tau_missing, stand = unusable_samples(tau, v)
    bad = np.flatnonzero(tau_missing)
    if bad.size:
        raise ValueError(f"{where}tau is missing {at(bad)} (the rider torque must be known at every sample)")
    if not np.isfinite(v).any():
        raise ValueError(f"{where}vx is missing at every sample")
    nonpos = np.flatnonzero(stand)
    if nonpos.size:
        raise ValueError(f"{where}vx must be positive (m/s) where present; vx = {v[int(nonpos[0])]:g} m/s "
                         f"{at(nonpos)}")
    return tau, held_speed(t, v)


#: Fewest consecutive identical readings at a channel's extreme that can read as a clipped sensor.
CLIP_MIN_RUN = 3
#: A channel is checked for clipping only when at most this fraction of its other consecutive readings repeat
#: exactly: a noisy sensor never repeats a reading, so a flat top there is the sensor's limit; a channel that is
#: often flat anyway (a quantised encoder, a held or noise-free signal) cannot show a clip by its shape.
CLIP_REPEAT_MAX = 0.05
#: A channel is checked for clipping only when its readings between the extremes are noisy: the median of
#: their second differences at least this fraction of the median step (white noise gives about 1.7; a smooth,
#: noise-free signal sampled fast far less, 0.13-0.22 on the disclosed noise-free log), so that a noise-free
#: signal that ramps to a value and holds it is not taken for a clip.
CLIP_NOISE_RATIO = 0.5
#: Channels checked for clipping: the known ones but time and the speed (a GPS reading is held by design).
CLIP_CHANNELS: tuple[str, ...] = tuple(c for c in KNOWN_COLUMNS if c not in ("t", "vx"))


def clipped_samples(log: RideLog) -> dict[str, dict[float, np.ndarray]]:
    """The readings of ``log`` at a sensor's limit: ``{column: {limit: mask}}`` for each clipped column of
    :data:`CLIP_CHANNELS` (one mask per clipped side, the readings equal to that limit).

    A sensor (or an actuator's logged command) that saturates reads its limit exactly for as long as the true
    value stays beyond it: a flat top. It is told from a signal that merely peaks by two facts, both required:

    * at least :data:`CLIP_MIN_RUN` consecutive readings equal the column's maximum (or minimum), and that value
      lies on its own side of zero (an upper limit above 0, a lower one below: a signal resting at 0 is not
      clipped);
    * the column's other readings are noisy: they seldom repeat (at most :data:`CLIP_REPEAT_MAX` of
      consecutive pairs) and their second differences are as large as noise makes them
      (:data:`CLIP_NOISE_RATIO`). In a noisy channel equal readings are the limit; in a quantised, held or
      noise-free one they are common or expected (a smooth maximum, a value ramped to and held) and prove
      nothing: such a channel is not judged, so a clip of a noise-free channel is not seen.

    Every reading equal to a found limit is in its mask (each says only that the true value is at or beyond
    it). The check reads nothing of the vehicle: a limit is found from the data, so any sensor range works.
    A clip smoothed by a filter before logging (an anti-alias resampling leaves no flat top) is not seen.
    """
    out: dict[str, dict[float, np.ndarray]] = {}
    for c in CLIP_CHANNELS:
        if not log.has(c):
            continue
        x = np.asarray(log[c], dtype=float)
        ok = np.isfinite(x)
        if ok.sum() < 2 * CLIP_MIN_RUN:
            continue
        lo, hi = float(np.min(x[ok])), float(np.max(x[ok]))
        if not hi > lo:
            continue  # a constant column: nothing to clip
        others = ok & (x != hi) & (x != lo)  # the readings between the extremes
        pair = others[1:] & others[:-1]
        if pair.sum() < CLIP_MIN_RUN:
            continue
        step = np.abs(np.diff(x))[pair]
        if np.mean(step == 0.0) > CLIP_REPEAT_MAX:
            continue  # quantised, held or noise-free: a flat top proves nothing
        triple = others[2:] & others[1:-1] & others[:-2]
        if not triple.any() or (float(np.median(np.abs(np.diff(x, 2))[triple]))
                                < CLIP_NOISE_RATIO * float(np.median(step[step > 0.0]))):
            continue  # a smooth, noise-free signal: a value it ramps to and holds is not a limit
        sides = {}
        for limit, side in ((hi, 1.0), (lo, -1.0)):
            at = ok & (x == limit)
            starts, ends = _runs(at)
            if limit * side > 0.0 and np.any(ends - starts >= CLIP_MIN_RUN):  # its own side of zero, a flat top
                sides[limit] = at
        if sides:
            out[c] = sides
    return out


def without_clipped(log: RideLog) -> tuple[RideLog, list[str]]:
    """``log`` with the readings at a sensor's limit (:func:`clipped_samples`) set as dropouts, and a note per
    clipped column saying what was set aside and why. ``log`` itself, with no note, when nothing is clipped.

    A clipped measured channel loses those samples from every comparison; a clipped ``tau`` (the input) makes
    them unusable samples of the input (:func:`unusable_samples`): the commands leave them out as they do a
    torque dropout. Shared by ``diagnose``, ``estimate`` and ``risk``: none of them may read a sensor's limit as
    the vehicle's response (a clipped gyro would look like a stiffer or saturating tire)."""
    clips = clipped_samples(log)
    if not clips:
        return log, []
    cols = dict(log.columns)
    notes = []
    for c, sides in clips.items():
        mask = np.logical_or.reduce(list(sides.values()))
        sides_text = ", ".join(f"{v:g} {COLUMN_UNITS.get(c, '')} at {int(m.sum())} sample(s)" for v, m in sides.items())
        cols[c] = np.where(mask, np.nan, cols[c])
        k = int(np.flatnonzero(mask)[0])
        what, use = (("a torque sensor's or the actuator's (or rider's) limit: which cannot be told, so the torque "
                      "there is not taken as known", "the windows and stretches holding them are left out as for a "
                      "torque dropout") if c == "tau" else
                     ("a clipped sensor", "they are left out of every comparison"))
        notes.append(f"column '{c}' reads its limit {sides_text} ({100.0 * mask.mean():.1f} % of the log, the first at "
                     f"{log.where(k)}): {what}, not a vehicle effect (flat tops at the column's extreme in a noisy "
                     f"channel that seldom repeats a reading); those readings are set as dropouts and {use}")
    part = RideLog(t=log.t, columns=cols, meta=log.meta, path=log.path, ignored_columns=log.ignored_columns,
                   lines=log.lines)
    return part, notes


def usable_part(log: RideLog) -> tuple[RideLog, list[str]]:
    """What a sequential estimator runs on (``ptw-assist estimate`` and ``risk``): ``log`` with the readings at a
    sensor's limit set aside (:func:`without_clipped`), then its longest ridden stretch (:func:`ridden_part`), and
    the notes of both."""
    log, clipped = without_clipped(log)
    part, trimmed = ridden_part(log)
    return part, clipped + trimmed


def check_against_vehicle(log: RideLog, vehicle: Any) -> None:
    """Refuse a log whose steer angle goes beyond the vehicle's steering lock.

    ``|delta| <= vehicle.steer_lock`` [rad] at every present sample
    (:attr:`ptw_env.vehicle.Vehicle.steer_lock`, ``[limits] steer_lock`` of a vehicle
    file; ``pi/2`` when the file gives none). The speed range is not checked here:
    each command states what it does with samples outside it (``diagnose`` leaves
    those windows out and says so).

    Raises
    ------
    LogFormatError
        Naming the file, the line and column ``delta``, the value in rad and deg, and the lock.
    """
    lock = float(vehicle.steer_lock)
    d = np.asarray(log.delta, dtype=float)
    over = np.flatnonzero(np.abs(np.nan_to_num(d)) > lock)
    if over.size:
        k = int(over[0])
        line = log.lines[k] if len(log.lines) == len(log.t) else None
        raise LogFormatError(log.path or "log", line, "delta",
                             f"{d[k]:g} rad ({math.degrees(d[k]):.1f} deg) at t = {log.t[k]:.3f} s is beyond "
                             f"{vehicle.name}'s steering lock {lock:.4g} rad ({math.degrees(lock):.1f} deg); "
                             f"{over.size} such sample(s)")


# --------------------------------------------------------------------------- writer


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"meta: {type(o).__name__} {o!r} is not JSON-serialisable")


def _fmt(values: np.ndarray) -> list[str]:
    # repr of a Python float is the shortest string that reads back to the same double
    return ["" if v != v else repr(v) for v in values.tolist()]


def write_log(
    path: str | os.PathLike,
    log_or_columns: RideLog | Mapping[str, Any],
    meta: Mapping[str, Any] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write a ride log (logs.md) and, with metadata, its sidecar ``<name>.json``.

    Columns are written in logs.md order (:data:`KNOWN_COLUMNS`), then the
    extra columns in their given order. Numbers are written with Python's
    ``repr``, the shortest text that reads back to the identical double (exact
    round trip); NaN (a dropout) is written as an empty cell. Files are written
    to a temporary file and renamed, so a failed write leaves nothing half done.

    Parameters
    ----------
    path : path-like
        The CSV file to write (conventionally ``.csv``).
    log_or_columns : RideLog or mapping column -> array
        The data; a mapping is checked as :class:`RideLog` checks it.
    meta : mapping, optional
        Sidecar content. When ``None``, a :class:`RideLog`'s own non-empty
        ``meta`` is used; otherwise no sidecar is written.
    overwrite : bool
        Replace existing files. The sidecar counts as part of the log: without
        ``overwrite`` an existing sidecar is an error too (it would be read
        with the new CSV), and with ``overwrite`` a stale sidecar is removed
        when the new log has no metadata.

    Returns
    -------
    Path
        The CSV path.

    Raises
    ------
    FileExistsError
        The CSV or its sidecar exists and ``overwrite`` is False.
    LogDataError
        The data cannot make a valid log (missing required column, lengths
        differ, infinite values, time not finite/increasing/uniform, a column
        name with a comma, meta not JSON-serialisable or contradicting the
        time column).
    """
    if not isinstance(overwrite, bool):
        raise LogDataError(f"overwrite must be True or False, got {overwrite!r}")
    if isinstance(log_or_columns, RideLog):
        log = log_or_columns
        if meta is None and log.meta:
            meta = log.meta
    elif isinstance(log_or_columns, Mapping):
        cols = dict(log_or_columns)
        if "t" not in cols:
            raise LogDataError(f"missing required column t; found {', '.join(map(str, cols))}", column="t")
        log = RideLog(t=cols["t"], columns=cols)
    else:
        raise LogDataError(f"write_log takes a RideLog or a mapping of columns, got {type(log_or_columns).__name__}")
    path = Path(path)
    if path.suffix.lower() == ".json":
        raise LogDataError(f"{path}: a log cannot be a .json file (that name is its sidecar's)")
    sidecar = _sidecar_path(path)
    meta_text = None
    if meta is not None:
        if not isinstance(meta, Mapping):
            raise LogDataError(f"meta must be a mapping, got {type(meta).__name__}")
        rate = _rate_problem(meta, log.t)
        if rate is not None:
            raise LogDataError(f"meta: {rate}")
        try:
            meta_text = json.dumps(dict(meta), indent=1, default=_json_default) + "\n"
        except (TypeError, ValueError) as e:
            raise LogDataError(str(e)) from None
    if not overwrite:
        for p in (path, sidecar):
            if p.exists():
                raise FileExistsError(f"{p} exists; pass overwrite=True to replace it")

    order = [c for c in KNOWN_COLUMNS if c in log.columns] + [c for c in log.columns if c not in KNOWN_COLUMNS]
    cells = [_fmt(log.columns[c]) for c in order]
    body = "\n".join(",".join(r) for r in zip(*cells))
    atomic_write_text(path, ",".join(order) + "\n" + body + ("\n" if body else ""))
    if meta_text is not None:
        atomic_write_text(sidecar, meta_text)
    elif overwrite and sidecar.exists():
        sidecar.unlink()
    return path
