"""Quantization: closed forms, the lemmas' bounds against independent W1 values, budgets
against brute force and the paper's recipe, streaming and refusal, sizes and memory limits."""

import importlib
import math
import re
import time
import tracemalloc
from fractions import Fraction
from pathlib import Path

import numpy as np
import ot
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, stats

from kinred.errors import InvalidInput, TooLarge
from kinred.measures import (
    Atomic,
    Dirac,
    Empirical1D,
    Mixture,
    TensorProduct,
    Uniform,
    Univariate,
    load_measure,
)
from kinred.projection import jl_matrix
from kinred.quantize import DEFAULT_MAX_BYTES, budget, paper_recipe, preflight, quantize, quantize_1d
from kinred.quantize._size import fmt_bytes, fmt_count, parse_bytes


# ---------------------------------------------------------------------------------- 1-D
@pytest.mark.parametrize("n", [1, 2, 3, 7, 50, 400])
@pytest.mark.parametrize("a,b", [(0.0, 1.0), (-3.0, 2.5), (100.0, 100.25)])
def test_uniform_closed_forms(n, a, b):
    sigma = b - a
    qp = quantize_1d(Uniform(a, b), n, rule="paper")
    qm = quantize_1d(Uniform(a, b), n, rule="midpoint")
    assert qp.points[0] == a  # x0 = a, eq. (4.20)
    assert math.isclose(qp.error, sigma / (2 * n), rel_tol=1e-9)
    assert math.isclose(qm.error, sigma / (4 * n), rel_tol=1e-9)
    assert qp.bound == pytest.approx(sigma / n) and qm.bound == pytest.approx(sigma / (2 * n))
    np.testing.assert_allclose(qm.points, a + sigma * (2 * np.arange(1, n + 1) - 1) / (2 * n))


def _w1_cdf_quad(mu, pts):
    """Independent W1 in x-space: ∫ |F(x) − G(x)| dx with G the step CDF of equal-weight atoms."""
    a, b = mu.support
    n = pts.size
    # breakpoints: the atoms (jumps of G) and where F crosses the levels k/n (kinks of |F − G|;
    # located with ppf, which only helps quad and cannot bias the integral)
    br = np.unique(np.concatenate([[a, b], pts, mu.ppf(np.arange(1, n) / n)]))
    total = 0.0
    for lo, hi in zip(br[:-1], br[1:]):
        G = np.searchsorted(pts, 0.5 * (lo + hi), side="right") / n
        total += integrate.quad(lambda x: abs(float(mu.cdf(x)) - G), lo, hi,
                                epsabs=1e-13, epsrel=1e-11, limit=200)[0]
    return total


@pytest.mark.parametrize("mu", [
    Univariate(stats.beta(2, 3)),
    Univariate(stats.beta(0.5, 0.7)),
    Univariate(stats.norm(0.3, 0.5), support=(-1.0, 1.0)),
    Univariate(stats.expon(scale=0.4), support=(0.0, 2.0)),
])
@pytest.mark.parametrize("rule", ["paper", "midpoint"])
def test_exact_1d_error_matches_cdf_integral(mu, rule):
    q = quantize_1d(mu, 9, rule=rule)
    assert q.error == pytest.approx(_w1_cdf_quad(mu, q.points), rel=1e-7, abs=1e-10)


@given(st.floats(0.3, 8.0), st.floats(0.3, 8.0), st.integers(1, 60), st.sampled_from(["paper", "midpoint"]))
def test_1d_error_below_bound_beta(a, b, n, rule):
    q = quantize_1d(Univariate(stats.beta(a, b)), n, rule=rule)
    assert 0.0 <= q.error <= q.bound * (1 + 1e-9)
    assert q.error_tol < 1e-8


@settings(max_examples=15)
@given(st.floats(-3.0, 2.0), st.floats(0.1, 4.0), st.floats(0.2, 3.0), st.integers(1, 40))
def test_midpoint_beats_paper_and_both_below_bound_truncnormal(lo, width, scale, n):
    mu = Univariate(stats.norm(0.0, scale), support=(lo, lo + width))
    qp = quantize_1d(mu, n, rule="paper")
    qm = quantize_1d(mu, n, rule="midpoint")
    assert qp.error <= qp.bound * (1 + 1e-9)
    assert qm.error <= qm.bound * (1 + 1e-9)
    # medians of the quantile cells are the W1-optimal equal-weight atoms
    assert qm.error <= qp.error + 1e-12


@given(st.lists(st.floats(-5, 5), min_size=1, max_size=30), st.integers(1, 12))
def test_empirical_exact_error_against_pot(values, n):
    mu = Empirical1D(values)
    q = quantize_1d(mu, n)
    want = ot.wasserstein_1d(np.asarray(values, float), q.points, p=1)
    assert q.error == pytest.approx(float(want), abs=1e-10)
    assert q.error <= q.bound + 1e-12


