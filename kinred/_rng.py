"""The one seed convention of kinred.

Randomness enters every public function through a single ``seed`` (or ``rng``) argument that
may be ``None``, an ``int``, a :class:`numpy.random.SeedSequence` or a
:class:`numpy.random.Generator`. It is converted once, by :func:`as_generator`.

Ensembles never share a generator between members: member ``i`` of a run with master seed
``s`` draws from ``SeedSequence(s, spawn_key=(i,))`` (:func:`member_seed`). Its numbers depend
only on ``(s, i)``, not on the executor, the number of workers or the order of completion
(the scikit-learn ``random_state`` convention, made executor-proof).
"""

from __future__ import annotations

import numbers

import numpy as np

from ._validate import _short
from .errors import InvalidInput

__all__ = ["as_generator", "member_seed", "member_generator", "SeedLike"]

SeedLike = "None | int | numpy.random.SeedSequence | numpy.random.Generator"


def as_generator(seed=None) -> np.random.Generator:
    """Convert ``seed`` into a :class:`numpy.random.Generator`.

    Parameters
    ----------
    seed : None, int, SeedSequence or Generator
        ``None`` draws fresh OS entropy; an ``int`` (>= 0) or a ``SeedSequence`` seeds a new
        PCG64 generator; a ``Generator`` is returned unchanged (shared state).

    Examples
    --------
    >>> a = as_generator(3).standard_normal()
    >>> b = as_generator(3).standard_normal()
    >>> a == b
    True
    """
    if seed is None:
        return np.random.default_rng()
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, np.random.SeedSequence):
        return np.random.default_rng(seed)
    if isinstance(seed, numbers.Integral) and not isinstance(seed, bool):
        if seed < 0:
            raise InvalidInput(f"seed must be a non-negative integer, got {seed}")
        return np.random.default_rng(int(seed))
    raise InvalidInput(
        "seed must be None, a non-negative int, a numpy SeedSequence or a numpy Generator, "
        f"got {_short(seed)} of type {type(seed).__name__}"
    )


def member_seed(master_seed: int, index: int | tuple[int, ...]) -> np.random.SeedSequence:
    """Seed of ensemble member ``index`` of a run with ``master_seed``.

    The result depends only on ``(master_seed, index)``.

    Examples
    --------
    >>> s1 = member_seed(7, 3).generate_state(1)[0]
    >>> s2 = member_seed(7, 3).generate_state(1)[0]
    >>> bool(s1 == s2) and bool(s1 != member_seed(7, 4).generate_state(1)[0])
    True
    """
    if not (isinstance(master_seed, numbers.Integral) and master_seed >= 0):
        raise InvalidInput(f"master_seed must be a non-negative integer, got {master_seed!r}")
    key = (index,) if isinstance(index, numbers.Integral) else tuple(index)
    if not key or any((not isinstance(k, numbers.Integral)) or k < 0 for k in key):
        raise InvalidInput(f"index must be a non-negative int or a tuple of them, got {index!r}")
    return np.random.SeedSequence(int(master_seed), spawn_key=tuple(int(k) for k in key))


def member_generator(master_seed: int, index: int | tuple[int, ...]) -> np.random.Generator:
    """Generator for ensemble member ``index``: ``default_rng(member_seed(master_seed, index))``."""
    return np.random.default_rng(member_seed(master_seed, index))
