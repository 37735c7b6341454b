"""Johnson–Lindenstrauss projections (Lemma 2.1 of the paper and the matrices after it)."""

from ._base import DenseProjection, Projection, as_projection

__all__ = ["Projection", "DenseProjection", "as_projection"]
