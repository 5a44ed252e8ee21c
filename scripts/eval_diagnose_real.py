"""Diagnose every real ride log of a folder (default ``shared/data/robot_bicycle/``) and tabulate the result.

For each log: :func:`assist.diagnose.diagnose` with the vehicle its sidecar names (the robot
bicycle's own file), the report JSON and figure, and one row of the table: what was trimmed,
the nominal held-out residual per channel against the noise, the effects.md verdict, the model
extension (closure terms with their fitted coefficients and 1-sigma), the held-out gains, and
whether the best model explains the log to within the noise.

Across runs (issue 19: does a closure describe the bicycle or one ride?): each run's model, frozen,
is scored on every other run with :func:`assist.diagnose.score_model` (nothing fitted on the scored
run but each window's initial state; gain ``1 - sqrt(S_model / S_nominal)`` as within a run), three
ways: the reported model (the extension when there is one) with every fitted value, the same with
its sensor parameters back at nominal (offsets, scales, biases and delays belong to one ride's
instruments), and the effects.md verdict alone. ``cross_run.png`` shows the first two matrices.

Usage::

    python scripts/eval_diagnose_real.py [--data DIR] [--out OUT_DIR] [--overwrite]

Writes ``OUT_DIR/table.md``, ``OUT_DIR/results.json``, ``OUT_DIR/<run>.png`` and
``OUT_DIR/cross_run.png`` (default ``out/diagnose_real/``). About 1.6 minutes for the 14 runs on an idle
2-core machine (diagnoses, 546 cross-run scores and the hand fits).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _outputs import add_overwrite, output_dir, shared_data  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=None, help="folder of ride logs (default shared/data/robot_bicycle)")
    ap.add_argument("--out", default="out/diagnose_real", help="output folder")
    add_overwrite(ap)
    a = ap.parse_args(argv)
    data = Path(a.data) if a.data else shared_data("robot_bicycle")
    paths = sorted(data.glob("*.csv"))
    if not paths:
        ap.error(f"no .csv ride log in {data}")
    out = output_dir(ap, a.out, a.overwrite)

    from assist.diagnose import diagnose, score_model
    from assist.diagnose.inverse_dynamics import steer_equation_fit
    from assist.diagnose.measurement import UNITS
    from ptw_env.logs import read_log

    t_all = time.perf_counter()
    rows, reports, logs = [], [], []
    for p in paths:
        log = read_log(p)
        t0 = time.perf_counter()
        rep = diagnose(log, progress=False)
        reports.append(rep)
        logs.append(log)
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
            "nominal_rmse": js["nominal"]["rmse"], "noise": js["noise"],
            "notes": js["method"].get("notes", []),
            # the hand fit: the lean from the firmware's complementary filter (the logs have no roll column)
            "hand_fit": steer_equation_fit(log, rep.vehicle, roll=log.columns.get("roll_cf")),
            "hand_fit_inertia": steer_equation_fit(log, rep.vehicle, roll=log.columns.get("roll_cf"),
                                                   terms=("damping", "inertia", "offset")),
            "diagnosed_added_damping_nms": diagnosed_damping(rep),
        })
        print(f"{p.stem}: {rows[-1]['verdict']} gain {rows[-1]['gain']:.3f}; extension "
              f"{rows[-1]['extension']} gain {rows[-1]['extension_gain']}; {sec:.1f} s", flush=True)

    # across runs: every run's model, frozen, on every other run
    t0 = time.perf_counter()
    ways = {"reported_all": ("reported", "all"), "reported_vehicle": ("reported", "vehicle"),
            "verdict_all": ("verdict", "all")}
    G = {w: np.full((len(paths), len(paths)), np.nan) for w in ways}
    for i, rep in enumerate(reports):
        for j, log in enumerate(logs):
            if i != j:
                for w, (model, parts) in ways.items():
                    G[w][i, j] = score_model(log, rep, model=model, parts=parts).gain
    cross_s = time.perf_counter() - t0
    off = ~np.eye(len(paths), dtype=bool)
    def gains(g: np.ndarray, mask: np.ndarray) -> dict:
        """Mean, median and min of the gains ``g[mask]``; a transfer whose replay diverged (gain -inf) is
        counted as diverged, left out of the mean, median and min (None when every one diverged)."""
        fin = g[mask & np.isfinite(g)]
        return {"mean": float(np.mean(fin)) if fin.size else None, "median": float(np.median(fin)) if fin.size else None,
                "min": float(np.min(fin)) if fin.size else None, "positive": int(np.sum(g[mask] > 0)),
                "diverged": int(np.sum(mask & ~np.isfinite(g))), "pairs": int(mask.sum())}

    def num(v: float | None) -> str:
        return "-" if v is None else f"{v:.3f}"

    cross = {w: {"matrix_from_row_on_column": [[None if not np.isfinite(v) else round(float(v), 4) for v in row]
                                               for row in g], **gains(g, off),
                 # per run: its model on every other run (does each run's model carry over, not only most pairs?)
                 "per_run": {p.stem: gains(g[i], off[i]) for i, p in enumerate(paths)}} for w, g in G.items()}
    extended_rows = [i for i, r in enumerate(rows) if r["extension"]]
    ext_off = np.zeros_like(off)
    ext_off[extended_rows] = True
    ext_off &= off & np.isfinite(G["reported_all"]) & np.isfinite(G["verdict_all"])
    cross["extension_beats_verdict"] = {"pairs": int(ext_off.sum()),
                                        "better": int(np.sum(G["reported_all"][ext_off] > G["verdict_all"][ext_off])),
                                        "median_difference": float(np.median(G["reported_all"][ext_off]
                                                                             - G["verdict_all"][ext_off]))
                                        if ext_off.any() else None}
    _plot_cross(G, [p.stem for p in paths], out / "cross_run.png")

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
        lines.append(f"| [{r['run']}]({r['run']}.png) | {r['duration_s']} | {'; '.join(r['verdict'])} | {r['gain']:.3f} | "
                     f"{ext} | {eg} | {expl} | {r['seconds']} |")
    chans = list(rows[0]["nominal_rmse"])
    lines += ["", "The nominal model's held-out error per channel: RMS residual [unit] and, in brackets, in noise levels "
                  "(the noise level each report estimated); the figure of each run (linked above) draws the nominal and "
                  "the reported model on the two channels the latter improves most.", "",
              "| run | " + " | ".join(f"{c} [{UNITS[c]}]" for c in chans) + " |", "|---|" + "---|" * len(chans)]
    for r in rows:
        lines.append(f"| {r['run']} | " + " | ".join(f"{r['nominal_rmse'][c]:.3g} ({r['nominal_rmse'][c] / r['noise'][c]:.1f})"
                                                    for c in chans) + " |")
    lines += ["", f"## Across runs ({cross_s:.0f} s, [figure](cross_run.png))", "",
              "Each run's model, frozen, scored on each of the other runs (every window held out; "
              "`assist.diagnose.score_model`). Gain over the nominal model, over the "
              f"{cross['reported_all']['pairs']} ordered pairs:", "",
              "| model carried over | median | min | pairs with a positive gain | diverged |", "|---|---|---|---|---|"]
    for w, label in (("reported_all", "reported model (extension if any), every fitted value"),
                     ("reported_vehicle", "the same, sensor parameters at nominal"),
                     ("verdict_all", "effects.md verdict alone")):
        c = cross[w]
        lines.append(f"| {label} | {num(c['median'])} | {num(c['min'])} | {c['positive']} of {c['pairs']} | {c['diverged']} |")
    lines += ["", "Per run: its reported model (every fitted value) on each of the other runs, and with its sensor "
                  "parameters at nominal:", "",
              "| run | mean gain | median | min | positive | mean, sensors at nominal | positive |", "|---|---|---|---|---|---|---|"]
    for p in paths:
        a, b = cross["reported_all"]["per_run"][p.stem], cross["reported_vehicle"]["per_run"][p.stem]
        div = f" ({a['diverged']} diverged)" if a["diverged"] else ""
        lines.append(f"| {p.stem} | {num(a['mean'])} | {num(a['median'])} | {num(a['min'])} | {a['positive']} of "
                     f"{a['pairs']}{div} | {num(b['mean'])} | {b['positive']} of {b['pairs']} |")
    eb = cross["extension_beats_verdict"]
    if eb["pairs"]:
        lines += ["", f"From the {len(extended_rows)} extended runs: the extension predicts the other run better than "
                      f"its own effects.md verdict in {eb['better']} of {eb['pairs']} pairs (median difference "
                      f"{eb['median_difference']:+.4f})."]
    lines += ["", "## By hand: inverse dynamics of the steer equation", "",
              "`assist.diagnose.inverse_dynamics.steer_equation_fit`: every term of the steer row from the measured "
              "signals (lean from `roll_cf`, derivatives by Savitzky-Golay, axle forces from the lateral and yaw rows "
              "and `ay`), the residual torque regressed on `[-delta_dot, 1]`. Damping added to the vehicle file's "
              "[N m s/rad]; R^2 is the share of the steer-row residual the fit explains.", "",
              "| run | hand fit: damping | offset N m | R^2 | residual rms N m | with a steer inertia J: J kg m^2, R^2 | "
              "diagnose: damping (verdict + closure) |",
              "|---|---|---|---|---|---|---|"]
    for r in rows:
        h, hj = r["hand_fit"], r["hand_fit_inertia"]
        lines.append(f"| {r['run']} | {h['damping_nms']:.2f} +- {h['damping_std']:.2f} | {h['offset_nm']:+.3f} | "
                     f"{h['r2']:.2f} | {h['residual_rms_nm']:.2f} | {hj['inertia_kgm2']:+.3f} +- {hj['inertia_std']:.3f}, "
                     f"{hj['r2']:.2f} | {r['diagnosed_added_damping_nms']:.2f} |")
    notes = sorted({n for r in rows for n in r["notes"]})
    if notes:
        lines += ["", "Notes the reports gave (trimming, thin evidence):", ""] + [f"- {n}" for n in notes]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    (out / "results.json").write_text(json.dumps({"data": str(data), "rows": rows, "cross_run": cross},
                                                 indent=1, allow_nan=False, default=float) + "\n")
    print("\n".join(lines))
    print(f"written to {out}/")
    return 0


def diagnosed_damping(report) -> float:
    """The viscous steering damping the reported model adds to the vehicle file's [N m s/rad]: effects.md's
    ``steer_damping`` above nominal plus the ``steer_viscous`` closure (a generalised force ``c delta_dot``, so ``-c``)."""
    from assist.diagnose.params import CAUSES, CLOSURE_INDEX, param_set

    z, i = report.model_z, CAUSES["steer_damping"][0]
    return float(z[i] - param_set(report.vehicle).params[i].nominal - z[CLOSURE_INDEX["steer_viscous"]])


def _plot_cross(G: dict, names: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    short = [n.replace("rb_", "") for n in names]
    fig, axs = plt.subplots(1, 2, figsize=(13, 5.6), constrained_layout=True)
    for ax, (w, title) in zip(axs, (("reported_all", "reported model, every fitted value"),
                                    ("reported_vehicle", "reported model, sensor parameters at nominal"))):
        g = np.ma.masked_invalid(np.where(np.eye(len(names), dtype=bool), np.nan, G[w]))
        cmap = plt.get_cmap("RdBu").copy()
        cmap.set_bad("0.8")  # the diagonal (a run on itself is the within-run score of the table)
        im = ax.imshow(g, vmin=-1.0, vmax=1.0, cmap=cmap)
        ax.set_xticks(range(len(names)), short, rotation=70, fontsize=7)
        ax.set_yticks(range(len(names)), short, fontsize=7)
        ax.set(xlabel="scored on run", ylabel="model fitted on run", title=title)
        for i in range(len(names)):
            for j in range(len(names)):
                if i != j and np.isfinite(G[w][i, j]):
                    ax.text(j, i, f"{G[w][i, j]:.2f}", ha="center", va="center", fontsize=5)
    fig.colorbar(im, ax=axs, label="held-out gain over the nominal model")
    fig.suptitle("robot bicycle: one run's diagnosed model on the other runs")
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
