"""Tests of kinred.distance: W1 against closed forms, independent solvers and the paper's bounds."""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import integrate, stats

from kinred.distance import sliced_w1, w1
from kinred.distance._bracket import dual_lower, hierarchical_upper, projection_lower
from kinred.distance._inputs import Pts, grid_marginals
from kinred.distance._oned import w2sq_1d
from kinred.errors import InvalidInput, NotConverged, TooLarge
from kinred.measures import Atomic, Dirac, Empirical1D, TensorProduct, Uniform, Univariate

REL = 1e-12


def _rand_weights(rng, n):
    w = rng.random(n) + 0.05
    return w / w.sum()


# --------------------------------------------------------------------------- closed forms
@given(st.integers(1, 6), st.integers(1, 30), st.integers(0, 10_000))
def test_translation_gives_norm_of_shift(d, n, s):
    rng = np.random.default_rng(s)
    x = rng.standard_normal((n, d)) * 3
    t = rng.standard_normal(d) * rng.choice([1e-3, 1.0, 50.0])
    w = _rand_weights(rng, n)
    r = w1(x, x + t, "exact", a=w, b=w)
    assert r.exact and r.method == "exact"
    assert r.value == pytest.approx(np.linalg.norm(t), rel=1e-11)
    assert r.lower == r.value == r.upper


def test_translation_lazy_and_auto_lazy():
    rng = np.random.default_rng(1)
    x = rng.random((60, 4))
    t = np.array([0.3, -0.1, 2.0, 0.0])
    r = w1(x, x + t, "exact-lazy")
    assert r.method == "exact-lazy" and r.value == pytest.approx(np.linalg.norm(t), rel=1e-11)
    r2 = w1(x, x + t, max_dense_bytes=1000)  # 60*60*8 > 1000: auto goes sparse (Euclidean)
    assert r2.method == "sparse" and r2.exact and "auto chose sparse" in r2.note
    assert r2.value == pytest.approx(np.linalg.norm(t), rel=1e-11)
    r3 = w1(x, x + t, max_dense_bytes=1000, metric="l1")  # l1: auto goes lazy
    assert r3.method == "exact-lazy" and r3.exact and "auto chose exact-lazy" in r3.note
    assert r3.value == pytest.approx(np.abs(t).sum(), rel=1e-11)


def test_two_diracs():
    x, y = np.array([1.0, -2.0, 0.5]), np.array([4.0, 2.0, 0.5])
    r = w1(Dirac(x), Dirac(y))
    assert r.exact and r.value == pytest.approx(5.0, rel=REL)
    assert w1(Dirac(2.0), Dirac(-1.5)).value == pytest.approx(3.5, rel=REL)
    assert w1(Dirac(2.0), Dirac(-1.5)).method == "exact-1d"


@pytest.mark.parametrize("N", [1, 2, 7, 100])
@pytest.mark.parametrize("ab", [(0.0, 1.0), (-3.0, 2.5)])
def test_uniform_vs_quantile_atoms_closed_form(N, ab):
    a, b = ab
    sig = b - a
    mu = Uniform(a, b)
    mid = a + sig * (2 * np.arange(1, N + 1) - 1) / (2 * N)   # W1-optimal, σ/(4N)
    paper = a + sig * np.arange(1, N + 1) / N                  # paper's levels i/N, σ/(2N)
    r1 = w1(mu, mid[:, None])
    r2 = w1(mu, Empirical1D(paper))
    assert r1.method == "exact-1d" and r1.exact
    assert r1.value == pytest.approx(sig / (4 * N), rel=1e-12)
    assert r2.value == pytest.approx(sig / (2 * N), rel=1e-12)
    # squared W2 of the midpoint quantizer: σ²/(12 N²)
    from kinred.distance._inputs import Cont1D

    v, _ = w2sq_1d(Cont1D(mu), Pts(mid[:, None], np.full(N, 1 / N)))
    assert v == pytest.approx(sig**2 / (12 * N**2), rel=1e-10)


def _u_space_w1(ppf, y, wy):
    """Independent reference: ∫₀¹ |F⁻¹(u) − Q(u)| du by quad over each cell of Q."""
    o = np.argsort(y)
    y, wy = y[o], wy[o]
    c = np.concatenate([[0.0], np.cumsum(wy)])
    c[-1] = 1.0
    tot = 0.0
    for k in range(y.size):
        v, _ = integrate.quad(lambda u: abs(float(ppf(u)) - y[k]), c[k], c[k + 1], limit=200,
                              epsabs=1e-15, epsrel=1e-13)
        tot += v
    return tot


