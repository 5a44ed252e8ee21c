"""Modal analysis of the PTW model linearised at the upright: weave, wobble, capsize, tire.

For each forward speed ``vx`` the eigenvalues of the state matrix
``E^-1 A(vx)`` (model.md, "Plausibility checks", linearised at ``phi = 0``;
:meth:`ptw_env.vehicle.Vehicle.state_matrix`) are computed and each one is
named after the motion it describes. With effects (effects.md) the state
matrix is the Jacobian :func:`ptw_env.dynamics.linearise` of the compiled
plant at ``x = 0``, ``tau = 0`` (for ``road_bank`` and ``roll_moment_offset``
``x = 0`` is not an equilibrium; the Jacobian there is still the upright
linearisation, the constant terms do not enter it).

How a mode is named
-------------------
Each eigenvalue ``lambda_i`` with right and left eigenvectors ``v_i``,
``w_i`` gets the participation factors (Perez-Arriaga, Verghese, Schweppe,
IEEE Trans. PAS 101(9), 1982)

.. math::

    p_{ki} = \\frac{\\bar w_{ki}\\, v_{ki}}{w_i^H v_i}, \\qquad \\sum_k p_{ki} = 1,

which, unlike raw eigenvector entries, do not depend on the units of the
states (a diagonal rescaling of x leaves them unchanged), so rad, m/s and N
need no arbitrary weights. Their moduli, summed over four coordinate groups
and normalised to one, give the *shares* of the mode in roll
(phi, phi_dot), steer (delta, delta_dot), lateral-yaw (vy, r) and tire force
(Fyf, Fyr). The tire group has an exact physical meaning: the relaxation
rows are proportional to ``1/sigma`` (``A v = lambda v`` then gives)

.. math::

    \\frac{\\sigma}{\\lambda_i}\\frac{\\partial\\lambda_i}{\\partial\\sigma}
    = -\\sum_{k\\in\\{F_{yf},F_{yr}\\}} p_{ki},

so the tire participation measures how much of the mode *is* the tire lag
(-1: a pure lag, ``lambda ~ -vx/sigma``; 0: a mode the relaxation length does
not move; ``tests/test_modes.py`` checks the identity against a finite
difference in the ``relaxation_length`` effect). The tire share is its
modulus version (0.77 and 0.90 for the two tire modes at 40 m/s, whose
elasticities are -0.98 and -1.11).

At every speed, with no speed-dependent threshold:

1. ``capsize``: the real eigenvalue with the largest roll share;
2. ``weave``: the complex pair with the largest roll share;
3. ``wobble``: of the other complex pairs, the one with the largest steer share;
4. ``tire``: of the rest, the set of modes holding as many eigenvalues as
   the model has tire-force states (2; a pair counts twice) with the largest
   total tire share (the tire participations of all modes add up to 2);
5. ``other``: what remains.

For the reference scooter this gives, at every speed of 3-40 m/s, one weave
pair, one wobble pair (8.8-11.8 Hz), one capsize, two tire modes and one
``other`` mode, which is a heavily damped non-oscillatory mechanical mode
without a classical name. It survives the limit ``sigma -> 0`` (it is
not a tire lag): below ~23 m/s it is the real steer (castering) mode
(-29.6 at 5 m/s, steer share 0.84); above, the lateral-yaw-roll mode
(-32.0 at 30 m/s). The exchange happens 0.15-0.2 m/s after the low-speed lateral-tire
oscillation (-11.2 +/- 58.5j at 5 m/s, tire share 0.47) splits into two real
modes (22.35 m/s): one continues as the rear tire lag (-182.2 at 40 m/s, Fyr
participation 0.98), the other as the lateral mode, while the steer branch
turns into the front tire lag (-185.6 at 40 m/s, Fyf participation 0.86;
both ~ -vx/sigma = -200). Names follow the physics of the mode at
that speed, not the identity of a branch.

Continuity across speed
-----------------------
:func:`eigen_analysis` also computes the spectrum on a fine speed grid
(0.05 m/s by default) over the vehicle's whole valid range and tracks the
eigenvalue branches along it (optimal assignment between neighbouring speeds
on a linear prediction of each branch). The grid and its branches give the curves
of :func:`plot_modes`, the brackets for :meth:`ModalResult.weave_boundaries`
(root finding on the weave's real part), and :meth:`ModalResult.label_changes`,
the places where a tracked branch changes name. For the reference scooter the
only change is the tire/other exchange just after the 22.35 m/s split
described above (the test suite checks this, and that the label counts stay
the same at every grid speed, so a classification that flickers fails).

Examples
--------
>>> res = eigen_analysis(speeds=[5.0, 30.0])
>>> res.labels[0]
('weave', 'weave', 'wobble', 'wobble', 'capsize', 'tire', 'tire', 'other')
>>> [round(float(z.real), 2) for z in res.select("weave")[0]]
[2.04, 2.04]
>>> round(res.stability_speed(), 2)
9.32
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np
import scipy.linalg
from scipy.optimize import brentq, linear_sum_assignment

from .dynamics import compile_plant, linearise
from .effects import Effects, as_effects
from .spectrum import marginal_tolerance
from .vehicle import DELTA, DELTA_DOT, FYF, FYR, PHI, PHI_DOT, R, REFERENCE_SCOOTER, VY, Vehicle

#: Mode names, in the order the eigenvalues of each speed are sorted.
LABELS: tuple[str, ...] = ("weave", "wobble", "capsize", "tire", "other")
#: Coordinate groups of the shares (participation factors), in ``shares[..., g]`` order.
GROUPS: tuple[str, ...] = ("roll", "steer", "lateral", "tire")
_GROUP_STATES = ((PHI, PHI_DOT), (DELTA, DELTA_DOT), (VY, R), (FYF, FYR))
_ROLL, _STEER, _LATERAL, _TIRE = range(4)
#: Default spacing [m/s] of the speed grid used for tracking and root finding.
GRID_STEP = 0.05


class ModesInputError(ValueError):
    """Bad arguments to :func:`eigen_analysis` (speeds, grid, batched effects)."""


# ----------------------------------------------------------------------------- one speed
def participation_factors(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of ``A`` and their participation factors.

    Parameters
    ----------
    A : ndarray, shape (8, 8)
        State matrix in the state order of model.md.

    Returns
    -------
    eigenvalues : ndarray, shape (8,), complex [1/s]
    P : ndarray, shape (8, 8), complex
        ``P[k, i] = conj(w_ki) v_ki / (w_i^H v_i)`` (Perez-Arriaga et al. 1982),
        ``w_i``, ``v_i`` the left and right eigenvectors of ``lambda_i``. Each
        column and each row sums to 1; ``P`` is unchanged by a diagonal
        scaling of the states; ``-(P[6, i] + P[7, i])`` is the elasticity
        ``(sigma/lambda_i) d lambda_i / d sigma`` of the eigenvalue to the
        tire relaxation length (module docstring).
    """
    A = np.asarray(A, dtype=float)
    if A.shape != (8, 8) or not np.all(np.isfinite(A)):
        raise ModesInputError(f"state matrix must be a finite (8, 8) array, got shape {A.shape}")
    lam, wl, vr = scipy.linalg.eig(A, left=True, right=True)
    p = np.conj(wl) * vr
    return lam, p / p.sum(axis=0)


