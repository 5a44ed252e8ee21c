"""Two hidden effects at once, and an effect outside effects.md (issue 7)."""

from __future__ import annotations

import dataclasses

from assist.diagnose import diagnose
from ptw_env.vehicle import R, REFERENCE_SCOOTER, VY
from test_diagnose import assert_found, ride


def test_two_hidden_effects_are_both_found():
    effects = {"road_bank": {"bank_rad": 0.04}, "gyro_bias": {"yaw_rate_bias": 0.01}}
    log = ride("urban", effects, seed=34)
    assert_found(diagnose(log, progress=False), effects)


def test_effect_outside_the_table_is_not_given_a_confident_name():
    """A yaw moment proportional to the lateral velocity (A0 row 4, column 3 of a custom vehicle, -100 N m
    per m/s: no cause of effects.md) must come out unexplained, or as a closest cause with a small gain;
    and the report says where the residual lives."""
    A0 = REFERENCE_SCOOTER.A0.copy()
    A0[R, VY] -= 100.0  # N m per m/s of side velocity, in the yaw equation
    odd = dataclasses.replace(REFERENCE_SCOOTER, A0=A0, name="yaw-moment-from-side-velocity")
    log = ride("urban", None, seed=37, vehicle=odd)
    rep = diagnose(log, progress=False)
    assert (not rep.explained) or rep.gain < 0.2, rep.to_json()["verdict"]
    if not rep.explained:
        res = rep.to_json()["verdict"]["residual"]
        assert res["summary"].startswith("residual beyond noise in")
        assert max(v["excess"] for v in res["channels"].values()) > 0.2
        assert {"speed_mps", "lean_deg", "frequency_hz", "riding"} <= set(res)
