"""Tests of kinred.projection: JL matrices, jl_min_dim, distortion along clouds and trajectories."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import scipy.stats

from kinred.errors import InvalidInput, KinredError
from kinred.projection import (
    KINDS,
    DenseProjection,
    SparseProjection,
    SRHTProjection,
    distortion,
    fwht,
    jl_matrix,
    jl_min_dim,
    trajectory_distortion,
)


# ----------------------------------------------------------------------------------------------
# jl_min_dim
# ----------------------------------------------------------------------------------------------
def test_jl_min_dim_formula_by_hand():
    # 4 ln(1e6) / (1/8 - 1/24) = 55.262 / 0.083333 = 663.15 -> 664 (sklearn truncates to 663)
    assert jl_min_dim(10**6, 0.5) == 664
    # 4 ln(100) / (0.005 - 0.000333...) = 18.4207 / 0.0046667 = 3947.3 -> 3948
    assert jl_min_dim(100, 0.1) == 3948
    assert jl_min_dim(1, 0.5) == 0  # one point: nothing to preserve


def test_jl_min_dim_vectorized_and_monotone():
    eps = np.array([0.05, 0.1, 0.2, 0.4, 0.8])
    k = jl_min_dim(500, eps)
    assert k.shape == (5,) and k.dtype == np.int64
    assert np.all(np.diff(k) < 0)  # more distortion allowed -> fewer dimensions
    for e, kk in zip(eps, k):
        bound = 4 * math.log(500) / (e**2 / 2 - e**3 / 3)
        assert kk - 1 < bound <= kk
    grid = jl_min_dim(np.array([[10], [1000]]), np.array([0.3, 0.6]))
    assert grid.shape == (2, 2) and np.all(grid[1] > grid[0])


@pytest.mark.parametrize("n, eps", [(0, 0.5), (10, 0.0), (10, 1.0), (10, -0.1), (2.5, 0.5), (10, np.nan)])
def test_jl_min_dim_rejects(n, eps):
    with pytest.raises(InvalidInput):
        jl_min_dim(n, eps)


# ----------------------------------------------------------------------------------------------
# Matrix statistics
# ----------------------------------------------------------------------------------------------
def test_gaussian_statistics():
    k, d = 50, 400
    M = jl_matrix(k, d, "gaussian", seed=11).to_dense()
    n = M.size
    # mean of n i.i.d. N(0, 1/k): standard error sqrt(1/(k n)); allow 5 standard errors
    assert abs(M.mean()) < 5 * math.sqrt(1.0 / (k * n))
    # k * sample variance of N(0, 1/k) is ~ chi2_n / n: standard error sqrt(2/n)
    assert abs(k * M.var() - 1.0) < 5 * math.sqrt(2.0 / n)
    # normality: a KS test against N(0, 1/k) (p-value of a correct sampler is uniform)
    assert scipy.stats.kstest(M.ravel() * math.sqrt(k), "norm").pvalue > 1e-4


def test_rademacher_entries_exact():
    k, d = 40, 300
    M = jl_matrix(k, d, "rademacher", seed=3).to_dense()
    assert np.all(np.abs(M) == 1.0 / math.sqrt(k))
    # share of +: Binomial(n, 1/2) / n, standard error 1/(2 sqrt n)
    frac = np.mean(M > 0)
    assert abs(frac - 0.5) < 5 * 0.5 / math.sqrt(M.size)


def test_achlioptas_sparse_statistics():
    k, d = 60, 500
    P = jl_matrix(k, d, "achlioptas", seed=5)
    assert isinstance(P, SparseProjection) and scipy.sparse.isspmatrix_csr(P.matrix)
    M = P.to_dense()
    n = M.size
    nz = M[M != 0]
    assert np.allclose(np.abs(nz), math.sqrt(3.0 / k), rtol=0, atol=1e-15)
    assert P.nnz == nz.size
    # zeros w.p. 2/3: standard error sqrt(p(1-p)/n)
    p0 = np.mean(M == 0)
    assert abs(p0 - 2 / 3) < 5 * math.sqrt((2 / 9) / n)
    # +/- symmetric among the non-zeros
    assert abs(np.mean(nz > 0) - 0.5) < 5 * 0.5 / math.sqrt(nz.size)
    # variance of an entry: 1/3 * 3/k = 1/k
    assert abs(k * np.mean(M**2) - 1.0) < 5 * math.sqrt(2.0 / n)
    # applied sparsely == dense product
    X = np.random.default_rng(0).standard_normal((7, d))
    np.testing.assert_allclose(P.apply(X), X @ M.T, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("d", [16, 64, 50])
def test_srht_entries_and_rows(d):
    k = 8
    P = jl_matrix(k, d, "srht", seed=7)
    M = P.to_dense()
    assert M.shape == (k, d) and P.d_padded == 1 << (d - 1).bit_length()
    # every entry of sqrt(d'/k) P H D is +-sqrt(d'/k)/sqrt(d') = +-1/sqrt(k)
    np.testing.assert_allclose(np.abs(M), 1.0 / math.sqrt(k), rtol=1e-13)
    if d == P.d_padded:  # no padding: orthogonal rows, M M^T = (d/k) I, ||M|| = sqrt(d/k)
        np.testing.assert_allclose(M @ M.T, (d / k) * np.eye(k), atol=1e-12)
    assert P.norm() == pytest.approx(np.linalg.norm(M, 2), rel=1e-12)
    assert P.norm() <= math.sqrt(P.d_padded / k) * (1 + 1e-12)


@pytest.mark.parametrize("d", [16, 37])
def test_dct_orthonormal_rows(d):
    k = 5
    P = jl_matrix(k, d, "dct", seed=2)
    M = P.to_dense()
    np.testing.assert_allclose(M @ M.T, (d / k) * np.eye(k), atol=1e-12)
    assert P.norm() == pytest.approx(math.sqrt(d / k), rel=1e-14)
    assert np.linalg.norm(M, 2) == pytest.approx(math.sqrt(d / k), rel=1e-12)


# ----------------------------------------------------------------------------------------------
# Fast transforms equal explicitly built matrices
# ----------------------------------------------------------------------------------------------
def test_fwht_matches_scipy_hadamard():
    X = np.random.default_rng(1).standard_normal((5, 64))
    H = scipy.linalg.hadamard(64) / 8.0
    np.testing.assert_allclose(fwht(X), X @ H.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fwht(fwht(X)), X, atol=1e-12)  # H is an involution
    with pytest.raises(InvalidInput):
        fwht(np.ones((2, 6)))


@pytest.mark.parametrize("d", [32, 45])
def test_srht_equals_explicit_matrix(d):
    k = 9
    P = jl_matrix(k, d, "srht", seed=4)
    dp = P.d_padded
    H = scipy.linalg.hadamard(dp) / math.sqrt(dp)
    M = math.sqrt(dp / k) * H[P.rows][:, :d] * P.signs[None, :]   # sqrt(d'/k) P H D
    X = np.random.default_rng(2).standard_normal((11, d))
    np.testing.assert_allclose(P.apply(X), X @ M.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P.to_dense(), M, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P @ X.T, M @ X.T, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("d", [12, 33])
def test_dct_equals_explicit_matrix(d):
    k = 4
    P = jl_matrix(k, d, "dct", seed=8)
    j = np.arange(d)[:, None]
    m = np.arange(d)[None, :]
    C = np.sqrt(2.0 / d) * np.cos(np.pi * j * (2 * m + 1) / (2 * d))   # orthonormal DCT-II
    C[0] /= np.sqrt(2.0)
    M = math.sqrt(d / k) * C[P.rows] * P.signs[None, :]
    X = np.random.default_rng(3).standard_normal((6, d))
    np.testing.assert_allclose(P.apply(X), X @ M.T, rtol=1e-12, atol=1e-12)


# ----------------------------------------------------------------------------------------------
# Normalization E||Mx||^2 = ||x||^2
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
def test_normalization_monte_carlo(kind):
    # R independent matrices applied to a fixed x; the mean of ||Mx||^2/||x||^2 must be 1 within
    # 5 sample standard errors (a z-test; for a correct sampler it fails w.p. ~6e-7).
    k, d, R = 4, 16, 3000
    x = np.linspace(-1.0, 2.0, d) ** 2 - 0.5
    seeds = np.random.SeedSequence(123).spawn(R)
    r = np.array([np.sum(jl_matrix(k, d, kind, seed=s).apply(x) ** 2) for s in seeds]) / (x @ x)
    se = r.std(ddof=1) / math.sqrt(R)
    assert abs(r.mean() - 1.0) < 5 * se
    if kind in ("gaussian", "rademacher", "achlioptas"):
        # Var(||Mx||^2/||x||^2) <= 2/k for i.i.d. entries with E m^4 <= 3 (E m^2)^2
        assert r.var(ddof=1) < 2.0 / k * 1.2


# ----------------------------------------------------------------------------------------------
# JL distortion on clouds
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("cloud", ["uniform", "gaussian"])
def test_distortion_within_jl_bound(kind, cloud):
    # n = 20 points, eps = 0.5: jl_min_dim = 144. We use k = 2 * 144 = 288 >= jl_min_dim: for a
    # Gaussian M each pair fails w.p. P(|chi2_288/288 - 1| > 0.5) ~ 2e-8, so all 190 pairs pass
    # with probability > 1 - 1e-5 (the other kinds concentrate at least as well on such clouds).
    n, eps = 20, 0.5
    k = 2 * jl_min_dim(n, eps)
    d = 512
    rng = np.random.default_rng(2024)
    X = rng.random((n, d)) if cloud == "uniform" else 3.0 + rng.standard_normal((n, d))
    P = jl_matrix(k, d, kind, seed=99)
    res = distortion(P, X)
    assert res.n_pairs == n * (n - 1) // 2 and res.n_coincident == 0
    assert 1 - eps < res.ratio_min <= res.ratio_max < 1 + eps
    assert res.eps == pytest.approx(max(1 - res.ratio_min, res.ratio_max - 1))
    # the reported pairs attain the extremes
    i, j = res.argmax
    r = np.sum((P.apply(X[i]) - P.apply(X[j])) ** 2) / np.sum((X[i] - X[j]) ** 2)
    assert r == pytest.approx(res.ratio_max, rel=1e-10)


def test_distortion_small_k_fails_jl():
    # k = 2 on 30 generic points in R^50: squared ratios ~ chi2_2/2 spread far beyond 1 +- 0.5
    X = np.random.default_rng(0).standard_normal((30, 50))
    res = distortion(jl_matrix(2, 50, "gaussian", seed=0), X)
    assert res.eps > 0.5


def test_distortion_exact_values_and_blocking(monkeypatch):
    # Diagonal M = diag(1, 2): ratio for a pair = (dx^2 + 4 dy^2) / (dx^2 + dy^2)
    X = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [3.0, 1.0]])
    M = np.diag([1.0, 2.0])
    import kinred.projection._distortion as mod

    ref = mod.distortion(M, X)
    monkeypatch.setattr(mod, "_BLOCK_BUDGET", 1)  # one row per block
    blk = mod.distortion(M, X)
    assert ref == blk
    assert ref.n_coincident == 1 and ref.n_pairs == 9       # pair (1, 3) coincides
    assert ref.ratio_min == 1.0 and ref.ratio_max == 4.0
    assert ref.argmax == (0, 2) and ref.eps == 3.0
    # translation invariance far from the origin: exact differences keep precision
    far = distortion(M, X + 1e8)
    assert far.ratio_min == 1.0 and far.ratio_max == 4.0


def test_distortion_validation():
    with pytest.raises(InvalidInput, match="columns"):
        distortion(np.eye(3), np.ones((4, 2)))
    with pytest.raises(InvalidInput, match="at least 2"):
        distortion(np.eye(3), np.ones((1, 3)))
    with pytest.raises(InvalidInput, match="distinct"):
        distortion(np.eye(3), np.ones((4, 3)))
    with pytest.raises(InvalidInput):
        distortion(np.eye(3), np.full((4, 3), np.nan))


# ----------------------------------------------------------------------------------------------
# Trajectory distortion (condition (3.4))
# ----------------------------------------------------------------------------------------------
def test_trajectory_distortion_closed_form():
    # M = diag(1, 1/2); agents at time t separated along e1 (ratio 1) or e2 (ratio 1/2).
    M = np.diag([1.0, 0.5])
    T = 4
    traj = np.zeros((T, 2, 2))
    traj[:, 1, 0] = [1.0, 0.0, 2.0, 0.0]
    traj[:, 1, 1] = [0.0, 3.0, 0.0, 0.0]   # t = 3: agents coincide
    r = trajectory_distortion(M, traj)
    np.testing.assert_allclose(r.ratio_min_t[:3], [1.0, 0.5, 1.0])
    assert np.isnan(r.ratio_min_t[3]) and np.isnan(r.eps_t[3])
    assert r.eps == 0.5 and r.worst_time == 1 and r.ratio_min == 0.5 and r.ratio_max == 1.0
    assert r.n_pairs == 3 and r.n_coincident == 1


def test_trajectory_distortion_non_squared_vs_cloud():
    rng = np.random.default_rng(5)
    traj = rng.random((3, 15, 40))
    P = jl_matrix(10, 40, "gaussian", seed=1)
    r = trajectory_distortion(P, traj)
    for t in range(3):
        c = distortion(P, traj[t])
        assert r.ratio_min_t[t] == pytest.approx(math.sqrt(c.ratio_min), rel=1e-12)
        assert r.ratio_max_t[t] == pytest.approx(math.sqrt(c.ratio_max), rel=1e-12)
    assert r.eps == pytest.approx(np.max(r.eps_t))
    # non-squared distortion is smaller than the squared one: |sqrt(r) - 1| <= |r - 1|
    assert r.eps <= max(distortion(P, traj[t]).eps for t in range(3))


def test_trajectory_distortion_validation():
    with pytest.raises(InvalidInput):
        trajectory_distortion(np.eye(2), np.zeros((3, 4)))
    with pytest.raises(InvalidInput, match="last axis"):
        trajectory_distortion(np.eye(2), np.zeros((3, 4, 3)))
    with pytest.raises(InvalidInput):
        trajectory_distortion(np.eye(2), np.zeros((3, 1, 2)))


# ----------------------------------------------------------------------------------------------
# Reproducibility, types, validation
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
def test_same_seed_same_matrix(kind):
    a = jl_matrix(6, 32, kind, seed=17)
    b = jl_matrix(6, 32, kind, seed=17)
    c = jl_matrix(6, 32, kind, seed=18)
    assert np.array_equal(a.to_dense(), b.to_dense())
    assert not np.array_equal(a.to_dense(), c.to_dense())
    assert a.kind == kind and a.seed == 17 and a.shape == (6, 32)
    g = jl_matrix(6, 32, kind, seed=np.random.SeedSequence(17))
    assert g.shape == (6, 32)


def test_types():
    assert isinstance(jl_matrix(3, 10, "gaussian", seed=0), DenseProjection)
    assert isinstance(jl_matrix(3, 10, "achlioptas", seed=0), SparseProjection)
    assert isinstance(jl_matrix(3, 10, "srht", seed=0), SRHTProjection)
    assert isinstance(jl_matrix(3, 10, "dct", seed=0), SRHTProjection)
    assert jl_matrix(3, 10, seed=0).kind == "gaussian"


@pytest.mark.parametrize(
    "args, match",
    [
        ((0, 10, "gaussian"), "k must be >= 1"),
        ((3, 0, "gaussian"), "d must be >= 1"),
        ((3, 10, "bernoulli"), "kind must be one of"),
        ((17, 16, "srht"), "k must be <= d'"),
        ((11, 10, "dct"), "k must be <= d"),
        ((2.5, 10, "gaussian"), "k must be an integer"),
    ],
)
def test_jl_matrix_validation(args, match):
    with pytest.raises(InvalidInput, match=match):
        jl_matrix(*args, seed=0)
    with pytest.raises(KinredError):
        jl_matrix(3, 10, "gaussian", seed=-1)


def test_apply_validation():
    P = jl_matrix(3, 8, "srht", seed=0)
    with pytest.raises(InvalidInput, match="8 columns"):
        P.apply(np.ones((2, 7)))
    assert P.apply(np.ones(8)).shape == (3,)


# ----------------------------------------------------------------------------------------------
# The array protocol: np.asarray(M), M @ x, X @ M.T, Y @ M (issue 18)
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("d", [16, 13])
def test_array_protocol_matches_dense(kind, d):
    M = jl_matrix(5, d, kind, seed=3)
    D = M.to_dense()
    A = np.asarray(M)
    assert A.shape == (5, d) and A.dtype == np.float64 and np.array_equal(A, D)
    assert M.ndim == 2 and M.dtype == np.float64 and M.shape == (5, d)
    rng = np.random.default_rng(1)
    X, Y = rng.standard_normal((7, d)), rng.standard_normal((4, 5))
    x, y = X[0], Y[0]
    tol = 1e-12 * np.abs(D).max() * d
    # X @ M.T is apply(X); the rows of a batch and a single vector
    assert np.allclose(X @ M.T, M.apply(X), rtol=0, atol=tol)
    assert np.allclose(np.matmul(X, M.T), X @ D.T, rtol=0, atol=tol)
    assert np.allclose(M @ x, D @ x, rtol=0, atol=tol) and (M @ x).shape == (5,)
    assert np.allclose(M @ X.T, D @ X.T, rtol=0, atol=tol)
    # the transpose, applied without the dense matrix: Y M and Mᵀ y
    assert np.allclose(Y @ M, Y @ D, rtol=0, atol=tol)
    assert np.allclose(y @ M, y @ D, rtol=0, atol=tol)
    assert np.allclose(M.T @ y, D.T @ y, rtol=0, atol=tol)
    assert np.allclose(M.T.apply(Y), Y @ D, rtol=0, atol=tol)
    assert np.array_equal(np.asarray(M.T), D.T) and M.T.shape == (d, 5) and M.T.T is M
    assert np.isclose(M.T.norm(), np.linalg.norm(D, 2))
    # a projection times a projection: the product of the matrices
    assert np.allclose(M @ M.T, D @ D.T, rtol=0, atol=tol)
    # stacks, as for ndarrays: (T, N, d) @ Mᵀ and M @ (T, d, m)
    S = rng.standard_normal((3, 7, d))
    assert np.allclose(S @ M.T, S @ D.T, rtol=0, atol=tol) and (S @ M.T).shape == (3, 7, 5)
    St = np.swapaxes(S, 1, 2)
    assert np.allclose(M @ St, D @ St, rtol=0, atol=tol) and (M @ St).shape == (3, 5, 7)


@pytest.mark.parametrize("kind", ["srht", "dct"])
def test_matmul_keeps_structured_apply(kind, monkeypatch):
    """``X @ M.T`` and ``Y @ M`` never build the dense matrix of a structured map."""
    M = jl_matrix(4, 32, kind, seed=0)
    D = M.to_dense()
    monkeypatch.setattr(SRHTProjection, "to_dense", lambda self: pytest.fail("dense matrix built"))
    X = np.random.default_rng(0).standard_normal((3, 32))
    assert np.allclose(X @ M.T, X @ D.T, atol=1e-12)
    assert np.allclose(np.ones((2, 4)) @ M, np.ones((2, 4)) @ D, atol=1e-12)


def test_asarray_copy_and_dtype():
    P = DenseProjection(np.eye(2, 3))
    assert np.asarray(P, copy=False) is P.matrix
    assert np.asarray(P, dtype=np.float32).dtype == np.float32
    c = np.array(P, copy=True)
    c[0, 0] = 7.0
    assert P.matrix[0, 0] == 1.0
    S = jl_matrix(2, 8, "srht", seed=0)
    with pytest.raises(InvalidInput, match=r"copy=False.*\(2, 8\) matrix"):
        np.asarray(S, copy=False)


@pytest.mark.parametrize("expr, match", [
    (lambda M: M @ np.ones(3), r"M @ x: shapes \(4, 13\) and \(3,\).*\(13,\) or \(\.\.\., 13, m\)"),
    (lambda M: M @ np.ones((4, 2)), r"M @ x: shapes \(4, 13\) and \(4, 2\)"),
    (lambda M: M @ np.ones((13, 2, 2)), r"shapes \(4, 13\) and \(13, 2, 2\)"),
    (lambda M: M @ np.float64(2.0), r"shapes \(4, 13\) and \(\)"),
    (lambda M: np.ones((2, 4)) @ M.T, r"x @ M.T: shapes \(2, 4\) and \(13, 4\).*\(\.\.\., 13\)"),
    (lambda M: np.ones((2, 13)) @ M, r"x @ M: shapes \(2, 13\) and \(4, 13\).*\(4,\) or \(\.\.\., 4\)"),
    (lambda M: M.T @ np.ones(13), r"M.T @ x: shapes \(13, 4\) and \(13,\)"),
    (lambda M: M @ np.full(13, np.nan), "must be finite"),
    (lambda M: M @ "abc", "must be a numeric array"),
])
@pytest.mark.parametrize("kind", ["gaussian", "achlioptas", "srht"])
def test_matmul_shape_errors_name_the_shapes(kind, expr, match):
    M = jl_matrix(4, 13, kind, seed=0)
    with pytest.raises(InvalidInput, match=match):
        expr(M)
