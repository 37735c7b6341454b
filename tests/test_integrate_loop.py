"""The cost of ``simulate``'s own loop (issue 24, item 5) and its step-size controller
argument (issue 23): the compiled kernels of the loop against their numpy twins, the loop's
calls per step, the fused observables against :mod:`kinred.observables`, and
``stepsize_controller=`` against today's ``dt``/tolerance paths, bit for bit."""

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import kinred.observables as obs
from kinred.dynamics import (Alignment, CuckerSmale, Drift, Scene, SelfPropulsion,
                             get_num_threads, set_num_threads)
from kinred.errors import InvalidInput
from kinred.integrate import AdaptiveStep, ConstantStep, SaveAt, simulate
from kinred.integrate import _kernels
from kinred.integrate._save import FUSED_MIN
from kinred.pairsum import RandomBatch


class num_threads:
    """The engine's thread count for a ``with`` block."""

    def __init__(self, n):
        self.n, self.old = n, get_num_threads()

    def __enter__(self):
        set_num_threads(self.n)

    def __exit__(self, *exc):
        set_num_threads(self.old)


def _rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


# ------------------------------------------------------------------ kernels against twins

@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 700), d=st.integers(1, 9), offset=st.sampled_from([0.0, 1.0, 1e6]),
       spread=st.sampled_from([1e-9, 1.0, 1e3]), weighted=st.booleans(),
       shifted=st.booleans(), centre=st.sampled_from(["zero", "near", "far"]),
       seed=st.integers(0, 2**16))
def test_moments_kernel_equals_its_numpy_twin(n, d, offset, spread, weighted, shifted, centre,
                                              seed):
    rng = np.random.default_rng(seed)
    z = offset + spread * rng.normal(size=(n, d))
    w = rng.dirichlet(np.ones(n)) if weighted else np.full(n, 1.0 / n)
    shift = rng.normal(size=d) * 10.0 if shifted else None
    zt = z if shift is None else z + shift
    # the reference centre: 0, near the mean (one sweep), or far from it (two sweeps)
    c = {"zero": np.zeros(d), "near": w @ zt + 1e-3 * spread * rng.normal(size=d),
         "far": w @ zt + 1e3 * spread * rng.normal(size=d)}[centre]
    out = np.empty(3)
    _kernels.moments(z, w, np.zeros(d) if shift is None else shift, c, out)
    ref = _kernels.moments_numpy(z, w, shift)
    # the centre is updated to the weighted mean
    assert np.allclose(c, w @ zt, rtol=1e-12, atol=1e-9 * spread)
    # the fluctuation: relative to itself (compensated centre, no cancellation), or, where it
    # is round-off of the coordinates (n = 1, tiny spread far out), within that round-off
    floor = 64 * np.finfo(float).eps ** 2 * float(np.max(zt * zt))
    assert abs(out[0] - ref[0]) <= 1e-12 * ref[0] + floor
    assert _rel(out[1], ref[1]) <= 1e-12
    assert abs(out[2] - ref[2]) <= 1e-12 * float(np.sum(np.abs(zt)))
    # ... and the twin is kinred.observables' Γ / Λ
    assert ref[0] == pytest.approx(obs.fluctuation(zt, w), rel=1e-12, abs=floor)


def test_moments_kernel_propagates_non_finite_values():
    z = np.ones((300, 3))
    w = np.full(300, 1 / 300)
    for bad in (np.nan, np.inf, 1e300):
        z[17, 1] = bad
        f, s, t = _kernels.state_moments(z, w)
        assert not np.isfinite(s) and (not np.isfinite(t) or bad == 1e300)


