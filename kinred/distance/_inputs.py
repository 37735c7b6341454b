"""Normalization of the measures handed to :func:`kinred.distance.w1`.

Every argument (an array of points, a kinred measure or a :mod:`kinred.quantize` result)
becomes one of three internal forms:

* :class:`Pts` -- atoms ``points (N, d)`` with probability ``weights (N,)``;
* :class:`Cont1D` -- a continuous 1-D law with ``cdf``, ``ppf`` and compact ``support``;
* :class:`Prod` -- a tensor product of 1-D factors, each a 1-D ``Pts`` or a ``Cont1D``.

:func:`normalize_pair` then moves both measures into one common frame ``x = c + s·z``
(:func:`common_frame`, exact: a power-of-two scale and a shift that does not round): every
method of :mod:`kinred.distance` computes on coordinates ``z`` of order one and multiplies its
result back by ``s``, since W1 is translation invariant and positively homogeneous,
``W1(c + sμ, c + sν) = s·W1(μ, ν)``. Costs ``|zᵢ − zⱼ|`` can then neither overflow (inputs
near 1e160 squared) nor underflow (inputs near 1e-200 squared).
"""

from __future__ import annotations

import math

import numpy as np

from .._validate import as_array, as_weights
from ..errors import InvalidInput, TooLarge

__all__ = ["Pts", "Cont1D", "Prod", "normalize", "normalize_pair", "common_frame", "grid_marginals"]


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
    """A continuous 1-D law (a :class:`kinred.measures.Univariate`), seen in the coordinate
    ``z = (x − shift)/scale``: ``cdf(z) = F(shift + scale·z)``, ``ppf(u) = (F⁻¹(u) − shift)/scale``.
    """

    dim = 1

    def __init__(self, measure, shift: float = 0.0, scale: float = 1.0):
        self.measure = measure
        a, b = (float(s) for s in measure.support)
        if not (np.isfinite(a) and np.isfinite(b)):
            raise InvalidInput(
                f"W1 needs a compactly supported law, got support ({a}, {b}); truncate it with "
                "Univariate(dist, support=(a, b))"
            )
        self.shift, self.scale = float(shift), float(scale)
        self.support = ((a - self.shift) / self.scale, (b - self.shift) / self.scale)
        self._mean = None

    def in_frame(self, shift: float, scale: float) -> "Cont1D":
        """The same law in the coordinate ``(x − shift)/scale`` (of the original ``x``)."""
        return Cont1D(self.measure, shift, scale)

    def cdf(self, x):
        x = np.asarray(x, dtype=np.float64)
        return np.asarray(self.measure.cdf(self.shift + self.scale * x), dtype=np.float64)

    def ppf(self, u):
        q = np.asarray(self.measure.ppf(u), dtype=np.float64)
        return (q - self.shift) / self.scale

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

    def grid_size(self) -> float | int:
        """Atoms of the full tensor grid: an exact int (inf for a continuous factor)."""
        if not self.all_atomic:
            return float("inf")
        return math.prod(f.n for f in self.factors)

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


