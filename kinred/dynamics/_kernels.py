"""Private numba kernels of the pairwise engine, each with a plain-numpy twin.

Only this module imports numba. Every kernel is compiled with ``cache=True`` and
``nogil=True`` (so that Python threads over row strips run in parallel) and uses fastmath
flags that only allow re-association and contraction of sums (``{"reassoc", "contract"}``):
NaN and Inf propagate exactly as in IEEE arithmetic, so divergence stays detectable.

Kernels
-------
``sqdist_gram_fix(G, ni, nj, Yi, Yj, tau)``
    Turns a Gram block ``G = Yi @ Yj.T`` into squared distances
    ``‖yᵢ‖² + ‖yⱼ‖² − 2⟨yᵢ, yⱼ⟩`` in place and recomputes by differences every entry whose
    value is below ``tau·(‖yᵢ‖² + ‖yⱼ‖²)``. Twin: :func:`sqdist_numpy` (pure differences).
``cs_halfint(Q, G, n2, out)``
    Cucker–Smale kernel ``G (1 + q)^(−n2/2)`` for integer ``n2`` with sqrt and division only
    (vectorizable without SVML). Twin: :func:`cs_numpy` (``G·exp(−β·log1p(q))``).

Accuracy of the Gram path
-------------------------
With ``γ = (k+2)u`` (``u`` the unit round-off) the computed value ``q̂`` of
``q = ‖yᵢ − yⱼ‖²`` satisfies ``|q̂ − q| ≤ 2γ (‖yᵢ‖² + ‖yⱼ‖²)``. Entries kept from the Gram
formula have ``q̂ > τ (‖yᵢ‖² + ‖yⱼ‖²)``, hence a relative error at most ``2γ/(τ − 2γ)``:
with ``τ = 2.5e-4 (k+2)`` (:func:`tau_for`) that is below ``1e-12`` for every ``k``; all other
entries (close or coincident pairs) are recomputed by differences, with relative error
``O(k u)``.
"""

from __future__ import annotations

import collections

import numpy as np
from numba import njit

__all__ = [
    "COUNTERS",
    "tau_for",
    "sqdist_gram_fix",
    "sqdist_block",
    "sqdist_numpy",
    "cs_halfint",
    "cs_numpy",
]

#: Instrumentation: how many row strips of pairwise squared distances were computed per
#: source (``"x"`` or ``"v"``). Tests use it to prove that a scene computes only what its
#: effects need.
COUNTERS: collections.Counter = collections.Counter()


_FM = {"reassoc", "contract"}


@njit(cache=True, nogil=True, fastmath=_FM)
def sqdist_gram_fix(G, ni, nj, Yi, Yj, tau):  # pragma: no cover - compiled
    b, m = G.shape
    k = Yi.shape[1]
    nfix = 0
    for a in range(b):
        na = ni[a]
        row = G[a]
        for j in range(m):
            row[j] = na + nj[j] - 2.0 * row[j]
        for c0 in range(0, m, 64):
            c1 = min(m, c0 + 64)
            cnt = 0
            for j in range(c0, c1):
                cnt += 1 if row[j] <= tau * (na + nj[j]) else 0
            if cnt > 0:
                for j in range(c0, c1):
                    if row[j] <= tau * (na + nj[j]):
                        s = 0.0
                        for l in range(k):
                            t = Yi[a, l] - Yj[j, l]
                            s += t * t
                        row[j] = s
                        nfix += 1
    return nfix


def tau_for(k: int) -> float:
    """Fix-up threshold for dimension ``k``: ``2.5e-4·(k+2)`` (capped at 1/8), so that kept
    Gram entries have relative error ≤ ``2(k+2)u/τ < 1e-12``."""
    return min(0.125, 2.5e-4 * (k + 2))


def sqdist_block(Yi: np.ndarray, Yj: np.ndarray, ni: np.ndarray, nj: np.ndarray,
                 out: np.ndarray, Xi: np.ndarray | None = None,
                 Xj: np.ndarray | None = None) -> np.ndarray:
    """Squared distances between the rows of ``Yi (b, k)`` and ``Yj (m, k)`` into ``out (b, m)``.

    ``Yi``/``Yj`` are centred coordinates, ``ni``/``nj`` their squared row norms. BLAS Gram
    product plus the numba fix-up kernel, which recomputes close pairs by differences of the
    raw (uncentred) rows ``Xi``/``Xj`` (default: ``Yi``/``Yj``) – differences of the inputs
    are exact to rounding, whereas centring a far-away cloud rounds at its distance scale.
    """
    np.matmul(Yi, Yj.T, out=out)
    sqdist_gram_fix(out, ni, nj, Yi if Xi is None else Xi, Yj if Xj is None else Xj,
                    tau_for(Yi.shape[1]))
    return out


def sqdist_numpy(Yi: np.ndarray, Yj: np.ndarray) -> np.ndarray:
    """Twin of :func:`sqdist_block`: ``Σₗ (Yi[a, l] − Yj[j, l])²`` by differences (b, m)."""
    Yi = np.asarray(Yi, dtype=float)
    Yj = np.asarray(Yj, dtype=float)
    out = np.empty((Yi.shape[0], Yj.shape[0]))
    step = max(1, 2_000_000 // max(1, Yj.shape[0] * Yi.shape[1]))
    for a in range(0, Yi.shape[0], step):
        diff = Yi[a:a + step, None, :] - Yj[None, :, :]
        out[a:a + step] = np.einsum("ijk,ijk->ij", diff, diff)
    return out


@njit(cache=True, nogil=True, fastmath=_FM)
def cs_halfint(Q, G, n2, out):  # pragma: no cover - compiled
    b, m = Q.shape
    half = n2 // 2
    odd = n2 % 2
    for a in range(b):
        q = Q[a]
        o = out[a]
        if odd:
            for j in range(m):
                o[j] = np.sqrt(1.0 + q[j])
        else:
            for j in range(m):
                o[j] = 1.0
        for _ in range(half):
            for j in range(m):
                o[j] *= 1.0 + q[j]
        for j in range(m):
            o[j] = G / o[j]
    return out


def cs_numpy(Q: np.ndarray, G: float, beta: float) -> np.ndarray:
    """Twin of :func:`cs_halfint`: ``G·exp(−β·log1p(q))`` with ``β = n2/2``."""
    return G * np.exp(-beta * np.log1p(np.asarray(Q, dtype=float)))
