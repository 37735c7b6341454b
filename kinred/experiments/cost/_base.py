"""The parts every study of ``kinred cost`` shares.

* :class:`Study` -- one knob: its config class, ``run``, ``n_units``, ``table``, ``figure``,
  ``headline``; :func:`registry` checks a list of studies and freezes it in report order.
* :class:`StudyConfig` -- base of the per-study frozen config dataclasses: the ``full``,
  ``quick`` and ``smoke`` presets and compact validation helpers.
* :func:`clock` (how every time is measured), :func:`pareto_front`, :func:`time_to_reach`,
  :func:`draw_front` (the grey front of every Pareto plot), :func:`progress_bar`,
  :func:`machine_info`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import platform
import time
import types
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from ..._rng import member_seed
from ..._validate import as_choice, as_float, as_int
from ...errors import InvalidInput

#: The config presets of every study, from largest to smallest.
PRESETS = ("full", "quick", "smoke")


class StudyConfig:
    """Mixin of the frozen config dataclass of a study.

    Subclasses are ``@dataclass(frozen=True)`` whose defaults are the full study, set
    ``study`` (the name used in error messages) and the field overrides ``_QUICK`` (about a
    minute for all studies together) and ``_SMOKE`` (seconds, for the tests), and validate in
    ``__post_init__`` with the helpers ``_ints``, ``_floats``, ``_each`` and ``_multiple``
    (argument names in messages: ``<study>.<field>``).
    """

    study: ClassVar[str] = ""
    _QUICK: ClassVar[dict] = {}
    _SMOKE: ClassVar[dict] = {}

    @classmethod
    def preset(cls, name: str = "full", **overrides):
        """The preset ``name`` (``"full"``, ``"quick"`` or ``"smoke"``) with some fields replaced."""
        as_choice(name, "preset", PRESETS)
        known = {f.name for f in dataclasses.fields(cls)}
        for key in overrides:
            if key not in known:
                raise InvalidInput(f"{cls.study} has no setting {key!r}; valid: "
                                   f"{', '.join(sorted(known))}")
        base = {"full": {}, "quick": cls._QUICK, "smoke": cls._SMOKE}[name]
        return cls(**{**base, **overrides})

    @classmethod
    def full(cls, **overrides):
        """The full study (the dataclass defaults)."""
        return cls.preset("full", **overrides)

    @classmethod
    def quick(cls, **overrides):
        """Reduced sizes (the whole cost study in about a minute on 2 cores)."""
        return cls.preset("quick", **overrides)

    @classmethod
    def smoke(cls, **overrides):
        """Tiny sizes, every code path (seconds; for the tests)."""
        return cls.preset("smoke", **overrides)

    def to_json(self) -> dict:
        """The fields as JSON types (tuples as lists)."""
        return {k: (list(v) if isinstance(v, tuple) else v)
                for k, v in dataclasses.asdict(self).items()}

    # -- validation helpers ---------------------------------------------------------------
    def _name(self, field: str) -> str:
        return f"{self.study}.{field}"

    def _ints(self, *fields: str, low: int) -> None:
        for f in fields:
            as_int(getattr(self, f), self._name(f), low=low)

    def _floats(self, *fields: str, **bounds) -> None:
        for f in fields:
            as_float(getattr(self, f), self._name(f), **bounds)

    def _each(self, field: str, check, *args, **kwargs) -> tuple:
        """Check every value of the non-empty list ``field`` with ``check(v, name, ...)``."""
        values = getattr(self, field)
        if isinstance(values, (str, bytes)) or not isinstance(values, (tuple, list)):
            raise InvalidInput(f"{self._name(field)} must be a tuple of knob values, "
                               f"got {values!r}")
        if not values:
            raise InvalidInput(f"{self._name(field)} must be non-empty (a list of knob values)")
        for v in values:
            check(v, self._name(field), *args, **kwargs)
        object.__setattr__(self, field, tuple(values))
        return tuple(values)

    def _multiple(self, field: str, of: str) -> None:
        n, m = getattr(self, field), getattr(self, of)
        if n % m:
            raise InvalidInput(f"{self._name(field)} must be a multiple of {self._name(of)}={m}, "
                               f"got {n}")


class Study:
    """One knob of ``kinred cost``: what it measures, how it is reported.

    A subclass sets the class attributes and implements the five methods (the registry
    refuses a study that does not); its module ends with ``STUDY = TheStudy()`` and the
    list in ``_registry.py`` names it.

    Attributes
    ----------
    name : str
        Key of the study: in ``cost.json``, ``cost_<name>.png``, ``kinred cost --only``.
    title : str
        Heading of its report section.
    Config : type
        Its frozen config dataclass (a :class:`StudyConfig`).
    key : int
        Its random streams: ``SeedSequence(seed, spawn_key=(key, ...))`` (:meth:`rng`) and
        ``(10 key + 1, ...)`` (:meth:`seed_of`); unique across the registry.
    """

    name: ClassVar[str]
    title: ClassVar[str]
    Config: ClassVar[type]
    key: ClassVar[int]

    def rng(self, seed: int, *index: int) -> np.random.Generator:
        """The study's generator ``default_rng(SeedSequence(seed, spawn_key=(key, *index)))``."""
        return np.random.default_rng(member_seed(seed, (self.key, *index)))

    def seed_of(self, seed: int, *index: int) -> np.random.SeedSequence:
        """Seed of one repetition: ``SeedSequence(seed, spawn_key=(10 key + 1, *index))``."""
        return member_seed(seed, (10 * self.key + 1, *index))

    def n_units(self, cfg) -> int:
        """How many times :meth:`run` calls ``bar.update(1)`` (the progress total)."""
        raise NotImplementedError

    def run(self, cfg, *, seed: int, bar) -> dict:
        """Measure; return JSON-ready numbers with a ``"setting"`` dict (shown in the report)."""
        raise NotImplementedError

    def table(self, result: dict):
        """The numbers of ``result`` as a :class:`kinred.report.Table`."""
        raise NotImplementedError

    def figure(self, result: dict, plt):
        """The Pareto plot of ``result``, drawn with the ``pyplot`` module ``plt``."""
        raise NotImplementedError

    def headline(self, result: dict, cfg) -> dict:
        """Quotable sentences: ``{key: {"text": sentence, numbers...}}`` (may be empty)."""
        raise NotImplementedError


