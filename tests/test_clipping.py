"""Saturated sensors in real logs (issue 19, item 1): found, set aside and said, never read as the vehicle.

Truth: a simulated ride (sensor noise as the reference sensors) whose channel is clipped afterwards at a
limit, as a saturating sensor does; every reading beyond the limit is then known. The check
(:func:`ptw_env.logs.clipped_samples`) reads no vehicle number: the limit is found from the data.
Measured: on the 60 s urban ride of seed 7 every clipped reading of every channel is found and no other
(below); the shared logs, the 14 real robot-bicycle rides, noise-free and saturating-tire rides are not
flagged (one simulated ride whose rider's torque hits its limit of 60 N m is: a true limit).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import assist.cli.estimate  # noqa: F401  (registers the subcommands)
import assist.cli.risk  # noqa: F401
from assist.cli import main
from assist.diagnose import diagnose
from conftest import DATA
from ptw_env.logs import CLIP_CHANNELS, CLIP_MIN_RUN, RideLog, clipped_samples, read_log, without_clipped, write_log
from ptw_env.ride import ride_scenario
from ptw_env.rider import DEFAULT_TAU_MAX
from ptw_env.vehicle import REFERENCE_SCOOTER
from ptw_env.scenarios import make_scenario
from ptw_env.sensors import SensorConfig


@pytest.fixture(scope="module")
def ride() -> RideLog:
    return ride_scenario(make_scenario("urban", duration_s=60.0), seed=7).log


def clip(log: RideLog, channel: str, lo: float | None, hi: float | None) -> tuple[RideLog, np.ndarray]:
    """``log`` with ``channel`` clipped to ``[lo, hi]`` (None: that side open) and the mask of readings at a
    limit (those beyond it before the clip)."""
    x = np.asarray(log[channel], dtype=float)
    beyond = np.zeros(x.size, dtype=bool)
    y = x.copy()
    if hi is not None:
        beyond |= x >= hi
        y = np.minimum(y, hi)
    if lo is not None:
        beyond |= x <= lo
        y = np.maximum(y, lo)
    return RideLog(t=log.t, columns={**log.columns, channel: y}, meta=log.meta), beyond


@pytest.mark.parametrize("channel", CLIP_CHANNELS[:-1])  # "roll" (optional) is clipped in the two-sided test
def test_every_clipped_reading_is_found_and_no_other(ride, channel):
    x = ride[channel]
    hi = 0.6 * float(np.nanmax(x))
    log, beyond = clip(ride, channel, None, hi)
    assert beyond.sum() >= 10  # the ride reaches the limit
    found = clipped_samples(log)
    assert set(found) == {channel} and list(found[channel]) == [hi]
    np.testing.assert_array_equal(found[channel][hi], beyond)


@pytest.mark.parametrize("channel", ["ay", "roll", "delta"])
def test_a_channel_clipped_at_both_ends_is_found_at_both(ride, channel):
    x = ride[channel]
    a = 0.5 * float(np.nanmax(np.abs(x)))
    log, beyond = clip(ride, channel, -a, a)
    sides = clipped_samples(log)[channel]
    assert sorted(sides) == [-a, a]
    np.testing.assert_array_equal(sides[a] | sides[-a], beyond)


def test_clean_logs_and_flat_signals_are_not_clipped(ride):
    assert clipped_samples(ride) == {}
    for p in sorted(DATA.glob("*.csv")):
        assert clipped_samples(read_log(p)) == {}, p
    real = sorted((DATA / "robot_bicycle").glob("*.csv"))
    for p in real:  # rb_20130704_009's torque saturation was smoothed by the anti-alias resampling: no flat top
        assert clipped_samples(read_log(p)) == {}, p
    # noise-free ride: smooth maxima settle (no step into a flat top), held or quantised channels repeat anyway
    quiet = ride_scenario("constant_radius", seed=2, sensors=SensorConfig.noiseless()).log
    assert clipped_samples(quiet) == {}
    # a noisy signal resting exactly at zero between pulses is not clipped at zero (its own side of zero)
    t = np.arange(2000) * 0.01
    rng = np.random.default_rng(3)
    pulses = np.where(np.sin(t) > 0.2, np.sin(t) + 0.02 * rng.standard_normal(t.size), 0.0)
    cols = {c: np.sin(t + i) * 0.1 + 0.001 * rng.standard_normal(t.size)
            for i, c in enumerate(("delta", "delta_rate", "yaw_rate", "roll_rate", "ay"))}
    log = RideLog(t=t, columns={"t": t, "tau": pulses, "vx": np.full_like(t, 10.0), **cols})
    assert clipped_samples(log) == {}
    # the same pulses clipped at 0.8: found (the zero rule alone keeps the rest out)
    clipped = RideLog(t=t, columns={**log.columns, "tau": np.minimum(pulses, 0.8)})
    assert set(clipped_samples(clipped)) == {"tau"}
    # a smooth channel is not judged, so its clip is not seen (a known limit): the disclosed log's rider torque
    disclosed = read_log(DATA / "nominal_urban.csv")
    clipped_tau, _ = clip(disclosed, "tau", None, 0.5 * float(np.nanmax(disclosed["tau"])))
    assert clipped_samples(clipped_tau) == {}
    # a noise-free signal that ramps to a value and holds it: not a clip (not judged: no noise)
    hold = np.clip(np.minimum(3.0 * t, 30.0 - 3.0 * t), 0.0, 5.0) + 0.5
    log = RideLog(t=t, columns={**log.columns, "tau": hold, "yaw_rate": 0.04 * hold})
    assert clipped_samples(log) == {}


def test_diagnose_reads_a_clipped_gyro_as_a_sensor_not_the_vehicle(ride, monkeypatch):
    x = ride["roll_rate"]
    log, beyond = clip(ride, "roll_rate", None, 0.5 * float(np.nanmax(x)))
    rep = diagnose(log, pairs=False, progress=False)
    assert rep.causes[0]["cause"] == "none" and rep.explained and not rep.extended  # a clean model, as it is
    note = [n for n in rep.method["notes"] if "column 'roll_rate' reads its limit" in n]
    assert len(note) == 1 and f"{int(beyond.sum())} sample(s)" in note[0] and "clipped sensor" in note[0]
    # the same log with the check taken away: the flat tops are read as a vehicle effect
    import assist.diagnose.diagnosis as diagnosis

    monkeypatch.setattr(diagnosis, "without_clipped", lambda lg: (lg, []))
    blind = diagnose(log, pairs=False, progress=False)
    assert blind.causes[0]["cause"] != "none" and not blind.explained


@pytest.mark.parametrize("command", ["estimate", "risk"])
def test_estimate_and_risk_set_clipped_readings_aside_and_say_so(ride, tmp_path, capsys, command):
    log, _ = clip(ride, "yaw_rate", None, 0.6 * float(np.nanmax(ride["yaw_rate"])))
    log, beyond_tau = clip(log, "tau", 0.8 * float(np.nanmin(ride["tau"])), None)
    p = tmp_path / "clipped.csv"
    write_log(p, log.columns, meta=log.meta)
    out = tmp_path / "out.json"
    assert main([command, str(p), "--json", str(out)]) == 0
    notes = json.loads(out.read_text())["notes"]
    assert any("column 'yaw_rate' reads its limit" in n for n in notes)
    assert any("column 'tau' reads its limit" in n and f"{int(beyond_tau.sum())} sample(s)" in n for n in notes)
    # the torque's limit readings are unusable samples: the stretch kept holds none of them
    assert any("kept the longest ridden stretch" in n for n in notes)


def test_without_clipped_keeps_the_log_when_nothing_is_clipped(ride):
    same, notes = without_clipped(ride)
    assert same is ride and notes == []


def test_a_rider_at_the_torque_limit_is_a_limit_too():
    """The simulated rider's torque is limited (``ptw_env.rider``, 60 N m on the reference scooter): on a steady
    turn whose tires saturate (mu_peak 0.6, seed 2) the rider holds it there for a few samples, and the check
    finds exactly those, at the rider's limit (a limit of a sensor or an actuator: either way the replay cannot
    take the torque beyond it as known)."""
    log = ride_scenario("constant_radius", seed=2, effects={"tire_saturation": {"mu_peak": 0.6}}).log
    tau_max = DEFAULT_TAU_MAX * REFERENCE_SCOOTER.torque_ratio  # the rider's limit (ptw_env.rider)
    found = clipped_samples(log)
    assert set(found) == {"tau"} and [abs(v) for v in found["tau"]] == [tau_max]
    mask = next(iter(found["tau"].values()))
    assert mask.sum() >= CLIP_MIN_RUN
    np.testing.assert_array_equal(mask, np.abs(log["tau"]) == tau_max)
