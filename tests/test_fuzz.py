"""Never an unnamed exception (issue 14): generated bad input at the public entry points.

Property: every call either works or raises a :class:`kinred.errors.KinredError` on one line;
an :class:`~kinred.errors.InvalidInput` or :class:`~kinred.errors.TooLarge` names the
argument that was replaced. Numerical outcomes (``SimulationDiverged``, ``NotConverged``)
may name other things. Each defect the fuzzing found is an ``@example`` (fails before its
fix). The memory limit is lowered to 64 MiB for these tests, so that a huge size is refused
at once instead of allocated. Files and the CLI: ``test_fuzz_files.py``; the memory
preflight: ``test_fuzz_alloc.py``.
"""

import os
import re
import warnings
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from kinred import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale, Drift, Field,
                    Morse, Noise, Quadratic, Scene, SelfPropulsion, TensorProduct, Uniform,
                    budget, jl_matrix, simulate, w1)
from kinred.ensemble import run_ensemble
from kinred.errors import InvalidInput, KinredError, TooLarge
from kinred.integrate import SaveAt
from kinred.kinetic import solve
from kinred.measures import Atomic
from kinred.quantize import quantize
from kinred.recovery import basis_pursuit

#: Deterministic (derandomized, no example database): the same examples on every run.
FUZZ = dict(deadline=None, derandomize=True, database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                   HealthCheck.filter_too_much])

_rng = np.random.default_rng(0)
X, V = _rng.uniform(0, 1, (6, 2)), _rng.uniform(-1, 1, (6, 2))
S = np.linspace(0.0, 3.0, 7)
A = _rng.standard_normal((4, 8))
Y = A @ np.eye(8)[:, :2]
MU = TensorProduct([Uniform(0, 1), Uniform(0, 0.5), Uniform(0, 0.1)])
MU4 = TensorProduct([Uniform(0, 1), Uniform(0, 0.5), Uniform(-1, 1), Uniform(-0.5, 0.5)])


@contextmanager
def small_limit(limit="64M"):
    """``KINRED_MAX_BYTES`` lowered for the block (restored after)."""
    old = os.environ.get("KINRED_MAX_BYTES")
    os.environ["KINRED_MAX_BYTES"] = limit
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("KINRED_MAX_BYTES")
        else:
            os.environ["KINRED_MAX_BYTES"] = old


def names(msg: str, name: str) -> bool:
    """``name`` appears in ``msg`` as a word (``x0`` in ``x0[1]``, not ``a`` in ``max``)."""
    return re.search(rf"(?<![A-Za-z0-9_]){re.escape(name)}(?![A-Za-z0-9_])", msg) is not None


def check_error(exc: BaseException, name: str) -> None:
    """The property: a KinredError on one line, naming ``name`` when it is about input."""
    assert isinstance(exc, KinredError), f"{type(exc).__name__} escaped: {exc}"
    msg = str(exc)
    assert "\n" not in msg and "\r" not in msg, f"message on several lines: {msg!r}"
    if isinstance(exc, (InvalidInput, TooLarge)):
        assert names(msg, name), f"message does not name {name!r}: {msg}"