# ---------------------------------------------------------------------------------- budgets
def _brute_eps(s, eps):
    P0 = math.prod(max(1, math.ceil(len(s) * x / eps)) for x in s)
    best = None
    ranges = [range(1, P0 + 1) if x > 0 else range(1, 2) for x in s]

    def rec(j, prod, tot):
        nonlocal best
        if j == len(s):
            if tot <= eps * (1 + 1e-12) and (best is None or prod < best):
                best = prod
            return
        for n in ranges[j]:
            if prod * n > P0 or (best is not None and prod * n >= best):
                break
            rec(j + 1, prod * n, tot + s[j] / n)

    rec(0, 1, 0.0)
    return best


def _brute_atoms(s, P):
    best = math.inf

    def rec(j, prod, tot):
        nonlocal best
        if j == len(s):
            best = min(best, tot)
            return
        n = 1
        while prod * n <= P:
            rec(j + 1, prod * n, tot + s[j] / n)
            n += 1

    rec(0, 1, 0.0)
    return best


widths_small = st.lists(st.one_of(st.just(0.0), st.floats(0.01, 2.0)), min_size=1, max_size=4)


@given(widths_small, st.floats(0.05, 1.0), st.sampled_from(["paper", "midpoint"]))
def test_budget_eps_is_optimal_vs_brute_force(w, eps, rule):
    c = {"paper": 1.0, "midpoint": 0.5}[rule]
    b = budget(w, eps=eps, rule=rule)
    s = [c * x for x in w]
    assert b.bound <= eps * (1 + 1e-9)
    assert sum(x / n for x, n in zip(s, b.counts)) == pytest.approx(b.bound)
    if math.prod(max(1, math.ceil(len(s) * x / eps)) for x in s) <= 3000:
        assert b.optimal
        assert b.n_atoms == _brute_eps(s, eps)
    assert b.lower_bound <= b.n_atoms * (1 + 1e-9)
    assert all(n == 1 for x, n in zip(w, b.counts) if x == 0)  # σ = 0 costs one atom


@given(widths_small, st.integers(1, 300), st.sampled_from(["paper", "midpoint"]))
def test_budget_atoms_is_optimal_vs_brute_force(w, P, rule):
    c = {"paper": 1.0, "midpoint": 0.5}[rule]
    b = budget(w, atoms=P, rule=rule)
    assert b.n_atoms <= P and b.optimal
    assert b.bound == pytest.approx(_brute_atoms([c * x for x in w], P), rel=1e-12, abs=1e-15)
    assert b.lower_bound <= b.bound * (1 + 1e-9)


@given(st.floats(0.3, 0.95), st.integers(1, 80), st.floats(0.005, 2.0), st.sampled_from(["paper", "midpoint"]))
def test_budget_beats_or_equals_paper_recipe(r, d, eps, rule):
    w = r ** np.arange(d)
    b = budget(w, eps=eps, rule=rule, node_limit=300)
    rec = paper_recipe(w, eps, rule=rule)
    assert b.bound <= eps * (1 + 1e-9)
    assert rec.bound <= eps * (1 + 1e-9)  # the recipe itself meets eq. (4.22)
    assert b.n_atoms <= rec.n_atoms
    assert b.lower_bound <= b.n_atoms * (1 + 1e-9)


def test_paper_recipe_by_hand():
    # σ = (1, 0.5, 0.25, 0.125), paper rule, ε = 0.5: tail beyond k̄ = 2 is 0.375 > 0.25,
    # beyond k̄ = 3 is 0.125 ≤ 0.25 → k̄ = 3; 𝒩 = ⌈1.75 / 0.25⌉ = 7; N = 343
    r = paper_recipe([0.125, 1.0, 0.25, 0.5], 0.5, rule="paper")
    assert (r.k_bar, r.n_common, r.n_atoms) == (3, 7, 343)
    assert r.bound == pytest.approx(1.75 / 7 + 0.125)


def test_budget_validation():
    with pytest.raises(InvalidInput, match="exactly one"):
        budget([1.0], eps=0.1, atoms=3)
    with pytest.raises(InvalidInput, match="exactly one"):
        budget([1.0])
    with pytest.raises(InvalidInput, match="widths must be >= 0"):
        budget([1.0, -0.1], eps=0.1)
    with pytest.raises(InvalidInput, match="eps must be > 0"):
        budget([1.0], eps=0.0)
    with pytest.raises(InvalidInput, match="rule"):
        budget([1.0], eps=0.1, rule="gauss")


# ---------------------------------------------------------------------------------- lemmas
def _fine(mu, n):
    """A fine tensor quantization (its own bound is known) for reference W1 values."""
    return quantize(mu, atoms=n)