def _box(m) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate ``(lo, hi)`` of the support of a normalized measure."""
    if isinstance(m, Pts):
        return m.points.min(axis=0), m.points.max(axis=0)
    if isinstance(m, Cont1D):
        return np.array([m.support[0]]), np.array([m.support[1]])
    boxes = [_box(f) for f in m.factors]
    return np.concatenate([b[0] for b in boxes]), np.concatenate([b[1] for b in boxes])


def common_frame(A, B) -> tuple[np.ndarray, float]:
    """Centre ``c (d,)`` and scale ``s`` of the common frame ``x = c + s·z`` of A and B.

    Exact by construction: on a coordinate whose joint support ``[lo, hi]`` lies at least
    twice its width from the origin, ``c`` is the support's midpoint and ``x − c`` is exact
    (Sterbenz's lemma: ``c/2 ≤ x ≤ 2c``); elsewhere ``c = 0`` (those coordinates are already
    within 2.5 widths of 0, and subtracting would round the atoms near 0). ``s`` is the power
    of two with ``s ≤ width < 2s`` for the widest side of the joint box, so dividing by it is
    exact, every ``|zⱼ| < 10`` and every Euclidean or ℓ1 cost ``|zᵢ − zⱼ|`` is below ``20d``
    for any finite input. ``s = 1`` when both measures sit on one point.
    """
    loA, hiA = _box(A)
    loB, hiB = _box(B)
    lo, hi = np.minimum(loA, loB), np.maximum(hiA, hiB)
    mid = 0.5 * lo + 0.5 * hi
    with np.errstate(over="ignore"):
        width = hi - lo  # inf when wider than the float64 range
        centre = np.where(np.abs(mid) >= 2.0 * width, mid, 0.0)
    widest = float(np.max(width))
    if not math.isfinite(widest):  # measure it in halves, then s ≤ width/2 < 2s
        widest = float(np.max(0.5 * hi - 0.5 * lo))
    if widest == 0.0:
        return centre, 1.0
    return centre, math.ldexp(1.0, math.frexp(widest)[1] - 1)


def _in_frame(m, centre: np.ndarray, scale: float):
    if isinstance(m, Pts):
        return Pts((m.points - centre) / scale, m.weights)
    if isinstance(m, Cont1D):
        return m.in_frame(float(centre[0]), scale)
    return Prod([_in_frame(f, centre[j:j + 1], scale) for j, f in enumerate(m.factors)])


def normalize_pair(mu, nu, a, b):
    """Normalize ``mu`` and ``nu`` (:func:`normalize`) and move both into their common frame.

    Returns
    -------
    A, B : Pts, Cont1D or Prod
        The two measures in the coordinate ``z = (x − c)/s`` of :func:`common_frame`.
    scale : float
        ``s``: a W1 (or bound, or standard error) computed between ``A`` and ``B`` is ``1/s``
        times the one between ``mu`` and ``nu``.
    """
    _equal_totals(a, b, mu, nu)
    A = normalize(mu, a, "mu", "a")
    B = normalize(nu, b, "nu", "b")
    if A.dim != B.dim:
        raise InvalidInput(f"mu and nu must live in the same dimension, got dim {A.dim} and {B.dim}")
    centre, scale = common_frame(A, B)
    return _in_frame(A, centre, scale), _in_frame(B, centre, scale), scale


def _measure_classes():
    from .. import measures

    return measures


#: Most atoms a quantization without tensor structure (mixture, push-forward) is
#: materialized to for W1 (:class:`~kinred.errors.TooLarge` above).
MAX_QUANTIZATION_ATOMS = 10**6


def normalize(obj, w, name: str, wname: str):
    """Turn ``obj`` (array, kinred measure or quantization) with optional weights ``w`` into
    Pts/Cont1D/Prod."""
    from ..quantize import Quantization

    ms = _measure_classes()
    if isinstance(obj, (ms.Measure, Quantization)):
        if w is not None:
            raise InvalidInput(
                f"{wname} must be None when {name} is a kinred measure or quantization (it "
                f"carries its own weights), got {type(w).__name__}"
            )
        if isinstance(obj, Quantization):
            return _from_quantization(obj, name)
        return _from_measure(obj, name, ms)
    X = as_array(obj, name, ndim=(1, 2))
    if X.ndim == 1:
        X = X[:, None]
    if X.shape[0] < 1 or X.shape[1] < 1:
        raise InvalidInput(f"{name} must hold at least one point of dimension >= 1, got shape {X.shape}")
    W = _weights(w, wname, X.shape[0])
    return Pts(np.ascontiguousarray(X, dtype=np.float64), W)


def _total(w, wname: str, n: int | None = None) -> float:
    """The total of weights ``w``: finite, non-negative, positive sum (InvalidInput else)."""
    w = as_array(w, wname, ndim=1)
    if n is not None and w.shape[0] != n:
        raise InvalidInput(f"{wname} must have length {n}, got length {w.shape[0]}")
    if np.any(w < 0):
        i = int(np.argmin(w))
        raise InvalidInput(f"{wname} must be non-negative, got {w[i]} at index {i}")
    total = float(np.sum(w))
    if not (total > 0 and math.isfinite(total)):
        raise InvalidInput(f"{wname} must have a positive finite total, got sum {total!r}")
    return total


def _weights(w, wname: str, n: int) -> np.ndarray:
    """Weights of ``n`` atoms divided by their (positive) total; uniform when None."""
    if w is None:
        return as_weights(None, wname, n)
    total = _total(w, wname, n)
    return as_array(w, wname, ndim=1) / total


def _equal_totals(a, b, mu, nu) -> None:
    """Refuse weights ``a``, ``b`` of raw points whose totals differ (relative 1e-9).

    Both measures are normalized by their totals (as SciPy's ``wasserstein_distance``); two
    different totals mean two measures of different masses, whose W1 is undefined.
    """
    if a is None or b is None:
        return
    ms = _measure_classes()
    from ..quantize import Quantization

    if any(isinstance(o, (ms.Measure, Quantization)) for o in (mu, nu)):
        return  # normalize() refuses the weights with its own message
    ta, tb = _total(a, "a"), _total(b, "b")
    if abs(ta - tb) > 1e-9 * max(ta, tb):
        raise InvalidInput(
            f"a and b must have equal totals (W1 compares measures of equal mass; both are "
            f"then divided by it), got sum(a) = {ta!r} and sum(b) = {tb!r}; divide each by its "
            "own sum to compare the two normalized measures")


def _from_quantization(q, name):
    """The atoms of a quantization result: stored atoms as they are (1-D quantile atoms, an
    atomic measure), a tensor grid as the product of its 1-D factors (never enumerated here),
    every other kind materialized up to :data:`MAX_QUANTIZATION_ATOMS` atoms."""
    from ..quantize import AtomicQuantization, Quantization1D, TensorQuantization

    if isinstance(q, Quantization1D):
        return Pts(np.ascontiguousarray(q.points, dtype=np.float64).reshape(-1, 1),
                   np.asarray(q.weights, dtype=np.float64))
    if isinstance(q, AtomicQuantization):
        return _from_measure(q.measure, name, _measure_classes())
    if isinstance(q, TensorQuantization):
        factors = []
        for f in q.factors:
            a = f.materialize()
            factors.append(Pts(np.ascontiguousarray(a.points, dtype=np.float64),
                               np.asarray(a.weights, dtype=np.float64)))
        return Prod(factors)
    try:
        a = q.materialize(max_atoms=MAX_QUANTIZATION_ATOMS)
    except TooLarge as exc:
        raise TooLarge(f"{name}: {exc}") from None
    return Pts(np.ascontiguousarray(a.points, dtype=np.float64), np.asarray(a.weights, float))


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
        "measures, a kinred.quantize result, or an (N, d) array of points); quantize it first "
        "(kinred.quantize)"
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
