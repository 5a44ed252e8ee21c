"""Two ways to describe a motorcycle's geometry and mass, both mapped to Table V's variables.

Table V (:mod:`ptw_env.sharp`) needs the mass-centre positions ``j, h, k, e``,
the contact-point arms ``l_f, l_r`` and the normal trail ``eta``. Nobody
measures those directly; a parameter file gives one of two *layouts* and
:func:`sharp_parameters` converts it. SAE axes, SI units throughout; ``s =
sin(eps)``, ``c = cos(eps)``; ``O`` is the ground point below the rear-frame
mass centre (Sharp's origin).

Layout ``"sharp_frames"`` (Sharp 1971's own dimensions)
------------------------------------------------------
The two frames separately, positions measured in Sharp's rear-frame axes
(``Z2`` along the steering axis, pointing down; ``X2`` normal to it, pointing
forward and up):

* ``a``: distance from ``O`` to the steering axis, normal to the axis;
* ``b``: rear contact point behind ``O`` (``l_r = b``);
* ``h``: height of the rear-frame mass centre;
* ``e``, ``f``: front-frame mass centre ahead of the steering axis (normal to
  it) and below the foot of the normal from ``O`` (along the axis);
* ``trail_normal``: the trail normal to the steering axis, Sharp's ``a_n``.

Then (projection of ``(a + e) X2 + f Z2`` on the ground axes, and of the
front contact point on ``X2``)::

    j = (a + e) s - f c      k = (a + e) c + f s      l_f = (a - trail_normal)/c      eta = trail_normal

For Sharp's standard machine: ``j = 0.4167 m``, ``k = 0.8796 m``, ``l_f =
0.9347 m``, wheelbase ``l_f + b = 1.4145 m``; the statics of these positions
put ``1012.5 N`` on the front wheel, 0.7 % from Sharp's ``Z_f = -1005.3 N``.
Reading ``trail_normal`` as a ground trail instead (``l_f = a/c - t``) would
give 0.3 %, so the loads do not decide between the readings; the normal trail
is taken because ``a`` is a normal distance in the same axes and
``l_f = (a - a_n)/c`` is then exact geometry.

Layout ``"whole_vehicle"`` (what one measures on one's own bike)
---------------------------------------------------------------
The whole machine with its rider (scales, pendulum tests) plus the front
assembly, which a steering-axis swing test or a CAD model gives:

* ``wheelbase``, ``caster`` and either ``trail`` (along the ground, as in
  spec sheets) or ``trail_normal`` (normal to the steering axis, ``= trail
  c``; books such as Cossalter's give this one);
* ``M``, ``x_G`` (total mass centre ahead of the rear contact), ``h_G`` (its
  height), ``I_xx``, ``I_zz``, ``C_xz`` (about the total mass centre,
  horizontal/vertical axes; ``C_xz`` is the SAE product ``int x z dm``, z down);
* ``M_f``, ``j`` (front-frame mass-centre height), ``e`` (ahead of the
  steering axis, normal to it), ``I_fz`` (about its steering-parallel axis).

Then, with ``x_f = wheelbase + trail - j tan(eps) + e/c`` the front-frame
mass centre ahead of the rear contact::

    M_r = M - M_f     x_r = (M x_G - M_f x_f)/M_r     h = (M h_G - M_f j)/M_r
    l_r = x_r         l_f = wheelbase - x_r           k = x_f - x_r          eta = trail c

and the rear frame (which here carries the front frame's transverse inertia,
``I_fx = 0``) is what is left of the whole after the front frame, by the
parallel-axis theorem about ``O`` (``d = x_G - x_r``)::

    I_rx  = I_xx + M h_G^2 - M_f j^2 - M_r h^2 - I_fz s^2
    I_rz  = I_zz + M d^2 - M_f k^2 - I_fz c^2
    C_rxz = C_xz - M d h_G + M_f j k + I_fz s c

Folding ``I_fx`` into the rear frame is exact: in Table V ``I_fx`` appears
only in ``e44``, ``e45``, ``e55``, each time summed with ``I_rz``, ``C_rxz``,
``I_rx``, and these three entries are the whole vehicle's yaw and roll
inertias and product about ``O``, which the data above fix. (A test builds
Sharp's machine both ways and compares the matrices.)

Both layouts take the wheel, steering and tyre data of :data:`COMMON_KEYS`;
``Z_f`` is optional and defaults to ``-Fzf`` of the statics
(:func:`ptw_env.sharp.static_front_load`).

Examples
--------
>>> from ptw_env.vehicle_files import load_parameters
>>> p = load_parameters("sharp1971")
>>> round(p.j, 4), round(p.k, 4), round(p.l_f, 4)
(0.4167, 0.8796, 0.9347)
"""

