r"""The assignment solver of ``method="sparse"`` (:mod:`kinred.distance._sparse`).

When both measures have the same number ``n`` of atoms, all of weight ``1/n`` (a kinetic
solution and its reduced twin, each a uniform quantization pushed forward, or two samples),
the transport problem of eq. (4.5) on the candidate graph ``E`` is an *assignment problem*:
its vertices are the permutations (Birkhoff–von Neumann), so an optimal plan is
``πᵢσ(i) = 1/n`` for a permutation ``σ`` of least cost ``Σᵢ |xᵢ − y_σ(i)|`` over the edges.
scipy's :func:`scipy.sparse.csgraph.min_weight_full_bipartite_matching` (the sparse
Jonker–Volgenant algorithm, LAPJVsp) finds it -- at 10⁶ atoms with 10⁷ edges in about a second,
where the network simplex takes tens of seconds. The dual potentials, which LAPJVsp does not
return, are the shortest-path distances of the residual graph
(:func:`kinred.distance._assign_kernels.assignment_potentials`).

Cold, LAPJVsp's augmenting paths grow long when the optimal permutation moves atoms by more
than their spacing (minutes at 10⁶ atoms of the delayed-curse scene). So it is warmed by
Bertsekas' ε-scaling auction (:func:`warm_prices`,
:func:`kinred.distance._auction_kernels.auction`): LAPJVsp runs on the reduced costs
``cᵢⱼ + pⱼ − hᵢ``, which have the same optimal permutations.

scipy's LAPJVsp can loop forever on ties (seen on 100 atoms in R¹; scipy gh-17269 reports
other infinite loops): :mod:`kinred.distance._sparse` calls it only on large graphs, in a forked
child stopped after an allowance, and otherwise solves with the network simplex.

Nothing here is trusted: the plan's cost is an upper bound because the plan is a coupling, and
the lower bound is the c-transform of the potentials over all pairs, as for every solve. A
permutation that is not optimal on ``E`` (its potentials do not converge) falls back to the
network simplex.
"""

from __future__ import annotations

import numpy as np

__all__ = ["is_assignment", "solve_assignment", "load_kernels", "ASSIGNMENT"]

#: The solver's name in results and notes.
ASSIGNMENT = "scipy's sparse Jonker–Volgenant assignment (LAPJVsp)"

#: Edge relaxations of the potentials' search per edge of the graph before it gives up.
WORK_PER_EDGE = 64

#: The first, short search for potentials of the original costs after a warm solve.
QUICK_WORK_PER_EDGE = 4

#: The auction's ε schedule (:func:`warm_prices`), in units of the mean edge cost: from
#: ``AUCTION_EPS_START`` down by ``AUCTION_THETA`` per phase to ``AUCTION_EPS_END``.
AUCTION_EPS_START = 0.5
AUCTION_EPS_END = 1e-4
AUCTION_THETA = 6.0

#: Bids per edge of the graph the auction may spend before the cold LAPJVsp takes over (the
#: delayed-curse scene's 10⁶ atoms: about 15 per edge).
AUCTION_BIDS_PER_EDGE = 64

_EPS = np.finfo(np.float64).eps


