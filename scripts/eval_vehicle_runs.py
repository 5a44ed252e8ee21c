"""The README's runs of other vehicles through the command line: sharp1971 through design, evaluate (TS, LQG,
LQR) and diagnose of a hidden road bank; the robot bicycle's lane change at 14 km/h (TS noise-free and at
5 %, LQG at 5 %). Writes the JSON and figures into OUT (``docs/results/vehicles`` in the repository).

Run: ``python scripts/eval_vehicle_runs.py OUT [--overwrite]`` (17 s on 2 cores, 2026-11-25).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.cli import main as cli  # noqa: E402
from _outputs import add_overwrite  # noqa: E402  (scripts/_outputs.py)

OUTPUTS = ("design_sharp1971.json", "evaluate_sharp1971.json", "evaluate_sharp1971.png", "evaluate_sharp1971_lqg.json",
           "evaluate_sharp1971_lqr.json", "diagnose_sharp1971_bank.json", "diagnose_sharp1971_bank.png", "estimate_sharp1971_worn.json",
           "evaluate_robot_bicycle_ts_noise0.json", "evaluate_robot_bicycle_ts_noise5.json",
           "evaluate_robot_bicycle_lqg_noise5.json")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", metavar="OUT")
    add_overwrite(ap)
    a = ap.parse_args(argv)
    out = Path(a.out)
    if not out.is_dir():
        ap.error(f"{out}: not a folder")
    clash = [n for n in OUTPUTS if (out / n).exists()]
    if clash and not a.overwrite:
        ap.error(f"{out} holds {', '.join(clash)}; pass --overwrite to replace them")
    ow = ["--overwrite"]
    with tempfile.TemporaryDirectory() as tmp:
        bank, worn = str(Path(tmp) / "bank.csv"), str(Path(tmp) / "worn.csv")
        def evaluate(vehicle: str, name: str, *extra: str) -> list[str]:
            return ["evaluate", "--vehicle", vehicle, *extra, "--json", str(out / name)]

        bike = ("--speed", "14")
        runs = [
            ["design", "--vehicle", "sharp1971", "--json", str(out / "design_sharp1971.json")],
            evaluate("sharp1971", "evaluate_sharp1971.json", "--noise", "5", "--plot", str(out / "evaluate_sharp1971.png")),
            evaluate("sharp1971", "evaluate_sharp1971_lqg.json", "--noise", "5", "--controller", "lqg"),
            evaluate("sharp1971", "evaluate_sharp1971_lqr.json", "--noise", "5", "--controller", "lqr"),
            ["simulate", "--vehicle", "sharp1971", "--scenario", "urban", "--noise", "5", "--seed", "3",
             "--effect", "road_bank:bank_rad=0.04", "--log", bank],
            ["diagnose", bank, "--no-progress", "--plot", str(out / "diagnose_sharp1971_bank.png"),
             "--json", str(out / "diagnose_sharp1971_bank.json")],
            ["simulate", "--vehicle", "sharp1971", "--scenario", "slalom", "--speed", "64.8", "--noise", "5",
             "--seed", "1", "--effect", "tire_stiffness:front_scale=0.8", "--effect", "tire_stiffness:rear_scale=0.8",
             "--log", worn],
            ["estimate", worn, "--json", str(out / "estimate_sharp1971_worn.json")],
            evaluate("robot-bicycle", "evaluate_robot_bicycle_ts_noise0.json", *bike, "--noise", "0"),
            evaluate("robot-bicycle", "evaluate_robot_bicycle_ts_noise5.json", *bike, "--noise", "5"),
            evaluate("robot-bicycle", "evaluate_robot_bicycle_lqg_noise5.json", *bike, "--noise", "5", "--controller", "lqg"),
        ]
        for argv_ in runs:
            t0 = time.perf_counter()
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf):
                rc = cli(argv_ + ow)
            print(f"$ ptw-assist {' '.join(argv_)}   ({time.perf_counter() - t0:.1f} s)")
            print("\n".join("    " + line for line in buf.getvalue().splitlines()[-6:]))
            if rc != 0:
                return rc
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
