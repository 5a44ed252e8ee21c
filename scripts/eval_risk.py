"""Evaluate the risk warning (issues 5 and 20) on seeded rides with tire saturation on.

Ride types (:mod:`assist.risk.evaluation`; default the six of issue 20, ``EVAL_KINDS``): ``dry``
(urban at 0.5 g, friction 0.9), ``dry_bank`` (on a cross-fall of 0.015-0.04 rad), ``dry_offsets``
(a yaw-gyro bias of 0.01 rad/s and an accelerometer offset of 0.1 m/s^2), ``wet_straight`` and
``wet_corner`` (the same ride onto a wet patch, friction 0.9 -> 0.45, beginning on a straight or in
a corner at 0.25-0.45 g), ``too_fast`` (a damp road, warm-up curves, then a curve entered at
1.2-1.35 times the speed the friction allows); also ``wet``, ``wet_long``, ``dry_long``,
``wet_bank`` of the earlier evaluation. Every ride: 5 % sensor noise, its own seed for route,
sensors and rider. Tires: friction scales the peak (``--scaling peak``, the default) or, the
earlier model, stiffness and peak (``--scaling stiffness_and_peak``).

Targets (issue 20), each summarised in ``results.md``:

* lead: every loss of grip (``|F_ss| >= 0.95 Fmax`` on either axle, from the true state) 1 s or
  more after the friction drop (or the curve entry) has a caution at least 0.5 s ahead;
* latency: after a drop under tires using ``|F|/Fz >= 0.2``, a caution within 0.3 s (median and
  95th percentile);
* false warnings: no danger, and a caution on at most 2 % of the dry rides.

Beside each, what oracles could do: two that read the tires with the true state, the window oracle
(:func:`assist.risk.evaluation.information_onset`), the earliest instant the tires have told the
wet road from the dry one, at 2 standard errors of 0.3 s of accelerometer noise (a bar no warning
with few false alarms could use: it is crossed by noise in 2.3 % of windows); and the sequential
oracle (:func:`assist.risk.evaluation.sequential_evidence`), the CUSUM of the accelerometer's
likelihood ratio of the wet road to the dry one, which adds evidence up over any time, its
threshold set on this run's dry rides (100 noise draws each) so that it warns on 2 % of them, the
false-warning share the target allows. The CUSUM is optimal in Lorden's sense (the least worst-case
delay at a given mean time between false alarms; Lorden 1971, Moustakides 1986), so where it
cannot warn 0.5 s ahead in half of its draws, a warning reading the tires' force through the
accelerometer at that false-warning share cannot either (the gyros also see the forces, through
the yaw and roll moments). And the observation oracle
(:func:`assist.risk.evaluation.observation_evidence`), a reader of all the warning's sensors that
does not know the state: the friction filter with two models only, the dry and the wet friction,
and the CUSUM of their likelihood ratio, its threshold set the same way on the dry rides (its own
noise and 4 other draws each, each a ride again; each draw judged between its own drop and its
own loss of grip). It knows the wet road's friction, which the
warning does not, and it is a reference, not a bound: a friction between its two (the patch's
ramp) it explains worse than a filter of more levels. Its threshold holds in the simulation, where the model
is exact; held to measured rides (``--real``, default the robot-bicycle rides of ``../shared/data``, taken as
dry, each with its own vehicle file), it is raised to the smallest value above its largest evidence on them,
what the model's error alone sums to, and its counts are given at that threshold too. Each loss of grip also
keeps the friction filter's own evidence there (``filter_evidence_max``), each dry ride its largest.

Writes ``results.json``, ``rides.json``, ``results.md`` and ``timeline_<type>.png`` (one seed
per type) into ``--out``.

Usage::

    python scripts/eval_risk.py --workers 2          # 40 seeds (1000-1039) per type, writes out/risk/
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ptw_env.cli import road_bank
from ptw_env.jobs import JobsError, run_jobs

from assist.risk.evaluation import (EVAL_KINDS, KINDS, LATENCY_LOAD, LATENCY_S, LEAD_S, WARNABLE_S, estimator_figures,
                                    make_case, oracle_could, run_case)
from ptw_env.friction import SCALINGS
from assist.risk.offline import plot_risk, replay
from _outputs import add_overwrite, output_dir, write_results  # noqa: E402  (scripts/_outputs.py)

#: Monitor variants compared on the same estimator outputs: the default (caution also when the grip is
#: not confirmed at 2 sigma) and one that acts on the estimate alone.
VARIANTS = {"default": {}, "estimate_only": {"confirm_sigmas": 0.0}}

_PIPES: dict = {}  # one pipeline per road-bank setting in each worker (its design is the slow part)
#: --road-bank ("auto", the default; a number [rad]; None: the estimator's level road), set by main()
_ROAD_BANK: float | str | None = "auto"


def _one(args: tuple) -> dict:
    """One ride: ``(kind, seed, figure path or None, road bank setting, friction scaling)``; everything the
    job needs is in its arguments (a spawned worker or a Dask worker does not see this process's globals)."""
    kind, seed, fig, bank, scaling = args
    from assist.risk.pipeline import RiskPipeline, default_estimator

    from assist.risk.friction_estimate import FrictionConfig, FrictionEstimate
    from assist.risk.monitor import RiskConfig, RiskMonitor

    key = repr((bank, scaling))
    if key not in _PIPES:  # the friction reading that matches the tires: their bend (peak) or their slope
        tire = "peak" if scaling == "peak" else "stiffness"
        _PIPES[key] = RiskPipeline(default_estimator(5.0, tire=tire), road_bank=bank,
                                   monitor=RiskMonitor(friction=FrictionEstimate(FrictionConfig(tire=tire))))
    pipe = _PIPES[key]

    from ptw_env.scenarios import ScenarioError

    t0 = time.perf_counter()
    try:
        case = make_case(kind, seed, scaling)
    except ScenarioError as e:
        if kind != "wet_corner":
            raise
        return {"kind": kind, "seed": seed, "no_ride": str(e)}  # its route has no corner of the drawn demand
    res = run_case(case, pipeline=pipe)
    out = {}
    for name, over in VARIANTS.items():
        run = res.run if not over else replay(res.run, RiskMonitor(RiskConfig(**over), friction=FrictionEstimate(
            pipe.monitor.friction.config)))
        s = res.summary(run, observation=True)
        w = run.warnings()
        s["warning_reasons"] = [e["reason"] for e in w][:6]
        s["unconfirmed_cautions"] = sum(1 for e in w if "not confirmed" in e["reason"])
        out[name] = s
    s = out["default"]
    s["variants"] = {k: v for k, v in out.items() if k != "default"}
    s["estimator"] = estimator_figures(res)
    s["seconds"] = round(time.perf_counter() - t0, 2)
    if fig:
        plot_risk(res.run, fig, mu_true=res.mu_true, true_utilisation=res.utilisation, saturation_t=res.events,
                  title=f"risk warning, {kind} ride, seed {seed}")
        s["figure"] = fig
    return s


def _stats(x: list[float]) -> dict:
    if not x:
        return {"n": 0, "min": None, "median": None, "max": None}
    a = np.asarray(x, dtype=float)
    return {"n": int(a.size), "min": round(float(a.min()), 3), "median": round(float(np.median(a)), 3),
            "max": round(float(a.max()), 3)}


def summarise(rides: list[dict], variant: str = "default") -> dict:
    """Per ride type: rides, saturation events, detections and lead times, false alarms."""
    if variant != "default":
        # the variants differ in the monitor only: the estimator's figures are the ride's
        rides = [{**r["variants"][variant], "kind": r["kind"], "estimator": r["estimator"]} for r in rides]
    out: dict = {}
    for kind in KINDS:
        rs = [r for r in rides if r["kind"] == kind]
        if not rs:
            continue
        ev = [e for r in rs for e in r["events"]]
        first = [r["events"][0] for r in rs if r["events"]]
        d: dict = {"rides": len(rs), "rides_with_saturation": sum(1 for r in rs if r["events"]),
                   "saturation_events": len(ev), "fell": sum(r["fell"] for r in rs),
                   "peak_true_utilisation_max": round(max(max(r["max_true_utilisation"]) for r in rs), 3),
                   "peak_true_utilisation_median": round(float(np.median([max(r["max_true_utilisation"]) for r in rs])), 3)}
        for lev in ("caution", "danger"):
            leads = [e[lev]["lead_s"] for e in ev if e[lev]["lead_s"] is not None]
            d[lev] = {
                "detected": len(leads),
                "detected_0p5s": sum(1 for x in leads if x >= LEAD_S),
                "missed": len(ev) - len(leads),
                "lead_s": _stats(leads),
                "late_s_of_missed": _stats([e[lev]["late_s"] for e in ev if e[lev]["lead_s"] is None
                                            and e[lev]["late_s"] is not None]),
                "first_event_lead_s": _stats([e[lev]["lead_s"] for e in first if e[lev]["lead_s"] is not None]),
            }
        if kind.startswith("wet"):  # split by whether the patch began early enough to be seen (WARNABLE_S)
            on = [(r["estimator"].get("onset_to_saturation_s"), r["events"][0]) for r in rs if r["events"]]
            ok = [e for o, e in on if o is not None and o >= WARNABLE_S]
            # the others: grip lost within WARNABLE_S of the drop; each with the true |F|/Fz of the more
            # loaded axle at the drop (in a corner: a large share) and its caution lead
            late = [(r["estimator"]["onset_to_saturation_s"], r["estimator"].get("load_at_drop"),
                     r["events"][0]["caution"]["lead_s"]) for r in rs if r["events"]
                    and r["estimator"].get("onset_to_saturation_s") is not None
                    and r["estimator"]["onset_to_saturation_s"] < WARNABLE_S]
            d["warnable"] = {"events": len(ok),
                             "caution_0p5s": sum(1 for e in ok if (e["caution"]["lead_s"] or 0.0) >= LEAD_S),
                             # the lead of those warned 0.5 s or more ahead
                             "lead_s": _stats([e["caution"]["lead_s"] for e in ok if (e["caution"]["lead_s"] or 0.0) >= LEAD_S]),
                             "too_late_onset_to_saturation_s": _stats([o for o, _ in on if o is not None and o < WARNABLE_S]),
                             "too_late": [{"onset_to_saturation_s": round(o, 2),
                                           "load_at_drop": None if ld is None else round(ld, 3),
                                           "caution_lead_s": None if c is None else round(c, 2)} for o, ld, c in late]}
        minutes = sum(r["duration_s"] for r in rs) / 60.0
        d["false_alarms"] = None
        if kind.startswith("dry"):
            d["false_alarms"] = {
                "rides_with_caution": sum(1 for r in rs if r["caution_episodes"] > 0),
                "rides_with_danger": sum(1 for r in rs if r["danger_episodes"] > 0),
                "caution_episodes": sum(r["caution_episodes"] for r in rs),
                "caution_episodes_unconfirmed_grip": sum(r["unconfirmed_cautions"] for r in rs),
                "danger_episodes": sum(r["danger_episodes"] for r in rs),
                "caution_per_min": round(sum(r["caution_episodes"] for r in rs) / minutes, 4),
                "danger_per_min": round(sum(r["danger_episodes"] for r in rs) / minutes, 4),
                "minutes": round(minutes, 2),
            }
        upright = [r["mu_hat_final"] for r in rs if not r["fell"]]
        d["mu_hat_final_median_upright"] = round(float(np.median(upright)), 3) if upright else None
        out[kind] = d
    return out


def estimator_summary(rides: list[dict]) -> dict:
    """Bias, calibration and reaction of the friction estimate, per ride type."""
    out: dict = {}
    for kind in KINDS:
        rs = [r["estimator"] for r in rides if r["kind"] == kind]
        if not rs:
            continue
        med = [r["rel_error"]["median"] for r in rs if "rel_error" in r]
        d = {"rides": len(rs), "rel_error_median": _stats(med),
             "within_2sigma_median": round(float(np.median([r["within_2sigma"] for r in rs if "within_2sigma" in r])), 3)
             if med else None,
             "informed_fraction_median": round(float(np.median([r["informed_fraction"] for r in rs])), 3)}
        if any("excitation_s" in r for r in rs):
            d["excitation_s"] = _stats([r["excitation_s"] for r in rs if r.get("excitation_s") is not None])
            d["detect_s"] = _stats([r["detect_s"] for r in rs if r.get("detect_s") is not None])
            d["not_detected"] = sum(1 for r in rs if r.get("excitation_s") is not None and r.get("detect_s") is None)
            d["detected_before_saturation_s"] = _stats([r["before_saturation_s"] for r in rs
                                                        if r.get("before_saturation_s") is not None])
        out[kind] = d
    return out


def estimator_markdown(est: dict) -> str:
    """Table of :func:`estimator_summary`."""
    lines = ["| ride | mu_hat/mu_true - 1 (median of rides: min / median / max) | within 2 sigma | informed "
             "| patch: time to excitation [s] | excitation to mu_hat within 20 % [s] | detection to saturation [s] |",
             "|---|---|---|---|---|---|---|"]

    def mm(s):
        return "-" if not s or s["n"] == 0 else f"{s['min']:.2f} / {s['median']:.2f} / {s['max']:.2f}"

    for kind, d in est.items():
        lines.append(f"| {kind} | {mm(d['rel_error_median'])} | {d['within_2sigma_median']} | "
                     f"{d['informed_fraction_median']} | {mm(d.get('excitation_s'))} | {mm(d.get('detect_s'))} "
                     f"{'' if not d.get('not_detected') else '(' + str(d['not_detected']) + ' never)'} | "
                     f"{mm(d.get('detected_before_saturation_s'))} |")
    return "\n".join(lines) + "\n"


def markdown(summary: dict, n: int) -> str:
    """The results table."""
    lines = [
        f"Risk warning, {n} seeds per ride type (rides per type: the table), 5 % sensor noise, tire_saturation on "
        "(saturation: |F_ss| >= 0.95 Fmax on either axle, from the simulator's true state). "
        "Lead = saturation instant - onset of the warning active then; target >= 0.5 s. Road bank given to "
        f"the estimator: {'none (level road)' if _ROAD_BANK is None else _ROAD_BANK}.",
        "",
        "| ride | rides / saturating | events | caution: warned (>= 0.5 s) | caution lead min / median [s] "
        "| danger: warned (>= 0.5 s) | danger lead min / median [s] | false alarms (rides with caution / danger) "
        "| peak true util. (median / max) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for kind, d in summary.items():
        c, g = d["caution"], d["danger"]
        fa = d["false_alarms"]
        fa_s = (f"{fa['rides_with_caution']}/{d['rides']} ({fa['caution_episodes_unconfirmed_grip']} of "
                f"{fa['caution_episodes']} episodes 'grip not confirmed') / {fa['rides_with_danger']}/{d['rides']}"
                if fa else "-")

        def mm(s):
            return "-" if s["n"] == 0 else f"{s['min']:.2f} / {s['median']:.2f}"

        ev = d["saturation_events"]
        lines.append(
            f"| {kind} | {d['rides']} / {d['rides_with_saturation']} | {ev} | "
            f"{c['detected']}/{ev} ({c['detected_0p5s']}) | {mm(c['lead_s'])} | "
            f"{g['detected']}/{ev} ({g['detected_0p5s']}) | {mm(g['lead_s'])} | {fa_s} | "
            f"{d['peak_true_utilisation_median']:.2f} / {d['peak_true_utilisation_max']:.2f} |")
    for kind, d in summary.items():
        w = d.get("warnable")
        if w:
            lines.append("")
            late = w["too_late_onset_to_saturation_s"]
            text = (f"{kind}: of the rides' first losses of grip, the {w['events']} that came at least {WARNABLE_S:g} s "
                    f"after the friction dropped: {w['caution_0p5s']} had a caution at least 0.5 s ahead (their lead min / median "
                    f"{w['lead_s']['min']} / {w['lead_s']['median']} s)")
            if late["n"]:
                cases = "; ".join(
                    f"{c['onset_to_saturation_s']:.2f} s, |F|/Fz {c['load_at_drop']}, caution "
                    + ("none" if c["caution_lead_s"] is None else f"{c['caution_lead_s']:.2f} s ahead")
                    for c in w["too_late"])
                text += (f"; the other {late['n']} came within {WARNABLE_S:g} s of the drop (time from the drop, "
                         f"true |F|/Fz of the more loaded axle at the drop, caution lead: {cases}). A patch that "
                         f"begins under tires already loaded in a corner (|F|/Fz ~0.3 and more) takes the grip "
                         f"before the tires have told anything: no warning that reads them can lead by 0.5 s there")
            lines.append(text + ".")
    return "\n".join(lines) + "\n"


def real_floor(p: argparse.ArgumentParser, folder: Path) -> dict[str, float]:
    """The observation oracle's largest evidence on each measured ride ``*.csv`` of ``folder`` (read as logs.md
    says, the part its sidecar marks usable, with the vehicle its sidecar names) [nats]: what the model's error
    alone sums to on a dry road (the rides are taken as dry: state it for a folder of your own). A folder that is
    not one, or holds no log, or a log that cannot be read stops the run (``--real none`` runs without it, e.g.
    where ``../shared/data`` is not beside the repository)."""
    from assist.risk.evaluation import observation_evidence
    from ptw_env.logs import read_log, usable_part
    from ptw_env.vehicle_files import vehicle_of_log

    if not folder.is_dir():
        p.error(f"--real: {folder} is not a folder (give a folder of measured dry rides, or 'none')")
    paths = sorted(folder.glob("*.csv"))
    if not paths:
        p.error(f"--real: no ride log (*.csv) in {folder} (give a folder of measured dry rides, or 'none')")
    out = {}
    for path in paths:
        try:
            log, _ = usable_part(read_log(str(path)))
            vehicle = vehicle_of_log(log.meta or {}, str(path))
            out[path.stem] = float(observation_evidence(log, vehicle=vehicle).max())
        except (OSError, ValueError) as e:  # the log's, the vehicle file's and the filter's errors name the place
            p.error(f"--real: {e}" if str(path) in str(e) else f"--real: {path}: {e}")
    return out


def _pct(x: list[float], q: float) -> float | None:
    """Percentile ``q`` of ``x`` (None: empty, or beyond the values: rides that never warned count as inf)."""
    if not x:
        return None
    v = float(np.percentile(np.asarray(x, dtype=float), q))
    return round(v, 3) if math.isfinite(v) else None


def targets(rides: list[dict], real: dict[str, float] | None = None) -> dict:
    """Issue 20's targets per ride type: lead, latency and false warnings, with the oracles beside them (the
    window oracle, :func:`assist.risk.evaluation.information_onset`; the sequential oracle,
    :func:`assist.risk.evaluation.sequential_evidence`, its threshold set on the dry rides of this run to warn
    on ORACLE_FALSE_SHARE of them; the observation oracle, the same way, and, given ``real`` (the observation
    oracle's largest evidence on each measured dry ride [nats]), also at the smallest threshold above all of
    them and its simulated one: held to the real rides' model error)."""
    from assist.risk.evaluation import ORACLE_FALSE_SHARE, oracle_threshold

    dry_max = [m for r in rides if r["kind"].startswith("dry") for m in r.get("oracle_dry_max", [])]
    h = oracle_threshold(dry_max) if dry_max else None
    dry_obs = [m for r in rides if r["kind"].startswith("dry") for m in r.get("observation_dry_max") or []]
    ho = oracle_threshold(dry_obs) if dry_obs else None
    # held to measured rides: the smallest threshold on the stored 0.01-nat grid above the largest measured value
    hr = None if ho is None or not real else max(ho, math.floor(100.0 * max(real.values()) + 1.0) / 100.0)
    out: dict = {"_sequential_oracle": {"threshold_nats": None if h is None else round(h, 3),
                                        "false_share": ORACLE_FALSE_SHARE, "dry_ride_draws": len(dry_max)},
                 "_observation_oracle": {"threshold_nats": None if ho is None else round(ho, 3),
                                         "false_share": ORACLE_FALSE_SHARE, "dry_ride_draws": len(dry_obs),
                                         "largest_dry_nats": max(dry_obs) if dry_obs else None,
                                         "real_threshold_nats": hr,
                                         "real_dry_max": None if real is None else {k: round(v, 3)
                                                                                    for k, v in real.items()}}}
    for kind in KINDS:
        rs = [r for r in rides if r["kind"] == kind]
        if not rs:
            continue
        d: dict = {"rides": len(rs)}
        ev = [e for r in rs for e in r["events"] if e.get("after_reference_s") is not None]
        late = [e for e in ev if e["after_reference_s"] >= WARNABLE_S]
        if ev:
            miss = [e for e in late if (e["caution"]["lead_s"] or 0.0) < LEAD_S]
            d["lead"] = {"events": len(ev), "events_1s_after": len(late),
                         "warned_0p5s": len(late) - len(miss),
                         "missed": [{"seed": r["seed"], "t": round(e["t"], 2),
                                     "after_reference_s": round(e["after_reference_s"], 2),
                                     "caution_lead_s": None if e["caution"]["lead_s"] is None
                                     else round(e["caution"]["lead_s"], 2),
                                     "information_lead_bound_s": None if e["information_lead_bound_s"] is None
                                     else round(e["information_lead_bound_s"], 2),
                                     "sequential_could": None if h is None or "sequential_max" not in e
                                     else oracle_could(e["sequential_max"], h),
                                     "observation_could": None if ho is None or "observation_max" not in e
                                     else oracle_could(e["observation_max"], ho),
                                     "observation_real_could": None if hr is None or "observation_max" not in e
                                     else oracle_could(e["observation_max"], hr),
                                     "filter_evidence_max": e.get("filter_evidence_max")}
                                    for r in rs for e in r["events"] if e in miss],
                         "oracle_warnable_0p5s": sum(1 for e in late if (e["information_lead_bound_s"] or 0.0) >= LEAD_S),
                         "sequential_warnable_0p5s": (sum(1 for e in late if oracle_could(e.get("sequential_max"), h))
                                                      if any("sequential_max" in e for e in late) else None),
                         "observation_warnable_0p5s": (sum(1 for e in late if oracle_could(e.get("observation_max"), ho))
                                                       if ho is not None and any("observation_max" in e for e in late)
                                                       else None),
                         "observation_real_warnable_0p5s": (sum(1 for e in late if oracle_could(e.get("observation_max"), hr))
                                                            if hr is not None and any("observation_max" in e for e in late)
                                                            else None),
                         # every loss of grip, also those within WARNABLE_S of the drop / curve entry
                         "all_warned_0p5s": sum(1 for e in ev if (e["caution"]["lead_s"] or 0.0) >= LEAD_S),
                         "all_oracle_0p5s": sum(1 for e in ev if (e["information_lead_bound_s"] or 0.0) >= LEAD_S),
                         "all_caution_lead_s": _stats([e["caution"]["lead_s"] for e in ev
                                                       if e["caution"]["lead_s"] is not None])}
        lat = [r["latency"] for r in rs if r.get("latency") and kind.startswith("wet")
               and r["latency"]["load_at_reference"] >= LATENCY_LOAD]
        if lat:
            c = [x["caution_after_s"] for x in lat if x["caution_after_s"] is not None]
            o = [x["information_after_s"] for x in lat if x["information_after_s"] is not None]
            d["latency"] = {"rides_loaded": len(lat), "caution_within": sum(1 for x in c if x <= LATENCY_S),
                            # a ride that never cautioned counts as an infinite latency (None: not reached)
                            "caution_never": len(lat) - len(c),
                            "caution_median_s": _pct(c + [math.inf] * (len(lat) - len(c)), 50),
                            "caution_p95_s": _pct(c + [math.inf] * (len(lat) - len(c)), 95), "oracle_within": sum(1 for x in o if x <= LATENCY_S),
                            "oracle_median_s": _pct(o, 50), "oracle_p95_s": _pct(o, 95),
                            "sequential_within": sum(1 for x in lat if oracle_could(x.get("sequential_max"), h)),
                            "observation_within": sum(1 for x in lat if oracle_could(x.get("observation_max"), ho)),
                            "observation_real_within": None if hr is None
                            else sum(1 for x in lat if oracle_could(x.get("observation_max"), hr))}
        if kind.startswith("dry"):
            d["false"] = {"rides_with_danger": sum(1 for r in rs if r["danger_episodes"] > 0),
                          "rides_with_caution": sum(1 for r in rs if r["caution_episodes"] > 0),
                          "caution_share": round(sum(1 for r in rs if r["caution_episodes"] > 0) / len(rs), 4),
                          "filter_evidence_max": max((r["filter_evidence_dry_max"] for r in rs
                                                      if r.get("filter_evidence_dry_max") is not None), default=None)}
        out[kind] = d
    return out


def _or_never(v: float | None) -> str:
    return "never" if v is None else f"{v:g}"


def targets_markdown(tg: dict, scaling: str) -> str:
    """The table of :func:`targets`."""
    from assist.risk.evaluation import ORACLE_FALSE_SHARE

    so = tg.get("_sequential_oracle") or {}
    h = so.get("threshold_nats")
    oo = tg.get("_observation_oracle") or {}
    ho = oo.get("threshold_nats")
    lines = [f"Issue 20's targets, tires with friction scaling '{scaling}' (5 % sensor noise). Oracle: a reader of the "
             "tires that knows the true state, sure at 2 standard errors of 0.3 s of accelerometer noise. Sequential "
             "oracle (`assist.risk.evaluation.sequential_evidence`): the CUSUM of a reader that knows the true state "
             "and the wet friction, reading the accelerometer, its threshold set on this run's dry rides to warn on "
             f"{100 * so.get('false_share', ORACLE_FALSE_SHARE):g} % of them ("
             + ("no dry ride in this run: not evaluated" if h is None else
                f"{h:g} nats over {so['dry_ride_draws']} ride-draws") + "); it could where it does in at least half "
             "of its noise draws. Observation oracle (`assist.risk.evaluation.observation_evidence`): the CUSUM of "
             "a reader of the warning's own sensors that knows the dry and the wet friction but not the state (the "
             "friction filter with those two models only), its threshold set the same way ("
             + ("not evaluated" if ho is None else
                f"{ho:g} nats over {oo['dry_ride_draws']} ride-draws, largest {oo['largest_dry_nats']:g}")
             + "), the same rule over its draws (the ride's own sensors and other noise)"
             + ("" if oo.get("real_threshold_nats") is None else
                "; held to measured rides, its threshold at least above its largest evidence on "
                f"{len(oo['real_dry_max'])} measured dry rides (their own vehicle; "
                + ", ".join(f"{k} {v:g}" for k, v in sorted(oo["real_dry_max"].items(), key=lambda kv: -kv[1])[:2])
                + f" nats the largest): {oo['real_threshold_nats']:g} nats, the last figure in brackets")
             + ".", "",
             "| ride | rides | lead: losses of grip >= 1 s after drop/entry, caution >= 0.5 s ahead (oracle could; "
             "sequential oracle could; observation oracle could; the same held to measured rides) "
             "| every loss of grip: caution >= 0.5 s ahead (oracle could); median lead [s] "
             "| latency: loaded drops (|F|/Fz >= 0.2), caution <= 0.3 s; median / p95 [s] (oracle; sequential "
             "oracle within 0.3 s; observation oracle within 0.3 s; the same held to measured rides) "
             "| false: rides with danger / caution (share); the filter's largest evidence [nats] |",
             "|---|---|---|---|---|---|"]
    for kind, d in tg.items():
        if kind.startswith("_"):
            continue
        le = d.get("lead")
        la = d.get("latency")
        fa = d.get("false")
        sq = None if not le or le.get("sequential_warnable_0p5s") is None or h is None else le["sequential_warnable_0p5s"]
        ob = None if not le or ho is None else le.get("observation_warnable_0p5s")
        obr = None if not le else le.get("observation_real_warnable_0p5s")
        lead = "-" if not le else (f"{le['warned_0p5s']} of {le['events_1s_after']} ({le['oracle_warnable_0p5s']}; "
                                   f"{'-' if sq is None else sq}; {'-' if ob is None else ob}"
                                   + ("" if obr is None else f"; {obr}") + ")")
        alle = "-" if not le else (f"{le['all_warned_0p5s']} of {le['events']} ({le['all_oracle_0p5s']}); "
                                   f"{le['all_caution_lead_s']['median']}")
        lat = "-" if not la else (f"{la['caution_within']} of {la['rides_loaded']} ({la['caution_never']} never); "
                                  f"{_or_never(la['caution_median_s'])} / {_or_never(la['caution_p95_s'])} "
                                  f"(oracle {la['oracle_within']} of "
                                  f"{la['rides_loaded']}; {la['oracle_median_s']} / {la['oracle_p95_s']}; "
                                  f"{'-' if h is None else la.get('sequential_within', '-')}; "
                                  f"{'-' if ho is None else la.get('observation_within', '-')}"
                                  + ("" if oo.get("real_threshold_nats") is None
                                     else f"; {la.get('observation_real_within', '-')}") + ")")
        fal = "-" if not fa else (f"{fa['rides_with_danger']} / {fa['rides_with_caution']} "
                                  f"({100 * fa['caution_share']:.1f} %); "
                                  f"{'-' if fa.get('filter_evidence_max') is None else fa['filter_evidence_max']}")
        lines.append(f"| {kind} | {d['rides']} | {lead} | {alle} | {lat} | {fal} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog="example: python scripts/eval_risk.py --seeds 20 --workers 2")
    p.add_argument("--seeds", type=int, default=40, help="seeds per ride type (default 40)")
    p.add_argument("--first-seed", type=int, default=1000,
                   help="first seed (default 1000: seeds 1000-1039, fixed before the first run of issue 20's evaluation)")
    p.add_argument("--kinds", default=",".join(EVAL_KINDS),
                   help=f"comma-separated ride types (default {','.join(EVAL_KINDS)}; known: {','.join(KINDS)})")
    p.add_argument("--scaling", default="peak", choices=SCALINGS,
                   help="what road friction scales in the tires: the peak (default) or stiffness and peak (earlier model)")
    p.add_argument("--workers", type=int, default=1, help="local processes (default 1), or the size of a local "
                                                         "Dask cluster with --scheduler local")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a Dask scheduler tcp://HOST:PORT or 'local' (ptw_env.jobs; the [cluster] extra)")
    p.add_argument("--out", default="out/risk", help="output directory (default out/risk/)")
    p.add_argument("--figure-seed", type=int, default=None, help="seed of the timeline figures (default: the first)")
    p.add_argument("--road-bank", default="auto", metavar="RAD|auto|none",
                   help="road bank given to the estimator (RiskPipeline road_bank): 'auto' (default, estimated on "
                        "line), a number in rad, or 'none' (the estimator's level road)")
    p.add_argument("--real", default=str(Path(__file__).resolve().parents[2] / "shared" / "data" / "robot_bicycle"),
                   metavar="DIR|none",
                   help="folder of measured dry rides (logs.md, each with its vehicle) on which the observation "
                        "oracle's model error is measured (default ../shared/data/robot_bicycle; 'none': not held to "
                        "measured rides)")
    add_overwrite(p)
    a = p.parse_args(argv)
    global _ROAD_BANK
    if a.road_bank.lower() in ("auto", "none"):
        _ROAD_BANK = None if a.road_bank.lower() == "none" else "auto"
    else:
        try:
            _ROAD_BANK = road_bank(a.road_bank)  # the CLI's check: a finite angle in rad, |bank| < 0.5
        except argparse.ArgumentTypeError as e:
            p.error(f"--road-bank: 'auto', 'none' or {e}")
    kinds = [k for k in a.kinds.split(",") if k]
    if not kinds:
        p.error(f"--kinds: no ride type given (known: {', '.join(KINDS)})")
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        p.error(f"--kinds: unknown ride type(s) {', '.join(bad)} (known: {', '.join(KINDS)})")
    if a.seeds < 1 or a.first_seed < 0:
        p.error(f"--seeds must be >= 1 and --first-seed >= 0 (seeds are non-negative), got {a.seeds}, {a.first_seed}")
    if a.figure_seed is not None and not a.first_seed <= a.figure_seed < a.first_seed + a.seeds:
        p.error(f"--figure-seed must be one of the seeds run, {a.first_seed}-{a.first_seed + a.seeds - 1}, got "
                f"{a.figure_seed}")
    if a.workers < 1:
        p.error(f"--workers must be >= 1, got {a.workers}")
    real = None
    if a.real.lower() != "none":  # before the rides: a log the oracle cannot read stops the run here, not after
        real = real_floor(p, Path(a.real))
    out = output_dir(p, a.out, a.overwrite)
    fseed = a.first_seed if a.figure_seed is None else a.figure_seed
    jobs = [(k, s, str(out / f"timeline_{k}.png") if s == fseed else None)
            for k in kinds for s in range(a.first_seed, a.first_seed + a.seeds)]
    t0 = time.perf_counter()
    try:  # the execution layer: serial, local processes (--workers) or a Dask cluster (--scheduler)
        done = run_jobs(_one, [((k, s), ((k, s, fig, _ROAD_BANK, a.scaling),)) for k, s, fig in jobs], workers=a.workers,
                        scheduler=a.scheduler, desc="rides")
    except JobsError as e:
        p.error(str(e))
    rides = [r for r in done.values() if "no_ride" not in r]
    no_ride = [r for r in done.values() if "no_ride" in r]
    if not rides:
        p.error("no ride left to evaluate: " + "; ".join(f"{r['kind']} seed {r['seed']}: {r['no_ride']}" for r in no_ride))
    # the rides first: a summary that fails must not lose them
    (out / "rides.json").write_text(json.dumps(rides, indent=1, allow_nan=False, default=float) + "\n")
    # on peak-scaling tires the default monitor already acts on the estimate alone (confirm_sigmas 0)
    variants = {k: v for k, v in VARIANTS.items() if a.scaling != "peak" or k == "default"}
    summary = {v: summarise(rides, v) for v in variants}
    est = estimator_summary(rides)
    tg = targets(rides, real)
    res = {"seeds": list(range(a.first_seed, a.first_seed + a.seeds)), "road_bank": _ROAD_BANK, "scaling": a.scaling,
           "variants": variants, "targets": tg, "summary": summary, "no_ride": no_ride,
           "estimator": est, "rides": rides, "seconds": round(time.perf_counter() - t0, 1)}
    md = "### targets (issue 20)\n\n" + targets_markdown(tg, a.scaling) + "\n" + "".join(
        f"No {r['kind']} ride for seed {r['seed']}: {r['no_ride']}.\n\n" for r in no_ride) + "\n".join(f"### monitor: {v} {variants[v] or '(defaults)'}\n\n" + markdown(summary[v], a.seeds)
                   for v in variants) + "\n### friction estimate vs truth\n\n" + estimator_markdown(est)
    write_results(out, res, md, f"{len(rides)} rides in {res['seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
