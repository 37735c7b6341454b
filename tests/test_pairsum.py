"""Pair-sum backends: the protocol (a toy backend plugged in from outside the package), the
plans a scene keeps, the aliases of ``Scene(pairsum=...)``, the kernel hook for compiled
forms, and what a scene's pairwise effects call for (``Scene.pair_terms``)."""

import numpy as np
import pytest

from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale, Drift,
                             Morse, PairwiseEffect, Quadratic, Scene, SelfPropulsion)
from kinred._parallel import num_threads
from kinred.errors import InvalidInput
from kinred.integrate import SaveAt, simulate
from kinred.kinetic._solution import weighted_scene
from kinred.pairsum import Dense, Numpy, PairSum, PairTerms, _kernels, as_pairsum, dense


class BruteForce:
    """A toy exact backend written only against the public protocol: ``scene.pair_terms``
    and ``scene.coefficients(n)``, N × N × d differences; counts its calls."""

    def __init__(self):
        self.plans = 0
        self.evaluations = 0
        self.rngs = []

    def plan(self, scene, n, dim):
        self.plans += 1
        return {"terms": scene.pair_terms, "c": scene.coefficients(n), "shape": (n, dim)}

    def evaluate(self, plan, x, v, rng=None):
        self.evaluations += 1
        self.rngs.append(rng)
        assert x.shape == plan["shape"]
        state = {"x": x, "v": v}
        c = plan["c"]
        out = {}
        for t in plan["terms"].terms:
            s = state[t.source]
            z = state[t.carrier]
            phi = t.kernel(np.sqrt(((s[:, None, :] - s[None, :, :]) ** 2).sum(-1)))
            contrib = np.einsum("ij,j,ijl->il", phi, c, z[None, :, :] - z[:, None, :])
            out[t.target] = out[t.target] + contrib if t.target in out else contrib
        return out


def _data(n, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (n, d)), rng.uniform(-1, 1, (n, d))


EFFECTS = [Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.2)),
           Alignment(CuckerSmale(0.5, 1.5), on="v"), SelfPropulsion(1.0, 0.5)]


@pytest.mark.parametrize("method, stages", [("euler", 1), ("rk4", 4)])
def test_a_backend_from_outside_runs_simulate_and_equals_dense(method, stages):
    x0, v0 = _data(40, 6)
    w = np.random.default_rng(1).dirichlet(np.ones(40))
    toy = BruteForce()
    assert isinstance(toy, PairSum)
    kw = dict(save=SaveAt(every=10, states=True), method=method)
    a = simulate(Scene(EFFECTS, "sum", weights=w, pairsum=toy), x0, v0, (0, 0.6), 0.02, **kw)
    b = simulate(Scene(EFFECTS, "sum", weights=w), x0, v0, (0, 0.6), 0.02, **kw)
    assert toy.plans == 1                                  # one plan per shape, kept
    assert toy.evaluations == 30 * stages                  # one evaluation per right-hand side
    assert toy.rngs == [None] * toy.evaluations
    for got, ref in ((a.x, b.x), (a.v, b.v)):
        assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))
    assert not np.array_equal(a.v[-1], a.v[0])             # it moved


