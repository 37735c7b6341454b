"""The NUFFT pair-sum backend: fast summation of smooth radial kernels against the exact
backends (Numpy twin, Dense) to the requested tolerance on random clouds, its accuracy as a
function of tol, the centring of the carriers, the grid cache, bad input, and simulations
(a short RK4 run, a reduced Table-1 run) that match the dense engine."""

import math
import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale, Morse,
                             Quadratic, Scene, SelfPropulsion)
from kinred._parallel import num_threads
from kinred.errors import InvalidInput, KinredError, TooLarge
from kinred.integrate import SaveAt, simulate
from kinred.observables import flocking_verdict, gamma
from kinred.pairsum import NUFFT, Dense, NUFFTPlan, as_pairsum, radial_profile
from kinred.projection import jl_matrix

CS = CuckerSmale(0.8, 1.5)
MORSE = Morse(Ca=1.0, la=2.0, Cr=1.5, lr=0.5, soft=0.3)
#: every term kind: positions → velocities (CS), positions → positions (Morse), velocities →
#: velocities (CS on velocity distances)
MIXED = [Alignment(CS), AttractionRepulsion(Morse(soft=0.5)),
         Alignment(CuckerSmale(0.5, 1.0), on="v")]


def _cloud(n, k, diameter, shift=0.0, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, diameter, (n, k)) + shift
    v = rng.normal(size=(n, k))
    w = rng.dirichlet(np.ones(n))
    return x, v, w


def _rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _field(effects, x, v, pairsum, weights=None, normalize="sum"):
    return Scene(effects, normalize, weights=weights, pairsum=pairsum).rhs(x, v)[1]


# ---------------------------------------------------------------------------- accuracy
@pytest.mark.parametrize("k, fine", [(1, 1e-10), (2, 1e-8), (3, 1e-6)])
def test_matches_the_numpy_twin_to_tol_far_from_the_origin_with_weights(k, fine):
    # (3-D soft Morse at 1e-8 needs more than the default max_modes: see the TooLarge tests)
    for n, tol, normalize in ((2, 1e-4, "sum"), (60, fine, "mean"), (500, 1e-4, "sum")):
        x, v, w = _cloud(n, k, 2.0, shift=1e6, seed=n + k)
        v *= 0.3 if k == 3 else 1.0         # velocity distances within a few kernel widths
        ref = _field(MIXED, x, v, "numpy", w, normalize)
        got = _field(MIXED, x, v, NUFFT(tol), w, normalize)
        assert _rel(got, ref) <= tol, (n, tol)


def test_two_agents_the_accuracy_scale_is_their_pair_not_the_self_pairs():
    """With N = 2 the field is one pair's: the accuracy scale κ (mean |φ| over pairs) must
    not count the self-pairs (φ(0), which cancel exactly), else the error is measured
    against φ(0) and reaches 4x tol when φ(d) is smaller."""
    rng = np.random.default_rng(5)
    x, v = rng.uniform(0.0, 2.0, (2, 3)) + 1e6, rng.normal(size=(2, 3))
    for eff in ([Alignment(CS)], [AttractionRepulsion(MORSE)],
                [Alignment(CuckerSmale(0.5, 1.0), on="v")]):
        ref = _field(eff, x, v, "numpy")
        for tol in (1e-3, 1e-4, 1e-5, 1e-6):
            assert _rel(_field(eff, x, v, NUFFT(tol)), ref) <= tol, (eff, tol)


@pytest.mark.parametrize("kernel", [CS, MORSE], ids=["cs", "morse"])
def test_each_kernel_alone_matches_dense_in_2d(kernel):
    x, v, w = _cloud(800, 2, 3.0, seed=5)
    eff = [Alignment(kernel)]
    ref = _field(eff, x, v, Dense(), w)
    for tol in (1e-3, 1e-6, 1e-9):
        assert _rel(_field(eff, x, v, NUFFT(tol), w), ref) <= tol


