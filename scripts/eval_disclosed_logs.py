"""``ptw-assist estimate`` on the disclosed logs of ``shared/data``, both adaptive-observer designs.

For each log (nominal_urban, friction_urban, nominal_urban_noiseless, bank_lane_change with its known bank
from the sidecar) the default design (Kalman vertex gains, one scale per axle) and the paper's Theorem-2
design with four stiffnesses; the table is the command's own output (estimate, C/C0, sidecar truth, error).

Run: ``python scripts/eval_disclosed_logs.py OUT.md [--data DIR] [--overwrite]`` (4 s on 2 cores, 2026-11-25).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import io
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.cli import main as cli  # noqa: E402
from ptw_env.outputs import atomic_write_text  # noqa: E402
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)

LOGS = ("nominal_urban.csv", "friction_urban.csv", "nominal_urban_noiseless.csv", "bank_lane_change.csv")
DESIGNS = ((), ("--gains", "theorem2", "--parametrisation", "stiffness"))


def _bank(log: Path) -> tuple[str, ...]:
    """``--road-bank B`` when the sidecar's truth holds a road bank (the known bank of the road)."""
    meta = json.loads(log.with_suffix(".json").read_text())
    for c in meta.get("truth", {}).get("causes", []):
        if c.get("cause") == "road_bank":
            return ("--road-bank", repr(float(c["params"]["bank_rad"])))
    return ()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", metavar="OUT.md")
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"), metavar="DIR",
                    help="folder of the disclosed logs (default ../shared/data)")
    add_overwrite(ap)
    a = ap.parse_args(argv)
    out = output_file(ap, "OUT.md", a.out, a.overwrite)
    data = Path(a.data)
    missing = [n for n in LOGS if not (data / n).is_file()]
    if missing:
        ap.error(f"--data {data}: missing {', '.join(missing)}")
    lines = [f"# ptw-assist estimate on the disclosed logs (shared/data), {datetime.date.today()}", "",
             "Final estimate vs the sidecar's truth (columns: estimate, scale, truth, error). Made by "
             "`python scripts/eval_disclosed_logs.py`; bank_lane_change is given its known bank (--road-bank, "
             "from its sidecar).", ""]
    for design in DESIGNS:
        lines += [f"## ptw-assist estimate LOG {' '.join(design)}", ""]
        for name in LOGS:
            log = data / name
            extra = _bank(log)
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf):
                rc = cli(["estimate", str(log), *design, *extra])
            if rc != 0:
                print(buf.getvalue(), file=sys.stderr)
                return rc
            text = buf.getvalue().splitlines()
            keep = [t for t in text if t.startswith(("design:", "C_")) or "observer scheduled" in t]
            lines += [f"### {name} {' '.join(extra)}", "```", *keep, "```", ""]
            print(f"{name} {' '.join(design + extra)}: done", file=sys.stderr)
    atomic_write_text(out, "\n".join(lines))
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
