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


def solve_assignment(a, rows, cols, costs, n: int):
    """The optimal assignment on the edges ``(rows, cols)`` of costs ``costs``: the plan
    ``(i, σ(i), aᵢ)`` and potentials ``u, v`` (tight on the plan, feasible on the edges up to
    round-off), or ``None`` when the graph has no perfect matching or the potentials do not
    converge (then the caller solves with the network simplex)."""
    from scipy.sparse import csr_array
    from scipy.sparse.csgraph import min_weight_full_bipartite_matching

    from ._assign_kernels import assignment_potentials

    G = csr_array((costs, (rows, cols)), shape=(n, n))
    G.sort_indices()
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
    lookup = G[ri, ci]
    mate_cost = np.empty(n)
    mate_cost[ci] = np.asarray(lookup).ravel()
    tiny = 16 * _EPS * float(G.data.max())
    dx, dy, status = assignment_potentials(
        G.indptr.astype(np.int64), G.indices.astype(np.int64), G.data, mate, mate_cost,
        tiny, WORK_PER_EDGE * G.data.size + 16 * n)
    if status != 0:
        return None
    return ri, ci, np.asarray(a, float)[ri], -dx, dy
