"""The cost scaling that prunes the candidate graph of weighted problems in w1(method="sparse")
(kinred.distance._costscale_kernels, kinred.distance._costscale).

Checked against independent computations: POT's dense network simplex for the optimum (an
ε-optimal flow costs at most (n + m)·ε more, Goldberg–Tarjan), the ε-optimality conditions
recomputed from the returned prices and flow, the plain-Python twin for the discharges, and
w1's exact value against POT dense when the pruned graph is used."""

import numpy as np
import ot
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import kinred.distance._costscale as CS
import kinred.distance._sparse as S
from kinred.distance import w1
from kinred.distance._costscale_kernels import transport_prices, transport_prices_numpy


def _problem(seed, n, m, d, shift, zero_mass_gap=False):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, d)) + shift
    Y = rng.standard_normal((m, d)) * 0.7 + shift + 0.3
    a, b = rng.random(n) + 0.05, rng.random(m) + 0.05
    return X, a / a.sum(), Y, b / b.sum()


def _dense_args(X, a, Y, b, eps_end_rel, theta=6.0):
    n, m = X.shape[0], Y.shape[0]
    C = ot.dist(X, Y, metric="euclidean")
    rows, cols = np.divmod(np.arange(n * m, dtype=np.int64), m)
    cost = C.ravel().copy()
    indptr = np.arange(0, n * m + 1, m, dtype=np.int64)
    colidx = np.argsort(cols, kind="stable").astype(np.int64)
    colptr = np.searchsorted(cols[colidx], np.arange(m + 1)).astype(np.int64)
    unit = cost.mean()
    tol = 1e-12 * max(a.max(), b.max()) + 2 * abs(a.sum() - b.sum())
    args = (indptr, cols, cost, colptr, colidx, rows, a, b, np.zeros(n), np.zeros(m),
            0.5 * unit, eps_end_rel * unit, theta, tol, 10**8, np.zeros(0, np.int64), np.zeros(0))
    return args, C, rows, cols, cost, eps_end_rel * unit, tol


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(1, 40), m=st.integers(1, 40),
       d=st.integers(1, 4), shift=st.sampled_from([0.0, -3.0, 1e4]),
       eps=st.sampled_from([1e-2, 1e-5]))
def test_flow_is_eps_optimal_and_within_its_bound_of_the_optimum(seed, n, m, d, shift, eps):
    X, a, Y, b = _problem(seed, n, m, d, shift)
    args, C, rows, cols, cost, eps_abs, tol = _dense_args(X, a, Y, b, eps)
    f, status, work = transport_prices(*args)
    px, py = args[8], args[9]
    assert status == 0 and work > 0
    # marginals within the balance tolerance
    assert np.abs(np.bincount(rows, f, n) - a).max() <= (n + m) * tol + 1e-15
    assert np.abs(np.bincount(cols, f, m) - b).max() <= (n + m) * tol + 1e-15
    r = cost + px[rows] - py[cols]
    slack = 1e-9 * (1 + np.abs(px).max() + np.abs(py).max())
    assert r.min() >= -eps_abs - slack                       # every edge
    assert r[f > 0].max() <= eps_abs + slack                 # edges with flow
    opt = ot.emd2(a, b, C)
    assert f @ cost >= opt - 1e-12 * max(opt, 1e-300) - (n + m) * tol * C.max()
    assert f @ cost <= opt + (n + m) * eps_abs + (n + m) * tol * C.max() + 1e-12


def test_kernel_equals_its_python_twin():
    X, a, Y, b = _problem(3, 12, 9, 2, 0.0)
    args, *_ = _dense_args(X, a, Y, b, 1e-3)
    twin = tuple(x.copy() if isinstance(x, np.ndarray) else x for x in args)
    f1, s1, w1_ = transport_prices(*args)
    f2, s2, w2 = transport_prices_numpy(*twin)
    assert (s1, w1_) == (s2, w2)
    assert np.array_equal(f1, f2) and np.array_equal(args[8], twin[8])
    assert np.array_equal(args[9], twin[9])


def test_work_budget_stops_it():
    X, a, Y, b = _problem(4, 30, 25, 2, 0.0)
    args, *_ = _dense_args(X, a, Y, b, 1e-6)
    args = args[:14] + (5,) + args[15:]
    _, status, work = transport_prices(*args)
    assert status == 1 and work == 6


def test_imbalance_above_the_tolerance_does_not_loop_for_ever():
    """The tolerance must exceed |Σa − Σb|: with it, a balanced problem ends."""
    X, a, Y, b = _problem(5, 20, 20, 2, 0.0)
    b = b * (1 + 1e-15)
    args, *_ = _dense_args(X, a, Y, b, 1e-6)
    _, status, _ = transport_prices(*args)
    assert status == 0


