"""Fit each cause of effects.md, alone and in pairs, to the fitting windows of a log.

A hypothesis is a set of causes (:data:`assist.diagnose.params.CAUSES`);
its free parameters are those causes' parameters, every other parameter stays
nominal. Fitting minimises the noise-weighted multi-step prediction error of
the fitting windows (:class:`assist.diagnose.replay.Replay`, each window
with its own least-squares initial state):

.. math::

    \\hat\\theta_h = \\arg\\min_{\\theta} \\sum_{w \\in \\text{fit}} \\sum_{k,c}
      r_{w,k,c}(\\theta)^2, \\qquad
      r = (y - \\hat y(\\theta, \\hat x_{0,w}(\\theta))) / \\sigma_c .

Search (all through the batched simulator, never a Python loop over vehicles):

1. **screening**: every single cause on a coarse grid of sizes
   (:attr:`assist.diagnose.params.ParamSet.grids`, in units of the vehicle), all causes and sizes batched (``candidates x windows``
   vehicles, array-valued effect parameters), on every other fitting window;
2. **refinement**: :func:`scipy.optimize.least_squares` (trust-region
   reflective, bounded) from the best grid point; its Jacobian is forward
   differences computed in *one* batched simulation per iteration (one
   vehicle per window and perturbed parameter);
3. **pairs** (forward selection): the best single cause with the next five
   single causes, with the three causes a score test finds would add most to
   it (a second effect can be outranked alone by causes that mimic a large
   first one), and the pairs among the three best; only causes that improve
   the fit alone (:data:`PAIR_MIN`) take part. Each pair starts from the two
   single-cause optima (or the better of them alone) and is refined the same
   way. (All 45 pairs on request.)
"""

from __future__ import annotations

import math

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .params import CAUSES, GRIDS, N_TABLE, PARAMS, cause_indices
from .replay import STATE_STEPS, Replay, keep_better

#: Relative forward-difference step of the Jacobian (fraction of each parameter's scale).
FD_STEP = 1e-3
#: A pair is fitted only when each of its causes alone improves the fitting windows by this much
#: (mean square, units of the noise variance): a cause that explains nothing alone is not
#: worth a second parameter set (``pairs="all"`` in :func:`assist.diagnose.diagnose` fits them all).
PAIR_MIN = 0.01
#: Pairs among this many best single causes are fitted, and the best with this many next ones.
PAIR_TOP = 3
PAIR_PARTNERS = 5
#: ... and with this many that a score test from the best finds would add most to it.
PAIR_PARTNERS_SCORE = 3
#: Re-linearisations of the initial-state fit per evaluated model in :meth:`HypothesisFitter.refine`
#: (0: the sensitivity at the measured start states only). A model far from the log (an effect
#: outside effects.md, a wrong cause) makes the speed correction large in the odd low-speed window,
#: where the outputs depend on it and the states bilinearly; the Gauss-Newton steps with the start
#: sensitivity then stop short of the window's optimum (e.g. 10 % of the cost left for steering
#: friction fitted as steer_damping), the objective over-states such a model's misfit, and its
#: finite-difference Jacobian (one step from there) can point the wrong way, so the refinement may
#: stop before the best size (measured: 22.9 / 30.0 / 33.1 N m s/rad from starts 20 / 30 / 40, against
#: 32.8-33.6 with one re-linearisation). A right model starts close to its optimum and is hardly
#: affected (with 0, the slow sweep sizes every hidden effect of effects.md within 5.2 % of its size).
#: 1 costs ~50 % more simulation per diagnosis (24.7 M instead of 16.2 M vehicle-steps on a 90 s
#: urban log); the verdict's residual is judged after two linearisations either way
#: (:func:`assist.diagnose.diagnose`), so a short fit can only leave *more* residual, never hide one.
RELINEARISE = 0
#: Function evaluations allowed per hypothesis refinement (scipy ``max_nfev``).
MAX_NFEV = 30
#: Termination of the refinement (scipy ``ftol``, ``xtol``). The selection prices everything in noise
#: variances per value (a parameter costs ``PARAM_PENALTY`` = 0.01, a verdict needs 0.02): the
#: refinement stops when a step gains less than ``FTOL`` = 0.001 noise variances per value, ten times
#: below the smallest price it tells apart (scipy's relative ``ftol`` is set to ``FTOL n / cost`` at
#: the start, at most ``FTOL``: a model far from the log is refined as finely). The refinement is
#: solved in units of each parameter's typical size (:data:`assist.diagnose.params.SCALE`), where
#: scipy's ``xtol`` stops at a step below 0.1 % of the norm of the parameter vector, the same for
#: every parameter (in the parameters' own units a pair's small one could stop while still moving
#: by its own size). 1e-2 there stopped a Coulomb-friction closure at -1.64 N m for -1.59 (tight
#: tolerances and 1e-3 agree). Against the former ``ftol`` 1e-6 / ``xtol`` 1e-5 in the parameters' own
#: units: the same verdicts on the eight 90 s logs of ``scripts/bench_diagnose.py`` (its timings are
#: in the README).
FTOL = 1e-3
XTOL = 1e-3



