"""Parallel regions shared by the dynamics engine and the recovery solver.

* the thread count (:func:`set_num_threads`, :func:`get_num_threads`, :func:`num_threads`):
  the row strips of one simulation (:mod:`kinred.dynamics`) and the row chunks of a batched
  ℓ1 solve (:mod:`kinred.recovery`) run in that many threads (a dense right-hand side too
  small to share, ``kinred.pairsum.dense.engine_threads``, in one); ensemble members use one;
* :func:`run_parallel`: one parallel region (group 0 in the calling thread, the others in a
  shared pool) with BLAS single-threaded until every group has finished;
* :func:`blas_threads`: numpy's OpenBLAS thread count for the duration of a ``with`` block;
* :func:`gemm`: ``C ← α·op(A)·op(B) + β·C`` in place on sub-blocks, by numpy's own
  ``cblas_?gemm`` (:func:`cblas_gemm_symbol` also gives the compiled strip worker of
  ``kinred.pairsum._kernels`` the symbol to link against).

No numba here: the compiled callers live in the ``_kernels`` modules.
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np

from ._validate import as_int

_STATE = {"n": max(1, min(os.cpu_count() or 1, 2)), "pool": None, "pool_n": 0}


def _openblas_function(names, restype, argtypes):
    """The first of ``names`` exported by numpy's bundled OpenBLAS as a ctypes function
    (``restype``/``argtypes`` set), with the library's path: ``(fn, path)``, or None."""
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*"))
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in names:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn.restype = restype
                fn.argtypes = argtypes
                return fn, os.path.abspath(path)
    return None


_found = _openblas_function(("openblas_set_num_threads_local",), ctypes.c_int, [ctypes.c_int])
_BLAS_LOCAL = _found[0] if _found else None
#: ``openblas_get_num_threads`` (tests read the count inside a parallel region), or None.
_found = _openblas_function(("scipy_openblas_get_num_threads64_", "openblas_get_num_threads"),
                            ctypes.c_int, [])
_BLAS_GET = _found[0] if _found else None


@contextlib.contextmanager
def blas_threads(n: int):
    """Limit BLAS to ``n`` threads for the duration (if supported).

    In numpy's OpenBLAS, ``openblas_set_num_threads_local`` acts on the whole process, not
    on the calling thread. Only the thread that owns a parallel region may therefore enter
    this context (:func:`run_parallel` does, for its workers): a worker restoring the count
    on its way out would switch the others' BLAS calls back to several threads mid-region
    (see docs/performance.md, "Threads and BLAS").
    """
    if _BLAS_LOCAL is None:
        yield
        return
    prev = _BLAS_LOCAL(int(n))
    try:
        yield
    finally:
        _BLAS_LOCAL(int(prev))


def run_parallel(fn, args: list) -> list:
    """``[fn(g, args[g]) for g in range(len(args))]`` in ``len(args)`` threads: group 0 in the
    calling thread, the others in the shared pool, with BLAS single-threaded for the whole
    region. The caller owns the BLAS setting and restores it after every group has finished
    (numpy's OpenBLAS applies it process-wide, see :func:`blas_threads`); pool threads also
    set it for themselves, in case a BLAS keeps it per thread. Results in group order."""
    n = len(args)
    with blas_threads(1):
        if n == 1:
            return [fn(0, args[0])]

        def pinned(g, a):
            if _BLAS_LOCAL is not None:
                _BLAS_LOCAL(1)
            return fn(g, a)

        futs = [pool(n - 1).submit(pinned, g, args[g]) for g in range(1, n)]
        try:
            first = fn(0, args[0])
        finally:
            wait(futs)      # never leave a thread writing into the caller's buffers
        return [first] + [f.result() for f in futs]


def set_num_threads(n: int) -> None:
    """Set the number of threads of one simulation or one batched ℓ1 solve.

    The row strips of the dynamics engine and the row chunks of
    :func:`kinred.recovery.basis_pursuit` / :func:`~kinred.recovery.lasso` run in ``n``
    threads (a dense right-hand side too small to share, ``kinred.pairsum.dense.engine_threads``:
    below 0.6 ms of one-thread work, 5 ms without compiled kernels, in one). With ``n = 1`` they
    are single-threaded, including the BLAS calls they make: an
    ensemble can then run one simulation per core (:func:`kinred.ensemble.run_ensemble` runs
    every member with one thread). The default is ``min(cpu_count, 2)``.

    Examples
    --------
    >>> from kinred.dynamics import set_num_threads, get_num_threads
    >>> old = get_num_threads(); set_num_threads(1); get_num_threads()
    1
    >>> set_num_threads(old)
    """
    _STATE["n"] = as_int(n, "n", low=1, high=256)


@contextlib.contextmanager
def num_threads(n: int):
    """Use ``n`` threads for the duration of the ``with`` block (then restore)."""
    prev = _STATE["n"]
    set_num_threads(n)
    try:
        yield
    finally:
        _STATE["n"] = prev


def get_num_threads() -> int:
    """Number of threads of a parallel region (see :func:`set_num_threads`)."""
    return _STATE["n"]


