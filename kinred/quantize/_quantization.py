"""Quantizations of measures: atoms, a-priori bounds and a-posteriori errors."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Iterator

import numpy as np
from scipy import integrate

from .._validate import as_choice, as_float, as_int
from ..errors import InvalidInput, TooLarge
from ..measures import (
    Atomic,
    Empirical1D,
    Measure,
    Mixture,
    PushForward,
    TensorProduct,
    Univariate,
)
from ._budget import RULE_CONSTANT, Budget, budget

__all__ = [
    "DEFAULT_MAX_ATOMS",
    "Quantization",
    "Quantization1D",
    "TensorQuantization",
    "MixtureQuantization",
    "PushQuantization",
    "AtomicQuantization",
    "quantize",
    "quantize_1d",
]

#: Default refusal limit of :meth:`Quantization.materialize` (atoms).
DEFAULT_MAX_ATOMS = 2_000_000

_INT64_MAX = 2**63 - 1


def _fmt_count(n: int) -> str:
    s = str(n)
    return s if len(s) <= 15 else f"{float(n):.3e}" if n < 10**300 else f"~1e{len(s) - 1}"


# ------------------------------------------------------------------------------------------
# exact 1-D error
# ------------------------------------------------------------------------------------------
_GL = {m: np.polynomial.legendre.leggauss(m) for m in (5, 10)}


def _gl(f, lo, hi, m):
    x, w = _GL[m]
    h = 0.5 * (hi - lo)
    c = 0.5 * (hi + lo)
    u = c[:, None] + h[:, None] * x[None, :]
    return (f(u) * w[None, :]).sum(axis=1) * h


def _w1_quantile(mu, points: np.ndarray, weights: np.ndarray) -> tuple[float, float]:
    """Exact ``W1(μ, Σ wᵢ δ_{xᵢ})`` in 1-D as ``∫₀¹ |F⁻¹(u) − Q(u)| du`` (sorted points).

    ``Q`` is the step quantile of the atoms: atom ``i`` holds the level cell
    ``[cᵢ, cᵢ₊₁)`` of the cumulative weights. Each cell is split where ``F⁻¹`` crosses ``xᵢ``
    (at ``u = F(xᵢ)``), so the integrand has one sign on each piece. Pieces touching
    ``u = 0`` or ``u = 1`` (where ``F⁻¹`` may be singular) use adaptive ``quad``; the others a
    10-point Gauss–Legendre rule, whose difference to a 5-point rule is returned as an
    accuracy estimate. For an :class:`Empirical1D` ``μ`` both quantiles are steps and the
    integral is summed exactly.

    Returns
    -------
    (value, abs_error_estimate)
    """
    c = np.concatenate([[0.0], np.cumsum(weights)])
    c[-1] = 1.0
    if isinstance(mu, Empirical1D):
        br = np.unique(np.concatenate([c, mu._cum, [0.0]]))
        br = br[(br >= 0) & (br <= 1)]
        mid = 0.5 * (br[:-1] + br[1:])
        qa = mu.ppf(mid)
        idx = np.minimum(np.searchsorted(c, mid, side="right") - 1, points.size - 1)
        return float(np.sum(np.abs(qa - points[idx]) * np.diff(br))), 0.0
    F = np.clip(mu.cdf(points), 0.0, 1.0)
    lo, hi = c[:-1], c[1:]
    split = np.clip(F, lo, hi)
    # pieces: [lo, split] where F⁻¹ ≤ x (integrand x − F⁻¹), [split, hi] where F⁻¹ ≥ x
    a = np.concatenate([lo, split])
    b = np.concatenate([split, hi])
    x = np.concatenate([points, points])
    sgn = np.concatenate([np.ones_like(points), -np.ones_like(points)])
    keep = b > a
    a, b, x, sgn = a[keep], b[keep], x[keep], sgn[keep]
    edge = (a <= 0.0) | (b >= 1.0)
    total, err = 0.0, 0.0
    inner = ~edge
    if np.any(inner):
        ai, bi, xi, si = a[inner], b[inner], x[inner], sgn[inner]

        def g(u):
            return si[:, None] * (xi[:, None] - mu.ppf(u))

        v10 = _gl(g, ai, bi, 10)
        v5 = _gl(g, ai, bi, 5)
        total += float(np.sum(np.maximum(v10, 0.0)))
        err += float(np.sum(np.abs(v10 - v5)))
    for ae, be, xe, se in zip(a[edge], b[edge], x[edge], sgn[edge]):
        val, e = integrate.quad(
            lambda u: se * (xe - float(mu.ppf(u))), float(ae), float(be),
            epsabs=1e-14, epsrel=1e-12, limit=200,
        )
        total += max(val, 0.0)
        err += e
    return total, err


def _as_1d(mu) -> Measure:
    if isinstance(mu, (Univariate, Empirical1D)):
        return mu
    if isinstance(mu, Atomic) and mu.dim == 1:
        return Empirical1D(mu.points[:, 0], mu.weights)
    raise InvalidInput(
        "mu must be a 1-D Univariate, Uniform, Empirical1D or 1-D Atomic/Dirac measure to be "
        f"quantized by quantile levels, got {mu!r}"
    )


# ------------------------------------------------------------------------------------------
# result objects
# ------------------------------------------------------------------------------------------
class Quantization:
    """Common interface of quantization results (frozen dataclasses).

    Every result knows, without building the atoms,

    * ``n_atoms`` -- the atom count, an exact Python ``int`` (it may be astronomically large);
    * ``bound`` -- the a-priori W1 bound of the paper's lemmas;
    * ``error`` -- an a-posteriori value, whose meaning ``error_kind`` states:
      ``"exact"`` (the exact W1), ``"product-l1"`` (the exact W1 for the ℓ1 ground cost, i.e.
      the sum of the exact marginal errors, an upper bound of the Euclidean W1) or
      ``"upper"`` (an upper bound of the Euclidean W1);
    * ``dim``.

    The atoms are built with :meth:`materialize` (refused above ``max_atoms``) or streamed
    with :meth:`iter_chunks`.
    """

    dim: int
    rule: str
    error_kind: str = "exact"

    n_atoms: int
    bound: float

    def __repr__(self) -> str:
        n = self.n_atoms
        if n < 10**12:
            count = str(n)
        else:  # exact ints beyond the float range: mantissa and exponent from the digits
            digits = str(n)
            count = f"{digits[0]}.{digits[1:4]}e+{len(digits) - 1}"
        return (f"{type(self).__name__}(dim={self.dim}, n_atoms={count}, bound={self.bound:.6g}, "
                f"rule={self.rule!r}, error_kind={self.error_kind!r})")

    def _block(self, start: int, count: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
        raise NotImplementedError

    @property
    def error(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def iter_chunks(self, chunk_size: int = 65536, *, start: int = 0,
                    stop: int | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Stream atoms ``[start, stop)`` as ``(points (m, dim), weights (m,))`` chunks, ``m ≤ chunk_size``.

        Tensor grids are enumerated in C order (last coordinate fastest) by mixed-radix index
        arithmetic, mixtures component after component; nothing beyond one chunk is built.
        """
        chunk_size = as_int(chunk_size, "chunk_size", low=1)
        start = as_int(start, "start", low=0)
        stop = self.n_atoms if stop is None else as_int(stop, "stop", low=start)
        stop = min(stop, self.n_atoms)
        if stop > _INT64_MAX:
            stop_ok = _INT64_MAX
        else:
            stop_ok = stop
        i = start
        while i < stop:
            if i >= stop_ok:
                raise TooLarge(f"atom indices beyond 2**63 - 1 cannot be streamed (n_atoms = {_fmt_count(self.n_atoms)})")
            m = min(chunk_size, stop - i)
            yield self._block(i, m)
            i += m

    def materialize(self, max_atoms: int = DEFAULT_MAX_ATOMS) -> Atomic:
        """All atoms as an :class:`~kinred.measures.Atomic` measure.

        Raises
        ------
        TooLarge
            If ``n_atoms > max_atoms`` (the count is known exactly before anything is built).
        """
        max_atoms = as_int(max_atoms, "max_atoms", low=1)
        if self.n_atoms > max_atoms:
            gib = self.n_atoms * (self.dim + 1) * 8 / 2**30
            raise TooLarge(
                f"the quantization has {_fmt_count(self.n_atoms)} atoms in dimension {self.dim} "
                f"(about {gib:.3g} GiB), more than max_atoms={max_atoms}: stream them with "
                "iter_chunks(), raise max_atoms, or ask for fewer atoms (larger eps / smaller atoms)"
            )
        pts, w = self._block(0, int(self.n_atoms))
        return Atomic(pts, w / w.sum())


