"""Short reprs of result objects: shapes and headline numbers, never whole arrays.

A result holding ``(T,)`` or ``(T, N, d)`` series would print them in full with the dataclass
repr (thousands of lines); :func:`result_repr` prints each field in one short item
(:func:`brief`) and wraps the items; :func:`table` lays out a few rows of series for the
``summary()`` methods.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Sequence

import numpy as np

from ._validate import fmt_count

__all__ = ["brief", "result_repr", "table", "sample_rows"]

_WIDTH = 96
_MAX_TEXT = 80


def _num(v) -> str:
    v = float(v)
    return repr(v) if not math.isfinite(v) else f"{v:.4g}"


def _array(a: np.ndarray) -> str:
    if a.ndim == 0 and a.dtype.kind in "biufU":      # a 0-d array (e.g. read from an .npz)
        return brief(a.item())
    if a.size <= 4 and a.ndim <= 1 and a.dtype.kind in "biuf":
        return "[" + ", ".join(_num(v) if a.dtype.kind == "f" else str(v) for v in a) + "]"
    shape = "(" + ", ".join(map(str, a.shape)) + ("," if a.ndim == 1 else "") + ")"
    if a.dtype.kind == "b":
        return f"<{shape} bool, {int(np.count_nonzero(a))} true>"
    if a.dtype.kind in "iuf" and a.size:
        fin = a[np.isfinite(a)] if a.dtype.kind == "f" else a
        rng = f" in [{_num(fin.min())}, {_num(fin.max())}]" if fin.size else " all non-finite"
        return f"<{shape} {a.dtype.name}{rng}>"
    return f"<{shape} {a.dtype.name}>"


def brief(value) -> str:
    """One short item for ``value``: arrays as shape, dtype and range; mappings by key;
    floats with 4 significant digits; long text cut.

    Examples
    --------
    >>> brief(np.arange(6.0).reshape(2, 3)), brief(np.array([0.5, 2.0])), brief(10**400)
    ('<(2, 3) float64 in [0, 5]>', '[0.5, 2]', '1.000e+400')
    """
    if isinstance(value, np.ndarray):
        return _array(value)
    if isinstance(value, (float, np.floating)):
        return _num(value)
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return fmt_count(value)                   # any size, exact up to 12 digits
    if isinstance(value, Mapping):
        items = [f"{k!r}: {brief(v)}" for k, v in list(value.items())[:8]]
        more = f", … {len(value) - 8} more" if len(value) > 8 else ""
        return "{" + ", ".join(items) + more + "}"
    if isinstance(value, (list, tuple)) and len(value) > 6:
        return f"<{type(value).__name__} of {len(value)}>"
    text = repr(value)
    return text if len(text) <= _MAX_TEXT else text[:_MAX_TEXT - 1] + "…"


def _wrap(head: str, items: Sequence[str]) -> str:
    lines, cur = [], head + "("
    for i, item in enumerate(items):
        piece = item + (", " if i < len(items) - 1 else ")")
        if len(cur) + len(piece) > _WIDTH and cur.strip() and not cur.endswith("("):
            lines.append(cur.rstrip())
            cur = "    "
        cur += piece
    if not items:
        cur += ")"
    return "\n".join(lines + [cur])


def result_repr(obj, headline: Sequence[tuple[str, object]] = (),
                skip: Sequence[str] = ()) -> str:
    """``Name(headline..., field=brief(value), ...)`` wrapped at 96 columns.

    ``headline`` items ``(name, value)`` come first (a ``str`` value is printed as it is; an
    empty name prints the value alone); dataclass fields follow unless listed in ``skip``.
    """
    items = [(f"{k}=" if k else "") + (v if isinstance(v, str) else brief(v))
             for k, v in headline]
    if dataclasses.is_dataclass(obj):
        items += [f"{f.name}={brief(getattr(obj, f.name))}" for f in dataclasses.fields(obj)
                  if f.repr and f.name not in skip]
    return _wrap(type(obj).__name__, items)


def sample_rows(n: int, rows: int) -> np.ndarray:
    """At most ``rows`` indices out of ``range(n)``, evenly spread, first and last included."""
    if n <= rows:
        return np.arange(n)
    return np.unique(np.rint(np.linspace(0, n - 1, max(rows, 2))).astype(int))


def table(columns: Mapping[str, np.ndarray], rows: np.ndarray) -> str:
    """The rows ``rows`` of equally long columns as a text table (4 significant digits)."""
    names = list(columns)
    cells = [[_num(columns[k][i]) if np.asarray(columns[k]).dtype.kind == "f"
              else str(columns[k][i]) for k in names] for i in rows]
    widths = [max([len(k)] + [len(r[j]) for r in cells]) for j, k in enumerate(names)]
    out = ["  ".join(k.rjust(w) for k, w in zip(names, widths))]
    out += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join(out)
