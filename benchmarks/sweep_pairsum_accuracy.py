"""Study: the approximate pair-sum backends against Dense on random clouds of every kind.

Each seed draws one scene and one cloud – dimension k = 1..3, N up to 8000, extents from
1e-3 to 300 with flat axes, offsets up to 1e4, uniform, Gaussian, ring, tightly clustered or
half-coincident agents; Cucker–Smale alignment on positions and on velocities, Morse
attraction–repulsion (soft 0, 0.01, 0.1, 0.5) or first-order aggregation; weights or none;
``tol`` from 1e-2 to 1e-8 – and compares ``NUFFT(near_field=None)``, ``NUFFT(near_field=True)``,
``CellList`` and ``Auto`` with Dense: the relative field error ``‖F − F_dense‖/‖F_dense‖``
over ``tol`` (a clear ``TooLarge`` refusal counts as such, not as a failure).

It prints every failure (error above tol), every call slower than 5 s, and per backend the
count of runs, refusals and failures and the worst error/tol. This is how the field check
of the NUFFT grids, the CellList's row-checked cutoff and the capped cheap mode estimate
were found (2026-12-07; before them: five clusters at 5·tol, a 3-D Gaussian cloud at
7.6·tol with the cell list, 33–40 s of ``Auto`` choosing for a 0.1 s dense sum).

Run from the repository root::

    python benchmarks/sweep_pairsum_accuracy.py              # seeds 0..199
    python benchmarks/sweep_pairsum_accuracy.py --seeds 1000 1100
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from kinred.dynamics import (Aggregation, Alignment, AttractionRepulsion,  # noqa: E402
                             CuckerSmale, Morse, Scene)
from kinred.errors import KinredError, KinredWarning, TooLarge  # noqa: E402
from kinred.pairsum import NUFFT, Auto, CellList  # noqa: E402

KINDS = ("uniform", "gauss", "ring", "clusters", "coincident")


def draw(seed: int):
    """``(x, v, effects, normalize, weights, tol, label)`` of one seed."""
    rng = np.random.default_rng(seed)
    k, n = int(rng.integers(1, 4)), int(rng.integers(2, 8000))
    ext = 10.0 ** rng.uniform(-3, 2.5, k)
    if rng.random() < 0.3:
        ext[rng.integers(k)] *= 10.0 ** -rng.uniform(1, 4)          # a flat axis
    off = float(rng.choice([0.0, 1e3, -1e4]) * rng.random())
    kind = str(rng.choice(KINDS))
    x = rng.uniform(0, 1, (n, k)) * ext
    if kind == "gauss":
        x = rng.normal(size=(n, k)) * ext
    elif kind == "clusters":
        c = rng.uniform(0, 1, (5, k)) * ext
        x = c[rng.integers(0, 5, n)] + 1e-3 * ext.max() * rng.normal(size=(n, k))
    elif kind == "ring" and k >= 2:
        th, R = rng.uniform(0, 2 * np.pi, n), ext.max()
        x = np.zeros((n, k))
        x[:, 0], x[:, 1] = R * np.cos(th), R * np.sin(th)
        x += 0.01 * R * rng.normal(size=(n, k))
    elif kind == "coincident":
        x[: n // 2] = x[0]
    x = x + off
    v = rng.normal(size=(n, k))
    effects = []
    if rng.random() < 0.7:
        effects.append(Alignment(CuckerSmale(float(rng.uniform(0.1, 2)),
                                             float(rng.uniform(0.1, 2.5)))))
    if rng.random() < 0.7 or not effects:
        effects.append(AttractionRepulsion(Morse(
            float(rng.uniform(0.1, 2)), float(rng.uniform(0.2, 5)), float(rng.uniform(0.1, 2)),
            float(rng.uniform(0.05, 2)), soft=float(rng.choice([0.0, 0.01, 0.1, 0.5])))))
    if rng.random() < 0.3:
        effects.append(Alignment(CuckerSmale(0.7, 1.0), on="v"))
    if rng.random() < 0.2:
        effects = [Aggregation(Morse(1.0, 2.0, 1.5, 0.5, soft=float(rng.choice([0.0, 0.2]))))]
    normalize = str(rng.choice(["sum", "mean"]))
    w = rng.dirichlet(np.ones(n)) if rng.random() < 0.5 else None
    tol = float(10.0 ** -rng.integers(2, 9))
    return x, v, effects, normalize, w, tol, f"k={k} n={n} {kind} ext={np.round(ext, 4)}"


def field(effects, normalize, w, pairsum, x, v):
    sc = Scene(effects, normalize, weights=w, pairsum=pairsum)
    first = sc.order == 1
    return sc.rhs(x, None if first else v)[0 if first else 1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(0, 200), metavar=("FROM", "TO"))
    args = ap.parse_args(argv)
    backends = {"nufft": lambda tol: NUFFT(tol, near_field=None),
                "nufft-split": lambda tol: NUFFT(tol, near_field=True),
                "cells": lambda tol: CellList(tol=tol), "auto": lambda tol: Auto(tol=tol)}
    stats = {b: {"runs": 0, "refused": 0, "failed": 0, "worst": 0.0} for b in backends}
    warnings.simplefilter("ignore", KinredWarning)
    for seed in range(*args.seeds):
        x, v, eff, norm, w, tol, label = draw(seed)
        try:
            ref = field(eff, norm, w, "dense", x, v)
        except TooLarge:
            continue
        nref = float(np.linalg.norm(ref))
        for name, make in backends.items():
            st = stats[name]
            t = time.perf_counter()
            try:
                got = field(eff, norm, w, make(tol), x, v)
            except TooLarge:
                st["refused"] += 1
                continue
            except KinredError as exc:         # a kernel the backend cannot take
                st["refused"] += 1
                print(f"  {seed} {name}: {type(exc).__name__}: {str(exc)[:80]}")
                continue
            dt = time.perf_counter() - t
            st["runs"] += 1
            err = float(np.linalg.norm(got - ref)) / nref / tol if nref > 0 else 0.0
            st["worst"] = max(st["worst"], err)
            if not err <= 1.0:
                st["failed"] += 1
            if not err <= 1.0 or dt > 5.0:
                print(f"  seed {seed} {name}: error {err:.3g}·tol, {dt:.1f} s; {label}, "
                      f"tol={tol:g}, {norm}, weights={w is not None}, {eff}", flush=True)
    print(f"seeds {args.seeds[0]}..{args.seeds[1] - 1}:")
    for name, st in stats.items():
        print(f"  {name:<12} runs {st['runs']:4d}  refused {st['refused']:4d}  failed "
              f"{st['failed']:3d}  worst error {st['worst']:.3g}·tol")
    return int(any(st["failed"] for st in stats.values()))


if __name__ == "__main__":
    sys.exit(main())
