"""Hidden dynamic effects (effects.md) in simulated ride logs must be found: cause named, size within 25 %.

45 s rides with the reference logs' sensors (noise on), two scenarios, several signs; the exhaustive
sweep is ``test_diagnose_sweep.py`` (slow); the other dynamic causes are in
``test_diagnose_hidden_dynamics.py``.
"""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from test_diagnose import assert_found, ride

CASES = [
    ("handling", {"tire_stiffness": {"front_scale": 1.0, "rear_scale": 1.35}}, 22),
    ("handling", {"payload": {"mass_kg": -40.0}}, 26),
    ("urban", {"steer_damping": {"damping_nms": 25.0}}, 27),
    ("handling", {"relaxation_length": {"sigma_m": 0.35}}, 28),
]


@pytest.mark.parametrize("scenario, effects, seed", CASES, ids=[next(iter(c[1])) + "-" + c[0] for c in CASES])
def test_hidden_dynamic_effect_is_found(scenario, effects, seed):
    log = ride(scenario, effects, seed=seed)
    assert_found(diagnose(log, progress=False), effects)
