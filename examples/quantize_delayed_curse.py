"""
The delayed curse of dimension
==============================

How many atoms does a measure on ℝᵈ need so that its quantization is within ``eps`` in W1?

A tensor product of ``d`` uniform laws with widths σⱼ, quantized with Nⱼ atoms on coordinate
``j``, has W1 ≤ Σⱼ c σⱼ / Nⱼ (eq. (4.22) of the paper). For equal widths the number of atoms
Πⱼ Nⱼ grows like ε^(-d): the curse of dimension. For geometrically decaying widths only the
first k̄(ε) coordinates need more than one atom: the curse is *delayed*. This example compares
kinred's optimal budget (:func:`kinred.quantize.budget`) with the paper's recipe of §4.5
(:func:`kinred.quantize.paper_recipe`: one common N on the first k̄ coordinates).

Run it with ``python examples/quantize_delayed_curse.py [--smoke] [--dim D] [--decay R]``;
``--smoke`` uses tiny sizes (what the test suite runs).
"""

# %%
# Sizes and widths
# ----------------
# Two shapes in the same dimension: equal widths (*isotropic*) and widths ``decay**j``.

import argparse

import matplotlib.pyplot as plt
import numpy as np

from kinred.quantize import budget, paper_recipe

ap = argparse.ArgumentParser(description="The delayed curse of dimension")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
ap.add_argument("--dim", type=int, default=50)
ap.add_argument("--decay", type=float, default=0.5)
args = ap.parse_args()
d = 8 if args.smoke else args.dim
epsilons = [0.5, 0.2] if args.smoke else [0.5, 0.2, 0.1, 0.05, 0.02, 0.01]

shapes = {
    "isotropic": np.ones(d),
    f"decay {args.decay}": args.decay ** np.arange(d),
}

# %%
# Atoms for ``W1 <= eps``
# -----------------------
# ``k_bar`` is the number of coordinates that get more than one atom; ``bound`` is the
# guaranteed W1 of the optimal budget; the last column is how many times more atoms the
# paper's recipe uses.

print(f"d = {d}; atoms for W1 <= eps (rule 'paper': W1 <= sum sigma_j / N_j)")
print(f"{'widths':>12} {'eps':>6} {'k_bar':>5} {'optimal N':>12} {'bound':>8}"
      f" {'recipe N':>12} {'recipe/optimal':>14}")
atoms = {name: ([], []) for name in shapes}   # name -> (optimal, recipe) atom counts
for name, widths in shapes.items():
    for eps in epsilons:
        b = budget(widths, eps=eps, rule="paper")
        r = paper_recipe(widths, eps, rule="paper")
        atoms[name][0].append(b.n_atoms)
        atoms[name][1].append(r.n_atoms)
        print(f"{name:>12} {eps:6.3f} {b.k_bar:5d} {b.n_atoms:12.4g} {b.bound:8.4f}"
              f" {r.n_atoms:12.4g} {r.n_atoms / b.n_atoms:14.3g}")
print("done: the decaying widths need exponentially fewer atoms")

# %%
# The curse and the delayed curse
# -------------------------------
# Atoms against the target ``eps`` on log-log axes: the isotropic counts are astronomical
# (a slope of ``-d``), the decaying ones grow slowly as ``eps`` shrinks.

fig, ax = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
for (name, (opt, rec)), colour in zip(atoms.items(), ("tab:red", "tab:blue")):
    ax.loglog(epsilons, opt, "o-", color=colour, label=f"{name}: optimal budget")
    ax.loglog(epsilons, rec, "s--", color=colour, alpha=0.6, label=f"{name}: paper's recipe")
ax.invert_xaxis()
ax.set_xlabel("target W1 accuracy eps (units of the widths)")
ax.set_ylabel("number of atoms  Π N_j")
ax.set_title(f"Atoms for W1 <= eps in d = {d}")
ax.grid(True, which="major", alpha=0.3)
ax.legend(fontsize="small")
plt.show()
