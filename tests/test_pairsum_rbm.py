"""The random batch pair-sum backend (kinred.pairsum.RandomBatch): the numpy twin for a fixed
permutation, exactness at p = N, unbiasedness of the batch field (weights, both
normalizations, p not dividing N), momentum conservation, reproducibility by seed and across
thread counts, the convergence law O(√(h/(p − 1))) and bad input."""

import numpy as np
import pytest

from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale, Morse,
                             Quadratic, Scene, SelfPropulsion)
from kinred._parallel import num_threads
from kinred.errors import InvalidInput, KinredError
from kinred.pairsum import Dense, RandomBatch, as_pairsum
from kinred.pairsum import _rbm_kernels
from kinred.pairsum.random_batch import pair_probability

EFFECTS = [Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.2)),
           Alignment(CuckerSmale(0.5, 1.5), on="v"), SelfPropulsion(1.0, 0.5)]


def _data(n, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (n, d)), rng.uniform(-1, 1, (n, d))


def _scene(pairsum, normalize="sum", weights=None, effects=EFFECTS):
    return Scene(effects, normalize, weights=weights, pairsum=pairsum)


def _twin(scene, plan, x, v, perm):
    """The numpy twin of the backend's output for the permutation ``perm``."""
    state = {"x": x, "v": v}
    out = {}
    for t in scene.pair_terms.terms:
        f = _rbm_kernels.batch_field_numpy(state[t.source], state[t.carrier], plan.cs, perm,
                                           plan.p, t.kernel)
        out[t.target] = out[t.target] + f if t.target in out else f
    return out


@pytest.mark.parametrize("n, p, block", [(23, 4, 7), (24, 4, 65536), (9, 2, 1), (10, 10, 3),
                                         (31, 6, 20)])
@pytest.mark.parametrize("normalize", ["sum", "mean"])
def test_compiled_kernels_equal_the_numpy_twin_for_a_fixed_permutation(n, p, block, normalize):
    x, v = _data(n, 3, seed=n)
    w = np.random.default_rng(1).dirichlet(np.ones(n))
    rb = RandomBatch(p=p, block=block)
    sc = _scene(rb, normalize, w)
    plan = rb.plan(sc, n, 3)
    got = rb.evaluate(plan, x, v, np.random.default_rng(11))
    ref = _twin(sc, plan, x, v, np.random.default_rng(11).permutation(n))
    assert sorted(got) == sorted(ref) == ["v"]
    scale = np.max(np.abs(ref["v"]))
    assert scale > 0
    assert np.max(np.abs(got["v"] - ref["v"])) <= 1e-12 * scale


def test_first_order_scene_and_a_plain_callable_kernel_equal_the_twin():
    x, _ = _data(17, 2, seed=4)
    eff = [Aggregation(Quadratic()), Aggregation(lambda s: np.exp(-s))]
    rb = RandomBatch(p=3)
    sc = _scene(rb, "mean", effects=eff)
    plan = rb.plan(sc, 17, 2)
    got = rb.evaluate(plan, x, None, np.random.default_rng(3))
    ref = _twin(sc, plan, x, None, np.random.default_rng(3).permutation(17))
    assert np.max(np.abs(got["x"] - ref["x"])) <= 1e-12 * np.max(np.abs(ref["x"]))


@pytest.mark.parametrize("normalize", ["sum", "mean"])
def test_one_batch_of_all_agents_is_the_exact_pair_sum(normalize):
    n = 19
    x, v = _data(n, 4, seed=2)
    w = np.random.default_rng(5).dirichlet(np.ones(n))
    got = _scene(RandomBatch(p=n), normalize, w).rhs(x, v, rng=np.random.default_rng(0))
    ref = _scene(Dense(), normalize, w).rhs(x, v)
    for g, r in zip(got, ref):
        assert np.max(np.abs(g - r)) <= 1e-12 * np.max(np.abs(r))


def test_pair_probability_is_the_frequency_of_sharing_a_batch():
    # closed form against counting over random permutations (n = 7, p = 3: batches 3, 3, 1)
    n, p = 7, 3
    q = pair_probability(n, p)
    assert q == (2 * 3 * 2 + 0) / (7 * 6)
    rng = np.random.default_rng(0)
    together = np.zeros((n, n))
    reps = 20000
    for _ in range(reps):
        perm = rng.permutation(n)
        i, j = _rbm_kernels.batch_pairs_numpy(perm, p)
        together[i, j] += 1
        together[j, i] += 1
    off = together[~np.eye(n, dtype=bool)] / reps
    se = np.sqrt(q * (1 - q) / reps)
    assert np.all(np.abs(off - q) <= 5 * se)
    assert pair_probability(12, 4) == 3 / 11                # p | N: (p − 1)/(N − 1)


