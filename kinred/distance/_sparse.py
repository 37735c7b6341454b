r"""Exact W1 of two large atomic measures on a sparse candidate graph, certified by its dual.

``method="sparse"`` of :func:`kinred.distance.w1` (eq. (4.5) of the paper, Euclidean ground
cost ``c(x, y) = |x − y|``):

1. **Candidate graph** ``E``: the ``k`` nearest ``yⱼ`` of every ``xᵢ`` and the ``k`` nearest
   ``xᵢ`` of every ``yⱼ`` (:func:`kinred.distance._search.knn`), plus the support of one
   coupling of the full measures -- the identity pairing ``i ↔ i`` when the atoms are paired
   (same count, same weights), otherwise the monotone coupling along the principal axis -- so
   the problem restricted to ``E`` is feasible.
2. **Solve** it with POT's network simplex on the edges ``E`` only (``ot.emd`` with a
   ``scipy.sparse`` cost): an optimal plan ``π`` of the restricted problem, which is a
   coupling of the full measures, so its cost ``U = Σ πᵢⱼ |xᵢ − yⱼ|`` is an **upper bound** of
   W1; and dual potentials ``u, v``.
3. **Certify**: the c-transforms over *all* pairs, ``fᵢ = minⱼ (|xᵢ − yⱼ| − vⱼ)`` and then
   ``gⱼ = minᵢ (|xᵢ − yⱼ| − fᵢ)`` (exact searches, :func:`kinred.distance._search.ctransform`),
   satisfy ``fᵢ + gⱼ ≤ |xᵢ − yⱼ|`` for every pair, so by weak duality of the full linear
   program (equivalently Kantorovich–Rubinstein: ``f`` is 1-Lipschitz)
   ``L = Σ aᵢ fᵢ + Σ bⱼ gⱼ`` is a **lower bound** of W1, whatever ``v`` was.
   With trees (low dimension), the solve's potentials are first **repaired** over all pairs
   (:mod:`kinred.distance._repair`: rebuilt tight along a forest of tight edges, then
   shortest paths on the plan's residual graph with negative-cycle cancelling): degenerate
   plans (paired atoms) have arbitrary restricted duals, whose c-transform leaves a gap that
   no re-solve closes; the repaired ones close it when the plan is optimal, and improve the
   plan when it is not. One full pass finds the violations, one pass restricted to the
   columns the repair changed proves the bound.
4. **Column generation**: the pairs where the dual constraint ``uᵢ + vⱼ ≤ |xᵢ − yⱼ|`` fails
   (up to :data:`VIOLATORS_PER_ROW` per atom, those of smallest reduced cost, collected by the
   certificate's searches) join ``E`` and the problem is solved again, until
   ``U − L`` is at the round-off of the values -- the value is then exact *and proved* -- or
   a budget (iterations, edges, seconds) is spent: the certified bracket ``[L, U]`` is
   returned with the reason.

Atoms of zero weight carry no mass and are dropped first. Memory is priced before anything
is allocated (:func:`kinred._validate.check_alloc`).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .._validate import check_alloc
from ..errors import NotConverged
from ._assign import ASSIGNMENT, is_assignment, load_kernels, solve_assignment
from ._bracket import principal_axis
from ._costscale import PRUNE_EDGES, prune
from ._inputs import Pts
from ._oned import monotone_pieces
from ._repair import certify_repaired
from ._costs import dual_scale, first_per, pair_costs, plan_cost, plan_noise, sorted_unique
from ._search import CTree, OutOfTime, _morton_order, ctransform, knn, use_tree

__all__ = ["SparseOutcome", "sparse_w1", "BYTES_PER_EDGE", "DEFAULT_K", "DEFAULT_RTOL"]

#: Default relative gap at which the bounds count as meeting (the round-off of the plan's cost
#: and of the duals, which the network simplex accumulates along its spanning tree).
DEFAULT_RTOL = 1e-13

#: Cap of the duals' round-off allowance, relative to the value: an exact result is proved
#: within ``(DEFAULT_RTOL + MAX_NOISE_RTOL)·W1`` plus the round-off of the dual sum.
MAX_NOISE_RTOL = 1e-11

#: Neighbours per atom of the candidate graph (from each side).
DEFAULT_K = 8

#: Violated pairs per atom that one round of column generation adds (the smallest reduced
#: costs the certificate's searches meet): several per atom close the gap in fewer solves.
VIOLATORS_PER_ROW = 4

#: Bytes per candidate edge at the peak of one solve: kinred's keys, rows, columns and costs
#: and POT's copies (64-bit sources, targets, costs) and network-simplex arc arrays.
BYTES_PER_EDGE = 128

_EPS = np.finfo(np.float64).eps

#: The general solver's name in results and notes.
NETWORK_SIMPLEX = "POT's network simplex"

#: Below this many pairs N·M the candidate graph is every pair (the problem is dense anyway).
_ALL_PAIRS = 20_000


@dataclass
class SparseOutcome:
    """What :func:`sparse_w1` computed (in the common frame of the measures)."""

    lower: float
    upper: float
    exact: bool
    iterations: int
    edges: int
    seconds: float
    reason: str
    timings: dict = field(default_factory=dict)
    #: the time budget stopped the first network-simplex solve (the bracket is not the dual's)
    first_solve_stopped: bool = False
    #: the solver of the restricted problems (:data:`NETWORK_SIMPLEX` or the assignment's)
    solver: str = ""


def _coupling_edges(X, a, Y, b, paired: bool):
    """One coupling of the full measures, identity or monotone along the pooled atoms'
    principal axis (computed, not drawn: the candidate graph, hence the whole computation,
    does not depend on the seed): its support ``(i, j)`` and masses."""
    if paired:
        idx = np.arange(X.shape[0], dtype=np.int64)
        return idx, idx, a
    pooled = np.concatenate([X, Y])
    pw = np.concatenate([a, b]) / 2.0
    th = principal_axis(pooled, pw)
    i, j, mass = monotone_pieces(X @ th, a, Y @ th, b)
    return i.astype(np.int64), j.astype(np.int64), mass


def _spatial_order(X, a, Y, b, paired: bool):
    """The atoms renumbered along the Z-order curve (the same permutation for both sides
    when they are paired, so that ``i ↔ i`` stays the pairing). W1 does not depend on the
    numbering; the cost scaling and the network simplex do, through memory: neighbours
    numbered near each other share cache lines (10⁵ vs 8·10⁴ weighted atoms in ℝ⁶, in the
    given order → in this one: the cost scaling's six phases 28 → 21 s, three network-simplex
    solves 26 → 16 s). Problems of equal weights (the assignment solver) keep their order."""
    ox = _morton_order(X)
    oy = ox if paired else _morton_order(Y)
    return X[ox], a[ox], Y[oy], b[oy]          # row gathers: C-contiguous already


def _initial_keys(X, a, Y, b, k: int, paired: bool):
    """The candidate graph's keys ``i·m + j`` (sorted, unique) and those of its coupling of the
    full measures (all pairs when there are few)."""
    n, m = X.shape[0], Y.shape[0]
    if n * m <= _ALL_PAIRS:
        every = np.arange(n * m, dtype=np.int64)
        return every, every
    ci, cj, _ = _coupling_edges(X, a, Y, b, paired)
    parts = [ci * m + cj]
    nx = knn(X, Y, k)
    parts.append((np.repeat(np.arange(n, dtype=np.int64), nx.shape[1]) * m) + nx.ravel())
    del nx
    ny = knn(Y, X, k)
    parts.append(ny.ravel() * m + np.repeat(np.arange(m, dtype=np.int64), ny.shape[1]))
    del ny
    # deduplicated: COO -> CSR sums repeats
    return sorted_unique(np.concatenate(parts)), parts[0]


def _solve(a, b, rows, cols, costs, n, m, num_iter_max, assignment=False):
    """The restricted problem on the edges: plan (rows, cols, mass), u, v and the solver's
    name -- with ``assignment`` (``a`` and ``b`` are ``n`` equal weights) the sparse
    assignment solver (:mod:`kinred.distance._assign`), else (or if that fails) POT's network
    simplex."""
    if assignment:
        out = solve_assignment(a, rows, cols, costs, n)
        if out is not None:
            return (*out, ASSIGNMENT)
    import ot
    from scipy.sparse import coo_array

    M = coo_array((costs, (rows, cols)), shape=(n, m))
    it = int(num_iter_max) if num_iter_max is not None else int(max(100_000, 50 * rows.size))
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        G, log = ot.emd(a, b, M, numItermax=it, log=True)
    code = int(log.get("result_code", 1))
    if code == 0:
        raise _Infeasible
    if code != 1:
        raise NotConverged(
            f"w1(method='sparse'): POT's network simplex on {rows.size} candidate edges of a "
            f"{n} x {m} problem returned status {code} ({log.get('warning')!r}) after at most "
            f"numItermax={it} iterations; pass a larger num_iter_max")
    keep = G.data > 0
    return (np.asarray(G.row)[keep].astype(np.int64), np.asarray(G.col)[keep].astype(np.int64),
            np.asarray(G.data)[keep], np.asarray(log["u"], float), np.asarray(log["v"], float),
            NETWORK_SIMPLEX)


#: Candidate graphs from this many edges solve in a forked child when a time budget is set:
#: the network simplex cannot be interrupted, the child can (below it, solves take < 1 s).
FORK_EDGES = 500_000

#: The assignment solver's allowance, before the network simplex takes over:
#: ``ASSIGN_SECONDS + ASSIGN_SECONDS_PER_EDGE·edges``. It runs only on graphs of
#: :data:`FORK_EDGES` edges or more, always in a forked child that can be stopped. Warmed by
#: the ε-scaling auction (:func:`kinred.distance._assign.warm_prices`), LAPJVsp finishes in
#: about a second even when the optimal plan moves atoms by more than their spacing; the
#: auction costs 0.1–5 µs per edge (10⁶ paired atoms near the identity: ~3 s; the
#: delayed-curse scene's 1 075 200 atoms, 10⁷ edges: ~40 s, where the network simplex and a
#: cold LAPJVsp take more than 270 s). scipy's implementation can loop forever on ties (seen
#: on 100 atoms in R¹, cf. scipy gh-17269): the allowance bounds what a wrong guess costs.
ASSIGN_SECONDS = 2.0
ASSIGN_SECONDS_PER_EDGE = 6e-6


class _SolveTimedOut(Exception):
    """Internal: a network-simplex solve passed the deadline (its child was stopped)."""


class _Infeasible(Exception):
    """Internal: the candidate graph holds no coupling of the two measures (POT's status 0).
    Only a pruned graph can be so: it keeps the ε-optimal flow's support, whose margins are
    the weights only within the cost scaling's balance tolerance."""


def _solve_until(a, b, rows, cols, costs, n, m, num_iter_max, deadline):
    """:func:`_solve`, stopped at ``deadline`` (``time.perf_counter``): in a forked child
    process when the graph is large (the inputs are inherited, not copied; only the plan and
    the duals, ``O(n + m)``, come back through a pipe). Raises :class:`_SolveTimedOut`.
    An assignment problem on a large graph first gets the assignment solver's allowance
    (:data:`ASSIGN_SECONDS`) in a child, then the network simplex."""
    import multiprocessing as mp

    args = (a, b, rows, cols, costs, n, m, num_iter_max)
    forkable = rows.size >= FORK_EDGES and "fork" in mp.get_all_start_methods()
    if forkable and is_assignment(a, b):
        load_kernels()
        start = time.perf_counter()
        stop = start + ASSIGN_SECONDS + ASSIGN_SECONDS_PER_EDGE * rows.size
        try:
            return _in_child(lambda: _solve(*args, True),
                             stop if deadline is None else min(stop, deadline))
        except _SolveTimedOut:
            if deadline is not None and time.perf_counter() >= deadline:
                raise
        out = (_solve(*args) if deadline is None else
               _in_child(lambda: _solve(*args), deadline))
        return (*out[:5], f"{out[5]} (the assignment solver was stopped after its "
                          f"{stop - start:.1f} s)")
    if deadline is None or not forkable:
        return _solve(*args)
    return _in_child(lambda: _solve(*args), deadline)


def _in_child(fn, deadline):
    """``fn()`` in a forked child, stopped at ``deadline``; raises what it raised."""
    import multiprocessing as mp
    import pickle

    left = deadline - time.perf_counter()
    if left <= 0:
        raise _SolveTimedOut
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)

    def child():
        try:
            out = ("ok", fn())
        except BaseException as exc:  # noqa: BLE001 -- re-raised in the parent
            out = ("error", exc)
        send.send_bytes(pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL))
        send.close()

    proc = ctx.Process(target=child, daemon=True)
    proc.start()
    send.close()
    try:
        if not recv.poll(left):
            raise _SolveTimedOut
        status, out = pickle.loads(recv.recv_bytes())
    except EOFError:                       # the child died without an answer (e.g. killed)
        status, out = "error", NotConverged(
            "w1(method='sparse'): the network-simplex process ended without a result "
            f"(exit code {proc.exitcode}); lower the atom count or raise the memory limit")
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
        recv.close()
    if status == "error":
        raise out
    return out