def test_split_rows_give_the_twin_whatever_the_threads():
    n, d = 4100, 256                       # above SPLIT_MIN: two row halves
    assert n * d >= _kernels.SPLIT_MIN and len(_kernels._halves(n, d)) == 2
    rng = np.random.default_rng(8)
    z, w, shift = rng.normal(size=(n, d)) + 7.0, rng.dirichlet(np.ones(n)), rng.normal(size=d)
    ref = _kernels.moments_numpy(z, w, shift)
    got = {}
    for threads in (1, 2):
        with num_threads(threads):
            got[threads] = _kernels.state_moments(z, w, shift)
            x, v, dv = z.copy(), z[::-1].copy(), rng.normal(size=(n, d))
            x2, v2 = x.copy(), v.copy()
            _kernels.euler(x, v, v, dv, 0.01)
            _kernels.euler_numpy(x2, v2, v2, dv, 0.01, np.empty_like(x))
            assert np.array_equal(x, x2) and np.array_equal(v, v2)
    assert got[1] == got[2]
    assert np.allclose(got[1], ref, rtol=1e-12, atol=0)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("alias", ["none", "dx_is_v", "dv_is_x"])
def test_euler_kernel_is_bitwise_numpys_update(order, alias):
    rng = np.random.default_rng(3)
    x, v, dx, dv = (rng.normal(size=(257, 5)) * s for s in (1.0, 3.0, 1e-3, 7.0))
    a = [x.copy(), v.copy(), dx.copy(), dv.copy()]
    b = [x.copy(), v.copy(), dx.copy(), dv.copy()]
    for arr in (a, b):
        if alias == "dx_is_v":
            arr[2] = arr[1]
        elif alias == "dv_is_x":
            arr[3] = arr[0]
    h = 0.0123
    if order == 1:
        _kernels.euler_one(a[0], a[2], h)
        _kernels.euler_numpy(b[0], b[2], None, None, h, np.empty_like(x))
    else:
        _kernels.euler_pair(a[0], a[2], a[1], a[3], h)
        _kernels.euler_numpy(b[0], b[2], b[1], b[3], h, np.empty_like(x))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


# ------------------------------------------------------------------ the loop's own cost

def _large_run(n=2048, d=128, steps=10, **kw):
    assert n * d >= FUSED_MIN
    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(0, 1, (n, d)) + 5.0, rng.normal(size=(n, d))
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5))], "mean", pairsum=RandomBatch(p=4))
    return sc, x0, v0, simulate(sc, x0, v0, (0.0, steps * 1e-3), 1e-3, seed=1, **kw)


def test_default_save_at_large_n_makes_no_numpy_deviation_pass(monkeypatch):
    """Today's main computed the centred deviations of the state (an N x d temporary and four
    passes) three times per step at the default save (guard, Γ, Λ): 33 calls in 10 steps. The
    loop now takes Γ, Λ and the guard's moments from one compiled pass per array."""
    calls = []
    real = obs._deviations
    monkeypatch.setattr(obs, "_deviations", lambda z, w: calls.append(z.shape) or real(z, w))
    _large_run()
    assert calls == []


def test_fused_observables_agree_with_kinred_observables():
    sc, x0, v0, tr = _large_run(save=SaveAt(states=True))
    w = sc.agent_weights(len(x0))
    for j in (0, len(tr.t) - 1):
        assert _rel(tr.observables["gamma"][j], obs.gamma(tr.v[j], w)) <= 1e-12
        assert _rel(tr.observables["lambda"][j], obs.lambda_(tr.x[j], w)) <= 1e-12
    # the default save: the same values, the final state as the run left it
    default = _large_run()[3]
    assert np.array_equal(default.observables["gamma"], tr.observables["gamma"])
    assert np.array_equal(default.observables["lambda"], tr.observables["lambda"])
    assert np.array_equal(default.x[-1], tr.x[-1]) and np.array_equal(default.v[-1], tr.v[-1])


def test_small_runs_record_kinred_observables_bit_for_bit():
    rng = np.random.default_rng(4)
    x0, v0 = rng.uniform(0, 1, (40, 3)) + 100.0, rng.normal(size=(40, 3))
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5)), Drift([0.1, 0.0, 0.0])], "mean")
    tr = simulate(sc, x0, v0, (0.0, 0.5), 0.05, save=SaveAt(states=True))
    assert list(tr.observables["gamma"]) == [obs.gamma(v) for v in tr.v]
    assert list(tr.observables["lambda"]) == [obs.lambda_(x) for x in tr.x]