@pytest.mark.parametrize("normalize, n, p", [("sum", 13, 4), ("mean", 13, 5), ("sum", 12, 3),
                                             ("mean", 11, 2)])
def test_the_batch_field_is_an_unbiased_estimate_of_the_dense_field(normalize, n, p):
    """Mean of the batch field over many seeds equals Dense to Monte-Carlo error (weights,
    attraction-repulsion and alignment terms, p not dividing N); with the plain
    (N − 1)/(p − 1) rescaling, the same criterion rejects the mean when p ∤ N."""
    x, v = _data(n, 2, seed=7)
    w = np.random.default_rng(8).dirichlet(np.ones(n) * 0.7)
    rb = RandomBatch(p=p)
    sc = _scene(rb, normalize, w)
    plan = rb.plan(sc, n, 2)
    dense = Dense().evaluate(Dense().plan(sc, n, 2), x, v)["v"]
    S = 4000
    rng = np.random.default_rng(123)
    draws = np.stack([rb.evaluate(plan, x, v, rng)["v"] for _ in range(S)])
    mean = draws.mean(axis=0)
    se = draws.std(axis=0, ddof=1) / np.sqrt(S)

    def accepted(m):
        z = (m - dense) / se
        K = z.size
        return np.max(np.abs(z)) <= 4.5 and np.sum(z * z) <= K + 5 * np.sqrt(2 * K)

    assert np.all(se > 0)
    assert accepted(mean)
    naive = mean * plan.q / ((p - 1) / (n - 1))          # Jin–Li–Liu's factor, p | N only
    assert accepted(naive) == (n % p == 0)


@pytest.mark.parametrize("weights", [None, "dirichlet"])
def test_alignment_conserves_the_weighted_momentum_exactly(weights):
    """Pair updates are equal and opposite in weighted form: Σᵢ wᵢ (batch field)ᵢ = 0."""
    n = 50
    x, v = _data(n, 3, seed=9)
    w = None if weights is None else np.random.default_rng(1).dirichlet(np.ones(n))
    sc = _scene(RandomBatch(p=3), "mean", w, effects=[Alignment(CuckerSmale(1.0, 0.5))])
    ww = np.full(n, 1 / n) if w is None else w
    rng = np.random.default_rng(0)
    m0 = ww @ v
    for _ in range(20):
        dv = sc.rhs(x, v, rng=rng)[1]
        assert np.max(np.abs(ww @ dv)) <= 1e-15 * np.max(np.abs(dv))
        x, v = x + 0.05 * v, v + 0.05 * dv
    assert np.max(np.abs(ww @ v - m0)) <= 1e-14


def _euler(scene, x, v, h, steps, rng):
    for _ in range(steps):
        dx, dv = scene.rhs(x, v, rng=rng)
        x, v = x + h * dx, v + h * dv
    return x, v


def _euler_dense(scene, x, v, h, steps):
    for _ in range(steps):
        dx, dv = scene.rhs(x, v)
        x, v = x + h * dx, v + h * dv
    return x, v


def test_same_seed_same_trajectory_bitwise_across_thread_counts_and_chunks():
    n = 401
    x0, v0 = _data(n, 3, seed=3)
    runs = {}
    for threads in (1, 2):
        with num_threads(threads):
            sc = _scene(RandomBatch(p=4, block=37), "mean")     # 401/4: many chunks
            assert len(sc._plan(n, 3).groups) == threads
            runs[threads] = _euler(sc, x0, v0, 0.02, 15, np.random.default_rng(2024))
    assert np.array_equal(runs[1][0], runs[2][0]) and np.array_equal(runs[1][1], runs[2][1])
    again = _euler(_scene(RandomBatch(p=4, block=37), "mean"), x0, v0, 0.02, 15,
                   np.random.default_rng(2024))
    assert np.array_equal(again[1], runs[1][1])
    other = _euler(_scene(RandomBatch(p=4, block=37), "mean"), x0, v0, 0.02, 15,
                   np.random.default_rng(2025))
    assert not np.allclose(other[1], runs[1][1])
    # the chunking changes nothing either (same partition, same per-agent order)
    one_chunk = _euler(_scene(RandomBatch(p=4), "mean"), x0, v0, 0.02, 15,
                       np.random.default_rng(2024))
    assert np.max(np.abs(one_chunk[1] - runs[1][1])) <= 1e-13