factor = st.one_of(
    st.builds(lambda lo, w: Uniform(lo, lo + w), st.floats(-1, 1), st.floats(0.05, 1.5)),
    st.builds(lambda a, b: Univariate(stats.beta(a, b)), st.floats(0.5, 5), st.floats(0.5, 5)),
    st.builds(lambda x: Dirac(x), st.floats(-1, 1)),
)


@given(st.lists(factor, min_size=1, max_size=3), st.integers(2, 40), st.sampled_from(["paper", "midpoint"]))
def test_tensor_bound_holds_against_independent_w1(factors, atoms, rule):
    mu = TensorProduct(factors)
    q = quantize(mu, atoms=atoms, rule=rule)
    assert q.n_atoms <= atoms
    A = q.materialize()
    # product-ℓ1 W1 = Σ marginal W1s, each computed by POT from the atoms' marginals against a
    # fine 1-D quantization of the factor (error ≤ σ/4000)
    l1 = 0.0
    slack = 0.0
    for j, f in enumerate(factors):
        if isinstance(f, Dirac):
            ref, wref, e = np.array([f.x[0]]), np.array([1.0]), 0.0
        else:
            fq = quantize_1d(f, 2000)
            ref, wref, e = fq.points, fq.weights, fq.bound
        l1 += float(ot.wasserstein_1d(A.points[:, j], ref, A.weights, wref, p=1))
        slack += e
    assert l1 == pytest.approx(q.error, abs=slack + 1e-9)  # the exact product-ℓ1 value
    assert q.error <= q.bound * (1 + 1e-9)  # Lemma 4.1
    # Euclidean W1 (exact LP) against a fine grid: ≤ product-ℓ1 ≤ bound (up to the fine error)
    fine = _fine(mu, 3000)
    F = fine.materialize()
    M = ot.dist(A.points, F.points, metric="euclidean")
    w1 = float(ot.emd2(A.weights, F.weights, M, numItermax=10**7))
    assert w1 <= q.error + fine.bound + 1e-9


@given(st.lists(st.tuples(st.floats(-1, 1), st.floats(0.05, 1.0), st.floats(0.05, 1.0)), min_size=1, max_size=3),
       st.lists(st.floats(0.05, 1.0), min_size=3, max_size=3), st.floats(0.1, 0.5))
def test_mixture_bound_holds_against_exact_emd(boxes, raw_w, eps):
    comps = [TensorProduct([Uniform(x, x + wx), Univariate(stats.beta(2, 3), support=None)])
             if k % 2 else TensorProduct([Uniform(x, x + wx), Uniform(0, wy)])
             for k, (x, wx, wy) in enumerate(boxes)]
    w = np.asarray(raw_w[: len(comps)])
    w = w / w.sum()
    mu = Mixture(comps, w)
    q = quantize(mu, eps=eps)
    assert q.bound <= eps * (1 + 1e-9)
    assert q.error <= q.bound * (1 + 1e-9)
    A = q.materialize()
    assert A.weights.min() > 0 and A.weights.sum() == pytest.approx(1.0)
    if A.n_atoms > 200:
        return
    fine = quantize(mu, eps=0.02)
    F = fine.materialize()
    w1 = float(ot.emd2(A.weights, F.weights, ot.dist(A.points, F.points, metric="euclidean"),
                       numItermax=10**7))
    assert w1 <= q.bound + fine.bound + 1e-9  # Lemma 4.2 with unequal weights and counts


@given(st.integers(1, 3), st.integers(0, 2**31), st.floats(0.1, 0.6))
def test_push_bound_scales_with_norm(k, seed, eps):
    rng = np.random.default_rng(seed)
    mu = TensorProduct([Uniform(0, 1), Univariate(stats.beta(2, 2)), Uniform(-0.2, 0.2)])
    M = rng.standard_normal((k, 3))
    q = quantize(mu.push(M), eps=eps)
    norm = np.linalg.norm(M, 2)
    assert q.bound <= eps * (1 + 1e-9)
    assert q.bound == pytest.approx(norm * q.base.bound)
    A = q.materialize()
    np.testing.assert_allclose(A.points, q.base.materialize().points @ M.T, atol=1e-12)
    if A.n_atoms > 300:
        return
    F = quantize(mu, atoms=2000)
    Fp = F.materialize().push(M)
    w1 = float(ot.emd2(A.weights, Fp.weights, ot.dist(A.points, Fp.points, metric="euclidean"),
                       numItermax=10**7))
    assert w1 <= q.bound + norm * F.bound + 1e-9


