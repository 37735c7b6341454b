"""Tabulated kernels of the compiled pair pass (kinred.pairsum._table): within their measured
budget of the kernel on random distances (bounded kernels, a 1/s cusp, sums of kernels, plain
callables, the near parts of NUFFT splits), the compiled lookup equal to its numpy twin, the
cell sums through a table within the budget of the exact ones, and no table where none can
reach the budget."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from kinred.dynamics import CuckerSmale, Morse
from kinred.pairsum import _nearfield, _table
from kinred.pairsum.cells import kernel_values, near_sums

SOFT = Morse(0.5, 2.0, 1.0, 0.5, soft=0.1)
CUSP = Morse(0.5, 2.0, 1.0, 0.5, soft=0.0)
CS = CuckerSmale(0.8, 0.7)


def _phi(kernel):
    vals = kernel_values(kernel)

    def phi(s):
        s = np.asarray(s, dtype=float)
        return vals(s.ravel() ** 2).reshape(s.shape)
    return phi


CASES = {
    "morse soft": (_phi(SOFT), 3.0, False),
    "morse cusp": (_phi(CUSP), 3.0, True),
    "cucker-smale": (_phi(CS), 10.0, False),
    "sum": (lambda s: _phi(SOFT)(s) + _phi(CS)(s), 4.0, False),
    "callable": (lambda s: np.exp(-np.asarray(s) ** 2) * np.cos(3 * np.asarray(s)), 5.0, False),
}


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("rtol", [1e-6, 1e-10])
def test_table_is_within_its_budget_on_random_distances(name, rtol):
    phi, R, singular = CASES[name]
    kappa = 1e-3
    tab = _table.tabulate(phi, R, rtol, kappa)
    assert tab is not None and tab.singular is singular and tab.error <= 1.0
    s = np.r_[np.random.default_rng(1).uniform(0.0, R, 200_000), np.geomspace(1e-9, R, 500)]
    s = s[s < R]
    exact = phi(s)
    err = np.abs(_table.evaluate(tab, s) - exact) / (rtol * kappa + rtol * np.abs(exact))
    assert err.max() <= 1.0
    # the budget is used, not wasted: a table of half the intervals fails it
    if tab.m > _table.M_MIN:
        half = _table.Table(_table._coefficients(
            (lambda t: t * phi(t)) if singular else phi, R, tab.m // 2), tab.m / 2 / R,
            singular, tab.at_zero, 0.0, tab.m // 2)
        err_half = np.abs(_table.evaluate(half, s) - exact) / (rtol * kappa + rtol * np.abs(exact))
        assert err_half.max() > 1.0
    # s = 0 takes the kernel's own value (Morse's cusp: 0 by convention)
    assert _table.evaluate(tab, np.zeros(1))[0] == phi(np.zeros(1))[0]


def test_near_part_of_a_split_is_tabulated_within_budget():
    for kernel in (SOFT, CUSP, CS):
        phi_f = _nearfield.far_profile(_phi(kernel), 0.9, 1e-9)
        near = _nearfield.near_kernel((kernel,), phi_f, 1e-8, 1e-2)
        assert near.table is not None
        s = np.random.default_rng(2).uniform(0.0, 0.9, 100_000)
        exact = near(s * s)
        err = np.abs(_table.evaluate(near.table, s) - exact)
        assert np.all(err <= 1e-8 * (1e-2 + np.abs(exact)))


def test_no_table_where_none_reaches_the_budget():
    assert _table.tabulate(lambda s: 1.0 / np.asarray(s) ** 2, 1.0, 1e-6, 1.0) is None
    assert _table.tabulate(_phi(SOFT), 0.0, 1e-6, 1.0) is None
    assert _table.tabulate(_phi(SOFT), 1.0, 1e-6, 0.0) is None
    assert _table.tabulate(lambda s: np.full_like(np.asarray(s, float), np.nan), 1.0, 1e-6,
                           1.0) is None


class _Tabulated:
    """A kernel-values function that the compiled pass runs through its table."""

    def __init__(self, phi, table):
        self.phi, self.table, self.fused, self.split = phi, table, None, None

    def __call__(self, q):
        return self.phi(np.sqrt(q))


@given(n=st.integers(2, 200), k=st.integers(1, 3), ext=st.floats(1e-2, 10.0),
       offset=st.floats(-1e4, 1e4), seed=st.integers(0, 2**31 - 1),
       R=st.floats(0.05, 3.0), which=st.sampled_from(sorted(CASES)), clump=st.booleans())
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_cell_sums_through_a_table_are_within_its_budget(n, k, ext, offset, seed, R, which,
                                                         clump):
    """The compiled pass with a table (KIND_TABLE) against the numpy pass on the exact
    kernel: every row within ``max pair error × Σⱼ |Zⱼ|``, the same pairs, coincident
    points included (s = 0 takes φ(0))."""
    phi, _, _ = CASES[which]
    rng = np.random.default_rng(seed)
    s = rng.uniform(0, ext, (n, k)) + offset
    if clump:
        s[: n // 2] = s[0]
    rtol, kappa = 1e-9, 1e-2
    table = _table.tabulate(phi, R * (1 + 1e-12), rtol, kappa)
    assert table is not None
    Z = rng.normal(size=(n, k + 1))
    A_tab, A_exact = np.zeros((n, k + 1)), np.zeros((n, k + 1))
    p1 = near_sums(s, R, [(_Tabulated(phi, table), Z, A_tab)], True)
    p0 = near_sums(s, R, [(lambda q: phi(np.sqrt(q)), Z, A_exact)], False)
    assert p1 == p0
    d = np.sqrt(np.sum((s[:, None] - s[None]) ** 2, axis=2))
    near = (d < R) & ~np.eye(n, dtype=bool)
    vals = np.where(near, np.abs(phi(d)), 0.0)
    # per pair: the table's budget plus the sums' own round-off
    budget = (rtol * (kappa + vals)) @ np.abs(Z) + 1e-13 * (vals @ np.abs(Z))
    assert np.all(np.abs(A_tab - A_exact) <= budget + 1e-300)


def test_compiled_lookup_equals_its_numpy_twin():
    from kinred.pairsum import _cell_kernels
    for name in sorted(CASES):
        phi, R, _ = CASES[name]
        tab = _table.tabulate(phi, R, 1e-8, 1e-2)
        s = np.r_[0.0, np.random.default_rng(3).uniform(0, R, 5000)]
        q = s * s
        bf = np.empty_like(q)
        _cell_kernels._values(_cell_kernels.KIND_TABLE, tab.params, np.zeros(5), tab.C, q, bf,
                              q.size)
        twin = _table.evaluate(tab, np.sqrt(q))
        np.testing.assert_allclose(bf, twin, rtol=1e-13, atol=1e-13 * np.abs(twin).max())


def test_distances_at_the_tables_end_stay_on_its_last_cubic():
    """A pair just inside the cutoff can have ``s·m/R`` round to ``m``: it stays on the last
    interval's cubic (a repeated last row would evaluate the cubic one interval too early:
    1.4e-3 off for ``exp(−s/2)`` on ``[0, 1.7]``, 10⁵ times the budget)."""
    phi = lambda s: np.exp(-np.asarray(s, dtype=float) / 2)      # noqa: E731
    for R in np.random.default_rng(4).uniform(0.5, 3.0, 200):
        tab = _table.tabulate(phi, R, 1e-8, 1.0)
        s = np.array([np.nextafter(R, 0.0), R])
        err = np.abs(_table.evaluate(tab, s) - phi(s))
        assert np.all(err <= 1e-8 * (1.0 + phi(s))), R
