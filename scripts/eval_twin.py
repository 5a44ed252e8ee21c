"""How well a digital twin's distribution holds the truth: simulated rides with a known hidden effect,
diagnosed and turned into a twin (:func:`assist.diagnose.twin.twin`); per fitted parameter the twin's
centre, its standard deviation and how many of them the truth lies away (a calibrated uncertainty has
|z| <= 2 about 95 % of the time).

Run: ``python scripts/eval_twin.py [--seeds 2] [--json OUT.json]`` (45 s rides, reference sensors; about
12 s per ride on 2 cores).
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
from assist.diagnose.twin import twin  # noqa: E402
from ptw_env.ride import ride_scenario  # noqa: E402
from ptw_env.scenarios import make_scenario  # noqa: E402
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)

CASES = [
    ("urban", {"payload": {"mass_kg": 40.0}}),
    ("handling", {"road_bank": {"bank_rad": -0.04}}),
    ("urban", {"tire_stiffness": {"front_scale": 0.7, "rear_scale": 0.7}}),
    ("urban", {"roll_moment_offset": {"moment_nm": 25.0}}),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=2, help="rides per case, seeds 100, 101, ... (default 2)")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    add_overwrite(ap)
    args = ap.parse_args()
    if not 1 <= args.seeds <= 50:
        ap.error(f"--seeds must be in [1, 50], got {args.seeds}")
    out = output_file(ap, "--json", args.json, args.overwrite)
    rows = []
    print(f"{'effect':38s} {'seed':>4s} {'truth':>9s} {'twin centre':>12s} {'twin std':>10s} {'z':>6s}")
    for scenario, eff in CASES:
        for seed in range(100, 100 + args.seeds):
            t0 = time.perf_counter()
            log = ride_scenario(make_scenario(scenario, duration_s=45.0), effects=eff, seed=seed).log
            tw = twin(diagnose(log, progress=False))
            for cause, ps in eff.items():
                for p, truth in ps.items():
                    d = tw["randomize"].get(f"{cause}:{p}")
                    if not isinstance(d, list):
                        rows.append({"effect": f"{cause}:{p}", "seed": seed, "truth": truth, "found": False})
                        print(f"{cause}:{p:26s} {seed:4d} {truth:9.4g}  not in the twin: {sorted(tw['randomize'])}")
                        continue
                    _, c, sd = d
                    if not sd > 0:  # a std that rounds to 0: no z to give
                        rows.append({"effect": f"{cause}:{p}", "seed": seed, "truth": truth, "centre": c, "std": sd,
                                     "found": True, "z": None})
                        print(f"{cause + ':' + p:38s} {seed:4d} {truth:9.4g} {c:12.5g} {sd:10.3g}  (std 0)")
                        continue
                    z = (truth - c) / sd
                    rows.append({"effect": f"{cause}:{p}", "seed": seed, "truth": truth, "centre": c, "std": sd,
                                 "z": z, "seconds": time.perf_counter() - t0, "found": True})
                    print(f"{cause + ':' + p:38s} {seed:4d} {truth:9.4g} {c:12.5g} {sd:10.3g} {z:6.2f}")
    zs = [abs(r["z"]) for r in rows if r["found"] and r.get("z") is not None]
    within = sum(z <= 2 for z in zs)
    if zs:
        print(f"|z| <= 2 in {within} of {len(zs)} parameters (a calibrated std: about 95 %); largest |z| {max(zs):.2f}")
    else:
        print("no parameter of the hidden effects was found in a twin")
    if out is not None:
        out.write_text(json.dumps({"rows": rows, "within_2_std": within, "n": len(zs)}, indent=2, allow_nan=False) + "\n")


if __name__ == "__main__":
    main()
