"""Normalization of the measures handed to :func:`kinred.distance.w1`.

Every argument becomes one of three internal forms:

* :class:`Pts` -- atoms ``points (N, d)`` with probability ``weights (N,)``;
* :class:`Cont1D` -- a continuous 1-D law with ``cdf``, ``ppf`` and compact ``support``;
* :class:`Prod` -- a tensor product of 1-D factors, each a 1-D ``Pts`` or a ``Cont1D``.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_array, as_weights
from ..errors import InvalidInput

__all__ = ["Pts", "Cont1D", "Prod", "normalize", "grid_marginals"]


class Pts:
    """Atoms ``points (N, d)`` with weights ``(N,)`` summing to one."""

    def __init__(self, points: np.ndarray, weights: np.ndarray):
        self.points = points
        self.weights = weights
        self.dim = int(points.shape[1])
        self.n = int(points.shape[0])

    def mean(self) -> np.ndarray:
        return self.weights @ self.points


class Cont1D:
    """A continuous 1-D law (a :class:`kinred.measures.Univariate`)."""

    dim = 1

    def __init__(self, measure):
        self.measure = measure
        a, b = (float(s) for s in measure.support)
        if not (np.isfinite(a) and np.isfinite(b)):
            raise InvalidInput(
                f"W1 needs a compactly supported law, got support ({a}, {b}); truncate it with "
                "Univariate(dist, support=(a, b))"
            )
        self.support = (a, b)
        self._mean = None

    def cdf(self, x):
        return np.asarray(self.measure.cdf(x), dtype=np.float64)

    def ppf(self, u):
        return np.asarray(self.measure.ppf(u), dtype=np.float64)

    def mean(self) -> np.ndarray:
        """``∫ x dμ = a + ∫_a^b (1 − F)`` by quadrature."""
        if self._mean is None:
            from scipy.integrate import quad

            a, b = self.support
            val, _ = quad(lambda x: 1.0 - float(self.cdf(x)), a, b, limit=200, epsabs=1e-14)
            self._mean = np.array([a + val])
        return self._mean


class Prod:
    """Tensor product of 1-D factors (``Pts`` of dim 1 or ``Cont1D``)."""

    def __init__(self, factors: list):
        self.factors = factors
        self.dim = len(factors)

    @property
    def all_atomic(self) -> bool:
        return all(isinstance(f, Pts) for f in self.factors)

    def grid_size(self) -> float:
        if not self.all_atomic:
            return float("inf")
        return float(np.prod([float(f.n) for f in self.factors]))

    def materialize(self) -> Pts:
        """The full tensor grid of an all-atomic product (caller checks the size)."""
        vals = [f.points[:, 0] for f in self.factors]
        wts = [f.weights for f in self.factors]
        grids = np.meshgrid(*vals, indexing="ij")
        wgrid = np.ones(())
        for w in wts:
            wgrid = np.multiply.outer(wgrid, w)
        P = np.stack([g.ravel() for g in grids], axis=1)
        W = np.asarray(wgrid).ravel()
        return Pts(np.ascontiguousarray(P), W / W.sum())

    def mean(self) -> np.ndarray:
        return np.concatenate([np.atleast_1d(f.mean()) for f in self.factors])


def _measure_classes():
    from .. import measures

    return measures


def normalize(obj, w, name: str, wname: str):
    """Turn ``obj`` (array or kinred measure) with optional weights ``w`` into Pts/Cont1D/Prod."""
    ms = _measure_classes()
    if isinstance(obj, ms.Measure):
        if w is not None:
            raise InvalidInput(
                f"{wname} must be None when {name} is a kinred measure (it carries its own "
                f"weights), got {type(w).__name__}"
            )
        return _from_measure(obj, name, ms)
    X = as_array(obj, name, ndim=(1, 2))
    if X.ndim == 1:
        X = X[:, None]
    if X.shape[0] < 1 or X.shape[1] < 1:
        raise InvalidInput(f"{name} must hold at least one point of dimension >= 1, got shape {X.shape}")
    W = as_weights(w, wname, X.shape[0])
    return Pts(np.ascontiguousarray(X, dtype=np.float64), W)


def _from_measure(m, name, ms):
    if isinstance(m, ms.Atomic):
        return Pts(np.ascontiguousarray(m.points, dtype=np.float64), np.asarray(m.weights, float))
    if isinstance(m, ms.Univariate):
        return Cont1D(m)
    if isinstance(m, ms.TensorProduct):
        factors = []
        for j, f in enumerate(m.factors):
            g = _from_measure(f, f"{name}.factors[{j}]", ms)
            if isinstance(g, Prod) and g.dim == 1:
                g = g.factors[0]
            if g.dim != 1 or isinstance(g, Prod):
                raise InvalidInput(f"{name}.factors[{j}] must be a 1-D measure, got dim {g.dim}")
            factors.append(g)
        return Prod(factors)
    if isinstance(m, ms.Mixture):
        parts = [_from_measure(c, f"{name}.components[{i}]", ms) for i, c in enumerate(m.components)]
        parts = [p.materialize() if isinstance(p, Prod) and p.grid_size() <= 10**6 else p for p in parts]
        if all(isinstance(p, Pts) for p in parts):
            P = np.concatenate([p.points for p in parts], axis=0)
            W = np.concatenate([wl * p.weights for wl, p in zip(np.asarray(m.weights), parts)])
            return Pts(np.ascontiguousarray(P), W / W.sum())
        raise InvalidInput(
            f"{name}: W1 of a Mixture is supported when all its components are atomic; "
            "quantize the continuous components first (kinred.quantize)"
        )
    raise InvalidInput(
        f"{name}: W1 is not available for a {type(m).__name__} (supported: Atomic, Dirac, "
        "Empirical1D, Univariate, Uniform, TensorProduct of 1-D measures, Mixture of atomic "
        "measures, or an (N, d) array of points); quantize it first (kinred.quantize)"
    )


def marginal(p: Pts, j: int) -> Pts:
    """The j-th coordinate marginal of atoms: unique values with summed weights."""
    v, inv = np.unique(p.points[:, j], return_inverse=True)
    w = np.bincount(inv.ravel(), weights=p.weights, minlength=v.size)
    return Pts(v[:, None], w / w.sum())


def grid_marginals(p: Pts, rtol: float = 1e-10):
    """Marginals of ``p`` if it is a full tensor grid with product weights, else ``None``.

    Safe detection: every coordinate's distinct values ``vⱼ`` are collected; the atoms must be
    pairwise distinct, ``N = ∏ⱼ |vⱼ|`` (so they are exactly the full grid), and each weight
    must equal the product of its coordinates' marginal weights to relative ``rtol``.
    """
    d = p.dim
    margs, invs = [], []
    total = 1.0
    for j in range(d):
        v, inv = np.unique(p.points[:, j], return_inverse=True)
        inv = inv.ravel()
        w = np.bincount(inv, weights=p.weights, minlength=v.size)
        margs.append(Pts(v[:, None], w))
        invs.append(inv)
        total *= v.size
    if total != p.n:
        return None
    # distinct rows: encode the multi-index (mixed radix) and count unique codes
    code = np.zeros(p.n, dtype=np.float64)
    for j in range(d):
        code = code * margs[j].n + invs[j]
    if total < 2**52 and np.unique(code).size != p.n:
        return None
    pred = np.ones(p.n)
    for j in range(d):
        pred = pred * margs[j].weights[invs[j]]
    if not np.allclose(pred, p.weights, rtol=rtol, atol=rtol * float(p.weights.max())):
        return None
    return [Pts(m.points, m.weights / m.weights.sum()) for m in margs]
