"""The ε-scaling auction that warms the assignment solver of w1(method="sparse")
(kinred.distance._auction_kernels, kinred.distance._assign.warm_prices).

Checked against independent computations: scipy's dense linear_sum_assignment for the optimum
(the auction's assignment is within n·ε of it, Bertsekas' bound), the plain-Python twin for
the bids, and the cold solver for the warm solver's plan and potentials."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_array

import kinred.distance._assign as A
from kinred.distance._auction_kernels import auction, auction_numpy
from kinred.distance._search import knn


def _problem(seed, n, d, spread, k, dup=False):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, d)) * np.linspace(1.0, 0.3, d)
    Y = X + spread * rng.standard_normal((n, d)) + 0.01
    if dup:
        X[n // 2:] = X[: n - n // 2]
        Y[: n // 4] = X[: n // 4]
    nx = knn(X, Y, min(k, n))
    rows = np.concatenate([np.arange(n), np.repeat(np.arange(n), nx.shape[1])])
    cols = np.concatenate([np.arange(n), nx.ravel()])
    keys = np.unique(rows * n + cols)
    r, c = np.divmod(keys, n)
    w = np.linalg.norm(X[r] - Y[c], axis=1)
    G = csr_array((w, (r, c)), shape=(n, n))
    G.sort_indices()
    return G, r, c, w


def _graph_optimum(G, n):
    C = np.full((n, n), 1e9)
    R = G.tocoo()
    C[R.row, R.col] = R.data
    i, j = linear_sum_assignment(C)
    return float(C[i, j].sum())


def _run(fn, G, eps_end, theta=6.0, max_bids=10**9):
    n = G.shape[0]
    price = np.zeros(n)
    phases = np.zeros(32, np.int64)
    unit = float(G.data.mean())
    sigma, bids, status = fn(G.indptr.astype(np.int64), G.indices.astype(np.int64), G.data,
                             price, 0.5 * unit, eps_end * unit, theta, max_bids, phases)
    return sigma, bids, status, price, phases, unit


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10**6), st.integers(2, 150), st.integers(1, 5),
       st.sampled_from([1e-3, 0.05, 1.0]), st.sampled_from([1, 3, 8]), st.booleans(),
       st.sampled_from([1e-2, 1e-4]))
def test_the_auction_is_within_n_eps_of_the_optimum_with_eps_cs(seed, n, d, spread, k, dup,
                                                                  eps_end):
    """Bertsekas: an assignment with ε-CS costs at most n·ε more than the optimum on the
    graph; ε-CS itself is checked row by row (the prices are the returned ones)."""
    G, r, c, w = _problem(seed, n, d, spread, k, dup)
    sigma, bids, status, price, phases, unit = _run(auction, G, eps_end)
    assert status == 0
    assert np.array_equal(np.sort(sigma), np.arange(n))            # a permutation
    eps = eps_end * unit
    cost = float(G[np.arange(n), sigma].sum())
    opt = _graph_optimum(G, n)
    assert opt - 1e-9 * (1 + opt) <= cost <= opt + n * eps * (1 + 1e-9) + 1e-12
    red = G.data + price[G.indices]
    best = np.minimum.reduceat(red, G.indptr[:-1])
    mine = np.asarray(G[np.arange(n), sigma]).ravel() + price[sigma]
    assert np.all(mine <= best + eps * (1 + 1e-9) + 1e-12)
    assert bids == phases[phases > 0].sum() and bids >= n


@pytest.mark.parametrize("seed", [0, 1])
def test_the_auction_equals_its_python_twin(seed):
    G, *_ = _problem(seed, 120, 3, 0.2, 4, seed == 1)
    s1, b1, st1, p1, ph1, _ = _run(auction, G, 1e-3)
    s2, b2, st2, p2, ph2, _ = _run(auction_numpy, G, 1e-3)
    assert (b1, st1) == (b2, st2) and np.array_equal(s1, s2) and np.array_equal(ph1, ph2)
    np.testing.assert_array_equal(p1, p2)


def test_the_bid_budget_stops_the_auction_and_the_cold_solver_answers(monkeypatch):
    G, r, c, w = _problem(5, 400, 2, 0.3, 4)
    sigma, bids, status, *_ = _run(auction, G, 1e-6, max_bids=500)
    assert status == 1 and bids == 500 and np.sum(sigma >= 0) < 400
    monkeypatch.setattr(A, "AUCTION_BIDS_PER_EDGE", 0)
    assert A.warm_prices(G) is None
    pr, pc, pm, u, v = A.solve_assignment(np.full(400, 1 / 400), r, c, w, 400)
    assert np.array_equal(np.sort(pr), np.arange(400))
    assert np.array_equal(np.sort(pc), np.arange(400))
    assert float(G[pr, pc].sum()) == pytest.approx(_graph_optimum(G, 400), rel=1e-12)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 10**6), st.integers(2, 200), st.integers(1, 6),
       st.sampled_from([1e-3, 0.05, 1.0]), st.sampled_from([1, 3, 8]), st.booleans(),
       st.sampled_from([1.0, 1e-150, 1e150]))
def test_warm_and_cold_solves_are_both_optimal_with_tight_feasible_potentials(
        seed, n, d, spread, k, dup, scale):
    """The warm solve (LAPJVsp on the reduced costs ``c + p − h``) returns the restricted
    optimum and potentials of the *original* costs, feasible and tight to round-off, at any
    scale (the reduced costs are computed in the costs' own unit)."""
    G, r, c, w = _problem(seed, n, d, spread, k, dup)
    w = w * scale
    a = np.full(n, 1.0 / n)
    opt = _graph_optimum(csr_array((w / scale, (r, c)), shape=(n, n)), n) * scale
    for warm in (True, False):
        out = A.solve_assignment(a, r, c, w, n, warm=warm)
        if out is None:                      # no convergence of the potentials: NS answers
            continue
        pr, pc, pm, u, v = out
        cost_of = dict(zip(zip(r.tolist(), c.tolist()), w.tolist()))
        cost = float(sum(cost_of[(i, j)] for i, j in zip(pr.tolist(), pc.tolist())))
        assert cost == pytest.approx(opt, rel=1e-9, abs=1e-12 * scale)
        slack = 64 * np.finfo(float).eps * (np.abs(w).max() + np.abs(u).max()
                                            + np.abs(v).max())
        assert np.min(w - u[r] - v[c]) >= -slack
        tight = np.array([cost_of[(i, j)] for i, j in zip(pr.tolist(), pc.tolist())])
        assert np.max(np.abs(tight - u[pr] - v[pc])) <= slack


def test_no_prices_without_a_perfect_matching():
    """A row without edges is refused before the auction; rows competing for one column bid
    until the budget (a price war: no perfect matching) and give no prices either."""
    lonely = csr_array((np.array([1.0]), (np.array([0]), np.array([0]))), shape=(2, 2))
    assert A.warm_prices(lonely) is None
    war = csr_array((np.array([1.0, 2.0]), (np.array([0, 1]), np.array([0, 0]))), shape=(2, 2))
    assert A.warm_prices(war) is None
