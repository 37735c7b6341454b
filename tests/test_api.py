"""The public API's shape (issue 21): names, flags, result objects and their reprs."""

import importlib
import pkgutil
import re
import types

import numpy as np
import pytest

import kinred
from kinred.certify import Certificate, certify
from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.integrate import SaveAt

MODULES = sorted(m.name for m in pkgutil.iter_modules(kinred.__path__)
                 if not m.name.startswith("_"))


# ------------------------------------------------------------------ names: one rule (item 8)
def test_the_package_has_the_modules_the_rule_is_about():
    assert {"quantize", "certify", "kinetic", "integrate", "distance"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_kinred_dot_module_is_the_module(name):
    mod = importlib.import_module(f"kinred.{name}")
    assert isinstance(mod, types.ModuleType) and mod.__name__ == f"kinred.{name}"
    assert getattr(kinred, name) is mod
    scope = {}
    exec(f"import kinred.{name} as alias", scope)                     # noqa: S102
    assert scope["alias"] is mod


def test_no_top_level_export_shadows_a_module():
    for name in kinred.__all__:
        obj = getattr(kinred, name)
        assert name not in MODULES or isinstance(obj, types.ModuleType), name


def test_namesake_functions_are_reached_through_their_module():
    from kinred.measures import TensorProduct, Uniform

    q = kinred.quantize.quantize(TensorProduct([Uniform(0, 1)] * 2), atoms=9)
    assert q.n_atoms == 9 and isinstance(q, kinred.quantize.Quantization)
    assert callable(kinred.certify.certify) and kinred.certify.Certificate is Certificate


# ------------------------------------------------------------ flags and numbers (item 5)
def _cert(dt=0.1, **kw):
    rng = np.random.default_rng(3)
    x0, v0 = rng.normal(size=(10, 6)), rng.normal(size=(10, 6))
    M = rng.normal(0, 1 / np.sqrt(2), (2, 6))
    return certify(Scene([Alignment(CuckerSmale(1.0, 0.4))]), M, x0, v0, t_span=(0, 2),
                   dt=dt, **kw)


def test_certificate_flags_and_numbers_are_properties():
    from dataclasses import replace

    c = _cert(save=SaveAt(every=5))
    assert c.valid is True
    bad = replace(c, bound=c.error * 0.5)          # a bound below the measured error
    assert bool(bad.valid) is False and bad.valid is False
    assert isinstance(c.ratio, np.ndarray) and c.ratio.shape == c.t.shape
    sel = c.error > 0
    np.testing.assert_array_equal(c.ratio[sel], c.bound[sel] / c.error[sel])
    np.testing.assert_array_equal(c.ratio_max[sel], c.bound_max[sel] / c.error_max[sel])
    assert np.isnan(replace(c, error=0 * c.error).ratio).all()          # no error: no ratio
    assert c.worst_ratio_after(1.0) == float(np.max(c.ratio[c.t >= 1.0]))


def test_worst_ratio_after_names_a_bad_norm():
    from kinred.errors import InvalidInput

    with pytest.raises(InvalidInput, match="norm"):
        _cert(save=SaveAt(every=10)).worst_ratio_after(1.0, "l1")


# ------------------------------------------------------------ the final state (item 6)
def _run(save=None, method="euler", x_shift=0.0):
    from kinred.integrate import simulate

    rng = np.random.default_rng(5)
    x0, v0 = rng.normal(size=(15, 4)) + x_shift, rng.normal(size=(15, 4))
    return simulate(Scene([Alignment(CuckerSmale(1.0, 0.4))]), x0, v0, (0.0, 1.0), 0.05,
                    method=method, save=save)


@pytest.mark.parametrize("method,x_shift", [("euler", 0.0), ("euler", 1e3), ("rk45", 0.0)])
def test_simulate_keeps_the_final_state_by_default(method, x_shift):
    tr = _run(method=method, x_shift=x_shift)
    full = _run(SaveAt(states=True), method=method, x_shift=x_shift)
    assert tr.x.shape == tr.v.shape == (1, 15, 4) and tr.t_states.tolist() == [1.0]
    np.testing.assert_array_equal(tr.x[-1], full.x[-1])
    np.testing.assert_array_equal(tr.v[-1], full.v[-1])
    np.testing.assert_array_equal(full.t_states, full.t)
    for k in tr.observables:                       # the rest of the run is unchanged
        np.testing.assert_array_equal(tr.observables[k], full.observables[k])
    assert not np.shares_memory(tr.x, tr.v)


def test_first_order_and_one_state_requests():
    from kinred.dynamics import Aggregation, Morse
    from kinred.integrate import simulate

    x0 = np.random.default_rng(6).normal(size=(8, 2))
    sc = Scene([Aggregation(Morse())])
    tr, full = (simulate(sc, x0, None, (0.0, 1.0), 0.1, save=s)
                for s in (None, SaveAt(states=True)))
    assert tr.v is None and tr.x.shape == (1, 8, 2)
    np.testing.assert_array_equal(tr.x[-1], full.x[-1])
    x_only = _run(SaveAt(every=5, states="x"))                  # kept as asked
    assert x_only.v is None and x_only.x.shape == (len(x_only.t), 15, 4)


def test_the_final_state_is_priced_before_the_run(monkeypatch):
    from kinred.errors import TooLarge
    from kinred.integrate import simulate
    from kinred.integrate._save import GRID_POINT_BYTES, OBS_VALUE_BYTES

    from kinred.dynamics import SelfPropulsion

    # no pair sums (their workspace is priced against the same limit)
    sc, x = Scene([SelfPropulsion(1.0, 0.5)]), np.random.default_rng(0).uniform(size=(40, 3))
    save = SaveAt(every=2, observables=("gamma",))              # 10 steps: 5 + 2 points
    need = 7 * (GRID_POINT_BYTES + OBS_VALUE_BYTES + 16 * 3) + 2 * 8 * 40 * 3
    monkeypatch.setenv("KINRED_MAX_BYTES", str(need))
    assert simulate(sc, x, x, (0.0, 1.0), 0.1, save=save).x.shape == (1, 40, 3)
    monkeypatch.setenv("KINRED_MAX_BYTES", str(need - 1))
    with pytest.raises(TooLarge, match=r"the final state \(N, d\) = \(40, 3\) x 2"):
        simulate(sc, x, x, (0.0, 1.0), 0.1, save=save)


# ------------------------------------------------------------------- reprs (item 7)
def test_certificate_repr_is_short_and_shows_headline_numbers():
    c = _cert(dt=0.004)                                           # 501 saved steps
    assert len(c.t) == 501
    text = repr(c)
    assert len(text.splitlines()) <= 8 and len(text) < 800
    assert "valid=True" in text and "N=10, d=6, k=2" in text and "n_steps=500" in text
    assert f"bound {c.bound[-1]:.4g}" in text and f"error {c.error[-1]:.4g}" in text
    assert f"worst_ratio_after(1.0)={c.worst_ratio_after(1.0):.4g}" in text


def test_certificate_summary_tabulates_the_series():
    c = _cert()
    lines = c.summary(rows=4).splitlines()
    assert lines[1].split() == ["t", "error", "bound", "ratio", "error_max", "bound_max",
                                "ratio_max", "w1_coupling", "w1_bound", "paper_bound"]
    rows = [list(map(float, ln.split())) for ln in lines[2:6]]
    assert [r[0] for r in rows] == pytest.approx([c.t[0], c.t[7], c.t[13], c.t[20]], rel=1e-3)
    assert rows[-1][1:3] == pytest.approx([c.error[-1], c.bound[-1]], rel=1e-3)
    assert lines[-1] == c.note


def test_trajectory_repr_is_short_at_any_length():
    from kinred.integrate import simulate

    rng = np.random.default_rng(0)
    x0, v0 = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    tr = simulate(Scene([Alignment()]), x0, v0, (0.0, 20.0), 0.01, save=SaveAt(states=True))
    text = repr(tr)
    assert len(tr.t) == 2001 and len(text.splitlines()) <= 8 and len(text) < 800
    assert "(2001, 40, 3)" in text and "n_steps=2000" in text and "'gamma': <(2001,)" in text
    lines = tr.summary(rows=5).splitlines()
    assert lines[0].split() == ["t", "gamma", "lambda"] and len(lines) == 6
    assert float(lines[-1].split()[1]) == pytest.approx(tr.observables["gamma"][-1], rel=1e-3)


# ------------------------------------------------------------ integrator aliases (item 11)
ALIAS_CASES = [("dopri5", "rk45"), ("DP45", "rk45"), ("RK45", "rk45"), ("Dormand-Prince", "rk45"),
               ("ode45", "rk45"), ("bs23", "rk23"), ("RK23", "rk23"), ("Bosh3", "rk23"),
               ("Bogacki_Shampine", "rk23"), ("Heun", "heun"), ("RK4", "rk4"),
               ("forward-euler", "euler"), ("Euler", "euler")]


@pytest.mark.parametrize("alias,name", ALIAS_CASES)
def test_integrator_aliases_run_the_named_integrator(alias, name):
    from kinred.integrate import method_name

    assert method_name(alias) == name
    a, b = _run(SaveAt(every=4, states=True), method=alias), _run(SaveAt(every=4, states=True),
                                                                   method=name)
    assert a.method == name and a.n_steps == b.n_steps and a.n_rejected == b.n_rejected
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.v, b.v)


