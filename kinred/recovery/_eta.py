r"""Automatic choice of the noise level η of (3.16) from the data.

With ``L`` independent projected simulations (3.17), the stacked data of
one agent at one time is ``y = 𝓜x + e`` with ``e = (e¹; …; eᴸ)`` the projected-simulation
errors, ``‖eˡ‖ ≤ C(t)ε`` by (3.15). Since ``m = kL < d`` in the regime of
interest, a least-squares fit interpolates ``y`` and its residual says nothing about ``e``.
The rule implemented uses the disagreement between the independent projections instead:

1. **Cross-validation over the blocks.** For a geometric grid of ``λ`` (``n_lambdas`` values
   from ``‖𝓜ᵀy‖∞`` down to ``lambda_min_ratio`` times it), the LASSO is fitted on all blocks
   but ``ℓ`` and predicts the held-out ``yˡ``; the prediction errors ``‖yˡ − Mˡẑ₋ₗ‖²``,
   summed over ``ℓ`` and over the columns of a group (a group shares one noise level;
   :func:`recover` pools all agents at one saved time, whose errors obey the same bound
   (3.15)), select ``λ*``. (With a single block the rows are split into 5 interleaved folds.)
2. **Degrees-of-freedom corrected residual** (Reid, Tibshirani & Friedman 2016): with the
   LASSO ``ẑ`` at ``λ*`` on all rows and its support ``Ŝ``,

   .. math::

       \hat\sigma^2 = \frac{\sum_j \|y_j - \mathcal M \hat z_j\|^2}{\sum_j (m - |\hat S_j|)} .

3. **Safety factor**: with ``‖e‖² ≈ σ²χ²_m`` (isotropic error, true for random projections),

   .. math::

       \eta = \hat\sigma\,\sqrt{m + c\sqrt{2m}} ,

   the ``χ²_m`` mean plus ``c`` standard deviations (``c = safety``, default 2: ``‖e‖ ≤ η``
   with probability about 98 % when ``σ̂ = σ``, and ``η/‖e‖ ≈ √(1 + c√(2/m))``).

At most ``per_group`` evenly spaced columns of each group enter the estimate (cost control).
The inner LASSO solves are truncated (``tol``, ``max_iter``): at low noise they overestimate σ
(measured accuracy: docs/performance.md, "Recovery"). The signal must be sparse enough that
``|Ŝ| < m``; otherwise the group is reported as not estimable (pass ``eta`` explicitly).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._validate import as_float, as_int
from ..errors import InvalidInput
from ._solver import _check_A, _check_Y, lasso

__all__ = ["EtaEstimate", "estimate_eta"]


@dataclass(frozen=True, repr=False)
class EtaEstimate:
    """Noise levels chosen by :func:`estimate_eta`.

    Attributes
    ----------
    eta : (n_rhs,) ndarray
        ``η`` per right-hand side.
    sigma : (n_rhs,) ndarray
        Estimated per-coordinate noise standard deviation ``σ̂`` (shared within a group).
    support_size : (n_rhs,) ndarray of int
        ``|Ŝ|`` of the LASSO fit at ``λ*`` (0 for columns left out of the estimate).
    rounds : int
        Number of cross-validation folds.
    safety : float
        The factor ``c`` of ``η = σ̂ √(m + c√(2m))``.
    rule : str
        One-line description of the rule.
    """

    eta: np.ndarray
    sigma: np.ndarray
    support_size: np.ndarray
    rounds: int
    safety: float
    rule: str

    def __repr__(self) -> str:
        return (
            f"EtaEstimate(n_rhs={self.eta.size}, median_eta={float(np.median(self.eta)):.3g}, "
            f"rounds={self.rounds}, safety={self.safety})"
        )


def estimate_eta(
    A,
    Y,
    *,
    groups=None,
    safety: float = 2.0,
    blocks=None,
    n_lambdas: int = 8,
    lambda_min_ratio: float = 1e-3,
    per_group: int = 20,
    tol: float = 1e-4,
    max_iter: int = 500,
) -> EtaEstimate:
    """Choose ``η`` for (3.16) from the data (block cross-validated LASSO).

    See the module docstring for the rule; in short ``η = σ̂ √(m + c√(2m))`` with ``σ̂`` the
    per-coordinate noise level: the degrees-of-freedom corrected residual of the LASSO whose
    ``λ`` predicts held-out blocks best.

    Parameters
    ----------
    A : (m, d) ndarray, Projection, or sequence of L Projections / (k, d) ndarrays
    Y : (m, n_rhs) or (m,) ndarray
    groups : None or (n_rhs,) int array, optional
        Columns with the same label share one noise level (pooled estimate); ``None``: each
        column alone.
    safety : float, default 2
        ``c ≥ 0`` in ``√(m + c√(2m))``: number of ``χ²_m`` standard deviations of margin.
    blocks : sequence of int, optional
        Row counts ``k_ℓ`` of the ``L`` stacked projections (the cross-validation folds);
        ``None``: one block (5 interleaved row folds).
    n_lambdas : int, default 8
        Size of the ``λ`` grid.
    lambda_min_ratio : float, default 1e-3
        Smallest ``λ`` of the grid relative to ``‖𝓜ᵀy‖∞``.
    per_group : int, default 20
        Columns per group used for the estimate.
    tol, max_iter : float, int
        Options of the inner LASSO solves (:func:`lasso`).

    Returns
    -------
    EtaEstimate

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> A = rng.standard_normal((60, 100)) / np.sqrt(60)
    >>> X = np.zeros((100, 40)); X[:5] = 1.0
    >>> E = 0.01 * rng.standard_normal((60, 40))
    >>> est = estimate_eta(A, A @ X + E, groups=np.zeros(40, int))
    >>> bool(0.7 < est.sigma[0] / 0.01 < 1.4)
    True
    """
    A = _check_A(A)
    Y = _check_Y(Y, A.shape[0])
    m = A.shape[0]
    n = Y.shape[1]
    if n == 0:
        raise InvalidInput(f"Y must have at least one column to estimate eta from, got shape {Y.shape}")
    safety = as_float(safety, "safety", low=0.0)
    n_lambdas = as_int(n_lambdas, "n_lambdas", low=2)
    lambda_min_ratio = as_float(
        lambda_min_ratio, "lambda_min_ratio", low=0.0, low_open=True, high=1.0, high_open=True
    )
    per_group = as_int(per_group, "per_group", low=1)
    labels, ng = _group_labels(groups, n)
    folds = _folds(blocks, m)
    sel = _subsample(labels, ng, per_group)
    Ys, ls = Y[:, sel], labels[sel]
    lam_star = _cv_lambda(A, Ys, ls, ng, folds, n_lambdas, lambda_min_ratio, tol, max_iter)
    sigma_g, supp = _refit_sigma(A, Ys, ls, ng, lam_star, tol, max_iter)
    support = np.zeros(n, dtype=np.int64)
    support[sel] = supp
    sigma = sigma_g[labels]
    eta = sigma * np.sqrt(m + safety * np.sqrt(2.0 * m))
    return EtaEstimate(
        eta=eta,
        sigma=sigma,
        support_size=support,
        rounds=len(folds),
        safety=safety,
        rule=(
            "block cross-validated LASSO, sigma^2 = sum ||y - A z||^2 / sum (m - |S|); "
            f"eta = sigma*sqrt(m + {safety:g}*sqrt(2m))"
        ),
    )


def _group_labels(groups, n: int):
    """Labels ``0 … ng−1`` of the columns' groups (each column alone if ``groups`` is None)."""
    if groups is None:
        labels = np.arange(n)
    else:
        g = np.asarray(groups)
        if g.shape != (n,) or not np.issubdtype(g.dtype, np.integer):
            raise InvalidInput(
                f"groups must be an integer array of shape ({n},) (one label per right-hand side), "
                f"got {g.dtype} array of shape {g.shape}"
            )
        _, labels = np.unique(g, return_inverse=True)
    return labels, int(labels.max()) + 1 if n else 0


