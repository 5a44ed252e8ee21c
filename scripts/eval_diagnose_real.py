"""Diagnose every real ride log of a folder (default ``shared/data/robot_bicycle/``) and tabulate the result.

For each log: :func:`assist.diagnose.diagnose` with the vehicle its sidecar names (the robot
bicycle's own file), the report JSON and figure, and one row of the table: what was trimmed,
the nominal held-out residual per channel against the noise, the effects.md verdict, the model
extension (closure terms with their fitted coefficients and 1-sigma), the held-out gains, and
whether the best model explains the log to within the noise.

Not yet here: scoring one run's extension, frozen, on the other runs (whether a closure describes
the bicycle or one ride); each run's gain is held-out within that run only.

Usage::

    python scripts/eval_diagnose_real.py [--data DIR] [--out OUT_DIR] [--overwrite]

Writes ``OUT_DIR/table.md``, ``OUT_DIR/results.json`` and ``OUT_DIR/<run>.png`` (default
``out/diagnose_real/``). About 2 minutes for the 14 runs on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _outputs import add_overwrite, output_dir  # noqa: E402


def _default_data() -> Path:
    for c in (os.environ.get("PTW_SHARED_DIR"), ROOT.parent / "shared", Path("/work/shared")):
        if c and (Path(c) / "data" / "robot_bicycle").is_dir():
            return Path(c) / "data" / "robot_bicycle"
    raise SystemExit("shared/data/robot_bicycle not found; pass --data or set PTW_SHARED_DIR")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=None, help="folder of ride logs (default shared/data/robot_bicycle)")
    ap.add_argument("--out", default="out/diagnose_real", help="output folder")
    add_overwrite(ap)
    a = ap.parse_args(argv)
    data = Path(a.data) if a.data else _default_data()
    paths = sorted(data.glob("*.csv"))
    if not paths:
        ap.error(f"no .csv ride log in {data}")
    out = output_dir(ap, a.out, a.overwrite)

    from assist.diagnose import diagnose
    from ptw_env.logs import read_log

    t_all = time.perf_counter()
    rows = []
    for p in paths:
        log = read_log(p)
        t0 = time.perf_counter()
        rep = diagnose(log, progress=False)
        sec = time.perf_counter() - t0
        rep.plot(out / f"{p.stem}.png")
        js = rep.to_json()
        (out / f"{p.stem}.json").write_text(json.dumps(js, indent=1, allow_nan=False) + "\n")
        ext = js["verdict"].get("extension")
        rows.append({
            "run": p.stem, "seconds": round(sec, 1), "duration_s": round(log.duration_s, 1),
            "vehicle": js["vehicle"]["name"],
            "verdict": [f"{c['cause']}(" + ", ".join(f"{k}={v:.3g}" for k, v in c["params"].items()) + ")"
                        for c in js["verdict"]["causes"]],
            "gain": js["verdict"]["gain"], "explained": js["verdict"]["explained"],
            "extension": None if ext is None else [f"{t['name']}: c = {t['coefficient']:.3g} +- {t['std']:.2g} {t['unit']}"
                                                   if t["std"] is not None else f"{t['name']}: c = {t['coefficient']:.3g} {t['unit']}"
                                                   for t in ext["terms"]],
            "extension_gain": None if ext is None else ext["gain"],
            "extended_explains": js["verdict"].get("extended", False),
            "notes": js["method"].get("notes", []),
        })
        print(f"{p.stem}: {rows[-1]['verdict']} gain {rows[-1]['gain']:.3f}; extension "
              f"{rows[-1]['extension']} gain {rows[-1]['extension_gain']}; {sec:.1f} s", flush=True)

    lines = [f"# diagnose on the real rides of {data.name}", "",
             f"`python scripts/eval_diagnose_real.py` ({time.perf_counter() - t_all:.0f} s). Vehicle: the sidecars' "
             f"({rows[0]['vehicle']}). Gains are held-out (alternate windows of the same run).", "",
             "| run | s of log | effects.md verdict | gain | extension (beyond effects.md) | gain | explained | "
             "diagnose s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ext = "; ".join(r["extension"]) if r["extension"] else "-"
        eg = "-" if r["extension_gain"] is None else f"{r['extension_gain']:.3f}"
        expl = "yes" if (r["explained"] or r["extended_explains"]) else "no"
        lines.append(f"| {r['run']} | {r['duration_s']} | {'; '.join(r['verdict'])} | {r['gain']:.3f} | {ext} | {eg} | "
                     f"{expl} | {r['seconds']} |")
    notes = sorted({n for r in rows for n in r["notes"]})
    if notes:
        lines += ["", "Notes the reports gave (trimming, thin evidence):", ""] + [f"- {n}" for n in notes]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    (out / "results.json").write_text(json.dumps({"data": str(data), "rows": rows},
                                                 indent=1, allow_nan=False, default=float) + "\n")
    print("\n".join(lines))
    print(f"written to {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
