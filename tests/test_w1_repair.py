"""The repair of a sparse network-simplex solution over all pairs (kinred.distance._repair).

Every claim is checked against independent computations on the full cost matrix: POT's dense
network simplex for the optimum, ``cdist`` for the dual constraints of every pair, the plain
numpy twin (dense Bellman–Ford) for the potentials.
"""

import math

import numpy as np
import ot
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

import kinred.distance._sparse as S
import kinred.distance._repair as RP
from kinred.distance import w1
from kinred.distance._costs import plan_cost
from kinred.distance._repair import repair, tighten
from kinred.distance._repair_kernels import repair_numpy
from kinred.distance._search import CTree, knn

EPS = np.finfo(float).eps


def _problem(seed, n, m, d, paired, spread=0.05):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, d)) * np.linspace(1.0, 0.3, d)
    if paired:
        Y = X + spread * rng.standard_normal((n, d)) + 0.01
        a = rng.random(n) if seed % 2 else np.ones(n)
        a /= a.sum()
        return X, a, Y, a.copy()
    Y = rng.standard_normal((m, d)) * np.linspace(1.0, 0.3, d) + 0.1
    a, b = rng.random(n), rng.random(m)
    return X, a / a.sum(), Y, b / b.sum()


def _sparse_solution(X, a, Y, b, k, paired):
    """POT's network simplex on ``k`` neighbours from one side and one coupling (sparse on
    purpose: the plan is often *not* optimal over all pairs)."""
    n, m = X.shape[0], Y.shape[0]
    ci, cj, _ = S._coupling_edges(X, a, Y, b, paired)
    nx = knn(X, Y, k)
    keys = S.sorted_unique(np.concatenate([ci * m + cj,
                                           np.repeat(np.arange(n), nx.shape[1]) * m
                                           + nx.ravel()]))
    up, u, v, plan, noise, _ = S._solve_round(X, a, Y, b, keys, None, None)
    return keys, up, u, v, plan, noise


def _tiny(up, u, v):
    return 4 * EPS * (up + np.abs(u).max() + np.abs(v).max())


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.integers(20, 160), st.integers(1, 4), st.booleans(),
       st.sampled_from([1, 2, 4]))
def test_converged_repair_is_the_dense_optimum_with_its_proof(seed, n, d, paired, k):
    """Converged ⇒ the plan is a coupling of both measures whose cost is POT's dense optimum
    (1e-12), the potentials satisfy every pair's constraint and are tight on the plan (to the
    round-off ``tiny``), so the dual value proves the cost; never worse than the solve's plan."""
    m = n if paired else n // 2 + 7
    X, a, Y, b = _problem(seed, n, m, d, paired)
    keys, up, u, v, plan, noise = _sparse_solution(X, a, Y, b, k, paired)
    u, v = tighten(X, Y, u, v, plan, keys, 1e3 * noise + _tiny(up, u, v))
    tiny = _tiny(up, u, v)
    r = repair(X, Y, u, v, plan, CTree(X), tiny, max_work=400 * (n + m))
    pr, pc, pm = r.plan
    assert np.all(pm > 0)
    np.testing.assert_allclose(np.bincount(pr, pm, n), a, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.bincount(pc, pm, m), b, rtol=0, atol=1e-15)
    cost = plan_cost(X, Y, r.plan)
    assert cost <= up * (1 + 1e-14)                       # cycle cancelling only improves
    if not r.converged:
        assert r.cycles > 0                               # stopped while still improving
        return
    C = cdist(X, Y)
    ref = float(ot.emd2(a, b, C, numItermax=10**7))
    assert cost == pytest.approx(ref, rel=1e-12)
    scale = np.abs(C).max() + np.abs(r.u).max() + np.abs(r.v).max()
    assert (r.u[:, None] + r.v[None, :] - C).max() <= 64 * EPS * scale
    assert np.abs(C[pr, pc] - r.u[pr] - r.v[pc]).max() <= 64 * EPS * scale
    lower = math.fsum(a * np.min(C - r.v[None, :], axis=1)) + math.fsum(b * r.v)
    assert lower == pytest.approx(ref, rel=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_potentials_equal_the_numpy_twin(seed):
    """With the dense optimum as the plan (nothing to cancel), the kernel's potentials are the
    Bellman–Ford fixed point below the start: the twin's, whatever the processing order."""
    X, a, Y, b = _problem(seed, 120, 120, 3, True)
    C = cdist(X, Y)
    G, log = ot.emd(a, b, C, log=True)
    pr, pc = np.nonzero(G > 0)
    plan = (pr.astype(np.int64), pc.astype(np.int64), G[pr, pc])
    rng = np.random.default_rng(seed)
    u = log["u"] + 0.01 * rng.random(120)               # start above the fixed point
    v = log["v"] + 0.01 * rng.random(120)
    tiny = _tiny(1.0, u, v)                             # round-off: no zero-length "cycles"
    r = repair(X, Y, u, v, plan, CTree(X), tiny)
    assert r.converged and r.cycles == 0
    tu, tv = repair_numpy(X, Y, pr, pc, u, v, tiny)
    np.testing.assert_allclose(r.u, tu, rtol=0, atol=1e-13)
    np.testing.assert_allclose(r.v, tv, rtol=0, atol=1e-13)


def test_twin_reports_a_negative_cycle():
    """A plan that is not optimal has a negative cycle: the dense Bellman–Ford never settles
    (``None``), and the kernel cancels it (the cost drops to the optimum)."""
    X = np.array([[0.0], [1.0]])
    Y = np.array([[1.0], [0.0]])
    a = np.array([0.5, 0.5])
    pr, pc = np.array([0, 1]), np.array([0, 1])                # crossing: cost 2·0.5
    plan = (pr, pc, a.copy())
    u, v = np.zeros(2), np.ones(2)
    assert repair_numpy(X, Y, pr, pc, u, v, max_sweeps=50) is None
    r = repair(X, Y, u, v, plan, CTree(X), 0.0)
    assert r.converged and r.cycles >= 1
    assert plan_cost(X, Y, r.plan) == pytest.approx(0.0, abs=1e-15)


def test_tighten_makes_the_simplex_potentials_exact():
    """POT's potentials carry its pivots' round-off on the plan's edges; rebuilt along a forest
    of tight edges they are tight to one rounding and still feasible on the graph."""
    X, a, Y, b = _problem(5, 3000, 3000, 4, True, spread=0.02)
    keys, up, u, v, plan, noise = _sparse_solution(X, a, Y, b, 6, True)
    pr, pc, _ = plan
    u2, v2 = tighten(X, Y, u, v, plan, keys, 1e3 * noise + _tiny(up, u, v))
    rows, cols = np.divmod(keys, Y.shape[0])
    c = S.pair_costs(X, Y, rows, cols)
    cp = S.pair_costs(X, Y, pr, pc)
    scale = np.abs(u).max() + np.abs(v).max() + up
    assert np.abs(cp - u2[pr] - v2[pc]).max() <= 8 * EPS * scale
    assert (u2[rows] + v2[cols] - c).max() <= 8 * EPS * scale
    assert math.fsum(a * u2) + math.fsum(b * v2) == pytest.approx(up, rel=1e-13)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(-5, 2**40), max_size=200))
