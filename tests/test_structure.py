"""Structural tools (assist.unknown_input.structure) on textbook systems with known answers, and the
scooter case analysis (assist.unknown_input.observability) against the paper and independent computations."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg as sla
from scipy import signal
from scipy.optimize import linear_sum_assignment

from assist.unknown_input.observability import (
    CASES,
    WORKING_CASE,
    ObservabilityError,
    format_report,
    observability_report,
    ptw_triplet,
)
from assist.unknown_input.structure import (
    StructureError,
    analyse,
    decoupling_matrix,
    invariant_zeros,
    normal_rank,
    relative_degree,
    toeplitz_strong_observability,
    weakly_unobservable_subspace,
    zeros_from_subspace,
)
from ptw_env.vehicle import REFERENCE_SCOOTER


def canonical(num, den):
    """Controllable canonical realisation (A, D, C) of num(s)/den(s), deg num < deg den."""
    A, B, C, _ = signal.tf2ss(num, den)
    return A, B, C


def block_diag_systems(*systems):
    A = sla.block_diag(*[s[0] for s in systems])
    D = sla.block_diag(*[s[1] for s in systems])
    C = sla.block_diag(*[s[2] for s in systems])
    return A, D, C


def same_set(a, b, tol=1e-6):
    """Equal as multisets of complex numbers (optimal matching, relative tolerance)."""
    a = np.asarray(a, dtype=complex).ravel()
    b = np.asarray(b, dtype=complex).ravel()
    if a.shape != b.shape:
        return False
    if a.size == 0:
        return True
    cost = np.abs(a[:, None] - b[None, :])
    i, j = linear_sum_assignment(cost)
    return bool(np.all(cost[i, j] <= tol * (1.0 + np.abs(b[j]))))


# ---------------------------------------------------------------------------
# SISO textbook cases: zeros are the roots of the numerator
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "num, den, zeros, r",
    [
        ([1, 2], np.poly([-1, -3, -4]), [-2], 2),
        ([1, -1], np.poly([-1, -2, -3]), [1], 2),
        ([2, 3, 5], np.poly([-1, -2, -3, -4]), np.roots([2, 3, 5]), 2),
        ([1], np.poly([-1, -2, -3]), [], 3),
        ([1, 0, 4, 0], np.poly([-1, -2, -3, -5]), [0, 2j, -2j], 1),
    ],
)
def test_siso_zeros_are_numerator_roots(num, den, zeros, r):
    A, D, C = canonical(num, den)
    z = invariant_zeros(A, D, C)
    assert same_set(z, zeros)
    zpk_zeros, _, _ = signal.tf2zpk(num, den)  # scipy's own answer
    assert same_set(z, zpk_zeros)
    assert relative_degree(A, D, C) == (r,)
    rep = analyse(A, D, C)
    assert rep.left_invertible
    assert rep.strongly_observable == (len(zeros) == 0)
    assert rep.strongly_detectable == bool(np.all(np.real(zeros) < 0))


def test_relative_degree_n_means_strongly_observable_prop_3_1():
    # [1] Prop. 3.1: r = n <=> no invariant zeros <=> strongly observable
    A = np.diag([-1.0, -2.0, -3.0, -4.0]) + np.diag([1.0, 1.0, 1.0], 1)
    D = np.array([0, 0, 0, 1.0])
    C = np.array([1.0, 0, 0, 0])
    rep = analyse(A, D, C)
    assert rep.relative_degree == (4,)
    assert rep.zeros.size == 0 and rep.strongly_observable
    assert toeplitz_strong_observability(A, D, C)
    # measuring the last state instead: r = 1, three zeros (the eigenvalues of the chain above it)
    rep2 = analyse(A, D, np.array([0, 0, 0, 1.0]))
    assert rep2.relative_degree == (1,)
    assert same_set(rep2.zeros, [-1, -2, -3])
    assert not toeplitz_strong_observability(A, D, np.array([0, 0, 0, 1.0]))


# ---------------------------------------------------------------------------
# MIMO cases
# ---------------------------------------------------------------------------
def test_block_diagonal_square_system_zeros_and_vector_relative_degree():
    s1 = canonical([1, 2], np.poly([-1, -3]))  # zero -2, r = 1
    s2 = canonical([1, -5], np.poly([-4, -6, -7]))  # zero +5, r = 2
    A, D, C = block_diag_systems(s1, s2)
    rep = analyse(A, D, C)
    assert same_set(rep.zeros, [-2, 5])
    assert rep.relative_degree == (1, 2)
    assert rep.has_vector_relative_degree and rep.decoupling_rank == 2
    assert len(rep.zeros) == A.shape[0] - sum(rep.relative_degree)  # n - |r| zeros (normal form)
    assert rep.left_invertible and not rep.strongly_detectable
    s2b = canonical([1, 5], np.poly([-4, -6, -7]))
    rep_b = analyse(*block_diag_systems(s1, s2b))
    assert same_set(rep_b.zeros, [-2, -5]) and rep_b.strongly_detectable and not rep_b.strongly_observable


def test_tall_system_has_only_the_common_zero():
    # y1 = (s+1)(s+2)/den, y2 = (s+1)(s+3)/den share only s = -1: a square generalised
    # eigenvalue problem cannot be posed (p = 2, q = 1), the reduction handles it
    den = np.poly([-4, -5, -6])
    A, D, C1 = canonical(np.poly([-1, -2]), den)
    _, _, C2 = canonical(np.poly([-1, -3]), den)
    C = np.vstack([C1, C2])
    rep = analyse(A, D, C)
    assert same_set(rep.zeros, [-1])
    assert rep.strongly_detectable and not rep.strongly_observable
    assert rep.relative_degree == (1, 1) and not rep.has_vector_relative_degree
    # the weakly unobservable subspace is one-dimensional and carries the zero
    V = weakly_unobservable_subspace(A, D, C)
    assert V.shape[1] == 1
    assert same_set(zeros_from_subspace(A, D, V), [-1])
    # no common zero: strongly observable, and Molinari's independent rank test agrees
    _, _, C3 = canonical(np.poly([-7, -8]), den)
    C_obs = np.vstack([C1, C3])
    assert analyse(A, D, C_obs).strongly_observable
    assert toeplitz_strong_observability(A, D, C_obs)


def test_not_left_invertible_is_neither_observable_nor_detectable():
    # two unknown inputs and one output: the pencil never reaches n + rank D
    A = np.diag([-1.0, -2.0, -3.0])
    D = np.array([[1.0, 0], [0, 1.0], [0, 0]])
    C = np.array([[1.0, 1.0, 1.0]])
    rep = analyse(A, D, C)
    assert not rep.left_invertible
    assert rep.normal_rank < A.shape[0] + rep.rank_D
    assert not rep.strongly_detectable and not rep.strongly_observable
    assert rep.max_zero_real == np.inf
    # an input the output never sees (D column in an unobserved direction) also breaks it
    rep2 = analyse(np.diag([-1.0, -2.0]), np.array([0.0, 1.0]), np.array([1.0, 0.0]))
    assert rep2.relative_degree == (None,)
    assert not rep2.strongly_detectable


def test_zeros_invariant_under_feedback_and_output_injection():
    rng = np.random.default_rng(7)
    n, q, p = 6, 2, 2
    A = rng.normal(size=(n, n))
    D = rng.normal(size=(n, q))
    C = rng.normal(size=(p, n))
    z = invariant_zeros(A, D, C)
    assert z.size == n - 2  # generic square system: relative degree [1, 1]
    F = rng.normal(size=(q, n))
    K = rng.normal(size=(n, p))
    assert same_set(invariant_zeros(A + D @ F + K @ C, D, C), z, tol=1e-6)
    # square case: equal to the finite generalised eigenvalues of the Rosenbrock pencil
    M = np.block([[A, D], [C, np.zeros((p, q))]])
    N = sla.block_diag(np.eye(n), np.zeros((p, q)))
    w = sla.eigvals(M, N)
    assert same_set(z, w[np.isfinite(w)], tol=1e-6)
    # and to the eigenvalues of A + DF on V* (a different algorithm)
    V = weakly_unobservable_subspace(A, D, C)
    assert V.shape[1] == z.size
    assert same_set(zeros_from_subspace(A, D, V), z, tol=1e-6)


def test_random_tall_systems_strongly_observable_square_ones_not():
    rng = np.random.default_rng(3)
    for _ in range(5):
        n = int(rng.integers(3, 7))
        A, D = rng.normal(size=(n, n)), rng.normal(size=(n, 1))
        C_tall = rng.normal(size=(2, n))
        C_sq = rng.normal(size=(1, n))
        assert analyse(A, D, C_tall).strongly_observable
        assert toeplitz_strong_observability(A, D, C_tall)
        assert not analyse(A, D, C_sq).strongly_observable
        assert not toeplitz_strong_observability(A, D, C_sq)


def test_relative_degree_definition_starts_at_j_zero():
    # C D != 0 -> r = 1 (the paper's printed j = 1..r-2 would never test C D)
    A = np.array([[0.0, 1.0], [-2.0, -3.0]])
    assert relative_degree(A, [1.0, 1.0], [1.0, 0.0]) == (1,)
    assert relative_degree(A, [0.0, 1.0], [1.0, 0.0]) == (2,)
    Db = decoupling_matrix(A, [0.0, 1.0], [1.0, 0.0])
    assert np.allclose(Db, [[1.0]])


def test_balancing_makes_badly_scaled_systems_work():
    # the same SISO system with states scaled by 1e4 (like N vs rad in the scooter)
    A, D, C = canonical([1, 2], np.poly([-1, -3, -4]))
    S = np.diag([1e4, 1.0, 1e-3])
    As, Ds, Cs = np.linalg.solve(S, A @ S), np.linalg.solve(S, D), C @ S
    assert same_set(invariant_zeros(As, Ds, Cs), [-2])
    assert normal_rank(As, Ds, Cs) == 4


@pytest.mark.parametrize(
    "args, match",
    [
        ((np.ones((2, 3)), np.ones(2), np.ones(2)), "A must be square"),
        ((np.eye(2), np.ones(3), np.ones(2)), "D has shape"),
        ((np.eye(2), np.ones(2), np.ones(3)), "C has shape"),
        ((np.array([[1.0, np.nan], [0, 1]]), np.ones(2), np.ones(2)), r"A\[0, 1\] is not finite"),
    ],
)
def test_bad_matrices_raise_named_errors(args, match):
    with pytest.raises(StructureError, match=match):
        analyse(*args)


# ---------------------------------------------------------------------------
# the scooter cases
# ---------------------------------------------------------------------------
SPEEDS = (8.0, 20.0, 27.78, 33.0)


@pytest.fixture(scope="module")
def report():
    return observability_report(SPEEDS)


def test_triplet_is_taken_from_the_vehicle_matrices():
    v = REFERENCE_SCOOTER
    tr = ptw_triplet(20.0, ("phi", "tau"), ("delta", "r", "ay"))
    A8 = v.state_matrix(20.0)
    keep = [1, 2, 3, 4, 5, 6, 7]
    assert np.array_equal(tr.A, A8[np.ix_(keep, keep)])
    assert np.array_equal(tr.D[:, 0], A8[keep, 0])
    assert np.array_equal(tr.D[:, 1], v.input_matrix()[keep, 0])
    assert np.array_equal(tr.C[2], v.ay_row()[keep])
    assert tr.state_names == ("delta", "vy", "r", "phi_dot", "delta_dot", "Fyf", "Fyr")
    assert tr.B.shape == (7, 0)
    tr_b = ptw_triplet(20.0, ("phi",), ("delta",))
    assert tr_b.known_inputs == ("tau",) and tr_b.B.shape == (7, 1)


@pytest.mark.parametrize(
    "ui, outs, match",
    [
        (("beta",), ("delta",), "not one of"),
        (("phi",), ("phi",), "not a state of the model"),
        (("tau",), ("speed",), "not a state"),
        ((), ("delta",), "at least one unknown input"),
    ],
)
def test_triplet_rejects_bad_names(ui, outs, match):
    with pytest.raises(ObservabilityError, match=match):
        ptw_triplet(20.0, ui, outs)


def test_triplet_rejects_speed_outside_model_range():
    with pytest.raises(ObservabilityError, match="outside"):
        ptw_triplet(50.0, ("tau",), ("delta",))


def test_report_has_cli_keys_and_is_json(report):
    s = json.loads(json.dumps(report))
    assert {c["name"] for c in s["cases"]} == {c.name for c in CASES}
    for c in s["cases"]:
        for key in ("name", "unknown_inputs", "outputs", "speeds", "relative_degree", "invariant_zeros",
                    "strongly_detectable"):
            assert key in c
        assert len(c["relative_degree"]) == len(c["invariant_zeros"]) == len(c["strongly_detectable"]) == len(SPEEDS)
        for zs in c["invariant_zeros"]:
            assert all(len(z) == 2 for z in zs)
    assert s["working_case"] == WORKING_CASE
    text = format_report(report)
    assert "c_roll_torque_delta_r" in text and "NOT strongly detectable" in text


def _case(report, name):
    return next(c for c in report["cases"] if c["name"] == name)


def test_paper_structure_reproduced_relative_degrees_and_zero_counts(report):
    # the structural part of the paper's claims holds for our scooter:
    # r = 2 with 6 zeros (n = 8), r = 2 with 5 zeros (n = 7), r = [2, 1] with 4 zeros
    a, b, c = (_case(report, n) for n in ("a_torque_delta", "b_roll_delta", "c_roll_torque_delta_r"))
    assert all(r == [2] for r in a["relative_degree"]) and set(a["n_zeros"]) == {6}
    assert all(r == [2] for r in b["relative_degree"]) and set(b["n_zeros"]) == {5}
    assert all(r == [2, 1] for r in c["relative_degree"]) and set(c["n_zeros"]) == {4}
    # case (a), the paper's "one unstable zero": a real unstable zero at low speed (+3.53 1/s at
    # 8 m/s on the corrected scooter), none from about 19 m/s up
    assert a["strongly_detectable"] == [False, True, True, True]  # SPEEDS = 8, 20, 27.78, 33 m/s
    unstable8 = [z for z in a["invariant_zeros"][0] if z[0] >= 0]
    assert len(unstable8) == 1 and unstable8[0][1] == 0.0 and 3.0 < unstable8[0][0] < 4.0


def test_paper_case_c_strongly_detectable_with_four_stable_zeros(report):
    """The paper's working case (phi, tau unknown; delta, r measured) on the corrected scooter
    (a45 = +3.665 vx): four stable zeros at every speed, the slowest -0.69 1/s at 8 m/s (with the
    printed a45's sign one of them was a real unstable zero, +0.7 to +3.5 1/s)."""
    c = _case(report, "c_roll_torque_delta_r")
    assert all(c["strongly_detectable"]) and not any(c["strongly_observable"])
    slowest = [max(z[0] for z in zs) for zs in c["invariant_zeros"]]
    assert all(x < 0 for x in slowest) and -0.75 < slowest[0] < -0.6


def test_case_c_zeros_match_square_pencil_eigenvalues():
    # independent computation: p = q = 2, the Rosenbrock pencil is square
    for v in SPEEDS:
        tr = ptw_triplet(v, ("phi", "tau"), ("delta", "r"))
        n, q = tr.n, 2
        M = np.block([[tr.A, tr.D], [tr.C, np.zeros((2, q))]])
        N = sla.block_diag(np.eye(n), np.zeros((2, q)))
        w = sla.eigvals(M, N)
        w = w[np.isfinite(w) & (np.abs(w) < 1e6)]
        assert same_set(invariant_zeros(tr.A, tr.D, tr.C), w, tol=1e-5)


def test_working_case_strongly_observable_at_every_speed(report):
    d = _case(report, WORKING_CASE)
    assert all(d["strongly_observable"]) and all(d["strongly_detectable"])
    assert all(r == [2, 1, 1] for r in d["relative_degree"])
    # cross-check with Molinari's rank test at one speed
    tr = ptw_triplet(27.78, ("phi", "tau"), ("delta", "r", "phi_dot"))
    assert toeplitz_strong_observability(tr.A, tr.D, tr.C)


def test_case_b_detectable_only_at_low_speed(report):
    b = _case(report, "b_roll_delta")
    det = dict(zip(b["speeds"], b["strongly_detectable"]))
    assert det[8.0] and not det[27.78] and not det[33.0]


# ---------------------------------------------------------------------------
# marginal zeros (ptw_env.spectrum): on the imaginary axis to within round-off
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("num, den, n_marginal", [
    ([1, 0, 4, 0], np.poly([-1, -2, -3, -5]), 3),      # zeros 0, +-2j
    ([1, 0], np.poly([-1, -2]), 1),                    # a pure differentiator: zero at 0
    ([1, 0, 0], np.poly([-1, -2, -4]), 2),             # a repeated zero at 0
    ([1, 0, 9], np.poly([-1, -2, -3]), 2),             # +-3j
    (np.poly([-1.0, -1.0]), np.poly([-2, -3, -4]), 0),  # repeated stable zeros: not marginal
])
def test_marginal_zeros_are_never_stable_whatever_the_round_off(num, den, n_marginal):
    """A zero on the imaginary axis comes out of LAPACK with a real part of +-1e-16 whose sign depends
    on the build; under 20 random orthogonal changes of coordinates (which move that round-off) the
    verdict is the same every time: 'marginal zero', not strongly detectable."""
    from ptw_env.spectrum import classify

    A, D, C = canonical(num, den)
    rng = np.random.default_rng(0)
    for _ in range(20):
        Q, _ = np.linalg.qr(rng.normal(size=A.shape))
        rep = analyse(Q @ A @ Q.T, Q @ D, C @ Q.T)
        kinds = classify(rep.zeros, np.linalg.norm(np.block([[A, D], [C, np.zeros((1, 1))]]), 2))
        assert kinds.count("marginal") == n_marginal, (rep.zeros, kinds)
        if n_marginal:
            assert not rep.strongly_detectable and rep.reason.startswith("marginal zero"), rep.reason
        else:
            assert rep.strongly_detectable and rep.reason == ""


def test_pure_integrator_eigenvalues_are_marginal_and_a_margin_moves_the_boundary():
    from ptw_env.spectrum import classify, marginal_tolerance, verdict

    lam = np.linalg.eigvals(np.array([[0.0, 1.0], [0.0, 0.0]]))  # double integrator
    assert classify(lam, scale=1.0) == ("marginal", "marginal")
    assert classify([-0.5 + 1e-12], scale=1.0, margin=0.5) == ("marginal",)
    assert classify([-0.6], scale=1.0, margin=0.5) == ("stable",)
    assert marginal_tolerance(1e5) == pytest.approx(1e-4) and marginal_tolerance(0.1) == pytest.approx(1e-9)
    assert verdict([-1.0, 2e-3], scale=1.0) == (False, "unstable zero (0.002+0j)")
    with pytest.raises(ValueError, match="scale"):
        marginal_tolerance(float("nan"))