def call_ok(fn, kwargs, name):
    with small_limit(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fn(**kwargs)
        except Exception as exc:  # noqa: BLE001 - the property is about every exception
            check_error(exc, name)


# ------------------------------------------------------------------------------------------
# the entry points: a call and valid keyword arguments; each argument is replaced in turn
# ------------------------------------------------------------------------------------------
def _scene():
    return Scene([Alignment(CuckerSmale())])


def _member(params, seed):
    return {"value": float(params["i"]), "draw": np.random.default_rng(seed).normal(size=3)}


def _field(t, x, v):
    return -x


def _noop(*args, **kwargs):
    return None


def _rhs(make):
    def rhs(**kw):
        sc = Scene([make(**kw)])
        return sc.rhs(X, V if sc.order == 2 else None)
    return rhs


ENTRIES = {
    "simulate": (simulate, lambda: dict(
        scene=_scene(), x0=X, v0=V, t_span=(0.0, 0.1), dt=0.05, method="euler", save=None,
        seed=1, rtol=1e-3, atol=1e-6, max_steps=200, observers=None)),
    "SaveAt": (lambda **kw: simulate(_scene(), X, V, (0.0, 0.1), 0.05, save=SaveAt(**kw)),
               lambda: dict(every=None, t=None, observables=None, states=False)),
    "Scene": (lambda **kw: Scene(**kw).rhs(X, V), lambda: dict(
        effects=[Alignment(CuckerSmale())], normalize="mean", weights=None, pairsum=None,
        block=None, precision=None)),
    "CuckerSmale": (lambda **kw: CuckerSmale(**kw)(S), lambda: dict(G=1.0, beta=1.5)),
    "Morse": (lambda **kw: Morse(**kw)(S), lambda: dict(Ca=1.0, la=2.0, Cr=1.5, lr=0.5,
                                                       soft=0.1)),
    "Quadratic": (lambda **kw: Quadratic(**kw)(S), lambda: dict(c=1.0)),
    "Alignment": (_rhs(Alignment), lambda: dict(kernel=CuckerSmale(), on="x")),
    "AttractionRepulsion": (_rhs(AttractionRepulsion), lambda: dict(potential=Morse(soft=0.1))),
    "Aggregation": (lambda **kw: Scene([Aggregation(**kw)]).rhs(X),
                    lambda: dict(potential=Quadratic())),
    "SelfPropulsion": (_rhs(SelfPropulsion), lambda: dict(a=1.0, b=0.5)),
    "Noise": (lambda **kw: simulate(Scene([Alignment(), Noise(**kw)]), X, V, (0.0, 0.1), 0.05,
                                    method="euler_maruyama", seed=0),
              lambda: dict(sigma=0.1, target=None, matrix=None)),
    "Drift": (_rhs(Drift), lambda: dict(c=np.ones(2), target=None)),
    "Field": (_rhs(Field), lambda: dict(fn=_field, target=None, translation_invariant=False)),
    "quantize": (lambda **kw: quantize(**kw).error, lambda: dict(
        mu=MU, eps=0.1, rule="midpoint", node_limit=100, max_bytes=None)),
    "quantize(atoms)": (lambda **kw: quantize(**kw).materialize(), lambda: dict(
        mu=MU, atoms=10, rule="paper", node_limit=100, max_bytes=None)),
    "budget": (budget, lambda: dict(widths=[1.0, 0.5], eps=0.1, rule="midpoint", node_limit=100)),
    "budget(atoms)": (budget, lambda: dict(widths=[1.0, 0.5, 0.0], atoms=10)),
    "w1": (lambda **kw: w1(**kw).value, lambda: dict(
        mu=X, nu=V, method="auto", a=None, b=None, metric="euclidean", seed=0)),
    "jl_matrix": (jl_matrix, lambda: dict(k=2, d=5, kind="gaussian", seed=0)),
    "basis_pursuit": (basis_pursuit, lambda: dict(
        A=A, Y=Y, eta=0.0, nonneg=False, tol=1e-6, max_iter=50, polish=True, relax=1.6,
        check_every=10, cert_tol=1e-9, mu0=None, adaptive=False)),
    "run_ensemble": (run_ensemble, lambda: dict(
        fn=_member, members=[{"i": 0}, {"i": 1}], master_seed=0, executor="serial",
        workers=None, resume=False, config=None, progress=False)),
    "solve": (solve, lambda: dict(
        scene=_scene(), mu0=MU4, atoms=8, t_span=(0.0, 0.1), dt=0.05, method="euler",
        save_every=None, rule="midpoint", max_atoms=100, seed=0)),
    "Uniform": (lambda **kw: quantize(Uniform(**kw), atoms=3).error, lambda: dict(a=0.0, b=1.0)),
    "Atomic": (lambda **kw: quantize(Atomic(**kw), eps=0.5).n_atoms,
               lambda: dict(points=X, weights=None)),
}
CASES = [(entry, arg) for entry, (_, kw) in ENTRIES.items() for arg in kw()]


def test_the_entry_points_work_with_their_valid_arguments():
    for entry, (fn, kw) in ENTRIES.items():
        with small_limit():
            fn(**kw())


_scalars = st.one_of(
    st.none(), st.booleans(), st.text(max_size=4), st.binary(max_size=4),
    st.complex_numbers(), st.floats(), st.integers(-2**80, 2**80),
    st.sampled_from([10**400, -10**400, 2**63, 1e308, -1e308, 5e-324, 1e-320, 0, -1, 0.0,
                     -0.0, float("nan"), float("inf"), -float("inf"), np.float32(np.inf),
                     np.int64(-3), np.complex128(1j), np.bool_(True), "x", "mean", ""]),
)
_arrays = hnp.arrays(
    dtype=st.sampled_from([np.float64, np.int64, np.complex128, np.bool_, np.float32,
                           np.dtype("U2")]),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4))
BAD = st.one_of(
    _scalars, _arrays,
    st.lists(_scalars, max_size=3), st.lists(st.lists(st.floats(), max_size=3), max_size=3),
    st.dictionaries(st.text(max_size=3), _scalars, max_size=2),
    st.tuples(st.floats(), st.floats()),
    st.sampled_from([object(), slice(1), {1, 2}, {"a": 1}, [[]], [{}], (1.0,), _noop,
                     np.zeros((6, 2)), np.full((6, 2), np.nan), np.ones((3, 2)) * 1e308,
                     np.ones((2, 2), dtype=object), ((0, 1), (2, 3))]),
)


