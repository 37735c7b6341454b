"""Scenes: engine vs twin, conservation, O(N·d), projection, custom effects."""

import numpy as np
import pytest

from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale, Drift,
                             Effect, Field, Morse, Noise, PairwiseEffect, ProjectedSystem,
                             Quadratic, Scene, SelfPropulsion, project_state, set_num_threads,
                             get_num_threads)
from kinred.projection import jl_matrix
from kinred.errors import InvalidInput, NotProjectable
from kinred.integrate import SaveAt, simulate
from kinred.observables import centre, mean_velocity
from kinred.pairsum import _kernels, dense


def _data(N=60, d=5, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (N, d)), rng.uniform(-1, 1, (N, d))


SCENES = [
    [Alignment(CuckerSmale(0.8, 1.5))],
    [Alignment(CuckerSmale(0.8, 1.62)), SelfPropulsion(1.0, 0.5)],
    [AttractionRepulsion(Morse()), SelfPropulsion(1.0, 0.5)],
    [AttractionRepulsion(Morse(soft=0.2)), Alignment(CuckerSmale(1.0, 0.5), on="v")],
]


@pytest.mark.parametrize("effects", SCENES, ids=range(len(SCENES)))
@pytest.mark.parametrize("normalize", ["mean", "sum"])
@pytest.mark.parametrize("threads", [1, 2])
def test_fast_engine_equals_numpy_twin(effects, normalize, threads, monkeypatch):
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)   # two threads even at this size
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    x, v = _data(97, 7)
    w = np.random.default_rng(5).uniform(0.5, 1.5, 97)
    w /= w.sum()
    old = get_num_threads()
    set_num_threads(threads)
    try:
        fast = Scene(effects, normalize, weights=w, block=13).rhs(x, v)[1]
    finally:
        set_num_threads(old)
    ref = Scene(effects, normalize, weights=w, engine="numpy").rhs(x, v)[1]
    assert np.max(np.abs(fast - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_alignment_closed_form_beta0():
    # beta = 0: g = G, dv_i = G (v_c - v_i) for "mean", N G (v_c - v_i) for "sum"
    x, v = _data(10, 3)
    vc = v.mean(axis=0)
    dv = Scene([Alignment(CuckerSmale(0.5, 0.0))], "mean").rhs(x, v)[1]
    assert np.allclose(dv, 0.5 * (vc - v), rtol=0, atol=1e-15)
    dv = Scene([Alignment(CuckerSmale(0.5, 0.0))], "sum").rhs(x, v)[1]
    assert np.allclose(dv, 10 * 0.5 * (vc - v), rtol=0, atol=1e-14)


def test_morse_force_sign_two_agents():
    # two agents at distance s on the line: dv_0 = (1/2) u(s) (x_1 - x_0)
    m = Morse(Ca=1.0, la=2.0, Cr=1.5, lr=0.5)
    s = 0.7
    x = np.array([[0.0], [s]])
    dv = Scene([AttractionRepulsion(m)], "mean").rhs(x, np.zeros((2, 1)))[1]
    dU = 1 / 2 * np.exp(-s / 2) - 1.5 / 0.5 * np.exp(-s / 0.5)   # U'(s) < 0 here: repulsive
    assert dv[0, 0] == pytest.approx(0.5 * dU, rel=1e-13)
    assert dv[0, 0] < 0 and dv[1, 0] == pytest.approx(-dv[0, 0], rel=1e-13)


@pytest.mark.parametrize("normalize", ["mean", "sum"])
@pytest.mark.parametrize("weighted", [False, True])
def test_cucker_smale_conserves_mean_velocity_and_moves_centre_linearly(normalize, weighted):
    x0, v0 = _data(80, 6, seed=2)
    w = None
    if weighted:
        w = np.random.default_rng(3).uniform(0.2, 1.0, 80)
        w /= w.sum()
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], normalize, weights=w)
    tr = simulate(sc, x0, v0, (0.0, 2.0), 0.02, save=SaveAt(every=10,
                  observables=("centre", "mean_velocity")))
    mv = tr.observables["mean_velocity"]
    vc0 = mean_velocity(v0, w)
    assert np.max(np.abs(mv - vc0)) < 1e-14
    cen = tr.observables["centre"]
    expect = centre(x0, w)[None, :] + tr.t[:, None] * vc0[None, :]
    assert np.max(np.abs(cen - expect)) < 1e-13


def test_non_pairwise_scene_is_order_N_and_alignment_needs_only_x():
    x, v = _data(200, 4)
    _kernels.COUNTERS.clear()
    Scene([SelfPropulsion(1.0, 0.5), Drift(np.ones(4))]).rhs(x, v)
    assert sum(_kernels.COUNTERS.values()) == 0
    Scene([Alignment(CuckerSmale())], block=50).rhs(x, v)
    assert _kernels.COUNTERS["x"] == 4 and _kernels.COUNTERS["v"] == 0
    _kernels.COUNTERS.clear()
    Scene([Alignment(CuckerSmale(), on="v")], block=50).rhs(x, v)
    assert _kernels.COUNTERS["v"] == 4 and _kernels.COUNTERS["x"] == 0


