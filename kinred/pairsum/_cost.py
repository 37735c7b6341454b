"""The cost model of the pair-sum backends: estimated seconds of one right-hand side.

Rates measured on the 2-core development VM (shared, so rough; per engine thread), used by
``pairsum="auto"`` (:mod:`kinred.pairsum.auto`) to rank the backends and by the NUFFT's
near-field split (:mod:`kinred.pairsum._nearfield`) to choose its radius. Only ratios
matter for the choices.
"""

from __future__ import annotations

import math

#: Dense: seconds per pair and engine thread of one term, by the kernel's compiled form
#: (``kernel.compiled_form()[0]``; None: a numpy kernel, e.g. Morse), plus
#: :data:`DENSE_DIM_SECONDS` per pair, term and dimension (the distances and the products).
#: Any numpy kernel sends the whole scene through the numpy strips, its compiled kernels
#: included. Measured per pair and thread (N = 10⁴ and 4000, d = 2, 3, 10, 50, 200):
#: Cucker–Smale β = 1.5 (``cs_halfint``) 4.2, 3.3, 5.7, 11, 39 ns; β = 0.7 (``cs_pow``)
#: 9.4, 7.4, 12, 22, 47 ns; soft Morse 21, 21, 30, 28, 57 ns; both terms 43, 42, 68, 54,
#: 106 ns (the 3-D slab of issue 24 was estimated at 3× too fast by one rate per scene).
DENSE_TERM_SECONDS = {"cs_halfint": 3.5e-9, "cs_pow": 8e-9, None: 2e-8}
DENSE_DIM_SECONDS = 2e-10
#: Cell list: seconds per pair within the cutoff (gather, numpy kernel, scatter) and per
#: candidate pair of the stencil; candidates per pair within the cutoff, by dimension.
CELL_PAIR_SECONDS = 8e-8
CELL_CANDIDATE_SECONDS = 3e-8
CELL_CANDIDATES = {1: 1.5, 2: 2.9, 3: 6.5}
#: The same for the compiled fused pass (``_cell_kernels.pairs_fused``, every kernel through
#: its table, :mod:`kinred.pairsum._table`): per pair within the cutoff, per pair of a NUFFT
#: split's near part, per candidate. By closed forms (before the tables), on the 2-D ring of
#: issue 24 (radius 20, N = 2·10⁴, cutoff 1.8, one thread): 22 ns per pair for Morse, 56 ns
#: for its near part with the transition's ``erfc``. By the tables, search and accumulation
#: included: 10.9 ns per pair and thread for Morse (2-D, D = 300, N = 10⁵, cutoff 19.2,
#: 6.1·10⁷ pairs; 18.3 ns by its closed form), 9.4 ns per near pair and thread, candidates
#: included (the ring of radius 5, N = 2·10⁴, ε_I = 0.94: 1.18·10⁷ pairs in 107 ms on one
#: thread). It was priced at 18 ns, and the far grid at twice its time (at finufft's
#: ``ε = tol·τ`` instead of its own): the errors cancelled on that ring, not on others.
FUSED_PAIR_SECONDS = 1.1e-8
FUSED_NEAR_PAIR_SECONDS = 3.6e-9
FUSED_CANDIDATE_SECONDS = 2e-9
#: NUFFT: seconds per spreading operation and per FFT point and ``log₂``.
SPREAD_SECONDS = 1e-9
FFT_SECONDS = 1e-9


def dense_seconds(n: int, dim: int, kinds: list) -> float:
    """One dense right-hand side on one engine thread: ``n(n − 1)/2`` pairs times the sum over
    the terms of :data:`DENSE_TERM_SECONDS` (``kinds``: each term's compiled kind, None for a
    numpy kernel) and ``dim ×`` :data:`DENSE_DIM_SECONDS`."""
    numpy_path = any(kd not in DENSE_TERM_SECONDS or kd is None for kd in kinds)
    per = sum(DENSE_TERM_SECONDS[None if numpy_path else kd] + dim * DENSE_DIM_SECONDS
              for kd in kinds)
    return n * (n - 1) / 2.0 * per


def cell_seconds(pairs: float, k: int, terms: int = 1, fused: bool = False,
                 near: bool = False) -> float:
    """The cell list's pairs within the cutoff (``terms`` kernels evaluated on each); ``fused``:
    by the compiled fused pass, ``near``: the near part of a NUFFT split."""
    cand = pairs * CELL_CANDIDATES.get(k, 3.0 ** k)
    if fused:
        rate = FUSED_NEAR_PAIR_SECONDS if near else FUSED_PAIR_SECONDS
        return terms * pairs * rate + cand * FUSED_CANDIDATE_SECONDS
    return terms * pairs * CELL_PAIR_SECONDS + cand * CELL_CANDIDATE_SECONDS


#: finufft's upsampling factors kinred chooses among (finufft ≥ 2.5 takes any σ > 1).
UPSAMPLING = (1.25, 1.5, 2.0)
#: finufft's widest spreading kernel.
MAX_WIDTH = 16


def spread_width(eps: float, k: int, sigma: float) -> int:
    """finufft 2.5's spreading width for tolerance ``eps`` in ``k`` dimensions at upsampling
    ``σ`` (its PSWF kernel: ``⌈ln(0.18·1.4^{k−1}/ε)/(π√(1 − 1/σ)) + 1⌉``, at least 2)."""
    eps = max(min(eps, 0.1), 1e-16)
    w = math.ceil(math.log(0.18 * 1.4 ** (k - 1) / eps) / (math.pi * math.sqrt(1.0 - 1.0 / sigma))
                  + 1.0)
    return max(2, w)


def upsampling(n: int, modes: int, eps: float, k: int) -> float:
    """The upsampling factor ``σ`` of least estimated cost (:func:`nufft_seconds`): ``σ = 2``
    for many points on few modes (spreading dominates), ``1.25`` for few points on many modes
    (the FFT of ``σᵏ×`` the modes dominates: the 2-D D'Orsogna ring's far part at
    N = 2·10⁴, 643 × 647 modes: 0.030 s per transform pair against 0.133 s at ``σ = 2``)."""
    ok = [s for s in UPSAMPLING if spread_width(eps, k, s) <= MAX_WIDTH] or [2.0]
    return min(ok, key=lambda s: (_transforms_seconds(n, modes, eps, k, s), -s))


def _transforms_seconds(n, modes, eps, k, sigma) -> float:
    w = spread_width(eps, k, sigma)
    fine = sigma ** k * modes
    return 2 * n * w ** k * SPREAD_SECONDS + 2 * fine * math.log2(max(fine, 2)) * FFT_SECONDS


def nufft_seconds(n: int, dim: int, modes: int, eps: float, k: int) -> float:
    """One group's transforms: ``(d + 2)//2`` complex transform pairs, ``2 N wᵏ`` spreading
    operations each (``w`` = :func:`spread_width`), FFTs of ``σᵏ`` times the modes, at the
    upsampling ``σ`` of :func:`upsampling`."""
    sigma = upsampling(n, modes, eps, k)
    return (dim + 2) // 2 * _transforms_seconds(n, modes, eps, k, sigma)