def test_sorted_unique_is_numpy_unique(values):
    a = np.array(values, dtype=np.int64)
    np.testing.assert_array_equal(S.sorted_unique(a), np.unique(a))


def test_paired_clouds_close_in_one_solve(monkeypatch):
    """Degenerate duals: paired atoms give a plan with n positive entries; without the repair
    the c-transform of POT's arbitrary dual left a gap and column generation drew another
    arbitrary dual each round. With it, one solve is exact (the repair's allowance lifted:
    on a loaded machine it could stop the repair, and the test is about what it computes)."""
    monkeypatch.setattr(RP, "REPAIR_SECONDS", 600.0)
    X, a, Y, b = _problem(11, 20_000, 20_000, 4, True, spread=0.01)
    r = w1(X, Y, "sparse", a=a, b=b)
    assert r.exact
    assert r.info["iterations"] == 1
    assert r.lower == r.value == r.upper


def test_a_repair_past_its_allowance_hands_over_to_column_generation(monkeypatch):
    """With no allowance at all the repair stops at its first look at the clock: its partial
    plan and the violators join the graph, the next solves close the gap, and the value is
    POT's dense optimum (the repair's allowance only moves work between repair and solves)."""
    monkeypatch.setattr(RP, "REPAIR_SECONDS", 0.0)
    monkeypatch.setattr(RP, "REPAIR_ALLOWANCE", 0.0)
    X, a, Y, b = _problem(12, 1500, 1500, 3, True, spread=0.05)
    r = w1(X, Y, "sparse", a=a, b=b)
    ref = float(ot.emd2(a, b, cdist(X, Y), numItermax=10**7))
    assert r.lower <= ref * (1 + 1e-12) and r.upper >= ref * (1 - 1e-12)
    assert r.exact and r.value == pytest.approx(ref, rel=1e-12)
    assert r.info["iterations"] >= 2 and r.info["repair_work"] == 0  # stopped at once


def test_a_spanning_tree_plan_goes_to_column_generation_without_repair(monkeypatch):
    """Weighted atoms in general position: the plan has n + m − 1 positive entries, its duals
    are unique up to a constant, and the repair is not called (it would only spend its
    allowance); column generation alone reaches POT's dense optimum, exactly."""
    calls = []
    monkeypatch.setattr(RP, "repair", lambda *a, **k: calls.append(1) or pytest.fail("repair"))
    X, a, Y, b = _problem(5, 1500, 1200, 3, False)
    r = w1(X, Y, "sparse", a=a, b=b)
    ref = float(ot.emd2(a, b, cdist(X, Y), numItermax=10**7))
    assert r.exact and r.value == pytest.approx(ref, rel=1e-12)
    assert not calls