def test_the_error_to_dense_follows_sqrt_h_over_p_minus_one():
    """RMS trajectory error (over seeds) of RBM-1 + Euler against Dense + Euler at the same
    step, Cucker–Smale alignment, N = 160: log-log slope in h/(p − 1) is 1/2."""
    n, T = 160, 1.0
    x0, v0 = _data(n, 2, seed=31)
    eff = [Alignment(CuckerSmale(1.0, 0.5))]
    dense_sc = _scene(Dense(), "mean", effects=eff)
    xs, errs = [], []
    for h in (0.1, 0.05, 0.025, 0.0125):
        steps = int(round(T / h))
        xd, vd = _euler_dense(dense_sc, x0, v0, h, steps)
        for p in (2, 3, 5, 9):
            sc = _scene(RandomBatch(p=p), "mean", effects=eff)
            sq = []
            for seed in range(6):
                xr, vr = _euler(sc, x0, v0, h, steps, np.random.default_rng(seed))
                sq.append(np.mean(np.sum((xr - xd) ** 2 + (vr - vd) ** 2, axis=1)))
            xs.append(h / (p - 1))
            errs.append(np.sqrt(np.mean(sq)))
    slope, icpt = np.polyfit(np.log(xs), np.log(errs), 1)
    resid = np.log(errs) - (slope * np.log(xs) + icpt)
    assert abs(slope - 0.5) <= 0.05, slope          # measured 0.506 (0.512 on other data)
    assert np.max(np.abs(resid)) <= 0.12            # measured 0.025


def test_attraction_repulsion_error_shrinks_with_the_batch_size():
    """D'Orsogna scene (self-propulsion + soft Morse): RMS error to Dense decreases with p
    and vanishes at p = N."""
    n = 60
    x0, v0 = _data(n, 2, seed=5)
    eff = [SelfPropulsion(1.0, 0.5), AttractionRepulsion(Morse(soft=0.2))]
    xd, vd = _euler_dense(_scene(Dense(), "mean", effects=eff), x0, v0, 0.02, 50)
    err = {}
    for p in (2, 6, 30, n):
        sc = _scene(RandomBatch(p=p), "mean", effects=eff)
        err[p] = np.sqrt(np.mean([np.mean((_euler(sc, x0, v0, 0.02, 50,
                                                   np.random.default_rng(s))[0] - xd) ** 2)
                                  for s in range(4)]))
    assert err[2] > err[6] > err[30] > 0
    assert err[n] <= 1e-12


@pytest.mark.parametrize("n, p, block", [(23, 4, 7), (25, 4, 65536), (9, 2, 1), (31, 6, 20)])
def test_out_arrays_are_overwritten_with_the_fresh_values_bitwise(n, p, block):
    """``evaluate(..., out=...)`` (reused arrays holding garbage, including N mod p = 1: a lone
    agent with no pair) returns ``out``'s arrays holding exactly the fresh result."""
    x, v = _data(n, 3, seed=n)
    rb = RandomBatch(p=p, block=block)
    for sc, vv in ((_scene(rb, "mean"), v),
                   (_scene(rb, "sum", effects=[Aggregation(Quadratic()),
                                               Aggregation(lambda s: np.exp(-s))]), None)):
        plan = rb.plan(sc, n, 3)
        fresh = rb.evaluate(plan, x, vv, np.random.default_rng(5))
        out = {t: np.full((n, 3), np.nan) for t in fresh}
        got = rb.evaluate(plan, x, vv, np.random.default_rng(5), out=out)
        twin = _twin(sc, plan, x, vv, np.random.default_rng(5).permutation(n))
        for t in fresh:
            assert got[t] is out[t]
            assert np.array_equal(got[t], fresh[t])
            scale = np.max(np.abs(twin[t]))
            assert np.max(np.abs(got[t] - twin[t])) <= 1e-12 * scale


