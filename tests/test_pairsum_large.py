"""Pair sums at large N: the dense backend's refusal of sizes out of reach (before any work),
the cell-list backend against the exact sums, ``pairsum="auto"``'s choice."""

import time

import numpy as np
import pytest

from kinred.dynamics import Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene
from kinred.errors import InvalidInput, TooLarge
from kinred.pairsum import Dense
from kinred.pairsum.dense import estimate_seconds

CS = CuckerSmale(0.8, 1.5)


# ------------------------------------------------------------------ Dense refuses
def test_dense_refuses_ten_million_agents_within_a_second():
    sc = Scene([Alignment(CS)])
    x = np.zeros((10**7, 2))        # calloc'd pages: nothing touched before the refusal
    t0 = time.perf_counter()
    with pytest.raises(TooLarge) as err:
        sc.rhs(x, x)
    assert time.perf_counter() - t0 < 1.0
    msg = str(err.value)
    assert "10000000 agents" in msg and "6.94 h" in msg       # the estimate, named
    assert "pairsum='auto'" in msg and "'nufft'" in msg and "'cells'" in msg


def test_dense_refusal_in_high_dimension_names_projection_and_random_batch():
    with pytest.raises(TooLarge, match="Scene.project.*random_batch"):
        Dense().plan(Scene([Alignment(CS)]), 10**7, 200)


def test_dense_estimate_is_a_lower_bound_and_scales_quadratically():
    terms = Scene([Alignment(CS)]).pair_terms
    morse = Scene([AttractionRepulsion(Morse(soft=0.1))]).pair_terms
    # independent closed form: n(n-1)/2 pairs at 2e9 pairs/s (compiled) or 5e8 (numpy kernel)
    assert estimate_seconds(10**7, 2, terms) == pytest.approx(10**7 * (10**7 - 1) / 2 / 2e9)
    assert estimate_seconds(10**5, 2, morse) == pytest.approx(10**5 * (10**5 - 1) / 2 / 5e8)
    # measured here: a dense rhs takes longer than the estimate (a lower bound)
    rng = np.random.default_rng(0)
    x, v = rng.uniform(0, 1, (4000, 2)), rng.normal(size=(4000, 2))
    sc = Scene([Alignment(CS)])
    sc.rhs(x, v)
    t0 = time.perf_counter()
    sc.rhs(x, v)
    assert time.perf_counter() - t0 > estimate_seconds(4000, 2, terms)


def test_dense_max_seconds_option():
    sc = Scene([Alignment(CS)], pairsum=Dense(max_seconds=1e-6))
    with pytest.raises(TooLarge, match="max_seconds=1e-06"):
        sc.rhs(np.zeros((1000, 2)), np.zeros((1000, 2)))
    assert repr(Dense(max_seconds=10.0)) == "Dense(max_seconds=10.0)"
    assert repr(Dense()) == "Dense()"
    for bad in (0.0, -1.0, float("inf"), "1"):
        with pytest.raises(InvalidInput, match="max_seconds"):
            Dense(max_seconds=bad)


def test_dense_refuses_a_workspace_beyond_the_memory_limit(monkeypatch):
    monkeypatch.setenv("KINRED_MAX_BYTES", "1M")
    with pytest.raises(TooLarge, match="Dense: the workspace"):
        Dense().plan(Scene([Alignment(CS)]), 20000, 2)
    monkeypatch.setenv("KINRED_MAX_BYTES", "1G")
    assert Dense().plan(Scene([Alignment(CS)]), 20000, 2).n == 20000


# ------------------------------------------------------------------ the cell list
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

from kinred.dynamics import Quadratic, SelfPropulsion  # noqa: E402
from kinred.pairsum import CellList, tail_bound  # noqa: E402
from kinred.pairsum import _cell_kernels, _cells  # noqa: E402
from kinred.pairsum.cells import cutoff_radius  # noqa: E402


