"""The rider of the scenarios: a gain-scheduled full-state LQR with integral action.

Two layers, kept apart on purpose:

* :func:`lqr_gain`, :func:`steady_turn` and :class:`GainSchedule` are the
  deterministic **full-state LQR** (roll tracking with integral action and a
  steady-turn feedforward). It is the "full-state LQR" baseline controller of
  the project as well as the rider's brain; it knows nothing of noise.
* :class:`LQRRider` wraps a schedule into the **rider-torque source** of the
  scenarios: it reads the true state (a human rider perceives his own
  motion), adds band-limited random torque, as the reference ride logs'
  "LQR rider with integral action and random torque" does, and saturates at
  the rider's strength.

The control law (units: ``tau`` N m, angles rad, ``e_I`` rad s) is

.. math::

    \\tau = \\tau_{ss}(v_x)\\,\\phi_{ref} - K_x(v_x)\\,(x - x_{des}) - k_I(v_x)\\, e_I,
    \\qquad x_{des} = x_{ss}(v_x)\\,\\phi_{ref} + e_{\\dot\\phi}\\,\\dot\\phi_{ref},
    \\qquad \\dot e_I = \\phi - \\phi_{ref},

with ``[K_x, k_I]`` the LQR gain of the model linearised at the upright
(``shared/spec/model.md``) augmented with the roll-error integral,
``(x_ss, tau_ss)`` the steady turn of the same linear model per radian of
roll, and ``e_phidot phi_ref_dot`` asking for the reference's roll rate
(the rider anticipates the roll the path needs; without this term the
scenarios' RMS roll error is about five times larger).

Examples
--------
>>> import numpy as np
>>> from ptw_env.dynamics import compile_plant
>>> from ptw_env.integrate import Stepper
>>> rider, step = LQRRider(), Stepper(compile_plant())
>>> x = np.zeros(8)
>>> for _ in range(500):                        # 5 s holding 10 deg at 15 m/s
...     ok = step.step(x, rider.torque(x, 15.0, np.radians(10.0)), 15.0)
>>> round(float(np.degrees(x[0])), 1)
10.0
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
import scipy.linalg

from .vehicle import PHI, REFERENCE_SCOOTER, Vehicle


class LQRDesignError(ValueError):
    """A weight of the wrong shape or sign, or a speed where no stabilising LQR gain exists."""


class RiderError(ValueError):
    """A rider setting out of range, or a rider used without its random generator."""


#: Default state weights: the inverse squares of the acceptable excursions (Bryson's rule),
#: order ``[phi, delta, vy, r, phi_dot, delta_dot, Fyf, Fyr, e_I]``.
#: phi 1 deg, r 0.1 rad/s, phi_dot 0.25 rad/s, delta_dot 0.5 rad/s, e_I 0.5 deg s; the steering
#: angle, the lateral velocity and the tire forces follow (weight 0). The yaw-rate weight damps
#: the weave at high speed (closed-loop damping ratio 0.66 at 40 m/s instead of 0.33 without it).
DEFAULT_MAX_EXCURSION = np.array(
    [math.radians(1.0), math.inf, math.inf, 0.1, 0.25, 0.5, math.inf, math.inf, math.radians(0.5)]
)
#: Default acceptable torque [N m] of the reference scooter (``R = 1 / tau_scale^2``); another vehicle
#: takes it times :attr:`ptw_env.vehicle.Vehicle.torque_ratio` (its steer torque per radian of lean
#: relative to the scooter's): a 37 kg bicycle's rider with the scooter's 20 N m saturates at 60 N m
#: and tracks a 14 km/h lane change to 1.8 deg RMS; with its own 1.06 N m, to 0.65 deg with 1.5 N m.
DEFAULT_TAU_SCALE = 20.0
#: Default saturation of the rider's torque [N m] on the reference scooter (times ``torque_ratio``).
DEFAULT_TAU_MAX = 60.0


def default_weights(integral: bool = True, vehicle: Vehicle | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The default ``(Q, R)``: Bryson's rule on :data:`DEFAULT_MAX_EXCURSION` and :data:`DEFAULT_TAU_SCALE`.

    ``Q = diag(1 / x_max^2)`` (9 x 9 with the integral, else 8 x 8),
    ``R = [[1 / tau_scale^2]]`` with ``tau_scale = DEFAULT_TAU_SCALE * vehicle.torque_ratio``
    (the reference scooter's by default). With these the scooter rider's torque stays below
    its 60 N m saturation on the scenarios and the slowest closed-loop mode of the
    linear model has a damping ratio above 0.5 at every speed in [3, 40] m/s
    (``tests/test_rider.py`` checks both).
    """
    ratio = 1.0 if vehicle is None else vehicle.torque_ratio
    q = 1.0 / DEFAULT_MAX_EXCURSION**2
    Q = np.diag(q if integral else q[:8])
    return Q, np.array([[1.0 / (DEFAULT_TAU_SCALE * ratio) ** 2]])


