"""Random Johnson–Lindenstrauss matrices (Lemma 2.1 of the paper and the matrices after it).

Four kinds, all normalized so that :math:`\\mathbb E\\|Mx\\|^2 = \\|x\\|^2` for every ``x``:

``"gaussian"``
    i.i.d. entries :math:`m_{ij} \\sim \\mathcal N(0, 1/k)` (the paper's first example after
    Lemma 2.1; Dasgupta–Gupta).
``"rademacher"``
    i.i.d. entries :math:`\\pm 1/\\sqrt k` with probability 1/2 each (the paper's Bernoulli
    example).
``"achlioptas"``
    Achlioptas' database-friendly sparse matrix (reference [A] of the paper, Theorem 1.1):
    :math:`\\sqrt{3/k}\\,\\{+1, 0, -1\\}` with probabilities :math:`\\{1/6, 2/3, 1/6\\}`; stored
    as a ``scipy.sparse`` CSR matrix (density 1/3) and applied sparsely.
``"srht"``
    Subsampled randomized Hadamard transform, a fast structured map in the spirit of
    Krahmer–Ward (Theorem 3.6 of the paper):
    :math:`M = \\sqrt{d'/k}\\, P H D`, with :math:`D` a diagonal of random signs (the
    Rademacher sequence :math:`\\xi` of Theorem 3.6), :math:`H` the orthonormal Walsh–Hadamard
    matrix of order :math:`d' = 2^{\\lceil \\log_2 d\\rceil}` acting on ``x`` padded with zeros,
    and :math:`P` a uniformly random choice of ``k`` distinct rows. Applied in
    :math:`O(d' \\log d')` per vector by a fast Walsh–Hadamard transform (Kronecker-blocked); the matrix
    is never formed.
``"dct"``
    The same construction with the orthonormal DCT-II of order :math:`d` (any ``d``, no
    padding; ``scipy.fft.dct``) in place of :math:`H`: :math:`M = \\sqrt{d/k}\\, P C D`.

For both structured kinds :math:`\\mathbb E\\|Mx\\|^2 = \\tfrac{d'}{k}\\,\\mathbb E\\|PHDx\\|^2 =
\\tfrac{d'}{k}\\tfrac{k}{d'}\\|HDx\\|^2 = \\|x\\|^2`. Their rows are orthonormal up to the factor
:math:`\\sqrt{d'/k}` when :math:`H` acts without padding (``"dct"``, or ``"srht"`` with ``d`` a
power of two), hence :math:`\\|M\\| = \\sqrt{d'/k}` exactly — the bound
:math:`\\|M\\| \\le \\sqrt{d/k}` assumed in Theorem 3.3 of the paper holds
with equality. With padding (``"srht"``, ``d`` not a power of two) the columns are cut to the
first ``d`` and :math:`\\|M\\| \\le \\sqrt{d'/k}`; :meth:`SRHTProjection.norm` computes it.
"""

from __future__ import annotations

import numbers

import numpy as np
import scipy.fft
import scipy.sparse

from .._rng import as_generator
from .._validate import as_array, as_choice, as_int, check_alloc
from ..errors import InvalidInput
from ._base import DenseProjection, Projection

__all__ = [
    "KINDS",
    "jl_matrix",
    "jl_min_dim",
    "SparseProjection",
    "SRHTProjection",
    "fwht",
]

#: The kinds accepted by :func:`jl_matrix`.
KINDS: tuple[str, ...] = ("gaussian", "rademacher", "achlioptas", "srht", "dct")


