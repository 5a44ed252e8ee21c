"""Each effect of shared/spec/effects.md against a consequence derived by hand in the test.

References: the effects.md definitions applied with numpy to the Vehicle's
E, A0, A1 (never the compiled plant's internals), closed-form steady tire
forces with model.md's tire parameters, and a steady state found with scipy.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import root

from ptw_env.dynamics import compile_plant, linearise
from ptw_env.effects import VOCABULARY, EffectError, Effects, as_effects
from ptw_env.integrate import simulate
from ptw_env.vehicle import G, REFERENCE_SCOOTER

V = REFERENCE_SCOOTER
M = 303.31  # model.md, e33 [kg]
# model.md, derived nominal tire parameters
C_AF, C_GF, C_AR, C_GR = 22486.0, 1063.8, 20178.0, 644.36
FZF = M * G * 0.624 / (0.856 + 0.624)  # 1254.5 N
FZR = M * G * 0.856 / (0.856 + 0.624)  # 1721.0 N
HP = 0.6  # payload height [m], effects.md


def random_states(seed: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (n, 8)) * np.array([0.6, 0.2, 1.5, 0.8, 2.0, 4.0, 1500.0, 1500.0])


def rhs_of(effects, x, tau=0.0, vx=15.0):
    return compile_plant(effects=effects).rhs(x, tau, vx)


def solve_E(E: np.ndarray, A: np.ndarray) -> np.ndarray:
    return np.linalg.solve(E, A)


def assert_matrix_close(A: np.ndarray, A_ref: np.ndarray, rtol: float = 1e-7) -> None:
    """Entry-wise, relative to each row's largest entry (tire rows are 1e5 larger than row 1)."""
    scale = np.maximum(np.abs(A_ref).max(axis=1, keepdims=True), 1e-300)
    assert np.all(np.abs(A - A_ref) <= rtol * scale), np.abs(A - A_ref) / scale


# ----------------------------------------------------------------------------- road_bank
@pytest.mark.parametrize("bank, payload", [(0.08, 0.0), (-0.15, 0.0), (0.1, 60.0)])
def test_bank_needs_tire_force_m_g_sin_beta_to_run_straight(bank, payload):
    eff = {"road_bank": {"bank_rad": bank}}
    if payload:
        eff["payload"] = {"mass_kg": payload}
    plant = compile_plant(effects=eff)
    vx = 15.0
    scale = np.array([0.1, 0.01, 0.1, 1000.0, 1000.0, 10.0])  # phi, delta, vy, Fyf, Fyr, tau

    def state(z):
        phi, delta, vy, fyf, fyr, tau = z * scale
        return np.array([phi, delta, vy, 0.0, 0.0, 0.0, fyf, fyr]), tau  # straight: r = 0, no rates

    def residual(z):
        x, tau = state(z)
        return plant.rhs(x, tau, vx)[2:] / np.array([1, 1, 1, 1, 1e3, 1e3])

    sol = root(residual, np.zeros(6), method="hybr", options={"xtol": 1e-13})
    assert sol.success, sol.message
    x, tau = state(sol.x)
    d = plant.rhs(x, tau, vx)
    assert np.abs(d[:6]).max() < 1e-9 and np.abs(d[6:]).max() < 1e-6  # a true equilibrium
    total = M + payload
    assert x[6] + x[7] == pytest.approx(total * G * math.sin(bank), rel=1e-9)
    assert plant.ay(x) == pytest.approx(G * math.sin(bank), rel=1e-9)  # ay = (Fyf + Fyr)/(M + m)
    # the rider leans toward the high side of the road and holds the bar against it
    assert np.sign(x[0]) == np.sign(bank)