@pytest.mark.parametrize("law", [stats.beta(2, 2), stats.beta(0.7, 3.0), "truncnorm"])
def test_continuous_vs_atoms_matches_quantile_integral(law):
    rng = np.random.default_rng(3)
    mu = Univariate(stats.norm(0.3, 1.0), support=(-1.0, 2.0)) if law == "truncnorm" else Univariate(law)
    lo, hi = mu.support
    y = lo - 0.2 + (hi - lo + 0.4) * rng.random(12)   # some atoms outside the support
    wy = _rand_weights(rng, 12)
    ref = _u_space_w1(mu.ppf, y, wy)
    r = w1(mu, y, b=wy)
    assert r.exact and r.method == "exact-1d"
    assert r.value == pytest.approx(ref, rel=1e-9, abs=1e-12)


def test_continuous_vs_continuous():
    # Uniform(0,1) vs Uniform(0.5, 2): ∫₀¹ |u − (0.5 + 1.5u)| du = 0.75
    assert w1(Uniform(0, 1), Uniform(0.5, 2)).value == pytest.approx(0.75, rel=1e-12)
    mu, nu = Univariate(stats.beta(2, 3)), Univariate(stats.beta(3, 1.5))
    ref, _ = integrate.quad(lambda u: abs(mu.ppf(u) - nu.ppf(u)), 0, 1, limit=400, epsabs=1e-14)
    assert w1(mu, nu).value == pytest.approx(ref, rel=1e-9)


@given(st.integers(1, 25), st.integers(1, 25), st.integers(0, 10_000))
def test_emd_agrees_with_exact_1d(n, m, s):
    rng = np.random.default_rng(s)
    x = rng.standard_normal(n) * rng.choice([0.01, 1.0, 100.0])
    y = rng.standard_normal(m) + 0.5
    if s % 3 == 0:
        y[: min(m, n)] = x[: min(m, n)]   # ties
    a, b = _rand_weights(rng, n), _rand_weights(rng, m)
    r1 = w1(x[:, None], y[:, None], "exact", a=a, b=b)
    r2 = w1(x, y, "exact-1d", a=a, b=b)
    r3 = w1(x, y, a=a, b=b)
    assert r3.method == "exact-1d"
    assert r2.value == pytest.approx(r1.value, rel=1e-12, abs=1e-14)
    # and against scipy's own 1-D routine
    assert r2.value == pytest.approx(stats.wasserstein_distance(x, y, a, b), rel=1e-10, abs=1e-14)


# --------------------------------------------------------------------------- product / ℓ1
def _grid(values, weights):
    pts = np.array(list(itertools.product(*values)))
    w = np.array([math.prod(c) for c in itertools.product(*weights)])
    return pts, w / w.sum()


@given(st.integers(2, 3), st.integers(0, 10_000))
def test_product_l1_equals_sum_of_marginals_and_bounds_euclidean(d, s):
    rng = np.random.default_rng(s)
    ns = rng.integers(1, 5, size=d)
    ms = rng.integers(1, 5, size=d)
    v1 = [np.sort(rng.standard_normal(k)) for k in ns]
    v2 = [np.sort(rng.standard_normal(k)) + rng.standard_normal() for k in ms]
    w1s = [_rand_weights(rng, k) for k in ns]
    w2s = [_rand_weights(rng, k) for k in ms]
    x, a = _grid(v1, w1s)
    y, b = _grid(v2, w2s)
    r = w1(x, y, "product-l1", a=a, b=b)          # grids are detected
    assert r.metric == "l1" and r.exact
    marg = sum(stats.wasserstein_distance(p, q, wp, wq) for p, q, wp, wq in zip(v1, v2, w1s, w2s))
    assert r.value == pytest.approx(marg, rel=1e-10, abs=1e-14)
    # an independent LP: POT with the ℓ1 (cityblock) ground cost on the full grids
    lp = w1(x, y, "exact", a=a, b=b, metric="l1")
    assert r.value == pytest.approx(lp.value, rel=1e-9, abs=1e-12)
    eu = w1(x, y, "exact", a=a, b=b)
    assert eu.value <= r.value * (1 + 1e-12) + 1e-14
    # the same through TensorProduct of Empirical1D factors
    T1 = TensorProduct([Empirical1D(v, w) for v, w in zip(v1, w1s)])
    T2 = TensorProduct([Empirical1D(v, w) for v, w in zip(v2, w2s)])
    assert w1(T1, T2, "product-l1").value == pytest.approx(marg, rel=1e-10, abs=1e-14)
    assert w1(T1, T2).value == pytest.approx(eu.value, rel=1e-10, abs=1e-14)  # small grids: exact


