"""The compiled strip worker (one GIL-free call per engine thread and step) and its
vectorized power kernels, against long-double references and the Python strip loop."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinred.dynamics import Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene
from kinred import _parallel
from kinred._parallel import num_threads
from kinred.pairsum import Dense, Numpy, _kernels, dense


def _pair_sums(scene, x, v, pairsum):
    """``{target: contribution}`` of ``scene``'s pair terms by the backend ``pairsum``."""
    return pairsum.evaluate(pairsum.plan(scene, *x.shape), x, v, None)


def test_compiled_worker_links_whenever_numpy_ships_openblas():
    # numpy's Linux wheels bundle OpenBLAS with cblas_dgemm/cblas_sgemm: then the worker must
    # link (with another BLAS the engine uses the Python strip loop, tested below)
    for kind, dt in (("d", np.float64), ("s", np.float32)):
        found = _parallel.cblas_gemm_symbol(kind) is not None
        assert _kernels.HAVE_COMPILED_FOR[np.dtype(dt)] == found
    assert _parallel.cblas_gemm_symbol("d") is not None     # the case on the project's CI


def _ref_pow(q, G, beta):
    """``G (1 + q)^(−β)`` in 80-bit long double (x86) or float64 elsewhere."""
    ql = np.asarray(q, dtype=np.longdouble)
    return (G * np.exp(-np.longdouble(beta) * np.log1p(ql))).astype(float)


def _qgrid():
    rng = np.random.default_rng(0)
    return np.concatenate([[0.0, 5e-324, 1e-300, 1e-17, 1.0, 3.0, 2.0 ** 52, 1e308],
                           rng.uniform(0, 5, 400), 10.0 ** rng.uniform(-20, 300, 600)])


@pytest.mark.parametrize("beta", [0.05, 0.3, 1.62, 1.7, 3.3, 9.9])
def test_pow_row64_matches_long_double(beta):
    q = _qgrid()
    got = _kernels.cs_pow(q.copy()[None, :], 0.8, beta, np.empty((3, q.size)))[0]
    ref = _ref_pow(q, 0.8, beta)
    y = beta * np.log2(1.0 + q)
    norm = ref > 1e-290
    rel = np.abs(got[norm] - ref[norm]) / ref[norm]
    # the error of the numpy chain G·exp(−β·log1p(q)): ≈ u·(1 + |y|)
    assert np.max(rel / (1.0 + y[norm])) < 2e-15
    assert np.all(np.abs(got[~norm]) <= 1e-290)           # underflow to (almost) 0
    assert got[0] == 0.8                                     # q = 0 gives G exactly


def test_pow_rows_special_values():
    scr = np.empty((3, 8))
    for dt in (np.float64, np.float32):
        q = np.array([[np.inf, np.nan, 0.0, 1.0]], dtype=dt)
        got = _kernels.cs_pow(q, dt(2.0), dt(1.62), scr)[0]
        assert got[0] == 0.0 and np.isnan(got[1]) and got[2] == 2.0
        assert got[3] == pytest.approx(2.0 * 2.0 ** -1.62, rel=1e-6 if dt == np.float32 else 1e-15)


@pytest.mark.parametrize("beta", [0.05, 1.62, 9.9])
def test_pow_row32_matches_float64_within_float32_rounding(beta):
    q = np.concatenate([np.random.default_rng(1).uniform(0, 5, 500),
                        10.0 ** np.random.default_rng(2).uniform(-20, 37, 500)]).astype(np.float32)
    got = _kernels.cs_pow(q.copy()[None, :], np.float32(0.8), np.float32(beta),
                          np.empty((3, q.size)))[0]
    ref = _ref_pow(q.astype(float), 0.8, float(np.float32(beta)))
    y = beta * np.log2(1.0 + q.astype(float))
    ok = ref > 1e-36
    rel = np.abs(got[ok] - ref[ok]) / ref[ok]
    assert np.max(rel / (1.0 + y[ok])) < 1e-6
    assert np.max(rel[q[ok] <= 5]) < 4e-7 * (1.0 + 2.0 * beta)   # q <= 5: as numpy float32


@settings(max_examples=60, deadline=None)
@given(q=st.lists(st.floats(0.0, 1e30, allow_nan=False), min_size=1, max_size=40),
       beta=st.floats(0.01, 10.0), G=st.floats(0.01, 100.0))
def test_pow_row64_property(q, beta, G):
    q = np.array(q)
    got = _kernels.cs_pow(q.copy()[None, :], G, beta, np.empty((3, q.size)))[0]
    ref = _ref_pow(q, G, beta)
    y = beta * np.log2(1.0 + q)
    norm = ref > 1e-290
    assert np.all(np.abs(got[norm] - ref[norm]) <= 2e-15 * (1.0 + y[norm]) * ref[norm])


