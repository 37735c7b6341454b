"""Sparse high-dimensional vectors recovered from L stacked low-dimensional projections.

Each of L projections M^ℓ: R^d -> R^k sees every vector x; stacking them gives one
(L·k, d) matrix A and the vector is recovered by basis pursuit,
min ‖z‖₁ subject to ‖A z − y‖₂ <= η (eq. (3.16) of the paper, label ``P1:eta``), for all
vectors at once (batched ADMM with a certified polish). §3.3.1: more projections recover
less sparse vectors.

    python examples/recovery_l1.py [--smoke]
"""

import argparse
import time

import numpy as np

from kinred.projection import jl_matrix
from kinred.recovery import basis_pursuit, stack_projections


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
    args = ap.parse_args(argv)
    d, k, n_vec, sparsity = (200, 20, 20, 8) if args.smoke else (500, 25, 40, 10)
    Ls = [1, 3] if args.smoke else [1, 2, 3, 4]

    rng = np.random.default_rng(0)
    X = np.zeros((d, n_vec))                      # columns: sparse vectors in R^d
    for j in range(n_vec):
        X[rng.choice(d, sparsity, replace=False), j] = rng.standard_normal(sparsity)
    print(f"{n_vec} vectors in R^{d} with {sparsity} non-zeros, projections to R^{k}")
    print(f"{'L':>3} {'rows':>5} {'max rel. error':>15} {'recovered':>10} {'seconds':>8}")
    for L in Ls:
        A = stack_projections([jl_matrix(k, d, seed=100 + l) for l in range(L)])
        t0 = time.perf_counter()
        res = basis_pursuit(A, A @ X)
        dt = time.perf_counter() - t0
        rel = np.linalg.norm(res.Z - X, axis=0) / np.linalg.norm(X, axis=0)
        ok = int(np.sum(rel < 1e-6))
        print(f"{L:3d} {A.shape[0]:5d} {rel.max():15.2e} {ok:>5d}/{n_vec:<4d} {dt:8.3f}")
    print("done")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
