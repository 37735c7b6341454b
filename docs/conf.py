"""Sphinx configuration of the kinred documentation.

Build (fails on any warning, as the test suite does)::

    python -m sphinx -W --keep-going -E -b html docs /tmp/kinred-html

Two small local extensions live in this file, so that generated content cannot drift from
its source:

* ``.. kinred-cli::`` renders ``format_help()`` of :func:`kinred.cli.build_parser` and of every
  sub-command registered in :data:`kinred.cli.COMMAND_MODULES` at build time.
* ``.. include-markdown:: FILE.md`` renders one of the Markdown pages of ``docs/`` (written by
  the package authors next to their code, readable on GitHub) inside the Sphinx site. MyST is
  not a dependency: the directive converts the small Markdown subset those pages use
  (ATX headings, paragraphs, ``-``/``*`` lists, pipe tables, fenced and indented code,
  inline code, links, emphasis) to reStructuredText. Anything it does not understand is kept as
  text, and reStructuredText warnings still fail the build.
"""

from __future__ import annotations

import argparse
import os
import re
import sys

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import kinred  # noqa: E402

# -- project -----------------------------------------------------------------------------------

project = "kinred"
author = "kinred authors"
copyright = "kinred authors"
version = release = kinred.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
]

source_suffix = {".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "**/.ipynb_checkpoints"]
templates_path: list[str] = []

# -- autodoc / numpydoc ------------------------------------------------------------------------

autodoc_default_options = {
    "members": True,
    "undoc-members": False,
    "show-inheritance": False,
    "member-order": "bysource",
}
autodoc_typehints = "none"          # numpydoc "Parameters" sections carry the types and shapes
autodoc_class_signature = "mixed"
numpydoc_show_class_members = False  # members are documented by autodoc's :members:
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = True
numpydoc_xref_param_type = False

# Every cross-reference must resolve (with -W a broken one fails the build). No intersphinx
# (the build must work offline), so references into other projects are ignored, narrowly:
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|scipy|concurrent|dask|distributed|ot|matplotlib)(\..*)?"),
    (r"py:.*", r"(os|pathlib|json|tomllib)(\..*)?"),
]
# kinred's own references must all resolve: nothing of kinred is ignored.
nitpick_ignore: list[tuple[str, str]] = []

# -- HTML --------------------------------------------------------------------------------------

html_theme = "alabaster"
html_title = f"kinred {release}"
html_static_path: list[str] = []
html_theme_options = {
    "description": "Interacting agents in high dimension, random projections, kinetic limits",
    "fixed_sidebar": True,
    "page_width": "1100px",
    "sidebar_width": "240px",
}
html_sidebars = {"**": ["about.html", "navigation.html", "searchbox.html"]}


# -- ``.. kinred-cli::`` -----------------------------------------------------------------------

def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:  # argparse has no public accessor for sub-parsers
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


class KinredCLI(Directive):
    """Render ``kinred --help`` and ``kinred COMMAND --help`` as literal blocks with headings."""

    has_content = False

    def run(self):
        from kinred.cli import build_parser

        os.environ.setdefault("COLUMNS", "96")  # argparse wraps to the terminal width
        parser = build_parser()
        out: list[nodes.Node] = []
        top = nodes.section(ids=["kinred-help"], names=["kinred --help"])
        top += nodes.title(text="kinred --help")
        top += nodes.literal_block(text=parser.format_help().rstrip(), language="text")
        out.append(top)
        for name, sub in _subparsers(parser):
            sec = nodes.section(ids=[f"kinred-{name}"], names=[f"kinred {name}"])
            sec += nodes.title(text=f"kinred {name}")
            sec += nodes.literal_block(text=sub.format_help().rstrip(), language="text")
            out.append(sec)
        return out


# -- ``.. include-markdown::`` -----------------------------------------------------------------

_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_FENCE = re.compile(r"^(\s*)(```+|~~~+)\s*([\w+-]*)\s*$")
_BULLET = re.compile(r"^(\s*)([-*+])\s+(.*)$")
_TABLE_SEP = re.compile(r"^\s*\|?\s*:?-{2,}:?\s*(\|\s*:?-{2,}:?\s*)*\|?\s*$")
_ADORN = "=-~^\"'"


_BEFORE_OK = set(" \t'\"([{<-/:")
_AFTER_OK = set(" \t'\")]}>-/:.,;!?\\")


def _inline(text: str) -> str:
    """Markdown inline markup -> reStructuredText inline markup."""
    # re.split with two groups yields [text, ticks, code, text, ticks, code, ...]
    parts = re.split(r"(`+)(.+?)\1", text)
    plains = []
    for i in range(0, len(parts), 3):
        plain = parts[i]
        plain = plain.replace("\\", "\\\\").replace("|", "\\|")
        plain = re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", lambda m: _link(m.group(1), m.group(2)),
                       plain)
        plain = re.sub(r"(?<![\w_*])_(\S(?:.*?\S)?)_(?![\w_])", r"*\1*", plain)
        plain = re.sub(r"(?<![\w_])__(\S(?:.*?\S)?)__(?![\w_])", r"**\1**", plain)
        plains.append(plain)
    codes = [parts[i + 2] for i in range(0, len(parts) - 1, 3)]
    out = [plains[0]]
    for j, code in enumerate(codes):
        lit = _literal(code.strip() or code)
        prev, nxt = out[-1], plains[j + 1]
        if prev and prev[-1] not in _BEFORE_OK:
            lit = "\\ " + lit
        if nxt and nxt[0] not in _AFTER_OK:
            lit = lit + "\\ "
        out += [lit, nxt]
    return "".join(out)


