"""Figures and self-contained HTML reports.

This is the only package of kinred that imports matplotlib (lazily, with the ``Agg``
backend), so that the numerical core never pays for it.
"""

from ._html import Report, Section, Table, validate_report_html
from ._figures import figure_png

__all__ = ["Report", "Section", "Table", "figure_png", "validate_report_html"]
