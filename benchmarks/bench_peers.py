"""kinred against its peers, in one process: W1 solvers and atom placement at equal atom counts.

Run ``python benchmarks/bench_peers.py [--quick]`` (single process, timings wall-clock; noisy on
a shared machine).

Part 1 -- exact W1 vs peers (complements ``bench_w1.py``, which covers d = 10 Gaussians):
for uniform clouds in d = 2 and 5 it prints, per size N, kinred's exact W1 (``w1(x, y,
"exact")``), ``scipy.stats.wasserstein_distance_nd`` (an LP through HiGHS) and POT called
naively: ``ot.emd2(a, b, ot.dist(x, y))`` -- squared Euclidean cost by default, so it returns
W2², not W1 -- and ``ot.emd2`` on the Euclidean cost with its default ``numItermax=100000``
(which may stop early and say so only through a warning / ``result_code``). Columns: time,
value, value / exact W1, time ratio peer / kinred.

Part 2 -- quantization vs random sampling (Monte Carlo) vs scrambled Sobol (``scipy.stats.qmc``,
mapped through the quantile functions) at equal atom counts N, for measures in d = 1, 2, 5:

* ``Σ marg``: Σⱼ W1(μⱼ, νⱼ), the exact 1-D W1 of the marginals summed -- for the quantization
  (a product grid) this is the exact W1 for the ℓ1 ground cost, an upper bound of the
  Euclidean W1; for MC and Sobol atoms (not product measures) it only compares marginals;
* ``W1~ref`` (N ≤ a limit): the exact Euclidean W1 (POT network simplex via ``kinred.w1``) to a
  fine quantization ``ref`` of the measure, whose own product-ℓ1 error ``e_ref`` is printed:
  the true W1(μ, ν) lies within ``W1~ref ± e_ref``.

MC and Sobol values are means over a few seeds. The quantization uses the delayed-curse budget
(``quantize(mu, atoms=N)``, at most N atoms; its actual count is printed).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from scipy import stats

from kinred.distance import w1
from kinred.measures import TensorProduct, Uniform, Univariate
from kinred.quantize import quantize


def _t(f):
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def part_w1(quick: bool) -> None:
    import ot
    from scipy.stats import wasserstein_distance_nd

    print("== Part 1: exact W1 vs scipy.stats.wasserstein_distance_nd and naive POT ==")
    print("uniform clouds U[0,1]^d vs U[0.2,1.2]^d, N = M atoms, uniform weights\n")
    hdr = (f"{'d':>2} {'N':>5} {'solver':<38} {'time [s]':>9} {'value':>9} {'value/W1':>9} "
           f"{'time/kinred':>11}")
    print(hdr)
    print("-" * len(hdr))
    sizes = (100, 300) if quick else (100, 300, 1000)
    scipy_max = 300 if quick else 1000
    for d in (2, 5):
        for n in sizes:
            rng = np.random.default_rng(1000 * d + n)
            x = rng.random((n, d))
            y = rng.random((n, d)) + 0.2
            ex, te = _t(lambda: w1(x, y, "exact"))
            W = ex.value

            def row(name, t, v, note=""):
                print(f"{d:>2} {n:>5} {name:<38} {t:>9.4f} {v:>9.5f} {v / W:>9.5f} "
                      f"{t / te:>11.2f}{note}")

            row("kinred w1(x, y, 'exact')", te, W)
            if n <= scipy_max:
                sc, ts = _t(lambda: wasserstein_distance_nd(x, y))
                row("scipy wasserstein_distance_nd", ts, sc)
            a = np.full(n, 1.0 / n)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                v2, t2 = _t(lambda: ot.emd2(a, a, ot.dist(x, y)))
            row("naive ot.emd2(a,b,ot.dist(x,y)) = W2^2", t2, float(v2), "  <- wrong quantity")
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("always")
                (v3, log), t3 = _t(lambda: ot.emd2(a, a, ot.dist(x, y, metric="euclidean"), log=True))
            flag = "  <- stopped early (numItermax)" if log.get("result_code") == 3 else ""
            row("ot.emd2(euclidean), default numItermax", t3, float(v3), flag)
        print()


def _measures():
    beta25 = Univariate(stats.beta(2, 5))
    tnorm = Univariate(stats.norm(), support=(-3.0, 3.0))
    return [
        ("d=1 Beta(2,5)", TensorProduct([beta25])),
        ("d=1 N(0,1) on [-3,3]", TensorProduct([tnorm])),
        ("d=2 Beta(2,5) x N(0,1)[-3,3]", TensorProduct([beta25, tnorm])),
        ("d=5 U[0,1]^5 (isotropic)", TensorProduct([Uniform(0.0, 1.0) for _ in range(5)])),
        ("d=5 U[0,0.5^j] (decaying)", TensorProduct([Uniform(0.0, 0.5 ** j) for j in range(5)])),
    ]


def _marg_sum(mu: TensorProduct, pts: np.ndarray) -> float:
    return float(sum(w1(f, pts[:, j], "exact-1d").value for j, f in enumerate(mu.factors)))


def _ppf(mu: TensorProduct, u: np.ndarray) -> np.ndarray:
    return np.column_stack([f.ppf(u[:, j]) for j, f in enumerate(mu.factors)])


def part_atoms(quick: bool) -> None:
    from scipy.stats import qmc

    print("== Part 2: quantization vs Monte Carlo vs scrambled Sobol at equal atom counts ==")
    print("Σ marg = Σ_j exact 1-D W1 of the marginals (for the grid: exact l1 W1 >= Euclidean W1);")
    print("W1~ref = exact Euclidean W1 (POT) to a fine quantization; true W1 within ± e_ref.\n")
    sizes = (16, 64, 256) if quick else (16, 64, 256, 1024, 4096)
    seeds = 3 if quick else 5
    ref_atoms = 2048 if quick else 8192
    ref_max = 256 if quick else 1024
    hdr = (f"{'measure':<30} {'N':>5} {'method':<10} {'N used':>6} {'Σ marg':>10} {'W1~ref':>10} "
           f"{'/quant':>7} {'time [s]':>9}")
    for name, mu in _measures():
        rq = quantize(mu, atoms=ref_atoms)
        ref = rq.materialize()
        print(f"{name}: reference {ref.n_atoms} atoms, e_ref = {rq.error:.2e}")
        print(hdr)
        print("-" * len(hdr))
        for n in sizes:
            res = {}
            q, tq = _t(lambda: quantize(mu, atoms=n).materialize())
            res["quantize"] = (q.n_atoms, q.points, q.weights, tq)
            for method in ("MC", "Sobol"):
                runs = []
                for s in range(seeds):
                    if method == "MC":
                        p, tm = _t(lambda: mu.sample(n, seed=s))
                    else:
                        def sob():
                            u = qmc.Sobol(mu.dim, scramble=True, seed=s).random_base2(int(np.log2(n)))
                            return _ppf(mu, u)
                        p, tm = _t(sob)
                    runs.append((p, tm))
                res[method] = runs
            base_m = base_r = None
            for method in ("quantize", "MC", "Sobol"):
                if method == "quantize":
                    nu, pts, wts, tm = res[method]
                    marg = float(quantize(mu, atoms=n).error)
                    wr = (w1(pts, ref.points, "exact", a=wts, b=ref.weights).value
                          if n <= ref_max else float("nan"))
                    base_m, base_r = marg, wr
                else:
                    nu = n
                    marg = float(np.mean([_marg_sum(mu, p) for p, _ in res[method]]))
                    wr = (float(np.mean([w1(p, ref.points, "exact", b=ref.weights).value
                                         for p, _ in res[method]])) if n <= ref_max else float("nan"))
                    tm = float(np.mean([t for _, t in res[method]]))
                ratio = wr / base_r if np.isfinite(wr) else marg / base_m
                print(f"{'':<30} {n:>5} {method:<10} {nu:>6} {marg:>10.3e} {wr:>10.3e} "
                      f"{ratio:>7.2f} {tm:>9.4f}")
        print()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (about half a minute)")
    ap.add_argument("--only", choices=("w1", "atoms"), default=None)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    if args.only in (None, "w1"):
        part_w1(args.quick)
    if args.only in (None, "atoms"):
        part_atoms(args.quick)
    print(f"bench_peers: {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
