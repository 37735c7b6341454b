r"""Figures and ``report.html`` of a :mod:`kinred.experiments.kinetic_run` result.

:func:`figures` draws the report's four figures (each in a guarded call,
:func:`kinred.report.draw_figure`) and :func:`report` builds the
:class:`kinred.report.Report`; :func:`kinred.experiments.kinetic_run.write_outputs` calls both
after the numbers are on disk. The report shows its figures first and folds the per-time
tables below them (HTML ``<details>``):

1. ``w1_vs_time.png``: the measured ``W1(M#μᴺ(t), νᴺ(t))`` per k with, when the result has
   them, its certified bound (``cert_w1``) and the reference estimate, on a log axis fitted to
   these curves only; below it, with certificates, the measured particle errors and their
   certified bounds (``err_rms``/``cert_rms``, ``err_max``/``cert_max``);
2. ``bound.png``: the a-priori bound of Theorem 4.3 (eq. (4.17)) with its quantization term,
   beside the diameter of the cloud when known: a bound above the diameter is vacuous (any two
   measures on the cloud are closer) and drawn over a shaded band;
3. ``observables.png``: Γ(t) with the flocking rule's thresholds, and the milling index only
   for scenes with self-propulsion or a Morse potential (the effects that make mills);
4. ``positions_final.png``: the original system at T (its positions when d ≤ 2, otherwise
   the first two coordinates of ``Mx`` for the first k's matrix) beside the reduced one
   (first two coordinates; a weighted histogram when k = 1), over the projected original.

Every figure works with and without the certificate arrays (``err_rms``, ``err_max``,
``cert_rms``, ``cert_max``, ``cert_w1``, ``paper_rms``, ``cert_saturated``, ``cert_note``,
``vacuous`` per k; ``diameter`` in ``result.high``); every curve is labelled measured,
certified bound, a-priori bound or estimate.
"""

from __future__ import annotations

import numpy as np

from ._kinetic_tables import k_table, method_text, shows_milling, summary_table, vacuous

__all__ = ["figures", "report", "shows_milling"]

_T = r"time $t$ (scene units)"


def _has(r, key) -> bool:
    """Whether the k stage ``r`` (a :class:`~kinred.experiments.kinetic_run.KStage`, or a
    mapping of its arrays) has array ``key`` with a finite value (a k that was not certified
    has NaN certificate arrays)."""
    return key in r and bool(np.any(np.isfinite(np.asarray(r[key], dtype=float))))


def _after_start(t):
    """Saved times after t = 0 (where measured errors are round-off), or all of them."""
    sel = np.asarray(t) > 0
    return sel if np.any(sel) else np.ones(len(t), bool)


def _w1_panel(ax, result, colors, leg):
    from ..report import fit_log_axis, log_plot

    t = result.t
    sel = _after_start(t)
    n_ref = result.high.get("n_atoms_reference")
    ref = f" ($N'$ = {n_ref})" if n_ref else ""
    for k, r in result.per_k.items():
        c = colors[k]
        line = log_plot(ax, t[sel], r["w1"][sel], "-o", color=c, ms=3, lw=1.8)
        leg.system(f"k = {k}", c, line)
        leg.style("-", "measured (exact)", line, "o")
        if "cert_w1" in r:
            line = log_plot(ax, t[sel], np.asarray(r["cert_w1"])[sel], "--", color=c, lw=1.3)
            leg.system(f"k = {k}", c, line)
            leg.style("--", "certified bound", line)
        if "w1_reference" in r:
            line = log_plot(ax, t[sel], r["w1_reference"][sel], ":", color=c, lw=1.8)
            leg.system(f"k = {k}", c, line)
            leg.style(":", f"estimate of $W_1(\\mu_M, \\nu)${ref}", line)
    fit_log_axis(ax)
    ax.set_xlabel(_T)
    ax.set_ylabel(r"$W_1$ on $\mathbb{R}^{2k}$ (scene units)")
    ax.set_title(r"$W_1(M_\#\mu^N(t),\,\nu^N(t))$: measured, certified bound, estimate")


