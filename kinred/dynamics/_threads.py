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


@contextlib.contextmanager
def blas_threads(n: int):
    """Limit BLAS to ``n`` threads in the calling thread for the duration (if supported)."""
    if _BLAS_LOCAL is None:
        yield
        return
    prev = _BLAS_LOCAL(int(n))
    try:
        yield
    finally:
        _BLAS_LOCAL(int(prev))


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


# ---------------------------------------------------------------------- direct BLAS (dgemm)
def _find_cblas_dgemm():
    """``cblas_dgemm`` of numpy's own OpenBLAS (ILP64 ``scipy_cblas_dgemm64_``), or None.

    Calling it directly lets the engine accumulate ``C += A·B`` in place (``beta = 1``) on
    sub-blocks with arbitrary leading dimensions, which ``np.matmul`` cannot do; the same
    library (and thread setting) as numpy's ``@`` is used.
    """
    libs = glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*"))
    for path in libs:
        for name, itype in (("scipy_cblas_dgemm64_", ctypes.c_int64), ("cblas_dgemm64_", ctypes.c_int64),
                            ("scipy_cblas_dgemm", ctypes.c_int), ("cblas_dgemm", ctypes.c_int)):
            try:
                fn = getattr(ctypes.CDLL(path), name)
            except (OSError, AttributeError):
                continue
            fn.restype = None
            fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, itype, itype, itype,
                           ctypes.c_double, ctypes.c_void_p, itype, ctypes.c_void_p, itype,
                           ctypes.c_double, ctypes.c_void_p, itype]
            return fn
    return None


_CBLAS_DGEMM = _find_cblas_dgemm()
_ROW, _NT, _T = 101, 111, 112


def _check_gemm_works() -> bool:
    if _CBLAS_DGEMM is None:
        return False
    try:
        a = np.arange(6.0).reshape(2, 3)
        b = np.arange(12.0).reshape(3, 4)
        c = np.ones((2, 4))
        _CBLAS_DGEMM(_ROW, _NT, _NT, 2, 4, 3, 2.0, a.ctypes.data, 3, b.ctypes.data, 4, 1.0,
                     c.ctypes.data, 4)
        return bool(np.array_equal(c, 1.0 + 2.0 * (a @ b)))
    except Exception:  # pragma: no cover - defensive: fall back to numpy
        return False


#: Whether the in-place ``gemm`` path is available (otherwise numpy ``matmul`` + add).
HAVE_GEMM = _check_gemm_works()


def gemm(alpha: float, A: np.ndarray, B: np.ndarray, beta: float, C: np.ndarray,
         trans_a: bool = False, trans_b: bool = False) -> None:
    """``C ← α·op(A)·op(B) + β·C`` in place, ``op(X) = X`` or ``Xᵀ``.

    ``A``, ``B``, ``C`` are float64 arrays with unit stride along their last axis (row-major
    blocks of larger arrays are fine). Falls back to numpy when the direct BLAS is missing.
    """
    m, k = A.shape[::-1] if trans_a else A.shape
    kb, n = B.shape[::-1] if trans_b else B.shape
    if kb != k or C.shape != (m, n):
        raise ValueError(f"gemm: incompatible shapes op(A) {(m, k)}, op(B) {(kb, n)}, C {C.shape}")
    if m == 0 or n == 0:
        return
    if (not HAVE_GEMM or k == 0 or A.strides[-1] != 8 or B.strides[-1] != 8
            or C.strides[-1] != 8 or C.dtype != np.float64):
        prod = (A.T if trans_a else A) @ (B.T if trans_b else B)
        if beta == 0.0:
            np.multiply(prod, alpha, out=C)
        else:
            if beta != 1.0:
                C *= beta
            C += alpha * prod if alpha != 1.0 else prod
        return
    _CBLAS_DGEMM(_ROW, _T if trans_a else _NT, _T if trans_b else _NT, m, n, k, alpha,
                 A.__array_interface__["data"][0], max(A.strides[0] // 8, A.shape[1], 1),
                 B.__array_interface__["data"][0], max(B.strides[0] // 8, B.shape[1], 1), beta,
                 C.__array_interface__["data"][0], max(C.strides[0] // 8, C.shape[1], 1))