def _augmented(vehicle: Vehicle, vx: float, integral: bool) -> tuple[np.ndarray, np.ndarray]:
    A = vehicle.state_matrix(vx)
    B = vehicle.input_matrix()
    if not integral:
        return A, B
    Aa = np.zeros((9, 9))
    Aa[:8, :8] = A
    Aa[8, PHI] = 1.0  # e_I' = phi - phi_ref
    return Aa, np.vstack([B, [[0.0]]])


def _weights(Q, R, integral: bool, vehicle: Vehicle | None = None) -> tuple[np.ndarray, np.ndarray]:
    n = 9 if integral else 8
    Q0, R0 = default_weights(integral, vehicle)
    Q = Q0 if Q is None else np.asarray(Q, dtype=float)
    R = R0 if R is None else np.atleast_2d(np.asarray(R, dtype=float))
    if Q.ndim == 1:
        Q = np.diag(Q)
    if Q.shape != (n, n):
        raise LQRDesignError(
            f"Q must be ({n}, {n}) (or a diagonal of length {n}) with integral={integral}, got {Q.shape}"
        )
    if R.shape != (1, 1):
        raise LQRDesignError(f"R must be a positive scalar or a (1, 1) array, got shape {R.shape}")
    if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(R))):
        raise LQRDesignError("Q and R must be finite")
    if not np.allclose(Q, Q.T) or np.linalg.eigvalsh((Q + Q.T) / 2).min() < -1e-12 * max(1.0, np.abs(Q).max()):
        raise LQRDesignError("Q must be symmetric positive semi-definite")
    if R[0, 0] <= 0:
        raise LQRDesignError(f"R must be > 0, got {R[0, 0]!r}")
    return (Q + Q.T) / 2, R


def lqr_gain(vehicle: Vehicle | None = None, vx: float = 15.0, Q=None, R=None, integral: bool = True) -> np.ndarray:
    """Continuous-time LQR gain of the linearised PTW, optionally with roll-error integral.

    Minimises ``int (z' Q z + R tau^2) dt`` for ``z' = A_a z + B_a tau`` with
    ``z = [x, e_I]``, ``A_a = [[A, 0], [e_phi', 0]]``, ``B_a = [B; 0]``,
    ``A = E^-1 A(vx)`` and ``B = E^-1 B`` (model.md, linearised at the
    upright); ``tau = -K z`` with ``K = R^-1 B_a' P`` and ``P`` the solution
    of the continuous algebraic Riccati equation
    (:func:`scipy.linalg.solve_continuous_are`).

    Parameters
    ----------
    vehicle : Vehicle, optional
        Defaults to the reference scooter.
    vx : float
        Forward speed [m/s], within ``[vehicle.vmin, vehicle.vmax]``.
    Q : array_like, optional
        State weight, (9, 9) with the integral, (8, 8) without, or its
        diagonal. Default: :func:`default_weights`.
    R : float or array_like, optional
        Torque weight [1/(N m)^2]. Default: ``1/20^2``.
    integral : bool
        Augment with ``e_I' = phi - phi_ref`` (default True).

    Returns
    -------
    ndarray, shape (1, 9) or (1, 8)
        ``K``; columns in the order of ``STATE_NAMES`` (then ``e_I``).

    Raises
    ------
    LQRDesignError
        Bad weights, a speed outside the vehicle's range, or no stabilising
        solution (the closed-loop eigenvalues of ``A_a - B_a K`` are checked).

    Examples
    --------
    >>> K = lqr_gain(vx=20.0)
    >>> K.shape, bool(np.all(np.linalg.eigvals(_augmented(REFERENCE_SCOOTER, 20.0, True)[0]
    ...                                  - _augmented(REFERENCE_SCOOTER, 20.0, True)[1] @ K).real < 0))
    ((1, 9), True)
    """
    vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
    vx = float(vx)
    if not (vehicle.vmin <= vx <= vehicle.vmax):
        raise LQRDesignError(f"vx = {vx:g} m/s is outside the vehicle's range [{vehicle.vmin:g}, {vehicle.vmax:g}] m/s")
    Q, R = _weights(Q, R, integral, vehicle)
    A, B = _augmented(vehicle, vx, integral)
    try:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise LQRDesignError(f"no LQR solution at vx = {vx:g} m/s ({exc}); is (A, sqrt(Q)) detectable?") from None
    K = np.linalg.solve(R, B.T @ P)
    eig = np.linalg.eigvals(A - B @ K)
    if not np.all(eig.real < 0):
        raise LQRDesignError(
            f"the LQR gain at vx = {vx:g} m/s does not stabilise the linear model "
            f"(max Re(eig) = {eig.real.max():.3g} rad/s); is (A, sqrt(Q)) detectable?"
        )
    return K