def _error_panel(ax, result, colors, measured, cert, what):
    from ..report import fit_log_axis, log_plot
    from ..report import StyleLegend

    t = result.t
    sel = _after_start(t)
    leg = StyleLegend()
    for k, r in result.per_k.items():
        if measured in r:
            line = log_plot(ax, t[sel], np.asarray(r[measured])[sel], "-", color=colors[k])
            leg.system(f"k = {k}", colors[k], line)
            leg.style("-", "measured", line)
        if cert in r:
            line = log_plot(ax, t[sel], np.asarray(r[cert])[sel], "--", color=colors[k])
            leg.system(f"k = {k}", colors[k], line)
            leg.style("--", "certified bound", line)
    fit_log_axis(ax)
    ax.set_xlabel(_T)
    ax.set_ylabel(f"{what} of $(y - Mx,\\ w - Mv)$")
    ax.set_title(f"particle error, {what}", fontsize=10)
    leg.draw(ax, outside=False, fontsize=7)


def _fig_w1(plt, result):
    from ..report import StyleLegend, k_colors

    colors = k_colors(result.per_k)
    with_err = any(_has(r, "err_rms") or _has(r, "err_max") for r in result.per_k.values())
    if with_err:
        fig = plt.figure(figsize=(10, 8.6), layout="constrained")
        grid = fig.add_gridspec(2, 2, height_ratios=(1.3, 1.0))
        ax = fig.add_subplot(grid[0, :])
        _error_panel(fig.add_subplot(grid[1, 0]), result, colors, "err_rms", "cert_rms",
                     "weighted RMS")
        _error_panel(fig.add_subplot(grid[1, 1]), result, colors, "err_max", "cert_max",
                     "max over atoms")
    else:
        fig, ax = plt.subplots(figsize=(9, 5), layout="constrained")
    leg = StyleLegend()
    _w1_panel(ax, result, colors, leg)
    leg.draw(ax)
    return fig


def _fig_bound(plt, result):
    from ..report import fit_log_axis, log_plot
    from ..report import StyleLegend, k_colors, note_not_drawn, shade_above

    t, colors = result.t, k_colors(result.per_k)
    fig, ax = plt.subplots(figsize=(9, 5), layout="constrained")
    leg, missing = StyleLegend(), []
    for k, r in result.per_k.items():
        c = colors[k]
        line = log_plot(ax, t, r["bound"], "-", color=c, lw=1.8)
        bad = np.count_nonzero(~(np.asarray(r["bound"], float) > 0) |
                               ~np.isfinite(np.asarray(r["bound"], float)))
        if bad:
            missing.append(f"k = {k} at {bad} of {len(t)} saved times")
        leg.system(f"k = {k}", c, line)
        leg.style("-", "a-priori bound, eq. (4.17)", line)
        q = log_plot(ax, t, r["term_quant"], ":", color=c, lw=1.3)
        leg.system(f"k = {k}", c, q)
        leg.style(":", r"its term $2C(t)\|M\|\varepsilon$", q)
        if "paper_rms" in r:
            p = log_plot(ax, t, r["paper_rms"], "-.", color=c, lw=1.2)
            leg.system(f"k = {k}", c, p)
            leg.style("-.", "a-priori bound of the RMS error, eq. (2.18)", p)
        if "vacuous" in r and line is not None:
            vac = np.asarray(r["vacuous"], bool) & np.isfinite(line.get_ydata())
            if np.any(vac):
                mark = ax.plot(t[vac], np.asarray(line.get_ydata())[vac], "x", color=c, ms=5)
                leg.style("", "vacuous (a-priori bound > diameter)", mark, "x")
    diam = result.high.get("diameter")
    dline = None if diam is None else log_plot(ax, t, diam, "k-", lw=2.5)
    leg.system("diameter of the cloud (upper bound)", "black", dline)
    fit_log_axis(ax)
    if dline is not None:
        leg.patch("vacuous region: above the diameter", "#f3c4c4", shade_above(ax, t, diam))
    note_not_drawn(ax, "a-priori bound", missing)
    if len(t) > 1:
        ax.set_xlim(t[0], t[-1])
    ax.set_xlabel(_T)
    ax.set_ylabel(r"a-priori bound on $W_1$ on $\mathbb{R}^{2k}$ (scene units)")
    ax.set_title(r"Theorem 4.3: $2C(t)\|M\|\varepsilon + \sqrt{2}\,D(t)\,\varepsilon_{JL}$"
                 " (proof's constants)")
    leg.draw(ax)
    return fig


