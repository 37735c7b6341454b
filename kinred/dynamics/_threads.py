"""Thread control of the dynamics engine (engine threads and BLAS threads)."""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .._validate import as_int

_STATE = {"n": max(1, min(os.cpu_count() or 1, 2)), "pool": None, "pool_n": 0}


def _find_openblas_local():
    """``openblas_set_num_threads_local`` of numpy's OpenBLAS, or None (best effort)."""
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*"))
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
            fn = lib.openblas_set_num_threads_local
            fn.argtypes = [ctypes.c_int]
            fn.restype = ctypes.c_int
            return fn
        except (OSError, AttributeError):
            continue
    return None


_BLAS_LOCAL = _find_openblas_local()


def _find_openblas_get():
    """``openblas_get_num_threads`` of numpy's OpenBLAS, or None (tests read it)."""
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*"))
    for path in libs:
        for name in ("scipy_openblas_get_num_threads64_", "openblas_get_num_threads"):
            try:
                fn = getattr(ctypes.CDLL(path), name)
            except (OSError, AttributeError):
                continue
            fn.restype = ctypes.c_int
            return fn
    return None


_BLAS_GET = _find_openblas_get()


@contextlib.contextmanager
def blas_threads(n: int):
    """Limit BLAS to ``n`` threads for the duration (if supported).

    In numpy's OpenBLAS, ``openblas_set_num_threads_local`` acts on the whole process, not
    on the calling thread (measured: a value set in one thread is read back in another).
    Only the thread that owns a parallel region may therefore enter this context; its
    workers call :func:`pin_blas_one`. (Two workers each entering it raced: the first to
    finish restored the old count while the other still computed, whose later BLAS calls
    then ran multithreaded – oversubscribed, and round-off that changed from call to call.)
    """
    if _BLAS_LOCAL is None:
        yield
        return
    prev = _BLAS_LOCAL(int(n))
    try:
        yield
    finally:
        _BLAS_LOCAL(int(prev))


def pin_blas_one() -> None:
    """In a worker of a parallel region: BLAS single-threaded, not restored. The region's
    owner holds :func:`blas_threads` ``(1)`` around the region and restores the count after
    every worker has finished; were the setting per thread, the pool threads are the
    engine's own and stay at one."""
    if _BLAS_LOCAL is not None:
        _BLAS_LOCAL(1)


def set_num_threads(n: int) -> None:
    """Set the number of threads one simulation uses (row strips run in ``n`` threads).

    With ``n = 1`` a simulation is single-threaded, including BLAS calls made by the engine:
    an ensemble can then run one simulation per core (:func:`kinred.ensemble.run_ensemble`
    runs every member with one thread). The default is ``min(cpu_count, 2)``.

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
    """Run the engine with ``n`` threads for the duration of the ``with`` block (then restore)."""
    prev = _STATE["n"]
    set_num_threads(n)
    try:
        yield
    finally:
        _STATE["n"] = prev


def get_num_threads() -> int:
    """Number of threads of the engine (see :func:`set_num_threads`)."""
    return _STATE["n"]


def pool(n: int) -> ThreadPoolExecutor:
    if _STATE["pool"] is None or _STATE["pool_n"] != n:
        if _STATE["pool"] is not None:
            _STATE["pool"].shutdown(wait=False)
        _STATE["pool"] = ThreadPoolExecutor(max_workers=n, thread_name_prefix="kinred-dyn")
        _STATE["pool_n"] = n
    return _STATE["pool"]


# ---------------------------------------------------------------------- direct BLAS (gemm)
def cblas_gemm_symbol(kind: str):
    """``(library path, symbol, ilp64)`` of ``cblas_?gemm`` (``kind`` = ``"d"`` or ``"s"``) in
    numpy's own OpenBLAS (ILP64 ``scipy_cblas_dgemm64_`` first), or None."""
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*"))
    for path in libs:
        for name, ilp64 in ((f"scipy_cblas_{kind}gemm64_", True), (f"cblas_{kind}gemm64_", True),
                            (f"scipy_cblas_{kind}gemm", False), (f"cblas_{kind}gemm", False)):
            try:
                getattr(ctypes.CDLL(path), name)
            except (OSError, AttributeError):
                continue
            return os.path.abspath(path), name, ilp64
    return None


def _find_cblas_gemm(kind: str):
    """``cblas_?gemm`` (``kind`` = ``"d"`` or ``"s"``) of numpy's own OpenBLAS (ILP64
    ``scipy_cblas_dgemm64_``), or None.

    Calling it directly lets the engine accumulate ``C += A·B`` in place (``beta = 1``) on
    sub-blocks with arbitrary leading dimensions, which ``np.matmul`` cannot do; the same
    library (and thread setting) as numpy's ``@`` is used.
    """
    scalar = ctypes.c_double if kind == "d" else ctypes.c_float
    found = cblas_gemm_symbol(kind)
    if found is None:
        return None
    path, name, ilp64 = found
    itype = ctypes.c_int64 if ilp64 else ctypes.c_int
    fn = getattr(ctypes.CDLL(path), name)
    fn.restype = None
    fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, itype, itype, itype,
                   scalar, ctypes.c_void_p, itype, ctypes.c_void_p, itype,
                   scalar, ctypes.c_void_p, itype]
    return fn


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
