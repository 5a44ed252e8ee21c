"""Modal analysis: labels, physics of each mode, stability speed, JSON and figure.

Independent references: eigenvalues of E^-1 A(vx) computed here with numpy,
model.md's eigenvalue table, relaxation-length finite differences, cli.md's
JSON keys.
"""

from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
import pytest

from ptw_env.dynamics import compile_plant, linearise
from ptw_env.effects import EffectError
from ptw_env.modes import (
    LABELS,
    ModalResult,
    ModesInputError,
    classify,
    eigen_analysis,
    participation_factors,
    participation_shares,
    plot_modes,
)
from ptw_env.vehicle import REFERENCE_SCOOTER

V = REFERENCE_SCOOTER
SPEEDS = np.arange(3.0, 40.01, 0.5)
EXPECTED_COUNTS = {"weave": 2, "wobble": 2, "capsize": 1, "tire": 2, "other": 1}


@pytest.fixture(scope="module")
def dense() -> ModalResult:
    return eigen_analysis(speeds=SPEEDS)


def _eig(vx: float) -> np.ndarray:
    return np.linalg.eigvals(np.linalg.solve(V.E, V.A0 + vx * V.A1))


# ----------------------------------------------------------------------------- labels
def test_one_weave_wobble_capsize_two_tire_one_other_at_every_speed(dense):
    for v, labs, ev in zip(dense.speeds, dense.labels, dense.eigenvalues):
        assert Counter(labs) == EXPECTED_COUNTS, v
        # the reported eigenvalues are those of E^-1 A(vx), nothing lost or invented
        ref = _eig(v)
        assert np.allclose(np.sort_complex(ev), np.sort_complex(ref), rtol=1e-10, atol=1e-10)
    # sorted consistently: the same label in the same column at every speed
    assert len(set(dense.labels)) == 1
    assert dense.labels[0] == ("weave", "weave", "wobble", "wobble", "capsize", "tire", "tire", "other")
    for labs, ev in zip(dense.labels, dense.eigenvalues):
        for lab in ("weave", "wobble"):
            z = ev[[x == lab for x in labs]]
            assert z[0].imag > 0 and z[1] == np.conj(z[0])  # a conjugate pair, + first
        assert ev[4].imag == 0  # capsize is real


def test_counts_hold_on_the_whole_tracking_grid_also_with_effects(dense):
    for res in (dense, eigen_analysis(effects={"tire_stiffness": {"front_scale": 0.6}}, grid_step=0.1),
                eigen_analysis(effects={"payload": {"mass_kg": 100.0}, "steer_damping": {"damping_nms": 25.0}},
                               grid_step=0.1)):
        for row in res.grid_labels:
            assert Counter(row.tolist()) == EXPECTED_COUNTS


def test_labels_change_along_a_branch_only_where_a_pair_splits(dense):
    # continuity: a tracked branch may change name only just after a complex pair splits
    # into two real eigenvalues (the tire/other exchange near 23 m/s), never flicker
    changes = dense.label_changes()
    assert len(changes) == 2
    n_real = (dense.grid_eigenvalues.imag == 0).sum(axis=1)
    splits = dense.grid_speeds[1:][np.diff(n_real) != 0]
    assert len(splits) == 1 and 22.0 < splits[0] < 24.0
    for v0, v1, _branch, old, new in changes:
        assert {old, new} == {"tire", "other"}
        assert 0.0 <= v1 - splits[0] <= 0.5


def test_weave_matches_table_and_is_unstable_only_at_low_speed():
    res = eigen_analysis(speeds=[5.0, 10.0, 20.0, 30.0])
    weave = [w[0] for w in res.select("weave")]
    for z, (re, im) in zip(weave, [(2.04, 3.55), (-0.411, 6.16), (-4.43, 15.8), (-2.25, 22.7)]):
        assert abs(z.real - re) < 0.05 and abs(z.imag - im) < 0.05
    assert weave[0].real > 0  # model.md: unstable below 9.32 m/s only
    assert weave[1].real < 0 and weave[2].real < 0 and weave[3].real < 0
    # the two fast oscillatory modes of the table: wobble = the steer one at 74 rad/s,
    # the 58.5 rad/s pair is the lateral-tire oscillation
    w5 = res.select("wobble")[0][0]
    t5 = res.select("tire")[0][0]
    assert abs(w5 - complex(-9.66, 74.0)) < 0.1 and abs(t5 - complex(-11.2, 58.5)) < 0.1
    assert res.shares[0, 2, 1] > 5 * res.shares[0, 5, 1]  # steer share of wobble vs tire pair


