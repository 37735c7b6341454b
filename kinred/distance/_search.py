r"""Exact nearest-neighbour searches of the sparse W1 solver (:mod:`kinred.distance._sparse`).

Two searches over all pairs ``(xᵢ, yⱼ)`` of two atomic measures, both exact:

* :func:`knn` -- the ``k`` nearest ``yⱼ`` of every ``xᵢ`` (the candidate graph): a
  :class:`scipy.spatial.cKDTree` in low dimension, blocked BLAS distances in high dimension
  (points centred first, so that ``|x|² + |y|² − 2x·y`` keeps its digits far from the origin;
  these distances only *choose* candidates, their costs are recomputed from differences);
* :func:`ctransform` -- the c-transform ``f(xᵢ) = minⱼ (|xᵢ − yⱼ| − vⱼ)`` over all ``j`` and a
  minimizer: in low dimension a branch and bound on a tree over the ``yⱼ`` whose nodes carry
  their bounding box and ``max v`` (a ``yⱼ`` whose distance exceeds the best value plus
  ``max v`` of its node cannot win; numba kernel :func:`kinred.distance._kernels.ctransform_tree`),
  in high dimension blocked BLAS minima with the near-minimal candidates of every row
  recomputed from coordinate differences (so the minimum is the exact one).
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["TREE_MAX_DIM", "BLAS_MAX_PAIRS", "use_tree", "knn", "ctransform", "CTree",
           "OutOfTime"]

#: Dimensions up to which the searches use trees (above: blocked BLAS, unless too many pairs).
TREE_MAX_DIM = 8

#: Above this many pairs N·M the searches use trees in any dimension (a BLAS pass over all
#: pairs would take minutes; clouds with decaying widths have a small intrinsic dimension).
BLAS_MAX_PAIRS = 2 * 10**9


#: Leaves a row of the tree search may visit once the deadline has passed.
LEAVES_PAST_DEADLINE = 8


class OutOfTime(Exception):
    """Internal: a search passed its deadline (caught by the sparse solver)."""


def use_tree(n: int, m: int, d: int) -> bool:
    """Whether the searches over ``n × m`` pairs in dimension ``d`` use trees."""
    return d <= TREE_MAX_DIM or n * m > BLAS_MAX_PAIRS

_EPS = np.finfo(np.float64).eps
_LEAF = 32


def _morton_order(Y: np.ndarray) -> np.ndarray:
    """A permutation of the rows of ``Y`` along the Z-order curve of a ``2^b``-grid."""
    n, d = Y.shape
    bits = max(1, min(21, 63 // d))
    lo, hi = Y.min(axis=0), Y.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    q = ((Y - lo) / span * (2**bits - 1)).astype(np.uint64)
    code = np.zeros(n, np.uint64)
    for b in range(bits - 1, -1, -1):
        for k in range(d):
            code = (code << np.uint64(1)) | ((q[:, k] >> np.uint64(b)) & np.uint64(1))
    return np.argsort(code, kind="stable")


def _depth(n: int, leaf: int) -> int:
    """Depth of the complete binary tree over ``n`` rows whose leaves hold about ``leaf``."""
    h = 0
    while (n >> (h + 1)) >= leaf // 2 and (n >> (h + 1)) >= 1 and h < 40:
        h += 1
    return h


class CTree:
    """Complete binary tree over the rows of ``Y`` (a k-d tree: every node split at the median
    of its widest coordinate, :func:`kinred.distance._kernels.kd_order`; leaves of about 32
    rows), with every node's bounding box; :meth:`node_vmax` adds ``max v`` per node."""

    def __init__(self, Y: np.ndarray):
        from ._kernels import kd_order

        n, d = Y.shape
        h = _depth(n, _LEAF)
        self.order = np.arange(n, dtype=np.int64)
        kd_order(np.ascontiguousarray(Y, dtype=np.float64), h, self.order)
        self.rank = np.empty_like(self.order)           # rank[order[p]] = p
        self.rank[self.order] = np.arange(n)
        self.Ys = np.ascontiguousarray(Y[self.order])
        n_leaves = 1 << h
        self.first_leaf = n_leaves - 1
        self.starts = (np.arange(n_leaves + 1, dtype=np.int64) * n) >> h
        self.lo = np.empty((2 * n_leaves - 1, d))
        self.hi = np.empty((2 * n_leaves - 1, d))
        self.lo[self.first_leaf:] = np.minimum.reduceat(self.Ys, self.starts[:-1], axis=0)
        self.hi[self.first_leaf:] = np.maximum.reduceat(self.Ys, self.starts[:-1], axis=0)
        self._up(self.lo, np.minimum)
        self._up(self.hi, np.maximum)

    def _up(self, arr, op):
        first = self.first_leaf
        while first > 0:
            parent = (first - 1) // 2
            arr[parent:first] = op(arr[first:2 * first + 1:2], arr[first + 1:2 * first + 2:2])
            first = parent

    def node_vmax(self, v: np.ndarray, ordered: bool = False) -> np.ndarray:
        """Each node's largest ``v`` over its points (``v`` in the points' order, or with
        ``ordered`` already in the tree's order)."""
        vs = v if ordered else v[self.order]
        out = np.empty(self.lo.shape[0])
        out[self.first_leaf:] = np.maximum.reduceat(vs, self.starts[:-1])
        self._up(out, np.maximum)
        return out


