"""Integrators as objects (issue 15): the one registry, solvers plugged in from outside the
package, per-step observers, the run's generator reaching the drift, solver and controller
objects against closed forms."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import kinred.cli as cli
from kinred.dynamics import (Aggregation, Alignment, CuckerSmale, Noise, Quadratic, Scene,
                             SelfPropulsion)
from kinred.errors import ConfigError, InvalidInput
from kinred.experiments import kinetic_run
from kinred.experiments.cost import integrators as cost_integrators
from kinred.integrate import (BS32, DOPRI5, EULER, METHODS, RK4, SOLVERS, TABLES, AdaptiveStep,
                              ConstantStep, ExplicitRK, RKTable, SaveAt, StepState,
                              register_solver, simulate, unregister_solver)
from kinred.observables import centre, gamma
from kinred.pairsum import Numpy, RandomBatch

from test_run_cli import BASE


# ---------------------------------------------------------------- toy solvers, from outside

class Midpoint:
    """The explicit midpoint rule written against the Solver protocol only (no table)."""

    order = 2

    def init(self, f, t0, state, dt):
        return None

    def step(self, f, t, state, h, solver_state, rng):
        x, v = state
        dx, dv = f(t, x, v, rng)
        xm = x + (0.5 * h) * dx
        vm = v + (0.5 * h) * dv if v is not None else None
        dx, dv = f(t + 0.5 * h, xm, vm, rng)
        return (x + h * dx, v + h * dv if v is not None else None), None, solver_state


#: Ralston's 2-stage method, and the Heun–Euler 2(1) embedded pair: tables only.
RALSTON = RKTable("ralston", np.array([0.0, 2 / 3]), np.array([[0.0, 0.0], [2 / 3, 0.0]]),
                  np.array([0.25, 0.75]), 2)
HEUN_EULER = RKTable("heun_euler", np.array([0.0, 1.0]), np.array([[0.0, 0.0], [1.0, 0.0]]),
                     np.array([0.5, 0.5]), 2, E=np.array([-0.5, 0.5]), error_order=1)

TOYS = ("midpoint", "ralston", "heun_euler")


@pytest.fixture
def toys():
    try:
        register_solver("midpoint", Midpoint, summary="explicit midpoint (test)")
        register_solver("ralston", lambda: ExplicitRK(RALSTON))
        register_solver("heun_euler", lambda: ExplicitRK(HEUN_EULER), adaptive=True)
        yield
    finally:
        for name in TOYS:
            if name in SOLVERS:
                unregister_solver(name)


def _problem():
    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(0, 1, (6, 2)), rng.uniform(-1, 1, (6, 2))
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5)), SelfPropulsion(0.5, 0.2)], "mean")
    T = 1.0

    def f(t, y):
        x, v = y[:12].reshape(6, 2), y[12:].reshape(6, 2)
        dx, dv = sc.rhs(x, v)
        return np.concatenate([dx.ravel(), dv.ravel()])

    ref = solve_ivp(f, (0, T), np.concatenate([x0.ravel(), v0.ravel()]), method="DOP853",
                    rtol=1e-13, atol=1e-14).y[:, -1]
    return sc, x0, v0, T, ref


def _final_error(tr, ref):
    return np.max(np.abs(np.concatenate([tr.x[-1].ravel(), tr.v[-1].ravel()]) - ref))


@pytest.mark.parametrize("name", ["midpoint", "ralston"])
def test_toy_solver_from_outside_converges_at_order_2(toys, name):
    sc, x0, v0, T, ref = _problem()
    dts = [0.1, 0.05, 0.025, 0.0125]
    errs = []
    for dt in dts:
        tr = simulate(sc, x0, v0, (0, T), dt, method=name, save=SaveAt(every=10**6, states=True))
        assert tr.method == name and tr.n_steps == round(T / dt)
        assert tr.n_rhs_evals == 2 * tr.n_steps
        errs.append(_final_error(tr, ref))
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert abs(slope - 2) < 0.25, (slope, errs)


def test_toy_embedded_pair_runs_adaptively(toys):
    sc, x0, v0, T, ref = _problem()
    assert SOLVERS["heun_euler"].adaptive and SOLVERS["heun_euler"].order == 2
    errs = []
    for rtol in (1e-3, 1e-5, 1e-7):
        tr = simulate(sc, x0, v0, (0, T), 0.1, method="heun_euler", rtol=rtol, atol=rtol * 1e-2,
                      save=SaveAt(every=10**6, states=True))
        # non-FSAL pair: 2 stages per first try, the first stage reused by a retry
        assert tr.n_rhs_evals == 2 * tr.n_steps + tr.n_rejected
        errs.append(_final_error(tr, ref))
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-6


def test_solver_registered_as_adaptive_must_estimate_its_error(toys):
    register_solver("midpoint_adaptive", Midpoint, adaptive=True)
    try:
        with pytest.raises(InvalidInput, match="registered as adaptive but its step returned "
                                               "no error estimate"):
            simulate(Scene([Alignment()]), np.zeros((3, 2)), np.ones((3, 2)), (0, 1), 0.1,
                     method="midpoint_adaptive")
    finally:
        unregister_solver("midpoint_adaptive")


# ---------------------------------------------------------------- the one registry

def test_registry_is_the_method_list():
    assert METHODS == tuple(SOLVERS) == ("euler", "heun", "rk4", "rk45", "rk23", "euler_maruyama")
    for name, spec in SOLVERS.items():
        assert spec.name == name
        if name in TABLES:
            assert spec.order == TABLES[name].order
            assert spec.adaptive == (TABLES[name].E is not None) and not spec.stochastic
    assert SOLVERS["euler_maruyama"].stochastic and not SOLVERS["euler_maruyama"].adaptive
    # the cost study and the scene files read the same list
    det = [m for m in METHODS if m != "euler_maruyama"]
    assert cost_integrators.methods() == (("euler", "heun", "rk4"), ("rk45", "rk23"))
    with pytest.raises(ConfigError, match="integrate.method: must be one of "
                                        + ", ".join(det) + ", got 'rk5'"):
        kinetic_run.config_from_dict({**kinetic_run.SMALL_SCENE, "integrate": {
            **kinetic_run.SMALL_SCENE["integrate"], "method": "rk5"}})
    with pytest.raises(InvalidInput, match="method must be one of "
                                           + ", ".join(map(repr, METHODS)) + "; got 'rk5'"):
        simulate(Scene([Alignment()]), np.zeros((3, 2)), np.ones((3, 2)), method="rk5")


def test_registered_solver_reaches_cost_study_scene_files_and_cli(toys, tmp_path, monkeypatch,
                                                                   capsys):
    fixed, adaptive = cost_integrators.methods()
    assert fixed == ("euler", "heun", "rk4", "midpoint", "ralston")
    assert adaptive == ("rk45", "rk23", "heun_euler")
    det = ", ".join(m for m in SOLVERS if m != "euler_maruyama")
    assert det.endswith("rk23, midpoint, ralston, heun_euler")
    with pytest.raises(ConfigError, match=f"must be one of {det}, got 'nope'"):
        kinetic_run.config_from_dict({**kinetic_run.SMALL_SCENE, "integrate": {
            **kinetic_run.SMALL_SCENE["integrate"], "method": "nope"}})
    # `kinred run` on a scene file that names the toy integrator
    if "kinred.commands.run" not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("kinred.commands.run",))
    scene = tmp_path / "mid.toml"
    scene.write_text(BASE.replace("[integrate]\n", '[integrate]\nmethod = "midpoint"\n'))
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0
    assert "midpoint dt = 0.1" in (tmp_path / "out" / "report.html").read_text()
    capsys.readouterr()


def test_register_solver_validation(toys):
    with pytest.raises(InvalidInput, match="'rk4' is already registered"):
        register_solver("rk4", Midpoint)
    with pytest.raises(InvalidInput, match="name must be a lower-case identifier"):
        register_solver("Mid Point", Midpoint)
    with pytest.raises(InvalidInput, match="adaptive must be True or False, got 1"):
        register_solver("mid2", Midpoint, adaptive=1)
    with pytest.raises(InvalidInput, match="make must be a callable"):
        register_solver("mid2", Midpoint())

    class NoStep:
        order = 1

        def init(self, f, t0, state, dt):
            return None

    with pytest.raises(InvalidInput, match=r"missing: step, order=1"):
        register_solver("nostep", NoStep)

    class NoOrder(Midpoint):
        order = None

    with pytest.raises(InvalidInput, match=r"missing: none, order=None"):
        register_solver("noorder", NoOrder)
    assert "nostep" not in SOLVERS and "noorder" not in SOLVERS and "mid2" not in SOLVERS
    with pytest.raises(InvalidInput, match="'euler' is a built-in integrator"):
        unregister_solver("euler")
    with pytest.raises(InvalidInput, match="'nope' is not registered"):
        unregister_solver("nope")


# ---------------------------------------------------------------- observers

class Energy:
    """An energy-like observer (an object with init and update), defined outside kinred."""

    def __init__(self, w):
        self.w, self.rows = w, []

    def init(self, t0, state, scene):
        self.rows = [(t0, state.step, state.h, self._kinetic(state))]

    def update(self, t, state, scene):
        assert isinstance(state, StepState) and state.t == t
        self.rows.append((t, state.step, state.dt, self._kinetic(state)))

    def _kinetic(self, state):
        return (0.5 * float(self.w @ np.einsum("ij,ij->i", state.v, state.v)),
                gamma(state.v, self.w))


def _spread(seen):
    """A custom diagnostic as a plain callable: max distance from the (absolute) centre."""
    def obs(t, state, scene):
        x = state.x + state.shift if state.shift is not None else state.x
        seen.append(float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1))))
    return obs


def test_observers_match_saved_states_fixed_step():
    rng = np.random.default_rng(1)
    x0, v0 = rng.uniform(0, 1, (15, 3)) + 100.0, rng.uniform(-1, 1, (15, 3))
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5)), SelfPropulsion(0.5, 0.2)], "mean")
    w = sc.agent_weights(15)
    energy, spread = Energy(w), []
    tr = simulate(sc, x0, v0, (0.0, 1.0), 0.05, method="rk4",
                  save=SaveAt(states=True), observers=[energy, _spread(spread)])
    # every accepted step is seen once, after init at t0, with its index and step size
    t, step, h, kin = zip(*energy.rows)
    assert step == tuple(range(21)) and h == (0.0,) + (0.05,) * 20
    assert np.array_equal(np.array(t[1:]), 0.05 * np.arange(1, 21))
    # ... and its values are those of the saved states, exactly
    ke = [0.5 * float(w @ np.einsum("ij,ij->i", v, v)) for v in tr.v]
    assert [k[0] for k in kin] == ke
    assert [k[1] for k in kin] == [gamma(v, w) for v in tr.v]
    assert np.array_equal([k[1] for k in kin], tr.observables["gamma"])
    assert spread == [float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))
                      for x in tr.x[1:]]
    # observers do not change the run
    plain = simulate(sc, x0, v0, (0.0, 1.0), 0.05, method="rk4", save=SaveAt(states=True))
    assert np.array_equal(plain.x, tr.x) and np.array_equal(plain.v, tr.v)


def test_observers_see_every_accepted_adaptive_step():
    rng = np.random.default_rng(2)
    x0, v0 = rng.uniform(0, 1, (10, 2)), rng.uniform(-1, 1, (10, 2))
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5))], "mean")
    rows = []
    tr = simulate(sc, x0, v0, (0.0, 2.0), 0.1, method="rk45", rtol=1e-8,
                  save=SaveAt(t=[0.3, 1.7], states=True),
                  observers=lambda t, s, scene: rows.append((t, s.step, s.h, s.x + s.shift)))
    t, step, h, x = zip(*rows)
    assert step == tuple(range(1, tr.n_steps + 1)) and tr.n_rejected > 0
    assert np.all(np.diff(t) > 0) and t[-1] == 2.0
    assert sum(h) == pytest.approx(2.0, rel=1e-12)
    for j, ts in enumerate(tr.t[1:], start=1):       # the save times are hit exactly
        assert np.array_equal(x[t.index(ts)], tr.x[j])


def test_observer_state_is_read_only_and_first_order_has_no_v():
    sc = Scene([Aggregation(Quadratic(1.0))])
    seen = []

    def obs(t, state, scene):
        seen.append((state.v, state.shift))
        state.x[0, 0] = 0.0

    with pytest.raises(ValueError, match="read-only"):
        simulate(sc, np.eye(3), None, (0, 1), 0.1, observers=obs)
    assert seen[0][0] is None and np.allclose(seen[0][1], np.full(3, 1 / 3), rtol=1e-15)


def test_a_callable_observer_object_is_called_and_init_comes_first():
    calls = []

    class Both:
        def init(self, t0, state, scene):
            calls.append(("init", state.step, t0))

        def __call__(self, t, state, scene):
            calls.append(("call", state.step, t))

        def update(self, t, state):                  # another signature: not the hook
            raise AssertionError("update must not be called on a callable observer")

    simulate(Scene([Alignment()]), np.zeros((2, 1)), np.ones((2, 1)), (0, 0.5), 0.25,
             observers=Both())
    assert calls == [("init", 0, 0.0), ("call", 1, 0.25), ("call", 2, 0.5)]


@pytest.mark.parametrize("bad", [42, [print, "x"], [object()]])
def test_observers_validation(bad):
    with pytest.raises(InvalidInput, match="observer"):
        simulate(Scene([Alignment()]), np.zeros((3, 2)), np.ones((3, 2)), (0, 1), 0.1,
                 observers=bad)


# ---------------------------------------------------------------- the generator reaches f

class JitterBackend(Numpy):
    """A stochastic pair-sum backend: exact pair sums plus a draw from the run's generator."""

    stochastic = True

    def __init__(self):
        super().__init__()
        self.rngs = []

    def evaluate(self, plan, x, v, rng=None):
        self.rngs.append(rng)
        out = super().evaluate(plan, x, v, rng)
        if self.stochastic:
            out["v"] = out["v"] + 1e-3 * rng.standard_normal(out["v"].shape)
        return out


