"""``Scene(precision="mixed")``: float32 pair sums, float64 state – what accuracy it keeps.

The error model (docs/dynamics.md): every pairwise sum has a relative error of a few float32
round-offs *relative to the fluctuation size* (the carriers are centred in float64 before
rounding), close pairs are recomputed in float64, everything else is float64. The tests pin
that down on the cases that break naive single precision: fluctuations near 1e-15, a cloud
1e6 away from the origin, coincident agents, k ≤ 3 and the Gram path, several threads.
"""

import numpy as np
import pytest

from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene,
                             SelfPropulsion)
from kinred import _parallel
from kinred._parallel import num_threads
from kinred.errors import InvalidInput
from kinred.integrate import SaveAt, simulate
from kinred.observables import above_floor, gamma_floor, mean_velocity
from kinred.pairsum import _kernels, dense


def _data(N, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (N, d)), rng.uniform(-1, 1, (N, d))


SCENES = [
    [Alignment(CuckerSmale(0.8, 1.5))],                    # half-integer kernel (numba)
    [Alignment(CuckerSmale(0.8, 1.62))],                   # ufunc chain
    [AttractionRepulsion(Morse(soft=0.2)), Alignment(CuckerSmale(1.0, 0.5), on="v")],
]


def _rel(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


@pytest.mark.parametrize("effects", SCENES, ids=range(len(SCENES)))
@pytest.mark.parametrize("d", [2, 9, 60])          # differences path (k <= 3) and Gram path
@pytest.mark.parametrize("threads", [1, 2])
def test_mixed_rhs_agrees_with_double_to_float32_accuracy(effects, d, threads, monkeypatch):
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)   # two threads even at this size
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    x, v = _data(301, d, seed=d)
    w = np.random.default_rng(1).uniform(0.5, 1.5, 301)
    w /= w.sum()
    with num_threads(threads):
        mixed = Scene(effects, "sum", weights=w, precision="mixed").rhs(x, v)[1]
    double = Scene(effects, "sum", weights=w, engine="numpy").rhs(x, v)[1]
    assert mixed.dtype == np.float64
    err = _rel(mixed, double)
    assert err < 2e-5, err
    assert err > 1e-12           # it really ran in float32 (not silently in float64)


def test_mixed_error_is_relative_to_the_fluctuations_and_to_translations():
    # velocities = a mean of size 1 plus fluctuations of size 1e-13; the cloud sits 1e6 away
    x, v = _data(200, 12, seed=3)
    v = 1.0 + 1e-13 * v
    far = x + 1e6
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum", precision="mixed")
    ref = Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum", engine="numpy").rhs(x, v)[1]
    assert np.max(np.abs(ref)) < 1e-11            # the field is of the fluctuation size
    assert _rel(sc.rhs(x, v)[1], ref) < 2e-5
    assert _rel(sc.rhs(far, v)[1], ref) < 2e-5


def test_mixed_coincident_agents_are_exact_zero_distance():
    x, v = _data(40, 5, seed=4)
    x[10:20] = x[3]                                  # eleven agents at one point
    effects = [AttractionRepulsion(Morse(soft=0.1)), SelfPropulsion(1.0, 0.5)]
    mixed = Scene(effects, "mean", precision="mixed", block=7).rhs(x, v)[1]
    ref = Scene(effects, "mean", engine="numpy").rhs(x, v)[1]
    assert np.all(np.isfinite(mixed)) and _rel(mixed, ref) < 2e-5