def test_grid_detection_is_safe():
    x, a = _grid([np.array([0.0, 1.0]), np.array([0.0, 2.0, 3.0])], [np.array([0.3, 0.7]), np.ones(3) / 3])
    assert grid_marginals(Pts(x, a)) is not None
    b = a.copy()
    b[0] += 0.01
    b[1] -= 0.01
    assert grid_marginals(Pts(x, b)) is None           # weights do not factorize
    assert grid_marginals(Pts(x[:-1], np.ones(5) / 5)) is None  # not the full grid
    y = np.array([[0.0, 0.0], [1.0, 1.0]])             # 2 distinct values each, but 2 != 4 atoms
    with pytest.raises(InvalidInput, match="product=True"):
        w1(y, y + 1, "product-l1")
    r = w1(y, y + 1, "product-l1", product=True)       # user-declared product: marginals used
    assert r.value == pytest.approx(2.0, rel=REL)


def test_tensor_products_continuous():
    T = TensorProduct([Uniform(0, 1), Uniform(0, 2), Uniform(-1, 1)])
    t = np.array([0.2, -0.5, 0.1])
    S = TensorProduct([Uniform(0 + t[0], 1 + t[0]), Uniform(t[1], 2 + t[1]), Uniform(-1 + t[2], 1 + t[2])])
    r = w1(T, S, "bracket")
    assert r.method == "bracket"
    assert r.lower == pytest.approx(np.linalg.norm(t), rel=1e-9)
    assert r.upper == pytest.approx(np.linalg.norm(t), rel=1e-9)
    assert w1(T, S, "product-l1").value == pytest.approx(np.abs(t).sum(), rel=1e-9)


def test_continuous_product_vs_atoms_bracket_is_consistent():
    T = TensorProduct([Uniform(0, 1), Uniform(0, 1)])
    rng = np.random.default_rng(5)
    y = rng.random((150, 2)) ** 2
    r = w1(T, y, "bracket", seed=0)
    assert r.method == "bracket" and not r.exact and r.n_atoms == (None, 150)
    # fine midpoint grid G (64x64): |W1(T, y) − W1(G, y)| ≤ W1(T, G) ≤ 2·1/(4·64)
    g = (2 * np.arange(1, 65) - 1) / 128
    G = np.array(list(itertools.product(g, g)))
    ref = w1(G, y).value
    e = 2 / (4 * 64)
    assert r.lower <= ref + e and r.upper >= ref - e
    assert r.upper - r.lower < 0.5 * r.upper


# --------------------------------------------------------------------------- push-forward
@given(st.integers(2, 5), st.integers(1, 4), st.integers(2, 25), st.integers(0, 10_000))
def test_pushforward_is_lipschitz(d, k, n, s):
    """W1(M#μ, M#ν) ≤ ‖M‖ W1(μ, ν) (eq. (4.8)-(4.9), labels pf, projatom)."""
    rng = np.random.default_rng(s)
    mu = Atomic(rng.standard_normal((n, d)), _rand_weights(rng, n))
    nu = Atomic(rng.standard_normal((n + 3, d)) + 0.5, _rand_weights(rng, n + 3))
    M = rng.standard_normal((k, d))
    lhs = w1(mu.push(M), nu.push(M)).value
    rhs = np.linalg.norm(M, 2) * w1(mu, nu).value
    assert lhs <= rhs * (1 + 1e-10) + 1e-13
    lhs2 = w1(mu.points @ M.T, nu.points @ M.T, a=mu.weights, b=nu.weights).value
    assert lhs2 == pytest.approx(lhs, rel=1e-12, abs=1e-14)


# --------------------------------------------------------------------------- POT pitfalls
def test_default_numitermax_stops_early_but_ours_converges():
    import ot

    rng = np.random.default_rng(0)
    n, d = 2500, 10
    x = rng.standard_normal((n, d))
    y = rng.standard_normal((n, d)) + 0.3
    a = np.full(n, 1 / n)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        naive, log = ot.emd2(a, a, ot.dist(x, y, metric="euclidean"), log=True)
    assert log["result_code"] == 3  # "numItermax reached before optimality"
    assert any("numItermax" in str(c.message) for c in caught)
    r = w1(x, y, "exact")
    assert r.exact
    assert naive > r.value * (1 + 1e-4)  # the naive call overestimates
    with pytest.raises(NotConverged, match="num_iter_max"):
        w1(x[:300], y[:300], "exact", num_iter_max=50)
    with pytest.raises(NotConverged):
        w1(x[:300], y[:300], "exact-lazy", num_iter_max=50)


