"""Observables: fluctuations at 1e-30, weights, verdict, the round-off floor of Γ."""

from fractions import Fraction

import numpy as np
import pytest

from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.errors import InvalidInput
from kinred.integrate import SaveAt, simulate
from kinred.observables import (FLOOR_FACTOR, above_floor, centre, flocking_verdict, gamma,
                                gamma_floor, lambda_, mean_velocity, relative_error)


def _exact_fluct(v, w):
    V = [[Fraction(float(a)) for a in row] for row in v]
    W = [Fraction(float(a)) for a in w]
    sw = sum(W)
    W = [a / sw for a in W]
    d = len(V[0])
    m = [sum(W[i] * V[i][j] for i in range(len(V))) for j in range(d)]
    return float(sum(W[i] * sum((V[i][j] - m[j]) ** 2 for j in range(d)) for i in range(len(V))))


@pytest.mark.parametrize("scale,eps", [(1.0, 1e-15), (1e3, 1e-11), (1e3, 1e-15)])
@pytest.mark.parametrize("weighted", [False, True])
def test_gamma_tiny_fluctuations_exact(scale, eps, weighted):
    rng = np.random.default_rng(0)
    c = scale * rng.uniform(0.5, 1.0, 4)
    v = c + eps * rng.normal(size=(30, 4))        # stored values; reference uses them exactly
    w = rng.uniform(0.1, 1.0, 30) if weighted else np.ones(30)
    w = w / w.sum()
    ref = _exact_fluct(v, w)
    got = gamma(v, w)
    if ref == 0.0:
        assert got <= 1e-40
    else:
        assert abs(got - ref) <= 1e-6 * ref
    if scale == 1.0:
        assert 1e-32 < ref < 1e-28


def test_lambda_centre_mean_velocity():
    x = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 4.0]])
    w = np.array([0.5, 0.25, 0.25])
    assert np.allclose(centre(x, w), [0.5, 1.0])
    assert lambda_(x, w) == pytest.approx(0.5 * 1.25 + 0.25 * (2.25 + 1) + 0.25 * (0.25 + 9))
    assert np.allclose(mean_velocity(x), [2 / 3, 4 / 3])


def test_flocking_verdict_rules():
    assert flocking_verdict(9.9e-11) == "pos"
    assert flocking_verdict(1e-10) == "n/a"
    assert flocking_verdict(1e-3) == "n/a"
    assert flocking_verdict(1.01e-3) == "neg"
    assert flocking_verdict(1e-6, yes_below=1e-5) == "pos"
    with pytest.raises(InvalidInput):
        flocking_verdict(-1.0)
    with pytest.raises(InvalidInput):
        flocking_verdict(1.0, yes_below=1.0, no_above=0.1)


def test_relative_error():
    assert relative_error([1.0, 2.0], [1.0, 2.5]) == pytest.approx(0.2)
    assert relative_error([0.0], [0.0]) == 0.0


# ----------------------------------------------------------------------------------------------
# The round-off floor of Gamma
# ----------------------------------------------------------------------------------------------

def test_gamma_floor_closed_form_and_validation():
    rng = np.random.default_rng(3)
    v = rng.uniform(-1, 1, (40, 7))
    w = rng.uniform(0.5, 1.5, 40)
    w /= w.sum()
    vc = mean_velocity(v, w)
    # F = n/12 sum_j ulp(v_cj)^2 and u^2 n |v_c|^2 / 12 < F <= u^2 n |v_c|^2 / 3
    assert gamma_floor(v, 1500, w) == pytest.approx(1500 * np.sum(np.spacing(np.abs(vc)) ** 2)
                                                     / 12, rel=1e-15)
    u2n = 2.0 ** -106 * 1500 * float(vc @ vc)
    assert u2n / 12 < gamma_floor(v, 1500, w) <= u2n / 3
    # linear in the steps, quadratic in the mean velocity, blind to the fluctuations
    assert gamma_floor(v, 3000, w) == 2 * gamma_floor(v, 1500, w)
    assert gamma_floor(v - vc + 4 * vc, 10, w) == pytest.approx(16 * gamma_floor(v, 10, w),
                                                               rel=1e-15)
    assert gamma_floor(vc + 1e-9 * (v - vc), 10, w) == pytest.approx(gamma_floor(v, 10, w),
                                                                    rel=1e-15)
    assert gamma_floor(v, 0) == 0.0 and gamma_floor(np.zeros((3, 2)), 10) == 0.0
    with pytest.raises(InvalidInput, match="n_steps"):
        gamma_floor(v, -1)
    with pytest.raises(InvalidInput, match="n_steps"):
        gamma_floor(v, 1.5)
    with pytest.raises(InvalidInput, match="v must have 2"):
        gamma_floor(v[0], 10)
    with pytest.raises(InvalidInput, match="v must be finite"):
        gamma_floor(np.full((2, 2), np.nan), 10)
    with pytest.raises(InvalidInput, match="weights"):
        gamma_floor(v, 10, np.ones(40))