def _folds(blocks, m: int) -> list:
    """Row indices of the cross-validation folds: the ``L`` blocks, or (one block) 5
    interleaved row folds."""
    if blocks is None:
        blocks = [m]
    elif isinstance(blocks, (str, bytes)) or not isinstance(blocks, (Sequence, np.ndarray)):
        raise InvalidInput(
            f"blocks must be a sequence of positive integers summing to m = {m}, got {blocks!r}"
        )
    sizes = [as_int(b, f"blocks[{i}]") for i, b in enumerate(blocks)]
    bounds = np.cumsum([0] + sizes)
    if bounds[-1] != m or np.any(np.diff(bounds) <= 0):
        raise InvalidInput(f"blocks must be positive sizes summing to m = {m}, got {list(blocks)}")
    if len(blocks) < 2:
        # no held-out block available: split the rows into 5 interleaved folds
        return [np.arange(f, m, 5) for f in range(min(5, m))]
    return [np.arange(bounds[i], bounds[i + 1]) for i in range(len(blocks))]


def _subsample(labels, ng: int, per_group: int):
    """At most ``per_group`` evenly spaced columns of each group."""
    def spaced(cols):
        return cols[np.unique(np.linspace(0, cols.size - 1, min(per_group, cols.size)).astype(int))]

    return np.concatenate([spaced(np.flatnonzero(labels == g)) for g in range(ng)])


