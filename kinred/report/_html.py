"""A small, dependency-free, self-contained HTML report (figures embedded as base64 PNG)."""

from __future__ import annotations

import base64
import datetime as _dt
import html
import math
from dataclasses import dataclass, field
from html.parser import HTMLParser
from typing import Sequence

from ..errors import InvalidInput

__all__ = ["Table", "Section", "Report", "validate_report_html"]

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _fmt(value) -> str:
    if isinstance(value, float):
        if value == 0.0 or math.isnan(value) or math.isinf(value):
            return str(value)
        a = abs(value)
        return f"{value:.4g}" if 1e-3 <= a < 1e5 else f"{value:.3e}"
    return str(value)


@dataclass(frozen=True)
class Table:
    """A table of numbers: ``header`` (column names) and ``rows`` (sequences of cells)."""

    header: Sequence[str]
    rows: Sequence[Sequence]
    caption: str = ""

    def to_html(self) -> str:
        head = "".join(f"<th>{html.escape(str(h))}</th>" for h in self.header)
        body = "".join(
            "<tr>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in row) + "</tr>"
            for row in self.rows
        )
        # the caption wraps at the page's width; the wrapper scrolls sideways when the table is
        # wider than the page (the page itself never does)
        cap = (f'<p class="table-caption">{html.escape(self.caption)}</p>'
               if self.caption else "")
        return (f'{cap}<div class="table-wrap"><table><thead><tr>{head}</tr></thead>'
                f"<tbody>{body}</tbody></table></div>")

    def to_text(self) -> str:
        """Plain-text rendering for terminals."""
        cells = [[str(h) for h in self.header]] + [[_fmt(c) for c in r] for r in self.rows]
        widths = [max(len(r[i]) for r in cells) for i in range(len(self.header))]
        lines = [" | ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
        lines.insert(1, "-+-".join("-" * w for w in widths))
        return "\n".join(lines)


@dataclass
class Section:
    """A heading, paragraphs of text, figures and tables (rendered in that order).

    A ``folded`` section is rendered as an HTML ``<details>`` element: only its heading shows
    until the reader opens it (for long tables below the figures). ``figures`` holds
    ``(caption, png bytes, None)`` for a drawn figure and ``(caption, None, note)`` for a
    figure that could not be drawn (the note is shown in its place).
    """

    title: str
    text: Sequence[str] = ()
    tables: list = field(default_factory=list)
    figures: list = field(default_factory=list)
    folded: bool = False

    def add_figure(self, caption: str, png: bytes) -> None:
        """Embed a PNG figure (bytes) with its caption."""
        if not isinstance(png, (bytes, bytearray)) or not bytes(png).startswith(_PNG_MAGIC):
            raise InvalidInput(f"figure {caption!r} must be PNG bytes")
        self.figures.append((caption, bytes(png), None))

    def add_drawn(self, drawn) -> None:
        """Add a :class:`~kinred.report.DrawnFigure`: its PNG, or a note saying why it is missing.

        Examples
        --------
        >>> from kinred.report import DrawnFigure
        >>> s = Section("Figures")
        >>> s.add_drawn(DrawnFigure("bound.png", "the bound", None, "OverflowError: too big"))
        >>> s.figures[0][2]  # doctest: +ELLIPSIS
        'Figure bound.png (the bound) could not be drawn: OverflowError: too big. The numbers...'
        """
        if drawn.png is not None:
            self.add_figure(drawn.caption, drawn.png)
            return
        self.figures.append((drawn.caption, None,
                             f"Figure {drawn.name} ({drawn.caption}) could not be drawn: "
                             f"{drawn.error}. The numbers it shows are in the tables and data "
                             "files of this result."))


@dataclass
class Report:
    """A self-contained HTML report: every figure is embedded, no external resource.

    Examples
    --------
    >>> r = Report("demo")
    >>> s = r.section("numbers", text=["one table"])
    >>> s.tables.append(Table(["k", "W1"], [[10, 0.5]]))
    >>> "<table>" in r.to_html()
    True
    """

    title: str
    subtitle: str = ""
    sections: list = field(default_factory=list)

    def section(self, title: str, text: Sequence[str] = (), *, folded: bool = False) -> Section:
        """Append and return a new :class:`Section` (``folded``: inside ``<details>``)."""
        s = Section(title, list(text), folded=folded)
        self.sections.append(s)
        return s

    def to_html(self) -> str:
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        parts = [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            f"<title>{html.escape(self.title)}</title>",
            f"<style>{_CSS}</style>",
            "</head><body>",
            f"<h1>{html.escape(self.title)}</h1>",
        ]
        if self.subtitle:
            parts.append(f"<p>{html.escape(self.subtitle)}</p>")
        parts.append(f"<p><small>generated by kinred, {stamp}</small></p>")
        for s in self.sections:
            parts.extend(_section_html(s))
        parts.append("</body></html>")
        return "\n".join(parts)


#: The report's style sheet: the page never scrolls sideways (wide tables scroll in their own
#: box), figures scale down to the page width, numbers do not break across lines.
_CSS = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;"
        "line-height:1.4;overflow-wrap:break-word}"
        ".table-wrap{overflow-x:auto;max-width:100%;margin:1em 0}"
        "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;"
        "text-align:right}td{white-space:nowrap}th{vertical-align:bottom}"
        ".table-caption{font-style:italic;margin:1em 0 0.3em}"
        ".table-caption+.table-wrap{margin-top:0}"
        "figure{margin:1.5em 0}img{max-width:100%;height:auto;display:block}"
        "figcaption{margin-top:0.4em;color:#333}"
        "details{margin:0.8em 0;border-top:1px solid #ddd;padding-top:0.4em}"
        "summary{cursor:pointer}summary h2{display:inline;font-size:1.2em}"
        ".figure-note{border-left:4px solid #c60;padding:0.3em 0.8em;background:#fff6ee}")


