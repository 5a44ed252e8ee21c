"""Stable, marginal or unstable: eigenvalues, poles and zeros against the imaginary axis.

One classification, with one documented tolerance, for every caller: the invariant zeros of the
structural analysis (``assist.unknown_input.structure``: strong detectability), the observability report and
the HOSM design (``assist.unknown_input.observability``, ``assist.unknown_input.hosm``), and the stability verdicts of the
modal analysis (:mod:`ptw_env.modes`: where the weave's real part changes sign).

A computed eigenvalue or zero carries round-off of the order of the machine precision times the
size of the matrix (pencil) it comes from, so a value *on* the imaginary axis (a pure
integrator, zeros at 0 and ``+-j w``) comes out with a real part of ``+-1e-16 ||M||``, whose sign
depends on the LAPACK build. The tolerance is therefore relative to the problem's scale:

.. math::

    \\text{tol} = \\text{RTOL}\\cdot\\max(1, s), \\qquad \\text{RTOL} = 10^{-9},

with ``s`` the largest singular value of the (balanced) matrix or pencil the values were computed
from. With a stability margin ``m >= 0`` (a value counts as stable when ``Re < -m``):

* ``stable``: ``Re < -m - tol``;
* ``marginal``: ``|Re + m| <= tol`` (on the boundary to within round-off: never called stable);
* ``unstable``: ``Re > -m + tol``.

``RTOL = 1e-9`` is seven orders of magnitude above double round-off (1e-16) and, for the
matrices of this project (``||M||`` up to ~1e5 for the tire rows), still below 1e-4 1/s, far
below any physical time constant.

Repeated values: a ``k``-fold root is perturbed by ``(eps ||M||)^(1/k)`` (a double zero at 0
comes out as ``+-2e-8``), but the *mean* of the ``k`` computed roots keeps ``eps``-level accuracy.
Values closer than ``CLUSTER_RTOL * max(1, s)`` to each other are therefore classified together,
by the mean of their real parts (two distinct values that close are indistinguishable in floating
point anyway).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

#: Relative tolerance of the marginal band (module docstring).
RTOL = 1e-9
#: Relative distance under which values are taken as one repeated value (module docstring).
CLUSTER_RTOL = 1e-4

Stability = Literal["stable", "marginal", "unstable"]


def marginal_tolerance(scale: float, rtol: float = RTOL) -> float:
    """``rtol * max(1, scale)`` [1/s]: half-width of the marginal band around ``Re = -margin``.

    Parameters
    ----------
    scale : float
        Largest singular value of the matrix or pencil the values come from (module docstring).
    """
    s = float(scale)
    if not np.isfinite(s) or s < 0:
        raise ValueError(f"scale must be a finite number >= 0, got {scale!r}")
    return float(rtol) * max(1.0, s)


def classify(values, scale: float, margin: float = 0.0, rtol: float = RTOL) -> tuple[Stability, ...]:
    """``stable`` / ``marginal`` / ``unstable`` for each value (module docstring).

    Examples
    --------
    >>> classify([-1.0, -1e-16 + 2j, 0.0, 0.05], scale=10.0)
    ('stable', 'marginal', 'marginal', 'unstable')
    >>> classify([-0.5], scale=1.0, margin=0.5)
    ('marginal',)
    """
    v = np.atleast_1d(np.asarray(values, dtype=complex))
    tol = marginal_tolerance(scale, rtol)
    near = marginal_tolerance(scale, CLUSTER_RTOL)
    # clusters of (numerically) repeated values: classified by the mean real part (module docstring)
    label = np.arange(len(v))
    for i in range(len(v)):
        for j in range(i):
            if abs(v[i] - v[j]) <= near:
                label[label == label[i]] = label[j]
    re = np.array([v.real[label == label[i]].mean() for i in range(len(v))]) + float(margin)
    return tuple("stable" if x < -tol else ("unstable" if x > tol else "marginal") for x in re)


def verdict(values, scale: float, margin: float = 0.0, rtol: float = RTOL) -> tuple[bool, str]:
    """``(all stable, reason)``: the reason names the first marginal or unstable value ("" when all
    are stable), e.g. ``"marginal zero 2j"``."""
    v = np.atleast_1d(np.asarray(values, dtype=complex))
    c = classify(v, scale, margin, rtol)
    for kind in ("unstable", "marginal"):
        bad = [z for z, k in zip(v, c) if k == kind]
        if bad:
            z = bad[int(np.argmax([b.real for b in bad]))]
            return False, f"{kind} zero {complex(round(z.real, 6), round(z.imag, 6))}"
    return True, ""


__all__ = ["RTOL", "CLUSTER_RTOL", "Stability", "marginal_tolerance", "classify", "verdict"]
