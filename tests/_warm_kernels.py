"""Compile the suite's numba kernels (``cache=True``) before pytest starts, in two processes.

On a fresh clone nothing is cached: both xdist workers, and the CLI subprocesses of the first
tests, would then compile the same kernels at the same moment. ``make test`` runs the
groups below in two processes first (small runs of the real pipeline, the twin tests of the
kernels the suite calls directly), so that every later
process loads the kernels from the cache. A failure here is reported and ignored: pytest then
compiles on first use, as before.

    python tests/_warm_kernels.py GROUP [GROUP ...]     # demo, fig4, w1, steps, twins

Measured on a fresh clone (2 cores): without the w1, steps and twins groups, the suite's
first uses compiled about 30 s of wall time inside pytest, in both workers at once.
"""

import sys
import tempfile


def main(group: str) -> int:
    from kinred.cli import main as kinred

    with tempfile.TemporaryDirectory(prefix="kinred-warm-") as out:
        if group == "demo":        # simulate, certificate, W1, report
            return kinred(["demo", "--smoke", "--no-progress", "--out", out])
        if group == "fig4":        # projected ensembles, recovery; float32 pair sums
            status = kinred(["paper", "fig4", "--quick", "--no-progress", "--out", out])
            _mixed_precision()
            return status
    if group == "w1":              # the sparse W1 solvers: assignment, auction, cost scaling,
        return _w1()               # repair, c-transform searches
    if group == "steps":           # compiled Euler steps, cell lists, random batches
        return _steps()
    if group == "twins":           # the kernels the suite calls directly, by their twin tests
        return _twins()
    raise SystemExit(f"unknown group {group!r}: demo, fig4, w1, steps or twins")


#: Tests that call compiled kernels directly, with the suite's argument types, beside their
#: numpy twins (small and quick once compiled; whole files where the kernels take many types).
TWINS = ["tests/test_w1_assign.py::test_kernel_potentials_equal_the_numpy_twin",
         "tests/test_w1_auction.py::test_the_auction_equals_its_python_twin",
         "tests/test_w1_costscale.py::test_kernel_equals_its_python_twin",
         "tests/test_w1_repair.py::test_potentials_equal_the_numpy_twin",
         "tests/test_w1_sparse.py::test_tree_ctransform_equals_its_numpy_twin",
         "tests/test_pairsum_large.py::test_cell_kernels_against_numpy_twins",
         # every dtype and layout of the pair kernels, fused Euler loops and random batches
         "tests/test_kernels.py", "tests/test_pairsum_strips.py",
         "tests/test_integrate_fused.py", "tests/test_rbm_fused_step.py"]


def _twins() -> int:
    import pytest

    return int(pytest.main(["-q", "-p", "no:cacheprovider", "-p", "no:xdist", *TWINS]))


def _mixed_precision() -> None:
    """The float32 kernels of ``precision="mixed"`` (differences path d ≤ 3, Gram path)."""
    import numpy as np

    from kinred.dynamics import Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene

    scenes = [[Alignment(CuckerSmale(0.8, 1.5))], [Alignment(CuckerSmale(0.8, 1.62))],
              [AttractionRepulsion(Morse(soft=0.2)), Alignment(CuckerSmale(1.0, 0.5), on="v")]]
    rng = np.random.default_rng(0)
    for d in (2, 60):
        x, v = rng.normal(size=(50, d)), rng.normal(size=(50, d))
        for effects in scenes:
            Scene(effects, "sum", precision="mixed").rhs(x, v)


def _w1() -> int:
    import numpy as np

    from kinred.distance import w1

    rng = np.random.default_rng(0)
    X = rng.normal(size=(20_000, 4))                # paired: assignment, repair
    w1(X, X + 0.01 * rng.normal(size=X.shape), "sparse")
    a, b = rng.uniform(1, 2, 20_000), rng.uniform(1, 2, 16_000)   # weighted: cost scaling
    w1(X, X[:16_000] + 0.01, "sparse", a=a / a.sum(), b=b / b.sum())
    X = rng.normal(size=(3000, 20))                 # high dimension: blocked neighbours
    w1(X, X + 0.01 * rng.normal(size=X.shape), "sparse")
    return 0


def _steps() -> int:
    """simulate's fused Euler loops (forced at any size, as the suite's tests force them), on
    every backend that takes the step itself, first and second order; a cell list."""
    import numpy as np

    from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion, CuckerSmale,
                                 Morse, Scene)
    from kinred.integrate import _save, _simulate, simulate
    from kinred.pairsum import CellList, Dense, RandomBatch

    _simulate.FUSED_MIN = _save.FUSED_MIN = 0
    rng = np.random.default_rng(0)
    second = [Alignment(CuckerSmale(0.8, 1.62)), AttractionRepulsion(Morse(soft=0.2))]
    first = [Aggregation(Morse(0.5, 2.0, 1.0, 0.5, soft=0.1))]
    for effects, order in ((second, 2), (first, 1), ([Alignment(CuckerSmale(1.0, 0.7))], 2)):
        for pairsum in (Dense(), RandomBatch(p=4)):
            for n, d in ((600, 3), (60, 40)):
                x = rng.normal(size=(n, d))
                v = rng.normal(size=(n, d)) if order == 2 else None
                simulate(Scene(effects, pairsum=pairsum), x, v, (0.0, 0.03), 0.01, seed=1)
    x = rng.uniform(0, 20, size=(3000, 2))
    Scene([AttractionRepulsion(Morse(soft=0.2))], pairsum=CellList()).rhs(x, x)
    _layouts(rng)
    return 0


def _layouts(rng) -> None:
    """Signatures the suite's tests reach directly (tests/test_compiled_worker.py) or through
    Fortran-ordered states, which a fresh clone otherwise compiled inside pytest (found by
    the cache files written after the warm-up: five signatures)."""
    import numpy as np

    from kinred.integrate import _kernels as ik
    from kinred.pairsum import _kernels as pk

    z = rng.normal(size=(8, 3))
    f, c = np.asfortranarray(z), np.ascontiguousarray(z)
    ik.euler_pair(f.copy(order="F"), c.copy(), c.copy(), c.copy(), 0.1)
    ik.euler_pair(c.copy(), c.copy(), c.copy(), f.copy(order="F"), 0.1)
    ik.sweep(f, np.ones(8), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(4))
    q = np.abs(rng.normal(size=(2, 5)))
    pk.cs_pow(q.copy(), 0.8, 1.62, np.empty((3, 5)))
    pk.cs_pow(q.astype(np.float32), np.float32(0.8), np.float32(1.62), np.empty((3, 5)))


if __name__ == "__main__":
    sys.exit(max(main(group) for group in sys.argv[1:]))