def steady_turn(vehicle: Vehicle | None = None, vx: float = 15.0) -> tuple[np.ndarray, float]:
    """Steady turn of the linear model per radian of roll: ``(x_ss, tau_ss)`` with ``x_ss[phi] = 1``.

    Solves ``0 = A x_ss + B tau_ss`` (``A = E^-1 A(vx)``, ``B = E^-1 B``,
    model.md) for the seven other states and the torque with ``phi = 1``:
    ``[A[:, 1:], B] [x_ss[1:]; tau_ss] = -A[:, 0]`` (8 equations, 8 unknowns;
    the first two rows give ``phi_dot = delta_dot = 0``). By linearity the
    steady turn at roll ``phi_ref`` is ``(x_ss phi_ref, tau_ss phi_ref)``.
    At 20 m/s: ``tau_ss = -42.3`` N m/rad (the rider counter-steers in a
    steady turn), ``r_ss = 0.479`` rad/s per rad, i.e.
    ``vx r_ss / g = 0.979``.

    Examples
    --------
    >>> xs, ts = steady_turn(vx=20.0)
    >>> round(ts, 1), round(float(xs[3] * 20.0 / 9.81), 3)
    (-42.3, 0.979)
    """
    vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
    A, B = vehicle.state_matrix(vx), vehicle.input_matrix()
    M = np.column_stack([A[:, 1:], B])
    scale = np.abs(M).max(axis=0)  # column scaling: the unknowns span N and rad
    sol = np.linalg.solve(M / scale, -A[:, PHI]) / scale
    return np.concatenate(([1.0], sol[:7])), float(sol[7])


# ----------------------------------------------------------------------------- schedule
_CACHE: "OrderedDict[bytes, tuple[np.ndarray, ...]]" = OrderedDict()
_CACHE_SIZE = 32


def _key(vehicle: Vehicle, Q: np.ndarray, R: np.ndarray, integral: bool, step: float) -> bytes:
    parts = [vehicle.E, vehicle.A0, vehicle.A1, vehicle.B, np.array([vehicle.vmin, vehicle.vmax, step, integral]), Q, R]
    return b"|".join(np.ascontiguousarray(p, dtype=float).tobytes() for p in parts)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=float)
    a.setflags(write=False)
    return a


