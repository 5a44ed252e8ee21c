"""Closed-loop evaluation of the TS observer-based controller against LQG and the full-state bounds.

Every episode runs through ``env.step`` (:func:`assist.evaluate.run_episode`),
the TS and LQG controllers seeing only the noisy yaw rate, roll rate,
steering angle and rate; the two full-state bounds see the true state:
``lqr`` (:class:`assist.control.lqg.TrackingLQR`, the bound of the issue: tracking
LQR with the TS controller's reference feedforward) and ``ts_state`` (the
TS design's gains on the true state, observer bypassed: what the TS
controller would do with a perfect observer). Grid:

* controllers: ``ts`` designed on the paper's 10-20 m/s, ``ts`` on the wide
  8-33 m/s range, ``ts_state`` (8-33 m/s), ``lqg``, ``lqr`` (and ``rl`` with
  ``--rl`` when a policy exists);
* scenarios: double lane change at 50 and 100 km/h, constant radius with
  acceleration 50 -> 100 km/h, urban ride (8-25 m/s);
* sensor noise 0, 5, 10 % of each channel's range; seeds 0..S-1.

Writes ``table.md`` (the metrics table: roll RMSE and max, torque RMS and
peak, falls, estimation RMSE of every state), ``results.json`` (every
episode's metrics) and one figure per scenario at 5 % noise
(``<scenario>_<speed>.png``: roll vs reference vs estimate, torque, tracking
error, every state true vs estimated, the LQG and the LQR bound overlaid)
into ``--out``.

Run: ``python scripts/eval_controller.py --out out/controller [--seeds 3] [--quick]``.
"""

from __future__ import annotations

import argparse
import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from tqdm import tqdm  # noqa: E402

from assist.evaluate import aggregate, metrics_table, plot_episode, run_episode  # noqa: E402
from _outputs import add_overwrite, output_dir  # noqa: E402  (scripts/_outputs.py)

SCENARIOS = [
    ("double_lane_change", 50.0),
    ("double_lane_change", 100.0),
    ("constant_radius", None),
    ("urban", None),
]
CONTROLLERS = [
    ("ts", {"vmin": 10.0, "vmax": 20.0}, "ts (10-20 m/s)"),
    ("ts", {"vmin": 8.0, "vmax": 33.0}, "ts (8-33 m/s)"),
    ("ts_state", {"vmin": 8.0, "vmax": 33.0}, "ts_state (true state)"),
    ("lqg", {}, "lqg"),
    ("lqr", {}, "lqr (full-state bound)"),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/controller", help="output directory (created)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--noise", default="0,5,10", help="noise levels in percent, comma-separated")
    ap.add_argument("--quick", action="store_true", help="one seed, 5 %% noise only")
    ap.add_argument("--rl", action="store_true", help="include the shipped RL policy")
    add_overwrite(ap)
    args = ap.parse_args()
    out = output_dir(ap, args.out, args.overwrite)
    noises = [5.0] if args.quick else [float(s) for s in args.noise.split(",")]
    seeds = range(1 if args.quick else args.seeds)
    ctrls = CONTROLLERS + ([("rl", {}, "rl")] if args.rl else [])

    jobs = [(sc, sp, c, opt, label, nz) for sc, sp in SCENARIOS for nz in noises for c, opt, label in ctrls]
    rows, allm = [], []
    figs = {}
    for sc, sp, c, opt, label, nz in tqdm(jobs, desc="configurations"):
        eps = [run_episode(c, sc, speed_kmh=sp, noise_pct=nz, seed=s, controller_options=opt) for s in seeds]
        agg = aggregate(eps)
        agg["controller"] = label
        agg["speed_kmh"] = sp
        rows.append(agg)
        allm += [dict(e.metrics(), controller=label) for e in eps]
        if nz == 5.0 and c in ("ts", "lqg", "lqr"):
            figs.setdefault((sc, sp), {})[label] = eps[0]
    table = metrics_table(rows)
    (out / "table.md").write_text(table + "\n")
    (out / "results.json").write_text(json.dumps(allm, indent=1))
    for (sc, sp), d in figs.items():
        main_ep = d.get("ts (8-33 m/s)")
        if main_ep is None:
            continue
        others = [d[k] for k in ("lqg", "lqr (full-state bound)") if k in d]
        path = out / f"{sc}_{int(sp) if sp else 'profile'}.png"
        plt.close(plot_episode(main_ep, path, compare=others))
        print(f"figure: {path}")
    print(table)
    print(f"\nwritten to {out}/")


if __name__ == "__main__":
    main()
