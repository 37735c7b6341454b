"""Quantization cost versus atom count: time, bound and exact error.

Run: ``python benchmarks/bench_quantize.py`` (single process; timings depend on machine load).

Tables:
1. 1-D quantization of Beta(2, 5) with N atoms: time to place the atoms, time of the exact
   W1 error (quantile integral), the exact error and the bound σ/(2N).
2. A 3-D tensor product (Uniform, Beta(2, 2), truncated normal) quantized with an atom budget:
   budget time, materialize time, the bound (Lemma 4.1) and the product-ℓ1 exact error.
3. The delayed-curse budget on d = 200 decaying widths: time, atoms, optimality, vs the recipe.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import stats

from kinred.measures import TensorProduct, Uniform, Univariate
from kinred.quantize import budget, quantize, quantize_1d


def _t(f):
    t = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t


def main() -> None:
    print("1-D Beta(2, 5), midpoint rule")
    print(f"{'N':>8} {'atoms [s]':>10} {'exact W1 [s]':>13} {'exact W1':>12} {'bound':>10} {'ratio':>7}")
    mu = Univariate(stats.beta(2, 5))
    for n in (10, 100, 1000, 10_000, 100_000):
        q, ta = _t(lambda: quantize_1d(mu, n))
        e, te = _t(lambda: q.error)
        print(f"{n:>8} {ta:>10.4f} {te:>13.4f} {e:>12.4e} {q.bound:>10.4e} {e / q.bound:>7.3f}")

    print("\n3-D tensor product (Uniform(0,1), Beta(2,2), N(0,1) on [-2,2]), atom budget")
    print(f"{'atoms':>9} {'N':>9} {'N_j':>16} {'quantize [s]':>13} {'materialize [s]':>16} "
          f"{'bound':>10} {'l1 exact':>10}")
    tp = TensorProduct([Uniform(0, 1), Univariate(stats.beta(2, 2)),
                        Univariate(stats.norm(), support=(-2, 2))])
    for atoms in (10, 100, 1000, 10_000, 100_000, 1_000_000):
        q, tq = _t(lambda: quantize(tp, atoms=atoms))
        A, tm = _t(lambda: q.materialize(max_atoms=2_000_000))
        print(f"{atoms:>9} {q.n_atoms:>9} {str(q.counts):>16} {tq:>13.4f} {tm:>16.4f} "
              f"{q.bound:>10.4e} {q.error:>10.4e}")

    print("\ndelayed-curse budget, d = 200, σ_j = 0.8^j, midpoint rule")
    print(f"{'eps':>7} {'time [s]':>9} {'k̄':>4} {'N':>11} {'optimal':>8} {'lower bd':>10} {'recipe N':>11}")
    w = 0.8 ** np.arange(200)
    for eps in (1.0, 0.3, 0.1, 0.03, 0.01):
        b, tb = _t(lambda: budget(w, eps=eps))
        print(f"{eps:>7g} {tb:>9.3f} {b.k_bar:>4} {float(b.n_atoms):>11.3e} {str(b.optimal):>8} "
              f"{b.lower_bound:>10.3e} {float(b.recipe.n_atoms):>11.3e}")


if __name__ == "__main__":
    main()