class GainSchedule:
    """LQR gains and steady turns on a speed grid, linearly interpolated in ``vx``.

    The grid runs from ``vehicle.vmin`` to ``vehicle.vmax`` (both included)
    uniformly every ``step`` m/s, or slightly less where ``step`` does not
    divide the range; below/above it the end values are used.
    Schedules are cached per ``(vehicle matrices, Q, R, integral, step)``,
    so building the same schedule again costs a dictionary look-up.

    Parameters
    ----------
    vehicle : Vehicle, optional
        Defaults to the reference scooter.
    Q, R : array_like, optional
        LQR weights (see :func:`lqr_gain`).
    integral : bool
        With roll-error integral (default True).
    step : float
        Grid spacing [m/s] (default 1).

    Attributes
    ----------
    speeds : ndarray, shape (n,)
        Grid speeds [m/s].
    gains : ndarray, shape (n, 9) or (n, 8)
        ``K`` at each grid speed.
    x_ss : ndarray, shape (n, 8)
        Steady-turn state per radian of roll.
    tau_ss : ndarray, shape (n,)
        Steady-turn torque per radian of roll [N m/rad].

    Examples
    --------
    >>> s = GainSchedule()
    >>> s.speeds[[0, -1]].tolist(), s.gain(12.5).shape, GainSchedule().gains is s.gains
    ([3.0, 40.0], (9,), True)
    """

    def __init__(
        self, vehicle: Vehicle | None = None, Q=None, R=None, integral: bool = True, step: float = 1.0
    ) -> None:
        self.vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
        if not (isinstance(step, (int, float)) and 0 < step <= self.vehicle.vmax - self.vehicle.vmin):
            raise LQRDesignError(f"step must be in (0, vmax - vmin] m/s, got {step!r}")
        self.integral = bool(integral)
        self.Q, self.R = _weights(Q, R, self.integral, self.vehicle)
        span = self.vehicle.vmax - self.vehicle.vmin
        self.step = span / math.ceil(span / float(step) - 1e-9)  # uniform grid, spacing <= step
        key = _key(self.vehicle, self.Q, self.R, self.integral, self.step)
        if key in _CACHE:
            _CACHE.move_to_end(key)
        else:
            _CACHE[key] = self._build()
            if len(_CACHE) > _CACHE_SIZE:
                _CACHE.popitem(last=False)
        self.speeds, self.gains, self.x_ss, self.tau_ss, self._table = _CACHE[key]

    def _build(self) -> tuple[np.ndarray, ...]:
        v = self.vehicle
        n = int(round((v.vmax - v.vmin) / self.step)) + 1
        speeds = np.linspace(v.vmin, v.vmax, n)
        gains = np.vstack([lqr_gain(v, s, self.Q, self.R, self.integral) for s in speeds])
        turns = [steady_turn(v, s) for s in speeds]
        x_ss = np.vstack([t[0] for t in turns])
        tau_ss = np.array([t[1] for t in turns])
        # per grid speed: [K_x (8), k_I, c] with tau = c phi_ref - K_x x - k_I e_I, c = tau_ss + K_x x_ss
        kI = gains[:, 8] if self.integral else np.zeros(n)
        table = np.column_stack([gains[:, :8], kI, tau_ss + np.einsum("ij,ij->i", gains[:, :8], x_ss)])
        return tuple(_frozen(a) for a in (speeds, gains, x_ss, tau_ss, table))

    def _weights_at(self, vx: float) -> tuple[int, float]:
        u = (float(vx) - self.speeds[0]) / self.step
        i = min(max(int(u), 0), len(self.speeds) - 2)
        return i, min(max(u - i, 0.0), 1.0)

    def _interp(self, a: np.ndarray, vx: float) -> np.ndarray:
        i, w = self._weights_at(vx)
        return a[i] + w * (a[i + 1] - a[i])

    def gain(self, vx: float) -> np.ndarray:
        """``K(vx)`` (shape (9,) with the integral, else (8,)), interpolated linearly."""
        return self._interp(self.gains, vx)

    def steady_state(self, vx: float, phi_ref: float) -> tuple[np.ndarray, float]:
        """``(x_ss, tau_ss)`` of the linear model in a steady turn at roll ``phi_ref`` [rad] (:func:`steady_turn`)."""
        return self._interp(self.x_ss, vx) * phi_ref, float(self._interp(self.tau_ss, vx)) * phi_ref

    def control(self, x: np.ndarray, vx: float, phi_ref: float = 0.0, e_int: float = 0.0,
                phi_ref_rate: float = 0.0) -> float:
        """The LQR torque [N m] (no noise, no saturation):
        ``tau_ss phi_ref - K_x (x - x_ss phi_ref - e_phidot phi_ref_rate) - k_I e_int``.

        ``x`` is the state (8,), ``e_int`` the roll-error integral [rad s]
        (ignored without integral action), ``phi_ref_rate`` the reference's
        roll rate [rad/s]. The feedforward gain ``c = tau_ss + K_x x_ss`` is
        interpolated as a whole.
        """
        row = self._interp(self._table, vx)
        return float(row[9] * phi_ref + row[4] * phi_ref_rate - row[:8] @ x - row[8] * e_int)


