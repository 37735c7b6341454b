"""Input validation shared by every public function, and the one memory preflight.

Each ``as_*`` helper raises :class:`kinred.errors.InvalidInput` with a message naming the
argument, the bad value and what would be valid.

:func:`check_alloc` is the preflight of every large allocation whose size follows from the
user's arguments (quantizations, saved trajectories, projection matrices, ensemble results,
the ``O(N²)`` reference pair sums): the bytes are computed from exact integers before anything
is allocated and compared with one limit, :func:`max_bytes_limit` -- the keyword
``max_bytes=`` of calls that have one, else the environment variable ``KINRED_MAX_BYTES``
(e.g. ``8G``), else :data:`DEFAULT_MAX_BYTES` (2 GiB). Past it the call raises
:class:`~kinred.errors.TooLarge` naming what would be allocated, the bytes, the limit and how
to change it. The default is a fixed number of bytes, not a fraction of the free memory, so
that a call is refused or accepted the same way on every machine and in every run.
"""

from __future__ import annotations

import math
import numbers
import os
import re
from typing import Callable, Iterable

import numpy as np

from .errors import InvalidInput, TooLarge

__all__ = [
    "as_array",
    "as_float",
    "as_int",
    "as_bool",
    "as_choice",
    "as_weights",
    "as_span",
    "DEFAULT_MAX_BYTES",
    "ENV_MAX_BYTES",
    "max_bytes_limit",
    "parse_bytes",
    "limit_text",
    "check_alloc",
    "fmt_count",
    "fmt_bytes",
]


def _short(value) -> str:
    """``repr(value)`` on one line (arrays print several), at most 80 characters."""
    r = " ".join(repr(value).split())
    return r if len(r) <= 80 else r[:77] + "..."


def _all_finite(arr: np.ndarray) -> bool:
    """No NaN or Inf in ``arr``. A large float array is first summed (one pass, no
    temporary): a NaN or an Inf makes the sum non-finite, so a finite sum clears it; a
    non-finite one (or an overflow) is settled element by element."""
    if arr.size >= 2 ** 16 and arr.dtype.kind in "fc":
        with np.errstate(all="ignore"):
            if np.isfinite(np.add.reduce(arr, axis=None)):
                return True
    return bool(np.all(np.isfinite(arr)))


def as_array(
    value,
    name: str,
    *,
    ndim: int | tuple[int, ...] | None = None,
    shape: tuple | None = None,
    finite: bool = True,
    dtype=np.float64,
    copy: bool = False,
) -> np.ndarray:
    """Convert ``value`` to an ndarray of ``dtype`` and check it.

    ``shape`` may contain ``None`` for free axes. ``finite`` rejects NaN and Inf.
    """
    if (isinstance(value, (np.ndarray, np.generic, complex)) and np.iscomplexobj(value)
            and not np.issubdtype(np.dtype(dtype), np.complexfloating)):
        raise InvalidInput(f"{name} must be real, got complex values {_short(value)}")
    try:
        arr = np.array(value, dtype=dtype, copy=copy) if copy else np.asarray(value, dtype=dtype)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InvalidInput(f"{name} must be a numeric array, got {_short(value)} ({exc})") from None
    if ndim is not None:
        allowed = (ndim,) if isinstance(ndim, int) else tuple(ndim)
        if arr.ndim not in allowed:
            raise InvalidInput(
                f"{name} must have {' or '.join(map(str, allowed))} dimension(s), "
                f"got an array of shape {arr.shape}"
            )
    if shape is not None:
        if arr.ndim != len(shape) or any(
            s is not None and s != a for s, a in zip(shape, arr.shape)
        ):
            want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
            raise InvalidInput(f"{name} must have shape {want}, got {arr.shape}")
    if finite and arr.size and not _all_finite(arr):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InvalidInput(
            f"{name} must be finite, got {arr[tuple(bad)]} at index {tuple(int(b) for b in bad)}"
        )
    return arr


