r"""Cell lists: every pair of points closer than a cutoff ``R``, in ``O(N)`` memory.

Used by :class:`~kinred.pairsum.CellList` (kernels truncated at ``R``) and by the near-field
correction of :class:`~kinred.pairsum.NUFFT` (the near part of a kernel, supported in
``|r| < ε_I``). The points ``s (N, k)`` are binned into cubic cells of side ``h ≥ R``
(``h = R`` unless the cell count would overflow 62-bit ids); only occupied cells are stored
(sorted ids, so memory is ``O(N)`` however sparse the cloud), the points are sorted by cell,
and each cell meets the cells of its *half stencil* (the ``(3ᵏ − 1)/2`` neighbour offsets
after zero in lexicographic order, found by binary search among the occupied ids) and itself
(pairs ``i < j``), so every unordered pair within ``R`` is met exactly once.

Work is cut into items (row ranges of one cell) and chunks of at most about :data:`CHUNK`
candidate pairs; the engine threads take chunks in turn, each with its own accumulators.
Per chunk, a compiled pass gathers the pairs within ``R`` and their squared distances,
the kernel is evaluated on them vectorized (any kernel: ``value_sq`` or ``φ(√q)``), and a
compiled pass adds ``φ Z[j]`` to row ``i`` and ``φ Z[i]`` to row ``j``.

Cost ``O(N log N)`` to build (one sort) and ``O(N · 3ᵏ ρ hᵏ)`` candidate pairs per
evaluation (``ρ`` the density of points): ``9/2`` cells per cell in 2-D, ``27/2`` in 3-D;
``3ᵏ/2`` in ``k`` dimensions, which is why the backends stop at ``k = 3``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .. import _parallel
from . import _cell_kernels

__all__ = ["CellGrid", "build", "accumulate", "CHUNK"]

#: Candidate pairs per chunk (the pair buffers: 20 bytes a pair, about 5 MB per thread).
CHUNK = 2 ** 18
_MAX_ID = 2 ** 62


@dataclass(frozen=True, eq=False)
class CellGrid:
    """The cells of one cloud for one cutoff.

    Attributes
    ----------
    r2 : float
        The squared cutoff: pairs with ``|sᵢ − sⱼ|² < r2`` are met.
    h : float
        The cell side.
    perm : (N,) int64
        Sorted position → original index.
    S : (N, k) ndarray
        The points in sorted order, translated by the cloud's lower corner.
    start, count : (cells,) int64
        Each occupied cell's first sorted position and its number of points.
    nbr : (cells, (3ᵏ − 1)/2) int64
        The occupied cells of each cell's half stencil (−1: empty).
    chunks : tuple of (items, 3) int64 ndarrays
        Work items ``(cell, a0, a1)``, grouped in chunks.
    buffer : int
        Pair-buffer length that holds any chunk's pairs.
    candidates : int
        Upper bound of the pairs examined per evaluation.
    """

    r2: float
    h: float
    perm: np.ndarray
    S: np.ndarray
    start: np.ndarray
    count: np.ndarray
    nbr: np.ndarray
    chunks: tuple
    buffer: int
    candidates: int

    @property
    def cells(self) -> int:
        return int(self.start.size)


def _half_stencil(k: int) -> np.ndarray:
    """The offsets ``o ∈ {−1, 0, 1}ᵏ`` whose first non-zero entry is positive, ``(nh, k)``."""
    offs = [o for o in itertools.product((-1, 0, 1), repeat=k)
            if any(o) and o[next(a for a in range(k) if o[a])] > 0]
    return np.array(offs, dtype=np.int64).reshape(-1, k)


def build(s: np.ndarray, R: float, chunk: int = CHUNK) -> CellGrid:
    """The :class:`CellGrid` of the points ``s (N, k)`` for the cutoff ``R > 0``."""
    n, k = s.shape
    lo = s.min(axis=0)
    ext = s.max(axis=0) - lo
    h = float(R)
    while True:
        nc = (np.floor(ext / h).astype(np.int64) + 1)
        dims = [int(c) + 2 for c in nc]
        total = 1
        for c in dims:
            total *= c
        if total < _MAX_ID:
            break
        h *= 2.0
    coords = np.minimum(np.floor((s - lo) / h).astype(np.int64), nc - 1)
    strides = np.ones(k, dtype=np.int64)
    for a in range(k - 2, -1, -1):
        strides[a] = strides[a + 1] * dims[a + 1]
    lin = (coords + 1) @ strides
    perm = np.argsort(lin, kind="stable")
    uniq, start, count = np.unique(lin[perm], return_index=True, return_counts=True)
    offs = _half_stencil(k)
    nbr = np.full((uniq.size, offs.shape[0]), -1, dtype=np.int64)
    for hh, o in enumerate(offs):
        want = uniq + int(o @ strides)
        pos = np.minimum(np.searchsorted(uniq, want), uniq.size - 1)
        nbr[:, hh] = np.where(uniq[pos] == want, pos, -1)
    nbsum = np.where(nbr >= 0, count[np.maximum(nbr, 0)], 0).sum(axis=1)
    chunks, buffer, cand = _items(count, count + nbsum, chunk)
    return CellGrid(r2=float(R) ** 2, h=h, perm=perm, S=np.ascontiguousarray((s - lo)[perm]),
                    start=start.astype(np.int64), count=count.astype(np.int64), nbr=nbr,
                    chunks=chunks, buffer=buffer, candidates=cand)


def _items(count: np.ndarray, rowbound: np.ndarray, chunk: int) -> tuple:
    """Work items ``(cell, a0, a1)`` (rows of a cell, at most about ``chunk`` candidates
    each unless one row has more) grouped into chunks; the buffer length and the candidates."""
    rows = np.maximum(1, chunk // np.maximum(rowbound, 1))
    nit = -(-count // rows)
    cell = np.repeat(np.arange(count.size), nit)
    first = np.repeat(np.cumsum(nit) - nit, nit)
    a0 = (np.arange(cell.size) - first) * rows[cell]
    a1 = np.minimum(a0 + rows[cell], count[cell])
    bound = (a1 - a0) * rowbound[cell]
    excl = np.cumsum(bound) - bound
    cid = excl // chunk
    items = np.stack([cell, a0, a1], axis=1).astype(np.int64)
    cuts = np.flatnonzero(np.diff(cid)) + 1
    chunks = tuple(np.split(items, cuts))
    per = np.bincount(cid, weights=bound) if bound.size else np.zeros(1)
    return chunks, int(max(chunk, per.max())) + 1, int(bound.sum())


def chunk_shares(nchunks: int, nthreads: int, first=None) -> list:
    """The chunks (indices) of each thread: interleaved (chunk ``c`` to thread
    ``c mod nthreads``, neighbouring cells cost alike), or with ``first`` the fraction
    ``first`` of them spread evenly to thread 0 and the rest interleaved over the others
    (thread 0 has other work first). Fixed by the counts alone: the same threads get the
    same chunks on every call, so the sums are reproducible."""
    nthreads = max(1, min(nthreads, max(nchunks, 1)))
    if first is None or nthreads == 1:
        return [list(range(g, nchunks, nthreads)) for g in range(nthreads)]
    first = min(max(float(first), 0.0), 1.0)
    c = np.arange(nchunks)
    zero = np.floor((c + 1) * first) > np.floor(c * first)
    rest = c[~zero]
    return [c[zero].tolist()] + [rest[g::nthreads - 1].tolist() for g in range(nthreads - 1)]


_NO_SPLIT = np.zeros(5)
_NO_TABLE = np.zeros((1, 4))


def accumulate(grid: CellGrid, evals: list, Zs: list, nacc: int, nthreads: int,
               compiled: bool = True, side=None, side_share: float = 0.0) -> tuple:
    """The pair sums of the grid's pairs: per thread an ``(nacc, N, d + 1)`` array (sorted
    order) ``A[a, i] += Σ_j φ_t(|sᵢ − sⱼ|) Z_t[j]`` over the terms ``t`` of ``evals``.

    Parameters
    ----------
    evals : list of (callable, int, int)
        Per term: ``phi(q) -> φ(√q)`` (a fresh or reused array of ``q``'s length), the index
        of its carrier in ``Zs`` and of its accumulator.
    Zs : list of (N, d + 1) ndarray
        The carriers ``[c z, c]`` in sorted order.
    side : callable, optional
        Other work (e.g. the NUFFT's transforms) run by the calling thread before its
        chunks, overlapping the other threads' pairs; that thread then takes only the
        fraction ``side_share`` of the chunks (:func:`chunk_shares`).

    Returns
    -------
    (accs, pairs)
        The per-thread accumulators and the number of pairs within the cutoff.
    """
    n = grid.S.shape[0]
    d1 = Zs[0].shape[1] if Zs else 1
    gather = _cell_kernels.gather_pairs if compiled else _cell_kernels.gather_pairs_numpy
    scatter = _cell_kernels.scatter_pairs if compiled else _cell_kernels.scatter_pairs_numpy
    shares = [[grid.chunks[c] for c in mine] for mine in
              chunk_shares(len(grid.chunks), nthreads, None if side is None else side_share)]

    def side_first(g):
        if g == 0 and side is not None:
            side()

    fused = compiled and all(getattr(fn, "fused", None) is not None
                             or getattr(fn, "table", None) is not None for fn, _, _ in evals)

    def work_fused(g, mine):
        side_first(g)
        A = np.zeros((nacc, n, d1))
        pairs = 0
        for fn, z, a in evals:
            table = getattr(fn, "table", None)
            if table is not None:
                kind, p, sp, tab = _cell_kernels.KIND_TABLE, table.params, _NO_SPLIT, table.C
            else:
                kind = {"morse": _cell_kernels.KIND_MORSE,
                        "cs": _cell_kernels.KIND_CS}[fn.fused[0]]
                p, tab = np.array(fn.fused[1], dtype=np.float64), _NO_TABLE
                sp = fn.split if getattr(fn, "split", None) is not None else _NO_SPLIT
            for items in mine:
                pairs += _cell_kernels.pairs_fused(items, grid.S, grid.start, grid.count,
                                                   grid.nbr, grid.r2, kind, p, sp, tab, Zs[z],
                                                   A[a])
        return A, pairs // max(1, len(evals))

    def work(g, mine):
        side_first(g)
        A = np.zeros((nacc, n, d1))
        oi = np.empty(grid.buffer, dtype=np.int64)
        oj = np.empty(grid.buffer, dtype=np.int64)
        oq = np.empty(grid.buffer)
        pairs = 0
        for items in mine:
            m = gather(items, grid.S, grid.start, grid.count, grid.nbr, grid.r2, oi, oj, oq)
            pairs += m
            if m == 0:
                continue
            for phi, z, a in evals:
                f = np.ascontiguousarray(phi(oq[:m]), dtype=np.float64)
                scatter(oi, oj, f, m, Zs[z], A[a])
        return A, pairs

    out = _parallel.run_parallel(work_fused if fused else work, shares)
    return [o[0] for o in out], sum(o[1] for o in out)
