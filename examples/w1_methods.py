"""
W1 by every method
==================

The same pair of point clouds, their Wasserstein-1 distance (eq. (4.5) of the paper) by every
method of :func:`kinred.distance.w1`: ``"exact"`` and ``"exact-lazy"`` (POT's network
simplex on a dense or lazily evaluated cost), and ``"bracket"``, a certified bracket
``lower <= W1 <= upper`` that needs no linear program. :func:`kinred.distance.sliced_w1` is a
different (smaller) distance, and says so.

Run it with ``python examples/w1_methods.py [--smoke]``; ``--smoke`` uses tiny sizes (what the
test suite runs).
"""

# %%
# Two clouds
# ----------
# Uniform on the unit cube, the second shifted by 0.2 in every coordinate, so that
# W1 >= 0.2·√d (the distance between the means).

import argparse
import time

import matplotlib.pyplot as plt
import numpy as np

from kinred.distance import sliced_w1, w1

ap = argparse.ArgumentParser(description="W1 by every method")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
args = ap.parse_args()
n, d = (200, 5) if args.smoke else (1500, 10)

rng = np.random.default_rng(0)
mu = rng.uniform(0.0, 1.0, (n, d))
nu = rng.uniform(0.0, 1.0, (n, d)) + 0.2
mean_shift = 0.2 * np.sqrt(d)
print(f"two clouds of {n} points in R^{d}; W1 >= {mean_shift:.4f} (mean shift)")

# %%
# Every method
# ------------
# The exact methods agree to the last digit; the bracket contains their value.

print(f"{'method':>12} {'value':>9} {'lower':>9} {'upper':>9} {'exact':>6} {'seconds':>8}")
results = {}
for method in ("exact", "exact-lazy", "bracket"):
    t0 = time.perf_counter()
    r = w1(mu, nu, method=method, seed=1)
    results[r.method] = (r, time.perf_counter() - t0)
    print(f"{r.method:>12} {r.value:9.5f} {r.lower:9.5f} {r.upper:9.5f} {str(r.exact):>6}"
          f" {results[r.method][1]:8.3f}")
t0 = time.perf_counter()
s = sliced_w1(mu, nu, n_projections=256, seed=1)
sliced_time = time.perf_counter() - t0
print(f"{'sliced':>12} {s.value:9.5f} {'':>9} {'':>9} {'--':>6} {sliced_time:8.3f}"
      f"   (stderr {s.stderr:.1e}; a different distance)")
print("done")

# %%
# Values, brackets and times
# --------------------------
# Left: each method's value with its certified interval (a point for the exact methods),
# the mean-shift lower bound, and the sliced distance for comparison. Right: wall time.

names = list(results) + ["sliced"]
values = [results[m][0].value for m in results] + [s.value]
lows = [results[m][0].lower for m in results] + [s.value]
highs = [results[m][0].upper for m in results] + [s.value]
times = [results[m][1] for m in results] + [sliced_time]
pos = np.arange(len(names))

fig, (ax, ax_t) = plt.subplots(1, 2, figsize=(9, 3.8), layout="constrained")
ax.errorbar(pos, values, yerr=[np.subtract(values, lows), np.subtract(highs, values)],
            fmt="o", capsize=6, color="tab:blue", label="value and certified [lower, upper]")
ax.axhline(mean_shift, color="grey", ls=":", label="0.2·√d (mean shift, a lower bound)")
ax.set_xticks(pos, names)
ax.set_xlabel("method")
ax.set_ylabel("W1 (Euclidean ground distance)")
ax.set_title(f"W1 between two clouds of {n} points in R^{d}")
ax.legend(fontsize="small", loc="center right")
ax_t.bar(pos, times, color="tab:grey")
ax_t.set_xticks(pos, names)
ax_t.set_xlabel("method")
ax_t.set_ylabel("wall time (s)")
ax_t.set_title("Cost")
plt.show()
