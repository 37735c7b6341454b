"""``kinred demo``: the interim quantization demo (the kinetic demo will replace it).

On built-in defaults -- a 200-dimensional tensor product of uniform laws with widths
``σⱼ = 0.8ʲ`` -- it prints the delayed-curse budget (eq. (4.22) of the paper, label
``delayed``) for a few ε beside the paper's recipe, and checks the 1-D quantization errors
against their closed forms for the uniform law (``σ/(2N)`` at levels ``i/N``, ``σ/(4N)`` at
levels ``(2i−1)/(2N)``). Runs in well under ten seconds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import stats

from ..measures import TensorProduct, Uniform, Univariate
from ..quantize import quantize, quantize_1d
from .quantize import fmt_count

NAME = "demo"
HELP = "quantization demo: delayed-curse budgets in d = 200 and 1-D closed-form checks"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dim", type=int, default=200, help="dimension d (default 200)")
    parser.add_argument("--decay", type=float, default=0.8, help="width ratio σⱼ₊₁/σⱼ (default 0.8)")
    parser.add_argument("--eps", type=float, nargs="+", default=[1.0, 0.3, 0.1, 0.03],
                        help="target W1 bounds (default 1 0.3 0.1 0.03)")


def run(args) -> int:
    t0 = time.perf_counter()
    from ..errors import InvalidInput

    if args.dim < 1:
        raise InvalidInput(f"--dim must be >= 1, got {args.dim}")
    if not 0 < args.decay <= 1:
        raise InvalidInput(f"--decay must be in (0, 1], got {args.decay}")
    mu = TensorProduct([Uniform(0.0, args.decay**j) for j in range(args.dim)])
    print(f"kinred demo: tensor product of {args.dim} uniform laws, widths σ_j = {args.decay:g}^j "
          f"(Σσ = {mu.support_widths().sum():.4g}), midpoint quantiles (1-D bound σ/(2N))")
    print("delayed curse of dimension, eq. (4.22): atoms per coordinate chosen by the budget vs "
          "the paper's recipe")
    head = f"{'eps':>8} {'k̄':>4} {'N (budget)':>12} {'bound':>10} {'ℓ1-W1':>10} {'optimal':>8} " \
           f"{'k̄ recipe':>9} {'N (recipe)':>12} {'recipe/budget':>14}"
    print(head)
    for eps in args.eps:
        q = quantize(mu, eps=eps)
        b = q.budget
        ratio = b.recipe.n_atoms / b.n_atoms
        print(f"{eps:>8g} {b.k_bar:>4} {fmt_count(b.n_atoms):>12} {b.bound:>10.4g} {q.error:>10.4g} "
              f"{str(b.optimal):>8} {b.recipe.k_bar:>9} {fmt_count(b.recipe.n_atoms):>12} {ratio:>14.3g}")
    print("(ℓ1-W1: exact W1 for the ℓ1 ground cost, the sum of exact marginal errors; it bounds "
          "the Euclidean W1 from above)")
    print("\n1-D check, uniform law on [0, 2] (σ = 2): exact W1 vs closed form")
    print(f"{'N':>6} {'paper i/N':>14} {'σ/(2N)':>12} {'midpoint':>14} {'σ/(4N)':>12}")
    ok = True
    for n in (1, 2, 10, 100):
        ep = quantize_1d(Uniform(0.0, 2.0), n, rule="paper").error
        em = quantize_1d(Uniform(0.0, 2.0), n, rule="midpoint").error
        ok &= bool(np.isclose(ep, 1.0 / n, rtol=1e-9) and np.isclose(em, 0.5 / n, rtol=1e-9))
        print(f"{n:>6} {ep:>14.10f} {1.0 / n:>12.10f} {em:>14.10f} {0.5 / n:>12.10f}")
    beta = Univariate(stats.beta(2, 5))
    print("\nBeta(2, 5), N = 20: exact W1 and bound")
    for rule in ("paper", "midpoint"):
        q = quantize_1d(beta, 20, rule=rule)
        print(f"  {rule:<9} exact {q.error:.6g} ≤ bound {q.bound:.6g}")
    print(f"\nclosed forms {'match' if ok else 'DO NOT MATCH'}; {time.perf_counter() - t0:.2f} s")
    return 0 if ok else 1
