r"""Private numba kernel of :mod:`kinred.distance`: prices of an assignment problem on a sparse
graph by Bertsekas' ε-scaling auction, the warm start of the exact assignment solver.

Only the ``_kernels`` modules of :mod:`kinred.distance` import numba; kernels use
``cache=True``.

The problem: ``n`` rows ("persons") and ``n`` columns ("objects"), edges ``(i, j)`` in CSR form
with costs ``cᵢⱼ``; minimize ``Σᵢ c_iσ(i)`` over the permutations ``σ`` using edges only.
The auction keeps prices ``pⱼ`` and a partial assignment satisfying **ε-complementary
slackness**: every assigned ``i`` holds a column within ``ε`` of its best,

.. math:: c_{i\sigma(i)} + p_{\sigma(i)} \le \min_j\,(c_{ij} + p_j) + \varepsilon .

An unassigned row bids for its best column ``j*`` (value ``w₁``, second best ``w₂``), raising
``p_j*`` by ``w₂ − w₁ + ε`` and taking it from its holder, who queues to bid again (Gauss–Seidel,
first in first out). When every row is assigned, ε-CS makes ``σ`` optimal within ``n·ε``
(Bertsekas 1988). ε-scaling runs phases with ``ε`` divided by ``theta``, each starting from the
last phase's prices and keeping the pairs that still satisfy ε-CS, so that every phase moves
the prices little.

Nothing here is trusted by kinred: the prices only make the exact solver (LAPJVsp on the
reduced costs ``cᵢⱼ + pⱼ``, :mod:`kinred.distance._assign`) fast, and the result is proved by
its dual as every solve. The plain-numpy twin :func:`auction_numpy` runs the same bids in the
same order (for the tests).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["auction", "auction_numpy"]


@njit(cache=True)
def auction(indptr, indices, cost, price, eps_start, eps_end, theta, max_bids, phase_bids):
    """ε-scaling auction: updates ``price`` in place; returns ``(sigma, bids, status)`` with
    ``sigma[i]`` the column of row ``i`` (``status`` 0) or ``status`` 1 when ``max_bids`` bids
    were spent (``sigma`` then partial, ``-1`` for free rows). Rows must have an edge each.
    ``phase_bids[p]`` receives the bids of phase ``p`` (phases past its size are not counted)."""
    n = indptr.size - 1
    owner = np.full(n, -1, np.int64)
    sigma = np.full(n, -1, np.int64)
    queue = np.empty(n, np.int64)
    spread = 0.0
    for e in range(cost.size):
        if cost[e] > spread:
            spread = cost[e]
    spread += eps_start
    bids = 0
    eps = eps_start
    phase = 0
    while True:
        start_bids = bids
        # keep the pairs that still satisfy eps-CS; queue the other rows
        head = 0
        count = 0
        for i in range(n):
            j0 = sigma[i]
            if j0 >= 0:
                best = np.inf
                mine = np.inf
                for e in range(indptr[i], indptr[i + 1]):
                    val = cost[e] + price[indices[e]]
                    if val < best:
                        best = val
                    if indices[e] == j0 and val < mine:
                        mine = val
                if mine <= best + eps:
                    continue
                sigma[i] = -1
                owner[j0] = -1
            queue[count] = i
            count += 1
        tail = count % n
        while count > 0:
            i = queue[head]
            head += 1
            if head == n:
                head = 0
            count -= 1
            best = np.inf
            second = np.inf
            bj = -1
            for e in range(indptr[i], indptr[i + 1]):
                val = cost[e] + price[indices[e]]
                if val < best:
                    second = best
                    best = val
                    bj = indices[e]
                elif val < second:
                    second = val
            if second == np.inf:
                second = best + spread
            price[bj] += (second - best) + eps
            prev = owner[bj]
            owner[bj] = i
            sigma[i] = bj
            if prev >= 0:
                sigma[prev] = -1
                queue[tail] = prev
                tail += 1
                if tail == n:
                    tail = 0
                count += 1
            bids += 1
            if bids >= max_bids:
                return sigma, bids, 1
        if phase < phase_bids.size:
            phase_bids[phase] = bids - start_bids
        phase += 1
        if eps <= eps_end:
            return sigma, bids, 0
        eps = max(eps / theta, eps_end)


def auction_numpy(indptr, indices, cost, price, eps_start, eps_end, theta, max_bids,
                  phase_bids):
    """The plain-Python twin of :func:`auction` (same bids in the same order)."""
    return auction.py_func(indptr, indices, cost, price, eps_start, eps_end, theta, max_bids,
                           phase_bids)
