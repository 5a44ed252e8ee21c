"""The hand fit of the steer equation (issue 19's comparison for the real rides), checked where the
truth is known: rides simulated with a hidden steering damping, on the robot bicycle and the scooter."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from assist.diagnose import DiagnoseInputError
from assist.diagnose.inverse_dynamics import steer_equation_fit
from ptw_env.ride import ride_scenario
from ptw_env.sensors import SensorConfig
from ptw_env.vehicle import REFERENCE_SCOOTER
from ptw_env.vehicle_files import load_vehicle

BICYCLE = load_vehicle("robot-bicycle")


def _ride(vehicle, kmh, damping, sensors=None, seed=2):
    eff = {"steer_damping": {"damping_nms": damping}} if damping else None
    return ride_scenario("double_lane_change", speed_kmh=kmh, vehicle=vehicle, effects=eff, seed=seed, sensors=sensors)


@pytest.mark.parametrize("vehicle, kmh, damping", [(BICYCLE, 14, 2.0), (REFERENCE_SCOOTER, 50, 25.0)],
                         ids=["robot-bicycle", "scooter"])
def test_a_hidden_steering_damping_is_recovered(vehicle, kmh, damping):
    r = _ride(vehicle, kmh, damping)  # default sensors: noise and encoder quantisation on
    fit = steer_equation_fit(r.log, vehicle, roll=r.log.columns["x_phi"])
    # effects.md's steer_damping sets a66 = -damping_nms; the fit measures what it adds to the file's own
    added = damping + float(vehicle.A0[5, 5])
    assert fit["damping_nms"] == pytest.approx(added, rel=0.02), fit  # measured -0.85 % (bicycle), -0.19 % (scooter)
    assert fit["damping_std"] < 0.1 * added, fit  # and the data say how well: a tight 1-sigma


def test_no_damping_is_fitted_on_a_clean_ride():
    r = _ride(BICYCLE, 14, 0.0, sensors=SensorConfig.noiseless())
    fit = steer_equation_fit(r.log, BICYCLE, roll=r.log.columns["x_phi"])
    assert abs(fit["damping_nms"]) < 0.05 and abs(fit["offset_nm"]) < 0.01, fit


def test_missing_lean_and_bad_options_are_refused():
    r = _ride(BICYCLE, 14, 0.0)
    log = dataclasses.replace(r.log, columns={k: v for k, v in r.log.columns.items() if k != "roll"})
    with pytest.raises(DiagnoseInputError, match="roll"):
        steer_equation_fit(log, BICYCLE)
    with pytest.raises(DiagnoseInputError, match="roll must be"):
        steer_equation_fit(r.log, BICYCLE, roll=np.zeros(3))
    with pytest.raises(DiagnoseInputError, match="window"):
        steer_equation_fit(r.log, BICYCLE, roll=r.log.columns["x_phi"], window=20)
