"""A diagnosed model carried to another log of the same vehicle (issue 19: gain across runs).

:func:`assist.diagnose.score_model` replays one log's fitted model, frozen, on another log. The
references are physical: a bank fitted on one banked ride predicts another banked ride of other
seeds better than the nominal model, and a level ride worse; a sensor cause is the ride's own
instruments, so with the sensor parameters at nominal (``parts="vehicle"``) it is the nominal model
exactly.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from assist.diagnose import DiagnoseInputError, TransferScore, diagnose, score_model
from assist.diagnose.diagnosis import sensor_indices
from assist.diagnose.params import CAUSES, CLOSURES, PARAMS, param_set
from test_diagnose import ride

BANK = {"road_bank": {"bank_rad": 0.05}}


def with_truth(report, effects):
    """``report`` with its model replaced by the true effects (the independent reference)."""
    z = param_set(report.vehicle).nominal
    for cause, params in effects.items():
        for i in CAUSES[cause]:
            z[i] = params[PARAMS[i].name]  # internal coordinates are the effects.md values (no inverse here)
    return dataclasses.replace(report, model_z=z)


@pytest.fixture(scope="module")
def bank_report():
    return diagnose(ride("double_lane_change", BANK, seed=3, duration_s=24.0), pairs=False, progress=False)


def test_a_fitted_bank_carries_to_another_banked_ride_and_not_to_a_level_one(bank_report):
    assert bank_report.causes[0]["cause"] == "road_bank"
    assert bank_report.explained and bank_report.extension is None
    assert np.array_equal(bank_report.model_z, bank_report.verdict_z)  # nothing extended: the verdict is the model
    other = ride("double_lane_change", BANK, seed=11, duration_s=24.0)
    banked = score_model(other, bank_report)
    truth = score_model(other, with_truth(bank_report, BANK))
    level = score_model(ride("double_lane_change", None, seed=11, duration_s=24.0), bank_report)
    assert isinstance(banked, TransferScore) and banked.windows >= 8
    # the reference: the true bank on the other ride; the fitted one does as well to 0.03
    assert truth.gain > 0.5, truth
    assert banked.gain > truth.gain - 0.03, (banked, truth)
    # on the level ride the fitted bank is a model error of the same size: worse than nominal
    assert level.gain < 0.0, level
    js = json.loads(json.dumps(banked.to_json(), allow_nan=False))
    assert js["model_from"] == bank_report.log and js["parts"] == "all" and not js["diverged"]


def test_a_sensor_cause_is_the_nominal_model_without_its_sensor_parameters():
    effects = {"gyro_bias": {"yaw_rate_bias": 0.01, "roll_rate_bias": -0.008}}
    rep = diagnose(ride("handling", effects, seed=31, duration_s=30.0), pairs=False, progress=False,
                   extend_model=False)
    assert rep.causes[0]["cause"] == "gyro_bias"
    other = ride("handling", effects, seed=41, duration_s=30.0)
    same_bias = score_model(other, rep)
    truth = score_model(other, with_truth(rep, effects))
    without = score_model(other, rep, parts="vehicle")
    assert truth.gain > 0.1, truth
    assert same_bias.gain > truth.gain - 0.03, (same_bias, truth)  # the same instruments: the bias carries over
    assert without.gain == pytest.approx(0.0, abs=1e-12)  # only sensor parameters were fitted


def test_sensor_indices_are_the_sensor_causes_and_sensor_closures():
    idx = set(sensor_indices())
    for c in ("gyro_bias", "ay_frame", "sensor_delay"):
        assert set(CAUSES[c]) <= idx
    for c in ("road_bank", "payload", "steer_damping", "tire_stiffness"):
        assert not set(CAUSES[c]) & idx
    names = {PARAMS[i].cause for i in idx}
    assert {n for n, t in CLOSURES.items() if t.equation.startswith("sensor:")} <= names
    assert "steer_viscous" not in names


def test_bad_arguments_are_refused(bank_report):
    log = ride("double_lane_change", BANK, seed=11, duration_s=24.0)
    with pytest.raises(DiagnoseInputError, match="parts"):
        score_model(log, bank_report, parts="sensors")
    with pytest.raises(DiagnoseInputError, match="model"):
        score_model(log, bank_report, model="best")
    with pytest.raises(DiagnoseInputError, match="DiagnosisReport"):
        score_model(log, {"verdict": {}})


def test_a_diverged_transfer_is_reported_without_inf_in_json():
    s = TransferScore("a.csv", "b.csv", "all", "reported", -math.inf, {"delta": -math.inf}, 3)
    js = json.loads(json.dumps(s.to_json(), allow_nan=False))
    assert s.diverged and js["diverged"] and js["gain"] is None and js["gain_channels"]["delta"] is None