def pool(n: int) -> ThreadPoolExecutor:
    """The shared pool of ``n`` worker threads (made anew when ``n`` changes)."""
    if _STATE["pool"] is None or _STATE["pool_n"] != n:
        if _STATE["pool"] is not None:
            _STATE["pool"].shutdown(wait=False)
        _STATE["pool"] = ThreadPoolExecutor(max_workers=n, thread_name_prefix="kinred-par")
        _STATE["pool_n"] = n
    return _STATE["pool"]


# ---------------------------------------------------------------------- direct BLAS (gemm)
_GEMM_NAMES = ("scipy_cblas_{}gemm64_", "cblas_{}gemm64_", "scipy_cblas_{}gemm", "cblas_{}gemm")


def cblas_gemm_symbol(kind: str):
    """``(library path, symbol, ilp64)`` of ``cblas_?gemm`` (``kind`` = ``"d"`` or ``"s"``) in
    numpy's own OpenBLAS (ILP64 ``scipy_cblas_dgemm64_`` first), or None."""
    found = _openblas_function(tuple(f.format(kind) for f in _GEMM_NAMES), None, None)
    if found is None:
        return None
    fn, path = found
    return path, fn.__name__, fn.__name__.endswith("64_")


def _find_cblas_gemm(kind: str):
    """``cblas_?gemm`` (``kind`` = ``"d"`` or ``"s"``) of numpy's own OpenBLAS (ILP64
    ``scipy_cblas_dgemm64_``), or None.

    Calling it directly lets the dynamics engine accumulate ``C += A·B`` in place (``beta = 1``) on
    sub-blocks with arbitrary leading dimensions, which ``np.matmul`` cannot do; the same
    library (and thread setting) as numpy's ``@`` is used.
    """
    scalar = ctypes.c_double if kind == "d" else ctypes.c_float
    found = cblas_gemm_symbol(kind)
    if found is None:
        return None
    itype = ctypes.c_int64 if found[2] else ctypes.c_int
    return _openblas_function((found[1],), None,
                              [ctypes.c_int, ctypes.c_int, ctypes.c_int, itype, itype, itype,
                               scalar, ctypes.c_void_p, itype, ctypes.c_void_p, itype,
                               scalar, ctypes.c_void_p, itype])[0]


_CBLAS = {np.dtype(np.float64): _find_cblas_gemm("d"), np.dtype(np.float32): _find_cblas_gemm("s")}
_ROW, _NT, _T = 101, 111, 112


def _check_gemm_works(dtype) -> bool:
    fn = _CBLAS[np.dtype(dtype)]
    if fn is None:
        return False
    try:
        a = np.arange(6.0, dtype=dtype).reshape(2, 3)
        b = np.arange(12.0, dtype=dtype).reshape(3, 4)
        c = np.ones((2, 4), dtype=dtype)
        fn(_ROW, _NT, _NT, 2, 4, 3, 2.0, a.ctypes.data, 3, b.ctypes.data, 4, 1.0,
           c.ctypes.data, 4)
        return bool(np.array_equal(c, 1.0 + 2.0 * (a @ b)))
    except Exception:  # pragma: no cover - defensive: fall back to numpy
        return False


#: Whether the in-place ``gemm`` path is available per dtype (otherwise numpy ``matmul`` + add).
HAVE_GEMM_FOR = {dt: _check_gemm_works(dt) for dt in _CBLAS}
#: Whether the in-place float64 ``gemm`` path is available (tests switch it off).
HAVE_GEMM = HAVE_GEMM_FOR[np.dtype(np.float64)]


def gemm(alpha: float, A: np.ndarray, B: np.ndarray, beta: float, C: np.ndarray,
         trans_a: bool = False, trans_b: bool = False) -> None:
    """``C ← α·op(A)·op(B) + β·C`` in place, ``op(X) = X`` or ``Xᵀ``.

    ``A``, ``B``, ``C`` are arrays of one dtype, float64 (``dgemm``) or float32 (``sgemm``,
    the engine's ``precision="mixed"``), with unit stride along their last axis (row-major
    blocks of larger arrays are fine). Falls back to numpy when the direct BLAS is missing.
    """
    m, k = A.shape[::-1] if trans_a else A.shape
    kb, n = B.shape[::-1] if trans_b else B.shape
    if kb != k or C.shape != (m, n):
        raise ValueError(f"gemm: incompatible shapes op(A) {(m, k)}, op(B) {(kb, n)}, C {C.shape}")
    if m == 0 or n == 0:
        return
    dt = C.dtype
    isz = dt.itemsize
    fast = (HAVE_GEMM if dt == np.float64 else HAVE_GEMM_FOR.get(dt, False))
    if (not fast or k == 0 or A.dtype != dt or B.dtype != dt or A.strides[-1] != isz
            or B.strides[-1] != isz or C.strides[-1] != isz):
        prod = (A.T if trans_a else A) @ (B.T if trans_b else B)
        if beta == 0.0:
            np.multiply(prod, alpha, out=C)
        else:
            if beta != 1.0:
                C *= beta
            C += alpha * prod if alpha != 1.0 else prod
        return
    _CBLAS[dt](_ROW, _T if trans_a else _NT, _T if trans_b else _NT, m, n, k, alpha,
               A.__array_interface__["data"][0], max(A.strides[0] // isz, A.shape[1], 1),
               B.__array_interface__["data"][0], max(B.strides[0] // isz, B.shape[1], 1), beta,
               C.__array_interface__["data"][0], max(C.strides[0] // isz, C.shape[1], 1))