def is_assignment(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal counts and one weight for every atom of both measures."""
    return (a.size == b.size and a.size > 0 and bool(np.all(a == a[0]))
            and bool(np.all(b == a[0])))


def load_kernels() -> None:
    """Load the potentials' kernel (and scipy's matching) in this process, so that a forked
    child inherits them instead of loading them on every solve (~0.3 s each)."""
    from scipy.sparse.csgraph import min_weight_full_bipartite_matching  # noqa: F401

    from ._assign_kernels import assignment_potentials

    one = np.zeros(1, np.int64)
    assignment_potentials(np.zeros(2, np.int64), np.zeros(0, np.int64), np.zeros(0), one,
                          np.zeros(1), 0.0, 1)


def warm_prices(G):
    """Column prices ``p`` of the assignment problem on the CSR graph ``G`` by the ε-scaling
    auction (:func:`kinred.distance._auction_kernels.auction`), ε from
    :data:`AUCTION_EPS_START` to :data:`AUCTION_EPS_END` times the mean edge cost, or ``None``
    when it spends :data:`AUCTION_BIDS_PER_EDGE` bids per edge (no perfect matching makes it
    bid until then) or a row has no edge."""
    from ._auction_kernels import auction

    n = G.shape[0]
    if G.data.size == 0 or np.any(np.diff(G.indptr) == 0):   # a row without edges: no matching
        return None
    unit = float(G.data.mean())
    if not unit > 0:
        return None
    price = np.zeros(n)
    _, _, status = auction(G.indptr.astype(np.int64), G.indices.astype(np.int64), G.data, price,
                           AUCTION_EPS_START * unit, AUCTION_EPS_END * unit, AUCTION_THETA,
                           int(AUCTION_BIDS_PER_EDGE * G.data.size + 16 * n),
                           np.zeros(0, np.int64))
    return price if status == 0 else None


def _lapjv(G, n):
    """LAPJVsp's optimal permutation ``(rows, cols)`` on ``G`` and each column's mate, or
    ``None`` without a perfect matching."""
    from scipy.sparse import csr_array
    from scipy.sparse.csgraph import min_weight_full_bipartite_matching

    # LAPJVsp sees every cost raised by the largest one: a constant moves every permutation's
    # cost by n times it (same optimum); zero costs (duplicate atoms) would otherwise be read
    # as missing edges, and on costs much smaller than 1 scipy's LAPJVsp was seen to loop
    # forever (71 atoms in R^3 with duplicates; the same graph raised by a constant: solved)
    shift = float(G.data.max()) if G.data.size and G.data.max() > 0 else 1.0
    lifted = csr_array((G.data + shift, G.indices, G.indptr), shape=(n, n))
    try:
        ri, ci = min_weight_full_bipartite_matching(lifted)
    except ValueError:                    # no perfect matching on E
        return None
    ri, ci = np.asarray(ri, np.int64), np.asarray(ci, np.int64)
    if ri.size != n:
        return None
    mate = np.empty(n, np.int64)
    mate[ci] = ri
    return ri, ci, mate


def solve_assignment(a, rows, cols, costs, n: int, warm: bool = True):
    """The optimal assignment on the edges ``(rows, cols)`` of costs ``costs``: the plan
    ``(i, σ(i), aᵢ)`` and potentials ``u, v`` (tight on the plan, feasible on the edges up to
    round-off), or ``None`` when the graph has no perfect matching or the potentials do not
    converge (then the caller solves with the network simplex).

    With ``warm``, LAPJVsp runs on the reduced costs
    ``rᵢⱼ = cᵢⱼ + pⱼ − hᵢ`` (``p`` the auction's prices, :func:`warm_prices`; ``hᵢ`` the row's
    least ``cᵢⱼ + pⱼ``): every permutation's cost moves by the same ``Σ p − Σ h``, so the
    optimum is the same, and near-optimal prices leave LAPJVsp short augmenting paths (10⁶
    atoms of the delayed-curse scene: about a second instead of minutes). The potentials are
    those of the original costs (residual shortest paths) when a short search finds them,
    else the reduced problem's ``u', v'`` shifted back, ``u = u' + h``, ``v = v' − p``. Every
    solve of column generation runs its own auction: the last round's exact duals as prices,
    on the enlarged graph, were seen to leave LAPJVsp minutes of augmenting paths at 10⁶
    atoms."""
    from scipy.sparse import csr_array

    G = csr_array((costs, (rows, cols)), shape=(n, n))
    G.sort_indices()
    price = warm_prices(G) if warm else None
    if price is not None:
        R = csr_array((G.data + price[G.indices], G.indices, G.indptr), shape=(n, n))
        h = np.minimum.reduceat(R.data, R.indptr[:-1]) if R.data.size else np.zeros(n)
        R.data -= np.repeat(h, np.diff(R.indptr))
        np.maximum(R.data, 0.0, out=R.data)
    else:
        R = G
    out = _lapjv(R, n)
    if out is None:
        return None
    ri, ci, mate = out
    # potentials: first those of the original costs, within a short search -- the reduced
    # problem's carry the auction's ε-overshoots, whose c-transform over all pairs leaves more
    # to repair (10⁶ paired atoms: 45 s of certificate and repair instead of 9 s) -- but on
    # plans far from the identity that search is long (the delayed-curse scene's 10⁵ atoms:
    # more than 10 s), and the reduced problem's search, near its fixed point, is short
    found = _potentials(G, ri, ci, mate, n, WORK_PER_EDGE if R is G else QUICK_WORK_PER_EDGE)
    if found is None and R is not G:
        found = _potentials(R, ri, ci, mate, n, WORK_PER_EDGE)
        if found is not None:
            found = (found[0] + h, found[1] - price)
    if found is None:
        return None
    return ri, ci, np.asarray(a, float)[ri], found[0], found[1]


def _potentials(G, ri, ci, mate, n, work_per_edge):
    """``(u, v)`` of the assignment ``(ri, ci)`` on ``G`` by the residual graph's shortest
    paths, or ``None`` past ``work_per_edge`` relaxations per edge."""
    from ._assign_kernels import assignment_potentials

    mate_cost = np.empty(n)
    mate_cost[ci] = np.asarray(G[ri, ci]).ravel()
    tiny = 16 * _EPS * float(G.data.max())
    dx, dy, status = assignment_potentials(
        G.indptr.astype(np.int64), G.indices.astype(np.int64), G.data, mate, mate_cost,
        tiny, work_per_edge * G.data.size + 16 * n)
    return None if status != 0 else (-dx, dy)
