"""The registry of pair-sum backends by name: :data:`PAIRSUMS`.

One registry serves both ways of naming a backend: ``Scene(pairsum="name")``
(:func:`~kinred.pairsum.as_pairsum`, the backend with its default options) and a scene file's
``[dynamics.pairsum] method = "name"`` (:mod:`kinred.scenefile`, with the options of the table
checked against the entry's :class:`~kinred.scenefile.Key` s). Registering a backend is one
call::

    register_pairsum("twin_copy", Numpy, doc="the numpy twin under another name")

after which ``Scene(effects, pairsum="twin_copy")`` and scene files with
``method = "twin_copy"`` build it, and the reference of ``docs/scene-file.md`` lists it.
"""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Callable

from .._schema import REQUIRED, Key, register_entry, unregister_entry, with_defaults
from ..errors import InvalidInput

__all__ = ["PairSumType", "PAIRSUMS", "register_pairsum", "unregister_pairsum", "make_pairsum"]


@dataclass(frozen=True)
class PairSumType:
    """A registered pair-sum backend (the ``method`` of ``[dynamics.pairsum]``, a name for
    ``Scene(pairsum=...)``).

    Attributes
    ----------
    make : callable
        ``make(**params) -> PairSum`` (absent optional keys are not passed); with ``mixed``
        also ``precision=`` (``dynamics.precision``).
    keys : tuple of Key
    doc : str
    mixed : bool
        The backend has a ``precision`` option (``"mixed"``: float32 pair sums); the others
        compute in float64 and refuse ``dynamics.precision = "mixed"``.
    """

    make: Callable
    keys: tuple
    doc: str = ""
    mixed: bool = False


_PAIRSUMS: dict[str, PairSumType] = {}
_BUILTIN: set = set()

#: The registered pair-sum backends by name, in order (a live read-only view).
PAIRSUMS = types.MappingProxyType(_PAIRSUMS)


def register_pairsum(name: str, make: Callable, *, keys: tuple = (), doc: str = "",
                     mixed: bool = False) -> PairSumType:
    """Register the pair-sum backend ``name`` for ``Scene(pairsum=name)`` and for scene files'
    ``[dynamics.pairsum]`` tables.

    Parameters
    ----------
    name : str
        Lower-case identifier, not registered yet.
    make : callable
        ``make(**params) -> PairSum``, ``params`` the entry's keys (see
        :class:`~kinred.pairsum.PairSumType`).
    keys : tuple of Key
        The options a scene file may give besides ``method``.
    doc : str
        One line for the reference (``docs/scene-file.md``).
    mixed : bool
        ``make`` takes ``precision=`` (``"double"`` or ``"mixed"``).

    Returns
    -------
    PairSumType

    Raises
    ------
    InvalidInput
        A bad or taken name, ``make`` not callable, keys that are not
        :class:`~kinred.scenefile.Key` objects or repeat a name.
    """
    if not callable(make):
        raise InvalidInput(f"make must be callable as make(**params), got {make!r}")
    if not isinstance(mixed, bool):
        raise InvalidInput(f"mixed must be True or False, got {mixed!r}")
    return register_entry(_PAIRSUMS, "pair-sum method", name, PairSumType(make, keys, doc, mixed),
                          "method")


def unregister_pairsum(name: str) -> None:
    """Remove a backend added by :func:`register_pairsum` (the built-in ones stay)."""
    unregister_entry(_PAIRSUMS, "pair-sum method", name, _BUILTIN)


def make_pairsum(name: str, params: dict | None = None, precision: str | None = None):
    """The backend ``name`` built with ``params`` (defaults of absent keys filled in) and,
    for a backend with a ``precision`` option, ``precision`` (None: its default)."""
    entry = _PAIRSUMS[name]
    kwargs = with_defaults(entry.keys, dict(params or {}))
    missing = [k.name for k in entry.keys if k.default is REQUIRED and k.name not in kwargs]
    if missing:
        raise InvalidInput(f"pair-sum method {name!r} needs the options {', '.join(missing)}; "
                           "build the backend object and pass it instead")
    if entry.mixed and precision is not None:
        kwargs["precision"] = precision
    return entry.make(**kwargs)


def _dense(**kw):
    from .dense import Dense

    return Dense(**kw)


def _numpy():
    from .reference import Numpy

    return Numpy()


def _random_batch(**kw):
    from .random_batch import RandomBatch

    return RandomBatch(**kw)


def _nufft(**kw):
    from .nufft import NUFFT

    return NUFFT(**kw)


def _cells(**kw):
    from .cells import CellList

    return CellList(**kw)


def _auto(**kw):
    from .auto import Auto

    return Auto(**kw)


def _register_builtins():
    register_pairsum("dense", _dense, mixed=True, keys=(
        Key("block", "integer", None, "rows per block", low=1,
            shown_default="chosen from N, d and the threads"),
    ), doc="exact: blocked BLAS products and numba kernels (the default)")
    register_pairsum("numpy", _numpy, doc="exact: the plain-numpy twin, float64 (reference)")
    register_pairsum("random_batch", _random_batch, keys=(
        Key("p", "integer", 2, "agents per random batch", low=2),
        Key("block", "integer", None, "batches per block of the kernel", low=1,
            shown_default="the backend's"),
    ), doc="random batch method: pair sums inside random batches of p agents, unbiased, "
           "O(N p d) per step; the run's seed draws the batches (use euler)")
    register_pairsum("nufft", _nufft, keys=(
        Key("tol", "number", 1e-6, "target relative accuracy of the pair sums", low=0.0,
            high=1.0, low_open=True, high_open=True),
        Key("max_modes", "integer", 2**20, "largest number of Fourier modes (TooLarge beyond)",
            low=1),
    ), doc="fast summation by non-equispaced FFTs (finufft) of smooth radial kernels, "
           "distances in k ≤ 3 dimensions, O(N + n^k log n) per step")
    register_pairsum("cells", _cells, keys=(
        Key("tol", "number", 1e-6, "target relative accuracy (sets the cutoff from the kernels' "
            "declared tails)", low=0.0, high=1.0, low_open=True, high_open=True),
    ), doc="cell list: short-range kernels truncated at a distance set from tol, distances "
           "in k ≤ 3 dimensions, O(N) memory")
    register_pairsum("auto", _auto, keys=(
        Key("tol", "number", 1e-6, "target relative accuracy of the approximate candidates",
            low=0.0, high=1.0, low_open=True, high_open=True),
        Key("max_seconds", "number", 60.0, "refuse (TooLarge) when every candidate is "
            "estimated beyond this many seconds per right-hand side", low=0.0, low_open=True),
    ), doc="the deterministic backend (dense, nufft, cells) of least estimated cost for each "
           "system and cloud, re-chosen when the cloud changes shape; never random_batch")
    _BUILTIN.update(_PAIRSUMS)


_register_builtins()