def ctransform(X: np.ndarray, Y: np.ndarray, v: np.ndarray, best: np.ndarray,
               jbest: np.ndarray, tree: CTree | None = None, block: int = 512,
               deadline: float | None = None, open_rows: np.ndarray | None = None,
               thr: np.ndarray | None = None, m: int = 1, rows: np.ndarray | None = None):
    """Exact ``f(xᵢ) = minⱼ (|xᵢ − yⱼ| − vⱼ)`` over all ``j`` and a minimizer ``jᵢ``.

    ``best``/``jbest`` are an attained value and its column for every row (from the candidate
    graph): the search starts from them. ``tree`` (a :class:`CTree` of ``Y``) selects the
    branch and bound; without it, blocked BLAS. Past ``deadline`` (``time.perf_counter``)
    the tree search visits at most :data:`LEAVES_PAST_DEADLINE` leaves per row, and a row it
    cuts short gets a certified lower bound of its minimum (``open_rows[i] = 1``); the BLAS
    search raises :class:`OutOfTime` between blocks. With ``thr`` it also returns the
    ``(N, m)`` *violators*: up to ``m`` columns of smallest value below ``thr[i]`` (``-1``
    padded; the BLAS path takes them among the ``m`` smallest of its approximate values).
    ``rows`` is the order in which the tree search takes the rows (e.g. a
    :class:`CTree`'s ``order`` of ``X``: neighbours one after the other).
    """
    want = thr is not None
    thr = np.full(X.shape[0], -np.inf) if thr is None else np.asarray(thr, np.float64)
    if tree is None:
        f, jb, cand = _ctransform_blas(X, Y, v, best, jbest, block, deadline, thr, m)
        return (f, jb, cand) if want else (f, jb)
    from .._parallel import get_num_threads, run_parallel
    from ._kernels import ctransform_tree

    f = np.array(best, dtype=np.float64)
    jp = tree.rank[jbest].astype(np.int64)
    vs = np.ascontiguousarray(v[tree.order])
    vmax = tree.node_vmax(v)
    scale = float(np.max(np.abs(tree.Ys))) + float(np.max(np.abs(X))) + float(np.max(np.abs(v)))
    X = np.ascontiguousarray(X)
    slack = 16 * _EPS * scale
    open_rows = np.zeros(X.shape[0], np.int8) if open_rows is None else open_rows
    rows = np.arange(X.shape[0], dtype=np.int64) if rows is None else rows.astype(np.int64)
    cand = np.empty((X.shape[0], m), np.int64)
    chunk = 1 << 14
    for s in range(0, X.shape[0], chunk):
        late = deadline is not None and time.perf_counter() > deadline
        cap = LEAVES_PAST_DEADLINE if late else 1 << 62
        e = min(s + chunk, X.shape[0])
        cuts = np.linspace(s, e, get_num_threads() + 1).astype(np.int64)
        run_parallel(lambda g, r: ctransform_tree(X, tree.Ys, vs, tree.lo, tree.hi, vmax,
                                                  tree.first_leaf, tree.starts, f, jp, slack,
                                                  rows, r[0], r[1], cap, open_rows, thr, cand),
                     [(int(cuts[i]), int(cuts[i + 1])) for i in range(cuts.size - 1)])
    cand = np.where(cand >= 0, tree.order[np.maximum(cand, 0)], -1)
    return (f, tree.order[jp], cand) if want else (f, tree.order[jp])


def _check(deadline):
    if deadline is not None and time.perf_counter() > deadline:
        raise OutOfTime


