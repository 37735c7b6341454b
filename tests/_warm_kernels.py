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
        if group == "fig4":        # projected ensembles, recovery
            return kinred(["paper", "fig4", "--quick", "--no-progress", "--out", out])
    raise SystemExit(f"unknown group {group!r}: demo or fig4")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
