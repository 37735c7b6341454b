"""Batched basis pursuit (kinred.recovery.basis_pursuit) vs one HiGHS LP per problem.

Problems: d = 200, kL = 120 (6 Gaussian projections into R^20, entries N(0, 1/k)), K = 40
nonzeros (the paper's 80 % zeros, §3.4.2), η = 0. The batched solver runs on all n problems
(several stacked matrices, one batched call each); HiGHS (scipy.optimize.linprog, the
z = p − q LP) runs on a subset of them and its time is extrapolated to n (said in the output).
HiGHS also runs on every problem the batched solver did not recover to 1e-6, so that the
fraction recovered can be compared over all n problems ("same accuracy").

    python benchmarks/bench_recovery.py            # n = 10^4 problems, 100 HiGHS calls
    python benchmarks/bench_recovery.py --quick    # n = 500, 20 HiGHS calls
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from kinred.recovery import basis_pursuit, stack_projections
from kinred.recovery._reference import reference_basis_pursuit


def make_problems(n, n_matrices, d=200, L=6, k=20, K=40, seed=0):
    rng = np.random.default_rng(seed)
    per = int(np.ceil(n / n_matrices))
    out = []
    for b in range(n_matrices):
        nb = min(per, n - b * per)
        if nb <= 0:
            break
        Ms = [rng.standard_normal((k, d)) / np.sqrt(k) for _ in range(L)]
        A = stack_projections(Ms)
        X = np.zeros((d, nb))
        for j in range(nb):
            X[rng.choice(d, K, replace=False), j] = rng.standard_normal(K)
        out.append((A, X, A @ X))
    return out


def rel_err(Z, X):
    return np.linalg.norm(Z - X, axis=0) / np.linalg.norm(X, axis=0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small version (n = 500, 20 HiGHS calls)")
    ap.add_argument("--n", type=int, default=None, help="number of problems (default 10000)")
    ap.add_argument("--highs", type=int, default=None, help="HiGHS calls timed (default 100)")
    ap.add_argument("--matrices", type=int, default=4, help="number of different stacked matrices")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-iter", type=int, default=5000, help="ADMM iteration cap (library default 5000)")
    args = ap.parse_args(argv)
    n = args.n or (500 if args.quick else 10_000)
    n_highs = args.highs or (20 if args.quick else 100)

    problems = make_problems(n, args.matrices, seed=args.seed)
    A0, X0, Y0 = problems[0]
    basis_pursuit(A0, Y0[:, :4])  # compile the numba kernel outside the timing

    t0 = time.perf_counter()
    results = [basis_pursuit(A, Y, max_iter=args.max_iter) for A, X, Y in problems]
    t_batch = time.perf_counter() - t0
    err_batch = np.concatenate([rel_err(r.Z, X) for r, (A, X, Y) in zip(results, problems)])
    status = np.concatenate([r.status for r in results])
    iters = np.concatenate([r.iterations for r in results])

    # HiGHS on the first n_highs problems (spread over the matrices)
    per = max(1, n_highs // len(problems))
    highs_err, batch_err_sub, t_highs, count = [], [], 0.0, 0
    for (A, X, Y), r in zip(problems, results):
        for j in range(min(per, Y.shape[1])):
            t1 = time.perf_counter()
            z = reference_basis_pursuit(A, Y[:, j])
            t_highs += time.perf_counter() - t1
            count += 1
            highs_err.append(np.linalg.norm(z - X[:, j]) / np.linalg.norm(X[:, j]))
            batch_err_sub.append(np.linalg.norm(r.Z[:, j] - z) / np.linalg.norm(z))
    highs_err = np.array(highs_err)
    per_highs = t_highs / count
    # same accuracy: HiGHS on every problem the batched solver did not recover to 1e-6 (the
    # timed subset alone is too small to contain them)
    miss_both = miss_highs_only = 0
    miss_diff = []
    for (A, X, Y), r in zip(problems, results):
        e = rel_err(r.Z, X)
        for j in np.flatnonzero(e > 1e-6):
            z = reference_basis_pursuit(A, Y[:, j])
            if np.linalg.norm(z - X[:, j]) <= 1e-6 * np.linalg.norm(X[:, j]):
                miss_highs_only += 1
            else:
                miss_both += 1
            miss_diff.append(np.linalg.norm(r.Z[:, j] - z) / np.linalg.norm(z))
    n_miss = miss_both + miss_highs_only
    t_highs_total = per_highs * n

    print(f"problems: n = {n}, d = 200, kL = 120 (6 x R^20), K = 40, eta = 0, {len(problems)} matrices, "
          f"max_iter = {args.max_iter}")
    print(f"batched ADMM   : {t_batch:8.3f} s total, {1e3 * t_batch / n:7.3f} ms/problem, "
          f"iterations median {int(np.median(iters))}, max {int(iters.max())}")
    print(f"                 status {dict((str(s), int(c)) for s, c in zip(*np.unique(status, return_counts=True)))}")
    print(f"HiGHS (linprog): {per_highs * 1e3:7.2f} ms/problem measured on {count} problems, "
          f"extrapolated to n: {t_highs_total:8.1f} s")
    print(f"accuracy vs the truth x (max over problems): batched {err_batch.max():.2e} (all {n}), "
          f"HiGHS {highs_err.max():.2e} (the {count} timed)")
    print(f"recovered to 1e-6 relative: batched {np.mean(err_batch <= 1e-6):.2%}, "
          f"HiGHS {np.mean(highs_err <= 1e-6):.2%} (of the {count} timed)")
    print(f"batched vs HiGHS on the timed problems: max relative difference {max(batch_err_sub):.2e}")
    print(f"problems the batched solver did not recover ({n_miss}): HiGHS recovers {miss_highs_only} "
          f"of them, the other {miss_both} are not ℓ1-recoverable (the LP solution ≠ x); "
          f"=> HiGHS would recover {1 - miss_both / n:.2%} of all n, batched {1 - n_miss / n:.2%}")
    if miss_diff:
        print(f"                 on those, batched vs HiGHS: median relative difference "
              f"{np.median(miss_diff):.1e}, max {max(miss_diff):.1e} (max_iter columns)")
    print(f"speed-up (extrapolated HiGHS / batched): {t_highs_total / t_batch:.0f}x  (target >= 100x)")


if __name__ == "__main__":
    main()