def _child_or_none(fn, deadline):
    """``fn()`` in a forked child stopped at ``deadline``, or ``None`` if stopped."""
    try:
        return _in_child(fn, deadline)
    except _SolveTimedOut:
        return None


def _certify(X, a, Y, b, u, v, plan, trees, tiny, deadline=None):
    """Exact c-transforms ``f = v^c`` (over all ``j``) and ``g = f^c`` (over all ``i``), the
    lower bound ``Σ a f + Σ b g`` (exact summation), the size of that sum, the number of rows
    whose search the deadline cut short (their ``f``/``g`` are lower bounds of the minima, so
    ``f + g ≤ c`` still holds for every pair), and the keys of the violated pairs the searches
    met (up to :data:`VIOLATORS_PER_ROW` per row: ``|xᵢ − yⱼ| − vⱼ < uᵢ`` and
    ``|xᵢ − yⱼ| − fᵢ < vⱼ``, beyond ``tiny``)."""
    pr, pc, _ = plan
    n, m = X.shape[0], Y.shape[0]
    c = pair_costs(X, Y, pr, pc)
    rows_x = None if trees[0] is None else trees[0].order
    rows_y = None if trees[1] is None else trees[1].order
    f0, j0 = first_per(pr, n, c - v[pc], pc)
    open_f, open_g = np.zeros(n, np.int8), np.zeros(m, np.int8)
    f, _, cf = ctransform(X, Y, v, f0, j0, trees[1], deadline=deadline, open_rows=open_f,
                          thr=u - tiny, m=VIOLATORS_PER_ROW, rows=rows_x)
    g0, i0 = first_per(pc, m, c - f[pr], pr)
    g, _, cg = ctransform(Y, X, f, g0, i0, trees[0], deadline=deadline, open_rows=open_g,
                          thr=v - tiny, m=VIOLATORS_PER_ROW, rows=rows_y)
    lower = math.fsum(a * f) + math.fsum(b * g)
    scale = dual_scale(a, f, b, g)
    ri, qi = np.nonzero(cf >= 0)
    cj, qj = np.nonzero(cg >= 0)
    new = np.concatenate([ri.astype(np.int64) * m + cf[ri, qi], cg[cj, qj] * m + cj])
    return lower, scale, int(open_f.sum()) + int(open_g.sum()), new