# ---------------------------------------------------------------------------------- objects
def test_streaming_reproduces_materialize():
    mu = Mixture([
        TensorProduct([Uniform(0, 1), Dirac(2.0), Univariate(stats.beta(2, 2))]),
        TensorProduct([Uniform(0, 0.1), Uniform(0, 3), Uniform(1, 2)]),
    ], [0.4, 0.6])
    q = quantize(mu, atoms=500)
    A = q.materialize()
    for size in (1, 7, 64, 10_000):
        chunks = list(q.iter_chunks(size))
        assert all(len(p) <= size for p, _ in chunks)
        np.testing.assert_array_equal(np.concatenate([p for p, _ in chunks]), A.points)
        np.testing.assert_allclose(np.concatenate([w for _, w in chunks]), A.weights, rtol=1e-12)
    # the grid is C-ordered: atom index → mixed-radix digits (last coordinate fastest)
    tq = q.components[1]
    i = 37
    digits = np.unravel_index(i, tq.counts)
    want = [f.points[d] for f, d in zip(tq.factors, digits)]
    np.testing.assert_array_equal(next(tq.iter_chunks(1, start=i))[0][0], want)


def test_huge_count_known_without_materializing():
    mu = TensorProduct([Uniform(0, 0.9**j) for j in range(120)])
    q = quantize(mu, eps=0.02)
    assert isinstance(q.n_atoms, int) and q.n_atoms == math.prod(q.counts) and q.n_atoms > 10**40
    assert q.bound <= 0.02 * (1 + 1e-9)
    with pytest.raises(TooLarge, match=r"atoms in dimension 120.*max_atoms=1000.*iter_chunks"):
        q.materialize(max_atoms=1000)
    # streaming far into the grid: the first coordinates (slowest digits) sit at their first atom
    start = 10**15
    P, W = next(q.iter_chunks(3, start=start))
    assert P.shape == (3, 120)
    digits = []
    rest = start
    for n in reversed(q.counts):
        digits.append(rest % n)
        rest //= n
    digits = digits[::-1]
    np.testing.assert_array_equal(P[0], [f.points[d] for f, d in zip(q.factors, digits)])
    assert W[0] == pytest.approx(1.0 / q.n_atoms, rel=1e-9)


def test_atomic_and_dirac_are_exact():
    X = np.array([[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]])
    q = quantize(Atomic(X, [0.2, 0.3, 0.5]), eps=0.01)
    assert q.bound == 0 and q.error == 0 and q.n_atoms == 3
    np.testing.assert_array_equal(q.materialize().points, X)
    assert quantize(Dirac([1.0, 2.0]), atoms=5).n_atoms == 1
    with pytest.raises(InvalidInput, match="fewer than"):
        quantize(Atomic(X), atoms=2)
    q1 = quantize(Empirical1D(np.arange(10.0)), atoms=2)  # 1-D atomic re-quantized
    np.testing.assert_array_equal(q1.points, [2.0, 7.0])


def test_eps_gives_fewest_atoms_in_1d():
    mu = Univariate(stats.beta(2, 2))
    q = quantize(mu, eps=0.01)
    assert q.n_atoms == 50 and q.bound <= 0.01  # σ/(2N) ≤ 0.01 ⇔ N ≥ 50
    assert quantize(mu, eps=0.01, rule="paper").n_atoms == 100


def test_quantize_validation():
    with pytest.raises(InvalidInput, match="exactly one"):
        quantize(Uniform(), eps=0.1, atoms=2)
    with pytest.raises(InvalidInput, match="Measure"):
        quantize(np.zeros(3), eps=0.1)
    with pytest.raises(InvalidInput, match="atoms must be >= 1"):
        quantize(Uniform(), atoms=0)
    with pytest.raises(InvalidInput, match="too small for this mixture"):
        quantize(Mixture([Uniform(), Uniform(1, 2), Uniform(3, 4)]), atoms=2)
    with pytest.raises(InvalidInput, match="1-D"):
        quantize_1d(TensorProduct([Uniform(), Uniform()]), 3)


def test_isotropic_curse_beyond_float_range():
    """200 unit widths at eps = 1 need 100 atoms per coordinate: N = 100**200 = 1e400 (the curse).

    The count is exact, the relaxation's lower bound overflows to inf instead of raising, and
    the repr stays short.
    """
    from kinred.measures import TensorProduct, Uniform
    from kinred.quantize import budget, quantize

    b = budget([1.0] * 200, eps=1.0)
    assert b.counts == (100,) * 200
    assert b.n_atoms == 100**200 and b.optimal
    assert b.recipe.n_atoms > b.n_atoms
    q = quantize(TensorProduct([Uniform(0.0, 1.0)] * 200), eps=1.0)
    assert q.n_atoms == 100**200
    assert "n_atoms=1.000e+400" in repr(q) and len(repr(q)) < 200


