"""Nonlinear right-hand side of the PTW model, for one vehicle or a batch.

The plant simulated by the environment (``shared/spec/model.md``, "The
nonlinear plant") with the optional dynamic effects of
``shared/spec/effects.md``:

.. math::

    E\\,\\dot x = (A_0 + v_x A_1)\\,x + B\\tau
      + \\text{(rows 5, 6)}\\; a_{i1}\\sin(\\phi-\\beta) + a_{i2}\\sin\\delta
      + c

with the tire rows ``(sigma/vx) F_k' = -F_k + F_ss,k``,
``F_ss,k = Fmax_k tanh(F_lin,k / Fmax_k)`` (``F_ss = F_lin`` without
saturation) and ``F_lin,k = -C_alpha_k alpha_k + C_gamma_k gamma_k`` read off
the printed rows 7-8 (``F_lin,k = (sigma_0/vx) sum_{j != k} a_kj x_j``).
``beta`` is the road bank angle, ``c`` collects the bank force
``-(M+m) g sin(beta)`` (row 3) and the roll-moment offset (row 5).

:func:`compile_plant` folds a :class:`~ptw_env.vehicle.Vehicle` and an
:class:`~ptw_env.effects.Effects` into one matrix ``W`` so that the
mechanical rows are a single matrix product with the feature vector
``z = [x, vx x, x/vx, sin(phi-beta), sin(delta), tau, 1, d, vx^2,
tanh(delta_dot/w)]`` (``d``: an external roll moment [N m], the environment's
disturbance input; the last two are zero in the model and carry the
generalised forces of a model extension, :func:`add_generalised_forces`);
effect parameters given as arrays give one ``W`` per vehicle of the batch.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from . import kernels
from .effects import PAYLOAD_HEIGHT, Effects, as_effects
from .vehicle import DELTA_DOT, FYF, FYR, G, REFERENCE_SCOOTER, Vehicle

#: number of features in z
NZ = 31
_ZX, _ZVX, _ZIV, _ZS1, _ZS2, _ZTAU, _ZONE, _ZDIST, _ZV2, _ZCOUL = 0, 8, 16, 24, 25, 26, 27, 28, 29, 30
#: Features a generalised force of a model extension may be proportional to
#: (:func:`add_generalised_forces`): name -> column of ``z``. ``w`` is
#: :data:`ptw_env.kernels.COULOMB_WIDTH`.
FORCE_FEATURES: dict[str, int] = {
    "1": _ZONE,
    "vx^2": _ZV2,
    "vx*vy": _ZVX + 2,
    "vx*delta": _ZVX + 1,
    "delta_dot": _ZX + DELTA_DOT,
    "tanh(delta_dot/w)": _ZCOUL,
}


@dataclass(frozen=True, eq=False)
class Plant:
    """A vehicle with its dynamic effects, compiled for fast evaluation.

    Attributes
    ----------
    W : ndarray, shape (*batch, 8, NZ)
        Rows 0-5 give ``[phi', delta', vy', r', phi_dot', delta_dot']`` and
        rows 6-7 give ``F_lin`` (the unsaturated steady-state tire forces).
    inv_sigma : ndarray, shape (*batch, 2)
        ``1/sigma_k`` [1/m] of the relaxation rows.
    fmax : ndarray, shape (*batch, 2)
        Saturation forces ``mu_peak Fz_k`` [N] (``inf``: linear tires).
    bank : ndarray, shape (*batch,)
        Road bank angle beta [rad].
    mass : ndarray, shape (*batch,)
        Total mass M + m [kg] (for ``ay``).
    Einv : ndarray, shape (*batch, 8, 8)
        ``E^-1`` of the plant (payload included): how a generalised force in a row of model.md
        moves the state derivative (:func:`add_generalised_forces`).
    fz : ndarray, shape (*batch, 2)
        Static normal loads ``(Fzf, Fzr)`` [N] of the vehicle's tires (of each drawn vehicle when the
        vehicle itself is randomised; ``vehicle`` is then the nominal one).
    """

    vehicle: Vehicle
    effects: Effects
    W: np.ndarray
    inv_sigma: np.ndarray
    fmax: np.ndarray
    bank: np.ndarray
    mass: np.ndarray
    Einv: np.ndarray
    fz: np.ndarray

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return self.W.shape[:-2]

    @property
    def saturates(self) -> bool:
        return bool(np.any(np.isfinite(self.fmax)))

    def flat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(W, inv_sigma, fmax, bank)`` with one leading axis (length 1 or the batch size), for the kernels."""
        K = int(np.prod(self.batch_shape)) if self.batch_shape else 1
        return (
            np.ascontiguousarray(self.W.reshape(K, 8, NZ)),
            np.ascontiguousarray(np.broadcast_to(self.inv_sigma, self.batch_shape + (2,)).reshape(K, 2)),
            np.ascontiguousarray(np.broadcast_to(self.fmax, self.batch_shape + (2,)).reshape(K, 2)),
            np.ascontiguousarray(np.broadcast_to(self.bank, self.batch_shape).reshape(K)),
        )

    def rhs(self, x: np.ndarray, tau: np.ndarray | float, vx: np.ndarray | float) -> np.ndarray:
        """``x' = f(x, tau, vx)``: state derivative, shape ``broadcast(x[..., 0], tau, vx) + (8,)``.

        ``vx`` must be positive (the tire rows divide by it). A batched plant
        (array-valued effects) requires the batch shape of ``x`` to match.
        """
        x = np.asarray(x, dtype=float)
        if x.shape[-1:] != (8,):
            raise ValueError(f"x must have a trailing axis of length 8 (the states), got shape {x.shape}")
        shape = np.broadcast_shapes(x.shape[:-1], np.shape(tau), np.shape(vx), self.batch_shape)
        if self.batch_shape and shape != self.batch_shape:
            raise ValueError(f"batched plant of shape {self.batch_shape} cannot evaluate states of shape {shape}")
        n = int(np.prod(shape)) if shape else 1
        xf = np.ascontiguousarray(np.broadcast_to(x, shape + (8,)).reshape(n, 8))
        tf = np.ascontiguousarray(np.broadcast_to(np.asarray(tau, dtype=float), shape).reshape(n))
        vf = np.ascontiguousarray(np.broadcast_to(np.asarray(vx, dtype=float), shape).reshape(n))
        out = np.empty((n, 8))
        kernels.rhs_into(xf, tf, vf, *self.flat(), out)
        return out.reshape(shape + (8,))

    def ay(self, x: np.ndarray) -> np.ndarray:
        """Lateral acceleration in the model (road-plane) frame ``(Fyf + Fyr)/(M + m)`` [m/s^2]."""
        x = np.asarray(x, dtype=float)
        return (x[..., FYF] + x[..., FYR]) / self.mass

    def steady_tire_force(self, x: np.ndarray, vx: np.ndarray | float) -> np.ndarray:
        """``F_ss`` per axle [N], shape ``(..., 2)`` (saturated when tire_saturation is on).

        Read back from the relaxation rows: ``F_ss = F + (sigma/vx) F'``.
        """
        x = np.asarray(x, dtype=float)
        vx = np.asarray(vx, dtype=float)
        d = self.rhs(x, 0.0, vx)
        return x[..., 6:8] + d[..., 6:8] / (vx[..., None] * self.inv_sigma)


