"""Wasserstein-1 distances (eq. (4.5) of the paper).

:func:`w1` returns a :class:`W1Result` saying what it computed: exact values (POT's network
simplex with a dense or lazily evaluated Euclidean cost, or on a sparse candidate graph
proved optimal by the c-transform of its duals over all pairs -- ``method="sparse"``, exact at
10⁵–10⁶ atoms, docs/w1.md --, exact 1-D formulas, the exact ℓ1 W1 of product measures) or a
certified bracket ``[lower, upper]`` (``method="bracket"``, or a sparse solve whose budget ran
out), which ``float()`` refuses. The default ``method="auto"`` returns exact values only: when
no method reaches one it raises, naming the exact method, its cost and the bracket. Measures, arrays of
points and :mod:`kinred.quantize` results are accepted alike.
:func:`sliced_w1` is a different distance and is kept under its own name.
:func:`paired_w1_bracket` brackets W1 between two measures whose atoms correspond (same count,
same weights) in ``O(N log N)`` without a linear program, for any number of atoms.

This is the only package of kinred that imports POT (``ot``), lazily.
"""

from ._paired import W1Bracket, paired_w1_bracket
from ._pot import default_num_iter_max
from ._result import SlicedW1Result, W1Result
from ._w1 import DEFAULT_MAX_DENSE_BYTES, DEFAULT_MAX_EXACT_PAIRS, METHODS, sliced_w1, w1

__all__ = [
    "w1",
    "sliced_w1",
    "paired_w1_bracket",
    "W1Result",
    "W1Bracket",
    "SlicedW1Result",
    "METHODS",
    "DEFAULT_MAX_DENSE_BYTES",
    "DEFAULT_MAX_EXACT_PAIRS",
    "default_num_iter_max",
]
