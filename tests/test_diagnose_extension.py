"""Model extension beyond the table of effects (diagnose.md ``verdict.extension``).

Effects outside effects.md are hidden in simulated rides by the test-only plants of
``tests/outside_effects.py`` (an independent RK4 that evaluates the extra force at every stage,
not the project's generalised-force features); no table cause can claim them, so the diagnosis
must extend the model with closure terms of its library and find their coefficients.
"""

from __future__ import annotations

import json

import pytest

from assist.diagnose import diagnose
from assist.diagnose.params import CLOSURES
from ptw_env.kernels import COULOMB_WIDTH
from outside_effects import ride_outside, yaw_gyro_scale
from test_diagnose import ride
from test_diagnose_outside import aero_side_force


def _terms(rep) -> dict[str, dict]:
    ext = rep.to_json()["verdict"].get("extension") or {}
    return {t["name"]: t for t in ext.get("terms", [])}


def _check_contract(rep) -> None:
    js = rep.to_json()
    json.dumps(js, allow_nan=False)
    v = js["verdict"]
    assert v["explained"] is False  # no table cause explains it: explained keeps its meaning
    ext = v["extension"]
    assert 0.0 < ext["gain"] <= 1.0
    for t in ext["terms"]:
        assert set(t) >= {"equation", "term", "coefficient", "unit", "std"}
        assert t["equation"] == CLOSURES[t["name"]].equation and t["std"] is not None and t["std"] > 0


def test_yaw_gyro_scale_error_is_found_as_a_sensor_closure(monkeypatch):
    """A yaw-rate gyro reading 1.2x: the closure yaw_rate * (1 + c) with c within 25 % of 0.2, alone,
    and the extended model explains the log (measured: c = 0.204 +- 0.001). The search starts from the
    nominal model and, its extension explaining the log, does not search from the table verdict too."""
    import assist.diagnose.extension as extension

    bases = []
    search = extension.extend

    def counted(fitter, base_z, *args, **kwargs):
        bases.append(base_z)
        return search(fitter, base_z, *args, **kwargs)

    monkeypatch.setattr(extension, "extend", counted)
    rep = diagnose(yaw_gyro_scale(ride("handling", None, seed=43), 1.2), progress=False)
    assert rep.causes[0]["cause"] != "none"  # a table verdict (a stand-in) that the search could have started from
    assert len(bases) == 1 and rep.extension["extends"] == "nominal model", (len(bases), rep.extension["extends"])
    _check_contract(rep)
    terms = _terms(rep)
    assert set(terms) == {"yaw_rate_scale"}, terms
    assert abs(terms["yaw_rate_scale"]["coefficient"] - 0.2) <= 0.25 * 0.2
    assert rep.extended and rep.extension["gain"] > rep.gain  # better than the table's stand-in


def test_aerodynamic_side_force_is_found_in_the_lateral_and_roll_equations(tmp_path):
    """F = 0.15 vx^2 [N] at 0.9 m: lateral c within 25 % of 0.15 N s^2/m^2 and roll c within 25 % of
    0.135 N m s^2/m^2 (measured 0.146 and 0.133), and the extended model explains the log."""
    rep = diagnose(ride_outside("handling", 42, force=aero_side_force(0.15)), progress=False)
    _check_contract(rep)
    terms = _terms(rep)
    assert {"lateral_aero", "roll_aero"} <= set(terms), terms
    assert abs(terms["lateral_aero"]["coefficient"] - 0.15) <= 0.25 * 0.15
    assert abs(terms["roll_aero"]["coefficient"] - 0.135) <= 0.25 * 0.135
    assert rep.extended
    _check_reported_model(rep, tmp_path)


