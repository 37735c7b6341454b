"""Random batch section of ``benchmarks/bench_large_n.py`` (issue 17).

``section_random_batch(quick=...)`` prints, in one process:

1. **One Euler step** of a Cucker–Smale alignment scene with ``RandomBatch(p)`` at
   ``N = 10⁶, d = 8`` (the delayed-curse atoms; target ≤ 1 s) and ``N = 10⁵, d = 200``
   (target ≤ 2 s), best of ``repeat`` steps, with the peak memory of a step (tracemalloc,
   numpy's allocations) against the state size ``N·d·8`` bytes, and the Dense step at a size
   where it still runs (its ``N²`` extrapolation for scale). ``--quick`` runs ``N/10`` and
   extrapolates linearly (the cost is ``O(N p d)``); the verdict is printed only for the
   full sizes.
2. **The error law** at ``N = 10⁴`` (``--quick``: ``N = 10³``): forward Euler runs with
   ``RandomBatch(p)`` against Dense with the same step ``h``, over ``p`` and ``h``, a few
   seeds each: RMS trajectory error, relative error of ``Γ(T)`` and the certified W1 bracket
   of the two final phase-space measures (``kinred.distance.paired_w1_bracket``, atoms paired
   by agent), each with its fitted log-log slope in ``h/(p − 1)`` (the RBM law predicts 1/2
   for the trajectory error: Jin–Li–Liu 2020, Ha–Jin–Kim–Ko 2021).

The Euler loop is written out here (``x += h·dx, v += h·dv``, as ``simulate(method="euler")``)
with the run's generator handed to ``Scene.rhs``; ``simulate`` passes its seed-derived
generator once the integrator does so for every scene.

Run from the repository root::

    python benchmarks/_bench_large_n_rbm.py --quick       # the reduced version
    python benchmarks/_bench_large_n_rbm.py               # full sizes (heavy: run alone)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from kinred.distance import paired_w1_bracket  # noqa: E402
from kinred.dynamics import Alignment, CuckerSmale, Scene, get_num_threads  # noqa: E402
from kinred.observables import gamma  # noqa: E402
from kinred.pairsum import Dense, RandomBatch  # noqa: E402

#: The alignment scene of the study: Cucker–Smale, G = 1, β = 0.5, mean-field normalization.
KERNEL = dict(G=1.0, beta=0.5)


def _scene(pairsum):
    return Scene([Alignment(CuckerSmale(**KERNEL))], normalize="mean", pairsum=pairsum)


def _state(n, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, (n, d)), rng.normal(0.0, 1.0, (n, d))


def _step(scene, x, v, h, rng):
    dx, dv = scene.rhs(x, v, rng=rng)
    x += h * dx
    v += h * dv


def time_step(n, d, p, repeat=3, seed=0):
    """Best wall time of one Euler step (``Scene.rhs`` + update) and its peak memory."""
    x, v = _state(n, d, seed)
    sc = _scene(RandomBatch(p=p))
    rng = np.random.default_rng(seed)
    _step(sc, x, v, 1e-3, rng)                         # plan, compile, warm caches
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        _step(sc, x, v, 1e-3, rng)
        best = min(best, time.perf_counter() - t0)
    tracemalloc.start()
    _step(sc, x, v, 1e-3, rng)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return best, peak


def time_dense(n, d, repeat=2, seed=0):
    x, v = _state(n, d, seed)
    sc = _scene(Dense())
    sc.rhs(x, v)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        sc.rhs(x, v)
        best = min(best, time.perf_counter() - t0)
    return best


def part_step_times(quick, out):
    """Targets: 10⁶ × 8 in ≤ 1 s, 10⁵ × 200 in ≤ 2 s (``quick``: N/10, extrapolated)."""
    div = 10 if quick else 1
    out(f"-- one Euler step, RandomBatch, Cucker-Smale alignment, {get_num_threads()} engine "
        f"thread(s){'  [quick: N/10, times x10 extrapolated]' if quick else ''}")
    res = {}
    for n_full, d, target in ((10**6, 8, 1.0), (10**5, 200, 2.0)):
        n = n_full // div
        for p in (2, 8):
            t, peak = time_step(n, d, p, repeat=2 if quick else 3)
            est = t * div
            verdict = "" if quick else (" target met" if est <= target else " target NOT met")
            out(f"N={n:>8d} d={d:<4d} p={p:<2d} step {t:8.3f} s"
                f"{f'  -> N={n_full}: ~{est:.2f} s' if quick else ''}  (target <= {target:g} s"
                f" at N={n_full}){verdict}; peak memory {peak / 2**20:7.1f} MiB = "
                f"{peak / (8 * n * d):.2f} x the state N*d*8")
            res[(n_full, d, p)] = est
    nd = 4000 if quick else 10**4
    t = time_dense(nd, 8)
    out(f"Dense for scale: N={nd} d=8 one right-hand side {t:.3f} s ({t / nd**2 * 1e9:.2f} ns "
        f"per pair) -> N=10^6 ~{t * (10**6 / nd) ** 2:.0f} s, N=10^5 d=200 ~"
        f"{time_dense(nd // 4, 200) * (10**5 / (nd // 4)) ** 2:.0f} s (N^2 extrapolation)")
    return res


def _run(scene, x0, v0, h, steps, rng):
    x, v = x0.copy(), v0.copy()
    for _ in range(steps):
        _step(scene, x, v, h, rng)
    return x, v


def part_error_law(quick, out, seeds=3):
    """Errors of RBM + Euler against Dense + Euler (same h) at time T, fitted slopes."""
    n, d, T = (1000, 8, 1.0) if quick else (10**4, 8, 1.0)
    hs = (0.1, 0.05, 0.025) if quick else (0.1, 0.05, 0.025, 0.0125)
    ps = (2, 3, 5) if quick else (2, 3, 5, 9)
    x0, v0 = _state(n, d, seed=1)
    out(f"-- error to Dense at T={T:g}, N={n}, d={d}, Cucker-Smale G={KERNEL['G']:g} "
        f"beta={KERNEL['beta']:g} (mean field), forward Euler, {seeds} seeds per (h, p)")
    out(f"{'h':>7s} {'p':>3s} {'h/(p-1)':>9s} {'rms traj':>10s} {'|dGamma|/Gamma':>14s} "
        f"{'W1 lower':>10s} {'W1 upper':>10s} {'rbm s/run':>9s}")
    rows = []
    dense = _scene(Dense())
    for h in hs:
        steps = int(round(T / h))
        xd, vd = _run(dense, x0, v0, h, steps, None)
        gd = gamma(vd)
        zd = np.concatenate([xd, vd], axis=1)
        for p in ps:
            sc = _scene(RandomBatch(p=p))
            sq, dg, lo, up = [], [], [], []
            t0 = time.perf_counter()
            for s in range(seeds):
                xr, vr = _run(sc, x0, v0, h, steps, np.random.default_rng(s))
                sq.append(np.mean(np.sum((xr - xd) ** 2 + (vr - vd) ** 2, axis=1)))
                dg.append(abs(gamma(vr) - gd) / gd)
                br = paired_w1_bracket(np.concatenate([xr, vr], axis=1), zd, seed=s)
                lo.append(br.lower)
                up.append(br.upper)
            dt = (time.perf_counter() - t0) / seeds
            row = (h, p, h / (p - 1), float(np.sqrt(np.mean(sq))), float(np.mean(dg)),
                   float(np.mean(lo)), float(np.mean(up)))
            rows.append(row)
            out(f"{h:7.4f} {p:3d} {row[2]:9.2e} {row[3]:10.3e} {row[4]:14.3e} {row[5]:10.3e} "
                f"{row[6]:10.3e} {dt:9.2f}")
    X = np.log([r[2] for r in rows])
    fits = {}
    for j, name in ((3, "rms trajectory error"), (4, "relative |dGamma(T)|"),
                    (5, "W1 lower bound"), (6, "W1 upper bound (index coupling)")):
        y = np.array([r[j] for r in rows])
        if np.all(y > 0):
            slope, icpt = np.polyfit(X, np.log(y), 1)
            spread = float(np.max(np.abs(np.log(y) - slope * X - icpt)))
            fits[name] = float(slope)
            out(f"fitted slope of log({name}) vs log(h/(p-1)): {slope:.3f} (law: 0.5), largest "
                f"log-residual {spread:.2f}")
        else:
            out(f"fitted slope of log({name}): not defined (a zero value)")
    return rows, fits


def section_random_batch(quick: bool = False, out=print) -> dict:
    """The random batch section of the large-N benchmark; returns the measured numbers."""
    out("== RandomBatch (random batch method, Jin-Li-Liu RBM-1) ==")
    steps = part_step_times(quick, out)
    rows, fits = part_error_law(quick, out)
    return {"step_seconds": steps, "error_rows": rows, "slopes": fits}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes (N/10)")
    args = ap.parse_args(argv)
    section_random_batch(quick=args.quick)


if __name__ == "__main__":
    main()
