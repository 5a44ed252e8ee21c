"""Fixed-step RK4 integration of the nonlinear model, one vehicle or a batch.

Inputs ``tau`` and ``vx`` are held constant over each control period ``dt``
(zero-order hold, as the instrumented scooter's logger and the reference ride
logs do). Inside a period the state is advanced by ``substeps`` classical RK4
steps. The default, :data:`DEFAULT_SUBSTEP` = 2.5 ms (4 substeps at 100 Hz),
keeps the relative error against a tight ``solve_ivp`` below 1e-5 up to
40 m/s, where the tire modes reach |lambda| ~ 190 rad/s (``|lambda h|``
~ 0.47, well inside RK4's stability region); ``tests/test_integrate.py``
checks 1e-4 over a 20 s ride. For another vehicle the substep is also kept
below ``MAX_LAMBDA_H / |lambda|_max`` (:attr:`ptw_env.vehicle.Vehicle.fastest_eigenvalue`),
so a vehicle with stiffer modes than the scooter's gets the same accuracy.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TypeVar

import numpy as np
from threadpoolctl import threadpool_limits

from . import kernels
from .dynamics import Plant, compile_plant, linearise
from .vehicle import RATE_GRID, Vehicle, speed_array

#: Largest internal RK4 step [s].
DEFAULT_SUBSTEP = 0.0025
#: Largest ``|lambda h|`` of the vehicle's fastest mode per RK4 substep (the scooter's 0.47 at 40 m/s).
MAX_LAMBDA_H = 0.47


_F = TypeVar("_F", bound=Callable)


def one_blas_thread(fn: _F) -> _F:
    """Decorator: while ``fn`` runs, the BLAS libraries loaded in the process (numpy's and scipy's OpenBLAS)
    use one thread each (``threadpoolctl.threadpool_limits(1, "blas")``); their settings are restored after.

    For work that alternates small linear algebra with the batched kernels (:func:`simulate`, which runs
    on numba's OpenMP threads, one per core). After each call that OpenBLAS spreads over its threads,
    they keep spinning for a while, waiting for the next one, and take the cores from the kernel that
    follows. Measured on 2 cores (``scripts/bench_diagnose.py``, nine 90 s logs: its median set and a log that
    needs the extension search; the two run in turn on the
    same log, the same verdicts and vehicle-steps): ``ptw-assist diagnose`` takes longer with OpenBLAS's default
    threads (the ratio per log is the benchmark's column "BLAS x"; its stored output is in the README). The matrices of
    such work are small (10 x 10 normal equations, least-squares Jacobians of a few columns): what a second
    BLAS thread gains there is less than what its spinning costs the kernel.
    Entered at each call, so that a BLAS library loaded after import is limited too. The limit is the
    process's (threadpoolctl): calls from several threads of one process share it.
    """

    @functools.wraps(fn)
    def limited(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return limited  # type: ignore[return-value]


class SimulationInputError(ValueError):
    """Inputs to :func:`simulate` with a wrong shape, a non-finite value or a speed outside the valid range."""


def speed_grid(vehicle: Vehicle, speeds) -> np.ndarray:
    """Speeds [m/s] at which a ride's fastest mode is sought: from the lowest to the highest of the speeds it
    meets (e.g. its speed profile) at the spacing of :attr:`ptw_env.vehicle.Vehicle.fastest_eigenvalue`
    (``RATE_GRID - 1`` intervals over the vehicle's range; both ends included; one speed for a ride at constant
    speed). Sizing a
    ride's step at its own speeds keeps ``|lambda h|`` of every mode it meets within :data:`MAX_LAMBDA_H`
    without paying, at 50 km/h, for a tire lag (``~vx / sigma``) met only at the top of the range."""
    try:
        v = speed_array(speeds)
    except ValueError as exc:
        raise SimulationInputError(str(exc)) from None
    lo, hi = float(v.min()), float(v.max())
    if lo < vehicle.vmin or hi > vehicle.vmax:  # as simulate(): the model holds on the vehicle's range only
        raise SimulationInputError(f"speeds {lo:g} to {hi:g} m/s leave the valid range [{vehicle.vmin:g}, "
                                   f"{vehicle.vmax:g}] m/s of the vehicle {vehicle.name!r}")
    span = max(vehicle.vmax - vehicle.vmin, 1e-9)
    n = 1 if hi - lo <= 1e-9 else 1 + max(1, math.ceil((RATE_GRID - 1) * (hi - lo) / span - 1e-9))
    return np.linspace(lo, hi, n)


def substeps_for(dt: float, max_substep: float = DEFAULT_SUBSTEP, vehicle: Vehicle | None = None,
                 extra_rate: float = 0.0, speeds=None) -> int:
    """Number of RK4 substeps per control period ``dt`` [s] so that each is at most ``max_substep``
    and, for ``vehicle``, at most ``MAX_LAMBDA_H / max(vehicle.fastest_eigenvalue, extra_rate)``
    (``extra_rate`` [1/s]: a faster mode a model extension adds, :func:`plant_rate`); given ``speeds``
    [m/s] (those a ride meets), the vehicle's fastest mode at those speeds (:func:`speed_grid`) instead of
    over its whole range (``extra_rate`` should then be taken at the same speeds)."""
    if not (dt > 0 and math.isfinite(dt)):
        raise SimulationInputError(f"dt must be a positive number of seconds, got {dt!r}")
    if vehicle is not None:
        own = vehicle.fastest_eigenvalue if speeds is None else vehicle.fastest_rate(speed_grid(vehicle, speeds))
        max_substep = min(max_substep, MAX_LAMBDA_H / max(own, float(extra_rate)))
    return max(1, math.ceil(dt / max_substep - 1e-9))


def plant_rate(plant: Plant) -> float:
    """Fastest rate [1/s] a plant's generalised forces add beyond its vehicle's modes: Coulomb
    steering friction ``Tc tanh(delta_dot / w)`` acts like a steering damping ``Tc / w`` near
    ``delta_dot = 0``, i.e. a steer mode of rate ``|d delta_dot' / d delta_dot| = |W[5, coulomb]| / w``."""
    col = plant.W[..., 5, -1]
    return float(np.max(np.abs(col))) / kernels.COULOMB_WIDTH if col.size else 0.0


def linear_rate(plant: Plant, speeds=None) -> np.ndarray:
    """Largest ``|eig|`` [1/s] of ``plant`` linearised at the upright (:func:`ptw_env.dynamics.linearise`; a
    Coulomb force's slope ``Tc / w`` included) at its vehicle's lowest, middle and highest speed (or at
    :func:`speed_grid` of ``speeds`` [m/s], those a ride meets), one per plant of a batch: the stiffest mode
    of a plant whose effects (a short relaxation length, a stiff damper) may be faster than its vehicle's
    (:attr:`ptw_env.vehicle.Vehicle.fastest_eigenvalue`)."""
    v = plant.vehicle
    rate = np.zeros(plant.batch_shape)
    grid = (v.vmin, 0.5 * (v.vmin + v.vmax), v.vmax) if speeds is None else speed_grid(v, speeds)
    for vx in grid:
        A, _ = linearise(plant, vx)
        rate = np.maximum(rate, np.abs(np.linalg.eigvals(A)).max(axis=-1))
    return rate


def _as_plant(vehicle: Vehicle | Plant | None, effects) -> Plant:
    if isinstance(vehicle, Plant):
        if effects is not None:
            raise SimulationInputError("pass effects either in the compiled Plant or as effects=, not both")
        return vehicle
    return compile_plant(vehicle, effects)


def _float_array(a, name: str) -> np.ndarray:
    """``a`` as a float array, or one clear error naming the argument (not numpy's)."""
    try:
        return np.asarray(a, dtype=float)
    except (TypeError, ValueError) as exc:
        kind = "ragged (rows of different lengths)" if "inhomogeneous" in str(exc) else "not numeric"
        raise SimulationInputError(f"{name} must be an array of numbers; it is {kind}: {exc}") from None


def simulate(
    x0,
    tau,
    vx,
    dt: float = 0.01,
    effects=None,
    vehicle: Vehicle | Plant | None = None,
    substeps: int | None = None,
) -> np.ndarray:
    """Simulate the nonlinear PTW for one vehicle or a batch in one call.

    Parameters
    ----------
    x0 : array_like, shape (8,) or (N, 8)
        Initial state ``[phi, delta, vy, r, phi_dot, delta_dot, Fyf, Fyr]``
        (rad, rad, m/s, rad/s, rad/s, rad/s, N, N).
    tau : array_like, shape (T,) or (N, T)
        Rider steering torque [N m], held over each period.
    vx : array_like, scalar, shape (T,) or (N, T)
        Forward speed [m/s], held over each period; must lie in the vehicle's
        valid range ``[vmin, vmax]``.
    dt : float
        Control/sampling period [s].
    effects : Effects, dict, list of ``"CAUSE:PARAM=VALUE"`` or None
        Dynamic effects of effects.md (sensor effects are ignored here).
        Array-valued parameters of shape (N,) give one plant per vehicle.
    vehicle : Vehicle or Plant, optional
        Defaults to the reference scooter.
    substeps : int, optional
        RK4 substeps per period (default: :func:`substeps_for` the vehicle: ``ceil(dt / 2.5 ms)``
        unless the vehicle has modes faster than the scooter's).

    Returns
    -------
    ndarray, shape (T + 1, 8) or (N, T + 1, 8)
        ``x[k]`` is the state at ``t = k dt``; ``x[0] = x0``. A vehicle that
        falls keeps being integrated (the model is only valid for
        |phi| <= 45 deg; :class:`ptw_env.env.PTWRollEnv` ends the episode there).

    Examples
    --------
    >>> import numpy as np
    >>> x = simulate(np.zeros(8), np.full(100, 2.0), 20.0)
    >>> x.shape, bool(abs(x[-1, 0]) > 0)
    ((101, 8), True)
    >>> xb = simulate(np.zeros((64, 8)), np.ones((64, 100)), 20.0)
    >>> xb.shape
    (64, 101, 8)
    """
    plant = _as_plant(vehicle, effects)
    if substeps is None:
        nsub = substeps_for(dt, vehicle=plant.vehicle, extra_rate=plant_rate(plant))
    else:
        nsub = int(substeps)
    if nsub < 1:
        raise SimulationInputError(f"substeps must be >= 1, got {substeps!r}")
    x0, tau, vx = (_float_array(a, n) for a, n in ((x0, "x0"), (tau, "tau"), (vx, "vx")))
    if x0.ndim not in (1, 2) or x0.shape[-1] != 8:
        raise SimulationInputError(f"x0 must have shape (8,) or (N, 8), got {x0.shape}")
    batched = x0.ndim == 2 or tau.ndim == 2 or vx.ndim == 2
    if tau.ndim not in (1, 2):
        raise SimulationInputError(f"tau must have shape (T,) or (N, T), got {tau.shape}")
    T = tau.shape[-1]
    if T < 1:
        raise SimulationInputError("tau must hold at least one sample")
    N = max(x0.shape[0] if x0.ndim == 2 else 1, tau.shape[0] if tau.ndim == 2 else 1, vx.shape[0] if vx.ndim == 2 else 1)
    if plant.batch_shape:
        if len(plant.batch_shape) != 1:
            raise SimulationInputError(f"batched effects must be 1-D arrays, got shape {plant.batch_shape}")
        if N == 1 and plant.batch_shape[0] > 1:
            N = plant.batch_shape[0]
            batched = True
        elif plant.batch_shape[0] not in (1, N):
            raise SimulationInputError(f"effects batch of {plant.batch_shape[0]} does not match {N} vehicles")
    try:
        x0b = np.ascontiguousarray(np.broadcast_to(x0, (N, 8)))
        taub = np.ascontiguousarray(np.broadcast_to(tau, (N, T)))
        vxb = np.ascontiguousarray(np.broadcast_to(vx if vx.ndim else np.full(T, float(vx)), (N, T)))
    except ValueError:
        raise SimulationInputError(
            f"shapes do not match: x0 {x0.shape}, tau {tau.shape}, vx {vx.shape} (expected (N, 8), (N, T), (N, T))"
        ) from None
    for name, a in (("x0", x0b), ("tau", taub), ("vx", vxb)):
        if not np.all(np.isfinite(a)):
            idx = np.argwhere(~np.isfinite(a))[0]
            raise SimulationInputError(f"{name} has a non-finite value at index {tuple(int(i) for i in idx)}")
    v = plant.vehicle
    bad = (vxb < v.vmin) | (vxb > v.vmax)
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise SimulationInputError(
            f"vx[{idx}] = {vxb[idx]:.4g} m/s is outside the model's valid range [{v.vmin}, {v.vmax}] m/s"
        )
    out = np.empty((N, T + 1, 8))
    kernels.simulate_batch(x0b, taub, vxb, *plant.flat(), float(dt), nsub, out)
    return out if batched else out[0]


class Stepper:
    """Advance one vehicle by one control period; what :class:`~ptw_env.env.PTWRollEnv` uses.

    Keeps the compiled plant's arrays so that a step costs one kernel call. ``substeps`` default: sized for the
    plant's own fastest linearised mode (:func:`linear_rate`: its effects, e.g. a short relaxation length, may
    be faster than its vehicle) and its vehicle's (:func:`substeps_for`), over the vehicle's speed range or at
    ``speeds`` [m/s] (those a ride meets, :func:`speed_grid`). (:func:`simulate` still sizes from
    the vehicle and Coulomb friction only, :func:`plant_rate`: the ride logs and the diagnosis replays keep
    their step.)
    """

    __slots__ = ("plant", "dt", "nsub", "_W", "_inv_sigma", "_fmax", "_bank")

    def __init__(self, plant: Plant, dt: float = 0.01, substeps: int | None = None, speeds=None) -> None:
        if plant.batch_shape:
            raise SimulationInputError("Stepper takes an unbatched plant")
        self.plant = plant
        self.dt = float(dt)
        self.nsub = (substeps_for(dt, vehicle=plant.vehicle, extra_rate=float(linear_rate(plant, speeds)), speeds=speeds)
                     if substeps is None else int(substeps))
        W, s, f, b = plant.flat()
        self._W, self._inv_sigma, self._fmax, self._bank = W[0], s[0], f[0], float(b[0])

    def step(self, x: np.ndarray, tau: float, vx: float, roll_moment: float = 0.0) -> bool:
        """Advance ``x`` (shape (8,), float64, modified in place) by ``dt`` with ``tau`` [N m],
        ``vx`` [m/s] and an external roll moment [N m] (disturbance) held over the period.
        Returns False when the new state is not finite (the model diverged)."""
        return kernels.step_one(x, tau, vx, roll_moment, self._W, self._inv_sigma, self._fmax, self._bank, self.dt, self.nsub)