def test_pot_default_metric_would_be_w2_squared():
    import ot

    x = np.zeros((1, 2))
    y = np.array([[3.0, 4.0]])
    assert ot.emd2([1.0], [1.0], ot.dist(x, y)) == pytest.approx(25.0)   # POT's default
    assert w1(x, y).value == pytest.approx(5.0, rel=REL)


# --------------------------------------------------------------------------- bracket
@pytest.mark.parametrize("s", range(4))
def test_bracket_contains_exact_value(s):
    rng = np.random.default_rng(100 + s)
    d = [2, 5, 10, 3][s]
    n, m = 500, 450
    if s == 3:  # clustered, weighted
        cx = rng.standard_normal((4, d)) * 5
        x = cx[rng.integers(0, 4, n)] + rng.standard_normal((n, d))
        y = cx[rng.integers(0, 4, m)] + rng.standard_normal((m, d)) * 0.5
    else:
        x = rng.standard_normal((n, d))
        y = rng.random((m, d)) * 2 + 0.2
    a, b = _rand_weights(rng, n), _rand_weights(rng, m)
    exact = w1(x, y, "exact", a=a, b=b).value
    r = w1(x, y, "bracket", a=a, b=b, leaf_size=100, dual_sample=150, n_projections=32, seed=s)
    assert r.method == "bracket" and not r.exact
    assert r.lower <= exact * (1 + 1e-12) and exact <= r.upper * (1 + 1e-12)
    assert r.lower <= r.value <= r.upper
    assert r.upper < 1.6 * exact and r.lower > 0.3 * exact   # informative, not just valid
    # each bound separately is a bound
    P, Q = Pts(x, a), Pts(y, b)
    g = np.random.default_rng(s)
    assert projection_lower(P, Q, g, n_projections=8)[0] <= exact * (1 + 1e-12)
    assert dual_lower(P, Q, g, n_sub=80) <= exact * (1 + 1e-12)
    assert hierarchical_upper(P, Q, leaf_size=60)[0] >= exact * (1 - 1e-12)


def test_bracket_on_translation_is_tight():
    rng = np.random.default_rng(7)
    x = rng.standard_normal((400, 6))
    t = np.full(6, 0.7)
    r = w1(x, x + t, "bracket", leaf_size=64, seed=1)
    assert r.lower == pytest.approx(np.linalg.norm(t), rel=1e-9)   # difference of means
    assert r.upper == pytest.approx(np.linalg.norm(t), rel=1e-9)


def test_auto_reports_method_and_exactness():
    rng = np.random.default_rng(2)
    x, y = rng.random((80, 3)), rng.random((70, 3))
    r = w1(x, y)
    assert r.method == "exact" and r.exact and r.note.startswith("auto chose exact")
    r = w1(x, y, "bracket", max_exact_pairs=100, leaf_size=20, dual_sample=30, seed=0)
    assert r.method == "bracket" and not r.exact
    assert r.lower <= w1(x, y).value <= r.upper and r.n_atoms == (80, 70)
    r = w1(x, y, "bracket", seed=0)   # a single exact leaf: the bounds meet
    assert r.exact and r.value == pytest.approx(w1(x, y).value, rel=1e-11)
    assert "bounds meet" in r.note


def test_auto_is_exact_or_raises_never_a_silent_bracket():
    """Issue 18: "auto" returned the midpoint of a wide bracket as its value (here 29 % off)."""
    rng = np.random.default_rng(0)
    x, y = rng.random((80, 3)), rng.random((70, 3))
    exact = w1(x, y, "exact").value
    br = w1(x, y, "bracket", leaf_size=20, dual_sample=30, seed=0)   # asked for: a bracket
    assert br.lower <= exact <= br.upper and not br.exact
    assert abs(br.value - exact) > 0.2 * exact                      # the midpoint is far off
    r = w1(x, y, max_exact_pairs=100, max_dense_bytes=0)            # beyond the LPs: sparse
    assert r.exact and r.method == "sparse" and r.value == pytest.approx(exact, rel=1e-12)
    with pytest.raises(TooLarge) as exc:                            # l1: no sparse method
        w1(x, y, metric="l1", max_exact_pairs=100, leaf_size=20, dual_sample=30, seed=0)
    msg = str(exc.value)
    for part in ("mu has 80 atoms and nu 70", "N·M = 5600", "max_exact_pairs = 100",
                 "method='exact-lazy'", "memory O(N + M)", "roughly", "method='exact'",
                 "max_exact_pairs >= 5600", "method='bracket'"):
        assert part in msg, part
    r = w1(x, y, max_exact_pairs=5600)                              # the limit raised: exact
    assert r.exact and r.method == "exact" and r.value == exact


