"""Hidden dynamic effects (effects.md) in simulated ride logs must be found: cause named, size within 25 %.

45 s rides with the reference logs' sensors (noise on), two scenarios, several signs; the exhaustive
sweep is ``test_diagnose_sweep.py`` (slow); the other dynamic causes are in
``test_diagnose_hidden_dynamics2.py``.
"""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from test_diagnose import assert_found, ride

CASES = [
    ("urban", {"tire_stiffness": {"front_scale": 0.7, "rear_scale": 0.7}}, 21),
    ("urban", {"tire_saturation": {"mu_peak": 0.5}}, 23),
    ("handling", {"road_bank": {"bank_rad": -0.04}}, 24),
    ("urban", {"roll_moment_offset": {"moment_nm": 25.0}}, 25),
]


@pytest.mark.parametrize("scenario, effects, seed", CASES, ids=[next(iter(c[1])) + "-" + c[0] for c in CASES])
def test_hidden_dynamic_effect_is_found(scenario, effects, seed):
    log = ride(scenario, effects, seed=seed)
    assert_found(diagnose(log, progress=False), effects)