# ----------------------------------------------------------------------------------------------
# Fast Walsh–Hadamard transform
# ----------------------------------------------------------------------------------------------
def fwht(X) -> np.ndarray:
    """Orthonormal fast Walsh–Hadamard transform of the rows of ``X (n, m)``, ``m = 2^p``.

    Returns ``X Hᵀ = X H`` where :math:`H_{ij} = (-1)^{\\mathrm{popcount}(i \\,\\&\\, j)}/\\sqrt m`
    is the Sylvester (natural-order) Hadamard matrix, i.e. ``scipy.linalg.hadamard(m) / √m``.
    Cost :math:`O(n\\, m \\log m)`: the Kronecker factorization of :math:`H` into dense
    blocks of order <= 32, each applied to all rows at once by one matrix product.

    Parameters
    ----------
    X : (n, m) or (m,) array_like
        Rows to transform; ``m`` must be a power of two.

    Returns
    -------
    (n, m) or (m,) ndarray
        The transformed rows (a new array).

    Examples
    --------
    >>> fwht(np.array([1.0, 0.0, 0.0, 0.0]))
    array([0.5, 0.5, 0.5, 0.5])
    """
    Y = as_array(X, "X", ndim=(1, 2), copy=True)
    m = Y.shape[-1]
    if m < 1 or m & (m - 1):
        raise InvalidInput(f"X must have a power-of-two number of columns, got {m}")
    squeeze = Y.ndim == 1
    Y = _fwht_rows(np.ascontiguousarray(Y.reshape(-1, m)))
    return Y[0] if squeeze else Y


_FWHT_BLOCK = 32  # largest dense Hadamard factor used by _fwht_rows


def _hadamard_factor(f: int) -> np.ndarray:
    """Orthonormal Sylvester Hadamard matrix of order ``f`` (a power of two), built by Kronecker."""
    H = np.ones((1, 1))
    H2 = np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2.0)
    while H.shape[0] < f:
        H = np.kron(H2, H)
    return H