#: What a :class:`Study` subclass must define.
_ATTRIBUTES = ("name", "title", "Config", "key")
_METHODS = ("n_units", "run", "table", "figure", "headline")


def registry(*studies: Study) -> Mapping:
    """Read-only ``{name: study}`` in the given (report) order; names and keys unique."""
    out = {}
    for s in studies:
        if not isinstance(s, Study):
            raise InvalidInput(f"studies must be Study objects, got {type(s).__name__}")
        missing = ([a for a in _ATTRIBUTES if not hasattr(s, a)]
                   + [m for m in _METHODS if getattr(type(s), m) is getattr(Study, m)])
        if missing:
            raise InvalidInput(f"study {type(s).__name__} does not define {', '.join(missing)}")
        if s.name in out or s.key in {t.key for t in out.values()}:
            raise InvalidInput(f"study {s.name!r} (key {s.key}) repeats a name or a key")
        out[s.name] = s
    return types.MappingProxyType(out)


def clock(fn, *, min_time: float = 0.02, max_repeat: int = 5):
    """``(result, seconds)``: one call, or the minimum of up to ``max_repeat`` when it is fast.

    Wall-clock seconds of single calls (the minimum of a few repetitions below ``min_time``);
    the studies call it after a warm-up run, so numba compilation is not timed.
    """
    t0 = time.perf_counter()
    out = fn()
    best = time.perf_counter() - t0
    n = 1
    while best < min_time and n < max_repeat:
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        n += 1
    return out, best


def pareto_front(times, errors) -> np.ndarray:
    """Indices of the non-dominated points (no other point is both faster and more accurate).

    Sorted by time; NaN errors are ignored.

    Examples
    --------
    >>> pareto_front([1.0, 2.0, 3.0, 1.5], [0.5, 0.1, 0.2, 0.6]).tolist()
    [0, 1]
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(errors, dtype=float)
    order = np.argsort(t, kind="stable")
    keep, best = [], math.inf
    for i in order:
        if np.isfinite(e[i]) and e[i] < best:
            keep.append(int(i))
            best = e[i]
    return np.array(keep, dtype=int)


def time_to_reach(times, errors, target: float) -> float | None:
    """Smallest measured time whose error is ``<= target`` (None if no point reaches it).

    Examples
    --------
    >>> time_to_reach([1.0, 2.0, 4.0], [1e-2, 1e-4, 1e-6], 1e-3)
    2.0
    >>> time_to_reach([1.0], [1e-2], 1e-3) is None
    True
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(errors, dtype=float)
    ok = np.isfinite(e) & (e <= target)
    return float(t[ok].min()) if np.any(ok) else None


def draw_front(ax, times, errors) -> None:
    """Draw the Pareto front of the points (a grey step line) on the axes ``ax``."""
    idx = pareto_front(times, errors)
    if idx.size > 1:
        t = np.asarray(times)[idx]
        e = np.asarray(errors)[idx]
        ax.step(t, e, where="post", color="0.6", lw=4, alpha=0.35, zorder=0, label="Pareto front")


def label_points(ax, xs, ys, texts, *, color=None, fontsize: int = 7) -> None:
    """Write ``texts`` next to the points ``(xs, ys)`` of ``ax`` without overlaps.

    Each label takes the first of a few offsets (right-above, right-below, left-above,
    left-below, further out) whose box does not overlap a label already placed on the axes
    (the axes keep the boxes, so successive calls avoid each other). Call it after the
    curves are drawn, so that the axis limits are final.
    """
    ax.autoscale_view()
    fig = ax.figure
    px = fig.dpi / 72.0                       # pixels per point
    placed = ax.__dict__.setdefault("_kinred_label_boxes", [])
    offsets = [(4, 3), (4, -3 - fontsize), (-4, 3), (-4, -3 - fontsize), (4, 3 + 1.6 * fontsize),
               (4, -3 - 2.6 * fontsize), (-4, 3 + 1.6 * fontsize), (-4, -3 - 2.6 * fontsize)]
    for x, y, text in zip(xs, ys, texts):
        if not (np.isfinite(x) and np.isfinite(y)) or (ax.get_yscale() == "log" and y <= 0):
            continue
        X, Y = ax.transData.transform((x, y))
        w, h = 0.62 * fontsize * len(text) * px, fontsize * px
        for dx, dy in offsets:
            left = X + dx * px if dx > 0 else X + dx * px - w
            box = (left, Y + dy * px, left + w, Y + dy * px + h)
            if not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3]
                       for b in placed):
                break
        placed.append(box)
        ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points",
                    fontsize=fontsize, color=color, ha="left" if dx > 0 else "right", va="bottom")


def progress_bar(total: int, enabled: bool):
    """A tqdm bar on stderr (time remaining), disabled unless ``enabled``."""
    from tqdm.auto import tqdm

    return tqdm(total=total, disable=not enabled, desc="kinred cost", unit="run", leave=True,
                dynamic_ncols=True, mininterval=0.5)


def machine_info() -> dict:
    """CPU model, logical cores, Python and NumPy versions of this machine."""
    model = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:  # pragma: no cover - non-Linux
        pass
    return {"cpu": model, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "platform": platform.platform()}