def compile_plant(vehicle: Vehicle | None = None, effects=None, model: tuple | None = None) -> Plant:
    """Fold a vehicle and its dynamic effects into a :class:`Plant`.

    ``model``: ``(E, A0, A1, mass, loads)`` of a batch of vehicles of ``vehicle``'s layout
    (:func:`ptw_env.sharp.parameter_batch`: the vehicle's masses, geometry or inertias drawn by domain
    randomisation) in place of ``vehicle``'s own matrices, total mass [kg] and static axle loads [N];
    its batch shape broadcasts with the effects'.

    Implements effects.md exactly:

    * ``tire_stiffness``: the stiffness-carrying entries of row 7 (a71..a76)
      scaled by ``front_scale``, of row 8 (a81..a84) by ``rear_scale``.
    * ``tire_saturation``: ``F_ss = Fmax tanh(F_lin/Fmax)``, ``Fmax_k = mu_peak Fz_k``.
    * ``road_bank``: row 3 gets ``-(M+m) g sin(beta)``; ``sin(phi)`` becomes
      ``sin(phi - beta)`` in rows 5 and 6.
    * ``roll_moment_offset``: constant moment added to row 5.
    * ``payload``: ``e33 += m``, ``e35 = e53 += m hp``, ``e55 += m hp^2``,
      ``a34 += -m vx``, ``a51 += m hp g``, ``a54 += -m hp vx`` (hp = 0.6 m).
    * ``steer_damping``: ``a66 = -damping_nms``.
    * ``relaxation_length``: both ``sigma`` set to ``sigma_m``; ``F_lin`` keeps
      the nominal stiffnesses (rows 7-8 are ``(sigma/vx) F' = -F + F_ss``).

    Sensor effects (gyro_bias, ay_frame, sensor_delay) are ignored here.
    """
    vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
    eff = as_effects(effects)
    if model is None:
        model = (vehicle.E, vehicle.A0, vehicle.A1, np.asarray(vehicle.mass, dtype=float),
                 np.array([vehicle.tires.Fzf, vehicle.tires.Fzr]))
    E0, A00, A10, mass0, fz = model
    bshape = np.broadcast_shapes(eff.batch_shape, np.shape(mass0))

    def p(cause: str, param: str, nominal: float | None = None) -> np.ndarray:
        return np.broadcast_to(np.asarray(eff.value(cause, param, nominal), dtype=float), bshape)

    E = np.broadcast_to(E0, bshape + (8, 8)).copy()
    A0 = np.broadcast_to(A00, bshape + (8, 8)).copy()
    A1 = np.broadcast_to(A10, bshape + (8, 8)).copy()
    Bv = vehicle.B

    # nominal relaxation lengths from a77 = -vx/sigma_f, a88 = -vx/sigma_r
    sigma0 = -1.0 / np.stack([A1[..., FYF, FYF], A1[..., FYR, FYR]], axis=-1)

    m = p("payload", "mass_kg")
    hp = PAYLOAD_HEIGHT
    E[..., 2, 2] += m
    E[..., 2, 4] += m * hp
    E[..., 4, 2] += m * hp
    E[..., 4, 4] += m * hp**2
    A1[..., 2, 3] += -m
    A0[..., 4, 0] += m * hp * G
    A1[..., 4, 3] += -m * hp

    A0[..., 5, 5] = -p("steer_damping", "damping_nms", -A0[..., DELTA_DOT, DELTA_DOT])

    # tire rows: F_lin,k = (sigma0_k / vx) * sum_{j != k} a_kj(vx) x_j, scaled by the stiffness factors
    scale = np.stack([p("tire_stiffness", "front_scale"), p("tire_stiffness", "rear_scale")], axis=-1)
    tire0 = A0[..., 6:8, :].copy()
    tire1 = A1[..., 6:8, :].copy()
    for k, col in enumerate((FYF, FYR)):
        tire0[..., k, col] = 0.0
        tire1[..., k, col] = 0.0
    tire0 *= (scale * sigma0)[..., None]
    tire1 *= (scale * sigma0)[..., None]

    total_mass = mass0 + m
    bank = p("road_bank", "bank_rad")
    const = np.zeros(bshape + (8,))
    const[..., 2] = -total_mass * G * np.sin(bank)
    const[..., 4] = p("roll_moment_offset", "moment_nm")

    # mechanical rows 0..5 solved through E; gravity/trail columns go to the sine features
    grav = A0[..., :, 0:2].copy()  # (.., 8, 2): only rows 4, 5 are non-zero among rows 0..5
    A0m = A0.copy()
    A0m[..., 4:6, 0:2] = 0.0
    grav[..., [0, 1, 2, 3, 6, 7], :] = 0.0
    Einv = np.linalg.inv(E)

    W = np.zeros(bshape + (8, NZ))
    W[..., 0:6, _ZX : _ZX + 8] = (Einv @ A0m)[..., 0:6, :]
    W[..., 0:6, _ZVX : _ZVX + 8] = (Einv @ A1)[..., 0:6, :]
    W[..., 0:6, _ZS1 : _ZS1 + 2] = (Einv @ grav)[..., 0:6, :]
    W[..., 0:6, _ZTAU] = (Einv @ Bv)[..., 0:6]
    W[..., 0:6, _ZONE] = np.einsum("...ij,...j->...i", Einv, const)[..., 0:6]
    W[..., 0:6, _ZDIST] = Einv[..., 0:6, 4]  # external roll moment enters row 5 like the offset
    # the tire columns of rows 0..5 (forces acting on the body) stay in W[.., 0:6, _ZX+6:_ZX+8] above
    W[..., 6:8, _ZIV : _ZIV + 8] = tire0
    W[..., 6:8, _ZX : _ZX + 8] = tire1

    if eff.has("relaxation_length"):
        inv_sigma = 1.0 / p("relaxation_length", "sigma_m")[..., None] * np.ones(2)
    else:
        inv_sigma = np.broadcast_to(1.0 / sigma0, bshape + (2,))
    fz = np.broadcast_to(fz, bshape + (2,))
    fmax = p("tire_saturation", "mu_peak")[..., None] * fz
    W.setflags(write=False)
    return Plant(
        vehicle=vehicle,
        effects=eff,
        W=W,
        inv_sigma=np.array(inv_sigma),
        fmax=np.array(fmax),
        bank=np.array(bank),
        mass=np.array(total_mass),
        Einv=Einv,
        fz=np.array(fz),
    )


