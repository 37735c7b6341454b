"""Benchmark: kinred's dynamics engine against the NumPy Cucker–Smale baseline.

Times, in one process, forward-Euler Cucker–Smale runs (β = 1.5 and 1.62, ``normalize="sum"``,
G = 0.8, h = 0.02) at (N, d) = (1000, 200) full and (1000, 10) projected against
``../shared/reference/cucker_smale_numpy.py`` (imported from its path, never copied), prints
both times (minimum over ``--repeat`` alternating runs, default 2), their ratio and the
largest relative Γ(t) difference while Γ > 1e-8 (before flocking), the same for
``precision="mixed"`` (float32 pair sums, float64 state: what the lower accuracy buys), then
a self-propulsion-only scene against an alignment scene at the same N, d, and
single-threaded per-step times at k = 2, 5, 10, 25, 50, 100, 150, 200 (process CPU time, less
sensitive to other load than wall time) and the resulting estimate of the full Table 1 run
(423 simulations of 1500 steps on 2 single-threaded workers).

Run from the repository root::

    python benchmarks/bench_dynamics.py            # 1500 steps, best of 2 alternating runs
    python benchmarks/bench_dynamics.py --quick    # 150 steps, one run
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from kinred._parallel import blas_threads  # noqa: E402
from kinred.dynamics import (Alignment, CuckerSmale, Scene, SelfPropulsion,  # noqa: E402
                             get_num_threads, set_num_threads)
from kinred.integrate import SaveAt, simulate  # noqa: E402


def load_baseline():
    path = os.path.join(ROOT, "..", "shared", "reference", "cucker_smale_numpy.py")
    spec = importlib.util.spec_from_file_location("cs_baseline", os.path.normpath(path))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run_pair(base, x0, v0, beta, steps, G, label, repeat=1):
    """Baseline and kinred (float64, then mixed) on the same data; each timed ``repeat``
    times, alternating, and compared by their minima (the least-disturbed run: on a shared
    VM single runs vary by up to 2x)."""
    t_base, t_ours, gammas = [], {"double": [], "mixed": []}, {}
    for _ in range(repeat):
        t = time.perf_counter()
        tb, gb = base.simulate(x0, v0, beta=beta, G=G, normalize="sum", h=0.02, steps=steps,
                               record_every=50)
        t_base.append(time.perf_counter() - t)
        for precision in ("double", "mixed"):
            scene = Scene([Alignment(CuckerSmale(G=G, beta=beta))], normalize="sum",
                          precision=precision)
            tr = simulate(scene, x0, v0, (0.0, steps * 0.02), 0.02, save=SaveAt(every=50,
                          observables=("gamma",)))
            t_ours[precision].append(tr.wall_time)
            gammas[precision] = tr.observables["gamma"]
    for precision in ("double", "mixed"):
        g = gammas[precision]
        mask = gb > 1e-8
        rel = float(np.max(np.abs(g[mask] - gb[mask]) / gb[mask])) if mask.any() else float("nan")
        name = label if precision == "double" else "  same, precision='mixed'"
        tb_min, to_min = min(t_base), min(t_ours[precision])
        runs = ("" if repeat == 1 else "  (runs: baseline " + ", ".join(f"{t:.2f}" for t in t_base)
                + "; kinred " + ", ".join(f"{t:.2f}" for t in t_ours[precision]) + ")")
        print(f"{name:34s} beta={beta:<5} baseline {tb_min:7.2f} s  kinred {to_min:7.2f} s  "
              f"ratio {tb_min / to_min:5.2f}x  max rel dGamma (Gamma>1e-8) {rel:.2e}  "
              f"Gamma(T) {g[-1]:.2e} vs {gb[-1]:.2e}{runs}")


def per_step(N, k, steps, beta=1.62, repeat=3, precision="double"):
    """Single-threaded ms per Euler step (minimum over ``repeat`` runs of CPU time)."""
    rng = np.random.default_rng(3)
    x0, v0 = rng.uniform(0, 1, (N, k)), rng.uniform(-1, 1, (N, k))
    scene = Scene([Alignment(CuckerSmale(G=0.8, beta=beta))], normalize="sum",
                  precision=precision)
    # N = 1000 agents in the unit cube with the sum normalization: the alignment Laplacian's
    # spectral radius is about 1.3e3, so Euler is stable for dt < 1.5e-3 (the divergence
    # guard stops dt = 0.02 at the first step); the cost of a step does not depend on dt
    dt = 1e-3
    best = float("inf")
    for _ in range(repeat):
        c0 = time.process_time()
        simulate(scene, x0, v0, (0.0, steps * dt), dt, save=SaveAt(every=50,
                 observables=("gamma",)))
        best = min(best, (time.process_time() - c0) / steps * 1e3)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="150 steps instead of 1500")
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--repeat", type=int, default=2,
                    help="timings per comparison, alternating baseline and kinred; the minima "
                         "are compared (default 2; 1 with --quick)")
    args = ap.parse_args(argv)
    steps = args.steps or (150 if args.quick else 1500)
    repeat = 1 if args.quick else max(1, args.repeat)
    base = load_baseline()
    N, d, k = 1000, 200, 10
    x0, v0 = base.paper_initial_data(N, d, seed=0)
    M = np.random.default_rng(1).normal(0.0, 1.0 / np.sqrt(k), (k, d))
    print(f"steps={steps}, repeat={repeat}, engine threads={get_num_threads()}, "
          f"cpu_count={os.cpu_count()}")
    for beta in (1.5, 1.62):
        run_pair(base, x0, v0, beta, steps, 0.8, f"full (N, d) = ({N}, {d})", repeat)
        run_pair(base, x0 @ M.T, v0 @ M.T, beta, steps, 0.8, f"projected (N, k) = ({N}, {k})",
                 repeat)

    # self-propulsion only vs alignment at the same N, d
    ns = min(steps, 150)
    for name, effects in (("self-propulsion only", [SelfPropulsion(1.0, 0.5)]),
                          ("alignment + self-propulsion", [Alignment(CuckerSmale(0.8, 1.62)),
                                                           SelfPropulsion(1.0, 0.5)])):
        tr = simulate(Scene(effects, normalize="sum"), x0, 0.1 * v0, (0.0, ns * 0.02), 0.02,
                      save=SaveAt(every=50, observables=("gamma",)))
        print(f"{name:30s} (N, d) = ({N}, {d}): {tr.wall_time / ns * 1e3:8.3f} ms/step")

    old = get_num_threads()
    set_num_threads(1)
    times = {"double": {}, "mixed": {}}
    try:
        ns = min(steps, 100)
        with blas_threads(1):
            for kk in (2, 5, 10, 25, 50, 100, 150, 200):
                for prec in ("double", "mixed"):
                    t15 = per_step(N, kk, ns, 1.5, precision=prec)
                    t162 = per_step(N, kk, ns, 1.62, precision=prec)
                    times[prec][kk] = (t15, t162)
                    print(f"single-threaded per-step time (CPU), N=1000, k={kk:3d}, {prec:6s}: "
                          f"beta=1.5 {t15:6.2f} ms, beta=1.62 {t162:6.2f} ms")
    finally:
        set_num_threads(old)
    for prec, tt in times.items():
        # beta = 1.7 costs what 1.62 costs (the same ufunc chain)
        per_beta = [sum(tt[kk][i] for kk in (150, 100, 50, 25, 10, 5, 2)) for i in (0, 1, 1)]
        orig = [tt[200][i] for i in (0, 1, 1)]
        total = sum(o + 20 * p for o, p in zip(orig, per_beta)) * 1500 / 2 / 1e3
        print(f"{prec}: sum over projected k of per-step times {per_beta[0]:.1f} ms (beta=1.5), "
              f"{per_beta[1]:.1f} ms (1.62); estimated Table 1 run (423 x 1500 steps, "
              f"2 single-threaded workers): {total:.0f} s = {total / 60:.1f} min")


if __name__ == "__main__":
    main()
