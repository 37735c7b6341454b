"""The assignment solver of w1(method="sparse") (kinred.distance._assign): equal counts and
uniform weights make the restricted problem an assignment problem (scipy's LAPJVsp), whose dual
potentials are the residual graph's shortest paths (a numba kernel and its numpy twin).

Checked against independent computations: POT's dense network simplex for the optimum,
``cdist`` for the dual constraints, the numpy twin for the potentials."""

from unittest import mock

import numpy as np
import ot
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

import kinred.distance._sparse as S
from kinred.distance import w1
from kinred.distance._assign import ASSIGNMENT, is_assignment, solve_assignment
from kinred.distance._assign_kernels import assignment_potentials, \
    assignment_potentials_numpy
from kinred.distance._search import knn


def _graph(X, Y, k):
    n = X.shape[0]
    nx = knn(X, Y, k)
    keys = S.sorted_unique(np.concatenate([np.arange(n) * n + np.arange(n),
                                           np.repeat(np.arange(n), nx.shape[1]) * n
                                           + nx.ravel()]))
    r, c = np.divmod(keys, n)
    return r, c, np.linalg.norm(X[r] - Y[c], axis=1)


def _clouds(seed, n, d, spread, dup):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, d)) * np.linspace(1.0, 0.3, d)
    Y = X + spread * rng.standard_normal((n, d)) + 0.01
    if dup:
        X[n // 2:] = X[: n - n // 2]            # duplicate atoms: zero and equal costs
        Y[: n // 4] = X[: n // 4]
    return X, Y


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10**6), st.integers(2, 120), st.integers(1, 6),
       st.sampled_from([1e-3, 0.05, 1.0]), st.booleans(), st.sampled_from([1, 3, 8]))
def test_assignment_is_the_restricted_optimum_with_feasible_tight_potentials(seed, n, d, spread,
                                                                              dup, k):
    """Through the guarded path (a forked child with its allowance, as every large graph):
    scipy's LAPJVsp can loop forever on ties, then the network simplex answers."""
    X, Y = _clouds(seed, n, d, spread, dup)
    a = np.full(n, 1.0 / n)
    r, c, w = _graph(X, Y, k)
    with mock.patch.object(S, "FORK_EDGES", 0), mock.patch.object(S, "ASSIGN_SECONDS", 0.3):
        pr, pc, pm, u, v, solver = S._solve_until(a, a, r, c, w, n, n, None, None)
    if solver == ASSIGNMENT:                                  # a permutation
        assert np.array_equal(np.sort(pr), np.arange(n))
        assert np.array_equal(np.sort(pc), np.arange(n)) and np.all(pm == 1.0 / n)
    else:                                                     # stopped: the network simplex
        assert solver.startswith(S.NETWORK_SIMPLEX)
    np.testing.assert_allclose(np.bincount(pr, pm, n), a, rtol=1e-12)
    np.testing.assert_allclose(np.bincount(pc, pm, n), a, rtol=1e-12)
    # the restricted optimum: POT on the same edges (a dense matrix, huge cost off the graph)
    C = np.full((n, n), 1e6)
    C[r, c] = w
    ref = float(ot.emd2(a, a, C, numItermax=10**7))
    cost = float(np.sum(pm * np.linalg.norm(X[pr] - Y[pc], axis=1)))
    assert cost == pytest.approx(ref, rel=1e-12, abs=1e-15)
    scale = 16 * np.finfo(float).eps * (1 + np.abs(u).max() + np.abs(v).max())
    if solver != ASSIGNMENT:                     # POT's potentials carry its pivots' round-off
        scale = 1e-12
    assert np.min(w - u[r] - v[c]) >= -scale                 # feasible on the graph
    assert np.max(np.abs(np.linalg.norm(X[pr] - Y[pc], axis=1) - u[pr] - v[pc])) <= scale
    assert np.sum(a * u) + np.sum(a * v) == pytest.approx(cost, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_potentials_equal_the_numpy_twin(seed):
    X, Y = _clouds(seed, 300, 3, 0.2, seed == 2)
    r, c, w = _graph(X, Y, 4)
    pr, pc, _, _, _ = solve_assignment(np.full(300, 1 / 300), r, c, w, 300)
    mate = np.empty(300, np.int64)
    mate[pc] = pr
    mcost = np.linalg.norm(X[mate] - Y, axis=1)
    order = np.lexsort((c, r))
    indptr = np.searchsorted(r[order], np.arange(301)).astype(np.int64)
    dx, dy, st_k = assignment_potentials(indptr, c[order], w[order], mate, mcost, 0.0, 10**9)
    tx, ty, st_t = assignment_potentials_numpy(r, c, w, mate, mcost, 300)
    assert st_k == st_t == 0
    np.testing.assert_allclose(dx, tx, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(dy, ty, rtol=1e-12, atol=1e-13)


def test_a_crossing_assignment_does_not_converge():
    """x = (0, 1), y = (0, 1) matched crosswise: the residual cycle x0 → y0 → x1 → y1 → x0 has
    length 0 − 1 + 0 − 1 = −2; both the kernel and its twin report it (status 1)."""
    r, c = np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])
    w = np.array([0.0, 1.0, 1.0, 0.0])
    mate, mcost = np.array([1, 0]), np.array([1.0, 1.0])
    assert assignment_potentials(np.array([0, 2, 4]), c, w, mate, mcost, 0.0, 1000)[2] == 1
    assert assignment_potentials_numpy(r, c, w, mate, mcost, 2, max_rounds=50)[2] == 1