def test_auto_on_continuous_laws_in_d_above_1_raises_with_the_alternatives():
    T = TensorProduct([Uniform(0, 1), Uniform(0, 1)])
    S = TensorProduct([Uniform(0.5, 1.5), Uniform(0, 1)])
    with pytest.raises(InvalidInput, match=r"mu and nu are continuous laws in d = 2.*"
                                           r"method='bracket'.*method='product-l1'"):
        w1(T, S)
    with pytest.raises(InvalidInput, match=r"mu is a continuous law in d = 2.*method='bracket'"
                                           r"(?!.*product-l1).*kinred.quantize"):
        w1(T, np.random.default_rng(0).random((10, 2)))
    assert w1(T, S, "bracket").exact and w1(T, S, "bracket").value == pytest.approx(0.5, rel=1e-9)
    assert w1(T, S, metric="l1").method == "product-l1"           # exact for the l1 cost
    assert w1(Uniform(0, 1), Uniform(0.5, 1.5)).value == pytest.approx(0.5, rel=1e-12)  # d = 1


# --------------------------------------------------------------------------- sliced
def test_sliced_is_a_different_distance():
    d = 10
    x = np.random.default_rng(0).standard_normal((5, d))
    t = np.random.default_rng(1).standard_normal(d)
    full = w1(x, x + t).value
    sw = sliced_w1(x, x + t, n_projections=3000, seed=0)
    factor = math.gamma(d / 2) / (math.sqrt(math.pi) * math.gamma((d + 1) / 2))  # E|θ₁| ≈ 0.2587
    assert full == pytest.approx(np.linalg.norm(t), rel=1e-11)
    assert abs(sw.value / full - factor) < 4 * sw.stderr / full
    assert 0.24 < sw.value / full < 0.28


# --------------------------------------------------------------------------- validation
def test_validation_messages():
    x = np.zeros((3, 2))
    with pytest.raises(InvalidInput, match="finite"):
        w1(np.array([[np.nan, 0.0]]), x)
    with pytest.raises(InvalidInput, match="finite"):
        w1(x, np.array([[np.inf, 0.0]]))
    with pytest.raises(InvalidInput, match="same dimension"):
        w1(x, np.zeros((3, 3)))
    with pytest.raises(InvalidInput, match="non-negative"):
        w1(x, x, a=[0.5, 0.6, -0.1])
    with pytest.raises(InvalidInput, match=r"equal totals.*sum\(a\) = 1.0 and sum\(b\) = 1.2"):
        w1(x, x, a=[0.5, 0.4, 0.1], b=[0.5, 0.6, 0.1])
    with pytest.raises(InvalidInput, match="length 3"):
        w1(x, x, a=[0.5, 0.5])
    with pytest.raises(InvalidInput, match="method must be one of"):
        w1(x, x, "sinkhorn")
    with pytest.raises(InvalidInput, match="metric"):
        w1(x, x, metric="sqeuclidean")
    with pytest.raises(InvalidInput, match="must be None"):
        w1(Atomic(x), x, a=np.ones(3) / 3)
    with pytest.raises(InvalidInput, match="exact-1d"):
        w1(x, x, "exact-1d")
    with pytest.raises(InvalidInput, match="two atomic"):
        w1(Uniform(0, 1), Dirac(0.0), "exact")
    with pytest.raises(TooLarge, match="exact-lazy"):
        w1(np.zeros((50, 2)), np.ones((50, 2)), "exact", max_dense_bytes=100)
    with pytest.raises(InvalidInput, match="seed"):
        w1(x, x + 1, "bracket", seed=-1)


def test_mixture_of_atomic_measures():
    from kinred.measures import Mixture

    m = Mixture([TensorProduct([Empirical1D([0.0, 1.0]), Dirac(0.0)]), Atomic([[5.0, 5.0]])], [0.5, 0.5])
    r = w1(m, Dirac([0.0, 0.0]))
    assert r.exact and r.value == pytest.approx(0.25 + 0.5 * math.sqrt(50.0), rel=REL)


# ------------------------------------------------------------- magnitudes (issue 14, W1 defects)
# W1 is translation invariant and homogeneous, W1(c + sμ, c + sν) = s·W1(μ, ν). Every method
# computes in one common frame of order one (kinred.distance._inputs.normalize_pair), so inputs
# near 1e160 (squared costs overflow) or 1e-200 (squared costs underflow) keep full accuracy.

#: The audit's scales, and powers of two next to them (scaling by those is exact, so large
#: shifts c can be added without rounding the inputs).
SCALES = [1e-200, 1e-100, 1.0, 1e100, 1e160, 1e200]
POW2_SCALES = [2.0**-664, 2.0**-332, 1.0, 2.0**332, 2.0**531, 2.0**664]