def participation_shares(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of ``A`` and their shares in roll / steer / lateral-yaw / tire coordinates.

    Parameters
    ----------
    A : ndarray, shape (8, 8)
        State matrix in the state order of model.md.

    Returns
    -------
    eigenvalues : ndarray, shape (8,), complex [1/s]
    shares : ndarray, shape (8, 4)
        ``shares[i, g] = sum_{k in g} |p_ki| / sum_k |p_ki|`` with the
        participation factors of :func:`participation_factors`; groups in
        :data:`GROUPS` order. Complex-conjugate eigenvalues have equal shares.
    """
    lam, p = participation_factors(A)
    p = np.abs(p)
    groups = np.stack([p[list(ks)].sum(axis=0) for ks in _GROUP_STATES], axis=-1)
    return lam, groups / groups.sum(axis=-1, keepdims=True)


def _units(lam: np.ndarray) -> list[tuple[int, ...]]:
    """Indices grouped into complex-conjugate pairs ``(i_pos, i_neg)`` and reals ``(i,)``."""
    pos = [i for i in range(len(lam)) if lam[i].imag > 0]
    neg = [i for i in range(len(lam)) if lam[i].imag < 0]
    units: list[tuple[int, ...]] = [(i,) for i in range(len(lam)) if lam[i].imag == 0]
    for i in pos:
        j = min(neg, key=lambda j: abs(lam[j] - np.conj(lam[i])))
        neg.remove(j)
        units.append((i, j))
    return units


def classify(eigenvalues: np.ndarray, shares: np.ndarray, n_tire: int = 2) -> tuple[str, ...]:
    """Name each eigenvalue of one speed (rules 1-5 of the module docstring).

    Parameters
    ----------
    eigenvalues : ndarray, shape (n,), complex
    shares : ndarray, shape (n, 4)
        From :func:`participation_shares`.
    n_tire : int
        Number of tire-force (relaxation) states, i.e. of tire modes.

    Returns
    -------
    tuple of str, one of :data:`LABELS` per eigenvalue (same order).
    """
    lam = np.asarray(eigenvalues, dtype=complex)
    sh = np.asarray(shares, dtype=float)
    if lam.ndim != 1 or sh.shape != (len(lam), len(GROUPS)):
        raise ModesInputError(
            f"classify takes eigenvalues of shape (n,) and shares of shape (n, {len(GROUPS)}), got {lam.shape} and {sh.shape}"
        )
    if np.sum(lam.imag > 0) != np.sum(lam.imag < 0):
        raise ModesInputError("classify: the eigenvalues of a real matrix come in conjugate pairs; these do not")
    labels = ["other"] * len(lam)
    units = _units(lam)
    reals = [u for u in units if len(u) == 1]
    pairs = [u for u in units if len(u) == 2]

    def take(pool: list[tuple[int, ...]], group: int, name: str) -> None:
        if pool:
            u = max(pool, key=lambda u: sh[u[0], group])
            pool.remove(u)
            for i in u:
                labels[i] = name

    take(reals, _ROLL, "capsize")
    take(pairs, _ROLL, "weave")
    take(pairs, _STEER, "wobble")
    # tire: the set of remaining units holding exactly n_tire eigenvalues (as
    # many as fit) with the largest total tire share; the tire participations
    # of all modes add up to n_tire, so this picks the modes that are the lag.
    rest = reals + pairs
    size = min(n_tire, sum(len(u) for u in rest))
    best: tuple[float, tuple[tuple[int, ...], ...]] = (-1.0, ())
    for r in range(len(rest) + 1):
        for combo in itertools.combinations(rest, r):
            if sum(len(u) for u in combo) == size:
                total = sum(sh[i, _TIRE] for u in combo for i in u)
                if total > best[0]:
                    best = (total, combo)
    for u in best[1]:
        for i in u:
            labels[i] = "tire"
    return tuple(labels)


def _sort_key(lam: complex, label: str) -> tuple[int, float, float]:
    return (LABELS.index(label), -lam.real, -lam.imag)


# ----------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class ModalResult:
    """Labelled eigenvalues of the upright linearisation, per speed.

    Attributes
    ----------
    speeds : ndarray, shape (S,)
        Forward speeds [m/s], in the order requested.
    eigenvalues : ndarray, shape (S, 8), complex
        Eigenvalues [1/s] per speed, sorted by label in :data:`LABELS` order
        (weave, wobble, capsize, tire, other), then by decreasing real part,
        then positive imaginary part first; so for the reference scooter
        column j is the same mode at every speed.
    labels : tuple of tuple of str
        Mode name of each eigenvalue, same layout.
    shares : ndarray, shape (S, 8, 4)
        Participation shares in roll / steer / lateral-yaw / tire coordinates.
    grid_speeds : ndarray, shape (G,)
        The fine speed grid [m/s] (the valid range plus the requested speeds).
    grid_eigenvalues : ndarray, shape (G, 8), complex
        Eigenvalues on the grid, column j = tracked branch j.
    grid_labels : ndarray, shape (G, 8), str
        Names on the grid, same layout.
    vehicle_name : str
    effects : Effects
        The dynamic effects the model was linearised with.
    """

    speeds: np.ndarray
    eigenvalues: np.ndarray
    labels: tuple[tuple[str, ...], ...]
    shares: np.ndarray
    grid_speeds: np.ndarray
    grid_eigenvalues: np.ndarray
    grid_labels: np.ndarray
    vehicle_name: str
    effects: Effects
    _state_matrix: Callable[[float], np.ndarray] = field(repr=False)

    @property
    def damping_ratio(self) -> np.ndarray:
        """``zeta = -Re(lambda)/|lambda|`` (-), shape (S, 8); 1 for a stable real mode, < 0 if unstable."""
        return -self.eigenvalues.real / np.abs(self.eigenvalues)

    @property
    def frequency_hz(self) -> np.ndarray:
        """Damped frequency ``|Im(lambda)|/(2 pi)`` [Hz], shape (S, 8); 0 for real modes."""
        return np.abs(self.eigenvalues.imag) / (2 * np.pi)

    @property
    def natural_frequency_hz(self) -> np.ndarray:
        """Undamped natural frequency ``|lambda|/(2 pi)`` [Hz], shape (S, 8)."""
        return np.abs(self.eigenvalues) / (2 * np.pi)

    def select(self, label: str) -> list[np.ndarray]:
        """The eigenvalues named ``label``, one array per speed (sorted as in :attr:`eigenvalues`)."""
        if label not in LABELS:
            raise ModesInputError(f"unknown mode label {label!r}; known: {', '.join(LABELS)}")
        return [ev[[lab == label for lab in labs]] for ev, labs in zip(self.eigenvalues, self.labels)]

    def label_changes(self) -> list[tuple[float, float, int, str, str]]:
        """Where a tracked branch of the grid changes name: ``(v_before, v_after, branch, old, new)``."""
        out = []
        g = self.grid_labels
        for k in range(len(self.grid_speeds) - 1):
            for j in np.nonzero(g[k] != g[k + 1])[0]:
                out.append((float(self.grid_speeds[k]), float(self.grid_speeds[k + 1]), int(j), str(g[k, j]), str(g[k + 1, j])))
        return out

    def _weave_real(self, vx: float) -> float:
        lam, sh = participation_shares(self._state_matrix(vx))
        w = [z.real for z, lab in zip(lam, classify(lam, sh)) if lab == "weave"]
        if not w:
            raise ModesInputError(f"no weave pair at vx = {vx:.4g} m/s: cannot locate the weave stability boundary")
        return float(w[0])

    def weave_boundaries(self) -> list[tuple[float, str]]:
        """All speeds [m/s] where the weave changes stability, with ``"stabilises"`` or ``"destabilises"``.

        Each sign change of ``Re(lambda_weave)`` is bracketed on the fine grid
        and refined by Brent's method (``xtol`` 1e-9 m/s) on the real part of
        the eigenvalue classified as weave at that speed. A stiff steering
        damper, for instance, gives a second, high-speed boundary.
        """
        re = np.array([self._grid_weave_real(k) for k in range(len(self.grid_speeds))])
        # a real part within round-off of 0 is marginal (ptw_env.spectrum), not a sign
        # (the scale: the spectral radius at each grid speed, a lower bound of ||E^-1 A||)
        tol = [marginal_tolerance(float(np.abs(ev).max())) for ev in self.grid_eigenvalues]
        re = np.where(np.abs(re) <= tol, 0.0, re)
        out = []
        for k in range(len(re) - 1):
            if np.sign(re[k]) != np.sign(re[k + 1]) and re[k] != 0 and np.all(np.isfinite(re[k : k + 2])):
                v0, v1 = float(self.grid_speeds[k]), float(self.grid_speeds[k + 1])
                v = v1 if re[k + 1] == 0 else float(brentq(self._weave_real, v0, v1, xtol=1e-9, rtol=1e-12))
                out.append((v, "stabilises" if re[k] > 0 else "destabilises"))
        return out

    def stability_speed(self) -> float:
        """Lowest speed [m/s] at which the weave turns from unstable to stable (see :meth:`weave_boundaries`).

        Returns ``nan`` when the weave never turns stable in the vehicle's
        speed range (stable already at ``vmin``, or unstable throughout).
        """
        for v, kind in self.weave_boundaries():
            if kind == "stabilises":
                return v
        return math.nan

    def _grid_weave_real(self, k: int) -> float:
        m = self.grid_labels[k] == "weave"
        return float(self.grid_eigenvalues[k, m][0].real) if np.any(m) else math.nan

    def to_json(self) -> dict[str, Any]:
        """The ``modes --json`` document of cli.md: ``{"speeds", "eigenvalues", "labels"}``.

        ``eigenvalues`` holds ``[re, im]`` pairs [1/s] per speed, ``labels``
        the matching names, both sorted as :attr:`eigenvalues`.
        """
        return {
            "speeds": [float(v) for v in self.speeds],
            "eigenvalues": [[[float(z.real), float(z.imag)] for z in ev] for ev in self.eigenvalues],
            "labels": [list(labs) for labs in self.labels],
        }


# ----------------------------------------------------------------------------- analysis
def _matrix_function(vehicle: Vehicle, effects: Effects) -> Callable[[float], np.ndarray]:
    dyn = effects.dynamic
    if not dyn:
        return vehicle.state_matrix
    plant = compile_plant(vehicle, dyn)
    if plant.batch_shape:
        raise ModesInputError(
            f"effects: eigen_analysis takes scalar effect parameters, got arrays of shape {plant.batch_shape}"
        )
    return lambda vx: linearise(plant, vx)[0]


def _track(lams: np.ndarray) -> np.ndarray:
    """Column permutation per grid row that makes each column a continuous branch.

    Between neighbouring speeds the eigenvalues are matched by an optimal
    assignment on ``|lambda_pred - lambda_new|``, ``lambda_pred`` the linear
    extrapolation of the branch from the two previous speeds (so crossing
    branches are followed through the crossing).
    """
    G, n = lams.shape
    order = np.empty((G, n), dtype=int)
    order[0] = np.arange(n)
    tracked = np.empty_like(lams)
    tracked[0] = lams[0]
    for k in range(1, G):
        pred = tracked[k - 1] if k == 1 else 2 * tracked[k - 1] - tracked[k - 2]
        _, col = linear_sum_assignment(np.abs(pred[:, None] - lams[k][None, :]))
        order[k] = col
        tracked[k] = lams[k][col]
    return order


def _as_speeds(speeds: Iterable[float] | float, vehicle: Vehicle) -> np.ndarray:
    try:
        s = np.atleast_1d(np.asarray(speeds, dtype=float))
    except (TypeError, ValueError):
        raise ModesInputError(f"speeds must be numbers in m/s, got {speeds!r}") from None
    if s.ndim != 1 or s.size == 0:
        raise ModesInputError(f"speeds must be a non-empty 1-D list of speeds in m/s, got shape {s.shape}")
    bad = s[~np.isfinite(s) | (s < vehicle.vmin) | (s > vehicle.vmax)]
    if bad.size:
        raise ModesInputError(
            f"speeds: {bad.tolist()} m/s outside the valid range [{vehicle.vmin}, {vehicle.vmax}] m/s of {vehicle.name}"
        )
    return s


def eigen_analysis(
    vehicle: Vehicle | None = None,
    speeds: Iterable[float] | float = (5.0, 10.0, 20.0, 30.0),
    effects: Effects | Any = None,
    *,
    grid_step: float = GRID_STEP,
) -> ModalResult:
    """Eigenvalues of the upright linearisation, labelled weave / wobble / capsize / tire / other.

    Parameters
    ----------
    vehicle : Vehicle, optional
        Defaults to the reference scooter (model.md).
    speeds : sequence of float or float
        Forward speeds [m/s] to report, inside ``[vehicle.vmin, vehicle.vmax]``.
        The default is the speeds of model.md's eigenvalue table.
    effects : Effects, dict, list of ``"CAUSE:PARAM=VALUE"`` or None
        Effects of effects.md with scalar parameters; the model is then
        linearised by :func:`ptw_env.dynamics.linearise` at ``x = 0``. Sensor
        effects do not change the modes and are dropped.
    grid_step : float
        Spacing [m/s] of the tracking grid over ``[vmin, vmax]``.

    Returns
    -------
    ModalResult

    Raises
    ------
    ModesInputError
        Speeds outside the valid range or not numbers, a bad ``grid_step``,
        array-valued effect parameters.
    ptw_env.effects.EffectError
        Unknown or out-of-range effects.
    """
    vehicle = REFERENCE_SCOOTER if vehicle is None else vehicle
    if not isinstance(vehicle, Vehicle):
        raise ModesInputError(f"vehicle must be a ptw_env.vehicle.Vehicle, got {type(vehicle).__name__}")
    eff = as_effects(effects).dynamic
    s = _as_speeds(speeds, vehicle)
    if not (isinstance(grid_step, (int, float)) and 0 < grid_step <= (vehicle.vmax - vehicle.vmin) / 4):
        raise ModesInputError(
            f"grid_step must be a positive speed step [m/s] of at most a quarter of the range, got {grid_step!r}"
        )
    matrix = _matrix_function(vehicle, eff)

    n_grid = int(math.ceil((vehicle.vmax - vehicle.vmin) / grid_step - 1e-9)) + 1
    grid = np.union1d(np.linspace(vehicle.vmin, vehicle.vmax, n_grid), s)
    lams = np.empty((len(grid), 8), dtype=complex)
    shs = np.empty((len(grid), 8, 4))
    for k, v in enumerate(grid):
        lams[k], shs[k] = participation_shares(matrix(float(v)))
    labs = np.array([classify(lams[k], shs[k]) for k in range(len(grid))])
    order = _track(lams)
    rows = np.arange(len(grid))[:, None]
    g_lam, g_lab, g_sh = lams[rows, order], labs[rows, order], shs[rows, order]

    ev_out, lab_out, sh_out = [], [], []
    for v in s:
        k = int(np.searchsorted(grid, v))
        idx = sorted(range(8), key=lambda i: _sort_key(lams[k, i], labs[k, i]))
        ev_out.append(lams[k, idx])
        lab_out.append(tuple(str(labs[k, i]) for i in idx))
        sh_out.append(shs[k, idx])

    def frozen(a: np.ndarray) -> np.ndarray:
        a = np.array(a)
        a.setflags(write=False)
        return a

    return ModalResult(
        speeds=frozen(s),
        eigenvalues=frozen(ev_out),
        labels=tuple(lab_out),
        shares=frozen(sh_out),
        grid_speeds=frozen(grid),
        grid_eigenvalues=frozen(g_lam),
        grid_labels=frozen(g_lab),
        vehicle_name=vehicle.name,
        effects=eff,
        _state_matrix=matrix,
    )


# ----------------------------------------------------------------------------- figure
_COLOURS = {"weave": "tab:blue", "wobble": "tab:orange", "capsize": "tab:green", "tire": "tab:red", "other": "tab:gray"}
_MARKERS = {"weave": "o", "wobble": "s", "capsize": "D", "tire": "^", "other": "v"}


def _runs(labels: np.ndarray) -> list[tuple[int, int, str]]:
    """Maximal runs ``[start, stop)`` of constant label along one branch."""
    out, start = [], 0
    for k in range(1, len(labels) + 1):
        if k == len(labels) or labels[k] != labels[start]:
            out.append((start, k, str(labels[start])))
            start = k
    return out


#: Modes drawn in the classic root locus (``plot_modes(..., classic=True)``).
CLASSIC_MODES = ("weave", "wobble", "capsize")


def _classic_locus(fig, result: ModalResult) -> None:
    """One panel in the style of Sharp (1971): Re(lambda) against frequency, speeds written on the loci.

    The window holds the weave, wobble and capsize over the whole tracked
    range (tyre lags and other modes far to the left are cut off); each
    tracked branch is a line coloured by its name, the requested speeds are
    dots labelled with the speed, the unstable half-plane is shaded and the
    weave stability boundaries are marked where the weave crosses it.
    """
    from matplotlib.lines import Line2D

    ax = fig.add_subplot()
    gl, gl_lab = result.grid_eigenvalues, result.grid_labels
    z = gl[np.isin(gl_lab, CLASSIC_MODES) & (gl.imag >= 0)]
    lo, hi = min(float(z.real.min()), 0.0), max(float(z.real.max()), 0.0)
    pad = 0.08 * (hi - lo) + 0.1
    f_top = 1.12 * max(float(z.imag.max()) / (2 * np.pi), 1.0)
    shown = set()
    for j in range(gl.shape[1]):
        for a, b, lab in _runs(gl_lab[:, j]):
            seg = gl[a:b, j]
            if not np.any(seg.imag >= 0):
                continue
            ax.plot(np.where(seg.imag >= 0, seg.real, np.nan), np.where(seg.imag >= 0, seg.imag / (2 * np.pi), np.nan),
                    color=_COLOURS[lab], lw=1.8 if lab in CLASSIC_MODES else 1.0)
            shown.add(lab)
    for v, ev, labs in zip(result.speeds, result.eigenvalues, result.labels):
        for lam, lab in zip(ev, labs):
            if lab in CLASSIC_MODES and lam.imag >= 0:
                x, y = float(lam.real), float(lam.imag) / (2 * np.pi)
                ax.plot(x, y, "o", color=_COLOURS[lab], ms=4)
                ax.annotate(f"{v:g}", (x, y), xytext=(4, 3), textcoords="offset points", fontsize=8, color=_COLOURS[lab])
    for vs, kind in result.weave_boundaries():
        lam, sh = participation_shares(result._state_matrix(vs))
        f = max(float(w.imag) for w, lab in zip(lam, classify(lam, sh)) if lab == "weave") / (2 * np.pi)
        ax.annotate(f"weave {'stable above' if kind == 'stabilises' else 'unstable above'} {vs:.2f} m/s", (0.0, f),
                    xytext=(10, 22), textcoords="offset points", fontsize=8, color=_COLOURS["weave"],
                    arrowprops={"arrowstyle": "-", "color": _COLOURS["weave"], "lw": 0.6})
    ax.axvspan(0.0, hi + pad, color="tab:red", alpha=0.08, lw=0)
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(-0.02 * f_top, f_top)
    ax.set_xlabel("real part of eigenvalue [1/s]  (shaded: unstable)")
    ax.set_ylabel("frequency Im$\\lambda$/2$\\pi$ [Hz]")
    vmin, vmax = float(result.grid_speeds.min()), float(result.grid_speeds.max())
    ax.set_title(f"root locus of {result.vehicle_name}, {vmin:g}-{vmax:g} m/s (numbers: forward speed in m/s)"
                 + ("" if not result.effects else f", {result.effects!r}"))
    ax.grid(alpha=0.3)
    ax.legend(handles=[Line2D([], [], color=_COLOURS[lab], label=lab) for lab in LABELS if lab in shown],
              loc="center right", fontsize=8)


def plot_modes(result: ModalResult, path: str | Path | None = None, *, classic: bool = False):
    """Root locus and modal characteristics versus speed.

    Panels: (a) root locus over the valid speed range, colour = speed, marker
    = mode, requested speeds ringed, with a zoom on the weave and capsize;
    (b) real part vs speed per mode (symmetric-log axis, unstable half
    shaded); (c) damped frequency [Hz] vs speed of the oscillatory modes. The
    weave stability boundaries (:meth:`ModalResult.weave_boundaries`) are
    marked in (b) and (c).

    With ``classic=True`` the figure is instead one root locus in the style
    of Sharp (1971) and the textbooks since: real part against frequency
    [Hz] of the weave, wobble and capsize, speeds written on the loci at the
    requested speeds (:func:`_classic_locus`).

    Parameters
    ----------
    result : ModalResult
    path : str or Path, optional
        Where to write the figure (format from the suffix, e.g. ``.png``).
    classic : bool
        The one-panel classic root locus instead of the three panels.

    Returns
    -------
    matplotlib.figure.Figure
        Rendered with the Agg backend (no display needed).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    if not isinstance(result, ModalResult):
        raise ModesInputError(f"plot_modes takes a ModalResult, got {type(result).__name__}")
    if classic:
        fig = Figure(figsize=(8, 6.5), layout="constrained")
        FigureCanvasAgg(fig)
        _classic_locus(fig, result)
        if path is not None:
            fig.savefig(path, dpi=120)
        return fig
    fig = Figure(figsize=(14, 7), layout="constrained")
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, 2, width_ratios=(1.1, 1.0))
    ax_rl = fig.add_subplot(gs[:, 0])
    ax_re = fig.add_subplot(gs[0, 1])
    ax_f = fig.add_subplot(gs[1, 1], sharex=ax_re)
    zoom = ax_rl.inset_axes((0.09, 0.56, 0.38, 0.4))

    gv, gl, gl_lab = result.grid_speeds, result.grid_eigenvalues, result.grid_labels
    norm = Normalize(vmin=float(gv.min()), vmax=float(gv.max()))
    thin = slice(None, None, max(1, len(gv) // 150))
    sc = None
    for lab in LABELS:
        m = gl_lab[thin] == lab
        if not np.any(m):
            continue
        vv = np.broadcast_to(gv[thin][:, None], m.shape)[m]
        z = gl[thin][m]
        for ax in (ax_rl, zoom):
            sc = ax.scatter(z.real, z.imag, c=vv, cmap="viridis", norm=norm, marker=_MARKERS[lab], s=10, linewidths=0)
    for ev, labs in zip(result.eigenvalues, result.labels):
        for z, lab in zip(ev, labs):
            for ax in (ax_rl, zoom):
                ax.scatter(z.real, z.imag, marker=_MARKERS[lab], s=60, facecolors="none", edgecolors="k", linewidths=0.8)
    for ax in (ax_rl, zoom):
        ax.axvline(0.0, color="k", lw=0.8)
        ax.axhline(0.0, color="k", lw=0.4)
        ax.grid(alpha=0.3)
    weave = gl[gl_lab == "weave"]
    caps = gl[gl_lab == "capsize"]
    near = np.concatenate([weave, caps])
    zoom.set_xlim(min(near.real.min(), 0.0) - 0.5, max(near.real.max(), 0.0) + 0.5)
    zoom.set_ylim(-0.5, max(weave.imag.max(), 1.0) + 1.0)
    zoom.set_title("weave and capsize", fontsize=8)
    zoom.tick_params(labelsize=7)
    ax_rl.set_xlabel("Re $\\lambda$ [1/s]")
    ax_rl.set_ylabel("Im $\\lambda$ [rad/s]")
    ax_rl.set_title(f"(a) root locus, {result.vehicle_name}" + ("" if not result.effects else f", {result.effects!r}"))
    fig.colorbar(sc, ax=ax_rl, label="forward speed $v_x$ [m/s]", shrink=0.8)
    handles = [Line2D([], [], ls="", marker=_MARKERS[lab], color="0.35", label=lab) for lab in LABELS]
    handles.append(Line2D([], [], ls="", marker="o", mfc="none", mec="k", label="requested speeds"))
    ax_rl.legend(handles=handles, loc="lower left", fontsize=8)

    for j in range(gl.shape[1]):
        for a, b, lab in _runs(gl_lab[:, j]):
            seg = slice(a, b)
            ax_re.plot(gv[seg], gl[seg, j].real, color=_COLOURS[lab], lw=1.4)
            if lab in ("weave", "wobble") or np.any(gl[seg, j].imag > 0):
                f = np.where(gl[seg, j].imag > 0, gl[seg, j].imag / (2 * np.pi), np.nan)
                ax_f.plot(gv[seg], f, color=_COLOURS[lab], lw=1.4)
    ax_re.set_yscale("symlog", linthresh=5.0)
    ax_re.axhspan(0, ax_re.get_ylim()[1], color="tab:red", alpha=0.08, lw=0)
    ax_re.axhline(0.0, color="k", lw=0.8)
    ax_re.set_ylabel("Re $\\lambda$ [1/s] (symlog)")
    ax_re.set_title("(b) real part vs speed (shaded: unstable)")
    ax_f.set_ylabel("damped frequency [Hz]")
    ax_f.set_xlabel("forward speed $v_x$ [m/s]")
    ax_f.set_title("(c) frequency of the oscillatory modes")
    for n, (vs, kind) in enumerate(result.weave_boundaries()):
        for ax in (ax_re, ax_f):
            ax.axvline(vs, color=_COLOURS["weave"], ls="--", lw=1.0)
        text = f"weave stable above {vs:.2f} m/s" if kind == "stabilises" else f"weave unstable above {vs:.2f} m/s"
        left = vs < 0.7 * float(gv.max())
        ax_re.annotate(text, xy=(vs, 0.0), xytext=(4 if left else -4, 6 + 11 * n), textcoords="offset points",
                       color=_COLOURS["weave"], fontsize=8, ha="left" if left else "right")
    for ax in (ax_re, ax_f):
        ax.grid(alpha=0.3)
    ax_re.legend(handles=[Line2D([], [], color=_COLOURS[lab], label=lab) for lab in LABELS], fontsize=8,
                 loc="lower left", ncol=3)
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig


__all__ = [
    "GROUPS",
    "LABELS",
    "ModalResult",
    "ModesInputError",
    "classify",
    "eigen_analysis",
    "participation_factors",
    "participation_shares",
    "plot_modes",
]