def test_no_perfect_matching_returns_none_and_w1_falls_back_to_the_network_simplex():
    """(and small graphs, below FORK_EDGES, never try the assignment solver: it could not be
    stopped there)"""
    r, c, w = np.array([0, 1]), np.array([0, 0]), np.array([1.0, 2.0])
    assert solve_assignment(np.full(2, 0.5), r, c, w, 2) is None
    X, Y = _clouds(3, 400, 2, 0.05, False)
    with mock.patch.object(S, "solve_assignment", return_value=None), \
            mock.patch.object(S, "FORK_EDGES", 0):
        r = w1(X, Y, "sparse")
    assert r.exact and r.info["solver"] == S.NETWORK_SIMPLEX
    assert r.value == pytest.approx(float(ot.emd2([], [], cdist(X, Y))), rel=1e-12)


def test_which_problems_are_assignments():
    one = np.full(4, 0.25)
    assert is_assignment(one, one.copy())
    assert not is_assignment(one, np.full(5, 0.2))
    assert not is_assignment(np.array([0.5, 0.25, 0.25]), np.array([0.5, 0.25, 0.25]))


@pytest.mark.parametrize("d", [2, 4, 20])
def test_w1_on_uniform_paired_clouds_uses_the_assignment_and_is_the_dense_optimum(d,
                                                                                  monkeypatch):
    monkeypatch.setattr(S, "FORK_EDGES", 0)          # the assignment's graphs, at a test's size
    X, Y = _clouds(d, 1500, d, 0.05, False)
    r = w1(X, Y, "sparse")
    assert r.info["solver"] == ASSIGNMENT and ASSIGNMENT in r.note
    assert r.exact
    assert r.value == pytest.approx(float(ot.emd2([], [], cdist(X, Y), numItermax=10**7)),
                                    rel=1e-12)
    weighted = w1(X, Y, "sparse", a=np.linspace(1, 2, 1500), b=np.linspace(1, 2, 1500))
    assert weighted.info["solver"] == S.NETWORK_SIMPLEX


def test_a_slow_assignment_is_stopped_and_the_network_simplex_answers(monkeypatch):
    """On large graphs the assignment solver runs in a child with an allowance; past it the
    child is stopped and POT's network simplex solves (exact, and the note says so)."""
    import time

    X, Y = _clouds(5, 1200, 3, 0.05, False)
    ref = float(ot.emd2([], [], cdist(X, Y), numItermax=10**7))
    monkeypatch.setattr(S, "FORK_EDGES", 0)
    monkeypatch.setattr(S, "ASSIGN_SECONDS", 0.5)
    monkeypatch.setattr(S, "ASSIGN_SECONDS_PER_EDGE", 0.0)
    fast = w1(X, Y, "sparse")                               # forked, within its allowance
    assert fast.exact and fast.info["solver"] == ASSIGNMENT
    assert fast.value == pytest.approx(ref, rel=1e-12)
    monkeypatch.setattr(S, "solve_assignment", lambda *args: time.sleep(600))
    t0 = time.perf_counter()
    slow = w1(X, Y, "sparse")
    assert time.perf_counter() - t0 < 60.0                  # not the 600 s of the sleep
    assert slow.exact and slow.value == pytest.approx(ref, rel=1e-12)
    assert slow.info["solver"].startswith(S.NETWORK_SIMPLEX)
    assert "assignment solver was stopped after its 0.5 s" in slow.note


def test_small_graphs_solve_with_the_network_simplex():
    X, Y = _clouds(4, 400, 2, 0.05, False)
    r = w1(X, Y, "sparse")
    assert r.exact and r.info["solver"] == S.NETWORK_SIMPLEX


def test_a_looping_lapjvsp_case_is_stopped_and_answered(monkeypatch):
    """A case on which scipy's LAPJVsp loops forever (100 atoms in R¹, found by the property
    test): the child is stopped after its allowance and the network simplex answers."""
    import time

    X, Y = _clouds(310716, 98, 1, 1.0, False)
    monkeypatch.setattr(S, "FORK_EDGES", 0)
    monkeypatch.setattr(S, "ASSIGN_SECONDS", 1.0)
    t0 = time.perf_counter()
    r = w1(X, Y, "sparse", neighbors=3)
    assert time.perf_counter() - t0 < 30.0
    assert r.exact
    assert r.value == pytest.approx(float(ot.emd2([], [], cdist(X, Y), numItermax=10**7)),
                                    rel=1e-12)
