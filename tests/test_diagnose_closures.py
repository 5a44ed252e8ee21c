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
``ay (1 - gravity_gain)``, a scale error. These four are found by the library's search alone, without
the table (the last test).

Measured (seed 51, 45 s, reference sensors): yaw_aero 0.0761 for 0.0756, yaw_vx_vy -3.040 for
-3.026, lateral_vx_vy -2.201 for -2.232, delta_offset 0.00971 for 0.01, ay_offset 0.297 for 0.3,
steer_self_aligning -1.362 for -1.389 (at 0.6 of its bound on the urban ride it is extended as
yaw_vx_vy instead, gain 0.05: a known confusion); ay_scale 0.2 named ay_frame -0.178. Sensor drifts
(linear in time, about the middle of the windows' span; the coefficient is the offset's change from the
middle to the end; seed 51, injected about the middle of the windows' span): yaw_rate_drift 0.01036 for
0.01 rad/s, roll_rate_drift -0.01008 for -0.01 rad/s, ay_drift 0.1486 for 0.15 m/s^2, each the only term,
extending the nominal model and explaining the log.
"""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from assist.diagnose.diagnosis import replay_windows
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
    if term.endswith("_drift"):  # a linear drift of the channel's offset, c at the end of the windows' span
        lg = ride("handling", None, seed=SEED)
        win, _ = replay_windows(lg, REFERENCE_SCOOTER)
        return sensor_error(lg, term[: -len("_drift")], offset=c * (lg.t - win.t_mid) / win.t_half)
    raise AssertionError(term)


CASES = [
    ("steer_self_aligning", -0.8 * HI["steer_self_aligning"]),
    ("yaw_aero", 0.3 * HI["yaw_aero"]),
    ("yaw_vx_vy", -0.3 * HI["yaw_vx_vy"]),
    ("lateral_vx_vy", -0.3 * HI["lateral_vx_vy"]),
    ("delta_offset", 0.01),
    ("ay_offset", 0.3),
    ("yaw_rate_drift", 0.01),  # a MEMS gyro warming up: 0.02 rad/s over the ride
    ("roll_rate_drift", -0.01),
    ("ay_drift", 0.15),
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
    if term.endswith("_drift"):  # a sensor's drift: alone, said to be a data problem, not carried by a twin
        from assist.diagnose.twin import twin

        assert list(terms) == [term], terms
        assert f"{term}: the sensors' (a channel's offset, scale or drift), a data problem" in rep.summary()
        assert any(n.startswith(term) and "no sensor drift" in n for n in twin(rep)["not_reproduced"])


def test_an_accelerometer_scale_error_is_named_as_its_equivalent_ay_frame():
    lg = ride("handling", None, seed=SEED)
    ay_true = (lg.columns["x_Fyf"] + lg.columns["x_Fyr"]) / REFERENCE_SCOOTER.mass  # model.md's ay row
    rep = diagnose(sensor_error(lg, "ay", scale=0.2, truth=ay_true), progress=False)
    assert rep.causes[0]["cause"] == "ay_frame" and rep.explained, rep.causes
    assert abs(-rep.causes[0]["params"]["gravity_gain"] - 0.2) <= 0.15 * 0.2  # measured 0.178


# ------------------------------------------------------------------ the library alone, where the table claims the effect
def _closure_search_alone(log):
    """The extension's forward selection (:func:`assist.diagnose.extension.extend`) from the nominal model,
    with the diagnosis's replay, noise weights, fitting and held-out windows, but no table cause; it stops at
    the first supported term."""
    import numpy as np

    from assist.diagnose.diagnosis import SCORE_STATE_STEPS, nominal_replay
    from assist.diagnose.extension import extend
    from assist.diagnose.hypotheses import MAX_NFEV, HypothesisFitter

    win, _, replay, _ = nominal_replay(log, "log", REFERENCE_SCOOTER)
    fit_w, test_w = np.flatnonzero(win.train), np.flatnonzero(~win.train)
    nominal = replay.params.nominal
    rt, _ = replay.fit_states(nominal[None], test_w, steps=SCORE_STATE_STEPS)
    return extend(HypothesisFitter(replay, fit_w, max_nfev=MAX_NFEV), nominal, test_w, win.score[test_w].sum(axis=1),
                  win.channels, float((rt**2).sum()), explains=lambda z: True, score_steps=SCORE_STATE_STEPS)


def _claimed_log(term: str, c: float):
    if term == "steer_viscous":  # a steering damper stiffer than nominal: effects.md's steer_damping
        nominal = param_set(REFERENCE_SCOOTER).vehicle_scales.steer_damping
        return ride("handling", {"steer_damping": {"damping_nms": nominal - c}}, seed=SEED)
    if term == "steer_offset":  # a torque the rider's sensor does not record (test plant)
        return ride_outside("handling", SEED, torque=lambda x, vx: c)
    if term == "roll_offset":  # effects.md's roll_moment_offset
        return ride("handling", {"roll_moment_offset": {"moment_nm": c}}, seed=SEED)
    lg = ride("handling", None, seed=SEED)  # ay_scale: an accelerometer reading (1 + c) ay
    ay_true = (lg.columns["x_Fyf"] + lg.columns["x_Fyr"]) / REFERENCE_SCOOTER.mass
    return sensor_error(lg, "ay", scale=c, truth=ay_true)


CLAIMED = [
    ("steer_viscous", -0.3 * HI["steer_viscous"]),
    ("steer_offset", 0.3 * HI["steer_offset"]),
    ("roll_offset", 0.3 * HI["roll_offset"]),
    ("ay_scale", 0.2),
]


@pytest.mark.parametrize("term, c", CLAIMED, ids=[c[0] for c in CLAIMED])
def test_a_term_the_table_claims_is_found_by_the_library_alone(term, c):
    """The four closure terms whose physics a table cause also carries (``steer_viscous`` is steer_damping,
    ``roll_offset`` roll_moment_offset, ``steer_offset`` a bank's twin, ``ay_scale`` ay_frame's twin in a
    turn) cannot be hidden where no table hypothesis claims them: the diagnosis rightly names the table
    cause. The library's search alone, from the nominal model, must still find each with its coefficient
    within 25 % (issue 19). Measured (seed 51): steer_viscous -24.11 for -23.90 N m s/rad, steer_offset 4.929
    for 4.930 N m, roll_offset 121.0 for 121.03 N m, ay_scale 0.1990 for 0.2; the runner-up each time is the
    twin term (steer_coulomb, roll_offset, steer_offset, ay_offset)."""
    ext = _closure_search_alone(_claimed_log(term, c))
    assert ext is not None and ext.terms[0]["name"] == term, None if ext is None else ext.steps[0]
    assert abs(ext.terms[0]["coefficient"] - c) <= 0.25 * abs(c), ext.terms[0]
