"""Measures on ℝᵈ: the objects the paper quantizes, pushes forward and compares in W1.

Every measure has ``dim``, ``sample(n, seed=None) -> (n, dim)``, ``support_widths()`` (the
σⱼ of §4.5) and ``push(M)`` (eq. (4.8)). :class:`Atomic` measures push exactly,
eq. (4.9). See :mod:`kinred.quantize` for atoms with error bounds and
:func:`load_measure` for the TOML measure files of ``kinred quantize``.
"""

from ._base import Atomic, Dirac, Measure, PushForward
from ._composite import Mixture, TensorProduct
from ._file import load_measure, measure_from_dict
from ._univariate import Empirical1D, Uniform, Univariate

__all__ = [
    "Measure",
    "Univariate",
    "Uniform",
    "Dirac",
    "Empirical1D",
    "TensorProduct",
    "Mixture",
    "PushForward",
    "Atomic",
    "load_measure",
    "measure_from_dict",
]