from __future__ import annotations

import math
from typing import Callable, Mapping

from .sharp import SPECS, ParameterSpec, SharpParameterError, SharpParameters, static_front_load

#: Layout-only keys (not Table V variables): unit, sign rule, meaning.
LAYOUT_SPECS: dict[str, ParameterSpec] = {
    "a": ParameterSpec("m", "positive", "distance from O to the steering axis, normal to the axis (Sharp)"),
    "b": ParameterSpec("m", "positive", "rear contact point behind O, the ground point below the rear-frame mass centre"),
    "f": ParameterSpec("m", "any", "front-frame mass centre below the foot of the normal from O, along the steering axis"),
    "trail_normal": ParameterSpec("m", "any", "mechanical trail measured normal to the steering axis (Sharp's a_n)"),
    "caster": ParameterSpec("rad", "angle", "caster angle of the steering axis from the vertical"),
    "wheelbase": ParameterSpec("m", "positive", "distance between the contact points"),
    "trail": ParameterSpec("m", "any", "mechanical trail along the ground (spec-sheet trail)"),
    "M": ParameterSpec("kg", "positive", "total mass with the rider"),
    "x_G": ParameterSpec("m", "positive", "total mass centre ahead of the rear contact point"),
    "h_G": ParameterSpec("m", "positive", "height of the total mass centre"),
    "I_xx": ParameterSpec("kg m^2", "positive", "total roll moment of inertia about the total mass centre"),
    "I_zz": ParameterSpec("kg m^2", "positive", "total yaw moment of inertia about the total mass centre"),
    "C_xz": ParameterSpec("kg m^2", "any", "total product of inertia about the total mass centre (SAE: int x z dm, z down)"),
}

#: Keys every layout takes: wheels, steering damper, tyres (``Z_f`` optional).
COMMON_KEYS: tuple[str, ...] = ("R_f", "R_r", "i_fy", "i_ry", "K", "C_f1", "C_f2", "C_r1", "C_r2", "sigma_f", "sigma_r")
OPTIONAL_KEYS: tuple[str, ...] = ("Z_f",)


def spec(key: str) -> ParameterSpec:
    """Unit, rule and meaning of a parameter-file key (Table V variable or layout key)."""
    return LAYOUT_SPECS[key] if key in LAYOUT_SPECS else SPECS[key]


def _finish(v: Mapping[str, float], **geo: float) -> SharpParameters:
    """SharpParameters from the common keys ``v`` and the layout's Table V variables ``geo``."""
    common = {k: float(v[k]) for k in COMMON_KEYS}
    if "Z_f" in v:
        z_f = float(v["Z_f"])
    else:
        z_f = -static_front_load(geo["M_f"], geo["M_r"], geo["k"], geo["l_f"], geo["l_r"])
    return SharpParameters(**common, **geo, Z_f=z_f)


def from_sharp_frames(v: Mapping[str, float]) -> SharpParameters:
    """Layout ``"sharp_frames"`` (module docstring) to :class:`~ptw_env.sharp.SharpParameters`.

    ``v`` holds :data:`LAYOUTS` ``["sharp_frames"]`` keys in SI units.
    """
    eps = float(v["caster"])
    s, c = math.sin(eps), math.cos(eps)
    a, e, f, an = (float(v[k]) for k in ("a", "e", "f", "trail_normal"))
    return _finish(
        v, M_f=float(v["M_f"]), M_r=float(v["M_r"]), j=(a + e) * s - f * c, h=float(v["h"]), k=(a + e) * c + f * s,
        e=e, l_f=(a - an) / c, l_r=float(v["b"]), eps=eps, eta=an,
        **{k: float(v[k]) for k in ("I_fx", "I_fz", "I_rx", "I_rz", "C_rxz")},
    )