def test_first_order_aggregation_and_a_constant_kernel_need_one_mode():
    x, _, w = _cloud(300, 2, 5.0, seed=2)
    sc = Scene([Aggregation(Quadratic(0.7))], "mean", weights=w, pairsum=NUFFT(1e-10))
    got = sc.rhs(x)[0]
    # closed form: dx_i = 0.7 Σ_j w_j (x_j − x_i) = 0.7 (x̄ − x_i)
    assert np.max(np.abs(got - 0.7 * (w @ x - x))) <= 1e-10 * np.max(np.abs(got))
    (info,) = next(iter(sc._plans.values())).info()
    assert info["modes"] == (1, 1)


def test_coincident_agents_all_or_some():
    x, v, w = _cloud(200, 2, 1.0, seed=3)
    x[:120] = x[0]                                         # 120 agents on one point
    for xs in (x, np.repeat(x[:1], 200, axis=0)):          # some coincide / all coincide
        ref = _field(MIXED, xs, v, "numpy", w)
        assert _rel(_field(MIXED, xs, v, NUFFT(1e-8), w), ref) <= 1e-8


def test_a_tiny_and_a_spread_cloud():
    x, v, w = _cloud(400, 2, 1e-8, shift=3e5, seed=4)      # diameter 1e-8 next to 3e5
    assert _rel(_field(MIXED, x, v, NUFFT(1e-7), w), _field(MIXED, x, v, "numpy", w)) <= 1e-7
    x, v, w = _cloud(400, 2, 30.0, seed=4)                 # 30 kernel widths
    eff = [Alignment(CS)]
    assert _rel(_field(eff, x, v, NUFFT(1e-6), w), _field(eff, x, v, "numpy", w)) <= 1e-6


def test_error_follows_tol_as_documented():
    """The documented relation (NUFFT docstring): relative field error below 0.2·tol for tol
    from 1e-2 to 1e-8, below 0.75·tol at 1e-10 (round-off of the transforms), and falling
    with tol (at least 10x per 100x in tol)."""
    x, v, w = _cloud(700, 2, 4.0, seed=6)
    ref = _field(MIXED, x, v, "numpy", w)
    errs = []
    for tol in (1e-2, 1e-4, 1e-6, 1e-8, 1e-10):
        errs.append(_rel(_field(MIXED, x, v, NUFFT(tol), w), ref))
        assert errs[-1] <= (0.2 if tol >= 1e-8 else 0.75) * tol, (tol, errs)
    assert all(b <= a / 10 for a, b in zip(errs, errs[1:])), errs


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 6), st.integers(40, 300), st.sampled_from([0.0, 0.1, 0.5]),
       st.sampled_from([1e-2, 1e-4, 1e-7]), st.floats(0.5, 20.0), st.floats(1e-4, 1.0),
       st.integers(0, 2**16))
def test_tight_clusters_keep_the_field_error_below_tol(n_clusters, n, soft, tol, spread,
                                                       flat, seed):
    """Agents in a few tight clusters with a soft-core (or cusped) Morse kernel: most of the
    largest kernel values sit on pairs inside a cluster, whose carrier difference vanishes,
    so they do not set the field's scale: the plain mean of ``|φ|`` over pairs (κ) let the
    error reach 5·tol (5 clusters, soft = 0.5, tol = 1e-7) before the field check rebuilt
    such grids finer."""
    rng = np.random.default_rng(seed)
    ext = spread * np.array([1.0, flat])
    centres = rng.uniform(0.0, 1.0, (n_clusters, 2)) * ext
    x = centres[rng.integers(0, n_clusters, n)] + 1e-3 * spread * rng.normal(size=(n, 2)) + 469.0
    v = rng.normal(size=(n, 2))
    w = rng.dirichlet(np.ones(n))
    eff = [AttractionRepulsion(Morse(1.07, 4.5, 1.17, 0.3, soft=soft))]
    ref = _field(eff, x, v, "numpy", w)
    assert _rel(_field(eff, x, v, NUFFT(tol, near_field=None), w), ref) <= tol