def test_mode_physics_across_the_range(dense):
    sh = dense.shares  # columns: weave, weave, wobble, wobble, capsize, tire, tire, other
    f = dense.frequency_hz
    # wobble: the fast steer oscillation, 8.8-11.8 Hz
    assert np.all((f[:, 2] > 8.5) & (f[:, 2] < 12.0))
    assert np.all(sh[:, 2, 1] > 0.15) and np.all(np.diff(sh[:, 2, 1]) > 0)  # steer share 0.2 -> 0.67
    # weave: the slow oscillation, below the wobble, with roll the largest single coordinate
    # share at low speed; frequency rises with speed (3.6 Hz at 30 m/s, 4.1 Hz at 40 m/s)
    assert np.all(f[:, 0] < 0.5 * f[:, 2]) and np.all(np.diff(f[:, 0]) > 0)
    assert np.all(sh[:, 0, 0] > sh[:, 2, 0])
    # capsize: real, stable, almost pure roll, slower with speed at high speed
    assert np.all(dense.eigenvalues[:, 4].real < 0) and np.all(sh[:, 4, 0] > 0.75)
    hi = dense.speeds >= 15
    assert np.all(np.diff(dense.eigenvalues[hi, 4].real) > 0)
    # tire: at high speed real, ~ -vx/sigma (sigma = 0.2 m), dominated by the tire forces
    v40 = dense.speeds == 40.0
    tire40 = dense.eigenvalues[v40, 5:7][0]
    assert np.all(tire40.imag == 0)
    assert np.allclose(tire40.real, -40.0 / 0.2, rtol=0.1)
    assert np.all(sh[v40, 5:7, 3] > 0.7)


def test_tire_participation_is_the_relaxation_length_elasticity():
    # -(P_Fyf,i + P_Fyr,i) = (sigma/lambda_i) d lambda_i / d sigma, checked by a central
    # difference through the relaxation_length effect of the compiled plant
    h = 1e-5
    for vx in (5.0, 40.0):
        lam, P = participation_factors(V.state_matrix(vx))
        lp = np.linalg.eigvals(linearise(compile_plant(effects={"relaxation_length": {"sigma_m": 0.2 * (1 + h)}}), vx)[0])
        lm = np.linalg.eigvals(linearise(compile_plant(effects={"relaxation_length": {"sigma_m": 0.2 * (1 - h)}}), vx)[0])
        for i, z in enumerate(lam):
            dz = lp[np.argmin(abs(lp - z))] - lm[np.argmin(abs(lm - z))]
            elasticity = dz / (2 * h) / z
            assert abs(elasticity + P[6, i] + P[7, i]) < 2e-3, (vx, z)


def test_participation_is_unit_free_and_classification_order_free():
    A = V.state_matrix(17.0)
    lam, sh = participation_shares(A)
    D = np.diag([57.3, 57.3, 3.6, 1.0, 0.1, 10.0, 1e-3, 1e-3])  # deg, km/h, kN ...
    lam2, sh2 = participation_shares(D @ A @ np.linalg.inv(D))
    for i, z in enumerate(lam):
        j = np.argmin(abs(lam2 - z))
        assert abs(lam2[j] - z) < 1e-8 * abs(z) and np.allclose(sh2[j], sh[i], atol=1e-8)
    _, P = participation_factors(A)
    assert np.allclose(P.sum(axis=0), 1) and np.allclose(P.sum(axis=1), 1)
    labels = classify(lam, sh)
    perm = np.random.default_rng(3).permutation(8)
    assert classify(lam[perm], sh[perm]) == tuple(labels[i] for i in perm)
    with pytest.raises(ModesInputError, match="shares of shape"):
        classify(lam, sh[:, :3])
    with pytest.raises(ModesInputError, match="conjugate pairs"):
        classify(lam + 1j, sh)


# ----------------------------------------------------------------------------- stability speed
def test_stability_speed_is_model_md_weave_boundary(dense):
    vs = dense.stability_speed()
    assert vs == pytest.approx(9.32, abs=0.005)  # model.md: the weave's real part crosses zero at 9.32 m/s
    # independent check: at vs one eigenvalue pair of E^-1 A(vs) sits on the imaginary axis
    lam = _eig(vs)
    crit = lam[np.argmin(np.abs(lam.real))]
    assert abs(crit.real) < 1e-6 and 4.0 < abs(crit.imag) < 8.0
    assert np.sum(_eig(vs - 0.01).real > 0) == 2 and np.sum(_eig(vs + 0.01).real > 0) == 0
    # independent of the requested speeds
    assert eigen_analysis(speeds=[30.0]).stability_speed() == pytest.approx(vs, abs=1e-8)