@dataclass(frozen=True, eq=False, repr=False)
class Quantization1D(Quantization):
    """Equal-weight atoms at quantile levels of a 1-D measure (eqs. (4.20)–(4.21) of the paper).

    Attributes
    ----------
    measure : the 1-D measure
    rule : ``"midpoint"`` (levels ``(2i−1)/(2N)``) or ``"paper"`` (levels ``i/N``, ``x₀ = a``)
    levels : (N,) ndarray -- quantile levels
    points : (N,) ndarray -- atoms ``F⁻¹(levels)``, non-decreasing
    weights : (N,) ndarray -- ``1/N`` each
    bound : float -- ``σ/N`` (paper) or ``σ/(2N)`` (midpoint)
    error : float -- exact W1 (lazy; ``error_tol`` estimates its quadrature error)
    """

    measure: Measure
    rule: str
    levels: np.ndarray
    points: np.ndarray
    weights: np.ndarray
    bound: float
    dim: int = 1

    @property
    def n_atoms(self) -> int:
        return int(self.points.size)

    @cached_property
    def _err(self):
        return _w1_quantile(self.measure, self.points, self.weights)

    @property
    def error(self) -> float:
        """Exact ``W1(μ, μᴺ) = ∫₀¹ |F⁻¹(u) − Q(u)| du``."""
        return self._err[0]

    @property
    def error_tol(self) -> float:
        """Estimated absolute quadrature error of :attr:`error` (0 for empirical measures)."""
        return self._err[1]

    def _block(self, start, count):
        return self.points[start:start + count, None].copy(), self.weights[start:start + count].copy()


