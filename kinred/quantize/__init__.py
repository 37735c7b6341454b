"""Quantization: atoms from measures, with a-priori bounds and exact errors (§4.4–4.5 of the paper).

* :func:`quantize_1d` -- equal-weight atoms at quantile levels (eqs. (4.20)–(4.21)).
* :func:`budget` -- atoms per coordinate for the delayed curse of dimension (eq. (4.22)).
* :func:`quantize` -- one entry point for every measure: tensor grids (Lemma 4.1), mixtures
  (Lemma 4.2; sparse grids), push-forwards (eq. (4.8)), atomic measures (identity).

Results know their atom count (exact Python int) and bound without building the atoms;
:meth:`Quantization.materialize` refuses above a limit and :meth:`Quantization.iter_chunks`
streams them.
"""

from ._budget import RULE_CONSTANT, Budget, Recipe, budget, paper_recipe
from ._quantization import (
    DEFAULT_MAX_ATOMS,
    AtomicQuantization,
    MixtureQuantization,
    PushQuantization,
    Quantization,
    Quantization1D,
    TensorQuantization,
    quantize,
    quantize_1d,
)

__all__ = [
    "quantize",
    "quantize_1d",
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
    "DEFAULT_MAX_ATOMS",
]
