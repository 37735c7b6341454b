"""Content of the ``kinred run`` report's figures and HTML (kinred.experiments.kinetic_report).

The figures are inspected as matplotlib objects: which curves are drawn, on which axes, with
which labels and limits; the browser-level checks are in test_report_browser.py.
"""

import dataclasses
import re

import numpy as np
import pytest

from kinred.distance import w1
from kinred.experiments import kinetic_report as kr
from kinred.experiments import kinetic_run
from kinred.report import figure_png
from kinred.report._figures import pyplot

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small_run():
    """SMALL_SCENE: d = 3, Cucker–Smale alignment only, k ∈ {1, 2}, no reference; with the
    pipeline's certificates."""
    return kinetic_run.run(kinetic_run.config_from_dict(kinetic_run.SMALL_SCENE), progress=False)


@pytest.fixture(scope="module")
def small(small_run):
    """The same run without certificates (the tests add made-up ones where they need them)."""
    return _plain(small_run)


@pytest.fixture(scope="module")
def mill():
    """The shipped d = 2 mill scene (self-propulsion + Morse) at smoke size, k ∈ {1, 2}."""
    cfg = kinetic_run.load_config(ROOT / "examples" / "scenes" / "dorsogna-mill-2d.toml",
                                  smoke=True)
    return kinetic_run.run(cfg, progress=False)


@pytest.fixture(scope="module")
def vacuous_report(small):
    """``small`` certified with diameter 1e-6 (the a-priori bound vacuous throughout) and its
    report's figures, drawn once for the module."""
    res = _certified(small, diameter=1e-6)
    return res, kr.figures(res)


#: What a run without certificates lacks (the arrays of kinetic_certify.CERT_KEYS and the
#: cloud's diameter): the report must work without them.
_CERT = ("err_rms", "err_max", "cert_rms", "cert_max", "cert_w1", "cert_saturated", "paper_rms",
         "paper_max", "bound_mixed", "vacuous", "cert_time", "cert_note")


def _plain(result):
    """``result`` without certificate arrays and diameters (as before they existed)."""
    per_k = {k: {n: v for n, v in r.items() if n not in _CERT} for k, r in result.per_k.items()}
    high = {n: v for n, v in result.high.items() if n not in ("diameter", "diameter_lower")}
    return dataclasses.replace(result, per_k=per_k, high=high)


def _with(result, high=None, **per_k_fns):
    """A copy of ``result`` with per-k arrays added or replaced: ``name=f(r)`` for every k."""
    per_k = {k: {**r, **{n: f(r) for n, f in per_k_fns.items()}} for k, r in result.per_k.items()}
    return dataclasses.replace(result, per_k=per_k, high={**result.high, **(high or {})})


def _certified(result, diameter=None):
    """``result`` with certificate arrays of the documented names (values made up, ordered as
    the certificate orders them: measured ≤ certified)."""
    high = None if diameter is None else {"diameter": np.full(len(result.t), diameter)}
    return _with(result, high, cert_w1=lambda r: 3.0 * r["w1"], err_rms=lambda r: 1.5 * r["w1"],
                 cert_rms=lambda r: 4.0 * r["w1"], err_max=lambda r: 2.0 * r["w1"],
                 cert_max=lambda r: 6.0 * r["w1"], paper_rms=lambda r: 0.5 * r["bound"],
                 w1_reference=lambda r: 1.2 * r["w1"], cert_saturated=lambda r: False,
                 cert_note=lambda r: "")


def _draw(fn, result):
    return fn(pyplot(), result)


def _legend_labels(ax):
    leg = ax.get_legend()
    return [] if leg is None else [t.get_text() for t in leg.get_texts()]


def _drawn(line):
    y = np.asarray(line.get_ydata(), float)
    return bool(np.any(np.isfinite(y)))


def _check_legends_name_drawn_curves(fig):
    """Every legend entry has a drawn curve in the figure: same colour (systems) or same line
    style (kinds of curve)."""
    lines = [ln for ax in fig.axes for ln in ax.get_lines() if _drawn(ln)]
    for ax in fig.axes:
        leg = ax.get_legend()
        if leg is None:
            continue
        for handle, text in zip(leg.legend_handles, leg.get_texts()):
            if not hasattr(handle, "get_linestyle") or not hasattr(handle, "get_color"):
                continue
            if handle.get_color() != "black":
                assert any(ln.get_color() == handle.get_color() for ln in lines), text.get_text()
            elif handle.get_linestyle() not in ("None", "none", ""):
                assert any(ln.get_linestyle() == handle.get_linestyle() for ln in lines), \
                    text.get_text()


