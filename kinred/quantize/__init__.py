"""Quantization: atoms from measures, with a-priori bounds and exact errors (§4.4–4.5 of the paper).

* :func:`quantize_1d` -- equal-weight atoms at quantile levels (eqs. (4.20)–(4.21)).
* :func:`budget` -- atoms per coordinate for the delayed curse of dimension (eq. (4.22)).
* :func:`quantize` -- one entry point for every measure: tensor grids (Lemma 4.1), mixtures
  (Lemma 4.2; sparse grids), push-forwards (eq. (4.8)), atomic measures (identity).
* :func:`preflight` -- the counts and the bytes :func:`quantize` and ``materialize()`` would
  allocate, without building anything.

Results know their atom count (exact Python int) and bound without building the atoms;
:meth:`Quantization.materialize` builds them and :meth:`Quantization.iter_chunks` streams them.

Memory limit: every stage (quantile arrays, the atom array, one streamed chunk) predicts its
peak bytes from exact integers before allocating and raises :class:`~kinred.errors.TooLarge`
past one limit: the keyword ``max_bytes=`` of the call, else the environment variable
``KINRED_MAX_BYTES`` (e.g. ``8G``), else :data:`DEFAULT_MAX_BYTES` (2 GiB).
"""

from ._budget import RULE_CONSTANT, Budget, Recipe, budget, paper_recipe
from ._plan import Preflight, preflight, quantize, quantize_1d
from ._quantization import (
    AtomicQuantization,
    MixtureQuantization,
    PushQuantization,
    Quantization,
    Quantization1D,
    TensorQuantization,
)
from ._size import DEFAULT_MAX_BYTES, ENV_MAX_BYTES

__all__ = [
    "quantize",
    "quantize_1d",
    "preflight",
    "Preflight",
    "budget",
    "paper_recipe",
    "Budget",
    "Recipe",
    "Quantization",
    "Quantization1D",
    "TensorQuantization",
    "MixtureQuantization",
    "PushQuantization",
    "AtomicQuantization",
    "RULE_CONSTANT",
    "DEFAULT_MAX_BYTES",
    "ENV_MAX_BYTES",
]
