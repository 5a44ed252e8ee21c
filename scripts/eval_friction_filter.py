"""Calibration and checks of the friction filter (assist.estimation.friction_imm), the numbers its docstring and
the README cite.

1. Calibration rides (risk evaluation types ``dry``, ``dry_bank``, ``dry_offsets``, ``wet_corner``, ``wet_straight``,
   seeds 0-39 by default; the evaluation of ``scripts/eval_risk.py`` uses 1000-1039).
   a. The filter's process noise and switching rate (:data:`FILTERS`: pairs of ``noise_scale``, ``switch_rate``), each at
      the default rule: the rides whose reference road (a dry ride, or a wet one before its patch, from 1 s on)
      took the lower frictions to 0.995 and to 0.999, the corner patches read within 0.3 s of the drop, the wet
      straights read at least 0.5 s before their first loss of grip (truth: ``|F_ss| >= 0.95 Fmax``; or read with
      no loss), the median nis. Selection rule (written after a first exploration of an earlier sweep on the same seeds, before
      this sweep was run with the speed tracker): among the filters with no
      reference-road ride at 0.995 (a margin of one rule below the 0.999 the reading uses), the one with the most
      corner patches read within 0.3 s, then the most wet straights read early, then the larger process noise
      (the more robust to model error). The table says which it picks; ``friction_imm.NOISE_SCALE`` and the
      default switching rate are that one.
   b. For the default filter, each decision rule (the lower side ``mu <= lower x mu_ref``, the probability
      ``decide``): the rides on the reference road read as lower and the corner patches read within 0.3 s of
      the drop; the normalised innovation squared per channel (``FrictionIMM.nis``) on these simulated rides.
      Selection rule (written before this table was made with the speed tracker): at ``decide`` 0.999, the
      largest ``lower`` (the finest reading) whose lower side took 0.995 on no reference-road ride and that
      reads as many corner patches within 0.3 s as any; the table says which it picks.
2. The 14 measured robot-bicycle rides: ``nis`` per ride, the largest probability of the lower frictions, whether
   the consistency gate held a reading back.
3. The four vehicle presets: a lane change at the middle of the control range on a dry (0.9) and a wet (0.45) road, the largest
   probability of the lower frictions (tests/test_presets.py asserts on it).
4. A curve entered too fast (seed 0): the largest probability of the lower frictions in the warm-up curves, before
   the critical curve's entry.
5. A yaw gyro reading 0.01 rad/s high (urban ride, seed 11): the filter's offset estimate.
6. The speed the filter predicts with (:mod:`assist.estimation.speed`), on the dry calibration rides: the error of the
   held GPS reading and of the tracker at each jerk intensity of :data:`JERKS` against the true speed (RMS and largest
   per ride, from 1 s on; the tracker's default is the one with the smallest mean of the largest errors), and the
   default filter's largest P(lower) when it takes the held reading as the speed (``speed_jerk=None``).
7. The evidence (``FrictionIMM.evidence``, the CUSUM of the two sides' log-likelihood ratio, the larger of the filter's
   two banks' sums): its largest value on the calibration rides' reference road and on the real rides (and each
   bank's), the patches read with it and with the probability alone (tables 1a and 1b count the probability alone),
   and the two wet straights of the risk evaluation
   (:data:`EVALUATION_STRAIGHTS`) that the version before it warned 0.1 s ahead.

Every ride is seeded; the same seeds give the same numbers. Example::

    python scripts/eval_friction_filter.py --workers 2 --out docs/results/risk/friction_filter --overwrite
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from assist.risk.evaluation import LATENCY_S, LEAD_S  # noqa: E402
from ptw_env.jobs import JobsError, run_jobs  # noqa: E402

from _outputs import add_overwrite, output_dir, write_results  # noqa: E402  (scripts/_outputs.py)

CAL_KINDS = ("dry", "dry_bank", "dry_offsets", "wet_corner", "wet_straight")
#: filters compared: (noise_scale, switch_rate); the default is (friction_imm.NOISE_SCALE, friction_imm.SWITCH_RATE)
FILTERS = ((1.0, 3.0), (0.3, 3.0), (0.1, 3.0), (0.1, 1.0), (0.1, 0.3), (0.03, 3.0), (0.03, 1.0), (0.03, 0.3))
#: jerk intensities of the speed tracker compared [m^2/s^5] (table 6)
JERKS = (1.0, 3.0, 10.0, 30.0, 100.0)
#: decision rules compared: (lower, decide); the filter's default is (0.7, 0.999)
RULES = tuple((lo, d) for lo in (0.85, 0.7) for d in (0.95, 0.99, 0.995, 0.999))
#: table 7: the wet straights of the risk evaluation (seeds 1000-1039) the previous version warned 0.1 s ahead
#: although the tires had told the road for many seconds (its README, "Risk warning")
EVALUATION_STRAIGHTS = (1008, 1027)


def _run(imm, log):
    """Probabilities (K, J), nis (K,), evidence [nats] (K, 3: the filter's, its mixing bank's, its own bank's) and
    where the filter's reading is a lower friction (K,) over a log."""
    from assist.risk.pipeline import output_matrix

    Y, tau, vx = output_matrix(log.columns), np.asarray(log.columns["tau"], float), np.asarray(log.columns["vx"], float)
    P, N, E = np.zeros((len(Y), imm.grid.size)), np.zeros(len(Y)), np.zeros((len(Y), 3))
    R = np.zeros(len(Y), dtype=bool)
    for k in range(len(Y)):
        imm.update(Y[k], tau[k], vx[k])
        P[k], N[k], E[k] = imm.probabilities, imm.nis, (imm.evidence, imm.evidence_mixing, imm.evidence_own)
        r = imm.friction_reading
        R[k] = r.informed and r.mu < imm.mu_ref
    return P, N, E, R


def _calibration_ride(kind: str, seed: int) -> dict | None:
    from assist.estimation.friction_imm import NOISE_SCALE, SWITCH_RATE, FrictionIMM
    from assist.risk.evaluation import make_case, ride_case, saturation_events, true_utilisation
    from ptw_env.scenarios import ScenarioError

    try:
        case = make_case(kind, seed)
    except ScenarioError:
        if kind != "wet_corner":
            raise
        return None  # a route with no corner of the drawn demand: no wet_corner ride for this seed
    r = ride_case(case)
    t = np.asarray(r.log.t)
    c = r.log.columns
    drop = case.notes.get("patch_start_s")
    ref = (t >= 1.0) & (t < (np.inf if drop is None else drop))
    out = {"kind": kind, "seed": seed, "drop_s": drop, "rules": {}, "filters": {}}
    if kind == "dry":
        out["speed"] = _speed_errors(r.log)
        imm = FrictionIMM(speed_jerk=None)
        P, _, _, _ = _run(imm, r.log)
        out["held_speed_ref_max"] = float(P[ref][:, imm.low].sum(axis=1).max())
    if drop is not None:
        util = true_utilisation(r.states, c["vx_true"], c["mu_true"], case.friction, case.effects)
        loss = saturation_events(t, util)
        out["loss_s"] = float(loss[0]) if loss.size else None  # the ride's first loss of grip (truth)
    for ns, sw in sweep():
        imm = FrictionIMM(noise_scale=ns, switch_rate=sw)
        P, N, E, R = _run(imm, r.log)
        low = P[:, imm.low].sum(axis=1)
        f = {"ref_max": float(low[ref].max()) if ref.any() else None, "nis_median": float(np.median(N[t >= 1.0]))}
        if drop is not None:
            k = np.flatnonzero((t >= drop) & (low >= imm.decide))
            f["read_s"] = float(t[k[0]]) if k.size else None
        out["filters"][f"{ns}/{sw}"] = f
        if (ns, sw) != (NOISE_SCALE, SWITCH_RATE):
            continue
        out["nis_median"], out["nis_max"] = f["nis_median"], float(N[t >= 1.0].max())
        out["evidence"] = _evidence(imm, t, P, E, R, ref, drop, out.get("loss_s"))
        for lo, d in RULES:
            low = P[:, imm.grid <= lo * imm.mu_ref].sum(axis=1)
            rule = {"false": bool((low[ref] >= d).any())}
            if drop is not None:
                k = np.flatnonzero((t >= drop) & (low >= d))
                rule["read_after_s"] = float(t[k[0]] - drop) if k.size else None
            out["rules"][f"{lo}/{d}"] = rule
    return out


def _evidence(imm, t, P, E, R, ref, drop, loss) -> dict:
    """Table 7 figures of one ride: the largest evidence [nats] on its reference road (the filter's, and each
    bank's), and (wet) the first
    lower reading after the drop with the evidence and with the probability alone [s after the drop], the largest
    evidence and P(lower) up to 0.5 s before the first loss of grip."""
    low = P[:, imm.low].sum(axis=1)
    out = {key: float(E[ref, i].max()) if ref.any() else None
           for i, key in enumerate(("ref_max", "ref_max_mixing", "ref_max_own"))}
    E = E[:, 0]
    if drop is not None:
        for key, on in (("read_after_s", R), ("read_after_s_probability", low >= imm.decide)):
            k = np.flatnonzero((t >= drop) & on)
            out[key] = float(t[k[0]] - drop) if k.size else None
        if loss is not None:
            m = (t >= drop) & (t <= loss - LEAD_S)
            out["before_loss"] = {"evidence_max": float(E[m].max()) if m.any() else None,
                                  "p_lower_max": float(low[m].max()) if m.any() else None}
    return out


def _evaluation_straight(seed: int) -> dict:
    """Table 7: a wet straight of the risk evaluation (scripts/eval_risk.py) with the default filter."""
    from assist.estimation.friction_imm import FrictionIMM
    from assist.risk.evaluation import make_case, ride_case, saturation_events, true_utilisation

    case = make_case("wet_straight", seed)
    r = ride_case(case)
    t, c = np.asarray(r.log.t), r.log.columns
    loss = saturation_events(t, true_utilisation(r.states, c["vx_true"], c["mu_true"], case.friction, case.effects))
    imm = FrictionIMM()
    P, _, E, R = _run(imm, r.log)
    drop = case.notes["patch_start_s"]
    ev = _evidence(imm, t, P, E, R, (t >= 1.0) & (t < drop), drop, float(loss[0]) if loss.size else None)
    return {"seed": seed, "drop_s": drop, "loss_s": float(loss[0]) if loss.size else None, **ev}


def _speed_errors(log) -> dict:
    """RMS and largest error [m/s] from 1 s on of the held speed reading and of the tracker at each of :data:`JERKS`."""
    from assist.estimation.speed import SpeedTracker
    from ptw_env.sensors import SensorConfig

    t = np.asarray(log.t)
    v, held = np.asarray(log.columns["vx_true"], float), np.asarray(log.columns["vx"], float)
    m = t >= 1.0
    fix_std = SensorConfig.from_percent(5.0).noise_std["vx"]
    out = {}
    for name, est in [("held", held)] + [(str(q), None) for q in JERKS]:
        if est is None:
            tr = SpeedTracker(float(log.dt), fix_std, float(name))
            est = np.array([tr.update(x) for x in held])
        e = np.abs(est - v)[m]
        out[name] = {"rms": float(np.sqrt(np.mean(e**2))), "max": float(e.max())}
    return out


def sweep() -> tuple[tuple[float, float], ...]:
    """:data:`FILTERS`, with the filter's default appended when it is not one of them (its rules and nis are
    reported)."""
    from assist.estimation.friction_imm import NOISE_SCALE, SWITCH_RATE

    return FILTERS if (NOISE_SCALE, SWITCH_RATE) in FILTERS else FILTERS + ((NOISE_SCALE, SWITCH_RATE),)


def filter_table(cal: list[dict]) -> tuple[list[dict], str]:
    """Per filter of :data:`FILTERS` at the default rule: the reference-road rides whose lower frictions reached 0.995
    and 0.999, the corner patches read within 0.3 s (and the median), the wet straights read at least 0.5 s before
    their first loss of grip (or read with no loss), the median nis; and the filter the selection rule takes (script
    docstring): among those with no reference-road ride at 0.995, the most corner patches within 0.3 s, then the
    most wet straights read, then the larger process noise."""
    rows = []
    for ns, sw in sweep():
        key = f"{ns}/{sw}"
        refs = [r["filters"][key]["ref_max"] for r in cal if r["filters"][key]["ref_max"] is not None]
        lat = [np.inf if r["filters"][key]["read_s"] is None else r["filters"][key]["read_s"] - r["drop_s"]
               for r in cal if r["kind"] == "wet_corner"]
        ws = [r for r in cal if r["kind"] == "wet_straight"]
        early = sum(1 for r in ws if r["filters"][key]["read_s"] is not None
                    and (r["loss_s"] is None or r["loss_s"] - r["filters"][key]["read_s"] >= LEAD_S))
        rows.append({"noise_scale": ns, "switch_rate": sw, "ref_rides": len(refs),
                     "ref_0.995": sum(1 for x in refs if x >= 0.995), "ref_0.999": sum(1 for x in refs if x >= 0.999),
                     "ref_max": max(refs), "corners": len(lat), "corners_in_0.3s": sum(1 for x in lat if x <= LATENCY_S),
                     "corner_median_s": float(np.median(lat)), "straights": len(ws), "straights_read_early": early,
                     "nis_median": float(np.median([r["filters"][key]["nis_median"] for r in cal]))})
    ok = [r for r in rows if r["ref_0.995"] == 0]
    best = max(ok, key=lambda r: (r["corners_in_0.3s"], r["straights_read_early"], r["noise_scale"])) if ok else None
    return rows, ("none" if best is None else f"{best['noise_scale']}/{best['switch_rate']}")


def _real_ride(path: str) -> dict:
    from assist.estimation.friction_imm import FrictionIMM
    from assist.estimation.identification import NIS_EXPLAINED
    from ptw_env.logs import read_log, usable_part
    from ptw_env.vehicle_files import vehicle_of_log

    log, _ = usable_part(read_log(path))
    imm = FrictionIMM(vehicle=vehicle_of_log(log.meta or {}, path), dt=float(log.dt))
    P, N, E, R = _run(imm, log)
    low = P[:, imm.low].sum(axis=1)
    t = np.asarray(log.t) - float(log.t[0])
    m = t >= 1.0
    held = (low >= imm.decide) & (N > NIS_EXPLAINED) & m
    return {"ride": Path(path).stem, "nis_median": float(np.median(N[m])), "p_lower_max": float(low[m].max()),
            "evidence_max": float(E[m, 0].max()), "evidence_max_mixing": float(E[m, 1].max()),
            "evidence_max_own": float(E[m, 2].max()), "read_lower_samples": int((R & m).sum()),
            "held_back_samples": int(held.sum()), "nis_where_held": [float(np.min(N[held])), float(np.max(N[held]))]
            if held.any() else None}


def _preset(name: str) -> dict:
    from assist.estimation.friction_imm import FrictionIMM
    from ptw_env.friction import FrictionSchedule
    from ptw_env.ride import ride_scenario
    from ptw_env.scenarios import make_scenario
    from ptw_env.vehicle_files import load_vehicle

    v = load_vehicle(name)
    lo, hi = v.control_range
    kmh = round(3.6 * (lo + hi) / 2.0, 1)  # the middle of the control range, as tests/test_presets.py
    out = {"vehicle": name}
    for mu in (0.9, 0.45):
        sc = make_scenario("double_lane_change", speed_kmh=kmh, run_in_s=6.0, duration_s=20.0)
        r = ride_scenario(sc, vehicle=v, effects="tire_saturation:mu_peak=0.9", noise_pct=5.0, seed=3,
                          friction=FrictionSchedule.constant(mu))
        imm = FrictionIMM(vehicle=v, dt=float(r.log.dt))
        P, _, _, _ = _run(imm, r.log)
        out[f"p_lower_max_mu{mu}"] = float(P[int(1.0 / r.log.dt):, imm.low].sum(axis=1).max())
    return out


def _too_fast(seed: int) -> dict:
    from assist.estimation.friction_imm import FrictionIMM
    from assist.risk.evaluation import make_case, ride_case

    case = make_case("too_fast", seed)
    r = ride_case(case)
    imm = FrictionIMM()
    P, _, _, _ = _run(imm, r.log)
    t = np.asarray(r.log.t)
    m = (t >= 1.0) & (t < case.notes["curve_entry_s"])
    return {"seed": seed, "mu_road": case.notes["mu_road"], "p_lower_max_before_entry": float(P[m][:, imm.low].sum(axis=1).max())}


def _gyro(seed: int) -> dict:
    from assist.estimation.friction_imm import FrictionIMM
    from ptw_env.ride import ride_scenario
    from ptw_env.scenarios import make_scenario

    r = ride_scenario(make_scenario("urban", duration_s=60.0), seed=seed,
                      effects={"gyro_bias": {"yaw_rate_bias": 0.01, "roll_rate_bias": 0.0}})
    imm = FrictionIMM()
    _run(imm, r.log)
    return {"seed": seed, "true_rad_s": 0.01, "estimate_rad_s": imm.yaw_rate_offset}


def _job(what: str, arg):
    return {"calibration": lambda: _calibration_ride(*arg), "real": lambda: _real_ride(arg),
            "preset": lambda: _preset(arg), "too_fast": lambda: _too_fast(arg), "gyro": lambda: _gyro(arg),
            "evaluation_straight": lambda: _evaluation_straight(arg)}[what]()


def summarise(res: dict) -> str:
    cal = [r for r in res["calibration"] if r is not None]
    rows, pick = filter_table(cal)
    n_ref = rows[0]["ref_rides"]
    lines = ["## 1a. Process noise and switching rate on the calibration rides (rule lower 0.7, decide 0.999)", "",
             f"{n_ref} rides with reference road (dry, and wet before the patch), "
             f"{rows[0]['corners']} corner patches, {rows[0]['straights']} wet straights (seeds "
             f"{res['seeds'][0]}-{res['seeds'][-1]}; a seed whose route has no corner of the drawn demand has no "
             "wet_corner ride).", "",
             "| noise_scale | switch_rate [1/s] | reference road at 0.995 / 0.999 (largest) | corner patches read within "
             "0.3 s; median [s] | wet straights read >= 0.5 s before their loss (or with none) | nis median |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['noise_scale']} | {r['switch_rate']} | {r['ref_0.995']} / {r['ref_0.999']} ({r['ref_max']:.4f}) "
                     f"| {r['corners_in_0.3s']} of {r['corners']}; {r['corner_median_s']:.2f} | "
                     f"{r['straights_read_early']} of {r['straights']} | {r['nis_median']:.2f} |")
    lines += ["", f"Selection rule (script docstring) picks noise_scale/switch_rate = {pick}; the filter's default is "
              f"{res['default_filter']}{'' if pick == res['default_filter'] else ' (DIFFERENT: update the default)'}.",
              "", "## 1b. Decision rule on the calibration rides (the default filter)", "",
             "| lower | decide | rides on the reference road read as lower | corner patches read within 0.3 s | median [s] |",
             "|---|---|---|---|---|"]
    for lo, d in RULES:
        key = f"{lo}/{d}"
        false = sum(1 for r in cal if r["rules"][key]["false"])
        lat = [r["rules"][key]["read_after_s"] for r in cal if r["kind"] == "wet_corner"]
        lat = [np.inf if x is None else x for x in lat]
        lines.append(f"| {lo} | {d} | {false} of {len(cal)} | {sum(1 for x in lat if x <= LATENCY_S)} of {len(lat)} | "
                     f"{np.median(lat):.2f} |")
    ok = [lo for lo, d in RULES if d == 0.999 and not any(r["rules"][f"{lo}/0.995"]["false"] for r in cal)]
    n03 = {lo: sum(1 for r in cal if r["kind"] == "wet_corner" and r["rules"][f"{lo}/0.999"]["read_after_s"] is not None
                   and r["rules"][f"{lo}/0.999"]["read_after_s"] <= LATENCY_S) for lo in ok}
    pick_rule = max((lo for lo in ok if n03[lo] == max(n03.values())), default=None)
    lines += ["", f"Selection rule (script docstring) picks lower = {pick_rule} at decide 0.999."]
    nm = [r["nis_median"] for r in cal]
    lines += ["", f"nis on these rides: median per ride {min(nm):.2f}-{max(nm):.2f}, largest "
              f"{max(r['nis_max'] for r in cal):.2f}", "", "## 2. Real robot-bicycle rides", "",
              "| ride | nis median | largest P(lower) | samples held back by the gate | nis there |", "|---|---|---|---|---|"]
    for r in res["real"]:
        lines.append(f"| {r['ride']} | {r['nis_median']:.2f} | {r['p_lower_max']:.3f} | {r['held_back_samples']} | "
                     f"{'-' if r['nis_where_held'] is None else '%.1f-%.1f' % tuple(r['nis_where_held'])} |")
    lines += ["", "## 3. Presets, lane change at the middle of the control range (seed 3)", "",
              "| vehicle | largest P(lower), dry 0.9 | wet 0.45 |", "|---|---|---|"]
    for r in res["preset"]:
        lines.append(f"| {r['vehicle']} | {r['p_lower_max_mu0.9']:.3f} | {r['p_lower_max_mu0.45']:.3f} |")
    tf = res["too_fast"]
    g = res["gyro"]
    lines += ["", f"## 4. Curve too fast (seed {tf['seed']}, damp road {tf['mu_road']:.3f}): largest P(lower) before the "
              f"critical curve's entry {tf['p_lower_max_before_entry']:.3f}", "",
              f"## 5. Yaw gyro 0.01 rad/s high (urban, seed {g['seed']}): estimated {g['estimate_rad_s']:.4f} rad/s", ""]
    dry = [r for r in cal if r["kind"] == "dry"]
    from assist.estimation.speed import JERK_INTENSITY

    lines += [f"## 6. Speed the filter predicts with, {len(dry)} dry calibration rides (from 1 s on)", "",
              "| speed | RMS error, mean over rides [m/s] | largest error per ride: mean / largest [m/s] |", "|---|---|---|"]
    for name in ["held"] + [str(q) for q in JERKS]:
        rms = [r["speed"][name]["rms"] for r in dry]
        mx = [r["speed"][name]["max"] for r in dry]
        label = "held GPS reading" if name == "held" else f"tracker, jerk {name} m^2/s^5"
        lines.append(f"| {label} | {np.mean(rms):.4f} | {np.mean(mx):.3f} / {np.max(mx):.3f} |")
    best = min(JERKS, key=lambda q: np.mean([r["speed"][str(q)]["max"] for r in dry]))
    held = [r["held_speed_ref_max"] for r in dry]
    tracked = [r["filters"][res["default_filter"]]["ref_max"] for r in dry]
    lines += ["", f"Smallest mean largest error: jerk {best:g}; the tracker's default is {JERK_INTENSITY:g}"
              f"{'' if best == JERK_INTENSITY else ' (DIFFERENT: update speed.JERK_INTENSITY)'}.", "",
              f"Default filter on these rides, largest P(lower): with the held reading as the speed "
              f"{max(held):.4f} ({sum(1 for x in held if x >= 0.9)} rides >= 0.9), with the tracker "
              f"{max(tracked):.4f} ({sum(1 for x in tracked if x >= 0.9)} rides >= 0.9).", ""]
    lines += _evidence_table(res, cal)
    return "\n".join(lines)


def _evidence_table(res: dict, cal: list[dict]) -> list[str]:
    from assist.estimation.friction_imm import FrictionIMM

    h = FrictionIMM().evidence_needed
    ref = sorted((r["evidence"]["ref_max"], r["kind"], r["seed"]) for r in cal if r["evidence"]["ref_max"] is not None)
    lines = [f"## 7. Evidence (CUSUM of the sides' log-likelihood ratio, the larger of the filter's two banks'), read "
             f"as lower at {h:.1f} nats", "",
             f"Reference road of the calibration rides ({len(ref)} stretches): largest {ref[-1][0]:.2f} nats "
             f"({ref[-1][1]} {ref[-1][2]}; {ref[-1][0] / h:.2f} of the bar), "
             f"{sum(1 for x in ref if x[0] >= h)} at the bar; the mixing bank's sum at most "
             f"{max(r['evidence']['ref_max_mixing'] for r in cal if r['evidence']['ref_max'] is not None):.2f}, "
             f"the own bank's {max(r['evidence']['ref_max_own'] for r in cal if r['evidence']['ref_max'] is not None):.2f}.",
             ""]
    for kind in ("wet_corner", "wet_straight"):
        rs = [r for r in cal if r["kind"] == kind]
        both = [r["evidence"]["read_after_s"] for r in rs]
        prob = [r["evidence"]["read_after_s_probability"] for r in rs]
        if kind == "wet_corner":
            lines.append(f"- {kind}: read within {LATENCY_S:g} s of the drop, probability alone "
                         f"{sum(1 for x in prob if x is not None and x <= LATENCY_S)} of {len(rs)}, with the evidence "
                         f"{sum(1 for x in both if x is not None and x <= LATENCY_S)}; read before the probability alone "
                         f"on {sum(1 for a, b in zip(both, prob) if a is not None and (b is None or a < b))}.")
        else:
            early = [r for r in rs if r.get("loss_s") is not None and "before_loss" in r["evidence"]]
            def n_early(key):
                return sum(1 for r in early if r["evidence"][key] is not None
                           and r["drop_s"] + r["evidence"][key] <= r["loss_s"] - LEAD_S)
            lines.append(f"- {kind}: read >= {LEAD_S:g} s before the first loss of grip, probability alone "
                         f"{n_early('read_after_s_probability')} of {len(early)} rides with a loss, with the evidence "
                         f"{n_early('read_after_s')}.")
    lines += ["", "Real robot-bicycle rides (from 1 s on): largest evidence "
              + ", ".join(f"{r['ride'][3:]} {r['evidence_max']:.2f} ({r['evidence_max_mixing']:.2f} / "
                          f"{r['evidence_max_own']:.2f})" for r in res["real"])
              + " (the mixing bank's / the own bank's)"
              + f"; samples read as lower: "
              f"{sum(r['read_lower_samples'] for r in res['real'])}.", "",
              "Wet straights of the risk evaluation that the previous version warned 0.1 s ahead:", "",
              "| seed | drop [s] | first loss [s] | largest evidence / P(lower) up to 0.5 s before it | read after the "
              "drop: with the evidence / probability alone [s] |", "|---|---|---|---|---|"]
    for r in res.get("evaluation_straights", []):
        b = r.get("before_loss") or {}
        lines.append(f"| {r['seed']} | {r['drop_s']:.2f} | {r['loss_s']:.2f} | {b.get('evidence_max', float('nan')):.1f} / "
                     f"{b.get('p_lower_max', float('nan')):.4f} | {_or_none(r['read_after_s'])} / "
                     f"{_or_none(r['read_after_s_probability'])} |")
    return lines + [""]


def _or_none(x) -> str:
    return "never" if x is None else f"{x:.2f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=40, help="calibration seeds per ride type (default 40: 0-39)")
    p.add_argument("--workers", type=int, default=1, help="local processes (default 1)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="a Dask scheduler (ptw_env.jobs)")
    p.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data" / "robot_bicycle"),
                   help="folder of the real robot-bicycle rides (default ../shared/data/robot_bicycle)")
    p.add_argument("--out", default="out/friction_filter", help="output directory (default out/friction_filter/)")
    add_overwrite(p)
    a = p.parse_args(argv)
    if a.seeds < 1:
        p.error(f"--seeds must be >= 1, got {a.seeds}")
    if a.workers < 1:
        p.error(f"--workers must be >= 1, got {a.workers}")
    real = sorted(Path(a.data).glob("rb_*.csv"))
    if not real:
        p.error(f"--data: no rb_*.csv ride in {a.data}")
    from assist.estimation.friction_imm import FrictionIMM
    from ptw_env.logs import read_log, usable_part
    from ptw_env.vehicle_files import vehicle_of_log

    for r in real:  # before the rides: a log the filter cannot take stops the run here, not after it
        try:
            log, _ = usable_part(read_log(str(r)))
            FrictionIMM(vehicle=vehicle_of_log(log.meta or {}, str(r)), dt=float(log.dt))
        except (OSError, ValueError) as e:  # LogFormatError, a vehicle file's error, FrictionFilterError
            p.error(f"--data: {r.name}: {e}")
    out = output_dir(p, a.out, a.overwrite)
    from ptw_env.vehicle_files import vehicle_names

    seeds = list(range(a.seeds))
    jobs = ([(("calibration", k, s), ("calibration", (k, s))) for k in CAL_KINDS for s in seeds]
            + [(("real", r.stem), ("real", str(r))) for r in real]
            + [(("preset", n), ("preset", n)) for n in vehicle_names()]
            + [(("too_fast", 0), ("too_fast", 0)), (("gyro", 11), ("gyro", 11))]
            + [(("evaluation_straight", s), ("evaluation_straight", s)) for s in EVALUATION_STRAIGHTS])
    t0 = time.perf_counter()
    try:
        done = run_jobs(_job, jobs, workers=a.workers, scheduler=a.scheduler, desc="rides")
    except JobsError as e:
        p.error(str(e))
    from assist.estimation.friction_imm import NOISE_SCALE, SWITCH_RATE

    res = {"seeds": seeds, "rules": [list(r) for r in RULES], "filters": [list(f) for f in sweep()],
           "default_filter": f"{NOISE_SCALE}/{SWITCH_RATE}",
           "calibration": [v for k, v in done.items() if k[0] == "calibration"],
           "real": [v for k, v in done.items() if k[0] == "real"],
           "preset": [v for k, v in done.items() if k[0] == "preset"],
           "too_fast": done[("too_fast", 0)], "gyro": done[("gyro", 11)],
           "evaluation_straights": [v for k, v in done.items() if k[0] == "evaluation_straight"],
           "seconds": round(time.perf_counter() - t0, 1)}
    write_results(out, res, summarise(res), f"{len(jobs)} jobs in {res['seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