def test_custom_effects_without_engine_changes():
    class Friction(Effect):
        target = "v"
        projectable = True
        translation_invariant = True

        def __init__(self, gamma):
            self.gamma = gamma

        def drift(self, x, v, t):
            return -self.gamma * v

        def project(self, M):
            return self

    x, v = _data(30, 3)
    dv = Scene([Friction(0.3)]).rhs(x, v)[1]
    assert np.array_equal(dv, -0.3 * v)
    # custom pairwise kernel (plain callable, no value_sq): runs on the numpy kernel path
    kern = lambda s: 1.0 / (1.0 + s)  # noqa: E731
    e = PairwiseEffect(kern, source="x", carrier="v", target="v")
    got = Scene([e], "mean", block=7).rhs(x, v)[1]
    S = np.sqrt(((x[:, None] - x[None]) ** 2).sum(-1))
    ref = ((kern(S)[:, :, None] * (v[None, :, :] - v[:, None, :])).sum(1)) / 30
    assert np.max(np.abs(got - ref)) < 1e-13


def test_first_order_aggregation_closed_form():
    # x' = c sum_j w_j (x_j - x_i) = c (x_c - x_i): x_i(t) - x_c = e^{-ct}(x_i(0) - x_c)
    x0, _ = _data(15, 2)
    sc = Scene([Aggregation(Quadratic(1.5))], "mean")
    assert sc.order == 1
    tr = simulate(sc, x0, None, (0.0, 1.0), 0.001, method="rk4", save=SaveAt(states=True, every=1000))
    xc = x0.mean(axis=0)
    assert np.max(np.abs(tr.x[-1] - (xc + np.exp(-1.5) * (x0 - xc)))) < 1e-12
    with pytest.raises(InvalidInput, match="first-order"):
        Scene([Aggregation(Quadratic(1.0)), SelfPropulsion()])


def test_projection_rotation_equals_rotated_original():
    x0, v0 = _data(40, 6, seed=7)
    Q, _ = np.linalg.qr(np.random.default_rng(8).normal(size=(6, 6)))
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.1)),
                SelfPropulsion(1.0, 0.5), Drift(np.arange(6.0))], "sum")
    ps = sc.project(Q)
    y0, w0 = sc.project_state(Q, x0, v0)
    a = simulate(sc, x0, v0, (0, 1), 0.01, save=SaveAt(every=50, states=True))
    b = simulate(ps, y0, w0, (0, 1), 0.01, save=SaveAt(every=50, states=True))
    assert np.max(np.abs(a.x @ Q.T - b.x)) < 1e-11
    assert np.max(np.abs(a.v @ Q.T - b.v)) < 1e-11
    assert np.allclose(a.observables["gamma"], b.observables["gamma"], rtol=1e-12)


def test_projected_gives_scene_and_state_in_one_call():
    """``scene.projected(M, x0, v0)``: the scene of ``project(M)`` started from ``project_state``."""
    x0, v0 = _data(40, 6, seed=7)
    Q, _ = np.linalg.qr(np.random.default_rng(8).normal(size=(6, 6)))
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.1)),
                SelfPropulsion(1.0, 0.5), Drift(np.arange(6.0))], "sum")
    p = sc.projected(Q, x0, v0)
    assert isinstance(p, ProjectedSystem) and p.scene.order == 2 and p.scene.projection.d == 6
    a = simulate(sc, x0, v0, (0, 1), 0.01, save=SaveAt(every=50, states=True))
    b = simulate(*p, (0, 1), 0.01, save=SaveAt(every=50, states=True))
    assert np.max(np.abs(a.x @ Q.T - b.x)) < 1e-11      # rotation: the projected run is the
    assert np.max(np.abs(a.v @ Q.T - b.v)) < 1e-11      # rotated original
    # the same numbers as the two calls by hand, for a structured map
    M = jl_matrix(3, 6, "dct", seed=2)
    scene_k, y0, w0 = sc.projected(M, x0, v0)
    assert np.array_equal(y0, M.apply(x0)) and np.array_equal(w0, M.apply(v0))
    by_hand = sc.project(M).rhs(*sc.project_state(M, x0, v0))
    assert all(np.array_equal(u, w) for u, w in zip(scene_k.rhs(y0, w0), by_hand))


def test_projected_first_order_closed_form():
    # x' = c (x_c - x_i) projects to y' = c (y_c - y_i): y_i(t) - y_c = e^{-ct}(M x_i(0) - y_c)
    x0, _ = _data(15, 5)
    M = jl_matrix(2, 5, "gaussian", seed=0)
    p = Scene([Aggregation(Quadratic(1.5))], "mean").projected(M, x0)
    assert p.w0 is None and p.scene.order == 1
    tr = simulate(*p, (0.0, 1.0), 0.001, method="rk4", save=SaveAt(states=True, every=1000))
    y0 = x0 @ M.T
    yc = y0.mean(axis=0)
    assert np.max(np.abs(tr.x[-1] - (yc + np.exp(-1.5) * (y0 - yc)))) < 1e-12


