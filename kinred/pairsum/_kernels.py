"""Private numba kernels of the pair-sum backends, each with a plain-numpy twin.

Only this module (and the other private ``_kernels.py`` modules) imports numba. Every kernel
is compiled with ``cache=True`` and ``nogil=True`` (so that Python threads over row strips
run in parallel) and uses fastmath flags that only allow re-association and contraction of
sums (``{"reassoc", "contract"}``): NaN and Inf propagate exactly as in IEEE arithmetic, so
divergence stays detectable.

All kernels live in this one file on purpose: the compiled strip worker inlines the kernel
rows (``_cs_row``, :func:`pow_row64`), and numba's on-disk cache of a function is
invalidated only when *its own* source file changes.

Kernels
-------
``sqdist_gram_fix(G, ni, nj, Yi, Yj, tau, diag)``
    Turns a block ``G = −2 Yi Yjᵀ`` (written by BLAS) into squared distances
    ``‖yᵢ‖² + ‖yⱼ‖² − 2⟨yᵢ, yⱼ⟩`` in place in one branch-free (vectorizable) pass that also
    counts the entries below ``tau·(‖yᵢ‖² + ‖yⱼ‖²)``; only rows with such entries get a second
    pass that recomputes them by differences. Twin: :func:`sqdist_numpy` (pure differences).
``sqdist_diff(YT, i0, i1, j0, out)``
    Squared distances by differences from transposed coordinates ``YT (k, N)``, vectorized
    over columns (the dense backend's path for ``k ≤ 3``). Twin: :func:`sqdist_numpy`.
``pair_strips(strips, ...)``
    The pairwise stage of one engine thread in one compiled call (Gram block by
    ``cblas_?gemm`` of numpy's OpenBLAS, fix-up, kernel, both pair-sum products per strip).
    Twin: the Python strip loop of :class:`kinred.pairsum.Dense` (same operations, same
    order).
``cs_pow(Q, G, beta, scr)`` (rows: ``pow_row64``, ``pow_row32``)
    Cucker–Smale ``G (1 + q)^(−β)`` for general β without libm calls (so that the compiled
    worker needs no Python call). Twin: :func:`cs_numpy`.
``cs_halfint(Q, G, n2, out)``
    Cucker–Smale kernel ``G (1 + q)^(−n2/2)`` for integer ``n2`` with sqrt and division
    only. Twin: :func:`cs_numpy` (``G·exp(−β·log1p(q))``).

In-place calls go to separate kernels that take one array: LLVM vectorizes a loop that reads
one array and writes another only behind a runtime no-overlap check, which fails when the two
are the same array. Timings of these kernels and of the variants that were tried and not
kept: docs/performance.md, section "Pair-sum engine".

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
import threading

import numpy as np
from numba import njit, types
from numba.extending import overload

from .. import _parallel

__all__ = [
    "COUNTERS",
    "count",
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
_COUNTERS_LOCK = threading.Lock()


def count(source: str, n: int = 1) -> None:
    """``COUNTERS[source] += n`` under a lock: pool threads and concurrent simulations count
    (``+=`` on a Counter is a read and a write another thread can interleave)."""
    with _COUNTERS_LOCK:
        COUNTERS[source] += n


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
        # general loop below re-reads and re-writes the row once per coordinate pair)
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
    _parallel.gemm(-2.0, Yi, Yj, 0.0, out, trans_b=True)
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


# ------------------------------------------------------------------ compiled strip worker
# One call per engine thread per step: the whole strip loop (BLAS Gram block, fix-up,
# kernel, both orientations of the pair sums) runs in compiled code without the GIL. The
# Python loop over strips makes 6-10 GIL-releasing calls per strip, and with two threads each
# call's GIL hand-back waits for the other thread's Python work (docs/performance.md).

#: Kernel kinds the compiled worker evaluates; a kernel's ``compiled_form()`` names them
#: (``"cs_halfint"``, ``"cs_pow"``, see :mod:`kinred.pairsum`) and the dense backend maps the
#: names to these codes.
KIND_CS_HALFINT = 1      # Cucker–Smale G (1 + q)^(−n2/2), a = G, b = n2 (integer >= 0)
KIND_CS_POW = 2          # Cucker–Smale G (1 + q)^(−β), a = G, b = β (general)


def _declare_blas():
    """ExternalFunction declarations of numpy's OpenBLAS ``cblas_dgemm``/``cblas_sgemm``
    (resolved by symbol name at link time, so compiled callers stay cacheable), or Nones."""
    try:
        import llvmlite.binding as llb
        from numba.core import types
    except ImportError:  # pragma: no cover - numba always ships llvmlite
        return None, None
    out = []
    for kind, scalar in (("d", types.float64), ("s", types.float32)):
        found = _parallel.cblas_gemm_symbol(kind)
        if found is None:
            out.append(None)
            continue
        path, name, ilp64 = found
        try:
            llb.load_library_permanently(path)
        except Exception:  # pragma: no cover - defensive: the Python path remains
            out.append(None)
            continue
        it = types.int64 if ilp64 else types.int32
        i32 = types.int32
        out.append(types.ExternalFunction(name, types.void(
            i32, i32, i32, it, it, it, scalar, types.intp, it, types.intp, it, scalar,
            types.intp, it)))
    return tuple(out)


_XDGEMM, _XSGEMM = _declare_blas()


@njit(inline="always")
def _ld(A):  # pragma: no cover - compiled
    return max(A.strides[0] // A.itemsize, A.shape[1], 1)


@njit(inline="always")
def _nb_gemm(alpha, A, ta, B, tb, beta, C):  # pragma: no cover - compiled
    """``C ← α op(A) op(B) + β C`` (row-major blocks, unit stride along rows) from compiled
    code: ``cblas_dgemm``/``cblas_sgemm`` of numpy's OpenBLAS, by the dtype of ``C``."""
    m, n = C.shape
    k = A.shape[0] if ta else A.shape[1]
    if m == 0 or n == 0 or k == 0:
        return
    t_a = np.int32(112) if ta else np.int32(111)
    t_b = np.int32(112) if tb else np.int32(111)
    if C.itemsize == 8:
        _XDGEMM(np.int32(101), t_a, t_b, m, n, k, np.float64(alpha), A.ctypes.data, _ld(A),
                B.ctypes.data, _ld(B), np.float64(beta), C.ctypes.data, _ld(C))
    else:
        _XSGEMM(np.int32(101), t_a, t_b, m, n, k, np.float32(alpha), A.ctypes.data, _ld(A),
                B.ctypes.data, _ld(B), np.float32(beta), C.ctypes.data, _ld(C))


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def pow_row64(q, G, beta, scr):  # pragma: no cover - compiled
    """``q ← G (1 + q)^(−β)`` in place on one float64 row, vectorizable (no libm calls).

    ``w = 1 + q = 2^e m`` (bit fields, ``m`` reduced to ``[1/√2, √2]``);
    ``ln m = 2 atanh(s)``, ``s = (m − 1)/(m + 1)``, ``|s| ≤ 0.172``, by the series to ``s²³``
    (truncation < 1e-17); ``y = −β (e + ln m / ln 2)``; ``2^y = 2^n · exp((y − n) ln 2)``
    with ``n = round(y)`` and the Taylor series to degree 13 (truncation < 5e-18); ``2^n`` as
    two exact powers of two built from bits (``y`` clamped to ``[−2000, 1000]``, so results
    below the float64 range come out 0, subnormals included).
    Relative error ≤ 1.2e-15·(1 + |y|), as ``G·exp(−β·log1p(q))`` in numpy (measured against
    80-bit long double for β from 0.05 to 9.9 and q from 0 to 1e300). ``q = +∞`` gives 0
    (β > 0), NaN gives NaN. ``scr``: float64 scratch ``(3, ≥ len(q))``.
    """
    m = q.shape[0]
    qi = q.view(np.int64)
    fb = scr[0]
    ib1 = scr[1].view(np.int64)
    ib2 = scr[2].view(np.int64)
    for j in range(m):
        q[j] = 1.0 + q[j]
    for j in range(m):
        ix = qi[j]
        fb[j] = np.float64((ix >> 52) - 1023)
        qi[j] = (ix & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000
    for j in range(m):
        mm = q[j]
        e = fb[j]
        special = e > 1023.5                    # w = +inf (mantissa exactly 1) or NaN
        yspec = -np.inf if mm == 1.0 else np.nan
        big = mm > 1.4142135623730951
        mm = mm * 0.5 if big else mm
        e = e + 1.0 if big else e
        s = (mm - 1.0) / (mm + 1.0)
        s2 = s * s
        pl = 2.0 / 23.0
        pl = pl * s2 + 2.0 / 21.0
        pl = pl * s2 + 2.0 / 19.0
        pl = pl * s2 + 2.0 / 17.0
        pl = pl * s2 + 2.0 / 15.0
        pl = pl * s2 + 2.0 / 13.0
        pl = pl * s2 + 2.0 / 11.0
        pl = pl * s2 + 2.0 / 9.0
        pl = pl * s2 + 2.0 / 7.0
        pl = pl * s2 + 2.0 / 5.0
        pl = pl * s2 + 2.0 / 3.0
        lnm = s * (pl * s2) + 2.0 * s
        y = -beta * (e + lnm * 1.4426950408889634)
        y = yspec if special else y
        y = -2000.0 if y < -2000.0 else y
        y = 1000.0 if y > 1000.0 else y
        n = np.floor(y + 0.5)
        r = (y - n) * 0.6931471805599453
        pe = 1.0 / 6227020800.0
        pe = pe * r + 1.0 / 479001600.0
        pe = pe * r + 1.0 / 39916800.0
        pe = pe * r + 1.0 / 3628800.0
        pe = pe * r + 1.0 / 362880.0
        pe = pe * r + 1.0 / 40320.0
        pe = pe * r + 1.0 / 5040.0
        pe = pe * r + 1.0 / 720.0
        pe = pe * r + 1.0 / 120.0
        pe = pe * r + 1.0 / 24.0
        pe = pe * r + 1.0 / 6.0
        pe = pe * r + 0.5
        pe = pe * r + 1.0
        q[j] = G * (pe * r + 1.0)
        fb[j] = n if n == n else 0.0            # NaN stays in q; keep the shift defined
    for j in range(m):
        n = np.int64(fb[j])
        n1 = n >> 1
        ib1[j] = (n1 + 1023) << 52
        ib2[j] = (n - n1 + 1023) << 52
    f1 = scr[1]
    f2 = scr[2]
    for j in range(m):
        q[j] = q[j] * f1[j] * f2[j]
    return q


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def pow_row32(q, G, beta, scr):  # pragma: no cover - compiled
    """Float32 twin of :func:`pow_row64` (``precision="mixed"``): series to ``s⁹`` and
    degree 8, ``y`` clamped to ``[−250, 120]``; error as numpy's float32
    ``G·2^(−β·log₂(1 + q))`` (dominated by rounding ``1 + q``: ≤ 3.6e-7 relative for
    q ≤ 5, β ≤ 1.7). ``scr``: float64 scratch ``(3, ≥ len(q)/2)``."""
    m = q.shape[0]
    qi = q.view(np.int32)
    fb = scr[0].view(np.float32)
    ib1 = scr[1].view(np.int32)
    ib2 = scr[2].view(np.int32)
    one = np.float32(1.0)
    for j in range(m):
        q[j] = one + q[j]
    for j in range(m):
        ix = qi[j]
        fb[j] = np.float32((ix >> 23) - 127)
        qi[j] = (ix & 0x007FFFFF) | 0x3F800000
    for j in range(m):
        mm = q[j]
        e = fb[j]
        special = e > np.float32(127.5)
        yspec = np.float32(-np.inf) if mm == one else np.float32(np.nan)
        big = mm > np.float32(1.4142135)
        mm = mm * np.float32(0.5) if big else mm
        e = e + one if big else e
        s = (mm - one) / (mm + one)
        s2 = s * s
        pl = np.float32(2.0 / 9.0)
        pl = pl * s2 + np.float32(2.0 / 7.0)
        pl = pl * s2 + np.float32(2.0 / 5.0)
        pl = pl * s2 + np.float32(2.0 / 3.0)
        lnm = s * (pl * s2) + np.float32(2.0) * s
        y = -beta * (e + lnm * np.float32(1.4426950408889634))
        y = yspec if special else y
        y = np.float32(-250.0) if y < np.float32(-250.0) else y
        y = np.float32(120.0) if y > np.float32(120.0) else y
        n = np.floor(y + np.float32(0.5))
        r = (y - n) * np.float32(0.6931471805599453)
        pe = np.float32(1.0 / 40320.0)
        pe = pe * r + np.float32(1.0 / 5040.0)
        pe = pe * r + np.float32(1.0 / 720.0)
        pe = pe * r + np.float32(1.0 / 120.0)
        pe = pe * r + np.float32(1.0 / 24.0)
        pe = pe * r + np.float32(1.0 / 6.0)
        pe = pe * r + np.float32(0.5)
        pe = pe * r + one
        q[j] = G * (pe * r + one)
        fb[j] = n if n == n else np.float32(0.0)
    for j in range(m):
        n = np.int32(fb[j])
        n1 = n >> 1
        ib1[j] = (n1 + 127) << 23
        ib2[j] = (n - n1 + 127) << 23
    f1 = scr[1].view(np.float32)
    f2 = scr[2].view(np.float32)
    for j in range(m):
        q[j] = q[j] * f1[j] * f2[j]
    return q


def _pow_row(q, G, beta, scr):  # pragma: no cover - compiled callers only
    """:func:`pow_row64` or :func:`pow_row32` by the dtype of ``q``, chosen when a caller is
    compiled (a branch on ``q.itemsize`` would compile both, one for the wrong dtype)."""
    raise NotImplementedError("_pow_row is only callable from compiled code")


@overload(_pow_row)
def _ol_pow_row(q, G, beta, scr):  # pragma: no cover - compiled
    if q.dtype == types.float64:
        return lambda q, G, beta, scr: pow_row64(q, G, beta, scr)
    return lambda q, G, beta, scr: pow_row32(q, G, beta, scr)


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def cs_pow(Q, G, beta, scr):  # pragma: no cover - compiled
    """``Q ← G (1 + Q)^(−β)`` in place, row by row (:func:`pow_row64` / :func:`pow_row32`
    by dtype). Twin: :func:`cs_numpy`."""
    for a in range(Q.shape[0]):
        _pow_row(Q[a], G, beta, scr)
    return Q


@njit(inline="always")
def _kernel_rows(kind, a, b, T, scr, one):  # pragma: no cover - compiled
    # a, b, one: scalars of T's dtype
    if kind == KIND_CS_HALFINT:
        n2 = np.int64(b)
        for r in range(T.shape[0]):
            row = T[r]
            _cs_row(row, row, a, n2 // 2, n2 % 2, one)
    else:
        for r in range(T.shape[0]):
            _pow_row(T[r], a, b, scr)


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def pair_strips(strips, diff, YT, Y, nrm, R, tau, esrc, elast, ekind, epar, ez, eacc, Z, acc,
                qbuf, pbuf, scr, one):  # pragma: no cover - compiled
    """The pairwise stage of a step over row strips, in one compiled call (see the module
    notes). Per strip ``[i0, i1)`` against columns ``i0:N`` and per source ``s``: squared
    distances (``diff``: by differences from ``YT[s] (k, N)``; else BLAS ``−2 Y Yᵀ`` plus
    :func:`sqdist_gram_fix` with raw rows ``R[s]``), then per effect ``e`` of that source its
    kernel (``ekind``/``epar``; into the distance block itself for the last effect of a
    source, ``elast``) and both orientations of ``acc[eacc[e]] += Φ Z[ez[e]]`` (each unordered
    pair's φ used twice). ``acc`` is zeroed first; ``epar``, ``tau`` and ``one`` are of the
    stage dtype. Same operations, in the same order, as the Python strip loop of
    :class:`kinred.pairsum.Dense`.
    """
    N = acc.shape[1]
    ns = YT.shape[0] if diff else Y.shape[0]
    ne = esrc.shape[0]
    acc[:] = 0.0
    for st in range(strips.shape[0]):
        i0 = strips[st, 0]
        i1 = strips[st, 1]
        bb = i1 - i0
        m = N - i0
        q = qbuf[: bb * m].reshape((bb, m))
        for s in range(ns):
            if diff:
                sqdist_diff(YT[s], i0, i1, i0, q)
            else:
                Ys = Y[s]
                Rs = R[s]
                _nb_gemm(-2.0, Ys[i0:i1], False, Ys[i0:], True, 0.0, q)
                sqdist_gram_fix(q, nrm[s, i0:i1], nrm[s, i0:], Rs[i0:i1], Rs[i0:], tau,
                                np.int64(0))
            for e in range(ne):
                if esrc[e] != s:
                    continue
                if elast[e]:
                    T = q
                else:
                    T = pbuf[: bb * m].reshape((bb, m))
                    T[:, :] = q
                _kernel_rows(ekind[e], epar[e, 0], epar[e, 1], T, scr, one)
                Ze = Z[ez[e]]
                Ae = acc[eacc[e]]
                _nb_gemm(1.0, T, False, Ze[i0:], False, 1.0, Ae[i0:i1])
                if i1 < N:
                    _nb_gemm(1.0, T[:, bb:], True, Ze[i0:i1], False, 1.0, Ae[i1:])
    return 0


#: Whether the compiled worker can run, per stage dtype (its BLAS symbols were found).
HAVE_COMPILED_FOR = {np.dtype(np.float64): _XDGEMM is not None and _parallel.HAVE_GEMM_FOR[np.dtype(np.float64)],
                     np.dtype(np.float32): _XSGEMM is not None and _parallel.HAVE_GEMM_FOR[np.dtype(np.float32)]}
