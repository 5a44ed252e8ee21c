"""A vehicle from physical parameters: Sharp's (1971) four-degree-of-freedom formulas.

:func:`sharp_vehicle` turns a :class:`SharpParameters` set (masses, geometry,
inertias, tyre data) into the same :class:`~ptw_env.vehicle.Vehicle` object as
the reference scooter: ``E``, ``A0``, ``A1``, ``B`` of
``E x' = (A0 + vx A1) x + B tau`` (``shared/spec/model.md``) and the derived
:class:`~ptw_env.vehicle.TireParameters`. It writes matrix entries only; the
one nonlinear right-hand side stays in :mod:`ptw_env.dynamics` /
:mod:`ptw_env.kernels`, so the simulator, the environment, the modal analysis,
the observers, the controller design and the diagnosis take the result
unchanged.

Axes, states and sign conventions
---------------------------------
Sharp's axes are SAE: x forward, y to the right, z down, origin ``O`` on the
ground directly below the rear-frame mass centre. The states are those of
model.md, ``x = [phi, delta, vy, r, phi_dot, delta_dot, Fyf, Fyr]``: roll
(positive leaning to +y), steer (positive turning the front wheel to +y),
the lateral velocity of ``O``, the yaw rate, and the two lateral tyre
forces. ``Z_f`` is the vertical ground force on the front tyre in these axes,
so it is *negative* (the ground pushes up); the reference scooter shows it:
its ``a52 = 164.34`` exceeds ``M_f e g = 1.83``, which ``a52 = M_f e g - eta
Z_f`` allows only with ``Z_f < 0``.

The formulas (Fouka, Nehaoua, Arioui, Table V; Sharp 1971)
----------------------------------------------------------
Units: kg, m, rad, kg m^2, N/rad, N, N m s/rad; ``g = 9.81 m/s^2``
(:data:`ptw_env.vehicle.G`); ``s = sin(eps)``, ``c = cos(eps)``; ``M = M_f +
M_r``. ``E`` is the identity except the symmetric block on rows/columns 3-6::

    e33 = M             e34 = M_f k                 e35 = M_f j + M_r h        e36 = M_f e
    e44 = M_f k^2 + I_rz + I_fx s^2 + I_fz c^2
    e45 = M_f j k - C_rxz + (I_fz - I_fx) s c       e46 = M_f e k + I_fz c
    e55 = M_f j^2 + M_r h^2 + I_rx + I_fx c^2 + I_fz s^2
    e56 = M_f e j + I_fz s                          e66 = I_fz + M_f e^2

``A(vx) = A0 + vx A1`` (a term written ``(..) vx`` goes to ``A1``)::

    a15 = 1   a26 = 1
    a34 = -M vx                 a37 = 1           a38 = 1
    a44 = -M_f k vx             a45 = (i_fy/R_f + i_ry/R_r) vx
    a46 = (i_fy/R_f) s vx       a47 = l_f         a48 = -l_r
    a51 = (M_f j + M_r h) g     a52 = M_f e g - eta Z_f
    a54 = -(M_f j + M_r h + i_fy/R_f + i_ry/R_r) vx      a56 = -(i_fy/R_f) c vx
    a61 = M_f e g - eta Z_f     a62 = (M_f e g - eta Z_f) s
    a64 = -(M_f e + (i_fy/R_f) s) vx    a65 = (i_fy/R_f) c vx    a66 = -K    a67 = -eta
    a71 = (C_f2/sigma_f) vx     a72 = ((C_f1 c + C_f2 s)/sigma_f) vx
    a73 = -C_f1/sigma_f         a74 = -C_f1 l_f/sigma_f   a76 = C_f1 eta/sigma_f   a77 = -vx/sigma_f
    a81 = (C_r2/sigma_r) vx     a83 = -C_r1/sigma_r       a84 = C_r1 l_r/sigma_r   a88 = -vx/sigma_r

and ``B = e6`` (the rider's torque enters the steering equation, [1]_ eq. 1).
Rows 7-8 are model.md's relaxation rows ``(sigma_k/vx) F_k' = -F_k - C_k1
alpha_k + C_k2 gamma_k`` with ``alpha_f = (vy + l_f r - eta delta_dot)/vx -
delta c``, ``gamma_f = phi + delta s``, ``alpha_r = (vy - l_r r)/vx``,
``gamma_r = phi`` ([1]_ eqs. 3-5, Sharp 1971).

Each entry was checked against the physics of Sharp's model (a derivation in
the SAE axes above, not only the transcription):

* the mass block is the kinetic energy of the two frames: the front mass
  centre moves laterally by ``vy + k r + j phi_dot + e delta_dot``, the rear
  one by ``vy + h phi_dot``, and the front frame's principal axes are the
  steering axis and its normal, which gives the ``s``, ``c`` terms;
* the gyroscopic terms of the spinning wheels are skew-symmetric between
  rows: ``a45 = +(i_fy/R_f + i_ry/R_r) vx`` against the ``-(..)vx`` in
  ``a54``, ``a46 = +(i_fy/R_f) s vx`` against ``-(i_fy/R_f) s vx`` in
  ``a64``, ``a56 = -(i_fy/R_f) c vx`` against ``a65 = +(i_fy/R_f) c vx``;
* the gravity and ground-force terms are the stiffness of one potential,
  so ``a52 = a61``;
* ``eta`` is the trail *measured normal to the steering axis* (Sharp's
  ``a_n``): the lateral tyre force acts on the steering axis with that arm
  (``a67``), a steer rate moves the contact point sideways at ``eta
  delta_dot`` (``a76``), and the front load and the front mass offset make the
  steer-roll stiffness ``M_f e g - eta Z_f`` (Whipple/benchmark bicycle:
  ``K0_{delta phi} = m_A u_A + mu m_T x_T`` with ``mu = c cos(lambda)/w``).

Corrections to the printed Table V (and why)
--------------------------------------------
* ``a81`` is printed ``C_r2/g_r vx``: ``g_r`` is a garbled ``sigma_r`` (the
  rear relaxation row, as ``a83``, ``a84``, ``a88``; the front twin ``a71`` reads
  ``C_f2/sigma_f vx``).
* ``e56`` is printed ``M_f e_j``: it is ``M_f e j`` (kinetic-energy cross term
  of ``j phi_dot`` and ``e delta_dot``).
* The printed ``E`` (nine columns, ``e45`` in row 3), ``A`` (thirteen rows)
  and ``B`` (the 1 in row 5 of 7) are garbled by the extraction; the layout
  used is eq. (1) of [1]_ and model.md: symmetric ``E``, torque in row 6.
* Table VI lists ``I_f``, ``I_r``; the formulas need the four moments
  ``I_fx``, ``I_fz``, ``I_rx``, ``I_rz`` and the product ``C_rxz`` (front frame
  about its steering-parallel principal axis and its normal, rear frame about
  horizontal/vertical axes, both through their mass centres).
* ``eta`` is Sharp's normal trail (above); a file may give the ground trail
  instead (:mod:`ptw_env.sharp_geometry`, ``eta = trail cos(eps)``).

Three findings that bear on the reference scooter: Table V *confirms*
model.md's resolutions of ``a71`` (``+C_f2/sigma_f vx``, positive) and ``a84``
(``C_r1 l_r/sigma_r``, no ``vx`` factor); and Table IV's printed ``a45 = -3.665
vx`` has the magnitude of Table V's formula (``a54 + e35 vx`` gives ``-3.668
vx``) but the sign the gyroscopic skew-symmetry forbids. This project reported
it first; model.md now resolves it as ``+3.665 vx`` (its third resolved entry),
so the reference scooter and the formula agree in every sign.

Derived tyre data (:class:`~ptw_env.vehicle.TireParameters`)
------------------------------------------------------------
``sigma_f, sigma_r``; ``C_alpha_f0 = C_f1``, ``C_gamma_f0 = C_f2``,
``C_alpha_r0 = C_r1``, ``C_gamma_r0 = C_r2``; ``caster = eps``; ``trail = eta``
(``= -a67``); slip arms ``lf_slip = l_f``, ``lr_slip = l_r`` (the arms of the
point ``O`` whose lateral velocity is ``vy``; ``= a74/a73``, ``-a84/a83``);
static loads from the statics of the two mass centres,
``Fzf = g (M_r l_r + M_f (l_r + k))/(l_f + l_r)``, ``Fzr = M g - Fzf``. In a
steady turn rows 3-4 share the lateral force between the axles in exactly
this ratio (``Fyf/(Fyf + Fyr) = (l_r + M_f k/M)/(l_f + l_r)``), so both
axles reach their friction limit together, as for the reference scooter.
``Z_f`` must agree with ``-Fzf`` to :data:`LOAD_TOLERANCE` (Sharp's standard
machine: 0.7 %); a larger gap means a sign or unit slip or inconsistent
geometry.

References
----------
.. [1] M. Fouka, L. Nehaoua, H. Arioui, "Motorcycle state estimation and tire
   cornering stiffness identification applied to road safety: using observer
   based identifiers", Table V (``shared/papers/000_348caefc9b08ee38.txt``).
.. [2] R. S. Sharp, "The stability and control of motorcycles", J. Mech. Eng.
   Sci. 13(5), 316-329, 1971.

Examples
--------
>>> from ptw_env.vehicle_files import load_vehicle
>>> v = load_vehicle("sharp1971")
>>> round(v.mass, 2), round(float(v.E[2, 3]), 3)   # M = M_f + M_r, e34 = M_f k
(248.1, 26.96)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from types import SimpleNamespace
from typing import Any, Mapping

import numpy as np

from .vehicle import G, TireParameters, Vehicle

#: Largest accepted relative gap between ``-Z_f`` and the static front load of the geometry.
LOAD_TOLERANCE = 0.05


def static_front_load(M_f: float, M_r: float, k: float, l_f: float, l_r: float, g: float = G) -> float:
    """Static vertical load on the front wheel [N]: ``g (M_r l_r + M_f (l_r + k))/(l_f + l_r)``.

    Moments about the rear contact point of the two frames' weights; ``k``,
    ``l_f``, ``l_r`` as in :data:`SPECS` [m], masses [kg], ``g`` [m/s^2].

    >>> round(static_front_load(30.65, 217.45, 0.8796, 0.9347, 0.4798), 1)
    1012.5
    """
    return g * (M_r * l_r + M_f * (l_r + k)) / (l_f + l_r)


#: row and column indices of the strict upper triangle of an 8 x 8 matrix (E is filled there, then mirrored)
_UPPER = np.triu_indices(8, 1)


def table_v(p: Any, g: float = G) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(E, A0, A1, B)`` of Table V (module docstring; Fouka et al. Table V, Sharp 1971) for ``p``: any object
    with the attributes of :data:`SPECS` (SI units), each a number or an array; arrays of one shape give a
    batch of vehicles, ``E`` of shape ``(*batch, 8, 8)`` (how domain randomisation draws whole vehicles,
    :func:`parameter_batch`). The one copy of the formulas: :meth:`SharpParameters.matrices` calls it.
    """
    v = {n: getattr(p, n) for n in SPECS}  # numbers and arrays broadcast in the formulas
    shape = np.broadcast_shapes(*(np.shape(x) for x in v.values()))
    s, c = np.sin(v["eps"]), np.cos(v["eps"])
    Mf, Mr, j, h, k, e, eta = (v[n] for n in ("M_f", "M_r", "j", "h", "k", "e", "eta"))
    Ifx, Ifz = v["I_fx"], v["I_fz"]
    E = np.zeros(shape + (8, 8))
    E[..., range(8), range(8)] = 1.0
    E[..., 2, 2], E[..., 2, 3], E[..., 2, 4], E[..., 2, 5] = Mf + Mr, Mf * k, Mf * j + Mr * h, Mf * e
    E[..., 3, 3] = Mf * k**2 + v["I_rz"] + Ifx * s**2 + Ifz * c**2
    E[..., 3, 4] = Mf * j * k - v["C_rxz"] + (Ifz - Ifx) * s * c
    E[..., 3, 5] = Mf * e * k + Ifz * c
    E[..., 4, 4] = Mf * j**2 + Mr * h**2 + v["I_rx"] + Ifx * c**2 + Ifz * s**2
    E[..., 4, 5] = Mf * e * j + Ifz * s
    E[..., 5, 5] = Ifz + Mf * e**2
    E[..., _UPPER[1], _UPPER[0]] = E[..., _UPPER[0], _UPPER[1]]
    gf, gr = v["i_fy"] / v["R_f"], v["i_ry"] / v["R_r"]  # wheel spin momentum per unit speed [kg m]
    mh = Mf * j + Mr * h
    stiff = Mf * e * g - eta * v["Z_f"]  # a52 = a61 [N m/rad]
    A0, A1 = np.zeros(shape + (8, 8)), np.zeros(shape + (8, 8))
    A0[..., 0, 4] = A0[..., 1, 5] = 1.0
    A1[..., 2, 3] = -(Mf + Mr)
    A0[..., 2, 6] = A0[..., 2, 7] = 1.0
    A1[..., 3, 3], A1[..., 3, 4], A1[..., 3, 5] = -Mf * k, gf + gr, gf * s
    A0[..., 3, 6], A0[..., 3, 7] = v["l_f"], -v["l_r"]
    A0[..., 4, 0], A0[..., 4, 1] = mh * g, stiff
    A1[..., 4, 3], A1[..., 4, 5] = -(mh + gf + gr), -gf * c
    A0[..., 5, 0], A0[..., 5, 1] = stiff, stiff * s
    A1[..., 5, 3], A1[..., 5, 4] = -(Mf * e + gf * s), gf * c
    A0[..., 5, 5], A0[..., 5, 6] = -v["K"], -eta
    sf, sr = v["sigma_f"], v["sigma_r"]
    Cf1, Cf2, Cr1, Cr2 = v["C_f1"], v["C_f2"], v["C_r1"], v["C_r2"]
    A1[..., 6, 0], A1[..., 6, 1] = Cf2 / sf, (Cf1 * c + Cf2 * s) / sf
    A0[..., 6, 2], A0[..., 6, 3] = -Cf1 / sf, -Cf1 * v["l_f"] / sf
    A0[..., 6, 5] = Cf1 * eta / sf
    A1[..., 6, 6] = -1.0 / sf
    A1[..., 7, 0] = Cr2 / sr
    A0[..., 7, 2], A0[..., 7, 3] = -Cr1 / sr, Cr1 * v["l_r"] / sr
    A1[..., 7, 7] = -1.0 / sr
    B = np.zeros(8)
    B[5] = 1.0
    return E, A0, A1, B


