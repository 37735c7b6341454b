r"""The candidate graph of weighted problems pruned by ε-optimal prices (``method="sparse"``).

POT's network simplex on the ``k``-nearest-neighbour graph of two *weighted* clouds grows like
``N^2.4`` when the optimal plan moves mass by more than the atoms' spacing (10⁵ vs 8·10⁴
atoms in ℝ⁶, 1.1·10⁶ edges: more than 240 s). On the edges of small reduced cost under
near-optimal prices it is fast (the same problem on 1.8·10⁵ such edges: about 2 s), and an
optimal plan lives there: complementary slackness puts it on the edges of zero reduced cost
under exact duals, which ε-optimal prices move by little.

:func:`prune` computes ε-optimal prices by cost scaling
(:func:`kinred.distance._costscale_kernels.transport_prices`, ``ε`` from
:data:`EPS_START` to :data:`EPS_END` times the mean edge cost) and keeps the edges with
``r_e ≤`` :data:`KEEP_EPS` ``· ε_end`` and the support of its ε-optimal flow (whose
margins are the weights within the balance tolerance: should the pruned problem be
infeasible, :func:`kinred.distance._sparse.sparse_w1` adds a coupling of the full measures).

Prices ε-optimal on the ``k``-nearest-neighbour graph only are not enough when the optimal plan
of the full measures uses pairs outside it: the kept edges then hold the graph's optimum, and
each round of column generation re-solves with a few of the missing pairs at a time. So the
prices are **extended** (:func:`_extended`): after every phase, ``search`` finds over
*all* pairs those of reduced cost below ``−SEARCH_EPS·ε`` (the c-transform's bounded search,
with the prices as duals), they join the graph, and the next phase prices them (after the
last, the phase runs again warm from its prices and flow) -- column generation done on
ε-optimal prices, where it is cheap, instead of on exact duals (10⁵ vs 8·10⁴ atoms in ℝ⁶:
240 s and not closed before, 55–56 s exact with it).

Nothing is lost if a guess is wrong: column generation adds every pair whose dual constraint
fails, over all pairs, and the value is proved by the c-transform as always.
"""

from __future__ import annotations

import numpy as np

from ._costs import pair_costs, sorted_unique

__all__ = ["prune", "PRUNE_EDGES"]

#: Weighted problems from this many candidate edges are pruned (below, the network simplex
#: takes a second or less on the whole graph).
PRUNE_EDGES = 200_000

#: The cost scaling's ε schedule, in units of the mean edge cost (as the auction's). The last
#: phases are cheap (the first ones move the mass) and finer prices need fewer rounds of
#: column generation on a smaller graph.
EPS_START = 0.5
EPS_END = 3e-5
THETA = 6.0

#: Edges kept: reduced cost at most ``KEEP_EPS · ε_end`` (and the flow's support), i.e. within
#: ``6·10⁻⁴`` of the mean edge cost. The network simplex is sensitive to the few edges beyond
#: the optimal plan's: 10⁵ vs 8·10⁴ weighted atoms in ℝ⁶, with ``ε_end = 10⁻⁴``, one solve on
#: the 1.82·10⁵ edges kept within ``6ε_end`` takes 3.1–3.7 s, on 1.83·10⁵ (``16ε_end``)
#: 4.5–5.9 s, on 1.88·10⁵ (``40ε_end``) 12–14 s. With ``ε_end = 3·10⁻⁵`` and the same band,
#: 2.0–2.4 s and three rounds: 51 s in all, against 60 s (five rounds) at ``10⁻⁴`` and 54 s
#: (two rounds, a longer pricing) at ``10⁻⁵`` with ``KEEP_EPS = 60``.
KEEP_EPS = 20.0

