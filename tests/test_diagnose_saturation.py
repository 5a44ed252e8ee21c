"""Tire saturation vs a lower cornering stiffness (issue 19, item 4).

Both lower the lateral force at a given slip; only a force that stops growing with slip in the
corners shows a saturation. Where the held-out data separate them the diagnosis names the right
one with its size; where they do not, the report says "ambiguous between A and B" with both fitted
sizes (:func:`assist.diagnose.selection.ambiguity`).

Measured (45 s rides, reference sensors, noise on): slalom, seed 61, mu_peak 0.6 (tires at up to
0.37 of their load sideways) named ``tire_saturation`` 0.604, held-out improvement 0.093 noise
variances per value against 0.018 for the stiffness change (0.92/0.93): separated. Constant radius
(a steady turn at 28 m/s), seeds 61 / 63 / 64 (``python scripts/eval_saturation.py``, stored in
docs/results/diagnose_saturation.txt; the tests below ride seed 61): mu_peak 0.8 named ``tire_saturation`` 0.811 / 0.849 /
0.818, separated; mu_peak 1.5 ambiguous (margins -0.0047 / -0.0006 / -0.0051, saturation fitted 1.41 /
1.375 / 1.363, the mimicking stiffness 0.85-0.86 / 0.88); a stiffness change of 0.8 named
``tire_stiffness`` 0.80-0.81, separated. The handling ride at mu_peak 0.6 (seeds 61 / 63 / 64) is named
``tire_saturation`` 0.600 / 0.599 / 0.593 since the sideslip start is picked by the window's replay and
the second fit runs wherever the start asks for a sideslip (it was a stiffness change 0.95 / 0.93 at seed
61: the true model's fit from vy = 0 trapped one held-out window at 2.4e6 noise variances). The rule is
also tested on held-out evidence built by hand (below), which is what it reads.
"""

from __future__ import annotations

import numpy as np
import pytest

from assist.diagnose import diagnose, selection
from assist.diagnose.diagnosis import replay_windows
from assist.diagnose.params import CAUSES, NOMINAL
from assist.diagnose.replay import Replay, window_costs
from ptw_env.sensors import DEFAULT_NOISE_STD, SensorConfig
from ptw_env.vehicle import REFERENCE_SCOOTER, VY
from test_diagnose import ride


def test_a_ride_that_uses_the_grip_separates_saturation_from_stiffness():
    rep = diagnose(ride("slalom", {"tire_saturation": {"mu_peak": 0.6}}, seed=61), pairs=False, progress=False)
    assert rep.causes[0]["cause"] == "tire_saturation", rep.causes
    assert abs(rep.causes[0]["params"]["mu_peak"] - 0.6) <= 0.25 * 0.6, rep.causes
    assert rep.ambiguous is None and "ambiguous" not in rep.to_json()["verdict"]
    imp = {"+".join(c["cause"] for c in h["causes"]): h["improvement"] for h in rep.hypotheses}
    assert imp["tire_saturation"] - imp["tire_stiffness"] >= selection.MIN_IMPROVEMENT, imp


def test_a_saturation_a_state_fit_from_vy_0_trapped_is_named():
    """The handling ride at mu_peak 0.6, seed 61: one held-out window's fit from vy = 0 reached the right
    sideslip with the other states trapped (2.4e6 noise variances for the true model), so a stiffness
    change 0.95 / 0.93 was named; the second fit from the sideslip start now runs wherever the start asks."""
    rep = diagnose(ride("handling", {"tire_saturation": {"mu_peak": 0.6}}, seed=61), pairs=False, progress=False)
    assert rep.causes[0]["cause"] == "tire_saturation", rep.causes
    assert abs(rep.causes[0]["params"]["mu_peak"] - 0.6) <= 0.25 * 0.6, rep.causes
    imp = {"+".join(c["cause"] for c in h["causes"]): h["improvement"] for h in rep.hypotheses}
    assert imp["tire_saturation"] > imp["tire_stiffness"] + selection.MIN_IMPROVEMENT, imp