def _figure_html(cap: str, png, note) -> str:
    if png is None:
        return (f'<p class="figure-note"><strong>Missing figure.</strong> '
                f"{html.escape(note)}</p>")
    b64 = base64.b64encode(png).decode("ascii")
    return (f'<figure><img alt="{html.escape(cap)}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{html.escape(cap)}</figcaption></figure>")


def _section_html(s: Section) -> list:
    """The HTML lines of a section: heading, text, figures, then tables."""
    title = html.escape(s.title)
    parts = [f"<details><summary><h2>{title}</h2></summary>" if s.folded else f"<h2>{title}</h2>"]
    parts.extend(f"<p>{html.escape(t)}</p>" for t in s.text)
    parts.extend(_figure_html(*f) for f in s.figures)
    parts.extend(t.to_html() for t in s.tables)
    if s.folded:
        parts.append("</details>")
    return parts


class _Checker(HTMLParser):
    _void = {"meta", "img", "br", "hr", "link", "input"}

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.images: list[bytes] = []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            src = dict(attrs).get("src") or ""
            prefix = "data:image/png;base64,"
            if not src.startswith(prefix):
                self.errors.append(f"image with non-embedded source {src[:40]!r}")
                return
            try:
                data = base64.b64decode(src[len(prefix):], validate=True)
            except ValueError:
                self.errors.append("image with invalid base64 data")
                return
            if not data.startswith(_PNG_MAGIC) or len(data) < 100:
                self.errors.append("image that is not a non-empty PNG")
            self.images.append(data)
        elif tag not in self._void:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if tag in self._void:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"unbalanced </{tag}> (open: {self.stack[-3:]})")
            if tag in self.stack:
                while self.stack and self.stack.pop() != tag:
                    pass
        else:
            self.stack.pop()


def validate_report_html(text: str) -> int:
    """Check a report without a browser: balanced tags, every figure an embedded non-empty PNG.

    Returns the number of figures; raises :class:`~kinred.errors.InvalidInput` listing the
    problems otherwise.
    """
    if not text.lstrip().lower().startswith("<!doctype html>"):
        raise InvalidInput("report must start with <!DOCTYPE html>")
    c = _Checker()
    c.feed(text)
    c.close()
    if c.stack:
        c.errors.append(f"unclosed tags {c.stack}")
    if c.errors:
        raise InvalidInput("invalid report HTML: " + "; ".join(c.errors[:5]))
    return len(c.images)