def test_run_generator_reaches_a_stochastic_pair_sum():
    rng = np.random.default_rng(3)
    x0, v0 = rng.uniform(0, 1, (5, 2)), rng.uniform(-1, 1, (5, 2))
    back = JitterBackend()
    sc = Scene([Alignment(CuckerSmale(1.0, 1.0))], pairsum=back)
    g = np.random.default_rng(11)
    a = simulate(sc, x0, v0, (0, 1), 0.1, method="rk4", seed=g, save=SaveAt(states=True))
    assert len(back.rngs) == a.n_rhs_evals == 40 and all(r is g for r in back.rngs)
    b = simulate(sc, x0, v0, (0, 1), 0.1, method="rk4", seed=11, save=SaveAt(states=True))
    c = simulate(sc, x0, v0, (0, 1), 0.1, method="rk4", seed=12, save=SaveAt(states=True))
    assert np.array_equal(a.v, b.v) and not np.array_equal(a.v, c.v)
    # an exact backend in a scene without noise gets rng=None (the deterministic drift)
    back.stochastic = False
    back.rngs = []
    simulate(sc, x0, v0, (0, 1), 0.1, method="heun", seed=1)
    assert back.rngs == [None] * 20


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_random_batch_runs_under_simulate_reproducibly_by_seed(method):
    # the random batch backend needs the run's generator in every evaluation: simulate gave
    # it rng=None (InvalidInput "RandomBatch needs the run's random generator")
    rng = np.random.default_rng(6)
    x0, v0 = rng.uniform(0, 1, (9, 3)), rng.uniform(-1, 1, (9, 3))
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5))], "sum", pairsum=RandomBatch(p=3))
    kw = dict(method=method, save=SaveAt(states=True))
    a = simulate(sc, x0, v0, (0, 1), 0.05, seed=7, **kw)
    b = simulate(sc, x0, v0, (0, 1), 0.05, seed=7, **kw)
    c = simulate(sc, x0, v0, (0, 1), 0.05, seed=8, **kw)
    assert np.array_equal(a.v, b.v) and not np.array_equal(a.v, c.v)
    # the mean velocity is conserved (equal weights: pairs exchange opposite updates) ...
    assert np.allclose(a.v.mean(axis=1), v0.mean(axis=0), rtol=0, atol=1e-14)
    if method == "euler":
        # ... and the run is Euler with the backend drawing one permutation per step from
        # the generator of the seed (a twin through the public Scene.rhs, absolute frame)
        g, x, v = np.random.default_rng(7), x0.copy(), v0.copy()
        for _ in range(20):
            dx, dv = sc.rhs(x, v, rng=g)
            x, v = x + 0.05 * dx, v + 0.05 * dv
        assert np.allclose(a.v[-1], v, rtol=1e-12, atol=1e-13)


