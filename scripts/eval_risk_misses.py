"""The risk warning's misses judged again with more noise draws of the observation oracle (issue 20).

``scripts/eval_risk.py`` judges the observation oracle (:func:`assist.risk.evaluation.observation_evidence`) on
5 draws per ride (the ride's own sensors and 4 rides of the same case with other sensor and rider noise): it
could where at least half of them reach its threshold. Where the warning missed a target that an oracle could
meet, 5 draws say little when one of them sits near the threshold. This script takes the stored results of
such runs, finds those misses (a loss of grip 1 s or more after the drop not cautioned 0.5 s ahead, or a loaded
patch not cautioned within 0.3 s, where the sequential or the observation oracle could at the run's own
thresholds) and rides each of those cases ``--draws`` times (default 25; the first 5 draws are the stored ones,
checked), at both of the run's thresholds: the simulated one and the one held to measured rides.

Usage::

    python scripts/eval_risk_misses.py docs/results/risk/results.json docs/results/risk/fresh_seeds_*/results.json \\
        --workers 2 --out docs/results/risk/misses
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from ptw_env.jobs import JobsError, run_jobs

from assist.risk.evaluation import (LATENCY_LOAD, LATENCY_S, OBSERVATION_DRAWS, make_case, oracle_could, oracle_share,
                                    run_case)
from _outputs import add_overwrite, output_dir, write_results  # noqa: E402  (scripts/_outputs.py)


def misses(res: dict) -> list[dict]:
    """The misses of one stored run (``results.json`` of ``scripts/eval_risk.py``) where an oracle could at the
    run's thresholds: the lead misses its targets list with ``sequential_could`` or ``observation_could``, and the
    loaded patches not cautioned within ``LATENCY_S`` where an oracle could: ``[{"kind", "seed", "target", "t",
    "stored"}]`` (``stored``: the observation oracle's stored largest evidence per draw)."""
    tg = res["targets"]
    h, ho = tg["_sequential_oracle"]["threshold_nats"], tg["_observation_oracle"]["threshold_nats"]
    rides = {(r["kind"], r["seed"]): r for r in res["rides"]}
    out = []
    for kind in ("wet_straight", "wet_corner"):
        for m in (tg.get(kind, {}).get("lead") or {}).get("missed", []):
            if m["sequential_could"] or m["observation_could"]:
                e = min(rides[(kind, m["seed"])]["events"], key=lambda e: abs(e["t"] - m["t"]))
                out.append({"kind": kind, "seed": m["seed"], "target": "lead", "t": e["t"],
                            "stored": e["observation_max"]})
        for (k, seed), r in rides.items():
            la = r.get("latency")
            if k == kind and la and la["load_at_reference"] >= LATENCY_LOAD and not (
                    la["caution_after_s"] is not None and la["caution_after_s"] <= LATENCY_S) and (
                    oracle_could(la.get("sequential_max"), h) or oracle_could(la.get("observation_max"), ho)):
                out.append({"kind": k, "seed": seed, "target": "latency", "t": None, "stored": la["observation_max"]})
    return out


def _one(kind: str, seed: int, scaling: str, draws: int, ts: list) -> dict:
    """Ride one case, its observation oracle on ``draws`` draws; the largest evidence per draw at each loss of
    grip at ``ts`` (lead windows; None: the latency window)."""
    res = run_case(make_case(kind, seed, scaling))
    s = res.summary(observation=True, draws=draws)
    out = {}
    for t in ts:
        if t is None:
            out["latency"] = s["latency"]["observation_max"]
        else:
            e = min(s["events"], key=lambda e: abs(e["t"] - t))
            out[repr(round(t, 3))] = e["observation_max"]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog="example: python scripts/eval_risk_misses.py docs/results/risk/results.json")
    p.add_argument("results", nargs="+", help="results.json of scripts/eval_risk.py runs")
    p.add_argument("--draws", type=int, default=25, help="noise draws per miss (default 25; at least the "
                                                          f"{OBSERVATION_DRAWS} stored)")
    p.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a Dask scheduler tcp://HOST:PORT or 'local'")
    p.add_argument("--out", default="out/risk_misses", help="output directory (default out/risk_misses/)")
    add_overwrite(p)
    a = p.parse_args(argv)
    if not OBSERVATION_DRAWS <= a.draws <= 1000:
        p.error(f"--draws must be in [{OBSERVATION_DRAWS}, 1000], got {a.draws}")
    if a.workers < 1:
        p.error(f"--workers must be >= 1, got {a.workers}")
    runs = []
    for path in a.results:  # every file read before the rides: one that is not a run stops here
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            p.error(f"{path}: cannot be read ({getattr(e, 'strerror', None) or e})")
        try:
            res = json.loads(text)
            oo = res["targets"]["_observation_oracle"]
            ho, hr = float(oo["threshold_nats"]), oo.get("real_threshold_nats")
            found = misses(res)
        except (OSError, ValueError, KeyError, TypeError) as e:
            p.error(f"{path}: not the results.json of a scripts/eval_risk.py run with the observation oracle ({e!r})")
        if hr is None:
            p.error(f"{path}: no threshold held to measured rides (run scripts/eval_risk.py with --real)")
        runs.append({"results": str(path), "scaling": res.get("scaling", "peak"), "threshold_nats": ho,
                     "real_threshold_nats": float(hr), "misses": found})
    out = output_dir(p, a.out, a.overwrite)
    cases: dict = {}
    for r in runs:
        for m in r["misses"]:
            cases.setdefault((m["kind"], m["seed"], r["scaling"]), []).append(m["t"])
    t0 = time.perf_counter()
    try:
        done = run_jobs(_one, [(k, (k[0], k[1], k[2], a.draws, ts)) for k, ts in cases.items()], workers=a.workers,
                        scheduler=a.scheduler, desc="cases")
    except JobsError as e:
        p.error(str(e))
    rows = []
    for r in runs:
        for m in r["misses"]:
            got = done[(m["kind"], m["seed"], r["scaling"])]["latency" if m["t"] is None else repr(round(m["t"], 3))]
            if not np.allclose(got[:len(m["stored"])], m["stored"], atol=0.011):  # stored to 0.01 nats
                p.error(f"{r['results']}: {m['kind']} {m['seed']}: the first draws {got[:len(m['stored'])]} are not "
                        f"the stored {m['stored']} (another version of the code?)")
            rows.append({**m, "results": r["results"], "draws": len(got), "maxima": got,
                         "share_at_threshold": oracle_share(got, r["threshold_nats"]), "threshold_nats": r["threshold_nats"],
                         "share_held": oracle_share(got, r["real_threshold_nats"]),
                         "real_threshold_nats": r["real_threshold_nats"]})
    doc = {"draws": a.draws, "runs": [{k: v for k, v in r.items() if k != "misses"} for r in runs], "misses": rows,
           "seconds": round(time.perf_counter() - t0, 1)}
    lines = [f"Misses of the risk warning where an oracle could, the observation oracle on {a.draws} noise draws "
             f"(the first {OBSERVATION_DRAWS} the stored ones); it could where at least half of them reach the "
             "threshold.", "",
             "| ride | seed | target | draws at or above the simulated threshold | at or above the threshold held to "
             "measured rides | largest per draw [nats]: median (min-max) |", "|---|---|---|---|---|---|"]
    for m in rows:
        g = np.asarray(m["maxima"])
        at = "" if m["t"] is None else f" (t {m['t']:.2f} s)"
        lines.append(f"| {m['kind']} | {m['seed']} | {m['target']}{at} "
                     f"| {int(round(m['share_at_threshold'] * m['draws']))} of {m['draws']} ({m['threshold_nats']:g}) "
                     f"| {int(round(m['share_held'] * m['draws']))} of {m['draws']} ({m['real_threshold_nats']:g}) "
                     f"| {np.median(g):.2f} ({g.min():.2f}-{g.max():.2f}) |")
    write_results(out, doc, "\n".join(lines) + "\n", f"{len(rows)} misses in {doc['seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
