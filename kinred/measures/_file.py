"""Measure files (TOML) for ``kinred quantize`` and the experiments.

Format (see ``docs/measures-file.md``)::

    name = "optional label"           # optional
    description = "optional text"     # optional

    [[coordinate]]                    # one table per coordinate, in order
    dist = "beta"                     # any scipy.stats continuous distribution, or "dirac"
    params = {a = 2.0, b = 3.0}       # keyword parameters of that distribution (shapes, loc, scale)
    support = [0.0, 1.0]              # truncation [a, b]; required for unbounded laws
    repeat = 50                       # optional: this coordinate 50 times (default 1)
    decay = 0.8                       # optional: copy i (0-based) is the law of decay**i * X

    [[coordinate]]
    dist = "dirac"
    at = 0.5                          # location of the point mass

A mixture replaces the top-level ``[[coordinate]]`` tables by components::

    [[component]]
    weight = 0.5
    [[component.coordinate]]
    dist = "uniform"
    params = {loc = 0.0, scale = 1.0}

    [[component]]
    weight = 0.5
    [[component.coordinate]]
    dist = "uniform"
    params = {loc = 2.0, scale = 1.0}

A uniform law may be written by its interval, as ``Uniform(a, b)`` in Python:
``params = {a = 2.0, b = 3.0}`` (or ``{low = 2.0, high = 3.0}``), or by scipy's
``{loc = 2.0, scale = 1.0}`` (the interval ``[loc, loc + scale]``); one spelling per table.

Coordinates make a :class:`~kinred.measures.TensorProduct`; components a
:class:`~kinred.measures.Mixture` (weights must sum to one). Unknown keys, unknown
distributions, invalid parameters, NaN, empty or reversed supports and bad weights raise
:class:`kinred.errors.ConfigError` naming the file and the key.
"""

from __future__ import annotations

import copy
import json
import math
import numbers
import os
import re
import sys

import numpy as np

from .._validate import _short, check_alloc, fmt_count
from ..errors import ConfigError, InvalidInput
from ._base import Dirac, Measure
from ._composite import Mixture, TensorProduct
from ._univariate import Univariate

__all__ = ["load_measure", "measure_from_dict"]

_TOP_KEYS = {"name", "description", "coordinate", "component"}
_COORD_KEYS = {"dist", "params", "support", "repeat", "decay", "at"}
_COMP_KEYS = {"weight", "coordinate"}


def _err(source: str, key: str, msg: str) -> ConfigError:
    return ConfigError(f"{source}: {key}: {msg}")


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key_text(key) -> str:
    """A key as TOML writes it (quoted when it is not bare), so messages stay on one line."""
    if isinstance(key, str) and _BARE_KEY.match(key):
        return key
    return json.dumps(key) if isinstance(key, str) else repr(key)


def _number(value, source, key) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise _err(source, key, f"must be a number, got {_short(value)}")
    v = float(value)
    if not math.isfinite(v):
        raise _err(source, key, f"must be finite, got {v}")
    return v


def _check_keys(table, allowed, source, where):
    if not isinstance(table, dict):
        raise _err(source, where, f"must be a table, got {_short(table)}")
    unknown = sorted(set(table) - allowed, key=str)
    if unknown:
        raise _err(
            source, f"{where}.{_key_text(unknown[0])}" if where else _key_text(unknown[0]),
            f"unknown key; valid keys are {', '.join(sorted(allowed))}",
        )


#: The interval spellings of a uniform law's parameters, besides scipy's ``{loc, scale}``.
_UNIFORM_ENDS = (("a", "b"), ("low", "high"))


def _uniform_params(pvals: dict, source: str, key: str) -> dict:
    """scipy's ``{loc, scale}`` for a uniform law given by its interval ``{a, b}`` or
    ``{low, high}`` (as ``Uniform(a, b)``); scipy's own spelling is passed through.

    Mixing spellings (even consistent ones), one end without the other, any other key, or
    ``a >= b`` is a :class:`~kinred.errors.ConfigError` naming the keys.
    """
    ends = [pair for pair in _UNIFORM_ENDS if set(pair) & set(pvals)]
    if not ends:
        return pvals
    lo_k, hi_k = ends[0]
    others = sorted(set(pvals) - {lo_k, hi_k})
    if len(ends) > 1 or others:
        raise _err(source, f"{key}.params",
                   f"uniform: give the interval one way, {{a, b}}, {{low, high}} or scipy's "
                   f"{{loc, scale}} (the interval [loc, loc + scale]); got the keys "
                   f"{', '.join(sorted(pvals))}")
    missing = [k for k in (lo_k, hi_k) if k not in pvals]
    if missing:
        raise _err(source, f"{key}.params.{missing[0]}",
                   f"missing: uniform {{{lo_k}, {hi_k}}} needs both ends of the interval")
    lo, hi = pvals[lo_k], pvals[hi_k]
    if not (lo < hi and math.isfinite(hi - lo)):
        raise _err(source, f"{key}.params",
                   f"uniform needs {lo_k} < {hi_k} (a finite, positive width), got "
                   f"{lo_k} = {lo!r}, {hi_k} = {hi!r}")
    return {"loc": lo, "scale": hi - lo}


