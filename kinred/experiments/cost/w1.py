"""W1 method.

Two Gaussian clouds in ℝᵈ, ``N(0, I)`` and ``N(0.3, I)`` with ``N = M`` atoms, growing ``N``:
exact dense, exact lazy (up to ``lazy_max`` atoms) and the certified bracket (eq. (4.5)) of
:func:`kinred.distance.w1`. Accuracy: ``|value − W1|/W1`` and, for the bracket, the certified
relative width ``(upper − lower)/W1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._validate import as_int
from ._base import Study, StudyConfig, clock

_STYLES = (("exact", "o-"), ("exact-lazy", "s-"), ("bracket", "^-"))


@dataclass(frozen=True)
class W1Config(StudyConfig):
    """Sizes of the two clouds (defaults: the full study)."""

    study = "w1"
    _QUICK = dict(sizes=(100, 200, 400, 800), lazy_max=800)
    _SMOKE = dict(sizes=(50, 100, 200), lazy_max=200)

    d: int = 5
    sizes: tuple = (100, 200, 400, 800, 1600, 3200)
    #: the exact-lazy method is timed up to this many atoms (0: never)
    lazy_max: int = 1600

    def __post_init__(self):
        self._ints("d", low=1)
        self._ints("lazy_max", low=0)
        self._each("sizes", as_int, low=2)


class W1Study(Study):
    """Exact dense, exact lazy and certified bracket W1 as the clouds grow."""

    name = "w1"
    title = "W1 method"
    Config = W1Config
    key = 5

    def n_units(self, cfg: W1Config) -> int:
        return len(cfg.sizes)

    def run(self, cfg: W1Config, *, seed: int, bar) -> dict:
        from ...distance import w1

        d = cfg.d
        rows = []
        w1(np.zeros((2, d)), np.ones((2, d)), "exact")  # warm-up (POT import)
        for n in cfg.sizes:
            rng = self.rng(seed, int(n))
            x = rng.standard_normal((n, d))
            y = rng.standard_normal((n, d)) + 0.3
            ex, t_ex = clock(lambda: w1(x, y, "exact"))
            W = ex.value
            rows.append(dict(N=int(n), method="exact", time_s=t_ex, value=W, rel_error=0.0,
                             rel_width=0.0))
            if n <= cfg.lazy_max:
                lz, t_lz = clock(lambda: w1(x, y, "exact-lazy"))
                rows.append(dict(N=int(n), method="exact-lazy", time_s=t_lz, value=lz.value,
                                 rel_error=abs(lz.value - W) / W, rel_width=0.0))
            br, t_br = clock(lambda: w1(x, y, "bracket", seed=seed))
            rows.append(dict(N=int(n), method="bracket", time_s=t_br, value=br.value,
                             lower=br.lower, upper=br.upper, rel_error=abs(br.value - W) / W,
                             rel_width=(br.upper - br.lower) / W))
            bar.update(1)
        return dict(setting=dict(d=d, clouds="N(0, I) vs N(0.3, I), N = M atoms"), rows=rows)

    def table(self, result: dict):
        from ...report import Table

        return Table(["N", "method", "time [s]", "value", "|value-W1|/W1", "certified width/W1"],
                     [[x["N"], x["method"], x["time_s"], x["value"], x["rel_error"],
                       x["rel_width"]] for x in result["rows"]])

    def figure(self, result: dict, plt):
        w = result
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
        for m, style in _STYLES:
            rs = [x for x in w["rows"] if x["method"] == m]
            if rs:
                axes[0].loglog([x["N"] for x in rs], [x["time_s"] for x in rs], style, label=m)
        axes[0].set_xlabel("atoms N = M")
        axes[0].set_ylabel("wall time [s]")
        axes[0].set_title(f"W1 methods, d = {w['setting']['d']}")
        axes[0].legend(fontsize=8)
        _draw_bracket(axes[1], w)
        return fig

    def headline(self, result: dict, cfg: W1Config) -> dict:
        w = result
        n = max(x["N"] for x in w["rows"])
        by = {x["method"]: x for x in w["rows"] if x["N"] == n}
        text = f"at N = {n} in d = {w['setting']['d']}: exact {by['exact']['time_s']:.2g} s"
        if "exact-lazy" in by:
            text += f", exact-lazy {by['exact-lazy']['time_s'] / by['exact']['time_s']:.2g}x that"
        b = by["bracket"]
        text += (f", certified bracket {b['time_s'] / by['exact']['time_s']:.2g}x the exact time "
                 f"with relative width {100 * b['rel_width']:.2g}%")
        return {"w1": dict(N=n, text=text)}


def _draw_bracket(ax, w: dict) -> None:
    """Right panel: certified width and error of the bracket against time."""
    rs = [x for x in w["rows"] if x["method"] == "bracket"]
    ax.loglog([x["time_s"] for x in rs], [x["rel_width"] for x in rs], "^-",
              label="bracket: certified (upper-lower)/W1")
    ax.loglog([x["time_s"] for x in rs], [max(x["rel_error"], 1e-16) for x in rs], "v:",
              label="bracket: |value - W1|/W1")
    for x in rs:
        ax.annotate(f"N={x['N']}", (x["time_s"], x["rel_width"]), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    for x in w["rows"]:
        if x["method"] == "exact":
            ax.axvline(x["time_s"], color="0.8", lw=0.8)
    ax.set_xlabel("wall time [s] (grey lines: exact at each N)")
    ax.set_ylabel("relative accuracy")
    ax.set_title("bracket accuracy vs time (exact methods: 0 error)")
    ax.legend(fontsize=8)


STUDY = W1Study()