def _pair_field(effects, x, v, pairsum, weights):
    """The pair contribution to the velocity field (the local effects subtracted)."""
    sc = Scene(effects, normalize="mean", weights=weights, pairsum=pairsum)
    return sc.rhs(x, v)[1]


@given(n=st.integers(2, 200), k=st.integers(1, 3), ext=st.floats(1e-3, 60.0),
       aspect=st.lists(st.floats(0.05, 1.0), min_size=3, max_size=3),
       offset=st.floats(-1e6, 1e6), seed=st.integers(0, 2**31 - 1),
       la=st.floats(0.2, 3.0), soft=st.sampled_from([0.0, 0.05, 0.3]),
       tol=st.sampled_from([1e-3, 1e-6, 1e-9]))
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_cell_list_matches_dense_on_random_clouds(n, k, ext, aspect, offset, seed, la, soft, tol):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 1.0, (n, k)) * (ext * np.array(aspect[:k])) + offset
    v = rng.normal(size=(n, k))
    w = rng.dirichlet(np.ones(n))
    eff = [AttractionRepulsion(Morse(1.0, la, 1.5, 0.5 * la, soft=soft)),
           Alignment(CuckerSmale(1.0, 2.0), on="v")]   # CS on velocities: an algebraic tail
    got = _pair_field(eff, x, v, CellList(tol=tol), w)
    exact = _pair_field(eff, x, v, Dense(), w)
    assert np.linalg.norm(got - exact) <= tol * np.linalg.norm(exact) + 1e-300


def test_cell_list_twins_and_threads_agree():
    from kinred._parallel import num_threads

    rng = np.random.default_rng(3)
    x = rng.uniform(0, 30, (1500, 2))
    v = rng.normal(size=(1500, 2))
    eff = [AttractionRepulsion(Morse(1.0, 1.0, 1.5, 0.5, soft=0.1)), SelfPropulsion(1.0, 0.5)]
    ref = Scene(eff, pairsum=CellList(tol=1e-6, compiled=False)).rhs(x, v)[1]
    for nt in (1, 2):
        with num_threads(nt):
            got = Scene(eff, pairsum=CellList(tol=1e-6)).rhs(x, v)[1]
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_cell_kernels_against_numpy_twins():
    rng = np.random.default_rng(5)
    for k in (1, 2, 3):
        s = rng.uniform(0, 10, (400, k)) - 5.0
        grid = _cells.build(s, 1.7, chunk=512)
        # every pair within R exactly once: against the brute force
        d2 = np.sum((s[:, None] - s[None]) ** 2, axis=2)
        want = int(np.sum(np.triu(d2 < 1.7 ** 2, 1)))
        got = 0
        Z = rng.normal(size=(400, 3))
        Zs = Z[grid.perm]                      # sorted order
        A1, A2 = np.zeros((400, 3)), np.zeros((400, 3))
        for items in grid.chunks:
            bufs = [np.empty(grid.buffer, np.int64), np.empty(grid.buffer, np.int64),
                    np.empty(grid.buffer)]
            twin = [np.empty(grid.buffer, np.int64), np.empty(grid.buffer, np.int64),
                    np.empty(grid.buffer)]
            m = _cell_kernels.gather_pairs(items, grid.S, grid.start, grid.count, grid.nbr,
                                           grid.r2, *bufs)
            m2 = _cell_kernels.gather_pairs_numpy(items, grid.S, grid.start, grid.count,
                                                  grid.nbr, grid.r2, *twin)
            assert m == m2
            for b, t in zip(bufs, twin):
                np.testing.assert_allclose(b[:m], t[:m], rtol=1e-12)
            phi = np.zeros(grid.buffer)
            phi[:m] = np.exp(-bufs[2][:m])
            _cell_kernels.scatter_pairs(bufs[0], bufs[1], phi, m, Zs, A1)
            _cell_kernels.scatter_pairs_numpy(bufs[0], bufs[1], phi, m, Zs, A2)
            got += m
        assert got == want
        np.testing.assert_allclose(A1, A2, rtol=1e-12, atol=1e-12 * np.abs(A2).max())
        # the sums against the brute force (sorted order back to the original)
        A = np.zeros((400, 3))
        A[grid.perm] = A1
        phi = np.where(d2 < 1.7 ** 2, np.exp(-d2), 0.0)
        np.fill_diagonal(phi, 0.0)
        np.testing.assert_allclose(A, phi @ Z, rtol=1e-12, atol=1e-12 * np.abs(A).max())


