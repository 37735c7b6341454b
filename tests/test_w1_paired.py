"""The certified W1 bracket of paired atoms (kinred.distance.paired_w1_bracket) and its use by
the kinetic pipeline above MAX_POT_ATOMS atoms (no linear program, no POT)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import kinred.distance._bracket as bracket_mod
import kinred.distance._w1 as w1_mod
from kinred.distance import W1Bracket, W1Result, paired_w1_bracket, w1
from kinred.distance._paired import _slice
from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.errors import InvalidInput
from kinred.kinetic import MAX_POT_ATOMS, compare, reduce, solve
from kinred.measures import Atomic
from kinred.projection import jl_matrix


@st.composite
def paired_atoms(draw):
    n = draw(st.integers(1, 12))
    d = draw(st.integers(1, 4))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, d)) * draw(st.sampled_from([1e-3, 1.0, 1e3]))
    kind = draw(st.sampled_from(["noise", "translate", "permute", "line", "equal"]))
    if kind == "noise":
        b = a + rng.normal(size=(n, d)) * draw(st.sampled_from([1e-6, 0.1, 10.0])) * np.abs(a).max()
    elif kind == "translate":
        b = a + rng.normal(size=d)
    elif kind == "permute":
        b = a[rng.permutation(n)]
    elif kind == "line":
        b = a + np.outer(rng.uniform(-1, 1, n), rng.normal(size=d))
    else:
        b = a.copy()
    w = rng.dirichlet(np.ones(n)) if draw(st.booleans()) else None
    return a, b, w


@given(paired_atoms())
def test_the_bracket_contains_the_exact_w1(case):
    a, b, w = case
    r = paired_w1_bracket(a, b, w, seed=0)
    exact = w1(a, b, "exact", a=w, b=w).value
    tol = 1e-13 * (np.abs(a).max() + np.abs(b).max())       # POT's own round-off
    assert r.lower <= exact + tol
    assert exact <= r.upper + tol
    assert isinstance(r, W1Result) and isinstance(r, W1Bracket)
    assert r.width == r.upper - r.lower >= 0
    assert r.method == "paired-bracket" and r.label == "certified bracket" and not r.exact
    assert r.lower <= r.value <= r.upper


def test_the_upper_bound_is_the_index_coupling():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    w = rng.dirichlet(np.ones(50))
    r = paired_w1_bracket(a, b, w)
    index = float(w @ np.linalg.norm(a - b, axis=1))
    assert index <= r.upper <= index * (1 + 1e-13)
    assert "index coupling" in r.upper_from and "max-sliced" in r.lower_from


@pytest.mark.parametrize("offset", [0.0, 1e6])
def test_a_translation_is_bracketed_tightly(offset):
    rng = np.random.default_rng(2)
    a = offset + rng.normal(size=(2000, 6))
    t = np.array([0.3, -0.4, 0.0, 1.2, 0.0, 0.0])
    b = a + t                                  # |t| = 1.3, up to the rounding of a + t
    r = paired_w1_bracket(a, b, seed=3)
    index = float(np.mean(np.linalg.norm(b - a, axis=1)))
    assert abs(index - 1.3) <= (1e-15 + 1e-9 * (offset > 0)) * 1.3
    assert r.lower <= index <= r.upper
    assert r.width <= 1e-9 * 1.3


def test_the_lower_bound_is_tight_when_the_differences_lie_on_one_line_in_order():
    """bᵢ = aᵢ + sᵢ u with sᵢ ≥ 0 increasing with u·aᵢ: the monotone 1-D coupling along u is
    the index coupling, so max-sliced W1 = Σ wᵢ sᵢ = W1 and the bracket closes."""
    rng = np.random.default_rng(4)
    n, d = 3000, 5
    a = rng.normal(size=(n, d))
    u = rng.normal(size=d)
    u /= np.linalg.norm(u)
    s = 0.05 + 0.02 * np.argsort(np.argsort(a @ u)) / n
    w = rng.dirichlet(np.ones(n))
    r = paired_w1_bracket(a, a + s[:, None] * u, w, n_directions=0)
    exact = float(w @ s)
    assert r.lower <= exact <= r.upper
    assert r.width <= 1e-9 * exact


def test_the_principal_direction_finds_a_hidden_direction():
    """A dilation along a direction u that is no axis (half the atoms move +0.5 u, half −0.5 u,
    order along u kept): W1 = 0.5 exactly; the axes and the mean difference see little, the
    principal direction of the difference cloud closes the bracket, the ascent improves."""
    rng = np.random.default_rng(5)
    n, d = 1500, 40
    a = rng.normal(size=(n, d))
    u = np.ones(d) / math.sqrt(d)
    s = np.where(a @ u > np.median(a @ u), 0.5, -0.5)
    b = a + s[:, None] * u
    axes = paired_w1_bracket(a, b, n_directions=0, n_principal=0, n_refine=0)
    assert axes.lower <= 0.25 and abs(axes.upper - 0.5) <= 1e-12
    full = paired_w1_bracket(a, b, n_directions=0, n_principal=1, n_refine=0)
    assert abs(full.lower - 0.5) <= 1e-9
    refined = paired_w1_bracket(a, b, n_directions=0, n_principal=0, n_refine=3)
    assert refined.lower >= 0.4 > 0.25 >= axes.lower


def test_the_ascent_direction_satisfies_the_euler_identity():
    """g of the monotone coupling: θ·g = W1(θ#μ, θ#ν) (exact 1-D W1, weights, ties)."""
    rng = np.random.default_rng(9)
    for n, d in ((1, 2), (7, 3), (60, 5)):
        A = rng.normal(size=(n, d))
        B = np.round(rng.normal(size=(n, d)), 1)
        B[: n // 2] = A[: n // 2]                               # some ties
        w = rng.dirichlet(np.ones(n))
        th = rng.normal(size=d)
        th /= np.linalg.norm(th)
        val, g = _slice(A, B, w, th, 0.0, grad=True)
        exact = w1(A @ th, B @ th, "exact-1d", a=w, b=w).value
        assert abs(th @ g - exact) <= 1e-13 and val <= exact + 1e-15
        assert val >= exact - 1e-12


def test_scaling_is_exact_and_tiny_distances_keep_their_accuracy():
    rng = np.random.default_rng(6)
    a = rng.normal(size=(400, 3))
    b = a + 1e-9 * rng.normal(size=(400, 3))
    r = paired_w1_bracket(a, b, seed=1)
    r2 = paired_w1_bracket(2.0**-300 * a, 2.0**-300 * b, seed=1)
    assert r2.lower == 2.0**-300 * r.lower and r2.upper == 2.0**-300 * r.upper
    exact = w1(a, b, "exact").value
    assert r.lower <= exact <= r.upper and r.upper <= 1.1e-8


def test_bad_input():
    a = np.zeros((4, 2))
    with pytest.raises(InvalidInput, match="same shape"):
        paired_w1_bracket(a, np.zeros((5, 2)))
    with pytest.raises(InvalidInput, match="same shape"):
        paired_w1_bracket(a, np.zeros((4, 3)))
    with pytest.raises(InvalidInput, match="b must be finite"):
        paired_w1_bracket(a, np.full((4, 2), np.nan))
    with pytest.raises(InvalidInput, match="weights must have length 4"):
        paired_w1_bracket(a, a, np.ones(3) / 3)
    with pytest.raises(InvalidInput, match="n_directions"):
        paired_w1_bracket(a, a, n_directions=-1)
    with pytest.raises(InvalidInput, match="a must have 2"):
        paired_w1_bracket(np.zeros(4), np.zeros(4))


# ----------------------------------------------------------------------- kinetic pipeline
def _kinetic(n=60, d=6, k=2):
    X0 = np.random.default_rng(7).normal(size=(n, 2 * d))
    w = np.random.default_rng(8).dirichlet(np.ones(n))
    sol = solve(Scene([Alignment(CuckerSmale(G=2.0, beta=1.0))]), Atomic(X0, w),
                t_span=(0.0, 1.0), dt=0.05, save_every=5)
    return sol, reduce(sol, M=jl_matrix(k, d, seed=3))


def test_compare_above_the_threshold_never_calls_pot_and_brackets_the_exact_w1(monkeypatch):
    sol, red = _kinetic()
    exact = compare(sol, red)                      # 60 atoms: POT, exact
    assert exact.exact.all() and exact.method == "exact"

    def no_pot(*args, **kwargs):
        raise AssertionError("POT called above max_pot_atoms")

    for mod in (w1_mod, bracket_mod):
        for name in ("emd_dense", "emd_lazy"):
            if hasattr(mod, name):
                monkeypatch.setattr(mod, name, no_pot)
    c = compare(sol, red, max_pot_atoms=59)
    assert c.method == "paired-bracket"
    assert np.all(c.lower <= exact.w1 + 1e-13) and np.all(exact.w1 <= c.upper + 1e-13)
    # the upper end is the index coupling the comparison reports anyway
    assert np.all(c.upper <= c.coupling * (1 + 1e-12)) and np.all(c.upper >= c.coupling)
    # exact (proved) where the dual bound met the index coupling, else the bracket's midpoint
    e = c.exact
    np.testing.assert_allclose(c.w1[e], exact.w1[e], rtol=1e-12, atol=1e-15)
    assert np.all(c.w1[~e] == 0.5 * (c.lower + c.upper)[~e])
    assert c.lower[-1] > 0.2 * c.upper[-1]         # informative, not just [0, coupling]
    with pytest.raises(AssertionError, match="POT called"):
        compare(sol, red, max_pot_atoms=60)        # at the threshold POT is still used
    assert MAX_POT_ATOMS == 10_000_000         # beyond the dense LP compare uses the sparse method


def test_compare_bad_arguments():
    sol, red = _kinetic(n=8)
    with pytest.raises(InvalidInput, match="max_pot_atoms"):
        compare(sol, red, max_pot_atoms=-1)
    with pytest.raises(InvalidInput, match="seed"):
        compare(sol, red, seed="x")