def _texts(fig):
    out = []
    for ax in fig.axes:
        out += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()] + _legend_labels(ax)
        out += [t.get_text() for t in ax.texts]
    return out


def test_w1_axis_spans_measured_certified_and_estimate_only(small):
    # an a-priori bound of 1e74 (as in the issue) must not stretch the W1 axis
    res = _certified(_with(small, bound=lambda r: np.full(len(r["w1"]), 1e74)))
    fig = _draw(kr._fig_w1, res)
    ax = fig.axes[0]
    sel = res.t > 0
    data = np.concatenate([np.r_[r["w1"][sel], r["cert_w1"][sel], r["w1_reference"][sel]]
                           for r in res.per_k.values()])
    lo, hi = ax.get_ylim()
    assert data.min() / 10 <= lo <= data.min() and data.max() <= hi <= 10 * data.max()
    assert _legend_labels(ax) == ["k = 1", "k = 2", "measured (exact)", "certified bound",
                                  "estimate of $W_1(\\mu_M, \\nu)$"]
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    assert [list(ln.get_ydata()) for ln in dashed] == \
        [list(r["cert_w1"][sel]) for r in res.per_k.values()]
    assert ax.get_ylabel() == r"$W_1$ on $\mathbb{R}^{2k}$ (scene units)"
    # with certificates, two more panels: the particle errors, measured and certified
    assert len(fig.axes) == 3 and "RMS" in fig.axes[1].get_ylabel()
    _check_legends_name_drawn_curves(fig)
    figure_png(fig)


def test_w1_figure_without_certificates_lists_no_bound(small):
    fig = _draw(kr._fig_w1, small)
    assert len(fig.axes) == 1
    assert _legend_labels(fig.axes[0]) == ["k = 1", "k = 2", "measured (exact)"]
    figure_png(fig)


def test_apriori_bound_figure_marks_vacuous_and_skips_infinite(small):
    res = _certified(small, diameter=0.05)
    k_inf = small.config.ks[1]
    per_k = dict(res.per_k)
    per_k[k_inf] = {**per_k[k_inf], "bound": np.full(len(res.t), np.inf),
                    "term_quant": np.full(len(res.t), np.inf),
                    "paper_rms": np.full(len(res.t), np.nan)}
    res = dataclasses.replace(res, per_k=per_k)
    fig = _draw(kr._fig_bound, res)
    ax = fig.axes[0]
    labels = _legend_labels(ax)
    assert f"k = {k_inf}" not in labels and "k = 1" in labels
    assert "diameter of the cloud (upper bound)" in labels
    assert "vacuous region: above the diameter" in labels
    assert any(f"k = {k_inf} at {len(res.t)} of {len(res.t)}" in t.get_text() for t in ax.texts)
    assert ax.collections, "the region above the diameter is shaded"
    lower = ax.collections[0].get_paths()[0].vertices[:, 1]
    assert np.isclose(lower.min(), 0.05)
    assert "a-priori bound" in ax.get_ylabel()
    _check_legends_name_drawn_curves(fig)
    figure_png(fig)


def test_observables_follow_the_scene_effects(small, mill):
    fig = _draw(kr._fig_observables, small)              # alignment only: no milling panel
    assert len(fig.axes) == 1 and "Gamma" in fig.axes[0].get_ylabel()
    assert not kr.shows_milling(small.config) and kr.shows_milling(mill.config)
    fig2 = _draw(kr._fig_observables, mill)
    assert len(fig2.axes) == 2 and "milling" in fig2.axes[1].get_ylabel()
    # milling of k = 1 is 0 by definition: not drawn; the original (black) and k = 2 are
    ys = [np.asarray(ln.get_ydata()) for ln in fig2.axes[1].get_lines()]
    assert len(ys) == 2 and np.allclose(ys[0], mill.high["milling"])
    assert np.allclose(ys[1], mill.per_k[2]["milling"])
    for f in (fig, fig2):
        _check_legends_name_drawn_curves(f)
        figure_png(f)