def _price_search(X, Y, trees, deadline):
    """The ``search`` of :func:`kinred.distance._costscale.prune`: over all pairs, up to
    :data:`VIOLATORS_PER_ROW` per row of those whose reduced cost ``|xᵢ − yⱼ| + pxᵢ − pyⱼ``
    is below ``−slack`` (the c-transform's search of ``py`` with threshold ``−px − slack``);
    nothing once the deadline has passed."""
    m = Y.shape[0]

    def search(keys, cost, px, py, slack):
        if deadline is not None and time.perf_counter() > deadline:
            return keys[:0]
        rows, cols = np.divmod(keys, m)
        f0, j0 = first_per(rows, X.shape[0], cost - py[cols], cols)
        try:
            _, _, cand = ctransform(X, Y, py, f0, j0, trees[1], deadline=deadline,
                                    thr=-px - slack, m=VIOLATORS_PER_ROW,
                                    rows=None if trees[0] is None else trees[0].order)
        except OutOfTime:
            return keys[:0]
        ri, qi = np.nonzero(cand >= 0)
        return ri.astype(np.int64) * m + cand[ri, qi]

    return search


def _cheap_lower(X, a, Y, b, rng) -> float:
    """A certified lower bound without the c-transform: the best 1-D projection (exact 1-D W1
    of the projected measures, a Kantorovich–Rubinstein bound)."""
    from ._bracket import projection_lower

    return projection_lower(Pts(X, a), Pts(Y, b), rng, n_projections=8, n_refine=5)[0]