def _scenes():
    """Scenes covering the worker's branches: small and Gram dimensions, general and
    half-integer β, weights, two kernels on one source, two sources."""
    yield "halfint", [Alignment(CuckerSmale(0.8, 1.5))], {}
    yield "general", [Alignment(CuckerSmale(0.8, 1.62))], {}
    yield "weights", [Alignment(CuckerSmale(1.1, 0.37))], {"weights": True}
    yield "two-on-x", [Alignment(CuckerSmale(0.8, 1.62)), Alignment(CuckerSmale(0.3, 2.5))], {}
    yield "x-and-v", [Alignment(CuckerSmale(0.8, 1.62)),
                      Alignment(CuckerSmale(0.5, 0.75), on="v")], {}


@pytest.mark.parametrize("precision", ["double", "mixed"])
@pytest.mark.parametrize("dim", [1, 3, 4, 10, 60])
@pytest.mark.parametrize("case", list(_scenes()), ids=[c[0] for c in _scenes()])
def test_compiled_worker_equals_python_strip_loop(case, dim, precision, monkeypatch):
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)   # two threads even at this size
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    name, effects, opts = case
    n = 150
    rng = np.random.default_rng(dim)
    x = rng.uniform(0, 1, (n, dim))
    v = rng.uniform(-1, 1, (n, dim))
    x[7] = x[3]                                   # coincident agents
    w = rng.dirichlet(np.ones(n)) if opts.get("weights") else None
    sc = Scene(effects, normalize="sum", weights=w, precision=precision, block=32)
    ref = _pair_sums(sc, x, v, Numpy())
    for threads in (1, 2):
        with num_threads(threads):
            got = _pair_sums(sc, x, v, Dense(block=32, precision=precision))
            loop = _pair_sums(sc, x, v, Dense(block=32, precision=precision, compiled=False))
        for key in ref:
            scale = np.max(np.abs(ref[key]))
            tol = 1e-13 if precision == "double" else 2e-5
            assert np.max(np.abs(got[key] - ref[key])) <= tol * scale
            # the same operations in the same order; only the kernel of general β differs
            # (vectorized pow vs numpy's exp/log chain): rounding-level differences
            assert np.max(np.abs(got[key] - loop[key])) <= (1e-14 if precision == "double"
                                                             else 1e-6) * scale


def test_compiled_worker_is_bitwise_the_python_loop_for_half_integer_beta():
    rng = np.random.default_rng(5)
    x, v = rng.uniform(0, 1, (300, 12)), rng.uniform(-1, 1, (300, 12))
    effects = [Alignment(CuckerSmale(0.8, 1.5))]
    a = Scene(effects, normalize="sum", pairsum=Dense()).rhs(x, v)[1]
    b = Scene(effects, normalize="sum", pairsum=Dense(compiled=False)).rhs(x, v)[1]
    assert np.array_equal(a, b)


def test_kernels_without_compiled_form_use_the_python_loop(monkeypatch):
    calls = []
    orig = _kernels.pair_strips
    monkeypatch.setattr(_kernels, "pair_strips", lambda *a: calls.append(1) or orig(*a))
    rng = np.random.default_rng(6)
    x, v = rng.uniform(0, 1, (80, 5)), rng.uniform(-1, 1, (80, 5))
    Scene([Alignment(CuckerSmale(0.8, 1.62))]).rhs(x, v)
    assert calls, "Cucker–Smale should run in the compiled worker"
    calls.clear()
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.1))])
    got = sc.rhs(x, v)[1]
    assert not calls                        # Morse has no compiled form: Python strip loop
    ref = _pair_sums(sc, x, v, Numpy())["v"]
    assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_blas_stays_single_threaded_inside_the_parallel_region(monkeypatch):
    # numpy's OpenBLAS applies openblas_set_num_threads_local process-wide: a worker that
    # restored the count on its way out used to switch the other worker's BLAS calls back to
    # multithreading mid-step. Now the caller owns the setting for the whole region.
    get = _parallel._BLAS_GET
    assert get is not None
    seen = []
    orig = _kernels.pair_strips

    def spy(*args):
        seen.append(get())
        out = orig(*args)
        seen.append(get())
        return out

    monkeypatch.setattr(_kernels, "pair_strips", spy)
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)   # two threads even at this size
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    before = get()
    rng = np.random.default_rng(8)
    x, v = rng.uniform(0, 1, (400, 30)), rng.uniform(-1, 1, (400, 30))
    with num_threads(2):
        for _ in range(5):
            Scene([Alignment(CuckerSmale(0.8, 1.62))]).rhs(x, v)
    assert len(seen) == 20 and set(seen) == {1}
    assert get() == before


def test_two_thread_steps_are_bitwise_reproducible():
    # in a fresh process (the race showed in the first calls): 25 right-hand sides, both
    # engine paths, must agree bit for bit
    code = textwrap.dedent("""
        import numpy as np
        from kinred.dynamics import Alignment, CuckerSmale, Scene, set_num_threads
        from kinred.pairsum import Dense
        set_num_threads(2)
        rng = np.random.default_rng(0)
        x, v = rng.uniform(0, 1, (1000, 200)), rng.uniform(-1, 1, (1000, 200))
        for compiled in (True, False):
            sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], normalize="sum",
                       pairsum=Dense(compiled=compiled))
            outs = [sc.rhs(x, v)[1].copy() for _ in range(25)]
            assert all(np.array_equal(o, outs[0]) for o in outs), compiled
        print("ok")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr[-2000:]
