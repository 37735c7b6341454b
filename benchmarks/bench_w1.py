"""W1 cost vs atom count: exact dense, exact lazy, sparse, bracket, sliced (a different distance).

Three parts (``python benchmarks/bench_w1.py [--quick] [--scaling] [--acceptance] [--figure P]``):

* default -- the comparison below (small sizes, every method against the exact value);
* ``--scaling [--max-n N]`` -- N from 10³ to ``--max-n`` (default 10⁶): paired clouds in ℝ⁴,
  ``X ~ N(0, diag(1, 1, .3, .3))``, ``Y = X + 0.01·noise + 0.005`` (issue 22's case): wall time
  and certified relative gap ``(upper − lower)/upper`` of each method (exact dense up to 4000
  atoms, exact-lazy up to 2000, sparse, bracket up to 10⁵, paired bracket without and with
  its dual lower bound, ``dual_seconds=60``); ``--figure P``
  draws them (docs/img/w1_methods.png is ``--scaling --max-n 100000 --figure ...``);
* ``--acceptance`` -- issue 22's four timings (a budget of 240 s each), each in its own
  process (peak memory from ``getrusage``): paired ℝ⁴ N = 10⁵ (≤ 10 s) and 10⁶ (≤ 60 s,
  ≤ 4 GB), unpaired weighted 10⁵ vs 8·10⁴ in ℝ⁶ (≤ 60 s), paired ℝ²⁰ N = 2·10⁴ (≤ 60 s);
  ``--case NAME`` runs one, printing the phases' seconds.

The comparison: two Gaussian clouds in d = 10 (the second
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
    ap.add_argument("--scaling", action="store_true", help="time and certified gap vs N")
    ap.add_argument("--max-n", type=int, default=10**6, help="largest N of --scaling")
    ap.add_argument("--figure", default=None, help="--scaling: write the figure to this PNG")
    ap.add_argument("--acceptance", action="store_true", help="issue 22's timings")
    ap.add_argument("--case", default=None, help="--acceptance: run only this case")
    args = ap.parse_args(argv)
    if args.scaling:
        return scaling(args.max_n, args.figure)
    if args.acceptance:
        return acceptance(args.case)
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


def paired_r4(n: int, seed: int = 0):
    """Issue 22's case: ``X ~ N(0, diag(1, 1, .3, .3))``, ``Y = X + 0.01·noise + 0.005``."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, 4)) * [1.0, 1.0, 0.3, 0.3]
    return x, x + 0.01 * rng.standard_normal((n, 4)) + 0.005


def _gap(r) -> float:
    return 0.0 if r.exact else (r.upper - r.lower) / r.upper


def scaling(max_n: int, figure=None):
    """Time and certified relative gap of each method, N = 10³ … ``max_n`` (paired ℝ⁴)."""
    from kinred.distance import paired_w1_bracket

    sizes = [n for n in (1000, 2000, 4000, 10_000, 20_000, 50_000, 100_000, 200_000, 500_000,
                         1_000_000) if n <= max_n]
    limits = {"exact": 4000, "exact-lazy": 2000, "bracket": 100_000}
    x, y = paired_r4(300)
    w1(x, y, "sparse", max_dense_bytes=0)               # warm-up: POT import, numba cache load
    w1(x, y, "exact")
    rows = []
    print(f"{'N':>8} {'method':<15} {'time [s]':>9} {'W1 or [lower, upper]':>40} {'gap':>9}")
    for n in sizes:
        x, y = paired_r4(n)
        for m in ("exact", "exact-lazy", "sparse", "bracket", "paired-bracket", "paired+dual"):
            if n > limits.get(m, n):
                continue
            if m == "paired-bracket":
                r, t = _t(lambda: paired_w1_bracket(x, y, seed=0))
            elif m == "paired+dual":
                r, t = _t(lambda: paired_w1_bracket(x, y, seed=0, dual_seconds=60))
            else:
                r, t = _t(lambda: w1(x, y, m, seed=0, max_bytes="6G"))
            val = f"{r.value:.12g}" if r.exact else f"[{r.lower:.8g}, {r.upper:.8g}]"
            print(f"{n:>8} {m:<15} {t:>9.2f} {val:>40} {_gap(r):>9.2g}", flush=True)
            rows.append((n, m, t, _gap(r)))
    if figure:
        _figure(rows, figure)
    return rows


