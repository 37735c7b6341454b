r"""Private numba kernel of :mod:`kinred.distance`: dual potentials of an optimal assignment
on a sparse candidate graph, by label-correcting shortest paths.

Only the ``_kernels`` modules of :mod:`kinred.distance` import numba; kernels use
``cache=True``.

Equal counts ``n`` and uniform weights make the transport problem (eq. (4.5) of the paper,
``c(x, y) = |x − y|``) an assignment problem: a permutation ``σ`` is optimal on the graph
``E`` if and only if the residual graph -- an edge ``xᵢ → yⱼ`` of length ``cᵢⱼ`` for every
``(i, j) ∈ E`` and ``y_σ(i) → xᵢ`` of length ``−c_iσ(i)`` -- has no cycle of negative length.
Its shortest-path distances ``d`` from a virtual source joined to every ``xᵢ`` at length 0 are
then dual potentials, ``uᵢ = −d(xᵢ)`` and ``vⱼ = d(yⱼ)``:

.. math:: u_i + v_j \le c_{ij} \ \text{on } E, \qquad u_i + v_{\sigma(i)} = c_{i\sigma(i)}.

:func:`assignment_potentials` runs the queue-based Bellman–Ford (SPFA) over the rows only:
each column has one outgoing residual edge (to its mate), relaxed at once. A relaxation counts
only when it improves by more than ``tiny`` (round-off of an optimal ``σ`` cannot loop), and a
work budget stops it on a non-optimal ``σ``. The plain-numpy twin is
:func:`assignment_potentials_numpy` (Bellman–Ford rounds over all edges at once).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["assignment_potentials", "assignment_potentials_numpy"]


@njit(cache=True)
def assignment_potentials(indptr, cols, costs, mate, mate_cost, tiny, max_work):
    """Distances ``d(xᵢ)``, ``d(yⱼ)`` of the residual graph of the assignment ``mate``
    (``mate[j]`` the row matched to column ``j``, at cost ``mate_cost[j]``) on the CSR graph
    ``(indptr, cols, costs)``; status 0 when converged, 1 when ``max_work`` edge relaxations
    passed (``σ`` not optimal beyond ``tiny``)."""
    n = indptr.size - 1
    m = mate.size
    dx = np.zeros(n)
    dy = np.full(m, np.inf)
    queue = np.arange(n)
    inq = np.ones(n, np.uint8)
    head, count, work = 0, n, 0
    while count > 0:
        p = queue[head]
        head = head + 1 if head + 1 < n else 0
        count -= 1
        inq[p] = 0
        dp = dx[p]
        for e in range(indptr[p], indptr[p + 1]):
            j = cols[e]
            nd = dp + costs[e]
            if nd < dy[j] - tiny:
                dy[j] = nd
                q = mate[j]
                nq = nd - mate_cost[j]
                if nq < dx[q] - tiny:
                    dx[q] = nq
                    if inq[q] == 0:
                        inq[q] = 1
                        tail = head + count
                        queue[tail - n if tail >= n else tail] = q
                        count += 1
        work += indptr[p + 1] - indptr[p]
        if work > max_work:
            return dx, dy, 1
    return dx, dy, 0


def assignment_potentials_numpy(rows, cols, costs, mate, mate_cost, n, tiny=0.0,
                                max_rounds=None):
    """The plain-numpy twin of :func:`assignment_potentials`: Bellman–Ford rounds over all
    edges at once (``d(yⱼ) = min over E of d(xᵢ) + cᵢⱼ``, then ``d(x_mate) ≤ d(yⱼ) − c``)
    until nothing improves by more than ``tiny``. Returns ``dx, dy, status``."""
    m = mate.size
    dx = np.zeros(n)
    dy = np.full(m, np.inf)
    for _ in range(max_rounds or n + m + 1):
        ny = np.full(m, np.inf)
        np.minimum.at(ny, cols, dx[rows] + costs)
        dy_new = np.where(ny < dy - tiny, ny, dy)
        cand = np.full(n, np.inf)
        np.minimum.at(cand, mate, dy_new - mate_cost)
        dx_new = np.where(cand < dx - tiny, cand, dx)
        if np.array_equal(dy_new, dy) and np.array_equal(dx_new, dx):
            return dx, dy, 0
        dx, dy = dx_new, dy_new
    return dx, dy, 1
