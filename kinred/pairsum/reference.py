r"""The plain-numpy twin of the pair sums: the reference the other backends are tested against.

For every pair term (see :class:`~kinred.pairsum.PairTerms`) it forms the full ``N × N``
distance matrix by differences, the kernel values by ``kernel(s)`` and

.. math:: \sum_j c_j \varphi_{ij} z_j - \Bigl(\sum_j c_j \varphi_{ij}\Bigr) z_i

with the carrier ``z`` centred. ``O(N²)`` memory: for tests and small systems.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import check_alloc
from ..errors import InvalidInput
from . import _kernels
from ._base import PairTerms, check_plan_args

__all__ = ["Numpy", "NumpyPlan"]

#: Peak bytes per pair of an evaluation: distances, their roots, the kernel values and its
#: temporaries, the weighted copy (about six ``(N, N)`` float64 arrays).
_PAIR_BYTES = 48


@dataclass(frozen=True, eq=False)
class NumpyPlan:
    """The plan of :class:`Numpy`: the terms, the shape and the coefficients ``c``."""

    n: int
    dim: int
    terms: PairTerms
    c: np.ndarray


class Numpy:
    """The plain-numpy twin backend (``pairsum="numpy"``): direct differences, kernels by
    ``kernel(s)``, float64 throughout; no threads, no compiled code.

    Examples
    --------
    >>> from kinred.dynamics import Alignment, CuckerSmale, Scene
    >>> from kinred.pairsum import Numpy
    >>> sc = Scene([Alignment(CuckerSmale(1.0, 0.0))], pairsum=Numpy())
    >>> sc.rhs(np.array([[0.0], [1.0]]), np.array([[1.0], [-1.0]]))[1].ravel()
    array([-1.,  1.])
    """

    #: The twin always computes in float64.
    precision = "double"

    #: The pair sums are exact (up to round-off): certificates cover this backend.
    exact = True

    def __repr__(self) -> str:
        return "Numpy()"

    def plan(self, scene, n: int, dim: int) -> NumpyPlan:
        """The plan of ``scene`` for states of shape ``(n, dim)`` (see
        :class:`~kinred.pairsum.PairSum`)."""
        terms, n, dim = check_plan_args(scene, n, dim)
        check_alloc(_PAIR_BYTES * n * n, f"the numpy pair sums of {n} agents",
                    "use the default backend pairsum='dense' (O(N) memory)",
                    detail=f" for about {_PAIR_BYTES // 8} (N, N) = ({n}, {n}) matrices")
        return NumpyPlan(n=n, dim=dim, terms=terms, c=scene.coefficients(n))

    def evaluate(self, plan: NumpyPlan, x: np.ndarray, v: np.ndarray | None, rng=None) -> dict:
        """``{target: (n, dim) ndarray}``, summed over the plan's terms (``rng`` ignored)."""
        if not isinstance(plan, NumpyPlan) or x.shape != (plan.n, plan.dim):
            raise InvalidInput(f"plan must be a NumpyPlan for states of shape (n, dim) = "
                               f"{getattr(plan, 'n', '?'), getattr(plan, 'dim', '?')}; got "
                               f"{type(plan).__name__} and x of shape {x.shape}")
        c = plan.c
        state = {"x": x, "v": v}
        out = {}
        for t in plan.terms.terms:
            S = np.sqrt(_kernels.sqdist_numpy(state[t.source], state[t.source]))
            phi = np.asarray(t.kernel(S), dtype=float)
            z = state[t.carrier] - state[t.carrier].mean(axis=0)
            contrib = (phi * c[None, :]) @ z - (phi @ c)[:, None] * z
            out[t.target] = contrib if t.target not in out else out[t.target] + contrib
        return out