def _literal(code: str) -> str:
    return "``" + code + "``" if "``" not in code else ":literal:`" + code.replace("`", "\\`") + "`"


def _link(text: str, target: str) -> str:
    if target.endswith(".md") and "://" not in target:
        return f":doc:`{text} <{target[:-3]}>`"
    if "://" in target:
        return f"`{text} <{target}>`__"
    return f"{text} (``{target}``)"


def _table(rows: list[str]) -> list[str]:
    def cells(line):
        line = line.strip()
        if line.startswith("|"):
            line = line[1:]
        if line.endswith("|") and not line.endswith("\\|"):
            line = line[:-1]
        return [c.strip() for c in re.split(r"(?<!\\)\|", line)]

    header = cells(rows[0])
    body = [cells(r) for r in rows[2:]]
    out = [".. list-table::", "   :header-rows: 1", ""]
    for row in [header] + body:
        row = (row + [""] * len(header))[: len(header)]
        for j, c in enumerate(row):
            out.append(("   * - " if j == 0 else "     - ") + (_inline(c) if c else ""))
    out.append("")
    return out


def markdown_to_rst(text: str, *, top_level: int = 0) -> list[str]:
    """Convert the Markdown subset used by the docs/*.md pages to reST lines.

    ``top_level`` shifts heading levels (0: ``#`` is the page title).
    """
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    n = len(lines)
    while i < n:
        line = lines[i]
        m = _FENCE.match(line)
        if m:
            fence, lang = m.group(2), m.group(3) or "text"
            lang = {"toml": "toml", "python": "python", "py": "python", "bash": "bash",
                    "sh": "bash", "console": "console", "json": "json"}.get(lang, "text")
            i += 1
            block = []
            while i < n and not lines[i].strip().startswith(fence):
                block.append(lines[i])
                i += 1
            i += 1
            out += [f".. code-block:: {lang}", ""] + ["   " + b if b else "" for b in block] + [""]
            continue
        m = _HEADING.match(line)
        if m:
            level = len(m.group(1)) - 1 + top_level
            title = _inline(m.group(2))
            out += ["", title, _ADORN[min(level, len(_ADORN) - 1)] * max(len(title), 3), ""]
            i += 1
            continue
        if line.strip().startswith("|") and i + 1 < n and _TABLE_SEP.match(lines[i + 1]):
            rows = [line, lines[i + 1]]
            i += 2
            while i < n and lines[i].strip().startswith("|"):
                rows.append(lines[i])
                i += 1
            out += [""] + _table(rows)
            continue
        if line.startswith("    ") and (not out or out[-1] == ""):
            block = []
            while i < n and (lines[i].startswith("    ") or not lines[i].strip()):
                block.append(lines[i][4:])
                i += 1
            while block and not block[-1].strip():
                block.pop()
            out += ["::", ""] + ["   " + b if b else "" for b in block] + [""]
            continue
        m = _BULLET.match(line)
        if m:
            indent = len(m.group(1))
            item = [m.group(3)]
            i += 1
            while i < n and lines[i].strip() and not _BULLET.match(lines[i]) \
                    and not _FENCE.match(lines[i]):
                item.append(lines[i].strip())
                i += 1
            pad = " " * indent
            if out and out[-1].strip():
                out.append("")  # reST wants a blank line before a list (and a nested one)
            out += [pad + "- " + _inline(" ".join(item))]
            if i < n and not lines[i].strip():
                out.append("")
            continue
        if not line.strip():
            out.append("")
            i += 1
            continue
        para = [line.strip()]
        i += 1
        while i < n and lines[i].strip() and not _HEADING.match(lines[i]) \
                and not _FENCE.match(lines[i]) and not _BULLET.match(lines[i]) \
                and not lines[i].strip().startswith("|"):
            para.append(lines[i].strip())
            i += 1
        out += [_inline(" ".join(para)), ""]
    return out


class IncludeMarkdown(Directive):
    """``.. include-markdown:: path.md`` (relative to this page), option ``:shift: N``."""

    required_arguments = 1
    option_spec = {"shift": directives.nonnegative_int}

    def run(self):
        env = self.state.document.settings.env
        rel, path = env.relfn2path(self.arguments[0])
        env.note_dependency(rel)
        if not os.path.exists(path):
            raise self.severe(f"include-markdown: {self.arguments[0]} does not exist ({path})")
        with open(path, encoding="utf-8") as fh:
            rst = markdown_to_rst(fh.read(), top_level=self.options.get("shift", 0))
        self.state_machine.insert_input(StringList(rst, source=path), path)
        return []


def setup(app):
    app.add_directive("kinred-cli", KinredCLI)
    app.add_directive("include-markdown", IncludeMarkdown)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
