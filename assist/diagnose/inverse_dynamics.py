"""Inverse dynamics of the steer equation: the hand fit a diagnosis is compared with (issue 19).

A careful engineer with a ride log and the model's equations would not replay anything: they
would compute every term of the steer equation from the measured signals and their derivatives
and regress what is left on the terms they suspect, here a viscous steering damping and a torque
offset. :func:`steer_equation_fit` does exactly that. It is an equation-error method: consistent
when the regressors are clean (checked on simulated logs with a known damping, which it recovers
to 1 %: ``tests/test_inverse_dynamics.py``), biased when they are noisy or when the equation misses a
term correlated with them. :func:`assist.diagnose.diagnose` is an output-error method over every
channel at once; ``scripts/eval_diagnose_real.py`` puts the two side by side on the real rides.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import savgol_filter

from ptw_env.logs import RideLog
from ptw_env.dynamics import compile_plant
from ptw_env.kernels import rhs_into
from ptw_env.vehicle import DELTA, DELTA_DOT, FYF, FYR, PHI, PHI_DOT, R, VY, Vehicle

from .data import DiagnoseInputError


#: The terms :func:`steer_equation_fit` can regress on, each with its regressor's name and its unit.
TERMS = {"damping": ("-delta_dot", "damping_nms", "N m s/rad"), "inertia": ("-delta_ddot", "inertia_kgm2", "kg m^2"),
         "offset": ("1", "offset_nm", "N m")}


def steer_equation_fit(log: RideLog, vehicle: Vehicle, roll: np.ndarray | None = None, window: int = 21,
                       terms: tuple[str, ...] = ("damping", "offset")) -> dict:
    """What a careful engineer fits by hand: inverse dynamics of the steer equation, least squares.

    Row ``delta_dot`` of model.md, ``E_6 x' = A_6(vx) x + tau`` (N m), with every term computed
    from the log: ``delta``, ``delta_rate``, ``yaw_rate``, ``roll_rate`` measured, the lean ``roll``
    [rad] (default the log's ``roll`` column), the gravity terms with their sines as the plant has them
    (the model's own right-hand side, :func:`ptw_env.kernels.rhs_into`),
    their derivatives by a Savitzky-Golay filter (``window`` samples, cubic;
    the same filter smooths every undifferentiated signal, so all terms have the same lag), and the
    unmeasured ``vy'``, ``Fyf``, ``Fyr`` solved per sample from the lateral and yaw rows and the
    accelerometer, ``M a_y = Fyf + Fyr``. The steer row's residual torque is regressed on
    ``terms`` over the samples ridden inside the vehicle's speed range. The model with an added
    damping ``d``, steer inertia ``J`` and torque offset ``o`` reads
    ``E_6 x' - A_6 x - tau = -d delta_dot - J delta'' + o``; the default fits ``d`` [N m s/rad] and
    ``o`` [N m], ``"inertia"`` adds ``J`` [kg m^2] (a steer motor's rotor left out of the fork's
    inertia). Returns each fitted value (``damping_nms``, ``inertia_kgm2``, ``offset_nm``) with its
    1-sigma (``..._std``, from the residual), the samples used, ``r2`` (the share of the
    steer-row residual the terms explain) and the residual's rms [N m]. Equation error: the regressor
    ``delta_rate`` carries noise (biasing the damping towards 0) and the torque comes from the
    robot's feedback controller (correlated with the state); the diagnosis's output-error replay
    is consistent under the first and fits initial states per window under the second.
    """
    c = log.columns
    if roll is None:
        if "roll" not in c:
            raise DiagnoseInputError(f"{log.path or 'log'}: the steer-equation fit needs the lean angle: the log has no "
                                     "'roll' column; pass roll= (e.g. an estimate of the lean)")
        roll = c["roll"]
    roll = np.asarray(roll, dtype=float)
    if roll.shape != np.shape(c["t"]) or not np.all(np.isfinite(roll)):
        raise DiagnoseInputError(f"roll must be {len(c['t'])} finite values [rad], one per sample of the log")
    if not terms or any(t not in TERMS for t in terms) or len(set(terms)) != len(terms):
        raise DiagnoseInputError(f"terms must be distinct names of {tuple(TERMS)}, got {terms!r}")
    if not isinstance(window, int) or window < 5 or window % 2 == 0 or window > len(roll):
        raise DiagnoseInputError(f"window must be an odd number of samples >= 5 and <= the log's length, got {window!r}")
    dt = float(np.median(np.diff(c["t"])))

    def sg(x, d=0):
        return savgol_filter(np.asarray(x, dtype=float), window, 3, deriv=d, delta=dt)

    phi = sg(roll)
    n = len(phi)
    X = np.zeros((n, 8))
    Xd = np.zeros((n, 8))
    X[:, PHI], X[:, DELTA], X[:, R] = phi, sg(c["delta"]), sg(c["yaw_rate"])
    X[:, PHI_DOT], X[:, DELTA_DOT] = sg(c["roll_rate"]), sg(c["delta_rate"])
    Xd[:, PHI], Xd[:, DELTA] = X[:, PHI_DOT], X[:, DELTA_DOT]
    Xd[:, R], Xd[:, PHI_DOT], Xd[:, DELTA_DOT] = sg(c["yaw_rate"], 1), sg(c["roll_rate"], 1), sg(c["delta_rate"], 1)
    vx, tau, ay = sg(c["vx"]), np.asarray(c["tau"], dtype=float), sg(c["ay"])
    E, B = vehicle.E, np.ravel(vehicle.B)
    if np.any(vehicle.A0[VY:DELTA_DOT + 1, VY]) or np.any(vehicle.A1[VY:DELTA_DOT + 1, VY]):
        raise DiagnoseInputError(f"{vehicle.name}: vy enters a mechanical row of A; the steer-equation fit cannot "
                                 "solve the axle forces from the accelerometer")
    # unknowns u = [vy', Fyf, Fyr] per sample: rows VY (lateral) and R (yaw) of E x' = A x + B tau (no sine
    # terms there), and the accelerometer M ay = Fyf + Fyr; solved with every other term from the log
    for k in range(n):
        A = vehicle.A(vx[k])
        M3 = np.array([[E[VY, VY], -A[VY, FYF], -A[VY, FYR]], [E[R, VY], -A[R, FYF], -A[R, FYR]],
                       [0.0, 1.0, 1.0]])
        rhs = np.array([-(E[VY] @ Xd[k] - A[VY] @ X[k] - B[VY] * tau[k]),
                        -(E[R] @ Xd[k] - A[R] @ X[k] - B[R] * tau[k]), vehicle.mass * ay[k]])
        Xd[k, VY], X[k, FYF], X[k, FYR] = np.linalg.solve(M3, rhs)
    # the steer row's residual torque through the model's own right-hand side (sin(phi), sin(delta) and all):
    # E_6 f(x, tau) is row 6 of A x + B tau with its sines, since E's row 6 has no tire-force columns
    f = np.empty_like(X)
    rhs_into(X, np.ascontiguousarray(tau), np.ascontiguousarray(vx), *compile_plant(vehicle).flat(), f)
    res = E[DELTA_DOT] @ (Xd - f).T
    half = window // 2
    ok = (vx >= vehicle.vmin) & (vx <= vehicle.vmax) & np.isfinite(res)
    ok[:half], ok[-half:] = False, False
    if ok.sum() < 10 * window:
        raise DiagnoseInputError(f"{log.path or 'log'}: {int(ok.sum())} samples ridden inside the vehicle's speed range "
                                 f"{vehicle.vmin:g}-{vehicle.vmax:g} m/s; the steer-equation fit needs {10 * window}")
    cols = {"damping": -X[ok, DELTA_DOT], "inertia": -Xd[ok, DELTA_DOT], "offset": np.ones(int(ok.sum()))}
    Phi = np.stack([cols[t] for t in terms], axis=1)
    coef, *_ = np.linalg.lstsq(Phi, res[ok], rcond=None)
    e = res[ok] - Phi @ coef
    cov = np.linalg.inv(Phi.T @ Phi) * float(e @ e) / max(int(ok.sum()) - len(terms), 1)
    out: dict = {}
    for i, t in enumerate(terms):
        out[TERMS[t][1]] = float(coef[i])
        out[TERMS[t][1].rsplit("_", 1)[0] + "_std"] = float(math.sqrt(cov[i, i]))
    out["samples"] = int(ok.sum())
    out["r2"] = 1.0 - float(e @ e) / float(((res[ok] - res[ok].mean()) ** 2).sum())
    out["residual_rms_nm"] = float(np.sqrt(np.mean(res[ok] ** 2)))
    return out
