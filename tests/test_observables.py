"""Observables: fluctuations at 1e-30, weights, verdict."""

from fractions import Fraction

import numpy as np
import pytest

from kinred.errors import InvalidInput
from kinred.observables import (centre, flocking_verdict, gamma, lambda_, mean_velocity,
                                relative_error)


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