def test_bank_replaces_sin_phi_by_sin_phi_minus_beta_in_rows_5_6():
    beta = 0.12
    x = random_states(1, 32)
    vx = np.linspace(4, 38, 32)
    got = rhs_of({"road_bank": {"bank_rad": beta}}, x, 2.0, vx) - rhs_of(None, x, 2.0, vx)
    a51, a61 = V.A0[4, 0], V.A0[5, 0]
    d = np.zeros((32, 8))
    d[:, 2] = -M * G * math.sin(beta)
    d[:, 4] = a51 * (np.sin(x[:, 0] - beta) - np.sin(x[:, 0]))
    d[:, 5] = a61 * (np.sin(x[:, 0] - beta) - np.sin(x[:, 0]))
    want = solve_E(V.E, d.T).T
    assert np.allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())
    assert np.all(got[:, 6:] == 0)  # the tire rows see the camber relative to the road: unchanged


# ----------------------------------------------------------------------------- tire_stiffness
@pytest.mark.parametrize("vx", [4.0, 20.0, 40.0])
def test_stiffness_scales_entries_a71_a76_and_a81_a84(vx):
    fs, rs = 0.7, 1.3
    A, B = linearise(compile_plant(effects={"tire_stiffness": {"front_scale": fs, "rear_scale": rs}}), vx)
    Ah = V.A(vx).copy()
    Ah[6, :6] *= fs  # a71..a76
    Ah[7, :6] *= rs  # a81..a84 (a82, a85, a86 are zero)
    assert Ah[6, 6] == -vx / 0.2 and Ah[7, 7] == -vx / 0.2  # a77, a88 untouched
    assert_matrix_close(A, solve_E(V.E, Ah))
    assert np.allclose(B, np.linalg.solve(V.E, V.B)[:, None], rtol=1e-9)


def test_steady_cornering_force_scales_with_stiffness():
    fs, rs, vx = 0.6, 1.4, 18.0
    nominal, scaled = compile_plant(), compile_plant(effects={"tire_stiffness": {"front_scale": fs, "rear_scale": rs}})
    x = np.zeros(8)
    x[2] = 0.3  # pure side slip alpha_f = alpha_r = vy/vx
    alpha = 0.3 / vx
    assert np.allclose(nominal.steady_tire_force(x, vx), [-C_AF * alpha, -C_AR * alpha], rtol=1e-9)
    assert np.allclose(scaled.steady_tire_force(x, vx), [-fs * C_AF * alpha, -rs * C_AR * alpha], rtol=1e-9)
    x = np.zeros(8)
    x[0] = 0.2  # pure camber gamma_f = gamma_r = phi
    assert np.allclose(scaled.steady_tire_force(x, vx), [fs * C_GF * 0.2, rs * C_GR * 0.2], rtol=1e-9)


# ----------------------------------------------------------------------------- tire_saturation
def test_saturation_is_tanh_of_linear_force():
    mu, vx = 0.8, 20.0
    plant = compile_plant(effects={"tire_saturation": {"mu_peak": mu}})
    fmax = mu * np.array([FZF, FZR])
    assert plant.saturates and not compile_plant().saturates
    for vy in [1e-4, 0.05, 0.4, 2.0, 6.0]:
        x = np.zeros(8)
        x[2] = vy
        flin = -np.array([C_AF, C_AR]) * vy / vx
        got = plant.steady_tire_force(x, vx)
        assert np.allclose(got, fmax * np.tanh(flin / fmax), rtol=1e-9)
        if vy == 1e-4:  # tiny slip: identical to linear
            assert np.allclose(got, flin, rtol=1e-6)
    # large slip (alpha = 0.3 rad, F_lin = 6.7 and 4.4 Fmax): the force is at the friction limit
    # mu Fz per axle to 0.1 % (tanh(4.4) = 0.9997), never beyond it
    x = np.zeros(8)
    x[2] = 0.3 * vx
    got = plant.steady_tire_force(x, vx)
    assert np.all(np.abs(got) < fmax) and np.allclose(np.abs(got), fmax, rtol=1e-3)


