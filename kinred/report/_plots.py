"""Plot pieces shared by the reports: colours per k, compact legends, vacuous regions, clouds.

Every function takes matplotlib axes made by the caller (the ``Agg`` backend of
:func:`kinred.report._figures.pyplot`); none imports matplotlib at module level.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["k_colors", "StyleLegend", "shade_above", "note_not_drawn", "point_cloud", "cloud_bins",
           "tidy_log_axes"]

#: Colours of the reduced systems, in the order of their k (matplotlib's ``tab10`` without
#: black and grey, which mark the original system and references).
_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
            "#bcbd22", "#17becf")


def k_colors(ks) -> dict:
    """``{k: colour}``, the same in every figure of a report.

    Examples
    --------
    >>> k_colors([2, 5])
    {2: '#1f77b4', 5: '#ff7f0e'}
    """
    return {k: _PALETTE[i % len(_PALETTE)] for i, k in enumerate(ks)}


class StyleLegend:
    """A compact legend: one colour entry per system, one line-style entry per kind of curve.

    Entries are registered together with the line they describe (the return value of
    :func:`kinred.report.log_plot`, ``None`` when nothing was drawn): an entry whose lines
    were all left undrawn is not listed, so the legend names only curves on the axes.

    Examples
    --------
    >>> from kinred.report._figures import pyplot
    >>> plt = pyplot()
    >>> fig, ax = plt.subplots()
    >>> leg = StyleLegend()
    >>> leg.system("k = 2", "C0", ax.plot([0, 1], [1, 2])[0])
    >>> leg.style("--", "certified bound", None)        # not drawn: not listed
    >>> leg.labels()
    ['k = 2']
    >>> plt.close(fig)
    """

    def __init__(self):
        self._systems: dict = {}
        self._styles: dict = {}

    def system(self, label: str, color, line) -> None:
        """Register a curve of a system drawn in ``color`` (``line`` None: not drawn)."""
        if line is not None:
            self._systems.setdefault(label, color)

    def style(self, linestyle: str, label: str, line, marker: str | None = None) -> None:
        """Register a curve of the kind ``label`` drawn with ``linestyle`` (None: not drawn)."""
        if line is not None:
            self._styles.setdefault(label, ("line", linestyle, marker))

    def patch(self, label: str, color, artist) -> None:
        """Register a shaded region in ``color`` (``artist`` None: not drawn)."""
        if artist is not None:
            self._styles.setdefault(label, ("patch", color, None))

    def labels(self) -> list:
        """The labels that :meth:`draw` will list, systems first."""
        return list(self._systems) + list(self._styles)

    def draw(self, ax, *, outside: bool = True, fontsize: float = 8) -> None:
        """Draw the legend (nothing if no entry); ``outside``: right of the axes."""
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        handles = [Line2D([], [], color=c, lw=2.5) for c in self._systems.values()]
        handles += [Patch(color=a, alpha=0.55) if kind == "patch" else
                    Line2D([], [], color="black", ls=a or "none", marker=m or "", ms=5, lw=1.3)
                    for kind, a, m in self._styles.values()]
        if not handles:
            return
        where = (dict(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
                 if outside else dict(loc="best"))
        ax.legend(handles, self.labels(), fontsize=fontsize, frameon=False, **where)


def shade_above(ax, x, y, *, color: str = "#f3c4c4", label: str | None = None):
    """Shade the region of a (log or linear) axes above the curve ``(x, y)``.

    Call after the y-limits are final (:func:`kinred.report.fit_log_axis`). Points where
    ``y`` is not finite and positive are left unshaded. Returns the artist, or ``None`` when
    there is nothing to shade.
    """
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(y) & (y > 0)
    if not np.any(ok):
        return None
    top = ax.get_ylim()[1]
    return ax.fill_between(np.asarray(x, dtype=float), np.where(ok, y, top), top, where=ok,
                           color=color, alpha=0.55, lw=0, zorder=0, label=label)


def note_not_drawn(ax, what: str, names) -> None:
    """Write ``"<what> not drawn where not finite and positive: <names>"`` in a corner."""
    names = list(names)
    if names:
        ax.text(0.01, 0.01, f"{what} not drawn where not finite and positive: " + ", ".join(names),
                transform=ax.transAxes, fontsize=7, color="#a00", va="bottom", ha="left")


def point_cloud(ax, pts, weights=None, *, color="C0", label=None, background: bool = False,
                bins=None):
    """Draw atoms: a weighted histogram in one dimension, a scatter of the first two otherwise.

    Parameters
    ----------
    pts : (n, m) array
        Positions (rows with a non-finite entry are left out).
    weights : (n,) array, optional
        Atom weights: histogram weights in one dimension, marker areas in two.
    background : bool
        Draw as a grey reference under the main cloud (filled histogram, hollow markers).
    bins : array, optional
        Histogram edges (share them between clouds compared on one axes).

    Returns the artist drawn, or ``None`` when no row is finite.
    """
    pts = np.asarray(pts, dtype=float)
    pts = pts.reshape(len(pts), -1)
    n = len(pts)
    w = np.full(n, 1.0 / max(n, 1)) if weights is None else np.asarray(weights, dtype=float)
    ok = np.all(np.isfinite(pts), axis=1) & np.isfinite(w)
    pts, w = pts[ok], w[ok]
    if not len(pts):
        return None
    if pts.shape[1] == 1:
        if bins is None:
            bins = cloud_bins(pts[:, 0])
        kw = (dict(histtype="stepfilled", color="0.8", edgecolor="0.6") if background
              else dict(histtype="step", color=color, lw=1.8))
        return ax.hist(pts[:, 0], bins=bins, weights=w, density=True, label=label, **kw)[2][0]
    size = 14.0 * w / w.mean() if w.mean() > 0 else np.full(len(w), 14.0)
    if background:
        return ax.scatter(pts[:, 0], pts[:, 1], s=size * 2.2, facecolors="none",
                          edgecolors="0.6", linewidths=0.7, label=label)
    return ax.scatter(pts[:, 0], pts[:, 1], s=size, color=color, alpha=0.8, lw=0, label=label)


def cloud_bins(values, *, count: int | None = None) -> np.ndarray:
    """Histogram edges spanning the finite ``values`` (``count`` bins; default ~ sqrt(n))."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if not v.size:
        return np.linspace(-1.0, 1.0, 11)
    count = count or int(min(40, max(8, math.sqrt(v.size) * 1.5)))
    lo, hi = float(v.min()), float(v.max())
    if hi - lo <= 1e-12 * max(1.0, abs(lo)):
        lo, hi = lo - 0.5, hi + 0.5
    return np.linspace(lo, hi, count + 1)


def tidy_log_axes(*axes) -> None:
    """Readable log axes: over less than three decades, ticks at 1, 2 and 5 times the powers
    of ten labelled plainly (``0.2``, ``0.5``, ``1``); over more, the decades only. Minor
    ticks stay, unlabelled."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    for ax in axes:
        for axis, lim in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            if axis.get_scale() != "log" or min(lim) <= 0:
                continue
            if math.log10(max(lim) / min(lim)) < 3:
                axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
                axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            axis.set_minor_formatter(NullFormatter())