@pytest.mark.parametrize("which", ["small", "mill"])
def test_positions_show_original_beside_reduced(which, small, mill):
    res = {"small": small, "mill": mill}[which]
    cfg = res.config
    fig = _draw(kr._fig_positions, res)
    axes = [ax for ax in fig.axes if ax.axison]
    assert len(axes) == 1 + len(cfg.ks)
    x = np.asarray(res.high["x_final"])
    assert np.array_equal(axes[0].collections[0].get_offsets(), x[:, :2])   # the original
    for ax, k in zip(axes[1:], cfg.ks):
        r = res.per_k[k]
        if k == 1:   # a weighted histogram, not a line
            assert ax.patches and not ax.get_lines() and "density" in ax.get_ylabel()
        else:
            back, red = ax.collections
            assert np.array_equal(red.get_offsets(), r["y_final"][:, :2])
        # the grey cloud is M#μᴺ(T) for the reduced system's own M: its W1 to νᴺ(T) is the
        # measured W1(T)
        M = kr._projection(cfg, k)
        A = np.c_[M.apply(x), M.apply(res.high["v_final"])]
        B = np.c_[r["y_final"], r["w_final"]]
        wts = res.high["weights"]
        assert w1(A, B, a=wts, b=wts).value == pytest.approx(r["w1"][-1], rel=1e-9, abs=1e-12)
        assert ax.get_xlabel().startswith("$y_1$")
    assert axes[0].get_xlabel().startswith("$x_1$") and axes[0].get_ylabel().startswith("$x_2$")
    figure_png(fig)


@pytest.mark.parametrize("certified", [False, True])
def test_every_axes_labelled_with_mathtext(certified, small, mill):
    for res in (small, mill):
        res = _certified(res, diameter=2.0) if certified else res
        for fn in (kr._fig_w1, kr._fig_bound, kr._fig_observables, kr._fig_positions):
            fig = _draw(fn, res)
            for ax in fig.axes:
                if ax.axison:
                    assert ax.get_xlabel() and ax.get_ylabel(), (fn.__name__, ax.get_title())
            for text in _texts(fig):   # no raw TeX outside $...$
                assert not re.search(r"[\^_]\{", re.sub(r"\$[^$]*\$", "", text)), text
            figure_png(fig)            # mathtext parses


def test_report_html_figures_first_tables_folded(small, vacuous_report):
    res, figures = vacuous_report                          # _certified(small, diameter=1e-6)
    html = kr.report(res, figures).to_html()
    assert html.index("<figure>") < html.index("<table")
    # the a-priori bound is vacuous throughout (diameter 1e-6): its figure is folded too
    assert html.count("<details>") == len(small.config.ks) + 1
    assert html.count("<img") == 4 and html.index("<details>") < html.index("<table")
    first_details = html.index("<details><summary><h2>Numbers over time")
    assert html.count("<table", first_details) == len(small.config.ks)   # per-time: folded
    assert html.count("<table") == len(small.config.ks) + 1               # + the summary
    assert "R^{" not in html and "(vacuous)" in html
    assert "W₁ certified bound" in html and "a-priori bound" in html
    plain = kr.report(small, kr.figures(small)).to_html()
    assert "(vacuous)" not in plain and "W₁ certified bound" not in plain
    assert "milling(T)" not in plain and "no milling index" in plain   # Cucker–Smale only


def test_summary_marks_vacuous_from_diameter_or_flag(small):
    from kinred.experiments._kinetic_tables import summary_table, vacuous

    d = float(np.max(small.per_k[1]["bound"])) * 2          # above every bound: not vacuous
    res = _with(small, {"diameter": np.full(len(small.t), d)})
    assert not vacuous(res, res.per_k[1]).any()
    res = _with(small, {"diameter": np.full(len(small.t), d)},
                vacuous=lambda r: np.ones(len(r["w1"]), bool))  # the flag wins
    assert all("(vacuous)" in str(row[-3]) for row in summary_table(res).rows[1:])
    assert vacuous(small, small.per_k[1]) is None


def test_pipeline_certificates_are_drawn_above_the_measured_w1(small_run):
    res = small_run                         # the certificates kinred run computes itself
    fig = _draw(kr._fig_w1, res)
    ax = fig.axes[0]
    assert "certified bound" in _legend_labels(ax) and len(fig.axes) == 3
    solid = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-"]
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    assert len(solid) == len(dashed) == len(res.per_k)
    for s, d in zip(solid, dashed):        # the certified bound lies on or above the measured W1
        assert np.all(np.asarray(d.get_ydata()) >= np.asarray(s.get_ydata()))
    fig = _draw(kr._fig_bound, res)
    assert "diameter of the cloud (upper bound)" in _legend_labels(fig.axes[0])
    html = kr.report(res, kr.figures(res)).to_html()
    vac = any(bool(np.asarray(r["vacuous"])[-1]) for r in res.per_k.values())
    assert ("(vacuous)" in html) == vac