def test_morse_tail_bound_bounds_the_kernel_beyond():
    for m in (Morse(1.0, 2.0, 1.5, 0.5, soft=0.0), Morse(0.5, 2.0, 1.0, 0.5, soft=0.1),
              Morse(2.0, 0.3, 0.1, 1.5, soft=1.0)):
        B = tail_bound(m)
        s = np.linspace(0.01, 40.0, 4000)
        run = np.maximum.accumulate(np.abs(m(s))[::-1])[::-1]     # sup over s' >= s
        assert np.all(run <= B(s) * (1 + 1e-12))
        assert np.all(np.diff(B(s)) <= 0)
    assert tail_bound(CS)(np.array([3.0]))[0] == pytest.approx(0.8 * 10 ** -1.5)
    assert tail_bound(Quadratic(-2.0))(np.array([1e9]))[0] == 2.0
    assert tail_bound(lambda s: s) is None


def test_cutoff_radius_closed_form():
    # B(s) = e^(-s): R = ln(1/target) exactly
    B = lambda s: np.exp(-np.asarray(s))              # noqa: E731
    assert cutoff_radius(B, 1e-6, 100.0) == pytest.approx(np.log(1e6), rel=1e-8)
    assert cutoff_radius(B, 1e-6, 5.0) == 5.0         # none within the cloud: no truncation


def test_cell_list_refuses_what_it_cannot_do():
    with pytest.raises(InvalidInput, match="3\\^4 = 81 cells"):
        Scene([Alignment(CS)], pairsum=CellList()).rhs(np.zeros((3, 4)), np.zeros((3, 4)))
    with pytest.raises(InvalidInput, match="declares none"):
        Scene([Alignment(lambda s: np.exp(-s))], pairsum=CellList()).rhs(
            np.eye(3), np.eye(3))
    for bad in ({"tol": 0.0}, {"tol": 1.0}, {"cutoff": -1.0}, {"compiled": "no"}):
        with pytest.raises(InvalidInput):
            CellList(**bad)


def test_cell_list_fixed_cutoff_for_an_unknown_tail():
    rng = np.random.default_rng(2)
    x, v = rng.uniform(0, 10, (300, 2)), rng.normal(size=(300, 2))
    eff = [Alignment(lambda s: np.exp(-s * s))]
    # independent: the dense sum with the kernel cut at 3 by hand (a fixed cutoff sums the
    # kernel itself, no table: exact within it)
    cut = [Alignment(lambda s: np.where(s < 3.0, np.exp(-s * s), 0.0))]
    ref = Scene(cut).rhs(x, v)[1]
    for compiled in (True, False):
        got = Scene(eff, pairsum=CellList(cutoff=3.0, compiled=compiled)).rhs(x, v)[1]
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-13)
    # a kernel infinite at 0 (unknown tail, so a fixed cutoff) still runs: no scale is sampled
    cusp = [Alignment(lambda s: np.exp(-s) / s)]
    got = Scene(cusp, pairsum=CellList(cutoff=2.0)).rhs(x, v)[1]
    assert np.all(np.isfinite(got))
    assert repr(CellList(cutoff=3.0)) == "CellList(tol=1e-06, cutoff=3.0)"