#: Rounds of extending the prices to pairs outside the pool at the last phase
#: (:func:`prune`'s ``search``).
EXTEND_ROUNDS = 8
#: The search for pairs outside the pool: reduced cost below ``−SEARCH_EPS·ε``, after every
#: phase; after the last, below ``−SEARCH_EPS_LAST·ε`` (every pair where ε-optimality fails),
#: until at most ``EXTEND_STOP·(n + m)`` are found. From the first phase on: the missing pairs
#: are found while ``ε`` is coarse, where pricing them is cheap. 10⁵ vs 8·10⁴ weighted atoms,
#: the second cloud shifted by 0.05: in ℝ⁴, where the plan moves mass far beyond the
#: ``k``-nearest-neighbour graph (390 000 pairs missing after the third phase), exact in 196 s
#: where searching only from ``ε = 1.4·10⁻²·unit`` on ended at 210 s with a bracket (each late
#: phase absorbing 200 000–400 000 pairs: 25–60 s); in ℝ⁶ (shift 0.02, the benchmark's case)
#: 51.6–56.2 s against 52.0 s. Searching only from ``3·10⁻³`` on, that case took 86 s.
SEARCH_EPS = 4.0
SEARCH_EPS_LAST = 1.0
EXTEND_STOP = 1e-3

#: A node counts as balanced within ``BALANCE·max weight`` (the prices only choose edges: mass
#: this small misplaced changes nothing, while a tolerance near the round-off of the excess
#: bookkeeping -- millions of ± updates -- can leave a crumb above it with no deficit to take
#: it, circulating until the work budget is spent).
BALANCE = 1e-9

#: Discharges per node the cost scaling may spend before the whole graph is solved instead
#: (10⁵ vs 8·10⁴ atoms in ℝ⁶: about 400).
WORK_PER_NODE = 4000


def prune(X, a, Y, b, keys: np.ndarray, deadline=None, run_until=None, search=None):
    """``(kept, pool)``: the edges of ``pool`` worth solving on and the pool -- ``keys``
    (``i·m + j``) grown by the pairs ``search`` found -- or ``None`` (no prices: a node
    without edges, the work budget spent, the deadline passed). ``run_until(fn, deadline)``:
    runs ``fn`` stopped at ``deadline`` (``None`` when stopped); used when ``deadline`` is
    set.

    ``search(keys, cost, px, py, slack)``: the keys of pairs, over *all* pairs, whose reduced
    cost ``c + px − py`` is below ``−slack`` (or an empty array). With it the prices are
    extended to the full problem (:func:`_extended`): the violators join the pool and the
    next phase -- after the last, the last phase again -- restores ε-optimality on them, so
    that the kept edges hold an optimal plan of the full measures, not only of the
    ``k``-nearest-neighbour graph."""
    n, m = X.shape[0], Y.shape[0]
    rows, cols = np.divmod(keys, m)
    if (np.count_nonzero(np.bincount(rows, minlength=n)) < n
            or np.count_nonzero(np.bincount(cols, minlength=m)) < m):
        return None
    cost = pair_costs(X, Y, rows, cols)
    unit = float(cost.mean())
    if not unit > 0:
        return None
    out = _extended(X, a, Y, b, keys, cost, unit, deadline, run_until, search)
    if out is None:
        return None
    keys, cost, px, py, f = out
    rows, cols = np.divmod(keys, m)
    rc = cost + px[rows] - py[cols]
    keep = (rc <= KEEP_EPS * EPS_END * unit) | (f > 0)
    return keys[keep], keys


