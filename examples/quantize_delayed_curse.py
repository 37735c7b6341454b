"""The delayed curse of dimension: atoms needed for W1 <= eps, isotropic vs decaying widths.

A tensor product of d uniform laws with widths σⱼ quantized with Nⱼ atoms per coordinate has
W1 ≤ Σⱼ c σⱼ / Nⱼ (eq. (4.22) of the paper, label ``delayed``). For equal widths the
number of atoms Πⱼ Nⱼ grows like ε^(-d) (the curse); for geometrically decaying widths only
the first k̄(ε) coordinates need more than one atom (the *delayed* curse). The table compares
kinred's optimal budget with the paper's recipe (one common N on the first k̄ coordinates).

    python examples/quantize_delayed_curse.py [--smoke]
"""

import argparse

import numpy as np

from kinred.quantize import budget, paper_recipe


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
    ap.add_argument("--dim", type=int, default=50)
    ap.add_argument("--decay", type=float, default=0.5)
    args = ap.parse_args(argv)
    d = 8 if args.smoke else args.dim
    epsilons = [0.5, 0.2] if args.smoke else [0.5, 0.2, 0.1, 0.05, 0.02, 0.01]

    shapes = {
        "isotropic": np.ones(d),
        f"decay {args.decay}": args.decay ** np.arange(d),
    }
    print(f"d = {d}; atoms for W1 <= eps (rule 'paper': W1 <= sum sigma_j / N_j)")
    print(f"{'widths':>12} {'eps':>6} {'k_bar':>5} {'optimal N':>12} {'bound':>8}"
          f" {'recipe N':>12} {'recipe/optimal':>14}")
    for name, widths in shapes.items():
        for eps in epsilons:
            b = budget(widths, eps=eps, rule="paper")
            r = paper_recipe(widths, eps, rule="paper")
            print(f"{name:>12} {eps:6.3f} {b.k_bar:5d} {b.n_atoms:12.4g} {b.bound:8.4f}"
                  f" {r.n_atoms:12.4g} {r.n_atoms / b.n_atoms:14.3g}")
    print("done: the decaying widths need exponentially fewer atoms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