def _every_method(x, y, a, b, seed=0):
    """``{name: (value, lower, upper)}`` of every method applicable to atoms ``x``, ``y``."""
    out = {}
    methods = ["exact", "exact-lazy", "bracket", "product-l1"] + (["exact-1d"] if x.shape[1] == 1 else [])
    for m in methods:
        r = w1(x, y, m, a=a, b=b, product=True, seed=seed)
        out[m] = (r.value, r.lower, r.upper)
    s = sliced_w1(x, y, n_projections=16, a=a, b=b, seed=seed)
    out["sliced_w1"] = (s.value, s.stderr, s.value)
    return out


def _assert_scaled(got, base, s, rel=1e-12, abs=0):
    """``got = s·base`` to ``rel`` (relative to the largest number of each method: a sliced
    W1's standard error is pure round-off in d = 1)."""
    for name, vals in base.items():
        want = tuple(s * v for v in vals)
        assert got[name] == pytest.approx(want, rel=rel, abs=rel * max(want)), name


@pytest.mark.parametrize("method", ["exact", "exact-lazy", "bracket", "auto"])
def test_w1_diracs_at_1e160_do_not_overflow(method):
    # the audit's reproducer: it returned inf (squared costs 1e320 overflow)
    r = w1(np.array([[1e160, 0.0]]), np.array([[0.0, 1e160]]), method)
    assert r.value == pytest.approx(math.sqrt(2.0) * 1e160, rel=1e-15, abs=0)
    assert r.lower <= r.value <= r.upper and math.isfinite(r.upper)
    p = w1(np.array([[1e160, 0.0]]), np.array([[0.0, 1e160]]), "product-l1")
    assert p.value == pytest.approx(2e160, rel=1e-15, abs=0)


@pytest.mark.parametrize("n", [2, 3, 5, 10])
@pytest.mark.parametrize("s", [1e155, 1e170, 1e200])
def test_w1_few_atoms_near_1e155_to_1e200_converge(n, s):
    # these raised NotConverged("... Check that a and b are in the simplex"), blaming the weights
    rng = np.random.default_rng(n)
    x, y = rng.random((n, 3)), rng.random((n, 3)) + 0.5
    for method in ("exact", "exact-lazy", "auto"):
        assert w1(s * x, s * y, method).value == pytest.approx(s * w1(x, y, method).value, rel=1e-12, abs=0)


def test_w1_at_1e_minus_200_is_not_zero():
    # the audit's reproducer: 0.0 (squared costs 1e-400 underflow) instead of sqrt(3)·1e-200
    A = np.random.default_rng(1).integers(0, 10, size=(10, 3)).astype(float)
    for method in ("exact", "exact-lazy", "bracket", "auto"):
        r = w1(A * 1e-200, (A + 1) * 1e-200, method)
        assert r.value == pytest.approx(math.sqrt(3.0) * 1e-200, rel=1e-12, abs=0), method
        assert r.lower <= r.value <= r.upper
    assert w1(A * 1e-200, (A + 1) * 1e-200, "product-l1", product=True).value == pytest.approx(
        3e-200, rel=1e-12, abs=0)


@pytest.mark.parametrize("s", SCALES)
@pytest.mark.parametrize("d", [1, 3])
def test_every_method_is_homogeneous_at_extreme_scales(s, d):
    rng = np.random.default_rng(10 + d)
    x, y = rng.standard_normal((6, d)), rng.standard_normal((5, d)) + 0.3
    a, b = _rand_weights(rng, 6), _rand_weights(rng, 5)
    _assert_scaled(_every_method(s * x, s * y, a, b), _every_method(x, y, a, b), s)


@pytest.mark.parametrize("s", POW2_SCALES)
@pytest.mark.parametrize("shift_bits", [0, 20, 40])
def test_every_method_is_translation_invariant_with_large_shifts(s, shift_bits):
    # dyadic atoms and shifts: s·(x + c) is exact, so the identity must hold to round-off
    rng = np.random.default_rng(shift_bits)
    x, y = rng.integers(-64, 64, (7, 3)) / 8.0, rng.integers(-64, 64, (6, 3)) / 8.0
    c = rng.integers(-(2**shift_bits), 2**shift_bits + 1, 3).astype(float)
    a, b = _rand_weights(rng, 7), _rand_weights(rng, 6)
    _assert_scaled(_every_method(s * (x + c), s * (y + c), a, b), _every_method(x, y, a, b), s)


@given(st.integers(1, 3), st.integers(1, 6), st.integers(1, 6), st.integers(-1000, 960),
       st.integers(0, 40), st.integers(0, 10_000))