def test_cell_list_coincident_agents_and_constant_kernel():
    x = np.zeros((5, 2))
    v = np.arange(10.0).reshape(5, 2)
    eff = [Alignment(CuckerSmale(1.0, 1.0))]
    # the middle agent's field is 0 exactly: compared at the round-off floor of a 5-term sum
    # of |v| <= 9 (the two passes add in different orders), not to its digits
    floor = 16 * len(v) * np.finfo(float).eps * np.abs(v).max()
    np.testing.assert_allclose(Scene(eff, pairsum=CellList()).rhs(x, v)[1],
                               Scene(eff).rhs(x, v)[1], rtol=1e-12, atol=floor)
    # Quadratic: no decay, so nothing is cut: the exact sum
    rng = np.random.default_rng(0)
    y = rng.normal(size=(50, 3))
    from kinred.dynamics import Aggregation
    agg = [Aggregation(Quadratic(0.7))]
    np.testing.assert_allclose(Scene(agg, pairsum=CellList()).rhs(y)[0],
                               Scene(agg).rhs(y)[0], rtol=1e-11, atol=1e-13)


# ------------------------------------------------------------------ pairsum="auto"
from kinred.pairsum import Auto, as_pairsum  # noqa: E402

CASES = [  # name, n, k, extents, effects, expected choice
    ("few agents", 500, 2, (1, 1), [Alignment(CS)], "dense"),
    ("compact 2-D CS", 100_000, 2, (1, 1), [Alignment(CS)], "nufft"),
    ("spread short-range Morse", 100_000, 2, (1000, 1000),
     [AttractionRepulsion(Morse(0.5, 1.0, 1.0, 0.5, soft=0.1))], "cells"),
    ("spread unsoftened Morse", 100_000, 2, (1000, 1000),
     [AttractionRepulsion(Morse(0.5, 1.0, 1.0, 0.5, soft=0.0))], "cells"),
    ("compact unsoftened Morse: near field", 20_000, 2, (5, 5),
     [AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=0.0))], "nufft"),
    ("high dimension", 20_000, 10, (1,) * 10, [Alignment(CS)], "dense"),
    ("compact 3-D CS", 50_000, 3, (1, 1, 1), [Alignment(CS)], "nufft"),
    # two terms, one a numpy kernel: Dense pays both (8.6 s measured, 3x the old estimate)
    ("3-D slab, CS + soft Morse", 30_000, 3, (29, 6, 1.7),
     [Alignment(CuckerSmale(0.8, 0.7)), AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.4, soft=0.3))],
     "nufft"),
]


@pytest.mark.parametrize("name,n,k,ext,effects,want", CASES, ids=[c[0] for c in CASES])
def test_auto_choice_on_a_table_of_cases(name, n, k, ext, effects, want):
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, (n, k)) * np.array(ext) + 1e3
    v = rng.normal(size=(n, k))
    sc = Scene(effects, pairsum="auto")
    plan = sc._plan(n, k)
    got = sc.pairsum.choose(plan, x, v)
    assert got == want, plan.info()
    est = plan.info()["estimates"]
    assert est[got] == min(est.values()) and "random_batch" not in est


def test_dense_cost_model_prices_every_term_and_its_kernel():
    """A term's cost by its kernel's compiled form; a numpy kernel sends every term through
    the numpy strips; the dimension adds to each term (rates in ``_cost``'s notes)."""
    from kinred.pairsum import _cost

    n = 10_000
    half, pw, npy = (_cost.dense_seconds(n, 2, [kd]) for kd in ("cs_halfint", "cs_pow", None))
    assert half < pw < npy
    assert _cost.dense_seconds(n, 2, ["cs_pow", "cs_halfint"]) == pytest.approx(half + pw)
    assert _cost.dense_seconds(n, 2, ["cs_pow", None]) == pytest.approx(2 * npy)
    assert _cost.dense_seconds(n, 200, [None]) > 2 * _cost.dense_seconds(n, 2, [None])
    assert _cost.dense_seconds(n, 2, ["unknown kind"]) == pytest.approx(npy)


