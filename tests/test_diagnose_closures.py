"""Every closure term of the extension library, hidden alone in a simulated ride (issue 19).

The hidden effect is not in effects.md, so no table cause can claim it: the diagnosis must extend
the model with the closure term of :data:`assist.diagnose.params.CLOSURE_LIBRARY` that is the hidden
physics, and fit its coefficient within 25 % (issue 19; held to 10 % here). The dynamic terms are added by the test-only plant
of :mod:`outside_effects` (an RK4 that evaluates the extra force or moment at every stage, not the
project's generalised-force features), the sensor terms to the logged channel with the sensor's
noise kept. Sizes are fractions of each term's search bound, which follows the vehicle
(:func:`assist.diagnose.params.param_set`).

Covered elsewhere: ``yaw_rate_scale``, ``lateral_aero`` and ``roll_aero`` (``test_diagnose_extension.py``);
``steer_coulomb`` (urban ride, there; on this handling ride viscous damping still wins). Terms the table claims,
so that no closure is needed: ``steer_viscous`` is effects.md's ``steer_damping``, ``roll_offset`` its
``roll_moment_offset``, ``steer_offset`` its ``road_bank`` (``test_diagnose_outside.py``). And
``ay_scale`` is named as ``ay_frame`` (below): in a steady turn a partly unrotated accelerometer reads
``ay (1 - gravity_gain)``, a scale error.

Measured (seed 51, 45 s, reference sensors): yaw_aero 0.0761 for 0.0756, yaw_vx_vy -3.040 for
-3.026, lateral_vx_vy -2.201 for -2.232, delta_offset 0.00971 for 0.01, ay_offset 0.297 for 0.3,
steer_self_aligning -1.362 for -1.389 (at 0.6 of its bound on the urban ride it is extended as
yaw_vx_vy instead, gain 0.05: a known confusion); ay_scale 0.2 named ay_frame -0.178.
"""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from assist.diagnose.params import param_set
from outside_effects import ride_outside, sensor_error
from test_diagnose import ride
from ptw_env.vehicle import DELTA, REFERENCE_SCOOTER, VY

SEED = 51
HI = {p.cause: p.hi for p in param_set(REFERENCE_SCOOTER).params}


def _log(term: str, c: float):
    if term == "steer_self_aligning":
        return ride_outside("handling", SEED, torque=lambda x, vx: c * vx * x[DELTA])
    if term == "yaw_aero":
        return ride_outside("handling", SEED, yaw_moment=lambda x, vx: c * vx * vx)
    if term == "yaw_vx_vy":
        return ride_outside("handling", SEED, yaw_moment=lambda x, vx: c * vx * x[VY])
    if term == "lateral_vx_vy":  # a side force at the ground: the lateral equation only
        return ride_outside("handling", SEED, force=lambda x, vx: c * vx * x[VY], height=0.0)
    if term == "delta_offset":
        return sensor_error(ride("handling", None, seed=SEED), "delta", offset=c)
    if term == "ay_offset":
        return sensor_error(ride("handling", None, seed=SEED), "ay", offset=c)
    raise AssertionError(term)


CASES = [
    ("steer_self_aligning", -0.8 * HI["steer_self_aligning"]),
    ("yaw_aero", 0.3 * HI["yaw_aero"]),
    ("yaw_vx_vy", -0.3 * HI["yaw_vx_vy"]),
    ("lateral_vx_vy", -0.3 * HI["lateral_vx_vy"]),
    ("delta_offset", 0.01),
    ("ay_offset", 0.3),
]


@pytest.mark.parametrize("term, c", CASES, ids=[c[0] for c in CASES])
def test_hidden_closure_term_is_found_with_its_coefficient(term, c):
    rep = diagnose(_log(term, c), progress=False)
    v = rep.to_json()["verdict"]
    assert v["explained"] is False, v["causes"]  # no table cause explains it
    terms = {t["name"]: t for t in (v.get("extension") or {}).get("terms", [])}
    assert term in terms, (v["causes"], terms)
    # issue 19 asks for 25 %; measured within 3 % (module docstring), held to 10 %
    assert abs(terms[term]["coefficient"] - c) <= 0.10 * abs(c), terms[term]
    assert rep.extension["gain"] > rep.gain  # the closure buys held-out accuracy over the table's stand-in


def test_an_accelerometer_scale_error_is_named_as_its_equivalent_ay_frame():
    lg = ride("handling", None, seed=SEED)
    ay_true = (lg.columns["x_Fyf"] + lg.columns["x_Fyr"]) / REFERENCE_SCOOTER.mass  # model.md's ay row
    rep = diagnose(sensor_error(lg, "ay", scale=0.2, truth=ay_true), progress=False)
    assert rep.causes[0]["cause"] == "ay_frame" and rep.explained, rep.causes
    assert abs(-rep.causes[0]["params"]["gravity_gain"] - 0.2) <= 0.15 * 0.2  # measured 0.178
