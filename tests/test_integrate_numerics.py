"""Small silent lies of the integrators (issue 21, item 4): the stability cache keyed by a
table's name, the guard's cancelling fluctuation, rk45 with atol = 0 and a tiny rtol."""

import warnings

import numpy as np
import pytest

from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.errors import KinredWarning, SimulationDiverged
from kinred.integrate import HEUN, RK4, SaveAt, simulate
from kinred.integrate._controllers import AdaptiveStep
from kinred.integrate._guard import real_stability
from kinred.integrate._tables import RKTable

RTOL_MIN = 100 * np.finfo(float).eps   # SciPy's floor of rtol


def _data(N, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (N, d)), rng.uniform(-1, 1, (N, d))


# ------------------------------------------------------------- (a) stability by content
def test_real_stability_is_cached_by_the_coefficients_not_the_name():
    """A Heun table named "rk4" got RK4's 2.785 from a cache keyed by the name."""
    # RK4: R(z) = 1 + z + z²/2 + z³/6 + z⁴/24 = 1 at z ≠ 0 ⇔ 1 + z/2 + z²/6 + z³/24 = 0
    roots = np.roots([1 / 24, 1 / 6, 1 / 2, 1.0])
    beta_rk4 = -float(min(r.real for r in roots if abs(r.imag) < 1e-12))
    assert real_stability(RK4) == pytest.approx(beta_rk4, abs=1e-6)         # fills the cache
    fake = RKTable("rk4", HEUN.C.copy(), HEUN.A.copy(), HEUN.B.copy(), 2)
    assert real_stability(fake) == 2.0       # Heun: |1 + z + z²/2| = 1 at z = −2
    assert real_stability(RK4) == pytest.approx(beta_rk4, abs=1e-6)


# ------------------------------------------------------------- (c) the guard at a large mean
@pytest.mark.parametrize("mean", [0.0, 1e8])
def test_guard_sees_growth_beside_a_large_mean_velocity(mean):
    """Table-1 setting at dt = 0.2 (h·ρ > 2: Γ grows 58x then settles) is stopped within
    3 steps; with every velocity shifted by 1e8, Σw|v|² − |v̄|² lost every digit of Γ ≈ 1 and
    its allowance 1e-9·Σw|v|² = 1e7 hid the growth, so main ran on to a wrong verdict."""
    x0, v0 = _data(200, 20)
    shift = np.full(20, mean / np.sqrt(20))           # |v̄| shifted by `mean`
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum")
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, x0, v0 + shift, (0, 30), 0.2, save=SaveAt(every=50))
    assert info.value.step <= 3 and "velocity fluctuation Γ" in str(info.value)


def test_guard_stays_silent_on_a_stable_run_beside_a_large_mean_velocity():
    """The same scene at a stable dt flocks down to the round-off floor with no false alarm,
    and Γ matches the run without the shift while it is above that floor."""
    x0, v0 = _data(60, 10, seed=5)
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum")
    shift = np.full(10, 1e8 / np.sqrt(10))
    a = simulate(sc, x0, v0, (0, 30), 0.05, save=SaveAt(every=2))
    b = simulate(sc, x0, v0 + shift, (0, 30), 0.05, save=SaveAt(every=2))
    ga, gb = a.observables["gamma"], b.observables["gamma"]
    assert ga[-1] < 1e-20 * ga[0]
    mask = ga > 1e-6 * ga[0]                            # far above the floor of |v̄| = 1e8
    assert mask.sum() >= 5
    assert np.max(np.abs(gb[mask] - ga[mask]) / ga[mask]) < 1e-6


# ------------------------------------------------------------- (d) rk45 tolerances
def _zero_last_coordinate(N=6, d=3):
    rng = np.random.default_rng(0)
    x0, v0 = rng.normal(size=(N, d)), rng.normal(size=(N, d))
    x0[:, -1] = 0.0
    v0[:, -1] = 0.0                                     # the last coordinate stays exactly 0
    return x0, v0


def test_rk45_with_atol_zero_and_a_coordinate_that_stays_zero():
    """Main: 0/0 in the error norm → "the drift is non-finite" at t = 0. The run must finish,
    keep the zero coordinate at 0 and agree with the same run in one dimension fewer."""
    x0, v0 = _zero_last_coordinate()
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5))])
    tr = simulate(sc, x0, v0, (0, 1), 0.1, method="rk45", atol=0.0, rtol=1e-8,
                  save=SaveAt(states=True))
    assert np.all(tr.x[-1][:, -1] == 0.0) and np.all(tr.v[-1][:, -1] == 0.0)
    ref = simulate(sc, x0[:, :-1], v0[:, :-1], (0, 1), 0.1, method="rk45", atol=1e-14,
                   rtol=1e-12, save=SaveAt(states=True))
    assert np.max(np.abs(tr.x[-1][:, :-1] - ref.x[-1])) < 1e-6
    assert np.max(np.abs(tr.v[-1][:, :-1] - ref.v[-1])) < 1e-6


def test_rtol_below_100_eps_is_floored_with_a_warning():
    """SciPy's rule: rtol < 100 eps warns and uses 100 eps (main kept 1e-20, which no step
    can meet)."""
    with pytest.warns(KinredWarning, match=r"rtol=1e-20 is below 100 machine epsilons"):
        ctl = AdaptiveStep(rtol=1e-20, atol=0.0)
    assert ctl.rtol == RTOL_MIN
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert AdaptiveStep(rtol=RTOL_MIN).rtol == RTOL_MIN     # no warning at the floor
    x0, v0 = _zero_last_coordinate()
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5))])
    with pytest.warns(KinredWarning, match="below 100 machine epsilons"):
        tr = simulate(sc, x0, v0, (0, 0.5), 0.1, method="rk45", atol=0.0, rtol=1e-20,
                      save=SaveAt(states=True))
    ref = simulate(sc, x0, v0, (0, 0.5), 0.1, method="rk45", atol=0.0, rtol=RTOL_MIN,
                   save=SaveAt(states=True))
    assert np.array_equal(tr.x[-1], ref.x[-1]) and np.array_equal(tr.v[-1], ref.v[-1])