# ----------------------------------------------------------------------------- rider
class LQRRider:
    """Rider-torque source: scheduled LQR on the true state + band-limited random torque.

    ``torque(x, vx, phi_ref)`` returns

    .. math::

        \\tau_k = \\mathrm{sat}_{\\tau_{max}}\\big(\\tau_{LQR}(x_k, v_x, \\phi_{ref,k},
                 \\dot\\phi_{ref,k}, e_{I,k}) + n_k\\big),
        \\qquad e_{I,k+1} = e_{I,k} + (\\phi_k - \\phi_{ref,k})\\,dt,

    (:meth:`GainSchedule.control`), the integral frozen while the torque
    saturates (conditional-integration anti-windup). The reference roll
    rate is ``(phi_ref,k - phi_ref,k-1)/dt`` (0 at the first call after
    :meth:`reset`) unless ``phi_ref_rate`` is given. The random torque
    ``n`` is a first-order Gauss-Markov process, stationary standard
    deviation ``torque_noise_nm`` and -3 dB bandwidth ``noise_bandwidth_hz``
    (``f_c``):

    .. math::

        n_{k+1} = a\\,n_k + \\sigma\\sqrt{1 - a^2}\\,w_k,\\quad a = e^{-2\\pi f_c\\,dt},
        \\quad w_k \\sim N(0, 1),\\quad n_0 \\sim N(0, \\sigma^2),

    drawn from the generator given to :meth:`reset` in blocks of 1024
    normals (same generator state, same torque sequence). Without noise the
    rider draws nothing and needs no :meth:`reset` before its first ride.

    Parameters
    ----------
    vehicle : Vehicle, optional
        Model the rider's gains are designed on (default: reference scooter).
    schedule : GainSchedule, optional
        Gains to use (default: ``GainSchedule(vehicle)``).
    torque_noise_nm : float
        Standard deviation of the random torque [N m] (default 0).
    noise_bandwidth_hz : float
        Corner frequency of the random torque [Hz] (default 2).
    tau_max : float, optional
        Saturation of the rider's torque [N m] (default :data:`DEFAULT_TAU_MAX` times the
        vehicle's ``torque_ratio``: 60 N m on the reference scooter).
    dt : float
        Call period of :meth:`torque` [s] (default 0.01).
    """

    __slots__ = ("schedule", "torque_noise_nm", "noise_bandwidth_hz", "tau_max", "dt", "_table", "_v0", "_inv_step",
                 "_nmax", "_e_int", "_noise", "_a", "_b", "_rng", "_w", "_iw", "_phi_prev")

    _BLOCK = 1024

    def __init__(
        self,
        vehicle: Vehicle | None = None,
        schedule: GainSchedule | None = None,
        torque_noise_nm: float = 0.0,
        noise_bandwidth_hz: float = 2.0,
        tau_max: float | None = None,
        dt: float = 0.01,
    ) -> None:
        if schedule is None:
            schedule = GainSchedule(vehicle)
        elif vehicle is not None and vehicle is not schedule.vehicle:
            raise RiderError("give either vehicle or schedule (a schedule carries its own vehicle), not both")
        if tau_max is None:
            tau_max = DEFAULT_TAU_MAX * schedule.vehicle.torque_ratio
        if not schedule.integral:
            raise RiderError("LQRRider needs a schedule with integral action (integral=True)")
        for name, val, zero_ok in (
            ("torque_noise_nm", torque_noise_nm, True),
            ("noise_bandwidth_hz", noise_bandwidth_hz, False),
            ("tau_max", tau_max, False),
            ("dt", dt, False),
        ):
            if (
                isinstance(val, bool)
                or not isinstance(val, (int, float))
                or not math.isfinite(val)
                or (val < 0 if zero_ok else val <= 0)
            ):
                bound = ">= 0" if zero_ok else "> 0"
                raise RiderError(f"LQRRider: {name} must be a finite number {bound}, got {val!r}")
        self.schedule = schedule
        self.torque_noise_nm = float(torque_noise_nm)
        self.noise_bandwidth_hz = float(noise_bandwidth_hz)
        self.tau_max = float(tau_max)
        self.dt = float(dt)
        self._table = schedule._table
        self._v0 = float(schedule.speeds[0])
        self._inv_step = 1.0 / schedule.step
        self._nmax = len(schedule.speeds) - 2
        self._a = math.exp(-2.0 * math.pi * self.noise_bandwidth_hz * self.dt)
        self._b = self.torque_noise_nm * math.sqrt(1.0 - self._a**2)
        self._rng = None
        self._w = np.zeros(0)
        self._iw = 0
        self._e_int = 0.0
        self._noise = 0.0
        self._phi_prev = None

    def reset(self, rng: np.random.Generator | int | None = None) -> None:
        """Zero the roll-error integral and restart the random torque from ``rng``
        (a Generator, or a seed for :func:`numpy.random.default_rng`)."""
        self._rng = np.random.default_rng(rng)
        self._e_int = 0.0
        self._phi_prev = None
        self._w = np.zeros(0)
        self._iw = 0
        self._noise = self.torque_noise_nm * self._normal() if self.torque_noise_nm > 0 else 0.0

    def _normal(self) -> float:
        if self._iw >= len(self._w):
            self._w = self._rng.standard_normal(self._BLOCK)
            self._iw = 0
        self._iw += 1
        return float(self._w[self._iw - 1])

    @property
    def vehicle(self) -> Vehicle:
        """The vehicle the gains were designed on."""
        return self.schedule.vehicle

    @property
    def integral(self) -> float:
        """The roll-error integral ``e_I`` [rad s]."""
        return self._e_int

    def torque(self, x: np.ndarray, vx: float, phi_ref: float, phi_ref_rate: float | None = None) -> float:
        """Rider torque [N m] for the true state ``x`` (8,), speed ``vx`` [m/s] and roll reference
        ``phi_ref`` [rad] (``phi_ref_rate`` [rad/s]: its rate, default a backward difference);
        advances the integral and the random torque by ``dt``."""
        if self.torque_noise_nm > 0 and self._rng is None:
            raise RiderError("LQRRider with torque noise: call reset(rng) before torque()")
        u = (vx - self._v0) * self._inv_step
        i = int(u) if u > 0 else 0
        if i > self._nmax:
            i = self._nmax
        w = u - i
        w = 0.0 if w < 0 else (1.0 if w > 1 else w)
        row = self._table[i] + w * (self._table[i + 1] - self._table[i])
        phi = float(x[PHI])
        if phi_ref_rate is None:
            phi_ref_rate = 0.0 if self._phi_prev is None else (phi_ref - self._phi_prev) / self.dt
        self._phi_prev = phi_ref
        tau = row[9] * phi_ref + row[4] * phi_ref_rate - float(row[:8] @ x) - row[8] * self._e_int
        if self.torque_noise_nm > 0:
            tau += self._noise
            self._noise = self._a * self._noise + self._b * self._normal()
        if tau > self.tau_max:
            return self.tau_max
        if tau < -self.tau_max:
            return -self.tau_max
        self._e_int += (phi - phi_ref) * self.dt
        return float(tau)