def test_auto_runs_says_what_it_chose_and_redecides():
    rng = np.random.default_rng(1)
    eff = [AttractionRepulsion(Morse(0.5, 1.0, 1.0, 0.5, soft=0.1))]
    x, v = rng.uniform(0, 1, (600, 2)), rng.normal(size=(600, 2))
    sc = Scene(eff, pairsum=Auto(tol=1e-8))
    f = sc.rhs(x, v)[1]
    info = sc.info()
    assert info["backend"] == "Auto(tol=1e-08)" and info["pairsum"]["chosen"] == "dense"
    np.testing.assert_allclose(f, Scene(eff).rhs(x, v)[1], rtol=1e-12)
    sc.rhs(x * 1.1, v)                      # same shape (within 25 %): no new decision
    assert sc.info()["pairsum"]["decisions"] == 1
    sc.rhs(x * 3.0, v)
    assert sc.info()["pairsum"]["decisions"] == 2
    assert as_pairsum("auto").tol == 1e-6 and repr(as_pairsum("auto")) == "Auto(tol=1e-06)"


def test_auto_refuses_what_nothing_deterministic_fits():
    sc = Scene([Alignment(CS)], pairsum="auto")
    plan = sc._plan(10**7, 10)
    with pytest.raises(TooLarge, match="no deterministic backend.*random_batch"):
        sc.pairsum.choose(plan, np.zeros((10**7, 10)))


def test_run_header_says_auto_chooses():
    from types import SimpleNamespace

    from kinred.commands.run import _backend_text

    text = _backend_text(SimpleNamespace(pairsum=("auto", {"tol": 1e-8}), precision="double"))
    assert text == ("auto pair sums (tol=1e-08, chosen per system among dense, nufft, cells by "
                    "estimated cost), precision double")


# ------------------------------------------------------------------ NUFFT near field
from kinred.pairsum import NUFFT  # noqa: E402
from kinred.pairsum import _nearfield  # noqa: E402


@given(n=st.integers(30, 400), k=st.integers(1, 3), ext=st.floats(0.5, 8.0),
       aspect=st.lists(st.floats(0.2, 1.0), min_size=3, max_size=3),
       offset=st.floats(-1e4, 1e4), seed=st.integers(0, 2**31 - 1),
       soft=st.sampled_from([0.0, 0.02, 0.1]), tol=st.sampled_from([1e-3, 1e-6]))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_nufft_near_field_matches_dense_on_random_clouds(n, k, ext, aspect, offset, seed, soft,
                                                         tol):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 1.0, (n, k)) * (ext * np.array(aspect[:k])) + offset
    v = rng.normal(size=(n, k))
    w = rng.dirichlet(np.ones(n))
    eff = [AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=soft))]
    sc = Scene(eff, normalize="mean", weights=w, pairsum=NUFFT(tol=tol, near_field=True))
    got = sc.rhs(x, v)[1]
    exact = _pair_field(eff, x, v, Dense(), w)
    assert np.linalg.norm(got - exact) <= tol * np.linalg.norm(exact)
    info = sc.info()["pairsum"][0]
    assert info["near_radius"] > 0 and info["near_pairs"] >= 0


def test_unsoftened_morse_runs_with_the_near_field():
    """Morse with soft = 0 (u ~ 1/s) has no smooth profile: the cusp goes to the near part."""
    rng = np.random.default_rng(4)
    x = rng.uniform(0, 5, (3000, 2)) + 100.0
    v = rng.normal(size=(3000, 2))
    eff = [AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=0.0))]
    sc = Scene(eff, pairsum=NUFFT(tol=1e-6, near_field=None))
    got = sc.rhs(x, v)[1]
    exact = Scene(eff).rhs(x, v)[1]
    assert np.linalg.norm(got - exact) <= 1e-6 * np.linalg.norm(exact)
    assert sc.info()["pairsum"][0]["near_radius"] is not None
    with pytest.raises(InvalidInput, match="smooth radial profile"):
        Scene(eff, pairsum=NUFFT()).rhs(x, v)          # the default: no split
    assert repr(NUFFT(near_field=True)) == "NUFFT(tol=1e-06, near_field=True)"
    assert repr(NUFFT(near_field=None)) == "NUFFT(tol=1e-06, near_field=None)"
    with pytest.raises(InvalidInput, match="near_field"):
        NUFFT(near_field="yes")


