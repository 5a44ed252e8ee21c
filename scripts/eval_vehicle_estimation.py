"""Stiffness and friction estimation on every vehicle preset (the rides of tests/test_presets.py, three seeds).

Per preset: (1) a friction drop 1 -> 0.6 at 20 s on a 0.3 g slalom at mid design speed, 5 % noise, the
vehicle's own LQR rider, the adaptive observer (Kalman vertex gains, one scale per axle) designed for the
vehicle (:func:`assist.estimation.adaptive_design.design_for_vehicle`): mean and worst error of each axle
scale from 15 s after the drop, error 10 s after it, the observer's speed range; (2) the risk warning's
friction estimate (its default pipeline for the vehicle) on a lane change at mid design speed on a road of
friction 0.6 (saturating tires, 5 % noise): median over the informed samples. Truth: the simulator's.

(3) For the robot bicycle, where (1) fails: the same drop at sensor noise 0, 1 and 2 % (seeds as above), and
noise-free on 0.1-0.3 g slaloms at 3.75 and 5.5 m/s (seed 0), with the estimated scales 40 s after the drop.

Run: ``python scripts/eval_vehicle_estimation.py [--json OUT.json] [--seeds 3] [--overwrite]`` (about 15 s).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assist.estimation.adaptive_design import AdaptiveDesignError, AdaptiveDesignOptions, design_for_vehicle  # noqa: E402
from assist.estimation.adaptive_observer import AdaptiveObserver  # noqa: E402
from assist.estimation.identification import simulate_friction_drop  # noqa: E402
from assist.risk.offline import assess_log  # noqa: E402
from ptw_env.friction import FrictionSchedule  # noqa: E402
from ptw_env.outputs import atomic_write_text  # noqa: E402
from ptw_env.ride import ride_scenario  # noqa: E402
from ptw_env.scenarios import make_scenario  # noqa: E402
from ptw_env.vehicle import G  # noqa: E402
from ptw_env.vehicle_files import load_vehicle, vehicle_names  # noqa: E402
from _outputs import add_overwrite, output_file  # noqa: E402  (scripts/_outputs.py)


def slalom_options(v, g: float = 0.3, vm: float | None = None) -> tuple[float, dict]:
    """A speed [km/h] (default the middle of the design range) and a slalom asking about ``g`` there (cones 4 s
    apart, path curvature amplitude ``A (pi / L)^2 = g G / vm^2``)."""
    lo, hi = v.control_range
    vm = 0.5 * (lo + hi) if vm is None else vm
    L = 4.0 * vm
    A = g * G / vm**2 / (math.pi / L) ** 2
    return 3.6 * vm, {"cone_spacing_m": round(L, 2), "amplitude_m": round(A, 3), "n_cones": 10, "run_in_s": 2.0}


def friction_drop(v, seed: int, noise: float = 5.0, g: float = 0.3, vm: float | None = None) -> dict:
    kmh, opts = slalom_options(v, g, vm)
    log, truth = simulate_friction_drop("slalom", switch_s=20.0, after=0.6, noise_pct=noise, seed=seed,
                                        duration_s=60.0, speed_kmh=kmh, vehicle=v, scenario_options=opts)
    try:  # noise-free logs: the gains of 2 % (a Kalman design needs some noise)
        d = design_for_vehicle(v, AdaptiveDesignOptions(noise_pct=max(noise, 2.0)), "kalman", log.columns["vx"])
    except AdaptiveDesignError as exc:
        return {"seed": seed, "design": str(exc)}
    run = AdaptiveObserver(d, parametrisation="axle").run_log(log)
    err = np.abs(run.stiffness / truth - 1.0)[:, [0, 2]]  # front and rear scale (camber follows)
    scale = run.stiffness[-1, [0, 2]] / d.model.theta0[[0, 2]]
    return {"seed": seed, "noise_pct": noise, "lateral_g": g, "speed_kmh": round(kmh, 2),
            "observer_speed_range": [d.model.vmin, d.model.vmax],
            "scales_40s_after": [round(float(x), 3) for x in scale],
            "mean_error_from_15s_after": [round(float(x), 4) for x in err[3500:].mean(axis=0)],
            "worst_error_from_15s_after": [round(float(x), 4) for x in err[3500:].max(axis=0)],
            "error_10s_after": [round(float(x), 4) for x in err[3000]]}


def risk_friction(v, seed: int) -> dict:
    lo, hi = v.control_range
    sc = make_scenario("double_lane_change", speed_kmh=round(1.8 * (lo + hi), 1), run_in_s=6.0, duration_s=20.0)
    ride = ride_scenario(sc, vehicle=v, effects="tire_saturation:mu_peak=0.9", noise_pct=5.0, seed=seed,
                         friction=FrictionSchedule.constant(0.6, scaling="stiffness_and_peak"))
    run = assess_log(ride.log)
    mu, inf = run.series("mu_hat"), run.series("friction_informed").astype(bool)
    return {"seed": seed, "fell": bool(ride.fell), "mu_true": 0.6,
            "mu_hat_median_informed": round(float(np.median(mu[inf])), 4) if inf.any() else None,
            "levels": sorted({a.level for a in run.assessments})}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None, metavar="OUT.json")
    ap.add_argument("--seeds", type=int, default=3)
    add_overwrite(ap)
    a = ap.parse_args(argv)
    out = output_file(ap, "--json", a.json, a.overwrite)
    t0 = time.perf_counter()
    res = {}
    for name in vehicle_names():
        v = load_vehicle(name)
        res[name] = {"friction_drop": [friction_drop(v, s) for s in range(a.seeds)],
                     "risk": [risk_friction(v, s) for s in range(a.seeds)]}
        if name == "robot-bicycle":
            res[name]["noise_study"] = [friction_drop(v, s, noise) for noise in (0.0, 1.0, 2.0) for s in range(a.seeds)]
            res[name]["noise_free_slaloms"] = [friction_drop(v, 0, 0.0, g, vm) for vm in (3.75, 5.5)
                                               for g in (0.1, 0.2, 0.3)]
            for r in res[name]["noise_study"] + res[name]["noise_free_slaloms"]:
                print(f"{name:<24} noise {r['noise_pct']:g} %, {r['lateral_g']:g} g at {r['speed_kmh']:g} km/h, seed "
                      f"{r['seed']}: mean {100 * max(r['mean_error_from_15s_after']):.1f} %, scales 40 s after the "
                      f"drop {r['scales_40s_after']}")
        for r in res[name]["friction_drop"]:
            print(f"{name:<24} drop seed {r['seed']}: " + (
                r["design"] if "design" in r else
                f"mean {100 * max(r['mean_error_from_15s_after']):.1f} %, worst "
                f"{100 * max(r['worst_error_from_15s_after']):.1f} %, 10 s after "
                f"{100 * max(r['error_10s_after']):.1f} % (observer {r['observer_speed_range']} m/s)"))
        for r in res[name]["risk"]:
            print(f"{name:<24} risk seed {r['seed']}: mu_hat median {r['mu_hat_median_informed']} for 0.6, "
                  f"levels {r['levels']}{' FELL' if r['fell'] else ''}")
    res["seconds"] = round(time.perf_counter() - t0, 1)
    print(f"{res['seconds']} s")
    if out is not None:
        atomic_write_text(out, json.dumps(res, indent=1, allow_nan=False) + "\n")
        print(f"written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