@dataclass(frozen=True, eq=False, repr=False)
class AtomicQuantization(Quantization):
    """An atomic measure is its own quantization (exact, error 0)."""

    measure: Atomic
    rule: str = "identity"
    bound: float = 0.0

    @property
    def dim(self) -> int:
        return self.measure.dim

    @property
    def n_atoms(self) -> int:
        return self.measure.n_atoms

    @property
    def error(self) -> float:
        return 0.0

    @property
    def points(self) -> np.ndarray:
        return self.measure.points

    @property
    def weights(self) -> np.ndarray:
        return self.measure.weights

    def _block(self, start, count):
        return self.measure.points[start:start + count].copy(), self.measure.weights[start:start + count].copy()


@dataclass(frozen=True, eq=False, repr=False)
class TensorQuantization(Quantization):
    """Grid of per-coordinate quantizations: Lemma 4.1 of the paper.

    .. math:: W_1(\\mu^1\\otimes\\cdots\\otimes\\mu^d, \\mu^N) \\le \\sum_j \\varepsilon_j,
              \\qquad N = \\prod_j N_j .

    ``error`` is the exact W1 for the ℓ1 ground cost, ``Σⱼ W1(μʲ, μʲ'ᴺʲ)`` (sum of the exact
    marginal errors), which is an upper bound of the Euclidean W1 (``error_kind="product-l1"``).

    Attributes
    ----------
    factors : tuple of Quantization1D / AtomicQuantization (1-D)
    budget : Budget or None -- the delayed-curse budget that chose the counts
    counts : tuple of int -- ``N_j``
    """

    measure: Measure
    rule: str
    factors: tuple
    budget: Budget | None = None
    error_kind: str = "product-l1"

    @property
    def dim(self) -> int:
        return len(self.factors)

    @property
    def counts(self) -> tuple:
        return tuple(f.n_atoms for f in self.factors)

    @property
    def n_atoms(self) -> int:
        return math.prod(self.counts)

    @property
    def bound(self) -> float:
        return float(sum(f.bound for f in self.factors))

    @property
    def k_bar(self) -> int:
        """Number of coordinates with more than one atom."""
        return sum(1 for n in self.counts if n > 1)

    @cached_property
    def error(self) -> float:
        return float(sum(f.error for f in self.factors))

    def _block(self, start, count):
        stop = start + count
        if stop - 1 > _INT64_MAX:
            raise TooLarge("atom indices beyond 2**63 - 1 cannot be streamed")
        idx = np.arange(count, dtype=np.int64) + np.int64(start)
        pts = np.empty((count, self.dim))
        w = np.ones(count)
        stride = 1
        for j in range(self.dim - 1, -1, -1):
            f = self.factors[j]
            nj = f.n_atoms
            fp, fw = f.points.reshape(-1), f.weights
            if nj == 1 or stride > stop - 1:
                pts[:, j] = fp[0]
                w *= fw[0]
            else:
                digit = (idx // np.int64(stride)) % np.int64(nj)
                pts[:, j] = fp[digit]
                w *= fw[digit]
            stride *= nj
        return pts, w


@dataclass(frozen=True, eq=False, repr=False)
class MixtureQuantization(Quantization):
    """Union of per-component quantizations, weights ``wₗ·(component weights)``.

    Lemma 4.2 of the paper, generalized to unequal weights and unequal
    atom counts by the same homogeneity/subadditivity argument:

    .. math:: W_1\\Bigl(\\sum_l w_l\\mu_l, \\sum_l w_l\\mu_l^{N_l}\\Bigr) \\le \\sum_l w_l\\,\\varepsilon_l .

    A mixture of anisotropic tensor products gives sparse-grid atoms (§4.5). The weights are
    never negative: signed Smolyak weights (chaospy, OpenTURNS) do not define a probability
    measure and cannot enter an optimal-transport problem. ``error = Σ wₗ errorₗ`` is an upper
    bound of the Euclidean W1 (``error_kind="upper"``).
    """

    measure: Measure
    rule: str
    components: tuple
    weights: np.ndarray
    error_kind: str = "upper"

    @property
    def dim(self) -> int:
        return self.components[0].dim

    @property
    def n_atoms(self) -> int:
        return sum(c.n_atoms for c in self.components)

    @property
    def bound(self) -> float:
        return float(sum(w * c.bound for w, c in zip(self.weights, self.components)))

    @cached_property
    def error(self) -> float:
        return float(sum(w * c.error for w, c in zip(self.weights, self.components)))

    def _block(self, start, count):
        pts, ws = [], []
        off = 0
        stop = start + count
        for w, c in zip(self.weights, self.components):
            n = c.n_atoms
            lo, hi = max(start, off), min(stop, off + n)
            if lo < hi:
                p, cw = c._block(lo - off, hi - lo)
                pts.append(p)
                ws.append(w * cw)
            off += n
            if off >= stop:
                break
        return np.concatenate(pts), np.concatenate(ws)


@dataclass(frozen=True, eq=False, repr=False)
class PushQuantization(Quantization):
    """Quantization of ``M#μ``: atoms of ``μ`` pushed by ``M`` (eq. (4.9)).

    Bound and error are those of the base times ``‖M‖`` (eq. (4.8):
    ``W1(M#μ, M#ν) ≤ ‖M‖ W1(μ, ν)``); ``error_kind="upper"``.
    """

    measure: Measure
    base: Quantization
    projection: object
    norm: float
    error_kind: str = "upper"

    @property
    def rule(self) -> str:
        return self.base.rule

    @property
    def dim(self) -> int:
        return int(self.projection.shape[0])

    @property
    def n_atoms(self) -> int:
        return self.base.n_atoms

    @property
    def bound(self) -> float:
        return self.norm * self.base.bound

    @cached_property
    def error(self) -> float:
        return self.norm * self.base.error

    def _block(self, start, count):
        p, w = self.base._block(start, count)
        return self.projection.apply(p), w


# ------------------------------------------------------------------------------------------
# entry points
# ------------------------------------------------------------------------------------------
def _levels(n: int, rule: str) -> np.ndarray:
    i = np.arange(n, dtype=np.float64)
    return i / n if rule == "paper" else (2 * i + 1) / (2 * n)


def quantize_1d(mu, n: int, *, rule: str = "midpoint") -> Quantization1D:
    """``n`` equal-weight atoms at quantile levels of a 1-D measure.

    ``rule="paper"``: levels ``i/N``, ``i = 0..N−1`` (so ``x₀ = a``), eq. (4.20) of the paper,
    with bound ``σ/N`` (eq. (4.21)).
    ``rule="midpoint"`` (default, W1-optimal): levels ``(2i−1)/(2N)``, ``i = 1..N``, the medians
    of the N quantile cells, with bound ``σ/(2N)``:

    .. math:: W_1(\\mu, \\mu^N) = \\int_0^1 |F^{-1}(u) - Q(u)|\\,du \\le \\frac{c\\,\\sigma}{N},
              \\quad c = \\tfrac12 \\text{ (midpoint)},\\ 1 \\text{ (paper)} .

    The result's ``error`` is this exact W1 (lazy).

    Examples
    --------
    >>> from kinred.measures import Uniform
    >>> q = quantize_1d(Uniform(0, 1), 4)
    >>> q.points, q.bound, round(q.error, 12)
    (array([0.125, 0.375, 0.625, 0.875]), 0.125, 0.0625)
    >>> round(quantize_1d(Uniform(0, 1), 4, rule="paper").error, 12)
    0.125
    """
    mu = _as_1d(mu)
    n = as_int(n, "n", low=1)
    rule = as_choice(rule, "rule", RULE_CONSTANT)
    lv = _levels(n, rule)
    pts = np.asarray(mu.ppf(lv), dtype=np.float64)
    pts = np.maximum.accumulate(pts)  # guard monotonicity against ppf round-off
    sigma = float(mu.support_widths()[0])
    return Quantization1D(
        measure=mu, rule=rule, levels=lv, points=pts, weights=np.full(n, 1.0 / n),
        bound=RULE_CONSTANT[rule] * sigma / n,
    )


def _n_for_eps(sigma: float, eps: float, c: float) -> int:
    if sigma <= 0:
        return 1
    n = max(1, math.ceil(c * sigma / eps * (1 - 1e-12)))
    while c * sigma / n > eps * (1 + 1e-12):
        n += 1
    return n


def _count(mu, eps, rule, node_limit) -> int:
    c = RULE_CONSTANT[rule]
    if isinstance(mu, Atomic):
        return mu.n_atoms
    if isinstance(mu, Univariate):
        return _n_for_eps(float(mu.support_widths()[0]), eps, c)
    if isinstance(mu, TensorProduct):
        return budget(mu.support_widths(), eps=eps, rule=rule, node_limit=node_limit).n_atoms
    if isinstance(mu, PushForward):
        norm = mu.projection.norm()
        return _count(mu.base, eps / norm if norm > 0 else math.inf, rule, node_limit)
    if isinstance(mu, Mixture):
        return sum(_count(m, eps, rule, node_limit) for m in mu.components)
    raise InvalidInput(f"cannot quantize a measure of type {type(mu).__name__}")


def _max_bound(mu, rule) -> float:
    """An ε at which every quantizer uses its minimal atom count."""
    return float(RULE_CONSTANT[rule] * np.sum(mu.support_widths()) * 2 + 1.0)


def quantize(mu: Measure, *, eps: float | None = None, atoms: int | None = None,
             rule: str = "midpoint", node_limit: int = 20000) -> Quantization:
    """Atoms for a measure with a guaranteed W1 bound: the one entry point.

    * 1-D laws: :func:`quantize_1d` with the fewest atoms meeting ``eps`` (or ``atoms``).
    * :class:`~kinred.measures.TensorProduct`: a grid whose per-coordinate counts come from
      :func:`~kinred.quantize.budget` (delayed curse, eq. (4.22)).
    * :class:`~kinred.measures.Mixture`: a union of component quantizations (Lemma 4.2); with
      ``eps`` every component gets accuracy ``eps`` (so ``Σ wₗ εₗ ≤ eps``), with ``atoms`` the
      smallest common component accuracy whose total count fits is found by bisection (the
      split of accuracy across components is not optimized).
    * :class:`~kinred.measures.PushForward`: quantize the base to ``eps/‖M‖`` and push the
      atoms (eq. (4.8)–(4.9)).
    * :class:`~kinred.measures.Atomic` / Dirac: the identity (exact). A 1-D atomic measure asked
      for fewer ``atoms`` than it has is re-quantized at quantile levels.

    Parameters
    ----------
    mu : Measure
    eps : float, optional -- target bound (> 0)
    atoms : int, optional -- atom budget (≥ 1); give exactly one of ``eps``, ``atoms``
    rule : {"midpoint", "paper"}
    node_limit : int -- branch-and-bound limit passed to :func:`~kinred.quantize.budget`

    Returns
    -------
    Quantization -- knows ``n_atoms``, ``bound``, ``error`` without materializing.

    Examples
    --------
    >>> from kinred.measures import TensorProduct, Uniform
    >>> mu = TensorProduct([Uniform(0, 1), Uniform(0, 0.5), Uniform(0, 0.01)])
    >>> q = quantize(mu, eps=0.1)
    >>> q.counts, q.n_atoms, round(q.bound, 4), round(q.error, 4)
    ((10, 6, 1), 60, 0.0967, 0.0483)
    """
    if not isinstance(mu, Measure):
        raise InvalidInput(f"mu must be a kinred Measure, got {type(mu).__name__}")
    rule = as_choice(rule, "rule", RULE_CONSTANT)
    if (eps is None) == (atoms is None):
        raise InvalidInput("give exactly one of eps (target W1 bound) and atoms (atom budget)")
    if eps is not None:
        eps = as_float(eps, "eps", low=0.0, low_open=True)
    else:
        atoms = as_int(atoms, "atoms", low=1)
    c = RULE_CONSTANT[rule]
    if isinstance(mu, Atomic):
        if atoms is not None and atoms < mu.n_atoms:
            if mu.dim == 1:
                return quantize_1d(mu, atoms, rule=rule)
            raise InvalidInput(
                f"atoms={atoms} is fewer than the {mu.n_atoms} atoms of this {mu.dim}-D atomic "
                "measure; an atomic measure quantizes exactly to itself"
            )
        return AtomicQuantization(mu)
    if isinstance(mu, Univariate):
        n = atoms if atoms is not None else _n_for_eps(float(mu.support_widths()[0]), eps, c)
        return quantize_1d(mu, n, rule=rule)
    if isinstance(mu, TensorProduct):
        b = budget(mu.support_widths(), eps=eps, atoms=atoms, rule=rule, node_limit=node_limit)
        factors = tuple(
            quantize_1d(f, n, rule=rule) if not (isinstance(f, Atomic) and f.n_atoms == 1)
            else AtomicQuantization(f)
            for f, n in zip(mu.factors, b.counts)
        )
        return TensorQuantization(measure=mu, rule=rule, factors=factors, budget=b)
    if isinstance(mu, PushForward):
        norm = float(mu.projection.norm())
        if eps is not None:
            base = quantize(mu.base, eps=eps / norm if norm > 0 else _max_bound(mu.base, rule),
                            rule=rule, node_limit=node_limit)
        else:
            base = quantize(mu.base, atoms=atoms, rule=rule, node_limit=node_limit)
        return PushQuantization(measure=mu, base=base, projection=mu.projection, norm=norm)
    if isinstance(mu, Mixture):
        if atoms is not None:
            hi = _max_bound(mu, rule)
            need = _count(mu, hi, rule, node_limit)
            if need > atoms:
                raise InvalidInput(
                    f"atoms={atoms} is too small for this mixture: its {len(mu.components)} "
                    f"components need at least {need} atoms together"
                )
            lo = hi * 1e-12
            if _count(mu, lo, rule, node_limit) <= atoms:
                hi = lo
            else:
                for _ in range(60):
                    mid = math.sqrt(lo * hi)
                    if _count(mu, mid, rule, node_limit) <= atoms:
                        hi = mid
                    else:
                        lo = mid
            eps = hi
        comps = tuple(quantize(m, eps=eps, rule=rule, node_limit=node_limit) for m in mu.components)
        return MixtureQuantization(measure=mu, rule=rule, components=comps, weights=mu.weights.copy())
    raise InvalidInput(f"cannot quantize a measure of type {type(mu).__name__}")
