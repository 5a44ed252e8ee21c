"""Outputs of the evaluation and benchmark scripts: nothing is overwritten without ``--overwrite``.

The scripts run as ``python scripts/NAME.py``, which puts this folder on ``sys.path``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path


def add_overwrite(parser: argparse.ArgumentParser) -> None:
    """The ``--overwrite`` option."""
    parser.add_argument("--overwrite", action="store_true", help="replace existing output files")


def output_dir(parser: argparse.ArgumentParser, path: str | os.PathLike, overwrite: bool) -> Path:
    """The output folder ``path``, created; one clear error (exit 2) if it is a file, or holds files
    and ``overwrite`` is false (the script would replace some of them)."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        parser.error(f"output folder {out} is a file")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        parser.error(f"output folder {out} is not empty; pass --overwrite to replace its files")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        parser.error(f"cannot create the output folder {out}: {e.strerror}")
    return out


def output_file(parser: argparse.ArgumentParser, option: str, path: str | os.PathLike | None,
                overwrite: bool) -> Path | None:
    """``path`` (the value of ``option``) checked before any work, as the commands check theirs
    (:func:`ptw_env.outputs.check_writable`: its folder exists and takes a new file, it is not a folder or a
    device, it does not exist unless ``overwrite``); a refusal is the parser's one-line error."""
    if path is None:
        return None
    from ptw_env.outputs import OutputError, check_writable

    try:
        check_writable(path, option, overwrite)
    except OutputError as exc:
        parser.error(str(exc))
    return Path(path)


def shared_data(sub: str) -> Path:
    """The folder ``shared/data/<sub>`` of the project's disclosed data: ``$PTW_SHARED_DIR``, else ``../shared``
    beside the checkout, else ``/work/shared``; exits with one line when none holds it."""
    root = Path(__file__).resolve().parents[1]
    for c in (os.environ.get("PTW_SHARED_DIR"), root.parent / "shared", Path("/work/shared")):
        if c and (Path(c) / "data" / sub).is_dir():
            return Path(c) / "data" / sub
    raise SystemExit(f"shared/data/{sub} not found; pass --data or set PTW_SHARED_DIR")


def local_executors(workers: int) -> list[tuple[str, dict]]:
    """The executors of :func:`ptw_env.jobs.run_jobs` a benchmark compares on this machine: serial, ``workers``
    local processes, and a Dask LocalCluster of ``workers`` when the ``[cluster]`` extra is installed."""
    out = [("serial", dict(workers=1)), (f"{workers} local processes", dict(workers=workers))]
    try:
        import distributed  # noqa: F401
    except ImportError:
        print("(Dask rows skipped: pip install \"ptw-assist[cluster]\")")
        return out
    return out + [(f"Dask LocalCluster, {workers} workers", dict(workers=workers, scheduler="local"))]


def write_results(out: Path, res: dict, md: str, done: str) -> None:
    """``results.json`` (finite JSON, floats of numpy types as floats) and ``results.md`` in ``out``; the table
    and the line ``done`` (e.g. "240 rides in 291 s") printed."""
    (out / "results.json").write_text(json.dumps(res, indent=1, allow_nan=False, default=float) + "\n")
    (out / "results.md").write_text(md)
    print(md)
    print(f"{done}; results in {out}/")