def test_a_saturation_whose_slide_window_sits_on_a_force_plateau_is_named():
    """The steady turn at mu_peak 0.6, seed 64, slides out; in the window that holds the slide the first
    sample's force cannot tell the candidate sideslips apart (a saturated plateau), and the smallest
    |beta| of them (vy -0.72 m/s for a true -0.83) trapped the state fit (cost 1e5-1e6 noise variances),
    so a stiffness change 0.80 / 0.83 was named; the start now takes the candidate whose replay of the
    window fits best (measured: tire_saturation 0.648)."""
    rep = diagnose(ride("constant_radius", {"tire_saturation": {"mu_peak": 0.6}}, seed=64), pairs=False,
                   progress=False)
    assert rep.causes[0]["cause"] == "tire_saturation", rep.causes
    assert abs(rep.causes[0]["params"]["mu_peak"] - 0.6) <= 0.25 * 0.6, rep.causes


def test_the_sideslip_start_finds_the_lateral_velocity_no_sensor_reads():
    """Replay.start under the true model of the mu_peak 0.8 turn: in the windows of the turn (true
    |vy| > 0.5 m/s, none is measured) it starts within 0.1 m/s of the true vy, where the measured start
    says 0; fitted from vy = 0 alone those windows diverge (cost above 1e6 noise variances, measured
    5e8-1e9), fitted from both starts (Replay.fit_states, the diagnosis's path) all but two of the 14
    come to within 3 noise variances per scored value (measured 1.2-2.3; the other two 4.0 and 42:
    two Gauss-Newton steps do not always reach the noise). On the straight lead-in (true |vy| < 0.01 m/s) the
    start keeps vy = 0."""
    log = ride("constant_radius", {"tire_saturation": {"mu_peak": 0.8}}, seed=61)
    win, _ = replay_windows(log, REFERENCE_SCOOTER)
    rp = Replay(win, np.array([DEFAULT_NOISE_STD[c] for c in win.channels]))
    Z = NOMINAL[None].copy()
    Z[0, CAUSES["tire_saturation"][0]] = 1.0 / 0.8  # the search variable is 1 / mu_peak
    allw = np.arange(len(win))
    vy_true = np.asarray(log["x_vy"])[win.starts]
    xs = rp.start(Z, allw)[0]
    turn, straight = np.abs(vy_true) > 0.5, np.abs(vy_true) < 0.01
    assert turn.sum() >= 5 and straight.sum() >= 2, vy_true
    assert np.all(np.abs(xs[turn, VY] - vy_true[turn]) < 0.1), (xs[turn, VY], vy_true[turn])
    assert np.all(xs[straight, VY] == rp.x_guess[straight, VY])
    x0 = rp.x_guess[None]
    r0, P = rp.linearise(Z, allw, x0)
    r_guess, _ = rp.gauss_newton(Z, allw, x0, r0, P, 2)
    r_both, _ = rp.fit_states(Z, allw)
    counts = win.score.sum(axis=(1, 2))
    assert np.all(window_costs(r_guess)[0, turn] > 1e6)
    per_value = window_costs(r_both)[0, turn] / counts[turn]
    assert np.sum(per_value < 3.0) >= turn.sum() - 2, per_value  # measured: 12 of 14, 1.2-2.3 (one 4.0, one 42)


def test_only_a_saturation_that_bites_gets_the_second_start():
    """The second start favours no hypothesis: in the turn at mu_peak 0.8 the nominal (linear) model's
    force misses the measured one too, but a linear tire gets no second start, nor does a saturation so
    weak that the tire is linear (mu_peak 1000, the search's bound): in one mixed batch its start stays
    at the measured one and its fit is bit-identical to the fit from that start alone (the nominal row
    never gets a second fit: Replay.saturating), while the saturation at 0.8 moves in every window of
    the turn and fits it better."""
    log = ride("constant_radius", {"tire_saturation": {"mu_peak": 0.8}}, seed=61)
    win, _ = replay_windows(log, REFERENCE_SCOOTER)
    rp = Replay(win, np.array([DEFAULT_NOISE_STD[c] for c in win.channels]))
    isat = CAUSES["tire_saturation"][0]
    Z = np.repeat(NOMINAL[None], 3, axis=0)
    Z[1, isat], Z[2, isat] = 1e-3, 1.0 / 0.8  # 1 / mu_peak: 1000 and 0.8
    allw = np.arange(len(win))
    turn = np.abs(np.asarray(log["x_vy"])[win.starts]) > 0.5
    xs = rp.start(Z, allw)
    assert np.all(xs[0, turn, VY] != rp.x_guess[turn, VY])  # the linear tire's force asks for a sideslip too
    assert np.all(xs[1, :, VY] == rp.x_guess[:, VY])
    assert np.all(xs[2, turn, VY] != rp.x_guess[turn, VY])
    assert list(rp.saturating(Z)) == [False, True, True]
    r, x, _ = rp.fit_from_starts(Z, allw, 2)
    x0 = np.repeat(rp.x_guess[None], 3, axis=0)
    r0, P = rp.linearise(Z, allw, x0)
    r_guess, x_guess = rp.gauss_newton(Z, allw, x0, r0, P, 2)
    assert np.array_equal(r[1], r_guess[1]) and np.array_equal(x[1], x_guess[1])  # mu 1000: no second fit
    assert np.all(window_costs(r)[2, turn] < window_costs(r_guess)[2, turn])


