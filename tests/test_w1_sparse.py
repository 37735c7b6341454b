"""w1(method="sparse"): the sparse network simplex certified by the c-transform of its duals.

Every number is checked against POT's dense network simplex on the full cost matrix (an
independent computation): ``lower ≤ dense ≤ upper`` always, and ``exact`` ⇒ equal to
1e-12 relative.
"""

from unittest import mock

import numpy as np
import ot
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import cdist

import kinred.distance._sparse as sparse_mod
from kinred.distance import W1Result, paired_w1_bracket, w1
from kinred.distance._inputs import Pts
from kinred.distance._kernels import ctransform_numpy
from kinred.distance._search import CTree, ctransform, knn
from kinred.errors import InvalidInput, TooLarge


def _dense(x, a, y, b):
    return float(ot.emd2(a, b, cdist(x, y), numItermax=10**7))


@st.composite
def clouds(draw):
    """Two weighted clouds: random or clustered, paired or not, duplicates, zero weights,
    dimensions 1 to 50, near or far from the origin."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    d = draw(st.sampled_from([1, 2, 3, 4, 6, 8, 9, 20, 50]))
    n = draw(st.integers(1, 90))
    paired = draw(st.booleans())
    m = n if paired else draw(st.integers(1, 90))
    kind = draw(st.sampled_from(["normal", "clusters", "duplicates"]))
    if kind == "clusters":
        centres = rng.normal(size=(3, d)) * 5
        x = centres[rng.integers(0, 3, n)] + 0.05 * rng.normal(size=(n, d))
        y = centres[rng.integers(0, 3, m)] + 0.05 * rng.normal(size=(m, d))
    else:
        x = rng.normal(size=(n, d))
        y = rng.normal(size=(m, d)) + 0.3
    if kind == "duplicates":
        x[n // 2:] = x[: n - n // 2]
        y[: m // 3] = y[-(m // 3):] if m // 3 else y[: m // 3]
    if paired:
        y = x + draw(st.sampled_from([1e-3, 0.05, 1.0])) * rng.normal(size=(n, d))
        if kind == "duplicates":
            y[: n // 4] = x[: n // 4]              # some atoms do not move at all
    a = rng.random(n) if draw(st.booleans()) else np.ones(n)
    b = a.copy() if paired and draw(st.booleans()) else (rng.random(m) if draw(st.booleans())
                                                         else np.ones(m))
    if draw(st.booleans()):                         # zero weights (not all)
        a[rng.random(n) < 0.3] = 0.0
        b[rng.random(m) < 0.3] = 0.0
        a[0], b[-1] = max(a[0], 0.1), max(b[-1], 0.1)
    shift = draw(st.sampled_from([0.0, 1e6, -3e9]))
    return x + shift, a / a.sum(), y + shift, b / b.sum()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(clouds(), st.sampled_from([1, 3, 8]))
def test_bounds_hold_and_exact_means_the_dense_optimum(c, k):
    x, a, y, b = c
    ref = _dense(x, a, y, b)
    with mock.patch.object(sparse_mod, "_ALL_PAIRS", 0):       # the sparse graph even when small
        r = w1(x, y, "sparse", a=a, b=b, neighbors=k)
        cut = w1(x, y, "sparse", a=a, b=b, neighbors=1, max_iter=1)   # a budget of one solve
    tol = 1e-12 * ref + 1e-300
    for res in (r, cut):
        assert res.lower <= ref + tol and ref <= res.upper + tol
        assert res.lower <= res.upper
        if res.exact:
            assert res.value == pytest.approx(ref, rel=1e-12, abs=1e-300)
            assert res.lower == res.value == res.upper
        else:
            assert "NOT exact" in res.note and "because" in res.note
    assert r.exact or r.info["iterations"] == 30 or "round-off" in r.note


@pytest.mark.parametrize("d", [2, 4, 8])
def test_tree_ctransform_equals_its_numpy_twin(d):
    rng = np.random.default_rng(d)
    X, Y = rng.normal(size=(700, d)), rng.normal(size=(900, d)) * 1.5
    v = rng.normal(size=900) * 0.7
    f_ref, j_ref = ctransform_numpy(X, Y, v)
    start = np.arange(700) % 900                        # any attained values to start from
    best = np.sqrt(((X - Y[start]) ** 2).sum(axis=1)) - v[start]
    f, j = ctransform(X, Y, v, best, start, CTree(Y))
    np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-15)
    vals = np.sqrt(((X - Y[j]) ** 2).sum(axis=1)) - v[j]       # j attains f
    np.testing.assert_allclose(vals, f, rtol=1e-12, atol=1e-15)
    fb, jb = ctransform(X, Y, v, best, start, None)            # the BLAS path (high d)
    np.testing.assert_allclose(fb, f_ref, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("d", [2, 4])
@pytest.mark.parametrize("m", [1, 3])
def test_tree_ctransform_violators_equal_their_numpy_twin(d, m):
    """The violators of column generation: the ``m`` smallest values below ``thr[i]`` (the
    same values as brute force, in any row order), and the minimum still exact."""
    rng = np.random.default_rng(10 * d + m)
    X, Y = rng.normal(size=(500, d)), rng.normal(size=(600, d))
    v = rng.normal(size=600) * 0.5
    thr = np.median(ctransform_numpy(X, Y, v)[0]) + 0.2 * rng.normal(size=500)
    f_ref, _, c_ref = ctransform_numpy(X, Y, v, thr=thr, m=m)
    start = rng.integers(0, 600, size=500)
    best = np.sqrt(((X - Y[start]) ** 2).sum(axis=1)) - v[start]
    rows = rng.permutation(500)
    for tree in (CTree(Y), None):
        f, j, cand = ctransform(X, Y, v, best, start, tree, thr=thr, m=m, rows=rows)
        np.testing.assert_allclose(f, f_ref, rtol=1e-12, atol=1e-15)
        assert ((cand >= 0) == (c_ref >= 0)).all()          # as many violators per row
        got = np.where(cand >= 0, np.sqrt(((X[:, None] - Y[np.maximum(cand, 0)]) ** 2)
                                          .sum(axis=2)) - v[np.maximum(cand, 0)], np.inf)
        ref = np.where(c_ref >= 0, np.sqrt(((X[:, None] - Y[np.maximum(c_ref, 0)]) ** 2)
                                           .sum(axis=2)) - v[np.maximum(c_ref, 0)], np.inf)
        np.testing.assert_allclose(np.sort(got, axis=1), np.sort(ref, axis=1), rtol=1e-12)
        assert (np.where(cand >= 0, got, -np.inf) < thr[:, None]).all()
    assert (c_ref >= 0).any() and (c_ref < 0).any()          # both kinds of rows occur


def test_blas_ctransform_far_from_the_origin_keeps_its_digits():
    rng = np.random.default_rng(3)
    X = 1e6 + rng.normal(size=(300, 20)) * 1e-3
    Y = 1e6 + rng.normal(size=(200, 20)) * 1e-3
    v = rng.normal(size=200) * 1e-4
    f_ref, _ = ctransform_numpy(X, Y, v)
    f, _ = ctransform(X, Y, v, np.full(300, np.inf), np.zeros(300, np.int64), None)
    np.testing.assert_allclose(f, f_ref, rtol=1e-12)


def test_knn_high_dimension_matches_brute_force():
    rng = np.random.default_rng(4)
    X, Y = rng.normal(size=(200, 20)) + 1e5, rng.normal(size=(300, 20)) + 1e5
    idx = knn(X, Y, 5)
    ref = np.sort(np.argsort(cdist(X, Y), axis=1)[:, :5], axis=1)
    assert np.array_equal(np.sort(idx, axis=1), ref)


@settings(max_examples=80, deadline=None)
@given(rows=st.integers(1, 30), cols=st.integers(1, 80), k=st.integers(1, 12),
       ties=st.booleans(), nans=st.integers(0, 5), seed=st.integers(0, 2**16))
def test_smallest_k_is_the_stable_argsort(rows, cols, k, ties, nans, seed):
    """The blocked searches' selection (numba) against its twin, a stable argsort: the same
    columns in the same order, ties broken by the lower column, +inf then NaN entries last."""
    from kinred.distance._kernels import smallest_k, smallest_k_numpy

    k = min(k, cols)
    rng = np.random.default_rng(seed)
    D = rng.integers(0, 4, (rows, cols)).astype(float) if ties else rng.normal(size=(rows, cols))
    D.flat[rng.integers(0, D.size, nans)] = np.nan
    D.flat[rng.integers(0, D.size, nans // 2)] = np.inf
    got = smallest_k(D, k, np.empty((rows, k), np.int64))
    assert np.array_equal(got, smallest_k_numpy(D, k))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 700), d=st.integers(1, 7), h=st.integers(0, 6), ties=st.booleans(),
       seed=st.integers(0, 2**16))
def test_kd_order_splits_every_node_at_the_median_of_its_widest_coordinate(n, d, h, ties,
                                                                           seed):
    """The trees' row order (numba) is a permutation in which every node of depth t < h
    (rows ``(i·n) >> t : ((i + 1)·n) >> t``) splits its rows between its two children at the
    median of its widest coordinate; without ties its leaves hold the rows of its numpy
    twin's (``np.argpartition``)."""
    from kinred.distance._kernels import kd_order, kd_order_numpy

    rng = np.random.default_rng(seed)
    P = (rng.integers(0, 3, (n, d)).astype(float) if ties else
         rng.normal(size=(n, d)) * rng.uniform(0.1, 10, d) + rng.normal(0, 1e4, d))
    perm = np.arange(n, dtype=np.int64)
    kd_order(P, h, perm)
    assert np.array_equal(np.sort(perm), np.arange(n))
    for t in range(h):
        for i in range(1 << t):
            s_, e, mid = (i * n) >> t, ((i + 1) * n) >> t, ((2 * i + 1) * n) >> (t + 1)
            if e - s_ < 2 or mid <= s_ or mid >= e:
                continue
            Q = P[perm[s_:e]]
            k = int(np.argmax(Q.max(axis=0) - Q.min(axis=0)))
            assert Q[:mid - s_, k].max() <= Q[mid - s_:, k].min()
    if not ties:
        ref = kd_order_numpy(P, h)
        for i in range(1 << h):
            s_, e = (i * n) >> h, ((i + 1) * n) >> h
            assert np.array_equal(np.sort(perm[s_:e]), np.sort(ref[s_:e]))


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 40), extra=st.integers(0, 200), levels=st.integers(1, 6),
       seed=st.integers(0, 2**16))
