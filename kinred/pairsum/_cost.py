"""The cost model of the pair-sum backends: estimated seconds of one right-hand side.

Rates measured on the 2-core development VM (shared, so rough; per engine thread), used by
``pairsum="auto"`` (:mod:`kinred.pairsum.auto`) to rank the backends and by the NUFFT's
near-field split (:mod:`kinred.pairsum._nearfield`) to choose its radius. Only ratios
matter for the choices.
"""

from __future__ import annotations

import math

#: Dense: pairs per second with compiled kernels and with numpy kernels.
DENSE_RATE = 4e8
DENSE_RATE_NUMPY = 8e7
#: Cell list: seconds per pair within the cutoff (gather, numpy kernel, scatter) and per
#: candidate pair of the stencil; candidates per pair within the cutoff, by dimension.
CELL_PAIR_SECONDS = 8e-8
CELL_CANDIDATE_SECONDS = 3e-8
CELL_CANDIDATES = {1: 1.5, 2: 2.9, 3: 6.5}
#: The same for the compiled fused pass (``_cell_kernels.pairs_fused``: Morse, Cucker–Smale):
#: per pair within the cutoff, per pair of a NUFFT split's near part (the transition's
#: ``erfc`` too), per candidate. Measured on the 2-D ring of issue 24 (radius 20,
#: N = 2·10⁴, cutoff 1.8, one thread): 22 ns per pair for Morse, 56 ns for its near part,
#: with about 2.1 candidates per pair.
FUSED_PAIR_SECONDS = 1.8e-8
FUSED_NEAR_PAIR_SECONDS = 5e-8
FUSED_CANDIDATE_SECONDS = 2e-9
#: NUFFT: seconds per spreading operation and per FFT point and ``log₂``.
SPREAD_SECONDS = 1e-9
FFT_SECONDS = 1e-9


def dense_seconds(n: int, dim: int, sources: int, compiled: bool) -> float:
    """One dense right-hand side."""
    rate = DENSE_RATE if compiled else DENSE_RATE_NUMPY
    return sources * n * (n - 1) / 2.0 * max(1.0, (dim + 1) / 4.0) / rate


def cell_seconds(pairs: float, k: int, terms: int = 1, fused: bool = False,
                 near: bool = False) -> float:
    """The cell list's pairs within the cutoff (``terms`` kernels evaluated on each); ``fused``:
    by the compiled fused pass, ``near``: the near part of a NUFFT split."""
    cand = pairs * CELL_CANDIDATES.get(k, 3.0 ** k)
    if fused:
        rate = FUSED_NEAR_PAIR_SECONDS if near else FUSED_PAIR_SECONDS
        return terms * pairs * rate + cand * FUSED_CANDIDATE_SECONDS
    return terms * pairs * CELL_PAIR_SECONDS + cand * CELL_CANDIDATE_SECONDS


def nufft_seconds(n: int, dim: int, modes: int, eps: float, k: int) -> float:
    """One group's transforms: ``(d + 2)//2`` complex transform pairs, ``2 N wᵏ`` spreading
    operations each (``w = ⌈log₁₀(1/ε)⌉ + 1``), FFTs of ``2ᵏ`` times the modes."""
    w = math.ceil(math.log10(1.0 / max(min(eps, 0.1), 1e-16))) + 1
    fine = (2 ** k) * modes
    return (dim + 2) // 2 * (2 * n * w ** k * SPREAD_SECONDS
                             + 2 * fine * math.log2(max(fine, 2)) * FFT_SECONDS)
