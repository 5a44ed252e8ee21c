"""Exhaustive sweep (slow): every cause of effects.md at several sizes and both signs, two scenarios,
full 90 s rides (and an 87 s track lap), sensor noise on (the reference logs' sensors, and 5 % of range),
no-effect rides, pairs, and a log without the roll column. Each must be named with every size within
25 % of the truth (of the effect's size, its deviation from nominal: ``test_diagnose.effect_size``) and
explained. Effects outside effects.md in the other scenario than ``test_diagnose_outside.py``'s must come
out unexplained, located where they act. Run with ``pytest -m slow tests/test_diagnose_sweep.py``.
"""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from ptw_env.ride import ride_scenario
from test_diagnose import assert_found
from test_diagnose_outside import OTHER_SCENARIO, case_ids, diagnose_outside

pytestmark = pytest.mark.slow

EFFECTS = [
    {},
    {"tire_stiffness": {"front_scale": 0.7, "rear_scale": 0.7}},
    {"tire_stiffness": {"front_scale": 1.0, "rear_scale": 0.75}},
    {"tire_stiffness": {"front_scale": 1.4, "rear_scale": 1.4}},
    {"road_bank": {"bank_rad": 0.03}},
    {"road_bank": {"bank_rad": -0.05}},
    {"roll_moment_offset": {"moment_nm": 30.0}},
    {"roll_moment_offset": {"moment_nm": -15.0}},
    {"payload": {"mass_kg": 60.0}},
    {"payload": {"mass_kg": -40.0}},
    {"steer_damping": {"damping_nms": 6.0}},
    {"steer_damping": {"damping_nms": 25.0}},
    {"relaxation_length": {"sigma_m": 0.35}},
    {"relaxation_length": {"sigma_m": 0.12}},
    {"gyro_bias": {"yaw_rate_bias": 0.01, "roll_rate_bias": -0.008}},
    {"gyro_bias": {"yaw_rate_bias": -0.006}},
    {"ay_frame": {"gravity_gain": 0.5}},
    {"ay_frame": {"gravity_gain": -1.0}},
    {"sensor_delay": {"delay_s": 0.03}},
    {"sensor_delay": {"delay_s": 0.015}},
    {"road_bank": {"bank_rad": 0.04}, "gyro_bias": {"yaw_rate_bias": 0.01}},
    {"tire_stiffness": {"front_scale": 0.7, "rear_scale": 0.7}, "payload": {"mass_kg": 60.0}},
]


def _id(e: dict) -> str:
    return "+".join(f"{c}:{','.join(f'{p}={v:g}' for p, v in ps.items())}" for c, ps in e.items()) or "none"


@pytest.mark.parametrize("scenario", ["urban", "handling"])
@pytest.mark.parametrize("effects", EFFECTS, ids=[_id(e) for e in EFFECTS])
def test_sweep_hidden_effect_is_found(scenario, effects):
    seed = 100 + EFFECTS.index(effects)
    log = ride_scenario(scenario, effects=effects, seed=seed).log
    assert_found(diagnose(log, progress=False), effects)


@pytest.mark.parametrize("effects, seed", [
    ({}, 201),
    ({"tire_stiffness": {"front_scale": 0.6, "rear_scale": 0.6}}, 202),
    ({"sensor_delay": {"delay_s": 0.04}}, 203),
    ({"road_bank": {"bank_rad": 0.05}}, 204),
], ids=["none", "tire_stiffness", "sensor_delay", "road_bank"])
def test_sweep_five_percent_noise(effects, seed):
    log = ride_scenario("urban", effects=effects, seed=seed, noise_pct=5.0).log
    assert_found(diagnose(log, progress=False), effects)


def test_sweep_tire_saturation():
    effects = {"tire_saturation": {"mu_peak": 0.5}}
    log = ride_scenario("urban", effects=effects, seed=16).log
    assert_found(diagnose(log, progress=False), effects)


@pytest.mark.parametrize("effects", [{}, {"road_bank": {"bank_rad": 0.04}}], ids=["none", "road_bank"])
def test_sweep_log_without_roll_column(effects):
    log = ride_scenario("urban", effects=effects, seed=205).log
    log = type(log)(t=log.t, columns={k: v for k, v in log.columns.items() if k != "roll"}, meta={})
    assert_found(diagnose(log, progress=False), effects)


@pytest.mark.parametrize("kind, scenario, seed", OTHER_SCENARIO, ids=case_ids(OTHER_SCENARIO))
def test_sweep_effect_outside_the_table(kind, scenario, seed):
    """The effects of ``test_diagnose_outside.py`` in the other scenario (45 s rides)."""
    diagnose_outside(kind, scenario, seed)