class SharpParameterError(ValueError):
    """A parameter set that cannot describe a motorcycle; the message names the parameter."""


@dataclass(frozen=True)
class ParameterSpec:
    """Unit, admissible sign and meaning of one physical parameter.

    ``rule`` is one of ``"positive"`` (> 0), ``"nonnegative"`` (>= 0),
    ``"negative"`` (< 0), ``"any"`` (finite) or ``"angle"`` (caster: ``0 <= x <
    pi/2`` rad).
    """

    unit: str
    rule: str
    meaning: str


#: Table V's variables: unit, sign rule, meaning (SAE axes; all about the frame's own mass centre).
SPECS: dict[str, ParameterSpec] = {
    "M_f": ParameterSpec("kg", "positive", "mass of the front frame (wheel, forks, handlebars)"),
    "M_r": ParameterSpec("kg", "positive", "mass of the rear frame with the rider rigidly attached"),
    "j": ParameterSpec("m", "positive", "height of the front-frame mass centre above the ground"),
    "h": ParameterSpec("m", "positive", "height of the rear-frame mass centre above the ground"),
    "k": ParameterSpec("m", "any", "front-frame mass centre ahead of the rear-frame mass centre"),
    "e": ParameterSpec("m", "any", "front-frame mass centre ahead of the steering axis, normal to it"),
    "l_f": ParameterSpec("m", "positive", "front contact point ahead of O (below the rear-frame mass centre)"),
    "l_r": ParameterSpec("m", "positive", "rear contact point behind O"),
    "i_fy": ParameterSpec("kg m^2", "positive", "spin (polar) moment of inertia of the front wheel"),
    "i_ry": ParameterSpec("kg m^2", "positive", "spin (polar) moment of inertia of the rear wheel"),
    "R_f": ParameterSpec("m", "positive", "front wheel rolling radius"),
    "R_r": ParameterSpec("m", "positive", "rear wheel rolling radius"),
    "eps": ParameterSpec("rad", "angle", "caster angle of the steering axis from the vertical"),
    "eta": ParameterSpec("m", "any", "mechanical trail measured normal to the steering axis (Sharp's a_n)"),
    "K": ParameterSpec("N m s/rad", "nonnegative", "steering damper coefficient"),
    "I_fx": ParameterSpec("kg m^2", "nonnegative", "front frame about its mass centre, axis normal to the steering axis"),
    "I_fz": ParameterSpec("kg m^2", "positive", "front frame about its mass centre, axis parallel to the steering axis"),
    "I_rx": ParameterSpec("kg m^2", "positive", "rear frame roll moment of inertia about its mass centre"),
    "I_rz": ParameterSpec("kg m^2", "positive", "rear frame yaw moment of inertia about its mass centre"),
    "C_rxz": ParameterSpec("kg m^2", "any", "rear frame product of inertia (SAE, enters e45 as -C_rxz)"),
    "Z_f": ParameterSpec("N", "negative", "vertical ground force on the front tyre (SAE: negative)"),
    "sigma_f": ParameterSpec("m", "positive", "front tyre relaxation length"),
    "sigma_r": ParameterSpec("m", "positive", "rear tyre relaxation length"),
    "C_f1": ParameterSpec("N/rad", "positive", "front tyre cornering (side-slip) stiffness"),
    "C_f2": ParameterSpec("N/rad", "nonnegative", "front tyre camber stiffness"),
    "C_r1": ParameterSpec("N/rad", "positive", "rear tyre cornering (side-slip) stiffness"),
    "C_r2": ParameterSpec("N/rad", "nonnegative", "rear tyre camber stiffness"),
}