def test_far_part_is_the_kernel_beyond_the_near_radius_and_bounded_inside():
    m = Morse(0.5, 2.0, 1.0, 0.5, soft=0.0)
    tau = 1e-9
    phi_f = _nearfield.far_profile(m, 1.0, tau)
    s = np.linspace(1.0, 20.0, 500)
    # beyond ε_I: φ_F = G φ with 1 − G ≤ τ
    assert np.all(np.abs(phi_f(s) - m(s)) <= tau * np.abs(m(s)) * (1 + 1e-6))
    inside = phi_f(np.linspace(0.0, 1.0, 500))
    assert np.all(np.isfinite(inside))
    assert np.max(np.abs(inside)) <= np.max(np.abs(m(np.array([0.25]))))   # clamped at a
    near = _nearfield.near_kernel((m,), phi_f)
    q = np.linspace(0.01, 4.0, 50) ** 2
    np.testing.assert_allclose(near(q) + phi_f(np.sqrt(q)), m(np.sqrt(q)), rtol=1e-12)


def test_near_field_split_error_is_clear_when_nothing_fits():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 3, (500, 3))
    eff = [AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=0.0))]
    with pytest.raises(TooLarge, match="near-field split.*max_modes=1000"):
        Scene(eff, pairsum=NUFFT(tol=1e-8, max_modes=1000, near_field=None)).rhs(x, x)


def test_nufft_periods_follow_a_flat_cloud(monkeypatch):
    """Per-axis periods: a 2-D strip 40 × 0.4 gets far fewer modes across than along, within
    tol of the exact sum; with the old aspect floor (1/8) the thin axis had many more."""
    from kinred.pairsum import _fastsum

    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, (800, 2)) * np.array([40.0, 0.4]) + 1e3
    v = rng.normal(size=(800, 2))
    eff = [Alignment(CuckerSmale(0.8, 1.5))]
    exact = Scene(eff).rhs(x, v)[1]
    modes = {}
    default = _fastsum.MIN_ASPECT
    for floor in (8.0, default):
        monkeypatch.setattr(_fastsum, "MIN_ASPECT", floor)
        sc = Scene(eff, pairsum=NUFFT(tol=1e-6))
        got = sc.rhs(x, v)[1]
        assert np.linalg.norm(got - exact) <= 1e-6 * np.linalg.norm(exact)
        modes[floor] = sc.info()["pairsum"][0]["modes"]
    assert modes[default][1] < modes[8.0][1]          # the default floor is lower than 1/8
    assert np.prod(modes[default]) < np.prod(modes[8.0])


def test_fused_cell_pass_against_the_numpy_path():
    """The compiled fused pass (Morse, Cucker–Smale, the near part of a split) equals the
    general path (gather, numpy value_sq, scatter) to 1e-12."""
    from kinred.pairsum.cells import kernel_values, near_sums

    rng = np.random.default_rng(8)
    for k in (1, 2, 3):
        s = rng.uniform(0, 6, (700, k)) + 50.0
        s[5] = s[6]                                   # a coincident pair (soft = 0: u := 0)
        Z = rng.normal(size=(700, k + 1))
        m0 = Morse(0.5, 2.0, 1.0, 0.5, soft=0.0)
        phi_f = _nearfield.far_profile(m0, 1.3, 1e-8)
        for fn in (kernel_values(Morse(0.5, 2.0, 1.0, 0.5, soft=0.1)), kernel_values(m0),
                   kernel_values(CuckerSmale(0.8, 1.5)), kernel_values(CuckerSmale(0.8, 0.7)),
                   _nearfield.near_kernel((m0,), phi_f)):
            assert fn.fused is not None
            out = {}
            for compiled in (True, False):
                A = np.zeros((700, k + 1))
                near_sums(s, 2.0, [(fn, Z, A)], compiled)
                out[compiled] = A
            np.testing.assert_allclose(out[True], out[False], rtol=1e-12,
                                       atol=1e-12 * np.abs(out[False]).max())


