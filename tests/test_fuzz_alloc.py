"""One memory preflight for every large allocation with user-given sizes (issue 14).

:func:`kinred._validate.check_alloc` reads one limit (``max_bytes=`` where a call has it, else
``KINRED_MAX_BYTES``, else 2 GiB) and raises ``TooLarge`` naming what would be allocated, the
bytes, the limit and how to change it, before anything is allocated. Each test checks the
refusal (peak of traced memory far below the request) and, where the size model is exact, its
tightness: the call passes with the limit at the priced bytes and fails one byte below.
"""

import tracemalloc

import numpy as np
import pytest

from kinred import Alignment, CuckerSmale, Scene, TensorProduct, Uniform, jl_matrix, simulate
from kinred._validate import DEFAULT_MAX_BYTES, check_alloc, max_bytes_limit
from kinred.ensemble import run_ensemble
from kinred.errors import InvalidInput, TooLarge
from kinred.integrate import SaveAt
from kinred.integrate._save import GRID_POINT_BYTES, OBS_VALUE_BYTES
from kinred.kinetic import lift, solve
from kinred.quantize import _size, quantize
from kinred.recovery import basis_pursuit


@pytest.fixture(autouse=True)
def _no_env_limit(monkeypatch):
    monkeypatch.delenv("KINRED_MAX_BYTES", raising=False)


def refused(fn, *args, **kwargs) -> str:
    """The TooLarge message of ``fn(...)``, checking that less than 16 MiB was allocated."""
    tracemalloc.start()
    try:
        with pytest.raises(TooLarge) as info:
            fn(*args, **kwargs)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, f"{peak} bytes allocated before the refusal"
    msg = str(info.value)
    assert "KINRED_MAX_BYTES" in msg and "\n" not in msg
    return msg


def test_check_alloc_reads_one_limit_and_names_what_bytes_limit_and_how(monkeypatch):
    assert max_bytes_limit() == DEFAULT_MAX_BYTES == 2 * 2**30
    assert check_alloc(DEFAULT_MAX_BYTES, "x") == DEFAULT_MAX_BYTES       # at the limit: fine
    with pytest.raises(TooLarge) as info:
        check_alloc(DEFAULT_MAX_BYTES + 1, "the (k, d) matrix", "a smaller k")
    assert str(info.value) == (
        "the (k, d) matrix would allocate 2 GiB, more than the limit of 2 GiB (environment "
        "variable KINRED_MAX_BYTES, e.g. KINRED_MAX_BYTES=8G; default 2 GiB); a smaller k")
    monkeypatch.setenv("KINRED_MAX_BYTES", "1M")
    assert max_bytes_limit() == 2**20 and max_bytes_limit("3K") == 3072   # the keyword wins
    calls = []
    check_alloc(2**20, "x", lambda: calls.append(1) or "hint")            # hint not evaluated
    assert calls == []
    with pytest.raises(TooLarge, match=r"^x would allocate at least 1 MiB \(y\), more than the "
                                       r"limit max_bytes = 1 MiB \(keyword max_bytes=.*; hint$"):
        check_alloc(2**20 + 1, "x", lambda: "hint", keyword="max_bytes", detail=" (y)",
                    at_least=True)
    monkeypatch.setenv("KINRED_MAX_BYTES", "lots")
    with pytest.raises(InvalidInput, match="environment variable KINRED_MAX_BYTES must be a byte"):
        check_alloc(1, "x")


def test_quantize_and_simulate_share_the_limit(monkeypatch):
    assert _size.max_bytes_limit is max_bytes_limit                      # one implementation
    q = quantize(TensorProduct([Uniform(0, 1)] * 3), atoms=10**4)
    sc = Scene([Alignment(CuckerSmale())])
    x = np.zeros((10, 2))
    assert q.materialize().n_atoms == q.n_atoms > 9000                  # 0.5 MB
    simulate(sc, x, x, (0.0, 1.0), 1e-3)                                 # 0.4 MB of records
    monkeypatch.setenv("KINRED_MAX_BYTES", "256K")
    assert "materialize() would allocate" in refused(q.materialize)
    assert "simulate(" in refused(simulate, sc, x, x, (0.0, 1.0), 1e-3)


def _record_bytes(n_save, n, d, n_obs, n_states):
    return n_save * (GRID_POINT_BYTES + n_obs * (OBS_VALUE_BYTES + 16 * d) + 8 * n * d * n_states)


def test_simulate_prices_its_records_exactly_before_the_run(monkeypatch):
    # strips of 8 rows: the pair sums' workspace (7 KiB) stays below the records' limit
    sc = Scene([Alignment(CuckerSmale())], block=8)
    x = np.random.default_rng(0).uniform(size=(40, 3))
    save = SaveAt(every=2, states=True)                                  # 10 steps: 5 + 2 points
    need = _record_bytes(7, 40, 3, 2, 2)
    monkeypatch.setenv("KINRED_MAX_BYTES", str(need))
    tr = simulate(sc, x, x, (0.0, 1.0), 0.1, save=save)
    assert tr.x.shape == (6, 40, 3)                                      # priced: an upper bound
    monkeypatch.setenv("KINRED_MAX_BYTES", str(need - 1))
    msg = refused(simulate, sc, x, x, (0.0, 1.0), 0.1, save=save)
    assert msg.startswith("simulate(x0 of shape (40, 3), t_span=(0, 1), dt=0.1, "
                          "save=SaveAt(every=2, states=True)): recording 7 save points")
    assert "states (T, N, d) = (7, 40, 3) x 2" in msg and "SaveAt(every=...)" in msg