def as_float(
    value,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Check a finite real scalar, optionally within [low, high] (open ends on request)."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise InvalidInput(f"{name} must be a real number, got {_short(value)}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond the float range
        raise InvalidInput(f"{name} must be finite (within the float range), got "
                           f"{fmt_count(value)}") from None
    if not np.isfinite(v):
        raise InvalidInput(f"{name} must be finite, got {v}")
    if low is not None and (v < low or (low_open and v == low)):
        raise InvalidInput(f"{name} must be {'>' if low_open else '>='} {low}, got {v}")
    if high is not None and (v > high or (high_open and v == high)):
        raise InvalidInput(f"{name} must be {'<' if high_open else '<='} {high}, got {v}")
    return v


def as_int(value, name: str, *, low: int | None = None, high: int | None = None) -> int:
    """Check an integer scalar, optionally within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, (numbers.Integral, np.integer)):
        if isinstance(value, (float, np.floating)) and float(value).is_integer():
            value = int(value)
        else:
            raise InvalidInput(f"{name} must be an integer, got {_short(value)}")
    v = int(value)
    if low is not None and v < low:
        raise InvalidInput(f"{name} must be >= {low}, got {v}")
    if high is not None and v > high:
        raise InvalidInput(f"{name} must be <= {high}, got {v}")
    return v


def as_bool(value, name: str) -> bool:
    """Check a boolean flag (``bool`` or ``numpy.bool_``; no other truthy objects)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidInput(f"{name} must be True or False, got {_short(value)}")
    return bool(value)


def as_choice(value, name: str, choices: Iterable[str]) -> str:
    """Check that ``value`` is one of ``choices`` (strings)."""
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        raise InvalidInput(f"{name} must be one of {', '.join(map(repr, choices))}; got {_short(value)}")
    return value


def as_weights(weights, name: str, n: int, *, atol: float = 1e-9) -> np.ndarray:
    """Probability weights of length ``n``: finite, >= 0, summing to one (within ``atol``).

    ``None`` gives uniform weights ``1/n``. The result is renormalized to sum exactly to one.
    """
    if weights is None:
        return np.full(n, 1.0 / n)
    w = as_array(weights, name, ndim=1)
    if w.shape[0] != n:
        raise InvalidInput(f"{name} must have length {n}, got length {w.shape[0]}")
    if np.any(w < 0):
        i = int(np.argmin(w))
        raise InvalidInput(f"{name} must be non-negative, got {w[i]} at index {i}")
    s = float(w.sum())
    if abs(s - 1.0) > atol:
        raise InvalidInput(f"{name} must sum to one (probability weights), got sum {s!r}")
    return w / s


def as_span(t_span, name: str = "t_span") -> tuple[float, float]:
    """A time interval ``(t0, t1)`` of finite floats with ``t1 > t0`` and a finite length."""
    try:
        t0, t1 = t_span
    except (TypeError, ValueError):
        raise InvalidInput(f"{name} must be a pair (t0, t1), got {_short(t_span)}") from None
    t0 = as_float(t0, f"{name}[0]")
    t1 = as_float(t1, f"{name}[1]", low=t0, low_open=True)
    if not math.isfinite(t1 - t0):
        raise InvalidInput(f"{name} must have a finite length t1 - t0 (in float64), got "
                           f"({t0!r}, {t1!r})")
    return t0, t1


# ------------------------------------------------------------------------------------------
# the memory preflight
# ------------------------------------------------------------------------------------------
#: Default memory limit of every preflighted allocation (bytes): 2 GiB. Override with the
#: environment variable :data:`ENV_MAX_BYTES` (or ``max_bytes=`` where a call has it).
DEFAULT_MAX_BYTES = 2 * 2**30

#: Environment variable read by :func:`max_bytes_limit` (``"8G"``, ``"512M"``, ``"1e9"``, ...).
ENV_MAX_BYTES = "KINRED_MAX_BYTES"

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
    """The memory limit in bytes: ``max_bytes`` if given (an int, or a string such as
    ``"4G"``), else the environment variable ``KINRED_MAX_BYTES``, else
    :data:`DEFAULT_MAX_BYTES` (2 GiB)."""
    if max_bytes is not None:
        if isinstance(max_bytes, str):
            return parse_bytes(max_bytes, "max_bytes")
        return as_int(max_bytes, "max_bytes", low=1)
    env = os.environ.get(ENV_MAX_BYTES, "").strip()
    return parse_bytes(env, f"environment variable {ENV_MAX_BYTES}") if env else DEFAULT_MAX_BYTES


def limit_text(limit: int, keyword: str | None = None) -> str:
    """How the limit is named in messages, and how to change it."""
    if keyword:
        return (f"the limit {keyword} = {fmt_bytes(limit)} (keyword {keyword}=, environment "
                f"variable {ENV_MAX_BYTES}; default {fmt_bytes(DEFAULT_MAX_BYTES)})")
    return (f"the limit of {fmt_bytes(limit)} (environment variable {ENV_MAX_BYTES}, e.g. "
            f"{ENV_MAX_BYTES}=8G; default {fmt_bytes(DEFAULT_MAX_BYTES)})")


def check_alloc(nbytes: int, what: str, hint: str | Callable[[], str] = "", *,
                max_bytes=None, keyword: str | None = None, detail: str = "",
                at_least: bool = False) -> int:
    """Raise :class:`~kinred.errors.TooLarge` before allocating ``nbytes`` past the limit.

    Parameters
    ----------
    nbytes : int
        What the call would allocate at its peak (an exact Python integer, any size).
    what : str
        The call or the arrays, e.g. ``"simulate: the saved states"``.
    hint : str or callable
        What would fit instead (a callable is evaluated only when the limit is exceeded).
    max_bytes : int or str, optional
        The call's own limit (keyword ``keyword``); default the environment, else 2 GiB.
    keyword : str, optional
        Name of the call's keyword that sets the limit, if it has one.
    detail : str
        Text after the bytes (``" for 10 atoms in dimension 3"``).
    at_least : bool
        ``nbytes`` is a lower bound.

    Returns
    -------
    int
        The limit in bytes.

    Examples
    --------
    >>> check_alloc(10**6, "x", max_bytes=2**20)
    1048576
    >>> check_alloc(2**40, "jl_matrix(k, d): a (k, d) matrix", "a smaller k", max_bytes=2**30)
    Traceback (most recent call last):
    ...
    kinred.errors.TooLarge: jl_matrix(k, d): a (k, d) matrix would allocate 1 TiB, more than ...
    """
    limit = max_bytes_limit(max_bytes)
    if nbytes <= limit:
        return limit
    hint = hint() if callable(hint) else hint
    least = "at least " if at_least else ""
    raise TooLarge(f"{what} would allocate {least}{fmt_bytes(nbytes)}{detail}, more than "
                   f"{limit_text(limit, keyword)}" + (f"; {hint}" if hint else ""))


def fmt_count(n: int) -> str:
    """An exact integer if it has at most 12 digits, else ``m.mmme+E`` (any size, no ``str(n)``).

    Examples
    --------
    >>> fmt_count(123456), fmt_count(50**18), fmt_count(10**1000)
    ('123456', '3.815e+30', '1.000e+1000')
    """
    n = int(n)
    if n < 0:
        return "-" + fmt_count(-n)
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