def test_a_backend_from_outside_is_kept_by_projection_and_weighting():
    toy = BruteForce()
    sc = Scene(EFFECTS, "mean", pairsum=toy)
    Q, _ = np.linalg.qr(np.random.default_rng(2).normal(size=(5, 5)))
    ps = sc.project(Q[:3])
    assert ps.pairsum is toy and weighted_scene(sc, np.full(7, 1 / 7)).pairsum is toy
    x, v = _data(7, 5, seed=3)
    dv = ps.rhs(x @ Q[:3].T, v @ Q[:3].T)[1]
    ref = Scene(EFFECTS, "mean").project(Q[:3]).rhs(x @ Q[:3].T, v @ Q[:3].T)[1]
    assert toy.evaluations == 1
    assert np.max(np.abs(dv - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_rhs_hands_its_rng_to_the_backend():
    toy = BruteForce()
    x, v = _data(5, 2)
    g = np.random.default_rng(0)
    Scene([Alignment()], pairsum=toy).rhs(x, v, rng=g)
    assert toy.rngs == [g]
    with pytest.raises(InvalidInput, match="rng must be a numpy.random.Generator"):
        Scene([Alignment()], pairsum=toy).rhs(x, v, rng=5)


def test_a_scene_without_pair_terms_never_calls_the_backend():
    toy = BruteForce()
    x, v = _data(30, 4)
    sc = Scene([SelfPropulsion(1.0, 0.5), Drift(np.ones(4))], pairsum=toy)
    assert not sc.pair_terms
    dv = sc.rhs(x, v)[1]
    assert toy.plans == 0 and toy.evaluations == 0
    assert np.array_equal(dv, SelfPropulsion(1.0, 0.5).drift(x, v, 0.0) + 1.0)


class SpyDense(Dense):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.shapes = []

    def plan(self, scene, n, dim):
        self.shapes.append((n, dim))
        return super().plan(scene, n, dim)


def test_plans_are_built_once_per_shape_and_thread_count(monkeypatch):
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)   # two threads even at this size
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    spy = SpyDense()
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum", pairsum=spy)
    x, v = _data(50, 4)
    with num_threads(1):
        simulate(sc, x, v, (0, 0.4), 0.02)                 # 20 right-hand sides
        one = sc.rhs(x, v)[1]
        assert spy.shapes == [(50, 4)]
        sc.rhs(x[:20], v[:20])
        sc.rhs(x, v)
        assert spy.shapes == [(50, 4), (20, 4)]
    with num_threads(2):
        two = sc.rhs(x, v)[1]
        assert spy.shapes == [(50, 4), (20, 4), (50, 4)]  # other strips: a new plan
    # the plan's per-term arrays are reused: the same numbers as a fresh scene
    with num_threads(1):
        assert np.array_equal(one, Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum").rhs(x, v)[1])
    assert np.max(np.abs(one - two)) <= 1e-12 * np.max(np.abs(one))
    for n in range(2, 12):                                  # few plans are kept
        sc.rhs(x[:n], v[:n])
    assert len(sc._plans) <= 4


def test_aliases_and_backend_options():
    assert repr(Scene([Alignment()]).pairsum) == "Dense()"
    for name in ("fast", "dense"):
        assert isinstance(Scene([Alignment()], pairsum=name).pairsum, Dense)
        assert isinstance(Scene([Alignment()], engine=name).pairsum, Dense)
    assert isinstance(Scene([Alignment()], pairsum="numpy").pairsum, Numpy)
    assert isinstance(Scene([Alignment()], engine="numpy", precision="double").pairsum, Numpy)
    sc = Scene([Alignment()], engine="fast", block=7, precision="mixed")
    assert (sc.pairsum.block, sc.pairsum.precision, sc.precision) == (7, "mixed", "mixed")
    assert "pairsum=Dense(block=7, precision='mixed')" in repr(sc)
    assert Scene([Alignment()], pairsum=Numpy()).precision == "double"
    assert Scene([Alignment()], pairsum=BruteForce()).precision == "double"
    assert as_pairsum(Dense(compiled=False)).compiled is False


@pytest.mark.parametrize("kw, match", [
    ({"pairsum": "gpu"}, "pairsum must be a PairSum backend or one of"),
    ({"engine": "gpu"}, "engine must be one of"),
    ({"pairsum": object()}, "pairsum must be a PairSum backend .an object with plan"),
    ({"pairsum": "numpy", "engine": "numpy"}, "not both"),
    ({"pairsum": "numpy", "block": 3}, "block= and precision= configure"),
    ({"engine": "numpy", "precision": "mixed"}, "block= and precision= configure"),
    ({"pairsum": Dense(), "precision": "double"}, "set them on the backend itself"),
    ({"block": 0}, "block"),
    ({"precision": "half"}, "precision"),
])
def test_bad_backend_arguments_are_refused(kw, match):
    with pytest.raises(InvalidInput, match=match):
        Scene([Alignment()], **kw)


def test_dense_validates_its_options_and_plan_arguments():
    with pytest.raises(InvalidInput, match="compiled must be True or False"):
        Dense(compiled="yes")
    with pytest.raises(InvalidInput, match="scene must be a kinred.dynamics.Scene"):
        Dense().plan(object(), 3, 2)
    sc = Scene([Alignment()])
    with pytest.raises(InvalidInput, match="n must be"):
        Numpy().plan(sc, 0, 2)
    plan = Dense().plan(sc, 4, 2)
    x, v = _data(5, 2)
    with pytest.raises(InvalidInput, match="DensePlan for states of shape"):
        Dense().evaluate(plan, x, v)
    with pytest.raises(InvalidInput, match="NumpyPlan"):
        Numpy().evaluate(plan, x[:4], v[:4])


class HookedPower:
    """A kernel outside the package that declares the compiled form of G (1 + s²)^(−β)."""

    def __init__(self, G, beta):
        self.G, self.beta = G, beta

    def __call__(self, s):
        return self.G * np.exp(-self.beta * np.log1p(np.asarray(s) ** 2))

    def compiled_form(self):
        return ("cs_pow", self.G, self.beta)


class PrivateOnly(HookedPower):
    """Only a private ``_compiled`` attribute: not a compiled form (never probed)."""

    compiled_form = None
    _compiled = (_kernels.KIND_CS_POW, 0.8, 1.62)


@pytest.mark.parametrize("d", [2, 9])
def test_kernel_hook_runs_custom_kernels_in_the_compiled_worker(d, monkeypatch):
    calls = []
    orig = _kernels.pair_strips
    monkeypatch.setattr(_kernels, "pair_strips", lambda *a: calls.append(1) or orig(*a))
    x, v = _data(90, d, seed=d)
    got = Scene([PairwiseEffect(HookedPower(0.8, 1.62))], "sum").rhs(x, v)[1]
    assert calls
    # the same compiled form as CuckerSmale(0.8, 1.62): the same operations, bit for bit
    assert np.array_equal(got, Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum").rhs(x, v)[1])
    calls.clear()
    sc = Scene([PairwiseEffect(PrivateOnly(0.8, 1.62))], "sum")
    loop = sc.rhs(x, v)[1]
    assert not calls                                       # Python strip loop
    ref = Scene([PairwiseEffect(PrivateOnly(0.8, 1.62))], "sum", pairsum="numpy").rhs(x, v)[1]
    assert np.max(np.abs(loop - ref)) <= 1e-12 * np.max(np.abs(ref))


@pytest.mark.parametrize("form", [("nufft", 1.0, 2.0), ("cs_halfint", 1.0, 1.5),
                                  ("cs_halfint", 1.0, -2.0), ("cs_pow", np.nan, 1.0),
                                  ("cs_pow", "G", 1.0), "cs_pow", ("cs_pow", 1.0)])
def test_invalid_compiled_forms_are_refused_when_the_scene_is_built(form):
    class Bad(HookedPower):
        def compiled_form(self):
            return form

    match = r"compiled_form\(\) returned .*kind in \('cs_halfint', 'cs_pow'\)"
    with pytest.raises(InvalidInput, match=match):
        Scene([PairwiseEffect(Bad(1.0, 1.0))])


def test_a_compiled_form_attribute_that_is_not_a_method_is_refused():
    class Attr(HookedPower):
        compiled_form = ("cs_pow", 1.0, 1.0)

    with pytest.raises(InvalidInput, match="compiled_form must be a method"):
        Scene([PairwiseEffect(Attr(1.0, 1.0))])


def test_pair_terms_list_only_what_the_effects_call_for():
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62), on="v"), SelfPropulsion(),
                AttractionRepulsion(Morse(soft=0.1)), Alignment(CuckerSmale(1.0, 0.5))])
    pt = sc.pair_terms
    assert isinstance(pt, PairTerms)
    assert pt.sources == ("x", "v") and pt.carriers == ("v", "x")
    assert pt.accumulators == (("v", "v"), ("v", "x"))
    assert [t.source for t in pt.of_source("x")] == ["x", "x"]
    assert [t.compiled is not None for t in pt.terms] == [True, False, True]
    assert [t.effect for t in pt.terms] == [sc.effects[0], sc.effects[2], sc.effects[3]]
    first = Scene([Aggregation(Quadratic(1.5))]).pair_terms
    assert (first.sources, first.carriers, first.accumulators) == (("x",), ("x",), (("x", "x"),))
    # the coefficient vector: w (mean) or N w (sum)
    w = np.array([0.5, 0.25, 0.25])
    assert np.array_equal(Scene([Alignment()], "sum", weights=w).coefficients(3), 3 * w)
    assert np.array_equal(Scene([Alignment()], "mean").coefficients(4), np.full(4, 0.25))
    # a source no effect needs is never computed
    _kernels.COUNTERS.clear()
    x, v = _data(100, 3)
    Scene([Alignment(on="v")], block=25, pairsum=None).rhs(x, v)
    assert _kernels.COUNTERS["v"] == 4 and _kernels.COUNTERS["x"] == 0