def test_first_per_is_the_lexsort_minimum_with_ties_to_the_first(n, extra, levels, seed):
    """The per-group minimum of the searches' start values and its column: the minimum of
    each group, and of tied minima the first in the given order (as a stable lexsort)."""
    from kinred.distance._costs import first_per

    rng = np.random.default_rng(seed)
    group = np.concatenate([np.arange(n), rng.integers(0, n, extra)])
    rng.shuffle(group)
    vals = rng.integers(0, levels, group.size).astype(float)
    other = rng.integers(0, 10**6, group.size)
    best, arg = first_per(group, n, vals, other)
    order = np.lexsort((vals, group))
    g = group[order]
    first = np.ones(g.size, bool)
    first[1:] = g[1:] != g[:-1]
    assert np.array_equal(best[g[first]], vals[order][first])
    assert np.array_equal(arg[g[first]], other[order][first])


def test_candidate_keys_are_deduplicated():
    """scipy's COO -> CSR sums repeated (i, j) entries: an edge listed twice would cost twice."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(400, 3))
    y = x.copy()                                         # identity + kNN list (i, i) twice
    keys, _ = sparse_mod._initial_keys(x, np.full(400, 1 / 400), y, np.full(400, 1 / 400), 4,
                                       True)
    assert np.unique(keys).size == keys.size and np.all(np.diff(keys) > 0)
    r = w1(x, y + 0.01, "sparse")
    assert r.exact and r.value == pytest.approx(0.01 * np.sqrt(3), rel=1e-12)


def test_paired_clouds_exact_at_a_size_the_dense_lp_refuses():
    rng = np.random.default_rng(6)
    x = rng.normal(size=(20_000, 4)) * [1, 1, 0.3, 0.3]
    t = np.array([0.003, -0.004, 0.0, 0.0])           # a translation: W1 = |t| = 0.005
    r = w1(x, x + t, "sparse")
    assert r.exact and r.value == pytest.approx(0.005, rel=1e-12)
    assert r.info["edges"] > 20_000 and r.info["iterations"] >= 1


@pytest.mark.parametrize("scale", [1e160, 1e-200])
def test_homogeneous_rescaling(scale):
    rng = np.random.default_rng(7)
    x, y = rng.normal(size=(300, 3)), rng.normal(size=(250, 3)) + 0.2
    with mock.patch.object(sparse_mod, "_ALL_PAIRS", 0):
        r1 = w1(x, y, "sparse")
        r2 = w1(scale * x, scale * y, "sparse")
    assert r1.exact and r2.exact
    assert r2.value == pytest.approx(scale * r1.value, rel=1e-12)


def test_budget_exhausted_gives_a_certified_bracket_with_the_reason():
    rng = np.random.default_rng(8)
    x, y = rng.random((500, 2)), rng.random((400, 2))
    ref = _dense(x, np.full(500, 1 / 500), y, np.full(400, 1 / 400))
    r = w1(x, y, "sparse", neighbors=1, max_iter=1)
    assert not r.exact and r.lower <= ref <= r.upper
    assert "max_iter = 1" in r.note and "NOT exact" in r.note
    with pytest.raises(InvalidInput, match="not exact"):
        float(r)


def test_memory_is_priced_first_and_the_refusal_names_what_fits():
    x = np.zeros((3000, 3))
    with pytest.raises(TooLarge, match=r"method='sparse'.*atoms per side fit"):
        w1(x, x + 1.0, "sparse", max_bytes="1M")


def test_sparse_validation():
    x = np.random.default_rng(0).random((10, 2))
    with pytest.raises(InvalidInput, match="neighbors"):
        w1(x, x, "sparse", neighbors=0)
    with pytest.raises(InvalidInput, match="Euclidean"):
        w1(x, x, "sparse", metric="l1")
    with pytest.raises(InvalidInput, match="max_iter"):
        w1(x, x, "sparse", max_iter=0)
    from kinred.measures import Uniform, TensorProduct
    with pytest.raises(InvalidInput, match="two atomic"):
        w1(TensorProduct([Uniform(0, 1)] * 2), x, "sparse")


def test_auto_uses_sparse_beyond_the_dense_matrix():
    rng = np.random.default_rng(9)
    x, y = rng.random((300, 3)), rng.random((200, 3))
    ref = w1(x, y, "exact")
    r = w1(x, y, max_dense_bytes=1000)
    assert r.exact and r.method == "sparse" and "auto chose sparse" in r.note
    assert r.value == pytest.approx(ref.value, rel=1e-12)


# ---------------------------------------------------------------- issue 21, items 9 and 10


def test_a_bracket_does_not_pass_as_a_distance():
    """Issue 21.9: float() of a bracket returned its midpoint silently."""
    rng = np.random.default_rng(0)
    x, y = rng.random((80, 3)), rng.random((70, 3))
    br = w1(x, y, "bracket", leaf_size=20, dual_sample=30, seed=0)
    assert not br.exact
    with pytest.raises(InvalidInput, match=r"not exact.*\[.*\].*midpoint"):
        float(br)
    assert repr(br).startswith("W1Result(W1 in [") and "not exact" in repr(br)
    assert br.midpoint == pytest.approx(0.5 * (br.lower + br.upper), rel=1e-15)
    pb = paired_w1_bracket(x[:50], y[:50])
    with pytest.raises(InvalidInput, match="not exact"):
        float(pb)
    assert "W1 in [" in repr(pb)
    ex = w1(x, y)
    assert float(ex) == ex.value == ex.midpoint and repr(ex).startswith("W1Result(W1 = ")


def test_weights_with_equal_totals_are_normalized_unequal_refused():
    """Issue 21.10: weights had to sum to one (SciPy normalizes)."""
    from scipy.stats import wasserstein_distance

    rng = np.random.default_rng(1)
    x, y = rng.random(7), rng.random(5)
    a, b = rng.random(7), rng.random(5)
    a, b = 3.0 * a / a.sum(), 3.0 * b / b.sum()        # equal totals 3
    r = w1(x, y, a=a, b=b)
    assert r.value == pytest.approx(wasserstein_distance(x, y, a, b), rel=1e-12)
    assert w1(x, y, a=5 * np.ones(7)).value == pytest.approx(w1(x, y).value, rel=1e-14)
    with pytest.raises(InvalidInput, match=r"sum\(a\) = 3.0.*sum\(b\) = 6.0"):
        w1(x, y, a=a, b=2 * b)
    with pytest.raises(InvalidInput, match="positive finite total"):
        w1(x, y, a=np.zeros(7))
    assert isinstance(r, W1Result)


@pytest.mark.parametrize("d", [3, 12])
def test_time_budget_gives_a_certified_bracket_with_the_reason(d):
    rng = np.random.default_rng(10)
    x, y = rng.random((400, d)), rng.random((300, d)) + 0.1
    ref = _dense(x, np.full(400, 1 / 400), y, np.full(300, 1 / 300))
    r = w1(x, y, "sparse", max_seconds=0.0)
    assert not r.exact and r.lower <= ref <= r.upper and 0 < r.lower
    assert "max_seconds = 0" in r.note and "NOT exact" in r.note
    if d == 3:                                     # the tree search: cut short, still a bound
        assert "cut short for" in r.note


def test_large_high_dimensional_problems_use_trees():
    from kinred.distance._search import use_tree

    assert use_tree(10**6, 10**6, 20) and not use_tree(2 * 10**4, 2 * 10**4, 20)
    assert use_tree(10, 10, 8)


def test_run_table_and_summary_state_the_certified_gap():
    """kinred run: a time that is not exact shows its bracket and gap; summary.json's
    ``w1_rel_gap_max`` is the largest relative gap (0 when every time is exact)."""
    from kinred.experiments.kinetic_run import _rel_gap

    r = {"lower": np.array([1.0, 0.99, 2.0]), "upper": np.array([1.0, 1.0, 2.5]),
         "exact": np.array([True, False, False])}
    np.testing.assert_allclose(_rel_gap(r), [0.0, 0.01, 0.2], rtol=1e-12)
    r["exact"][:] = True
    assert np.all(_rel_gap(r) == 0.0)


def test_a_search_cut_short_gives_a_lower_bound_of_the_minimum():
    from kinred.distance import _search

    rng = np.random.default_rng(11)
    X, Y = rng.normal(size=(500, 3)), rng.normal(size=(3000, 3))
    v = rng.normal(size=3000) * 0.3
    f_ref, _ = ctransform_numpy(X, Y, v)
    start = np.zeros(500, np.int64)
    best = np.sqrt(((X - Y[0]) ** 2).sum(axis=1)) - v[0]
    opened = np.zeros(500, np.int8)
    f, _ = ctransform(X, Y, v, best, start, CTree(Y), deadline=0.0, open_rows=opened)
    assert 0 < opened.sum() < 500                             # some rows cut short, not all
    assert np.all(f <= f_ref + 1e-12)                         # a bound, never above the minimum
    np.testing.assert_allclose(f[opened == 0], f_ref[opened == 0], rtol=1e-12, atol=1e-15)
    assert _search.LEAVES_PAST_DEADLINE == 8


def test_auto_when_the_sparse_preflight_refuses():
    x = np.random.default_rng(12).random((300, 3))
    r = w1(x, x + 0.1, max_dense_bytes=0, max_bytes=10_000)          # lazy LP still allowed
    assert r.exact and r.method == "exact-lazy"
    assert r.value == pytest.approx(0.1 * np.sqrt(3), rel=1e-12)
    with pytest.raises(TooLarge, match="method='sparse'.*atoms per side fit"):
        w1(x, x + 0.1, max_dense_bytes=0, max_bytes=10_000, max_exact_pairs=10)


def _paired(n, d=4, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, d))
    return x, x + 0.05 * rng.normal(size=(n, d))


def test_a_forked_solve_gives_the_in_process_numbers(monkeypatch):
    """Large graphs with a time budget solve in a forked child: the same plan and duals."""
    x, y = _paired(3000)
    ref = w1(x, y, "sparse", seed=0, max_dense_bytes=0)
    monkeypatch.setattr(sparse_mod, "FORK_EDGES", 0)
    got = w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=600.0)
    assert got.exact and ref.exact
    assert (got.value, got.lower, got.upper) == (ref.value, ref.lower, ref.upper)


@pytest.mark.parametrize("paired", [True, False])
def test_a_solve_past_the_budget_is_stopped_and_its_bracket_certified(monkeypatch, paired):
    """The network simplex cannot be interrupted, its child process can: a solve that would
    run past ``max_seconds`` is stopped there, and the answer is the certified bracket of an
    explicit coupling and 1-D projections (paired: the paired bracket), with the reason."""
    import time

    x, y = _paired(2000)
    if not paired:
        y = y[:1500]
    exact = w1(x, y, "exact").value
    monkeypatch.setattr(sparse_mod, "FORK_EDGES", 0)
    monkeypatch.setattr(sparse_mod, "_solve", lambda *args: time.sleep(600))
    t0 = time.perf_counter()
    r = w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=3.0)
    took = time.perf_counter() - t0
    assert took < 30.0                                 # stopped near its 3 s, not after 600 s
    assert not r.exact and "ran out during solve 1" in r.note
    assert r.lower <= exact <= r.upper
    assert r.upper / exact < (1.01 if paired else 2.0)  # a coupling: a bound, not a blank
    assert r.lower / exact > (0.05 if paired else 0.3)  # projections: weak in R^4, not void


def test_a_later_solve_past_the_budget_keeps_the_better_of_dual_and_projections(monkeypatch):
    """Solve 2 stopped: the bracket is the earlier rounds' -- with the lower end at least the
    1-D projections' bound, even when round 1's c-transform was poor (here forced to -1)."""
    x, y = _paired(2000)
    y = y + 0.05
    exact = w1(x, y, "exact").value
    real_round = sparse_mod._solve_round
    calls = []

    def round_then_stop(*args):
        calls.append(1)
        if len(calls) > 1:
            raise sparse_mod._SolveTimedOut
        return real_round(*args)

    def poor_certificate(X, a, Y, b, u, v, plan, keys, trees, roundoff, noise, deadline, tm,
                         violators):
        far = np.arange(0, X.shape[0] * Y.shape[0], 997, dtype=np.int64)  # not all in E
        return sparse_mod.plan_cost(X, Y, plan), -1.0, 1.0, 0, far, noise

    monkeypatch.setattr(sparse_mod, "_solve_round", round_then_stop)
    monkeypatch.setattr(sparse_mod, "certify_repaired", poor_certificate)
    monkeypatch.setattr(sparse_mod, "_certify", lambda X, *a, **k: (
        -1.0, 1.0, 0, np.arange(0, X.shape[0] ** 2, 997, dtype=np.int64)))
    r = w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=60.0)
    assert len(calls) == 2 and not r.exact and "ran out during solve 2" in r.note
    assert "1-D projections" in r.note
    assert 0.3 * exact < r.lower <= exact <= r.upper


def test_a_first_solve_that_ends_past_the_budget_gets_the_paired_bracket_and_its_cost(
        monkeypatch):
    """Paired atoms whose first solve ends after ``max_seconds`` (the certificate has no time
    left): the lower end is the paired bracket's (as for a stopped solve), the upper end the
    solved plan's cost, below the index coupling's; flagged like a stopped first solve, so
    that the kinetic comparison does not wait again at the later times."""
    from kinred.distance import paired_w1_bracket

    x, y = _paired(2000)
    y = y + 0.05 * np.random.default_rng(3).standard_normal(y.shape)
    exact = w1(x, y, "exact").value
    monkeypatch.setattr(sparse_mod._Budget, "spent", lambda self: True)
    r = w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=60.0)
    pb = paired_w1_bracket(x, y, np.full(2000, 1 / 2000), seed=0)
    assert r.info["first_solve_stopped"] and r.info["iterations"] == 1
    assert "before its certificate" in r.note
    assert r.lower <= exact * (1 + 1e-12) and r.upper >= exact * (1 - 1e-12)
    assert r.upper < pb.upper * (1 - 1e-4)            # the solve's plan, not the pairing
    assert r.upper == pytest.approx(exact, rel=1e-6)  # optimal on the 8-NN graph already


@pytest.mark.parametrize("cut", [False, True])
def test_a_first_certificate_that_ends_past_the_budget_gets_the_paired_bracket(monkeypatch,
                                                                               cut):
    """The budget runs out during round 1's certificate (a poor certificate, then the clock;
    or a search cut short, ``OutOfTime``): no 1-D projections, no round 2 -- the paired
    bracket's dual bound met with the round's bounds, flagged as stopped."""
    from kinred.distance._search import OutOfTime

    from kinred.distance import paired_w1_bracket

    x, y = _paired(2000)
    y = y + 0.05 * np.random.default_rng(4).standard_normal(y.shape)
    exact = w1(x, y, "exact").value
    clock = []

    def spent(self):
        clock.append(1)
        return len(clock) > 1      # time left after the solve, none after the certificate

    def poor_certificate(X, a, Y, b, u, v, plan, keys, trees, roundoff, noise, deadline, tm,
                         violators):
        if cut:
            raise OutOfTime
        return sparse_mod.plan_cost(X, Y, plan), -1.0, 1.0, 0, np.array([0], np.int64), noise

    monkeypatch.setattr(sparse_mod._Budget, "spent", spent)
    monkeypatch.setattr(sparse_mod, "certify_repaired", poor_certificate)
    monkeypatch.setattr(sparse_mod, "_cheap_lower", lambda *a: pytest.fail("projections run"))
    r = w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=60.0)
    pb = paired_w1_bracket(x, y, np.full(2000, 1 / 2000), seed=0, dual_seconds=60.0)
    assert r.info["first_solve_stopped"] and r.info["iterations"] == 1
    assert "during solve 1's certificate" in r.note
    assert r.lower >= pb.lower * (1 - 1e-9) and r.lower <= exact * (1 + 1e-12)
    assert exact * (1 - 1e-12) <= r.upper < pb.upper


def test_a_stopped_solve_on_paired_atoms_is_exact_when_the_dual_proves_the_pairing(
        monkeypatch):
    """Paired atoms whose index coupling is optimal (a translation smaller than the atoms'
    spacing): when the first solve is stopped, the fallback's dual bound still proves the
    value, ``exact=True`` with the stopped solve named in the note."""
    import time

    x, _ = _paired(2000)
    y = x + np.array([1e-4, 0.0, 0.0, 0.0])
    monkeypatch.setattr(sparse_mod, "FORK_EDGES", 0)
    monkeypatch.setattr(sparse_mod, "_solve", lambda *args: time.sleep(600))
    r = w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=2.0)
    assert r.exact and r.info["first_solve_stopped"]
    assert r.value == pytest.approx(1e-4, rel=1e-12)
    assert "exact all the same" in r.note and "ran out during solve 1" in r.note


def test_a_failing_child_raises_a_named_error(monkeypatch):
    from kinred.errors import NotConverged

    x, y = _paired(2000)
    monkeypatch.setattr(sparse_mod, "FORK_EDGES", 0)

    def boom(*args):
        raise NotConverged("w1(method='sparse'): status 2")

    monkeypatch.setattr(sparse_mod, "_solve", boom)
    with pytest.raises(NotConverged, match="status 2"):
        w1(x, y, "sparse", seed=0, max_dense_bytes=0, max_seconds=60.0)


def test_the_path_does_not_depend_on_the_seed():
    """The exact method draws nothing: the monotone coupling's axis is computed, so two calls
    without a seed take the same path (same solves, same edges) to the same value -- and a
    bracket, when the budget stops the method, is the same too."""
    rng = np.random.default_rng(8)
    x, y = rng.normal(size=(1500, 3)), rng.normal(size=(1200, 3)) * 0.8 + 0.1
    a, b = rng.random(1500), rng.random(1200)
    a, b = a / a.sum(), b / b.sum()
    r1, r2 = (w1(x, y, "sparse", a=a, b=b, neighbors=3) for _ in range(2))
    assert r1.exact and r1.value == r2.value
    assert r1.info["iterations"] == r2.info["iterations"] and r1.info["edges"] == r2.info["edges"]
    axis = sparse_mod.principal_axis(np.concatenate([x, y]), np.concatenate([a, b]) / 2)
    w = np.concatenate([a, b]) / 2
    z = np.concatenate([x, y]) - w @ np.concatenate([x, y])
    lam = axis @ (z.T @ (w[:, None] * z)) @ axis
    assert lam == pytest.approx(np.linalg.eigvalsh(z.T @ (w[:, None] * z))[-1], rel=1e-12)


@pytest.mark.parametrize("paired", [True, False])
def test_the_value_does_not_depend_on_the_atoms_numbering(paired):
    """The solver renumbers the atoms along the Z-order curve (cache locality); W1 does not
    depend on the numbering, and paired atoms keep their pairing (one permutation for both
    sides: with paired weights the identity coupling is the graph's feasible coupling). A
    relabelled input gives the dense optimum again, to 1e-12."""
    rng = np.random.default_rng(21)
    n = 1200
    x = rng.normal(size=(n, 4)) * [1.0, 1.0, 0.3, 0.3]
    a = rng.random(n)
    a /= a.sum()
    if paired:
        y, b = x + 0.01 * rng.normal(size=(n, 4)), a
    else:
        y, b = rng.normal(size=(900, 4)) + 0.05, rng.random(900)
        b /= b.sum()
    ref = _dense(x, a, y, b)
    p = rng.permutation(n)
    q = p if paired else rng.permutation(y.shape[0])
    for xx, aa, yy, bb in ((x, a, y, b), (x[p], a[p], y[q], b[q])):
        r = w1(xx, yy, "sparse", a=aa, b=bb, neighbors=4)
        assert r.exact and r.value == pytest.approx(ref, rel=1e-12)
    # the renumbering keeps the pairs: the same permutation on both sides
    ox = sparse_mod._morton_order(x)
    X2, a2, Y2, b2 = sparse_mod._spatial_order(x, a, y, b, paired)
    assert np.array_equal(X2, x[ox]) and np.array_equal(a2, a[ox])
    if paired:
        assert np.array_equal(Y2 - X2, (y - x)[ox]) and np.array_equal(b2, a2)