def _fig_observables(plt, result):
    from ..report import finite_values, fit_log_axis, log_plot
    from ..report import StyleLegend, k_colors

    cfg, t, colors = result.config, result.t, k_colors(result.per_k)
    mill = shows_milling(cfg)
    fig, axes = plt.subplots(1, 2 if mill else 1, figsize=(12, 4.6) if mill else (9, 4.6),
                             squeeze=False, layout="constrained")
    ax = axes[0, 0]
    leg = StyleLegend()
    leg.system(f"original $\\mu^N$, $d$ = {cfg.d}", "black",
               log_plot(ax, t, result.high["gamma"], "k-", lw=2.5))
    for k, r in result.per_k.items():
        leg.system(f"reduced $\\nu^N$, $k$ = {k}", colors[k],
                   log_plot(ax, t, r["gamma"], "-", color=colors[k], lw=1.5))
    for level in (cfg.yes_below, cfg.no_above):
        leg.style("--", f"flocking rule: pos < {cfg.yes_below:g}, neg > {cfg.no_above:g}",
                  ax.axhline(level, color="0.45", ls="--", lw=0.9))
    fit_log_axis(ax)
    ax.set_xlabel(_T)
    ax.set_ylabel(r"$\Gamma(t)$, measured (velocity$^2$ units)")
    ax.set_title(r"velocity fluctuation $\Gamma(t) = \sum_i w_i\,|v_i - v_c|^2$")
    if mill:
        ax2 = axes[0, 1]
        ax2.plot(t, finite_values(result.high["milling"]), "k-", lw=2.5)
        for k, r in result.per_k.items():
            if k > 1 and np.any(np.isfinite(r["milling"])):   # 0 by definition when k = 1
                ax2.plot(t, finite_values(r["milling"]), "-", color=colors[k], lw=1.5)
        ax2.set_ylim(-0.03, 1.03)
        ax2.set_xlabel(_T)
        ax2.set_ylabel("milling index, measured (dimensionless)")
        ax2.set_title("milling index: 1 for a mill, 0 for a straight flock")
    leg.draw(axes[0, -1])
    return fig


def _projection(cfg, k):
    """The JL matrix of the reduced system ``k`` (the draw of ``kinetic_run``'s stage k)."""
    from .._rng import member_seed
    from ..projection import jl_matrix

    return jl_matrix(k, cfg.d, kind=cfg.kind, seed=member_seed(cfg.projection_seed, k))


#: At most this many reduced systems get a panel in ``positions_final.png``.
MAX_POSITION_PANELS = 5


def positions_data(result):
    """The atoms at T drawn by ``positions_final.png``: ``(original, weights, {k: (Mx, y)})``.

    ``original`` is the first two coordinates of the original positions ``x`` (all of them
    when ``d ≤ 2``; ``None`` when the result does not hold ``high["x_final"]``); for each of
    the first :data:`MAX_POSITION_PANELS` values of k, ``Mx`` (the projected original, or
    ``None``) and ``y`` (the reduced positions), first two coordinates each.
    """
    cfg = result.config
    x = result.high.get("x_final")
    x = None if x is None else np.asarray(x, dtype=float)
    panels = {}
    for k in list(cfg.ks)[:MAX_POSITION_PANELS]:
        y = np.asarray(result.per_k[k]["y_final"], dtype=float)[:, :2]
        panels[k] = (None if x is None else _projection(cfg, k).apply(x)[:, :2], y)
    return (None if x is None else x[:, :2]), result.high.get("weights"), panels


