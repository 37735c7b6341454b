"""RandomBatch's fused Euler step (RandomBatch.euler_step, used by simulate's Euler loop):
the state after each step equals the unfused step (the right-hand side, then the update),
bit for bit when every target has at most one local effect, for first- and second-order
scenes, weights, N not divisible by p and any thread count; the moments it gives equal the
observables of the saved state; the compiled kernel equals its numpy twin; bad input."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale, Drift,
                             Morse, Scene, SelfPropulsion)
from kinred._parallel import num_threads
from kinred.errors import InvalidInput
from kinred.integrate import VectorField, simulate
from kinred.integrate import _save, _simulate, _solvers
from kinred.observables import gamma, lambda_
from kinred.pairsum import RandomBatch
from kinred.pairsum import _rbm_kernels

SECOND = [Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.2)),
          Alignment(CuckerSmale(0.5, 1.5), on="v"), SelfPropulsion(1.0, 0.5)]
FIRST = [Aggregation(Morse(0.5, 2.0, 1.0, 0.5, soft=0.1))]
EULER_STEP = VectorField.euler_step


def _data(n, d, order, seed=0, offset=0.0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(0, 1, (n, d)) + offset,
            rng.uniform(-1, 1, (n, d)) if order == 2 else None)


def _runs(scene, x0, v0, monkeypatch, steps=6, h=0.01, seed=3):
    """``(fused, unfused)`` trajectories of simulate's Euler loop (the fused loop forced at
    any size), and the number of fused steps taken."""
    calls = []
    step = EULER_STEP

    def counted(self, *args):
        got = step(self, *args)
        calls.append(got is not None)
        return got
    monkeypatch.setattr(_simulate, "FUSED_MIN", 0)        # the fused loop ...
    monkeypatch.setattr(_save, "FUSED_MIN", 0)            # ... and Γ, Λ from its sums
    monkeypatch.setattr(_solvers.VectorField, "euler_step", counted)
    fused = simulate(scene, x0, v0, (0.0, steps * h), h, seed=seed)
    monkeypatch.setattr(_solvers.VectorField, "euler_step", lambda self, *a: None)
    plain = simulate(scene, x0, v0, (0.0, steps * h), h, seed=seed)
    return fused, plain, sum(calls)


@pytest.mark.parametrize("effects,order", [
    (SECOND[:1], 2), (SECOND, 2), (FIRST, 1), (FIRST + [Aggregation(Morse(soft=0.3))], 1),
    # several local effects on one target, added in the scene's order
    (SECOND + [Drift([0.3, -1.7, 2.9])], 2), (FIRST + [Drift([0.1, 0.2, -0.3])], 1),
    (FIRST + [Drift([0.1, 0.2, -0.3]), Drift([1e-3, 7.0, -0.01])], 1)])
@pytest.mark.parametrize("n,p,block", [(41, 4, None), (37, 3, 5), (50, 7, 11), (2, 2, None)])
def test_fused_steps_equal_the_right_hand_side_and_update_bitwise(effects, order, n, p, block,
                                                                  monkeypatch):
    x0, v0 = _data(n, 3, order, seed=n, offset=40.0)
    w = np.random.default_rng(1).uniform(0.5, 2.0, n)
    for weights in (None, w / w.sum()):
        sc = Scene(effects, "mean", weights=weights, pairsum=RandomBatch(p=p, block=block))
        fused, plain, taken = _runs(sc, x0, v0, monkeypatch)
        assert taken == 6 and fused.n_rhs_evals == plain.n_rhs_evals == 6
        assert np.array_equal(fused.x, plain.x)
        if order == 2:
            assert np.array_equal(fused.v, plain.v)
        for name, vals in plain.observables.items():
            assert np.allclose(fused.observables[name], vals, rtol=1e-12, atol=0.0), name


def test_thread_counts_give_the_same_states_and_moments(monkeypatch):
    """The pieces are dealt to threads in runs; the moments are summed in the pieces' order:
    one thread and two give the same bits, states and the moments the loop records."""
    n, d = 3001, 5
    x0, v0 = _data(n, d, 2, seed=5)
    monkeypatch.setattr(_simulate, "FUSED_MIN", 0)
    monkeypatch.setattr(_save, "FUSED_MIN", 0)
    from kinred.pairsum import _rbm_step
    monkeypatch.setattr(_rbm_step, "PIECE_BYTES", 512)      # many pieces
    out = {}
    for threads in (1, 2):
        with num_threads(threads):
            sc = Scene(SECOND, "mean", pairsum=RandomBatch(p=3, block=100))
            out[threads] = simulate(sc, x0, v0, (0.0, 0.05), 0.01, seed=11)
    a, b = out[1], out[2]
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    for name in a.observables:
        assert np.array_equal(a.observables[name], b.observables[name]), name


def test_moments_of_the_fused_step_are_the_observables_of_the_state():
    """The row sums euler_step returns give Γ and Λ of the new state: equal to
    kinred.observables on the state itself (positions in a frame shifted by 1e3, whose
    shift the moments add back), to 1e-12."""
    from kinred.integrate import _kernels
    n, d = 2000, 4
    x, v = _data(n, d, 2, seed=2, offset=1e3)
    w = np.random.default_rng(4).uniform(0.5, 1.5, n)
    w /= w.sum()
    f = VectorField(Scene(SECOND, "mean", weights=w, pairsum=RandomBatch(p=5)))
    shift = np.full(d, 1e3)
    x -= shift
    mx, mv = _kernels.Moments(w, shift), _kernels.Moments(w, None)
    got = _kernels.step_moments(
        x, v, w, shift, [mx.ready(x), mv.ready(v)],
        lambda sh, c: f.euler_step(0.0, x, v, 0.01, np.random.default_rng(0), w, sh, c))
    assert f.n_evals == 1
    assert got[0][0] == pytest.approx(lambda_(x + shift, w), rel=1e-12)
    assert got[1][0] == pytest.approx(gamma(v, w), rel=1e-12)
    assert got[1][1] == pytest.approx(float(np.sum(w[:, None] * v * v)), rel=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_compiled_fused_step_equals_its_numpy_twin(order):
    n, d, p = 53, 3, 4
    rng = np.random.default_rng(7)
    x = rng.uniform(0, 1, (n, d))
    v = rng.uniform(-1, 1, (n, d)) if order == 2 else None
    effects = SECOND if order == 2 else FIRST
    sc = Scene(effects, "sum", pairsum=RandomBatch(p=p))
    plan = sc._plan(n, d)
    locx = () if order == 2 else (rng.normal(size=(n, d)), rng.normal(size=(n, d)))
    locv = (rng.normal(size=(n, d)),) if order == 2 else ()
    perm = np.random.default_rng(5).permutation(n)
    terms = [(t.kernel, t.source, t.carrier, t.target) for t in plan.terms.terms]
    tx, tv = _rbm_kernels.batch_euler_numpy(x, v, plan.cs, perm, p, terms, 0.01, locx, locv)
    xs, vs = x.copy(), (None if v is None else v.copy())
    k = 1 if v is None else 2
    r, acc = RandomBatch(p=p).euler_step(plan, xs, vs, 0.01, np.random.default_rng(5),
                                         (locx, locv), np.full(n, 1.0), np.zeros((k, d)),
                                         np.zeros((k, d)))
    assert np.allclose(xs, tx, rtol=1e-13, atol=1e-15)
    if order == 2:
        assert np.allclose(vs, tv, rtol=1e-13, atol=1e-15)
    # the sums about 0 with unit weights: Σ a and Σ‖a‖² of the new state
    assert np.allclose(r[0], xs.sum(axis=0), rtol=1e-12)
    assert acc[0, 1] == pytest.approx(float(np.sum(xs * xs)), rel=1e-12)
    assert acc[0, 3] == n


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(2, 60), p=st.integers(2, 9), d=st.integers(1, 4),
       offset=st.sampled_from([0.0, -3.0, 1e4]), seed=st.integers(0, 2**16))
def test_fused_equals_unfused_on_random_scenes(n, p, d, offset, seed):
    p = min(p, n)
    x0, v0 = _data(n, d, 2, seed=seed, offset=offset)
    sc = Scene(SECOND[:2], "mean", pairsum=RandomBatch(p=p))
    mp = pytest.MonkeyPatch()
    try:
        fused, plain, taken = _runs(sc, x0, v0, mp, steps=3)
    finally:
        mp.undo()
    assert taken == 3
    assert np.array_equal(fused.x, plain.x) and np.array_equal(fused.v, plain.v)


def test_dense_and_lone_agents_take_the_unfused_step(monkeypatch):
    """No fused step where the backend has none (Dense) or there is no pair to sum (N = 1)."""
    x0, v0 = _data(30, 2, 2)
    _, _, taken = _runs(Scene(SECOND, "mean"), x0, v0, monkeypatch)
    assert taken == 0
    _, _, taken = _runs(Scene(SECOND, "mean", pairsum=RandomBatch(p=2)), x0[:1], v0[:1],
                        monkeypatch)
    assert taken == 0


def test_bad_input():
    """Every argument of RandomBatch.euler_step is checked before the state is touched: an
    InvalidInput naming it (no numba TypingError, no read past an array's end)."""
    n, d = 10, 2
    x, v = _data(n, d, 2)
    x0, v0 = x.copy(), v.copy()
    sc = Scene(SECOND, "mean", pairsum=RandomBatch(p=2))
    plan = sc._plan(n, d)
    rb, gen, w, z = RandomBatch(p=2), np.random.default_rng(0), np.ones(n), np.zeros((2, d))
    none = ((), ())
    cases = [
        ("RandomBatchPlan", (object(), x, v, 0.1, gen, none, w, z, z)),
        ("generator", (plan, x, v, 0.1, None, none, w, z, z)),
        ("h", (plan, x, v, float("nan"), gen, none, w, z, z)),
        ("h", (plan, x, v, "a", gen, none, w, z, z)),
        ("h", (plan, x, v, None, gen, none, w, z, z)),
        ("v must be given", (plan, x, None, 0.1, gen, none, w, z, z)),
        ("local must be a pair", (plan, x, v, 0.1, gen, None, w, z, z)),
        ("local must be a pair", (plan, x, v, 0.1, gen, ((),), w, z, z)),
        ("local v drift 0 must be a C-contiguous float64",
         (plan, x, v, 0.1, gen, ((), (np.ones((n, d), np.float32),)), w, z, z)),
        ("x must be a C-contiguous", (plan, np.asfortranarray(x), v, 0.1, gen, none, w, z, z)),
        ("x must be a C-contiguous", (plan, [[0.0] * d] * n, v, 0.1, gen, none, w, z, z)),
        ("x must be .* of shape", (plan, x[:5].copy(), v, 0.1, gen, none, w, z, z)),
        ("w", (plan, x, v, 0.1, gen, none, w[:5], z, z)),
        ("w", (plan, x, v, 0.1, gen, none, np.ones((n, 1)), z, z)),
        ("shift", (plan, x, v, 0.1, gen, none, w, z[:1], z)),
        ("shift", (plan, x, v, 0.1, gen, none, w, np.zeros(d), z)),
        ("centres", (plan, x, v, 0.1, gen, none, w, z, np.zeros((2, 1)))),
        ("x shares memory with v", (plan, x, x, 0.1, gen, none, w, z, z)),
        ("v shares memory with local v drift 0", (plan, x, v, 0.1, gen, ((), (v,)), w, z, z)),
    ]
    for match, args in cases:
        with pytest.raises(InvalidInput, match=match):
            rb.euler_step(*args)
    ro = v.copy()
    ro.flags.writeable = False
    with pytest.raises(InvalidInput, match="v must be .*writeable"):
        rb.euler_step(plan, x, ro, 0.1, gen, none, w, z, z)
    first = Scene(FIRST, "mean", pairsum=RandomBatch(p=2))._plan(n, d)
    with pytest.raises(InvalidInput, match="v must be None"):
        rb.euler_step(first, x, v, 0.1, gen, none, w, z, z)
    assert np.array_equal(x, x0) and np.array_equal(v, v0)        # nothing was stepped


def test_warnings_of_a_local_drift_reach_the_caller_on_the_fused_path(monkeypatch):
    """The fused step does not hide the floating-point warnings of the scene's own drifts
    (numpy's error state is the caller's, as on the unfused path)."""
    from kinred.dynamics import Field
    x0, v0 = _data(30, 2, 2)
    sc = Scene(SECOND[:1] + [Field(lambda t, x, v: np.log(x - x))], "mean",
               pairsum=RandomBatch(p=3))
    monkeypatch.setattr(_simulate, "FUSED_MIN", 0)
    with np.errstate(divide="raise"), pytest.raises(FloatingPointError):
        simulate(sc, x0, v0, (0.0, 0.02), 0.01, seed=1)