@pytest.mark.parametrize("n, dim, groups", [(200, 2, 1), (300, 2, 1), (1000, 2, 2), (100, 200, 1),
                                             (400, 200, 2), (300, 25, 1), (700, 25, 2)])
def test_small_right_hand_sides_run_in_one_thread(n, dim, groups, monkeypatch):
    """Below PARALLEL_MIN_SECONDS of one-thread work (by the cost model's dense_seconds) a
    right-hand side runs in one thread: the hand-off to a second one costs about 0.2 ms. The
    sums are those of two threads to the round-off of their order."""
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum")
    terms = sc.pair_terms
    assert (dense.one_thread_seconds(n, dim, terms) >= dense.PARALLEL_MIN_SECONDS) == (groups == 2)
    x, v = _data(n, dim)
    with num_threads(2):
        plan = Dense().plan(sc, n, dim)
        assert dense.engine_threads(n, dim, terms, compiled=True) == groups
        assert len(plan.groups) == dense.engine_threads(n, dim, terms, plan.worker is not None)
        auto = sc.rhs(x, v)[1]
        monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)
        monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
        assert len(Dense().plan(sc, n, dim).groups) == 2
        two = Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum").rhs(x, v)[1]
    with num_threads(1):
        assert len(Dense().plan(sc, n, dim).groups) == 1
    assert np.max(np.abs(auto - two)) <= 1e-12 * np.max(np.abs(two))


