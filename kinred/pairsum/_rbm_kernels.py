r"""Private numba kernels of the random batch backend, each with a plain-numpy twin.

The agents ``perm[b·p : (b+1)·p]`` form batch ``b`` (the last batch holds the ``N mod p``
remaining agents when ``p ∤ N``). The kernels walk a range of batches ``[b0, b1)`` and, in
each batch, its unordered pairs in the fixed order ``(a, a′)`` with ``a < a′`` (positions in
the batch): pair ``k`` of the range is the ``k``-th pair in that order. Every kernel writes
only rows of the agents of its own batches, so ranges of batches can run in parallel threads
(``nogil=True``) and each agent's sums are accumulated in the same order whatever the threads.

Kernels
-------
``batch_sqdist(S, perm, p, b0, b1, out)``
    Squared distances ``‖sᵢ − sⱼ‖²`` of the pairs of batches ``[b0, b1)``, by differences,
    into ``out[:m]``. Twin: :func:`batch_pairs_numpy` and plain numpy.
``batch_accumulate(Z, cs, perm, p, b0, b1, phi, out, clear)``
    ``outᵢ += csⱼ φₖ (zⱼ − zᵢ)`` and ``outⱼ += csᵢ φₖ (zᵢ − zⱼ)`` for every pair ``k = (i, j)``
    of the range: the difference of the carriers is taken directly (no centring needed: its
    relative accuracy does not depend on where the cloud sits). With ``clear`` the rows of a
    batch are first set to 0 (the first term of a target: the result arrays need no clearing
    pass of their own, and the rows are cleared while in cache). Twin:
    :func:`batch_field_numpy`.
``batch_euler(X, V, order, cs, perm, p, b0, b1, phis, carriers, targets, h, locx, nlx, locv,
nlv, px, pv, w, shift, c, r, acc)``
    Forward Euler's step (eq. (1.6)) of the batches ``[b0, b1)``, in place, batch by batch:
    the batch's pair sums of every term (``phis[t]``, carrier ``carriers[t]`` and target
    ``targets[t]``, 0 for ``x`` and 1 for ``v``, accumulated as :func:`batch_accumulate`
    does, in the same order) into a ``(2, p, d)`` scratch, then the update of the batch's rows
    (:func:`_batch_apply`: ``x ← x + h·(v + Fₓ + locₓ)`` for ``order = 2``, ``x + h·(Fₓ +
    locₓ)`` for 1, ``v ← v + h·(F_v + loc_v)``, the local drifts being the first ``nlx``
    (``nlv``) arrays of the tuple ``locx`` (``locv``) added one after the other; ``px``,
    ``pv`` say whether a pair term targets ``x``, ``v``), then the row sums of the new rows
    (:func:`kinred._rowsum_kernels.row_sums` of ``x + shift[0]`` and ``v + shift[1]`` about
    ``c``) into ``r, acc``. A batch's rows are read and written only by that batch, so the
    in-place update equals the update from a whole right-hand side: the new state is
    bit-identical to :func:`batch_accumulate` followed by ``simulate``'s Euler update (the
    update runs without fastmath: a rounded product and a rounded sum, numpy's), and the
    state is read and written once per step. Twin: :func:`batch_euler_numpy`.

Flags as in :mod:`kinred.pairsum._kernels`: ``cache=True``, ``nogil=True``, fastmath limited
to re-association and contraction (NaN and Inf propagate).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .._rowsum_kernels import BLOCK, flush, row_sums

__all__ = ["batch_sqdist", "batch_accumulate", "batch_euler", "pairs_in", "batch_pairs_numpy",
           "batch_field_numpy", "batch_euler_numpy"]

_FM = {"reassoc", "contract"}


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def batch_sqdist(S, perm, p, b0, b1, out):  # pragma: no cover - compiled
    n, d = S.shape
    k = 0
    for b in range(b0, b1):
        s0 = b * p
        s1 = min(s0 + p, n)
        for a in range(s0, s1):
            i = perm[a]
            for a2 in range(a + 1, s1):
                j = perm[a2]
                acc = 0.0
                for l in range(d):
                    t = S[i, l] - S[j, l]
                    acc += t * t
                out[k] = acc
                k += 1
    return k


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def batch_accumulate(Z, cs, perm, p, b0, b1, phi, out, clear):  # pragma: no cover - compiled
    n, d = Z.shape
    k = 0
    for b in range(b0, b1):
        s0 = b * p
        s1 = min(s0 + p, n)
        if clear:
            for a in range(s0, s1):
                i = perm[a]
                for l in range(d):
                    out[i, l] = 0.0
        for a in range(s0, s1):
            i = perm[a]
            for a2 in range(a + 1, s1):
                j = perm[a2]
                f = phi[k]
                fi = cs[j] * f
                fj = cs[i] * f
                for l in range(d):
                    t = Z[j, l] - Z[i, l]
                    out[i, l] += fi * t
                    out[j, l] -= fj * t
                k += 1
    return k


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def _batch_terms(X, V, cs, perm, s0, s1, phis, k0, carriers, targets, F):  # pragma: no cover
    """The pair sums of one batch (rows ``perm[s0:s1]``) of every term into ``F[target, a]``
    (``a``: position in the batch); pairs from ``k0`` on in each ``phis[t]``. Returns the
    next batch's first pair."""
    d = X.shape[1]
    sz = s1 - s0
    for g in range(2):
        for a in range(sz):
            for l in range(d):
                F[g, a, l] = 0.0
    k = k0
    for t in range(phis.shape[0]):
        Z = X if carriers[t] == 0 else V
        g = targets[t]
        k = k0
        for a in range(sz):
            i = perm[s0 + a]
            for a2 in range(a + 1, sz):
                j = perm[s0 + a2]
                f = phis[t, k]
                fi = cs[j] * f
                fj = cs[i] * f
                for l in range(d):
                    u = Z[j, l] - Z[i, l]
                    F[g, a, l] += fi * u
                    F[g, a2, l] -= fj * u
                k += 1
    return k


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _add_locals(f, locs, nl, i, has_pair):  # pragma: no cover - compiled
    """``f ← f + loc₁ᵢ + loc₂ᵢ + …`` in order (``f ← loc₁ᵢ + …`` without a pair term):
    numpy's ``dv += loc`` of the scene's local effects, one after the other."""
    d = f.shape[0]
    for q in range(nl):
        li = locs[q][i]
        if q == 0 and not has_pair:
            for l in range(d):
                f[l] = li[l]
        else:
            for l in range(d):
                f[l] = f[l] + li[l]


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _batch_apply(X, V, order, F, h, locx, nlx, locv, nlv, px, pv, perm, s0,
                 s1):  # pragma: no cover - compiled
    """Euler's update of one batch's rows from its sums ``F`` and the local drifts (no
    fastmath: numpy's rounding of ``dx = v + Fₓ + locₓ…`` and of ``x + dx·h``). ``F`` is
    overwritten with the drift."""
    d = X.shape[1]
    for a in range(s1 - s0):
        i = perm[s0 + a]
        fx = F[0, a]
        fv = F[1, a]
        x = X[i]
        _add_locals(fx, locx, nlx, i, px)
        hx = px or nlx > 0
        if order == 2:
            v = V[i]
            if hx:
                for l in range(d):
                    fx[l] = v[l] + fx[l]
                for l in range(d):
                    x[l] = x[l] + fx[l] * h
            else:
                for l in range(d):
                    x[l] = x[l] + v[l] * h
            _add_locals(fv, locv, nlv, i, pv)
            if pv or nlv > 0:
                for l in range(d):
                    v[l] = v[l] + fv[l] * h
            else:
                for l in range(d):
                    v[l] = v[l] + 0.0 * h
        elif hx:
            for l in range(d):
                x[l] = x[l] + fx[l] * h
        else:
            for l in range(d):
                x[l] = x[l] + 0.0 * h


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def batch_euler(X, V, order, cs, perm, p, b0, b1, phis, carriers, targets, h, locx, nlx,
                locv, nlv, px, pv, w, shift, c, r, acc):  # pragma: no cover - compiled
    """The module's ``batch_euler``: returns the number of pairs visited."""
    n, d = X.shape
    kk = 2 if order == 2 else 1
    F = np.empty((2, p, d))
    blk = np.zeros((2, d))
    part = np.zeros((2, 4))
    for g in range(kk):
        for l in range(d):
            r[g, l] = 0.0
        for m in range(4):
            acc[g, m] = 0.0
    k = 0
    rows = 0
    for b in range(b0, b1):
        s0 = b * p
        s1 = min(s0 + p, n)
        k = _batch_terms(X, V, cs, perm, s0, s1, phis, k, carriers, targets, F)
        _batch_apply(X, V, order, F, h, locx, nlx, locv, nlv, px, pv, perm, s0, s1)
        for a in range(s0, s1):
            i = perm[a]
            row_sums(X, i, 0, w[i], shift, c, blk, part)
            if kk == 2:
                row_sums(V, i, 1, w[i], shift, c, blk, part)
            rows += 1
            if rows % BLOCK == 0:
                for g in range(kk):
                    flush(g, blk, part, r, acc)
    for g in range(kk):
        flush(g, blk, part, r, acc)
    return k


