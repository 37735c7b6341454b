"""Kinetic solutions, reduced solutions, W1 between them and Theorem 4.3's bound pieces."""

import math

import numpy as np
import pytest

from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Drift, Morse, Noise,
                             Scene, SelfPropulsion)
from kinred.errors import InvalidInput
from kinred.kinetic import (compare, d_estimate, effect_constants, lift, max_pairwise_distance,
                            milling_index, phase_space, reduce, reference_estimate, solve,
                            stability_constant, theorem_bound)
from kinred.measures import Atomic, Mixture, TensorProduct, Uniform
from kinred.projection import jl_matrix


def _mu(d, decay=0.6):
    pos = TensorProduct([Uniform(-0.5 * decay**j, 0.5 * decay**j) for j in range(d)])
    vel = TensorProduct([Uniform(-decay**j, decay**j) for j in range(d)])
    return phase_space(pos, vel)


def _free(d):
    return Scene([Drift(np.zeros(d))])


# ----------------------------------------------------------------------- exact projection
@pytest.mark.parametrize("scene_fn", [
    lambda d: _free(d),                                               # free transport x' = v
    lambda d: Scene([Alignment(CuckerSmale(G=1.5, beta=0.0))]),       # constant kernel: linear
])
def test_linear_scenes_project_exactly(scene_fn):
    d, k = 12, 3
    sol = solve(scene_fn(d), _mu(d), atoms=60, t_span=(0.0, 2.0), dt=0.05, save_every=10)
    M = jl_matrix(k, d, seed=1)
    red = reduce(sol, M=M)
    c = compare(sol, red)
    scale = float(np.abs(sol.x).max() + np.abs(sol.v).max())
    assert c.exact.all()
    assert c.w1.max() < 1e-12 * scale * math.sqrt(M.norm())
    assert c.uniform.max() < 1e-12 * scale * 10
    tb = theorem_bound(sol, red)
    # L'' = 0 for these scenes, so Theorem 3.1's term vanishes identically: D(t) = 0
    assert np.all(tb.term_jl == 0.0)


