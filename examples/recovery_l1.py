"""
Recovery from stacked projections
=================================

Sparse high-dimensional vectors recovered from ``L`` stacked low-dimensional projections.

Each of ``L`` projections ``M^ℓ: R^d -> R^k`` sees every vector ``x``; stacking them gives one
``(L·k, d)`` matrix ``A``, and the vector is recovered by basis pursuit,
min ‖z‖₁ subject to ‖A z − y‖₂ <= η (eq. (3.16) of the paper), for all vectors at once
(:func:`kinred.recovery.basis_pursuit`: batched ADMM with a certified polish). §3.3.1 of the
paper: more projections recover less sparse vectors.

Run it with ``python examples/recovery_l1.py [--smoke]``; ``--smoke`` uses tiny sizes (what
the test suite runs). The full run takes from 10 s to a minute on two cores (the ``L = 2``
problems, at the edge of recoverability, are the slow ones), so the documentation's gallery
runs the smoke sizes: ``docs/conf.py`` sets the environment variable
``KINRED_EXAMPLES_SMOKE=1``, which this script reads like ``--smoke``.
"""

# %%
# Sparse vectors
# --------------
# ``n_vec`` vectors in ℝᵈ, each with ``sparsity`` non-zero Gaussian entries.

import argparse
import os
import time

import matplotlib.pyplot as plt
import numpy as np

from kinred.projection import jl_matrix
from kinred.recovery import basis_pursuit, stack_projections

ap = argparse.ArgumentParser(description="Recovery from stacked projections")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
args = ap.parse_args()
smoke = args.smoke or os.environ.get("KINRED_EXAMPLES_SMOKE") == "1"
d, k, n_vec, sparsity = (200, 20, 20, 8) if smoke else (500, 25, 40, 10)
Ls = [1, 2, 3] if smoke else [1, 2, 3, 4]

rng = np.random.default_rng(0)
X = np.zeros((d, n_vec))                      # columns: sparse vectors in R^d
for j in range(n_vec):
    X[rng.choice(d, sparsity, replace=False), j] = rng.standard_normal(sparsity)

# %%
# Recovery for growing L
# ----------------------
# A vector counts as recovered when its relative error is below 1e-6.

print(f"{n_vec} vectors in R^{d} with {sparsity} non-zeros, projections to R^{k}")
print(f"{'L':>3} {'rows':>5} {'max rel. error':>15} {'recovered':>10} {'seconds':>8}")
errors, recovered = {}, {}
for L in Ls:
    A = stack_projections([jl_matrix(k, d, seed=100 + ell) for ell in range(L)])
    t0 = time.perf_counter()
    res = basis_pursuit(A, A @ X)
    seconds = time.perf_counter() - t0
    errors[L] = np.linalg.norm(res.Z - X, axis=0) / np.linalg.norm(X, axis=0)
    recovered[L] = res.Z[:, 0]
    ok = int(np.sum(errors[L] < 1e-6))
    print(f"{L:3d} {A.shape[0]:5d} {errors[L].max():15.2e} {ok:>5d}/{n_vec:<4d} {seconds:8.3f}")
print("done")

# %%
# Errors and one recovered vector
# -------------------------------
# Left: the relative error of every vector against the number of stacked projections (the
# floor is round-off: exact recovery). Right: the first vector and its recoveries from one
# projection and from the most projections.

fig, (ax, ax_v) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
for L in Ls:
    ax.semilogy(np.full(n_vec, L), np.maximum(errors[L], 1e-17), "o", alpha=0.5,
                color="tab:blue")
ax.set_xticks(Ls)
ax.set_xlabel("number of stacked projections L (rows = L·k)")
ax.set_ylabel("relative error ‖z − x‖ / ‖x‖")
ax.set_title(f"Basis pursuit, d = {d}, k = {k}, {sparsity} non-zeros")
ax.axhline(1e-6, color="grey", ls=":", label="recovered below 1e-6")
ax.legend(fontsize="small")
idx = np.arange(d)
ax_v.plot(idx, X[:, 0], "ko", ms=6, mfc="none", label="true x")
for L, style in ((Ls[0], "x"), (Ls[-1], ".")):
    ax_v.plot(idx, recovered[L], style, label=f"recovered, L = {L}")
ax_v.set_xlabel("coordinate index j")
ax_v.set_ylabel("x_j")
ax_v.set_title("The first vector")
ax_v.legend(fontsize="small")
plt.show()
