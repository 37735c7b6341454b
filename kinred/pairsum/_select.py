"""``as_pairsum``: a backend from a ``Scene(pairsum=...)`` argument and its older aliases.

Names are those of the registry :data:`kinred.pairsum.PAIRSUMS` (shared with scene files'
``[dynamics.pairsum]``), plus ``"fast"`` for ``"dense"``."""

from __future__ import annotations

from ..errors import InvalidInput
from ._base import PairSum
from ._registry import PAIRSUMS, make_pairsum
from .dense import Dense

__all__ = ["as_pairsum", "names"]


def names() -> tuple:
    """Names accepted for ``pairsum=`` (and the older ``engine=``): ``"fast"`` (the dense
    backend) and every registered backend of :data:`~kinred.pairsum.PAIRSUMS`."""
    return ("fast", *PAIRSUMS)


def as_pairsum(pairsum=None, *, engine: str | None = None, block: int | None = None,
               precision: str | None = None) -> PairSum:
    """The pair-sum backend a :class:`~kinred.dynamics.Scene` uses.

    Parameters
    ----------
    pairsum : PairSum or str, optional
        A backend object (anything with ``plan`` and ``evaluate``, see
        :class:`~kinred.pairsum.PairSum`), or a name: ``"fast"``/``"dense"`` for
        :class:`~kinred.pairsum.Dense` (the default), ``"numpy"`` for the twin
        :class:`~kinred.pairsum.Numpy`, ``"random_batch"`` for
        :class:`~kinred.pairsum.RandomBatch` with ``p = 2``, ``"nufft"`` for
        :class:`~kinred.pairsum.NUFFT` with ``tol = 1e-6``, ``"cells"`` for
        :class:`~kinred.pairsum.CellList` with ``tol = 1e-6``, ``"auto"`` for
        :class:`~kinred.pairsum.Auto` (the deterministic backend of least estimated cost,
        ``tol = 1e-6``; other options: pass the object), or the name of a backend added by
        :func:`~kinred.pairsum.register_pairsum` (built with its default options).
    engine : {"fast", "dense", "numpy", "random_batch", "nufft"}, optional
        The older name of ``pairsum`` (strings only); give one of the two.
    block, precision : optional
        Options of the default backend, ``Dense(block=..., precision=...)``; only with
        ``pairsum`` a name of the dense backend or None (``"numpy"`` takes
        ``precision="double"``, what it computes).

    Returns
    -------
    PairSum

    Raises
    ------
    InvalidInput
        Unknown name, an object that is not a backend, or conflicting arguments.

    Examples
    --------
    >>> as_pairsum(), as_pairsum("numpy"), as_pairsum(engine="fast", precision="mixed")
    (Dense(), Numpy(), Dense(precision='mixed'))
    >>> as_pairsum("random_batch"), as_pairsum("nufft")
    (RandomBatch(p=2), NUFFT(tol=1e-06))
    """
    aliases = names()
    if engine is not None:
        if pairsum is not None:
            raise InvalidInput(f"give pairsum= or its older alias engine=, not both; got "
                               f"pairsum={pairsum!r}, engine={engine!r}")
        if not isinstance(engine, str) or engine not in aliases:
            raise InvalidInput(f"engine must be one of {aliases}, got {engine!r}")
        pairsum = engine
    if pairsum is None:
        pairsum = "fast"
    if isinstance(pairsum, str):
        if pairsum not in aliases:
            raise InvalidInput(f"pairsum must be a PairSum backend or one of {aliases}, "
                               f"got {pairsum!r}")
        if pairsum in ("fast", "dense"):
            return Dense(block=block, precision="double" if precision is None else precision)
    elif not isinstance(pairsum, PairSum):
        raise InvalidInput(f"pairsum must be a PairSum backend (an object with plan(scene, n, "
                           f"dim) and evaluate(plan, x, v, rng)) or one of {aliases}, got "
                           f"{pairsum!r}")
    if isinstance(pairsum, str) and pairsum == "numpy" and precision == "double":
        precision = None                # what the twin computes anyway
    if block is not None or precision is not None:
        raise InvalidInput(f"block= and precision= configure the default dense backend; with "
                           f"pairsum={pairsum!r} set them on the backend itself (e.g. "
                           f"pairsum=Dense(block=..., precision=...)); got block={block!r}, "
                           f"precision={precision!r}")
    return make_pairsum(pairsum) if isinstance(pairsum, str) else pairsum