def test_simulate_refuses_a_huge_step_count_before_building_the_grid():
    sc = Scene([Alignment(CuckerSmale())])
    x = np.zeros((3, 2))
    msg = refused(simulate, sc, x, x, (0.0, 1e12), 0.01)                # 1e14 saved steps
    assert ("recording 1.000e+14 save points would allocate 34.1 PiB (2 observables, the final "
            "state (N, d) = (3, 2) x 2)") in msg
    with pytest.raises(InvalidInput, match=r"dt must be at least \(t1 - t0\)/2\*\*53"):
        simulate(sc, x, x, (0.0, 1.0), 1e-320)                           # was OverflowError
    with pytest.raises(InvalidInput, match="t_span must have a finite length"):
        simulate(sc, x, x, (-1e308, 1e308), 1.0)


def test_solve_prices_the_trajectory_before_building_the_atoms():
    mu = TensorProduct([Uniform(0, 1), Uniform(0, 1), Uniform(-1, 1), Uniform(-1, 1)])
    msg = refused(solve, Scene([Alignment(CuckerSmale())]), mu, atoms=10**5, t_span=(0, 100),
                  dt=1e-3)
    n = quantize(mu, atoms=10**5).n_atoms
    assert msg.startswith(f"solve(mu0 quantized to {n} atoms in R^(2·2), t_span=(0, 100)")
    assert f"states (T, N, d) = (100002, {n}, 2) x 2" in msg and "save_every=" in msg


@pytest.mark.parametrize("kind,per_entry", [("gaussian", 8), ("rademacher", 17),
                                            ("achlioptas", 16)])
def test_jl_matrix_prices_dense_kinds_exactly(monkeypatch, kind, per_entry):
    k, d = 30, 200
    monkeypatch.setenv("KINRED_MAX_BYTES", str(per_entry * k * d))
    assert jl_matrix(k, d, kind, seed=0).shape == (k, d)
    monkeypatch.setenv("KINRED_MAX_BYTES", str(per_entry * k * d - 1))
    msg = refused(jl_matrix, k, d, kind, seed=0)
    assert msg.startswith(f"jl_matrix(k={k}, d={d}, kind={kind!r}) would allocate")


def test_jl_matrix_refuses_huge_matrices_and_suggests_structured_kinds():
    msg = refused(jl_matrix, 2**20, 2**20)                               # was MemoryError
    assert "8 TiB for a dense (1048576, 1048576) matrix" in msg and "'srht'" in msg
    assert jl_matrix(2**10, 2**20, "srht", seed=0).shape == (2**10, 2**20)   # O(d) memory
    assert "signs (1099511627776,)" in refused(jl_matrix, 4, 2**40, "srht")
    with pytest.raises(TooLarge, match="k=9223372036854775808"):          # was ValueError
        jl_matrix(2**63, 5)


def test_basis_pursuit_prices_its_gram_matrix_and_iterates():
    A = np.ones((2, 40_000))                                             # AᵀA: 12.8 GB
    msg = refused(basis_pursuit, A, np.ones(2))
    assert msg.startswith("basis_pursuit: A of shape (2, 40000) with 1 right-hand sides would "
                          "allocate 11.9 GiB") and "fewer columns of Y" in msg


def _big_member(params, seed):
    return {"x": np.full(2**20, float(params["i"])), "label": "member"}  # 8 MiB each


def test_run_ensemble_prices_the_kept_results_from_the_first_member(monkeypatch, tmp_path):
    monkeypatch.setenv("KINRED_MAX_BYTES", "64M")
    members = [{"i": i} for i in range(20)]                               # 160 MiB in all
    with pytest.raises(TooLarge) as info:
        run_ensemble(_big_member, members, master_seed=0, store=tmp_path / "s", progress=False)
    msg = str(info.value)
    assert msg.startswith("run_ensemble: keeping the results of 20 members would allocate 160 MiB")
    assert "measured on 1" in msg and "resume=True" in msg
    assert len(list((tmp_path / "s" / "members").glob("*.npz"))) == 1   # the first one is kept
    res = run_ensemble(_big_member, members[:7], master_seed=0, progress=False)   # 56 MiB fits
    assert [float(r["x"][0]) for r in res.results] == list(range(7))


def test_numpy_pair_sums_and_lift_are_priced():
    sc = Scene([Alignment(CuckerSmale())], pairsum="numpy")
    x = np.zeros((10_000, 2))
    msg = refused(sc.rhs, x, x)                                          # 4.8 GB of (N, N)
    assert "the numpy pair sums of 10000 agents would allocate 4.47 GiB" in msg
    assert "pairsum='dense'" in msg
    mu = TensorProduct([Uniform(0, 1)] * 4)
    assert "lift(mu, d=1000000000)" in refused(lift, mu, 10**9, seed=0)  # was MemoryError

