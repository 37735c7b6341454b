"""The fused Euler pass of ``simulate`` (issue 24, item 5): forward Euler's update and the
moments of the new state (the guard's ``Γ``, the recorded ``Γ`` and ``Λ``, the finiteness
test) from one compiled pass per step, against its numpy twin, against the unfused loop, and
the number of passes a run makes."""

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinred.dynamics import (Aggregation, Alignment, CuckerSmale, Scene, get_num_threads,
                             set_num_threads)
from kinred.dynamics.kernels import Quadratic
import kinred.observables as obs
from kinred.integrate import SaveAt, simulate, working_frame
from kinred.integrate import _kernels, _simulate
from kinred.integrate._kernels import Moments
from kinred.integrate._observers import FRAME_MIN
from kinred.integrate._save import FUSED_MIN
from kinred.integrate._solvers import EulerMoments, _RKState
from kinred.pairsum import RandomBatch


def _rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


def _close(got, ref, z):
    """``(F, S, T)`` of the kernel against the twin's: 1e-12 relative (``F`` within the
    round-off of the coordinates when it is that small, as in test_integrate_loop)."""
    floor = 64 * np.finfo(float).eps ** 2 * float(np.max(z * z))
    assert abs(got[0] - ref[0]) <= 1e-12 * ref[0] + floor
    assert _rel(got[1], ref[1]) <= 1e-12
    assert abs(got[2] - ref[2]) <= 1e-12 * float(np.sum(np.abs(z)))


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 700), d=st.integers(1, 9), order=st.sampled_from([1, 2]),
       alias=st.sampled_from(["none", "dx_is_v", "dv_is_x"]),
       offset=st.sampled_from([0.0, 1.0, 1e6]), weighted=st.booleans(), shifted=st.booleans(),
       centre=st.sampled_from(["zero", "near", "far"]), seed=st.integers(0, 2**16))
