"""Tire saturation vs a lower cornering stiffness (issue 19, item 4): which one the diagnosis names,
or whether it says "ambiguous between them", on rides with one of them hidden.

Cases (45 s rides, reference sensors, noise on, ``pairs=False`` as the tests): the slalom with
saturation at mu_peak 0.6; a steady turn at
28 m/s (``constant_radius``) with saturation at mu_peak 0.6 (the ride slides out), 0.8 and 1.5, a
stiffness change of 0.8 and nothing hidden; the ``handling`` ride with saturation 0.6. Per ride: the
verdict, whether it is ambiguous (and with what), the held-out improvement of the saturation and of
the stiffness hypothesis (noise variances per value), whether the ride fell and the log's length [s]
(a ride that falls ends there).

Run: ``python scripts/eval_saturation.py [--seeds 61 63 64] [--json OUT.json]`` (about 5 min on 2 cores
for the default seeds).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.diagnose import diagnose  # noqa: E402
from assist.diagnose.report import causes_text  # noqa: E402
from ptw_env.outputs import atomic_write_text  # noqa: E402
from ptw_env.ride import ride_scenario  # noqa: E402
from ptw_env.scenarios import make_scenario  # noqa: E402
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)

CASES = [
    ("slalom", {"tire_saturation": {"mu_peak": 0.6}}),
    ("constant_radius", {"tire_saturation": {"mu_peak": 0.6}}),
    ("constant_radius", {"tire_saturation": {"mu_peak": 0.8}}),
    ("constant_radius", {"tire_saturation": {"mu_peak": 1.5}}),
    ("constant_radius", {"tire_stiffness": {"front_scale": 0.8, "rear_scale": 0.8}}),
    ("constant_radius", None),
    ("handling", {"tire_saturation": {"mu_peak": 0.6}}),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[61, 63, 64], help="ride seeds (default 61 63 64)")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    add_overwrite(ap)
    args = ap.parse_args()
    out = output_file(ap, "--json", args.json, args.overwrite)
    rows = []
    print(f"{'ride':16s} {'hidden':44s} {'seed':>4s} {'fell':>5s} {'log s':>5s}  {'verdict':52s} {'imp sat':>8s} {'imp stiff':>9s}  ambiguous")
    for scenario, eff in CASES:
        for seed in args.seeds:
            t0 = time.perf_counter()
            log = ride_scenario(make_scenario(scenario, duration_s=45.0), effects=eff, seed=seed).log
            rep = diagnose(log, pairs=False, progress=False)
            imp = {"+".join(c["cause"] for c in h["causes"]): h["improvement"] for h in rep.hypotheses}
            amb = rep.ambiguous
            row = {"ride": scenario, "hidden": eff or {}, "seed": seed, "fell": bool(log.meta.get("fell")),
                   "log_s": round(float(log.duration_s), 2),
                   "verdict": rep.causes, "explained": rep.explained,
                   "improvement_saturation": imp.get("tire_saturation"), "improvement_stiffness": imp.get("tire_stiffness"),
                   "ambiguous": amb, "seconds": round(time.perf_counter() - t0, 1)}
            rows.append(row)
            hidden = causes_text([{"cause": c, "params": p} for c, p in (eff or {}).items()]) or "none"
            amb_s = (f"{amb['separation_margin']:+.4f} between {' and '.join(causes_text(b) for b in amb['between'])}"
                     if amb else "-")
            print(f"{scenario:16s} {hidden:44s} {seed:4d} {str(row['fell']):>5s} {row['log_s']:5.1f}  {causes_text(rep.causes):52s} "
                  f"{row['improvement_saturation']:8.4f} {row['improvement_stiffness']:9.4f}  {amb_s}", flush=True)
    if out is not None:
        atomic_write_text(out, json.dumps({"command": "python scripts/eval_saturation.py " + " ".join(sys.argv[1:]),
                                   "rows": rows}, indent=1, allow_nan=False))


if __name__ == "__main__":
    main()