def test_pair_form_hook():
    from kinred.pairsum import pair_form

    assert pair_form(Morse(1.0, 2.0, 1.5, 0.5, soft=0.2)) == ("morse", (1.0, 2.0, 1.5, 0.5, 0.2))
    assert pair_form(CuckerSmale(0.8, 0.7)) == ("cs", (0.8, 0.7))
    assert pair_form(lambda s: s) is None

    class Bad:
        def pair_form(self):
            return ("morse", (1.0, 2.0))

    with pytest.raises(InvalidInput, match="pair_form"):
        pair_form(Bad())


def test_cell_list_cusp_on_a_close_pair_does_not_shrink_the_cutoff():
    """Regression (found by hypothesis): 15 agents on a line, Morse soft = 0 – one close
    pair's u ~ 1/s inflated κ and shrank the cutoff; the error was 3.4·tol."""
    rng = np.random.default_rng(0)
    n, k = 15, 1
    x = rng.uniform(0.0, 1.0, (n, k)) * 5.0
    v = rng.normal(size=(n, k))
    w = rng.dirichlet(np.ones(n))
    eff = [AttractionRepulsion(Morse(1.0, 1.0, 1.5, 0.5, soft=0.0)),
           Alignment(CuckerSmale(1.0, 2.0), on="v")]
    got = _pair_field(eff, x, v, CellList(tol=1e-3), w)
    exact = _pair_field(eff, x, v, Dense(), w)
    assert np.linalg.norm(got - exact) <= 1e-3 * np.linalg.norm(exact)


@given(n=st.integers(200, 1500), k=st.integers(2, 3), spread=st.floats(20.0, 2000.0),
       flat=st.floats(1e-5, 1.0), ring=st.booleans(), seed=st.integers(0, 2**31 - 1),
       la=st.floats(1.0, 5.0), soft=st.sampled_from([0.01, 0.5]),
       tol=st.sampled_from([1e-6, 1e-8]))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_cell_list_cutoff_follows_the_field_of_spread_clouds(n, k, spread, flat, ring, seed, la,
                                                             soft, tol):
    """Spread Gaussian clouds and rings, far larger than the kernel's range: the field's scale
    per unit of carrier is far below the kernel's mean over random pairs (floored at
    ``10⁻⁴‖φ‖∞``), and the pairs the cutoff leaves out are those of largest carrier
    difference; a cutoff from the pair mean alone let the error reach 7.6·tol (3-D Gaussian
    240 × 1600 × 0.02, tol 1e-8) and 2.3·tol (a 2-D ring, 1e-7)."""
    rng = np.random.default_rng(seed)
    if ring:
        th = rng.uniform(0.0, 2 * np.pi, n)
        x = np.zeros((n, k))
        x[:, 0], x[:, 1] = spread * np.cos(th), spread * np.sin(th)
        x += 0.01 * spread * rng.normal(size=(n, k))
    else:
        x = rng.normal(size=(n, k)) * (spread * np.array([0.15, 1.0, flat])[:k])
    x += 470.0
    v = rng.normal(size=(n, k))
    w = rng.dirichlet(np.ones(n)) if seed % 2 else None
    eff = [AttractionRepulsion(Morse(0.53, la, 1.1, 1.48, soft=soft))]
    sc = Scene(eff, normalize="sum", weights=w, pairsum=CellList(tol=tol))
    got = sc.rhs(x, v)[1]
    # the reference sums φᵢⱼ (xⱼ − xᵢ) pair by pair: Dense forms Σ cφ x̃ⱼ − (Σ cφ) x̃ᵢ, whose
    # round-off floor (ε·φ(0)·|x̃| from the self-pairs' soft core) is a relative 1e-6 of a
    # field of 10⁻¹³ (agents 20–700 kernel widths apart)
    c = sc.coefficients(n)
    exact = np.zeros_like(x)
    for i in range(n):
        d = x - x[i]
        exact[i] = (c * eff[0].kernel(np.sqrt(np.sum(d * d, axis=1)))) @ d
    assert np.linalg.norm(got - exact) <= tol * np.linalg.norm(exact) + 1e-300