def _paired_late(X, a, Y, b, rng, lower, upper, max_seconds, when: str):
    """Paired atoms whose first round ran out of time after its solve: the paired bracket
    (:func:`_timed_out`) met with the bounds already proved (``lower``, the plan's cost
    ``upper``). Returns ``(lower, upper, reason, exact)``."""
    lo, up, reason, exact = _timed_out(X, a, Y, b, True, rng, lower, upper, 1, max_seconds,
                                       after=when)
    return max(lo, lower), min(up, upper), reason, exact


def _timed_out(X, a, Y, b, paired, rng, lower, upper, it, max_seconds, after: str = ""):
    """``(lower, upper, reason, exact)`` when the budget ran out during solve ``it``: the
    bounds of the earlier solves, or (first solve) those of
    :func:`kinred.distance.paired_w1_bracket` (paired atoms: index coupling, 1-D projections
    and the dual bound searched within another ``max_seconds``, which may prove the index
    coupling optimal) or of the general bracket (explicit couplings, projections, a
    sub-sampled dual)."""
    head = (f"the time budget max_seconds = {max_seconds:g} ran out during solve {it} "
            f"(stopped; " if not after else
            f"the time budget max_seconds = {max_seconds:g} ran out {after} (upper: the "
            f"solved plan's cost; lower: ")
    if it > 1:
        # an early round's c-transform can be a poor (even negative) bound: the 1-D
        # projections' bound costs O(N log N)
        return (max(lower, _cheap_lower(X, a, Y, b, rng)), upper,
                head + "the bounds of the earlier solves and of 1-D projections)", False)
    if paired:
        from ._paired import paired_w1_bracket

        r = paired_w1_bracket(X, Y, a, seed=int(rng.integers(2**32)), dual_seconds=max_seconds)
        how = ("proved optimal by the dual bound" if r.exact else
               "index coupling, 1-D projections, the dual bound")
        return r.lower, r.upper, head + f"the paired bracket: {how})", r.exact
    from ._bracket import bracket_atoms

    lo, up, note = bracket_atoms(Pts(X, a), Pts(Y, b), rng)
    return lo, up, head + note + ")", False