def _check_reported_model(rep, tmp_path) -> None:
    """The reported model is the extension: ``extended_model()`` adds its closure forces to the model it
    extends (checked against model.md's ``E``: the force enters its equation's row, 3 lateral, 4 yaw,
    5 roll, 6 steer, through ``E^-1`` like every other generalised force), and the figure draws and names it."""
    import numpy as np
    import matplotlib

    from ptw_env.dynamics import compile_plant
    from ptw_env.effects import Effects

    base = rep.extension["extends"]
    base_plant = compile_plant(rep.vehicle, Effects.from_causes(base if isinstance(base, list) else []).dynamic)
    x, vx = np.array([0.05, 0.01, 0.2, 0.1, 0.02, 0.01, 50.0, 40.0]), 12.0
    g = np.zeros(8)
    features = {"1": 1.0, "vx^2": vx**2, "vx*vy": vx * x[2], "delta_dot": x[5], "vx*delta": vx * x[1],
                "tanh(delta_dot/w)": np.tanh(x[5] / COULOMB_WIDTH)}
    rows = {"lateral": 2, "yaw": 3, "roll": 4, "steer": 5}
    forces = [t for t in rep.extension["terms"] if not t["equation"].startswith("sensor:")]
    assert forces  # this ride's extension has force closures
    for t in forces:
        g[rows[t["equation"]]] += t["coefficient"] * features[CLOSURES[t["name"]].feature]
    got = rep.extended_model().rhs(x, 0.0, vx) - base_plant.rhs(x, 0.0, vx)
    np.testing.assert_allclose(got, np.linalg.solve(rep.vehicle.E, g), rtol=1e-10, atol=1e-9)  # measured 1e-14
    fig = rep.plot(str(tmp_path / "r.png"))
    labels = [t.get_text() for ax in fig.axes for t in (ax.get_legend().get_texts() if ax.get_legend() else [])]
    assert any(all(t["name"] in lab for t in rep.extension["terms"]) for lab in labels), labels
    # the bars are the drawn replays' RMS residuals, in noise levels
    d, chans = rep.plot_data, list(rep.nominal_rmse)
    e = np.where(d["score"], d["Y"] - d["Yext"], 0.0)
    want = np.sqrt((e**2).sum(axis=(0, 1)) / d["score"].sum(axis=(0, 1))) / np.array([rep.noise[c] for c in chans])
    bars = [p.get_height() for p in fig.axes[2].patches][len(chans):]
    np.testing.assert_allclose(bars, want, rtol=1e-12)
    matplotlib.pyplot.close(fig)


def test_a_log_the_table_explains_gets_no_closure():
    rep = diagnose(ride("urban", {"road_bank": {"bank_rad": 0.03}}, seed=5), progress=False)
    v = rep.to_json()["verdict"]
    assert v["explained"] and "extension" not in v and v["extended"] is False
    clean = diagnose(ride("urban", None, seed=6), pairs=False, progress=False).to_json()["verdict"]
    assert clean["causes"] == [{"cause": "none", "params": {}}] and "extension" not in clean


def test_coulomb_steering_friction_is_found_with_its_coefficient():
    """1.5 N m of Coulomb steering friction (``-Tc tanh(delta_dot / 0.02)``, the library's own form,
    by the test-only plant) on the urban ride: the diagnosis's table stand-in is a steering damping
    (41 N m s/rad); the extension names ``steer_coulomb`` with ``c`` within 25 % of -1.5 (measured
    -1.593) and explains the log with it. Before the initial-state fits had a second start (the
    current model's states, ``Replay.fit_states_from``) one held-out window was trapped in a local
    minimum and viscous damping (-28 N m s/rad) won. Known miss: on the handling ride (seed 51) the
    viscous term still wins (held-out improvement 4.8 against 1.5 noise variances per value)."""
    from test_diagnose_outside import coulomb_friction

    rep = diagnose(ride_outside("urban", 41, torque=coulomb_friction(1.5)), progress=False)
    terms = _terms(rep)
    assert "steer_coulomb" in terms, terms
    assert abs(terms["steer_coulomb"]["coefficient"] + 1.5) <= 0.25 * 1.5, terms
    assert rep.extended and rep.extension["gain"] > rep.gain
