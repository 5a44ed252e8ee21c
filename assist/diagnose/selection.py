r"""Rank the fitted hypotheses on held-out windows and pick the verdict.

Every hypothesis ``h`` (fitted on the fitting windows) is replayed on the
held-out windows, each with its own least-squares initial state. With
``S_h`` the noise-weighted sum of squared residuals there (``sum (e/sigma)^2``
over ``n`` scored values) and ``S_0`` that of the nominal model:

* **gain** ``= 1 - sqrt(S_h / S_0)``: the fractional reduction of the held-out
  RMS prediction error (0: no better than nominal, 1: perfect; negative:
  worse), overall and per channel;
* **improvement** ``Delta_h = (S_0 - S_h) / n``: the held-out mean-square
  error removed, in units of the noise variance;
* **penalised improvement** ``Delta_h - PARAM_PENALTY k_h`` with ``k_h`` free
  parameters. The penalty plays the role of BIC's ``k ln n``: BIC's ``ln n``
  per parameter assumes independent residuals, but replay residuals are
  correlated over a window (initial-state fit, quantisation, speed
  reconstruction), which inflates every fitted improvement; a fixed price per
  parameter in noise units does not depend on the sampling rate or the log's
  length.
* **support**: a hypothesis is *accepted* (can be the verdict) only if its
  held-out improvement is at least :data:`MIN_IMPROVEMENT` (an effect whose
  RMS is a sizeable fraction of the noise), does not rest on a few windows
  (with the :data:`TRIM` share of the held-out windows that improve most left
  out, at least one window, the improvement of the others is still at least
  half of :data:`MIN_IMPROVEMENT`), and pays for its parameters (penalised
  improvement > 0). (A cause that only fits one peculiar manoeuvre fails; an
  effect that shows only in some manoeuvres, tire saturation in tight turns,
  say, passes: a rank test over windows would count every window where it
  cannot show as evidence against it.) A pair must, in addition, beat each of
  its two single causes in the same way (improvement and trimmed improvement
  *over that single cause*), and pay for the parameters it adds to it
  (``PARAM_PENALTY`` each, as a nested-model test must: without that price a
  pair that adds a 2 % stiffness change to a payload of the right size was
  accepted on a 0.002 noise-variance edge), else its better single cause
  stands. Each test is
  a margin ``m_i`` (noise variances per value) that must be ``>= 0``; the
  **support margin** is their minimum.
* **score**, the one number hypotheses are ranked by (``none`` scores 0):

  .. math::

      \text{score}_h = \begin{cases}
          \Delta_h - \text{PARAM\_PENALTY}\, k_h > 0 & \text{accepted,} \\
          \min(0, \min_i m_{h,i}) \le 0 & \text{not accepted,}
      \end{cases}

  so the accepted hypotheses come first, by penalised improvement, then
  ``none``, then the others by how far they fall short of acceptance (a pair
  that fits as well as its better single cause but adds nothing to it scores
  just below 0, however large its improvement over nominal). The report lists
  them in this order (ties: fewer parameters, then the name).

The verdict is the best-scoring hypothesis: an accepted one, else ``none``.
It *explains* the log when its held-out residual is at the noise level:
every channel's RMS residual within ``1 + EXPLAINED_TOL`` of the noise
level (:mod:`assist.diagnose.noise`), i.e. what is left beyond the noise
is below ``sqrt((1 + EXPLAINED_TOL)^2 - 1)`` ~ 35 % of it. (A right model
replays the simulator's own noisy logs at 1.00-1.03 times the noise: the
rest is the speed channel's error and the initial-state fit.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Price of one free parameter in held-out mean-square improvement, units of the noise variance.
PARAM_PENALTY = 0.01
#: Smallest held-out improvement a verdict needs, units of the noise variance.
MIN_IMPROVEMENT = 0.02
#: Share of the held-out windows left out (the most improved, at least one) for the robustness
#: part of the support test.
TRIM = 0.1
#: Largest ratio of held-out RMS residual to noise level, minus 1, of an explained channel.
EXPLAINED_TOL = 0.06


@dataclass(frozen=True)
class Ranked:
    """One hypothesis's held-out evidence (module docstring)."""

    name: str
    causes: tuple[str, ...]
    k: int
    gain: float
    gain_channels: dict[str, float]
    improvement: float  #: held-out mean-square improvement over nominal [noise variances per value]
    trimmed: float  #: improvement without the most improved held-out windows (TRIM)
    penalised: float  #: improvement - PARAM_PENALTY * k (0 for none)
    margin: float  #: support margin: the smallest margin of the acceptance tests (>= 0: all pass)
    score: float  #: the ranking key (module docstring)
    supported: bool  #: accepted: can be the verdict


def _trimmed(d: np.ndarray, n: np.ndarray) -> float:
    """Mean improvement per value without the :data:`TRIM` share of windows that improve most.

    ``d``: improvement per window (sum over its values), ``n``: values per window."""
    k = max(1, int(round(TRIM * len(d))))
    if len(d) <= k:
        return -math.inf
    keep = np.argsort(-d, kind="stable")[k:]
    return float(d[keep].sum() / n[keep].sum())


def _margins(d: np.ndarray, n: np.ndarray) -> tuple[float, float, float]:
    """Improvement, trimmed improvement and the support margin
    ``min(imp - MIN_IMPROVEMENT, trimmed - MIN_IMPROVEMENT / 2)`` of per-window improvements ``d``."""
    imp = float(d.sum() / n.sum())
    tr = _trimmed(d, n)
    return imp, tr, min(imp - MIN_IMPROVEMENT, tr - 0.5 * MIN_IMPROVEMENT)


