"""The RK4 integrator against independent references.

* scipy's DOP853 at rtol 1e-10 integrating the same :meth:`Plant.rhs` period by
  period with the inputs held (zero-order hold), over 20 s rides;
* the noise-free reference ride log ``nominal_urban_noiseless.csv``, written by
  an independent simulator (RK4 with 1 ms steps) with the true state in its
  ``x_*`` columns;
* bad inputs.

"Relative error" of state j is ``max_t |x_j - x_ref,j| / max_t |x_ref,j|``,
the maximum taken over the ride (solve_ivp) or over each 2 s window of the log
(the stricter choice there: quiet windows have small states).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from ptw_env.dynamics import compile_plant, linearise
from ptw_env.integrate import SimulationInputError, Stepper, simulate, substeps_for
from ptw_env.vehicle import STATE_NAMES

DT = 0.01
T = 2000  # 20 s at 100 Hz
from conftest import DATA  # noqa: E402  (shared/data beside the repository)


def _smooth_torque(seed: int, amplitude: float) -> np.ndarray:
    """Sum of four sines (0.1-1 Hz, random phases) [N m], sampled at the periods."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(0.1, 1.0, 4)
    ph = rng.uniform(0, 2 * np.pi, 4)
    t = np.arange(T) * DT
    return amplitude * np.sin(2 * np.pi * f[:, None] * t + ph[:, None]).sum(axis=0) / 2


