"""Structural analysis of linear systems with unknown inputs: invariant zeros,
vector relative degree, strong observability and strong detectability.

For the triplet ``(A, D, C)`` of

.. math::

    \\dot x = A x + B u + D \\zeta, \\qquad y = C x

(``x`` in R^n, unknown input ``zeta`` in R^q, output ``y`` in R^p; the known
input ``B u`` plays no role here) the tools below answer the questions of
Nehaoua et al. [1]_, section III, for any ``p`` and ``q``:

* **Rosenbrock matrix** ([1]_, Definition 3.1)

  .. math::

      R(s) = \\begin{bmatrix} sI - A & -D \\\\ C & 0 \\end{bmatrix}.

  ``s0`` is an **invariant zero** when ``rank R(s0) < n + rank D`` ([1]_,
  Def. 3.1; Trentelman, Stoorvogel, Hautus [2]_, sec. 7.3). When the *normal*
  rank of ``R`` (its rank at almost every ``s``) is already below
  ``n + rank D`` (the unknown input is not left-invertible from ``y``),
  every ``s`` is a zero: :class:`StructureReport` says so with
  ``left_invertible = False`` and lists the finite points where the rank drops
  further. The finite zeros are computed by the Emami-Naeini & Van Dooren
  reduction [3]_ of the pencil to a regular one, then its generalised
  eigenvalues; this works for non-square systems (``p != q``), where a plain
  generalised eigenvalue problem on ``R`` does not.
* **Vector relative degree** ([1]_ after Def. 3.1, [4]_): ``r_i`` is the
  smallest ``k >= 1`` with ``C_i A^(k-1) D != 0``, i.e.

  .. math::

      C_i A^j D = 0 \\quad (j = 0, \\dots, r_i - 2), \\qquad
      C_i A^{r_i - 1} D \\neq 0,

  and the system *has* the vector relative degree ``r`` when the decoupling
  matrix ``Dbar = [C_i A^(r_i-1) D]_i`` is invertible (square case).
  **Correction to [1]_**: the printed conditions run over ``j = 1, ..., r-2``
  (and ``s = 1, ..., r_i - 2``); they must start at ``j = 0`` (``C D = 0``
  is the first condition of a relative degree above one, [4]_ sec. 4.1).
* **Strong observability / detectability** ([1]_ Def. 3.2, Prop. 3.1; [2]_
  Theorems 7.16-7.17): strongly observable iff ``rank R(s) = n + rank D`` for
  every complex ``s`` (left-invertible, no invariant zero); strongly detectable
  iff that holds for every ``Re s >= 0`` (left-invertible, every zero stable).
  An independent test, used as a cross-check, is Molinari's rank condition
  ``rank [O_n, H_n] - rank H_n = n`` with the observability matrix ``O_n``
  and the block-Toeplitz matrix ``H_n`` of Markov parameters ``C A^k D``
  (:func:`toeplitz_strong_observability`).
* **Weakly unobservable subspace** ``V*`` ([2]_ sec. 7.3): the initial
  states from which some unknown input keeps ``y = 0``; ``V* = lim V_k``,
  ``V_0 = R^n``, ``V_{k+1} = ker C ∩ A^{-1}(V_k + im D)``. For a
  left-invertible system ``dim V*`` equals the number of invariant zeros and
  the zeros are the eigenvalues of ``A + D F`` restricted to ``V*``
  (another cross-check; :func:`weakly_unobservable_subspace`).

Numerics: before any rank decision the triplet is balanced (a diagonal state
scaling from :func:`scipy.linalg.matrix_balance`, and unit-norm columns of
``D`` and rows of ``C``); zeros, ranks and relative degrees are invariant
under these scalings. Rank decisions use singular values relative to the
norm of the balanced system matrix (``tol``, default ``1e-9``).

References
----------
.. [1] L. Nehaoua, D. Ichalal, H. Arioui, J. Davila, S. Mammar, L. Fridman,
   "An unknown input HOSM approach to estimate lean and steering motorcycle
   dynamics", IEEE Trans. Vehicular Technology 63(7), 3116-3127, 2014
   (``shared/papers/001_19401b3c72cfcc01.txt``).
.. [2] H. L. Trentelman, A. A. Stoorvogel, M. Hautus, *Control Theory for
   Linear Systems*, Springer, 2001.
.. [3] A. Emami-Naeini, P. Van Dooren, "Computation of zeros of linear
   multivariable systems", Automatica 18(4), 415-430, 1982.
.. [4] A. Isidori, *Nonlinear Control Systems*, 3rd ed., Springer, 1995.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ptw_env import spectrum

#: Default relative tolerance of rank decisions (singular values below ``tol * ||system||``).
DEFAULT_TOL = 1e-9


class StructureError(ValueError):
    """A matrix of the wrong shape or with a non-finite entry given to a structural tool."""


# ---------------------------------------------------------------------------
# input checking and balancing
# ---------------------------------------------------------------------------
def _mat(name: str, a, shape: tuple[int | None, int | None]) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim == 1 and shape[1] == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise StructureError(f"{name} must be a 2-D matrix, got an array of shape {a.shape}")
    for k, (got, want) in enumerate(zip(a.shape, shape)):
        if want is not None and got != want:
            raise StructureError(f"{name} has shape {a.shape}; axis {k} must have length {want}")
    if not np.all(np.isfinite(a)):
        i, j = np.argwhere(~np.isfinite(a))[0]
        raise StructureError(f"{name}[{i}, {j}] is not finite ({a[i, j]!r})")
    return a


def check_triplet(A, D, C) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate ``(A, D, C)``: ``A`` (n, n), ``D`` (n, q) (a 1-D ``D`` is a column), ``C`` (p, n) (a 1-D ``C`` is a row)."""
    A = _mat("A", A, (None, None))
    n = A.shape[0]
    if A.shape != (n, n):
        raise StructureError(f"A must be square, got shape {A.shape}")
    D = _mat("D", D, (n, None)) if np.ndim(D) != 1 else _mat("D", np.asarray(D, float)[:, None], (n, 1))
    C = np.asarray(C, dtype=float)
    C = _mat("C", C[None, :] if C.ndim == 1 else C, (None, n))
    return A, D, C