def test_euler_maruyama_draws_the_drift_then_the_increments():
    rng = np.random.default_rng(4)
    x0, v0 = rng.uniform(0, 1, (5, 2)), rng.uniform(-1, 1, (5, 2))
    sc = Scene([Alignment(CuckerSmale(1.0, 1.0)), Noise(0.5)], pairsum=JitterBackend())
    tr = simulate(sc, x0, v0, (0, 0.2), 0.1, method="euler_maruyama", seed=5,
                  save=SaveAt(states=True))
    g, x, v = np.random.default_rng(5), x0 - centre(x0, np.full(5, 0.2)), v0.copy()
    plain = Scene([Alignment(CuckerSmale(1.0, 1.0))], pairsum="numpy")
    for n in range(2):
        dx, dv = plain._rhs(x, v, 0.1 * n)
        dv = dv + 1e-3 * g.standard_normal(dv.shape)
        x = x + 0.1 * dx
        v = v + 0.1 * dv + 0.5 * np.sqrt(0.1) * g.standard_normal(v.shape)
    assert np.allclose(tr.v[-1], v, rtol=1e-14, atol=1e-15)


def test_seed_is_validated_for_deterministic_scenes_too():
    with pytest.raises(InvalidInput, match="seed must be a non-negative integer, got -1"):
        simulate(Scene([Alignment()]), np.zeros((3, 2)), np.ones((3, 2)), (0, 1), 0.1, seed=-1)