def _coordinates(tables, source, where) -> list[Measure]:
    if not isinstance(tables, list) or not tables:
        raise _err(source, where, "must be a non-empty array of tables ([[coordinate]])")
    out: list[Measure] = []
    total = 0
    for i, t in enumerate(tables):
        key = f"{where}[{i}]"
        _check_keys(t, _COORD_KEYS, source, key)
        repeat = t.get("repeat", 1)
        if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
            raise _err(source, f"{key}.repeat", f"must be an integer >= 1, got {_short(repeat)}")
        # the coordinates' objects (a frozen scipy law ~13 kB, a Dirac ~0.6 kB), before building
        total += (1024 if t.get("dist") == "dirac" else 16384) * repeat
        check_alloc(total, f"{source}: {key}.repeat = {fmt_count(repeat)}: "
                           f"{fmt_count(len(out) + repeat)} coordinates",
                    "fewer coordinates (each is built as an object of 1 to 16 KiB)")
        decay = _number(t.get("decay", 1.0), source, f"{key}.decay")
        if decay <= 0:
            raise _err(source, f"{key}.decay", f"must be > 0, got {decay}")
        if (repeat - 1) * math.log(decay) > 709.0:  # decay**(repeat - 1) beyond float64
            raise _err(source, f"{key}.decay", f"decay**(repeat - 1) = {decay}**{repeat - 1} "
                       "overflows float64: use decay <= 1 or fewer repeats")
        if "dist" not in t:
            raise _err(source, f"{key}.dist", "missing (a scipy.stats distribution name or 'dirac')")
        name = t["dist"]
        if not isinstance(name, str):
            raise _err(source, f"{key}.dist", f"must be a string, got {_short(name)}")
        if name == "dirac":
            for bad in ("params", "support"):
                if bad in t:
                    raise _err(source, f"{key}.{bad}", "not used by dist = 'dirac' (give 'at')")
            if "at" not in t:
                raise _err(source, f"{key}.at", "missing: location of the point mass")
            at = _number(t["at"], source, f"{key}.at")
            out.extend(Dirac(at * decay**r) for r in range(repeat))
            continue
        if "at" in t:
            raise _err(source, f"{key}.at", "only used with dist = 'dirac'")
        from scipy import stats  # imported here: scipy.stats takes ~1 s of `import kinred`

        gen = getattr(stats, name, None)
        if not isinstance(gen, stats.rv_continuous):
            raise _err(
                source, f"{key}.dist",
                f"unknown distribution {_short(name)}: use a scipy.stats continuous distribution "
                "name (e.g. 'uniform', 'beta', 'norm', 'truncnorm') or 'dirac'",
            )
        params = t.get("params", {})
        if not isinstance(params, dict):
            raise _err(source, f"{key}.params", f"must be a table, got {_short(params)}")
        for k in params:
            if not (isinstance(k, str) and k.isidentifier()):
                raise _err(source, f"{key}.params.{_key_text(k)}",
                           f"not a parameter of {name} (parameter names are identifiers such as "
                           "loc, scale, a)")
        pvals = {k: _number(v, source, f"{key}.params.{k}") for k, v in params.items()}
        if name == "uniform":
            pvals = _uniform_params(pvals, source, key)
        try:
            shapes, loc, scale = gen._parse_args(**pvals)
        except TypeError as exc:
            raise _err(source, f"{key}.params", f"invalid parameters for {name}: {exc}") from None
        if not (scale > 0) or not bool(np.all(gen._argcheck(*shapes))):
            raise _err(source, f"{key}.params", f"invalid parameter values for {name}: {pvals}")
        support = _support(t, source, key)
        width = scale if support is None else support[1] - support[0]
        _check_underflow(decay, repeat, width, source, key)
        laws = _scaled_laws(gen, shapes, loc, scale, decay, repeat)
        for r in range(repeat):
            f = decay**r
            try:
                sup = None if support is None else (support[0] * f, support[1] * f)
                out.append(Univariate(laws[r], support=sup))
            except InvalidInput as exc:
                raise _err(source, key, str(exc)) from None
    return out