def test_centred_carriers_keep_the_accuracy_of_tiny_fluctuations():
    """Velocities with a common mean 1e3 and fluctuations 1e-9: the pair sum (of size ~1e-9)
    is accurate relative to the fluctuations, not to the mean (1e12 times larger)."""
    x, v, w = _cloud(500, 2, 2.0, seed=7)
    v = 1e3 + 1e-9 * v
    eff = [Alignment(CS)]
    ref = _field(eff, x, v, "numpy", w)
    assert 1e-10 < np.max(np.abs(ref)) < 1e-5
    assert _rel(_field(eff, x, v, NUFFT(1e-6), w), ref) <= 1e-6


def test_thread_counts_agree():
    x, v, w = _cloud(300, 3, 1.5, seed=8)
    ref = _field(MIXED, x, v, "numpy", w)
    for n in (1, 2):
        with num_threads(n):
            assert _rel(_field(MIXED, x, v, NUFFT(1e-5), w), ref) <= 1e-5


# ---------------------------------------------------------------------------- caching
def test_grids_and_plans_are_kept_while_the_cloud_fits():
    x, v, w = _cloud(400, 2, 3.0, seed=9)
    sc = Scene([Alignment(CS)], "sum", weights=w, pairsum=NUFFT(1e-6))
    ref = Scene([Alignment(CS)], "sum", weights=w, pairsum="numpy")
    with num_threads(1):
        for shift in range(5):                             # the cloud translates: same grid
            xs = x + 7.0 * shift
            assert _rel(sc.rhs(xs, v)[1], ref.rhs(xs, v)[1]) <= 1e-6
        plan = sc._plans[(400, 2, 1)]
        assert isinstance(plan, NUFFTPlan)
        assert (plan.groups[0].builds, plan.groups[0].plans) == (1, 1)
        for scale, builds in ((1.1, 1), (2.0, 2), (0.1, 3)):   # fits / grew / shrank 20x
            xs = x * scale
            assert _rel(sc.rhs(xs, v)[1], ref.rhs(xs, v)[1]) <= 1e-6
            assert plan.groups[0].builds == builds, scale


def test_a_diverging_state_gives_nan_not_a_crash():
    x, v, w = _cloud(50, 2, 1.0)
    sc = Scene([Alignment(CS)], "sum", weights=w, pairsum=NUFFT())
    plan = sc.pairsum.plan(sc, 50, 2)
    x[3, 0] = np.inf
    assert np.all(np.isnan(sc.pairsum.evaluate(plan, x, v)["v"]))


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("tol", [0.0, 1.0, -1e-3, 2.0, float("nan"), "1e-6", None])
def test_tol_outside_zero_one_is_refused(tol):
    with pytest.raises(InvalidInput, match="tol must"):
        NUFFT(tol)


def test_max_modes_is_validated():
    with pytest.raises(InvalidInput, match="max_modes must be >= 1"):
        NUFFT(max_modes=0)


def test_more_than_three_dimensions_is_refused_at_plan_time():
    x, v, _ = _cloud(10, 4, 1.0)
    with pytest.raises(InvalidInput, match=r"k <= 3 .* dim = 4: project"):
        Scene([Alignment(CS)], pairsum=NUFFT()).rhs(x, v)


