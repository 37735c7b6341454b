"""Quantizations of measures: result objects that know their atoms without building them."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Iterator

import numpy as np

from .._validate import as_int, check_alloc
from ..errors import TooLarge
from ..measures import Atomic, Measure
from ._budget import Budget
from ._error1d import w1_quantile
from ._planning import materialize_fit
from ._size import block_rows, chunks_bytes, fmt_count, largest, materialize_bytes, max_bytes_limit

__all__ = [
    "Quantization",
    "Quantization1D",
    "TensorQuantization",
    "MixtureQuantization",
    "PushQuantization",
    "AtomicQuantization",
]

_INT64_MAX = 2**63 - 1


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

    The atoms are built with :meth:`materialize` or streamed with :meth:`iter_chunks`; both
    first predict the bytes they will allocate (:attr:`materialize_bytes`, see
    :func:`~kinred.quantize.preflight`) and raise :class:`~kinred.errors.TooLarge` past the
    limit (``max_bytes=``, else ``KINRED_MAX_BYTES``, else
    :data:`~kinred.quantize.DEFAULT_MAX_BYTES`).
    """

    dim: int
    rule: str
    error_kind: str = "exact"

    n_atoms: int
    bound: float

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(dim={self.dim}, n_atoms={fmt_count(self.n_atoms)}, "
                f"bound={self.bound:.6g}, rule={self.rule!r}, error_kind={self.error_kind!r})")

    @property
    def _width(self) -> int:
        """Entries of the widest row one block of atoms holds (a push-forward: base + image)."""
        return self.dim

    @property
    def materialize_bytes(self) -> int:
        """Bytes :meth:`materialize` would allocate at its peak (an exact int, nothing is built)."""
        return materialize_bytes(self.n_atoms, self.dim, self._width)

    def _block(self, start: int, count: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
        raise NotImplementedError

    @property
    def error(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def iter_chunks(self, chunk_size: int = 65536, *, start: int = 0, stop: int | None = None,
                    max_bytes=None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Stream atoms ``[start, stop)`` as ``(points (m, dim), weights (m,))`` chunks, ``m ≤ chunk_size``.

        Tensor grids are enumerated in C order (last coordinate fastest) by mixed-radix index
        arithmetic, mixtures component after component; nothing beyond one chunk is built.

        Raises
        ------
        TooLarge
            If one chunk would allocate more than ``max_bytes`` (checked here, before the
            first chunk).
        """
        chunk_size = as_int(chunk_size, "chunk_size", low=1)
        start = as_int(start, "start", low=0)
        stop = self.n_atoms if stop is None else as_int(stop, "stop", low=start)
        stop = min(stop, self.n_atoms)
        limit = max_bytes_limit(max_bytes)
        rows = min(chunk_size, max(stop - start, 1))

        def fit():
            k = largest(lambda r: chunks_bytes(r, self._width) <= limit, rows)
            return f"chunk_size <= {k} fits" if k else "no chunk size fits: raise max_bytes"

        check_alloc(chunks_bytes(rows, self._width), f"iter_chunks(chunk_size={chunk_size})", fit,
                    max_bytes=limit, keyword="max_bytes",
                    detail=f" per chunk of {rows} atoms in dimension {self.dim}")
        return self._chunks(chunk_size, start, stop)

    def _chunks(self, chunk_size, start, stop):
        i = start
        while i < stop:
            if i > _INT64_MAX:
                raise TooLarge("atom indices beyond 2**63 - 1 cannot be streamed "
                               f"(n_atoms = {fmt_count(self.n_atoms)})")
            m = min(chunk_size, stop - i)
            yield self._block(i, m)
            i += m

    def materialize(self, max_atoms: int | None = None, *, max_bytes=None) -> Atomic:
        """All atoms as an :class:`~kinred.measures.Atomic` measure.

        Parameters
        ----------
        max_atoms : int, optional -- refuse more atoms than this (no count limit by default)
        max_bytes : int or str, optional -- memory limit (default: ``KINRED_MAX_BYTES``, else
            :data:`~kinred.quantize.DEFAULT_MAX_BYTES`)

        Raises
        ------
        TooLarge
            If ``n_atoms > max_atoms`` or :attr:`materialize_bytes` exceeds the memory limit
            (both known exactly before anything is built). The message names the atoms, the
            bytes, the limit, and the atom count and ε that would fit.
        """
        limit = max_bytes_limit(max_bytes)
        n = self.n_atoms
        if max_atoms is not None and n > as_int(max_atoms, "max_atoms", low=1):
            raise TooLarge(
                f"the quantization has {fmt_count(n)} atoms in dimension {self.dim}, more than "
                f"max_atoms={max_atoms}: stream them with iter_chunks(), raise max_atoms, or ask for "
                "fewer atoms (larger eps / smaller atoms)"
            )

        def fit():
            return f"{materialize_fit(self, limit)}; or stream them with iter_chunks()"

        check_alloc(self.materialize_bytes, "materialize()", fit, max_bytes=limit,
                    keyword="max_bytes", detail=f" for {fmt_count(n)} atoms in dimension {self.dim}")
        n = int(n)
        rows = block_rows(self._width)
        pts, w = np.empty((n, self.dim)), np.empty(n)
        for i in range(0, n, rows):
            m = min(rows, n - i)
            pts[i:i + m], w[i:i + m] = self._block(i, m)
        w /= w.sum()
        return Atomic(pts, w)


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
        return w1_quantile(self.measure, self.points)

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
    def _width(self) -> int:
        return max(c._width for c in self.components)

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

    @property
    def _width(self) -> int:
        return self.base._width + self.dim

    def _block(self, start, count):
        p, w = self.base._block(start, count)
        return self.projection.apply(p), w