def test_mixed_flocking_run_follows_double_down_to_the_round_off_floor():
    # the paper's beta = 1.5 setting at reduced N: Gamma decays over ~30 decades, down to the
    # round-off floor of the float64 velocities (1.3e-31 here; both runs stop near 3e-33)
    x0, v0 = _data(60, 10, seed=5)
    kw = dict(save=SaveAt(every=1, observables=("gamma", "mean_velocity")))
    runs = {p: simulate(Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum", precision=p), x0, v0,
                        (0, 30), 0.02, **kw) for p in ("double", "mixed")}
    gd, gm = runs["double"].observables["gamma"], runs["mixed"].observables["gamma"]
    F = gamma_floor(v0, runs["double"].n_steps)
    # both reach the floor (the floor, not digits, below it)
    assert not above_floor(gd[-1], F, factor=1.0) and not above_floor(gm[-1], F, factor=1.0)
    # relative agreement of Gamma at every step of the decay (float32 pair sums, float64
    # state): to float32 accuracy far above the floor, with the round-off of the velocities on
    # top nearer to it (measured: <= 1.5e-5 above 1e4 F, <= 6.4e-5 above 100 F; 2.8e-4 just
    # above F, where a relative comparison compares rounding noise)
    rel = np.abs(gm - gd) / gd
    far, well = above_floor(gd, F, factor=1e4), above_floor(gd, F)
    assert far.sum() >= 100 and well.sum() > far.sum()
    assert np.max(rel[far]) < 5e-5 and np.max(rel[well]) < 5e-4
    # the mean velocity is conserved to float32 round-off of the pair sums
    mv = runs["mixed"].observables["mean_velocity"]
    assert np.max(np.abs(mv - mean_velocity(v0))) < 1e-7


def test_mixed_projects_and_validates():
    sc = Scene([Alignment(CuckerSmale())], precision="mixed")
    assert sc.project(np.eye(2, 3)).precision == "mixed"
    from kinred.kinetic._solution import weighted_scene
    assert weighted_scene(sc, np.full(4, 0.25)).precision == "mixed"
    assert "precision='mixed'" in repr(sc)
    with pytest.raises(InvalidInput, match="precision"):
        Scene([Alignment(CuckerSmale())], precision="half")


def test_mixed_results_do_not_depend_on_threads():
    x, v = _data(500, 30, seed=6)
    sc = Scene([Alignment(CuckerSmale(0.8, 1.62))], "sum", precision="mixed")
    with num_threads(1):
        one = sc.rhs(x, v)[1]
    with num_threads(2):
        two = sc.rhs(x, v)[1]
    # different strip sets per thread: sums differ by float32 re-association only
    assert _rel(one, two) < 1e-5


def test_float32_kernels_and_sgemm_against_float64():
    rng = np.random.default_rng(7)
    q = (rng.exponential(2.0, (17, 45)) ** 2).astype(np.float32)
    for n2 in (1, 3, 4):
        ref = _kernels.cs_numpy(q.astype(np.float64), 0.7, n2 / 2)
        out = np.empty_like(q)
        got = _kernels.cs_halfint(q, 0.7, n2, out)
        assert got.dtype == np.float32 and np.max(np.abs(got - ref) / ref) < 1e-6
    # Gram block in float32: kept entries within the documented bound, close pairs exact
    Y = rng.normal(size=(40, 20))
    Y[7] = Y[3] + 1e-6                           # a close pair: recomputed in float64
    Y32 = Y.astype(np.float32)
    nn = np.einsum("ij,ij->i", Y32.astype(float), Y32.astype(float)).astype(np.float32)
    out = np.empty((40, 40), np.float32)
    _kernels.sqdist_block(Y32, Y32, nn, nn, out, Y, Y, diag=0)
    ref = _kernels.sqdist_numpy(Y, Y)
    off = ~np.eye(40, dtype=bool)
    assert np.max(np.abs(out[off] - ref[off]) / ref[off]) < 1e-4
    assert np.all(np.diag(out) == 0.0)
    assert out[3, 7] == pytest.approx(20e-12, rel=1e-4)
    # sgemm through the direct BLAS, in place on sub-blocks
    P = rng.normal(size=(13, 40)).astype(np.float32)
    Z = rng.normal(size=(40, 4)).astype(np.float32)
    A = np.zeros((40, 4), np.float32)
    _parallel.gemm(1.0, P[:, 5:], Z[:13], 1.0, A[5:], trans_a=True)
    expect = np.einsum("ji,jl->il", P[:, 5:].astype(float), Z[:13].astype(float))
    assert np.max(np.abs(A[5:] - expect)) < 1e-5 and np.all(A[:5] == 0.0)
