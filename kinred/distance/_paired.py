r"""A certified W1 bracket for two atomic measures whose atoms correspond, in ``O(N log N)``.

Two measures ``μ = Σᵢ wᵢ δ_{aᵢ}`` and ``ν = Σᵢ wᵢ δ_{bᵢ}`` with the same weights and atoms
paired by index (a particle solution and its reduction or projection, two runs of one
system) have W1 (eq. (4.5) of the paper) bracketed by

* **lower**: ``max_θ W1(θ#μ, θ#ν)`` over unit directions θ — each projection ``x ↦ θ·x`` is
  1-Lipschitz, so each 1-D W1 is a Kantorovich–Rubinstein lower bound; the 1-D W1 is exact,
  ``∫ |F_θ#μ − F_θ#ν|`` from one sort of the ``2N`` projected values;
* **upper**: the cost of the index coupling ``Σᵢ wᵢ ‖aᵢ − bᵢ‖`` (an explicit coupling, the
  one the proof of Theorem 4.3 uses);
* **lower, with** ``dual_seconds``: the dual value ``Σᵢ wᵢ fᵢ + Σⱼ wⱼ gⱼ`` of the distance
  to ν's atoms ``fᵢ = minⱼ ‖aᵢ − bⱼ‖`` and its c-transform ``gⱼ = minᵢ (‖aᵢ − bⱼ‖ − fᵢ)``,
  both exact searches over *all* pairs (:func:`kinred.distance._search.ctransform`), so
  that ``fᵢ + gⱼ ≤ ‖aᵢ − bⱼ‖`` for every pair and weak duality of eq. (4.5)'s linear program
  makes it a lower bound. It is tight when the displacements ``‖aᵢ − bᵢ‖`` are small
  against the spacing of the atoms (then ``fᵢ = ‖aᵢ − bᵢ‖``, ``gᵢ = 0``): high-dimensional
  clouds of many atoms, the kinetic comparison at k = 10.

Both are ``O(N log N)`` per direction with ``O(N d)`` memory, and no LP is solved (no POT).
Round-off is accounted for: the ends are moved outwards by a priori bounds of the
floating-point errors of the sums (``γₙ = n u/(1 − n u)``), so the bracket holds for the
exact W1 of the given atoms.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .._rng import as_generator
from .._validate import as_array, as_float, as_int, as_weights, check_alloc
from ..errors import InvalidInput, TooLarge
from ._inputs import Pts, normalize_pair
from ._result import W1Result

__all__ = ["W1Bracket", "paired_w1_bracket", "MAX_AXES"]

#: Relative gap at which the dual bound and the index coupling count as meeting (beyond the
#: certificate's own round-off pad): the index coupling is then optimal and the result exact
#: (as the sparse method's ``DEFAULT_RTOL``).
EXACT_RTOL = 1e-13

#: Coordinate axes tried at most (those with the largest mean ``|aᵢ − bᵢ|`` per coordinate).
MAX_AXES = 64

_EPS = np.finfo(np.float64).eps
_U = _EPS / 2


def _gamma(n: int) -> float:
    """``γₙ = n u / (1 − n u)``, the relative error bound of ``n`` floating-point operations."""
    return n * _U / (1.0 - n * _U)


@dataclass(frozen=True, repr=False)
class W1Bracket(W1Result):
    """A certified bracket ``lower ≤ W1 ≤ upper`` (a :class:`W1Result` with labels).

    Attributes
    ----------
    lower_from, upper_from : str
        What gave each end (``"max-sliced W1 over 41 directions"``, ``"index coupling
        sum_i w_i |a_i - b_i|"``).
    n_directions : int
        Directions whose exact 1-D W1 was computed.
    label : str
        ``"certified bracket"``, or ``"exact, proved by its dual"`` when the bounds met.

    Other attributes as in :class:`W1Result` (``value`` is the midpoint, also named
    ``midpoint``, and ``float()`` refuses the bracket, unless ``exact``; ``method`` is
    ``"paired-bracket"``, ``width = upper − lower``).
    """

    lower_from: str = ""
    upper_from: str = ""
    n_directions: int = 0
    label: str = "certified bracket"


def _slice(A: np.ndarray, B: np.ndarray, w: np.ndarray, theta: np.ndarray, proj_err: float,
           grad: bool = False):
    """A certified lower bound of the exact 1-D W1 of ``θ#μ`` and ``θ#ν`` and, with ``grad``,
    the ascent direction ``g`` of the monotone coupling.

    ``W1 = ∫|F − G| = Σₖ |Cₖ| (z₍ₖ₊₁₎ − z₍ₖ₎)`` over the merged sorted projected values ``z``
    with ``C`` the running sum of ``+w`` (atoms of ``μ``) and ``−w`` (of ``ν``); ties may sit in
    any order (their gaps are 0), so one unstable sort suffices.

    ``g = Σ_π π_{ij} sign(θ·(aᵢ − bⱼ)) (aᵢ − bⱼ)`` over the monotone (optimal) coupling ``π`` of
    the projections, so that ``θ·g = W1(θ)``: the atom of ``μ`` at sorted position ``k`` (mass
    ``w``, running sums ``C₋ = Cₖ₋₁`` before and ``C₊ = Cₖ`` after it) is coupled above
    itself with mass ``clip(−C₋, 0, w)`` and below with ``clip(C₊, 0, w)``; an atom of ``ν``
    with ``clip(−C₊, 0, w)`` and ``clip(C₋, 0, w)``. The step ``θ ← g/|g|`` is the fixed-point
    ascent of ``kinred.distance._bracket.projection_lower`` (a heuristic: every tried
    direction's certified value counts, none is assumed).

    Round-off subtracted: the summation error (``|Ĉₖ − Cₖ| ≤ 2γ₂ₙ``, hence ``2γ₂ₙ·span``,
    plus ``γ_{2n+d+6}`` relative for the products, the sum and ``‖θ̂‖ ≠ 1``) and
    ``2·proj_err``, twice a bound of the error of each computed projection (moving every atom
    by ``δ`` moves W1 by at most ``2δ``).
    """
    n, d = A.shape
    z = np.concatenate([A @ theta, B @ theta])
    order = np.argsort(z)
    zs = z[order]               # sorted values (one gather: less than half a second sort)
    sw = np.concatenate([w, -w])[order]
    C = np.cumsum(sw)
    val = float(np.abs(C[:-1]) @ np.diff(zs))
    err = 2.0 * _gamma(2 * n) * float(zs[-1] - zs[0]) + 2.0 * proj_err
    cert = max(0.0, val * (1.0 - _gamma(2 * n + d + 6)) - err)
    if not grad:
        return cert, None
    m = np.abs(sw)
    before = np.concatenate([[0.0], C[:-1]])
    mu = sw > 0
    coef = np.where(mu, np.clip(-before, 0, m) - np.clip(C, 0, m),
                    np.clip(C, -m, 0) + np.clip(before, 0, m))
    full = np.empty(2 * n)
    full[order] = coef
    return cert, full[:n] @ A + full[n:] @ B


def _unit(theta: np.ndarray) -> np.ndarray | None:
    nrm = float(np.linalg.norm(theta))
    return theta / nrm if nrm > 0 and np.isfinite(nrm) else None


def _candidates(D: np.ndarray, w: np.ndarray, rng, n_random: int, n_principal: int) -> list:
    """Directions: coordinate axes (at most 64, ``MAX_AXES``), the mean difference, the
    principal directions of the difference cloud ``D = A − B`` (top eigenvectors of
    ``Σᵢ wᵢ dᵢ dᵢᵀ``) and ``n_random`` uniformly random ones."""
    n, d = D.shape
    axes = np.argsort(-(w @ np.abs(D)), kind="stable")[:MAX_AXES]
    cands = [np.eye(1, d, int(k))[0] for k in axes]
    cands.append(w @ D)
    if n_principal:
        r = min(n_principal, d)
        if d <= 256:
            M = D.T @ (w[:, None] * D)
            vals, vecs = np.linalg.eigh(0.5 * (M + M.T))
            cands.extend(vecs[:, ::-1][:, :r].T)
        else:                               # subspace iteration, O(N d r) per sweep
            Q = np.linalg.qr(rng.standard_normal((d, r)))[0]
            for _ in range(12):
                Q = np.linalg.qr(D.T @ (w[:, None] * (D @ Q)))[0]
            cands.extend(Q.T)
    cands.extend(rng.standard_normal((n_random, d)))
    return [u for u in (_unit(c) for c in cands) if u is not None]


def _lower(PA: Pts, PB: Pts, D: np.ndarray, rng, n_random: int, n_principal: int,
           n_refine: int) -> tuple[float, int, str]:
    """Max-sliced lower bound: every candidate scored, the best two refined by the
    fixed-point ascent ``θ ← g/|g|`` of :func:`_slice` (while it increases)."""
    A, B, w = PA.points, PB.points, PA.weights
    d = PA.dim
    # |computed θ·x − θ·x| <= γ_d Σ_l |θ_l x_l| <= γ_d √d max|x_l|  (|θ| = 1)
    err = _gamma(d + 2) * np.sqrt(d) * float(max(np.max(np.abs(A)), np.max(np.abs(B))))
    scored = sorted(((_slice(A, B, w, th, err)[0], i, th) for i, th in
                     enumerate(_candidates(D, w, rng, n_random, n_principal))),
                    key=lambda s: (-s[0], s[1]))
    tried = len(scored)
    best = scored[0][0]
    for _, _, th in scored[:2] if n_refine else ():
        val, g = _slice(A, B, w, th, err, grad=True)
        for _ in range(n_refine):
            nxt = _unit(g)
            if nxt is None:
                break
            v2, g = _slice(A, B, w, nxt, err, grad=True)
            tried += 1
            best = max(best, v2)
            if v2 <= val * (1 + 1e-12):
                break
            val = v2
    return best, tried, f"max-sliced W1 over {tried} directions"


def _nearest(A: np.ndarray, B: np.ndarray, c: np.ndarray, deadline: float,
             open_rows: np.ndarray) -> np.ndarray:
    """``fᵢ = min(cᵢ, minⱼ ‖aᵢ − bⱼ‖)``: exact nearest-neighbour queries of a
    :class:`scipy.spatial.cKDTree` of ``B`` (within ``max c``, both cores), in blocks of rows;
    past ``deadline`` the remaining rows get the certified ``0`` (``open_rows = 1``)."""
    from scipy.spatial import cKDTree

    from .._parallel import get_num_threads

    f = np.zeros(A.shape[0])
    tree = cKDTree(B)
    r = float(np.max(c))
    block = 1 << 16
    for s in range(0, A.shape[0], block):
        e = min(s + block, A.shape[0])
        if time.perf_counter() > deadline:
            open_rows[s:] = 1
            break
        dist, j = tree.query(A[s:e], k=1, distance_upper_bound=r, workers=get_num_threads())
        # the own partner nearest: its cost as computed here (not the tree's rounding of it)
        f[s:e] = np.where(j == np.arange(s, e), c[s:e], np.minimum(dist, c[s:e]))
    return f


def _dual_lower(PA: Pts, PB: Pts, cost: np.ndarray, upper: float,
                seconds: float) -> tuple[float, str, float]:
    """The certified dual lower bound ``Σ w f + Σ w g − pad`` (module docstring) of the
    normalized paired atoms (``cost``: the index pairs' ``‖aᵢ − bᵢ‖``), searched within
    ``seconds``, what it is, and ``pad``; ``(-inf, why, 0)`` when it cannot be had.

    ``f`` is a nearest-neighbour search (:func:`_nearest`; blocked BLAS in ``d > 8`` with few
    pairs). ``g`` starts from ``‖aⱼ − bⱼ‖ − fⱼ`` (attained), so its search only looks for
    smaller values. Both are ``≥ 0`` (``f`` is a distance and ``fᵢ ≤ ‖aᵢ − bⱼ‖`` for every
    ``j``), so ``g`` is searched only where its start value is positive (where ``aⱼ``'s
    nearest atom of ν is not ``bⱼ``: a few percent of the rows when displacements are small
    against the spacing). Past the deadline the tree
    search finishes each row with a certified lower bound of its minimum (``f + g ≤ c`` still
    holds; the note counts those rows); the BLAS search (``d > 8`` and few pairs) stops.
    ``pad = 8ε·(upper + S) + (d + 8)ε·(max f + max g)``: ``S`` the size of the dual sum
    (:func:`kinred.distance._costs.dual_scale`) covers the sums, as in the sparse method's
    certificate; the second term the computed distances (a violated pair has
    ``|aᵢ − bⱼ| ≤ fᵢ + gⱼ``, and its distance is off by less than ``(d/2 + 2)u`` of it).
    """
    from ._costs import dual_scale
    from ._search import CTree, OutOfTime, _morton_order, ctransform, use_tree

    keep = PA.weights > 0                           # zero-weight atoms are in neither support
    n, d = int(keep.sum()), PA.dim
    try:             # the two trees' copies and boxes, the differences, f, g, c and indices
        check_alloc(8 * n * (4 * d + 8), "paired_w1_bracket: the dual lower bound's trees",
                    detail=f" for {n} atoms in dimension {d}")
    except TooLarge as exc:
        return -math.inf, f"no dual bound ({exc})", 0.0
    A, B, w, c = PA.points[keep], PB.points[keep], PA.weights[keep], cost[keep]
    deadline = time.perf_counter() + seconds
    idx = np.arange(n)
    tree = CTree(A) if use_tree(n, n, A.shape[1]) else None
    open_f = np.zeros(n, np.int8)
    try:
        if tree is None:                            # d > 8 and few pairs: blocked BLAS
            f, _ = ctransform(A, B, np.zeros(n), c.copy(), idx, None, deadline=deadline)
        else:
            f = _nearest(A, B, c, deadline, open_f)
        f = np.maximum(f, 0.0)                  # distances: a row cut short is still >= 0
        # g_j >= 0 (f_i <= |a_i - b_j| for every pair): where the start value c_j - f_j is
        # already 0 (a_j's nearest atom of nu is b_j) nothing is searched
        sub = np.flatnonzero(c - f > 0)
        g = np.zeros(n)
        open_g = np.zeros(sub.size, np.int8)
        if sub.size:
            order = None if tree is None else _morton_order(B[sub])   # neighbours in turn
            gs, _ = ctransform(B[sub], A, f, (c - f)[sub], sub, tree, deadline=deadline,
                               open_rows=open_g, rows=order)
            g[sub] = np.maximum(gs, 0.0)
    except OutOfTime:
        return -math.inf, f"the dual searches ran out of dual_seconds = {seconds:g}", 0.0
    # a pair's computed distance is off by at most ~(d/2 + 2)u of it, and a violated pair has
    # |a_i - b_j| <= f_i + g_j: lowering g by (d + 8)eps(max f + max g) makes (f, g) feasible
    # in exact arithmetic; 8eps(upper + S) covers the sums
    pad = 8 * _EPS * (upper + dual_scale(w, f, w, g)) + (d + 8) * _EPS * (f.max() + g.max())
    lower = math.fsum(w * f) + math.fsum(w * g) - pad
    cut = int(open_f.sum()) + int(open_g.sum())
    how = "" if not cut else f", {cut} of {2 * n} searches cut short by dual_seconds"
    return lower, ("dual value of the distance to nu's atoms and its c-transform over all pairs"
                   + how), pad


def paired_w1_bracket(a, b, weights=None, *, n_directions: int = 16, n_principal: int = 3,
                      n_refine: int = 4, dual_seconds: float | None = None,
                      seed=0) -> W1Bracket:
    r"""Certified ``lower ≤ W1(μ, ν) ≤ upper`` for ``μ = Σᵢ wᵢ δ_{aᵢ}``, ``ν = Σᵢ wᵢ δ_{bᵢ}``.

    For two atomic measures with the same atom count and weights whose atoms correspond (a
    particle solution and its projection or reduction): lower bound the largest exact 1-D W1
    of the projections on the coordinate axes (at most 64, ``MAX_AXES``), the mean
    difference, the principal directions of the differences ``aᵢ − bᵢ`` and
    ``n_directions`` random unit vectors (the best two then refined by fixed-point ascent);
    upper bound the index coupling ``Σᵢ wᵢ‖aᵢ − bᵢ‖``. ``O((directions)·N log N)`` time,
    ``O(N d)`` memory, no linear program (no POT), certified including floating-point
    round-off. With ``dual_seconds``, the lower bound is also the dual value of the distance
    to ν's atoms and its c-transform over all pairs (module docstring), whichever is larger:
    tight when the displacements are small against the spacing of the atoms.

    Parameters
    ----------
    a, b : (N, d) array_like
        The paired atoms (row ``i`` of ``a`` corresponds to row ``i`` of ``b``).
    weights : (N,) array_like, optional
        Common probability weights (uniform by default).
    n_directions : int
        Random unit directions (``>= 0``).
    n_principal : int
        Principal directions of the difference cloud (``>= 0``).
    n_refine : int
        Ascent steps for each of the two best directions (``>= 0``).
    dual_seconds : float, optional
        Time budget of the dual lower bound (``>= 0``; default: not computed). Its exact
        searches take under a second for 10⁵ atoms in ℝ⁴ and about 20 s for 10⁶ atoms in
        ℝ²⁰ of small intrinsic dimension; past the budget, rows are finished with certified partial
        bounds (the result then depends on the machine's speed, and the note says so).
    seed : None, int, SeedSequence or Generator
        For the random directions (the bracket is certified whatever they are).

    Returns
    -------
    W1Bracket
        ``lower``, ``upper``, ``width``, ``value`` (midpoint), ``method="paired-bracket"``,
        ``lower_from``/``upper_from`` and ``label``; ``exact`` is False, except with
        ``dual_seconds`` when the dual bound meets the index coupling within
        1e-13 relative (``EXACT_RTOL``) plus twice its round-off pad: then the index coupling
        is optimal, ``exact`` is True, ``value = lower = upper`` its cost and ``label``
        ``"exact, proved by its dual"``.

    Raises
    ------
    InvalidInput
        Non-finite or mismatched arrays, bad weights or counts.

    Examples
    --------
    >>> a = np.random.default_rng(0).normal(size=(500, 3))
    >>> r = paired_w1_bracket(a, a + [0.0, 3.0, 4.0])     # a translation: W1 = 5
    >>> bool(r.lower <= 5.0 <= r.upper), r.width < 1e-9, r.label
    (True, True, 'certified bracket')
    """
    A = as_array(a, "a", ndim=2)
    B = as_array(b, "b", ndim=2)
    if A.shape != B.shape or A.shape[0] < 1 or A.shape[1] < 1:
        raise InvalidInput(f"a and b must be paired atoms of the same shape (N, d) with N, d >= 1;"
                           f" got {A.shape} and {B.shape}")
    w = as_weights(weights, "weights", A.shape[0])
    n_directions = as_int(n_directions, "n_directions", low=0)
    n_principal = as_int(n_principal, "n_principal", low=0)
    n_refine = as_int(n_refine, "n_refine", low=0)
    if dual_seconds is not None:
        dual_seconds = as_float(dual_seconds, "dual_seconds", low=0.0)
    rng = as_generator(seed)
    PA, PB, unit = normalize_pair(A, B, w, w)
    n, d = A.shape
    D = PA.points - PB.points
    # each |a_i - b_i| within d ulps (sequential hypot), one more for w_i·c_i, fsum rounds once
    cost = np.hypot.reduce(D, axis=1)
    upper = math.fsum(w * cost) * (1 + _gamma(d + 4)) * unit
    lower, tried, lower_from = _lower(PA, PB, D, rng, n_directions, n_principal, n_refine)
    pad = 0.0
    if dual_seconds is not None:
        dual, dual_from, pad = _dual_lower(PA, PB, cost, upper / unit, dual_seconds)
        if dual > lower:
            lower, lower_from = dual, dual_from
    lower = min(lower * unit, upper)
    upper_from = "index coupling sum_i w_i |a_i - b_i|"
    # met: the gap is within EXACT_RTOL and the certificate's own round-off (as the sparse
    # method's test U - L <= rtol·U + 16eps·S)
    if dual_seconds is not None and upper - lower <= EXACT_RTOL * upper + 2 * pad * unit:
        note = (f"exact: the {lower_from} meets the {upper_from} within {EXACT_RTOL:g} "
                "relative, so the index coupling is optimal (proved; no linear program solved)")
        return W1Bracket(float(upper), "paired-bracket", True, float(upper), float(upper),
                         (n, n), note, "euclidean", lower_from=lower_from,
                         upper_from=upper_from, n_directions=tried,
                         label="exact, proved by its dual")
    note = (f"certified bracket: lower bound from the {lower_from}, upper bound from the "
            f"{upper_from}; no linear program solved")
    return W1Bracket(0.5 * (lower + upper), "paired-bracket", False, float(lower), float(upper),
                     (n, n), note, "euclidean", lower_from=lower_from, upper_from=upper_from,
                     n_directions=tried)
