"""Johnson–Lindenstrauss projections (Lemma 2.1 of the paper and the matrices after it).

* :func:`jl_matrix` draws ``M: ℝᵈ → ℝᵏ`` of kind ``"gaussian"``, ``"rademacher"``,
  ``"achlioptas"`` (sparse), ``"srht"`` (fast Walsh–Hadamard, Krahmer–Ward) or ``"dct"``;
* :func:`jl_min_dim` is the Dasgupta–Gupta bound on ``k``;
* :func:`distortion` and :func:`trajectory_distortion` measure eq. (2.1) on a cloud and
  condition (3.4) along a trajectory.

Every map is a :class:`Projection`, which numpy code can use as its ``(k, d)`` matrix:
``np.asarray(M)``, ``M @ x``, ``X @ M.T`` (``M.T`` is a :class:`TransposedProjection`).
"""

from ._base import DenseProjection, Projection, TransposedProjection, as_projection
from ._distortion import (
    DistortionResult,
    TrajectoryDistortionResult,
    distortion,
    trajectory_distortion,
)
from ._jl import KINDS, SparseProjection, SRHTProjection, fwht, jl_matrix, jl_min_dim

__all__ = [
    "Projection",
    "DenseProjection",
    "TransposedProjection",
    "SparseProjection",
    "SRHTProjection",
    "as_projection",
    "KINDS",
    "jl_matrix",
    "jl_min_dim",
    "fwht",
    "distortion",
    "trajectory_distortion",
    "DistortionResult",
    "TrajectoryDistortionResult",
]