@pytest.fixture(scope="module")
def rides():
    """Four 20 s rides integrated by DOP853 (reference) and by the RK4 kernel.

    0: 5 m/s (open-loop unstable weave) stabilised by an LQR state feedback
       computed on the sampled state and held over the period (the same law
       for both integrators, each on its own samples), plus a smooth torque;
    1: 15 m/s, 2: 40 m/s, 3: speed ramp 12 -> 40 m/s held in 0.1 s steps:
       open loop (self-stable above 11 m/s) with a smooth torque.
    Peak roll 5-32 deg, so the sine terms of the plant are exercised.
    """
    plant = compile_plant()
    vx = np.array([np.full(T, 5.0), np.full(T, 15.0), np.full(T, 40.0), np.repeat(np.linspace(12, 40, T // 10), 10)])
    tau = np.array([_smooth_torque(s, a) for s, a in [(1, 6.0), (2, 12.0), (3, 30.0), (4, 20.0)]])
    N = len(vx)
    K = np.zeros((N, 8))
    A, B = linearise(plant, 5.0)
    P = scipy.linalg.solve_continuous_are(A, B, np.diag([100.0, 10, 1, 1, 1, 1, 0, 0]), np.array([[1.0]]))
    K[0] = (B.T @ P).ravel()

    # reference: all rides as one 32-dimensional ODE, restarted at every period
    atol = np.tile(1e-12 * np.array([1, 1, 1, 1, 1, 1, 1e3, 1e3]), N)
    x = np.zeros((N, 8))
    ref = np.zeros((N, T + 1, 8))
    for k in range(T):
        u = tau[:, k] - np.einsum("nj,nj->n", K, x)

        def f(_t, y, u=u, v=vx[:, k]):
            return plant.rhs(y.reshape(N, 8), u, v).ravel()

        sol = solve_ivp(f, (0.0, DT), x.ravel(), method="DOP853", rtol=1e-10, atol=atol)
        assert sol.success
        x = sol.y[:, -1].reshape(N, 8)
        ref[:, k + 1] = x

    rk4 = np.zeros((N, T + 1, 8))
    for n in range(N):
        st = Stepper(plant, DT)
        xn = np.zeros(8)
        for k in range(T):
            st.step(xn, tau[n, k] - K[n] @ xn, vx[n, k])
            rk4[n, k + 1] = xn
    return {"ref": ref, "rk4": rk4, "tau": tau, "vx": vx, "K": K}


def _relative_error(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.abs(x - ref).max(axis=-2) / np.abs(ref).max(axis=-2)


@pytest.mark.parametrize("ride", [0, 1, 2, 3], ids=["5ms-feedback", "15ms", "40ms", "ramp12-40"])
def test_rk4_matches_dop853_over_20s(rides, ride):
    ref, rk4 = rides["ref"][ride], rides["rk4"][ride]
    assert np.all(np.isfinite(ref))
    assert np.degrees(np.abs(ref[:, 0]).max()) > 4.0  # a real manoeuvre, not the trivial solution
    assert np.degrees(np.abs(ref[:, 0]).max()) < 45.0  # inside the model's validity
    err = _relative_error(rk4, ref)
    assert err.max() < 1e-4, dict(zip(STATE_NAMES, err))


def test_simulate_equals_stepper_on_open_loop_rides(rides):
    # the batched simulator and the one-vehicle stepper are the same integrator
    xs = simulate(np.zeros((3, 8)), rides["tau"][1:], rides["vx"][1:])
    assert xs.shape == (3, T + 1, 8)
    assert np.allclose(xs, rides["rk4"][1:], rtol=0, atol=1e-12 * np.abs(xs).max())


def test_rk4_is_fourth_order(rides):
    # on the first 2 s of the 40 m/s ride: halving the substep divides the error by ~16
    n = 200
    ref = rides["ref"][2, : n + 1]
    errs = [np.abs(simulate(np.zeros(8), rides["tau"][2, :n], 40.0, substeps=m) - ref).max(axis=0) / np.abs(ref).max(axis=0)
            for m in (4, 8, 16)]
    e4, e8, e16 = (e.max() for e in errs)
    assert 13 < e4 / e8 < 19, (e4, e8, e16)
    assert 13 < e8 / e16 < 19, (e4, e8, e16)
    assert substeps_for(0.01) == 4  # the default, 2.5 ms


def test_stepper_roll_moment_is_a_roll_moment_offset():
    # the environment's disturbance input enters row 5 exactly like effects.md's roll_moment_offset
    x1 = np.zeros(8)
    x2 = np.zeros(8)
    s1 = Stepper(compile_plant(), DT)
    s2 = Stepper(compile_plant(effects={"roll_moment_offset": {"moment_nm": 25.0}}), DT)
    for k in range(100):
        s1.step(x1, 1.0, 18.0, 25.0)
        s2.step(x2, 1.0, 18.0)
    assert abs(x1[0]) > 1e-3
    assert np.allclose(x1, x2, rtol=1e-12, atol=1e-12 * np.abs(x2).max())


# ----------------------------------------------------------------------------- reference log
def _read_log(name: str) -> dict[str, np.ndarray]:
    d = np.genfromtxt(DATA / f"{name}.csv", delimiter=",", names=True)
    return {n: d[n] for n in d.dtype.names}


@pytest.fixture(scope="module")
def log():
    d = _read_log("nominal_urban_noiseless")
    x = np.stack([d[f"x_{s}"] for s in STATE_NAMES], axis=1)
    return d, x


def test_replay_reference_log_in_2s_windows(log):
    import json

    d, X = log
    meta = json.loads((DATA / "nominal_urban_noiseless.json").read_text())
    assert meta["sample_rate_hz"] == 100 and meta["truth"]["causes"] == [{"cause": "none", "params": {}}]
    assert np.allclose(np.diff(d["t"]), DT, atol=1e-9)
    W = 200  # 2 s
    n = (len(X) - 1) // W
    starts = np.arange(n) * W
    steps = starts[:, None] + np.arange(W)[None, :]
    # each window starts from the true state; tau and vx held over each sample
    sim = simulate(X[starts], d["tau"][steps], d["vx"][steps])
    truth = X[starts[:, None] + np.arange(W + 1)[None, :]]
    last = simulate(X[n * W], d["tau"][n * W: -1], d["vx"][n * W: -1])  # the remaining samples
    assert n * W + len(last) == len(X)
    err_window = np.abs(sim - truth).max(axis=1) / np.abs(truth).max(axis=1)  # per window and state
    assert err_window.max() < 1e-3, dict(zip(STATE_NAMES, err_window.max(axis=0)))
    err_log = np.abs(np.concatenate([(sim - truth).reshape(-1, 8), last - X[n * W:]])).max(axis=0) / np.abs(X).max(axis=0)
    assert err_log.max() < 1e-3, dict(zip(STATE_NAMES, err_log))


def test_log_ay_is_model_output(log):
    d, X = log
    assert np.allclose(compile_plant().ay(X), d["ay"], rtol=1e-8, atol=1e-9)


# ----------------------------------------------------------------------------- bad input
def test_nan_in_tau_is_named():
    tau = np.zeros(10)
    tau[3] = np.nan
    with pytest.raises(SimulationInputError, match=r"tau .*index \(0, 3\)"):
        simulate(np.zeros(8), tau, 20.0)


def test_nan_in_x0_is_named():
    x0 = np.zeros(8)
    x0[2] = np.inf
    with pytest.raises(SimulationInputError, match="x0"):
        simulate(x0, np.zeros(10), 20.0)


@pytest.mark.parametrize("kw, match", [
    ({"vx": "abc"}, "vx must be an array of numbers; it is not numeric"),
    ({"tau": [[1.0, 2.0], [3.0]]}, "tau must be an array of numbers; it is ragged"),
    ({"x0": ["a"] * 8}, "x0 must be an array of numbers"),
])
def test_non_numeric_input_is_named(kw, match):
    args = {"x0": np.zeros(8), "tau": np.zeros(5), "vx": 15.0, **kw}
    with pytest.raises(SimulationInputError, match=match):
        simulate(**args)


def test_speed_range_is_inclusive():
    x = simulate(np.zeros(8), np.zeros(3), np.array([3.0, 40.0, 3.0]))
    assert x.shape == (4, 8) and np.all(x == 0)  # upright at rest is an equilibrium


@pytest.mark.parametrize("speed", [2.0, 0.0, -5.0, 41.0])
def test_speed_outside_valid_range_is_named(speed):
    vx = np.full(10, 20.0)
    vx[4] = speed
    with pytest.raises(SimulationInputError, match=r"vx\[\(0, 4\)\].*outside the model's valid range \[3.0, 40.0\]"):
        simulate(np.zeros(8), np.zeros(10), vx)


@pytest.mark.parametrize(
    "x0, tau, vx, what",
    [
        (np.zeros(7), np.zeros(10), 20.0, "x0 must have shape"),
        (np.zeros((2, 8)), np.zeros((3, 10)), 20.0, "shapes do not match"),
        (np.zeros(8), np.zeros(10), np.full(9, 20.0), "shapes do not match"),
        (np.zeros(8), np.zeros((2, 3, 10)), 20.0, "tau must have shape"),
        (np.zeros(8), np.zeros(0), 20.0, "tau must hold at least one sample"),
    ],
)
def test_shape_mismatch_is_named(x0, tau, vx, what):
    with pytest.raises(SimulationInputError, match=what):
        simulate(x0, tau, vx)


def test_bad_step_and_unknown_options():
    with pytest.raises(SimulationInputError, match="dt"):
        simulate(np.zeros(8), np.zeros(5), 20.0, dt=0.0)
    with pytest.raises(SimulationInputError, match="substeps"):
        simulate(np.zeros(8), np.zeros(5), 20.0, substeps=0)
    with pytest.raises(TypeError):
        simulate(np.zeros(8), np.zeros(5), 20.0, method="euler")
    # an error is a ValueError for callers that catch the built-in
    assert issubclass(SimulationInputError, ValueError)


@pytest.mark.parametrize("name", ["sharp1971", "cossalter-sport-touring", "robot-bicycle"])
def test_default_substeps_follow_each_vehicles_fastest_mode(name):
    """Every preset, at the top of its speed range, with the default substeps: within 1e-4 of DOP853
    (rtol 1e-10) over a 5 s open-loop ride with a smooth torque. The Cossalter sport-tourer's fastest
    mode is ~470 1/s, so a fixed 2.5 ms step would give |lambda h| ~ 1.2; it gets 10 substeps."""
    from ptw_env.vehicle_files import load_vehicle

    v = load_vehicle(name)
    plant = compile_plant(v)
    n = substeps_for(DT, vehicle=v)
    assert v.fastest_eigenvalue * DT / n <= 0.47 + 1e-12
    steps = 500
    vx = v.vmax
    tau = _smooth_torque(7, 0.2 * v.steer_torque_scale)[:steps]
    x, ref = np.zeros(8), np.zeros(8)
    out, outr = [], []
    st = Stepper(plant, DT)
    for k in range(steps):
        st.step(x, float(tau[k]), vx)
        sol = solve_ivp(lambda _t, y: plant.rhs(y, tau[k], vx), (0.0, DT), ref, method="DOP853", rtol=1e-10,
                        atol=1e-12 * np.array([1, 1, 1, 1, 1, 1, 1e3, 1e3]))
        ref = sol.y[:, -1]
        out.append(x.copy())
        outr.append(ref.copy())
    out, outr = np.array(out), np.array(outr)
    scale = np.abs(outr).max(axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(out - outr).max(axis=0) / scale) < 1e-4


def test_one_blas_thread_limits_blas_while_the_function_runs_and_restores_it():
    """The work that alternates BLAS with the batched kernel (diagnose, score_model) runs with one BLAS
    thread per library (ptw_env.integrate.one_blas_thread: spinning OpenBLAS threads took the cores from
    the kernel), and the caller's settings come back afterwards, also after an error."""
    import numpy as np
    import scipy.linalg  # noqa: F401  (scipy's own OpenBLAS loaded too)
    from threadpoolctl import threadpool_limits

    from ptw_env.integrate import one_blas_thread

    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        assert before and max(before) == 2  # a BLAS with 2 threads to limit
        seen = []

        @one_blas_thread
        def work(fail: bool) -> int:
            seen.append(blas_threads())
            if fail:
                raise RuntimeError("inside")
            return int(np.ones((3, 3)).dot(np.ones(3))[0])

        assert work(False) == 3
        with pytest.raises(RuntimeError, match="inside"):
            work(True)
        assert seen == [[1] * len(before)] * 2
        assert blas_threads() == before


def test_diagnose_and_score_model_read_the_log_with_one_blas_thread(monkeypatch):
    """diagnose and score_model run under one_blas_thread: the log is read (their first step after the
    argument checks) with one BLAS thread per library, and the caller's two are back after the call."""
    import types

    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    import assist.diagnose.diagnosis as dg

    seen = []

    def reading(path):
        seen.append(blas_threads())
        raise RuntimeError(f"read {path}")

    monkeypatch.setattr(dg, "read_log", reading)  # diagnose's first step
    monkeypatch.setattr(dg, "_load", reading)  # score_model's, after its checks of the report (stubbed below)
    monkeypatch.setattr(dg, "DiagnosisReport", types.SimpleNamespace)
    report = types.SimpleNamespace(model_z=[0.0], verdict_z=[0.0], vehicle=None)
    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        with pytest.raises(RuntimeError, match="read ride.csv"):
            dg.diagnose("ride.csv")
        with pytest.raises(RuntimeError, match="read other.csv"):
            dg.score_model("other.csv", report)
        assert blas_threads() == before and max(before) == 2
    assert seen == [[1] * len(before)] * 2


def blas_threads() -> list[int]:
    """Threads of each BLAS library loaded in the process."""
    from threadpoolctl import threadpool_info

    return sorted(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")


@pytest.mark.parametrize("speeds", ["fast", {"a": 1}, [[1.0, 2.0], [3.0]], [], [float("nan")]])
def test_bad_speeds_are_one_clear_error(speeds):
    """``speeds=`` that are not finite numbers of m/s: one error naming ``speeds``, never numpy's."""
    from ptw_env.friction import FrictionPlants, FrictionSchedule
    from ptw_env.integrate import SimulationInputError, speed_grid, substeps_for
    from ptw_env.vehicle import REFERENCE_SCOOTER

    with pytest.raises(SimulationInputError, match="speeds must be"):
        speed_grid(REFERENCE_SCOOTER, speeds)
    with pytest.raises(SimulationInputError, match="speeds must be"):
        substeps_for(0.01, vehicle=REFERENCE_SCOOTER, speeds=speeds)
    with pytest.raises(ValueError, match="speeds must be"):
        REFERENCE_SCOOTER.fastest_rate(speeds)
    with pytest.raises(ValueError, match="speeds must be"):  # when built, not at the first new friction
        FrictionPlants(FrictionSchedule.constant(0.9), speeds=speeds)


@pytest.mark.parametrize("speeds", [[0.0, 1e15], [-5.0], [10.0, 100.0]])
def test_speeds_outside_the_vehicles_range_are_one_clear_error(speeds):
    """A ride's speeds beyond the vehicle's valid range are refused as simulate() refuses them (a span of
    1e15 m/s asked speed_grid for petabytes of speeds; a negative speed gave a mode rate silently)."""
    from ptw_env.integrate import SimulationInputError, speed_grid, substeps_for
    from ptw_env.vehicle import REFERENCE_SCOOTER

    with pytest.raises(SimulationInputError, match="valid range"):
        speed_grid(REFERENCE_SCOOTER, speeds)
    with pytest.raises(SimulationInputError, match="valid range"):
        substeps_for(0.01, vehicle=REFERENCE_SCOOTER, speeds=speeds)
    from ptw_env.friction import FrictionPlants, FrictionSchedule

    with pytest.raises(SimulationInputError, match="valid range"):  # at once, not at the first new friction
        FrictionPlants(FrictionSchedule(((0.0, 0.9), (10.0, 0.5))), speeds=speeds)
