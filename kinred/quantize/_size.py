"""Preflight size model of quantization: the bytes a stage will allocate, known before it does.

Every stage that builds arrays works in bounded chunks, so its peak memory is

* the arrays it keeps, proportional to an exact integer count, plus
* one chunk of temporaries (scipy's quantile functions, the exact 1-D error, grid indices),
  bounded by a constant, plus
* :data:`OVERHEAD` for Python objects and small arrays.

The counts come from the budget (pure integers, never built), so the bytes are exact Python
integers computed before anything is allocated and compared with one limit,
:func:`max_bytes_limit`: the keyword ``max_bytes=`` of the call, else the environment variable
``KINRED_MAX_BYTES``, else :data:`DEFAULT_MAX_BYTES`. Past the limit the call raises
:class:`~kinred.errors.TooLarge` (through :func:`kinred._validate.check_alloc`, the preflight
shared by every large allocation of kinred). The default is a fixed number of bytes, not a
fraction of the memory free at the time, so that a call is refused or accepted the same way on
every machine and in every run.
"""

from __future__ import annotations

from .._validate import (  # the one limit of every preflight (kinred._validate.check_alloc)
    DEFAULT_MAX_BYTES,
    ENV_MAX_BYTES,
    fmt_bytes,
    fmt_count,
    max_bytes_limit,
    parse_bytes,
)

__all__ = [
    "DEFAULT_MAX_BYTES",
    "ENV_MAX_BYTES",
    "max_bytes_limit",
    "parse_bytes",
    "fmt_count",
    "fmt_bytes",
]

#: Bytes kept per point of a 1-D quantization: levels, points and weights (float64 each).
POINT_BYTES = 24
#: Levels per chunk when quantiles are evaluated; cells per chunk of the exact 1-D error.
LEVEL_CHUNK = 8192
ERROR_CHUNK = 512
#: Temporaries per level of one quantile chunk (scipy measured ≤ 250 B, truncnorm) and per
#: cell of one error chunk (20 quantile evaluations and the piece arrays).
LEVEL_WORK = 2048
CELL_WORK = 32768
#: Bytes per atom for an :class:`~kinred.measures.Empirical1D` copy of a 1-D atomic factor.
EMPIRICAL_BYTES = 128
#: Temporaries of one block of atoms (the rows per block follow from it).
BLOCK_BYTES = 16 * 2**20
#: Python objects and small arrays of any stage.
OVERHEAD = 2**20


def atom_bytes(dim: int) -> int:
    """Bytes per materialized atom: points (8·dim), weights (8), and the finiteness and sign
    masks that :class:`~kinred.measures.Atomic` checks (dim + 16)."""
    return 9 * dim + 24


def row_work(width: int) -> int:
    """Temporaries per row of a block of atoms whose widest row has ``width`` entries (grid
    digits, the base rows of a push-forward, the projection's work)."""
    return 128 * (width + 4)


def quantile_bytes(points: int, largest: int, empirical: int = 0) -> int:
    """Peak of building 1-D quantizations with ``points`` points in all (at most ``largest``
    in one), and copying ``empirical`` atoms of 1-D atomic factors; also covers their exact
    error (chunked, its temporaries fit the same workspace)."""
    work = max(LEVEL_WORK * min(largest, LEVEL_CHUNK), CELL_WORK * min(largest, ERROR_CHUNK))
    return OVERHEAD + POINT_BYTES * points + EMPIRICAL_BYTES * empirical + work


def block_rows(width: int) -> int:
    """Rows per block of atoms so that one block's temporaries stay within :data:`BLOCK_BYTES`."""
    return max(1, BLOCK_BYTES // row_work(width))


def chunks_bytes(rows: int, width: int) -> int:
    """Peak of producing one block of ``rows`` atoms whose widest row has ``width`` entries."""
    return OVERHEAD + rows * row_work(width)


def materialize_bytes(n_atoms: int, dim: int, width: int) -> int:
    """Peak of :meth:`Quantization.materialize`: the atom array and one block of temporaries."""
    return n_atoms * atom_bytes(dim) + chunks_bytes(min(n_atoms, block_rows(width)), width)


def largest(fits, hi: int) -> int:
    """Largest ``k`` in ``[1, hi]`` with ``fits(k)`` for a monotone ``fits`` (0 if none)."""
    if not fits(1):
        return 0
    lo = 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid - 1)
    return lo
