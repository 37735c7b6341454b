"""numba kernels vs numpy twins, kernel closed forms."""

import math

import numpy as np
import pytest

from kinred.dynamics import CuckerSmale, Morse, Quadratic
from kinred.pairsum import _kernels


@pytest.mark.parametrize("k", [1, 2, 10, 57, 200])
def test_sqdist_numba_equals_numpy_twin(k):
    rng = np.random.default_rng(k)
    Y = rng.normal(size=(120, k))
    Y[5] = Y[7]                      # coincident pair
    Y[9] = Y[11] + 1e-9              # very close pair (fallback path)
    Y[20:30] += 1e3                  # a far cluster
    Y -= Y.mean(axis=0)
    n = np.einsum("ij,ij->i", Y, Y)
    out = np.empty((40, 120 - 3))
    _kernels.sqdist_block(Y[3:43], Y[3:], n[3:43], n[3:], out)
    ref = _kernels.sqdist_numpy(Y[3:43], Y[3:])
    mask = ref > 0
    assert np.all(out[~mask] == 0.0)
    assert np.max(np.abs(out[mask] - ref[mask]) / ref[mask]) < 1e-12


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.5, 3.0, 10.0])
def test_cs_halfint_equals_twin(beta):
    rng = np.random.default_rng(1)
    q = rng.exponential(5.0, (17, 33)) ** 2
    q[0, 0] = 0.0
    q[1, 1] = 1e12
    out = np.empty_like(q)
    _kernels.cs_halfint(q, 0.7, int(2 * beta), out)
    ref = _kernels.cs_numpy(q, 0.7, beta)
    assert np.max(np.abs(out - ref) / ref) < 1e-12


@pytest.mark.parametrize("in_place", [False, True])
@pytest.mark.parametrize("beta", [0.0, 0.3, 0.5, 1.0, 1.5, 1.62, 1.7, 2.0, 2.5, 10.0])
def test_cucker_smale_value_sq_matches_formula(beta, in_place):
    g = CuckerSmale(G=0.8, beta=beta)
    s = np.concatenate([[0.0], np.geomspace(1e-8, 1e150, 200)])
    q = (s * s).reshape(1, -1)
    got = g.value_sq(q, q if in_place else np.empty_like(q))[0]
    with np.errstate(over="ignore"):
        ref = 0.8 / (1.0 + s * s) ** beta       # direct formula (inf**beta -> 0)
    assert np.all(np.isfinite(got))
    big = ref > 1e-280
    assert np.max(np.abs(got[big] - ref[big]) / ref[big]) < 1e-12
    assert np.all(got[~big] < 1e-270)


@pytest.mark.parametrize("beta", [0.25, 1.5, 1.62, 10.0])
def test_cucker_smale_sup_and_lipschitz_against_numerical_maxima(beta):
    g = CuckerSmale(G=1.3, beta=beta)
    s = np.linspace(0, 5, 2_000_001)
    assert g.sup_norm() == pytest.approx(float(np.max(g(s))), rel=1e-15)
    dg = 1.3 * 2 * beta * s / (1 + s * s) ** (beta + 1)
    assert g.lipschitz() == pytest.approx(float(np.max(dg)), rel=1e-9)


def test_morse_coincident_and_bounded_force():
    m = Morse(Ca=1.0, la=2.0, Cr=1.5, lr=0.5)
    s = np.concatenate([[0.0], np.geomspace(1e-300, 1e3, 500)])
    u = m(s)
    assert u[0] == 0.0 and np.all(np.isfinite(u))
    assert np.max(np.abs(u * s)) <= m.force_sup() * (1 + 1e-12)
    assert m.sup_norm() == math.inf and m.lipschitz() == math.inf


def test_morse_soft_sup_lipschitz_against_grid():
    m = Morse(Ca=1.0, la=2.0, Cr=1.5, lr=0.5, soft=0.3)
    s = np.linspace(0, 30, 3_000_001)
    assert m.sup_norm() == pytest.approx(float(np.max(np.abs(m(s)))), rel=1e-8)
    num = np.abs(np.gradient(m(s), s))
    assert m.lipschitz() == pytest.approx(float(np.max(num)), rel=1e-5)
    # u(s) = U'(r)/r with r = sqrt(s^2 + eps^2), checked against the closed form
    r = np.sqrt(s[:50] ** 2 + 0.09)
    ref = (1.0 / 2.0 * np.exp(-r / 2.0) - 1.5 / 0.5 * np.exp(-r / 0.5)) / r
    assert np.allclose(m(s[:50]), ref, rtol=1e-13, atol=0)