def _sizes(rep) -> dict[str, dict]:
    return {"+".join(c["cause"] for c in h["causes"]): h for h in rep.hypotheses}


def test_a_steady_turn_near_the_limit_is_named_saturation():
    """Constant-radius ride, 28 m/s, mu_peak 0.8 (tires at ~0.7 of their peak in the turn): the force
    has stopped growing with slip, and the saturation wins over a stiffness change by more than the
    separation margin. (Before each model's start took its own sideslip, ``Replay.start``, this ride
    was named tire_stiffness 0.77/0.80: every window of the turn diverged from ``vy = 0``.)"""
    rep = diagnose(ride("constant_radius", {"tire_saturation": {"mu_peak": 0.8}}, seed=61), pairs=False,
                   progress=False)
    assert rep.causes[0]["cause"] == "tire_saturation", rep.causes
    assert abs(rep.causes[0]["params"]["mu_peak"] - 0.8) <= 0.25 * 0.8, rep.causes
    assert rep.ambiguous is None, rep.ambiguous
    h = _sizes(rep)
    assert h["tire_saturation"]["improvement"] - h["tire_stiffness"]["improvement"] >= selection.MIN_IMPROVEMENT


def test_a_mild_steady_turn_is_ambiguous_between_saturation_and_stiffness():
    """The same turn on a grippier tire (mu_peak 1.5: ~0.37 of the peak used) stays on the nearly
    straight part of the tanh: a stiffness 0.86/0.88 mimics it, the held-out data do not separate
    them, and the report says so with both fitted sizes. The same ride with a stiffness change of
    0.8 (no saturation) is named and separated."""
    rep = diagnose(ride("constant_radius", {"tire_saturation": {"mu_peak": 1.5}}, seed=61), pairs=False,
                   progress=False)
    assert rep.ambiguous is not None, [(h["causes"], h["improvement"]) for h in rep.hypotheses[:3]]
    between = {c[0]["cause"]: c[0]["params"] for c in rep.ambiguous["between"]}
    assert set(between) == {"tire_saturation", "tire_stiffness"}
    assert abs(between["tire_saturation"]["mu_peak"] - 1.5) <= 0.25 * 1.5, between
    assert 0.7 <= between["tire_stiffness"]["front_scale"] <= 0.95, between  # the mimicking stiffness
    assert rep.to_json()["verdict"]["ambiguous"]["between"] == rep.ambiguous["between"]
    assert "ambiguous between" in rep.summary()
    rep = diagnose(ride("constant_radius", {"tire_stiffness": {"front_scale": 0.8, "rear_scale": 0.8}}, seed=61),
                   pairs=False, progress=False)
    assert rep.causes[0]["cause"] == "tire_stiffness" and rep.ambiguous is None, (rep.causes, rep.ambiguous)
    assert abs(rep.causes[0]["params"]["front_scale"] - 0.8) <= 0.05, rep.causes
    assert not any("quantisation" in n for n in rep.method["notes"]), rep.method["notes"]  # a real change: no doubt


def test_a_clean_steady_turn_without_encoder_quantisation_names_nothing():
    """The clean turn's false stiffness verdict (next test) comes from the steering encoder: the same ride
    with the angle not quantised (the same seed and noise otherwise) gets no cause."""
    log = ride("constant_radius", None, seed=61, sensors=SensorConfig(delta_quantum=None))
    rep = diagnose(log, pairs=False, progress=False, encoder_quantum=None)
    assert [c["cause"] for c in rep.causes] == ["none"], rep.causes