def test_budget_repr_is_short_for_d_200_and_huge_counts():
    """Issue 18: the repr printed all 200 widths (about 4600 characters)."""
    b = budget(0.99 ** np.arange(200), eps=0.01, node_limit=200)
    assert b.n_atoms > 10**300                            # beyond the float range
    r = repr(b)
    assert len(r) < 250 and r.count("\n") == 0
    assert r.startswith("Budget(d=200, eps=0.01, rule='midpoint', n_atoms=")
    assert f"k_bar={b.k_bar}" in r and "…" in r
    assert f"counts=({b.counts[0]}, {b.counts[1]}, {b.counts[2]}, {b.counts[3]}, …, " \
           f"{b.counts[-2]}, {b.counts[-1]})" in r
    a = budget(np.ones(200), atoms=10**80)
    assert "atoms=1.000e+80" in repr(a) and f"n_atoms={float(a.n_atoms):.3e}" in repr(a)
    assert len(repr(a)) < 250
    small = budget([1.0, 0.5, 0.25, 0.0], eps=0.25)       # d <= 8: every count and width
    assert repr(small) == ("Budget(d=4, eps=0.25, rule='midpoint', n_atoms=30, bound=0.245833, "
                           "k_bar=3, counts=(5, 3, 2, 1), widths=(1, 0.5, 0.25, 0), optimal=True)")


# ---------------------------------------------------------------------------------- extreme budgets
# Issue 14: budgets are integers of any size and must stay cheap however many atoms they count.
def test_counts_beyond_the_int_string_limit_print():
    """Counts past 4300 digits (Python's int→str limit) are formatted from logarithms."""
    b = budget([1.0] * 200, eps=1e-30)  # 1e32 atoms per coordinate: 6401 digits
    assert len(set(b.counts)) == 1 and b.counts[0] == pytest.approx(1e32, rel=1e-11)
    assert len(str(b.counts[0])) == 32 and "n_atoms=1.000e+6400" in repr(b)
    assert fmt_count(10**5000) == "1.000e+5000" and fmt_count(10**1000 - 1) == "1.000e+1000"
    assert fmt_count(999_999_999_999) == "999999999999" and fmt_count(50**18) == "3.815e+30"
    assert fmt_bytes(3 * 2**30) == "3 GiB" and fmt_bytes(10**400) == "≈1.000e+400 bytes"


@pytest.mark.parametrize("widths", [list(0.8 ** np.arange(200)), [1.0] * 200, [1.0, 1e-3, 1e-9]])
@pytest.mark.parametrize("eps", [1e-30, 1e-300])
def test_budget_at_tiny_eps_is_fast_and_feasible(widths, eps):
    """Budgets are numbers: they must stay cheap however many atoms they count (the local
    search once stepped N_j by one, forever at N_j ~ 1e30)."""
    t0 = time.perf_counter()
    b = budget(widths, eps=eps)
    assert time.perf_counter() - t0 < 60  # ~1 s on a loaded 2-core machine
    s = [Fraction(0.5 * w) for w in widths]
    # feasible in exact arithmetic, and every N_j at least its own share c σ_j / eps
    assert sum(si / n for si, n in zip(s, b.counts)) <= Fraction(eps) * Fraction(1 + 1e-9)
    assert all(n >= si / (Fraction(eps) * Fraction(1 + 1e-9)) for si, n in zip(s, b.counts))
    assert b.n_atoms == math.prod(b.counts) <= b.recipe.n_atoms
    if len(set(widths)) == 1:  # isotropic: between the continuous optimum and its rounding
        d = len(widths)
        cont = (d * s[0] / (Fraction(eps) * Fraction(1 + 1e-9))) ** d
        assert cont <= b.n_atoms <= math.ceil(d * s[0] / Fraction(eps)) ** d


def test_paper_recipe_and_budget_at_subnormal_eps():
    r = paper_recipe([1.0, 1.0, 1.0], 5e-324)  # 2Σcσ/ε overflows a float
    n = math.ceil(Fraction(3 * 0.5) / (Fraction(5e-324) / 2 * Fraction(1 + 1e-12)))
    assert (r.k_bar, r.n_common, r.n_atoms) == (3, n, n**3)
    with pytest.raises(InvalidInput, match=r"eps=5e-324 is too small.*eps must be >= 4\.5e-305"):
        budget([1.0, 1.0, 1.0], eps=5e-324)


def test_budget_with_an_astronomical_atom_budget():
    b = budget([1.0, 0.5, 0.25], atoms=10**400)
    assert b.n_atoms <= 10**400 and b.optimal
    # continuous optimum: N_j = s_j / ν with ∏ N_j = P, bound 3ν = 3 (∏ s / P)^(1/3)
    assert b.bound == pytest.approx(3 * (0.5 * 0.25 * 0.125) ** (1 / 3) * 10 ** (-400 / 3), rel=1e-9)
    with pytest.raises(InvalidInput, match="too large for 3 coordinate"):
        budget([1.0, 0.5, 0.25], atoms=10**5000)