@pytest.mark.parametrize("steps", [1, 10])
def test_the_loop_holds_no_state_sized_temporaries(steps):
    """Peak memory of a run (numpy's allocations, tracemalloc) in states ``N·d·8`` bytes: the
    working ``x`` and ``v`` and the drift's ``dv`` (3), whatever the number of steps. Today's
    main peaked at 5 (``x + shift`` for the recorder, the centred deviations of Γ and Λ)."""
    n, d = 2048, 128
    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(0, 1, (n, d)) + 5.0, rng.normal(size=(n, d))
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5))], "mean", pairsum=RandomBatch(p=4))
    simulate(sc, x0, v0, (0.0, steps * 1e-3), 1e-3, seed=1)          # compile, plan
    tracemalloc.start()
    try:
        tr = simulate(sc, x0, v0, (0.0, steps * 1e-3), 1e-3, seed=1)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    state = 8 * n * d
    assert tr.n_steps == steps and 2.0 <= kept / state < 2.1       # the final (x, v)
    assert peak / state < 3.5, peak / state


# ------------------------------------------------------------------ stepsize_controller

def _scene_state():
    rng = np.random.default_rng(5)
    x0, v0 = rng.uniform(0, 1, (30, 2)), rng.normal(size=(30, 2))
    return Scene([Alignment(CuckerSmale(1.0, 0.5)), SelfPropulsion(0.5, 0.3)], "mean"), x0, v0


def _same(a, b):
    assert np.array_equal(a.t, b.t) and a.n_steps == b.n_steps
    assert a.n_rejected == b.n_rejected and a.n_rhs_evals == b.n_rhs_evals
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)
    for k in a.observables:
        assert np.array_equal(a.observables[k], b.observables[k])


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_constant_step_controller_is_the_dt_path(method):
    sc, x0, v0 = _scene_state()
    save = SaveAt(every=3, states=True)
    ref = simulate(sc, x0, v0, (0.0, 1.2), 0.04, method=method, save=save)
    got = simulate(sc, x0, v0, (0.0, 1.2), 0.04, method=method, save=save,
                   stepsize_controller=ConstantStep())
    _same(got, ref)


def test_adaptive_controller_is_the_tolerance_path():
    sc, x0, v0 = _scene_state()
    save = SaveAt(t=[0.0, 2.0], states=True)
    ref = simulate(sc, x0, v0, (0.0, 2.0), 0.1, method="rk45", rtol=1e-9, atol=1e-12,
                   max_steps=5000, save=save)
    got = simulate(sc, x0, v0, (0.0, 2.0), 0.1, method="rk45", save=save,
                   stepsize_controller=AdaptiveStep(rtol=1e-9, atol=1e-12, max_steps=5000))
    _same(got, ref)
    assert ref.n_steps > 20            # the controller did choose the steps
    # a looser controller takes other steps: the argument is used
    loose = simulate(sc, x0, v0, (0.0, 2.0), 0.1, method="rk45", save=save,
                     stepsize_controller=AdaptiveStep(rtol=1e-3, atol=1e-6))
    assert loose.n_steps < ref.n_steps


def test_constant_step_runs_an_adaptive_pair_at_fixed_steps():
    sc, x0, v0 = _scene_state()
    tr = simulate(sc, x0, v0, (0.0, 1.0), 0.05, method="rk45",
                  stepsize_controller=ConstantStep())
    assert tr.n_steps == 20 and tr.n_rejected == 0 and np.allclose(np.diff(tr.t), 0.05)


@pytest.mark.parametrize("kw, words", [
    (dict(stepsize_controller="adaptive"), ["stepsize_controller", "'adaptive'", "ConstantStep"]),
    (dict(stepsize_controller=AdaptiveStep()), ["method='euler'", "error estimate", "'rk45'"]),
    (dict(stepsize_controller=AdaptiveStep(), method="rk45", rtol=1e-3),
     ["rtol=0.001", "AdaptiveStep(...)"]),
    (dict(stepsize_controller=ConstantStep(), max_steps=10), ["max_steps=10", "no tolerances"]),
])
def test_stepsize_controller_conflicts_are_named(kw, words):
    sc, x0, v0 = _scene_state()
    with pytest.raises(InvalidInput) as e:
        simulate(sc, x0, v0, (0.0, 1.0), 0.05, **kw)
    for word in words:
        assert word in str(e.value)