def test_saturation_keeps_the_relaxation_row():
    mu, vx, sigma = 0.5, 12.0, 0.2
    plant = compile_plant(effects={"tire_saturation": {"mu_peak": mu}})
    x = np.zeros(8)
    x[2], x[6], x[7] = 0.8, 300.0, -900.0
    flin = -np.array([C_AF, C_AR]) * 0.8 / vx
    fss = mu * np.array([FZF, FZR]) * np.tanh(flin / (mu * np.array([FZF, FZR])))
    d = plant.rhs(x, 0.0, vx)
    assert np.allclose(d[6:], vx / sigma * (fss - x[6:]), rtol=1e-9)


# ----------------------------------------------------------------------------- roll_moment_offset
def test_roll_moment_adds_E_solve_of_e5():
    m0 = 35.0
    x = random_states(2, 16)
    got = rhs_of({"roll_moment_offset": {"moment_nm": m0}}, x, 1.0, 22.0) - rhs_of(None, x, 1.0, 22.0)
    want = np.linalg.solve(V.E, np.eye(8)[4]) * m0
    assert np.allclose(got, want[None, :], rtol=1e-10, atol=1e-12)
    assert np.allclose(linearise(compile_plant(effects={"roll_moment_offset": {"moment_nm": m0}}), 22.0)[0],
                       linearise(compile_plant(), 22.0)[0], rtol=1e-6, atol=1e-6)


# ----------------------------------------------------------------------------- payload
def payload_matrices(m: float, vx: float) -> tuple[np.ndarray, np.ndarray]:
    """E and A(vx) with a point mass m at hp = 0.6 m, by the formulas of effects.md."""
    E, A = V.E.copy(), V.A(vx).copy()
    E[2, 2] += m
    E[2, 4] += m * HP
    E[4, 2] += m * HP
    E[4, 4] += m * HP**2
    A[2, 3] += -m * vx
    A[4, 0] += m * HP * G
    A[4, 3] += -m * HP * vx
    return E, A


@pytest.mark.parametrize("m, vx", [(80.0, 6.0), (80.0, 30.0), (-40.0, 15.0)])
def test_payload_changes_E_and_A_as_listed(m, vx):
    plant = compile_plant(effects={"payload": {"mass_kg": m}})
    A, B = linearise(plant, vx)
    E_h, A_h = payload_matrices(m, vx)
    assert_matrix_close(A, solve_E(E_h, A_h))
    assert np.allclose(B, np.linalg.solve(E_h, V.B)[:, None], rtol=1e-9, atol=1e-12)
    x = np.zeros(8)
    x[6], x[7] = 500.0, 700.0
    assert float(plant.mass) == pytest.approx(M + m)
    assert plant.ay(x) == pytest.approx(1200.0 / (M + m))
    # tire loads unchanged: the friction limit of tire_saturation stays mu Fz of model.md
    sat = compile_plant(effects={"payload": {"mass_kg": m}, "tire_saturation": {"mu_peak": 0.9}})
    assert np.allclose(sat.fmax, 0.9 * np.array([FZF, FZR]), rtol=1e-12)


# ----------------------------------------------------------------------------- steer_damping
@pytest.mark.parametrize("damping", [0.0, 4.0, 40.0])
def test_steer_damping_sets_a66(damping):
    vx = 9.0
    A, _ = linearise(compile_plant(effects={"steer_damping": {"damping_nms": damping}}), vx)
    Ah = V.A(vx).copy()
    Ah[5, 5] = -damping
    assert_matrix_close(A, solve_E(V.E, Ah))
    # the nominal value is the printed a66
    assert VOCABULARY["steer_damping"]["damping_nms"][0] == -V.A0[5, 5] == 12.67