#: Rows of model.md (1-based) that take a generalised force: lateral (3), yaw (4), roll (5), steer (6).
FORCE_ROWS = {"lateral": 3, "yaw": 4, "roll": 5, "steer": 6}


def add_generalised_forces(plant: Plant, forces: list[tuple[str, str, np.ndarray | float]]) -> Plant:
    """The plant with extra generalised forces: ``E x' = ... + sum_k c_k phi_k(x, vx) e_row(k)``.

    Each force is ``(equation, feature, coefficient)``: ``equation`` one of :data:`FORCE_ROWS`
    (``steer`` adds a torque about the steering axis [N m], ``roll`` a roll moment [N m], ``yaw`` a
    yaw moment [N m], ``lateral`` a lateral force [N]), ``feature`` one of :data:`FORCE_FEATURES`,
    the coefficient a number or an array (one plant per element; a batch). This is how a model
    extension of the diagnosis (closure terms, ``assist.diagnose``) enters the one right-hand side:
    the force goes through the plant's own ``E^-1`` like every other term, and the tire rows are
    untouched.
    """
    extra = [(FORCE_ROWS[eq], FORCE_FEATURES[feat], np.asarray(c, dtype=float)) for eq, feat, c in forces]
    shapes = [plant.batch_shape] + [c.shape for _, _, c in extra]
    bshape = np.broadcast_shapes(*shapes)
    W = np.array(np.broadcast_to(plant.W, bshape + (8, NZ)))
    Einv = np.broadcast_to(plant.Einv, bshape + (8, 8))
    for row, col, c in extra:
        W[..., 0:6, col] += Einv[..., 0:6, row - 1] * np.broadcast_to(c, bshape)[..., None]
    W.setflags(write=False)
    return dataclasses.replace(plant, W=W, Einv=np.array(Einv))