def test_report_title_subtitle_and_summary_say_each_thing_once(small):
    """Issue 21 item 16: no "kinred run: kinred demo", d stated once, no "0.5^j", no raw keys."""
    from kinred.experiments import demo
    from kinred.experiments.kinetic_certify import CERT_KEYS

    cfg = dataclasses.replace(small.config, title=demo.DEMO_SCENE["title"],
                              description=demo.DEMO_SCENE["description"])
    res = _certified(dataclasses.replace(small, config=cfg), diameter=2.0)
    html = kr.report(res, kr.figures(res)).to_html()
    h1 = re.search(r"<h1>(.*?)</h1>", html).group(1)
    assert h1 == demo.DEMO_SCENE["title"] and "kinred run" not in h1
    subtitle = re.search(r"</h1>\n<p>(.*?)</p>", html).group(1)
    assert subtitle.count("d = ") == 1 and "^" not in subtitle, subtitle
    other = dataclasses.replace(small.config, title="my scene")
    assert "<h1>kinred run: my scene</h1>" in kr.report(
        dataclasses.replace(small, config=other), []).to_html()
    summary = html[html.index("<h2>Summary</h2>"):]
    summary = summary[:summary.index("<h2>", 5)]
    keys = set(CERT_KEYS) | set(kinetic_run.LABELS)
    leaked = sorted(k for k in keys if "_" in k and re.search(rf"\b{k}\b", summary))
    assert not leaked, leaked


def test_positions_reduced_panels_share_ranges_and_legend_covers_no_point(small):
    """Issue 21 item 16: the reduced panels (k ≥ 2) share one range, the legend is outside."""
    per_k = dict(small.per_k)
    per_k[3] = {**per_k[2], "y_final": 10.0 * np.asarray(per_k[2]["y_final"]) + 5.0}
    cfg = dataclasses.replace(small.config, ks=(*small.config.ks, 3))
    res = dataclasses.replace(small, config=cfg, per_k=per_k)
    fig = _draw(kr._fig_positions, res)
    axes = [ax for ax in fig.axes if ax.axison]
    planar = axes[2:]                                  # the original, k = 1, then k = 2, 3
    assert len(planar) == 2
    assert planar[0].get_xlim() == planar[1].get_xlim()
    assert planar[0].get_ylim() == planar[1].get_ylim()
    y3 = per_k[3]["y_final"][:, :2]
    (x0, x1), (y0, y1) = planar[0].get_xlim(), planar[0].get_ylim()
    assert x0 <= y3[:, 0].min() and y3[:, 0].max() <= x1
    assert y0 <= y3[:, 1].min() and y3[:, 1].max() <= y1
    assert all(ax.get_legend() is None for ax in axes) and len(fig.legends) == 1
    figure_png(fig)


def test_apriori_figure_folded_only_when_vacuous_throughout(small, vacuous_report):
    for diameter, folded in ((1e-6, True), (1e6, False)):
        if folded:
            res, figures = vacuous_report                  # _certified(small, diameter=1e-6)
        else:
            res = _certified(small, diameter=diameter)
            figures = kr.figures(res)
        assert kr.vacuous_throughout(res) is folded
        html = kr.report(res, figures).to_html()
        start = html.index("<h2>Figures</h2>")
        figs = html[start:html.index("<h2>", start + 5)]
        assert figs.count("<img") == (3 if folded else 4) and html.count("<img") == 4
        assert ("<details><summary><h2>A-priori bound" in html) is folded
    assert not kr.vacuous_throughout(small)            # no diameter: unknown, not folded


def test_figure_png_of_a_constrained_figure_is_matplotlibs_png(mill):
    # figure_png lays a constrained figure out once and saves it without a layout pass; the
    # bytes are those of matplotlib's own savefig (which lays it out in two draws): the
    # positions, three panels and a figure legend outside the axes
    import io

    res = _certified(mill, diameter=2.0)
    for fn in (kr._fig_positions,):
        fig = _draw(fn, res)
        assert fig.get_layout_engine().__class__.__name__ == "ConstrainedLayoutEngine"
        png = figure_png(fig, dpi=80, close=False)
        assert fig.get_layout_engine().__class__.__name__ == "ConstrainedLayoutEngine"
        pyplot().close(fig)
        buf = io.BytesIO()
        fig = _draw(fn, res)
        fig.savefig(buf, format="png", dpi=80)
        pyplot().close(fig)
        assert png == buf.getvalue(), fn.__name__
