"""W1 method.

Two Gaussian clouds in ℝᵈ, ``N(0, I)`` and ``N(0.3, I)`` with ``N = M`` atoms, growing ``N``:
exact dense, exact lazy (up to ``lazy_max`` atoms), the sparse network simplex certified by
its dual (exact when its bounds meet) and the certified bracket (eq. (4.5)) of
:func:`kinred.distance.w1`. Accuracy: ``|value − W1|/W1`` and, for the bracket, the certified
relative width ``(upper − lower)/W1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._validate import as_int
from ._base import Study, StudyConfig, clock

_STYLES = (("exact", "o-"), ("exact-lazy", "s-"), ("sparse", "D-"), ("bracket", "^-"))


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
    """Exact dense, exact lazy, sparse and certified bracket W1 as the clouds grow."""

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
            sp, t_sp = clock(lambda: w1(x, y, "sparse", seed=seed))
            rows.append(dict(N=int(n), method="sparse", time_s=t_sp, value=sp.midpoint,
                             lower=sp.lower, upper=sp.upper, exact=bool(sp.exact),
                             rel_error=abs(sp.midpoint - W) / W,
                             rel_width=(sp.upper - sp.lower) / W))
            br, t_br = clock(lambda: w1(x, y, "bracket", seed=seed))
            rows.append(dict(N=int(n), method="bracket", time_s=t_br, value=br.midpoint,
                             lower=br.lower, upper=br.upper, rel_error=abs(br.midpoint - W) / W,
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
        if "sparse" in by:
            sp = by["sparse"]
            text += (f", sparse {sp['time_s'] / by['exact']['time_s']:.2g}x that "
                     f"({'exact' if sp.get('exact', True) else 'not exact'}, "
                     f"|value-W1|/W1 = {sp['rel_error']:.1g})")
        b = by["bracket"]
        text += (f", certified bracket {b['time_s'] / by['exact']['time_s']:.2g}x the exact time "
                 f"with relative width {100 * b['rel_width']:.2g}%")
        return {"w1": dict(N=n, text=text)}


def _draw_bracket(ax, w: dict) -> None:
    """Right panel: the certified bracket [lower, upper] as a band around the exact W1, per N
    (everything divided by the exact value, so the band's height is the relative width)."""
    exact = {x["N"]: x["value"] for x in w["rows"] if x["method"] == "exact"}
    rs = sorted((x for x in w["rows"] if x["method"] == "bracket" and exact.get(x["N"])),
                key=lambda x: x["N"])
    n = [x["N"] for x in rs]
    lo = [x["lower"] / exact[x["N"]] for x in rs]
    hi = [x["upper"] / exact[x["N"]] for x in rs]
    ax.fill_between(n, lo, hi, color="C2", alpha=0.25, lw=0,
                    label="certified bracket [lower, upper] (eq. (4.5))")
    ax.plot(n, lo, "-", color="C2", lw=0.8)
    ax.plot(n, hi, "-", color="C2", lw=0.8)
    ax.plot(n, [x["value"] / exact[x["N"]] for x in rs], "^", color="C2",
            label="bracket's returned value")
    ax.axhline(1.0, color="k", lw=1, label="exact W1 (exact, exact-lazy)")
    ax.set_xscale("log")
    ax.set_xticks(n, [str(v) for v in n])
    ax.minorticks_off()
    pad = max([abs(v - 1.0) for v in lo + hi] + [0.01])
    ax.set_ylim(1.0 - 1.3 * pad, 1.0 + 1.3 * pad)
    ax.set_xlabel("atoms N = M")
    ax.set_ylabel("W1 / exact W1")
    ax.set_title("certified bracket around the exact value")
    ax.legend(fontsize=8, loc="upper left")


STUDY = W1Study()
