"""Two hidden effects at once (issue 7); effects outside effects.md are in ``test_diagnose_outside.py``."""

from __future__ import annotations

from assist.diagnose import diagnose
from test_diagnose import assert_found, ride


def test_two_hidden_effects_are_both_found():
    effects = {"road_bank": {"bank_rad": 0.04}, "gyro_bias": {"yaw_rate_bias": 0.01}}
    log = ride("urban", effects, seed=34)
    assert_found(diagnose(log, progress=False), effects)