@pytest.mark.parametrize("d,seed", [(2, 0), (3, 1), (6, 2)])
def test_pruned_graph_gives_the_dense_optimum(monkeypatch, d, seed):
    """Weighted, unequal sizes, pruned from the first solve on (PRUNE_EDGES lowered): exact and
    equal to POT dense; the pruned graph is smaller than the k-NN graph."""
    monkeypatch.setattr(S, "PRUNE_EDGES", 0)
    calls = []
    orig = CS.prune

    def spy(*args, **kwargs):
        out = orig(*args, **kwargs)
        keys = args[4]
        calls.append((keys.size, None if out is None else out[0].size))
        return out

    monkeypatch.setattr(S, "prune", spy)
    X, a, Y, b = _problem(seed, 300, 240, d, 0.0)
    r = w1(X, Y, "sparse", a=a, b=b)
    dense = ot.emd2(a, b, ot.dist(X, Y, metric="euclidean"))
    assert r.exact and r.value == pytest.approx(dense, rel=1e-12)
    assert calls and calls[0][1] is not None and calls[0][1] < calls[0][0]
    assert r.info["seconds_prices"] >= 0.0


@pytest.mark.parametrize("budget", [None, 120.0])
def test_an_infeasible_pruned_graph_gets_the_coupling(monkeypatch, budget):
    """A pruned graph that holds no coupling (here: column 0 without edges -- the flow's
    support is feasible only within the balance tolerance) gets the full measures' coupling
    and gives the dense optimum, with or without the forked solves of a time budget."""
    monkeypatch.setattr(S, "PRUNE_EDGES", 0)
    monkeypatch.setattr(S, "FORK_EDGES", 0)
    m = 240

    def pruned_too_far(*args, **kwargs):
        kept, pool = CS.prune(*args, **kwargs)
        return kept[kept % m != 0], pool

    monkeypatch.setattr(S, "prune", pruned_too_far)
    X, a, Y, b = _problem(3, 300, m, 3, 0.0)
    r = w1(X, Y, "sparse", a=a, b=b, max_seconds=budget)
    dense = ot.emd2(a, b, ot.dist(X, Y, metric="euclidean"))
    assert r.exact and r.value == pytest.approx(dense, rel=1e-12)


def test_pruning_within_a_time_budget_gives_the_dense_optimum(monkeypatch):
    """The forked path (a deadline set) gives the same exact value."""
    monkeypatch.setattr(S, "PRUNE_EDGES", 0)
    X, a, Y, b = _problem(7, 250, 200, 3, 5.0)
    r = w1(X, Y, "sparse", a=a, b=b, max_seconds=120.0)
    dense = ot.emd2(a, b, ot.dist(X, Y, metric="euclidean"))
    assert r.exact and r.value == pytest.approx(dense, rel=1e-12)


def _corner(a, b):
    """The keys of the north-west-corner coupling (a feasible plan: the part stays feasible)."""
    i = j = 0
    ra, rb, out = a.copy(), b.copy(), []
    while i < a.size and j < b.size:
        out.append(i * b.size + j)
        if ra[i] <= rb[j]:
            rb[j] -= ra[i]
            i += 1
        else:
            ra[i] -= rb[j]
            j += 1
    return np.array(out, np.int64)


def _subgraph_args(X, a, Y, b, keys, eps_rel):
    """Kernel arguments on the edges ``keys`` (sorted ``i·m + j``)."""
    n, m = X.shape[0], Y.shape[0]
    rows, cols = np.divmod(keys, m)
    cost = np.linalg.norm(X[rows] - Y[cols], axis=1)
    indptr = np.searchsorted(rows, np.arange(n + 1)).astype(np.int64)
    colidx = np.argsort(cols, kind="stable").astype(np.int64)
    colptr = np.searchsorted(cols[colidx], np.arange(m + 1)).astype(np.int64)
    unit = cost.mean()
    tol = 1e-9 * max(a.max(), b.max())
    return [indptr, cols, cost, colptr, colidx, rows, a, b, np.zeros(n), np.zeros(m),
            0.5 * unit, eps_rel * unit, 6.0, tol, 10**8, np.zeros(0, np.int64), np.zeros(0)]


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(2, 30), m=st.integers(2, 30),
       keep=st.floats(0.3, 0.9))