def test_scipy_names_give_scipy_accuracy():
    """``method="RK45"`` is the same Dormand–Prince pair as SciPy's: both reach the
    closed-form solution of a linear alignment to their tolerances."""
    from kinred.dynamics import Quadratic
    from kinred.integrate import simulate

    rng = np.random.default_rng(2)
    x0, v0 = rng.normal(size=(5, 2)), rng.normal(size=(5, 2))
    sc = Scene([Alignment(Quadratic(1.0))])                 # v' = -(v - v̄): v̄ + e^{-t}(v0 - v̄)
    vb = v0.mean(axis=0)
    for m in ("RK45", "RK23", "dopri5", "bs23"):
        tr = simulate(sc, x0, v0, (0.0, 2.0), 0.1, method=m, rtol=1e-8, atol=1e-10,
                      save=SaveAt(every=10**6))
        np.testing.assert_allclose(tr.v[-1], vb + np.exp(-2.0) * (v0 - vb), rtol=0, atol=1e-6)


def test_scene_file_accepts_aliases_and_unknown_names_list_them():
    from kinred.errors import ConfigError, InvalidInput
    from kinred.integrate import simulate
    from kinred.scenefile import SMALL_SCENE, config_from_dict

    for alias, name in [("dopri5", "rk45"), ("RK23", "rk23"), ("Heun", "heun")]:
        cfg = config_from_dict({**SMALL_SCENE, "integrate": {**SMALL_SCENE["integrate"],
                                                              "method": alias}})
        assert cfg.method == name
    with pytest.raises(ConfigError, match="integrate.method: must be one of euler, heun"):
        config_from_dict({**SMALL_SCENE, "integrate": {**SMALL_SCENE["integrate"],
                                                        "method": "dop853"}})
    with pytest.raises(InvalidInput, match=r"method must be one of 'euler'.*; got 'dop853' "
                                           r"\(or an alias.*rk45 = .*dopri5.*rk23 = .*bs23"):
        simulate(Scene([Alignment()]), np.zeros((3, 2)), np.ones((3, 2)), method="dop853")


