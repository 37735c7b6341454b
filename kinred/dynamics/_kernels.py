"""Private numba kernels of the pairwise engine, each with a plain-numpy twin.

Only this module imports numba. Every kernel is compiled with ``cache=True`` and
``nogil=True`` (so that Python threads over row strips run in parallel) and uses fastmath
flags that only allow re-association and contraction of sums (``{"reassoc", "contract"}``):
NaN and Inf propagate exactly as in IEEE arithmetic, so divergence stays detectable.

Kernels
-------
``sqdist_gram_fix(G, ni, nj, Yi, Yj, tau, diag)``
    Turns a block ``G = −2 Yi Yjᵀ`` (written by BLAS) into squared distances
    ``‖yᵢ‖² + ‖yⱼ‖² − 2⟨yᵢ, yⱼ⟩`` in place in one branch-free (vectorizable) pass that also
    counts the entries below ``tau·(‖yᵢ‖² + ‖yⱼ‖²)``; only rows with such entries get a second
    pass that recomputes them by differences. Twin: :func:`sqdist_numpy` (pure differences).
``sqdist_diff(YT, i0, i1, j0, out)``
    Squared distances by differences from transposed coordinates ``YT (k, N)``, vectorized
    over columns (the engine's path for ``k ≤ 3``). Twin: :func:`sqdist_numpy`.
``cs_halfint(Q, G, n2, out)``
    Cucker–Smale kernel ``G (1 + q)^(−n2/2)`` for integer ``n2`` with sqrt and division only
    (``out`` may be ``Q``: a separate in-place kernel, since LLVM vectorizes a loop over two
    arrays only after a runtime no-overlap check, and exact aliasing fails it: measured 3.7
    vs 0.87 ns per entry). Twin: :func:`cs_numpy` (``G·exp(−β·log1p(q))``).

Performance notes (Xeon with AVX-512, then AMD EPYC Zen 4; no SVML in numba): numba's
scalar ``exp``/``log1p`` cost 11–20 ns per entry, numpy's SIMD ufuncs ≈ 1 ns each (the chain
``G·exp(−β·log1p(q))`` ≈ 2.2–3 ns per entry; ``G·exp2(−β·log2(1+q))`` costs the same in
float64 and 1.4× less in float32, where the engine uses it), square roots and
divisions ≈ 1 ns even vectorized; kernels therefore evaluate transcendentals with numpy ufuncs on the engine's
cache-sized blocks and numba does only cheap arithmetic (``cs_halfint`` for ``2β ≤ 5``:
0.87 ns per entry). A branch-free polynomial ``exp(−β log(1+q))`` in numba (bit casts,
degree-11 ``atanh`` series and degree-13 Taylor, relative error ≤ 3e-16·(1 + β log(1+q)))
vectorizes to 512-bit code on Zen 4 but is compute-bound at 2.6 ns per entry – no faster
than the ufunc chain (measured twice, on both machines) – and was not kept.

A fused compiled loop for small dimensions (distances by differences, kernel and both
orientations of the pair sum per row, no BLAS and no Python per strip) was measured at
k = 10 and not kept: distances 1.3 ns and the two sums 2.3 ns per pair, i.e. no faster than
the BLAS products it would replace (the engine's k = 10 step is ≈ 3.9 ns per pair in all).

A dense variant of the d = 200 step (one threaded ``syrk`` for the whole Gram matrix, the
kernel on N × N, one threaded ``gemm``) was measured against the strips at N = 1000 with 1
and 2 threads: no faster on this machine (10.4–13 ms per step either way, within the noise),
and it needs O(N²) memory; not kept.

A loop that reads one array and writes another vectorizes only behind a runtime no-overlap
check, which fails when the two are the same array: in-place calls therefore go to separate
kernels that take one array (measured 3.7 vs 0.87 ns per entry for ``cs_halfint``).

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

from . import _threads

__all__ = [
    "COUNTERS",
    "sqdist_diff",
    "sqdist_rows",
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


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def sqdist_gram_fix(G, ni, nj, Yi, Yj, tau, diag):  # pragma: no cover - compiled
    b, m = G.shape
    k = Yi.shape[1]
    nfix = 0
    for a in range(b):
        na = ni[a]
        row = G[a]
        # one branch-free (vectorizable) pass: q = |y_a|^2 + |y_j|^2 + G (G holds -2<y_a, y_j>)
        # and the number of entries at or below the fix-up threshold
        cnt = 0
        for j in range(m):
            r = na + nj[j] + row[j]
            row[j] = r
            cnt += r <= tau * (na + nj[j])
        s_ = a + diag if diag >= 0 else -1
        if s_ >= 0 and s_ < m:
            cnt -= row[s_] <= tau * (na + nj[s_])
            row[s_] = 0.0           # the agent itself
        if cnt > 0:                 # rare: close pairs, recomputed by differences
            for j in range(m):
                if j != s_ and row[j] <= tau * (na + nj[j]):
                    acc = 0.0
                    for l in range(k):
                        t = Yi[a, l] - Yj[j, l]
                        acc += t * t
                    row[j] = acc
                    nfix += 1
    return nfix


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def sqdist_diff(YT, i0, i1, j0, out):  # pragma: no cover - compiled
    k, n = YT.shape
    m = n - j0
    if k <= 3:
        # the engine's dimensions: one store per entry, coordinates in registers (the
        # general loop below re-reads and re-writes the row once per coordinate pair:
        # measured 1.1–1.3 vs 0.2–0.3 ns per entry at k = 2)
        r0 = YT[0, j0:]
        r1 = YT[min(1, k - 1), j0:]
        r2 = YT[k - 1, j0:]
        for a in range(i1 - i0):
            row = out[a]
            ia = i0 + a
            y0 = YT[0, ia]
            if k == 1:
                for j in range(m):
                    t0 = y0 - r0[j]
                    row[j] = t0 * t0
            elif k == 2:
                y1 = YT[1, ia]
                for j in range(m):
                    t0 = y0 - r0[j]
                    t1 = y1 - r1[j]
                    row[j] = t0 * t0 + t1 * t1
            else:
                y1 = YT[1, ia]
                y2 = YT[2, ia]
                for j in range(m):
                    t0 = y0 - r0[j]
                    t1 = y1 - r1[j]
                    t2 = y2 - r2[j]
                    row[j] = t0 * t0 + t1 * t1 + t2 * t2
        return out
    for a in range(i1 - i0):
        row = out[a]
        for j in range(m):
            row[j] = 0.0
        ia = i0 + a
        for l in range(0, k - 1, 2):
            y0 = YT[l, ia]
            y1 = YT[l + 1, ia]
            r0 = YT[l]
            r1 = YT[l + 1]
            for j in range(m):
                t0 = y0 - r0[j0 + j]
                t1 = y1 - r1[j0 + j]
                row[j] += t0 * t0 + t1 * t1
        if k % 2 == 1:
            y0 = YT[k - 1, ia]
            r0 = YT[k - 1]
            for j in range(m):
                t0 = y0 - r0[j0 + j]
                row[j] += t0 * t0
    return out


def tau_for(k: int, dtype=np.float64) -> float:
    """Fix-up threshold for dimension ``k``.

    float64: ``2.5e-4·(k+2)`` (capped at 1/8), so that kept Gram entries have relative error
    ≤ ``2(k+2)u/τ < 1e-12``. float32 (``precision="mixed"``, ``u = 2⁻²⁴``): ``1.2e-3·(k+2)``
    capped at 1/4, i.e. relative error ≤ 1e-4 up to ``k = 200`` (≤ 5e-4 at ``k = 1000``;
    typical errors are ``√k·u ≈ 1e-6``); the recomputed close pairs are exact to float64
    rounding before they are stored.
    """
    if np.dtype(dtype) == np.float32:
        return min(0.25, 1.2e-3 * (k + 2))
    return min(0.125, 2.5e-4 * (k + 2))


def sqdist_block(Yi: np.ndarray, Yj: np.ndarray, ni: np.ndarray, nj: np.ndarray,
                 out: np.ndarray, Xi: np.ndarray | None = None,
                 Xj: np.ndarray | None = None, diag: int = -1) -> np.ndarray:
    """Squared distances between the rows of ``Yi (b, k)`` and ``Yj (m, k)`` into ``out (b, m)``.

    ``Yi``/``Yj`` are centred coordinates, ``ni``/``nj`` their squared row norms, all of the
    dtype of ``out`` (float64, or float32 for ``precision="mixed"``). BLAS Gram
    product (``−2 Yi Yjᵀ`` straight into ``out``) plus the numba fix-up kernel, which adds the
    norms and recomputes close pairs by differences of the raw (uncentred) rows ``Xi``/``Xj``
    (default: ``Yi``/``Yj``) – differences of the inputs are exact to rounding, whereas
    centring a far-away cloud rounds at its distance scale. ``diag >= 0`` says that row ``a``
    and column ``a + diag`` are the same agent (set to exactly 0).
    """
    _threads.gemm(-2.0, Yi, Yj, 0.0, out, trans_b=True)
    ty = out.dtype.type
    sqdist_gram_fix(out, ni, nj, Yi if Xi is None else Xi, Yj if Xj is None else Xj,
                    ty(tau_for(Yi.shape[1], out.dtype)), int(diag))
    return out


def sqdist_rows(YT: np.ndarray, i0: int, i1: int, j0: int, out: np.ndarray) -> np.ndarray:
    """Squared distances by differences, rows ``i0:i1`` against columns ``j0:N``.

    ``YT (k, N)`` holds the coordinates transposed (contiguous), ``out (i1 − i0, N − j0)``.
    Exact to rounding (no cancellation), vectorized over columns; the engine's path for small
    dimensions. Twin: :func:`sqdist_numpy`.
    """
    return sqdist_diff(YT, int(i0), int(i1), int(j0), out)


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


@njit(inline="always", fastmath=_FM, boundscheck=False, error_model="numpy")
def _cs_row(q, o, G, half, odd, one):  # pragma: no cover - compiled
    # G (1 + q)^(-(2 half + odd)/2) over one row, branch-free inner loops. Called with
    # o = q (the same view) for in-place use: after inlining LLVM sees one pointer and
    # vectorizes; two *different* arrays that happen to alias would get the scalar loop
    # (runtime overlap check), which is 4x slower.
    m = q.shape[0]
    if odd:
        if half == 0:
            for j in range(m):
                o[j] = G / np.sqrt(one + q[j])
        elif half == 1:
            for j in range(m):
                w = one + q[j]
                o[j] = G / (w * np.sqrt(w))
        elif half == 2:
            for j in range(m):
                w = one + q[j]
                o[j] = G / (w * w * np.sqrt(w))
        else:
            for j in range(m):
                w = one + q[j]
                p = np.sqrt(w)
                for _ in range(half):
                    p *= w
                o[j] = G / p
    else:
        if half == 0:
            for j in range(m):
                o[j] = G
        elif half == 1:
            for j in range(m):
                o[j] = G / (one + q[j])
        elif half == 2:
            for j in range(m):
                w = one + q[j]
                o[j] = G / (w * w)
        else:
            for j in range(m):
                w = one + q[j]
                p = w
                for _ in range(half - 1):
                    p *= w
                o[j] = G / p


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def _cs_halfint_out(Q, G, n2, out, one):  # pragma: no cover - compiled
    for a in range(Q.shape[0]):
        _cs_row(Q[a], out[a], G, n2 // 2, n2 % 2, one)
    return out


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def _cs_halfint_inplace(Q, G, n2, one):  # pragma: no cover - compiled
    for a in range(Q.shape[0]):
        r = Q[a]
        _cs_row(r, r, G, n2 // 2, n2 % 2, one)
    return Q


def cs_halfint(Q: np.ndarray, G: float, n2: int, out: np.ndarray) -> np.ndarray:
    """Cucker–Smale kernel ``G (1 + q)^(−n2/2)`` of squared distances ``Q (b, m)`` into
    ``out`` (which may be ``Q`` itself: the in-place kernel is then used, which vectorizes;
    a call with two aliasing arrays would fall back to scalar code). Twin: :func:`cs_numpy`."""
    # G and 1 in the dtype of the output: float32 blocks (precision="mixed") stay float32
    ty = out.dtype.type
    if out is Q:
        return _cs_halfint_inplace(Q, ty(G), int(n2), ty(1.0))
    return _cs_halfint_out(Q, ty(G), int(n2), out, ty(1.0))


def cs_numpy(Q: np.ndarray, G: float, beta: float) -> np.ndarray:
    """Twin of :func:`cs_halfint`: ``G·exp(−β·log1p(q))`` with ``β = n2/2``."""
    return G * np.exp(-beta * np.log1p(np.asarray(Q, dtype=float)))


# ------------------------------------------------------------------ O(N·d) passes of a step
# Fused single passes over the (N, d) state arrays (each numpy ufunc is a separate pass, with a
# temporary where dtypes mix; at k = 150 the numpy versions cost ≈ 1 ms of a 9 ms step).


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def centre_rows(z, out):  # pragma: no cover - compiled
    """``out = z − mean(z, axis=0)`` (the column mean accumulated row by row, as numpy does)."""
    n, d = z.shape
    mean = np.zeros(d)
    for i in range(n):
        for l in range(d):
            mean[l] += z[i, l]
    for l in range(d):
        mean[l] /= n
    for i in range(n):
        for l in range(d):
            out[i, l] = z[i, l] - mean[l]
    return out


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def gram_rows(centred, Y, nrm, cast):  # pragma: no cover - compiled
    """Squared row norms of the Gram operand into ``nrm``; with ``cast`` the operand ``Y`` is
    first written as ``centred`` rounded to ``Y``'s dtype (float32) and the norms are those
    of the rounded rows (accumulated in float64), so the Gram formula stays consistent."""
    n, d = centred.shape
    for i in range(n):
        s = 0.0
        if cast:
            for l in range(d):
                Y[i, l] = centred[i, l]
            for l in range(d):
                y = np.float64(Y[i, l])
                s += y * y
        else:
            for l in range(d):
                y = centred[i, l]
                s += y * y
        nrm[i] = s
    return nrm


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def zext_rows(centred, c, Z):  # pragma: no cover - compiled
    """``Z = [c·z, c]`` (``Z`` of shape ``(N, d+1)``, float64 or float32)."""
    n, d = centred.shape
    for i in range(n):
        ci = c[i]
        for l in range(d):
            Z[i, l] = ci * centred[i, l]
        Z[i, d] = ci
    return Z


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def pair_finish(A, centred, out):  # pragma: no cover - compiled
    """``out = A[:, :d] − A[:, d]·z`` in float64: ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ``."""
    n, d = centred.shape
    for i in range(n):
        r = np.float64(A[i, d])
        for l in range(d):
            out[i, l] = np.float64(A[i, l]) - r * centred[i, l]
    return out
