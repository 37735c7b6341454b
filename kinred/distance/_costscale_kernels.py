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
prices and flow) keeps every phase short. A **global price update** (Goldberg 1997, "An efficient
implementation of a scaling minimum-cost flow algorithm") at each phase's start and every
:data:`UPDATE_EVERY` ``·(n + m)`` discharges lowers every node's price by ``ε`` times its
distance to the nearest deficit in the residual graph (arc length ``⌊r/ε⌋ + 1``, Dial's
buckets): ε-optimality holds, and every excess then has a path of admissible edges to a deficit,
which local relabels find only one ``ε`` at a time (10⁵ vs 8·10⁴ atoms in ℝ⁶: 7.3·10⁷
discharges without it, the phases 2.5 times faster with it). A phase may start from a given
flow (a warm start on a grown edge set: the flow of the last run, zero on the new edges).

A node counts as balanced when its excess is at most ``tol`` -- which must exceed
``|Σ a − Σ b|``, else the last crumbs of mass circulate for ever.

Nothing here is trusted: the prices only choose the candidate edges (those of small reduced
cost) on which the exact solver runs, and the result is proved by its dual over all pairs as
every solve of ``method="sparse"``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["transport_prices"]

#: A global price update (:func:`_global_update`) at each phase's start and after every
#: ``UPDATE_EVERY·(n + m)`` discharges. One update costs about as much as ``0.1·(n + m)``
#: discharges (44 ms at n + m = 1.8·10⁵), and one every ``(n + m)/2`` discharges saves more
#: than it costs: 10⁵ vs 8·10⁴ weighted atoms in ℝ⁶, the two phases after the first searches
#: took 9.0–9.4 s together (4.3 million discharges each), against 14.9–15.5 s at 2 (11.5 million)
#: and 10.1 s at 1 (best of 2 interleaved runs in one process; 10.0 s at 0.3, 10.6 s at 0.25).
UPDATE_EVERY = 0.5
#: Buckets of the update's search, per node (distances beyond: the search stops there).
BUCKETS_PER_NODE = 4


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
def _global_update(indptr, indices, cost, colptr, costc, rowc, px, py, f, exx, exy, eps, tol,
                   dist, done, bhead, enode, enext):
    """Goldberg's global price update: ``D(w)``, the length of a shortest residual path from
    node ``w`` to a node short of its demand with arc lengths ``ℓ = ⌊r/ε⌋ + 1`` (``≥ 0`` under
    ε-optimality), by Dial's buckets searched backwards from the deficits; then
    ``p(w) −= ε·D(w)``. Every reduced cost stays ``≥ −ε`` (``r − εℓ ≥ −ε``) and the arcs of the
    shortest paths become admissible (``r < 0``), so every excess has an admissible path to a
    deficit. The search stops once every node with excess is reached; the nodes not reached
    get the distance it stopped at (still valid: none of them is closer). Nodes ``0 … n−1``
    are rows, ``n …`` columns; ``costc, rowc``: the costs and rows of the edges in column
    order."""
    n = indptr.size - 1
    m = colptr.size - 1
    nb = bhead.size
    for w in range(n + m):
        dist[w] = nb
        done[w] = 0
    for d in range(nb):
        bhead[d] = -1
    used = 0
    todo = 0
    for i in range(n):
        if exx[i] > tol:
            todo += 1
    for j in range(m):
        if exy[j] > tol:
            todo += 1
        elif exy[j] < -tol:
            dist[n + j] = 0
            enode[used] = n + j
            enext[used] = bhead[0]
            bhead[0] = used
            used += 1
    if used == 0 or todo == 0:
        return
    inv = 1.0 / eps
    d = 0
    while d < nb and todo > 0:
        k = bhead[d]
        if k < 0:
            d += 1
            continue
        bhead[d] = enext[k]
        w = enode[k]
        if done[w] or dist[w] != d:
            continue
        done[w] = 1
        if w < n:
            if exx[w] > tol:
                todo -= 1
            i = w                       # arcs into a row: j -> i where f_e > 0
            for e in range(indptr[i], indptr[i + 1]):
                if f[e] > 0.0:
                    j = indices[e]
                    r = -(cost[e] + px[i] - py[j])
                    ln = int(np.floor(r * inv)) + 1
                    if ln < 0:
                        ln = 0
                    nd = d + ln
                    if nd < dist[n + j] and nd < nb:
                        dist[n + j] = nd
                        enode[used] = n + j
                        enext[used] = bhead[nd]
                        bhead[nd] = used
                        used += 1
        else:
            j = w - n
            if exy[j] > tol:
                todo -= 1
            for k2 in range(colptr[j], colptr[j + 1]):   # arcs into a column: i -> j
                i = rowc[k2]
                r = costc[k2] + px[i] - py[j]
                ln = int(np.floor(r * inv)) + 1
                if ln < 0:
                    ln = 0
                nd = d + ln
                if nd < dist[i] and nd < nb:
                    dist[i] = nd
                    enode[used] = i
                    enext[used] = bhead[nd]
                    bhead[nd] = used
                    used += 1
    for w in range(n + m):
        dw = dist[w] if done[w] else d
        if w < n:
            px[w] -= eps * dw
        else:
            py[w - n] -= eps * dw


@njit(cache=True)
def transport_prices(indptr, indices, cost, colptr, colidx, rowof, a, b, px, py, eps_start,
                     eps_end, theta, tol, max_work, phase_work, flow):
    """ε-scaling push–relabel; updates ``px, py`` in place and returns ``(f, status, work)``:
    the flow on the edges, status 0 (every node balanced within ``tol`` at ``ε = eps_end``) or
    1 (``max_work`` discharges spent), and the discharges. ``colptr, colidx``: each column's
    edges; ``rowof``: each edge's row. Every row and column must have an edge.
    ``phase_work[p]`` receives the discharges of phase ``p`` (phases past its size are not
    counted). ``flow``: the starting flow on the edges (empty: zero), e.g. that of an earlier
    call on fewer edges, with ``eps_start`` its ``ε`` (one phase: a warm start)."""
    n = indptr.size - 1
    m = colptr.size - 1
    size = n + m
    f = np.zeros(cost.size) if flow.size == 0 else flow.copy()
    exx = a.copy()
    exy = -b
    if flow.size:
        for i in range(n):
            for e in range(indptr[i], indptr[i + 1]):
                exx[i] -= f[e]
                exy[indices[e]] += f[e]
    queue = np.empty(size, np.int64)
    inq = np.zeros(size, np.uint8)
    work = 0
    eps = eps_start
    phase = 0
    dist = np.empty(size, np.int64)
    done = np.empty(size, np.uint8)
    bhead = np.empty(BUCKETS_PER_NODE * size, np.int64)
    enode = np.empty(cost.size + size, np.int64)
    enext = np.empty(cost.size + size, np.int64)
    every = max(1, int(UPDATE_EVERY * size))
    costc = cost[colidx]
    rowc = rowof[colidx]
    while True:
        start = work
        _restore(indptr, indices, cost, px, py, f, exx, exy, eps)
        _global_update(indptr, indices, cost, colptr, costc, rowc, px, py, f, exx, exy, eps,
                       tol, dist, done, bhead, enode, enext)
        last = work
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
            if work - last >= every:
                _global_update(indptr, indices, cost, colptr, costc, rowc, px, py, f, exx,
                               exy, eps, tol, dist, done, bhead, enode, enext)
                last = work
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
