"""Issue 5 targets on seeded rides with tire saturation on (truth: the simulator's tire forces).

* dry ride at normal pace: never saturates, no danger warning;
* wet patch (0.9 -> 0.45) at unchanged pace and a curve entered too fast: grip is really lost
  (|F_ss| >= 0.95 Fmax), and a warning is active when it happens.
* the 0.5 s lead target: met by the caution on the too-fast rides; NOT met on the wet-patch rides
  (an expected failure, with the measured numbers: the patch is invisible until the tires carry
  lateral force, and on urban corners the front saturates 0.4-0.8 s after the lean-in starts).

Seeds are the first ones of each ride type (``scripts/eval_risk.py`` runs 20 per type).
"""

from __future__ import annotations

import pytest

from assist.risk.evaluation import make_case, run_case
from assist.risk.pipeline import RiskPipeline, default_estimator

SEEDS = (0, 1)


@pytest.fixture(scope="module")
def rides():
    pipe = RiskPipeline(default_estimator(5.0))
    return {(k, s): run_case(make_case(k, s), pipeline=pipe).summary() for k in ("dry", "wet", "too_fast")
            for s in SEEDS}


@pytest.mark.parametrize("seed", SEEDS)
def test_dry_ride_is_normal_pace_and_has_no_danger(rides, seed):
    s = rides[("dry", seed)]
    assert not s["fell"] and s["events"] == []
    assert 0.3 < max(s["max_true_utilisation"]) < 0.7  # cornering, but clearly below the grip
    assert s["danger_episodes"] == 0


@pytest.mark.parametrize("kind", ["wet", "too_fast"])
@pytest.mark.parametrize("seed", SEEDS)
def test_grip_is_lost_and_a_warning_is_active_when_it_happens(rides, kind, seed):
    s = rides[(kind, seed)]
    assert s["events"], "the ride must really lose grip"
    for e in s["events"]:
        assert e["caution"]["lead_s"] is not None and e["caution"]["lead_s"] > 0.0
        assert e["danger"]["lead_s"] is not None and e["danger"]["lead_s"] > 0.0


@pytest.mark.parametrize("seed", SEEDS)
def test_too_fast_curve_caution_half_a_second_ahead(rides, seed):
    for e in rides[("too_fast", seed)]["events"]:
        assert e["caution"]["lead_s"] >= 0.5


@pytest.mark.xfail(strict=True, reason="target not met on wet patches (scripts/eval_risk.py, 20 seeds): caution >= 0.5 s "
                   "ahead in 4 of 16 saturating urban rides (lead min 0.06 s, median 0.15 s) and 4 of 14 with 2.5 s "
                   "curve entries (median 0.27 s); the friction drop is seen only once the tires carry lateral force")
def test_wet_patch_warning_half_a_second_ahead(rides):
    for seed in SEEDS:
        for e in rides[("wet", seed)]["events"]:
            assert e["caution"]["lead_s"] >= 0.5