def balance(A: np.ndarray, D: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Diagonally rescaled triplet with the same zeros, ranks and relative degrees.

    ``x = S x_b`` with ``S`` from :func:`scipy.linalg.matrix_balance` applied
    to ``[[A, D], [C, 0]]`` padded square (states only are scaled), then
    columns of ``D`` and rows of ``C`` normalised to unit 2-norm.
    """
    if not (np.any(A) or np.any(D) or np.any(C)):
        return A.copy(), D.copy(), C.copy()
    s = _balance_scaling(A, D, C)
    Ab = A * (1.0 / s)[:, None] * s[None, :]
    Db = D / s[:, None]
    Cb = C * s[None, :]
    dn = np.linalg.norm(Db, axis=0)
    Db = Db / np.where(dn > 0, dn, 1.0)
    cn = np.linalg.norm(Cb, axis=1)
    Cb = Cb / np.where(cn > 0, cn, 1.0)[:, None]
    return Ab, Db, Cb


def _rank(M: np.ndarray, thresh: float) -> int:
    if M.size == 0:
        return 0
    return int(np.sum(np.linalg.svd(M, compute_uv=False) > thresh))


# ---------------------------------------------------------------------------
# Emami-Naeini & Van Dooren reduction
# ---------------------------------------------------------------------------
def _reduce(A, B, C, D, thresh):
    """One pass of [3]_'s reduction: returns ``(A, B, C, D, mu_sum)`` with ``D`` of full row rank.

    The pencil ``[[A - sI, B], [C, D]]`` keeps its finite zero structure and
    ``rank P(s) = mu_sum + rank P_reduced(s)`` (unimodular eliminations).
    """
    mu_sum = 0
    while True:
        n, m = B.shape
        p = C.shape[0]
        if p == 0 or n == 0:
            return A, B, C, D, mu_sum
        U, sv, _ = np.linalg.svd(D) if D.size else (np.eye(p), np.zeros(0), None)
        rho = int(np.sum(sv > thresh)) if D.size else 0
        # rows: first p - rho zero rows of U^T D, last rho full-row-rank rows
        Ut = np.concatenate([U[:, rho:], U[:, :rho]], axis=1).T
        Ct = Ut @ C
        Dt = Ut @ D
        C1, C2 = Ct[: p - rho], Ct[p - rho :]
        D2 = Dt[p - rho :]
        if p - rho == 0:
            return A, B, C, D, mu_sum
        _, s1, W1t = np.linalg.svd(C1)
        mu = int(np.sum(s1 > thresh))
        if mu == 0:
            # zero rows: drop them, D is now of full row rank
            A, B, C, D = A, B, C2, D2
            continue
        W1 = W1t.T
        V = np.concatenate([W1[:, mu:], W1[:, :mu]], axis=1)  # last mu columns span the row space of C1
        At = V.T @ A @ V
        Bt = V.T @ B
        C2v = C2 @ V
        n1 = n - mu
        A, B, C, D = (
            At[:n1, :n1],
            Bt[:n1],
            np.vstack([At[n1:, :n1], C2v[:, :n1]]),
            np.vstack([Bt[n1:], D2]),
        )
        mu_sum += mu


def _pencil_zeros(A, B, C, D, thresh) -> tuple[np.ndarray, int]:
    """Finite zeros of ``[[A - sI, B], [C, D]]`` and its normal rank."""
    A1, B1, C1, D1, mu1 = _reduce(A, B, C, D, thresh)
    # dual pass: reduce the transposed system so that D also has full column rank
    A2, B2, C2, D2, mu2 = _reduce(A1.T, C1.T, B1.T, D1.T, thresh)
    Ar, Br, Cr, Dr = A2.T, C2.T, B2.T, D2.T
    nr = Ar.shape[0]
    rank_d = _rank(Dr, thresh)
    normal_rank = mu1 + mu2 + nr + rank_d
    if nr == 0:
        return np.zeros(0, dtype=complex), normal_rank
    if Dr.shape[0] != Dr.shape[1] or rank_d != Dr.shape[0]:  # pragma: no cover - guarded by the reduction
        raise StructureError("zero computation failed: the reduced feedthrough is not square invertible")
    m = Br.shape[1]
    # compress the columns of [C D] to [0 Df]; the zeros are eig(Af, Bf) ([3]_, sec. 4)
    CD = np.hstack([Cr, Dr])
    _, _, Wt = np.linalg.svd(CD)
    W = Wt.T
    Wr = np.concatenate([W[:, CD.shape[0] :], W[:, : CD.shape[0]]], axis=1)
    AB = np.hstack([Ar, Br]) @ Wr
    IE = np.hstack([np.eye(nr), np.zeros((nr, m))]) @ Wr
    Af = AB[:, :nr]
    Bf = IE[:, :nr]
    z = sla.eigvals(Af, Bf)
    z = z[np.isfinite(z)]
    return np.sort_complex(z), normal_rank


# ---------------------------------------------------------------------------
# public tools
# ---------------------------------------------------------------------------
def _pencil_scale(A, D, C) -> float:
    """Largest singular value of the Rosenbrock pencil's constant part ``[[A, D], [C, 0]]``: the
    scale of the round-off in its zeros (:mod:`ptw_env.spectrum`)."""
    p, q = C.shape[0], D.shape[1]
    return float(np.linalg.norm(np.block([[A, D], [C, np.zeros((p, q))]]), 2))


def _threshold(A, D, C, tol: float) -> float:
    return tol * max(1.0, _pencil_scale(A, D, C))


def invariant_zeros(A, D, C, tol: float = DEFAULT_TOL, balanced: bool = True) -> np.ndarray:
    """Finite invariant zeros of ``(A, D, C)``: where the Rosenbrock matrix loses rank.

    Returns the finite ``s`` at which ``rank R(s)`` drops below the normal
    rank of ``R`` ([3]_; for a left-invertible triplet the normal rank is
    ``n + rank D``, [1]_ Def. 3.1), sorted, as a complex array. Works for any
    numbers of outputs and unknown inputs. See :func:`analyse` for the
    left-invertibility flag (when it fails every ``s`` is a zero in the sense
    of [1]_ Def. 3.1).

    Examples
    --------
    >>> import numpy as np
    >>> A = np.array([[0., 1.], [-2., -3.]]); D = np.array([0., 1.]); C = np.array([3., 1.])
    >>> np.round(invariant_zeros(A, D, C).real, 6)   # (s + 3)/((s + 1)(s + 2))
    array([-3.])
    """
    A, D, C = check_triplet(A, D, C)
    if balanced:
        A, D, C = balance(A, D, C)
    thresh = _threshold(A, D, C, tol)
    # rank R(s) = rank [[A - sI, D], [C, 0]] (first block row times -1)
    z, _ = _pencil_zeros(A, D, C, np.zeros((C.shape[0], D.shape[1])), thresh)
    return z


def normal_rank(A, D, C, tol: float = DEFAULT_TOL) -> int:
    """Normal rank of the Rosenbrock matrix ``R(s)`` (its rank for almost every ``s``)."""
    A, D, C = check_triplet(A, D, C)
    A, D, C = balance(A, D, C)
    thresh = _threshold(A, D, C, tol)
    _, nr = _pencil_zeros(A, D, C, np.zeros((C.shape[0], D.shape[1])), thresh)
    return nr


def relative_degree(A, D, C, tol: float = DEFAULT_TOL) -> tuple[int | None, ...]:
    """Relative degree ``r_i`` of each output with respect to the unknown input (all of its columns).

    ``r_i = min {k >= 1 : C_i A^(k-1) D != 0}`` ([1]_, corrected as in the
    module docstring); ``None`` for an output that no unknown input reaches
    (``C_i A^k D = 0`` for all ``k < n``, Cayley-Hamilton).
    """
    A, D, C = check_triplet(A, D, C)
    A, D, C = balance(A, D, C)
    n = A.shape[0]
    thresh = _threshold(A, D, C, tol)
    out: list[int | None] = []
    for i in range(C.shape[0]):
        row = C[i : i + 1]
        r = None
        for k in range(1, n + 1):
            if np.linalg.norm(row @ D) > thresh:
                r = k
                break
            row = row @ A
            nr = np.linalg.norm(row)
            if nr == 0:
                break
            row = row / nr  # keep the scale (only zero / non-zero matters)
        out.append(r)
    return tuple(out)


def decoupling_matrix(A, D, C, r: tuple[int | None, ...] | None = None) -> np.ndarray:
    """``Dbar`` with rows ``C_i A^(r_i - 1) D`` ([1]_, the determinant condition after Def. 3.2).

    Raises :class:`StructureError` if an output has no relative degree.
    """
    A, D, C = check_triplet(A, D, C)
    r = relative_degree(A, D, C) if r is None else tuple(r)
    if len(r) != C.shape[0]:
        raise StructureError(f"r has {len(r)} entries for {C.shape[0]} outputs")
    rows = []
    for i, ri in enumerate(r):
        if ri is None:
            raise StructureError(f"output {i} has no relative degree (no unknown input reaches it)")
        rows.append(C[i] @ np.linalg.matrix_power(A, ri - 1) @ D)
    return np.array(rows)


def weakly_unobservable_subspace(A, D, C, tol: float = DEFAULT_TOL) -> np.ndarray:
    """Orthonormal basis (columns) of the weakly unobservable subspace ``V*`` ([2]_ sec. 7.3).

    ``V_0 = R^n``, ``V_{k+1} = ker C ∩ A^{-1}(V_k + im D)`` until the
    dimension stops decreasing (at most ``n + 1`` steps). Computed on the
    balanced triplet and mapped back to the original coordinates.
    """
    A0, D0, C0 = check_triplet(A, D, C)
    n = A0.shape[0]
    Ab, Db, Cb = balance(A0, D0, C0)
    # recover the diagonal state scaling used by balance: A_b = S^-1 A S
    thresh = _threshold(Ab, Db, Cb, tol)
    V = np.eye(n)
    for _ in range(n + 1):
        span = np.hstack([V, Db])
        Us, ss, _ = np.linalg.svd(span, full_matrices=True)
        rk = int(np.sum(ss > thresh))
        perp = Us[:, rk:]  # orthogonal complement of V_k + im D
        M = np.vstack([Cb, perp.T @ Ab])
        _, sm, Wt = np.linalg.svd(M, full_matrices=True)
        rk_m = int(np.sum(sm > thresh))
        Vn = Wt[rk_m:].T
        if Vn.shape[1] == V.shape[1]:
            V = Vn
            break
        V = Vn
    # map back: x = S x_b
    S = _balance_scaling(A0, D0, C0)
    Vo = S[:, None] * V
    if Vo.shape[1] == 0:
        return Vo
    Q, _ = np.linalg.qr(Vo)
    return Q


def _balance_scaling(A, D, C) -> np.ndarray:
    """State scaling ``S`` of :func:`balance`: :func:`scipy.linalg.matrix_balance` of ``[[A, D], [C, 0]]`` padded
    square, its first ``n`` factors (ones for an all-zero triplet)."""
    n, q = D.shape
    p = C.shape[0]
    m = max(q, p)
    big = np.zeros((n + m, n + m))
    big[:n, :n] = A
    big[:n, n : n + q] = D
    big[n : n + p, :n] = C
    if not np.any(big):
        return np.ones(n)
    _, (scale, _) = sla.matrix_balance(big, permute=False, separate=True)
    return scale[:n]


def zeros_from_subspace(A, D, V: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``A + D F`` restricted to an ``(A + DF)``-invariant ``V`` (basis columns).

    Solves ``A V = V X + D U`` (unique when ``[V, D]`` has full column rank,
    i.e. ``V ∩ im D = 0``) and returns ``eig(X)``; with ``V = V*`` of a
    left-invertible triplet these are the invariant zeros ([2]_ sec. 7.3).
    """
    A = np.asarray(A, float)
    D = np.asarray(D, float).reshape(A.shape[0], -1)
    if V.shape[1] == 0:
        return np.zeros(0, dtype=complex)
    sol, *_ = np.linalg.lstsq(np.hstack([V, D]), A @ V, rcond=None)
    X = sol[: V.shape[1]]
    return np.sort_complex(np.linalg.eigvals(X))


def toeplitz_strong_observability(A, D, C, tol: float = DEFAULT_TOL) -> bool:
    """Molinari's test: strongly observable iff ``rank [O_n, H_n] - rank H_n = n``.

    ``O_n = [C; C A; ...; C A^(n-1)]`` and ``H_n`` is the lower block-
    triangular Toeplitz matrix with blocks ``C A^(i-j-1) D`` (``i > j``):
    the stacked output derivatives ``Y = O_n x + H_n Z`` determine ``x``
    regardless of the unknown-input derivatives ``Z`` exactly when the
    columns of ``O_n`` are independent of each other and of those of ``H_n``.
    Independent of the zero computation; used as a cross-check.
    """
    A, D, C = check_triplet(A, D, C)
    A, D, C = balance(A, D, C)
    n, q = D.shape
    p = C.shape[0]
    O = np.zeros((n * p, n))
    H = np.zeros((n * p, n * q))
    Ak = np.eye(n)
    mk = []
    for k in range(n):
        O[k * p : (k + 1) * p] = C @ Ak
        mk.append(C @ Ak @ D)
        Ak = A @ Ak
    for i in range(n):
        for j in range(i):
            H[i * p : (i + 1) * p, j * q : (j + 1) * q] = mk[i - j - 1]
    # row-scale each derivative block to comparable size
    for k in range(n):
        blk = np.hstack([O[k * p : (k + 1) * p], H[k * p : (k + 1) * p]])
        s = np.linalg.norm(blk)
        if s > 0:
            O[k * p : (k + 1) * p] /= s
            H[k * p : (k + 1) * p] /= s
    OH = np.hstack([O, H])
    th = tol * max(1.0, float(np.linalg.norm(OH, 2)))
    return _rank(OH, th) - _rank(H, th) == n


@dataclass(frozen=True)
class StructureReport:
    """Everything :func:`analyse` finds about a triplet ``(A, D, C)``.

    Attributes
    ----------
    n, n_unknown, n_outputs : int
        Numbers of states, unknown inputs (columns of ``D``) and outputs.
    rank_D : int
    normal_rank : int
        Normal rank of the Rosenbrock matrix; ``n + rank_D`` when left-invertible.
    left_invertible : bool
        ``normal_rank == n + rank_D``. If False, every ``s`` is an invariant
        zero in the sense of [1]_ Def. 3.1 and the system is neither strongly
        observable nor strongly detectable.
    zeros : ndarray of complex
        Finite points where the Rosenbrock matrix loses rank below its normal rank.
    relative_degree : tuple of int or None
        Per output (see :func:`relative_degree`).
    decoupling_rank : int
        Rank of ``Dbar`` (0 if an output has no relative degree).
    has_vector_relative_degree : bool
        Square (``p == q``) with ``Dbar`` invertible ([1]_ after Def. 3.2).
    strongly_observable, strongly_detectable : bool
        [1]_ Def. 3.2 via the rank tests of the module docstring.
    """

    n: int
    n_unknown: int
    n_outputs: int
    rank_D: int
    normal_rank: int
    left_invertible: bool
    zeros: np.ndarray
    relative_degree: tuple[int | None, ...]
    decoupling_rank: int
    has_vector_relative_degree: bool
    strongly_observable: bool
    strongly_detectable: bool
    reason: str = ""  #: why not strongly detectable: "not left-invertible", "unstable zero ...", "marginal zero ..."

    @property
    def max_zero_real(self) -> float:
        """Largest real part of a finite zero (``-inf`` without zeros, ``+inf`` if not left-invertible)."""
        if not self.left_invertible:
            return float("inf")
        return float(np.max(self.zeros.real)) if self.zeros.size else float("-inf")


def analyse(A, D, C, tol: float = DEFAULT_TOL, stability_margin: float = 0.0) -> StructureReport:
    """Zeros, relative degree, strong observability and detectability of ``(A, D, C)``.

    ``stability_margin`` [1/s]: a zero counts as stable when ``Re s < -stability_margin``.

    Examples
    --------
    >>> import numpy as np
    >>> A = np.diag([-1.0, -2.0, -3.0]) + np.diag([1.0, 1.0], 1)
    >>> rep = analyse(A, [0, 0, 1], [1, 0, 0])        # chain of integrators: r = n
    >>> rep.relative_degree, rep.zeros.size, rep.strongly_observable
    ((3,), 0, True)
    """
    A, D, C = check_triplet(A, D, C)
    Ab, Db, Cb = balance(A, D, C)
    n, q = D.shape
    p = C.shape[0]
    thresh = _threshold(Ab, Db, Cb, tol)
    rank_d = _rank(Db, thresh)
    zeros, nrank = _pencil_zeros(Ab, Db, Cb, np.zeros((p, q)), thresh)
    left_inv = nrank == n + rank_d
    r = relative_degree(A, D, C, tol)
    if any(ri is None for ri in r):
        dec_rank = 0
    else:
        dec_rank = _rank(decoupling_matrix(Ab, Db, Cb, r), thresh)
    has_vrd = p == q and all(ri is not None for ri in r) and dec_rank == q
    so = left_inv and zeros.size == 0
    # stable / marginal / unstable with the tolerance of ptw_env.spectrum, scaled to this pencil: a
    # zero on the imaginary axis (0, +-j w) is never "stable" whatever sign round-off gives it
    stable, why = spectrum.verdict(zeros, _pencil_scale(Ab, Db, Cb), margin=stability_margin)
    sd = left_inv and stable
    reason = "" if sd else ("not left-invertible" if not left_inv else why)
    return StructureReport(
        n=n,
        n_unknown=q,
        n_outputs=p,
        rank_D=rank_d,
        normal_rank=nrank,
        left_invertible=left_inv,
        zeros=zeros,
        relative_degree=r,
        decoupling_rank=dec_rank,
        has_vector_relative_degree=has_vrd,
        strongly_observable=so,
        strongly_detectable=sd,
        reason=reason,
    )


__all__ = [
    "DEFAULT_TOL",
    "StructureError",
    "StructureReport",
    "analyse",
    "balance",
    "check_triplet",
    "decoupling_matrix",
    "invariant_zeros",
    "normal_rank",
    "relative_degree",
    "toeplitz_strong_observability",
    "weakly_unobservable_subspace",
    "zeros_from_subspace",
]
