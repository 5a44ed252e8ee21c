"""The LMI plumbing shared by the two designs (the TS controller's Theorems 1-2, :mod:`assist.control.ts_design`,
and the adaptive observer's Theorem 2, :mod:`assist.estimation.adaptive_design`).

* :func:`symmetric`: ``(A + A^T) / 2``, the matrix a solver's (or a product's) round-off leaves nearly symmetric;
* :func:`max_eig`: the largest eigenvalue of a block's symmetric part, what a numpy certificate compares with
  ``-margin`` (``block < 0`` holds iff ``max_eig(block) < 0``);
* :func:`solve_quietly`: ``prob.solve`` with the solver's warnings silenced and its failures turned into a
  status string instead of an exception (``"solver_error: ..."`` for cvxpy's SolverError, ``"solver_crash:
  ..."`` for a panic of the compiled solver, e.g. Clarabel's pyo3 PanicException, which derives from
  BaseException);
* :class:`Certificate` of :class:`CertificateEntry`: the numpy re-check of every inequality of a design
  (both designs report through it).

May import: numpy, cvxpy (lazily). Imported by the control and estimation families.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np


def symmetric(a: np.ndarray) -> np.ndarray:
    """``(a + a^T) / 2`` as floats."""
    a = np.asarray(a, dtype=float)
    return 0.5 * (a + a.T)


def max_eig(block: np.ndarray) -> float:
    """Largest eigenvalue of the symmetric part of ``block`` (numpy ``eigvalsh``)."""
    return float(np.linalg.eigvalsh(symmetric(block))[-1])


def solve_quietly(prob: Any, solver: str) -> str:
    """Solve the cvxpy problem ``prob`` with ``solver`` (a cvxpy solver name such as ``"CLARABEL"``).

    Returns cvxpy's status (``"optimal"``, ``"optimal_inaccurate"``, ``"infeasible"``, ...) or
    ``"solver_error: <message>"`` / ``"solver_crash: <type>: <message>"``. Never raises for a solver failure;
    ``KeyboardInterrupt`` and ``SystemExit`` pass through.

    >>> import cvxpy as cp
    >>> x = cp.Variable((2, 2), symmetric=True)
    >>> solve_quietly(cp.Problem(cp.Minimize(cp.trace(x)), [x >> np.eye(2)]), "CLARABEL")
    'optimal'
    >>> round(max_eig(np.eye(2) - x.value), 6) <= 1e-6
    True
    """
    import cvxpy as cp

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            prob.solve(solver=getattr(cp, solver))
        except cp.error.SolverError as exc:
            return f"solver_error: {' '.join(str(exc).split())}"
        except BaseException as exc:  # noqa: BLE001  (a compiled solver's panic derives from BaseException)
            if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
            return f"solver_crash: {type(exc).__name__}: {' '.join(str(exc).split())}"
    return str(prob.status)


#: Tolerance of a non-strict inequality ``block <= 0`` (relative to the block's size where the design says so).
NONSTRICT_TOL = 1e-7


@dataclass(frozen=True)
class CertificateEntry:
    """Largest eigenvalue ``max_eig`` of one inequality ``block < 0`` (``block <= 0`` when not ``strict``),
    checked in numpy: ``lmi`` names it, ``vertex`` is the polytope vertex (None: a vertex-free condition such as
    ``P > 0``), ``theorem`` the theorem it belongs to when a design proves several (None otherwise)."""

    lmi: str
    vertex: int | None
    max_eig: float
    strict: bool = True
    theorem: str | None = None


@dataclass(frozen=True)
class Certificate:
    """The numpy re-check of every inequality of a design: a strict one holds when ``max_eig < -margin``, a
    non-strict one when ``max_eig <= NONSTRICT_TOL``."""

    margin: float
    entries: tuple[CertificateEntry, ...]

    def failures(self) -> list[CertificateEntry]:
        """Entries that violate their inequality."""
        return [e for e in self.entries if (e.max_eig >= -self.margin if e.strict else e.max_eig > NONSTRICT_TOL)]

    @property
    def passed(self) -> bool:
        return not self.failures()

    def worst(self, theorem: str | None = None, lmis: tuple[str, ...] | None = None) -> CertificateEntry:
        """The strict entry closest to violation, optionally of one ``theorem`` and of the LMI names ``lmis``."""
        es = [e for e in self.entries if e.strict and (theorem is None or e.theorem == theorem)
              and (lmis is None or e.lmi in lmis)]
        return max(es, key=lambda e: e.max_eig)


__all__ = ["Certificate", "CertificateEntry", "NONSTRICT_TOL", "max_eig", "solve_quietly", "symmetric"]
