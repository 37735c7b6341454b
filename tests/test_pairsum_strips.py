"""The public strip walker (``kinred.pairsum.strips``): walked from outside the package, it
gives the dense engine's pair sums bit for bit; its functions refuse bad arguments by name."""

import numpy as np
import pytest

from kinred.dynamics import Alignment, CuckerSmale, Scene, get_num_threads, set_num_threads
from kinred.errors import InvalidInput
from kinred.pairsum import Dense, Numpy, strips


def _walk(scene, x, v):
    """The alignment pair sums of ``scene`` at ``(x, v)``, walked with the public pieces only."""
    n, d = x.shape
    G, n2 = scene.effects[0].kernel.compiled_form()[1:]
    c = scene.coefficients(n)
    vc = strips.centre_rows(v, np.empty_like(v))
    Z = strips.zext_rows(vc, c, np.empty((n, d + 1)))
    A = np.zeros((n, d + 1))
    if d <= strips.SMALL_K:
        YT = np.ascontiguousarray(x.T)
    else:
        xc = strips.centre_rows(x, np.empty_like(x))
        nrm = strips.gram_rows(xc, xc, np.empty(n), False)
    groups = strips.deal(strips.row_strips(n, None, d, 1), n, 1)
    assert len(groups) == 1
    for i0, i1 in groups[0]:
        q = np.empty((i1 - i0, n - i0))
        if d <= strips.SMALL_K:
            strips.sqdist_rows(YT, i0, i1, i0, q)
        else:
            strips.sqdist_block(xc[i0:i1], xc[i0:], nrm[i0:i1], nrm[i0:], q, x[i0:i1], x[i0:],
                                diag=0)
        strips.cs_halfint(q, G, int(n2), q)
        strips.pair_products(q, Z, A, i0, i1, n)
    return strips.pair_finish(A, vc, np.empty((n, d)))


@pytest.mark.parametrize("d", [2, 7])
def test_walking_the_strips_gives_the_dense_engine_bit_for_bit(d):
    rng = np.random.default_rng(d)
    n = 700                                            # several strips
    x, v = rng.normal(size=(n, d)) + 20.0, rng.normal(size=(n, d))
    scene = Scene([Alignment(CuckerSmale(1.3, 1.0))])
    old = get_num_threads()
    set_num_threads(1)
    try:
        assert len(strips.row_strips(n, None, d, 1)) > 3
        ours = _walk(scene, x, v)
        dense = Dense(compiled=False)
        engine = dense.evaluate(dense.plan(scene, n, d), x, v)["v"]
    finally:
        set_num_threads(old)
    assert np.array_equal(ours, engine)
    ref = Numpy()
    twin = ref.evaluate(ref.plan(scene, n, d), x, v)["v"]
    assert np.allclose(ours, twin, rtol=1e-12, atol=1e-12 * np.abs(twin).max())


def test_the_strips_cover_the_upper_triangle_once_and_deal_is_balanced():
    n = 1000
    st = strips.row_strips(n, None, 2, 2)
    assert st[0][0] == 0 and st[-1][1] == n
    assert all(a[1] == b[0] for a, b in zip(st, st[1:]))
    groups = strips.deal(st, n, 2)
    assert sorted(s for g in groups for s in g) == st
    loads = [sum((i1 - i0) * (n - i0) for i0, i1 in g) for g in groups]
    biggest = max((i1 - i0) * (n - i0) for i0, i1 in st)
    assert abs(loads[0] - loads[1]) <= biggest
    assert strips.row_strips(10, 4) == [(0, 4), (4, 8), (8, 10)]


def test_sqdist_twin_and_threshold():
    rng = np.random.default_rng(1)
    Y = rng.normal(size=(9, 5))
    d2 = strips.sqdist_numpy(Y, Y[3:])
    assert np.allclose(d2, ((Y[:, None, :] - Y[None, 3:, :]) ** 2).sum(-1), rtol=1e-14)
    assert strips.tau_for(10) == pytest.approx(2.5e-4 * 12)
    assert strips.tau_for(10, np.float32) == pytest.approx(1.2e-3 * 12)
    assert len(strips.compiled_blocks()) == 4


@pytest.mark.parametrize("call, name", [
    (lambda: strips.row_strips(-1), "n"),
    (lambda: strips.row_strips(5, 0), "block"),
    (lambda: strips.row_strips(5, itemsize=2), "itemsize"),
    (lambda: strips.deal([(0, 9)], 5, 1), "strip_list"),
    (lambda: strips.deal("ab", 5, 1), "strip_list"),
    (lambda: strips.sqdist_rows(np.zeros((2, 4)), 0, 5, 0, np.zeros((5, 4))), "i0:i1"),
    (lambda: strips.sqdist_rows(np.zeros((2, 4)), 0, 2, 0, np.zeros((2, 3))), "out"),
    (lambda: strips.sqdist_rows([[0.0]], 0, 1, 0, np.zeros((1, 1))), "YT"),
    (lambda: strips.sqdist_block(np.zeros((2, 4)), np.zeros((3, 5)), np.zeros(2), np.zeros(3),
                                 np.zeros((2, 3))), "Yi and Yj"),
    (lambda: strips.sqdist_block(np.zeros((2, 4)), np.zeros((3, 4)), np.zeros(2), np.zeros(4),
                                 np.zeros((2, 3))), "nj"),
    (lambda: strips.centre_rows(np.zeros((3, 2)), np.zeros((2, 3))), "out"),
    (lambda: strips.centre_rows(np.zeros((3, 2), np.float32), np.zeros((3, 2))), "z"),
    (lambda: strips.gram_rows(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), 1), "cast"),
    (lambda: strips.zext_rows(np.zeros((3, 2)), np.zeros(3), np.zeros((3, 2))), "Z"),
    (lambda: strips.pair_products(np.zeros((2, 4)), np.zeros((4, 3)), np.zeros((4, 3)), 0, 2,
                                  5), "phi"),
    (lambda: strips.pair_products(np.zeros((2, 4)), np.zeros((4, 3)),
                                  np.zeros((4, 3), np.float32), 0, 2, 4), "share one dtype"),
    (lambda: strips.pair_finish(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((3, 2))), "A"),
    (lambda: strips.cs_halfint(np.zeros((2, 2)), 1.0, -1, np.zeros((2, 2))), "n2"),
    (lambda: strips.cs_halfint(np.zeros((2, 2)), "one", 2, np.zeros((2, 2))), "G"),
    (lambda: strips.tau_for(3, np.int64), "dtype"),
])
def test_bad_arguments_are_named(call, name):
    with pytest.raises(InvalidInput, match=name):
        call()


def test_results_go_to_writable_arrays_only():
    out = np.zeros((3, 2))
    out.flags.writeable = False
    with pytest.raises(InvalidInput, match="out must be writable"):
        strips.centre_rows(np.ones((3, 2)), out)
