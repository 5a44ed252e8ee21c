r"""Extend the model beyond the table of effects (diagnose.md ``verdict.extension``).

When no cause of effects.md (alone or in a pair) explains a log, the diagnosis still extends the
model: it searches the library of closure terms :data:`assist.diagnose.params.CLOSURE_LIBRARY`
(generalised forces added to one equation of model.md, or a sensor offset or scale) for the
sparsest set that explains the residual, from the nominal model and from the table verdict
(:func:`best_extension` keeps the better: the verdict of a log with an effect outside the table is
often a table cause standing in for it), unless the nominal model's extension already explains the
log and beats the verdict, in which case the verdict's base is not searched.

Method: **forward selection on held-out output error**, one term at a time (at most
:data:`MAX_TERMS`):

1. every term not yet chosen is screened on a grid of sizes (``+-`` 0.5 to 16 typical sizes,
   batched, every other fitting window), and the :data:`REFINE_TOP` best are refined by
   :meth:`assist.diagnose.hypotheses.HypothesisFitter.refine` (least squares on the fitting
   windows, each window from its own least-squares initial state, jointly with the terms already
   chosen);
2. each refined model is replayed on the held-out windows and ranked against the current model by
   :func:`assist.diagnose.selection.rank`: a term is kept only if it is *supported* exactly as a
   table cause must be (held-out improvement at least ``MIN_IMPROVEMENT`` noise variances, not
   resting on a few windows, paying ``PARAM_PENALTY`` for its coefficient);
3. the selection stops when no term is supported, when the extended model explains the log to
   within the noise, or after :data:`MAX_TERMS`.

Why not SINDy's sequentially thresholded least squares (pysindy) on the equations: that is an
*equation-error* regression, which needs the derivatives of all states (``vy`` and the tire forces
are not measured, ``phi`` only through a filter on real data) and, on closed-loop data from an
open-loop-unstable vehicle, is biased by the noise the feedback feeds back into the regressors.
The output-error fit over short windows (:mod:`assist.diagnose.replay`) needs neither, and
selecting terms by *held-out* prediction error is cross-validated sparsity: the thresholding step
of STLSQ replaced by the same acceptance test every table cause passes. The coefficients'
standard deviations come from the weighted-residual Jacobian at the optimum,
``std = sqrt(diag((J^T J)^-1) s^2)`` with ``s^2`` the residual variance per value (1 when the
model explains the log to within the noise; larger when it does not, which widens them honestly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import selection
from .hypotheses import Fit, Hypothesis, HypothesisFitter
from .params import CLOSURE_INDEX, CLOSURE_LIBRARY, CLOSURES

#: Most closure terms an extension may hold.
MAX_TERMS = 3
#: Screened terms refined at each step of the selection.
REFINE_TOP = 3
#: Screening sizes in typical sizes of each coefficient (both signs).
SCREEN_SIZES = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0)


@dataclass
class Extension:
    """A model extension: the closure terms chosen and what they buy on held-out data."""

    terms: list[dict]  #: diagnose.md: equation, term, coefficient, unit, std (and the term's name)
    z: np.ndarray  #: full parameter vector of the extended model (its base + closures)
    gain: float  #: held-out gain of the extended model over the nominal model
    gain_over_base: float  #: held-out gain over the model it extends
    S: float  #: held-out weighted sum of squares of the extended model
    base: list[dict] = field(default_factory=list)  #: the table causes it extends ([] : the nominal model)
    k_base: int = 0  #: free parameters of the base
    steps: list[dict] = field(default_factory=list)  #: per step: the candidates' held-out scores
    explains: bool = False  #: the search stopped because the extended model explains the log to within the noise

    @property
    def k(self) -> int:
        """Free parameters: the base's and one per closure term."""
        return self.k_base + len(self.terms)

    def to_json(self) -> dict:
        return {"terms": self.terms, "gain": round(float(self.gain), 4), "extends": self.base or "nominal model",
                "gain_over_what_it_extends": round(float(self.gain_over_base), 4), "selection": self.steps}