def test_quadratic():
    assert Quadratic(2.5).sup_norm() == 2.5 and Quadratic(2.5).lipschitz() == 0.0


def test_invalid_kernel_parameters():
    from kinred.errors import InvalidInput
    with pytest.raises(InvalidInput, match="beta"):
        CuckerSmale(G=1.0, beta=-1.0)
    with pytest.raises(InvalidInput, match="la"):
        Morse(la=0.0)


@pytest.mark.parametrize("k", [1, 2, 3, 6])
def test_sqdist_diff_equals_numpy_twin(k):
    rng = np.random.default_rng(10 + k)
    Y = rng.normal(size=(90, k))
    Y[5] = Y[7]                      # coincident pair: exactly 0
    Y[9] = Y[11] + 1e-9              # very close pair
    Y[20:30] += 1e6                  # a far cluster: differences stay exact
    YT = np.ascontiguousarray(Y.T)
    out = np.empty((17, 90 - 4))
    _kernels.sqdist_rows(YT, 4, 21, 4, out)
    ref = _kernels.sqdist_numpy(Y[4:21], Y[4:])
    mask = ref > 0
    assert np.all(out[~mask] == 0.0) and (~mask).sum() >= 17      # self pairs + coincident
    assert np.max(np.abs(out[mask] - ref[mask]) / ref[mask]) < 1e-12


def test_sqdist_gram_diag_and_offsets():
    # strip layout of the engine: rows i0:i1 against columns i0:, self pairs at (a, a)
    rng = np.random.default_rng(3)
    Y = rng.normal(size=(70, 12))
    Y[40] = Y[41]
    Y -= Y.mean(axis=0)
    n = np.einsum("ij,ij->i", Y, Y)
    out = np.full((25, 70 - 30), np.nan)
    _kernels.sqdist_block(Y[30:55], Y[30:], n[30:55], n[30:], out, diag=0)
    ref = _kernels.sqdist_numpy(Y[30:55], Y[30:])
    assert np.all(np.diag(out[:, :25]) == 0.0) and out[10, 11] == 0.0 and out[11, 10] == 0.0
    mask = ref > 0
    assert np.max(np.abs(out[mask] - ref[mask]) / ref[mask]) < 1e-12


@pytest.mark.parametrize("n2", [0, 1, 2, 3, 7])
def test_cs_halfint_in_place(n2):
    rng = np.random.default_rng(n2)
    q = rng.exponential(3.0, (9, 31)) ** 2
    ref = _kernels.cs_numpy(q, 1.3, n2 / 2)
    got = _kernels.cs_halfint(q, 1.3, n2, q)          # out aliases the input
    assert got is q and np.max(np.abs(q - ref) / ref) < 1e-12


@pytest.mark.parametrize("native", [True, False])
def test_inplace_gemm_on_sub_blocks(native, monkeypatch):
    from kinred import _parallel
    if not native:
        monkeypatch.setattr(_parallel, "HAVE_GEMM", False)
    rng = np.random.default_rng(0)
    P = rng.normal(size=(13, 40))                       # a strip; columns 5: are a sub-block
    Z = rng.normal(size=(40, 4))
    A = rng.normal(size=(40, 4))
    A0 = A.copy()
    _parallel.gemm(1.0, P, Z, 1.0, A[:13])              # A_I += P Z
    _parallel.gemm(1.0, P[:, 5:], Z[:13], 1.0, A[5:], trans_a=True)   # A_J += P_Jᵀ Z_I
    expect = A0.copy()
    expect[:13] += np.einsum("ij,jl->il", P, Z)
    expect[5:] += np.einsum("ji,jl->il", P[:, 5:], Z[:13])
    with pytest.raises(ValueError, match="shapes"):
        _parallel.gemm(1.0, P[:, 5:], Z[:13], 1.0, A[18:], trans_a=True)
    assert np.max(np.abs(A - expect)) < 1e-13
    C = np.full((13, 35), np.nan)
    _parallel.gemm(-2.0, P[:, :7], Z[:35, :].repeat(2, axis=1)[:, :7], 0.0, C, trans_b=True)
    assert np.max(np.abs(C + 2.0 * np.einsum("il,jl->ij", P[:, :7],
                                              Z[:35].repeat(2, axis=1)[:, :7]))) < 1e-13


from hypothesis import given, settings
from hypothesis import strategies as st