def test_registered_aliases_are_checked_and_removed_with_their_integrator():
    from kinred.errors import InvalidInput
    from kinred.integrate import ALIASES, RK4, ExplicitRK, method_name, register_solver
    from kinred.integrate import unregister_solver

    with pytest.raises(InvalidInput, match="'DOPRI5' would name two integrators"):
        register_solver("toy_rk", lambda: ExplicitRK(RK4), aliases=("DOPRI5",))
    with pytest.raises(InvalidInput, match="aliases must be"):
        register_solver("toy_rk", lambda: ExplicitRK(RK4), aliases=(1,))
    register_solver("toy_rk", lambda: ExplicitRK(RK4), aliases=("toy-4",))
    try:
        assert method_name("TOY_4") == "toy_rk" and ALIASES["toy-4"] == "toy_rk"
    finally:
        unregister_solver("toy_rk")
    assert "toy-4" not in ALIASES
    with pytest.raises(InvalidInput, match="got 'toy-4'"):
        method_name("toy-4")


# ---------------------------------------------- finite, true messages (item 12, two parts)
@pytest.mark.parametrize("max_modes,scale", [(1, 1.0), (2**20, 1e6)])
def test_nufft_too_large_names_a_finite_count(max_modes, scale):
    from kinred.errors import TooLarge
    from kinred.pairsum import NUFFT

    rng = np.random.default_rng(0)
    x, v = rng.normal(size=(40, 3)) * scale, rng.normal(size=(40, 3))
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5))], pairsum=NUFFT(max_modes=max_modes))
    with pytest.raises(TooLarge) as info:
        sc.rhs(x, v)
    msg = str(info.value)
    assert "inf" not in msg.replace("Fourier", "") and "nan" not in msg
    assert re.search(rf"needs at least [0-9][0-9,.]* ?[a-zA-Z]* Fourier modes for tol=1e-06, "
                     rf"more than max_modes={max_modes}\b", msg), msg
    assert " 0 MB" not in msg