def _held_out(fitter: HypothesisFitter, Z: np.ndarray, test_w: np.ndarray, steps: int,
              x_alt: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Held-out weighted squares per (row, window, channel) and the fitted initial states; with
    ``x_alt`` the states start from the measured guess, from ``x_alt`` and from the states of the
    row that fits each window best (:meth:`assist.diagnose.replay.Replay.fit_states_from`).

    Known tilt: the nominal model and the table verdict the extension is compared with
    (``S_nominal``, ``S_verdict``) were scored from the measured start only, and more starts can
    only lower a sum of squares, so the comparison leans towards the extension. Scoring them with
    the same starts was tried: on the bicycle's real rides it kept extensions whose single-start
    gain is below their verdict's and whose models carry over worse to other runs (worst cross-run
    gain -3.3 instead of -0.62); the extra starts let the state fit absorb model error on a vehicle
    that is open-loop unstable. Left as is, said in the README."""
    if x_alt is None:
        rt, x = fitter.replay.fit_states(Z, test_w, steps=steps)
    else:
        rt, x = fitter.replay.fit_states_from(Z, test_w, x_alt, steps=steps, cross=True)
    return (rt**2).sum(axis=2), x  # (H, Wt, C), (H, Wt, NX)


def _usable(name: str, channels: tuple[str, ...]) -> bool:
    eq = CLOSURES[name].equation
    return not eq.startswith("sensor:") or eq.split(":", 1)[1] in channels


def extend(fitter: HypothesisFitter, base_z: np.ndarray, test_w: np.ndarray, counts: np.ndarray,
           channels: tuple[str, ...], S_nominal: float, explains, score_steps: int = 3) -> Extension | None:
    """Forward selection of closure terms on top of ``base_z`` (module docstring).

    Parameters
    ----------
    fitter : HypothesisFitter
        The fitter of the diagnosis (its replay, fitting windows, parameter set).
    base_z : ndarray
        Parameter vector of the table verdict (nominal for ``none``).
    test_w : ndarray of int
        Held-out windows.
    counts : ndarray, shape (Wt, C)
        Scored values per held-out window and channel.
    channels : tuple of str
    S_nominal : float
        Held-out weighted sum of squares of the nominal model (for the gain).
    explains : callable
        ``explains(z) -> bool``: whether a parameter vector explains the log to within the noise
        (the diagnosis's own test), to stop early.

    Returns
    -------
    Extension or None
        ``None`` when no term is supported.
    """
    ps = fitter.params
    chosen: list[str] = []
    z = np.array(base_z, dtype=float)
    steps_json: list[dict] = []
    fits: dict[str, Fit] = {}
    done = False  # stopped because the extended model explains the log
    S0, x0 = _held_out(fitter, z[None], test_w, score_steps)
    S_base, x_cur = float(S0.sum()), x0[0]
    for _ in range(MAX_TERMS):
        # the current model's states on the fitting windows: a second start of every candidate's
        # fit (a sharp closure, Coulomb friction, traps the fit from the measured states)
        x_fit = fitter.replay.fit_states(z[None], fitter.widx)[1][0]
        cands = [t.name for t in CLOSURE_LIBRARY if t.name not in chosen and _usable(t.name, channels)]
        if not cands:
            break
        # 1. screening: every candidate on the grid of sizes, one batch
        Z, owner = [z.copy()], [""]
        for c in cands:
            i = CLOSURE_INDEX[c]
            for k in SCREEN_SIZES:
                for sgn in (-1.0, 1.0):
                    v = z[i] + sgn * k * ps.scale[i]
                    if ps.lower[i] <= v <= ps.upper[i]:
                        zz = z.copy()
                        zz[i] = v
                        Z.append(zz)
                        owner.append(c)
        r, _ = fitter.replay.fit_states(np.array(Z), fitter.widx[::2])  # one start: it only ranks
        cost = np.einsum("mwkc,mwkc->m", r, r)
        best_of = {c: min((cost[j], j) for j, o in enumerate(owner) if o == c) for c in cands}
        top = sorted(cands, key=lambda c: best_of[c][0])[:REFINE_TOP]
        # 2. refine the best, jointly with the terms already chosen, on top of the table verdict
        names, zs = ["current"], [z]
        for c in top:
            hyp = Hypothesis(tuple(chosen) + (c,))
            f = fitter.refine(hyp, Z[best_of[c][1]], base=z, x_alt=x_fit)
            fits[c] = f
            names.append(c)
            zs.append(f.z)
        # every candidate's held-out states also start from the current model's (a second start:
        # a sharp closure such as Coulomb friction can trap the first one in a local minimum)
        S, xs = _held_out(fitter, np.array(zs), test_w, score_steps, x_cur)
        ranked = selection.rank(names, [()] + [(c,) for c in top], [0] + [1] * len(top), S, counts, channels)
        steps_json.append({"chosen_so_far": list(chosen),
                           "candidates": [{"term": rk.name, "improvement": round(rk.improvement, 4),
                                           "score": round(rk.score, 4), "supported": bool(rk.supported)}
                                          for rk in selection.order(ranked) if rk.name != "current"]})
        best = selection.choose(ranked)
        if best.name == "current" or not best.supported:
            break
        chosen.append(best.name)
        z = fits[best.name].z
        x_cur = xs[names.index(best.name)]
        if explains(z):
            done = True
            break
    if not chosen:
        return None
    # the extended model's coefficients with their uncertainty (weighted-residual Jacobian)
    std = fits[chosen[-1]].std(fitter.n_values)
    S_ext = float(_held_out(fitter, z[None], test_w, score_steps, x_cur)[0].sum())
    terms = []
    for j, c in enumerate(chosen):
        t, i = CLOSURES[c], CLOSURE_INDEX[c]
        sd = float(std[j]) if j < len(std) and math.isfinite(std[j]) else None
        terms.append({"name": c, "equation": t.equation, "term": t.term, "coefficient": ps.params[i].report(z[i]),
                      "unit": t.unit, "std": None if sd is None else float(f"{sd:.3g}")})
    return Extension(terms=terms, z=z, gain=1.0 - math.sqrt(S_ext / S_nominal) if S_nominal > 0 else 0.0,
                     gain_over_base=1.0 - math.sqrt(S_ext / S_base) if S_base > 0 else 0.0, S=S_ext,
                     steps=steps_json, explains=done)


def best_extension(fitter: HypothesisFitter, bases: list[tuple[list[dict], int, np.ndarray]], test_w: np.ndarray,
                   counts: np.ndarray, channels: tuple[str, ...], S_nominal: float, explains,
                   score_steps: int = 3, S_verdict: float | None = None, k_verdict: int = 0) -> Extension | None:
    """:func:`extend` from each base ``(causes, k, z)`` (the nominal model, the table verdict), and
    the better one by held-out improvement over nominal minus ``PARAM_PENALTY`` per parameter (its
    base's and its terms'): a table cause that stood in for an effect outside the table (a steering
    damping for Coulomb friction) must not be kept under the closures that explain it better.
    The table verdict itself (held-out ``S_verdict`` with ``k_verdict`` parameters) competes on the
    same score: an extension that does not beat it is not reported (``None``).

    The bases are tried in order, the sparsest first (the nominal model): once an extension explains the log to
    within the noise, the later bases are not tried, as :func:`extend` adds no term once its model explains
    the log and beats the table verdict's score (issue 19: the sparsest set that explains the residual).
    On the benchmark's 90 s urban log with a yaw gyro reading 1.2x (``scripts/bench_diagnose.py``, its "x replay"
    column, stored under ``docs/results/``) the nominal model with ``yaw_rate_scale`` explains it and the
    verdict's base is not searched."""
    n = float(counts.sum())
    best, best_score = None, -math.inf
    if S_verdict is not None:
        best_score = (S_nominal - S_verdict) / n - selection.PARAM_PENALTY * k_verdict
    for causes, k, z in bases:
        e = extend(fitter, z, test_w, counts, channels, S_nominal, explains, score_steps)
        if e is None:
            continue
        e.base, e.k_base = causes, k
        score = (S_nominal - e.S) / n - selection.PARAM_PENALTY * e.k
        if score > best_score:
            best, best_score = e, score
        if best is e and e.explains:
            break
    return best


__all__ = ["Extension", "extend", "best_extension", "MAX_TERMS", "REFINE_TOP", "SCREEN_SIZES"]
