"""Levant's arbitrary-order robust exact differentiator, discretised for sampled signals.

Continuous-time differentiator of order ``n`` (Levant [1]_, non-recursive
form; the recursive form is [1]_ eq. (11) and Nehaoua et al. [2]_ eqs. 8, 13, 14):

.. math::

    \\dot z_i = -\\kappa_{n-i} L^{\\frac{i+1}{n+1}}
        \\lfloor z_0 - f \\rceil^{\\frac{n-i}{n+1}} + z_{i+1}
        \\quad (i = 0, \\dots, n-1), \\qquad
    \\dot z_n = -\\kappa_0 L \\,\\mathrm{sign}(z_0 - f),

with ``⌊e⌉^a = |e|^a sign(e)``. If ``|f^(n+1)| <= L`` and ``f`` is exact,
``z_i = f^(i)`` after a finite time. ``L`` has the units of ``f`` per
second^(n+1).

Gains. The recursive form of [1]_ (and [2]_ eq. 8: ``3, 2, 1.5, 1.1``; eq. 14:
``2, 1.5, 1.1``) uses ``lambda_n, ..., lambda_0`` with
``v_{i-1} = -lambda_{n-i+1} L^{1/(n-i+2)} ⌊z_{i-1} - v_{i-2}⌉^{(n-i+1)/(n-i+2)} + z_i``.
Substituting gives the non-recursive gains

.. math::

    \\kappa_n = \\lambda_n, \\qquad
    \\kappa_{j} = \\lambda_{j}\\, \\kappa_{j+1}^{\\,j/(j+1)} \\quad (j = n-1, \\dots, 0)

(:func:`recursive_to_nonrecursive`). We use the recursive sequence
:data:`RECURSIVE_GAINS` ``= (1.1, 1.5, 2, 3, 5, 7, 10)``: Levant's [1]_
``1.1, 1.5, 2, 3, 5`` (the paper's values for ``n <= 3``), then the
``7, 10`` that reproduce the non-recursive table of Levant & Livne [4]_
(``n = 5``: ``1.1, 6.75, 20.26, 32.24, 23.72, 7``; [1]_ gives ``8`` for
``lambda_5``: both are admissible, sufficient choices, not a misprint; [2]_
uses orders up to 3 only and prints no ``lambda_5``).

Corrections to the paper's printed differentiator ([2]_ eqs. 8, 13, 14):

* the sign of the innovation: eq. (8) writes ``v_1 - y_p + C_p z``, i.e. it
  differentiates ``e_y = y - C z``; we keep that (``f = e_y``);
* eq. (13)-(14) state ``v_i in R^(r_M + k + 1)`` for every output, but eq.
  (14) has ``r_2 + k + 1 = 3`` states: each output gets its own order
  ``r_i + k`` (what the equations do), not ``r_M + k``.

Discretisation (Livne & Levant [3]_). With sampling step ``tau`` and samples
``f_k``, the differentiator advances by Euler steps of the *homogeneous
correction* plus the exact Taylor propagation of a degree-``n`` polynomial:

.. math::

    z_i(t_{k+1}) = z_i(t_k) + \\sum_{j=1}^{n-i} \\frac{\\tau^j}{j!} z_{i+j}(t_k)
        - \\tau\\,\\kappa_{n-i} L^{\\frac{i+1}{n+1}} \\lfloor z_0(t_k) - f_k \\rceil^{\\frac{n-i}{n+1}} .

Without the Taylor terms (plain Euler) the discrete differentiator loses the
accuracy below; with them it keeps the continuous-time asymptotics ([3]_,
Theorem 1): for noise ``|eta| <= eps``, after a finite time

.. math::

    |z_i(t_k) - f^{(i)}(t_k)| \\le \\mu_i L \\rho^{n+1-i}, \\qquad
    \\rho = \\max\\bigl(\\tau, (\\varepsilon / L)^{1/(n+1)}\\bigr),

i.e. ``O(L tau^(n+1-i))`` from sampling and ``O(L^(i/(n+1)) eps^((n+1-i)/(n+1)))``
from noise (:func:`accuracy_scale`; the constants ``mu_i`` depend only on
``n`` and the gains).

Timing convention. :meth:`LevantDifferentiator.update` takes the sample
``f_k`` and advances the state to ``z(t_{k+1})`` as above. It returns, by
default (``estimate="posterior"``), the estimate at ``t_k`` that already uses
``f_k``: the new state propagated back one step by the exact Taylor map
``P`` (``z_{k+1} = P z_k - corr_k``),

.. math::

    z_k^{+} = P^{-1} z_{k+1} = z_k - P^{-1}\\,\\mathrm{corr}_k ,

which has the same accuracy order as ``z_k`` (``P^{-1}`` mixes derivative
``i + j`` into ``i`` with weight ``(-tau)^j/j!``, so ``O(L tau^(n+1-i-j))``
errors enter as ``O(L tau^(n+1-i))``) but no one-sample lag: for a signal
driven by a sampled input, the estimate at ``t_k`` then reflects the input up
to ``t_k``. ``estimate="prior"`` returns ``z_k`` (computed from
``f_0 .. f_{k-1}``), the quantity of [3]_'s theorem.

References
----------
.. [1] A. Levant, "Higher-order sliding modes, differentiation and
   output-feedback control", Int. J. Control 76(9-10), 924-941, 2003.
.. [2] L. Nehaoua et al., IEEE TVT 63(7), 2014 (``shared/papers/001_19401b3c72cfcc01.txt``).
.. [3] M. Livne, A. Levant, "Proper discretization of homogeneous
   differentiators", Automatica 50(8), 2007-2014, 2014.
.. [4] A. Levant, M. Livne, "Robust exact filtering differentiators",
   European J. Control 55, 33-44, 2020.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

#: Recursive-form gains ``lambda_0, lambda_1, ...`` (module docstring) for orders up to 6.
RECURSIVE_GAINS: tuple[float, ...] = (1.1, 1.5, 2.0, 3.0, 5.0, 7.0, 10.0)
#: Highest order with default gains.
MAX_ORDER = len(RECURSIVE_GAINS) - 1


class DifferentiatorError(ValueError):
    """A differentiator setting (order, Lipschitz constant, step, gains) or a sample that is unusable."""


def recursive_to_nonrecursive(recursive: Sequence[float]) -> tuple[float, ...]:
    """Non-recursive gains ``kappa_0..kappa_n`` from recursive ``lambda_0..lambda_n`` (module docstring).

    Examples
    --------
    >>> [round(k, 2) for k in recursive_to_nonrecursive((1.1, 1.5, 2.0, 3.0))]   # paper eq. (8)
    [1.1, 3.06, 4.16, 3.0]
    """
    lam = [float(v) for v in recursive]
    if not lam or any(not (v > 0 and math.isfinite(v)) for v in lam):
        raise DifferentiatorError(f"recursive gains must be positive and finite, got {tuple(recursive)!r}")
    n = len(lam) - 1
    kappa = [0.0] * (n + 1)
    kappa[n] = lam[n]
    for j in range(n - 1, -1, -1):
        kappa[j] = lam[j] * kappa[j + 1] ** (j / (j + 1))
    return tuple(kappa)


def default_gains(order: int) -> tuple[float, ...]:
    """Non-recursive gains ``kappa_0..kappa_order`` from :data:`RECURSIVE_GAINS`."""
    if not isinstance(order, (int, np.integer)) or isinstance(order, bool) or not 0 <= order <= MAX_ORDER:
        raise DifferentiatorError(f"order must be an integer in [0, {MAX_ORDER}] for the default gains, got {order!r}")
    return recursive_to_nonrecursive(RECURSIVE_GAINS[: order + 1])


def accuracy_scale(order: int, lipschitz: float, dt: float, noise: float = 0.0) -> np.ndarray:
    """``L rho^(n+1-i)`` for ``i = 0..n``, ``rho = max(dt, (noise/L)^(1/(n+1)))`` ([3]_, Theorem 1).

    The asymptotic error of derivative ``i`` is this times a constant ``mu_i``.
    """
    n = int(order)
    rho = max(float(dt), (float(noise) / float(lipschitz)) ** (1.0 / (n + 1)))
    return np.array([float(lipschitz) * rho ** (n + 1 - i) for i in range(n + 1)])


class LevantDifferentiator:
    """Discrete-time Levant differentiator of order ``n`` (module docstring), batched over leading axes.

    Parameters
    ----------
    order : int
        Highest derivative estimated, ``n >= 0``.
    lipschitz : float or array_like
        ``L`` [units of f / s^(n+1)], a bound of ``|f^(n+1)|``; an array
        gives one constant per signal of the batch.
    dt : float
        Sampling step [s].
    gains : sequence of float, optional
        Non-recursive gains ``kappa_0..kappa_n`` (default :func:`default_gains`).
    estimate : {"posterior", "prior"}
        What :meth:`update` returns (module docstring, timing convention).

    Examples
    --------
    >>> import numpy as np
    >>> d = LevantDifferentiator(order=2, lipschitz=1.0, dt=1e-3)
    >>> t = np.arange(0, 6, 1e-3)
    >>> z = np.array([d.update(0.5 * tk**2) for tk in t])     # f = t^2/2, f' = t, f'' = 1
    >>> bool(abs(z[-1, 1] - t[-1]) < 1e-3 and abs(z[-1, 2] - 1) < 1e-2)
    True
    """

    def __init__(self, order: int, lipschitz, dt: float, gains: Sequence[float] | None = None,
                 estimate: str = "posterior") -> None:
        if estimate not in ("posterior", "prior"):
            raise DifferentiatorError(f"estimate must be 'posterior' or 'prior', got {estimate!r}")
        self.estimate = estimate
        if not isinstance(order, (int, np.integer)) or isinstance(order, bool) or order < 0:
            raise DifferentiatorError(f"order must be a non-negative integer, got {order!r}")
        self.order = int(order)
        L = np.asarray(lipschitz, dtype=float)
        if not np.all(np.isfinite(L)) or np.any(L <= 0):
            raise DifferentiatorError(f"lipschitz must be positive and finite, got {lipschitz!r}")
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt) and dt > 0):
            raise DifferentiatorError(f"dt must be a positive number of seconds, got {dt!r}")
        self.lipschitz = L
        self.dt = float(dt)
        if gains is None:
            kappa = default_gains(self.order)
        else:
            kappa = tuple(float(g) for g in gains)
            if len(kappa) != self.order + 1 or any(not (g > 0 and math.isfinite(g)) for g in kappa):
                raise DifferentiatorError(
                    f"gains must be {self.order + 1} positive numbers kappa_0..kappa_{self.order}, got {tuple(gains)!r}"
                )
        self.gains = kappa
        n = self.order
        # per-row constants: correction gain c_i = kappa_{n-i} L^{(i+1)/(n+1)}, exponent (n-i)/(n+1)
        self._expo = np.array([(n - i) / (n + 1) for i in range(n + 1)])
        self._c = np.stack([kappa[n - i] * L ** ((i + 1) / (n + 1)) for i in range(n + 1)], axis=-1) * self.dt
        # Taylor propagation matrix: z <- P z with P[i, i+j] = dt^j / j!
        P = np.eye(n + 1)
        for i in range(n + 1):
            for j in range(1, n - i + 1):
                P[i, i + j] = self.dt**j / math.factorial(j)
        self._P = P
        self._Pinv = np.linalg.inv(P)
        self._z: np.ndarray | None = None

    @property
    def state(self) -> np.ndarray | None:
        """Current estimates ``[z_0, ..., z_n]`` (batch + (n+1,)), at the next sample instant; None before the first sample."""
        return None if self._z is None else self._z.copy()

    def reset(self, f0=None, derivatives=None) -> None:
        """Forget the state. With ``f0`` (and optionally ``derivatives`` of shape batch + (n,)) set it now;
        otherwise the first :meth:`update` starts at ``[f_0, 0, ..., 0]``."""
        if f0 is None:
            self._z = None
            return
        f0 = np.asarray(f0, dtype=float)
        z = np.zeros(f0.shape + (self.order + 1,))
        z[..., 0] = f0
        if derivatives is not None:
            d = np.asarray(derivatives, dtype=float)
            if d.shape != f0.shape + (self.order,):
                raise DifferentiatorError(f"derivatives must have shape {f0.shape + (self.order,)}, got {d.shape}")
            z[..., 1:] = d
        self._z = z

    def update(self, f) -> np.ndarray:
        """Feed sample ``f_k``, advance to ``t_{k+1}``; return the estimate at ``t_k`` (batch + (n+1,)),
        posterior (using ``f_k``) or prior (module docstring)."""
        f = np.asarray(f, dtype=float)
        if not np.all(np.isfinite(f)):
            raise DifferentiatorError(f"sample is not finite: {f!r}")
        if self._z is None:
            self.reset(f)
        z = self._z
        if z.shape[:-1] != f.shape:
            raise DifferentiatorError(f"sample has shape {f.shape}, the differentiator's batch is {z.shape[:-1]}")
        e = z[..., 0] - f
        s = np.sign(e)[..., None]
        corr = self._c * np.abs(e)[..., None] ** self._expo * s
        self._z = z @ self._P.T - corr
        if self.estimate == "prior":
            return z.copy()
        return z - corr @ self._Pinv.T


def differentiate(signal, dt: float, order: int, lipschitz, gains: Sequence[float] | None = None,
                  derivatives0=None, estimate: str = "posterior") -> np.ndarray:
    """Run a :class:`LevantDifferentiator` over ``signal`` (shape (T, ...)); returns (T, ..., order+1).

    Row ``k`` is the estimate at sample ``k`` (``estimate``: see the timing convention).
    """
    sig = np.asarray(signal, dtype=float)
    if sig.ndim < 1 or sig.shape[0] < 1:
        raise DifferentiatorError(f"signal must have at least one sample along axis 0, got shape {sig.shape}")
    d = LevantDifferentiator(order, lipschitz, dt, gains, estimate)
    d.reset(sig[0], derivatives0)
    out = np.empty(sig.shape + (order + 1,))
    for k in range(sig.shape[0]):
        out[k] = d.update(sig[k])
    return out


def estimate_lipschitz(signal, dt: float, order: int, margin: float = 2.0) -> float:
    """A Lipschitz constant for an order-``n`` differentiator from a noise-free sampled signal.

    ``margin * max |Delta^(n+1) f| / dt^(n+1)`` (forward differences of order
    ``n + 1``). Use on simulated, noise-free signals to tune ``L``; on noisy
    data the differences measure the noise, not the signal.
    """
    f = np.asarray(signal, dtype=float)
    if f.ndim != 1 or f.size < order + 3:
        raise DifferentiatorError(f"signal must be 1-D with at least {order + 3} samples, got shape {f.shape}")
    d = np.diff(f, n=order + 1)
    return float(margin * np.max(np.abs(d)) / dt ** (order + 1))


__all__ = [
    "DifferentiatorError",
    "LevantDifferentiator",
    "MAX_ORDER",
    "RECURSIVE_GAINS",
    "accuracy_scale",
    "default_gains",
    "differentiate",
    "estimate_lipschitz",
    "recursive_to_nonrecursive",
]
