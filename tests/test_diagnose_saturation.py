"""Tire saturation vs a lower cornering stiffness (issue 19, item 4).

Both lower the lateral force at a given slip; only a force that stops growing with slip in the
corners shows a saturation. Where the held-out data separate them the diagnosis names the right
one with its size; where they do not, the report says "ambiguous between A and B" with both fitted
sizes (:func:`assist.diagnose.selection.ambiguity`).

Measured (45 s rides, reference sensors, noise on, seed 61, mu_peak 0.6): slalom (tires at up to
0.37 of their load sideways) named ``tire_saturation`` 0.604, held-out improvement 0.093 noise
variances per value against 0.018 for the stiffness change (0.92/0.93): separated. On this
project's own plant no ride of the five scenarios at seeds 61-62 came out ambiguous; the rule is
therefore also tested on held-out evidence built by hand (below), which is what it reads.
"""

from __future__ import annotations

import numpy as np

from assist.diagnose import diagnose, selection
from test_diagnose import ride


def test_a_ride_that_uses_the_grip_separates_saturation_from_stiffness():
    rep = diagnose(ride("slalom", {"tire_saturation": {"mu_peak": 0.6}}, seed=61), pairs=False, progress=False)
    assert rep.causes[0]["cause"] == "tire_saturation", rep.causes
    assert abs(rep.causes[0]["params"]["mu_peak"] - 0.6) <= 0.25 * 0.6, rep.causes
    assert rep.ambiguous is None and "ambiguous" not in rep.to_json()["verdict"]
    imp = {"+".join(c["cause"] for c in h["causes"]): h["improvement"] for h in rep.hypotheses}
    assert imp["tire_saturation"] - imp["tire_stiffness"] >= selection.MIN_IMPROVEMENT, imp


def _ranked(S, counts):
    names = ["none", "tire_stiffness", "tire_saturation", "road_bank"]
    causes = [(), ("tire_stiffness",), ("tire_saturation",), ("road_bank",)]
    return selection.rank(names, causes, [0, 2, 1, 1], S, counts, ("roll_rate",))


def test_the_ambiguity_rule_reads_the_held_out_evidence():
    """Ten held-out windows of 100 values, noise-weighted squares per window: nominal 200 each; the
    stiffness model (2 parameters) 140 (improvement 0.6 per value); the saturation model (1) 140 + d."""
    counts = np.full((10, 1), 100)
    base = np.full((10, 1), 200.0)

    def case(d_sat: np.ndarray):
        S = np.stack([base, base - 60.0, base - 60.0 + d_sat[:, None], base - 1.0])
        ranked = _ranked(S, counts)
        verdict = selection.choose(ranked)
        return verdict, selection.ambiguity(ranked, verdict, S, counts)

    # saturation worse by 1.5 per window (0.015 per value < MIN_IMPROVEMENT): ambiguous
    verdict, amb = case(np.full(10, 1.5))
    assert verdict.name == "tire_stiffness" and amb is not None
    rival, margin = amb
    assert rival.name == "tire_saturation" and margin < 0
    # saturation worse by 10 per window everywhere (0.1 per value): separated
    verdict, amb = case(np.full(10, 10.0))
    assert verdict.name == "tire_stiffness" and amb is None
    # worse by 100 in one window only: rests on one window, not separated
    d = np.zeros(10)
    d[3] = 100.0
    verdict, amb = case(d)
    assert amb is not None
    # a rival that gains nothing over nominal is no rival
    S = np.stack([base, base - 60.0, base + 5.0, base - 1.0])
    ranked = _ranked(S, counts)
    assert selection.ambiguity(ranked, selection.choose(ranked), S, counts) is None


def test_an_ambiguous_verdict_is_in_the_json_and_the_summary():
    rep = diagnose(ride("double_lane_change", {"road_bank": {"bank_rad": 0.05}}, seed=3, duration_s=24.0),
                   pairs=False, progress=False)
    rep.ambiguous = {"between": [[{"cause": "tire_stiffness", "params": {"front_scale": 0.8, "rear_scale": 0.84}}],
                                 [{"cause": "tire_saturation", "params": {"mu_peak": 0.6}}]],
                     "separation_margin": -0.004}
    assert rep.to_json()["verdict"]["ambiguous"]["between"][1][0]["params"]["mu_peak"] == 0.6
    s = rep.summary()
    assert "ambiguous between tire_stiffness(front_scale=0.8, rear_scale=0.84) and tire_saturation(mu_peak=0.6)" in s