def _figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.8))
    floor = 1e-16
    for m, style in (("exact", "o-"), ("exact-lazy", "s-"), ("sparse", "D-"),
                     ("bracket", "^-"), ("paired-bracket", "v-"), ("paired+dual", "x-")):
        rs = [r for r in rows if r[1] == m]
        if not rs:
            continue
        ax0.loglog([r[0] for r in rs], [r[2] for r in rs], style, label=m, ms=4)
        ax1.loglog([r[0] for r in rs], [max(r[3], floor) for r in rs], style, label=m, ms=4)
    ax0.set_xlabel("atoms N = M")
    ax0.set_ylabel("wall time [s]")
    ax0.set_title("time (paired clouds in R^4)")
    ax1.set_xlabel("atoms N = M")
    ax1.set_ylabel("certified relative gap (upper - lower)/upper")
    ax1.set_title(f"gap (exact values drawn at {floor:g})")
    ax0.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    print(f"figure written to {path}")


_CASES = {
    "paired-r4-1e5": "paired R^4, N = 1e5 (<= 10 s)",
    "paired-r4-1e6": "paired R^4, N = 1e6 (<= 60 s, <= 4 GB)",
    "unpaired-r6-1e5": "unpaired weighted 1e5 vs 8e4 in R^6 (<= 60 s)",
    "paired-r20-2e4": "paired R^20, N = 2e4 (<= 60 s)",
}


def _case_data(name: str):
    rng = np.random.default_rng(1)
    if name == "paired-r4-1e5":
        return (*paired_r4(100_000), None, None)
    if name == "paired-r4-1e6":
        return (*paired_r4(1_000_000), None, None)
    if name == "unpaired-r6-1e5":
        x = rng.standard_normal((100_000, 6)) * [1, 1, 0.5, 0.5, 0.3, 0.3]
        y = rng.standard_normal((80_000, 6)) * [1, 1, 0.5, 0.5, 0.3, 0.3] + 0.02
        a, b = rng.random(100_000), rng.random(80_000)
        return x, y, a / a.sum(), b / b.sum()
    x = rng.standard_normal((20_000, 20)) * 0.8 ** np.arange(20)
    return x, x + 0.01 * rng.standard_normal((20_000, 20)) + 0.005, None, None


def _one_case(name: str):
    import os
    import resource

    x, y, a, b = _case_data(name)
    k = int(os.environ.get("KINRED_BENCH_NEIGHBORS", "8"))
    r, t = _t(lambda: w1(x, y, "sparse", a=a, b=b, max_bytes="6G", max_seconds=240.0,
                         neighbors=k))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # KiB -> GiB
    val = f"W1 = {r.value:.15g}" if r.exact else f"[{r.lower:.15g}, {r.upper:.15g}]"
    print(f"{name:<16} {_CASES[name]:<48} {t:>7.1f} s  peak {peak:.2f} GiB  exact={r.exact}  "
          f"{val}  ({r.info.get('iterations')} solves, {r.info.get('edges')} edges)", flush=True)
    phases = {k[len("seconds_"):]: v for k, v in r.info.items()
              if k.startswith("seconds_")}
    print("    phases (s): " + ", ".join(f"{k} {v:.1f}" for k, v in phases.items())
          + f"; repair: {r.info.get('repair_cycles', 0)} cycles cancelled, "
            f"{r.info.get('repair_work', 0)} queue steps", flush=True)
    if not r.exact:
        print(f"    not exact: {r.info.get('reason')}", flush=True)


def acceptance(case=None):
    """Each case in a fresh process (its own peak memory)."""
    import subprocess
    import sys

    if case is not None:
        return _one_case(case)
    for name in _CASES:
        subprocess.run([sys.executable, __file__, "--acceptance", "--case", name], check=True)


if __name__ == "__main__":
    main()