def test_euler_moments_equals_its_numpy_twin(n, d, order, alias, offset, weighted, shifted,
                                             centre, seed):
    rng = np.random.default_rng(seed)
    x, v, dx, dv = (offset * (k == 0) + s * rng.normal(size=(n, d))
                    for k, s in enumerate((1.0, 3.0, 1e-3, 7.0)))
    w = rng.dirichlet(np.ones(n)) if weighted else np.full(n, 1.0 / n)
    shift = rng.normal(size=d) * 10.0 if shifted else None
    a, b = [x.copy(), v.copy(), dx.copy(), dv.copy()], [x.copy(), v.copy(), dx, dv]
    for arr in (a, b):
        if alias == "dx_is_v":
            arr[2] = arr[1]
        elif alias == "dv_is_x":
            arr[3] = arr[0]
    xt = x if shift is None else x + shift
    guess = {"zero": np.zeros(d), "near": w @ xt + 1e-3 * rng.normal(size=d),
             "far": w @ xt + 1e3 * rng.normal(size=d)}[centre]
    centres = [guess.copy(), np.zeros(d)]
    h = 0.0123
    if order == 1:
        got = _kernels.euler_moments(a[0], a[2], None, None, h, w, shift, centres)
        ref = _kernels.euler_moments_numpy(b[0], b[2], None, None, h, w, shift, np.empty_like(x))
    else:
        got = _kernels.euler_moments(a[0], a[2], a[1], a[3], h, w, shift, centres)
        ref = _kernels.euler_moments_numpy(b[0], b[2], b[1], b[3], h, w, shift, np.empty_like(x))
    # the state: numpy's update bit for bit (x first, then v, element by element)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    _close(got[0], ref[0], b[0] if shift is None else b[0] + shift)
    if order == 1:
        assert got[1] is None and ref[1] is None
    else:
        _close(got[1], ref[1], b[1])
    # the reference centres are moved to the new means
    xn = b[0] if shift is None else b[0] + shift
    assert np.allclose(centres[0], w @ xn, rtol=1e-12, atol=1e-9 * (1 + offset))
    if order == 2:
        assert np.allclose(centres[1], w @ b[1], rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("kernel", ["euler_sweep", "euler_sweep_v", "euler_sweep_one"])
def test_fused_kernels_give_the_sweep_sums(kernel):
    """The raw sums ``r = Σ w (a − c)``, ``acc = [Σ w|a − c|², Σ w|a|², Σ a, Σ w]`` of the new
    state, against numpy's, at 1e-12 relative."""
    rng = np.random.default_rng(11)
    n, d = 1000, 6                      # several blocks of BLOCK rows and a partial one
    x, v, dv = rng.normal(size=(n, d)) + 4.0, rng.normal(size=(n, d)), rng.normal(size=(n, d))
    w = rng.dirichlet(np.ones(n))
    shift, c = rng.normal(size=(2, d)), rng.normal(size=(2, d))
    k = 1 if kernel == "euler_sweep_one" else 2
    r, acc = np.empty((k, d)), np.empty((k, 4))
    xk, vk, h = x.copy(), v.copy(), 0.01
    if kernel == "euler_sweep":
        _kernels.euler_sweep(xk, vk, vk, dv, h, w, shift, c, r, acc)
    elif kernel == "euler_sweep_v":
        _kernels.euler_sweep_v(xk, vk, dv, h, w, shift, c, r, acc)
    else:
        _kernels.euler_sweep_one(xk, dv, h, w, shift[:1], c[:1], r, acc)
    xn = x + v * h if k == 2 else x + dv * h
    new = [xn, v + dv * h][:k]
    for m in range(k):
        a = new[m] + shift[m]
        e = a - c[m]
        ref_acc = [w @ np.sum(e * e, axis=1), w @ np.sum(a * a, axis=1), np.sum(a), np.sum(w)]
        assert np.allclose(r[m], w @ e, rtol=1e-12, atol=1e-13)
        assert np.allclose(acc[m], ref_acc, rtol=1e-12, atol=1e-12 * np.sum(np.abs(a)))
    assert np.array_equal(xk, new[0]) and (k == 1 or np.array_equal(vk, new[1]))


def test_split_rows_and_threads_give_the_same_pass():
    n, d = 4100, 256                       # above SPLIT_MIN: two row halves
    assert len(_kernels._halves(n, d)) == 2
    rng = np.random.default_rng(8)
    x0, v0, dv = rng.normal(size=(n, d)) + 7.0, rng.normal(size=(n, d)), rng.normal(size=(n, d))
    w, shift = rng.dirichlet(np.ones(n)), rng.normal(size=d)
    got, old = {}, get_num_threads()
    try:
        for threads in (1, 2):
            set_num_threads(threads)
            x, v = x0.copy(), v0.copy()
            got[threads] = (_kernels.euler_moments(x, v, v, dv, 0.01, w, shift,
                                                   [np.zeros(d), np.zeros(d)]), x, v)
    finally:
        set_num_threads(old)
    assert got[1][0] == got[2][0]
    assert np.array_equal(got[1][1], got[2][1]) and np.array_equal(got[1][2], got[2][2])
    x, v = x0.copy(), v0.copy()
    ref = _kernels.euler_moments_numpy(x, v, v, dv, 0.01, w, shift, np.empty_like(x))
    assert np.array_equal(x, got[1][1]) and np.array_equal(v, got[1][2])
    for m in (0, 1):
        assert np.allclose(got[1][0][m], ref[m], rtol=1e-12, atol=0)


def test_euler_moments_propagates_non_finite_values():
    n, d = 300, 3
    for bad in (np.nan, np.inf):
        x, v, dv = np.ones((n, d)), np.ones((n, d)), np.zeros((n, d))
        dv[17, 1] = bad
        mx, mv = _kernels.euler_moments(x, v, v, dv, 0.1, np.full(n, 1 / n), None,
                                        [np.zeros(d), np.zeros(d)])
        assert np.all(np.isfinite(mx)) and not np.isfinite(mv[2])


def test_euler_moments_step_falls_back_for_other_arrays():
    """A drift of another dtype: the numpy update and the run's Moments, same values."""
    rng = np.random.default_rng(2)
    n, d = 50, 4
    x, v, w = rng.normal(size=(n, d)), rng.normal(size=(n, d)), np.full(n, 1 / n)
    dv = rng.normal(size=(n, d)).astype(np.float32)
    step = EulerMoments(w, Moments(w, np.ones(d)), Moments(w))
    (xs, vs), (mx, mv) = step(lambda t, x, v, rng: (v, dv), 0.0, (x.copy(), v.copy()), 0.1,
                              _RKState(), None)
    assert np.array_equal(xs, x + v * 0.1) and np.array_equal(vs, v + dv * 0.1)
    ref = _kernels.moments_numpy(xs, w, np.ones(d)), _kernels.moments_numpy(vs, w)
    assert np.allclose(mx, ref[0], rtol=1e-12) and np.allclose(mv, ref[1], rtol=1e-12)


# ------------------------------------------------------------------ simulate

def _large(order=2, n=2048, d=128):
    assert n * d >= FUSED_MIN
    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(0, 1, (n, d)) + 5.0, rng.normal(size=(n, d))
    if order == 2:
        return Scene([Alignment(CuckerSmale(1.0, 0.5))], "mean", pairsum=RandomBatch(p=4)), x0, v0
    return Scene([Aggregation(Quadratic(1.0))], "mean"), x0, None


@pytest.mark.parametrize("order", [1, 2])
def test_fused_run_is_the_unfused_run(order, monkeypatch):
    """The fused pass changes no state bit and the recorded Γ, Λ by round-off only."""
    sc, x0, v0 = _large(order)
    runs = []
    for fused in (True, False):
        if not fused:                   # the step and the moments in separate passes
            monkeypatch.setattr(_simulate, "FUSED_MIN", 2**62)
        runs.append(simulate(sc, x0, v0, (0.0, 8e-3), 1e-3, seed=1, save=SaveAt(states=True)))
    a, b = runs
    assert np.array_equal(a.x, b.x) and (order == 1 or np.array_equal(a.v, b.v))
    for name in a.observables:
        assert np.allclose(a.observables[name], b.observables[name], rtol=1e-12, atol=0)
    assert not np.array_equal(a.x[0], a.x[-1])


@pytest.mark.parametrize("backend", ["random_batch", "dense"])
def test_a_step_is_one_pass_over_the_state(backend, monkeypatch):
    """One fused call per step and no sweep of its own: the run's only sweeps are those of the
    initial centroid (two: x0 is far from 0), which give Λ(x0) too, and Γ(v0) comes with the
    copy of v0 (today's main: 2 sweeps per step and 3 at t0, 23 for 10 steps, beside the
    Euler update and a sum of x per step). With RandomBatch the backend's fused step
    (RandomBatch.euler_step) takes the update and the sums too: no Euler sweep at all."""
    from kinred.pairsum import Dense, RandomBatch
    calls = []

    def spy(name, owner=_kernels):
        real = getattr(owner, name)
        monkeypatch.setattr(owner, name, lambda *a: calls.append(name) or real(*a))
    sc, x0, v0 = _large()
    if backend == "dense":
        sc = Scene(sc.effects, "mean", pairsum=Dense())
    simulate(sc, x0, v0, (0.0, 1e-3), 1e-3, seed=1)       # numba loads its registries first
    for name in ("sweep", "euler_pair", "euler_one", "euler_sweep", "euler_sweep_v",
                 "euler_sweep_one", "copy_sweep"):
        spy(name)
    spy("euler_step", RandomBatch)
    sums = []
    real_sum = np.sum
    monkeypatch.setattr(np, "sum", lambda a, *k, **kw: sums.append(np.shape(a)) or
                        real_sum(a, *k, **kw))
    tr = simulate(sc, x0, v0, (0.0, 10e-3), 1e-3, seed=1)
    assert tr.n_steps == 10
    step = "euler_step" if backend == "random_batch" else "euler_sweep_v"
    assert sorted(calls) == ["copy_sweep"] + [step] * 10 + ["sweep"] * 2
    assert x0.shape not in sums                 # no separate sum of a state array


def test_observers_see_the_working_positions_at_the_last_step():
    sc, x0, v0 = _large()
    seen = []
    tr = simulate(sc, x0, v0, (0.0, 3e-3), 1e-3, seed=1,
                  observers=lambda t, s, scene: seen.append(s.x + s.shift))
    assert np.array_equal(seen[-1], tr.x[-1])
    ref = simulate(sc, x0, v0, (0.0, 3e-3), 1e-3, seed=1, save=SaveAt(states=True))
    assert np.array_equal(ref.x[-1], tr.x[-1])


# ------------------------------------------------------------------ the run's fixed costs

@pytest.mark.parametrize("offset", [0.0, 0.5, 1e6])
def test_frame_centres_as_kinred_observables(offset):
    """The compiled working frame: the compensated centroid to round-off of the spread, and
    the copy relative to it, bit for bit numpy's ``x0 - shift``."""
    rng = np.random.default_rng(4)
    n, d = 3000, 90
    x0 = offset + rng.uniform(-1, 1, (n, d))
    w = rng.dirichlet(np.ones(n))
    x, c, m = _kernels.frame(x0, w)
    ref = obs.centre(x0, w)
    assert np.max(np.abs(c - ref)) <= 4 * np.finfo(float).eps * (1.0 + offset)
    assert np.array_equal(x, x0 - c) and x.flags.c_contiguous and not np.shares_memory(x, x0)
    assert np.allclose(m, _kernels.moments_numpy(x0, w), rtol=1e-12, atol=0)


def test_working_frame_at_large_n_is_the_small_n_frame():
    sc, x0, v0 = _large()
    x0 = x0 + 1e3
    w = sc.agent_weights(len(x0))
    assert x0.size >= FRAME_MIN
    x, v, shift = working_frame(sc, x0, v0)
    assert np.max(np.abs(shift - obs.centre(x0, w))) <= 1e-15 * 1e3
    assert np.array_equal(x, x0 - shift) and np.array_equal(v, v0)
    assert not np.shares_memory(x, x0) and not np.shares_memory(v, v0)


def test_the_run_checks_its_state_once_and_the_frame_holds_two_arrays(monkeypatch):
    """Today's main tested the finiteness of x0 five times per run (``simulate``'s validation,
    working_frame's, kinred.observables.centre's) by ``np.isfinite`` temporaries; now once per
    array in ``working_frame``, and ``simulate`` takes it from the frame's own sums (no pass of
    its own). The working frame allocates its two arrays and nothing else."""
    from kinred import _validate

    seen = []
    real = _validate._all_finite
    monkeypatch.setattr(_validate, "_all_finite", lambda a: seen.append(a.shape) or real(a))
    sc, x0, v0 = _large()
    x, v, shift = working_frame(sc, x0, v0)       # compile
    tracemalloc.start()
    try:
        seen.clear()
        working_frame(sc, x0, v0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert seen == [x0.shape, x0.shape]
    assert peak / x0.nbytes < 2.1, peak / x0.nbytes             # x and v, nothing else
    seen.clear()
    simulate(sc, x0, v0, (0.0, 1e-3), 1e-3, seed=1)
    assert seen.count(x0.shape) == 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, "inf-inf", "overflow"])
