"""Diagnose a fleet of ride logs on one execution layer (issue 22; cli.md ``diagnose LOG.csv [LOG2.csv ...]``).

Each log is one independent job of :func:`ptw_env.jobs.run_jobs` (serial, local processes or a Dask
cluster, the same numbers whichever runs it): :func:`diagnose_one` reads the log, diagnoses it
against its vehicle, writes its report (diagnose.md JSON, and the figure) into the output folder
atomically and returns one row of the fleet table. :func:`diagnose_fleet` runs them, keeps every
finished row in ``<out>/fleet_jobs.jsonl`` as it arrives (a rerun with ``resume=True`` skips the
logs already done, so a dead worker or an interrupted run loses nothing finished), and writes the
fleet table ``<out>/fleet.csv``: per log the vehicle, the verdict's causes and sizes, the held-out
gain, whether it explains the log, and the model extension with its gain.

>>> import tempfile, pathlib
>>> from ptw_env.ride import ride_scenario
>>> from ptw_env.logs import write_log
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> for s in (1, 2):
...     _ = write_log(d / f"ride{s}.csv",
...                   ride_scenario("double_lane_change", effects={"road_bank": {"bank_rad": 0.05}}, seed=s).log)
>>> rows = diagnose_fleet([d / "ride1.csv", d / "ride2.csv"], d / "out", pairs=False, progress=False)
>>> [(r["log_name"], r["causes"][0]["cause"], r["explained"]) for r in rows]
[('ride1', 'road_bank', True), ('ride2', 'road_bank', True)]
>>> sorted(p.name for p in (d / "out").iterdir())
['fleet.csv', 'fleet_jobs.jsonl', 'ride1.json', 'ride1.png', 'ride2.json', 'ride2.png']
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ptw_env.jobs import run_jobs
from ptw_env.logs import read_log
from ptw_env.outputs import atomic_path, atomic_write_text
from ptw_env.vehicle import Vehicle

from .data import DiagnoseInputError
from .diagnosis import diagnose
from .report import causes_text

#: Columns of the fleet table (``fleet.csv``).
TABLE_COLUMNS = ("log", "vehicle", "causes", "gain", "explained", "extension", "extension_gain", "extended",
                 "report")


def diagnose_one(path: str, out_dir: str, vehicle: Vehicle | None = None, window_s: float | None = None,
                 pairs: bool | str = True, figure: bool = True) -> dict[str, Any]:
    """Job: diagnose the log at ``path`` (``vehicle``: default its sidecar's), write
    ``<out_dir>/<stem>.json`` (and ``.png``), return its row of the fleet table (JSON-serialisable)."""
    log = read_log(path)
    rep = diagnose(log, window_s=window_s, pairs=pairs, vehicle=vehicle, progress=False)
    stem = Path(path).stem
    out = Path(out_dir)
    report = out / f"{stem}.json"
    atomic_write_text(report, json.dumps(rep.to_json(), indent=1, allow_nan=False) + "\n")
    if figure:
        with atomic_path(out / f"{stem}.png") as tmp:
            rep.plot(tmp)
    ext = rep.extension
    return {"log": str(path), "log_name": stem, "vehicle": rep.vehicle.name, "causes": rep.causes,
            "gain": round(float(rep.gain), 4), "explained": bool(rep.explained),
            "extension": None if ext is None else [{k: t[k] for k in ("name", "coefficient", "std", "unit")}
                                                   for t in ext["terms"]],
            "extension_gain": None if ext is None else ext["gain"], "extended": bool(rep.extended),
            "report": report.name}


def fleet_table(rows: Sequence[dict[str, Any]]) -> str:
    """The fleet table as CSV text (:data:`TABLE_COLUMNS`; causes and extension terms as text)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TABLE_COLUMNS)
    for r in rows:
        ext = "" if r["extension"] is None else "; ".join(f"{t['name']}={t['coefficient']:g}" for t in r["extension"])
        w.writerow([r["log_name"], r["vehicle"], causes_text(r["causes"]), r["gain"], r["explained"], ext,
                    "" if r["extension_gain"] is None else r["extension_gain"], r["extended"], r["report"]])
    return buf.getvalue()


def plot_fleet(rows: Sequence[dict[str, Any]], path: str | os.PathLike) -> None:
    """One bar per log: the held-out gain of the verdict and of the extended model, the verdict named."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    n = len(rows)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.55 * n + 2.0), 5.0), constrained_layout=True)
    x = np.arange(n)
    g = [r["gain"] for r in rows]
    ge = [r["extension_gain"] if r["extension_gain"] is not None else np.nan for r in rows]
    ax.bar(x - 0.2, g, 0.4, label="effects.md verdict", color=["C2" if r["explained"] else "C1" for r in rows])
    ax.bar(x + 0.2, ge, 0.4, label="extended model", color="C0")
    for i, r in enumerate(rows):
        ax.text(i - 0.2, 0.02, "+".join(c["cause"] for c in r["causes"]), rotation=90, fontsize=7, va="bottom",
                ha="center")
    ax.set_xticks(x, [r["log_name"] for r in rows], rotation=60, fontsize=7, ha="right")
    ax.set(ylabel="held-out gain over the nominal model", ylim=(min(0.0, np.nanmin(g + ge)) - 0.05, 1.05),
           title=f"diagnosis of {n} ride logs (green: explained to within the noise)")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def diagnose_fleet(paths: Sequence[str | os.PathLike], out_dir: str | os.PathLike, *,
                   vehicles: Sequence[Vehicle | None] | None = None, window_s: float | None = None,
                   pairs: bool | str = True, figures: bool = True, workers: int = 1, scheduler: str | None = None,
                   resume: bool = False, progress: bool = True) -> list[dict[str, Any]]:
    """Diagnose every log of ``paths`` (module docstring); return the fleet rows in the order of ``paths``.

    ``vehicles``: one per log (None: the log's sidecar's), default all None. ``workers``,
    ``scheduler``: the executor (:func:`ptw_env.jobs.run_jobs`). ``resume``: keep the rows already in
    ``<out_dir>/fleet_jobs.jsonl`` and diagnose only the other logs; without it that file starts empty.
    Raises :class:`~assist.diagnose.DiagnoseInputError` for two logs with one name (their reports
    would collide).
    """
    paths = [str(p) for p in paths]
    stems = [Path(p).stem for p in paths]
    dup = sorted({s for s in stems if stems.count(s) > 1})
    if dup:
        raise DiagnoseInputError(f"two logs named {dup[0]!r}: their reports would both be {dup[0]}.json; rename one")
    out = Path(out_dir)
    clash = [p for p in paths if Path(p).resolve().parent == out.resolve()]
    if clash:
        raise DiagnoseInputError(f"the output folder {out} holds the log {clash[0]}: its report would replace the "
                                 "log's sidecar; write the reports to another folder")
    vehicles = list(vehicles) if vehicles is not None else [None] * len(paths)
    if len(vehicles) != len(paths):
        raise DiagnoseInputError(f"vehicles: {len(vehicles)} given for {len(paths)} logs")
    out.mkdir(parents=True, exist_ok=True)
    jobs_file = out / "fleet_jobs.jsonl"
    if not resume and jobs_file.exists():
        jobs_file.unlink()
    jobs = [(p, (p, str(out), v, window_s, pairs, figures)) for p, v in zip(paths, vehicles)]
    done = run_jobs(diagnose_one, jobs, workers=workers, scheduler=scheduler, results=jobs_file,
                    progress=progress, desc="logs")
    rows = [done[p] for p in paths]
    atomic_write_text(out / "fleet.csv", fleet_table(rows))
    return rows