@dataclass(frozen=True)
class Hypothesis:
    """A set of causes of effects.md (empty: ``none``)."""

    causes: tuple[str, ...]

    @property
    def idx(self) -> tuple[int, ...]:
        """Indices of the free parameters in :data:`assist.diagnose.params.PARAMS`."""
        return tuple(i for c in self.causes for i in cause_indices(c))

    @property
    def k(self) -> int:
        """Number of free parameters."""
        return len(self.idx)

    @property
    def name(self) -> str:
        return "+".join(self.causes) if self.causes else "none"


def all_hypotheses(pairs: bool = True) -> list[Hypothesis]:
    """``none``, every single cause, and (``pairs``) every pair, in effects.md order."""
    singles = list(CAUSES)
    out = [Hypothesis(())] + [Hypothesis((c,)) for c in singles]
    if pairs:
        out += [Hypothesis(p) for p in itertools.combinations(singles, 2)]
    return out


@dataclass
class Fit:
    """A hypothesis fitted on the fitting windows."""

    hypothesis: Hypothesis
    z: np.ndarray  #: full internal parameter vector (nominal outside the hypothesis)
    cost: float  #: weighted sum of squared residuals on the fitting windows
    nfev: int = 0
    message: str = ""
    extra: dict = field(default_factory=dict)

    def std(self, n_values: int) -> np.ndarray:
        """Standard deviations of the fitted parameters (internal coordinates, the hypothesis's order) from
        the weighted-residual Jacobian ``J`` of the refinement: ``sqrt(diag((J^T J)^-1) s^2)``, ``s^2`` the
        residual variance per value ``cost / (n_values - k)`` (at least 1: the residuals are weighted by
        the noise, so a model that fits to within the noise has 1). NaN where ``J^T J`` is singular or no
        Jacobian was kept (Bard, Nonlinear Parameter Estimation, 1974, sec. 7-5)."""
        J = np.asarray(self.extra.get("jac", np.zeros((0, 0))), dtype=float)
        k = J.shape[1] if J.ndim == 2 else 0
        if k == 0:
            return np.full(self.hypothesis.k, math.nan)
        s2 = max(self.cost / max(n_values - k, 1), 1.0)
        try:
            cov = np.linalg.inv(J.T @ J) * s2
        except np.linalg.LinAlgError:
            return np.full(k, math.nan)
        return np.sqrt(np.clip(np.diag(cov), 0.0, None))


