"""Matplotlib helpers (Agg backend, PNG bytes), guarded drawing and overflow-safe log axes."""

from __future__ import annotations

import io
import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import KinredWarning

#: Decades a log axis may reach either side of 1: beyond about 1e300 matplotlib's log
#: transform and tick locator overflow (``OverflowError: cannot convert float infinity to
#: integer``) or silently collapse the axis to (1, 10).
LOG_AXIS_LIMIT = 300


def pyplot():
    """Return ``matplotlib.pyplot`` with the non-interactive ``Agg`` backend selected."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def figure_png(fig, *, dpi: int = 110, close: bool = True) -> bytes:
    """Render a matplotlib figure to PNG bytes (and close it unless ``close=False``).

    A figure laid out by the constrained layout engine already fits its labels, titles and
    legends inside the canvas: it is laid out once at ``dpi`` and saved as it is (matplotlib
    would lay it out in a draw before saving and again in the saving draw; the PNG is the
    same byte for byte); any other figure is saved with ``bbox_inches="tight"``, which draws
    it twice (once to measure, once to save).

    Examples
    --------
    >>> plt = pyplot()
    >>> fig, ax = plt.subplots()
    >>> _ = ax.plot([0, 1], [1, 0])
    >>> figure_png(fig)[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
    True
    """
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    buf = io.BytesIO()
    engine = fig.get_layout_engine()
    if isinstance(engine, ConstrainedLayoutEngine):
        own_dpi = fig.get_dpi()
        fig.set_dpi(dpi)
        engine.execute(fig)
        fig.set_dpi(own_dpi)
        fig.set_layout_engine(None)            # laid out: no layout pass in the saving draw
        try:
            fig.savefig(buf, format="png", dpi=dpi)
        finally:
            fig.set_layout_engine(engine)
    else:
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    if close:
        pyplot().close(fig)
    return buf.getvalue()


@dataclass(frozen=True)
class DrawnFigure:
    """The outcome of :func:`draw_figure`: the PNG, or why the figure could not be drawn.

    Attributes
    ----------
    name : str
        File name of the figure (``"bound.png"``).
    caption : str
    png : bytes or None
        ``None`` when drawing failed.
    error : str or None
        ``"<ExceptionType>: <message>"`` when drawing failed.
    """

    name: str
    caption: str
    png: bytes | None = None
    error: str | None = None


def draw_figure(name: str, caption: str, make: Callable, *args, **kwargs) -> DrawnFigure:
    """Draw one figure without letting a plotting failure escape.

    Calls ``make(plt, *args, **kwargs)``, which returns a matplotlib figure, and renders it
    to PNG. Any exception (matplotlib's ``OverflowError`` on astronomically large values, a
    bug in ``make``) is caught: the figures opened by ``make`` are closed, a
    :class:`~kinred.errors.KinredWarning` names the figure and the reason, and the result
    carries the reason instead of a PNG, so that the caller still writes its data and a report
    (:meth:`kinred.report.Section.add_drawn` turns it into a note). ``KeyboardInterrupt``
    is not caught.

    Examples
    --------
    >>> def bad(plt):
    ...     raise OverflowError("cannot convert float infinity to integer")
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     d = draw_figure("b.png", "the bound", bad)
    >>> d.png is None, d.error
    (True, 'OverflowError: cannot convert float infinity to integer')
    """
    plt = pyplot()
    before = set(plt.get_fignums())
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # numpy overflow inside matplotlib
            png = figure_png(make(plt, *args, **kwargs))
    except Exception as exc:  # noqa: BLE001 - a figure must never lose the result it shows
        for num in set(plt.get_fignums()) - before:
            plt.close(num)
        reason = f"{type(exc).__name__}: {exc}"
        warnings.warn(f"figure {name} could not be drawn ({reason}); the report has a note "
                      "instead", KinredWarning, stacklevel=2)
        return DrawnFigure(name, caption, None, reason)
    return DrawnFigure(name, caption, png)


def log_values(y) -> np.ndarray:
    """``y`` as floats, with the entries a log axis cannot show (non-finite, ``<= 0``) as NaN.

    Matplotlib leaves NaN points out of a curve.

    Examples
    --------
    >>> log_values([1.0, 0.0, float("inf"), -2.0, 1e-20])
    array([1.e+00,    nan,    nan,    nan, 1.e-20])
    """
    y = np.asarray(y, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(y) & (y > 0), y, np.nan)


def finite_values(y) -> np.ndarray:
    """``y`` as floats with non-finite entries as NaN (left out of a linear-axis curve)."""
    y = np.asarray(y, dtype=float)
    return np.where(np.isfinite(y), y, np.nan)


def log_plot(ax, x, y, *fmt, **kwargs):
    """Plot the positive finite points of ``y`` against ``x`` on a log y-axis.

    Returns the line, or ``None`` when ``y`` has no such point (no curve and no legend
    entry). A curve with a single such point gets a marker (a lone point of a line style
    would be invisible). Autoscaling of the y-axis is switched off: call :func:`fit_log_axis`
    after the last curve.

    Examples
    --------
    >>> plt = pyplot()
    >>> fig, ax = plt.subplots()
    >>> log_plot(ax, [0, 1, 2], [float("inf"), float("inf"), 0.0]) is None
    True
    >>> log_plot(ax, [0, 1, 2], [3.0, float("inf"), float("inf")], "--").get_marker()
    'o'
    >>> plt.close(fig)
    """
    ly = log_values(y)
    finite = int(np.count_nonzero(np.isfinite(ly)))
    if not finite:
        return None
    ax.set_yscale("log")
    ax.set_autoscaley_on(False)
    (line,) = ax.plot(x, ly, *fmt, **kwargs)
    if finite == 1 and line.get_marker() in ("None", None, "", " "):
        line.set_marker("o")
    return line


def fit_log_axis(ax) -> tuple[float, float]:
    """Set the y-limits (and, for wide ranges, decade ticks) of a log axis from its curves.

    The limits enclose the positive finite data with a small margin, clipped to
    ``[1e-300, 1e300]`` (``LOG_AXIS_LIMIT``); over more than 12 decades the ticks are
    powers of ten every 2, 5, 10, 20, 25, 50, 100 or 200 decades (at most nine ticks), placed
    here rather than by matplotlib's locator, which overflows near the float limits. Returns
    the limits.

    Examples
    --------
    >>> plt = pyplot()
    >>> fig, ax = plt.subplots()
    >>> _ = log_plot(ax, [0, 1, 2], [1e-16, 1e150, 8.5e297])
    >>> lo, hi = fit_log_axis(ax); hi
    1e+300
    >>> figure_png(fig)[:4] == b"\\x89PNG"
    True
    """
    ys = [log_values(line.get_ydata()) for line in ax.get_lines()]
    ys = np.concatenate(ys) if ys else np.array([])
    ys = ys[np.isfinite(ys)]
    lo, hi = (math.log10(ys.min()), math.log10(ys.max())) if ys.size else (-1.0, 1.0)
    pad = max(0.05 * (hi - lo), 0.3)
    lo = min(max(lo - pad, -LOG_AXIS_LIMIT), LOG_AXIS_LIMIT - 1)
    hi = max(min(hi + pad, LOG_AXIS_LIMIT), lo + 1)
    ax.set_yscale("log")
    ax.set_ylim(10.0 ** lo, 10.0 ** hi)
    if hi - lo > 12:
        from matplotlib.ticker import FixedLocator, NullLocator

        step = next(s for s in (2, 5, 10, 20, 25, 50, 100, 200) if s >= (hi - lo) / 8)
        first = math.ceil(lo / step) * step
        ax.yaxis.set_major_locator(FixedLocator(10.0 ** np.arange(first, math.floor(hi) + 1, step)))
        ax.yaxis.set_minor_locator(NullLocator())
    return 10.0 ** lo, 10.0 ** hi


def legend(ax, **kwargs) -> None:
    """``ax.legend(**kwargs)`` if the axes have labelled curves (no warning otherwise)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kwargs)
