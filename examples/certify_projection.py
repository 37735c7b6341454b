"""
Certified error of a projected run
==================================

A Cucker–Smale alignment scene in ℝᵈ (eq. (2.12)–(2.13) of the paper) and its projection
by a Johnson–Lindenstrauss matrix ``M`` into ℝᵏ (eq. (2.14)–(2.15)).
:func:`kinred.certify.certify` runs the high-dimensional forward-Euler scheme with
:func:`~kinred.integrate.simulate`, steps the projected run alongside, and returns the *measured* error ``y − Mx`` of the projected run next to a *certified* upper bound of it:
the proofs of Theorems 2.2 and 2.3 applied step by step with what is measured at that step
(the defect of the projected trajectory as a vector, the projected run's graph Laplacian and
its spectral gap, localized kernel slopes; ``docs/certificates.md``). The paper's own
right-hand side of eq. (2.18) is printed for comparison.

.. code-block:: console

    python examples/certify_projection.py [--smoke] [--out FIGURE.png]
"""

# %%
# Sizes
# -----
# Figure 4's setting reduced (normal initial data, β = 0.4, mean-field coupling);
# ``--smoke`` shrinks it further for the test suite.
import argparse

import numpy as np

from kinred.certify import certify
from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.integrate import SaveAt
from kinred.projection import jl_matrix

ap = argparse.ArgumentParser(description="Certified error of a projected run")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
ap.add_argument("--out", default=None, help="also save the figure to this file (PNG)")
args, _ = ap.parse_known_args()
N, d, k, T = (40, 50, 8, 3.0) if args.smoke else (200, 200, 20, 15.0)
dt = 0.02

# %%
# The scene, the initial data and the projection
# -----------------------------------------------
rng = np.random.default_rng(2012)
x0 = rng.standard_normal((N, d))
v0 = rng.standard_normal((N, d))
scene = Scene([Alignment(CuckerSmale(G=1.0, beta=0.4))], normalize="mean")
M = jl_matrix(k, d, kind="gaussian", seed=7)

# %%
# Certify
# -------
# Both runs are forward Euler with step ``dt``; the errors and bounds are recorded every
# ``T/10`` (weighted RMS over agents of ``(|y_i − M x_i|² + |w_i − M v_i|²)^½``).
every = int(round(T / dt / 10))
cert = certify(scene, M, x0, v0, t_span=(0.0, T), dt=dt, save=SaveAt(every=every))
print(f"Cucker-Smale N={N}, d={d}, projected to k={k}; Euler dt={dt}, T={T}")
print(f"{'t':>6} {'error (' + cert.labels['error'] + ')':>20} "
      f"{'bound (' + cert.labels['bound'] + ')':>26} {'ratio':>6} "
      f"{'eq. (2.18) (' + cert.labels['paper_bound'].split(' (')[0] + ')':>26}")
for j in range(2, len(cert.t), 2):
    print(f"{cert.t[j]:6.2f} {cert.error[j]:20.3e} {cert.bound[j]:26.3e} "
          f"{cert.bound[j] / cert.error[j]:6.2f} {cert.paper_bound[j]:26.3e}")
print(f"valid: {cert.valid}; worst ratio over t >= 1: {cert.worst_ratio_after(1.0):.2f} "
      f"(max over agents: {cert.worst_ratio_after(1.0, 'max'):.2f})")

# %%
# Plot
# ----
# The measured error and its certified bound (the paper's a-priori bound is many orders of
# magnitude above both: printed only).
import matplotlib.pyplot as plt  # noqa: E402

fig, ax = plt.subplots(figsize=(6.5, 4))
ax.plot(cert.t, cert.error, "o-", label="measured error")
ax.plot(cert.t, cert.bound, "s--", label="certified bound")
ax.set_xlabel("t")
ax.set_ylabel("RMS error of the projected run")
ax.set_title(f"Projected Cucker-Smale run, N={N}, d={d}, k={k}")
ax.legend()
fig.tight_layout()
if args.out:
    fig.savefig(args.out, dpi=100)
    print(f"figure: {args.out}")
print("done")
