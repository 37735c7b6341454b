"""Figures and self-contained HTML reports.

This is the only package of kinred that imports matplotlib (lazily, with the ``Agg``
backend), so that the numerical core never pays for it. Reports can be checked and
photographed in headless Chromium: ``python -m kinred.report.screenshot REPORT.html --out
shot.png`` (:mod:`kinred.report.screenshot`).
"""

from ._html import Report, Section, Table, validate_report_html
from ._figures import (DrawnFigure, draw_figure, figure_png, finite_values, fit_log_axis, legend,
                       log_plot, log_values)
from ._plots import (StyleLegend, cloud_bins, k_colors, note_not_drawn, point_cloud, shade_above,
                     tidy_log_axes)

__all__ = ["Report", "Section", "Table", "figure_png", "validate_report_html", "DrawnFigure",
           "draw_figure", "log_plot", "log_values", "finite_values", "fit_log_axis", "legend",
           "StyleLegend", "k_colors", "shade_above", "note_not_drawn", "point_cloud", "cloud_bins",
           "tidy_log_axes"]
