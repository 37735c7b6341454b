"""Pair sums at large N: the dense backend's refusal of sizes out of reach (before any work),
the cell-list backend against the exact sums, ``pairsum="auto"``'s choice."""

import time

import numpy as np
import pytest

from kinred.dynamics import Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene
from kinred.errors import InvalidInput, TooLarge
from kinred.pairsum import Dense
from kinred.pairsum.dense import estimate_seconds

CS = CuckerSmale(0.8, 1.5)


# ------------------------------------------------------------------ Dense refuses
def test_dense_refuses_ten_million_agents_within_a_second():
    sc = Scene([Alignment(CS)])
    x = np.zeros((10**7, 2))        # calloc'd pages: nothing touched before the refusal
    t0 = time.perf_counter()
    with pytest.raises(TooLarge) as err:
        sc.rhs(x, x)
    assert time.perf_counter() - t0 < 1.0
    msg = str(err.value)
    assert "10000000 agents" in msg and "6.94 h" in msg       # the estimate, named
    assert "pairsum='auto'" in msg and "'nufft'" in msg and "'cells'" in msg


def test_dense_refusal_in_high_dimension_names_projection_and_random_batch():
    with pytest.raises(TooLarge, match="Scene.project.*random_batch"):
        Dense().plan(Scene([Alignment(CS)]), 10**7, 200)


def test_dense_estimate_is_a_lower_bound_and_scales_quadratically():
    terms = Scene([Alignment(CS)]).pair_terms
    morse = Scene([AttractionRepulsion(Morse(soft=0.1))]).pair_terms
    # independent closed form: n(n-1)/2 pairs at 2e9 pairs/s (compiled) or 5e8 (numpy kernel)
    assert estimate_seconds(10**7, 2, terms) == pytest.approx(10**7 * (10**7 - 1) / 2 / 2e9)
    assert estimate_seconds(10**5, 2, morse) == pytest.approx(10**5 * (10**5 - 1) / 2 / 5e8)
    # measured here: a dense rhs takes longer than the estimate (a lower bound)
    rng = np.random.default_rng(0)
    x, v = rng.uniform(0, 1, (4000, 2)), rng.normal(size=(4000, 2))
    sc = Scene([Alignment(CS)])
    sc.rhs(x, v)
    t0 = time.perf_counter()
    sc.rhs(x, v)
    assert time.perf_counter() - t0 > estimate_seconds(4000, 2, terms)


def test_dense_max_seconds_option():
    sc = Scene([Alignment(CS)], pairsum=Dense(max_seconds=1e-6))
    with pytest.raises(TooLarge, match="max_seconds=1e-06"):
        sc.rhs(np.zeros((1000, 2)), np.zeros((1000, 2)))
    assert repr(Dense(max_seconds=10.0)) == "Dense(max_seconds=10.0)"
    assert repr(Dense()) == "Dense()"
    for bad in (0.0, -1.0, float("inf"), "1"):
        with pytest.raises(InvalidInput, match="max_seconds"):
            Dense(max_seconds=bad)


def test_dense_refuses_a_workspace_beyond_the_memory_limit(monkeypatch):
    monkeypatch.setenv("KINRED_MAX_BYTES", "1M")
    with pytest.raises(TooLarge, match="Dense: the workspace"):
        Dense().plan(Scene([Alignment(CS)]), 20000, 2)
    monkeypatch.setenv("KINRED_MAX_BYTES", "1G")
    assert Dense().plan(Scene([Alignment(CS)]), 20000, 2).n == 20000