def test_compare_beyond_the_dense_lp_is_sparse_exact_or_a_certified_bracket(monkeypatch):
    """Beyond the dense LP, compare gets the exact W1 from the sparse method (issue 22); when
    its memory preflight refuses, the paired certified bracket, which ``exact``/``lower``/
    ``upper`` report."""
    from kinred.distance import w1

    d = 6
    sc = Scene([Alignment(CuckerSmale(G=1.0, beta=0.5))])
    sol = solve(sc, _mu(d), atoms=40, t_span=(0.0, 1.0), dt=0.05, save_every=10)
    red = reduce(sol, M=jl_matrix(2, d, seed=0))
    exact = compare(sol, red)
    assert exact.exact.all() and exact.method == "exact"
    monkeypatch.setitem(w1.__kwdefaults__, "max_dense_bytes", 0)     # no dense LP
    monkeypatch.setitem(w1.__kwdefaults__, "max_exact_pairs", 10)    # nor a lazy one
    sp = compare(sol, red)
    assert sp.method == "sparse" and sp.exact.all()
    np.testing.assert_allclose(sp.w1, exact.w1, rtol=1e-12, atol=1e-15)
    monkeypatch.setitem(w1.__kwdefaults__, "max_bytes", 1000)        # the preflight refuses
    br = compare(sol, red)
    assert br.method == "paired-bracket"
    assert np.all(br.lower <= exact.w1 * (1 + 1e-12)) and np.all(exact.w1 <= br.upper * (1 + 1e-12))
    # where the dual bound meets the index coupling the value is exact (proved), else a bracket
    e = br.exact
    np.testing.assert_allclose(br.w1[e], exact.w1[e], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(br.w1[~e], 0.5 * (br.lower + br.upper)[~e], rtol=1e-15)


def test_a_first_solve_stopped_by_the_budget_sends_later_times_to_the_paired_bracket(
        monkeypatch):
    """When the sparse method's first solve at one saved time is stopped by ``max_seconds``
    (no plan, a bracket), the later times take the paired bracket without the same wait; the
    brackets stay certified around the exact values."""
    import time

    import kinred.distance._sparse as sparse_mod
    from kinred.distance import w1

    d = 6
    sc = Scene([Alignment(CuckerSmale(G=1.0, beta=0.5))])
    sol = solve(sc, _mu(d), atoms=40, t_span=(0.0, 1.5), dt=0.05, save_every=10)
    red = reduce(sol, M=jl_matrix(2, d, seed=0))
    exact = compare(sol, red)
    monkeypatch.setitem(w1.__kwdefaults__, "max_dense_bytes", 0)     # no dense LP
    monkeypatch.setitem(w1.__kwdefaults__, "max_exact_pairs", 10)    # nor a lazy one
    monkeypatch.setattr(sparse_mod, "FORK_EDGES", 0)                 # every solve forked
    calls = []

    def slow(*args):
        calls.append(1)                                              # (in the child: no effect)
        time.sleep(600)

    monkeypatch.setattr(sparse_mod, "_solve", slow)
    t0 = time.perf_counter()
    c = compare(sol, red, max_seconds=1.0)
    took = time.perf_counter() - t0
    assert len(c.t) == 4
    # no time is exact by a solve: brackets, or the paired bracket's dual meeting its coupling
    np.testing.assert_allclose(c.w1[c.exact], exact.w1[c.exact], rtol=1e-12, atol=1e-15)
    assert took < 15.0           # one stopped solve (~1 s; t = 0 is two equal clouds), not four
    # t = 0 (equal clouds): the stopped solve falls back on the paired bracket, whose dual
    # bound meets the index coupling (0): W1 = 0, exact; the later times take the paired
    # bracket directly
    assert c.method == "sparse+paired-bracket" and c.exact[0] and c.w1[0] == 0.0
    assert np.all(c.lower <= exact.w1 * (1 + 1e-12) + 1e-300)
    assert np.all(exact.w1 <= c.upper * (1 + 1e-12))


def test_free_transport_closed_form():
    d = 4
    X0 = np.random.default_rng(0).normal(size=(7, 2 * d))
    sol = solve(_free(d), Atomic(X0), t_span=(0.0, 1.0), dt=0.25)
    np.testing.assert_allclose(sol.x[-1], X0[:, :d] + X0[:, d:], rtol=0, atol=1e-14)
    np.testing.assert_array_equal(sol.v[-1], X0[:, d:])
    assert sol.eps == 0.0


def test_initial_distance_is_zero_and_nonlinear_is_not():
    d, k = 20, 2
    sc = Scene([Alignment(CuckerSmale(G=2.0, beta=1.0))])
    sol = solve(sc, _mu(d, 0.8), atoms=80, t_span=(0.0, 2.0), dt=0.05, save_every=8)
    red = reduce(sol, M=jl_matrix(k, d, seed=3))
    c = compare(sol, red)
    assert c.w1[0] < 1e-14
    assert c.w1[-1] > 1e-6                      # a genuine non-linear effect of the projection
    assert np.all(c.w1 <= c.coupling + 1e-12)   # index coupling bounds W1
    assert np.all(c.coupling <= math.sqrt(2) * c.uniform + 1e-12)
    tb = theorem_bound(sol, red)
    assert np.all(c.w1[1:] <= tb.term_jl[1:])   # Theorem 3.1's term bounds the measured W1
    assert np.all(tb.bound >= tb.term_jl)


def test_weights_enter_the_scene_and_w1():
    comps = [TensorProduct([Uniform(0, 1), Uniform(0, 1), Uniform(-1, 0), Uniform(0, 0.1)]),
             TensorProduct([Uniform(3, 4), Uniform(0, 1), Uniform(0, 1), Uniform(0, 0.1)])]
    mu = Mixture(comps, [0.8, 0.2])
    sol = solve(Scene([Alignment(CuckerSmale(1.0, 0.0))]), mu, eps=0.6, t_span=(0, 1), dt=0.1)
    w = sol.weights
    assert not np.allclose(w, w[0])
    # β = 0: mean velocity Σ wᵢ vᵢ is conserved with the atom weights
    np.testing.assert_allclose(w @ sol.v[-1], w @ sol.v[0], atol=1e-13)
    assert sol.scene.weights is not None and np.allclose(sol.scene.weights, w)


def test_reference_estimate_and_stability_constant():
    d = 6
    sc = Scene([Alignment(CuckerSmale(G=1.0, beta=0.5))])
    mu = _mu(d, 0.5)
    kw = dict(t_span=(0.0, 1.0), dt=0.05, save_every=5)
    sol = solve(sc, mu, atoms=20, **kw)
    ref = solve(sc, mu, atoms=120, **kw)
    M = jl_matrix(2, d, seed=0)
    est = reference_estimate(sol, ref, reduce(ref, M=M))
    assert est.exact and est.n_atoms_reference > est.n_atoms
    tb = theorem_bound(sol, reduce(sol, M=M))
    tbr = theorem_bound(ref, reduce(ref, M=M))
    # Dobrushin: W1(μᴺ(t), μᴺ'(t)) ≤ C(t) W1(μᴺ(0), μᴺ'(0)) for two measure solutions;
    # the constants must cover both systems, so take the larger rate.
    C = np.maximum(tb.C, tbr.C)
    assert np.all(est.w1_quantization <= C * est.w1_quantization[0] * (1 + 1e-9))
    assert est.w1_quantization[0] <= sol.eps + ref.eps
    # W1(μᴺ, μᴺ') does not depend on M: another projection reuses it, the rest is recomputed
    M5 = jl_matrix(5, d, seed=1)
    fresh = reference_estimate(sol, ref, reduce(ref, M=M5))
    reused = reference_estimate(sol, ref, reduce(ref, M=M5), quantization=est.w1_quantization)
    np.testing.assert_array_equal(reused.w1_quantization, fresh.w1_quantization)
    np.testing.assert_array_equal(reused.w1_reference, fresh.w1_reference)
    assert not np.array_equal(fresh.w1_reference, est.w1_reference)
    with pytest.raises(InvalidInput, match="quantization must hold"):
        reference_estimate(sol, ref, reduce(ref, M=M5), quantization=est.w1_quantization[:-1])


def test_solve_validation():
    d = 2
    with pytest.raises(InvalidInput, match="normalize"):
        solve(Scene([Alignment()], normalize="sum"), _mu(d), atoms=4, t_span=(0, 1), dt=0.5)
    with pytest.raises(InvalidInput, match="even"):
        solve(Scene([Alignment()]), TensorProduct([Uniform(0, 1)] * 3), atoms=4)
    with pytest.raises(InvalidInput, match="M must"):
        sol = solve(Scene([Alignment()]), _mu(d), atoms=4, t_span=(0, 1), dt=0.5)
        reduce(sol, M=np.eye(2, 5))


def test_lift_is_an_isometry_and_mill_index():
    mu = TensorProduct([Uniform(0, 1)] * 4)
    big = lift(mu, 9, seed=3)
    B = big.projection.to_dense()
    np.testing.assert_allclose(B.T @ B, np.eye(4), atol=1e-13)
    th = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    x = np.c_[np.cos(th), np.sin(th)]
    v = np.c_[-np.sin(th), np.cos(th)]
    Q = B[:9, :2]
    assert milling_index(x @ Q.T, v @ Q.T) == pytest.approx(1.0, abs=1e-12)   # rotation invariant
    assert milling_index(x, -v) == pytest.approx(1.0, abs=1e-12)
    assert milling_index(x, np.tile([1.0, 0.0], (12, 1))) == pytest.approx(0.0, abs=1e-12)


# ----------------------------------------------------------------------- bound pieces
def test_d_estimate_closed_form():
    # eq. (3.7): ε α t (L‖M‖ + L''β) exp[(2L‖M‖ + 2βL'' + L')t]
    eps, a, b, L, Lp, Lpp, nM, t = 0.2, 3.0, 1.5, 0.5, 2.0, 0.25, 1.7, 0.8
    want = eps * a * t * (L * nM + Lpp * b) * math.exp((2 * L * nM + 2 * b * Lpp + Lp) * t)
    assert d_estimate(t, eps, a, b, L, Lp, Lpp, nM) == pytest.approx(want, rel=1e-14)
    assert d_estimate(0.0, eps, a, b, L, Lp, Lpp, nM) == 0.0
    assert stability_constant(1.5, 2.0) == pytest.approx(math.exp(3.0), rel=1e-15)


def test_cucker_smale_constants_match_section_2_3():
    G, beta = 1.3, 1.5
    g = CuckerSmale(G, beta)
    s = 1 / math.sqrt(2 * beta + 1)                      # argmax of |g'|
    lip = 2 * G * beta * s / (1 + s * s) ** (beta + 1)
    c = effect_constants(Alignment(g), diam_v=2.0)
    assert c.L == 0.0
    assert c.Lp == pytest.approx(2 * G)                 # L' ≥ max(1, 2G) (§2.3)
    assert c.Lpp == pytest.approx(2 * lip, rel=1e-12)   # L'' ≤ 2‖g‖_Lip (§2.3)
    assert c.lip_state == pytest.approx(G + lip * 2.0, rel=1e-12)
    c2 = effect_constants(Alignment(g), coef_sum=4.0)
    assert c2.Lp == pytest.approx(8 * G)


def test_self_propulsion_and_morse_constants():
    c = effect_constants(SelfPropulsion(a=1.0, b=0.5), speed=3.0)
    assert (c.Lp, c.Lpp) == (1.0 + 0.5 * 9.0, 2 * 0.5 * 3.0)   # §3.3.2
    assert c.lip_state == abs(1.0 - 3 * 0.5 * 9.0) and c.lip_measure == 0.0
    c = effect_constants(SelfPropulsion(a=2.0, b=0.1), speed=1.0)
    assert c.lip_state == 2.0                                   # max(|a|, |a − 3bR²|)
    m = Morse(1.0, 2.0, 1.5, 0.5, soft=0.3)
    ce = effect_constants(AttractionRepulsion(m), diam_x=4.0)
    assert ce.Lp == pytest.approx(2 * m.sup_norm()) and ce.Lpp == pytest.approx(2 * m.lipschitz())
    assert ce.lip_measure == pytest.approx(m.sup_norm() + 4.0 * m.lipschitz())
    assert math.isinf(effect_constants(AttractionRepulsion(Morse(1.0, 2.0, 1.5, 0.5))).Lp)
    assert math.isnan(effect_constants(Noise(0.1)).Lp)
    assert effect_constants(Drift([0.0])).Lp == 0.0


def test_self_propulsion_lipschitz_is_attained():
    # the Jacobian norm of h(v) = (a − b|v|²)v on |v| ≤ R is max(|a|, |a − 3bR²|)
    a, b, R = 1.0, 0.5, 2.0
    c = effect_constants(SelfPropulsion(a, b), speed=R).lip_state
    h = lambda v: (a - b * v @ v) * v
    v = np.array([R, 0.0]) * (1 - 1e-7)
    dv = np.array([1e-6, 0.0])
    slope = np.linalg.norm(h(v) - h(v - dv)) / 1e-6
    assert slope == pytest.approx(c, rel=1e-4)


def test_max_pairwise_distance():
    Z = np.random.default_rng(2).normal(size=(40, 5)) + 1e3
    brute = max(np.linalg.norm(a - b) for a in Z for b in Z)
    assert max_pairwise_distance(Z) == pytest.approx(brute, rel=1e-9)


def test_theorem_bound_pieces_on_small_case():
    d, k = 3, 2
    sc = Scene([Alignment(CuckerSmale(G=1.0, beta=1.0))])
    sol = solve(sc, _mu(d, 0.7), atoms=10, t_span=(0.0, 0.5), dt=0.05, save_every=5)
    M = jl_matrix(k, d, seed=5)
    red = reduce(sol, M=M)
    tb = theorem_bound(sol, red)
    g = CuckerSmale(1.0, 1.0)
    assert np.allclose(tb.Lpp, 2 * g.lipschitz())
    assert np.allclose(tb.Lp, max(1.0, 2.0))
    assert tb.norm_M == pytest.approx(np.linalg.norm(M.to_dense(), 2))
    # α is the max position distance at saved times (running max), β the max projected norm
    alpha0 = max_pairwise_distance(sol.x[0])
    assert tb.alpha[0] == pytest.approx(alpha0)
    assert np.all(np.diff(tb.alpha) >= 0) and np.all(np.diff(tb.eps_jl) >= 0)
    i = -1
    want = (2 * tb.C[i] * tb.norm_M * sol.eps
            + math.sqrt(2) * d_estimate(tb.t[i], tb.eps_jl[i], tb.alpha[i], tb.beta[i], 0.0,
                                        tb.Lp[i], tb.Lpp[i], tb.norm_M))
    assert tb.bound[i] == pytest.approx(want, rel=1e-12)
    assert tb.C[i] == pytest.approx(math.exp(tb.Lambda[i] * tb.t[i]))


# ------------------------------------------------- W1 at extreme magnitudes (issue 14, W1)
@pytest.mark.parametrize("s", [1e-200, 1e160, 1e200])
def test_compare_and_reference_estimate_are_homogeneous_at_extreme_scales(s):
    # free transport is linear, so scaling the data by s scales every W1, coupling and uniform
    # error by s; squared differences used to overflow (inf) near 1e160 and underflow (0) near 1e-200
    import dataclasses

    d = 4
    X0 = np.random.default_rng(3).integers(-8, 8, size=(7, 2 * d)) / 8.0
    M = jl_matrix(2, d, seed=1)
    off = np.array([0.375, -0.25])

    def run(scale):
        sol = solve(_free(d), Atomic(scale * X0), t_span=(0.0, 1.0), dt=0.25)
        red = reduce(sol, M=M)
        red = dataclasses.replace(red, y=red.y + scale * off)
        ref = solve(_free(d), Atomic(scale * (X0 + 0.125)), t_span=(0.0, 1.0), dt=0.25)
        est = reference_estimate(sol, ref, reduce(ref, M=M))
        return compare(sol, red), est

    c1, e1 = run(1.0)
    cs, es = run(s)
    assert c1.w1.min() > 0.1 and cs.exact.all() and es.exact
    for name in ("w1", "lower", "upper", "coupling", "uniform"):
        np.testing.assert_allclose(getattr(cs, name), s * getattr(c1, name), rtol=1e-12, atol=0)
    np.testing.assert_allclose(es.w1_quantization, s * e1.w1_quantization, rtol=1e-12, atol=0)
    assert es.w1_reference.max() <= 1e-12 * s       # a linear scene projects exactly: round-off
    # closed form of the quantization W1: a translation by 0.125 (1 + t) in x and 0.125 in v
    want = 0.125 * np.sqrt(d * (1 + e1.t) ** 2 + d)
    np.testing.assert_allclose(e1.w1_quantization, want, rtol=1e-12)
