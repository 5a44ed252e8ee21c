"""The digital twin (issue 21): a twin made from a log with a known injected effect reproduces that
effect's size distribution in the environments, and a closure term of the diagnosis becomes a
generalised force of the twin's plants."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import ptw_env
from assist.cli import main
from assist.diagnose import diagnose
from assist.diagnose.twin import twin
from outside_effects import ride_outside
from ptw_env.env import PTWRollEnv
from ptw_env.randomize import Randomization
from ptw_env.vector import PTWRollVectorEnv
from ptw_env.vehicle import DELTA
from test_diagnose import ride

TRUE_PAYLOAD = 40.0


@pytest.fixture(scope="module")
def payload_twin(tmp_path_factory):
    """The twin of a 45 s urban ride with a hidden 40 kg payload, through the command line."""
    d = tmp_path_factory.mktemp("twin")
    log = ride("urban", {"payload": {"mass_kg": TRUE_PAYLOAD}}, seed=5)
    path = d / "ride.csv"
    from ptw_env.logs import write_log

    write_log(path, log)
    assert main(["twin", str(path), "--out", str(d / "twin.json"), "--no-progress"]) == 0
    return d / "twin.json"


def test_twin_reproduces_the_injected_effects_size_distribution(payload_twin):
    t = json.loads(payload_twin.read_text())
    kind, mean, std = t["randomize"]["payload:mass_kg"]
    assert kind == "normal" and std > 0
    # the measured distribution holds the truth (3 of its standard deviations: a calibrated uncertainty)
    assert abs(mean - TRUE_PAYLOAD) <= 3 * std, (mean, std)
    kw = Randomization.env_kwargs(str(payload_twin))
    assert set(kw) <= {"vehicle", "effects", "randomize"}
    n = 4000
    venv = PTWRollVectorEnv(num_envs=n, scenario="urban", **kw)
    _, info = venv.reset(seed=0)
    m = info["randomized"]["payload:mass_kg"]
    # the environments draw the twin's distribution: its mean and spread
    assert abs(m.mean() - mean) <= 4 * std / math.sqrt(n)
    assert abs(m.std() / std - 1) <= 4 / math.sqrt(2 * n)
    # and each env's plant carries its drawn payload (its steady roll gravity term, model.md a51 += m hp g)
    for i in (0, 1, 2):
        W, *_ = venv.plant_of(i)
        ref = ptw_env.compile_plant(venv.template.vehicle, {"payload": {"mass_kg": m[i]}})
        np.testing.assert_allclose(W, ref.W, rtol=1e-12, atol=1e-12)


def test_a_closure_term_becomes_a_force_of_the_twin():
    """A hidden self-aligning steering torque c vx delta (not in effects.md): the diagnosis extends the model
    with it, the twin carries it as force:steer:vx*delta, and the twin's plant adds that torque."""
    c = -1.389
    rep = diagnose(ride_outside("handling", 51, torque=lambda x, vx: c * vx * x[DELTA]), progress=False)
    t = twin(rep)
    kind, coef, std = t["randomize"]["force:steer:vx*delta"]
    assert abs(coef - c) <= 0.10 * abs(c) and std > 0
    env = PTWRollEnv(scenario="handling", randomize=t["randomize"])
    _, info = env.reset(seed=3)
    drawn = info["randomized"]["force:steer:vx*delta"]
    # the plant's steer row gains drawn * vx * delta through E^-1 (model.md row 6)
    base = ptw_env.compile_plant(env.vehicle, Randomization(t["randomize"]).effects(env.effects, info["randomized"]).dynamic)
    col = ptw_env.dynamics.FORCE_FEATURES["vx*delta"]
    np.testing.assert_allclose(env.plant.W[0:6, col] - base.W[0:6, col], base.Einv[0:6, 5] * drawn, rtol=1e-12, atol=1e-15)


def test_twin_options_are_checked(tmp_path, capsys):
    log = tmp_path / "missing.csv"
    assert main(["twin", str(log), "--out", str(tmp_path / "t.json")]) == 2
    assert "missing.csv" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["twin", str(log), "--out", str(tmp_path / "t.json"), "--spread", "0"])
    assert e.value.code == 2 and "--spread" in capsys.readouterr().err
    assert not (tmp_path / "t.json").exists()