class HypothesisFitter:
    """Fits hypotheses on a replay's fitting windows (module docstring).

    Parameters
    ----------
    replay : Replay
    widx : ndarray of int
        The fitting windows.
    max_nfev : int
        Budget of :func:`scipy.optimize.least_squares` per hypothesis.
    """

    def __init__(self, replay: Replay, widx: np.ndarray, max_nfev: int = MAX_NFEV) -> None:
        self.replay = replay
        self.widx = np.asarray(widx)
        self.max_nfev = int(max_nfev)
        self.params = replay.params  # the vehicle's parameter set: nominal, bounds, scales, grids
        self.nominal_cost = float(self.costs(self.params.nominal[None])[0])
        self.n_values = int(replay.win.score[self.widx].sum())

    # -- evaluation -------------------------------------------------------------
    def residuals(self, Z: np.ndarray) -> np.ndarray:
        """Weighted residuals of the fitting windows, shape (m, Ws * n * C), one row per parameter vector."""
        r, _ = self.replay.fit_states(Z, self.widx)
        return r.reshape(r.shape[0], -1)

    def costs(self, Z: np.ndarray) -> np.ndarray:
        """Weighted sum of squares per parameter vector, shape (m,)."""
        r = self.residuals(Z)
        return np.einsum("ij,ij->i", r, r)

    # -- search -------------------------------------------------------------------
    def screen(self, causes: list[str]) -> dict[str, tuple[np.ndarray, float]]:
        """Best grid point of each single cause, on every other fitting window (a start for
        :meth:`refine`; all causes and sizes batched). cause -> (z, cost on those windows)."""
        nominal = self.params.nominal
        Z, owner = [nominal.copy()], ["none"]
        for c in causes:
            for combo in itertools.product(*self.params.grids[c]):
                z = nominal.copy()
                z[list(CAUSES[c])] = combo
                if not np.array_equal(z, nominal):
                    Z.append(z)
                    owner.append(c)
        r, _ = self.replay.fit_states(np.array(Z), self.widx[::2])  # every other fitting window
        cost = np.einsum("mwkc,mwkc->m", r, r)
        out = {}
        for c in causes:
            sel = [i for i, o in enumerate(owner) if o == c]
            j = sel[int(np.argmin(cost[sel]))]
            j = j if cost[j] < cost[0] else 0  # no grid point beats nominal: start there
            out[c] = (np.array(Z[j]), float(cost[j]))
        return out

    def refine(self, hyp: Hypothesis, z_start: np.ndarray, base: np.ndarray | None = None,
               x_alt: np.ndarray | None = None) -> Fit:
        """:func:`scipy.optimize.least_squares` on ``hyp``'s parameters from ``z_start``.

        Each evaluated model gets its own initial-state sensitivity (:meth:`Replay.linearise`)
        and :data:`STATE_STEPS` Gauss-Newton steps from the measured start states
        (:attr:`Replay.x_guess`, and for a saturating tire its own sideslip where its saturation
        asks for one: :meth:`Replay.fit_from_starts`). The Jacobian is variable projection by forward differences:
        every perturbed model re-fits the initial states by one Gauss-Newton step from the
        unperturbed optimum, and so does the unperturbed model itself (the difference then
        holds only the parameter's effect, not the last step's), all in one batched simulation.
        ``base``: the values of the parameters outside ``hyp`` (default nominal; a model extension
        is refined on top of the table verdict). The result keeps the weighted-residual Jacobian
        (``extra["jac"]``) for the parameters' uncertainty. ``x_alt`` (shape ``(Ws, NX)``): a
        second start of every window's initial-state fit (the states another model fitted), the
        better kept per window (:meth:`Replay.fit_states_from` says why: Coulomb friction).
        """
        idx = list(hyp.idx)
        k = len(idx)
        lo, hi, sc = self.params.lower[idx], self.params.upper[idx], self.params.scale[idx]
        rp, widx = self.replay, self.widx
        cache: dict[bytes, tuple[np.ndarray, np.ndarray, tuple]] = {}

        z_base = self.params.nominal if base is None else np.asarray(base, dtype=float)

        def full(P: np.ndarray) -> np.ndarray:
            Z = np.repeat(z_base[None], len(P), axis=0)
            Z[:, idx] = P
            return Z

        def evaluate(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
            key = q.tobytes()
            if key not in cache:
                cache.clear()
                Z = full(q[None])
                r, x, P = rp.fit_from_starts(Z, widx, STATE_STEPS)
                if x_alt is not None:
                    xa = np.asarray(x_alt, dtype=float)[None]
                    r0a, Pa = rp.linearise(Z, widx, xa)
                    ra, xa = rp.gauss_newton(Z, widx, xa, r0a, Pa, STATE_STEPS)
                    r, x, *P, _ = keep_better((r, x, *P), (ra, xa, *Pa))
                    P = tuple(P)
                for _ in range(RELINEARISE):
                    r0, P = rp.linearise(Z, widx, x)
                    r, x = rp.gauss_newton(Z, widx, x, r0, P, 1)
                cache[key] = (r.reshape(-1), x, P)
            return cache[key]

        def fun(q: np.ndarray) -> np.ndarray:
            return evaluate(q)[0]

        def jac(q: np.ndarray) -> np.ndarray:
            _, x, P = evaluate(q)
            h = FD_STEP * sc
            h = np.where(q + h > hi, -h, h)  # step inward at the upper bound
            Q = np.repeat(q[None], k + 1, axis=0)  # row 0: the unperturbed model, same procedure
            Q[np.arange(1, k + 1), np.arange(k)] += h
            Z = full(Q)
            xk = np.broadcast_to(x, (k + 1,) + x.shape[1:])
            Pk = tuple(np.broadcast_to(a, (k + 1,) + a.shape[1:]) for a in P)
            R, _ = rp.gauss_newton(Z, widx, xk, rp.residual(Z, widx, xk), Pk, 1, safeguard=False)
            R = R.reshape(k + 1, -1)
            return ((R[1:] - R[0][None]) / h[:, None]).T

        # solved in units of each parameter's typical size (q = sc q_h), so that scipy's xtol, which
        # compares the step with the norm of the parameter vector, means the same for every parameter
        p0 = np.clip(z_start[idx], lo, hi) / sc
        # scipy's ftol is relative to the cost; FTOL is per scored value (noise variances), so that a
        # model far from the log (an extension of an unexplained log) is refined as finely
        r_start = fun(p0 * sc)
        ftol = min(FTOL, max(1e-10, FTOL * self.n_values / max(float(r_start @ r_start), 1e-300)))
        res = least_squares(lambda qh: fun(qh * sc), p0, jac=lambda qh: jac(qh * sc) * sc[None, :],
                            bounds=(lo / sc, hi / sc), method="trf", max_nfev=self.max_nfev, xtol=XTOL,
                            ftol=ftol, gtol=1e-8)
        z = full((res.x * sc)[None])[0]
        return Fit(hyp, z, float(2.0 * res.cost), int(res.nfev), str(res.message),
                   extra={"jac": res.jac / sc[None, :]})

    def added_value(self, fit: Fit) -> dict[str, float]:
        """Score test: how much each other cause would add to ``fit`` (noise variances per value).

        From ``fit``'s parameters, every parameter of every other cause is moved by one typical
        size (:data:`assist.diagnose.params.SCALE`, inward at a bound: a secant, so that a cause
        whose effect starts quadratically, tire saturation, still shows), the initial states
        re-fitted by one Gauss-Newton step (all in one batched simulation), and the linearised
        best combination of each cause's moves gives its predicted improvement.
        """
        rp, widx = self.replay, self.widx
        z = fit.z
        own = set(fit.hypothesis.idx)
        others = [i for i in range(N_TABLE) if i not in own]  # the table's causes (closures: extension.py)
        scale, upper = self.params.scale, self.params.upper
        _, xb, P = rp.fit_from_starts(z[None], widx, STATE_STEPS)
        Q = np.repeat(z[None], len(others) + 1, axis=0)  # row 0: unmoved, same procedure
        for j, i in enumerate(others):
            Q[j + 1, i] += scale[i] if z[i] + scale[i] <= upper[i] else -scale[i]
        m = len(Q)
        xm = np.broadcast_to(xb, (m,) + xb.shape[1:])
        Pm = tuple(np.broadcast_to(a, (m,) + a.shape[1:]) for a in P)
        R, _ = rp.gauss_newton(Q, widx, xm, rp.residual(Q, widx, xm), Pm, 1, safeguard=False)
        R = R.reshape(m, -1)
        D = R[1:] - R[0][None]
        out = {}
        for c, ii in CAUSES.items():
            cols = [others.index(i) for i in ii if i in others]
            if not cols or c in fit.hypothesis.causes:
                continue
            A = D[cols].T
            a, *_ = np.linalg.lstsq(A, -R[0], rcond=None)
            out[c] = float((R[0] @ R[0] - np.sum((R[0] + A @ a) ** 2)) / self.n_values)
        return out

    def improvement(self, fit: Fit) -> float:
        """Fitting-window mean-square improvement over nominal, units of the noise variance."""
        return (self.nominal_cost - fit.cost) / self.n_values

    def fit_all(self, hypotheses: list[Hypothesis], progress=None, pair_min: float | None = PAIR_MIN) -> dict[str, Fit]:
        """Screen the single causes, refine them, then the pairs from the single optima. name -> Fit.

        Pairs (``pair_min`` not ``None``): forward selection among the single causes that alone
        improve the fitting windows by at least ``pair_min`` (noise variances per value), ranked
        by that improvement: the best paired with the next :data:`PAIR_PARTNERS`, with the
        :data:`PAIR_PARTNERS_SCORE` causes that would add most to it (:meth:`added_value`, a
        second effect whose own single fit is outranked by causes mimicking the first), plus
        the pairs among the :data:`PAIR_TOP` best. ``pair_min=None``: every pair.
        """
        nominal = self.params.nominal
        fits: dict[str, Fit] = {"none": Fit(Hypothesis(()), nominal.copy(), self.nominal_cost)}
        singles = [h for h in hypotheses if h.k and len(h.causes) == 1]
        multi = [h for h in hypotheses if len(h.causes) > 1]
        starts = self.screen([h.causes[0] for h in singles])
        for h in singles:
            z0, _ = starts[h.causes[0]]
            fits[h.name] = self.refine(h, z0)
            if progress is not None:
                progress.update(1)
        if pair_min is not None:
            # forward selection among the causes that improve the fit alone: the best one with
            # the next PAIR_PARTNERS, with the PAIR_PARTNERS_SCORE that would add most to it
            # (score test), and the pairs among the PAIR_TOP best
            ranked = [c for c in sorted((c for c in fits if c != "none"), key=lambda c: -self.improvement(fits[c]))
                      if self.improvement(fits[c]) >= pair_min]
            keep = {frozenset(p) for p in itertools.combinations(ranked[:PAIR_TOP], 2)}
            if ranked:
                best = ranked[0]
                keep |= {frozenset((best, c)) for c in ranked[1:1 + PAIR_PARTNERS]}
                added = self.added_value(fits[best])
                extra = sorted((c for c in added if added[c] >= pair_min), key=lambda c: -added[c])
                keep |= {frozenset((best, c)) for c in extra[:PAIR_PARTNERS_SCORE]}
            multi = [h for h in multi if frozenset(h.causes) in keep]
        if progress is not None:
            progress.total = len(singles) + len(multi)
            progress.refresh()
        for h in multi:
            # start from the best of: all parts at their single optima, or one part alone
            # (two effects that each fit alone may together drive the model unstable)
            starts = [nominal.copy()]
            for c in h.causes:
                ii = list(CAUSES[c])
                starts[0][ii] = fits[c].z[ii] if c in fits else nominal[ii]
                if c in fits:
                    z = nominal.copy()
                    z[ii] = fits[c].z[ii]
                    starts.append(z)
            cost = self.costs(np.array(starts))
            fits[h.name] = self.refine(h, starts[int(np.argmin(cost))])
            if progress is not None:
                progress.update(1)
        return fits


__all__ = ["Hypothesis", "Fit", "HypothesisFitter", "all_hypotheses", "GRIDS", "PARAMS"]