def _scaled_laws(gen, shapes, loc, scale, decay, repeat) -> list:
    """The frozen laws ``gen(*shapes, loc=loc·decay^r, scale=scale·decay^r)``, ``r < repeat``.

    Freezing a scipy law builds a new generator instance (about 2 ms: scipy rebuilds its
    docstring and signatures), which made the 400 coordinates of a shipped scene cost most of
    a second; the copies share the first law's generator and differ in ``loc`` and ``scale``
    only (a frozen law evaluates ``dist.method(x, *args, **kwds)``).
    """
    laws: list = []
    for r in range(repeat):
        f = decay**r
        if not laws:
            laws.append(gen(*shapes, loc=loc * f, scale=scale * f))
            continue
        law = copy.copy(laws[0])
        law.kwds = {**laws[0].kwds, "loc": loc * f, "scale": scale * f}
        laws.append(law)
    return laws


def _support(t, source, key) -> tuple | None:
    """The coordinate's ``support = [a, b]`` (None when absent), checked: ``a < b``."""
    if "support" not in t:
        return None
    s = t["support"]
    if not (isinstance(s, list) and len(s) == 2):
        raise _err(source, f"{key}.support", f"must be [a, b], got {_short(s)}")
    a = _number(s[0], source, f"{key}.support[0]")
    b = _number(s[1], source, f"{key}.support[1]")
    if not a < b:
        raise _err(source, f"{key}.support", f"needs a < b (a positive width), got [{a}, {b}]")
    return (a, b)


def _check_underflow(decay: float, repeat: int, width: float, source: str, key: str) -> None:
    """Refuse a ``decay`` whose last copy ``decay**(repeat - 1)·X`` has a width (scale or
    support) below the smallest normal float64 (computed in log space: it would be 0 or lose
    its digits, and the law would have no support)."""
    if decay >= 1.0 or repeat < 2:
        return
    log_w = math.log(width) + (repeat - 1) * math.log(decay)
    tiny = sys.float_info.min
    if log_w < math.log(tiny):
        r = min(repeat - 1, max(1, math.ceil((math.log(tiny) - math.log(width))
                                             / math.log(decay))))
        raise _err(source, f"{key}.decay",
                   f"the widths underflow: {width:g}·decay**r is below the smallest float64 "
                   f"{tiny:.3g} from copy r = {r} on (decay = {decay:g}; the last, r = "
                   f"{repeat - 1}, ≈ 10^{log_w / math.log(10):.0f}), so those laws would "
                   "have width 0 and no support; "
                   "use a larger decay or fewer repeats")


def measure_from_dict(data: dict, source: str = "<measure>") -> Measure:
    """Build a measure from the parsed TOML table ``data`` (format in the module docstring).

    Parameters
    ----------
    data : dict
        The parsed file.
    source : str
        Name used in error messages (the file path).

    Examples
    --------
    >>> mu = measure_from_dict({"coordinate": [
    ...     {"dist": "uniform", "params": {"loc": 0.0, "scale": 2.0}, "repeat": 3, "decay": 0.5}]})
    >>> mu.support_widths()
    array([2. , 1. , 0.5])
    """
    _check_keys(data, _TOP_KEYS, source, "")
    if ("coordinate" in data) == ("component" in data):
        raise _err(source, "coordinate/component",
                   "give exactly one of [[coordinate]] (a tensor product) or [[component]] (a mixture)")
    if "coordinate" in data:
        return TensorProduct(_coordinates(data["coordinate"], source, "coordinate"))
    comps = data["component"]
    if not isinstance(comps, list) or not comps:
        raise _err(source, "component", "must be a non-empty array of tables ([[component]])")
    measures, weights = [], []
    for l, c in enumerate(comps):
        key = f"component[{l}]"
        _check_keys(c, _COMP_KEYS, source, key)
        if "weight" not in c:
            raise _err(source, f"{key}.weight", "missing")
        w = _number(c["weight"], source, f"{key}.weight")
        if w < 0:
            raise _err(source, f"{key}.weight", f"must be >= 0, got {w}")
        weights.append(w)
        measures.append(TensorProduct(_coordinates(c.get("coordinate"), source, f"{key}.coordinate")))
    dims = {m.dim for m in measures}
    if len(dims) > 1:
        raise _err(source, "component", f"all components need the same number of coordinates, got {[m.dim for m in measures]}")
    s = sum(weights)
    if abs(s - 1.0) > 1e-9:
        raise _err(source, "component.weight", f"weights must sum to one, got sum {s!r}")
    return Mixture(measures, weights)


def load_measure(path: str | os.PathLike) -> Measure:
    """Read a measure file (TOML; format in ``docs/measures-file.md``).

    Raises
    ------
    ConfigError
        Missing file, a directory, not UTF-8, invalid TOML, or any invalid key/value (the
        message names file and key).
    """
    from ..io import read_toml

    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise InvalidInput(f"path must be a str or os.PathLike, got {path!r}")
    path = os.fspath(path)
    return measure_from_dict(read_toml(path, what="measure file"), source=path)
