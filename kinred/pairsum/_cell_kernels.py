"""Private numba kernels of the cell list (:mod:`kinred.pairsum._cells`), each with a numpy twin.

Points are sorted by cell, so that the agents of a cell are contiguous; a work item is a row
range ``[a0, a1)`` of one cell (positions in the sorted order) and its half stencil of
neighbour cells (those after it in lexicographic offset order), so that every unordered pair
within the cutoff is met exactly once.

Kernels (``cache=True``, ``nogil=True``: threads over work items run in parallel)
-------
``gather_pairs(items, S, start, count, nbr, r2, oi, oj, oq)``
    The pairs ``(i, j)`` (sorted positions, ``i < j`` within a cell) of the items with
    ``|sᵢ − sⱼ|² < r2`` and their squared distances, written to ``oi, oj, oq``; returns
    their number. Twin: :func:`gather_pairs_numpy`.
``scatter_pairs(oi, oj, phi, m, Z, A)``
    ``A[i] += φ Z[j]`` and ``A[j] += φ Z[i]`` for the first ``m`` pairs (each unordered
    pair's kernel value used in both orientations). Twin: :func:`scatter_pairs_numpy`.
``pairs_fused(items, S, start, count, nbr, r2, kind, p, sp, tab, Z, A)``
    The three steps in one pass (buffers of one neighbour block only), for kernels with a
    closed form (``kind``: Morse ``p = (Cₐ, ℓₐ, C_r, ℓ_r, soft)``, Cucker–Smale
    ``p = (G, β)``), optionally the near part of a NUFFT split (``sp = (1, a, mid, σ, φ(a))``,
    see ``kinred.pairsum._nearfield``), or for any kernel tabulated (``KIND_TABLE``, the
    table ``tab`` of :mod:`kinred.pairsum._table`; a split's near part at about 4 ns a value
    instead of 50). Per row and neighbour block, a branch-light distance
    loop collects the pairs within the cutoff, one tight loop per kind evaluates the kernel
    on them (reciprocals hoisted), then they are accumulated: ``A[j] += φ zᵢ`` pair by pair,
    row ``i``'s own sum in scalars over all its blocks and added once (unrolled for
    ``d + 1 = 3, 4``; the twin's sums up to the order of the additions, 1e-12 in the tests).
    Measured on the 2-D ring of radius 20, N = 2·10⁴, cutoff 1.8, one thread, idle machine:
    Morse 53 → 22 ns per pair within the cutoff, the near part of a split 64–74 → 56 ns (its
    ``erfc`` takes about 19 ns). By its table, on the ring of radius 5 (N = 2·10⁴, ε_I = 0.94,
    1.18·10⁷ pairs, 2.5·10⁷ candidates, one thread): 101 → 80 ms with the row sum in scalars,
    of which the candidates take 22 ms, the table 35 ms (3 ns a pair: square root, lookup,
    Horner) and the accumulation 19 ms. In 3-D (soft Morse, N = 3·10⁴ in 6 × 6 × 2, cutoff
    0.8, 1.03·10⁷ pairs, one thread): 232 → 212 ms. Twin: :func:`gather_pairs` + the kernel's numpy ``value_sq`` +
    :func:`scatter_pairs` (the cell list's general path).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["gather_pairs", "gather_pairs_numpy", "scatter_pairs", "scatter_pairs_numpy",
           "pairs_fused", "KIND_MORSE", "KIND_CS"]

_FM = {"reassoc", "contract"}


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def gather_pairs(items, S, start, count, nbr, r2, oi, oj, oq):  # pragma: no cover - compiled
    k = S.shape[1]
    nh = nbr.shape[1]
    m = 0
    for it in range(items.shape[0]):
        cell, a0, a1 = items[it, 0], items[it, 1], items[it, 2]
        s0 = start[cell]
        e0 = s0 + count[cell]
        for i in range(s0 + a0, s0 + a1):
            m = _gather_row(S, i, i + 1, e0, k, r2, oi, oj, oq, m)
            for h in range(nh):
                b = nbr[cell, h]
                if b >= 0:
                    m = _gather_row(S, i, start[b], start[b] + count[b], k, r2, oi, oj, oq, m)
    return m


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy",
      inline="always")
def _gather_row(S, i, j0, j1, k, r2, oi, oj, oq, m):  # pragma: no cover - compiled
    """The pairs ``(i, j)``, ``j0 ≤ j < j1``, within ``r2``, appended from slot ``m``."""
    for j in range(j0, j1):
        q = 0.0
        for l in range(k):
            t = S[i, l] - S[j, l]
            q += t * t
        if q < r2:
            oi[m] = i
            oj[m] = j
            oq[m] = q
            m += 1
    return m


def gather_pairs_numpy(items, S, start, count, nbr, r2, oi, oj, oq) -> int:
    """Twin of :func:`gather_pairs` (numpy, item by item; same pairs in the same order)."""
    m = 0
    for cell, a0, a1 in np.asarray(items):
        s0, e0 = start[cell], start[cell] + count[cell]
        blocks = [nbr[cell, h] for h in range(nbr.shape[1]) if nbr[cell, h] >= 0]
        for i in range(s0 + a0, s0 + a1):
            js = np.concatenate([np.arange(i + 1, e0)]
                                + [np.arange(start[b], start[b] + count[b]) for b in blocks])
            q = np.sum((S[i] - S[js]) ** 2, axis=1)
            keep = q < r2
            c = int(keep.sum())
            oi[m:m + c] = i
            oj[m:m + c] = js[keep]
            oq[m:m + c] = q[keep]
            m += c
    return m


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def scatter_pairs(oi, oj, phi, m, Z, A):  # pragma: no cover - compiled
    d1 = Z.shape[1]
    for p in range(m):
        i, j, f = oi[p], oj[p], phi[p]
        for l in range(d1):
            A[i, l] += f * Z[j, l]
            A[j, l] += f * Z[i, l]
    return A


def scatter_pairs_numpy(oi, oj, phi, m, Z, A):
    """Twin of :func:`scatter_pairs` (``np.add.at``)."""
    i, j, f = oi[:m], oj[:m], phi[:m, None]
    np.add.at(A, i, f * Z[j])
    np.add.at(A, j, f * Z[i])
    return A


#: Kernel kinds of :func:`pairs_fused` (``kinred.pairsum._base.pair_form``), and a
#: tabulated kernel (:mod:`kinred.pairsum._table`: ``p = (m/R, singular, φ(0))``, ``tab``).
KIND_MORSE = 1
KIND_CS = 2
KIND_TABLE = 3


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def _values(kind, p, sp, tab, bq, bf, c):  # pragma: no cover - compiled
    """``bf[t] = φ(√bq[t])`` (the near part of a split when ``sp[0] > 0``) for ``t < c``:
    one tight loop per kind, reciprocals hoisted (one division a pair, not five); a table
    (``KIND_TABLE``) holds the whole function, split or not."""
    if kind == KIND_TABLE:
        inv_h, singular, at0 = p[0], p[1] > 0.0, p[2]
        last = tab.shape[0] - 1
        for t in range(c):
            s = math.sqrt(bq[t])
            u = s * inv_h
            i = min(int(u), last)
            w = u - i
            val = ((tab[i, 3] * w + tab[i, 2]) * w + tab[i, 1]) * w + tab[i, 0]
            if s > 0.0:
                bf[t] = val / s if singular else val
            else:
                bf[t] = at0
        return
    if kind == KIND_MORSE:
        ia, ir, s2 = 1.0 / p[1], 1.0 / p[3], p[4] * p[4]
        ca, cr = p[0] * ia, p[2] * ir
        for t in range(c):
            r = math.sqrt(bq[t] + s2)
            f = ca * math.exp(-r * ia) - cr * math.exp(-r * ir)
            bf[t] = f / r if r > 0.0 else 0.0
    else:
        for t in range(c):
            bf[t] = p[0] * math.exp(-p[1] * math.log1p(bq[t]))
    if sp[0] > 0.0:             # the near part of a split: φ − φ_F
        a, mid, isig, pa = sp[1], sp[2], 1.0 / sp[3], sp[4]
        for t in range(c):
            s = math.sqrt(bq[t])
            g = 0.5 * math.erfc((mid - s) * isig)
            bf[t] = bf[t] * (1.0 - g) if s >= a else bf[t] - g * pa


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def pairs_fused(items, S, start, count, nbr, r2, kind, p, sp, tab, Z, A):  # pragma: no cover
    k = S.shape[1]
    nh = nbr.shape[1]
    d1 = Z.shape[1]
    big = 1
    for c in range(count.shape[0]):
        big = max(big, count[c])
    bj = np.empty(big, dtype=np.int64)      # one block's pairs within the cutoff
    bq = np.empty(big)
    bf = np.empty(big)
    zi = np.empty(d1)
    ai = np.zeros(d1)
    si = np.empty(k)
    m = 0
    for it in range(items.shape[0]):
        cell, a0, a1 = items[it, 0], items[it, 1], items[it, 2]
        s0 = start[cell]
        e0 = s0 + count[cell]
        for i in range(s0 + a0, s0 + a1):
            for l in range(d1):
                zi[l] = Z[i, l]
            for l in range(k):
                si[l] = S[i, l]
            for h in range(-1, nh):
                if h < 0:
                    j0, j1 = i + 1, e0
                else:
                    b = nbr[cell, h]
                    if b < 0:
                        continue
                    j0, j1 = start[b], start[b] + count[b]
                c = _block(S, si, j0, j1, k, r2, bj, bq)
                _values(kind, p, sp, tab, bq, bf, c)  # the kernel only on the pairs within r2
                _scatter_block(A, Z, bj, bf, c, zi, ai)
                m += c
            for l in range(d1):          # row i's own sum, kept in registers over its blocks
                A[i, l] += ai[l]
                ai[l] = 0.0
    return m


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy",
      inline="always")
def _scatter_block(A, Z, bj, bf, c, zi, ai):  # pragma: no cover - compiled
    """``ai += Σₜ fₜ Z[jₜ]`` and ``A[jₜ] += fₜ zi`` over one block's ``c`` pairs: unrolled
    for ``d + 1 = 3`` and ``4`` (2-D and 3-D carriers), row ``i``'s sum in scalars."""
    d1 = Z.shape[1]
    if d1 == 3 or d1 == 4:
        four = d1 == 4                   # loop-invariant: the compiler unswitches it
        z0, z1, z2, z3 = zi[0], zi[1], zi[2], zi[d1 - 1]
        s0 = s1 = s2 = s3 = 0.0
        for t in range(c):
            j = bj[t]
            f = bf[t]
            s0 += f * Z[j, 0]
            s1 += f * Z[j, 1]
            s2 += f * Z[j, 2]
            A[j, 0] += f * z0
            A[j, 1] += f * z1
            A[j, 2] += f * z2
            if four:
                s3 += f * Z[j, 3]
                A[j, 3] += f * z3
        ai[0] += s0
        ai[1] += s1
        ai[2] += s2
        if four:
            ai[3] += s3
    else:
        for t in range(c):
            j = bj[t]
            f = bf[t]
            for l in range(d1):
                ai[l] += f * Z[j, l]
                A[j, l] += f * zi[l]


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy",
      inline="always")
def _block(S, si, j0, j1, k, r2, bj, bq):  # pragma: no cover - compiled
    """The points ``j0 ≤ j < j1`` within ``r2`` of ``si`` into ``bj, bq`` (a branch-light
    distance loop, unrolled for ``k ≤ 3``); returns their number."""
    c = 0
    if k == 2:
        x0, x1 = si[0], si[1]
        for j in range(j0, j1):
            t0 = S[j, 0] - x0
            t1 = S[j, 1] - x1
            q = t0 * t0 + t1 * t1
            bj[c] = j
            bq[c] = q
            c += q < r2
    elif k == 3:
        x0, x1, x2 = si[0], si[1], si[2]
        for j in range(j0, j1):
            t0 = S[j, 0] - x0
            t1 = S[j, 1] - x1
            t2 = S[j, 2] - x2
            q = t0 * t0 + t1 * t1 + t2 * t2
            bj[c] = j
            bq[c] = q
            c += q < r2
    else:
        for j in range(j0, j1):
            q = 0.0
            for l in range(k):
                t = S[j, l] - si[l]
                q += t * t
            bj[c] = j
            bq[c] = q
            c += q < r2
    return c