def _cv_lambda(A, Y, labels, ng, folds, n_lambdas, lambda_min_ratio, tol, max_iter):
    """Per column, the ``λ`` of the geometric grid (``n_lambdas`` values from ``‖Aᵀy‖∞`` down to
    ``lambda_min_ratio`` times it) with the smallest held-out error summed over the folds and
    over the column's group."""
    m = A.shape[0]
    n = Y.shape[1]
    G = int(n_lambdas)
    lam_max = np.max(np.abs(A.T @ Y), axis=0)  # λ ≥ ‖Aᵀy‖∞ gives z = 0
    ratios = np.logspace(0.0, np.log10(lambda_min_ratio), G + 1)[1:]
    lam_grid = lam_max[:, None] * ratios[None, :]  # (n, G)
    YG = np.repeat(Y, G, axis=1)  # column j*G + g
    lamG = lam_grid.ravel()
    cv = np.zeros(n * G)
    for rows in folds:
        train = np.setdiff1d(np.arange(m), rows)
        res = lasso(A[train], YG[train], lamG, tol=tol, max_iter=max_iter)
        pred = A[rows] @ res.Z
        cv += np.sum((YG[rows] - pred) ** 2, axis=0)
    cv_g = np.zeros((ng, G))
    np.add.at(cv_g, labels, cv.reshape(n, G))
    best = np.argmin(cv_g, axis=1)  # per group
    return lam_grid[np.arange(n), best[labels]]


def _refit_sigma(A, Y, labels, ng, lam_star, tol, max_iter):
    """``σ̂`` per group from the LASSO at ``λ*`` (degrees-of-freedom corrected residual) and
    the support size per column."""
    m = A.shape[0]
    full = lasso(A, Y, lam_star, tol=tol, max_iter=max_iter)
    supp = np.count_nonzero(full.Z, axis=0)
    dof = np.maximum(m - supp, 0).astype(float)
    rss = full.residual**2
    num = np.bincount(labels, weights=np.where(dof > 0, rss, 0.0), minlength=ng)
    den = np.bincount(labels, weights=dof, minlength=ng)
    if np.any(den <= 0):
        bad = np.flatnonzero(den <= 0)
        raise InvalidInput(
            f"cannot estimate eta for group(s) {bad[:5].tolist()}: the cross-validated LASSO support "
            f"has >= m = {m} entries (signal not sparse enough for m); pass eta explicitly"
        )
    return np.sqrt(num / den), supp