def test_warm_start_on_more_edges_is_eps_optimal(seed, n, m, keep):
    """One warm phase (the flow and prices of a run on part of the edges, ``eps_start =
    eps_end``) on all of them: ε-optimal and balanced, as a cold run."""
    X, a, Y, b = _problem(seed, n, m, 2, 0.0)
    rng = np.random.default_rng(seed)
    every = np.arange(n * m, dtype=np.int64)
    part = np.unique(np.concatenate([every[rng.random(n * m) < keep], _corner(a, b)]))
    args = _subgraph_args(X, a, Y, b, part, 1e-3)
    f, status, _ = transport_prices(*args)
    assert status == 0
    flow = np.zeros(every.size)
    flow[part] = f
    full = _subgraph_args(X, a, Y, b, every, 1e-3)
    eps = full[11]
    full[8], full[9], full[10], full[16] = args[8].copy(), args[9].copy(), eps, flow
    g, status, work = transport_prices(*full)
    assert status == 0
    r = full[2] + full[8][full[5]] - full[9][full[1]]
    slack = 1e-9 * (1 + np.abs(full[8]).max() + np.abs(full[9]).max())
    assert r.min() >= -eps - slack and r[g > 0].max() <= eps + slack
    tol = (n + m) * full[13] + 1e-15
    assert np.abs(np.bincount(full[5], g, n) - a).max() <= tol
    assert np.abs(np.bincount(full[1], g, m) - b).max() <= tol


def test_global_update_keeps_eps_optimality_and_makes_paths_admissible():
    """Goldberg's update on a mid-phase state: reduced costs stay ≥ −ε, and from every node
    with excess an admissible path (r < 0) leads to a deficit."""
    from kinred.distance._costscale_kernels import _global_update

    X, a, Y, b = _problem(11, 25, 20, 2, 0.0)
    args, C, rows, cols, cost, eps, tol = _dense_args(X, a, Y, b, 1e-2)
    n, m = 25, 20
    rng = np.random.default_rng(0)
    # an ε-optimal state: py_j = min_i c_ij + ε/2, px = 0; some flow on edges with r ≤ ε
    px, py = np.zeros(n), C.min(axis=0) + eps / 2
    r0 = cost + px[rows] - py[cols]
    f = np.where((r0 <= eps) & (rng.random(cost.size) < 0.7), 0.05 / n, 0.0)
    exx = a - np.bincount(rows, f, n)
    exy = np.bincount(cols, f, m) - b
    assert (exx > tol).any() and (exy < -tol).any() and (exx >= 0).all()
    colidx = args[4]
    _global_update(args[0], cols, cost, args[3], cost[colidx], rows[colidx], px, py, f,
                   exx, exy, eps, tol, np.empty(n + m, np.int64), np.empty(n + m, np.uint8),
                   np.empty(4 * (n + m), np.int64), np.empty(cost.size + n + m, np.int64),
                   np.empty(cost.size + n + m, np.int64))
    r = cost + px[rows] - py[cols]
    assert r.min() >= -eps * (1 + 1e-12)                      # forward arcs
    assert (-r[f > 0]).min() >= -eps * (1 + 1e-12)            # reverse arcs of flow edges
    # admissible arcs: i -> j where r < 0, j -> i where f > 0 and -r < 0
    reach = exy < -tol                                        # nodes that reach a deficit
    reach_x = np.zeros(n, bool)
    for _ in range(n + m):
        reach_x = np.bincount(rows, (r < 0) & reach[cols], n) > 0
        new = reach | (np.bincount(cols, (f > 0) & (-r < 0) & reach_x[rows], m) > 0)
        if (new == reach).all():
            break
        reach = new
    assert reach_x[exx > tol].all() and reach[exy > tol].all()


def test_extended_prices_hold_the_optimal_plan(monkeypatch):
    """Weighted, unequal sizes, a graph of 2 neighbours that misses the optimal plan: the
    prices extended over all pairs keep every edge of POT's dense optimal plan."""
    X, a, Y, b = _problem(5, 200, 150, 3, 0.0)
    n, m = 200, 150
    keys, _ = S._initial_keys(X, a, Y, b, 2, False)
    G = ot.emd(a, b, ot.dist(X, Y, metric="euclidean"))
    support = np.flatnonzero(G.ravel() > 1e-15)
    assert np.setdiff1d(support, keys).size > 0               # the k-NN graph misses some
    from kinred.distance._search import CTree

    trees = (CTree(X), CTree(Y))
    kept, pool = CS.prune(X, a, Y, b, keys, search=S._price_search(X, Y, trees, None))
    assert pool.size > keys.size and np.setdiff1d(support, kept).size == 0
    assert kept.size < pool.size
    plain = CS.prune(X, a, Y, b, keys)[0]           # without the search: misses
    assert np.setdiff1d(support, plain).size > 0