# ----------------------------------------------------------------------------- relaxation_length
@pytest.mark.parametrize("sigma", [0.05, 0.5])
def test_relaxation_length_time_constant_and_unchanged_steady_force(sigma):
    vx = 16.0
    plant = compile_plant(effects={"relaxation_length": {"sigma_m": sigma}})
    A, _ = linearise(plant, vx)
    A0n = V.A(vx)
    # rows 7-8: (sigma/vx) F' = -F + F_ss with the nominal F_ss = (0.2/vx) sum_j a_kj x_j
    Ah = solve_E(V.E, A0n)
    Ah[6:8] = (0.2 / sigma) * A0n[6:8]
    assert_matrix_close(A, Ah)
    assert A[6, 6] == pytest.approx(-vx / sigma, rel=1e-7) and A[7, 7] == pytest.approx(-vx / sigma, rel=1e-7)
    # a pure force (no slip) decays with time constant sigma/vx; the steady force is unchanged
    x = random_states(3, 1)[0]
    d = plant.rhs(x, 0.0, vx)
    fss = compile_plant().steady_tire_force(x, vx)
    assert np.allclose(sigma / vx * d[6:] + x[6:], fss, rtol=1e-9, atol=1e-9 * np.abs(fss).max())
    assert np.allclose(plant.steady_tire_force(x, vx), fss, rtol=1e-9, atol=1e-6)


# ----------------------------------------------------------------------------- composition, batches
def test_bank_and_stiffness_compose():
    x = random_states(4, 8)
    bank = {"road_bank": {"bank_rad": 0.07}}
    stiff = {"tire_stiffness": {"front_scale": 0.5, "rear_scale": 0.8}}
    both = rhs_of({**bank, **stiff}, x)
    want = rhs_of(stiff, x) + (rhs_of(bank, x) - rhs_of(None, x))
    assert np.allclose(both, want, rtol=1e-10, atol=1e-9 * np.abs(want).max())


def test_payload_and_steer_damping_compose():
    vx, m, c = 12.0, 50.0, 20.0
    A, _ = linearise(compile_plant(effects={"payload": {"mass_kg": m}, "steer_damping": {"damping_nms": c}}), vx)
    E_h, A_h = payload_matrices(m, vx)
    A_h[5, 5] = -c
    assert_matrix_close(A, solve_E(E_h, A_h))


def test_array_parameters_give_one_plant_per_vehicle():
    fs = np.array([0.5, 1.0, 1.5, 0.8])
    bank = np.array([0.0, 0.05, -0.05, 0.1])
    eff = Effects({"tire_stiffness": {"front_scale": fs}, "road_bank": {"bank_rad": bank}, "payload": {"mass_kg": 30.0}})
    plant = compile_plant(effects=eff)
    assert plant.batch_shape == (4,)
    x = random_states(5, 4)
    got = plant.rhs(x, 1.0, 20.0)
    tau = np.full((4, 60), 1.0)
    sim = simulate(np.zeros((4, 8)), tau, 20.0, effects=eff)
    for n in range(4):
        single = {"tire_stiffness": {"front_scale": fs[n]}, "road_bank": {"bank_rad": bank[n]}, "payload": {"mass_kg": 30.0}}
        assert np.allclose(got[n], rhs_of(single, x[n], 1.0, 20.0), rtol=1e-12, atol=1e-9)
        assert np.allclose(sim[n], simulate(np.zeros(8), tau[n], 20.0, effects=single), rtol=1e-12, atol=1e-12)
    assert np.allclose(plant.mass, M + 30.0)
    # one initial state for all: the batch size comes from the effects
    sim1 = simulate(np.zeros(8), tau[0], 20.0, effects=eff)
    assert sim1.shape == (4, 61, 8) and np.allclose(sim1, sim, rtol=0, atol=1e-12)


def test_sensor_effects_do_not_change_dynamics():
    nominal = compile_plant()
    for spec in ["gyro_bias:yaw_rate_bias=0.02,roll_rate_bias=-0.01", "ay_frame:gravity_gain=1", "sensor_delay:delay_s=0.05"]:
        plant = compile_plant(effects=[spec])
        assert np.array_equal(plant.W, nominal.W)
        for name in ("inv_sigma", "fmax", "bank", "mass"):
            assert np.array_equal(getattr(plant, name), getattr(nominal, name))
        e = Effects.parse([spec])
        assert not e.dynamic and e.sensor == e