def test_finiteness_check_of_large_arrays(bad):
    from kinred._validate import as_array
    from kinred.errors import InvalidInput

    z = np.ones((300, 300))
    if bad == "inf-inf":
        z[3, 4], z[200, 1] = np.inf, -np.inf
    elif bad == "overflow":             # finite entries whose sum overflows: accepted
        z[:] = 1e308
    else:
        z[77, 5] = bad
    if bad == "overflow":
        assert as_array(z, "x0") is z
        return
    with pytest.raises(InvalidInput, match=r"x0 must be finite, got .* at index \((3, 4|77, 5)\)"):
        as_array(z, "x0")


@pytest.mark.parametrize("which", ["x0", "v0"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, "overflow"])
@pytest.mark.parametrize("invariant", [True, False])
def test_simulate_tests_finiteness_from_the_frames_pass(which, bad, invariant):
    """At large N ``simulate`` takes the NaN/Inf test of ``x0`` and ``v0`` from the sums of
    the working frame's compiled pass (no pass of its own): a bad entry is still refused,
    named with its index, whether or not the scene centres its positions; finite entries
    whose sum overflows are not refused by the test."""
    from kinred.dynamics import Field
    from kinred.errors import InvalidInput, SimulationDiverged

    sc, x0, v0 = _large()
    if not invariant:           # a field of absolute positions: no centring, no frame sums
        sc = Scene([Alignment(CuckerSmale(1.0, 0.5)), Field(lambda t, x, v: -x, target="v")],
                   "mean")
        assert not sc.translation_invariant
    z = x0 if which == "x0" else v0
    if bad == "overflow":
        z[:, :] = 1e300 if which == "x0" else 1e-3
        z[:, 0] = 1e308
        try:        # not refused as non-finite: it may run or diverge, never "must be finite"
            simulate(sc, x0, v0, (0.0, 1e-3), 1e-3, seed=1)
        except SimulationDiverged:
            pass
        return
    z[1000, 7] = bad
    with pytest.raises(InvalidInput, match=rf"{which} must be finite, got .* at index "
                                           rf"\(1000, 7\)"):
        simulate(sc, x0, v0, (0.0, 1e-3), 1e-3, seed=1)


