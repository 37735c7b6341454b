"""Measures: distribution functions against closed forms, sampling statistics, push-forwards,
validation."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import special, stats

from kinred.errors import InvalidInput
from kinred.measures import (
    Atomic,
    Dirac,
    Empirical1D,
    Mixture,
    PushForward,
    TensorProduct,
    Uniform,
    Univariate,
)
from kinred.projection import as_projection


def test_uniform_sample_statistics():
    mu = Uniform(-1.0, 3.0)
    x = mu.sample(20000, seed=1)
    assert x.shape == (20000, 1)
    assert x.min() >= -1.0 and x.max() <= 3.0
    # mean 1, sd 4/sqrt(12): 5 standard errors
    assert abs(x.mean() - 1.0) < 5 * (4 / math.sqrt(12)) / math.sqrt(20000)
    assert abs(x.var() - 16 / 12) < 0.05
    np.testing.assert_array_equal(mu.sample(5, seed=3), mu.sample(5, seed=3))


def test_unbounded_law_needs_support():
    with pytest.raises(InvalidInput, match="unbounded support.*support=\\(a, b\\)"):
        Univariate(stats.norm())
    with pytest.raises(InvalidInput, match="frozen scipy.stats"):
        Univariate(stats.norm)
    with pytest.raises(InvalidInput, match="a < b"):
        Univariate(stats.norm(), support=(1.0, 1.0))
    with pytest.raises(InvalidInput, match="does not overlap"):
        Univariate(stats.beta(2, 2), support=(2.0, 3.0))
    with pytest.raises(InvalidInput, match="finite"):
        Univariate(stats.norm(), support=(0.0, np.nan))


def test_truncated_normal_against_closed_form():
    a, b = -0.5, 2.0
    mu = Univariate(stats.norm(1.0, 2.0), support=(a, b))
    assert mu.support == (a, b) and mu.truncated
    x = np.linspace(a, b, 11)
    Phi = lambda t: special.ndtr((t - 1.0) / 2.0)  # noqa: E731
    want = (Phi(x) - Phi(a)) / (Phi(b) - Phi(a))
    np.testing.assert_allclose(mu.cdf(x), want, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(mu.ppf(want), x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(mu.support_widths(), [b - a])


def test_far_tail_truncation_is_accurate():
    # exponential law truncated to [30, 31]: F(x) = (1 - e^{-(x-30)}) / (1 - e^{-1})
    mu = Univariate(stats.expon(), support=(30.0, 31.0))
    x = np.linspace(30.0, 31.0, 7)
    want = -np.expm1(-(x - 30.0)) / -np.expm1(-1.0)
    np.testing.assert_allclose(mu.cdf(x), want, rtol=1e-10, atol=1e-14)
    u = np.linspace(0, 1, 9)
    np.testing.assert_allclose(mu.ppf(u), 30.0 - np.log1p(-u * -np.expm1(-1.0)), rtol=1e-12)
    # a normal truncated 40 standard deviations out still has its shape
    nu = Univariate(stats.norm(), support=(-41.0, -40.0))
    assert -41.0 <= float(nu.ppf(0.5)) <= -40.0
    assert float(nu.ppf(0.5)) > -40.1  # mass piles up at the end nearest the mode
    with pytest.raises(InvalidInput, match="no probability mass"):
        Univariate(stats.expon(), support=(900.0, 901.0))


@given(st.floats(0.3, 6.0), st.floats(0.3, 6.0), st.floats(0.0, 1.0))
def test_beta_ppf_inverts_cdf(a, b, u):
    mu = Univariate(stats.beta(a, b))
    x = mu.ppf(u)
    assert 0.0 <= x <= 1.0
    assert abs(float(mu.cdf(x)) - u) < 1e-8


def test_empirical_step_quantile():
    mu = Empirical1D([2.0, 0.0, 1.0, 5.0], [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(mu.values, [0.0, 1.0, 2.0, 5.0])
    # cumulative weights 0.2, 0.5, 0.6, 1.0
    np.testing.assert_array_equal(mu.ppf([0.0, 0.2, 0.2001, 0.5, 0.55, 0.61, 1.0]),
                                  [0.0, 0.0, 1.0, 1.0, 2.0, 5.0, 5.0])
    np.testing.assert_allclose(mu.cdf([-1.0, 0.0, 1.5, 5.0, 9.0]), [0.0, 0.2, 0.5, 1.0, 1.0])
    assert mu.support == (0.0, 5.0)
    assert mu.n_atoms == 4 and mu.dim == 1


def test_dirac_and_atomic_validation():
    d = Dirac([1.0, -2.0])
    assert d.dim == 2 and d.n_atoms == 1
    np.testing.assert_array_equal(d.support_widths(), [0.0, 0.0])
    np.testing.assert_array_equal(d.sample(3, seed=0), [[1.0, -2.0]] * 3)
    with pytest.raises(InvalidInput, match="finite"):
        Atomic([[0.0, np.nan]])
    with pytest.raises(InvalidInput, match="finite"):
        Dirac(np.inf)
    with pytest.raises(InvalidInput, match="non-negative"):
        Atomic([[0.0], [1.0]], [1.5, -0.5])
    with pytest.raises(InvalidInput, match="sum to one"):
        Atomic([[0.0], [1.0]], [0.5, 0.6])
    with pytest.raises(InvalidInput, match="length 2"):
        Atomic([[0.0], [1.0]], [1.0])
    with pytest.raises(InvalidInput, match="source dimension|measure's dimension"):
        Atomic([[0.0, 1.0]]).push(np.eye(3))
    with pytest.raises(InvalidInput, match="1-D measure"):
        TensorProduct([Uniform(), Dirac([0.0, 1.0])])
    with pytest.raises(InvalidInput, match="same dim"):
        Mixture([Uniform(), Dirac([0.0, 1.0])])
    with pytest.raises(InvalidInput, match="sum to one"):
        Mixture([Uniform(), Uniform()], [0.5, 0.6])
    with pytest.raises(InvalidInput, match="a < b"):
        Uniform(1.0, 0.0)
    with pytest.raises(InvalidInput, match="n must be >= 0"):
        Uniform().sample(-1)


@given(st.integers(1, 6), st.integers(1, 4), st.integers(1, 30), st.integers(0, 2**31))
def test_atomic_push_is_exact(d, k, n, seed):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, d))
    w = rng.random(n)
    w /= w.sum()
    M = rng.standard_normal((k, d))
    mu = Atomic(X, w)
    nu = mu.push(M)
    assert isinstance(nu, Atomic) and nu.dim == k
    np.testing.assert_allclose(nu.points, X @ M.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(nu.weights, mu.weights)
    # with a Projection object too
    np.testing.assert_allclose(mu.push(as_projection(M)).points, X @ M.T, rtol=1e-12, atol=1e-12)


def test_pushforward_samples_and_support():
    mu = TensorProduct([Uniform(0, 1), Uniform(-1, 1), Univariate(stats.beta(2, 2))])
    M = np.array([[1.0, -2.0, 0.5], [0.0, 1.0, 1.0]])
    nu = mu.push(M)
    assert isinstance(nu, PushForward) and nu.dim == 2 and nu.base is mu
    np.testing.assert_allclose(nu.sample(50, seed=4), mu.sample(50, seed=4) @ M.T)
    # the box image: width_i = Σ_j |M_ij| σ_j
    np.testing.assert_allclose(nu.support_widths(), np.abs(M) @ np.array([1.0, 2.0, 1.0]))
    lo, hi = nu.support_box()
    y = nu.sample(2000, seed=5)
    assert np.all(y >= lo - 1e-12) and np.all(y <= hi + 1e-12)
    # mean of the image is M times the mean
    assert np.allclose(y.mean(axis=0), M @ [0.5, 0.0, 0.5], atol=0.1)


def test_mixture_sampling_frequencies():
    mu = Mixture([Uniform(0, 1), Uniform(10, 11)], [0.3, 0.7])
    x = mu.sample(20000, seed=2)[:, 0]
    frac = np.mean(x > 5)
    assert abs(frac - 0.7) < 5 * math.sqrt(0.21 / 20000)
    np.testing.assert_allclose(mu.support_widths(), [11.0])


def test_tensor_product_sampling_is_independent_per_coordinate():
    mu = TensorProduct([Uniform(0, 1), Dirac(3.0), Uniform(0, 2)])
    x = mu.sample(20000, seed=7)
    assert np.all(x[:, 1] == 3.0)
    assert abs(np.corrcoef(x[:, 0], x[:, 2])[0, 1]) < 0.05
    assert abs(x[:, 2].mean() - 1.0) < 0.03


# ----------------------------------------------------------------------------- measure files
def _uniform_file(params: dict, **extra):
    from kinred.measures import measure_from_dict

    return measure_from_dict({"coordinate": [{"dist": "uniform", "params": params, **extra}]},
                             source="m.toml")


@pytest.mark.parametrize("params", [{"a": 2.0, "b": 3.5}, {"low": 2.0, "high": 3.5},
                                    {"loc": 2.0, "scale": 1.5}])
def test_measure_file_uniform_accepts_the_interval_and_scipys_spelling(params):
    """Issue 18: Uniform(a, b) in Python is [a, b]; files now accept {a, b}/{low, high} too."""
    u = np.linspace(0.0, 1.0, 11)
    ref = Uniform(2.0, 3.5)
    mu = _uniform_file(params).factors[0]
    assert mu.support == pytest.approx(ref.support, abs=0)
    np.testing.assert_allclose(mu.ppf(u), ref.ppf(u), rtol=1e-15, atol=0)
    np.testing.assert_allclose(mu.cdf([2.0, 2.75, 3.5]), [0.0, 0.5, 1.0], rtol=1e-15, atol=0)
    # repeat/decay scale the interval: copy i is the law of 0.5**i X, on [2, 3.5]·0.5**i
    widths = _uniform_file(params, repeat=3, decay=0.5).support_widths()
    np.testing.assert_allclose(widths, [1.5, 0.75, 0.375], rtol=1e-15)


@pytest.mark.parametrize("params, needle", [
    ({"a": 0.0, "b": 1.0, "loc": 0.0, "scale": 1.0},
     r"coordinate\[0\]\.params: uniform: give the interval one way.*got the keys a, b, loc, scale"),
    ({"a": 0.0, "b": 1.0, "scale": 1.0}, "got the keys a, b, scale"),
    ({"a": 0.0, "high": 1.0}, "got the keys a, high"),
    ({"low": 0.0, "high": 1.0, "b": 1.0}, "got the keys b, high, low"),
    ({"a": 0.0}, r"coordinate\[0\].params.b: missing: uniform \{a, b\} needs both ends"),
    ({"high": 1.0}, r"params.low: missing"),
    ({"a": 3.0, "b": 2.0}, "uniform needs a < b.*got a = 3.0, b = 2.0"),
    ({"low": 1.0, "high": 1.0}, "uniform needs low < high"),
    ({"a": -1e308, "b": 1e308}, "finite, positive width"),
])
def test_measure_file_uniform_spellings_refused(params, needle):
    from kinred.errors import ConfigError

    with pytest.raises(ConfigError, match=needle):
        _uniform_file(params)
