"""Tests of kinred.recovery: batched ℓ1 solver, exact references, η rule, recover()."""

import numpy as np
import pytest

from kinred.errors import InvalidInput
from kinred.projection import DenseProjection
from kinred.recovery import (
    basis_pursuit,
    estimate_eta,
    lasso,
    recover,
    relative_error,
    stack_projections,
)
from kinred.recovery._kernels import _admm_step_nb, admm_step_numpy
from kinred.recovery._reference import (
    reference_basis_pursuit,
    reference_bpdn,
    reference_lasso,
)


def gaussian_projections(rng, L, k, d):
    """L independent Gaussian projections with N(0, 1/k) entries (the paper's normalization)."""
    return [rng.standard_normal((k, d)) / np.sqrt(k) for _ in range(L)]


def sparse_columns(rng, d, K, n, nonneg=False):
    X = np.zeros((d, n))
    for j in range(n):
        vals = rng.standard_normal(K)
        X[rng.choice(d, K, replace=False), j] = np.abs(vals) if nonneg else vals
    return X


# ---------------------------------------------------------------------------------------------
# numba kernel vs numpy twin


@pytest.mark.parametrize("lasso_form", [False, True])
@pytest.mark.parametrize("nonneg", [False, True])
def test_kernel_matches_numpy_twin(lasso_form, nonneg):
    rng = np.random.default_rng(1)
    n, d, m = 7, 11, 5
    arrs = {k: rng.standard_normal((n, d)) for k in ("z", "u", "p")}
    arrs.update({k: rng.standard_normal((n, m)) for k in ("Az", "v", "q", "Y")})
    thr = rng.uniform(0.05, 1.0, n)
    param = np.abs(rng.standard_normal(n))
    param[0] = 1e3  # a row whose point is already inside the ball
    outs = []
    for fn in (_admm_step_nb, admm_step_numpy):
        c = {k: v.copy() for k, v in arrs.items()}
        a = np.zeros((n, d))
        b = np.zeros((n, m))
        fn(c["z"], c["Az"], c["u"], c["v"], c["p"], c["q"], a, b, thr, c["Y"], param, 1.6, lasso_form, nonneg)
        outs.append([c["u"], c["v"], c["p"], c["q"], a, b])
    for x, y in zip(*outs):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-14)
    if nonneg:
        assert np.all(outs[0][0] >= 0)


# ---------------------------------------------------------------------------------------------
# acceptance: exact recovery inside the phase transition


def test_exact_recovery_inside_phase_transition():
    """d = 200, K = 40 (80 % zeros), kL = 120 (6 projections into R^20): >= 99 % of 200 exact."""
    d, K, L, k = 200, 40, 6, 20
    recovered = 0
    for batch in range(4):  # a different stacked matrix per batch
        rng = np.random.default_rng(100 + batch)
        Ms = gaussian_projections(rng, L, k, d)
        X = sparse_columns(rng, d, K, 50)
        res = basis_pursuit(Ms, stack_projections(Ms) @ X)
        err = np.linalg.norm(res.Z - X, axis=0) / np.linalg.norm(X, axis=0)
        recovered += int(np.sum(err <= 1e-6))
    assert recovered >= 198, recovered


