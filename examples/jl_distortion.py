"""
Johnson–Lindenstrauss distortion against k
==========================================

For ``n`` points, a random ``M: R^d -> R^k`` keeps every squared pairwise distance within
``(1 ± eps)`` (eq. (2.1) of the paper) with high probability once
``k >= jl_min_dim(n, eps) = 4 ln n / (eps²/2 - eps³/3)``. This example measures the worst
distortion of every kind of map of :func:`kinred.projection.jl_matrix` over all pairs of a
Gaussian cloud (:func:`kinred.projection.distortion`) and sets it beside the ``eps`` that the
bound guarantees: the measured distortion is much smaller than the bound suggests.

Run it with ``python examples/jl_distortion.py [--smoke]``; ``--smoke`` uses tiny sizes (what
the test suite runs).
"""

# %%
# The bound, inverted
# -------------------
# ``bound_eps(n, k)`` is the smallest ``eps`` with ``jl_min_dim(n, eps) <= k``: what the
# lemma promises for a given ``k`` (None when it promises nothing below 1).

import argparse

import matplotlib.pyplot as plt
import numpy as np

from kinred.projection import distortion, jl_matrix, jl_min_dim


def bound_eps(n, k):
    """Smallest eps in (0, 1) with jl_min_dim(n, eps) <= k (bisection), or None."""
    lo, hi = 1e-3, 0.999
    if jl_min_dim(n, hi) > k:
        return None
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if jl_min_dim(n, mid) <= k else (mid, hi)
    return hi


ap = argparse.ArgumentParser(description="Johnson–Lindenstrauss distortion against k")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
args = ap.parse_args()
n, d = (50, 256) if args.smoke else (200, 1024)
ks = [16, 64, 128] if args.smoke else [16, 32, 64, 128, 256, 512]
kinds = ("gaussian", "srht") if args.smoke else ("gaussian", "rademacher", "achlioptas",
                                                  "srht", "dct")

# %%
# Measured distortion
# -------------------
# One map of each kind per ``k`` (seeded by ``k``), the worst pair of the cloud.

pts = np.random.default_rng(0).standard_normal((n, d))
print(f"{n} points in R^{d}: worst squared-distance distortion eps over all pairs")
print(f"{'k':>5} " + " ".join(f"{kind:>10}" for kind in kinds) + f" {'bound eps':>10}")
measured = {kind: [] for kind in kinds}
bounds = []
for k in ks:
    for kind in kinds:
        measured[kind].append(distortion(jl_matrix(k, d, kind=kind, seed=k), pts).eps)
    b = bound_eps(n, k)
    bounds.append(np.nan if b is None else b)
    print(f"{k:>5} " + " ".join(f"{measured[kind][-1]:10.3f}" for kind in kinds)
          + (f" {b:10.3f}" if b is not None else f" {'(none<1)':>10}"))
print("bound eps: the smallest eps with jl_min_dim(n, eps) <= k")
print("done")

# %%
# Distortion against k
# --------------------
# Every kind follows roughly ``eps ∝ 1/√k``; the guaranteed ``eps`` (black) exists only
# once ``k`` is large enough and stays well above the measured one.

fig, ax = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
for kind in kinds:
    ax.loglog(ks, measured[kind], "o-", label=kind)
ax.loglog(ks, bounds, "k^--", label="guaranteed by jl_min_dim")
ax.set_xticks(ks, [str(k) for k in ks], minor=False)
ax.tick_params(axis="x", which="minor", bottom=False, labelbottom=False)
ax.set_xlabel("target dimension k")
ax.set_ylabel("worst distortion eps of squared distances")
ax.set_title(f"JL distortion of {n} Gaussian points in R^{d}")
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize="small")
plt.show()
