"""W1 cost vs atom count: exact dense, exact lazy, bracket, sliced (a different distance).

Run ``python benchmarks/bench_w1.py [--quick]``. Two Gaussian clouds in d = 10 (the second
shifted by 0.3 per coordinate), N = M atoms. For each N it prints wall time and what each
method reached: the exact value, the bracket [lower, upper] and its width relative to the exact
value, sliced W1 / W1 (a different distance, for reference), POT called naively (default
``numItermax`` and default metric, i.e. W2² -- and with metric="euclidean" but the default
iteration cap), and ``scipy.stats.wasserstein_distance_nd`` at small sizes, with ratios.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from kinred.distance import sliced_w1, w1


def _t(f):
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, finishes in < 30 s")
    ap.add_argument("--d", type=int, default=10)
    args = ap.parse_args(argv)
    import ot
    from scipy.stats import wasserstein_distance_nd

    sizes = [250, 500, 1000] if args.quick else [250, 500, 1000, 2000, 4000]
    lazy_max = 1000 if args.quick else 4000
    scipy_max = 250 if args.quick else 500
    d = args.d
    print(f"W1 between two Gaussian clouds in d={d} (N = M atoms, shift 0.3 per coordinate)")
    print("timings are wall-clock on a shared machine; 'rel' = value / exact W1\n")
    hdr = f"{'N':>5} {'method':<34} {'time [s]':>9} {'value':>10} {'rel/width':>22}"
    print(hdr)
    print("-" * len(hdr))
    for n in sizes:
        rng = np.random.default_rng(n)
        x = rng.standard_normal((n, d))
        y = rng.standard_normal((n, d)) + 0.3
        ex, te = _t(lambda: w1(x, y, "exact"))
        W = ex.value
        print(f"{n:>5} {'exact (ot.emd2, dense)':<34} {te:>9.3f} {W:>10.5f} {'exact':>22}")
        if n <= lazy_max:
            lz, tl = _t(lambda: w1(x, y, "exact-lazy"))
            print(f"{n:>5} {'exact-lazy (ot.lp.emd2_lazy)':<34} {tl:>9.3f} {lz.value:>10.5f} "
                  f"{'rel ' + format(lz.value / W, '.12f'):>22}")
        br, tb = _t(lambda: w1(x, y, "bracket", seed=0))
        print(f"{n:>5} {'bracket':<34} {tb:>9.3f} {br.value:>10.5f} "
              f"{'[' + format(br.lower / W, '.3f') + ', ' + format(br.upper / W, '.3f') + ']':>22}")
        print(f"{'':>5}   ({br.note})")
        sw, ts = _t(lambda: sliced_w1(x, y, n_projections=200, seed=0))
        print(f"{n:>5} {'sliced W1 (different distance!)':<34} {ts:>9.3f} {sw.value:>10.5f} "
              f"{'ratio ' + format(sw.value / W, '.3f'):>22}")
        a = np.full(n, 1.0 / n)
        with warnings.catch_warnings(record=True):
            warnings.simplefilter("always")
            (nv, log), tn = _t(lambda: ot.emd2(a, a, ot.dist(x, y, metric="euclidean"), log=True))
        flag = " (stopped early!)" if log["result_code"] == 3 else ""
        print(f"{n:>5} {'naive ot.emd2, default numItermax':<34} {tn:>9.3f} {nv:>10.5f} "
              f"{'rel ' + format(nv / W, '.5f'):>22}{flag}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            (n2, tn2) = _t(lambda: ot.emd2(a, a, ot.dist(x, y)))
        print(f"{n:>5} {'naive ot.emd2(ot.dist(x,y)) = W2^2':<34} {tn2:>9.3f} {n2:>10.5f} "
              f"{'rel ' + format(n2 / W, '.3f'):>22}")
        if n <= scipy_max:
            sc, tsc = _t(lambda: wasserstein_distance_nd(x, y))
            print(f"{n:>5} {'scipy wasserstein_distance_nd':<34} {tsc:>9.3f} {sc:>10.5f} "
                  f"{'rel ' + format(sc / W, '.10f'):>22}  time ratio scipy/ours {tsc / te:.1f}")
        print()


if __name__ == "__main__":
    main()