def price(n: int, m: int, d: int, k: int, edges: int, max_bytes=None) -> None:
    """The memory preflight of :func:`sparse_w1` for a graph of ``edges`` edges (TooLarge
    naming the size that fits)."""
    per_atom = 8 * (4 * d + 40)
    nbytes = BYTES_PER_EDGE * edges + per_atom * (n + m)

    def hint():
        per = 2 * (BYTES_PER_EDGE * (k + 1) + per_atom)     # n = m: edges (k + 1)(n + m)
        from .._validate import max_bytes_limit
        fits = max_bytes_limit(max_bytes) // max(per, 1)
        return (f"about {fits} atoms per side fit (k = {k}); pass a smaller k or max_edges, or "
                "raise the limit")

    check_alloc(nbytes, "w1(method='sparse'): the candidate graph and the network simplex",
                hint, max_bytes=max_bytes, keyword="max_bytes",
                detail=f" for {n} x {m} atoms in dimension {d} ({edges} edges of "
                       f"{BYTES_PER_EDGE} bytes)")


def _fits(n, m, d, k, edges, max_bytes) -> bool:
    from ..errors import TooLarge

    try:
        price(n, m, d, k, edges, max_bytes)
    except TooLarge:
        return False
    return True


def default_max_edges(n: int, m: int, k: int) -> int:
    """Edge budget of the column generation: four times the initial graph's size."""
    return int(min(n * m, 4 * (2 * k + 1) * (n + m)))


