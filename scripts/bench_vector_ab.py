"""Benchmark: the native vector env of this checkout against another checkout (an earlier commit), in the
same run.

Two versions of the package cannot live in one process, so each figure is one process per version, the two
run one after the other in alternating order (this one first, then the other first, ...): a drift of the
machine's speed then falls on both alike. Each process times ``gymnasium.make_vec("PTWRoll-v0", N,
vectorization_mode="vector_entry_point")`` with its own checkout's ``scripts/bench_vector.py``
``rate`` (random torques of a tenth of the box, 2100 steps with autoresets, best of 2). Prints each pair
and the ratio this / other, then the median ratio.

Run: ``git worktree add /tmp/old COMMIT && python scripts/bench_vector_ab.py /tmp/old [--pairs 6] [--envs 1024]
[--json OUT.json]``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)

sys.path.insert(0, str(ROOT))
from ptw_env.outputs import atomic_write_text  # noqa: E402

#: What each process runs: the checkout's own package and its own benchmark's ``rate``.
CHILD = """
import sys
root = sys.argv[1]
sys.path[:0] = [root, root + "/scripts"]
import gymnasium as gym, ptw_env
assert ptw_env.__file__.startswith(root), ptw_env.__file__
from bench_vector import rate
envs = gym.make_vec("PTWRoll-v0", num_envs=int(sys.argv[2]), vectorization_mode="vector_entry_point")
print(rate(envs, 2100, 2)[0])
"""


def one(root: Path, n: int) -> float:
    """env-steps/s of checkout ``root``'s native vector env at ``n`` envs, in a fresh process."""
    out = subprocess.run([sys.executable, "-c", CHILD, str(root), str(n)], capture_output=True, text=True)
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or [f"exit status {out.returncode}, nothing on stderr"])[-1]
        sys.exit(f"bench_vector_ab: the run of {root} failed:\n{last}")
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("other", help="the other checkout (a folder holding ptw_env/ and scripts/bench_vector.py)")
    ap.add_argument("--pairs", type=int, default=6, help="process pairs (default 6)")
    ap.add_argument("--envs", type=int, default=1024, help="number of envs (default 1024)")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    add_overwrite(ap)
    a = ap.parse_args()
    other = Path(a.other).resolve()
    if not ((other / "ptw_env" / "__init__.py").is_file() and (other / "scripts" / "bench_vector.py").is_file()):
        ap.error(f"{other} is not a checkout of this project (no ptw_env/ or scripts/bench_vector.py)")
    if a.pairs < 1 or a.envs < 1:
        ap.error(f"--pairs and --envs must be positive, got {a.pairs} and {a.envs}")
    out = output_file(ap, "--json", a.json, a.overwrite)
    rows = []
    for k in range(a.pairs):
        order = [ROOT, other] if k % 2 == 0 else [other, ROOT]
        got = {r: one(r, a.envs) for r in order}
        ratio = got[ROOT] / got[other]
        rows.append({"this": got[ROOT], "other": got[other], "ratio": ratio, "first": "this" if k % 2 == 0 else "other"})
        print(f"pair {k + 1} ({rows[-1]['first']} first): this {got[ROOT]:12,.0f}  other {got[other]:12,.0f} "
              f"env-steps/s  ratio {ratio:.3f}", flush=True)
    ratios = [r["ratio"] for r in rows]
    print(f"N = {a.envs}: this / other median {statistics.median(ratios):.3f}, range {min(ratios):.3f}-{max(ratios):.3f} "
          f"over {a.pairs} pairs ({ROOT} vs {other})")
    if out is not None:
        atomic_write_text(out, json.dumps({"envs": a.envs, "this": str(ROOT), "other": str(other), "pairs": rows,
                                   "median_ratio": statistics.median(ratios)}, indent=2) + "\n")


if __name__ == "__main__":
    main()