def test_tiny_coefficients_are_recovered_exactly():
    """A true entry of relative size ~1e-5 is still below ADMM's soft threshold when ADMM
    meets its tolerance (it needs 2000–4000 more iterations to release it); the polish repair
    (residual-correlation expansion, minimum-norm certificate) must recover it exactly, as the
    exact LP does (measured: 15 such problems in the 10⁴ of benchmarks/bench_recovery.py)."""
    rng = np.random.default_rng(7)
    d, K, L, k = 200, 40, 6, 20
    Ms = gaussian_projections(rng, L, k, d)
    A = stack_projections(Ms)
    X = sparse_columns(rng, d, K, 24)
    for j in range(X.shape[1]):
        i = np.flatnonzero(X[:, j])[j % K]
        X[i, j] = np.sign(X[i, j]) * 10.0 ** rng.uniform(-5.5, -4.5) * np.linalg.norm(X[:, j])
    res = basis_pursuit(A, A @ X)
    err = np.linalg.norm(res.Z - X, axis=0) / np.linalg.norm(X, axis=0)
    ok = err <= 1e-9
    for j in np.flatnonzero(~ok):      # allowed only where the exact LP does not recover X
        z = reference_basis_pursuit(A, A @ X[:, j])
        assert np.linalg.norm(z - X[:, j]) > 1e-6 * np.linalg.norm(X[:, j]), (j, err[j])
    assert np.sum(ok) >= 22, err
    # the support includes the tiny entries
    tiny = np.abs(X) < 1e-4 * np.linalg.norm(X, axis=0)
    assert np.all(np.sign(res.Z[tiny & (X != 0) & ok[None, :]]) != 0)


# ---------------------------------------------------------------------------------------------
# agreement with the exact references


def test_basis_pursuit_matches_highs():
    rng = np.random.default_rng(2)
    m, d = 30, 60
    A = rng.standard_normal((m, d)) / np.sqrt(m)
    X = sparse_columns(rng, d, 14, 12)  # beyond the transition: BP differs from X sometimes
    Y = A @ X
    res = basis_pursuit(A, Y, tol=1e-8)
    assert np.all(res.status == "optimal"), res.counts()
    for j in range(Y.shape[1]):
        z = reference_basis_pursuit(A, Y[:, j])
        l1 = np.abs(z).sum()
        assert abs(res.objective[j] - l1) <= 1e-8 * l1
        assert np.linalg.norm(res.Z[:, j] - z) <= 1e-6 * np.linalg.norm(z)
        assert res.residual[j] <= 1e-10 * np.linalg.norm(Y[:, j])


@pytest.mark.parametrize("nonneg", [False, True])
def test_bpdn_matches_clarabel(nonneg):
    rng = np.random.default_rng(3)
    m, d, n = 30, 60, 10
    A = rng.standard_normal((m, d)) / np.sqrt(m)
    X = sparse_columns(rng, d, 6, n, nonneg=nonneg)
    Y = A @ X + 0.05 * rng.standard_normal((m, n))
    eta = 0.05 * np.sqrt(m) * rng.uniform(0.5, 1.5, n)  # per-column η
    res = basis_pursuit(A, Y, eta, nonneg=nonneg, tol=1e-8, max_iter=20000)
    assert np.all(res.status == "optimal"), res.counts()
    assert np.all(res.gap <= 1e-8)
    for j in range(n):
        z = reference_bpdn(A, Y[:, j], eta[j], nonneg=nonneg)
        l1 = np.abs(z).sum()
        assert abs(res.objective[j] - l1) <= 1e-5 * l1
        assert np.linalg.norm(res.Z[:, j] - z) <= 1e-5 * np.linalg.norm(z)
        # the constraint is active at the solution (η < ‖y‖), to round-off
        assert abs(res.residual[j] - eta[j]) <= 1e-9 * eta[j]
    if nonneg:
        assert np.all(res.Z >= 0)


@pytest.mark.parametrize("nonneg", [False, True])
def test_lasso_matches_clarabel(nonneg):
    rng = np.random.default_rng(4)
    m, d, n = 30, 60, 8
    A = rng.standard_normal((m, d)) / np.sqrt(m)
    X = sparse_columns(rng, d, 6, n, nonneg=nonneg)
    Y = A @ X + 0.05 * rng.standard_normal((m, n))
    lam = 0.05 * rng.uniform(0.5, 2.0, n)
    res = lasso(A, Y, lam, nonneg=nonneg, tol=1e-8, max_iter=20000)
    assert np.all(res.status == "optimal"), res.counts()
    for j in range(n):
        z = reference_lasso(A, Y[:, j], lam[j], nonneg=nonneg)
        obj = 0.5 * np.sum((A @ z - Y[:, j]) ** 2) + lam[j] * np.abs(z).sum()
        assert abs(res.objective[j] - obj) <= 1e-6 * obj
        assert res.objective[j] <= obj * (1 + 1e-9)  # never worse than the reference
        assert np.linalg.norm(res.Z[:, j] - z) <= 1e-5 * np.linalg.norm(z)