def sparse_w1(P: Pts, Q: Pts, rng, *, k: int = DEFAULT_K, rtol: float | None = None,
              max_iter: int = 30, max_edges: int | None = None, max_seconds: float | None = None,
              max_bytes=None, num_iter_max: int | None = None) -> SparseOutcome:
    """Certified ``lower ≤ W1(P, Q) ≤ upper`` by the sparse network simplex and its dual.

    Parameters
    ----------
    P, Q : Pts
        The measures (same dimension; any weights, zero weights allowed).
    rng : numpy Generator
        For the principal axis of the monotone coupling (unpaired atoms).
    k : int
        Nearest neighbours per atom from each side.
    rtol : float, optional
        Stop (``exact``) when ``upper − lower ≤ rtol·upper + 16ε·S + 4δ``: ``S = Σ aᵢ|fᵢ − t| +
        Σ bⱼ|gⱼ + t|`` the size of the dual sum (``t`` the median of ``f``) and ``δ =
        max |c − u − v|`` over the plan's edges (zero in exact arithmetic: the round-off the
        network simplex left in its potentials; ``4δ`` capped at ``MAX_NOISE_RTOL·upper``).
        Default :data:`DEFAULT_RTOL`.
    max_iter, max_edges, max_seconds : budgets of the column generation.
    max_bytes : the memory limit of the preflight.
    num_iter_max : network-simplex iterations per solve (default ``max(1e5, 50·edges)``).
    """
    t0 = time.perf_counter()
    X, a, Y, b, paired = _positive_atoms(P, Q)
    n, m, d = X.shape[0], Y.shape[0], X.shape[1]
    budget = _Budget(max_iter, default_max_edges(n, m, k) if max_edges is None
                     else int(max_edges), max_seconds, max_bytes, t0)
    tm = {}
    keys, unpruned, trees = _candidates(X, a, Y, b, k, paired, budget, tm)
    tm["solve"] = tm["certify"] = 0.0
    lower, upper, scale, reason, exact, it = -math.inf, math.inf, 0.0, "", False, 0
    stopped_first = False
    solver = NETWORK_SIMPLEX
    while True:
        it += 1
        s = time.perf_counter()
        try:
            up, u, v, plan, noise, solver = _solve_round(X, a, Y, b, keys, num_iter_max,
                                                         budget.deadline)
        except _Infeasible:
            if unpruned is None:
                raise NotConverged(f"w1(method='sparse'): POT's network simplex found the "
                                   f"{keys.size} candidate edges of a {n} x {m} problem "
                                   "infeasible although they hold a coupling of the measures")
            # the full measures' coupling makes the pruned graph feasible (kept out until
            # needed: its long edges make the solves three times slower)
            tm["solve"] += time.perf_counter() - s
            keys, unpruned, it = sorted_unique(np.concatenate([keys, unpruned])), None, it - 1
            continue
        except _SolveTimedOut:
            tm["solve"] += time.perf_counter() - s
            lower, upper, reason, exact = _timed_out(X, a, Y, b, paired, rng, lower, upper,
                                                     it, max_seconds)
            stopped_first = it == 1
            break
        tm["solve"] += time.perf_counter() - s
        # paired atoms, first solve, budget spent: the paired bracket's dual bound (what a
        # stopped first solve gets) with the plan's cost as upper end, flagged as stopped so
        # that the kinetic comparison's later times do not wait again
        late = it == 1 and paired and max_seconds is not None
        if late and budget.spent():
            lower, upper, reason, exact = _paired_late(X, a, Y, b, rng, lower, min(upper, up),
                                                       max_seconds, "with solve 1, before its "
                                                       "certificate")
            stopped_first = True
            break
        upper = min(upper, up)
        try:
            upper, lo, scale, n_open, new, noise = _certificate(
                X, a, Y, b, u, v, plan, keys, trees, upper, noise, budget.deadline, tm)
        except OutOfTime:
            if not late:
                lower, scale = max(lower, _cheap_lower(X, a, Y, b, rng)), upper
                reason = (f"the time budget max_seconds = {max_seconds:g} ran out during the "
                          "certificate (lower bound: the best of the c-transform of an earlier "
                          "solve and 1-D projections)")
                break
            # a search cut short by the deadline: the paired bracket below gives the lower end
            lo, scale, n_open, new = -math.inf, upper, 0, keys[:0]
        late = late and budget.spent()
        if n_open and not late:
            lo = max(lo, _cheap_lower(X, a, Y, b, rng))
        lower = max(lower, lo)
        tol = ((rtol if rtol is not None else DEFAULT_RTOL) * upper + 16 * _EPS * scale
               + min(4 * noise, MAX_NOISE_RTOL * upper))
        if upper - lower <= tol:
            exact = True
            break
        if late:
            lower, upper, reason, exact = _paired_late(X, a, Y, b, rng, lower, upper,
                                                       max_seconds, "during solve 1's "
                                                       "certificate")
            stopped_first = True
            break
        merged = sorted_unique(np.concatenate([keys, new]))
        reason = budget.stop_reason(keys.size, merged.size, it, n_open, (n, m, d, k))
        if reason:
            break
        keys = merged
    if not exact:
        pad = 8 * _EPS * (upper + scale)
        lower, upper = max(0.0, lower - pad), upper + pad
    return SparseOutcome(lower=max(lower, 0.0) if not exact else upper, upper=upper, exact=exact,
                         iterations=it, edges=int(keys.size),
                         seconds=time.perf_counter() - t0, reason=reason, timings=tm,
                         first_solve_stopped=stopped_first, solver=solver)