def bank_lean(vehicle: Vehicle | None, bank_rad: float, vx: float) -> float:
    """Roll relative to the road normal [rad] at which ``vehicle`` runs straight (yaw rate 0) on a road of
    cross-slope ``bank_rad`` [rad] at ``vx`` [m/s]: the steady state of the linearised plant with
    effects.md's ``road_bank`` (row 3 gets ``-M g sin(beta)``, rows 5-6 ``sin(phi - beta)``),

    .. math::

        A x + B \\tau + e(\\beta) = 0,\\qquad r = x_4 = 0,

    nine equations for the eight states and the torque. About ``beta`` itself (the vehicle upright in
    gravity): a rider who holds a straight line on a banked road leans by it, relative to the road,
    where a rider who keeps the road-relative roll at zero turns downhill.

    >>> round(bank_lean(None, 0.03, 15.0) / 0.03, 3)
    1.005
    """
    from .dynamics import compile_plant, linearise

    vx = float(vx)
    p0 = compile_plant(vehicle, None)
    pb = compile_plant(vehicle, f"road_bank:bank_rad={float(bank_rad)!r}")
    A, B = linearise(p0, vx)
    x0 = np.zeros(8)
    M = np.zeros((9, 9))
    M[:8, :8] = A
    M[:8, 8] = B[:, 0]
    M[8, 3] = 1.0  # r = 0
    sol = np.linalg.solve(M, np.concatenate([p0.rhs(x0, 0.0, vx) - pb.rhs(x0, 0.0, vx), [0.0]]))
    return float(sol[PHI])


__all__ = [
    "GainSchedule",
    "LQRDesignError",
    "LQRRider",
    "RiderError",
    "bank_lean",
    "default_weights",
    "lqr_gain",
    "steady_turn",
]