def _extended(X, a, Y, b, keys, cost, unit, deadline, run_until, search):
    """The cost scaling phase by phase, its prices extended to all pairs: after every phase,
    the pairs of reduced cost below ``−SEARCH_EPS·ε`` join
    the pool, and the next phase prices them (its start restores ε-optimality on them with
    the step in ``ε``); after the last phase, every pair where ε-optimality fails (reduced
    cost below ``−SEARCH_EPS_LAST·ε``) joins, and the phase runs again from its prices and
    flow while more than ``EXTEND_STOP·(n + m)`` are found (at most :data:`EXTEND_ROUNDS`
    times; the last few found join the pool unpriced: their reduced cost is negative, so
    they are kept). Running a phase again at the same ``ε`` costs a whole phase: 46 000 pairs found
    at ``ε = 3.9·10⁻⁴·unit`` took 12–13 s against 4 s for the phase itself (10⁵ vs 8·10⁴
    weighted atoms in ℝ⁶: 106 s with a re-run at each phase, 91–96 s with the next phase
    absorbing them). Without ``search``, plain cost scaling. Returns ``(keys, cost, px, py,
    flow)`` or ``None``."""
    n, m = X.shape[0], Y.shape[0]
    eps, flow, px, py = EPS_START * unit, None, np.zeros(n), np.zeros(m)
    while True:
        last = eps <= EPS_END * unit
        for rnd in range(EXTEND_ROUNDS + 1):
            rows, cols = np.divmod(keys, m)
            out = _prices(rows, cols, cost, a, b, n, m, unit, deadline, run_until, px, py,
                          flow, eps, eps)
            if out is None:
                return None
            px, py, flow = out
            if search is None or rnd == EXTEND_ROUNDS:
                break
            slack = (SEARCH_EPS_LAST if last else SEARCH_EPS) * eps
            new = _absent(sorted_unique(search(keys, cost, px, py, slack)), keys)
            if new.size:
                grown = sorted_unique(np.concatenate([keys, new]))
                pos = np.searchsorted(grown, keys)
                f2, c2 = np.zeros(grown.size), np.empty(grown.size)
                f2[pos], c2[pos] = flow, cost
                fresh = np.ones(grown.size, bool)
                fresh[pos] = False
                c2[fresh] = pair_costs(X, Y, *np.divmod(grown[fresh], m))
                keys, cost, flow = grown, c2, f2
            if not last or new.size <= EXTEND_STOP * (n + m):
                break
        if last:
            return keys, cost, px, py, flow
        eps = max(eps / THETA, EPS_END * unit)


def _absent(new: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """The values of ``new`` not in ``keys`` (both sorted and distinct): ``np.setdiff1d`` by a
    binary search instead of two hashing ``np.unique`` (0.3 s each on 1.2·10⁶ keys)."""
    if keys.size == 0:
        return new
    pos = np.minimum(np.searchsorted(keys, new), keys.size - 1)
    return new[keys[pos] != new]


def _prices(rows, cols, cost, a, b, n, m, unit, deadline, run_until, px, py, flow, eps0,
            eps1):
    """``(px, py, flow)`` of the cost scaling from the prices ``px, py`` (and ``flow``, or
    zero), ``ε`` from ``eps0`` to ``eps1``, or ``None``; in a forked child stopped at
    ``deadline`` when one is set (the kernel cannot be interrupted)."""
    from ._costscale_kernels import transport_prices

    indptr = np.searchsorted(rows, np.arange(n + 1)).astype(np.int64)   # keys are sorted
    colidx = np.argsort(cols, kind="stable").astype(np.int64)
    colptr = np.searchsorted(cols[colidx], np.arange(m + 1)).astype(np.int64)
    tol = BALANCE * max(float(a.max()), float(b.max())) + 2.0 * abs(float(a.sum() - b.sum()))
    if flow is not None:
        # the crumbs a warm start inherits (each node balanced within the last call's
        # tolerance) count as balanced, else they may gather on one node above ``tol`` with
        # no deficit left to take them, and circulate until the work budget is spent
        tol += 2.0 * (np.abs(a - np.bincount(rows, flow, n)).sum()
                      + np.abs(np.bincount(cols, flow, m) - b).sum())

    def run():
        qx, qy = px.copy(), py.copy()
        f, status, _ = transport_prices(indptr, cols.astype(np.int64), cost, colptr, colidx,
                                        rows.astype(np.int64), a, b, qx, qy, eps0,
                                        eps1, THETA, tol, WORK_PER_NODE * (n + m),
                                        np.zeros(0, np.int64),
                                        np.zeros(0) if flow is None else flow)
        return (qx, qy, f) if status == 0 else None

    if deadline is None or run_until is None:
        return run()
    _load(transport_prices)           # compiled (or loaded) here, not in every child
    return run_until(run, deadline)


def _load(kernel) -> None:
    one, two = np.zeros(1, np.int64), np.array([0, 1], np.int64)
    w = np.ones(1)
    kernel(two, one, np.ones(1), two, one, one, w, w, np.zeros(1), np.zeros(1), 1.0, 1.0, 2.0,
           0.0, 10, np.zeros(0, np.int64), np.zeros(0))