def _positive_atoms(P: Pts, Q: Pts):
    """``(X, a, Y, b, paired)``: the atoms of positive weight, contiguous, in a spatial order
    when the problem is past all pairs (an assignment keeps its order); ``paired``: the
    measures have equal sizes and weights."""
    ka, kb = P.weights > 0, Q.weights > 0
    paired = P.n == Q.n and bool(np.array_equal(P.weights, Q.weights))
    X, a = np.ascontiguousarray(P.points[ka]), P.weights[ka]
    Y, b = np.ascontiguousarray(Q.points[kb]), Q.weights[kb]
    if X.shape[0] * Y.shape[0] > _ALL_PAIRS and not is_assignment(a, b):
        X, a, Y, b = _spatial_order(X, a, Y, b, paired)
    return X, a, Y, b, paired


def _candidates(X, a, Y, b, k: int, paired: bool, budget: "_Budget", tm: dict):
    """The first candidate graph after its memory preflight: ``(keys, unpruned, trees)``.

    ``keys``: the edges (nearest neighbours of both sides and a feasible coupling), pruned by
    the cost-scaling prices when large; ``unpruned``: that coupling's edges when the pruning
    may have dropped them (added back if a solve finds the graph infeasible), else None;
    ``trees``: the KD-trees of both sides (or ``(None, None)``). Times go to ``tm`` (the
    graph's from the budget's start)."""
    n, m, d = X.shape[0], Y.shape[0], X.shape[1]
    price(n, m, d, k, min(n * m, k * (n + m) + n + m), budget.max_bytes)
    keys, coupling = _initial_keys(X, a, Y, b, k, paired)
    trees = (CTree(X), CTree(Y)) if use_tree(n, m, d) else (None, None)
    tm["graph"] = time.perf_counter() - budget.t0
    unpruned = None
    if keys.size >= PRUNE_EDGES and not is_assignment(a, b):
        s = time.perf_counter()
        pruned = prune(X, a, Y, b, keys, budget.deadline, run_until=_child_or_none,
                       search=_price_search(X, Y, trees, budget.deadline))
        if pruned is not None:
            keys, unpruned = pruned[0], coupling
        tm["prices"] = time.perf_counter() - s
    return keys, unpruned, trees


def _certificate(X, a, Y, b, u, v, plan, keys, trees, upper, noise, deadline, tm):
    """One round's certificate of the duals ``(u, v)``: ``(upper, lower, scale, open rows,
    new edges, noise)``. With KD-trees the plan is repaired first (its cost may lower
    ``upper``); :class:`OutOfTime` (its time counted in ``tm``) if the deadline passes."""
    s = time.perf_counter()
    roundoff = 4 * _EPS * (upper + float(np.max(np.abs(u))) + float(np.max(np.abs(v))))
    try:
        if trees[0] is not None:
            up, lo, scale, n_open, new, noise = certify_repaired(
                X, a, Y, b, u, v, plan, keys, trees, roundoff, noise, deadline, tm,
                VIOLATORS_PER_ROW)
            return min(upper, up), lo, scale, n_open, new, noise
        lo, scale, n_open, new = _certify(X, a, Y, b, u, v, plan, trees, roundoff + 2 * noise,
                                          deadline)
    except OutOfTime:
        tm["certify"] += time.perf_counter() - s
        raise
    tm["certify"] += time.perf_counter() - s
    return upper, lo, scale, n_open, new, noise