def test_projected_validation():
    sc2, sc1 = Scene([Alignment()]), Scene([Aggregation(Quadratic(1.0))])
    x0 = np.zeros((3, 4))
    M = np.eye(2, 4)
    with pytest.raises(InvalidInput, match=r"v0 must be given for a second-order"):
        sc2.projected(M, x0)
    with pytest.raises(InvalidInput, match=r"v0 must be None for a first-order"):
        sc1.projected(M, x0, x0)
    with pytest.raises(InvalidInput, match=r"x0 must have shape \(N, 4\).*shape \(2, 4\)\), got \(3, 5\)"):
        sc2.projected(M, np.zeros((3, 5)), np.zeros((3, 5)))
    with pytest.raises(InvalidInput, match=r"v0 must have shape \(3, 4\)"):
        sc2.projected(M, x0, np.zeros((2, 4)))
    with pytest.raises(InvalidInput, match="weights"):
        Scene([Alignment()], weights=[0.5, 0.5]).projected(M, x0, x0)
    with pytest.raises(InvalidInput, match=r"x0 must have 4 columns.*shape \(2, 4\)\), got shape \(3, 5\)"):
        project_state(M, np.zeros((3, 5)))
    with pytest.raises(NotProjectable):
        Scene([Field(lambda t, x, v: np.sin(x))]).projected(M, x0, x0)


def test_projected_noise_is_M_sigma_dW():
    x0, v0 = _data(10, 4)
    Q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(4, 4)))
    sc = Scene([Alignment(CuckerSmale(1.0, 1.0)), Noise(0.3)])
    ps = sc.project(Q)
    a = simulate(sc, x0, v0, (0, 0.5), 0.01, method="euler_maruyama", seed=4,
                 save=SaveAt(every=50, states=True))
    b = simulate(ps, *project_state(Q, x0, v0), (0, 0.5), 0.01, method="euler_maruyama", seed=4,
                 save=SaveAt(every=50, states=True))
    assert np.max(np.abs(a.v @ Q.T - b.v)) < 1e-12


def test_not_projectable_refused():
    sc = Scene([Alignment(), Field(lambda t, x, v: np.where(np.arange(x.shape[1]) == 0,
                                                              np.sin(x), 0.0))])
    with pytest.raises(NotProjectable, match="class \\(1.1\\)"):
        sc.project(np.eye(2, 3))


def test_weights_and_state_validation():
    with pytest.raises(InvalidInput, match="sum to one"):
        Scene([Alignment()], weights=[0.5, 0.6])
    with pytest.raises(InvalidInput, match="normalize"):
        Scene([Alignment()], normalize="avg")
    sc = Scene([Alignment()], weights=[0.5, 0.5])
    with pytest.raises(InvalidInput, match="weights"):
        sc.rhs(np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(InvalidInput, match="v must"):
        Scene([Alignment()]).rhs(np.zeros((3, 2)))
    with pytest.raises(InvalidInput, match="not an Effect"):
        Scene([object()])


@pytest.mark.parametrize("d", [2, 3, 4, 30])
@pytest.mark.parametrize("threads", [1, 2])
def test_default_strips_both_distance_paths_equal_twin(d, threads, monkeypatch):
    # default strip layout (no block=): differences for d <= 3, Gram + fix-up above
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)   # two threads even at this size
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    x, v = _data(700, d, seed=d)
    x[3] = x[4]                                      # coincident agents
    effects = [Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.1))]
    old = get_num_threads()
    set_num_threads(threads)
    try:
        fast = Scene(effects, "sum").rhs(x, v)[1]
    finally:
        set_num_threads(old)
    ref = Scene(effects, "sum", engine="numpy").rhs(x, v)[1]
    assert np.max(np.abs(fast - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_scratch_reuse_never_aliases_results(monkeypatch):
    """The engine reuses its scratch buffers between calls: a drift returned earlier must not
    change when the scene is evaluated again (on another state), and large workspaces are not
    kept at all."""
    from kinred.pairsum import dense as dense_mod

    rng = np.random.default_rng(3)
    x1, v1, x2, v2 = (rng.normal(size=(60, 7)) for _ in range(4))
    sc = Scene([Alignment(CuckerSmale(G=1.0, beta=0.8))])
    _, dv1 = sc.rhs(x1, v1)
    keep = dv1.copy()
    _, dv2 = sc.rhs(x2, v2)
    np.testing.assert_array_equal(dv1, keep)
    _, dv1b = sc.rhs(x1, v1)
    np.testing.assert_array_equal(dv1b, keep)          # same numbers from reused buffers
    twin = Scene([Alignment(CuckerSmale(G=1.0, beta=0.8))], engine="numpy").rhs(x2, v2)[1]
    np.testing.assert_allclose(dv2, twin, rtol=1e-12, atol=1e-12)

    dense_mod._SCRATCH.cache = {}
    monkeypatch.setattr(dense_mod, "_SCRATCH_MAX_BYTES", 1024)
    sc.rhs(x1, v1)
    assert dense_mod._SCRATCH.cache == {}               # too large to keep