@pytest.mark.xfail(strict=True, reason="known defect (README, 'Saturation or stiffness?'): in a steady turn the angle "
                   "barely moves, so the encoder's quantisation (q = 2 pi / 1024) is a constant bias, priced as white "
                   "noise, which a 1 % stiffness change absorbs: tire_stiffness 0.996 / 1.012 is named")
def test_a_clean_steady_turn_names_nothing():
    rep = diagnose(ride("constant_radius", None, seed=61), pairs=False, progress=False)
    assert [c["cause"] for c in rep.causes] == ["none"], rep.causes


def test_the_clean_steady_turns_verdict_says_it_may_be_the_encoder():
    """The defect above is said, not hidden (issue 19: never treat a data problem as a vehicle effect without
    saying so): the verdict's gain is largest in the steering angle, where it moves the prediction by less than
    half an encoder step (measured 0.81 mrad, q = 6.14 mrad), and the report's notes say it may be reading the
    encoder's quantisation."""
    rep = diagnose(ride("constant_radius", None, seed=61), pairs=False, progress=False)
    notes = [n for n in rep.method["notes"] if "quantisation" in n]
    assert rep.causes[0]["cause"] != "none" and len(notes) == 1, (rep.causes, rep.method["notes"])
    from ptw_env.sensors import ENCODER_QUANTUM

    assert f"under half the encoder's step ({1e3 * ENCODER_QUANTUM:.2f} mrad)" in notes[0]
    assert "note: " + notes[0] in rep.summary()


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


def test_an_ambiguous_verdict_is_reported_with_both_fitted_sizes(monkeypatch):
    """The diagnosis's wiring: when the rule finds a rival, the report names both with their own
    fitted sizes, in ``verdict.ambiguous`` and in the summary. The rule is forced here (the second
    best hypothesis as the rival) on a short banked ride, so that the test is about the wiring."""
    from assist.diagnose import diagnosis

    seen = {}

    def forced(ranked, verdict, S, counts):
        rival = [r for r in selection.order(ranked) if r.name not in ("none", verdict.name)][0]
        seen["rival"] = rival.name
        return rival, -0.004

    monkeypatch.setattr(diagnosis.selection, "ambiguity", forced)
    rep = diagnose(ride("double_lane_change", {"road_bank": {"bank_rad": 0.05}}, seed=3, duration_s=24.0),
                   pairs=False, progress=False)
    a = rep.to_json()["verdict"]["ambiguous"]
    assert a["between"][0] == rep.causes and a["separation_margin"] == -0.004
    rival = [h["causes"] for h in rep.hypotheses if "+".join(c["cause"] for c in h["causes"]) == seen["rival"]][0]
    assert a["between"][1] == rival  # the rival's own fitted sizes, as the hypotheses list has them
    assert "ambiguous between road_bank(bank_rad=" in rep.summary()


def test_two_starts_keep_the_better_state_fit_per_window():
    """``Replay.fit_states_from``: per (row, window) the weighted residual is the smaller of the fits
    from the measured start and from ``x_alt`` (and never above either)."""
    from assist.diagnose.diagnosis import replay_windows
    from assist.diagnose.replay import Replay
    from ptw_env.sensors import DEFAULT_NOISE_STD
    from ptw_env.vehicle import REFERENCE_SCOOTER

    win, _ = replay_windows(ride("double_lane_change", None, seed=4, duration_s=24.0), REFERENCE_SCOOTER)
    rp = Replay(win, np.array([DEFAULT_NOISE_STD[c] for c in win.channels]), REFERENCE_SCOOTER)
    w = np.arange(len(rp.win))
    z = np.stack([rp.params.nominal, rp.params.nominal])
    r1, x1 = rp.fit_states(z, w)
    bad = x1[0] + rp.state_scale * 3.0  # a poor second start
    r2, x2 = rp.fit_states_from(z, w, bad)
    n1, n2 = (np.einsum("mwkc,mwkc->mw", r, r) for r in (r1, r2))
    assert np.all(n2 <= n1 + 1e-9)
    r3, _ = rp.fit_states(z, w, x0=np.broadcast_to(bad, x1.shape).copy())
    n3 = np.einsum("mwkc,mwkc->mw", r3, r3)
    assert np.allclose(n2, np.minimum(n1, n3))
    # a good second start (the converged states) helps where the first fit stopped short
    r4, _ = rp.fit_states_from(z, w, x1[0], cross=True)
    assert np.all(np.einsum("mwkc,mwkc->mw", r4, r4) <= n1 + 1e-9)
