"""
Flocking, full and projected
============================

One Cucker–Smale run in ℝᵈ, the same run projected to a few ``k``, and the flocking verdicts.

The full system is eqs. (2.12)–(2.13) of the paper with g(s) = G / (1 + s²)^β; the projected
one is eq. (3.5), started from (M x⁰, M v⁰). The trajectory error max_i ‖y_i(t) − M x_i(t)‖
is bounded by eq. (3.7); the verdict is the paper's rule on the velocity fluctuation Γ(T)
(§3.4.1): "pos" below 1e-10, "neg" above 1e-3, "n/a" in between.

Run it with ``python examples/flocking_projected.py [--smoke] [--beta B]``; ``--smoke`` uses
tiny sizes (what the test suite runs); the gallery shows the full sizes (about 10 s).
"""

# %%
# The scene and the initial data
# ------------------------------
# The paper's §3.4 initial data: positions uniform on the unit cube, velocities uniform on
# ``[-1, 1]^d``.

import argparse

import matplotlib.pyplot as plt
import numpy as np

from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.integrate import SaveAt, simulate
from kinred.observables import flocking_verdict
from kinred.projection import jl_matrix

ap = argparse.ArgumentParser(description="Flocking, full and projected")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
ap.add_argument("--beta", type=float, default=1.5)
args = ap.parse_args()
N, d, T = (40, 50, 2.0) if args.smoke else (200, 200, 30.0)
ks = [20, 10] if args.smoke else [100, 30, 10]
dt = 0.02

rng = np.random.default_rng(0)
x0 = rng.uniform(0.0, 1.0, (N, d))
v0 = rng.uniform(-1.0, 1.0, (N, d))
# The paper's §3.4 runs N = 1000 agents with (in kinred's conventions) G = 0.8 and
# normalize="sum" (docs: dynamics). With fewer agents keep the same total coupling N·G.
G = 0.8 * 1000 / N
scene = Scene([Alignment(CuckerSmale(G=G, beta=args.beta))], normalize="sum")
save = SaveAt(every=int(round(T / dt / 50)), observables=("gamma",), states=True)

# %%
# Full and projected runs
# -----------------------
# Forward Euler for both; ``M x_i(t)`` is compared with the projected agents at every saved
# time.

full = simulate(scene, x0, v0, t_span=(0.0, T), dt=dt, save=save)
g_full = full.observables["gamma"][-1]
print(f"Cucker-Smale, N={N}, d={d}, G={G:g}, beta={args.beta}, T={T}, Euler dt={dt}")
print(f"{'k':>5} {'Gamma(T)':>10} {'verdict':>8} {'max_i,t |y_i - M x_i|':>22} {'seconds':>8}")
print(f"{'full':>5} {g_full:10.2e} {flocking_verdict(g_full):>8} {'':>22} {full.wall_time:8.2f}")
runs = {}
for k in ks:
    M = jl_matrix(k, d, kind="gaussian", seed=k)
    low_scene, y0, w0 = scene.projected(M, x0, v0)     # eq. (3.5) from (M x0, M v0)
    low = simulate(low_scene, y0, w0, t_span=(0.0, T), dt=dt, save=save)
    Mx = full.x @ M.T                                   # M x_i(t), all saved times
    err_t = np.linalg.norm(low.x - Mx, axis=-1).max(axis=1)
    runs[k] = (low, err_t)
    g = low.observables["gamma"][-1]
    print(f"{k:>5} {g:10.2e} {flocking_verdict(g):>8} {err_t.max():22.3e} {low.wall_time:8.2f}")
print("done")

# %%
# Γ(t) and the trajectory error
# -----------------------------
# Left: the velocity fluctuation Γ(t) of the full system and of each projection, with the
# paper's two thresholds. Right: the distance between the projected agents and the projected
# full trajectory, which grows as ``k`` falls.

fig, (ax, ax_e) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
ax.semilogy(full.t, full.observables["gamma"], "k-", lw=2, label=f"full, d = {d}")
for k, (low, err_t) in runs.items():
    ax.semilogy(low.t, low.observables["gamma"], label=f"projected, k = {k}")
    ax_e.plot(low.t, err_t, label=f"k = {k}")
ax.axhline(1e-10, color="tab:green", ls=":", label="1e-10 (flocking)")
ax.axhline(1e-3, color="tab:red", ls=":", label="1e-3 (no flocking)")
ax.set_xlabel("time t")
ax.set_ylabel("velocity fluctuation Γ(t)")
ax.set_title(f"Cucker–Smale, N = {N}, β = {args.beta}")
ax.legend(fontsize="small")
ax_e.set_xlabel("time t")
ax_e.set_ylabel("max_i ‖y_i(t) − M x_i(t)‖")
ax_e.set_title("Trajectory error of the projected run")
ax_e.legend(fontsize="small")
plt.show()