def test_lasso_orthogonal_design_is_soft_threshold():
    """For A with orthonormal columns the LASSO solution is soft(Aᵀy, λ) in closed form."""
    rng = np.random.default_rng(5)
    Q, _ = np.linalg.qr(rng.standard_normal((40, 25)))
    Y = rng.standard_normal((40, 6))
    lam = 0.3
    c = Q.T @ Y
    expect = np.sign(c) * np.maximum(np.abs(c) - lam, 0)
    res = lasso(Q, Y, lam)
    np.testing.assert_allclose(res.Z, expect, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# invariances, trivial and infeasible columns


def test_scaling_invariance():
    """min ‖z‖₁ s.t. ‖cAz − cy‖ ≤ cη has the same solution; scaling y and η by s scales z."""
    rng = np.random.default_rng(6)
    A = rng.standard_normal((40, 80)) / np.sqrt(40)
    X = sparse_columns(rng, 80, 8, 5)
    Y = A @ X + 0.01 * rng.standard_normal((40, 5))
    eta = 0.01 * np.sqrt(40)
    base = basis_pursuit(A, Y, eta)
    assert np.all(base.status == "optimal")
    scaled_A = basis_pursuit(1e3 * A, 1e3 * Y, 1e3 * eta)
    np.testing.assert_allclose(scaled_A.Z, base.Z, rtol=1e-8, atol=1e-10)
    s = np.array([1e-4, 1.0, 7.0, 1e3, 2.0])
    scaled_y = basis_pursuit(A, Y * s, eta * s)
    np.testing.assert_allclose(scaled_y.Z, base.Z * s, rtol=1e-8, atol=1e-10 * s.max())


def test_zero_and_infeasible_columns():
    A = np.array([[1.0, 0.0, 1.0], [1.0, 0.0, 1.0]])  # rank one: range = span{(1, 1)}
    Y = np.array([[0.1, 2.0, 1.0], [0.1, 2.0, -1.0]])
    res = basis_pursuit(A, Y, np.array([0.5, 0.0, 0.1]))
    assert list(res.status) == ["zero", "optimal", "infeasible"]
    np.testing.assert_array_equal(res.Z[:, 0], 0.0)
    assert abs(np.abs(res.Z[:, 1]).sum() - 2.0) < 1e-10  # ‖z‖₁ = 2 on the segment z₀ + z₂ = 2
    assert np.all(np.isnan(res.Z[:, 2]))
    assert not res.converged[2]


def test_projection_objects_and_stacking():
    rng = np.random.default_rng(7)
    Ms = gaussian_projections(rng, 3, 10, 40)
    stacked = stack_projections([DenseProjection(Ms[0]), Ms[1], DenseProjection(Ms[2])])
    np.testing.assert_array_equal(stacked, np.vstack(Ms))
    x = np.zeros(40)
    x[[3, 17]] = [1.0, -2.0]
    res = basis_pursuit([DenseProjection(M) for M in Ms], stacked @ x)
    np.testing.assert_allclose(res.Z[:, 0], x, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# the automatic η rule


def test_auto_eta_covers_noise_and_recovers_like_oracle():
    rng = np.random.default_rng(8)
    d, L, k, K, n = 200, 6, 20, 40, 40
    Ms = gaussian_projections(rng, L, k, d)
    A = stack_projections(Ms)
    m = A.shape[0]
    X = sparse_columns(rng, d, K, n)
    Y0 = A @ X
    sigma = 1e-2 * np.linalg.norm(Y0) / np.sqrt(Y0.size)  # 1 % relative noise, known size
    E = sigma * rng.standard_normal((m, n))
    est = estimate_eta(A, Y0 + E, groups=np.arange(n) // 20, blocks=[k] * L)
    e_norm = np.linalg.norm(E, axis=0)
    assert np.mean(est.eta >= e_norm) >= 0.9  # covers the true ‖e‖ with high probability
    assert np.all(est.eta <= 2.0 * e_norm)  # and is not wildly larger
    assert np.all(np.abs(est.sigma / sigma - 1) < 0.25)
    auto = basis_pursuit(A, Y0 + E, est.eta, tol=1e-5, max_iter=2000)
    oracle = basis_pursuit(A, Y0 + E, e_norm, tol=1e-5, max_iter=2000)
    err_auto = np.linalg.norm(auto.Z - X) / np.linalg.norm(X)
    err_oracle = np.linalg.norm(oracle.Z - X) / np.linalg.norm(X)
    assert err_auto <= 1.5 * err_oracle, (err_auto, err_oracle)


# ---------------------------------------------------------------------------------------------
# recover()


def test_recover_exact_trajectories_and_relative_error():
    rng = np.random.default_rng(9)
    T, N, d, L, k = 3, 5, 60, 3, 10
    Ms = gaussian_projections(rng, L, k, d)
    X = np.zeros((T, N, d))
    for t in range(T):
        for i in range(N):
            X[t, i, rng.choice(d, 5, replace=False)] = rng.standard_normal(5)
    Ys = [X @ M.T for M in Ms]  # noise-free projected trajectories (T, N, k)
    rec = recover(Ms, Ys, eta=0.0, original=X)
    assert rec.X.shape == (T, N, d) and rec.eta.shape == (T, N) and rec.status.shape == (T, N)
    assert rec.relative_error.shape == (T,)
    assert np.all(rec.relative_error < 1e-9)
    # agent/time layout: perturb one agent at one time only
    X2 = X.copy()
    X2[1, 2] *= 1.5
    err = relative_error(X2, X)
    assert err[0] == 0.0 and err[2] == 0.0
    expect = 0.5 * np.linalg.norm(X[1, 2]) / np.linalg.norm(X[1])
    assert abs(err[1] - expect) < 1e-14


def test_recover_auto_eta_with_noise():
    rng = np.random.default_rng(10)
    T, N, d, L, k = 2, 20, 100, 4, 15
    Ms = gaussian_projections(rng, L, k, d)
    X = np.zeros((T, N, d))
    for t in range(T):
        for i in range(N):
            X[t, i, rng.choice(d, 8, replace=False)] = rng.standard_normal(8)
    noise = [1e-2 * (t + 1) for t in range(T)]  # the projection error grows in time
    Ys = [X @ M.T + noise[0] * rng.standard_normal((T, N, k)) * np.array(noise)[:, None, None] / noise[0] for M in Ms]
    rec = recover(Ms, Ys, original=X)
    assert rec.eta_rule.startswith("block cross-validated")
    # η pooled per time, growing with the noise
    assert np.allclose(rec.eta[0], rec.eta[0, 0]) and rec.eta[1, 0] > 1.5 * rec.eta[0, 0]
    assert np.all(rec.relative_error < 0.1)


# ---------------------------------------------------------------------------------------------
# validation


def test_validation_errors():
    rng = np.random.default_rng(11)
    A = rng.standard_normal((6, 10))
    Y = rng.standard_normal((6, 3))
    with pytest.raises(InvalidInput, match="Y must have m = 6 rows"):
        basis_pursuit(A, np.ones((5, 3)))
    Ybad = Y.copy()
    Ybad[2, 1] = np.nan
    with pytest.raises(InvalidInput, match="Y must be finite"):
        basis_pursuit(A, Ybad)
    with pytest.raises(InvalidInput, match="eta must be >= 0"):
        basis_pursuit(A, Y, -0.1)
    with pytest.raises(InvalidInput, match="eta must be >= 0"):
        basis_pursuit(A, Y, np.array([0.1, -1.0, 0.0]))
    with pytest.raises(InvalidInput, match=r"eta must be a scalar or have shape \(3,\)"):
        basis_pursuit(A, Y, np.zeros(4))
    with pytest.raises(InvalidInput, match="lam must be >= 0"):
        lasso(A, Y, -1.0)
    with pytest.raises(InvalidInput, match="tol must be"):
        basis_pursuit(A, Y, tol=0.0)
    with pytest.raises(InvalidInput, match="relax must be"):
        basis_pursuit(A, Y, relax=2.0)
    Abad = A.copy()
    Abad[0, 0] = np.inf
    with pytest.raises(InvalidInput, match="A must be finite"):
        basis_pursuit(Abad, Y)
    with pytest.raises(InvalidInput, match="same source dimension"):
        stack_projections([np.ones((2, 5)), np.ones((2, 6))])
    with pytest.raises(InvalidInput, match="at least one projection"):
        stack_projections([])


def test_recover_validation_errors():
    rng = np.random.default_rng(12)
    Ms = gaussian_projections(rng, 2, 4, 12)
    Ys = [rng.standard_normal((3, 5, 4)) for _ in range(2)]
    with pytest.raises(InvalidInput, match="same length L"):
        recover(Ms, Ys[:1])
    with pytest.raises(InvalidInput, match=r"last axis k = 4"):
        recover(Ms, [Ys[0], rng.standard_normal((3, 5, 3))])
    with pytest.raises(InvalidInput, match=r"shape \(T, N\) = \(3, 5\)"):
        recover(Ms, [Ys[0], rng.standard_normal((3, 6, 4))])
    bad = Ys[1].copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(InvalidInput, match=r"projected_trajectories\[1\] must be finite"):
        recover(Ms, [Ys[0], bad])
    with pytest.raises(InvalidInput, match="eta must be one of 'auto'"):
        recover(Ms, Ys, eta="oracle")
    with pytest.raises(InvalidInput, match="eta must be >= 0"):
        recover(Ms, Ys, eta=-1.0)
    with pytest.raises(InvalidInput, match=r"original must have shape \(3, 5, 12\)"):
        recover(Ms, Ys, eta=0.0, original=np.zeros((3, 5, 11)))
    with pytest.raises(InvalidInput, match="groups must be an integer array"):
        estimate_eta(stack_projections(Ms), rng.standard_normal((8, 4)), groups=np.zeros(3, int))



def test_estimate_eta_rejects_bad_blocks_and_empty_data():
    """Bad ``blocks`` and a ``Y`` without columns escaped as TypeError / IndexError /
    ValueError; integral float sizes are sizes (the same estimate as integer ones)."""
    rng = np.random.default_rng(13)
    A = rng.standard_normal((6, 10))
    Y = rng.standard_normal((6, 3))
    with pytest.raises(InvalidInput, match="blocks must be a sequence of positive integers"):
        estimate_eta(A, Y, blocks=6)
    with pytest.raises(InvalidInput, match="blocks must be a sequence of positive integers"):
        estimate_eta(A, Y, blocks="ab")
    with pytest.raises(InvalidInput, match=r"blocks\[0\] must be an integer, got 2.5"):
        estimate_eta(A, Y, blocks=[2.5, 3.5])
    with pytest.raises(InvalidInput, match=r"blocks must be positive sizes summing to m = 6"):
        estimate_eta(A, Y, blocks=[2, 3])
    with pytest.raises(InvalidInput, match=r"at least one column .* got shape \(6, 0\)"):
        estimate_eta(A, np.zeros((6, 0)))
    A = rng.standard_normal((60, 100)) / np.sqrt(60)
    X = np.zeros((100, 6))
    X[:5] = 1.0
    Y = A @ X + 0.01 * rng.standard_normal((60, 6))
    ints = estimate_eta(A, Y, groups=np.zeros(6, int), blocks=[20, 20, 20])
    floats = estimate_eta(A, Y, groups=np.zeros(6, int), blocks=np.array([20.0, 20.0, 20.0]))
    assert np.array_equal(ints.eta, floats.eta) and ints.rounds == floats.rounds == 3
    assert 0.5 < ints.sigma[0] / 0.01 < 2.0


def test_recover_rejects_empty_trajectories_and_checks_original_before_solving(monkeypatch):
    """No saved time or no agent escaped as a reshape ValueError; a wrong ``original`` was
    found only after the whole solve (and the automatic eta)."""
    import kinred.recovery._recover as recover_mod

    rng = np.random.default_rng(14)
    Ms = gaussian_projections(rng, 2, 4, 12)
    with pytest.raises(InvalidInput, match=r"at least one saved time and one agent, got shape \(0, 5, 4\)"):
        recover(Ms, [np.zeros((0, 5, 4))] * 2, eta=0.0)
    with pytest.raises(InvalidInput, match="at least one saved time and one agent"):
        recover(Ms, [np.zeros((3, 0, 4))] * 2)

    def solve_too_early(*args, **kwargs):
        raise AssertionError("solved before the arguments were checked")

    monkeypatch.setattr(recover_mod, "estimate_eta", solve_too_early)
    monkeypatch.setattr(recover_mod, "basis_pursuit", solve_too_early)
    Ys = [rng.standard_normal((3, 5, 4)) for _ in range(2)]
    for eta in ("auto", 0.1, np.full((3, 5), 0.1)):
        with pytest.raises(InvalidInput, match=r"original must have shape \(3, 5, 12\)"):
            recover(Ms, Ys, eta=eta, original=np.zeros((3, 5, 11)))
    with pytest.raises(InvalidInput, match="eta must be >= 0"):      # eta is still checked first
        recover(Ms, Ys, eta=-1.0, original=np.zeros((3, 5, 11)))
    with pytest.raises(InvalidInput, match=r"eta must be >= 0, got -1.0 at index 7"):
        recover(Ms, Ys, eta=np.where(np.arange(15).reshape(3, 5) == 7, -1.0, 0.1))

def test_support_solve_matches_numpy_and_flags_singular():
    from kinred.recovery._kernels import support_solve
    rng = np.random.default_rng(11)
    A = rng.standard_normal((30, 50))
    AtA = A.T @ A
    idx = np.array([rng.permutation(50)[:12] for _ in range(5)])
    cnt = np.array([12, 7, 1, 12, 3])
    rhs = rng.standard_normal((5, 12, 3))
    sol, ok = support_solve(AtA, idx, cnt, rhs)
    assert ok.all()
    for t in range(5):
        k, S = cnt[t], idx[t, : cnt[t]]
        ref = np.linalg.solve(AtA[np.ix_(S, S)], rhs[t, :k])
        assert np.max(np.abs(sol[t, :k] - ref)) <= 1e-10 * np.max(np.abs(ref))
        assert np.all(sol[t, k:] == 0.0)
    # a repeated column makes the Gram matrix singular: flagged, not a wrong answer
    idx[1, 1] = idx[1, 0]
    sol, ok = support_solve(AtA, idx, cnt, rhs)
    assert not ok[1] and ok[[0, 2, 3, 4]].all()


def test_chunked_threads_give_the_same_solutions(monkeypatch):
    """Rows are independent problems: the chunked iteration over two threads gives what one
    thread and what one single chunk give, bit for bit (reproducible whatever the threads)."""
    import kinred.recovery._sweep as sweep
    from kinred._parallel import num_threads

    rng = np.random.default_rng(5)
    Ms = gaussian_projections(rng, 6, 20, 200)
    X = sparse_columns(rng, 200, 40, 300)
    Y = stack_projections(Ms) @ X
    assert -(-X.shape[1] // sweep._CHUNK_ROWS) == 3     # the first sweeps: 3 chunks, 2 threads
    with num_threads(2):
        chunked = basis_pursuit(Ms, Y)
    with num_threads(1):
        one_thread = basis_pursuit(Ms, Y)
    monkeypatch.setattr(sweep, "_CHUNK_ROWS", 10**6)
    one_chunk = basis_pursuit(Ms, Y)
    for other in (one_thread, one_chunk):
        assert np.array_equal(chunked.status, other.status)
        assert np.array_equal(chunked.iterations, other.iterations)
        assert np.array_equal(chunked.Z, other.Z)


def test_iterates_and_residuals_match_a_plain_unrotated_admm():
    """Ten iterations of the solver (no polish) against the textbook form of the same ADMM in
    the original coordinates: ``w = (I + ÂÂᵀ)⁻¹(b − Âa)``, ``z = a + Âᵀw``, and the residuals of
    Boyd et al. §3.3 (``r = ‖(z − u, Âz − v)‖``, ``s = μ‖Δu + ÂᵀΔv‖``). Catches an error in the
    rotated iteration or in the residuals computed inside the chunks."""
    from kinred.recovery._kernels import admm_step_numpy

    rng = np.random.default_rng(9)
    m, d, tol, relax, omega = 24, 60, 1e-6, 1.6, 10.0
    A = rng.standard_normal((m, d)) / np.sqrt(m)
    X = sparse_columns(rng, d, 6, 3)
    Y = A @ X
    eta = 0.05 * np.linalg.norm(Y, axis=0)     # η > 0: v moves (for η = 0, v = y throughout)
    res = basis_pursuit(A, Y, eta, tol=tol, max_iter=10, polish=False, check_every=10)
    assert np.all(res.status == "max_iter")
    An = A * (omega / np.linalg.norm(A, 2))
    G = np.eye(m) + An @ An.T
    for j in range(Y.shape[1]):
        yn = np.linalg.norm(Y[:, j])
        y = (Y[:, j] / yn)[None, :]
        mu = np.array([omega**2 / (0.1 * np.max(np.abs(An.T @ y[0])))])
        u, p, a = (np.zeros((1, d)) for _ in range(3))
        v, q, b = (np.zeros((1, m)) for _ in range(3))
        for _ in range(10):
            w = np.linalg.solve(G, (b - a @ An.T).T).T
            z = a + w @ An
            Az = b - w
            u_old, v_old = u.copy(), v.copy()
            admm_step_numpy(z, Az, u, v, p, q, a, b, 1.0 / mu, y, np.array([eta[j] / yn]), relax,
                            False, False)
        assert np.linalg.norm(v - v_old) > 1e-6 * np.linalg.norm(v)
        r = np.sqrt(np.sum((z - u) ** 2) + np.sum((Az - v) ** 2))
        s = mu[0] * np.linalg.norm((u - u_old) + (v - v_old) @ An)
        eps_p = np.sqrt(d + m) * 1e-2 + max(np.sqrt(np.sum(z**2) + np.sum(Az**2)),
                                            np.sqrt(np.sum(u**2) + np.sum(v**2)))
        eps_d = np.sqrt(d) * 1e-2 + mu[0] * np.linalg.norm(p + q @ An)
        scale = yn * omega / np.linalg.norm(A, 2)
        assert np.allclose(res.Z[:, j], u[0] * scale, rtol=1e-9, atol=1e-12 * scale)
        assert res.primal_residual[j] == pytest.approx(r / eps_p, rel=1e-8)
        assert res.dual_residual[j] == pytest.approx(s / eps_d, rel=1e-8)
