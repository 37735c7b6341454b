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
``r_e ≤`` :data:`KEEP_EPS` ``· ε_end``, the support of its ε-optimal flow and the full
measures' coupling (so the pruned problem stays feasible). Nothing is lost if the guess is
wrong: column generation adds every pair whose dual constraint fails, over all pairs, and the
value is proved by the c-transform as always.
"""

from __future__ import annotations

import numpy as np

from ._costs import pair_costs, sorted_unique

__all__ = ["prune", "PRUNE_EDGES"]

#: Weighted problems from this many candidate edges are pruned (below, the network simplex
#: takes a second or less on the whole graph).
PRUNE_EDGES = 200_000

#: The cost scaling's ε schedule, in units of the mean edge cost (as the auction's).
EPS_START = 0.5
EPS_END = 1e-4
THETA = 6.0

#: Edges kept: reduced cost at most ``KEEP_EPS · ε_end`` (and the flow's support).
KEEP_EPS = 16.0

#: Discharges per node the cost scaling may spend before the whole graph is solved instead
#: (10⁵ vs 8·10⁴ atoms in ℝ⁶: about 400).
WORK_PER_NODE = 4000


def prune(X, a, Y, b, keys: np.ndarray, coupling: np.ndarray, deadline=None, start=None,
          run_until=None):
    """The edges of ``keys`` (``i·m + j``) worth solving on, or ``None`` (no prices: a node
    without edges, the work budget spent, the deadline passed). ``coupling``: keys always
    kept (one coupling of the full measures at least). ``start``: duals ``(u, v)`` to start
    the prices from (``px = −u``, ``py = v``; default zero). ``run_until(fn, deadline)``: runs
    ``fn`` stopped at ``deadline`` (``None`` when stopped); used when ``deadline`` is set."""
    n, m = X.shape[0], Y.shape[0]
    rows, cols = np.divmod(keys, m)
    if np.unique(rows).size < n or np.unique(cols).size < m:
        return None
    cost = pair_costs(X, Y, rows, cols)
    unit = float(cost.mean())
    if not unit > 0:
        return None
    out = _prices(rows, cols, cost, a, b, n, m, unit, deadline, start, run_until)
    if out is None:
        return None
    px, py, f = out
    rc = cost + px[rows] - py[cols]
    keep = (rc <= KEEP_EPS * EPS_END * unit) | (f > 0)
    return sorted_unique(np.concatenate([keys[keep], coupling]))


def _prices(rows, cols, cost, a, b, n, m, unit, deadline, start, run_until):
    """``(px, py, flow)`` of the cost scaling, or ``None``; in a forked child stopped at
    ``deadline`` when one is set (the kernel cannot be interrupted)."""
    from ._costscale_kernels import transport_prices

    indptr = np.searchsorted(rows, np.arange(n + 1)).astype(np.int64)   # keys are sorted
    colidx = np.argsort(cols, kind="stable").astype(np.int64)
    colptr = np.searchsorted(cols[colidx], np.arange(m + 1)).astype(np.int64)
    tol = 1e-12 * max(float(a.max()), float(b.max())) + 2.0 * abs(float(a.sum() - b.sum()))

    def run():
        px, py = ((np.zeros(n), np.zeros(m)) if start is None else
                  (-np.asarray(start[0], float), np.array(start[1], float)))
        f, status, _ = transport_prices(indptr, cols.astype(np.int64), cost, colptr, colidx,
                                        rows.astype(np.int64), a, b, px, py, EPS_START * unit,
                                        EPS_END * unit, THETA, tol, WORK_PER_NODE * (n + m),
                                        np.zeros(0, np.int64))
        return (px, py, f) if status == 0 else None

    if deadline is None or run_until is None:
        return run()
    _load(transport_prices)           # compiled (or loaded) here, not in every child
    return run_until(run, deadline)


def _load(kernel) -> None:
    one, two = np.zeros(1, np.int64), np.array([0, 1], np.int64)
    w = np.ones(1)
    kernel(two, one, np.ones(1), two, one, one, w, w, np.zeros(1), np.zeros(1), 1.0, 1.0, 2.0,
           0.0, 10, np.zeros(0, np.int64))