# ---------------------------------------------------------------- solver and controller objects

def _amplification(table, z):
    s = table.stages
    return 1.0 + z * table.B @ np.linalg.solve(np.eye(s) - z * table.A, np.ones(s))


@pytest.mark.parametrize("table", [EULER, RK4, DOPRI5, BS32], ids=lambda t: t.name)
def test_explicit_rk_step_is_the_stability_function(table):
    # y' = λ y: one step multiplies y by R(hλ) = 1 + z Bᵀ(I − zA)⁻¹1; the error estimate of
    # an embedded pair is (R − R̂)(z) y with R̂ from the weights B − E
    lam, h = -1.3, 0.2
    y0 = np.array([[1.0, -2.0], [0.5, 3.0]])
    solver = ExplicitRK(table)

    def f(t, x, v, rng):
        return lam * x, None

    ss = solver.init(f, 0.0, (y0.copy(), None), h)
    (y, _), err, _ = solver.step(f, 0.0, (y0.copy(), None), h, ss, None)
    assert np.allclose(y, _amplification(table, h * lam) * y0, rtol=1e-14, atol=0)
    if table.E is None:
        assert err is None
    else:
        emb = RKTable("emb", table.C, table.A, table.B - table.E, table.error_order)
        diff = _amplification(table, h * lam) - _amplification(emb, h * lam)
        assert np.allclose(err[0], diff * y0, rtol=1e-9, atol=1e-17)


