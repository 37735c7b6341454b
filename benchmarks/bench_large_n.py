"""Benchmark: pair sums at large N – sub-quadratic backends against the dense engine.

One section per backend, each a function ``section_<name>(args)`` registered in
:data:`SECTIONS` (run them all, or some with ``--only``); every ratio and error of a section is
measured in one process run.

* ``nufft`` – :class:`kinred.pairsum.NUFFT` (fast summation by finufft), Cucker–Smale
  alignment ``g(s) = 0.8 (1 + s²)^(−1.5)``, positions ``U[0, D]²``, velocities ``N(0, 1)``,
  ``normalize="sum"``:

  1. one right-hand side at N = 2·10⁴ (k = 2, D = 1 and D = 10): Dense vs NUFFT(tol = 1e-6),
     the time ratio (target ≥ 20×) and the relative field error ``‖F − F_dense‖/‖F_dense‖``
     (target ≤ 1e-6);
  2. one right-hand side at N = 10⁶ (k = 2, D = 1; target ≤ 1.5 s on 2 cores) – skipped with
     ``--quick`` (N = 10⁵ instead);
  3. the error against the exact sum as a function of tol (1e-2 … 1e-10) on random clouds
     (k = 1, 2, 3; Cucker–Smale and soft Morse; weighted; far from the origin): the table
     behind the accuracy statement of ``NUFFT``'s docstring;
  4. the peer: pykeops (the engine behind SiSyPHE) on the same dense 2-D sum at N = 10⁵, when
     it is importable (it is not a kinred dependency).

* ``auto`` – ``pairsum="auto"`` on the cases of issue 24 (the D'Orsogna ring, the 3-D slab,
  unsoftened Morse, a spread short-range cloud, the dense refusal of N = 10⁷): see
  ``_bench_large_n_auto.py``.

* ``overhead`` – ``simulate``'s own cost at N = 10⁵, d = 200, ``RandomBatch(p = 4)``, 10 Euler
  steps with the default save (``--quick``: N = 10⁴): one right-hand side, a hand-written
  Euler step, ``simulate``'s time per step and its overhead (target ≤ 15 % of the
  right-hand sides), split into the steps' own cost and the run's fixed cost.

Run from the repository root::

    python benchmarks/bench_large_n.py                 # everything, full sizes
    python benchmarks/bench_large_n.py --quick         # reduced sizes (no N = 10⁶)
    python benchmarks/bench_large_n.py --only nufft    # one section
    python benchmarks/bench_large_n.py --only overhead # simulate's loop against its rhs

A new section: write ``section_<name>(args)`` printing its lines and add it to
:data:`SECTIONS`.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Morse,  # noqa: E402
                             Scene, get_num_threads)
from kinred.errors import TooLarge  # noqa: E402
from kinred.pairsum import NUFFT, Dense  # noqa: E402

CS = CuckerSmale(0.8, 1.5)


def best_time(fn, repeat: int) -> tuple[float, object]:
    """``(min wall time over repeat calls, last result)`` after one untimed warm-up call."""
    out = fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def cloud(n, k, diameter, seed=0, shift=0.0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(0.0, diameter, (n, k)) + shift, rng.normal(size=(n, k)),
            rng.dirichlet(np.ones(n)))


def rhs_fn(backend, x, v, effects=(Alignment(CS),), weights=None):
    scene = Scene(list(effects), "sum", weights=weights, pairsum=backend)
    return lambda: scene.rhs(x, v)[1], scene


# ---------------------------------------------------------------------------- NUFFT
def nufft_vs_dense(n, diameter, tol, repeat):
    """One right-hand side, Dense and NUFFT(tol): times, ratio, field error, modes."""
    x, v, _ = cloud(n, 2, diameter, seed=1)
    dense, _ = rhs_fn(Dense(), x, v)
    fast, scene = rhs_fn(NUFFT(tol), x, v)
    t_dense, ref = best_time(dense, repeat)
    t_fast, got = best_time(fast, repeat)
    info = next(iter(scene._plans.values())).info()[0]
    print(f"  N = {n}, k = 2, D = {diameter:g}: Dense {t_dense:.3f} s, NUFFT(tol={tol:g}) "
          f"{1e3 * t_fast:.1f} ms -> {t_dense / t_fast:.1f}x (target >= 20x); relative field "
          f"error {rel(got, ref):.2e} (target <= {tol:g}); modes {info['modes']}")


def nufft_one_rhs(n, tol, repeat):
    """One right-hand side of NUFFT alone at size ``n`` (first call = grid + plan, then the
    per-step cost)."""
    x, v, _ = cloud(n, 2, 1.0, seed=2)
    fast, scene = rhs_fn(NUFFT(tol), x, v)
    t = time.perf_counter()
    fast()
    first = time.perf_counter() - t
    t_fast, _ = best_time(fast, repeat)
    info = next(iter(scene._plans.values())).info()[0]
    print(f"  N = {n}, k = 2, D = 1, NUFFT(tol={tol:g}): {t_fast:.3f} s per right-hand side "
          f"(first call with grid and plan {first:.3f} s; modes {info['modes']}, finufft eps "
          f"{info['eps']:g})")


def nufft_error_table(n, tols):
    """Relative field error / tol on random clouds: rows (k, kernel, diameter), columns tol."""
    kernels = {"cs": [Alignment(CS)],
               "morse": [AttractionRepulsion(Morse(Ca=1.0, la=2.0, Cr=1.5, lr=0.5, soft=0.3))]}
    print(f"  relative field error / tol (and Fourier modes), N = {n}, weighted, 1e6 from "
          "the origin:")
    print("  " + f"{'k kernel D':<16}" + "".join(f"{'tol=%g' % t:>20}" for t in tols))
    worst = {t: 0.0 for t in tols}
    for k, diameters in ((1, (1e-6, 1.0, 10.0)), (2, (1e-6, 1.0, 10.0)), (3, (1e-6, 1.0))):
        for name, eff in kernels.items():
            for diameter in diameters:
                x, v, w = cloud(n, k, diameter, seed=k, shift=1e6)
                ref = Scene(eff, "sum", weights=w, pairsum="numpy").rhs(x, v)[1]
                cells = []
                for tol in tols:
                    scene = Scene(eff, "sum", weights=w, pairsum=NUFFT(tol))
                    try:
                        err = rel(scene.rhs(x, v)[1], ref) / tol
                    except TooLarge:
                        cells.append(f"{'TooLarge':>20}")
                        continue
                    worst[tol] = max(worst[tol], err)
                    modes = int(np.prod(next(iter(scene._plans.values())).info()[0]["modes"]))
                    cells.append(f"{err:>11.2e} ({modes:>6d})")
                print("  " + f"{f'{k} {name} {diameter:g}':<16}" + "".join(cells))
    print("  worst error / tol: " + ", ".join(f"{t:g}: {e:.2f}" for t, e in worst.items()))


def keops_peer(n, repeat):
    """The same dense 2-D Cucker–Smale sum by pykeops (a LazyTensor reduction, compiled on
    first use and warmed up on a small cloud; timed once: it is O(N²)), if importable."""
    try:
        from pykeops.numpy import LazyTensor
    except Exception as exc:   # not a kinred dependency
        print(f"  pykeops: not importable here ({type(exc).__name__}: {exc}); skipped")
        return

    def keops(x, v):
        xi, xj = LazyTensor(x[:, None, :]), LazyTensor(x[None, :, :])
        vj = LazyTensor(np.hstack([v, np.ones((len(x), 1))])[None, :, :])
        # 0.8 (1 + s²)^(−3/2); measured faster than rsqrt(·)**3 in pykeops 2.3 on CPU
        g = 0.8 * (1.0 + ((xi - xj) ** 2).sum(-1)) ** (-1.5)
        A = (g * vj).sum(axis=1)
        return A[:, :2] - A[:, 2:] * v

    t = time.perf_counter()
    keops(*cloud(1000, 2, 1.0, seed=4)[:2])
    t_compile = time.perf_counter() - t
    x, v, _ = cloud(n, 2, 1.0, seed=3)
    t = time.perf_counter()
    got = keops(x, v)
    t_k = time.perf_counter() - t
    t_f, ref = best_time(rhs_fn(NUFFT(1e-6), x, v)[0], repeat)
    print(f"  pykeops dense sum, N = {n}, k = 2: {t_k:.3f} s per right-hand side (first use "
          f"incl. compilation {t_compile:.1f} s; NUFFT 1e-6: {t_f:.3f} s); relative "
          f"difference {rel(got, ref):.1e}")


def section_nufft(args):
    print(f"NUFFT fast summation (finufft), {get_num_threads()} engine threads")
    repeat = 1 if args.quick else args.repeat
    for diameter in (1.0, 10.0):
        nufft_vs_dense(20_000, diameter, 1e-6, repeat)
    if args.quick:
        nufft_one_rhs(100_000, 1e-6, repeat)
        print("  N = 10^6: skipped with --quick")
    else:
        nufft_one_rhs(1_000_000, 1e-6, repeat)
    nufft_error_table(500 if args.quick else 2000, (1e-2, 1e-4, 1e-6, 1e-8, 1e-10))
    keops_peer(20_000 if args.quick else 100_000, repeat)


#: The sections, in the order they run.
def section_random_batch(args):
    """RandomBatch: one step at N = 10⁶ (d = 8) and N = 10⁵ (d = 200), and the error law in
    h/(p − 1) at N = 10⁴ (see ``_bench_large_n_rbm.py``)."""
    from _bench_large_n_rbm import section_random_batch as run

    run(quick=args.quick)


def section_auto(args):
    """pairsum="auto" on the cases of issue 24 (see ``_bench_large_n_auto.py``)."""
    from _bench_large_n_auto import section_auto as run

    run(quick=args.quick, repeat=1 if args.quick else args.repeat)


# ---------------------------------------------------------------------------- overhead
def loop_overhead(n, d, p, steps, repeat):
    """``simulate``'s own cost beside its right-hand sides: RandomBatch(p) Cucker–Smale
    alignment (G = 1, β = 0.5, mean field), forward Euler, the default save (Γ and Λ at every
    step, the final state), ``steps`` steps; best of ``repeat`` runs after a warm-up run."""
    from kinred.integrate import simulate
    from kinred.pairsum import RandomBatch

    rng = np.random.default_rng(0)
    x0, v0 = rng.uniform(0.0, 1.0, (n, d)), rng.normal(0.0, 1.0, (n, d))
    scene = Scene([Alignment(CuckerSmale(1.0, 0.5))], "mean", pairsum=RandomBatch(p=p))
    gen = np.random.default_rng(1)
    x, v = x0.copy(), v0.copy()
    h = 1e-3

    def euler_by_hand():            # the Euler step of _bench_large_n_rbm.py
        dx, dv = scene.rhs(x, v, rng=gen)
        x.__iadd__(h * dx)
        v.__iadd__(h * dv)

    def run():
        return simulate(scene, x0, v0, (0.0, steps * h), h, seed=1)

    t_rhs, _ = best_time(lambda: scene.rhs(x0, v0, rng=gen), repeat)
    # the right-hand side simulate calls: without the public call's validation of x and v
    t_int, _ = best_time(lambda: scene._rhs(x0, v0, 0.0, rng=gen), repeat)
    t_hand, _ = best_time(euler_by_hand, repeat)
    t_sim, tr = best_time(run, repeat)
    per_step = t_sim / steps
    assert tr.n_rhs_evals == steps
    print(f"  N = {n}, d = {d}, RandomBatch(p={p}), {steps} Euler steps, default save:")
    print(f"    one right-hand side {1e3 * t_rhs:.1f} ms; a hand-written Euler step (rhs + "
          f"x += h dx, v += h dv) {1e3 * t_hand:.1f} ms")
    print(f"    simulate {1e3 * per_step:.1f} ms per step ({1e3 * t_sim:.0f} ms for the run, "
          f"validation, centring and the final state included)")
    print(f"    overhead of simulate: {100 * (per_step - t_rhs) / t_rhs:.0f} % of the right-hand "
          f"sides (target <= 15 %), {100 * (per_step - t_hand) / t_hand:.0f} % of the "
          f"hand-written Euler steps")
    print(f"    against the unvalidated right-hand side simulate calls ({1e3 * t_int:.1f} ms): "
          f"overhead {100 * (per_step - t_int) / t_int:.0f} %")
    # the VM's speed drifts between the blocks above: pair each run with the right-hand
    # sides measured next to it, and take the median of the pairs' overheads
    # and split the run: a one-step run next to it gives the run's fixed cost (validation,
    # the working frame's copies, the final state) and the steps' own cost
    ratios, step_ratios, fixed = [], [], []
    for _ in range(max(3, repeat)):
        t = time.perf_counter()
        for _ in range(steps):
            scene._rhs(x0, v0, 0.0, rng=gen)
        t_rhs_pair = (time.perf_counter() - t) / steps
        t = time.perf_counter()
        run()
        t_run = time.perf_counter() - t
        t = time.perf_counter()
        simulate(scene, x0, v0, (0.0, h), h, seed=1)
        t_one = time.perf_counter() - t
        per = (t_run - t_one) / (steps - 1)
        ratios.append(t_run / steps / t_rhs_pair - 1.0)
        step_ratios.append(per / t_rhs_pair - 1.0)
        fixed.append(t_one - per)
    print(f"    interleaved, {len(ratios)} pairs of a run and {steps} unvalidated right-hand "
          f"sides: overhead median {100 * float(np.median(ratios)):.0f} % (range "
          f"{100 * min(ratios):.0f}–{100 * max(ratios):.0f} %)")
    print(f"      of which the steps (a {steps}-step run minus a one-step run, per step, "
          f"against the right-hand side): median {100 * float(np.median(step_ratios)):.0f} % "
          f"(range {100 * min(step_ratios):.0f}–{100 * max(step_ratios):.0f} %); the run's "
          f"fixed cost (validation, copies, final state): median "
          f"{1e3 * float(np.median(fixed)):.0f} ms (range {1e3 * min(fixed):.0f}–"
          f"{1e3 * max(fixed):.0f} ms)")


def section_overhead(args):
    """``simulate``'s loop against its right-hand sides (issue 24, item 5)."""
    print(f"simulate's own cost, {get_num_threads()} engine threads")
    n = 10_000 if args.quick else 100_000
    loop_overhead(n, 200, 4, 10, 1 if args.quick else args.repeat)


SECTIONS = {"nufft": section_nufft, "random_batch": section_random_batch, "auto": section_auto,
            "overhead": section_overhead}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes (no N = 10^6)")
    ap.add_argument("--only", nargs="+", choices=sorted(SECTIONS), help="sections to run")
    ap.add_argument("--repeat", type=int, default=3, help="timed repeats (minimum reported)")
    args = ap.parse_args(argv)
    for name in args.only or list(SECTIONS):
        t = time.perf_counter()
        SECTIONS[name](args)
        print(f"[{name}: {time.perf_counter() - t:.1f} s]\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