def test_measure_file_widths_that_underflow_are_named():
    from kinred.errors import ConfigError
    from kinred.measures._file import measure_from_dict

    def coords(decay, repeat, **kw):
        return {"name": "u", "coordinate": [{"dist": "uniform", "repeat": repeat, "decay": decay,
                                             "params": {"loc": 0.0, "scale": 1.0}, **kw}]}

    with pytest.raises(ConfigError, match=r"coordinate\[0\]\.decay: the widths underflow: .* "
                                          r"from copy r = 2 on .*≈ 10\^-400") as info:
        measure_from_dict(coords(1e-200, 3))
    assert "nan" not in str(info.value) and "unbounded" not in str(info.value)
    with pytest.raises(ConfigError, match=r"from copy r = 1022 on \(decay = 0.5; the last, "
                                          r"r = 1099"):
        measure_from_dict(coords(0.5, 1100))
    with pytest.raises(ConfigError, match="widths underflow"):     # a support's width too
        measure_from_dict(coords(1e-160, 3, support=[0.0, 1e-10]))
    mu = measure_from_dict(coords(0.5, 1000))                       # 2^-999 is still normal
    assert mu.support_widths()[-1] == 0.5**999


def test_a_law_without_support_is_named_as_such():
    from scipy import stats

    from kinred.errors import InvalidInput
    from kinred.measures import Univariate

    with pytest.raises(InvalidInput, match=r"uniform has no support: .*\(nan, nan\); its "
                                           r"parameters are invalid") as info:
        Univariate(stats.uniform(0.0, 0.0))
    assert "unbounded" not in str(info.value)


# ------------------------------------------------------- the other results' reprs (item 7)
def test_result_reprs_stay_short():
    from kinred.ensemble import run_ensemble
    from kinred.kinetic import compare, reduce, solve, theorem_bound
    from kinred.measures import TensorProduct, Uniform
    from kinred.projection import trajectory_distortion

    sc = Scene([Alignment(CuckerSmale(1.0, 0.4))])
    sol = solve(sc, TensorProduct([Uniform(0, 1)] * 4), t_span=(0, 1), dt=0.05, eps=0.45)
    M = np.random.default_rng(1).normal(size=(1, 2))
    red = reduce(sol, M=M)
    ens = run_ensemble(lambda p, ss: {"a": np.zeros(100) + p["i"]},
                       [dict(i=i) for i in range(30)], master_seed=0)
    found = {"KineticSolution": (sol, f"x=<({len(sol.t)}, {sol.n_atoms}, 2) float64"),
             "ReducedSolution": (red, f"y=<({len(sol.t)}, {sol.n_atoms}, 1) float64"),
             "Comparison": (compare(sol, red), f"w1=<({len(sol.t)},) float64"),
             "TheoremBound": (theorem_bound(sol, red), f"bound=<({len(sol.t)},) float64"),
             "EnsembleResult": (ens, "results=<tuple of 30>"),
             "TrajectoryDistortionResult": (trajectory_distortion(M, sol.x[:, :300]),
                                            f"eps_t=<({len(sol.t)},) float64")}
    assert sol.n_atoms >= 400
    for name, (obj, shape) in found.items():
        text = repr(obj)
        assert text.startswith(name + "(") and shape in text, (name, text)
        assert len(text.splitlines()) <= 16 and len(text) < 1600, (name, len(text))
