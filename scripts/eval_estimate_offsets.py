"""Sensor offsets as nuisance parameters of ``ptw-assist estimate`` (issue 19, item 1): what the joint EKF
finds, what ``estimate`` removes, and what that does to the stiffness estimate.

* Simulated rides (reference scooter, reference sensors, tire stiffness 0.8 of nominal: the truth), each
  once clean and once with constant offsets added to the logged steering angle, both gyros and the lateral
  accelerometer (the noise kept), drawn from a generator seeded with the ride's seed (uniform, up to 0.02 rad,
  0.03 rad/s, 0.03 rad/s and 0.5 m/s^2; the same offsets on each ride of one seed): ``ptw-assist estimate`` with its defaults (offsets estimated, the
  significant ones removed where the filter with them explains the log) on the clean and the offset log, and
  with ``--offsets none`` on the offset log. Rides and seeds fixed before the first run: urban, handling and
  the double lane change at seeds 300 and 301, 60 s each.
* Drifts: the same rides once more with each offset a line over the log, from a start drawn uniform in
  +-half the span above to an end drawn in +-the span (drawn after the constant offsets from the same
  generator): the drift rate found, whether ``estimate`` used the drifting filter and removed the lines, and
  the stiffness against the clean log's; and how often a drift is used on the clean and constant-offset logs.
* The disclosed logs of ``shared/data`` (truth in the sidecars), with the defaults and with ``--offsets none``;
  the banked one also with ``--road-bank`` at its true bank.
* The robot bicycle's measured rides (``shared/data/robot_bicycle``): what the filter reads as offsets, how
  well the model with them explains the log, and whether ``estimate`` removed them.

Run: ``python scripts/eval_estimate_offsets.py [--json OUT.json]`` (well under a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import assist.cli.estimate  # noqa: E402,F401  (registers the subcommand)
from assist.cli import main as cli  # noqa: E402
from assist.estimation.identification import OFFSET_CHANNELS, OFFSET_SIGNIFICANCE  # noqa: E402
from ptw_env.logs import RideLog, write_log  # noqa: E402
from ptw_env.ride import ride_scenario  # noqa: E402
from ptw_env.scenarios import make_scenario  # noqa: E402
from _outputs import add_overwrite, output_file, shared_data  # noqa: E402  (scripts/_outputs.py)

RIDES = ("urban", "handling", "double_lane_change")
SEEDS = (300, 301)
SCALE = 0.8
#: Largest offset drawn per channel (uniform in +-this).
SPAN = {"delta": 0.02, "yaw_rate": 0.03, "roll_rate": 0.03, "ay": 0.5}


def run_estimate(path: Path, *extra: str) -> dict:
    """``ptw-assist estimate PATH --json ...`` in this process (its console output swallowed); the JSON."""
    with tempfile.TemporaryDirectory() as tmp:
        js = Path(tmp) / "e.json"
        with contextlib.redirect_stdout(io.StringIO()):
            code = cli(["estimate", str(path), "--json", str(js), *extra])
        if code != 0:
            raise SystemExit(f"estimate failed on {path} ({code})")
        return json.loads(js.read_text())


def ratios(js: dict) -> list[float]:
    r = js["stiffness_ratio_to_nominal"]
    return [r["C_alpha_f"], r["C_alpha_r"]]


def with_offsets(log: RideLog, off: dict[str, float]) -> RideLog:
    cols = {k: (v + off[k] if k in off else v) for k, v in log.columns.items()}
    return RideLog(t=log.t, columns=cols, meta=log.meta)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    add_overwrite(ap)
    args = ap.parse_args()
    out = output_file(ap, "--json", args.json, args.overwrite)
    t0 = time.perf_counter()
    sim = []
    print("simulated rides (truth: stiffness scale 0.8, the offsets below); front / rear scale per estimate")
    print(f"{'ride':20s} {'seed':>4s}  {'channel':9s} {'offset':>9s} {'found':>9s} {'std':>8s} {'removed':>7s}")
    eff = {"tire_stiffness": {"front_scale": SCALE, "rear_scale": SCALE}}
    with tempfile.TemporaryDirectory() as tmp:
        for ride in RIDES:
            for seed in SEEDS:
                log = ride_scenario(make_scenario(ride, duration_s=60.0), effects=eff, seed=seed).log
                rng = np.random.default_rng(seed)
                off = {c: float(rng.uniform(-SPAN[c], SPAN[c])) for c in OFFSET_CHANNELS}
                b0 = {c: float(rng.uniform(-SPAN[c] / 2, SPAN[c] / 2)) for c in OFFSET_CHANNELS}
                b1 = {c: float(rng.uniform(-SPAN[c], SPAN[c])) for c in OFFSET_CHANNELS}
                span_t = float(log.t[-1] - log.t[0])
                rate = {c: (b1[c] - b0[c]) / span_t for c in OFFSET_CHANNELS}
                line = {c: b0[c] + rate[c] * (log.t - log.t[0]) for c in OFFSET_CHANNELS}
                clean_p, off_p = Path(tmp) / f"{ride}_{seed}.csv", Path(tmp) / f"{ride}_{seed}_off.csv"
                drift_p = Path(tmp) / f"{ride}_{seed}_drift.csv"
                write_log(clean_p, log.columns, meta=log.meta)
                write_log(off_p, with_offsets(log, off).columns, meta=log.meta)
                write_log(drift_p, with_offsets(log, line).columns, meta=log.meta)
                clean, got, bare = run_estimate(clean_p), run_estimate(off_p), run_estimate(off_p, "--offsets", "none")
                drifted = run_estimate(drift_p)
                row = {"ride": ride, "seed": seed, "offsets": off, "found": got["sensor_offsets"],
                       "clean_found": clean["sensor_offsets"],
                       "scale_clean": ratios(clean), "scale_offsets_removed": ratios(got),
                       "scale_offsets_kept": ratios(bare),
                       "drift_start": b0, "drift_end": b1, "drift_rate": rate, "span_s": span_t,
                       "drift_found": drifted["sensor_offsets"],
                       "scale_drift_removed": ratios(drifted)}
                sim.append(row)
                for c in OFFSET_CHANNELS:
                    e = got["sensor_offsets"][c]
                    print(f"{ride:20s} {seed:4d}  {c:9s} {off[c]:+9.4f} {e['value']:+9.4f} {e['std']:8.2g} "
                          f"{'yes' if e['removed'] else 'no':>7s}")
                for c in OFFSET_CHANNELS:
                    d = drifted["sensor_offsets"][c]["drift"]
                    print(f"{'':26s}drift {c:9s} {rate[c]:+10.3e} /s found {d['value']:+10.3e} (std {d['std']:.1e}) "
                          f"used {'yes' if d['used'] else 'no'}, removed {'yes' if drifted['sensor_offsets'][c]['removed'] else 'no'}")
                fmt = lambda r: f"{r[0]:.3f} / {r[1]:.3f}"  # noqa: E731
                print(f"{'':26s}scale: clean log {fmt(row['scale_clean'])}; offset log, offsets removed "
                      f"{fmt(row['scale_offsets_removed'])}; offsets kept (--offsets none) {fmt(row['scale_offsets_kept'])};"
                      f" clean log removed {sum(e['removed'] for e in clean['sensor_offsets'].values())} offset(s)")
    err = [abs(r["found"][c]["value"] - r["offsets"][c]) / SPAN[c] for r in sim for c in OFFSET_CHANNELS]
    dev_rm = [abs(a / b - 1) for r in sim for a, b in zip(r["scale_offsets_removed"], r["scale_clean"])]
    dev_kept = [abs(a / b - 1) for r in sim for a, b in zip(r["scale_offsets_kept"], r["scale_clean"])]
    n_rm = sum(e["removed"] for r in sim for e in r["found"].values())
    n_clean_rm = sum(e["removed"] for r in sim for e in r["clean_found"].values())
    print(f"summary: offsets found within {100 * max(err):.2f} % of each channel's span (median {100 * np.median(err):.2f} %); "
          f"removed {n_rm} of {len(err)}; on the clean logs removed {n_clean_rm} of {len(err)}; stiffness scale vs the "
          f"clean log's: with the offsets removed within {100 * max(dev_rm):.2f} % (median {100 * np.median(dev_rm):.2f} %), "
          f"kept {100 * min(dev_kept):.1f}-{100 * max(dev_kept):.1f} % off")
    # drift: the error of the rate found, as the change it makes over the ride, in the channel's span
    found = [(r, c, r["drift_found"][c].get("drift")) for r in sim for c in OFFSET_CHANNELS]
    derr = [abs(d["value"] - r["drift_rate"][c]) * r["span_s"] / SPAN[c] for r, c, d in found if d]
    sig = [abs(d["value"] / r["drift_rate"][c] - 1.0) for r, c, d in found if d and d["significant"]]
    rides_used = sum(any(bool(e.get("drift", {}).get("used")) for e in r["drift_found"].values()) for r in sim)
    n_drm = sum(r["drift_found"][c]["removed"] for r in sim for c in OFFSET_CHANNELS)
    false_used = sum(bool(e.get("drift", {}).get("used")) for r in sim for key in ("found", "clean_found")
                     for e in r[key].values())
    dev_dr = [abs(a / b - 1) for r in sim for a, b in zip(r["scale_drift_removed"], r["scale_clean"])]
    print(f"summary (drift; {len(SEEDS)} draws of {len(OFFSET_CHANNELS)} lines, each on {len(RIDES)} rides): rates "
          f"within {100 * max(derr):.2f} % of the channel's span over the ride (median {100 * np.median(derr):.2f} %); "
          f"{len(sig)} of {len(found)} beyond {OFFSET_SIGNIFICANCE:g} standard deviations, within "
          f"{100 * max(sig):.1f} % of their rate (median {100 * np.median(sig):.1f} %); the drifting filter used on "
          f"{rides_used} of {len(sim)} drift rides, lines removed on {n_drm} channels; a drift used on the clean and "
          f"constant-offset rides' channels: {false_used} of {2 * len(found)}; stiffness scale vs the clean log's "
          f"with the lines removed within {100 * max(dev_dr):.2f} % (median {100 * np.median(dev_dr):.2f} %)")

    print("\ndisclosed logs (shared/data, an independent simulator; truth in the sidecars): error of the front / rear "
          "estimate against the truth with the defaults and with --offsets none; offsets removed")
    disclosed = []
    for f in sorted(shared_data(".").glob("*.csv")):
        bank = [c["params"]["bank_rad"] for c in json.loads(f.with_suffix(".json").read_text()).get("truth", {})
                .get("causes", []) if c.get("cause") == "road_bank"]
        for extra in ([], ["--road-bank", repr(bank[0])]) if bank else ([],):
            got, bare = run_estimate(f, *extra), run_estimate(f, "--offsets", "none", *extra)
            e = lambda js: [js["relative_error"][n] for n in ("C_alpha_f", "C_alpha_r")]  # noqa: E731
            removed = {c: o["value"] for c, o in got["sensor_offsets"].items() if o["removed"]}
            disclosed.append({"log": f.stem, "options": extra, "error": e(got), "error_offsets_none": e(bare),
                              "removed": removed})
            print(f"{f.stem:26s} {' '.join(extra):18s} {100 * e(got)[0]:+7.2f} / {100 * e(got)[1]:+7.2f} %   "
                  f"none: {100 * e(bare)[0]:+7.2f} / {100 * e(bare)[1]:+7.2f} %   removed "
                  + (", ".join(f"{c} {v:+.4g}" for c, v in removed.items()) or "none"))

    real = []
    print("\nrobot bicycle, measured rides: offsets the filter reads (value, std), the worst channel's mean normalised "
          "innovation with them, removed?, front / rear scale")
    for f in sorted(shared_data("robot_bicycle").glob("*.csv")):
        js = run_estimate(f)
        offs = js["sensor_offsets"]
        worst = max((v, c) for c, v in js["offset_filter_nis"].items() if v is not None)
        real.append({"run": f.stem, "offsets": offs, "scale": ratios(js), "notes": js.get("notes", [])})
        drifts = [c for c, e in offs.items() if e.get("drift", {}).get("significant")]
        print(f"{f.stem:16s} " + "  ".join(f"{c} {e['value']:+.4f}" for c, e in offs.items())
              + f"  drifting {','.join(drifts) or '-'}"
              + f"  worst {worst[1]} {worst[0]:.1f}  removed {sum(e['removed'] for e in offs.values())}"
              + f"  scale {js['stiffness_ratio_to_nominal']['C_alpha_f']:.3f} / {js['stiffness_ratio_to_nominal']['C_alpha_r']:.3f}")
    n_real_rm = sum(e["removed"] for r in real for e in r["offsets"].values())
    n_real_dr = sum(bool(e.get("drift", {}).get("significant")) for r in real for e in r["offsets"].values())
    n_real_used = sum(bool(e.get("drift", {}).get("used")) for r in real for e in r["offsets"].values())
    print(f"summary: {n_real_rm} offsets removed over {len(real)} rides; {n_real_dr} channel drifts beyond "
          f"{OFFSET_SIGNIFICANCE:g} standard deviations, {n_real_used} used ({time.perf_counter() - t0:.0f} s in all)")
    if out is not None:
        out.write_text(json.dumps({"simulated": sim, "disclosed": disclosed, "robot_bicycle": real}, indent=1) + "\n")


if __name__ == "__main__":
    main()
