"""Which speed ranges the TS observer-based controller design certifies, per vehicle preset.

For each preset: its whole valid range, its design range (``[speed_range] design_vmin, design_vmax``,
:attr:`ptw_env.vehicle.Vehicle.control_range`) and the other ranges tried when choosing it; each is
designed from scratch (Theorems 1-2, Clarabel, every LMI re-checked in numpy) and reported as
certified or with the theorem, LMI and vertex speed where it fails.

Run: ``python scripts/eval_design_ranges.py [--json OUT.json] [--overwrite]`` (56 s on 2 cores, 2026-11-25).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.control.ts_design import DesignError, design  # noqa: E402
from ptw_env.vehicle_files import load_vehicle, vehicle_names  # noqa: E402
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)

#: Ranges tried besides each vehicle's valid and design ranges [m/s] (the search that chose the design ranges).
TRIED = {
    "reference-scooter": [(10.0, 20.0), (3.0, 33.0), (8.0, 40.0)],
    "sharp1971": [(8.0, 33.0), (10.0, 40.0), (5.0, 40.0), (4.0, 30.0)],
    "cossalter-sport-touring": [(8.0, 25.0), (8.0, 33.0), (12.0, 36.0), (15.0, 45.0), (20.0, 50.0)],
    "robot-bicycle": [(2.0, 8.0), (2.5, 6.0), (3.0, 8.0), (4.0, 10.0), (5.0, 11.2), (2.0, 11.2)],
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None, metavar="OUT.json", help="write every case here")
    add_overwrite(ap)
    a = ap.parse_args(argv)
    out = output_file(ap, "--json", a.json, a.overwrite)
    rows = []
    for name in vehicle_names():
        v = load_vehicle(name)
        ranges = [("valid", (v.vmin, v.vmax)), ("design", v.control_range)] + [("tried", r) for r in TRIED[name]]
        seen = set()
        for kind, (lo, hi) in ranges:
            if (lo, hi) in seen:
                continue
            seen.add((lo, hi))
            t0 = time.perf_counter()
            try:
                design(v, vmin=lo, vmax=hi, cache=False)
                ok, why = True, ""
            except DesignError as err:
                ok, why = False, " ".join(str(err).split())[:160]
            sec = time.perf_counter() - t0
            rows.append({"vehicle": name, "kind": kind, "vmin": lo, "vmax": hi, "certified": ok, "why": why,
                         "seconds": round(sec, 2)})
            print(f"{name:24s} {kind:6s} {lo:5.1f}-{hi:5.1f} m/s  {'certified' if ok else 'FAILS'}  {sec:5.1f} s"
                  + (f"  {why}" if why else ""), flush=True)
    if out is not None:
        out.write_text(json.dumps({"cases": rows}, indent=1) + "\n")
        print(f"written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
