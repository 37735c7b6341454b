"""Base class of measures, push-forwards and atomic measures."""

from __future__ import annotations

import numpy as np

from .._rng import as_generator
from .._validate import as_array, as_int, as_weights
from ..errors import InvalidInput

__all__ = ["Measure", "PushForward", "Atomic", "Dirac"]


class Measure:
    """A compactly supported probability measure on ℝᵈ (the paper's :math:`\\mathcal P_c(\\mathbb R^d)`).

    Every measure has

    * ``dim`` -- the dimension ``d``;
    * ``sample(n, seed=None) -> (n, d) ndarray`` -- ``n`` independent draws;
    * ``support_box() -> (lo (d,), hi (d,))`` -- a coordinate box containing the support;
    * ``support_widths() -> (d,) ndarray`` -- the widths ``σⱼ = bⱼ − aⱼ`` of that box, the
      quantities that drive the delayed-curse budget, eq. (4.22) of the paper;
    * ``push(M) -> Measure`` -- the push-forward ``M#μ`` of eq. (4.8).

    Subclasses implement ``_sample(n, rng)`` and ``support_box``.
    """

    dim: int

    def sample(self, n: int, seed=None) -> np.ndarray:
        """Draw ``n`` independent points, returned as an ``(n, dim)`` float64 array.

        Parameters
        ----------
        n : int
            Number of draws (>= 0).
        seed : None, int, SeedSequence or Generator
            Randomness, converted once with :func:`kinred._rng.as_generator`.
        """
        n = as_int(n, "n", low=0)
        rng = as_generator(seed)
        out = np.asarray(self._sample(n, rng), dtype=np.float64)
        return out.reshape(n, self.dim)

    def _sample(self, n: int, rng: np.random.Generator) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def support_box(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        """Lower and upper corners ``(lo (d,), hi (d,))`` of a box containing the support."""
        raise NotImplementedError

    def support_widths(self) -> np.ndarray:
        """Widths ``σⱼ = bⱼ − aⱼ`` of the coordinate supports, shape ``(dim,)``."""
        lo, hi = self.support_box()
        return np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)

    def push(self, M) -> "Measure":
        """Push-forward ``M#μ`` by a linear map ``M`` (``(k, d)`` ndarray or ``Projection``).

        eq. (4.8) of the paper: ``(M#μ)(B) = μ(M⁻¹(B))``. Atomic measures push
        exactly (:meth:`Atomic.push`); other measures return a :class:`PushForward`.
        """
        return PushForward(self, M)


def _projection(M, d: int):
    from ..projection import as_projection

    P = as_projection(M)
    if P.shape[1] != d:
        raise InvalidInput(
            f"M must map from the measure's dimension {d}, got a map of shape {P.shape} "
            f"(k, d) with d = {P.shape[1]}"
        )
    return P


class PushForward(Measure):
    """The image measure ``M#μ`` of ``base`` under a linear map ``M: ℝᵈ → ℝᵏ``.

    eq. (4.8) of the paper: :math:`\\int \\varphi\\, d(M\\#\\mu) =
    \\int \\varphi(Mx)\\, d\\mu(x)`. Sampling draws from the base and maps the draws.
    Its support box is the image of the base's box, which per output coordinate has width

    .. math:: \\sigma'_i = \\sum_j |M_{ij}|\\, \\sigma_j .

    Parameters
    ----------
    mu : Measure
        The base measure on ℝᵈ.
    M : (k, d) ndarray or Projection
        The linear map.

    Examples
    --------
    >>> from kinred.measures import Uniform, TensorProduct
    >>> mu = TensorProduct([Uniform(0, 1), Uniform(0, 2)])
    >>> nu = mu.push(np.array([[1.0, 1.0]]))
    >>> nu.dim, nu.support_widths()
    (1, array([3.]))
    """

    def __init__(self, mu: Measure, M):
        if not isinstance(mu, Measure):
            raise InvalidInput(f"mu must be a kinred Measure, got {type(mu).__name__}")
        self.base = mu
        self.projection = _projection(M, mu.dim)
        self.dim = int(self.projection.shape[0])

    def _sample(self, n, rng):
        X = self.base.sample(n, rng)
        if n == 0:
            return np.zeros((0, self.dim))
        return self.projection.apply(X)

    def support_box(self):
        lo, hi = self.base.support_box()
        c = 0.5 * (lo + hi)
        h = 0.5 * (hi - lo)
        A = self.projection.to_dense()
        mc = A @ c
        mh = np.abs(A) @ h
        return mc - mh, mc + mh

    def __repr__(self):
        return f"PushForward({self.base!r}, shape={self.projection.shape})"