def rank(names: list[str], causes: list[tuple[str, ...]], ks: list[int], S: np.ndarray, counts: np.ndarray,
         channels: tuple[str, ...]) -> list[Ranked]:
    """Evidence and score of each hypothesis (module docstring); ``names[0]`` must be ``none``.

    Parameters
    ----------
    names : list of str
        Hypothesis names (``"a+b"`` for a pair).
    causes : list of tuple of str
        The causes of each hypothesis.
    ks : list of int
        Free parameters of each hypothesis.
    S : ndarray, shape (H, Wt, C)
        Held-out weighted sums of squares per hypothesis, window and channel.
    counts : ndarray, shape (Wt, C)
        Scored values per window and channel.
    channels : tuple of str
        The C channels.

    Returns
    -------
    list of Ranked
        In the order of ``names`` (:func:`order` sorts them by score).
    """
    nw = counts.sum(axis=1).astype(float)  # values per held-out window
    Sw = S.sum(axis=2)  # (H, Wt)
    S0 = float(Sw[0].sum())
    Sc0 = S[0].sum(axis=0)
    by_name = {n: i for i, n in enumerate(names)}
    out = []
    for h, name in enumerate(names):
        Sh = float(Sw[h].sum())
        gain = 1.0 - math.sqrt(Sh / S0) if S0 > 0 else 0.0
        gc = {c: (1.0 - math.sqrt(float(S[h, :, i].sum()) / Sc0[i]) if Sc0[i] > 0 else 0.0)
              for i, c in enumerate(channels)}
        if h == 0:
            out.append(Ranked(name, causes[h], ks[h], gain, gc, 0.0, 0.0, 0.0, 0.0, 0.0, False))
            continue
        imp, tr, margin = _margins(Sw[0] - Sw[h], nw)
        penalised = imp - PARAM_PENALTY * ks[h]
        margin = min(margin, penalised)
        if len(causes[h]) > 1:  # a pair must also beat each of its single causes
            for c in causes[h]:
                j = by_name.get(c)
                if j is not None:
                    added = PARAM_PENALTY * (ks[h] - ks[j])  # the price of what the pair adds
                    margin = min(margin, _margins(Sw[j] - Sw[h], nw)[2] - added)
        ok = margin >= 0.0 and penalised > 0.0
        score = penalised if ok else min(0.0, margin)
        out.append(Ranked(name, causes[h], ks[h], gain, gc, imp, tr, penalised, margin, score, ok))
    return out


#: Causes whose effects look alike unless the ride reaches the friction limit: a lower cornering
#: stiffness and a saturating tire (``Fmax tanh(F_lin / Fmax)``, effects.md) both lower the lateral
#: force at a given slip; only a force that stops growing with slip in the corners tells the
#: saturation apart. When the held-out data do not separate the two, the report says so.
CONFUSABLE: tuple[tuple[str, str], ...] = (("tire_stiffness", "tire_saturation"),)


def ambiguity(ranked: list[Ranked], verdict: Ranked, S: np.ndarray, counts: np.ndarray) -> tuple[Ranked, float] | None:
    """The rival of a single-cause ``verdict`` that the held-out data do not separate from it.

    For a verdict ``A`` in a :data:`CONFUSABLE` pair ``(A, B)`` whose other member ``B`` gains on
    the log too (held-out improvement over nominal at least :data:`MIN_IMPROVEMENT`), ``A`` is
    *separated* from ``B`` when it beats ``B`` as a pair must beat its single cause: improvement of
    ``A`` over ``B`` at least :data:`MIN_IMPROVEMENT` noise variances per value and, without the
    :data:`TRIM` share of the windows where it gains most, at least half of that (the support
    margin of :func:`rank`, with ``B`` in place of the nominal model), less ``PARAM_PENALTY`` for
    each parameter ``A`` has beyond ``B``'s. Returns ``(B, margin)`` when that margin is negative
    (ambiguous), else ``None``. ``S``, ``counts``: as :func:`rank`, rows in the order of ``ranked``.
    """
    if len(verdict.causes) != 1:
        return None
    a = verdict.causes[0]
    rivals = [b for pair in CONFUSABLE if a in pair for b in pair if b != a]
    by_causes = {r.causes: h for h, r in enumerate(ranked)}
    ha = by_causes.get(verdict.causes)
    nw = counts.sum(axis=1).astype(float)
    Sw = S.sum(axis=2)
    for b in rivals:
        hb = by_causes.get((b,))
        if ha is None or hb is None or ranked[hb].improvement < MIN_IMPROVEMENT:
            continue
        margin = _margins(Sw[hb] - Sw[ha], nw)[2] - PARAM_PENALTY * max(0, verdict.k - ranked[hb].k)
        if margin < 0.0:
            return ranked[hb], margin
    return None


def order(ranked: list[Ranked]) -> list[Ranked]:
    """Best first: by score (ties: fewer parameters, then the name); ``none`` leads the score-0 ties."""
    return sorted(ranked, key=lambda r: (-r.score, r.k, r.name))


def choose(ranked: list[Ranked]) -> Ranked:
    """The verdict: the best-scoring hypothesis, an accepted one or else ``none`` (``ranked[0]``)."""
    best = order(ranked)[0]
    return best if best.supported else ranked[0]


__all__ = ["Ranked", "rank", "choose", "order", "ambiguity", "CONFUSABLE", "PARAM_PENALTY", "MIN_IMPROVEMENT", "TRIM", "EXPLAINED_TOL"]
