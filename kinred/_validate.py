"""Input validation shared by every public function.

Each helper raises :class:`kinred.errors.InvalidInput` with a message naming the argument,
the bad value and what would be valid.
"""

from __future__ import annotations

import numbers
from typing import Iterable

import numpy as np

from .errors import InvalidInput

__all__ = [
    "as_array",
    "as_float",
    "as_int",
    "as_choice",
    "as_weights",
    "as_span",
]


def _short(value) -> str:
    r = repr(value)
    return r if len(r) <= 80 else r[:77] + "..."


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
    try:
        arr = np.array(value, dtype=dtype, copy=copy) if copy else np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
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
    if finite and arr.size and not np.all(np.isfinite(arr)):
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
    v = float(value)
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


def as_choice(value, name: str, choices: Iterable[str]) -> str:
    """Check that ``value`` is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
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
    """A time interval ``(t0, t1)`` of finite floats with ``t1 > t0``."""
    try:
        t0, t1 = t_span
    except (TypeError, ValueError):
        raise InvalidInput(f"{name} must be a pair (t0, t1), got {_short(t_span)}") from None
    t0 = as_float(t0, f"{name}[0]")
    t1 = as_float(t1, f"{name}[1]", low=t0, low_open=True)
    return t0, t1