def pairs_in(n: int, p: int, b0: int, b1: int) -> int:
    """Number of within-batch pairs of batches ``[b0, b1)`` (``N = n`` agents, batches of ``p``,
    the last one of ``n mod p`` agents when ``p`` does not divide ``n``)."""
    nb, r = divmod(n, p)
    m = max(0, min(b1, nb) - b0) * (p * (p - 1) // 2)
    if r and b0 <= nb < b1:
        m += r * (r - 1) // 2
    return m


def batch_pairs_numpy(perm: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Twin: the pairs ``(i, j)`` of all batches of ``perm``, in the kernels' order."""
    n = perm.shape[0]
    nb, r = divmod(n, p)
    out_i, out_j = [], []
    for rows, size in ((perm[: nb * p].reshape(nb, p), p), (perm[nb * p:].reshape(1, r), r)):
        if size < 2 or rows.shape[0] == 0:
            continue
        ia, ib = np.triu_indices(size, k=1)
        out_i.append(rows[:, ia].ravel())
        out_j.append(rows[:, ib].ravel())
    if not out_i:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    return np.concatenate(out_i), np.concatenate(out_j)


def batch_field_numpy(S: np.ndarray, Z: np.ndarray, cs: np.ndarray, perm: np.ndarray, p: int,
                      kernel) -> np.ndarray:
    """Twin of one term: ``Σ_{j ∈ batch(i)} csⱼ φ(‖sᵢ − sⱼ‖)(zⱼ − zᵢ)`` with ``φ = kernel``."""
    i, j = batch_pairs_numpy(perm, p)
    phi = np.asarray(kernel(np.sqrt(np.sum((S[i] - S[j]) ** 2, axis=1))), dtype=float)
    diff = Z[j] - Z[i]
    out = np.zeros_like(Z, dtype=float)
    np.add.at(out, i, (cs[j] * phi)[:, None] * diff)
    np.add.at(out, j, -(cs[i] * phi)[:, None] * diff)
    return out


def batch_euler_numpy(x, v, cs, perm, p, terms, h, locx=(), locv=()):
    """Twin of :func:`batch_euler`'s state update: ``terms`` is a list of
    ``(kernel, source, carrier, target)`` (names ``"x"``/``"v"``), each summed by
    :func:`batch_field_numpy`; then ``x ← x + h·(v + Fₓ + Σ locₓ)`` (order 2, ``v`` given) or
    ``x + h·(Fₓ + Σ locₓ)``, ``v ← v + h·(F_v + Σ loc_v)`` (``locx``, ``locv``: sequences of
    local drifts), as new arrays."""
    state = {"x": x, "v": v}
    sums = {"x": np.zeros_like(x), "v": None if v is None else np.zeros_like(v)}
    for kernel, source, carrier, target in terms:
        sums[target] += batch_field_numpy(state[source], state[carrier], cs, perm, p, kernel)
    fx = sums["x"] + sum(locx, np.zeros_like(x))
    if v is None:
        return x + fx * h, None
    fv = sums["v"] + sum(locv, np.zeros_like(v))
    return x + (v + fx) * h, v + fv * h