@pytest.mark.parametrize("method,stages", [("rk45", 6), ("rk23", 3)])
def test_fsal_pairs_evaluate_the_drift_once_per_new_stage(method, stages):
    sc, x0, v0, T, _ = _problem()
    tr = simulate(sc, x0, v0, (0, T), 0.5, method=method, rtol=1e-9, atol=1e-12)
    assert tr.n_rejected > 0
    assert tr.n_rhs_evals == 1 + stages * (tr.n_steps + tr.n_rejected)


def test_euler_maruyama_without_noise_is_euler_bit_for_bit():
    sc, x0, v0, T, _ = _problem()
    a = simulate(sc, x0, v0, (0, T), 0.05, save=SaveAt(states=True))
    b = simulate(sc, x0, v0, (0, T), 0.05, method="euler_maruyama", seed=1,
                 save=SaveAt(states=True))
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v)


def test_controller_objects_validate():
    assert ConstantStep().init(None, 0.0, 2.0, 0.1, "euler").n_steps == 20
    with pytest.raises(InvalidInput, match="must be a positive integer for method='heun'"):
        ConstantStep().init(None, 0.0, 1.0, 0.3, "heun")
    for kw, msg in [({"rtol": 0.0}, "rtol must be > 0.0"), ({"atol": -1.0}, "atol must be >= 0.0"),
                    ({"max_steps": 0}, "max_steps must be >= 1, got 0"),
                    ({"safety": 1.5}, "safety must be <= 1.0, got 1.5"),
                    ({"min_factor": 1.0}, "min_factor must be < 1.0, got 1.0"),
                    ({"max_factor": 1.0}, "max_factor must be > 1.0, got 1.0"),
                    ({"floor": 0.0}, "floor must be > 0.0, got 0.0")]:
        with pytest.raises(InvalidInput, match=msg):
            AdaptiveStep(**kw)
    run = AdaptiveStep().init(ExplicitRK(DOPRI5), 0.0, 10.0, 0.01, "rk45")
    assert run.max_steps == 1_000_000 and run.q == 5      # 1000·⌈span/dt⌉; min(5, 4) + 1
    # step-to-hit: a step that would pass the next save time ends on it
    assert run.propose(0.0, 0, 0.004, None) == (0.004, 0.004, True)
    assert run.propose(0.0, 0, 0.5, None) == (0.01, 0.01, False)


def test_observer_methods_declaration_refuses_other_integrators_before_work():
    """An observer with a ``methods`` attribute runs only with those integrators: any other
    method is refused before the first evaluation (init never called)."""
    calls = []

    class EulerOnly:
        methods = ("euler",)

        def init(self, t0, state, scene):
            calls.append("init")

        def update(self, t, state, scene):
            calls.append(state.step)

    sc = Scene([Alignment()])
    x0, v0 = np.zeros((3, 2)), np.eye(3)[:, :2]
    simulate(sc, x0, v0, (0, 0.2), 0.1, observers=EulerOnly())
    assert calls == ["init", 1, 2]
    for method in ("rk4", "rk45", "euler_maruyama"):
        calls.clear()
        with pytest.raises(InvalidInput, match=r"observers\[1\] .* valid only for method in "
                                               r"\('euler',\); got method='" + method):
            simulate(sc, x0, v0, (0, 0.2), 0.1, method=method,
                     observers=[lambda t, s, scene: calls.append(t), EulerOnly()])
        assert calls == []