# ----------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    "params, message",
    [
        ({"road_bnak": {"bank_rad": 0.1}}, "unknown effect 'road_bnak'"),
        ({"road_bank": {"bank": 0.1}}, "effect road_bank: unknown parameter 'bank'; known: bank_rad"),
        ({"road_bank": {"bank_rad": 0.6}}, r"bank_rad = 0.6 rad is outside its physical range \[-0.5, 0.5\]"),
        ({"tire_stiffness": {"front_scale": 0.0}}, "front_scale .* outside its physical range"),
        ({"tire_saturation": {"mu_peak": 0.01}}, "mu_peak .* outside"),
        ({"payload": {"mass_kg": float("nan")}}, "mass_kg must be finite"),
        ({"road_bank": {"bank_rad": float("inf")}}, "bank_rad must be finite"),
        ({"payload": {"mass_kg": "heavy"}}, "mass_kg must be a number"),
        ({"steer_damping": {"damping_nms": [5.0, -1.0]}}, "damping_nms .* outside"),
        ({"road_bank": 0.1}, "parameters must be a mapping"),
    ],
)
def test_bad_effects_raise_effect_error_naming_the_problem(params, message):
    with pytest.raises(EffectError, match=message):
        Effects(params)


@pytest.mark.parametrize(
    "spec, message",
    [
        ("road_bank", "expected CAUSE:PARAM=VALUE"),
        ("road_bank:", "expected CAUSE:PARAM=VALUE"),
        ("road_bank:bank_rad", "'bank_rad' is not PARAM=VALUE"),
        ("road_bank:bank_rad=steep", "value 'steep' of bank_rad is not a number"),
        ("tyre_stiffness:front_scale=0.7", "unknown effect 'tyre_stiffness'"),
        ("tire_stiffness:front=0.7", "unknown parameter 'front'"),
    ],
)
def test_bad_cli_strings(spec, message):
    with pytest.raises(EffectError, match=message):
        Effects.parse([spec])


def test_parse_and_to_causes_round_trip():
    specs = ["road_bank:bank_rad=0.05", "tire_stiffness:front_scale=0.7,rear_scale=0.8", "gyro_bias:yaw_rate_bias=0.01"]
    e = Effects.parse(specs)
    causes = e.to_causes()
    assert causes == [
        {"cause": "road_bank", "params": {"bank_rad": 0.05}},
        {"cause": "tire_stiffness", "params": {"front_scale": 0.7, "rear_scale": 0.8}},
        {"cause": "gyro_bias", "params": {"yaw_rate_bias": 0.01}},
    ]
    again = Effects.from_causes(causes)
    assert again.to_causes() == causes
    strings = [c["cause"] + ":" + ",".join(f"{p}={v!r}" for p, v in c["params"].items()) for c in causes]
    assert Effects.parse(strings).to_causes() == causes
    assert as_effects(specs).to_causes() == causes and as_effects(causes).to_causes() == causes
    # values and nominals
    assert e.value("tire_stiffness", "rear_scale") == 0.8 and e.value("payload", "mass_kg") == 0.0
    assert e.value("tire_saturation", "mu_peak") == math.inf
    # no effect
    assert Effects.parse(["none"]).to_causes() == [{"cause": "none", "params": {}}]
    assert Effects.parse(None).to_causes() == [{"cause": "none", "params": {}}]
    assert not Effects.parse(["none"])


def test_other_misuse_is_named():
    with pytest.raises(EffectError, match="unknown effect parameter road_bank:angle"):
        Effects().value("road_bank", "angle")
    with pytest.raises(EffectError, match="do not broadcast"):
        compile_plant(effects={"tire_stiffness": {"front_scale": [1.0, 2.0]}, "road_bank": {"bank_rad": [0.0, 0.1, 0.2]}})
    with pytest.raises(EffectError, match="cannot interpret"):
        as_effects(42)
    with pytest.raises(EffectError, match="no 'cause' key"):
        Effects.from_causes([{"params": {}}])
    with pytest.raises(EffectError, match="none takes no parameters"):
        Effects({"none": {"x": 1}})
    assert issubclass(EffectError, ValueError)
