"""Generalised forces of a model extension in the one right-hand side (ptw_env.dynamics.add_generalised_forces).

Independent references: ``E^-1 g`` computed here by hand from model.md's rows, and scipy's DOP853
integrating the nominal plant's right-hand side plus that hand-computed term (so the kernel's
per-stage Coulomb evaluation is checked against a continuous one).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ptw_env.dynamics import FORCE_FEATURES, FORCE_ROWS, add_generalised_forces, compile_plant
from ptw_env.integrate import simulate
from ptw_env.kernels import COULOMB_WIDTH
from ptw_env.vehicle import REFERENCE_SCOOTER


def _g(x: np.ndarray, vx: float, forces) -> np.ndarray:
    feats = {"1": 1.0, "vx^2": vx * vx, "vx*vy": vx * x[2], "vx*delta": vx * x[1], "delta_dot": x[5],
             "tanh(delta_dot/w)": np.tanh(x[5] / COULOMB_WIDTH)}
    g = np.zeros(8)
    for eq, feat, c in forces:
        g[FORCE_ROWS[eq] - 1] += c * feats[feat]
    return g


FORCES = [("steer", "tanh(delta_dot/w)", -2.0), ("roll", "vx^2", 0.5), ("yaw", "vx*vy", 3.0),
          ("lateral", "vx^2", 1.2), ("steer", "1", 0.7), ("steer", "vx*delta", -0.4), ("steer", "delta_dot", -1.5)]


def test_every_feature_and_row_enter_through_the_plants_own_E_inverse():
    assert set(FORCE_FEATURES) == {f for _, f, _ in FORCES} and set(FORCE_ROWS) == {e for e, _, _ in FORCES}
    rng = np.random.default_rng(0)
    p0 = compile_plant(REFERENCE_SCOOTER, {"payload": {"mass_kg": 50.0}})  # E with the payload
    p1 = add_generalised_forces(p0, FORCES)
    E = REFERENCE_SCOOTER.E.copy()
    E[2, 2] += 50.0
    E[2, 4] += 50.0 * 0.6
    E[4, 2] += 50.0 * 0.6
    E[4, 4] += 50.0 * 0.36
    for _ in range(5):
        x = rng.normal(size=8) * np.array([0.1, 0.02, 0.3, 0.2, 0.2, 0.3, 300, 300])
        vx = float(rng.uniform(5, 35))
        d = p1.rhs(x, 3.0, vx) - p0.rhs(x, 3.0, vx)
        np.testing.assert_allclose(d, np.linalg.solve(E, _g(x, vx, FORCES)), rtol=1e-9, atol=1e-12)
    assert np.array_equal(p0.rhs(np.ones(8), 1.0, 10.0), compile_plant(REFERENCE_SCOOTER, {"payload": {"mass_kg": 50.0}})
                          .rhs(np.ones(8), 1.0, 10.0))  # the original plant is untouched


def test_batched_coefficients_and_the_coulomb_stage_evaluation_match_a_continuous_reference():
    """Coulomb friction evaluated at every RK4 stage (not held over the sample): the batched
    simulator stays within 1e-4 of DOP853 on the nominal right-hand side plus the hand-computed force."""
    tcs = np.array([0.0, 2.0, 6.0])
    forces = [("steer", "tanh(delta_dot/w)", -tcs), ("lateral", "vx^2", np.array([0.0, 0.5, 1.0]))]
    p0 = compile_plant()
    pb = add_generalised_forces(p0, forces)
    assert pb.batch_shape == (3,)
    T, vx = 300, 15.0
    tau = 8.0 * np.sin(np.arange(T) * 0.04)
    X = simulate(np.zeros((3, 8)), np.tile(tau, (3, 1)), vx, vehicle=pb)
    Einv = np.linalg.inv(REFERENCE_SCOOTER.E)
    for n in range(3):
        fn = [(e, f, float(np.asarray(c)[n])) for e, f, c in forces]
        x = np.zeros(8)
        ref = [x]
        for k in range(T):
            sol = solve_ivp(lambda _t, y, u=tau[k]: p0.rhs(y, u, vx) + Einv @ _g(y, vx, fn), (0.0, 0.01), x,
                            method="DOP853", rtol=1e-10, atol=1e-12 * np.array([1, 1, 1, 1, 1, 1, 1e3, 1e3]))
            x = sol.y[:, -1]
            ref.append(x)
        ref = np.array(ref)
        scale = np.abs(ref).max(axis=0)
        assert np.max(np.abs(X[n] - ref).max(axis=0) / scale) < 1e-4, n
    # the forces change the ride (not a vacuous comparison of three equal trajectories)
    assert np.abs(X[2] - X[0]).max(axis=0)[5] > 0.1 * np.abs(X[0, :, 5]).max()


def test_unknown_equation_or_feature_is_a_key_error():
    with pytest.raises(KeyError):
        add_generalised_forces(compile_plant(), [("pitch", "1", 1.0)])
    with pytest.raises(KeyError):
        add_generalised_forces(compile_plant(), [("steer", "vx^3", 1.0)])