def _solve_round(X, a, Y, b, keys, num_iter_max, deadline):
    """One solve on the edges ``keys``: the plan's cost, the duals, the plan, and the largest
    ``|c − u − v|`` on the plan's edges (zero in exact arithmetic: the duals' round-off)."""
    n, m = X.shape[0], Y.shape[0]
    rows, cols = np.divmod(keys, m)
    costs = pair_costs(X, Y, rows, cols)
    pr, pc, pm, u, v, solver = _solve_until(a, b, rows, cols, costs, n, m, num_iter_max,
                                            deadline)
    del costs, rows, cols
    plan = (pr, pc, pm)
    return plan_cost(X, Y, plan), u, v, plan, plan_noise(X, Y, u, v, plan), solver


@dataclass
class _Budget:
    """The column generation's budgets: solves, edges, seconds, bytes."""

    max_iter: int
    max_edges: int
    max_seconds: float | None
    max_bytes: object
    t0: float

    @property
    def deadline(self):
        return None if self.max_seconds is None else self.t0 + self.max_seconds

    def spent(self) -> bool:
        """Whether the time budget is spent."""
        return self.deadline is not None and time.perf_counter() >= self.deadline

    def stop_reason(self, size: int, merged: int, it: int, n_open: int, dims) -> str:
        """Why the next round does not run ("" when it does)."""
        elapsed = time.perf_counter() - self.t0
        if merged == size:
            return ("no dual constraint of the restricted problem fails beyond round-off "
                    "(its duals are not accurate enough to close the gap)")
        if it >= self.max_iter:
            return f"the iteration budget max_iter = {self.max_iter} is spent"
        if merged > self.max_edges:
            return (f"the edge budget max_edges = {self.max_edges} is spent (the next graph "
                    f"has {merged} edges)")
        if not _fits(*dims, merged, self.max_bytes):
            return (f"the next graph ({merged} edges) would exceed the memory limit "
                    f"max_bytes (KINRED_MAX_BYTES)")
        if self.max_seconds is not None and elapsed >= self.max_seconds:
            return (f"the time budget max_seconds = {self.max_seconds:g} is spent "
                    f"({elapsed:.1f} s" + (
                        f"; the certificate's search was cut short for {n_open} atoms, whose "
                        "c-transform values are the bounds of the regions left open)"
                        if n_open else ")"))
        return ""


def describe(o: SparseOutcome, k: int, unit: float) -> str:
    """The note of a ``method="sparse"`` result."""
    head = (f"{o.solver or NETWORK_SIMPLEX} on a sparse candidate graph ({k} nearest "
            f"neighbours from each side + one coupling; {o.edges} edges after {o.iterations} "
            f"solve(s) of "
            f"column generation, {o.seconds:.2f} s)")
    if o.exact and o.first_solve_stopped:
        return (head + f"; exact all the same: {o.reason}; the index coupling's cost meets "
                       "the dual lower bound to round-off")
    if o.exact:
        return (head + "; optimal over all pairs: the c-transform lower bound meets the plan's "
                       "cost to round-off")
    gap = (o.upper - o.lower) / o.upper if o.upper > 0 else 0.0
    src = ("" if o.first_solve_stopped else
           " (lower: c-transform of the duals over all pairs; upper: the plan's cost)")
    return (head + f"; NOT exact, certified bracket of relative width {gap:.2g}{src} because "
                   f"{o.reason}")



def run_sparse(PA: Pts, PB: Pts, rng, *, k: int, rtol, max_iter: int, max_edges, max_seconds,
               max_bytes, num_iter_max, n_atoms, unit: float):
    """``method="sparse"`` of :func:`kinred.distance.w1`: a :class:`W1Result` in the common
    frame (exact, or the certified bracket with the reason in its note)."""
    from ._result import W1Result

    o = sparse_w1(PA, PB, rng, k=k, rtol=rtol, max_iter=max_iter, max_edges=max_edges,
                  max_seconds=max_seconds, max_bytes=max_bytes, num_iter_max=num_iter_max)
    info = {"iterations": o.iterations, "edges": o.edges, "seconds": o.seconds,
            "reason": o.reason, "first_solve_stopped": o.first_solve_stopped,
            "solver": o.solver,
            **{(key if key.startswith("repair_") else f"seconds_{key}"): val
               for key, val in o.timings.items()}}
    value = o.upper if o.exact else 0.5 * (o.lower + o.upper)
    return W1Result(value, "sparse", o.exact, o.lower, o.upper, n_atoms, describe(o, k, unit),
                    "euclidean", info)
