"""Section ``auto`` of ``bench_large_n.py``: the cases of issue 24 on ``pairsum="auto"``.

Rows (each one process run; the first call of a backend builds its grids/cells and is
reported apart from the per-step cost; a row against Dense reports the best of the first call
and at least :data:`RATIO_REPEAT` further calls of each):

1. Dense refuses N = 10⁷ in 2-D before any work (seconds to the refusal);
2. 2-D D'Orsogna ring (radius 5 and 20, Morse Ca = 0.5, la = 2, Cr = 1, lr = 0.5,
   soft = 0.1, self-propulsion), tol 1e-6: N = 2·10⁴ auto vs Dense (ratio, field error),
   N = 10⁶ auto alone (skipped with ``--quick``: N = 10⁵);
3. 3-D cloud of extents 29 × 6 × 1.7, 10⁴ from the origin, CS β = 0.7 + soft Morse
   (lr = 0.4, soft = 0.3): N = 3·10⁴ auto vs Dense; N = 10⁶ auto alone (``--quick``: 10⁵);
4. unsoftened Morse (soft = 0) in 2-D, D = 5: N = 2·10⁴ auto vs Dense, N = 10⁵ auto alone;
5. a spread short-range cloud (2-D, D = 1000, Morse la = 1, soft = 0.1), N = 10⁵: auto
   (the cell list) alone, and its error against Dense at N = 2·10⁴.
"""

from __future__ import annotations

import time

import numpy as np

from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene,
                             SelfPropulsion)
from kinred.errors import TooLarge
from kinred.pairsum import Auto, Dense


def _ring(n, radius, seed=0):
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, 2 * np.pi, n)
    r = radius + 0.1 * rng.normal(size=n)
    x = np.c_[r * np.cos(th), r * np.sin(th)]
    v = np.c_[-np.sin(th), np.cos(th)] + 0.1 * rng.normal(size=(n, 2))
    return x, v


def _slab(n, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(0, 1, (n, 3)) * np.array([29.0, 6.0, 1.7]) + 1e4,
            rng.normal(size=(n, 3)))


def _pairs_only(effects, x, v, backend):
    """The pair contribution to dv (the local effects subtracted) and the scene."""
    sc = Scene(effects, pairsum=backend)
    local = sum((e.drift(x, v, 0.0) for e in effects if not e.pairwise), np.zeros_like(v))
    return (lambda: sc.rhs(x, v)[1] - local), sc


def _timed(fn, repeat):
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    best = first
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return first, best, out


#: Timed calls of a row against Dense, at least (each after the first call): on a shared VM
#: one call of 0.1 s can take 50 % longer, so the ratio uses the best of several on both sides.
RATIO_REPEAT = {"auto": 5, "dense": 2}


def _row(label, effects, x, v, tol, repeat, dense=True):
    fast, sc = _pairs_only(effects, x, v, Auto(tol=tol))
    t = time.perf_counter()
    try:
        first, t_auto, got = _timed(fast, max(repeat, RATIO_REPEAT["auto"]) if dense else repeat)
    except TooLarge as exc:      # every candidate estimated beyond Auto's max_seconds
        print(f"  {label}, N = {len(x)}: auto refused in {time.perf_counter() - t:.2f} s: "
              f"{str(exc)[:220]}...")
        return
    info = sc.info()["pairsum"]
    line = (f"  {label}, N = {len(x)}: auto -> {info['chosen']} {t_auto:.3f} s per rhs "
            f"(first call {first:.2f} s)")
    if dense:
        exact, _ = _pairs_only(effects, x, v, Dense())
        _, t_dense, ref = _timed(exact, max(repeat, RATIO_REPEAT["dense"]))
        err = float(np.linalg.norm(got - ref) / np.linalg.norm(ref))
        line += f"; Dense {t_dense:.2f} s -> {t_dense / t_auto:.1f}x; field error {err:.1e}"
    print(line)


def section_auto(quick: bool, repeat: int) -> None:
    print("pairsum='auto' on the cases of issue 24")
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5))])
    z = np.zeros((10**7, 2))
    t = time.perf_counter()
    try:
        sc.rhs(z, z)
        print("  Dense N = 10^7, d = 2: NOT refused")
    except TooLarge as exc:
        print(f"  Dense N = 10^7, d = 2: refused in {time.perf_counter() - t:.3f} s: "
              f"{str(exc)[:110]}...")
    big = 100_000 if quick else 1_000_000
    ring = [SelfPropulsion(1.0, 0.5),
            AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=0.1))]
    for radius in (5.0, 20.0):
        _row(f"2-D ring R = {radius:g}", ring, *_ring(20_000, radius), 1e-6, repeat)
        _row(f"2-D ring R = {radius:g}", ring, *_ring(big, radius), 1e-6, 1, dense=False)
    slab = [Alignment(CuckerSmale(0.8, 0.7)),
            AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.4, soft=0.3))]
    _row("3-D slab 29x6x1.7", slab, *_slab(30_000), 1e-6, repeat)
    _row("3-D slab 29x6x1.7", slab, *_slab(big), 1e-6, 1, dense=False)
    cusp = [AttractionRepulsion(Morse(0.5, 2.0, 1.0, 0.5, soft=0.0))]
    rng = np.random.default_rng(3)
    _row("2-D soft = 0, D = 5", cusp, rng.uniform(0, 5, (20_000, 2)),
         rng.normal(size=(20_000, 2)), 1e-6, repeat)
    _row("2-D soft = 0, D = 5", cusp, rng.uniform(0, 5, (100_000, 2)),
         rng.normal(size=(100_000, 2)), 1e-6, 1, dense=False)
    short = [AttractionRepulsion(Morse(0.5, 1.0, 1.0, 0.5, soft=0.1))]
    _row("2-D spread D = 1000", short, rng.uniform(0, 1000, (20_000, 2)),
         rng.normal(size=(20_000, 2)), 1e-6, repeat)
    _row("2-D spread D = 1000", short, rng.uniform(0, 1000, (100_000, 2)),
         rng.normal(size=(100_000, 2)), 1e-6, 1, dense=False)