# ---------------------------------------------------------------------------------- sizes
# Issue 14: every stage prices what it will allocate from exact integers before allocating,
# and past one limit (max_bytes=, else KINRED_MAX_BYTES, else 2 GiB) raises TooLarge naming
# the atoms, the bytes, the limit and what would fit.
_plan_mod = importlib.import_module("kinred.quantize._plan")
_planning_mod = importlib.import_module("kinred.quantize._planning")   # where budgets are asked
_error_mod = importlib.import_module("kinred.quantize._error1d")
DECAYING = Path(__file__).resolve().parents[1] / "examples" / "measures" / "decaying-200.toml"
MU200 = TensorProduct([Uniform(0.0, 1.0)] * 200)
WORKSPACE = 17 * 2**20  # 1 MiB of Python objects + one 16 MiB chunk of quantile temporaries


@pytest.fixture
def default_limit(monkeypatch):
    monkeypatch.delenv("KINRED_MAX_BYTES", raising=False)


def _suggested_eps(message: str) -> float:
    return float(re.search(r"eps >= ([0-9.e+-]+) fits", message).group(1))


def _refuse(monkeypatch, mu, eps):
    """quantize(mu, eps) → (message, traced peak bytes, the eps of every budget computed)."""
    seen = []
    real = _planning_mod.budget
    monkeypatch.setattr(_planning_mod, "budget", lambda w, **kw: seen.append(kw["eps"]) or real(w, **kw))
    tracemalloc.start()
    try:
        with pytest.raises(TooLarge) as exc:
            quantize(mu, eps=eps)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return str(exc.value), peak, seen


def test_tiny_eps_on_200_unit_widths_refused_before_any_array(default_limit, monkeypatch):
    """Defect 3: eps = 1e-12 asked numpy for 728 TiB and escaped as a raw MemoryError."""
    msg, peak, seen = _refuse(monkeypatch, MU200, 1e-12)
    # every coordinate needs N_j ≥ c σ / eps = 5e11 points (24 bytes each) before any budget
    assert "at least 2.13 PiB" in msg and "at least 1.000e+14 per-coordinate quantile points" in msg
    assert "at least 6.223e+2339 atoms in dimension 200" in msg  # (5e11)^200
    assert "max_bytes = 2 GiB" in msg and "KINRED_MAX_BYTES" in msg
    assert min(seen) > 1e-6  # no budget at the refused eps, only while searching what fits
    assert peak < 50 * 2**20
    e = _suggested_eps(msg)  # the smallest eps that fits, to a few percent
    assert preflight(MU200, eps=e).quantize_bytes <= DEFAULT_MAX_BYTES
    assert preflight(MU200, eps=e / 1.05).quantize_bytes > DEFAULT_MAX_BYTES


@pytest.mark.parametrize("eps", [1e-6, 1e-300])
def test_decaying_200_refused_without_allocating(default_limit, monkeypatch, eps):
    """Defect 4: eps = 1e-6 grew to 18.6 GB (every quantile array built up front); 1e-300 ran
    for minutes (a local search looping once per atom)."""
    mu = load_measure(DECAYING)
    t0 = time.perf_counter()
    msg, peak, seen = _refuse(monkeypatch, mu, eps)
    elapsed = time.perf_counter() - t0
    assert peak < 50 * 2**20 and elapsed < 60  # ~1 s on a loaded 2-core machine
    e = _suggested_eps(msg)
    assert msg.count("eps >= ") == 1 and 1e-6 < e < 1e-5
    if eps == 1e-6:  # exact figures: the plan was computed, 24 bytes per quantile point
        p = preflight(mu, eps=eps)
        assert p.quantize_bytes == 24 * p.points + WORKSPACE > DEFAULT_MAX_BYTES
        assert f"{fmt_bytes(p.quantize_bytes)} before" in msg and f" {p.points} per-coordinate" in msg
        assert f"for {fmt_count(p.atoms)} atoms in dimension 200" in msg and "at least" not in msg
    else:  # refused from the per-coordinate lower bounds alone
        assert "at least" in msg and min(seen) > 1e-7
    assert preflight(mu, eps=e).quantize_bytes <= DEFAULT_MAX_BYTES
    assert preflight(mu, eps=e / 1.05).quantize_bytes > DEFAULT_MAX_BYTES


