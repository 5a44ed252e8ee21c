"""Levant's robust exact differentiator (assist.unknown_input.differentiator): gains, finite-time exactness,
and the accuracy asymptotics of Levant (2003) / Livne & Levant (2014) with sampling and noise."""

from __future__ import annotations

import numpy as np
import pytest

from assist.unknown_input.differentiator import (
    DifferentiatorError,
    LevantDifferentiator,
    accuracy_scale,
    default_gains,
    differentiate,
    estimate_lipschitz,
    recursive_to_nonrecursive,
)


# ---------------------------------------------------------------------------
# gains: the paper's recursive parameters against Levant & Livne's published non-recursive table
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "order, table",
    [
        (1, (1.1, 1.5)),
        (2, (1.1, 2.12, 2.0)),
        (3, (1.1, 3.06, 4.16, 3.0)),
        (4, (1.1, 4.57, 9.30, 10.03, 5.0)),
        (5, (1.1, 6.75, 20.26, 32.24, 23.72, 7.0)),
    ],
)
def test_default_gains_match_levant_livne_table(order, table):
    assert np.allclose(default_gains(order), table, atol=0.006)


def test_paper_recursive_gains_eq_8_and_14():
    # eq. (8): 3, 2, 1.5, 1.1 (order 3); eq. (14): 2, 1.5, 1.1 (order 2)
    assert np.allclose(recursive_to_nonrecursive((1.1, 1.5, 2.0, 3.0)), (1.1, 1.5 * (2 * 3 ** (2 / 3)) ** 0.5,
                                                                          2 * 3 ** (2 / 3), 3.0))
    assert np.allclose(recursive_to_nonrecursive((1.1, 1.5, 2.0)), (1.1, 1.5 * 2 ** 0.5, 2.0))


def test_recursive_and_nonrecursive_forms_are_the_same_vector_field():
    # evaluate both right-hand sides at random points: recursive form of [1] eq. (11) vs ours
    rng = np.random.default_rng(0)
    lam = (1.1, 1.5, 2.0, 3.0)
    kappa = recursive_to_nonrecursive(lam)
    n, L = 3, 7.0
    sg = lambda e, a: np.abs(e) ** a * np.sign(e)  # noqa: E731
    for _ in range(20):
        z = rng.normal(size=n + 1)
        f = rng.normal()
        # recursive
        v = []
        prev = f
        for i in range(n):
            k = n - i
            vi = -lam[k] * L ** (1 / (k + 1)) * sg(z[i] - prev, k / (k + 1)) + z[i + 1]
            v.append(vi)
            prev = vi
        v.append(-lam[0] * L * np.sign(z[n] - prev))
        # non-recursive
        e = z[0] - f
        w = [-kappa[n - i] * L ** ((i + 1) / (n + 1)) * sg(e, (n - i) / (n + 1)) + z[i + 1] for i in range(n)]
        w.append(-kappa[0] * L * np.sign(e))
        assert np.allclose(v[:n], w[:n], rtol=1e-12, atol=1e-12)
        assert np.sign(v[n]) == np.sign(w[n])  # sign(z_n - v_{n-1}) == sign(e) in the recursive form


# ---------------------------------------------------------------------------
# exactness without noise
# ---------------------------------------------------------------------------
def _poly_truth(t):
    # f = 1 + 2 t - t^2 + t^3/3: f''' = 2, f'''' = 0
    return np.stack([1 + 2 * t - t**2 + t**3 / 3, 2 - 2 * t + t**2, -2 + 2 * t, 2 + 0 * t], axis=1)


@pytest.mark.parametrize("estimate", ["posterior", "prior"])
def test_polynomial_derivatives_exact_in_the_limit_after_finite_time(estimate):
    # order 3 on a cubic (f'''' = 0 <= L): after a finite time the error is the sampling band
    # mu_i L tau^(4-i), which vanishes as tau -> 0 at the rate the theory gives
    n, L = 3, 2.0
    errs, t_hit = [], []
    for tau in (4e-3, 2e-3, 1e-3):
        t = np.arange(0, 8, tau)
        F = _poly_truth(t)
        z = differentiate(F[:, 0], tau, n, L, estimate=estimate)
        err = np.abs(z - F)
        late = t >= 5.0
        errs.append(err[late].max(axis=0))
        # finite-time convergence: first time the velocity error stays below 1e-2
        bad = np.nonzero(err[:, 1] > 1e-2)[0]
        t_hit.append(t[bad[-1] + 1])
    errs = np.array(errs)
    for i in range(n + 1):
        ratio = errs[:-1, i] / errs[1:, i]
        assert np.all(ratio > 0.6 * 2 ** (n + 1 - i)), (i, ratio)
        assert np.all(ratio < 1.6 * 2 ** (n + 1 - i)), (i, ratio)
    assert errs[-1, 3] < 0.02 and errs[-1, 2] < 1e-3 and errs[-1, 1] < 1e-5
    # the convergence time does not depend on the step (a continuous-time property)
    assert max(t_hit) < 5.0 and (max(t_hit) - min(t_hit)) < 0.25 * max(t_hit)