def test_kernels_without_a_smooth_radial_profile_are_refused():
    x, v, _ = _cloud(10, 2, 1.0)
    with pytest.raises(InvalidInput, match=r"Morse\(.*soft=0.0\).*returned None.*soft > 0"):
        Scene([AttractionRepulsion(Morse())], pairsum="nufft").rhs(x, v)
    with pytest.raises(InvalidInput, match=r"<lambda>.*has no radial_profile\(\) method"):
        Scene([Alignment(lambda s: np.exp(-s * s))], pairsum="nufft").rhs(x, v)

    class NotCallable:
        def __call__(self, s):
            return np.ones_like(s)

        def radial_profile(self):
            return 3.0

    with pytest.raises(InvalidInput, match="returned 3.0, not a callable"):
        Scene([Alignment(NotCallable())], pairsum="nufft").rhs(x, v)

    class Broken(NotCallable):
        def radial_profile(self):
            return lambda s: s[:, None]

    with pytest.raises(InvalidInput, match="radial profile of .*Broken.* must return"):
        Scene([Alignment(Broken())], pairsum="nufft").rhs(x, v)


def test_radial_profiles_of_the_shipped_kernels():
    s = np.array([0.0, 0.5, 3.0])
    for kern in (CS, MORSE, Quadratic(2.0)):
        assert np.array_equal(radial_profile(kern)(s), kern(s))
    with pytest.raises(InvalidInput, match="not smooth where agents coincide"):
        radial_profile(Morse(soft=0.0))


def test_a_3d_cloud_of_diameter_1000_is_too_large_before_any_big_allocation():
    x, v, _ = _cloud(2000, 3, 1000.0)
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5))], pairsum=NUFFT(1e-6))
    tracemalloc.start()
    try:
        with pytest.raises(TooLarge, match=r"3-D cloud of extents .* needs at least .* Fourier "
                                           r"modes for tol=1e-06, more than max_modes=1048576"):
            sc.rhs(x, v)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20                               # no mode array was allocated


def test_a_smaller_max_modes_is_respected():
    x, v, w = _cloud(100, 2, 5.0)
    with pytest.raises(TooLarge, match="more than max_modes=100"):
        _field([Alignment(CS)], x, v, NUFFT(1e-8, max_modes=100), w)


def test_alias_and_repr():
    assert repr(as_pairsum("nufft")) == "NUFFT(tol=1e-06)"
    assert repr(NUFFT(1e-3, max_modes=4096)) == "NUFFT(tol=0.001, max_modes=4096)"
    assert Scene([Alignment()], pairsum="nufft").precision == "double"
    with pytest.raises(InvalidInput, match="block= and precision= configure the default"):
        Scene([Alignment()], pairsum="nufft", precision="mixed")
    assert issubclass(TooLarge, KinredError)


# ---------------------------------------------------------------------------- simulations
def test_a_short_rk4_run_matches_dense_trajectories():
    x, v, w = _cloud(300, 2, 3.0, seed=11)
    eff = [Alignment(CS), AttractionRepulsion(MORSE), SelfPropulsion(1.0, 0.5)]
    kw = dict(method="rk4", save=SaveAt(every=5, states=True))
    a = simulate(Scene(eff, "mean", weights=w, pairsum=NUFFT(1e-9)), x, v, (0, 0.8), 0.04, **kw)
    b = simulate(Scene(eff, "mean", weights=w), x, v, (0, 0.8), 0.04, **kw)
    assert np.max(np.abs(a.v[-1] - a.v[0])) > 0.05                      # it moved
    for got, ref in ((a.x, b.x), (a.v, b.v)):
        assert np.max(np.abs(got - ref)) <= 1e-8 * np.max(np.abs(ref))


