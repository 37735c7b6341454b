r"""Private numba kernel of :mod:`kinred.distance`: the exact c-transform by branch and bound.

Only this module of :mod:`kinred.distance` imports numba; the kernel uses ``cache=True``.

``ctransform_tree(X, Ys, vs, lo, hi, vmax, first_leaf, starts, best, jbest, slack, rows, r0,
r1, max_leaves, open_rows, thr, cand)``
    For every row ``xᵢ``, ``i`` in ``rows[r0:r1]`` (rows taken in that order: neighbours in
    space one after the other keep the tree's leaves in cache), the exact c-transform

    .. math:: f(x_i) = \min_j \bigl(|x_i - y_j| - v_j\bigr)

    and a minimizer ``j`` (an index into ``Ys``), over *all* columns, by a depth-first
    branch and bound on a complete binary tree over the rows of ``Ys`` (heap layout: node
    ``k`` has children ``2k + 1`` and ``2k + 2``; leaf ``l`` = node ``first_leaf + l`` holds
    the rows ``starts[l] : starts[l + 1]``). Node ``k`` has the bounding box
    ``[lo[k], hi[k]]`` of its rows and ``vmax[k] = max v`` over them, so
    ``dist(xᵢ, box) − vmax[k]`` is below every value of its rows and the node is skipped when
    that bound is not below the best value found (less a safety ``slack`` covering the
    round-off of the bound). A node's bound is computed once, when it is stacked (its parent
    needs it to visit the nearer child first), and kept beside it on the stack: half the box
    distances of recomputing it when the node is taken (10⁵ rows in ℝ⁶: 1.12–1.18 → 0.75 s per
    30 000 rows, the same results). ``best``/``jbest`` enter as an upper bound and its minimizer
    (from the candidate graph: a value that is attained) and are overwritten with the result.
    A row that would visit more than ``max_leaves`` leaves stops there: its ``best`` becomes
    the smallest bound of the nodes still open (a certified *lower* bound of its minimum, not
    attained), ``open_rows[i] = 1``, and ``jbest`` the best column found.
    **Violators**: ``cand[i]`` (``m`` columns) receives the ``m`` columns of smallest value
    among those with ``|xᵢ − yⱼ| − vⱼ < thr[i]`` (``-1`` where fewer were found): the
    search then prunes at the ``m``-th smallest of them instead of the minimum (column
    generation adds them all in one round; with ``thr = −inf`` it is the plain minimum).
    Distances of leaf rows are computed from the coordinate differences,
    ``sqrt(Σₖ (xₖ − yₖ)²)``, in the order of :func:`scipy.spatial.distance.cdist`. The GIL is
    released (``nogil``): disjoint row ranges run in the threads of
    :func:`kinred._parallel.run_parallel`.

Its plain-numpy twin is :func:`ctransform_numpy` (the same minimum by brute force, in
blocks; tests compare the two at 1e-12 relative).

``kd_order(P, h, perm)``
    The row order of a **k-d tree** of depth ``h`` over the points ``P``: ``perm`` (entering
    as ``0, 1, …, n − 1``) is rearranged so that the node ``i`` of depth ``t`` holds the rows
    ``perm[(i·n) >> t : ((i + 1)·n) >> t]`` (the index ranges of :class:`kinred.distance._search.CTree`)
    and each node's two children are split at the median of its widest coordinate (every row
    of the first child at most, every row of the second at least that median). Quickselect
    per node, ``O(n·(d + 1)·h)``. In ℝ⁶ its nodes' boxes are tighter than those of the Z-order
    curve's ranges: the c-transform of 10⁵ vs 8·10⁴ weighted atoms visits fewer leaves and
    takes 2.2–2.9 s instead of 5.9–6.9 s (same values). Its numpy twin is
    :func:`kd_order_numpy` (``np.argpartition``; the same node contents, in another order
    within a node).

``smallest_k(D, k, out)``
    ``out[r]`` = the columns of the ``k`` smallest entries of row ``r`` of ``D`` in ascending
    order of value (ties: the lower column first) – the selection of the blocked searches in
    high dimension (the ``k`` nearest neighbours, the c-transform's violators). One
    comparison per entry against the row's current ``k``-th value, an insertion (``O(k)``)
    only for the few entries that beat it (:func:`_insert`): about 1.6 ns an entry, where
    ``np.argpartition`` along the rows took 43 ns (17 of the 29 s of 2·10⁴ paired atoms in
    ℝ²⁰). ``+inf`` and then NaN entries come last, as in the twin :func:`smallest_k_numpy`
    (a stable argsort).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["ctransform_tree", "ctransform_numpy", "smallest_k", "smallest_k_numpy",
           "kd_order", "kd_order_numpy"]


@njit(cache=True, nogil=True)
def smallest_k(D, k, out):  # pragma: no cover - compiled
    n, m = D.shape
    vals = np.empty(k)
    idx = np.empty(k, np.int64)
    for r in range(n):
        vals[:] = np.inf
        idx[:] = -1
        for j in range(m):
            if D[r, j] < vals[k - 1]:           # the one comparison of most entries
                _insert(vals, idx, D[r, j], j)
        cnt = 0
        while cnt < k and idx[cnt] >= 0:
            cnt += 1
        for want_nan in (False, True):          # then +inf columns, then NaN ones (argsort's order)
            for j in range(m):
                if cnt == k:
                    break
                x = D[r, j]
                if (x != x) if want_nan else (x == np.inf):
                    idx[cnt] = j
                    cnt += 1
        for q in range(k):
            out[r, q] = idx[q]
    return out


def smallest_k_numpy(D: np.ndarray, k: int) -> np.ndarray:
    """Twin of :func:`smallest_k`: the first ``k`` columns of a stable argsort of every row
    (NaN sorts last)."""
    return np.argsort(D, axis=1, kind="stable")[:, :k].astype(np.int64)


@njit(cache=True)
def _box_bound(x, lo, hi, node):
    s = 0.0
    for k in range(x.shape[0]):
        t = lo[node, k] - x[k]
        if t < 0.0:
            t = x[k] - hi[node, k]
        if t > 0.0:
            s += t * t
    return np.sqrt(s)


@njit(cache=True)
def _insert(vals, idx, val, j):
    """Insert ``(val, j)`` into the ascending list ``vals``/``idx`` (a ``j`` already listed is
    not listed twice); the largest entry falls off."""
    m = vals.shape[0]
    q = m - 1
    for p in range(m):
        if idx[p] == j:
            if not val < vals[p]:
                return
            q = p                              # the same column, a smaller value: move it up
            break
    if not val < vals[q]:
        return
    while q > 0 and val < vals[q - 1]:
        vals[q] = vals[q - 1]
        idx[q] = idx[q - 1]
        q -= 1
    vals[q] = val
    idx[q] = j


@njit(cache=True, nogil=True)
def ctransform_tree(X, Ys, vs, lo, hi, vmax, first_leaf, starts, best, jbest, slack, rows, r0,
                    r1, max_leaves, open_rows, thr, cand):
    d = X.shape[1]
    n_nodes = lo.shape[0]
    m = cand.shape[1]
    stack = np.empty(256, np.int64)
    bound = np.empty(256)          # each stacked node's bound, computed once (when stacked)
    vals = np.empty(m)
    idx = np.empty(m, np.int64)
    for r in range(r0, r1):
        i = rows[r]
        x = X[i]
        vals[:] = np.inf
        idx[:] = -1
        vals[0] = best[i]
        idx[0] = jbest[i]
        t_i = thr[i]
        top = 1
        stack[0] = 0
        bound[0] = _box_bound(x, lo, hi, 0) - vmax[0]
        leaves = 0
        while top > 0:
            # prune at the best value, or while collecting violators below thr[i], at the
            # m-th smallest of them
            cut = vals[m - 1] if vals[m - 1] < t_i else t_i
            if cut < vals[0]:
                cut = vals[0]
            if leaves >= max_leaves:          # stop: the frontier's bounds bound the minimum
                lower = vals[0]
                for q in range(top):
                    lb = bound[q] - slack
                    if lb < lower:
                        lower = lb
                if lower < vals[0]:
                    vals[0] = lower
                    open_rows[i] = 1
                break
            top -= 1
            node = stack[top]
            if bound[top] - slack >= cut:
                continue
            if node >= first_leaf:
                leaves += 1
                leaf = node - first_leaf
                for j in range(starts[leaf], starts[leaf + 1]):
                    s = 0.0
                    for k in range(d):
                        t = x[k] - Ys[j, k]
                        s += t * t
                    val = np.sqrt(s) - vs[j]
                    if val < vals[0] or (val < t_i and val < vals[m - 1]):
                        _insert(vals, idx, val, j)
                continue
            c1 = 2 * node + 1
            c2 = c1 + 1
            if c2 >= n_nodes:
                stack[top] = c1
                bound[top] = _box_bound(x, lo, hi, c1) - vmax[c1]
                top += 1
                continue
            b1 = _box_bound(x, lo, hi, c1) - vmax[c1]
            b2 = _box_bound(x, lo, hi, c2) - vmax[c2]
            if b1 <= b2:
                stack[top], bound[top] = c2, b2
                stack[top + 1], bound[top + 1] = c1, b1
            else:
                stack[top], bound[top] = c1, b1
                stack[top + 1], bound[top + 1] = c2, b2
            top += 2
        best[i] = vals[0]
        jbest[i] = idx[0]
        for q in range(m):
            cand[i, q] = idx[q] if vals[q] < t_i else -1


def ctransform_numpy(X: np.ndarray, Y: np.ndarray, v: np.ndarray, block: int = 1024,
                     thr: np.ndarray | None = None, m: int = 1):
    """``minⱼ (|xᵢ − yⱼ| − vⱼ)`` and a minimizer for every row, by brute force (``cdist``);
    with ``thr``, also the ``(N, m)`` violators of :func:`ctransform_tree` (the ``m`` columns
    of smallest value below ``thr[i]``, ``-1`` padded).

    The plain-numpy twin of :func:`ctransform_tree` (and the reference of the tests).
    """
    from scipy.spatial.distance import cdist

    f = np.empty(X.shape[0])
    j = np.empty(X.shape[0], np.int64)
    cand = np.full((X.shape[0], m), -1, np.int64)
    for s in range(0, X.shape[0], block):
        G = cdist(X[s:s + block], Y) - v[None, :]
        j[s:s + block] = np.argmin(G, axis=1)
        f[s:s + block] = G[np.arange(G.shape[0]), j[s:s + block]]
        if thr is not None:
            order = np.argsort(G, axis=1, kind="stable")[:, :m]
            below = np.take_along_axis(G, order, axis=1) < thr[s:s + block, None]
            cand[s:s + block] = np.where(below, order, -1)
    return (f, j) if thr is None else (f, j, cand)


@njit(cache=True, nogil=True)
def kd_order(P, h, perm):  # pragma: no cover - compiled
    n, d = P.shape
    keys = np.empty(n)
    for t in range(h):
        for i in range(1 << t):
            s = (i * n) >> t
            e = ((i + 1) * n) >> t
            mid = ((2 * i + 1) * n) >> (t + 1)
            if e - s < 2 or mid <= s or mid >= e:
                continue
            dim = 0
            wide = -1.0
            for k in range(d):
                lo = np.inf
                hi = -np.inf
                for q in range(s, e):
                    z = P[perm[q], k]
                    if z < lo:
                        lo = z
                    if z > hi:
                        hi = z
                if hi - lo > wide:
                    wide = hi - lo
                    dim = k
            for q in range(s, e):
                keys[q] = P[perm[q], dim]
            _select(keys, perm, s, e - 1, mid)


@njit(cache=True, nogil=True)
def _select(keys, perm, left, right, k):  # pragma: no cover - compiled
    """Rearrange ``keys[left:right + 1]`` (and ``perm`` alongside) so that ``keys[k]`` is the
    value of rank ``k − left``, those before it at most and those after at least it
    (Hoare partitions around the median of three)."""
    while right > left:
        a, b, c = keys[left], keys[(left + right) >> 1], keys[right]
        pivot = max(min(a, b), min(max(a, b), c))
        i, j = left, right
        while i <= j:
            while keys[i] < pivot:
                i += 1
            while keys[j] > pivot:
                j -= 1
            if i <= j:
                keys[i], keys[j] = keys[j], keys[i]
                perm[i], perm[j] = perm[j], perm[i]
                i += 1
                j -= 1
        if k <= j:
            right = j
        elif k >= i:
            left = i
        else:
            return


def kd_order_numpy(P: np.ndarray, h: int) -> np.ndarray:
    """The plain-numpy twin of :func:`kd_order`: the same split of every node (median of the
    widest coordinate by ``np.argpartition``), hence the same node contents."""
    n = P.shape[0]
    perm = np.arange(n, dtype=np.int64)
    for t in range(h):
        for i in range(1 << t):
            s, e, mid = (i * n) >> t, ((i + 1) * n) >> t, ((2 * i + 1) * n) >> (t + 1)
            if e - s < 2 or mid <= s or mid >= e:
                continue
            sub = perm[s:e]
            Q = P[sub]
            dim = int(np.argmax(Q.max(axis=0) - Q.min(axis=0)))
            perm[s:e] = sub[np.argpartition(Q[:, dim], mid - s, kind="introselect")]
    return perm
