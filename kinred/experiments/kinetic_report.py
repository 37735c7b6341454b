"""Figures and ``report.html`` of a :mod:`kinred.experiments.kinetic_run` result.

:func:`figures` draws the report's figures (each in a guarded call,
:func:`kinred.report.draw_figure`) and :func:`report` builds the
:class:`kinred.report.Report`; :func:`kinred.experiments.kinetic_run.write_outputs` calls both
after the numbers are on disk.
"""

from __future__ import annotations

import numpy as np

__all__ = ["figures", "report"]


def _fig_w1(plt, result):
    from ..report import fit_log_axis, legend, log_plot

    t = result.t
    fig, ax = plt.subplots(figsize=(8, 5))
    for k, r in result.per_k.items():
        line = log_plot(ax, t[1:], r["w1"][1:], "-o", ms=3, label=f"W1, k={k}")
        color = None if line is None else line.get_color()
        log_plot(ax, t[1:], r["term_jl"][1:], "--", color=color, lw=1, label=f"√2·D(t)·ε_JL, k={k}")
        if "w1_reference" in r:
            log_plot(ax, t[1:], r["w1_reference"][1:], ":", color=color, lw=1.5,
                     label=f"reference N'={result.high.get('n_atoms_reference')}, k={k}")
    fit_log_axis(ax)
    ax.set_xlabel("t")
    ax.set_ylabel("W1 on R^{2k}")
    ax.set_title("W1(M#μᴺ(t), νᴺ(t)) (exact) and Theorem 3.1's term of the bound")
    legend(ax, fontsize=7, ncol=2)
    return fig


def _fig_bound(plt, result):
    from ..report import fit_log_axis, legend, log_plot

    k0 = result.config.ks[0]
    fig, ax = plt.subplots(figsize=(8, 5))
    for k, r in result.per_k.items():
        log_plot(ax, result.t, r["bound"], label=f"bound, k={k}")
    log_plot(ax, result.t, result.per_k[k0]["term_quant"], "k:", label=f"2C(t)‖M‖ε, k={k0}")
    fit_log_axis(ax)
    ax.set_xlabel("t")
    ax.set_title("Theorem 4.3: 2C(t)‖M‖ε + √2·D(t)·ε_JL")
    legend(ax, fontsize=8)
    return fig


def _fig_observables(plt, result):
    from ..report import finite_values, fit_log_axis, legend, log_plot

    cfg, t = result.config, result.t
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    log_plot(axes[0], t, result.high["gamma"], "k-", lw=2, label=f"μᴺ, d={cfg.d}")
    for k, r in result.per_k.items():
        log_plot(axes[0], t, r["gamma"], label=f"νᴺ, k={k}")
        axes[1].plot(t, finite_values(r["milling"]), label=f"νᴺ, k={k}")
    axes[1].plot(t, finite_values(result.high["milling"]), "k-", lw=2, label=f"μᴺ, d={cfg.d}")
    fit_log_axis(axes[0])
    axes[0].set_title("velocity fluctuation Γ(t)")
    axes[1].set_title("milling index (angular momentum)")
    for ax in axes:
        ax.set_xlabel("t")
        legend(ax, fontsize=7)
    return fig


def _fig_positions(plt, result):
    k0 = result.config.ks[0]
    y = np.asarray(result.per_k[k0]["y_final"], dtype=float)
    y = y[np.all(np.isfinite(y), axis=1)]
    fig, ax = plt.subplots(figsize=(5.5, 5))
    ax.scatter(y[:, 0], y[:, 1] if y.shape[1] > 1 else np.zeros(len(y)), s=6)
    ax.set_title(f"reduced positions at T, k={k0} (first two coordinates)")
    ax.set_aspect("equal", adjustable="datalim")
    return fig


def figures(result):
    """The report's figures, each drawn in a guarded call (a list of DrawnFigure)."""
    from ..report import draw_figure

    k0 = result.config.ks[0]
    return [
        draw_figure("w1_vs_time.png", "W1 between projected and reduced solutions, with the "
                    "bound's √2·D(t)·ε_JL term (dashed)", _fig_w1, result),
        draw_figure("bound.png", "The right-hand side of eq. (4.17) with the proof's constants",
                    _fig_bound, result),
        draw_figure("observables.png", "Flocking (Γ) and milling observables", _fig_observables,
                    result),
        draw_figure("positions_final.png", f"Reduced particle positions at T (k={k0})",
                    _fig_positions, result),
    ]

def _k_table(result, k, r):
    from ..report import Table

    rows = []
    for i, ti in enumerate(result.t):
        row = [float(ti), float(r["w1"][i]), bool(r["exact"][i]), float(r["coupling"][i]),
               float(r["uniform"][i]), float(r["term_jl"][i]), float(r["term_quant"][i]),
               float(r["bound"][i]), float(r["eps_jl"][i]), float(r["C"][i])]
        if "w1_reference" in r:
            row += [float(r["w1_reference"][i]), float(r["w1_quantization"][i])]
        rows.append(row)
    head = ["t", "W1 (exact)", "exact", "coupling ≥ W1", "E(t)", "√2·D·ε_JL", "2C‖M‖ε",
            "bound", "ε_JL", "C(t)"]
    if "w1_reference" in r:
        head += ["W1 ref (estimate of W1(μ_M,ν))", "W1(μᴺ, μᴺ′) on R^{2d}"]
    return Table(head, rows, caption=f"k = {k}: measured vs bound over time")


def report(result, figures):
    from ..report import Report

    cfg = result.config
    rep = Report(f"kinred run: {cfg.title}",
                 subtitle=(cfg.description + " " if cfg.description else "") +
                 f"d = {cfg.d}, N = {result.n_atoms} atoms (quantization bound ε = {result.eps:.4g}), "
                 f"k ∈ {list(cfg.ks)} ({cfg.kind}), {cfg.method} dt = {cfg.dt:g}, T = {cfg.t_final:g}"
                 + (" [smoke sizes]" if cfg.smoke else "") + f"; wall time {result.wall_time:.1f} s.")
    s = rep.section("Summary", [
        "W1(M#μᴺ(t), νᴺ(t)) is exact (POT network simplex on the two atomic measures on R^{2k}). "
        "The bound is the right-hand side of eq. (4.17) as its proof yields it: "
        "2C(t)‖M‖ε + √2·D(t)·ε_JL with C(t) = exp(Λt) (Dobrushin stability), D(t)·ε_JL the RHS of "
        "eq. (3.7) with α, β, ε_JL measured on the trajectories (running maxima at saved times) "
        "and L, L′, L″ from the effects' kernels (docs/kinetic.md). The bound is not tuned.",
        "Flocking verdict: the paper's rule on Γ(T): pos if < %g, neg if > %g, n/a otherwise."
        % (cfg.yes_below, cfg.no_above)])
    s.tables.append(result.table())
    for k, r in result.per_k.items():
        sec = rep.section(f"k = {k}", [
            f"‖M‖ = {float(r['norm_M']):.4g}; final constants: α = {float(r['alpha'][-1]):.4g}, "
            f"β = {float(r['beta'][-1]):.4g}, L = {float(r['L']):g}, L′ = {float(r['Lp'][-1]):.4g}, "
            f"L″ = {float(r['Lpp'][-1]):.4g}, Λ = {float(r['Lambda'][-1]):.4g}."])
        sec.tables.append(_k_table(result, k, r))
    fsec = rep.section("Figures")
    for drawn in figures:
        fsec.add_drawn(drawn)
    return rep
