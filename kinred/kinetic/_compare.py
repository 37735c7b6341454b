r"""W1 between the projected and the reduced particle solutions, and reference estimates.

What is exact and what is an estimate
-------------------------------------
* :func:`compare` -- ``W1(M#μᴺ(t), νᴺ(t))`` on ``ℝ²ᵏ``: **exact** (POT's network simplex on
  the two atomic measures, :func:`kinred.distance.w1`: the dense LP up to a few thousand
  atoms, beyond it ``method="sparse"``, exact and certified by its dual; ``exact`` says so
  per time). Where the sparse method does not close within its budget (``max_seconds`` per
  time) its **certified bracket** is reported; where its memory preflight refuses, or above
  ``max_pot_atoms`` atoms (:data:`MAX_POT_ATOMS`), no linear program is solved and the
  certified bracket of :func:`kinred.distance.paired_w1_bracket` is reported instead (lower
  bound: the larger of the max-sliced bound and the dual value of the distance to the
  reduced atoms and its c-transform over all pairs, searched within ``max_seconds``; upper
  bound: the index coupling); with the
  index coupling ``Σᵢ wᵢ ‖(Mxᵢ, Mvᵢ) − (yᵢ, wᵢ)‖`` (an upper bound, the one the proof of
  Theorem 4.3 uses) and the uniform error ``E(t) = max`` over the ``2N`` variables of
  Theorem 3.1 (eq. (3.7)).
* :func:`reference_estimate` -- with a finer reference (more atoms ``N′``),
  ``W1(M#μᴺ′(t), νᴺ′(t))`` (exact for the reference atoms) is an **estimate** of the
  continuum ``W1(μ_M(t), ν(t))``, off by at most ``W1(μ_M, M#μᴺ′) + W1(ν, νᴺ′)`` (unknown;
  ``≤ 2C(t)‖M‖ε′`` by the theorem's terms). ``W1(μᴺ(t), μᴺ′(t))`` on ``ℝ²ᵈ`` (exact between
  the two atomic measures) checks the stability estimate (4.6) against ``C(t)·W1`` at 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._repr import result_repr
from .._rng import member_seed
from .._validate import as_array, as_float, as_int
from ..errors import InvalidInput, TooLarge
from ._solution import KineticSolution, ReducedSolution

__all__ = ["Comparison", "ReferenceEstimate", "compare", "reference_estimate", "milling_index",
           "MAX_POT_ATOMS"]

#: Atom counts above which :func:`compare` solves no linear program (POT) and reports the
#: certified bracket of :func:`kinred.distance.paired_w1_bracket` instead.
MAX_POT_ATOMS = 10_000_000

#: Time budget (seconds) of the sparse W1 method per saved time in :func:`compare`: past it,
#: its certified bracket is reported (``exact`` False at that time), tightened by the paired
#: bracket's dual lower bound (searched within the same budget again). When the budget ran out
#: in its *first* network-simplex solve, the later times of the run take the paired bracket
#: directly (the same wait would end the same way).
MAX_W1_SECONDS = 60.0


@dataclass(frozen=True)
class Comparison:
    """``W1(M#μᴺ(t), νᴺ(t))`` over time.

    Attributes
    ----------
    t : (T,) ndarray
    w1 : (T,) ndarray
        W1 on ``ℝ²ᵏ`` (Euclidean ground metric) between ``M#μᴺ(t)`` and ``νᴺ(t)``.
    exact : (T,) bool ndarray
        Whether each value is exact (POT) or the midpoint of a certified bracket (``w1`` then
        holds the bracket's midpoint, ``lower``/``upper`` its ends).
    lower, upper : (T,) ndarray
        Certified bracket (equal to ``w1`` when exact).
    coupling : (T,) ndarray
        ``Σᵢ wᵢ ‖(Mxᵢ − yᵢ, Mvᵢ − wᵢ)‖ ≥ W1`` (the index coupling).
    uniform : (T,) ndarray
        ``E(t) = maxᵢ max(‖Mxᵢ − yᵢ‖, ‖Mvᵢ − wᵢ‖)`` (Theorem 3.1).
    method : str
        W1 method(s) used, joined by ``"+"`` when they differ over time (``"exact"``,
        ``"sparse"``, ``"exact-lazy"``, ``"bracket"``, ``"paired-bracket"``).
    k : int
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    t: np.ndarray
    w1: np.ndarray
    exact: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    coupling: np.ndarray
    uniform: np.ndarray
    method: str
    k: int


def _row_norms(D: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of ``D`` by repeated ``hypot``: no overflow or underflow of
    the squares (rows of size 1e160 or 1e-200 keep their relative accuracy)."""
    return np.hypot.reduce(D, axis=1)


def _w1_atoms(A, B, wa, wb, *, max_seconds=MAX_W1_SECONDS, seed=0):
    """The exact W1 of two atomic measures (``w1(method="auto")``: dense LP, or the sparse
    method beyond it), else a certified bracket; ``exact``/``lower``/``upper`` say which.

    When the sparse method does not close within ``max_seconds`` its certified bracket is
    returned; when a memory preflight refuses (:class:`~kinred.errors.TooLarge`, raised before
    any work) the paired bracket if the atoms correspond (same count and weights), else the
    general bracket."""
    from ..distance import w1

    paired = A.shape == B.shape and np.array_equal(wa, wb)
    r = None
    try:
        r = w1(A, B, method="auto", a=wa, b=wb, max_seconds=max_seconds, seed=seed)
        if r.exact:
            return r
    except TooLarge as exc:
        r = getattr(exc, "result", None)
    if paired:
        if r is not None and (r.info or {}).get("first_solve_stopped"):
            return r        # its bracket is already the paired one, with the dual bound
        q = _paired_bracket(A, B, wa, seed, max_seconds)
        return q if r is None or q.exact else _tighter(r, q)
    return r if r is not None else w1(A, B, method="bracket", a=wa, b=wb, seed=seed)


def _tighter(r, q):
    """Both certified brackets hold: their intersection ``[max lower, min upper]``."""
    import dataclasses

    lo, up = max(r.lower, q.lower), min(r.upper, q.upper)
    if (lo, up) == (r.lower, r.upper):
        return r
    return dataclasses.replace(r, lower=lo, upper=up, value=0.5 * (lo + up),
                               note=r.note + "; intersected with the paired bracket "
                                             f"[{q.lower:.6g}, {q.upper:.6g}]")


def _paired_bracket(A, B, w, seed, dual_seconds=None):
    """``kinred.distance.paired_w1_bracket`` (imported lazily, as in ``_w1_atoms``), with its
    dual lower bound searched within ``dual_seconds``."""
    from ..distance import paired_w1_bracket as bracket

    return bracket(A, B, w, seed=seed, dual_seconds=dual_seconds)


def compare(solution: KineticSolution, reduced: ReducedSolution, *,
            max_pot_atoms: int = MAX_POT_ATOMS, max_seconds: float = MAX_W1_SECONDS,
            seed=0) -> Comparison:
    r"""``W1(M#μᴺ(t), νᴺ(t))`` at every saved time (exact with POT up to ``max_pot_atoms``).

    .. math:: W_1\bigl((\mu^N(t))_M, \nu^N(t)\bigr) \le \sum_i w_i
              \bigl\|(Mx_i(t) - y_i(t),\, Mv_i(t) - w_i(t))\bigr\|

    Parameters
    ----------
    solution : KineticSolution
    reduced : ReducedSolution
        ``reduce(solution, ...)``: the same atoms and weights.
    max_pot_atoms : int
        Above this many atoms no linear program is solved: each time gets the certified
        bracket of :func:`kinred.distance.paired_w1_bracket` (``method="paired-bracket"``).
    max_seconds : float
        Time budget of the sparse W1 method per saved time (``MAX_W1_SECONDS``, 60 s). When
        it runs out during the first network-simplex solve of a time, the later times take
        the paired bracket directly (their problems are no smaller). A paired bracket
        searches its dual lower bound within the same budget (``dual_seconds``).
    seed : int
        Seed of the bracket's random directions (time ``i`` uses ``member_seed(seed, i)``).

    Returns
    -------
    Comparison

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> from kinred.measures import Atomic
    >>> from kinred.kinetic import solve, reduce
    >>> mu0 = Atomic(np.random.default_rng(0).random((8, 6)))
    >>> sol = solve(Scene([Alignment(CuckerSmale(1.0, 0.0))]), mu0, t_span=(0, 1), dt=0.1)
    >>> c = compare(sol, reduce(sol, M=np.eye(2, 3)))
    >>> bool(c.w1.max() < 1e-12), bool(c.exact.all())
    (True, True)
    """
    if not isinstance(solution, KineticSolution) or not isinstance(reduced, ReducedSolution):
        raise InvalidInput("compare needs a KineticSolution and its ReducedSolution")
    if not np.array_equal(solution.t, reduced.t) or solution.x.shape[1] != reduced.y.shape[1]:
        raise InvalidInput("solution and reduced must share save times and atoms (use reduce(solution, ...))")
    max_pot_atoms = as_int(max_pot_atoms, "max_pot_atoms", low=0)
    max_seconds = as_float(max_seconds, "max_seconds", low=0.0)
    seed = as_int(seed, "seed", low=0)
    P = reduced.projection
    T = len(solution.t)
    w = solution.weights
    paired = solution.x.shape[1] > max_pot_atoms
    same_weights = bool(np.array_equal(w, reduced.weights))
    if paired and not same_weights:
        raise InvalidInput("solution and reduced must carry the same atom weights (use "
                           "reduce(solution, ...)); the paired bracket couples atom i with atom i")
    vals, ex, lo, hi, cpl, uni = (np.empty(T) for _ in range(6))
    ex = np.zeros(T, bool)
    methods, stopped = [], False
    for i in range(T):
        Mx, Mv = P.apply(solution.x[i]), P.apply(solution.v[i])
        A = np.concatenate([Mx, Mv], axis=1)
        B = np.concatenate([reduced.y[i], reduced.w[i]], axis=1)
        if paired or (stopped and same_weights):
            r = _paired_bracket(A, B, w, member_seed(seed, i), max_seconds)
        else:
            r = _w1_atoms(A, B, w, reduced.weights, max_seconds=max_seconds,
                          seed=member_seed(seed, i))
            # its first network-simplex solve did not finish within max_seconds: the later
            # times (as large, and further apart) take the paired bracket, not the same wait
            stopped = bool((r.info or {}).get("first_solve_stopped", False))
        vals[i], ex[i], lo[i], hi[i] = r.midpoint, r.exact, r.lower, r.upper
        methods.append(r.method)
        ex_ = _row_norms(Mx - reduced.y[i])
        ev_ = _row_norms(Mv - reduced.w[i])
        cpl[i] = float(w @ np.hypot(ex_, ev_))
        uni[i] = float(max(ex_.max(), ev_.max()))
    return Comparison(t=np.asarray(solution.t, float), w1=vals, exact=ex, lower=lo, upper=hi,
                      coupling=cpl, uniform=uni, method="+".join(dict.fromkeys(methods)), k=P.k)


@dataclass(frozen=True)
class ReferenceEstimate:
    """Estimates against a finer reference solution (``N′`` atoms).

    Attributes
    ----------
    t : (T,) ndarray
    w1_reference : (T,) ndarray
        ``W1(M#μᴺ′(t), νᴺ′(t))`` (exact for the reference atoms): an **estimate** of
        ``W1(μ_M(t), ν(t))``.
    w1_quantization : (T,) ndarray
        ``W1(μᴺ(t), μᴺ′(t))`` on ``ℝ²ᵈ`` (exact): how the two quantizations separate.
    n_atoms, n_atoms_reference : int
    eps_reference : float
        Quantization bound of the reference.
    exact : bool
        Whether every W1 above was computed exactly.
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    t: np.ndarray
    w1_reference: np.ndarray
    w1_quantization: np.ndarray
    n_atoms: int
    n_atoms_reference: int
    eps_reference: float
    exact: bool


def reference_estimate(solution: KineticSolution, reference: KineticSolution,
                       reference_reduced: ReducedSolution, *,
                       quantization=None) -> ReferenceEstimate:
    """Estimate ``W1(μ_M(t), ν(t))`` by a finer reference, and ``W1(μᴺ(t), μᴺ′(t))``.

    ``reference`` must be saved at the same times as ``solution``. ``W1(μᴺ(t), μᴺ′(t))`` does
    not depend on the projection: pass ``quantization`` (its ``(T,)`` values from an earlier
    call with the same two solutions, computed exactly) to reuse it instead of solving its ``T``
    transport problems on ``ℝ²ᵈ`` again.
    """
    if not np.allclose(solution.t, reference.t):
        raise InvalidInput("solution and reference must share their save times")
    c = compare(reference, reference_reduced)
    T = len(solution.t)
    exact = bool(c.exact.all())
    if quantization is not None:
        q = as_array(quantization, "quantization", ndim=1)
        if q.shape != (T,) or not np.all(q >= 0):
            raise InvalidInput(f"quantization must hold W1(μᴺ(t), μᴺ′(t)) >= 0 at the {T} saved "
                               f"times, got shape {q.shape}")
        return ReferenceEstimate(t=np.asarray(solution.t, float), w1_reference=c.w1,
                                 w1_quantization=q.copy(), n_atoms=solution.n_atoms,
                                 n_atoms_reference=reference.n_atoms,
                                 eps_reference=reference.eps, exact=exact)
    q = np.empty(T)
    for i in range(T):
        r = _w1_atoms(np.concatenate([solution.x[i], solution.v[i]], axis=1),
                      np.concatenate([reference.x[i], reference.v[i]], axis=1),
                      solution.weights, reference.weights)
        q[i] = r.midpoint
        exact &= bool(r.exact)
    return ReferenceEstimate(t=np.asarray(solution.t, float), w1_reference=c.w1, w1_quantization=q,
                             n_atoms=solution.n_atoms, n_atoms_reference=reference.n_atoms,
                             eps_reference=reference.eps, exact=exact)


def milling_index(x, v, weights=None) -> float:
    r"""Normalized angular momentum: ``≈ 1`` for a mill, ``≈ 0`` for a translating flock.

    .. math:: m = \frac{\bigl\|\sum_i w_i\, r_i \wedge v_i\bigr\|}{\sum_i w_i \|r_i\|\,\|v_i\|},
              \qquad r_i = x_i - \sum_j w_j x_j,

    with ``‖r ∧ v‖² = ‖r‖²‖v‖² − (r·v)²`` (in ``d = 2`` the usual angular momentum; valid in
    any dimension, so a rotated mill in ``ℝ²⁰⁰`` has the same index).

    Examples
    --------
    >>> th = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    >>> x = np.c_[np.cos(th), np.sin(th)]; v = np.c_[-np.sin(th), np.cos(th)]
    >>> round(milling_index(x, v), 12), round(milling_index(x, np.ones_like(x)), 12)
    (1.0, 0.0)
    """
    x = np.asarray(x, float)
    v = np.asarray(v, float)
    n = x.shape[0]
    w = np.full(n, 1.0 / n) if weights is None else np.asarray(weights, float)
    r = x - w @ x
    A = (r * w[:, None]).T @ v
    W = A - A.T
    num = np.sqrt(0.5 * np.sum(W * W))
    den = float(w @ (np.linalg.norm(r, axis=1) * np.linalg.norm(v, axis=1)))
    return float(num / den) if den > 0 else 0.0
