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
:class:`~kinred.errors.TooLarge`. The default is a fixed number of bytes, not a fraction of the
memory free at the time, so that a call is refused or accepted the same way on every machine
and in every run.
"""

from __future__ import annotations

import math
import os
import re

from .._validate import as_int
from ..errors import InvalidInput

__all__ = [
    "DEFAULT_MAX_BYTES",
    "ENV_MAX_BYTES",
    "max_bytes_limit",
    "parse_bytes",
    "fmt_count",
    "fmt_bytes",
]

#: Default memory limit of every quantization stage (bytes): 2 GiB. Override per call with
#: ``max_bytes=`` or for a process with the environment variable :data:`ENV_MAX_BYTES`.
DEFAULT_MAX_BYTES = 2 * 2**30

#: Environment variable read by :func:`max_bytes_limit` (``"8G"``, ``"512M"``, ``"1e9"``, ...).
ENV_MAX_BYTES = "KINRED_MAX_BYTES"

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

_UNITS = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40, "p": 2**50}
_BYTES_RE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:e[+]?[0-9]+)?)\s*([kmgtp]?)(?:i?b)?\s*$", re.I)


def parse_bytes(text, name: str) -> int:
    """A byte count from ``text``: an integer, a float such as ``1e9``, or a number with a
    binary suffix ``K``, ``M``, ``G``, ``T``, ``P`` (optionally followed by ``B`` or ``iB``).

    Examples
    --------
    >>> parse_bytes("512M", "x"), parse_bytes("2GiB", "x"), parse_bytes("1e9", "x")
    (536870912, 2147483648, 1000000000)
    """
    m = _BYTES_RE.match(str(text))
    value = float(m.group(1)) * _UNITS[m.group(2).lower()] if m else math.nan
    if not (math.isfinite(value) and value >= 1):
        raise InvalidInput(
            f"{name} must be a byte count >= 1 such as 2147483648, 1e9, 512M or 4G, got {text!r}"
        )
    return int(value)


def max_bytes_limit(max_bytes=None) -> int:
    """The memory limit of a quantization stage, in bytes.

    ``max_bytes`` if given (an int, or a string such as ``"4G"``), else the environment
    variable ``KINRED_MAX_BYTES``, else :data:`DEFAULT_MAX_BYTES` (2 GiB).
    """
    if max_bytes is not None:
        if isinstance(max_bytes, str):
            return parse_bytes(max_bytes, "max_bytes")
        return as_int(max_bytes, "max_bytes", low=1)
    env = os.environ.get(ENV_MAX_BYTES, "").strip()
    return parse_bytes(env, f"environment variable {ENV_MAX_BYTES}") if env else DEFAULT_MAX_BYTES


def fmt_count(n: int) -> str:
    """An exact integer if it has at most 12 digits, else ``m.mmme+E`` (any size, no ``str(n)``).

    Examples
    --------
    >>> fmt_count(123456), fmt_count(50**18), fmt_count(10**1000)
    ('123456', '3.815e+30', '1.000e+1000')
    """
    n = int(n)
    if n < 10**12:
        return str(n)
    if n.bit_length() < 1000:
        return f"{float(n):.3e}"
    lg = math.log10(n)  # exact enough: a 1e6-digit count still has ~9 significant digits
    e = math.floor(lg)
    m = round(10 ** (lg - e), 3)
    if m >= 10.0:
        m, e = m / 10, e + 1
    return f"{m:.3f}e+{e}"


def fmt_bytes(b: int) -> str:
    """Bytes in binary units (``"4.57 GiB"``), or ``"≈m.mmme+E bytes"`` beyond PiB."""
    b = int(b)
    for unit, k in (("PiB", 5), ("TiB", 4), ("GiB", 3), ("MiB", 2), ("KiB", 1)):
        if b >= 2 ** (10 * k):
            if k == 5 and b >= 2**60:
                return f"≈{fmt_count(b)} bytes"
            return f"{b / 2 ** (10 * k):.3g} {unit}"
    return f"{b} bytes"


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
