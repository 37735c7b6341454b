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

Flags as in :mod:`kinred.pairsum._kernels`: ``cache=True``, ``nogil=True``, fastmath limited
to re-association and contraction (NaN and Inf propagate).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["batch_sqdist", "batch_accumulate", "pairs_in", "batch_pairs_numpy",
           "batch_field_numpy"]

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