def test_above_floor_mask_and_validation():
    g = np.array([[1.0, 1e-28], [1e-29, 0.0]])
    np.testing.assert_array_equal(above_floor(g, 1e-31), [[True, True], [False, False]])
    np.testing.assert_array_equal(above_floor(g, 1e-31, factor=1.0), [[True, True], [True, False]])
    assert FLOOR_FACTOR == 100.0 and above_floor(np.inf, 1.0) and not above_floor(0.0, 0.0)
    for bad, match in ((dict(gamma_values=[np.nan]), "gamma_values"),
                       (dict(gamma_values=[-1e-30]), "gamma_values"),
                       (dict(floor=-1.0), "floor"), (dict(floor=np.nan), "floor"),
                       (dict(factor=0.5), "factor")):
        args = dict(gamma_values=[1.0], floor=1e-30) | bad
        with pytest.raises(InvalidInput, match=match):
            above_floor(**args)


# The Table-1 setting where Gamma reaches the floor: the paper's initial data with N = 100,
# Gaussian projections of d = 200 to k = 25, sum normalization, G = 8, beta = 1.5, 1500 Euler
# steps of 0.02 (Gamma decays from 60 through 32 decades, then stops at about 3e-31).
_STEPS = 1500


def _floor_run(x0, v0, *, perm=None, block=None, states=False):
    sc = Scene([Alignment(CuckerSmale(8.0, 1.5))], "sum", block=block)
    if perm is not None:
        x0, v0 = x0[perm], v0[perm]
    tr = simulate(sc, x0, v0, (0.0, _STEPS * 0.02), 0.02,
                  save=SaveAt(every=10, observables=("gamma",), states="v" if states else False))
    assert tr.n_steps == _STEPS
    if not states:
        return tr.observables["gamma"]
    v = tr.v if perm is None else tr.v[:, np.argsort(perm)]
    return tr.observables["gamma"], v


@pytest.fixture(scope="module", params=[0, 2])
def floor_case(request):
    from kinred._rng import member_seed
    from kinred.experiments.table1 import initial_data
    from kinred.projection import jl_matrix

    x0, v0 = initial_data(100, 200, 0)
    M = jl_matrix(25, 200, seed=member_seed(20120101, request.param))
    x0, v0 = M.apply(x0), M.apply(v0)
    g, v = _floor_run(x0, v0, states=True)
    return x0, v0, g, v


def test_rounding_twins_agree_above_the_floor_and_stay_at_it_below(floor_case):
    # the same run with the agents permuted and another strip size: float64 sums taken in
    # another order, mathematically the same Gamma
    x0, v0, ga, _ = floor_case
    gb = _floor_run(x0, v0, perm=np.random.default_rng(1).permutation(100), block=7)
    F = gamma_floor(v0, _STEPS)
    well = above_floor(ga, F)
    assert well.sum() >= 50 and (~well).sum() >= 10     # decades above the floor, and at it
    assert np.max(np.abs(gb[well] - ga[well]) / ga[well]) < 5e-4        # measured <= 1e-4
    # below: the floor, not digits -- both at it, differing by a small part of it
    assert np.all(~above_floor(gb[~well], F, factor=1.01 * FLOOR_FACTOR))
    assert np.max(np.abs(gb[~well] - ga[~well])) < 0.1 * F               # measured <= 1e-2 F


def test_the_floor_moves_with_the_mean_velocity_squared(floor_case):
    # Galilean twins: every velocity shifted by c leaves Gamma of the dynamics unchanged, but
    # raises the floor with |v_c + c|^2 (by 1e4 and 4e6); the unshifted run is exact there
    x0, v0, g0, V0 = floor_case
    F0 = gamma_floor(v0, _STEPS)
    levels = []
    for c in (16.0, 256.0):
        gc, Vc = _floor_run(x0, v0 + c, states=True)
        Fc = gamma_floor(v0 + c, _STEPS)
        assert Fc > 1e3 * F0
        # the floor bounds the round-off noise E = (shifted state) - (exact state), and is
        # not absurdly loose: measured Gamma(E) <= 0.3 F all along, 0.08-0.3 F at the end
        noise = np.array([gamma(a - b) for a, b in zip(Vc, V0)])
        assert np.max(noise) <= Fc and noise[-1] >= Fc / 100
        # the shifted run stops decaying at the floor (measured 0.1-0.3 F); the exact one not
        assert Fc / 100 <= gc[-1] <= Fc and g0[-1] < 1e-3 * Fc
        levels.append(gc[-1] / Fc)
        # relative agreement well above the floor (measured <= 8e-3 at 100 F, 2e-4 at 1e4 F)
        well = above_floor(g0, Fc)
        assert np.max(np.abs(gc[well] - g0[well]) / g0[well]) < 3e-2
        far = above_floor(g0, Fc, factor=1e4)
        assert far.sum() >= 20 and np.max(np.abs(gc[far] - g0[far]) / g0[far]) < 1e-3
    # the level where Gamma stops tracks the predicted floor (c^2: 256x apart here)
    assert 1 / 1.5 < levels[0] / levels[1] < 1.5