def _fig_positions(plt, result):
    from ..report import cloud_bins, k_colors, point_cloud

    cfg, colors = result.config, k_colors(result.per_k)
    orig, w, panels = positions_data(result)
    n = 1 + len(panels)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.3 * cols, 4.0 * rows), squeeze=False,
                             layout="constrained")
    axes = axes.ravel()
    for ax in axes[n:]:
        ax.set_axis_off()
    title = f"original system at $T$ = {cfg.t_final:g}, $d$ = {cfg.d}"
    if orig is None:
        axes[0].text(0.5, 0.5, "the original atoms are not in this result", ha="center",
                     transform=axes[0].transAxes)
        axes[0].set_axis_off()
    else:
        point_cloud(axes[0], orig, w, color="black")
        _cloud_axes(axes[0], orig, "x", title)
    for ax, (k, (mx, y)) in zip(axes[1:], panels.items()):
        bins = cloud_bins(y[:, 0] if mx is None else np.r_[y[:, 0], mx[:, 0]])
        bins = bins if y.shape[1] == 1 else None
        if mx is not None:
            point_cloud(ax, mx, w, background=True, bins=bins,
                        label="projected original $M_\\#\\mu^N(T)$")
        point_cloud(ax, y, w, color=colors[k], bins=bins, label=f"reduced $\\nu^N(T)$")
        _cloud_axes(ax, y, "y", f"reduced system at $T$, $k$ = {k}")
    planar = [(ax, mx, y) for ax, (mx, y) in zip(axes[1:], panels.values()) if y.shape[1] > 1]
    _same_limits([(ax, np.vstack([y] if mx is None else [y, mx])) for ax, mx, y in planar])
    if len(axes) > 1:   # one legend for the reduced panels, below them: it covers no point
        handles, labels = axes[1].get_legend_handles_labels()
        if handles:
            fig.legend(handles, labels, loc="outside lower center", ncols=len(handles),
                       fontsize=8, markerscale=1.5)
    return fig


def _same_limits(panels) -> None:
    """Give every ``(ax, points)`` panel the same square x- and y-range (enclosing all of
    the points), so that the reduced systems for different k compare at a glance."""
    if not panels:
        return
    pts = np.vstack([p[:, :2] for _, p in panels])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if not len(pts):
        return
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid = (lo + hi) / 2
    half = 1.06 * max(float(np.max(hi - lo)) / 2, 1e-9 * max(1.0, float(np.max(np.abs(mid)))))
    for ax, _ in panels:
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)


def _cloud_axes(ax, pts, name, title):
    ax.set_title(title, fontsize=10)
    if pts is None:
        return
    if pts.shape[1] == 1:
        ax.set_xlabel(f"${name}_1$, position (scene units)")
        ax.set_ylabel("density of the atoms' weight (1 / scene unit)")
    else:
        ax.set_xlabel(f"${name}_1$, position (scene units)")
        ax.set_ylabel(f"${name}_2$, position (scene units)")
        ax.set_aspect("equal", adjustable="datalim")


#: Why a figure of a run started with ``figures=False`` (``--no-figures``) has no PNG.
NOT_DRAWN = "the run was asked not to draw figures (--no-figures)"


def figures(result, *, draw: bool = True):
    """The report's figures, each drawn in a guarded call (a list of DrawnFigure); with
    ``draw=False`` none is drawn: each carries its caption and ``NOT_DRAWN`` as the reason."""
    from ..report import DrawnFigure, draw_figure

    def not_drawn(name, caption, *_):
        return DrawnFigure(name, caption, None, NOT_DRAWN)

    figure = draw_figure if draw else not_drawn

    cfg, k0 = result.config, result.config.ks[0]
    ref = result.high.get("n_atoms_reference")
    has_cert = any(_has(r, "cert_w1") for r in result.per_k.values())
    w1_cap = ("W₁(M#μᴺ(t), νᴺ(t)) on phase space ℝ²ᵏ, per k: measured exactly (solid)"
              + (", its certified bound (dashed)" if has_cert else "")
              + (f", and the estimate of W₁(μ_M(t), ν(t)) from a reference with N′ = {ref} "
                 "atoms (dotted)" if ref else "")
              + ". The axis spans these curves only; the a-priori bound is the next figure.")
    if any(_has(r, "err_rms") for r in result.per_k.values()):
        w1_cap += (" Below: the particle errors (y − Mx, w − Mv), measured (solid) and "
                   "certified (dashed).")
    notes = {k: str(r.get("cert_note", "")).strip() for k, r in result.per_k.items()}
    notes = {k: n for k, n in notes.items() if n}
    if len(set(notes.values())) == 1 and len(notes) == len(result.per_k):
        notes = [f" Certificate: {next(iter(notes.values()))}."]
    else:
        notes = [f" Certificate, k = {k}: {n}." for k, n in notes.items()]
    sat = [str(k) for k, r in result.per_k.items() if np.any(r.get("cert_saturated", False))]
    if sat:
        w1_cap += (f" Certificate saturated for k = {', '.join(sat)}: there the bound only says "
                   "that the reduced run has left the projected one.")
    w1_cap += "".join(notes)
    diam = result.high.get("diameter")
    b_cap = ("A-priori bound of Theorem 4.3 (right-hand side of eq. (4.17), constants of its "
             "proof measured on this run) per k, with its quantization term (dotted)"
             + (", beside an upper bound of the diameter of supp μᴺ(t) in ℝ²ᵈ (black): above "
                "it (shaded) the bound says nothing about a cloud of that size (vacuous)"
                if diam is not None else "; the cloud's diameter is not in this result")
             + ".")
    o_cap = ("Velocity fluctuation Γ(t), measured, of the original system (black) and of the "
             "reduced ones, with the flocking rule's thresholds (dashed)"
             + (", and the milling index, measured (not drawn for k = 1, where it is 0 by "
                "definition)." if shows_milling(cfg) else
                "; no milling index: the scene has no self-propulsion or Morse effect."))
    shown = list(cfg.ks)[:MAX_POSITION_PANELS]
    p_cap = (f"Positions at T = {cfg.t_final:g}. First panel, the original system: "
             + ("its positions x" if cfg.d <= 2 else
                f"the first two of its d = {cfg.d} position coordinates")
             + f". Then the reduced system for k = {', '.join(map(str, shown))}: the first "
             "two coordinates of y" + (" (a weighted histogram for k = 1)" if 1 in shown else "")
             + ", over the projected original Mx with the same M (grey). Marker area ∝ atom "
             "weight.")
    return [figure("w1_vs_time.png", w1_cap, _fig_w1, result),
            figure("bound.png", b_cap, _fig_bound, result),
            figure("observables.png", o_cap, _fig_observables, result),
            figure("positions_final.png", p_cap, _fig_positions, result)]