def _centred(X: np.ndarray, Y: np.ndarray):
    c = 0.5 * (X.mean(axis=0) + Y.mean(axis=0))
    Xc, Yc = X - c, Y - c
    return Xc, Yc, np.einsum("ij,ij->i", Xc, Xc), np.einsum("ij,ij->i", Yc, Yc)


def _smallest(D: np.ndarray, k: int) -> np.ndarray:
    """Columns of the ``k`` smallest entries of every row of ``D`` (ascending; ties: the
    lower column): :func:`kinred.distance._kernels.smallest_k`."""
    from ._kernels import smallest_k

    return smallest_k(np.ascontiguousarray(D, dtype=np.float64), int(k),
                      np.empty((D.shape[0], k), np.int64))


def _ctransform_blas(X, Y, v, best, jbest, block, deadline, thr, m):
    """Blocked ``|x|² + |y|² − 2x·y`` (centred), then the exact values of every column within
    twice the distance error of the row's minimum (so the minimum over them is exact); the
    violators among the ``m`` smallest approximate values."""
    d = X.shape[1]
    Xc, Yc, x2, y2 = _centred(X, Y)
    f = np.array(best, dtype=np.float64)
    jb = np.array(jbest, dtype=np.int64)
    cand = np.full((X.shape[0], m), -1, np.int64)
    m = min(m, Y.shape[0])
    for s in range(0, X.shape[0], block):
        if s % (64 * block) == 0:
            _check(deadline)
        e = min(s + block, X.shape[0])
        D2 = x2[s:e, None] + y2[None, :] - 2.0 * (Xc[s:e] @ Yc.T)
        # |D2 − |x − y|²| <= δ, so |sqrt(D2₊) − |x − y|| <= sqrt(δ)
        delta = 4.0 * (d + 4) * _EPS * (float(x2[s:e].max()) + float(y2.max()))
        r = np.sqrt(delta)
        np.maximum(D2, 0.0, out=D2)
        G = np.sqrt(D2, out=D2)
        G -= v[None, :]
        if np.isfinite(thr[s:e]).any():
            top = _smallest(G, m) if m < G.shape[1] else \
                np.broadcast_to(np.arange(m), (e - s, m))
            ii = np.repeat(np.arange(e - s), m)
            exact = np.sqrt(np.sum((X[s + ii] - Y[top.ravel()]) ** 2, axis=1)) - v[top.ravel()]
            below = exact.reshape(e - s, m) < thr[s:e, None]
            cand[s:e, :m] = np.where(below, top, -1)
        upper = np.minimum(G.min(axis=1) + r, f[s:e])
        ii, jj = np.nonzero(G <= (upper + r)[:, None])
        vals = np.sqrt(np.sum((X[s + ii] - Y[jj]) ** 2, axis=1)) - v[jj]
        order = np.lexsort((vals, ii))
        first = np.ones(order.size, bool)
        first[1:] = ii[order][1:] != ii[order][:-1]
        rows, cols, vv = s + ii[order][first], jj[order][first], vals[order][first]
        better = vv < f[rows]
        f[rows[better]] = vv[better]
        jb[rows[better]] = cols[better]
    return f, jb, cand


def knn(X: np.ndarray, Y: np.ndarray, k: int, block: int = 512) -> np.ndarray:
    """Indices ``(N, k)`` of the ``k`` nearest rows of ``Y`` for every row of ``X``."""
    k = min(k, Y.shape[0])
    if use_tree(X.shape[0], Y.shape[0], X.shape[1]):
        from scipy.spatial import cKDTree

        # queries along the Z-order curve: neighbours one after the other keep the tree's
        # nodes in cache (3x faster at 10⁶ atoms than the atoms' own order; same result)
        order = _morton_order(X) if X.shape[0] > 4096 else np.arange(X.shape[0])
        _, idx = cKDTree(Y).query(X[order], k=k, workers=-1)
        out = np.empty((X.shape[0], k), np.int64)
        out[order] = np.asarray(idx, dtype=np.int64).reshape(X.shape[0], k)
        return out
    Xc, Yc, x2, y2 = _centred(X, Y)
    out = np.empty((X.shape[0], k), np.int64)
    for s in range(0, X.shape[0], block):
        D2 = y2[None, :] - 2.0 * (Xc[s:s + block] @ Yc.T)
        if k < Y.shape[0]:
            out[s:s + block] = _smallest(D2, k)
        else:
            out[s:s + block] = np.arange(k)[None, :]
    return out