def rule_violation(value: float, rule: str) -> str | None:
    """Why ``value`` breaks ``rule`` (:class:`ParameterSpec`), or ``None`` if it does not."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"must be a finite number, got {value!r}"
    if rule == "positive" and not value > 0:
        return f"must be > 0, got {value:g}"
    if rule == "nonnegative" and not value >= 0:
        return f"must be >= 0, got {value:g}"
    if rule == "negative" and not value < 0:
        return f"must be < 0, got {value:g}"
    if rule == "angle" and not 0 <= value < math.pi / 2:
        hint = f" (it looks like degrees: {value:g} deg = {math.radians(value):.4g} rad)" if 1.0 < value < 90.0 else ""
        return f"must be an angle in radians in [0, pi/2), got {value:g}{hint}"
    return None


def _load_violation(p: Any, Fzf: Any, Fzr: Any) -> str | None:
    """Why the static loads ``Fzf``, ``Fzr`` [N] (numbers, or arrays of one shape: one per vehicle) are
    impossible, or None: each wheel must carry a positive load."""
    Fzf, Fzr = np.ravel(Fzf), np.ravel(Fzr)
    bad = np.flatnonzero((Fzf <= 0) | (Fzr <= 0))
    if not bad.size:
        return None
    i = bad[0]
    k, lf, lr = (float(np.ravel(np.broadcast_to(getattr(p, n), np.shape(Fzf)))[i]) for n in ("k", "l_f", "l_r"))
    front, rear = float(Fzf[i]), float(Fzr[i])
    return (f"the mass centres put {front:.1f} N on the front wheel and {rear:.1f} N on the rear (k = {k:g} m, "
            f"l_f = {lf:g} m, l_r = {lr:g} m): the combined mass centre must lie between the contact points")


def _inertia_violation(E: np.ndarray) -> str | None:
    """Why the mass matrix ``E`` (shape ``(*batch, 8, 8)``) is not positive definite, or None."""
    lam = np.linalg.eigvalsh(E[..., 2:6, 2:6])[..., 0]
    if np.all(lam > 0):
        return None
    return ("the mass matrix E of these masses and inertias is not positive definite: check I_fx, I_fz, "
            "I_rx, I_rz, C_rxz (a product of inertia too large for the moments?)")


def parameter_batch(params: "SharpParameters", values: Mapping[str, Any],
                    g: float = G) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Table V's model of ``params`` with ``values`` (parameter name -> number or array, one shape) in place of
    its own: ``(E, A0, A1, mass, loads)`` with ``E`` of shape ``(*batch, 8, 8)``, ``mass = M_f + M_r`` [kg] and
    ``loads = (Fzf, Fzr)`` [N] of shape ``(*batch, 2)`` (:func:`table_v`; :meth:`SharpParameters.static_loads`).
    A batch of vehicles of one layout, drawn by domain randomisation (``randomize={"vehicle:M_r": ...}``).

    ``Z_f`` is not a free parameter here: it follows the statics of each drawn geometry,
    ``Z_f' = Z_f Fzf'/Fzf`` (the file's own relative gap to the statics kept), so that moving a mass moves the
    front load (a52, a61) with it.

    Raises
    ------
    SharpParameterError
        A value that breaks its parameter's rule (:data:`SPECS`), a mass centre outside the wheelbase or a
        mass matrix that is not positive definite (as :class:`SharpParameters`), naming the first such draw.
    """
    if "Z_f" in values:
        raise SharpParameterError("Z_f follows the statics of the drawn geometry (Z_f' = Z_f Fzf'/Fzf): it is not "
                                  "drawn itself")
    base: dict[str, Any] = {n: getattr(params, n) for n in SPECS}
    for n, v in values.items():
        if n not in SPECS:
            raise SharpParameterError(f"unknown parameter {n!r}; parameters: {', '.join(SPECS)}")
        a = np.asarray(v, dtype=float)
        for end in (a.min(initial=np.inf), a.max(initial=-np.inf)) if a.size else ():
            why = rule_violation(float(end), SPECS[n].rule)  # a rule is an interval: both ends in it, all in it
            if why:
                raise SharpParameterError(f"{n} [{SPECS[n].unit}] ({SPECS[n].meaning}) {why}")
        base[n] = a
    p = SimpleNamespace(**base)
    Fzf = np.broadcast_to(static_front_load(p.M_f, p.M_r, p.k, p.l_f, p.l_r, g),
                          np.broadcast_shapes(*(np.shape(v) for v in values.values())))  # the rest are numbers
    mass = np.broadcast_to(p.M_f + p.M_r, Fzf.shape)
    Fzr = mass * g - Fzf  # as SharpParameters.static_loads
    why = _load_violation(p, Fzf, Fzr)
    if why:
        raise SharpParameterError(why)
    p.Z_f = params.Z_f * Fzf / params.static_loads(g)[0]
    E, A0, A1, _ = table_v(p, g)
    why = _inertia_violation(E)
    if why:
        raise SharpParameterError(why)
    return E, A0, A1, mass, np.stack([Fzf, Fzr], axis=-1)


