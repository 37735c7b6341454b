r"""Private numba kernel of :mod:`kinred.distance`: ε-optimal prices of a transportation problem
on a sparse graph by cost scaling (push–relabel), the graph pruning of ``method="sparse"``.

Only the ``_kernels`` modules of :mod:`kinred.distance` import numba; kernels use
``cache=True``.

The problem: rows ``i`` with supplies ``aᵢ``, columns ``j`` with demands ``bⱼ`` (any positive
weights, ``Σ a = Σ b`` up to round-off), edges ``e = (i, j)`` in CSR form by rows with costs
``c_e`` and uncapacitated flows ``f_e ≥ 0``; minimize ``Σ c_e f_e`` with row sums ``a`` and
column sums ``b`` (eq. (4.5) of the paper restricted to the edges). With prices ``pxᵢ, pyⱼ``
and reduced costs ``r_e = c_e + pxᵢ − pyⱼ`` (``uᵢ = −pxᵢ``, ``vⱼ = pyⱼ`` are the duals of
``uᵢ + vⱼ ≤ cᵢⱼ``), a pseudoflow is **ε-optimal** (Goldberg–Tarjan 1990) when

.. math:: r_e \ge -\varepsilon \ \text{on every edge}, \qquad
          r_e \le \varepsilon \ \text{where } f_e > 0 .

Each phase restores ε-optimality for the new ``ε`` (a row's price rises to ``maxⱼ(pyⱼ − c_e) −
ε`` if below it; flow on edges with ``r_e > ε`` returns to its row) and then discharges the
nodes with excess, first in first out:

* a **row** sends all its excess along its edge of least reduced cost, after lowering its
  price to make that edge's ``r_e = −ε`` if it was not negative (relabel);
* a **column** that received more than ``bⱼ`` sends the surplus back along its edges with
  flow and ``r_e > 0``, lowering its price to ``max(pxᵢ + c_e) − ε`` over them when none is left.

Prices only fall within a phase, and ε-scaling (``ε ÷ theta`` per phase, from the last phase's
prices and flow) keeps every phase short. A node counts as balanced when its excess is at most
``tol`` -- which must exceed ``|Σ a − Σ b|``, else the last crumbs of mass circulate for ever.

Nothing here is trusted: the prices only choose the candidate edges (those of small reduced
cost) on which the exact solver runs, and the result is proved by its dual over all pairs as
every solve of ``method="sparse"``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["transport_prices"]


@njit(cache=True)
def _restore(indptr, indices, cost, px, py, f, exx, exy, eps):
    """ε-optimality for the phase's ``ε``: rows' prices raised to ``maxⱼ(pyⱼ − c_e) − ε``
    where below, flow on edges with ``r_e > ε`` returned to its row."""
    n = indptr.size - 1
    for i in range(n):
        best = -np.inf
        for e in range(indptr[i], indptr[i + 1]):
            val = py[indices[e]] - cost[e]
            if val > best:
                best = val
        if px[i] < best - eps:
            px[i] = best - eps
        for e in range(indptr[i], indptr[i + 1]):
            if f[e] > 0.0:
                j = indices[e]
                if cost[e] + px[i] - py[j] > eps:
                    exx[i] += f[e]
                    exy[j] -= f[e]
                    f[e] = 0.0


@njit(cache=True)
def _push_row(i, indptr, indices, cost, px, py, f, exx, exy, eps):
    """Row ``i``'s whole excess along its edge of least reduced cost (relabelled to ``−ε`` if it
    was not negative); returns the column that received it."""
    best = -np.inf
    be = indptr[i]
    for e in range(indptr[i], indptr[i + 1]):
        val = py[indices[e]] - cost[e]
        if val > best:
            best = val
            be = e
    if px[i] - best >= 0.0:
        px[i] = best - eps
    j = indices[be]
    d = exx[i]
    f[be] += d
    exx[i] = 0.0
    exy[j] += d
    return j


@njit(cache=True)
def transport_prices(indptr, indices, cost, colptr, colidx, rowof, a, b, px, py, eps_start,
                     eps_end, theta, tol, max_work, phase_work):
    """ε-scaling push–relabel; updates ``px, py`` in place and returns ``(f, status, work)``:
    the flow on the edges, status 0 (every node balanced within ``tol`` at ``ε = eps_end``) or
    1 (``max_work`` discharges spent), and the discharges. ``colptr, colidx``: each column's
    edges; ``rowof``: each edge's row. Every row and column must have an edge.
    ``phase_work[p]`` receives the discharges of phase ``p`` (phases past its size are not
    counted)."""
    n = indptr.size - 1
    m = colptr.size - 1
    size = n + m
    f = np.zeros(cost.size)
    exx = a.copy()
    exy = -b
    queue = np.empty(size, np.int64)
    inq = np.zeros(size, np.uint8)
    work = 0
    eps = eps_start
    phase = 0
    while True:
        start = work
        _restore(indptr, indices, cost, px, py, f, exx, exy, eps)
        head = 0
        cnt = 0
        for node in range(size):
            ex = exx[node] if node < n else exy[node - n]
            if ex > tol:
                queue[cnt] = node
                inq[node] = 1
                cnt += 1
        while cnt > 0:
            node = queue[head]
            head = (head + 1) % size
            cnt -= 1
            inq[node] = 0
            work += 1
            if work > max_work:
                return f, 1, work
            if node < n:
                if exx[node] <= tol:
                    continue
                j = _push_row(node, indptr, indices, cost, px, py, f, exx, exy, eps)
                if exy[j] > tol and inq[n + j] == 0:
                    queue[(head + cnt) % size] = n + j
                    inq[n + j] = 1
                    cnt += 1
                continue
            j = node - n
            while exy[j] > tol:
                for k in range(colptr[j], colptr[j + 1]):
                    e = colidx[k]
                    if f[e] > 0.0:
                        i = rowof[e]
                        if cost[e] + px[i] - py[j] > 0.0:
                            d = min(exy[j], f[e])
                            f[e] -= d
                            exy[j] -= d
                            exx[i] += d
                            if exx[i] > tol and inq[i] == 0:
                                queue[(head + cnt) % size] = i
                                inq[i] = 1
                                cnt += 1
                            if exy[j] <= tol:
                                break
                if exy[j] <= tol:
                    break
                best = -np.inf                    # relabel: the best edge back gets r = eps
                for k in range(colptr[j], colptr[j + 1]):
                    e = colidx[k]
                    if f[e] > 0.0:
                        val = px[rowof[e]] + cost[e]
                        if val > best:
                            best = val
                if best == -np.inf:               # round-off crumbs without a way back
                    break
                py[j] = best - eps
        if phase < phase_work.size:
            phase_work[phase] = work - start
        phase += 1
        if eps <= eps_end:
            return f, 0, work
        eps = max(eps / theta, eps_end)


def transport_prices_numpy(*args):
    """The plain-Python twin of :func:`transport_prices` (the same discharges in the same
    order, for the tests)."""
    return transport_prices.py_func(*args)
