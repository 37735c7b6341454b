"""Cost of applying a JL map: dense Gaussian vs sparse Achlioptas vs fast SRHT / DCT, against d.

Run: ``python benchmarks/bench_projection.py [--n N] [--k K]``. Prints the time to project
``N`` vectors of dimension ``d`` to ``k`` dimensions (best of 3), and the time to draw the map.
The dense product costs O(N k d); the structured transforms O(N d log d) independent of k, so
they win once k exceeds a few multiples of log d. No assertions (timings are machine-dependent).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from kinred.projection import jl_matrix


def best_of(f, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="number of vectors (default 1000)")
    ap.add_argument("--k", type=int, default=256, help="target dimension (default 256)")
    ap.add_argument("--dims", type=int, nargs="+", default=[1024, 4096, 16384])
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    kinds = ("gaussian", "achlioptas", "srht", "dct")
    print(f"apply time [ms] for n={args.n} vectors, k={args.k} (best of 3; draw time in brackets)")
    print(f"{'d':>7} " + " ".join(f"{k:>20}" for k in kinds))
    for d in args.dims:
        X = rng.standard_normal((args.n, d))
        cells = []
        for kind in kinds:
            t0 = time.perf_counter()
            M = jl_matrix(args.k, d, kind, seed=1)
            draw = time.perf_counter() - t0
            t = best_of(lambda: M.apply(X))
            cells.append(f"{1e3 * t:9.1f} [{1e3 * draw:7.1f}]")
        print(f"{d:>7} " + " ".join(f"{c:>20}" for c in cells))


if __name__ == "__main__":
    main()
