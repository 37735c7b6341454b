"""Pair-sum backends: how a scene's pairwise effects are summed over all pairs of agents.

A :class:`~kinred.dynamics.Scene` lists what its pairwise effects call for once
(:class:`PairTerms`: terms, distance sources, carriers, accumulators, coefficients) and hands
it to a backend implementing the :class:`PairSum` protocol: ``plan(scene, n, dim)`` once per
state shape, ``evaluate(plan, x, v, rng)`` per right-hand side.

* :class:`Dense` (the default, ``pairsum="fast"``): exact, blocked BLAS products and numba
  kernels, threads; float64 or mixed float32 pair sums.
* :class:`Numpy` (``pairsum="numpy"``): the plain-numpy twin, the reference in tests.
* :class:`RandomBatch` (``pairsum="random_batch"``, ``p = 2``): the random batch method,
  pair sums inside random batches of ``p`` agents, unbiased, ``O(N p d)`` per evaluation.
* :class:`NUFFT` (``pairsum="nufft"``): fast summation of smooth radial kernels by
  non-equispaced FFTs (finufft) for distances in ``k ≤ 3`` dimensions, ``O(N + n^k log n)``
  at a requested relative accuracy ``tol``; kernels declare ``radial_profile()``.

* :class:`CellList` (``pairsum="cells"``): short-range kernels (a declared tail bound,
  :func:`tail_bound`) truncated at a distance set from ``tol``, pairs from a cell list,
  ``k ≤ 3``, ``O(N)`` memory.

* :class:`Auto` (``pairsum="auto"``): the deterministic backend (Dense, NUFFT, CellList) of
  least estimated cost for the scene and the cloud, re-chosen when the cloud changes shape,
  said by ``Scene.info()``; never RandomBatch.

A backend declares whether its pair sums are exact (``exact = True``: Dense, Numpy) or
approximate (NUFFT, RandomBatch, CellList, Auto; a backend that does not say is approximate,
:func:`is_exact`): certificates cover exact backends only.

The exact engine's strip walker (row strips, their threads, distance blocks, products) is
public in :mod:`kinred.pairsum.strips`, for other passes over all pairs (the certificate's).

Backends are known by name through one registry, :data:`PAIRSUMS`, shared by
``Scene(pairsum="name")`` and scene files' ``[dynamics.pairsum] method = "name"``: a new
backend is one file implementing the protocol and one :func:`register_pairsum` call; kernels may declare a closed form
through ``compiled_form()`` (see :func:`compiled_form`). See docs/dynamics.md.
"""

from ._base import (COMPILED_KINDS, PairSum, PairTerm, PairTerms, compiled_form, is_exact,
                    pair_form, tail_bound)
from ._registry import (PAIRSUMS, PairSumType, make_pairsum, register_pairsum,
                        unregister_pairsum)
from ._select import as_pairsum
from .auto import Auto, AutoPlan
from .cells import CellList, CellListPlan
from .dense import Dense, DensePlan
from .nufft import NUFFT, NUFFTPlan, radial_profile
from .random_batch import RandomBatch, RandomBatchPlan
from .reference import Numpy, NumpyPlan

__all__ = ["PairSum", "PairTerm", "PairTerms", "Dense", "DensePlan", "Numpy", "NumpyPlan",
           "RandomBatch", "RandomBatchPlan", "NUFFT", "NUFFTPlan", "as_pairsum", "compiled_form",
           "radial_profile", "COMPILED_KINDS", "is_exact", "CellList", "CellListPlan",
           "tail_bound", "Auto", "AutoPlan", "pair_form", "PAIRSUMS", "PairSumType",
           "register_pairsum", "unregister_pairsum", "make_pairsum"]