@settings(max_examples=60, deadline=None)
@given(Ca=st.floats(0.0, 5.0), la=st.floats(0.05, 10.0), Cr=st.floats(0.0, 5.0),
       lr=st.floats(0.05, 10.0), soft=st.sampled_from([0.0, 1e-3, 0.1, 2.0]),
       rows=st.integers(1, 40), cols=st.integers(1, 70), alias=st.booleans(),
       scale=st.sampled_from([1e-6, 1.0, 30.0, 1e3, 1e5]), seed=st.integers(0, 2**16))
def test_morse_in_place_value_sq_is_the_formula_bit_for_bit(Ca, la, Cr, lr, soft, rows, cols,
                                                            alias, scale, seed):
    """The dense backend's in-place Morse evaluation (scratch arrays, no temporaries) is the
    expression ``U′(r)/r`` of ``dU`` bit for bit: any parameters, coincident agents (q = 0,
    u(0) = 0 when soft = 0), ``out`` aliasing ``q``; far pairs whose exponentials would
    underflow (floored at e^-600) within 2.7e-261 of the kernel's scale."""
    m = Morse(Ca, la, Cr, lr, soft=soft)
    rng = np.random.default_rng(seed)
    q = (rng.uniform(0.0, scale, (rows, cols))) ** 2
    q.flat[::7] = 0.0
    ref = m._value_sq(q.copy(), np.empty_like(q))
    out = q.copy() if alias else np.empty_like(q)
    got = m.value_sq(out if alias else q, out)
    assert got is out
    r = np.sqrt(q + soft * soft)
    floored = np.maximum(r / la, r / lr) > 600.0         # an exponent at EXP_FLOOR
    assert np.array_equal(got[~floored], ref[~floored], equal_nan=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        slack = 2.7e-261 * (Ca / la + Cr / lr) / r
    assert np.all(np.abs(got[floored] - ref[floored]) <= slack[floored])
    if soft == 0.0:
        assert np.all(got[q == 0.0] == 0.0)


def test_morse_value_sq_allocates_nothing_per_block():
    """A dense strip's kernel values cost no allocation of the block's size per call (each
    was a fresh mmap whose pages faulted in: 1.8 s against 0.8 s per right-hand side of the
    2-D ring at N = 2·10⁴); the scratch is kept per thread, so threads do not share it."""
    import threading
    import tracemalloc

    m = Morse(0.5, 2.0, 1.0, 0.5, soft=0.1)
    q = np.random.default_rng(0).uniform(0.0, 100.0, (200, 1000))
    out = np.empty_like(q)
    m.value_sq(q, out)                          # the thread's scratch is made here
    narrower = [(np.ascontiguousarray(q[:, :c]), np.empty((200, c)))
                for c in (999, 990, 500, 1)]     # the dense strips' blocks narrow
    tracemalloc.start()
    try:
        m.value_sq(q, out)
        for qc, oc in narrower:
            m.value_sq(qc, oc)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 0.05 * q.nbytes, peak
    # two threads at once, different shapes: each gets its own scratch, the values are exact
    shapes = [(200, 1000), (37, 53)]
    got = {}

    def work(shape):
        z = np.random.default_rng(shape[0]).uniform(0.0, 30.0, shape)
        for _ in range(20):
            v = m.value_sq(z, np.empty_like(z))
        got[shape] = np.array_equal(v, m._value_sq(z, np.empty_like(z)))

    threads = [threading.Thread(target=work, args=(s,)) for s in shapes]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got == {s: True for s in shapes}


def test_morse_far_pairs_take_no_slow_exponential():
    """A cloud spread over 1000 Morse lengths: numpy's exp of arguments below -708 (subnormal
    or zero results) is 6–35× slower; the floored exponents keep a block of far pairs within
    2× the cost of a block of near ones (it was 4×), whatever the machine's speed."""
    import time

    m = Morse(0.5, 1.0, 1.0, 0.5, soft=0.1)
    rng = np.random.default_rng(0)
    near = rng.uniform(0.0, 10.0, (200, 1000)) ** 2
    far = rng.uniform(0.0, 1400.0, (200, 1000)) ** 2
    out = np.empty_like(near)

    def best(q):
        m.value_sq(q, out)
        ts = []
        for _ in range(15):
            t = time.perf_counter()
            m.value_sq(q, out)
            ts.append(time.perf_counter() - t)
        return min(ts)
    ratio = min(best(far) / best(near) for _ in range(3))
    assert ratio < 2.0, ratio
