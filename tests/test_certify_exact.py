"""Certificates cover exact pair sums only (issue 21, items 1 and 12): ``certify`` refuses an
approximate backend (NUFFT, RandomBatch, a backend that does not declare ``exact = True``) as
``kinred certify`` does, and a ``paper`` that is not a bool."""

import numpy as np
import pytest

from kinred.certify import certify
from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.errors import InvalidInput, KinredError
from kinred.pairsum import NUFFT, Dense, Numpy, RandomBatch, is_exact


def _issue_case(seed=0, n=40, d=3):
    rng = np.random.default_rng(seed)
    x0, v0 = rng.normal(size=(n, d)), rng.normal(size=(n, d))
    M = rng.normal(0.0, 1.0 / np.sqrt(d), (d, d))
    return M, x0, v0


class _Wrapped:
    """A third-party backend: Dense's sums, with or without ``exact`` declared."""

    def __init__(self, exact=None):
        self._dense = Dense()
        self.precision = "double"
        if exact is not None:
            self.exact = exact

    def plan(self, scene, n, dim):
        return self._dense.plan(scene, n, dim)

    def evaluate(self, plan, x, v, rng=None):
        return self._dense.evaluate(plan, x, v, rng)


def test_the_issue_nufft_case_is_refused_naming_the_backend():
    # issue 21 item 1: NUFFT(tol=0.9) returned a "certified bound" below the measured error
    M, x0, v0 = _issue_case()
    scene = Scene([Alignment(CuckerSmale(2, .5))], pairsum=NUFFT(tol=0.9))
    with pytest.raises(InvalidInput) as info:
        certify(scene, M, x0, v0, t_span=(0, 3), dt=0.05)
    msg = str(info.value)
    assert "NUFFT(tol=0.9)" in msg and "approximate" in msg
    assert "Dense()" in msg and "Numpy()" in msg and "\n" not in msg


@pytest.mark.parametrize("backend", [RandomBatch(p=2), RandomBatch(p=40), NUFFT(),
                                     _Wrapped(), _Wrapped(exact=False), _Wrapped(exact="yes")])
def test_every_approximate_or_undeclared_backend_is_refused(backend):
    M, x0, v0 = _issue_case(1)
    scene = Scene([Alignment(CuckerSmale(2, .5))], pairsum=backend)
    with pytest.raises(KinredError) as info:
        certify(scene, M, x0, v0, t_span=(0, 1), dt=0.05)
    msg = str(info.value)
    assert repr(backend) in msg and "exact" in msg
    assert "rng" not in msg                  # not RandomBatch's complaint about Scene.rhs(rng=)


def test_exact_backends_are_certified_and_declared_ones_agree_with_dense():
    M, x0, v0 = _issue_case(2)
    certs = {}
    for name, backend in [("dense", Dense()), ("numpy", Numpy()), ("declared", _Wrapped(True))]:
        scene = Scene([Alignment(CuckerSmale(2, .5))], pairsum=backend)
        certs[name] = certify(scene, M, x0, v0, t_span=(0, 1), dt=0.05)
        c = certs[name]
        assert np.all(c.bound >= c.error) and np.all(c.bound_max >= c.error_max)
    # a third-party backend declaring exact = True runs Dense's sums: the same numbers
    np.testing.assert_array_equal(certs["declared"].bound, certs["dense"].bound)
    np.testing.assert_allclose(certs["numpy"].error, certs["dense"].error, rtol=1e-9,
                               atol=1e-14)


def test_is_exact_reads_the_declaration():
    assert is_exact(Dense()) and is_exact(Dense(precision="mixed")) and is_exact(Numpy())
    assert not any(is_exact(b) for b in (NUFFT(), RandomBatch(), _Wrapped(), _Wrapped(1),
                                         None))


@pytest.mark.parametrize("paper", ["no", 0, 1, None, np.array([True])])
def test_certify_paper_must_be_a_bool(paper):
    M, x0, v0 = _issue_case(3)
    with pytest.raises(InvalidInput, match=r"paper must be True or False, got"):
        certify(Scene([Alignment(CuckerSmale(2, .5))]), M, x0, v0, t_span=(0, 1), dt=0.05,
                paper=paper)


def test_kinred_certify_refusal_uses_the_same_declaration():
    from kinred.experiments.kinetic_certify import check_certifiable
    from kinred.scenefile import SMALL_SCENE, config_from_dict

    data = {**SMALL_SCENE, "dynamics": {**SMALL_SCENE["dynamics"],
                                        "pairsum": {"method": "nufft", "tol": 0.5}}}
    with pytest.raises(KinredError, match=r"cannot certify: .*NUFFT\(tol=0\.5\).*approximate"):
        check_certifiable(config_from_dict(data))
