"""Linear maps ℝᵈ → ℝᵏ used as projections.

Every projection in kinred is a :class:`Projection`: it maps a batch of row vectors
``X (n, d)`` to ``X Mᵀ (n, k)`` with :meth:`Projection.apply`, and knows its shape, its
operator norm and its dense matrix. Dense matrices (``ndarray (k, d)``) are accepted wherever
a projection is, through :func:`as_projection`.

A projection also behaves like the ``(k, d)`` matrix it is, for numpy code:
``np.asarray(M)`` is :meth:`Projection.to_dense`, ``M @ x`` maps a vector ``(d,)`` or the
columns of ``(d, n)``, ``X @ M.T`` maps the rows of ``X (n, d)`` and ``Y @ M`` applies the
transpose. ``M.T`` is a :class:`TransposedProjection`, which keeps the fast apply of the
structured maps (no dense matrix is formed for ``@``).
"""

from __future__ import annotations

import numpy as np

from .._validate import as_array
from ..errors import InvalidInput

__all__ = ["Projection", "DenseProjection", "TransposedProjection", "as_projection"]


class Projection:
    """Base class of linear maps ``M: ℝᵈ → ℝᵏ`` acting on row vectors.

    Subclasses implement ``_apply`` (for a validated ``(n, d)`` float array), :meth:`to_dense`
    and, when they have a faster one than the dense product, ``_rapply`` (``Y (n, k) -> Y M``);
    they set ``self.shape = (k, d)``, ``self.kind`` and ``self.seed``.

    The array protocol makes a projection usable where numpy expects its ``(k, d)`` matrix:

    * ``np.asarray(M)`` is ``M.to_dense()`` (``float64``). For the structured maps (``"srht"``,
      ``"dct"``) this builds the matrix, ``O(k·d)`` memory and ``O(d·d′ log d′)`` time;
      ``np.asarray(M, copy=False)`` is refused for them (:class:`~kinred.errors.InvalidInput`,
      a ``ValueError`` as numpy's protocol asks).
    * ``M @ x`` for ``x (d,)`` gives ``M x (k,)``; for ``x (d, n)`` the ``(k, n)`` images of the
      columns. ``X @ M.T`` for ``X (n, d)`` is :meth:`apply` (``X Mᵀ``), ``Y @ M`` for
      ``Y (n, k)`` or ``(k,)`` is ``Y M`` and ``M.T @ y`` is ``Mᵀ y``. Stacks broadcast as for
      ndarrays (``X (T, N, d) @ M.T`` is ``(T, N, k)``). None of them forms the dense matrix
      of a structured map. Operands of the wrong shape raise
      :class:`~kinred.errors.InvalidInput` naming both shapes.
    * ``M.shape == (k, d)``, ``M.ndim == 2``, ``M.dtype == float64``; ``M.T`` is a
      :class:`TransposedProjection` with ``M.T.T is M``.

    Examples
    --------
    >>> M = DenseProjection([[1.0, 0.0, 2.0], [0.0, 1.0, 0.0]])
    >>> M @ np.array([1.0, 1.0, 1.0])
    array([3., 1.])
    >>> np.array([[1.0, 1.0, 1.0]]) @ M.T
    array([[3., 1.]])
    >>> np.asarray(M).shape, M.T.shape
    ((2, 3), (3, 2))
    """

    shape: tuple[int, int]
    kind: str = "dense"
    seed = None

    #: Matrix rank, as for a 2-d ndarray.
    ndim = 2
    #: Entries are float64.
    dtype = np.dtype(np.float64)
    #: Whether :meth:`to_dense` returns a stored array (no copy, no computation).
    _stores_dense = False

    @property
    def k(self) -> int:
        """Target dimension."""
        return self.shape[0]

    @property
    def d(self) -> int:
        """Source dimension."""
        return self.shape[1]

    @property
    def T(self) -> "Projection":
        """The transposed map ``Mᵀ: ℝᵏ → ℝᵈ`` (a :class:`TransposedProjection`, nothing copied)."""
        return TransposedProjection(self)

    def apply(self, X) -> np.ndarray:
        """Return ``X Mᵀ``: rows of ``X (n, d)`` (or a single vector ``(d,)``) mapped to ℝᵏ."""
        X = as_array(X, "X", ndim=(1, 2))
        if X.shape[-1] != self.d:
            raise InvalidInput(
                f"X must have {self.d} columns (the projection's source dimension d), "
                f"got shape {X.shape}"
            )
        if X.ndim == 1:
            return self._apply(X[None, :])[0]
        return self._apply(X)

    # ------------------------------------------------------------------ array protocol
    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        """The dense ``(k, d)`` matrix, for ``np.asarray(M)`` (numpy 2 signature)."""
        if copy is False and not self._stores_dense:
            raise InvalidInput(
                f"np.asarray({type(self).__name__}, copy=False): this {self.kind!r} map has no "
                f"stored {self.shape} matrix; it is built by to_dense() (drop copy=False)"
            )
        A = self.to_dense()
        if dtype is not None and np.dtype(dtype) != A.dtype:
            if copy is False:
                raise InvalidInput(f"np.asarray(projection, dtype={np.dtype(dtype)}, copy=False): "
                                   f"the matrix is {A.dtype}; converting it needs a copy")
            return A.astype(dtype)
        return A.copy() if copy else A

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        """``np.matmul`` (and ``ndarray @ projection``) without forming the dense matrix;
        every other ufunc acts on the dense matrix."""
        if ufunc is np.matmul and method == "__call__" and not kwargs and len(inputs) == 2:
            a, b = inputs
            return self.__matmul__(b) if a is self else self.__rmatmul__(a)
        dense = [np.asarray(x) if isinstance(x, Projection) else x for x in inputs]
        return getattr(ufunc, method)(*dense, **kwargs)

    def _operand(self, other, left: bool) -> np.ndarray:
        """``other`` as a float array aligned with ``self``: ``M @ x`` (``left``) or ``x @ M``."""
        sym = "M.T" if isinstance(self, TransposedProjection) else "M"
        expr = f"{sym} @ x" if left else f"x @ {sym}"
        x = as_array(other, f"x in {expr}", ndim=None)
        n = self.d if left else self.k
        axis = (0 if x.ndim == 1 else -2) if left else -1
        if x.ndim < 1 or x.shape[axis] != n:
            want = f"({n},) or (..., {n}, m)" if left else f"({n},) or (..., {n})"
            shapes = f"{self.shape} and {x.shape}" if left else f"{x.shape} and {self.shape}"
            raise InvalidInput(
                f"{expr}: shapes {shapes} are not aligned ({sym} is a {type(self).__name__} "
                f"of shape {self.shape}); x must have shape {want}"
            )
        return x

    def __matmul__(self, other) -> np.ndarray:
        """``M @ x`` for a vector ``x (d,)`` or matrices ``(..., d, m)`` of column vectors."""
        x = self._operand(other, True)
        if x.ndim == 1:
            return self._apply(x[None, :])[0]
        rows = np.swapaxes(x, -1, -2)
        out = self._apply(rows.reshape(-1, self.d)).reshape(rows.shape[:-1] + (self.k,))
        return np.swapaxes(out, -1, -2)

    def __rmatmul__(self, other) -> np.ndarray:
        """``x @ M = x M`` for a vector ``x (k,)`` or rows ``x (..., k)``."""
        x = self._operand(other, False)
        return self._rapply(x.reshape(-1, self.k)).reshape(x.shape[:-1] + (self.d,))

    # ------------------------------------------------------------------ to implement
    def _apply(self, X: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _rapply(self, Y: np.ndarray) -> np.ndarray:
        """``Y M`` for validated rows ``Y (n, k)``; by default through the dense matrix."""
        return Y @ self.to_dense()

    def to_dense(self) -> np.ndarray:  # pragma: no cover - abstract
        """The ``(k, d)`` matrix of the map."""
        raise NotImplementedError

    def norm(self) -> float:
        """Operator norm ‖M‖₂ (largest singular value)."""
        return float(np.linalg.norm(self.to_dense(), 2))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(kind={self.kind!r}, shape={self.shape}, seed={self.seed!r})"


class TransposedProjection(Projection):
    """The transpose ``Mᵀ: ℝᵏ → ℝᵈ`` of a projection ``M``, built by ``M.T``.

    Applies ``M``'s transpose (``X (n, k) -> X M``) and, for ``X @ M.T``, ``M`` itself
    (:meth:`Projection.apply`): structured maps keep their fast transforms. ``kind`` and
    ``seed`` are those of ``M``; ``M.T.T`` is ``M``.

    Parameters
    ----------
    base : Projection
        The map ``M``.

    Examples
    --------
    >>> M = DenseProjection(np.eye(2, 3))
    >>> M.T.apply(np.array([1.0, 2.0])), M.T.T is M
    (array([1., 2., 0.]), True)
    """

    def __init__(self, base: Projection):
        if not isinstance(base, Projection):
            raise InvalidInput(f"base must be a Projection, got {type(base).__name__}")
        self.base = base
        self.shape = (base.d, base.k)
        self.kind = base.kind
        self.seed = base.seed
        self._stores_dense = base._stores_dense

    @property
    def T(self) -> Projection:
        return self.base

    def _apply(self, X: np.ndarray) -> np.ndarray:
        return self.base._rapply(X)

    def _rapply(self, Y: np.ndarray) -> np.ndarray:
        return self.base._apply(Y)

    def to_dense(self) -> np.ndarray:
        return self.base.to_dense().T

    def norm(self) -> float:
        return self.base.norm()

    def __repr__(self) -> str:
        return f"{self.base!r}.T"


class DenseProjection(Projection):
    """A projection given by an explicit ``(k, d)`` matrix.

    Examples
    --------
    >>> P = DenseProjection(np.eye(2, 3))
    >>> P.apply(np.array([[1.0, 2.0, 3.0]]))
    array([[1., 2.]])
    """

    _stores_dense = True

    def __init__(self, matrix, *, kind: str = "dense", seed=None):
        M = as_array(matrix, "M", ndim=2)
        if M.shape[0] < 1 or M.shape[1] < 1:
            raise InvalidInput(f"M must have at least one row and one column, got shape {M.shape}")
        self.matrix = np.ascontiguousarray(M)
        self.shape = (int(M.shape[0]), int(M.shape[1]))
        self.kind = kind
        self.seed = seed

    def _apply(self, X: np.ndarray) -> np.ndarray:
        return X @ self.matrix.T

    def _rapply(self, Y: np.ndarray) -> np.ndarray:
        return Y @ self.matrix

    def to_dense(self) -> np.ndarray:
        return self.matrix


def as_projection(M) -> Projection:
    """Accept a :class:`Projection` or a ``(k, d)`` array; return a :class:`Projection`."""
    if isinstance(M, Projection):
        return M
    return DenseProjection(M)
