"""Tensor products of 1-D measures and finite mixtures of measures."""

from __future__ import annotations

import numpy as np

from .._validate import as_weights
from ..errors import InvalidInput
from ._base import Measure

__all__ = ["TensorProduct", "Mixture"]


class TensorProduct(Measure):
    """Product measure ``μ¹ ⊗ … ⊗ μᵈ`` of 1-D measures (coordinates independent).

    The setting of Lemma 4.1 of the paper and of the delayed curse
    of dimension, eq. (4.22).

    Parameters
    ----------
    factors : sequence of 1-D measures
        ``Univariate``, ``Uniform``, ``Empirical1D`` or 1-D ``Dirac``/``Atomic``.

    Attributes
    ----------
    factors : list of Measure
    dim : int -- ``len(factors)``

    Examples
    --------
    >>> from kinred.measures import Uniform, Dirac
    >>> mu = TensorProduct([Uniform(0, 1), Uniform(0, 0.5), Dirac(2.0)])
    >>> mu.dim, mu.support_widths()
    (3, array([1. , 0.5, 0. ]))
    >>> mu.sample(4, seed=1).shape
    (4, 3)
    """

    def __init__(self, factors):
        try:
            factors = list(factors)
        except TypeError:
            raise InvalidInput(f"factors must be a sequence of 1-D measures, got {factors!r}") from None
        if not factors:
            raise InvalidInput("factors must hold at least one 1-D measure, got an empty sequence")
        for j, f in enumerate(factors):
            if not isinstance(f, Measure):
                raise InvalidInput(f"factors[{j}] must be a kinred Measure, got {type(f).__name__}")
            if f.dim != 1:
                raise InvalidInput(f"factors[{j}] must be a 1-D measure, got dim {f.dim}")
        self.factors = factors
        self.dim = len(factors)

    def _sample(self, n, rng):
        out = np.empty((n, self.dim))
        for j, f in enumerate(self.factors):
            out[:, j] = f.sample(n, rng)[:, 0]
        return out

    def support_box(self):
        boxes = [f.support_box() for f in self.factors]
        lo = np.array([float(b[0][0]) for b in boxes])
        hi = np.array([float(b[1][0]) for b in boxes])
        return lo, hi

    def __repr__(self):
        return f"TensorProduct(dim={self.dim})"


class Mixture(Measure):
    """Finite mixture ``Σₗ wₗ μₗ`` of measures of one dimension.

    The setting of Lemma 4.2 of the paper; a mixture of anisotropic
    tensor products quantizes to the sparse-grid atoms of §4.5.

    Parameters
    ----------
    components : sequence of Measure, all of the same ``dim``
    weights : (L,) array_like, optional
        Probability weights (>= 0, summing to one); uniform by default.

    Attributes
    ----------
    components : list of Measure
    weights : (L,) float64 ndarray
    dim : int

    Examples
    --------
    >>> from kinred.measures import Uniform
    >>> mu = Mixture([Uniform(0, 1), Uniform(2, 3)], [0.25, 0.75])
    >>> mu.support_widths(), mu.weights
    (array([3.]), array([0.25, 0.75]))
    """

    def __init__(self, components, weights=None):
        try:
            components = list(components)
        except TypeError:
            raise InvalidInput(f"components must be a sequence of measures, got {components!r}") from None
        if not components:
            raise InvalidInput("components must hold at least one measure, got an empty sequence")
        for l, c in enumerate(components):
            if not isinstance(c, Measure):
                raise InvalidInput(f"components[{l}] must be a kinred Measure, got {type(c).__name__}")
            if c.dim != components[0].dim:
                raise InvalidInput(
                    f"all components must have the same dim; components[0] has dim "
                    f"{components[0].dim}, components[{l}] has dim {c.dim}"
                )
        self.components = components
        self.weights = as_weights(weights, "weights", len(components))
        self.dim = int(components[0].dim)

    def _sample(self, n, rng):
        which = rng.choice(len(self.components), size=n, p=self.weights)
        out = np.empty((n, self.dim))
        for l, c in enumerate(self.components):
            idx = np.flatnonzero(which == l)
            if idx.size:
                out[idx] = c.sample(idx.size, rng)
        return out

    def support_box(self):
        boxes = [c.support_box() for c, w in zip(self.components, self.weights) if w > 0]
        lo = np.min([b[0] for b in boxes], axis=0)
        hi = np.max([b[1] for b in boxes], axis=0)
        return lo, hi

    def __repr__(self):
        return f"Mixture(L={len(self.components)}, dim={self.dim})"
