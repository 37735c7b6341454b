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
    an ensemble can then run one simulation per core.

    Examples
    --------
    >>> from kinred.dynamics import set_num_threads, get_num_threads
    >>> old = get_num_threads(); set_num_threads(1); get_num_threads()
    1
    >>> set_num_threads(old)
    """
    _STATE["n"] = as_int(n, "n", low=1, high=256)


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