@pytest.mark.parametrize("beta, t_end, verdict", [(1.5, 12.0, "pos"), (1.7, 3.0, "neg")])
def test_reduced_table1_run_projected_to_2d_gives_the_dense_verdict_and_gamma(beta, t_end,
                                                                             verdict):
    """Table 1 reduced (N = 200 in d = 200, Gaussian JL to k = 2, G = 0.8·1000/N, Euler
    h = 0.02): the same verdict and Γ(t) within 1e-4 relative wherever Γ > 1e-20 (a
    conservative stand-in for the round-off floor of ``kinred.observables.gamma_floor``,
    about 1e-30 here)."""
    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(0.0, 1.0, (200, 200)), rng.uniform(-1.0, 1.0, (200, 200))
    M = jl_matrix(2, 200, kind="gaussian", seed=4)
    y0, w0 = M.apply(x0), M.apply(v0)
    gam = {}
    for name, ps in (("dense", Dense()), ("nufft", NUFFT(1e-5))):
        sc = Scene([Alignment(CuckerSmale(4.0, beta))], "sum", pairsum=ps)
        tr = simulate(sc, y0, w0, (0.0, t_end), 0.02, method="euler",
                      save=SaveAt(every=10, observables=("gamma",)))
        gam[name] = tr.observables["gamma"]
    g, h = gam["dense"], gam["nufft"]
    assert flocking_verdict(g[-1]) == flocking_verdict(h[-1]) == verdict
    keep = g > 1e-20
    assert keep.sum() == g.size
    assert np.max(np.abs(h[keep] - g[keep]) / g[keep]) <= 1e-4
    assert gamma(w0) == pytest.approx(g[0], rel=1e-12)



@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 50.0), min_size=1, max_size=3), st.floats(1e-3, 100.0),
       st.integers(1, 10**7))
def test_slice_cap_is_the_smallest_slice_whose_grid_exceeds_max_modes(ext, t, max_modes):
    """The 1-D search stops at ``_slice_cap``: the first half-mode count of the widest axis
    whose k-D grid (every axis counted) has more than ``max_modes`` modes – checked against
    the count itself at the cap and one below (the refusal of a 3-D cloud at 2²⁰ modes took
    9 s of 6-million-sample slices when the cap was max_modes half-modes)."""
    from kinred.pairsum._fastsum import _slice_cap

    E = np.array(ext)
    big = float(E.max()) + t

    def count(m):
        return math.prod(2 * math.floor(m * ((e + t) / big)) + 1 for e in E)

    cap = _slice_cap(E, t, max_modes)
    assert count(cap) > max_modes
    assert cap == 0 or count(cap - 1) <= max_modes


def test_the_cheap_mode_estimate_samples_no_slice_beyond_the_mode_limit(monkeypatch):
    """``estimate_modes`` (what ``pairsum="auto"`` ranks NUFFT by before building a grid)
    samples a 1-D slice only up to the half-modes whose k-D grid exceeds ``max_modes``: with
    ``max_modes`` itself as the cap, a flat 3-D cloud with a narrow soft core sampled slices
    of 10⁸ points, 33 s of "cheap" estimate before a 0.1 s dense sum."""
    from kinred.pairsum import _fastsum

    sizes = []
    profile = _fastsum._profile
    monkeypatch.setattr(_fastsum, "_profile",
                        lambda phi, s, name: (sizes.append(s.size), profile(phi, s, name))[1])
    phi = radial_profile(Morse(1.34, 4.25, 0.64, 0.17, soft=0.01))
    for max_modes in (2**20, 2**24):
        sizes.clear()
        assert _fastsum.estimate_modes(phi, np.array([0.65, 234.0, 0.0028]), 1e-6, 10.0, 1e-3,
                                       max_modes, "Morse") is None
        assert 0 < max(sizes) <= 2**13, max(sizes)
    # a cloud whose grid fits is still estimated (the cap does not cut a slice that fits)
    soft = radial_profile(Morse(soft=0.5))
    assert _fastsum.estimate_modes(soft, np.array([2.0, 1.0, 0.5]), 1e-4, 1.0, 0.1, 2**20,
                                   "Morse") is not None


def _clusters(seed, n=1200):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.0, 1.0, (5, 2)) * [0.0055, 7.74]
    x = centres[rng.integers(0, 5, n)] + 7.74e-3 * rng.normal(size=(n, 2)) + 469.0
    return x, rng.normal(size=(n, 2)), rng.dirichlet(np.ones(n))