def test_w1_homogeneity_and_translation_property(d, n, m, k, shift_bits, seed):
    rng = np.random.default_rng(seed)
    x, y = rng.integers(-64, 64, (n, d)) / 8.0, rng.integers(-64, 64, (m, d)) / 8.0
    c = rng.integers(-(2**shift_bits), 2**shift_bits + 1, d).astype(float)
    a, b = _rand_weights(rng, n), _rand_weights(rng, m)
    s = math.ldexp(1.0, k)
    _assert_scaled(_every_method(s * (x + c), s * (y + c), a, b, seed), _every_method(x, y, a, b, seed), s)


@pytest.mark.parametrize("p, q", [
    ([1e300, -1e300], [-1e300, 1e300]),
    ([1e200, 1e-200], [-1e200, 0.0]),
    ([3e-300, 0.0], [0.0, 4e-300]),
    ([7 * 5e-324, 0.0, 0.0], [0.0, 0.0, 0.0]),          # subnormal coordinates
    ([1e16 + 2.0, 1e16], [1e16, 1e16 + 4.0]),           # a small distance far from the origin
])
def test_w1_of_two_diracs_is_their_distance(p, q):
    ref = math.dist(p, q)
    for method in ("exact", "exact-lazy", "bracket", "auto"):
        r = w1(Dirac(p), Dirac(q), method)
        assert r.value == pytest.approx(ref, rel=1e-14, abs=0), method
    assert w1(Dirac(p), Dirac(q), "product-l1").value == pytest.approx(
        sum(abs(u - v) for u, v in zip(p, q)), rel=1e-14, abs=0)


@pytest.mark.parametrize("s", SCALES)
def test_closed_forms_of_continuous_laws_at_extreme_scales(s):
    # uniform shift: W1(U(c, c + s), U(c + t, c + t + s)) = t; midpoint quantizer: s/(4N)
    c, t = 3.0 * s, 0.25 * s
    assert w1(Uniform(c, c + s), Uniform(c + t, c + t + s)).value == pytest.approx(t, rel=1e-12, abs=0)
    N = 8
    q = s * (2.0 * np.arange(1, N + 1) - 1.0) / (2 * N)
    assert w1(Uniform(0.0, s), q).value == pytest.approx(s / (4 * N), rel=1e-12, abs=0)
    x = np.array([0.0, 1.0, 5.0]) * s
    assert w1(x, x + t).value == pytest.approx(t, rel=1e-12, abs=0)
    # a product of uniforms translated by (t, t): W1 = sqrt(2)·t (the bracket's bounds meet),
    # l1 cost 2t; at 1e160 the squared marginal W2s overflowed and "exact" W1 was 2t
    P = TensorProduct([Uniform(c, c + s), Uniform(-c, -c + 2 * s)])
    Q = TensorProduct([Uniform(c + t, c + t + s), Uniform(-c + t, -c + t + 2 * s)])
    r = w1(P, Q, "bracket")
    assert r.method == "bracket" and r.exact
    assert r.value == pytest.approx(math.sqrt(2.0) * t, rel=1e-12, abs=0)
    assert w1(P, Q, "product-l1").value == pytest.approx(2 * t, rel=1e-12, abs=0)


def test_common_frame_does_not_round_the_atoms():
    # a detail of 1e-20 next to an atom at 1e10 survives (the box touches 0: no shift), and so
    # does a unit detail at 1e16 (the box is far from 0: shifted by its centre, exactly)
    for off in (0.0, 1e16):
        x = np.array([[off, 0.0], [off + 1e10, 0.0]])
        y = np.array([[off + (1e-20 if off == 0 else 2.0), 0.0], [off + 1e10, 0.0]])
        want = 0.5e-20 if off == 0 else 1.0
        for method in ("exact", "exact-lazy", "bracket", "product-l1", "auto"):
            assert w1(x, y, method, product=True).value == pytest.approx(want, rel=1e-12, abs=0), method


def test_w1_above_the_float_range_is_an_error_not_inf():
    r = w1(np.array([[-8e307, 0.0]]), np.array([[8e307, 0.0]]))
    assert r.value == pytest.approx(1.6e308, rel=1e-15, abs=0)
    assert w1(np.array([-8e307]), np.array([8e307])).value == pytest.approx(1.6e308, rel=1e-15, abs=0)
    with pytest.raises(InvalidInput, match="exceeds the largest float64"):
        w1(np.array([[-1e308, -1e308]]), np.array([[1e308, 1e308]]))
    with pytest.raises(InvalidInput, match="exceeds the largest float64"):
        w1(np.array([-1e308]), np.array([1e308]), "exact-1d")