@settings(max_examples=3000, **FUZZ)
@given(case=st.sampled_from(CASES), bad=BAD)
# regressions: each failed before its fix (the exception that escaped, or the name missing)
@example(case=("CuckerSmale", "beta"), bad=1e308)            # OverflowError in int(2·beta)
@example(case=("CuckerSmale", "G"), bad=10**400)             # OverflowError in float()
@example(case=("simulate", "dt"), bad=1e-320)                # OverflowError: (t1-t0)/dt = inf
@example(case=("simulate", "dt"), bad=1e-9)                  # 1e8 save points: MemoryError
@example(case=("simulate", "t_span"), bad=(-1e308, 1e308))   # a span of infinite length
@example(case=("simulate", "x0"), bad=None)                  # named 'x', not 'x0'
@example(case=("simulate", "x0"), bad=np.zeros((3, 2)))      # named 'v0' only
@example(case=("simulate", "method"), bad=np.zeros(2))       # ValueError in `not in`
@example(case=("simulate", "observers"), bad={"a": 1})       # TypeError at the first step
@example(case=("simulate", "seed"), bad=np.zeros((3, 2)))    # message on several lines
@example(case=("SaveAt", "states"), bad=np.zeros(3))         # ValueError (truth of array)
@example(case=("Scene", "normalize"), bad=np.array([]))      # ValueError in `not in`
@example(case=("AttractionRepulsion", "potential"), bad=1.0)  # named 'kernel'
@example(case=("Aggregation", "potential"), bad="x")         # named 'kernel'
@example(case=("Field", "translation_invariant"), bad=np.zeros(2))  # ValueError
@example(case=("Noise", "target"), bad=np.zeros(2))          # ValueError in `not in`
@example(case=("quantize", "eps"), bad=10**400)              # OverflowError
@example(case=("budget", "widths"), bad=[10**400])           # OverflowError in asarray
@example(case=("w1", "mu"), bad=[[10**400]])                 # OverflowError in asarray
@example(case=("jl_matrix", "k"), bad=2**63)                 # ValueError from numpy
@example(case=("jl_matrix", "d"), bad=10**9)                 # MemoryError (8 GB matrix)
@example(case=("basis_pursuit", "A"), bad=[])                # named 'projections'
@example(case=("basis_pursuit", "A"), bad=np.ones((4, 8)) * 1e300)  # LinAlgError from eigh
@example(case=("basis_pursuit", "polish"), bad=np.zeros(2))  # ValueError (truth of array)
@example(case=("run_ensemble", "progress"), bad=np.zeros(2))  # ValueError (truth of array)
@example(case=("run_ensemble", "resume"), bad=np.zeros(2))   # ValueError (truth of array)
@example(case=("Alignment", "on"), bad=None)                  # named 'source'
@example(case=("SaveAt", "observables"), bad=False)          # TypeError: bool not iterable
@example(case=("Scene", "effects"), bad=np.array(0.0))       # TypeError: 0-d iteration
@example(case=("Scene", "weights"), bad=[[1.0], [1.0, 2.0]])  # ValueError: ragged
@example(case=("run_ensemble", "members"), bad=np.array(0.0))  # TypeError: 0-d iteration
@example(case=("basis_pursuit", "eta"), bad=[[1.0], [1.0, 2.0]])  # ValueError: ragged
@example(case=("Noise", "matrix"), bad=np.zeros((0, 0)))     # ValueError: broadcast at run
@example(case=("Noise", "sigma"), bad=1e308)                 # OverflowError: sigma ** 2
@example(case=("simulate", "t_span"), bad=(-1e-05, 0.05))    # named '(t1 - t0)/dt' only
def test_bad_arguments_raise_a_named_kinred_error(case, bad):
    entry, arg = case
    fn, kw = ENTRIES[entry]
    kwargs = kw()
    kwargs[arg] = bad
    call_ok(fn, kwargs, arg)