def test_materialize_refusal_names_a_1001_digit_count(default_limit):
    """Defect 5: the TooLarge message itself raised OverflowError (int / int → float)."""
    q = quantize(MU200, eps=1e-3)  # 1e5 atoms per coordinate: 2e7 quantile points, 480 MB
    assert 10**999 < q.n_atoms <= 10**1000 and "n_atoms=1.000e+1000" in repr(q)
    with pytest.raises(TooLarge) as exc:
        q.materialize()
    msg = str(exc.value)
    # 10^1000 atoms × (9·200 + 24) bytes
    assert "≈1.824e+1003 bytes for 1.000e+1000 atoms in dimension 200" in msg
    k = int(re.search(r"at most (\d+) atoms fit", msg).group(1))
    assert k == (DEFAULT_MAX_BYTES - 2**20 - 16 * 2**20 // (128 * 204) * 128 * 204) // (9 * 200 + 24)
    e = _suggested_eps(msg)
    assert preflight(MU200, eps=e).materialize_bytes <= DEFAULT_MAX_BYTES
    assert preflight(MU200, eps=e / 1.05).materialize_bytes > DEFAULT_MAX_BYTES


# one small measure of each kind, and an atom budget or eps for it
_law = st.sampled_from([
    Uniform(-1.0, 2.0), Univariate(stats.beta(2, 3)),
    Univariate(stats.norm(0.3, 0.5), support=(-1.0, 1.0)),
    Univariate(stats.expon(scale=0.4), support=(0.0, 2.0)),
])


@st.composite
def _requests(draw):
    kind = draw(st.sampled_from(["1d", "tensor", "empirical", "mixture", "push"]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    if kind == "1d":
        return draw(_law), {"atoms": draw(st.integers(1, 30000))}
    if kind == "empirical":
        return Atomic(rng.random((draw(st.integers(2, 20000)), 1))), {"atoms": draw(st.integers(1, 5000))}
    factors = draw(st.lists(st.one_of(_law, st.just(Dirac(0.5))), min_size=1, max_size=4))
    tp = TensorProduct(factors)
    if kind == "tensor":
        return tp, {"atoms": draw(st.integers(1, 60000))}
    if kind == "mixture":
        box = TensorProduct([Uniform(0, 1)] * tp.dim)
        return Mixture([tp, box], [0.4, 0.6]), {"eps": draw(st.floats(0.01, 1.0))}
    kind, k = draw(st.sampled_from(["gaussian", "srht"])), draw(st.integers(1, 6))
    if kind == "srht":  # at most the dimension padded to a power of two
        k = min(k, 1 << (tp.dim - 1).bit_length())
    M = jl_matrix(k, tp.dim, kind=kind, seed=seed)
    return tp.push(M), {"atoms": draw(st.integers(1, 20000))}


@settings(max_examples=20, deadline=None)
@given(_requests())
def test_preflight_bytes_bound_the_traced_peaks(req):
    mu, kw = req
    p = preflight(mu, **kw)
    quantize(mu, **kw).error  # warm-up: scipy and numpy caches are not the model's business
    tracemalloc.start()
    try:
        q = quantize(mu, **kw)
        q.error  # the exact 1-D errors run in chunks within the same workspace
        assert tracemalloc.get_traced_memory()[1] <= p.quantize_bytes
        assert q.n_atoms == p.atoms and q.materialize_bytes == p.materialize_bytes
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        A = q.materialize()
        used = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    assert A.points.nbytes + A.weights.nbytes <= used <= p.materialize_bytes


@settings(max_examples=20, deadline=None)
@given(_requests())
def test_limit_just_below_the_prediction_raises_and_at_it_works(req):
    mu, kw = req
    p = preflight(mu, **kw)
    with pytest.raises(TooLarge, match="max_bytes"):
        quantize(mu, **kw, max_bytes=p.quantize_bytes - 1)
    q = quantize(mu, **kw, max_bytes=p.quantize_bytes)
    with pytest.raises(TooLarge, match="max_bytes"):
        q.materialize(max_bytes=p.materialize_bytes - 1)
    assert q.materialize(max_bytes=p.materialize_bytes).n_atoms == p.atoms


def test_model_is_tight_where_the_arrays_dominate():
    """Large enough that the proportional terms dominate the constant workspace."""
    mu = Univariate(stats.beta(2, 3))
    p = preflight(mu, atoms=3_000_000)
    tracemalloc.start()
    try:
        q = quantize_1d(mu, 3_000_000)
        peak = tracemalloc.get_traced_memory()[1]
        assert q.n_atoms == 3_000_000
    finally:
        tracemalloc.stop()
    assert p.quantize_bytes == 24 * 3_000_000 + WORKSPACE
    assert 24 * 3_000_000 <= peak <= p.quantize_bytes and peak > 0.75 * p.quantize_bytes
    grid = quantize(TensorProduct([Uniform(0, 1)] * 10), atoms=4**10)
    tracemalloc.start()
    try:
        A = grid.materialize()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert grid.n_atoms == 4**10  # points 80 MiB, weights 8 MiB: the array dominates
    assert grid.materialize_bytes == 4**10 * (9 * 10 + 24) + 2**20 + 16 * 2**20 // (128 * 14) * 128 * 14
    assert A.points.nbytes + A.weights.nbytes <= peak <= grid.materialize_bytes
    assert peak > 0.6 * grid.materialize_bytes


def test_limit_from_keyword_environment_and_default(monkeypatch):
    mu = TensorProduct([Uniform(0, 1)] * 3)
    need = preflight(mu, atoms=10**6).quantize_bytes  # 300 quantile points: the constants
    monkeypatch.setenv("KINRED_MAX_BYTES", "1M")
    with pytest.raises(TooLarge, match=r"max_bytes = 1 MiB \(keyword max_bytes=, environment variable"):
        quantize(mu, atoms=10**6)
    assert quantize(mu, atoms=10**6, max_bytes=need).n_atoms == 10**6  # the keyword wins
    assert quantize(mu, atoms=10**6, max_bytes="18MiB").n_atoms == 10**6
    monkeypatch.setenv("KINRED_MAX_BYTES", "lots")
    with pytest.raises(InvalidInput, match="environment variable KINRED_MAX_BYTES must be a byte count"):
        quantize(mu, atoms=8)
    monkeypatch.delenv("KINRED_MAX_BYTES")
    assert _plan_mod.max_bytes_limit() == DEFAULT_MAX_BYTES == 2**31
    assert parse_bytes("512M", "x") == 2**29 and parse_bytes(" 1.5 GiB ", "x") == 3 * 2**29
    with pytest.raises(InvalidInput, match="max_bytes must be >= 1"):
        quantize(mu, atoms=8, max_bytes=0)


def test_quantize_1d_and_iter_chunks_refuse_before_allocating(default_limit):
    most = (DEFAULT_MAX_BYTES - WORKSPACE) // 24  # quantile points that fit in 2 GiB
    with pytest.raises(TooLarge, match=rf"quantize_1d\(n=1\.000e\+12\).*n <= {most} fits"):
        quantize_1d(Uniform(0, 1), 10**12)
    with pytest.raises(TooLarge, match=r"quantize\(atoms=1\.000e\+12\)") as exc:
        quantize(Univariate(stats.beta(2, 2)), atoms=10**12)
    k = int(re.search(r"atoms <= (\d+) fits", str(exc.value)).group(1))
    assert 0.98 * most <= k <= most  # found by a 1 % bisection
    q = quantize(MU200, eps=1.0)
    with pytest.raises(TooLarge, match=r"iter_chunks\(chunk_size=1000000000\).*chunk_size <= \d+ fits") as exc:
        q.iter_chunks(10**9)  # refused when called, not when iterated
    k = int(re.search(r"chunk_size <= (\d+) fits", str(exc.value)).group(1))
    assert k == (DEFAULT_MAX_BYTES - 2**20) // (128 * 204)
    P, W = next(q.iter_chunks(3, start=10**15))  # a small chunk is fine
    assert P.shape == (3, 200) and W.shape == (3,)


def test_chunked_1d_quantiles_and_errors_match_closed_forms():
    n = 20_000  # crosses the quantile chunks (8192 levels) and the error chunks (512 cells)
    q = quantize_1d(Uniform(-1.0, 2.0), n)
    np.testing.assert_allclose(q.points, -1.0 + 3.0 * (2 * np.arange(n) + 1) / (2 * n), rtol=0, atol=1e-15)
    assert q.error == pytest.approx(3.0 / (4 * n), rel=1e-9)
    mu = Univariate(stats.norm(0.3, 0.5), support=(-1.0, 1.0))
    qn = quantize_1d(mu, 3000, rule="paper")
    lv = np.arange(3000) / 3000
    np.testing.assert_array_equal(qn.points, np.maximum.accumulate(mu.ppf(lv)))
    with pytest.MonkeyPatch.context() as mp:  # one chunk holding every cell: the same value
        mp.setattr(_error_mod, "ERROR_CHUNK", 10**9)
        one = _error_mod.w1_quantile(mu, qn.points)
    assert qn.error == pytest.approx(one[0], rel=1e-12) and qn.error <= qn.bound


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=1, max_size=40), st.integers(1, 30), st.integers(1, 4))
def test_empirical_error_walk_in_tiny_windows_matches_pot(values, n, window):
    mu = Empirical1D(values)
    q = quantize_1d(mu, n)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_error_mod, "LEVEL_CHUNK", window)
        got = _error_mod.w1_quantile(mu, q.points)[0]
    want = float(ot.wasserstein_1d(np.asarray(values, float), q.points, p=1))
    assert got == pytest.approx(want, abs=1e-10)


def test_empirical_error_over_many_windows_matches_pot():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(30_000)
    mu = Empirical1D(x)
    q = quantize(mu, atoms=20_000)
    assert q.error == pytest.approx(float(ot.wasserstein_1d(x, q.points, p=1)), rel=1e-9, abs=1e-12)
