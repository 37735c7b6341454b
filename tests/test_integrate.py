"""Integrators: RK table identities, convergence orders, Euler–Maruyama, divergence, SaveAt."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from kinred.dynamics import Alignment, CuckerSmale, Noise, Scene, SelfPropulsion
from kinred.errors import InvalidInput, SimulationDiverged
from kinred.integrate import DOPRI5, BS32, EULER, HEUN, RK4, SaveAt, simulate


@pytest.mark.parametrize("tab", [EULER, HEUN, RK4, DOPRI5, BS32], ids=lambda t: t.name)
def test_rk_table_identities(tab):
    A, B, C = tab.A, tab.B, tab.C
    assert np.allclose(A.sum(axis=1), C, atol=1e-15)
    assert np.all(np.triu(A) == 0)
    assert B.sum() == pytest.approx(1.0, abs=1e-15)
    p = tab.order
    if p >= 2:
        assert B @ C == pytest.approx(1 / 2, abs=1e-15)
    if p >= 3:
        assert B @ C ** 2 == pytest.approx(1 / 3, abs=1e-15)
        assert B @ (A @ C) == pytest.approx(1 / 6, abs=1e-15)
    if p >= 4:
        assert B @ C ** 3 == pytest.approx(1 / 4, abs=1e-15)
        assert B @ (C * (A @ C)) == pytest.approx(1 / 8, abs=1e-15)
        assert B @ (A @ C ** 2) == pytest.approx(1 / 12, abs=1e-15)
        assert B @ (A @ (A @ C)) == pytest.approx(1 / 24, abs=1e-15)
    if p >= 5:
        assert B @ C ** 4 == pytest.approx(1 / 5, abs=1e-15)
        assert B @ (A @ (A @ (A @ C))) == pytest.approx(1 / 120, abs=1e-15)
    if tab.E is not None:
        assert abs(tab.E.sum()) < 1e-15     # embedded weights also sum to one


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


@pytest.mark.parametrize("method,order", [("euler", 1), ("heun", 2), ("rk4", 4)])
def test_convergence_order(method, order):
    sc, x0, v0, T, ref = _problem()
    dts = [0.1, 0.05, 0.025, 0.0125] if order < 4 else [0.2, 0.1, 0.05, 0.025]
    errs = []
    for dt in dts:
        tr = simulate(sc, x0, v0, (0, T), dt, method=method, save=SaveAt(every=10**6, states=True))
        y = np.concatenate([tr.x[-1].ravel(), tr.v[-1].ravel()])
        errs.append(np.max(np.abs(y - ref)))
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert abs(slope - order) < 0.25, (slope, errs)


@pytest.mark.parametrize("method,q", [("rk45", 5), ("rk23", 3)])
def test_adaptive_error_decreases_with_rtol(method, q):
    sc, x0, v0, T, ref = _problem()
    errs, evals = [], []
    rtols = [1e-4, 1e-6, 1e-8]
    for r in rtols:
        tr = simulate(sc, x0, v0, (0, T), 0.1, method=method, rtol=r, atol=r * 1e-2,
                      save=SaveAt(every=10**6, states=True))
        y = np.concatenate([tr.x[-1].ravel(), tr.v[-1].ravel()])
        errs.append(np.max(np.abs(y - ref)))
        evals.append(tr.n_rhs_evals)
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-7
    # error ~ rtol (tolerance proportionality), within a generous factor
    slope = np.polyfit(np.log(rtols), np.log(errs), 1)[0]
    assert 0.6 < slope < 1.3
    # work grows like rtol^(-1/q)
    assert evals[2] > evals[0]


def test_euler_maruyama_strong_order_additive_noise():
    # dv = -v dt + sigma dW with x' = v: linear, exact solution from the same Brownian path.
    # With additive noise EM has strong order 1 (not only 1/2).
    from kinred.dynamics import Field
    sigma, T = 0.5, 1.0
    fine = 2 ** 12
    n_paths = 200
    errs = {}
    for m in (2 ** 4, 2 ** 5, 2 ** 6, 2 ** 7):
        errs[m] = 0.0
    rng = np.random.default_rng(11)
    for p in range(n_paths):
        dW = rng.normal(0, np.sqrt(T / fine), fine)
        # exact: v(T) = e^{-T} v0 + sigma * int e^{-(T-s)} dW_s (fine Riemann sum, O(1e-4) error)
        s = np.arange(fine) * T / fine
        v_exact = np.exp(-T) * 1.0 + sigma * np.sum(np.exp(-(T - s)) * dW)
        for m in errs:
            h = T / m
            inc = dW.reshape(m, -1).sum(axis=1)
            v = 1.0
            for n in range(m):
                v = v - h * v + sigma * inc[n]
            errs[m] += (v - v_exact) ** 2 / n_paths
    hs = np.array([T / m for m in errs])
    e = np.sqrt(np.array(list(errs.values())))
    slope = np.polyfit(np.log(hs), np.log(e), 1)[0]
    assert 0.8 < slope < 1.2
    # and the engine's EM reproduces that recursion exactly (same increments, scaled)
    sc = Scene([Field(lambda t, x, v: -v, translation_invariant=True), Noise(sigma)])
    tr = simulate(sc, np.zeros((1, 1)), np.ones((1, 1)), (0, T), T / 16, method="euler_maruyama",
                  seed=3, save=SaveAt(every=16, states=True))
    g = np.random.default_rng(3)
    v = 1.0
    for n in range(16):
        v = v - (T / 16) * v + sigma * np.sqrt(T / 16) * g.standard_normal((1, 1))[0, 0]
    assert tr.v[-1, 0, 0] == pytest.approx(v, rel=1e-14)


def test_noise_requires_euler_maruyama():
    sc = Scene([Alignment(), Noise(0.1)])
    with pytest.raises(InvalidInput, match="euler_maruyama"):
        simulate(sc, np.zeros((3, 2)), np.zeros((3, 2)), (0, 1), 0.1, method="rk4")


def test_divergence_names_time_step_and_hint():
    rng = np.random.default_rng(0)
    sc = Scene([SelfPropulsion(1.0, 50.0)])
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, rng.normal(size=(5, 3)), 3 * rng.normal(size=(5, 3)), (0, 10), 0.5)
    msg = str(info.value)
    assert "t=" in msg and "step" in msg and "dt*b*max|v|^2" in msg
    assert info.value.step >= 1 and info.value.t == pytest.approx(0.5 * info.value.step)


def test_saveat_grid_and_validation():
    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(size=(5, 2)), rng.uniform(size=(5, 2))
    sc = Scene([Alignment()])
    tr = simulate(sc, x0, v0, (0, 1), 0.1, save=SaveAt(every=3))
    assert np.allclose(tr.t, [0, 0.3, 0.6, 0.9, 1.0])
    tr = simulate(sc, x0, v0, (0, 1), 0.1, save=SaveAt(t=[0.2, 0.5], states="x"))
    assert np.allclose(tr.t, [0, 0.2, 0.5, 1.0]) and tr.x.shape == (4, 5, 2) and tr.v is None
    with pytest.raises(InvalidInput, match="step grid"):
        simulate(sc, x0, v0, (0, 1), 0.1, save=SaveAt(t=[0.25]))
    with pytest.raises(InvalidInput, match="integer"):
        simulate(sc, x0, v0, (0, 1), 0.3)
    tr = simulate(sc, x0, v0, (0, 1), 0.1, method="rk45", save=SaveAt(t=[0.25, 0.7]))
    assert np.allclose(tr.t, [0, 0.25, 0.7, 1.0])
    fn = lambda t, x, v, w: float(np.max(np.abs(v)))  # noqa: E731
    tr = simulate(sc, x0, v0, (0, 1), 0.1, save=SaveAt(every=5, observables={"vmax": fn}))
    assert tr.observables["vmax"].shape == (3,)
    with pytest.raises(InvalidInput, match="unknown"):
        SaveAt(observables=("gama",)) and simulate(sc, x0, v0, (0, 1), 0.1,
                                                    save=SaveAt(observables=("gama",)))