def test_complex_input_is_refused_not_truncated():
    """numpy casts complex to float with only a ComplexWarning (the imaginary part dropped)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")                     # no ComplexWarning either
        with pytest.raises(InvalidInput, match=r"^mu must be real, got complex values"):
            w1(np.array([[1 + 1j, 0.0]]), X)
        with pytest.raises(InvalidInput, match=r"^x0 must be real"):
            simulate(_scene(), X + 0j, V, (0.0, 0.1), 0.05)
        with pytest.raises(InvalidInput, match=r"^A must be real"):
            basis_pursuit(A.astype(complex), Y)


# ------------------------------------------------------------------------------------------
# valid but extreme input: magnitudes, kernels, scales
# ------------------------------------------------------------------------------------------
_MAG = st.sampled_from([2.0**-1000, 1e-200, 1e-20, 1.0, 1e20, 1e150, 1e200, 1e300])


def _cloud(n, d):
    return hnp.arrays(np.float64, (n, d), elements=st.one_of(
        st.floats(-1, 1), st.sampled_from([0.0, 1e-310, -1.0, 1.0])))


@settings(max_examples=60, **FUZZ)
@given(n=st.integers(1, 5), m=st.integers(1, 5), d=st.integers(1, 3), data=st.data(),
       sx=_MAG, sy=_MAG)
def test_w1_of_any_finite_clouds_is_finite_or_a_kinred_error(n, m, d, data, sx, sy):
    x, y = data.draw(_cloud(n, d)) * sx, data.draw(_cloud(m, d)) * sy
    with small_limit():
        try:
            value = w1(x, y).value
        except Exception as exc:  # noqa: BLE001
            check_error(exc, "mu")
        else:
            assert np.isfinite(value) and value >= 0.0


@settings(max_examples=25, **FUZZ)
@given(ea=st.integers(-990, 990), ey=st.integers(-990, 990), seed=st.integers(0, 3))
@example(ea=990, ey=990, seed=0)       # A A^T overflowed: LinAlgError from eigh
@example(ea=-990, ey=-990, seed=1)     # norms underflowed (ran for minutes)
def test_basis_pursuit_is_homogeneous_in_powers_of_two(ea, ey, seed):
    """A·2^ea, Y·2^ey give Z·2^(ey−ea) bit for bit (the solver scales both to O(1)) while
    the solution is a normal float64."""
    assume(abs(ey - ea) <= 990)
    rng = np.random.default_rng(seed)
    A0 = rng.standard_normal((12, 30))
    Z0 = np.zeros((30, 2))
    Z0[rng.choice(30, 3, replace=False), [0, 1, 0]] = rng.standard_normal(3)
    ref = basis_pursuit(A0, A0 @ Z0)
    res = basis_pursuit(np.ldexp(A0, ea), np.ldexp(A0 @ Z0, ey))
    np.testing.assert_array_equal(np.ldexp(res.Z, ea - ey), ref.Z)
    assert list(res.status) == list(ref.status) == ["optimal", "optimal"]
    assert np.max(np.abs(ref.Z - Z0)) < 1e-8


def test_basis_pursuit_names_a_solution_beyond_the_float_range():
    with pytest.raises(InvalidInput, match=r"^A \(entries up to 2\^-1000\) and Y \(up to "
                                           r"2\^1002\) have a solution beyond the float64 range"):
        basis_pursuit(np.ldexp(np.eye(3), -1001), np.ldexp(np.ones(3), 1001))


_KERNELS = st.one_of(
    st.builds(CuckerSmale, st.sampled_from([0.0, 1e-300, 1.0, 1e6, 1e300]),
              st.sampled_from([0.0, 0.5, 1.5, 1e6, 1e300])),
    st.builds(Morse, st.sampled_from([0.0, 1.0, 1e6, 1e300]), st.sampled_from([1e-300, 1.0, 1e300]),
              st.sampled_from([0.0, 1.0, 1e300]), st.sampled_from([1e-300, 0.5, 1e300]),
              st.sampled_from([0.0, 0.25, 1e300])),
    st.builds(Quadratic, st.sampled_from([0.0, -1.0, 1e300])))


@settings(max_examples=40, **FUZZ)
@given(kernel=_KERNELS, which=st.sampled_from([Alignment, AttractionRepulsion]),
       n=st.integers(1, 5), d=st.integers(1, 3), data=st.data(), scale=_MAG,
       method=st.sampled_from(["euler", "rk4", "rk45"]), normalize=st.sampled_from(["mean", "sum"]),
       dt=st.sampled_from([1e-3, 0.01, 0.1]))
def test_simulate_with_extreme_kernels_and_states_ends_in_a_result_or_a_kinred_error(
        kernel, which, n, d, data, scale, method, normalize, dt):
    x, v = data.draw(_cloud(n, d)) * scale, data.draw(_cloud(n, d)) * scale
    with small_limit():
        try:
            tr = simulate(Scene([which(kernel)], normalize), x, v, (0.0, 0.1), dt, method=method,
                          max_steps=500, save=SaveAt(every=10, states=True))
        except Exception as exc:  # noqa: BLE001
            check_error(exc, "x0")
        else:  # the states stay finite; Γ ≤ (2 max|v|)² is finite while max|v| < 1e150
            assert np.all(np.isfinite(tr.x)) and np.all(np.isfinite(tr.v))
            small = np.max(np.abs(tr.v), axis=(1, 2)) < 1e150
            assert np.all(np.isfinite(tr.observables["gamma"][small]))