CLUSTER_MORSE = [AttractionRepulsion(Morse(1.066, 4.535, 1.169, 0.3015, soft=0.5))]


def test_the_field_check_rebuilds_a_grid_that_misses_tol_on_sampled_rows():
    """A grid's first sums are compared with the exact ones on sampled rows (all of them
    here); five tight clusters miss tol with the accuracy scale of random pairs, so the grid
    is rebuilt finer until they do not – and the whole field is then within tol."""
    x, v, w = _clusters(2)
    sc = Scene(CLUSTER_MORSE, "sum", weights=w, pairsum=NUFFT(1e-7))
    got = sc.rhs(x, v)[1]
    g = next(iter(sc._plans.values())).groups[0]
    assert g.builds >= 2 and g.kappa_scale < 0.5, (g.builds, g.kappa_scale)
    assert g.check["error"] <= 0.5e-7 and not g.check["below_floor"]
    assert _rel(got, _field(CLUSTER_MORSE, x, v, "numpy", w)) <= 1e-7
    # the check ran once: the next call reuses the grid
    sc.rhs(x, v)
    assert g.builds == next(iter(sc._plans.values())).groups[0].builds


def test_the_field_check_keeps_a_grid_that_meets_tol():
    x, v, w = _cloud(800, 2, 4.0, seed=11)
    sc = Scene(MIXED, weights=w, pairsum=NUFFT(1e-6))
    sc.rhs(x, v)
    for g in next(iter(sc._plans.values())).groups:
        assert g.builds == 1 and g.kappa_scale == 1.0
        assert g.check["error"] <= 0.5e-6


def test_the_field_check_warns_when_no_finer_grid_meets_it(monkeypatch):
    """A check that cannot be met (made impossible here) gives up – after CHECK_REBUILDS finer
    grids, or when the next one would exceed max_modes – with a KinredWarning naming the
    measured error, and the sums of the last grid are returned."""
    from kinred.errors import KinredWarning
    from kinred.pairsum import nufft

    monkeypatch.setattr(nufft, "CHECK_FACTOR", 1e-30)
    x, v, w = _clusters(1, n=300)
    sc = Scene(CLUSTER_MORSE, "sum", weights=w, pairsum=NUFFT(1e-4))
    with pytest.warns(KinredWarning, match="miss the requested tol=0.0001 on 300 sampled rows"):
        got = sc.rhs(x, v)[1]
    assert _rel(got, _field(CLUSTER_MORSE, x, v, "numpy", w)) <= 1e-2
    g = next(iter(sc._plans.values())).groups[0]
    assert g.checked and 1 <= g.builds <= 1 + nufft.CHECK_REBUILDS


def test_pairs_without_a_carrier_difference_do_not_set_the_accuracy_scale():
    """Half the agents on one point: a quarter of the pairs sit at φ(0) but add nothing to the
    field (their carrier difference is zero), and inflated κ 80× (3-D, Morse with a narrow
    repulsion: field error 7·tol at tol = 1e-3, found by benchmarks/sweep_pairsum_accuracy)."""
    from kinred.pairsum import _fastsum

    rng = np.random.default_rng(13)
    x = rng.uniform(0.0, 1.0, (1600, 3)) * [50.6, 28.9, 4e-5] - 26.3
    x[:800] = x[0]
    v = rng.normal(size=x.shape)
    eff = [AttractionRepulsion(Morse(0.475, 3.16, 1.85, 0.132, soft=0.5))]
    phi = radial_profile(eff[0].kernel)
    ext = np.ptp(x, axis=0)
    _, plain = _fastsum.kernel_scales(phi, x, ext, "Morse")
    _, moving = _fastsum.kernel_scales(phi, x, ext, "Morse", z=x)
    assert moving < plain / 20
    # the velocities differ on coincident positions: those pairs count for alignment
    assert _fastsum.kernel_scales(phi, x, ext, "Morse", z=v)[1] == plain
    ref = _field(eff, x, v, "numpy", None, "mean")
    assert _rel(_field(eff, x, v, NUFFT(1e-3, near_field=None), None, "mean"), ref) <= 1e-3