# ------------------------------------------------------------------ overlap of grid and pairs
@given(nchunks=st.integers(0, 60), nthreads=st.integers(1, 4),
       first=st.one_of(st.none(), st.floats(0.0, 1.0)))
def test_chunk_shares_cover_every_chunk_once_and_give_thread_zero_its_fraction(nchunks,
                                                                               nthreads,
                                                                               first):
    shares = _cells.chunk_shares(nchunks, nthreads, first)
    flat = sorted(c for mine in shares for c in mine)
    assert flat == list(range(nchunks))
    assert len(shares) == max(1, min(nthreads, max(nchunks, 1)))
    if first is None:
        assert all(len(s) - len(shares[-1]) in (0, 1) for s in shares)   # interleaved
    elif len(shares) > 1:
        assert abs(len(shares[0]) - first * nchunks) <= 1.0
    assert shares == _cells.chunk_shares(nchunks, nthreads, first)      # fixed by the counts


def test_overlap_share_balances_the_transforms_against_the_pairs():
    from types import SimpleNamespace

    from kinred.pairsum.nufft import overlap_share

    sp = SimpleNamespace(near_seconds=0.105, grid_seconds=0.062)
    # G + x·P = (1 − x)·P on two threads: x = (P − G)/(2P)
    assert overlap_share(sp, 2, 1) == pytest.approx((0.105 - 0.062) / 0.21)
    assert overlap_share(sp, 4, 1) == 0.0                    # 3·G > P: the pairs go elsewhere
    assert overlap_share(SimpleNamespace(near_seconds=1.0, grid_seconds=0.0), 2, 1) == 0.5
    assert overlap_share(sp, 1, 1) is None and overlap_share(sp, 2, 2) is None


def test_nufft_with_overlap_equals_the_sequential_sums_and_repeats_bitwise(monkeypatch):
    """The transforms overlap the other thread's near pairs (finufft on one thread below 10⁵
    points): the same sums as one after the other, to round-off, and the same bits on every
    call (the chunks' shares are fixed by the counts)."""
    from kinred._parallel import num_threads
    from kinred.pairsum import nufft

    rng = np.random.default_rng(5)
    th = rng.uniform(0, 2 * np.pi, 4000)
    x = np.c_[5 * np.cos(th), 5 * np.sin(th)] + 0.1 * rng.normal(size=(4000, 2)) + 50.0
    v = rng.normal(size=(4000, 2))
    eff = [AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=0.1))]
    with num_threads(2):
        sc = Scene(eff, pairsum=NUFFT(tol=1e-6, near_field=True))
        got = sc.rhs(x, v)[1]
        g = next(iter(sc._plans.values())).groups[0]
        share = nufft.overlap_share(g.split, 2, g.fast.nthreads)
        assert share is not None and 0.0 <= share <= 0.5
        assert np.array_equal(sc.rhs(x, v)[1], got)
        monkeypatch.setattr(nufft, "overlap_share", lambda *a: None)
        seq = sc.rhs(x, v)[1]
    assert np.abs(got - seq).max() <= 1e-13 * np.abs(seq).max()
    exact = Scene(eff).rhs(x, v)[1]
    assert np.linalg.norm(got - exact) <= 1e-6 * np.linalg.norm(exact)
