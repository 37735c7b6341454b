"""Exact optimal transport through POT (the only module of kinred that imports ``ot``).

POT is imported lazily, inside the solvers (its import is slow: docs/performance.md,
section W1).

Two pitfalls of calling POT directly are handled here:

* ``ot.dist`` defaults to the *squared* Euclidean cost, whose optimal value is W2², not W1;
  we build the Euclidean (or ℓ1, ``"cityblock"``) cost ourselves, from coordinate
  differences (:func:`cost_matrix`), and pass ``metric="euclidean"`` to the lazy solver;
* ``ot.emd2`` stops after ``numItermax = 100000`` network-simplex pivots and only *warns*; the
  returned cost is then that of a sub-optimal plan (several percent too large at a few
  thousand atoms). We set ``numItermax`` from the problem size and raise
  :class:`kinred.errors.NotConverged` when the solver still reports an early stop.

A third one is magnitude: squared coordinate differences overflow past about 1e154 (the cost
becomes ``inf`` and POT reports an "infeasible" problem, blaming the weights) and underflow
below about 1e-154 (every cost becomes 0). :func:`kinred.distance.w1` therefore hands these
solvers coordinates of order one (the common frame of
:func:`kinred.distance._inputs.normalize_pair`); :func:`_cost_bound` refuses coordinates whose
costs could overflow, and a failure message states the weight sums and the cost bound.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import InvalidInput, NotConverged

__all__ = ["default_num_iter_max", "emd_dense", "emd_lazy", "cost_matrix", "POT_METRIC"]

POT_METRIC = {"euclidean": "euclidean", "l1": "cityblock"}

_CODES = {0: "infeasible", 1: "optimal", 2: "unbounded", 3: "numItermax reached"}


def default_num_iter_max(n: int, m: int) -> int:
    """``max(100000, 50·n·m)`` network-simplex iterations (POT's default is a flat 100000)."""
    return int(max(100_000, 50 * int(n) * int(m)))


#: Largest admissible bound on a ground cost: its square (computed by the solvers) stays finite.
_MAX_COST = 1e150


def _cost_bound(x: np.ndarray, y: np.ndarray) -> float:
    """``d·(max|x| + max|y|)``, a bound on every Euclidean and ℓ1 cost ``|xᵢ − yⱼ|``.

    Raises
    ------
    InvalidInput
        When the bound exceeds ``1e150`` (squared differences could overflow).
    """
    with np.errstate(over="ignore"):
        bound = x.shape[1] * (float(np.max(np.abs(x))) + float(np.max(np.abs(y))))
    if not bound <= _MAX_COST:
        raise InvalidInput(
            f"coordinates up to {float(np.max(np.abs(x))):.3g} and {float(np.max(np.abs(y))):.3g} "
            f"in d = {x.shape[1]} give OT costs up to {bound:.3g} > {_MAX_COST:.0e}, whose squares "
            "overflow; rescale the points (kinred.distance.w1 does so itself)"
        )
    return bound


def _check(log: dict, num_iter_max: int, n: int, m: int, solver: str, a, b, bound: float) -> None:
    code = int(log.get("result_code", 1))
    if code == 1:
        return
    if code == 3:
        raise NotConverged(
            f"POT {solver} stopped after numItermax={num_iter_max} network-simplex iterations "
            f"before reaching the optimum ({n} x {m} atoms); its cost would overestimate W1. "
            "Pass a larger num_iter_max"
        )
    raise NotConverged(
        f"POT {solver} returned status {code} ({_CODES.get(code, 'unknown')}) on a {n} x {m} "
        f"problem whose weights sum to {float(np.sum(a))!r} and {float(np.sum(b))!r} and whose "
        f"costs are finite and at most {bound:.3g}; POT's message: {log.get('warning')!r}"
    )


def cost_matrix(x: np.ndarray, y: np.ndarray, metric: str = "euclidean") -> np.ndarray:
    """Dense ground-cost matrix ``(N, M)``: ``|xᵢ − yⱼ|₂`` or ``|xᵢ − yⱼ|₁``.

    Same numbers as ``ot.dist(x, y, metric="euclidean" | "cityblock")``, but computed from the
    coordinate differences (:func:`scipy.spatial.distance.cdist`) rather than the Gram-matrix
    identity ``|x|² + |y|² − 2x·y``, which loses digits for nearby points far from the origin.
    """
    from scipy.spatial.distance import cdist

    return cdist(x, y, metric=POT_METRIC[metric])


def emd_dense(x, a, y, b, *, metric: str = "euclidean", num_iter_max: int | None = None,
              return_duals: bool = False):
    """Exact OT cost with a dense cost matrix: ``ot.emd2(a, b, ot.dist(x, y, metric))``.

    Parameters
    ----------
    x : (N, d) ndarray, a : (N,) ndarray, y : (M, d) ndarray, b : (M,) ndarray
    metric : {"euclidean", "l1"}
    num_iter_max : int, optional -- default :func:`default_num_iter_max`.
    return_duals : bool -- also return the dual potentials ``(u (N,), v (M,))`` with
        ``uᵢ + vⱼ ≤ c(xᵢ, yⱼ)``.

    Raises
    ------
    InvalidInput
        Coordinates so large that squared costs could overflow (:func:`_cost_bound`).
    NotConverged
        When the network simplex stopped early (or reported infeasibility).
    """
    import ot

    n, m = x.shape[0], y.shape[0]
    it = default_num_iter_max(n, m) if num_iter_max is None else int(num_iter_max)
    bound = _cost_bound(x, y)
    M = cost_matrix(x, y, metric)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        cost, log = ot.emd2(a, b, M, numItermax=it, log=True)
    _check(log, it, n, m, "emd2", a, b, bound)
    if return_duals:
        return float(cost), (np.asarray(log["u"]), np.asarray(log["v"]))
    return float(cost)


def emd_lazy(x, a, y, b, *, metric: str = "euclidean", num_iter_max: int | None = None) -> float:
    """Exact OT cost without the dense matrix: ``ot.lp.emd2_lazy`` (memory ``O(N + M)``)."""
    import ot

    if not hasattr(ot.lp, "emd2_lazy"):  # pragma: no cover - POT < 0.9.6
        raise InvalidInput(
            f"method 'exact-lazy' needs POT >= 0.9.6 (ot.lp.emd2_lazy); installed POT is {ot.__version__}"
        )
    n, m = x.shape[0], y.shape[0]
    it = default_num_iter_max(n, m) if num_iter_max is None else int(num_iter_max)
    bound = _cost_bound(x, y)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        cost, log = ot.lp.emd2_lazy(
            np.ascontiguousarray(x), np.ascontiguousarray(y), a, b, metric=POT_METRIC[metric],
            numItermax=it, log=True, return_matrix=False,
        )
    _check(log, it, n, m, "emd2_lazy", a, b, bound)
    return float(cost)
