"""Exact (slow) reference solvers, one problem at a time, for tests and benchmarks.

* :func:`reference_basis_pursuit` — basis pursuit ``min ‖z‖₁ s.t. Az = y`` as the linear
  program ``min 1ᵀ(p + q) s.t. A(p − q) = y, p, q ≥ 0`` solved by HiGHS
  (:func:`scipy.optimize.linprog`); ``z = p − q``.
* :func:`reference_bpdn` — basis-pursuit denoising (3.16) as the
  second-order cone program ``min 1ᵀ(p + q) s.t. ‖A(p − q) − y‖₂ ≤ η, p, q ≥ 0`` solved by
  Clarabel (an interior-point conic solver; an optional test dependency).
* :func:`reference_lasso` — ``min ½‖Az − y‖² + λ‖z‖₁`` as a quadratic program in Clarabel.

Each returns ``z (d,)`` and raises :class:`kinred.errors.NotConverged` when the solver does
not report an optimal solution.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from .._validate import as_array, as_float
from ..errors import InvalidInput, NotConverged

__all__ = ["reference_basis_pursuit", "reference_bpdn", "reference_lasso"]


def _check(A, y):
    A = as_array(A, "A", ndim=2)
    y = as_array(y, "y", ndim=1)
    if y.shape[0] != A.shape[0]:
        raise InvalidInput(f"y must have length m = {A.shape[0]} (rows of A), got {y.shape[0]}")
    return A, y


def reference_basis_pursuit(A, y, *, nonneg: bool = False) -> np.ndarray:
    """Basis pursuit by HiGHS: ``min ‖z‖₁ s.t. Az = y`` (``z ≥ 0`` if ``nonneg``).

    Parameters
    ----------
    A : (m, d) ndarray
    y : (m,) ndarray
    nonneg : bool, default False

    Returns
    -------
    (d,) ndarray

    Examples
    --------
    >>> z = reference_basis_pursuit(np.array([[1.0, 1.0]]), np.array([2.0]))
    >>> float(np.abs(z).sum())
    2.0
    """
    A, y = _check(A, y)
    m, d = A.shape
    if nonneg:
        res = linprog(np.ones(d), A_eq=A, b_eq=y, bounds=(0, None), method="highs")
    else:
        res = linprog(np.ones(2 * d), A_eq=np.hstack([A, -A]), b_eq=y, bounds=(0, None), method="highs")
    if res.status != 0:
        raise NotConverged(f"HiGHS did not solve the basis-pursuit LP: {res.message}")
    return res.x if nonneg else res.x[:d] - res.x[d:]


def _clarabel_solve(P, c, G, h, cones, tol):
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = tol
    settings.tol_gap_rel = tol
    settings.tol_feas = tol
    settings.tol_ktratio = 1e-8
    sol = clarabel.DefaultSolver(P, c, G, h, cones, settings).solve()
    if str(sol.status) not in ("Solved",):
        raise NotConverged(f"Clarabel did not solve the problem: status {sol.status}")
    return np.asarray(sol.x)


def reference_bpdn(A, y, eta: float, *, nonneg: bool = False, tol: float = 1e-10) -> np.ndarray:
    """Basis-pursuit denoising by Clarabel: ``min ‖z‖₁ s.t. ‖Az − y‖₂ ≤ η``.

    .. math::

        \\min_{p, q \\ge 0} \\mathbf 1^\\top (p + q) \\quad\\text{s.t.}\\quad
        \\big(\\eta,\\ y - A(p - q)\\big) \\in \\mathcal Q^{m+1}

    Parameters
    ----------
    A : (m, d) ndarray
    y : (m,) ndarray
    eta : float
        ``η ≥ 0``.
    nonneg : bool, default False
        Impose ``z ≥ 0`` (then ``q = 0``).
    tol : float, default 1e-10
        Clarabel's gap and feasibility tolerances.

    Returns
    -------
    (d,) ndarray

    Examples
    --------
    >>> z = reference_bpdn(np.eye(2), np.array([3.0, 0.0]), 1.0)
    >>> np.round(z, 6) + 0.0
    array([2., 0.])
    """
    import clarabel

    A, y = _check(A, y)
    eta = as_float(eta, "eta", low=0.0)
    m, d = A.shape
    B = A if nonneg else np.hstack([A, -A])
    nv = B.shape[1]
    # rows: -x <= 0 (nonnegative cone), then s = (η, y - Bx) in the second-order cone
    G = sp.vstack([-sp.eye(nv), sp.csc_matrix(np.vstack([np.zeros((1, nv)), B]))]).tocsc()
    h = np.concatenate([np.zeros(nv), [eta], y])
    cones = [clarabel.NonnegativeConeT(nv), clarabel.SecondOrderConeT(m + 1)]
    x = _clarabel_solve(sp.csc_matrix((nv, nv)), np.ones(nv), G, h, cones, tol)
    return x if nonneg else x[:d] - x[d:]


def reference_lasso(A, y, lam: float, *, nonneg: bool = False, tol: float = 1e-10) -> np.ndarray:
    """LASSO by Clarabel: ``min ½‖Az − y‖² + λ‖z‖₁`` (as a QP in ``p, q ≥ 0``).

    Examples
    --------
    >>> z = reference_lasso(np.eye(2), np.array([3.0, 0.5]), 1.0)
    >>> np.round(z, 6) + 0.0
    array([2., 0.])
    """
    import clarabel

    A, y = _check(A, y)
    lam = as_float(lam, "lam", low=0.0)
    d = A.shape[1]
    B = A if nonneg else np.hstack([A, -A])
    nv = B.shape[1]
    P = sp.csc_matrix(np.triu(B.T @ B))
    c = lam * np.ones(nv) - B.T @ y
    G = -sp.eye(nv, format="csc")
    x = _clarabel_solve(P, c, G, np.zeros(nv), [clarabel.NonnegativeConeT(nv)], tol)
    return x if nonneg else x[:d] - x[d:]
