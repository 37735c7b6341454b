"""Compile the suite's numba kernels (``cache=True``) before pytest starts, in two processes.

On a fresh clone nothing is cached: both xdist workers, and the CLI subprocesses of the first
tests, would then compile the same kernels at the same moment. ``make test`` runs the two
groups below side by side first (each a small run of the real pipeline), so that every later
process loads the kernels from the cache. A failure here is reported and ignored: pytest then
compiles on first use, as before.

    python tests/_warm_kernels.py demo|fig4
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
    raise SystemExit(f"unknown group {group!r}: demo or fig4")


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


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
