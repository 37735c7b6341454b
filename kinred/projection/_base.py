"""Linear maps ℝᵈ → ℝᵏ used as projections.

Every projection in kinred is a :class:`Projection`: it maps a batch of row vectors
``X (n, d)`` to ``X Mᵀ (n, k)`` with :meth:`Projection.apply`, and knows its shape, its
operator norm and its dense matrix. Dense matrices (``ndarray (k, d)``) are accepted wherever
a projection is, through :func:`as_projection`.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_array
from ..errors import InvalidInput

__all__ = ["Projection", "DenseProjection", "as_projection"]


class Projection:
    """Base class of linear maps ``M: ℝᵈ → ℝᵏ`` acting on row vectors.

    Subclasses implement ``_apply`` (for a validated ``(n, d)`` float array) and
    :meth:`to_dense`; they set ``self.shape = (k, d)``, ``self.kind`` and ``self.seed``.
    """

    shape: tuple[int, int]
    kind: str = "dense"
    seed = None

    @property
    def k(self) -> int:
        """Target dimension."""
        return self.shape[0]

    @property
    def d(self) -> int:
        """Source dimension."""
        return self.shape[1]

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

    def __matmul__(self, other):
        """``M @ x`` for a vector ``x (d,)`` or a matrix ``(d, m)`` of column vectors."""
        other = np.asarray(other, dtype=float)
        if other.ndim == 1:
            return self.apply(other)
        return self.apply(other.T).T

    def _apply(self, X: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_dense(self) -> np.ndarray:  # pragma: no cover - abstract
        """The ``(k, d)`` matrix of the map."""
        raise NotImplementedError

    def norm(self) -> float:
        """Operator norm ‖M‖₂ (largest singular value)."""
        return float(np.linalg.norm(self.to_dense(), 2))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(kind={self.kind!r}, shape={self.shape}, seed={self.seed!r})"


class DenseProjection(Projection):
    """A projection given by an explicit ``(k, d)`` matrix.

    Examples
    --------
    >>> P = DenseProjection(np.eye(2, 3))
    >>> P.apply(np.array([[1.0, 2.0, 3.0]]))
    array([[1., 2.]])
    """

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

    def to_dense(self) -> np.ndarray:
        return self.matrix


def as_projection(M) -> Projection:
    """Accept a :class:`Projection` or a ``(k, d)`` array; return a :class:`Projection`."""
    if isinstance(M, Projection):
        return M
    return DenseProjection(M)