class Atomic(Measure):
    """A discrete measure ``Σᵢ wᵢ δ_{xᵢ}`` on ℝᵈ.

    Parameters
    ----------
    points : (N, d) array_like
        The atoms ``xᵢ``; a 1-D array is read as ``N`` points of ℝ¹. Finite values only.
    weights : (N,) array_like, optional
        Probability weights (non-negative, summing to one); uniform ``1/N`` by default.

    Attributes
    ----------
    points : (N, d) float64 ndarray
    weights : (N,) float64 ndarray
    n_atoms : int
    dim : int

    Notes
    -----
    :meth:`push` is exact, eq. (4.9) of the paper:
    :math:`M\\#\\bigl(\\sum_i w_i\\delta_{x_i}\\bigr) = \\sum_i w_i \\delta_{Mx_i}`.

    Examples
    --------
    >>> mu = Atomic([[0.0, 0.0], [1.0, 2.0]])
    >>> mu.n_atoms, mu.dim, mu.weights
    (2, 2, array([0.5, 0.5]))
    >>> mu.push(np.array([[1.0, 1.0]])).points
    array([[0.],
           [3.]])
    """

    def __init__(self, points, weights=None):
        X = as_array(points, "points", ndim=(1, 2))
        if X.ndim == 1:
            X = X[:, None]
        if X.shape[0] < 1 or X.shape[1] < 1:
            raise InvalidInput(f"points must hold at least one point of dimension >= 1, got shape {X.shape}")
        self.points = np.ascontiguousarray(X, dtype=np.float64)
        self.weights = as_weights(weights, "weights", X.shape[0])
        self.dim = int(X.shape[1])

    @property
    def n_atoms(self) -> int:
        """Number of atoms ``N``."""
        return int(self.points.shape[0])

    def _sample(self, n, rng):
        idx = rng.choice(self.n_atoms, size=n, p=self.weights)
        return self.points[idx]

    def support_box(self):
        return self.points.min(axis=0), self.points.max(axis=0)

    def push(self, M) -> "Atomic":
        """Exact push-forward: atoms ``M xᵢ`` with the same weights (eq. (4.9), ``projatom``)."""
        P = _projection(M, self.dim)
        Y = as_array(P.apply(self.points), "M x")  # finite check: the image must be finite too
        out = Atomic.__new__(Atomic)
        out.points = np.ascontiguousarray(Y, dtype=np.float64)
        out.weights = self.weights.copy()  # the very same weights, not renormalized
        out.dim = int(Y.shape[1])
        return out

    def __repr__(self):
        return f"{type(self).__name__}(n_atoms={self.n_atoms}, dim={self.dim})"


class Dirac(Atomic):
    """Point mass ``δ_x`` at ``x ∈ ℝᵈ`` (support width 0 in every coordinate).

    Parameters
    ----------
    x : float or (d,) array_like
        The location; a scalar gives a measure on ℝ¹.

    Examples
    --------
    >>> Dirac([1.0, 2.0]).support_widths()
    array([0., 0.])
    >>> Dirac(3.0).sample(2, seed=0)
    array([[3.],
           [3.]])
    """

    def __init__(self, x):
        x = as_array(x, "x", ndim=(0, 1))
        x = np.atleast_1d(x)
        if x.size < 1:
            raise InvalidInput("x must hold at least one coordinate, got an empty array")
        self.x = x.copy()
        super().__init__(x[None, :])

    def _sample(self, n, rng):
        return np.broadcast_to(self.x, (n, self.dim)).copy()

    def push(self, M) -> "Dirac":
        """``M#δ_x = δ_{Mx}``."""
        P = _projection(M, self.dim)
        return Dirac(P.apply(self.x))

    def __repr__(self):
        return f"Dirac({self.x.tolist()!r})"