@settings(max_examples=40, deadline=None)
@given(k=st.integers(1, 3), seed=st.integers(0, 2**31), full=st.booleans(),
       route=st.sampled_from([0.0, math.inf, 48.0]))
def test_truncated_series_is_the_inverse_dct_of_the_masked_coefficients(k, seed, full, route):
    """The grid's truncation error is measured on the flat region's points by a separable
    sum (``_fastsum.truncated_series``: each axis by a matrix product or by its inverse DCT,
    ``route`` the ratio between them); its twin is scipy's inverse DCT-I of the masked
    coefficients on the whole orthant."""
    from scipy import fft as sfft

    from kinred.pairsum import _fastsum

    old = _fastsum.SERIES_MATRIX_RATIO
    _fastsum.SERIES_MATRIX_RATIO = route
    try:
        _truncated_series_twin(k, seed, full, sfft, _fastsum)
    finally:
        _fastsum.SERIES_MATRIX_RATIO = old


@pytest.mark.parametrize("shape", [(2000, 6), (6, 2000), (1500, 5, 3)])
def test_truncated_series_mixes_its_two_routes_in_one_call(shape):
    """A long axis by its inverse DCT and the short ones by matrix products, in one call (the
    ratio's own choice), against the twin."""
    from scipy import fft as sfft

    from kinred.pairsum import _fastsum

    _truncated_series_twin(len(shape), 7, False, sfft, _fastsum, shape=shape)


def _truncated_series_twin(k, seed, full, sfft, _fastsum, shape=None):
    rng = np.random.default_rng(seed)
    if shape is None:
        shape = tuple(int(n) for n in rng.integers(2, 40 if k < 3 else 14, k))
    b = rng.standard_normal(shape) * np.exp(-0.2 * sum(np.ix_(*[np.arange(n) for n in shape])))
    counts = [n if full else int(rng.integers(1, n + 1)) for n in shape]
    rows = [np.sort(rng.choice(n, int(rng.integers(1, n + 1)), replace=False)) for n in shape]
    if max(shape) >= 1000:                          # the routes-mixing cases: a long axis
        counts = [max(1, int(0.8 * n)) for n in shape]
        rows = [np.arange(n) for n in shape]
    mask = np.zeros(shape, bool)
    mask[tuple(slice(0, c) for c in counts)] = True
    twin = sfft.idctn(np.where(mask, b, 0.0) * math.prod(2 * (n - 1) for n in shape),
                      type=1)[np.ix_(*rows)]
    got = _fastsum.truncated_series(b, counts, rows)
    assert got.shape == twin.shape
    assert np.max(np.abs(got - twin)) <= 1e-13 * np.sum(np.abs(b)) * 2 ** k


@settings(max_examples=25, deadline=None)
@given(k=st.integers(1, 6), seed=st.integers(0, 2**31), scale=st.sampled_from([1e-3, 1.0, 1e4]))
def test_sq_distances_are_the_broadcast_sum_bit_for_bit(k, seed, scale):
    """The rows of the field check and of the cell list's cutoff: coordinate by coordinate,
    the bits of numpy's broadcast sum over the last axis (their cutoffs and checks did not
    change when it replaced that sum)."""
    from kinred.pairsum import _fastsum

    rng = np.random.default_rng(seed)
    p = rng.standard_normal((int(rng.integers(1, 40)), k)) * scale + 1e3 * scale
    q = rng.standard_normal((int(rng.integers(1, 60)), k)) * scale + 1e3 * scale
    assert np.array_equal(_fastsum.sq_distances(p, q),
                          np.sum((q[None, :, :] - p[:, None, :]) ** 2, axis=2))