def from_whole_vehicle(v: Mapping[str, float]) -> SharpParameters:
    """Layout ``"whole_vehicle"`` (module docstring) to :class:`~ptw_env.sharp.SharpParameters`.

    Raises
    ------
    SharpParameterError
        If the front assembly does not fit inside the whole vehicle (its mass,
        the rear frame's mass-centre position, or the remaining inertias).
    """
    eps = float(v["caster"])
    s, c = math.sin(eps), math.cos(eps)
    w, M, xG, hG = (float(v[k]) for k in ("wheelbase", "M", "x_G", "h_G"))
    t = float(v["trail"]) if "trail" in v else float(v["trail_normal"]) / c
    Mf, j, e, Ifz = (float(v[k]) for k in ("M_f", "j", "e", "I_fz"))
    if not Mf < M:
        raise SharpParameterError(f"M_f = {Mf:g} kg must be less than the total mass M = {M:g} kg")
    if not 0 < xG < w:
        raise SharpParameterError(f"x_G = {xG:g} m must lie between the contact points (0 < x_G < wheelbase = {w:g} m)")
    Mr = M - Mf
    xf = w + t - j * math.tan(eps) + e / c
    xr = (M * xG - Mf * xf) / Mr
    h = (M * hG - Mf * j) / Mr
    if not (0 < xr < w and h > 0):
        raise SharpParameterError(
            f"the rear frame (whole vehicle minus front frame) has its mass centre at x = {xr:.4g} m, height "
            f"{h:.4g} m: outside the wheelbase or below ground; check M, x_G, h_G, M_f, j, e")
    d, k = xG - xr, xf - xr
    Irx = float(v["I_xx"]) + M * hG**2 - Mf * j**2 - Mr * h**2 - Ifz * s**2
    Irz = float(v["I_zz"]) + M * d**2 - Mf * k**2 - Ifz * c**2
    for name, val, whole in (("roll", Irx, "I_xx"), ("yaw", Irz, "I_zz")):
        if not val > 0:
            raise SharpParameterError(
                f"the front frame (M_f, j, e, I_fz) carries more {name} inertia than the whole vehicle ({whole}): "
                f"the rear frame would have {val:.4g} kg m^2")
    Crxz = float(v["C_xz"]) - M * d * hG + Mf * j * k + Ifz * s * c
    return _finish(v, M_f=Mf, M_r=Mr, j=j, h=h, k=k, e=e, l_f=w - xr, l_r=xr, eps=eps, eta=t * c,
                   I_fx=0.0, I_fz=Ifz, I_rx=Irx, I_rz=Irz, C_rxz=Crxz)


#: layout name -> (its own required keys, groups of alternatives of which exactly one is given, converter);
#: every layout also takes COMMON_KEYS and OPTIONAL_KEYS.
LAYOUTS: dict[str, tuple[tuple[str, ...], tuple[tuple[str, ...], ...],
                         Callable[[Mapping[str, float]], SharpParameters]]] = {
    "sharp_frames": (("M_f", "M_r", "a", "b", "e", "f", "h", "trail_normal", "caster",
                      "I_fx", "I_fz", "I_rx", "I_rz", "C_rxz"), (), from_sharp_frames),
    "whole_vehicle": (("wheelbase", "caster", "M", "x_G", "h_G", "I_xx", "I_zz", "C_xz", "M_f", "j", "e", "I_fz"),
                      (("trail", "trail_normal"),), from_whole_vehicle),
}


def layout_problems(layout: str, keys: set[str]) -> tuple[list[str], list[str]]:
    """``(missing, conflicting)``: keys ``layout`` needs but ``keys`` lacks, and keys it cannot take.

    Alternatives (``trail`` / ``trail_normal``) count as missing when neither
    is given (reported as ``"trail or trail_normal"``) and conflicting when
    both are. Keys that no layout knows are not reported here.
    """
    required, one_of, _ = LAYOUTS[layout]
    missing = [k for k in required + COMMON_KEYS if k not in keys]
    conflicting = []
    allowed = set(required + COMMON_KEYS + OPTIONAL_KEYS)
    for group in one_of:
        given = [k for k in group if k in keys]
        if not given:
            missing.append(" or ".join(group))
        elif len(given) > 1:
            conflicting.append(" and ".join(given) + " (give one)")
        allowed.update(group)
    known = set(SPECS) | set(LAYOUT_SPECS)
    conflicting += [f"{k} (not used by layout {layout!r})" for k in sorted(keys & known - allowed)]
    return missing, conflicting


def sharp_parameters(layout: str, values: Mapping[str, float]) -> SharpParameters:
    """Table V's variables from a layout's values (SI units, keys of :data:`LAYOUTS`).

    Raises
    ------
    SharpParameterError
        Unknown layout, missing keys, or values that do not describe a motorcycle.
    """
    if layout not in LAYOUTS:
        raise SharpParameterError(f"unknown layout {layout!r}; known: {', '.join(LAYOUTS)}")
    missing, conflicting = layout_problems(layout, set(values))
    if missing or conflicting:
        raise SharpParameterError(f"layout {layout!r}: " + "; ".join(
            ([f"missing {', '.join(missing)}"] if missing else []) + ([f"cannot take {', '.join(conflicting)}"] if conflicting else [])))
    return LAYOUTS[layout][2](values)


__all__ = ["COMMON_KEYS", "LAYOUTS", "LAYOUT_SPECS", "OPTIONAL_KEYS", "from_sharp_frames", "from_whole_vehicle",
           "layout_problems", "sharp_parameters", "spec"]
