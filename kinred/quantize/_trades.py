"""Local improvement of integer budgets: the trades between coordinates, filtered with numpy.

Private to :mod:`kinred.quantize._budget` (the loops over pairs of its local searches, which
are O(d²) Python steps, with the same results: see tests/test_budget_search.py).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

#: Counts above which a ±1 change of N_j is not resolved by a float sum (no unit trades there).
_UNIT_STEP = 2**30


def _ratio(x: float, n: int) -> float:
    """``x / n`` for an integer ``n`` of any size (float division overflows past 1e308)."""
    return x / n if n.bit_length() < 1000 else float(Fraction(x) / n)


def _pairs(N):
    act = [i for i in range(len(N)) if N[i] > 1]
    nxt = next((i for i in range(len(N)) if N[i] == 1), None)
    return act, act + ([nxt] if nxt is not None else [])


def _trades_eps(s, N, tot, lim, moves, max_moves):
    """Unit trades (N_i − 1, N_j + 1) with N_i ≤ N_j that keep the bound ≤ ``lim``, in place.

    For each i (in index order) the trades go to the first j, in index order, with a feasible
    one; the feasibility of every j is evaluated at once with numpy in the scalar formula's
    order of operations (IEEE: the same floats as the loop over pairs, which is O(d²)
    Python steps). Returns (bound, moves, whether anything traded).
    """
    act = [i for i in range(len(N)) if 1 < N[i] <= _UNIT_STEP]
    if len(act) < 2:
        return tot, moves, False
    sa = np.array([s[i] for i in act])
    na = np.array([float(N[i]) for i in act])  # exact: N_j ≤ 2**30 + max_moves
    traded = False
    for a, i in enumerate(act):
        p = 0  # next position in act to try
        while moves < max_moves and N[i] > 1 and p < len(act):
            base = tot - s[i] / N[i] + s[i] / (N[i] - 1)
            new = base - sa[p:] / na[p:] + sa[p:] / (na[p:] + 1)
            ok = (na[p:] >= N[i]) & (new <= lim)
            if a >= p:
                ok[a - p] = False
            hits = np.flatnonzero(ok)
            if hits.size == 0:
                break
            b = p + int(hits[0])
            tot = float(new[hits[0]])
            N[i] -= 1
            N[act[b]] += 1
            na[a] -= 1.0
            na[b] += 1.0
            moves += 1
            traded = True
            p = b + 1
    return tot, moves, traded


def _trades_atoms(s, N, P, prod, moves, max_moves):
    """Pair trades (N_i − 1, N_j + 1) and (⌊N_i/2⌋, 2N_j) that lower the bound with ∏ ≤ P, in place.

    The loop over pairs (i, j) tests each pair exactly as before, but for each i numpy first
    rules out, at once, every j whose trades cannot gain 1e-15 or cannot keep ∏ ≤ P (in
    floats, with margins far above their rounding: 1e-14 of the terms, 1e-9 in the log of
    the product); the j left are tested in order, and after a trade the filter is redone. Returns (∏ N, moves, whether anything traded).
    """
    act, targets = _pairs(N)
    if not act:
        return prod, moves, False
    st = np.array([s[j] for j in targets])
    nt = np.array([_as_float(N[j]) for j in targets])
    pos = {j: b for b, j in enumerate(targets)}
    traded = False
    for i in act:
        p = 0
        while p < len(targets) and moves < max_moves and N[i] >= 2:
            room = math.log(P) - math.log(prod) + 1e-9  # log of the product's headroom
            cand = _may_gain(s[i], N[i], st[p:], nt[p:], room)
            if i in pos and pos[i] >= p:
                cand[pos[i] - p] = False
            for b in (p + np.flatnonzero(cand)).tolist():  # the survivors, tested exactly
                done = _trade_pair(s, N, P, i, targets[b], prod, moves, max_moves)
                if done is not None:
                    prod, moves = done
                    traded = True
                    nt[b] = _as_float(N[targets[b]])
                    if i in pos:
                        nt[pos[i]] = _as_float(N[i])
                    p = b + 1  # N_i and ∏ changed: filter again after b
                    break
            else:
                break
    return prod, moves, traded


def _trade_pair(s, N, P, i, j, prod, moves, max_moves):
    """The loop's exact test of pair (i, j), in place: (∏, moves) if it traded, else None."""
    start = moves
    for di, dj in ((N[i] - 1, N[j] + 1), (N[i] // 2, N[j] * 2)):
        if di < 1 or moves >= max_moves:
            continue
        p2 = prod // (N[i] * N[j]) * di * dj
        old = _ratio(s[i], N[i]) + _ratio(s[j], N[j])
        if p2 <= P and _ratio(s[i], di) + _ratio(s[j], dj) < old - 1e-15:
            N[i], N[j], prod = di, dj, p2
            moves += 1
    return (prod, moves) if moves > start else None


def _as_float(n: int) -> float:
    """``float(n)``, or inf beyond 2**1000 (where ``s/n`` is 0 at the 1e-15 scale of a gain)."""
    return float(n) if n.bit_length() < 1000 else math.inf


def _may_gain(si, ni: int, sj, nj, room):
    """Mask of the j whose trade (ni − 1, nj + 1) or (⌊ni/2⌋, 2nj) may lower the bound by 1e-15
    and may keep the log of the product within ``room`` (both with margins over rounding).
    ``ni`` is an int of any size, ``nj`` floats (inf for the huge ones)."""
    out = np.zeros(sj.shape, dtype=bool)
    c, d = _ratio(si, ni), sj / nj
    with np.errstate(divide="ignore"):
        grow_j = (np.log1p(1.0 / nj), math.log(2.0))
    for k, di in enumerate((ni - 1, ni // 2)):
        a, b = _ratio(si, di), sj / (nj + 1.0 if k == 0 else 2.0 * nj)
        grow = math.log(di) - math.log(ni) + grow_j[k]
        out |= ((a - c) + (b - d) < -1e-15 + 1e-14 * (a + b + c + d)) & (grow <= room)
    return out
