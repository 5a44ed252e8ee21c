"""Hidden sensor effects and no effect (issue 7); pairs are in ``test_diagnose_hidden_pair.py``, effects
outside effects.md in ``test_diagnose_outside.py``.

45 s rides with noise on; the sensor effects are applied by :class:`ptw_env.sensors.SensorModel`
in the ride and fitted on the measurement side by the diagnosis.
"""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from test_diagnose import assert_found, ride

CASES = [
    ("handling", {"gyro_bias": {"yaw_rate_bias": 0.01, "roll_rate_bias": -0.008}}, 31, None),
    ("urban", {"ay_frame": {"gravity_gain": 0.5}}, 32, None),
    ("handling", {"sensor_delay": {"delay_s": 0.03}}, 33, None),
    ("urban", {}, 35, None),
    ("handling", {}, 36, 5.0),  # 5 % noise, the papers' level
]


@pytest.mark.parametrize("scenario, effects, seed, noise_pct", CASES,
                         ids=["+".join(c[1]) + "-" + c[0] if c[1] else "none-" + c[0] for c in CASES])
def test_hidden_sensor_effect_or_none_is_found(scenario, effects, seed, noise_pct):
    log = ride(scenario, effects, seed=seed, noise_pct=noise_pct)
    assert_found(diagnose(log, progress=False), effects)