@dataclass(frozen=True)
class SharpParameters:
    """The physical parameters of Table V (Sharp 1971), SI units, SAE axes (module docstring).

    Field names, units and meanings: :data:`SPECS`. ``Z_f`` is negative.

    Raises
    ------
    SharpParameterError
        A value that is not a finite number, breaks its sign rule, a front
        load ``-Z_f`` more than :data:`LOAD_TOLERANCE` away from the statics
        of the geometry, or an inertia set whose mass matrix is not positive
        definite.
    """

    M_f: float
    M_r: float
    j: float
    h: float
    k: float
    e: float
    l_f: float
    l_r: float
    i_fy: float
    i_ry: float
    R_f: float
    R_r: float
    eps: float
    eta: float
    K: float
    I_fx: float
    I_fz: float
    I_rx: float
    I_rz: float
    C_rxz: float
    Z_f: float
    sigma_f: float
    sigma_r: float
    C_f1: float
    C_f2: float
    C_r1: float
    C_r2: float

    def __post_init__(self) -> None:
        for f in fields(self):
            why = rule_violation(getattr(self, f.name), SPECS[f.name].rule)
            if why:
                raise SharpParameterError(f"{f.name} [{SPECS[f.name].unit}] ({SPECS[f.name].meaning}) {why}")
        Fzf, Fzr = self.static_loads()
        why = _load_violation(self, Fzf, Fzr)
        if why:
            raise SharpParameterError(why)
        gap = abs(-self.Z_f - Fzf) / Fzf
        if gap > LOAD_TOLERANCE:
            raise SharpParameterError(
                f"Z_f = {self.Z_f:g} N disagrees with the static front load of the geometry, {-Fzf:.1f} N, by "
                f"{100 * gap:.1f} % (more than {100 * LOAD_TOLERANCE:g} %): check the sign (SAE: negative), the "
                f"unit (N) and the mass-centre positions")
        why = _inertia_violation(self.mass_matrix())
        if why:
            raise SharpParameterError(why)

    @property
    def mass(self) -> float:
        """Total mass ``M = M_f + M_r`` [kg]."""
        return self.M_f + self.M_r

    def static_loads(self, g: float = G) -> tuple[float, float]:
        """Static vertical loads ``(Fzf, Fzr)`` [N] of the two wheels from the mass-centre positions.

        ``Fzf = g (M_r l_r + M_f (l_r + k))/(l_f + l_r)`` (moments about the
        rear contact point), ``Fzr = (M_f + M_r) g - Fzf``.
        """
        Fzf = static_front_load(self.M_f, self.M_r, self.k, self.l_f, self.l_r, g)
        return Fzf, self.mass * g - Fzf

    def mass_matrix(self) -> np.ndarray:
        """``E`` of the module docstring (8 x 8, symmetric, identity outside rows/columns 3-6)."""
        return table_v(self)[0]

    def matrices(self, g: float = G) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(E, A0, A1, B)`` of Table V (module docstring), ``A(vx) = A0 + vx A1``."""
        return table_v(self, g)

    def tire_parameters(self) -> TireParameters:
        """The derived :class:`~ptw_env.vehicle.TireParameters` (module docstring)."""
        Fzf, Fzr = self.static_loads()
        return TireParameters(
            sigma_f=self.sigma_f, sigma_r=self.sigma_r, C_alpha_f0=self.C_f1, C_gamma_f0=self.C_f2,
            C_alpha_r0=self.C_r1, C_gamma_r0=self.C_r2, caster=self.eps, trail=self.eta,
            lf_slip=self.l_f, lr_slip=self.l_r, Fzf=Fzf, Fzr=Fzr,
        )


def sharp_vehicle(
    params: SharpParameters,
    name: str,
    vmin: float,
    vmax: float,
    provenance: Mapping[str, str] | None = None,
    steer_lock: float = math.pi / 2,
    design_range: tuple[float, float] | None = None,
) -> Vehicle:
    """The :class:`~ptw_env.vehicle.Vehicle` of a Sharp (1971) parameter set (Table V formulas).

    Parameters
    ----------
    params : SharpParameters
    name : str
        Identifier used in logs, reports and figure titles.
    vmin, vmax : float
        Valid forward-speed range [m/s] (``0 < vmin < vmax``).
    provenance : mapping of str to str, optional
        Where the numbers come from (per parameter); the builder adds the formulas' source.

    Returns
    -------
    Vehicle
        ``E, A0, A1, B`` of the module docstring, ``mass = M_f + M_r``, the
        derived tyre data.

    Examples
    --------
    >>> from ptw_env.vehicle_files import load_parameters
    >>> p = load_parameters("sharp1971")
    >>> v = sharp_vehicle(p, "my-bike", vmin=3.0, vmax=50.0)
    >>> round(float(v.A0[3, 6]), 4) == round(p.l_f, 4)   # a47 = l_f
    True
    """
    if not isinstance(params, SharpParameters):
        raise SharpParameterError(f"params must be a SharpParameters, got {type(params).__name__}")
    E, A0, A1, B = params.matrices()
    prov = {"E, A0, A1, B": "Sharp (1971) formulas as in Fouka, Nehaoua, Arioui, Table V (ptw_env.sharp)"}
    prov.update(dict(provenance or {}))
    prov.setdefault("parameters", ", ".join(f"{k} = {v:.6g}" for k, v in asdict(params).items()))
    return Vehicle(name=name, E=E, A0=A0, A1=A1, B=B, mass=params.mass, tires=params.tire_parameters(),
                   vmin=float(vmin), vmax=float(vmax), provenance=prov, steer_lock=float(steer_lock),
                   design_range=design_range, parameters=params)


__all__ = ["LOAD_TOLERANCE", "ParameterSpec", "SPECS", "SharpParameterError", "SharpParameters", "parameter_batch",
           "rule_violation", "sharp_vehicle", "static_front_load", "table_v"]