def test_sampling_accuracy_orders_on_a_sine():
    # |f^(n+1)| <= 1 = L: the error of derivative i scales as tau^(n+1-i)
    for n in (1, 2):
        errs = []
        for tau in (1e-2, 5e-3, 2.5e-3):
            t = np.arange(0, 12, tau)
            z = differentiate(np.sin(t), tau, n, 2.0)
            truth = np.stack([np.sin(t), np.cos(t), -np.sin(t)], axis=1)[:, : n + 1]
            errs.append(np.abs(z - truth)[t > 6].max(axis=0))
        errs = np.array(errs)
        for i in range(n + 1):
            slope = np.polyfit(np.log([1e-2, 5e-3, 2.5e-3]), np.log(errs[:, i]), 1)[0]
            assert abs(slope - (n + 1 - i)) < 0.35, (n, i, slope)


# ---------------------------------------------------------------------------
# accuracy with bounded noise
# ---------------------------------------------------------------------------
def test_noise_accuracy_exponents_match_theory():
    # |z_i - f^(i)| ~ L^(i/(n+1)) eps^((n+1-i)/(n+1)) when (eps/L)^(1/(n+1)) >> tau
    n, L, tau = 2, 1.0, 1e-3
    t = np.arange(0, 25, tau)
    eps = np.array([1e-2, 1e-3, 1e-4, 1e-5])
    rng = np.random.default_rng(0)
    f = np.sin(t)[:, None] + rng.uniform(-1, 1, size=(t.size, 1)) * eps
    z = differentiate(f, tau, n, L)
    truth = [np.sin(t), np.cos(t), -np.sin(t)]
    late = t > 10
    for i in range(n + 1):
        err = np.array([np.abs(z[late, j, i] - truth[i][late]).max() for j in range(eps.size)])
        slope = np.polyfit(np.log(eps), np.log(err), 1)[0]
        assert abs(slope - (n + 1 - i) / (n + 1)) < 0.1, (i, slope)
        # and the level is the theory's scale up to a modest constant mu_i
        scale = np.array([accuracy_scale(n, L, tau, e)[i] for e in eps])
        assert np.all(err / scale < 5.0) and np.all(err / scale > 0.2), (i, err / scale)


def test_batch_with_per_signal_lipschitz_equals_separate_runs():
    tau = 0.01
    t = np.arange(0, 3, tau)
    sig = np.stack([np.sin(t), 2 * np.cos(3 * t)], axis=1)
    Ls = np.array([2.0, 60.0])
    zb = differentiate(sig, tau, 2, Ls)
    for j in range(2):
        zs = differentiate(sig[:, j], tau, 2, Ls[j])
        assert np.allclose(zb[:, j], zs, rtol=0, atol=1e-12)


def test_estimate_lipschitz_of_a_sine():
    tau, w = 1e-3, 3.0
    t = np.arange(0, 5, tau)
    for n in (1, 2, 3):
        assert estimate_lipschitz(np.sin(w * t), tau, n, margin=1.0) == pytest.approx(w ** (n + 1), rel=0.02)


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(order=-1, lipschitz=1.0, dt=0.01), "order"),
        (dict(order=1.5, lipschitz=1.0, dt=0.01), "order"),
        (dict(order=2, lipschitz=0.0, dt=0.01), "lipschitz"),
        (dict(order=2, lipschitz=1.0, dt=0.0), "dt"),
        (dict(order=2, lipschitz=1.0, dt=0.01, gains=(1.1, 1.5)), "gains"),
        (dict(order=2, lipschitz=1.0, dt=0.01, estimate="smooth"), "estimate"),
        (dict(order=9, lipschitz=1.0, dt=0.01), r"order must be an integer in \[0, 6\]"),
    ],
)
def test_bad_settings_raise(kwargs, match):
    with pytest.raises(DifferentiatorError, match=match):
        LevantDifferentiator(**kwargs)


def test_bad_samples_raise():
    d = LevantDifferentiator(2, 1.0, 0.01)
    d.update(np.zeros(3))
    with pytest.raises(DifferentiatorError, match="shape"):
        d.update(np.zeros(2))
    with pytest.raises(DifferentiatorError, match="not finite"):
        d.update(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(TypeError):
        LevantDifferentiator(2, 1.0, 0.01, gain=(1, 2, 3))  # unknown keyword rejected