def test_simulate_reuses_the_sums_arrays_and_keeps_the_trajectory():
    """simulate's Euler step takes RandomBatch's sums in arrays kept for the run
    (VectorField.transient): two calls give the same array objects, and the trajectory is
    bit-identical to a hand-written Euler loop on fresh arrays from the same generator."""
    from kinred._rng import as_generator
    from kinred.integrate import VectorField, simulate
    n, h, steps = 41, 0.01, 6
    x0, v0 = _data(n, 3, seed=9)
    sc = _scene(RandomBatch(p=4), "mean", effects=EFFECTS[:2])
    f = VectorField(sc)
    a = f.transient(0.0, x0, v0, np.random.default_rng(1))[1]
    b = f.transient(0.0, x0, v0, np.random.default_rng(1))[1]
    assert a is b and f.n_evals == 2
    assert np.array_equal(b, f(0.0, x0, v0, np.random.default_rng(1))[1])
    assert f(0.0, x0, v0, np.random.default_rng(1))[1] is not b

    class Watched(VectorField):             # a subclass that watches its calls
        calls = 0

        def __call__(self, t, x, v, rng=None):
            Watched.calls += 1
            return super().__call__(t, x, v, rng)

    g = Watched(sc)
    c = g.transient(0.0, x0, v0, np.random.default_rng(1))[1]
    assert Watched.calls == 1 and np.array_equal(c, b) and c is not b
    tr = simulate(sc, x0, v0, (0.0, steps * h), h, method="euler", seed=3)
    x, v, gen = x0.copy(), v0.copy(), as_generator(3)        # simulate's generator of seed 3
    for _ in range(steps):
        dx, dv = sc.rhs(x, v, rng=gen)
        x += h * dx
        v += h * dv
    # simulate runs in the centred frame: equal up to the round-off of the shift
    assert np.max(np.abs(tr.v[-1] - v)) <= 1e-12 * np.max(np.abs(v))
    assert np.max(np.abs(tr.x[-1] - x)) <= 1e-12 * np.max(np.abs(x))
    assert not np.allclose(tr.v[-1], simulate(sc, x0, v0, (0.0, steps * h), h,
                                              method="euler", seed=4).v[-1])


def test_bad_input():
    with pytest.raises(InvalidInput, match="p must"):
        RandomBatch(p=1)
    with pytest.raises(InvalidInput, match="p must"):
        RandomBatch(p=2.5)
    with pytest.raises(InvalidInput, match="block"):
        RandomBatch(p=2, block=0)
    x, v = _data(5, 2)
    sc = _scene(RandomBatch(p=6))
    with pytest.raises(InvalidInput, match=r"p <= N.*N = 5"):
        sc.rhs(x, v, rng=np.random.default_rng(0))
    sc = _scene(RandomBatch(p=2))
    with pytest.raises(InvalidInput, match="random generator"):
        sc.rhs(x, v)
    rb = RandomBatch(p=2)
    plan = rb.plan(sc, 5, 2)
    with pytest.raises(InvalidInput, match="random generator"):
        rb.evaluate(plan, x, v, 7)
    with pytest.raises(InvalidInput, match="RandomBatchPlan"):
        rb.evaluate(plan, x[:4], v[:4], np.random.default_rng(0))
    with pytest.raises(InvalidInput, match="RandomBatchPlan"):
        rb.evaluate(Dense().plan(sc, 5, 2), x, v, np.random.default_rng(0))
    with pytest.raises(KinredError):
        pair_probability(5, 6)
    g = np.random.default_rng(0)
    for bad in (np.empty((5, 3)), np.empty((5, 2), np.float32), np.empty((2, 5)).T,
                [[0.0] * 2] * 5):
        with pytest.raises(InvalidInput, match=r"out\['v'\] must be a writeable C-contiguous"):
            rb.evaluate(plan, x, v, g, out={"v": bad})
    with pytest.raises(InvalidInput, match=r"out\['v'\] shares memory with the state's v"):
        rb.evaluate(plan, x, v, g, out={"v": v})


def test_alias_and_repr():
    assert repr(as_pairsum("random_batch")) == "RandomBatch(p=2)"
    assert repr(RandomBatch(p=8, block=100)) == "RandomBatch(p=8, block=100)"
    sc = Scene(EFFECTS, pairsum="random_batch")
    assert isinstance(sc.pairsum, RandomBatch) and "RandomBatch(p=2)" in repr(sc)
    assert isinstance(Scene(EFFECTS, pairsum=RandomBatch(3)).project(np.eye(2, 3)).pairsum,
                      RandomBatch)
    with pytest.raises(InvalidInput, match="block= and precision="):
        Scene(EFFECTS, pairsum="random_batch", precision="mixed")
