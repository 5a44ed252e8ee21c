"""``ptw-assist diagnose LOG.csv --json REPORT.json [--plot REPORT.png]`` (``shared/spec/diagnose.md``).

Registered into the one command line of :mod:`ptw_env.cli` when it builds its
parser (``import assist.cli.diagnose``). A bad log ends with one line naming
the file, the line and the column (:class:`ptw_env.logs.LogFormatError`) and
exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ptw_env.cli import (
    CLIError,
    add_vehicle_option,
    check_outputs,
    command,
    number,
    emit,
    vehicle_for_log,
)


#: ``--window``: replay window length [s].
_window = number(0.2, 20.0, unit="s")


@command(
    "diagnose",
    "replay the nominal model against a ride log, name the effect of effects.md that explains the "
    "difference, and measure the held-out gain",
    "ptw-assist diagnose ride.csv --json report.json --plot report.png",
)
def _build_diagnose(p: argparse.ArgumentParser):
    p.add_argument("log", metavar="LOG.csv", help="ride log (logs.md), with an optional JSON sidecar")
    add_vehicle_option(p, from_log=True)
    p.add_argument("--json", default=None, metavar="REPORT.json", help="write the report (diagnose.md)")
    p.add_argument("--plot", default=None, metavar="REPORT.png",
                   help="measured vs nominal vs extended model, residual before/after")
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

        check_outputs(a, "json", "plot")
        log = Path(a.log)
        if not log.exists():
            raise FileNotFoundError(f"{log}: no such file")
        if log.is_dir():
            raise CLIError(f"{log} is a directory, not a ride log")
        from ptw_env.logs import read_log

        pairs = {"auto": True, "all": "all", "none": False}[a.pairs]
        ride = read_log(log)
        v = vehicle_for_log(a, ride)  # --vehicle, else the sidecar's, else the reference scooter
        print(f"vehicle: {v.name}")
        rep = diagnose(ride, window_s=a.window, pairs=pairs, progress=False if a.no_progress else None, vehicle=v)
        print(rep.summary())
        print(f"diagnosed in {rep.seconds:.1f} s ({100 * rep.sim_seconds / rep.seconds:.0f} % in the simulator)")
        emit(a, rep.to_json() if a.json else None, {"plot": rep.plot}, what="report")
        return 0

    return run