def test_stability_speed_moves_with_effects_as_physics_says():
    nominal = eigen_analysis(speeds=[20.0])
    heavier_damper = eigen_analysis(speeds=[20.0], effects={"steer_damping": {"damping_nms": 30.0}}, grid_step=0.1)
    # a stiffer steering damper destabilises the weave (raises the speed, and brings back a
    # high-speed weave instability) and damps the wobble
    assert heavier_damper.stability_speed() > nominal.stability_speed() + 0.5
    assert heavier_damper.damping_ratio[0, 2] > nominal.damping_ratio[0, 2]
    assert [k for _, k in nominal.weave_boundaries()] == ["stabilises"]
    bounds = heavier_damper.weave_boundaries()
    assert [k for _, k in bounds] == ["stabilises", "destabilises"]
    A30 = V.A0.copy()
    A30[5, 5] = -30.0  # effects.md: a66 = -damping_nms, applied by hand

    def n_unstable(vx):
        return int(np.sum(np.linalg.eigvals(np.linalg.solve(V.E, A30 + vx * V.A1)).real > 0))

    for v, kind in bounds:
        below, above = n_unstable(v - 1e-3), n_unstable(v + 1e-3)
        assert (below, above) == ((2, 0) if kind == "stabilises" else (0, 2)), (v, kind)
    assert 30.0 < bounds[1][0] < 40.0
    # an effect at its nominal value reproduces the nominal modes through the linearise path
    same = eigen_analysis(speeds=[5.0, 20.0], effects={"tire_stiffness": {"front_scale": 1.0}}, grid_step=0.5)
    ref = eigen_analysis(speeds=[5.0, 20.0], grid_step=0.5)
    assert np.allclose(same.eigenvalues, ref.eigenvalues, rtol=1e-6) and same.labels == ref.labels
    # sensor effects do not change the modes
    sens = eigen_analysis(speeds=[5.0, 20.0], effects=["gyro_bias:yaw_rate_bias=0.1"], grid_step=0.5)
    assert np.array_equal(sens.eigenvalues, ref.eigenvalues) and not sens.effects


# ----------------------------------------------------------------------------- outputs
def test_to_json_has_cli_keys_and_shapes():
    res = eigen_analysis(speeds=[5.0, 10.0, 20.0, 30.0])
    js = res.to_json()
    assert set(js) == {"speeds", "eigenvalues", "labels"}
    assert js["speeds"] == [5.0, 10.0, 20.0, 30.0]
    assert len(js["eigenvalues"]) == len(js["labels"]) == 4
    for v, evs, labs in zip(js["speeds"], js["eigenvalues"], js["labels"]):
        assert len(evs) == len(labs) == 8
        assert all(len(p) == 2 and all(type(c) is float for c in p) for p in evs)
        assert set(labs) <= set(LABELS)
        got = np.sort_complex(np.array([complex(re, im) for re, im in evs]))
        assert np.allclose(got, np.sort_complex(_eig(v)), rtol=1e-10, atol=1e-10)
    assert json.loads(json.dumps(js)) == js


def test_derived_quantities():
    res = eigen_analysis(speeds=[20.0])
    z = res.eigenvalues[0]
    assert np.allclose(res.frequency_hz[0], np.abs(z.imag) / (2 * math.pi))
    assert np.allclose(res.natural_frequency_hz[0], np.abs(z) / (2 * math.pi))
    assert np.allclose(res.damping_ratio[0], -z.real / np.abs(z))
    assert res.damping_ratio[0, 4] == pytest.approx(1.0)  # a stable real mode
    with pytest.raises(ModesInputError, match="unknown mode label 'wiggle'"):
        res.select("wiggle")


def test_plot_writes_a_png(tmp_path, dense):
    from matplotlib.figure import Figure

    out = tmp_path / "modes.png"
    fig = plot_modes(dense, out)
    assert isinstance(fig, Figure) and len(fig.axes) >= 3
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    assert isinstance(plot_modes(dense), Figure)  # no file
    with pytest.raises(ModesInputError, match="ModalResult"):
        plot_modes({"speeds": [5.0]})


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"speeds": [2.0, 10.0]}, r"speeds: \[2.0\] m/s outside the valid range \[3.0, 40.0\]"),
        ({"speeds": [10.0, 45.0]}, r"speeds: \[45.0\] m/s outside"),
        ({"speeds": [float("nan")]}, "outside the valid range"),
        ({"speeds": []}, "non-empty"),
        ({"speeds": "fast"}, "speeds must be numbers"),
        ({"speeds": [[5.0, 10.0]]}, "1-D"),
        ({"grid_step": 0.0}, "grid_step"),
        ({"grid_step": 20.0}, "grid_step"),
        ({"effects": {"tire_stiffness": {"front_scale": [0.5, 1.0]}}}, "scalar effect parameters"),
        ({"vehicle": "scooter"}, "Vehicle"),
    ],
)
def test_bad_arguments_are_named(kwargs, message):
    with pytest.raises(ModesInputError, match=message):
        eigen_analysis(**kwargs)


def test_bad_effects_and_unknown_options():
    with pytest.raises(EffectError, match="unknown effect 'tyre_stiffness'"):
        eigen_analysis(effects=["tyre_stiffness:front_scale=0.7"])
    with pytest.raises(TypeError):
        eigen_analysis(speed=[5.0])
    assert issubclass(ModesInputError, ValueError)