def test_add_shift_is_numpys_add_bit_for_bit():
    rng = np.random.default_rng(6)
    x, s = rng.normal(size=(4100, 256)) * 1e3, rng.normal(size=256) * 1e6
    ref = x + s
    _kernels.add_shift(x, s)
    assert np.array_equal(x, ref)


def test_the_fused_pass_feeds_the_divergence_guard():
    """An unstable step at large N is stopped from the fused pass's moments as from the
    unfused loop's: the same step, the same message."""
    from kinred.errors import SimulationDiverged

    sc = Scene([Alignment(CuckerSmale(1.0, 0.0))], "sum")       # sum: rate N·G, dt·ρ >> 2
    _, x0, v0 = _large()
    errs = []
    for fused_min in (FUSED_MIN, 2**62):
        _simulate.FUSED_MIN = fused_min
        try:
            with pytest.raises(SimulationDiverged) as exc:
                simulate(sc, x0, v0, (0.0, 0.5), 0.01)
        finally:
            _simulate.FUSED_MIN = FUSED_MIN
        errs.append(exc.value)
    assert errs[0].step == errs[1].step and str(errs[0]) == str(errs[1])


@pytest.mark.parametrize("mean", [0.0, 1e4])
def test_copy_moments_is_a_copy_and_the_moments(mean):
    """The velocities' copy and Γ(v0) in one pass (two sweeps when the mean is far from 0)."""
    rng = np.random.default_rng(9)
    v0, w = mean + rng.normal(size=(3000, 90)), rng.dirichlet(np.ones(3000))
    v, m, c = _kernels.copy_moments(v0, w)
    assert np.array_equal(v, v0) and not np.shares_memory(v, v0)
    _close(m, _kernels.moments_numpy(v0, w), v0)
    assert np.allclose(c, w @ v0, rtol=1e-12, atol=1e-12)