@pytest.mark.parametrize("n, groups", [(300, 1), (600, 1), (1500, 2)])
def test_the_python_strip_loop_shares_from_more_work(n, groups, monkeypatch):
    """Morse (no compiled form) runs in the Python strip loop, whose calls hand the GIL back:
    two threads only from PARALLEL_MIN_SECONDS_LOOP of one-thread work (the compiled worker
    shares from PARALLEL_MIN_SECONDS, a tenth of it); Auto prices it with those threads."""
    sc = Scene([AttractionRepulsion(Morse(soft=0.1))], "sum")
    terms = sc.pair_terms
    secs = dense.one_thread_seconds(n, 2, terms)
    assert secs >= dense.PARALLEL_MIN_SECONDS                 # the compiled rule would share
    assert (secs >= dense.PARALLEL_MIN_SECONDS_LOOP) == (groups == 2)
    x, v = _data(n, 2)
    with num_threads(2):
        assert len(Dense().plan(sc, n, 2).groups) == groups
        assert dense.engine_threads(n, 2, terms, compiled=False) == groups
        auto = Scene([AttractionRepulsion(Morse(soft=0.1))], "sum", pairsum="auto")
        auto.rhs(x, v)
        plan = next(iter(auto._plans.values()))
        assert plan.estimates["dense"] == pytest.approx(secs / groups)
        monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
        assert len(Dense().plan(sc, n, 2).groups) == 2