def _fwht_rows(Y: np.ndarray) -> np.ndarray:
    """Orthonormal Walsh–Hadamard transform of the rows of ``Y (n, m)``, ``m = 2^p`` (new array).

    Sylvester's construction gives :math:`H_m = H_{f_1} \\otimes \\cdots \\otimes H_{f_r}` for
    ``m = f_1 ⋯ f_r``. Writing a row index in mixed radix ``(j_1, …, j_r)``, the transform
    applies the small dense :math:`H_{f}` (``f <= 32``) along one digit at a time: a batched
    matmul over the last digit, then a transpose that moves this digit to the front. After
    ``r`` steps every digit has been transformed and rotated back into place. Cost
    :math:`O(n\\, m \\sum_i f_i) = O(n\\, m \\log m)` (as ``f_i <= 32``), in BLAS calls rather
    than ``log₂ m`` Python-level butterfly passes.
    """
    n, m = Y.shape
    p = m.bit_length() - 1
    lb = _FWHT_BLOCK.bit_length() - 1
    sizes = [_FWHT_BLOCK] * (p // lb) + ([1 << (p % lb)] if p % lb else [])
    Z = Y
    for f in reversed(sizes):
        Z = (Z.reshape(n, m // f, f) @ _hadamard_factor(f)).transpose(0, 2, 1).reshape(n, m)
    return np.ascontiguousarray(Z)


# ----------------------------------------------------------------------------------------------
# Projection classes
# ----------------------------------------------------------------------------------------------
class SparseProjection(Projection):
    """A projection stored as a ``scipy.sparse`` CSR matrix ``(k, d)`` and applied sparsely.

    Parameters
    ----------
    matrix : scipy.sparse matrix or array ``(k, d)``
    kind, seed
        Recorded as attributes.

    Examples
    --------
    >>> P = SparseProjection(scipy.sparse.eye(2, 3))
    >>> P.apply(np.array([[1.0, 2.0, 3.0]]))
    array([[1., 2.]])
    """

    def __init__(self, matrix, *, kind: str = "sparse", seed=None):
        S = scipy.sparse.csr_matrix(matrix, dtype=np.float64)
        if S.shape[0] < 1 or S.shape[1] < 1:
            raise InvalidInput(f"matrix must have at least one row and one column, got {S.shape}")
        if S.nnz and not np.all(np.isfinite(S.data)):
            raise InvalidInput("matrix must be finite")
        self.matrix = S
        self.shape = (int(S.shape[0]), int(S.shape[1]))
        self.kind = kind
        self.seed = seed

    @property
    def nnz(self) -> int:
        """Number of stored non-zeros."""
        return int(self.matrix.nnz)

    def _apply(self, X: np.ndarray) -> np.ndarray:
        # (M Xᵀ)ᵀ: sparse × dense costs O(nnz · n).
        return np.ascontiguousarray(np.asarray(self.matrix @ X.T).T)

    def _rapply(self, Y: np.ndarray) -> np.ndarray:
        # Y M = (Mᵀ Yᵀ)ᵀ, sparse as well.
        return np.ascontiguousarray(np.asarray(self.matrix.T @ Y.T).T)

    def to_dense(self) -> np.ndarray:
        return self.matrix.toarray()


class SRHTProjection(Projection):
    """Structured map :math:`M = \\sqrt{d'/k}\\, P T D` applied without forming ``M``.

    :math:`D = \\mathrm{diag}(\\text{signs})`, :math:`T` the orthonormal Walsh–Hadamard matrix
    of order :math:`d'` (``transform="hadamard"``, ``x`` zero-padded from ``d`` to ``d'``) or the
    orthonormal DCT-II of order :math:`d' = d` (``transform="dct"``), and :math:`P` keeps the
    rows ``rows`` (``k`` distinct indices in ``[0, d')``). Usually built by
    :func:`jl_matrix` with ``kind="srht"`` or ``"dct"``.

    Parameters
    ----------
    signs : (d,) array_like of ±1
    rows : (k,) array_like of distinct ints in ``[0, d')``
    transform : {"hadamard", "dct"}
    kind, seed
        Recorded as attributes.

    Examples
    --------
    >>> P = SRHTProjection(np.ones(4), [0], transform="hadamard")
    >>> P.apply(np.array([1.0, 1.0, 1.0, 1.0]))   # sqrt(4/1) * (sum / 2)
    array([4.])
    """

    def __init__(self, signs, rows, *, transform: str = "hadamard", kind: str | None = None,
                 seed=None):
        transform = as_choice(transform, "transform", ("hadamard", "dct"))
        signs = as_array(signs, "signs", ndim=1)
        if signs.size < 1 or not np.all(np.abs(signs) == 1.0):
            raise InvalidInput("signs must be a non-empty vector of +1/-1 entries")
        d = signs.size
        d_pad = 1 << (d - 1).bit_length() if transform == "hadamard" else d
        rows = np.asarray(rows)
        if rows.ndim != 1 or rows.size < 1 or not np.issubdtype(rows.dtype, np.integer):
            raise InvalidInput(f"rows must be a non-empty 1-d integer array, got {rows!r}")
        if rows.min() < 0 or rows.max() >= d_pad or np.unique(rows).size != rows.size:
            raise InvalidInput(f"rows must be distinct integers in [0, {d_pad}), got {rows!r}")
        self.signs = signs.copy()
        self.rows = rows.astype(np.intp)
        self.transform = transform
        self.d_padded = int(d_pad)
        self.shape = (int(rows.size), int(d))
        self.scale = float(np.sqrt(d_pad / rows.size))
        self.kind = kind if kind is not None else ("srht" if transform == "hadamard" else "dct")
        self.seed = seed

    def _apply(self, X: np.ndarray) -> np.ndarray:
        n, d = X.shape
        if self.transform == "hadamard":
            Y = np.zeros((n, self.d_padded))
            np.multiply(X, self.signs, out=Y[:, :d])
            Y = _fwht_rows(Y)
        else:
            Y = scipy.fft.dct(X * self.signs, type=2, norm="ortho", axis=1)
        out = Y[:, self.rows]
        out *= self.scale
        return out

    def _rapply(self, Y: np.ndarray) -> np.ndarray:
        """``Y M = √(d'/k) (Y P) T D`` row-wise: scatter into the kept rows, inverse transform
        (``H`` is symmetric and orthonormal, the DCT-II's inverse is its transpose), cut the
        padding, multiply by the signs; same cost as :meth:`apply`."""
        n = Y.shape[0]
        Z = np.zeros((n, self.d_padded))
        Z[:, self.rows] = Y
        if self.transform == "hadamard":
            Z = _fwht_rows(Z)
        else:
            Z = scipy.fft.idct(Z, type=2, norm="ortho", axis=1)
        out = Z[:, :self.d] * self.signs
        out *= self.scale
        return out

    def to_dense(self) -> np.ndarray:
        """The ``(k, d)`` matrix, built by applying the map to the identity (for tests)."""
        return np.ascontiguousarray(self._apply(np.eye(self.d)).T)

    def norm(self) -> float:
        """Exact operator norm: ``√(d'/k)`` when no padding occurs (orthonormal rows), else SVD."""
        if self.d_padded == self.d and self.k <= self.d:
            return self.scale
        return super().norm()


# ----------------------------------------------------------------------------------------------
# Factory
# ----------------------------------------------------------------------------------------------
def jl_matrix(k: int, d: int, kind: str = "gaussian", seed=None) -> Projection:
    """Draw a random Johnson–Lindenstrauss map ``M: ℝᵈ → ℝᵏ`` (Lemma 2.1, eq. (2.1)).

    With :math:`k \\ge` :func:`jl_min_dim` ``(n, ε)``, ``M`` satisfies, with high probability,
    for all pairs of ``n`` given points

    .. math::

        (1-\\varepsilon)\\|x-\\tilde x\\|^2 \\le \\|Mx - M\\tilde x\\|^2 \\le (1+\\varepsilon)\\|x-\\tilde x\\|^2 ,

    and every kind is normalized so that :math:`\\mathbb E\\|Mx\\|^2 = \\|x\\|^2`.

    Parameters
    ----------
    k : int
        Target dimension, ``k >= 1`` (``k <= d`` for ``"dct"``, ``k <= d'`` for ``"srht"``).
    d : int
        Source dimension, ``d >= 1``.
    kind : {"gaussian", "rademacher", "achlioptas", "srht", "dct"}
        See the module docstring for the distributions.
    seed : None, int, SeedSequence or Generator
        Randomness (:func:`kinred._rng.as_generator`). Draw order: ``gaussian`` one
        ``standard_normal((k, d))``; ``rademacher`` one ``integers(0, 2, (k, d))``;
        ``achlioptas`` one ``integers(0, 6, (k, d))`` (0 → +, 1 → −, else 0); structured kinds
        ``integers(0, 2, d)`` for the signs then ``choice(d', k, replace=False)`` for the rows.

    Returns
    -------
    Projection
        A :class:`~kinred.projection.DenseProjection` (gaussian, rademacher),
        :class:`SparseProjection` (achlioptas) or :class:`SRHTProjection` (srht, dct), with
        ``.kind``, ``.seed`` and ``.shape == (k, d)``.

    Raises
    ------
    TooLarge
        The matrix would exceed the memory limit (environment variable ``KINRED_MAX_BYTES``,
        default 2 GiB); checked before anything is drawn.

    Examples
    --------
    >>> M = jl_matrix(3, 8, "rademacher", seed=0)
    >>> M.shape, M.kind, bool(np.all(np.abs(M.to_dense()) == 1 / np.sqrt(3)))
    ((3, 8), 'rademacher', True)
    >>> S = jl_matrix(4, 16, "srht", seed=1)
    >>> bool(np.isclose(S.norm(), np.sqrt(16 / 4)))
    True
    """
    k = as_int(k, "k", low=1)
    d = as_int(d, "d", low=1)
    kind = as_choice(kind, "kind", KINDS)
    _check_size(k, d, kind)
    rng = as_generator(seed)
    stored_seed = seed if (seed is None or isinstance(seed, numbers.Integral)) else repr(seed)
    if kind == "gaussian":
        M = rng.standard_normal((k, d))
        M *= 1.0 / np.sqrt(k)
        return DenseProjection(M, kind=kind, seed=stored_seed)
    if kind == "rademacher":
        bits = rng.integers(0, 2, size=(k, d), dtype=np.int8)
        M = np.where(bits == 1, 1.0, -1.0) / np.sqrt(k)
        return DenseProjection(M, kind=kind, seed=stored_seed)
    if kind == "achlioptas":
        u = rng.integers(0, 6, size=(k, d), dtype=np.int8)
        vals = np.zeros((k, d), dtype=np.float64)
        vals[u == 0] = 1.0
        vals[u == 1] = -1.0
        S = scipy.sparse.csr_matrix(vals)
        S.data *= np.sqrt(3.0 / k)
        return SparseProjection(S, kind=kind, seed=stored_seed)
    # structured kinds
    transform = "hadamard" if kind == "srht" else "dct"
    d_pad = 1 << (d - 1).bit_length() if transform == "hadamard" else d
    if k > d_pad:
        what = "d' (d padded to a power of two)" if transform == "hadamard" else "d"
        raise InvalidInput(f"k must be <= {what} = {d_pad} for kind={kind!r}, got k={k}")
    signs = np.where(rng.integers(0, 2, size=d) == 1, 1.0, -1.0)
    rows = np.sort(rng.choice(d_pad, size=k, replace=False))
    return SRHTProjection(signs, rows, transform=transform, kind=kind, seed=stored_seed)


#: Peak bytes per entry of a ``(k, d)`` matrix while it is drawn: float64 entries (gaussian);
#: int8 bits, the ±1 array and the scaled copy (rademacher); int8 draws, boolean masks, the
#: dense values and the CSR arrays of about a third of them (achlioptas).
_ENTRY_BYTES = {"gaussian": 8, "rademacher": 17, "achlioptas": 16}


def _check_size(k: int, d: int, kind: str) -> None:
    """:func:`~kinred._validate.check_alloc` of :func:`jl_matrix` before anything is drawn."""
    if kind in _ENTRY_BYTES:
        need, arrays = _ENTRY_BYTES[kind] * k * d, f"a dense ({k}, {d}) matrix"
    else:  # signs (d,), the padded transform's row choice (d'), the rows (k,)
        d_pad = 1 << (d - 1).bit_length() if kind == "srht" else d
        need, arrays = 8 * (d + 2 * d_pad) + 16 * k, f"signs ({d},) and a row choice of {d_pad}"
    check_alloc(need, f"jl_matrix(k={k}, d={d}, kind={kind!r})",
                "a smaller k (kinred.projection.jl_min_dim gives the k a distortion needs) or "
                "a structured kind ('srht', 'dct': O(d) memory)" if kind in _ENTRY_BYTES else
                "a smaller d", detail=f" for {arrays}")


def jl_min_dim(n_points, eps):
    """Smallest ``k`` for which the Johnson–Lindenstrauss bound guarantees distortion ``eps``.

    .. math::

        k \\ge \\frac{4 \\ln n}{\\varepsilon^2/2 - \\varepsilon^3/3}

    (Dasgupta & Gupta, *An elementary proof of a theorem of Johnson and Lindenstrauss*, 2003,
    Theorem 2.1 — reference [DG] of the paper; the same formula as scikit-learn's
    ``johnson_lindenstrauss_min_dim``). For such ``k`` a Gaussian ``M`` satisfies eq. (2.1)
    for all pairs of ``n`` points with probability at least :math:`1/n`
    per draw in the original statement — in practice with overwhelming probability. The
    result is rounded **up** (``ceil``) so that ``k`` satisfies the inequality; scikit-learn
    truncates and can return a value one below it.

    Parameters
    ----------
    n_points : int or array_like of int
        Number of points, ``>= 1``.
    eps : float or array_like of float
        Distortion, in ``(0, 1)``. Broadcast against ``n_points``.

    Returns
    -------
    int or ndarray of int64
        ``int`` when both arguments are scalars, else an array of the broadcast shape.

    Examples
    --------
    >>> jl_min_dim(10**6, 0.5)
    664
    >>> jl_min_dim(1000, [0.1, 0.5]).tolist()
    [5921, 332]
    """
    n = np.asarray(n_points)
    e = as_array(eps, "eps", ndim=None)
    if n.dtype == object or not (np.issubdtype(n.dtype, np.integer) or np.issubdtype(n.dtype, np.floating)):
        raise InvalidInput(f"n_points must be a positive integer (or array of them), got {n_points!r}")
    if np.any(~np.isfinite(n)) or np.any(n < 1) or np.any(n != np.floor(n)):
        raise InvalidInput(f"n_points must be integers >= 1, got {n_points!r}")
    if np.any(e <= 0) or np.any(e >= 1):
        raise InvalidInput(f"eps must lie in the open interval (0, 1), got {eps!r}")
    denom = e**2 / 2.0 - e**3 / 3.0
    k = np.ceil(4.0 * np.log(n.astype(np.float64)) / denom).astype(np.int64)
    if np.ndim(k) == 0:
        return int(k)
    return k
