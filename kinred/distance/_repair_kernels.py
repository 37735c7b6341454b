r"""Private numba kernel of :mod:`kinred.distance`: repair of a transport plan and its duals
over *all* pairs, by label-correcting shortest paths with negative-cycle cancelling.

Only the ``_kernels`` modules of :mod:`kinred.distance` import numba; kernels use
``cache=True``.

The problem (eq. (4.5) of the paper, ground cost ``c(x, y) = |x − y|``): a coupling ``π`` of
the two measures (a finite list of edges ``(i, j, πᵢⱼ)``, the output of a network simplex on a
sparse candidate graph) and potentials ``u, v``. ``π`` is optimal over all pairs if and only
if potentials exist with

.. math:: u_i + v_j \le |x_i - y_j| \ \text{for all } (i, j), \qquad
          u_i + v_j = |x_i - y_j| \ \text{where } \pi_{ij} > 0,

and such potentials are the shortest-path distances of the *residual graph*: nodes
``xᵢ``, ``yⱼ``; an edge ``yⱼ → xᵢ`` of length ``cᵢⱼ`` for **every** pair (moving more mass
along ``(i, j)``) and an edge ``xᵢ → yⱼ`` of length ``−cᵢⱼ`` where ``πᵢⱼ > 0`` (moving less),
with ``d(xᵢ) = uᵢ`` and ``d(yⱼ) = −vⱼ``. :func:`repair_plan` runs the queue-based
Bellman–Ford (SPFA) from the given potentials:

* a row ``xᵢ`` whose ``uᵢ`` went down relaxes its plan edges: ``vⱼ ← max(vⱼ, cᵢⱼ − uᵢ)``;
* a column ``yⱼ`` whose ``vⱼ`` went up relaxes *all* rows, ``uᵢ ← min(uᵢ, cᵢⱼ − vⱼ)``, by a
  branch and bound over a tree of the ``xᵢ`` whose nodes carry their bounding box and an upper
  bound of ``u`` over them (``u`` only decreases, so bounds computed once stay valid): a node
  with ``dist(yⱼ, box) − max u ≥ vⱼ`` holds no violated pair.

When the predecessor edges close a cycle, it is a cycle of negative length: moving the mass
``δ`` (the smallest on its decreasing edges) around it lowers the plan's cost by ``δ·|length|``
and keeps both marginals -- the plan is repaired too (cycle cancelling). Cycles are found when
a new predecessor closes one within :data:`WALK` steps and, every ``n + m`` steps of work, by
a sweep over all predecessor chains. When the queue empties, ``u, v`` satisfy both conditions
up to ``tiny``: the plan is optimal over all pairs (up to round-off), and the c-transform of
``v`` proves it (:func:`kinred.distance._sparse._certify`, independent of this kernel).

The plain-numpy twin is :func:`repair_numpy` (dense Bellman–Ford for small problems, plan
kept fixed); the tests compare the potentials' dual values and check optimality against POT.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import _box_bound

__all__ = ["repair_plan", "repair_numpy", "WALK"]

#: Predecessor steps a new label walks back to find a cycle it closes.
WALK = 256

# status codes of repair_plan
CONVERGED, OUT_OF_WORK, OUT_OF_EDGES = 0, 1, 2


@njit(cache=True)
def _dist(A, p, B, j):
    s = 0.0
    for k in range(A.shape[1]):
        t = A[p, k] - B[j, k]
        s += t * t
    return np.sqrt(s)


@njit(cache=True)
def _push(queue, inq, qs, w):
    """Enqueue node ``w`` (rows ``0..n-1``, columns ``n..n+m-1``) unless queued."""
    if inq[w]:
        return
    inq[w] = 1
    queue[qs[1]] = w
    qs[1] = (qs[1] + 1) % queue.shape[0]
    qs[2] += 1


@njit(cache=True)
def _find_edge(head, nxt, ecol, p, j):
    e = head[p]
    while e >= 0:
        if ecol[e] == j:
            return e
        e = nxt[e]
    return -1


@njit(cache=True)
def _cancel(p0, pred_x, pred_y, erow, ecol, emass, head, nxt, ne, rows, queue, inq, qs):
    """Move mass around the predecessor cycle through row ``p0`` (``pred_x[p0]`` set).

    Returns the new edge count, or ``-1`` when the edge arrays have no room (nothing moved)."""
    k = 0
    p = p0
    delta = np.inf
    arg = -1
    new = 0
    while True:                                  # walk once: length, bottleneck, new edges
        rows[k] = p
        k += 1
        j = pred_x[p]
        if _find_edge(head, nxt, ecol, p, j) < 0:
            new += 1
        e = pred_y[j]
        if emass[e] < delta:
            delta = emass[e]
            arg = e
        p = erow[e]
        if p == p0 or k >= rows.shape[0]:
            break
    if p != p0 or ne + new > erow.shape[0]:
        return -1
    for q in range(k):
        p = rows[q]
        j = pred_x[p]
        e = pred_y[j]
        emass[e] = 0.0 if e == arg else emass[e] - delta
        if emass[e] < 0.0:
            emass[e] = 0.0
        f = _find_edge(head, nxt, ecol, p, j)
        if f < 0:
            f = ne
            erow[f], ecol[f], emass[f] = p, j, 0.0
            nxt[f] = head[p]
            head[p] = f
            ne += 1
        emass[f] += delta
    for q in range(k):                           # the cycle is gone: its labels restart
        p = rows[q]
        pred_y[pred_x[p]] = -1
        pred_x[p] = -1
        _push(queue, inq, qs, p)
    return ne


@njit(cache=True)
def _closes_cycle(p, j, pred_x, pred_y, erow, walk):
    """Whether row ``p`` is an ancestor of column ``j`` within ``walk`` predecessor steps."""
    q = j
    for _ in range(walk):
        e = pred_y[q]
        if e < 0:
            return False
        r = erow[e]
        if r == p:
            return True
        q = pred_x[r]
        if q < 0:
            return False
    return False


@njit(cache=True)
def _sweep(pred_x, pred_y, erow, mark, n):
    """A row on a predecessor cycle, or ``-1`` (every chain followed once)."""
    mark[:] = 0
    for s in range(n):
        p = s
        while p >= 0 and mark[p] == 0:
            mark[p] = s + 1
            j = pred_x[p]
            if j < 0:
                break
            e = pred_y[j]
            if e < 0:
                break
            p = erow[e]
        if p >= 0 and mark[p] == s + 1 and pred_x[p] >= 0 and pred_y[pred_x[p]] >= 0:
            return p
    return -1


@njit(cache=True)
def _relax_row(p, Xs, Y, us, v, erow, ecol, emass, head, nxt, pred_y, queue, inq, qs, n,
               tiny):
    e = head[p]
    while e >= 0:
        if emass[e] > 0.0:
            j = ecol[e]
            val = _dist(Xs, p, Y, j) - us[p]
            if val > v[j] + tiny:
                v[j] = val
                pred_y[j] = e
                _push(queue, inq, qs, n + j)
        e = nxt[e]


@njit(cache=True)
def repair_plan(Xs, Y, us, v, lo, hi, umax, first_leaf, starts, erow, ecol, emass, ne, head,
                nxt, queue, inq, qs, pred_x, pred_y, rows, tiny, slack, max_work):
    """SPFA with negative-cycle cancelling (module docstring), at most ``max_work`` queue
    steps; call again to resume. ``Xs``, ``us``, ``erow`` in the tree's row order; ``us``,
    ``v``, the plan edges (``erow, ecol, emass``, the first ``ne`` used; rows' lists
    ``head``/``nxt``) and the search's state (circular ``queue`` of nodes -- rows ``0..n-1``,
    columns ``n..n+m-1`` -- with ``inq`` flags and ``qs = [head, tail, length, steps since
    the last sweep]``; predecessors ``pred_x`` (a column) and ``pred_y`` (a plan edge);
    ``rows`` scratch of ``n``) are updated in place.
    Returns ``(edges used, status, work, cycles cancelled)``."""
    n = Xs.shape[0]
    m = Y.shape[0]
    stack = np.empty(256, np.int64)
    n_nodes = lo.shape[0]
    work, cycles, status = 0, 0, CONVERGED
    while qs[2] > 0:
        if work >= max_work:
            status = OUT_OF_WORK
            break
        if qs[3] >= n + m:                       # the sweep: cycles the walks missed
            qs[3] = 0
            p = _sweep(pred_x, pred_y, erow, rows, n)
            if p >= 0:
                ne2 = _cancel(p, pred_x, pred_y, erow, ecol, emass, head, nxt, ne, rows,
                              queue, inq, qs)
                if ne2 < 0:
                    status = OUT_OF_EDGES
                    break
                ne = ne2
                cycles += 1
        w = queue[qs[0]]
        qs[0] = (qs[0] + 1) % queue.shape[0]
        qs[2] -= 1
        inq[w] = 0
        work += 1
        qs[3] += 1
        if w < n:
            _relax_row(w, Xs, Y, us, v, erow, ecol, emass, head, nxt, pred_y, queue, inq, qs,
                       n, tiny)
            continue
        j = w - n
        vj = v[j]
        top = 1
        stack[0] = 0
        while top > 0:
            top -= 1
            node = stack[top]
            if _box_bound(Y[j], lo, hi, node) - umax[node] - slack >= vj:
                continue
            if node < first_leaf:
                c1 = 2 * node + 1
                stack[top] = c1
                top += 1
                if c1 + 1 < n_nodes:
                    stack[top] = c1 + 1
                    top += 1
                continue
            for p in range(starts[node - first_leaf], starts[node - first_leaf + 1]):
                val = _dist(Xs, p, Y, j) - vj
                if not val < us[p] - tiny:
                    continue
                us[p] = val
                closes = _closes_cycle(p, j, pred_x, pred_y, erow, WALK)
                pred_x[p] = j
                _push(queue, inq, qs, p)
                if closes:
                    ne2 = _cancel(p, pred_x, pred_y, erow, ecol, emass, head, nxt, ne, rows,
                                  queue, inq, qs)
                    if ne2 < 0:
                        return ne, OUT_OF_EDGES, work, cycles
                    ne = ne2
                    cycles += 1
    return ne, status, work, cycles


def repair_numpy(X: np.ndarray, Y: np.ndarray, pr: np.ndarray, pc: np.ndarray,
                 u: np.ndarray, v: np.ndarray, tiny: float = 0.0, max_sweeps: int | None = None):
    """The plain-numpy twin of :func:`repair_plan` for small problems with an *optimal* plan
    (no cycle to cancel): dense Bellman–Ford sweeps ``u ← min(u, min_j (c − v))``,
    ``v ← max(v, max over the plan's edges of (c − u))`` until nothing moves. Returns ``u, v``
    (``None`` when ``max_sweeps`` (default ``n + m``) pass: a negative cycle)."""
    from scipy.spatial.distance import cdist

    C = cdist(X, Y)
    u, v = np.array(u, float), np.array(v, float)
    for _ in range(max_sweeps or X.shape[0] + Y.shape[0]):
        u_new = np.minimum(u, np.min(C - v[None, :], axis=1))
        u_new = np.where(u_new < u - tiny, u_new, u)
        v_new = v.copy()
        np.maximum.at(v_new, pc, C[pr, pc] - u_new[pr])
        v_new = np.where(v_new > v + tiny, v_new, v)
        if np.array_equal(u_new, u) and np.array_equal(v_new, v):
            return u, v
        u, v = u_new, v_new
    return None


@njit(cache=True)
def propagate_tight(order, pred, n, X, Y, u, v):
    """Potentials exactly tight along a spanning forest: nodes (rows ``0..n-1``, columns
    ``n..``) in breadth-first ``order`` with their parent ``pred`` (``< 0``: a root, whose
    value stays); a column gets ``vⱼ = |x_p − yⱼ| − u_p`` from its parent row ``p``, a row
    ``uᵢ = |xᵢ − y_q| − v_q`` from its parent column ``q``."""
    for w in order:
        p = pred[w]
        if p < 0:
            continue
        if w >= n:
            v[w - n] = _dist(X, p, Y, w - n) - u[p]
        else:
            u[w] = _dist(X, w, Y, p - n) - v[p - n]
