r"""Repair of a sparse network-simplex solution over all pairs (:mod:`kinred.distance._sparse`).

The network simplex on a candidate graph returns a plan ``π`` that is optimal *on the graph*
and potentials ``u, v`` that are one of many optimal duals of the restricted problem -- when
the plan is degenerate (paired atoms: ``n`` positive entries instead of ``2n − 1``) the
restricted duals are far from unique, and the c-transform of an arbitrary choice can leave a
gap although the plan is already optimal over all pairs. Adding the violated pairs and solving
again (column generation) then only draws another arbitrary dual.

:func:`repair` instead corrects the potentials in place by shortest paths on the residual
graph of ``π`` over *all* pairs (:func:`kinred.distance._repair_kernels.repair_plan`): the
largest potentials below the given ones that are feasible for every pair and tight on the
plan's support. If the plan is not optimal over all pairs, the same search meets a cycle of
negative length and moves mass around it (cycle cancelling), so the plan improves too. The
result is checked by the certificate (the c-transform over all pairs), never trusted.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ._costs import dual_scale, first_per, pair_costs, plan_cost, plan_noise, sorted_unique
from ._search import CTree, ctransform

__all__ = ["repair", "RepairOutcome"]

#: Work budget of one repair (queue steps) per atom.
WORK_PER_ATOM = 20

#: The repair's allowance in one round of column generation: ``REPAIR_ALLOWANCE`` times the
#: seconds of the round's certificate pass, plus ``REPAIR_SECONDS``.
REPAIR_ALLOWANCE = 1.0
REPAIR_SECONDS = 2.0

#: Room for the edges that cycle cancelling adds, per atom.
NEW_EDGES_PER_ATOM = 1.0


@dataclass
class RepairOutcome:
    """What :func:`repair` returned: the plan ``(rows, cols, mass)``, ``u``, ``v``, the kernel's
    status (0: the potentials converged, feasible and tight up to ``tiny``; 1: the work budget
    or the deadline stopped it; 2: no room for new edges), the queue steps, the cycles
    cancelled and the seconds of the first (parallel) search."""

    plan: tuple
    u: np.ndarray
    v: np.ndarray
    status: int
    work: int
    cycles: int
    search_seconds: float

    @property
    def converged(self) -> bool:
        return self.status == 0


def tighten(X, Y, u, v, plan, keys, tol: float):
    """Potentials recomputed exactly tight along a spanning forest of the candidate graph's
    nearly tight edges (``|c − u − v| ≤ tol``; the plan's edges first): a network simplex's
    potentials carry the round-off of its pivots (about ``1e-11`` on 10⁶ atoms), the
    forest's are exact up to one rounding per edge along a path. Values at the forest's roots
    (one per component) are kept. Returns new ``u, v``."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import breadth_first_order, connected_components, \
        minimum_spanning_tree

    from ._repair_kernels import propagate_tight
    n, m = X.shape[0], Y.shape[0]
    pr, pc, _ = plan
    rows, cols = np.divmod(keys, m)
    rc = np.abs(pair_costs(X, Y, rows, cols) - u[rows] - v[cols])
    near = rc <= tol
    w = np.concatenate([np.full(pr.size, 1e-300), np.maximum(rc[near], 1e-280) + 1e-280])
    r = np.concatenate([pr, rows[near]])
    c = np.concatenate([pc, cols[near]]) + n
    G = coo_array((w, (r, c)), shape=(n + m + 1, n + m + 1)).tocsr()   # repeats: summed, tiny
    T = minimum_spanning_tree(G)
    ncomp, label = connected_components(T, directed=False)
    roots = np.unique(label[:n + m], return_index=True)[1]
    T = (T + T.T).tocoo()
    R = coo_array((np.ones(roots.size), (np.full(roots.size, n + m), roots)),
                  shape=(n + m + 1, n + m + 1))
    order, pred = breadth_first_order((T + R + R.T).tocsr(), n + m, directed=False)
    pred = np.where(pred == n + m, -1, pred)
    u, v = np.array(u, float), np.array(v, float)
    propagate_tight(order[1:].astype(np.int64), pred.astype(np.int64), n,
                    np.ascontiguousarray(X), np.ascontiguousarray(Y), u, v)
    return u, v


def _violating_columns(X, Y, u, v, plan, tree: CTree, tiny: float) -> np.ndarray:
    """Columns ``j`` with some ``|xᵢ − yⱼ| − uᵢ < vⱼ − tiny`` (in parallel, exact search)."""
    pr, pc, _ = plan
    c = pair_costs(X, Y, pr, pc)
    g0, i0 = first_per(pc, Y.shape[0], c - u[pr], pr)
    _, _, cand = ctransform(Y, X, u, g0, i0, tree, thr=v - tiny, m=1)
    return np.nonzero(cand[:, 0] >= 0)[0]


def repair(X, Y, u, v, plan, tree: CTree, tiny: float, max_work: int | None = None,
           max_new_edges: int | None = None, deadline: float | None = None,
           start: np.ndarray | None = None) -> RepairOutcome:
    """Potentials feasible over all pairs and tight on the plan (and the plan itself improved
    by cycle cancelling), starting from ``u, v``; ``tree`` is a :class:`CTree` of ``X``.
    ``start``: the columns to search first -- for every pair violated by ``u, v`` beyond
    ``tiny``, its column or, for its row, the column of the row's minimum of ``c − v`` (by
    default found by one parallel search over all pairs)."""
    from ._repair_kernels import OUT_OF_WORK, repair_plan

    n, m = X.shape[0], Y.shape[0]
    pr, pc, pm = plan
    t0 = time.perf_counter()
    if start is None:
        start = _violating_columns(X, Y, u, v, plan, tree, tiny)
    t_search = time.perf_counter() - t0
    if start.size == 0:
        return RepairOutcome(plan, u, v, 0, 0, 0, t_search)
    extra = int(max_new_edges if max_new_edges is not None
                else max(1024, NEW_EDGES_PER_ATOM * (n + m)))
    cap = pr.size + extra
    erow = np.empty(cap, np.int64)
    ecol = np.empty(cap, np.int64)
    emass = np.zeros(cap)
    erow[:pr.size] = tree.rank[pr]
    ecol[:pr.size] = pc
    emass[:pr.size] = pm
    head = np.full(n, -1, np.int64)
    nxt = np.full(cap, -1, np.int64)
    _link(erow, head, nxt, pr.size)
    us = np.ascontiguousarray(u[tree.order], dtype=np.float64)
    v = np.array(v, dtype=np.float64)
    umax = tree.node_vmax(u)
    scale = float(np.max(np.abs(tree.Ys))) + float(np.max(np.abs(Y))) + float(np.max(np.abs(u)))
    slack = 16 * np.finfo(np.float64).eps * scale
    budget = int(max_work if max_work is not None else WORK_PER_ATOM * (n + m))
    queue = np.empty(n + m, np.int64)
    queue[:start.size] = n + start
    inq = np.zeros(n + m, np.uint8)
    inq[n + start] = 1
    qs = np.array([0, start.size % (n + m), start.size, 0], np.int64)
    pred_x, pred_y = np.full(n, -1, np.int64), np.full(m, -1, np.int64)
    rows = np.empty(n, np.int64)
    Yc = np.ascontiguousarray(Y, dtype=np.float64)
    ne, status, work, cycles = pr.size, OUT_OF_WORK, 0, 0
    chunk = 10_000                       # queue steps between looks at the clock
    while status == OUT_OF_WORK and work < budget:
        if deadline is not None and time.perf_counter() > deadline:
            break
        ne, status, w, c = repair_plan(
            tree.Ys, Yc, us, v, tree.lo, tree.hi, umax, tree.first_leaf, tree.starts, erow,
            ecol, emass, ne, head, nxt, queue, inq, qs, pred_x, pred_y, rows, float(tiny),
            slack, min(chunk, budget - work))
        work += w
        cycles += c
        if status == OUT_OF_WORK:
            # u only went down: the nodes' bounds of u, computed again, prune more
            umax = tree.node_vmax(us, ordered=True)
    keep = emass[:ne] > 0
    u_new = np.empty(n)
    u_new[tree.order] = us
    new_plan = (tree.order[erow[:ne][keep]], ecol[:ne][keep], emass[:ne][keep])
    return RepairOutcome(new_plan, u_new, v, int(status), int(work), int(cycles), t_search)


def _link(erow, head, nxt, ne):
    """Each row's list of plan edges (``head[p]``, then ``nxt[e]``), ``O(edges)``."""
    order = np.argsort(erow[:ne], kind="stable")
    rows = erow[:ne][order]
    first = np.ones(ne, bool)
    first[1:] = rows[1:] != rows[:-1]
    nxt[order[:-1]] = np.where(first[1:], -1, order[1:])
    if ne:
        nxt[order[-1]] = -1
    head[rows[first]] = order[first]


def _restricted_ctransform(X, Y, v, cols, f):
    """``min(fᵢ, min over j in cols of (|xᵢ − yⱼ| − vⱼ))`` for every row (exact; a tree over
    the few ``cols`` only: rows whose bound already beats every node stop at the root)."""
    if cols.size == 0:
        return f
    sub = CTree(np.ascontiguousarray(Y[cols]))
    out, _ = ctransform(X, Y[cols], v[cols], np.array(f, float),
                        np.zeros(X.shape[0], np.int64), sub)
    return np.minimum(out, f)


def certify_repaired(X, a, Y, b, u, v, plan, keys, trees, roundoff, noise, deadline, tm,
                     violators: int):
    """One round's certificate with the repair (tree searches; ``trees`` of ``X`` and ``Y``).

    1. ``u, v`` rebuilt tight (:func:`tighten`); 2. ``f = v^c`` over all pairs (one parallel
    pass; ``L₀ = Σ a f + Σ b v`` is already a lower bound) with the violators of every row;
    3. if rows are violated, :func:`repair` from the columns of their minima; if it converged,
    the certificate of the repaired ``v′`` costs one restricted pass: ``f′ = min(f, min over
    the changed columns J of (c − v′))`` satisfies ``f′ᵢ + v′ⱼ ≤ cᵢⱼ`` for every pair (``v′ = v``
    off ``J``), so ``L = Σ a f′ + Σ b v′`` is proved without a second full pass.

    Returns ``(upper, lower, scale, open rows, new candidate keys, noise)``: the best plan's
    cost, the lower bound, the size of the dual sum, rows the deadline cut short, the
    violators and repaired plan's edges for column generation, the potentials' round-off on
    the plan."""
    n, m = X.shape[0], Y.shape[0]
    s = time.perf_counter()
    u, v = tighten(X, Y, u, v, plan, keys, 1e3 * noise + roundoff)
    tm["tighten"] = tm.get("tighten", 0.0) + time.perf_counter() - s
    s = t_certify = time.perf_counter()
    pr, pc, _ = plan
    f0, j0 = first_per(pr, n, pair_costs(X, Y, pr, pc) - v[pc], pc)
    open_f = np.zeros(n, np.int8)
    f, jf, cand = ctransform(X, Y, v, f0, j0, trees[1], deadline=deadline, open_rows=open_f,
                             thr=u - roundoff, m=violators, rows=trees[0].order)
    ri, qi = np.nonzero(cand >= 0)
    new = ri.astype(np.int64) * m + cand[ri, qi]
    upper = plan_cost(X, Y, plan)
    lower = math.fsum(a * f) + math.fsum(b * v)
    tm["certify"] = tm.get("certify", 0.0) + time.perf_counter() - s
    bad = f < u - roundoff
    n_open = int(open_f.sum())
    # a plan of n + m − 1 positive entries (weighted atoms, in general position) is a spanning
    # tree: its duals are unique up to a constant, so the repair has no dual to choose, and
    # its cycle cancelling over all pairs is slower than column generation (10⁵ vs 8·10⁴
    # weighted atoms in ℝ⁶: out of its allowance, 5 s per round, in every round)
    if not bad.any() or n_open or pr.size >= n + m - 1:
        return upper, lower, dual_scale(a, f, b, v), n_open, new, plan_noise(X, Y, u, v, plan)
    s = time.perf_counter()
    # the repair is quick on an optimal plan and slow on one far from it (cycle cancelling:
    # minutes at 10^5 atoms): it gets about the certificate's time, then column generation
    # improves the plan and the next round's repair finishes
    allowance = s + REPAIR_ALLOWANCE * (s - t_certify) + REPAIR_SECONDS
    r = repair(X, Y, u, v, plan, trees[0], roundoff,
               deadline=allowance if deadline is None else min(deadline, allowance),
               start=sorted_unique(jf[bad]))
    tm["repair"] = tm.get("repair", 0.0) + time.perf_counter() - s
    tm["repair_cycles"] = tm.get("repair_cycles", 0) + r.cycles
    tm["repair_work"] = tm.get("repair_work", 0) + r.work
    rp, rc, _ = r.plan
    new = np.concatenate([new, rp * m + rc])
    upper = min(upper, plan_cost(X, Y, r.plan))
    if not r.converged:
        return upper, lower, dual_scale(a, f, b, v), 0, new, plan_noise(X, Y, u, v, plan)
    s = time.perf_counter()
    f2 = _restricted_ctransform(X, Y, r.v, np.nonzero(r.v != v)[0], f)
    lower = max(lower, math.fsum(a * f2) + math.fsum(b * r.v))
    tm["certify"] += time.perf_counter() - s
    return upper, lower, dual_scale(a, f2, b, r.v), 0, new, plan_noise(X, Y, r.u, r.v, r.plan)