def rhs(x: np.ndarray, tau, vx, vehicle: Vehicle | None = None, effects=None) -> np.ndarray:
    """Convenience: ``x'`` of the nonlinear plant (compiles the plant each call; use
    :func:`compile_plant` and :meth:`Plant.rhs` in loops)."""
    return compile_plant(vehicle, effects).rhs(x, tau, vx)


def linearise(plant: Plant | Vehicle | None, vx: float, x: np.ndarray | None = None, tau: float = 0.0,
              eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians ``(A, B)`` of ``x' = f(x, tau, vx)`` at ``(x, tau)`` by central differences.

    For the nominal plant at ``x = 0`` this is ``(E^-1 A(vx), E^-1 B)`` of
    model.md up to rounding (the sines have unit slope at 0); a test checks it.
    A batched plant gives one pair per plant: ``A`` of shape ``(*batch, 8, 8)``, ``B`` ``(*batch, 8, 1)``.
    """
    plant = compile_plant(plant) if not isinstance(plant, Plant) else plant
    bshape = plant.batch_shape
    x0 = np.zeros(bshape + (8,)) if x is None else np.array(np.broadcast_to(np.asarray(x, dtype=float), bshape + (8,)))
    n = 8
    A = np.empty(bshape + (n, n))
    for j in range(n):
        h = eps * np.maximum(1.0, np.abs(x0[..., j]))
        xp = x0.copy(); xp[..., j] += h
        xm = x0.copy(); xm[..., j] -= h
        A[..., :, j] = (plant.rhs(xp, tau, vx) - plant.rhs(xm, tau, vx)) / (2 * h)[..., None]
    Bm = ((plant.rhs(x0, tau + 1.0, vx) - plant.rhs(x0, tau - 1.0, vx)) / 2.0)[..., None]
    return A, Bm


__all__ = ["Plant", "compile_plant", "rhs", "linearise", "add_generalised_forces", "FORCE_FEATURES", "FORCE_ROWS"]