def test_pot_wrappers_refuse_costs_that_would_overflow():
    # kinred.distance.w1 never hands POT such coordinates; its private wrappers refuse them
    # instead of letting POT report an "infeasible" problem that blames the weights
    from kinred.distance._pot import emd_dense, emd_lazy

    x, y, w = np.array([[1e160, 0.0]]), np.array([[0.0, 1e160]]), np.ones(1)
    for f in (emd_dense, emd_lazy):
        with pytest.raises(InvalidInput, match="overflow"):
            f(x, w, y, w)


# --------------------------------------------------------------------------- quantizations as inputs
def test_w1_accepts_quantizations():
    """Issue 18: w1(q, qref) on quantize() results raised "mu must be a numeric array"."""
    from kinred.measures import Mixture
    from kinred.quantize import quantize

    mu = TensorProduct([Uniform(0, 1), Uniform(0, 0.5), Uniform(0, 0.25)])
    q, qref = quantize(mu, eps=0.1), quantize(mu, eps=0.05)
    r = w1(q, qref)                               # two tensor grids, small: the exact LP
    assert r.exact and r.method == "exact" and r.n_atoms == (q.n_atoms, qref.n_atoms)
    twin = w1(q.materialize(), qref.materialize(), "exact").value
    assert r.value == pytest.approx(twin, rel=1e-12)
    # the product structure is kept: the l1 W1 to the law is the sum of exact marginal errors
    assert w1(q, mu, "product-l1").value == pytest.approx(q.error, rel=1e-12)
    # 1-D: the midpoint quantizer of U(0, 1) with N atoms is at W1 = 1/(4N)
    assert w1(quantize(Uniform(0, 1), atoms=8), Uniform(0, 1)).value == pytest.approx(1 / 32, rel=1e-12)
    # mixtures (and push-forwards) are materialized: W1 to their own atoms is 0
    mix = Mixture([TensorProduct([Uniform(0, 1), Uniform(0, 0.1)]),
                   TensorProduct([Uniform(0, 0.1), Uniform(0, 1)])], [0.3, 0.7])
    qm = quantize(mix, eps=0.1)
    assert w1(qm, qm.materialize()).value == pytest.approx(0.0, abs=1e-15)
    assert sliced_w1(qm, qm.materialize(), n_projections=8, seed=0).value == pytest.approx(0.0, abs=1e-15)
    with pytest.raises(InvalidInput, match="a must be None when mu is a kinred measure or quantization"):
        w1(q, qref, a=np.ones(q.n_atoms) / q.n_atoms)


def test_w1_on_huge_tensor_grids_never_enumerates_them():
    from kinred.quantize import quantize

    mu = TensorProduct([Uniform(0, 0.9**j) for j in range(40)])
    q, q2 = quantize(mu, eps=0.5), quantize(mu, eps=0.3)
    assert q.n_atoms > 10**25
    assert w1(q, mu, "product-l1").value == pytest.approx(q.error, rel=1e-12)
    with pytest.raises(TooLarge, match=r"mu has 3\.\d\de\+28 atoms.*tensor grid.*method='bracket'"
                                       r".*method='product-l1'"):
        w1(q, q2)


def test_w1_refuses_to_materialize_a_huge_mixture_quantization(monkeypatch):
    from kinred.distance import _inputs
    from kinred.measures import Mixture
    from kinred.quantize import quantize

    mix = Mixture([TensorProduct([Uniform(0, 1), Uniform(0, 1)])] * 2, [0.5, 0.5])
    qm = quantize(mix, eps=0.05)
    monkeypatch.setattr(_inputs, "MAX_QUANTIZATION_ATOMS", qm.n_atoms - 1)
    with pytest.raises(TooLarge, match=rf"nu: the quantization has {qm.n_atoms} atoms"):
        w1(np.zeros((1, 2)), qm)


def test_w1_uses_the_stored_atoms_of_atomic_and_1d_quantizations(monkeypatch):
    from kinred.distance import _inputs
    from kinred.quantize import quantize

    monkeypatch.setattr(_inputs, "MAX_QUANTIZATION_ATOMS", 1)   # nothing is materialized
    x = np.random.default_rng(0).random((30, 2))
    qa = quantize(Atomic(x), eps=0.1)                             # AtomicQuantization
    assert w1(qa, x + [0.3, 0.4]).value == pytest.approx(0.5, rel=1e-12)
    q1 = quantize(Uniform(0, 1), atoms=8)                          # Quantization1D
    assert w1(q1, Uniform(0, 1)).value == pytest.approx(1 / 32, rel=1e-12)
