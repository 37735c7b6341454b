"""Kinetic (mean-field) particle solutions, reduced solutions and Theorem 4.3 (§4 of the paper).

The data flow of §4.3: a phase-space measure ``μ₀`` on ``ℝ²ᵈ`` is quantized into atoms
(:func:`solve`, delayed-curse budget), the weighted particle system gives ``μᴺ(t)``; the
projected atoms ``M#μ₀ᴺ`` start the reduced system in ``ℝ²ᵏ`` (:func:`reduce`), giving
``νᴺ(t)``; :func:`compare` computes ``W1(M#μᴺ(t), νᴺ(t))`` exactly (a certified bracket above
:data:`MAX_POT_ATOMS` atoms) and :func:`theorem_bound`
the right-hand side of eq. (4.17) with the constants of its proof.
See docs/kinetic.md.
"""

from ._bounds import (
    EXACT_DIAMETER_MAX,
    EffectConstants,
    TheoremBound,
    d_estimate,
    diameter_bounds,
    effect_constants,
    max_pairwise_distance,
    stability_constant,
    theorem_bound,
)
from ._compare import (MAX_POT_ATOMS, Comparison, ReferenceEstimate, compare, milling_index,
                       reference_estimate)
from ._solution import (
    KineticSolution,
    ReducedSolution,
    lift,
    phase_space,
    reduce,
    solve,
    weighted_scene,
)

__all__ = [
    "solve",
    "reduce",
    "compare",
    "MAX_POT_ATOMS",
    "reference_estimate",
    "theorem_bound",
    "phase_space",
    "lift",
    "weighted_scene",
    "milling_index",
    "effect_constants",
    "d_estimate",
    "stability_constant",
    "max_pairwise_distance",
    "diameter_bounds",
    "EXACT_DIAMETER_MAX",
    "KineticSolution",
    "ReducedSolution",
    "Comparison",
    "ReferenceEstimate",
    "TheoremBound",
    "EffectConstants",
]