def vacuous_throughout(result) -> bool:
    """Whether the a-priori bound is vacuous (above the cloud's diameter) at every saved time
    for every k: then the report folds its figure, which would show nothing but the region
    above the diameter."""
    flags = [vacuous(result, r) for r in result.per_k.values()]
    return bool(flags) and all(f is not None and f.size and f.all() for f in flags)


def report(result, figures):
    """The :class:`kinred.report.Report` of a run: figures, summary, folded per-time tables."""
    from ..report import Report

    cfg = result.config
    # a scene title that already names its command ("kinred demo: ...") is not prefixed again
    title = cfg.title if cfg.title.startswith("kinred ") else f"kinred run: {cfg.title}"
    rep = Report(title,
                 subtitle=(cfg.description.rstrip(".") + ". " if cfg.description else "") +
                 f"d = {cfg.d}, N = {result.n_atoms} atoms (ε = {result.eps:.4g}, a-priori "
                 f"bound of W₁(μ₀, μ₀ᴺ)), k ∈ {list(cfg.ks)} ({cfg.kind}), {cfg.method} dt = "
                 f"{cfg.dt:g}, T = {cfg.t_final:g}" + (" [smoke sizes]" if cfg.smoke else "")
                 + f"; wall time {result.wall_time:.1f} s.")
    fsec = rep.section("Figures", [
        f"μᴺ(t) is the N-atom particle solution on phase space ℝ²ᵈ (d = {cfg.d} position and "
        f"{cfg.d} velocity coordinates); νᴺ(t) the reduced solution on ℝ²ᵏ started from "
        "M#μ₀ᴺ. Every number is labelled: measured, certified bound, a-priori bound or "
        "estimate. Units are the scene's."])
    folded = vacuous_throughout(result)
    for drawn in figures:
        if not (folded and drawn.name == "bound.png"):
            fsec.add_drawn(drawn)
    if folded:
        rep.section("A-priori bound (vacuous here: above the cloud's diameter at every saved "
                    "time, for every k)", folded=True).add_drawn(
            next(d for d in figures if d.name == "bound.png"))
    s = rep.section("Summary", method_text(result))
    s.tables.append(summary_table(result))
    for k, r in result.per_k.items():
        sec = rep.section(f"Numbers over time, k = {k}", [
            f"‖M‖ = {float(r['norm_M']):.4g}; final constants of the a-priori bound: "
            f"α = {float(r['alpha'][-1]):.4g}, β = {float(r['beta'][-1]):.4g}, "
            f"L = {float(r['L']):g}, L′ = {float(r['Lp'][-1]):.4g}, "
            f"L″ = {float(r['Lpp'][-1]):.4g}, Λ = {float(r['Lambda'][-1]):.4g}."],
            folded=True)
        sec.tables.append(k_table(result, k, r))
    return rep
