"""Sphinx configuration of the kinred documentation.

Build (fails on any warning, as the test suite does)::

    make docs      # creates .venv, installs the docs extra, builds docs/_build/html
    python -m sphinx -W --keep-going -E -b html docs docs/_build/html   # the same, by hand

The build needs no network: MathJax comes from the ``sphinx-mathjax-offline`` wheel and is
copied into ``_static/mathjax``, and no page loads anything from another site.

The scripts of ``examples/`` become a gallery (sphinx-gallery): each runs at build time, and
its printed output and matplotlib figures are rendered under its code. Scripts whose full run
is long read ``KINRED_EXAMPLES_SMOKE=1`` (set below) and run their ``--smoke`` sizes, as each
says in its docstring. Generated gallery pages go to ``docs/auto_examples/`` (git-ignored).

Three small local extensions live in this file, so that generated content cannot drift from
its source:

* ``.. kinred-cli::`` renders ``format_help()`` of :func:`kinred.cli.build_parser` and of every
  sub-command registered in :data:`kinred.cli.COMMAND_MODULES` at build time.
* ``.. include-markdown:: FILE.md`` renders one of the Markdown pages of ``docs/`` (written by
  the package authors next to their code, readable on GitHub) inside the Sphinx site. MyST is
  not a dependency: the directive converts the small Markdown subset those pages use
  (ATX headings, paragraphs, ``-``/``*`` lists, pipe tables, fenced and indented code,
  inline code, links, emphasis) to reStructuredText. Anything it does not understand is kept as
  text, and reStructuredText warnings still fail the build. ``:section: TITLE`` includes
  only the section under the heading ``TITLE`` (used for README.md's Table 1).
* ``.. kinred-demo::`` runs ``kinred demo`` (with the flags of ``:args:``) at build time and
  renders what it prints and the figures of its ``report.html`` with their captions, so the
  pictures are always those of the current code.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import html
import io
import os
import re
import shlex
import sys
import tempfile

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

# Before anything imports matplotlib: no display, and the gallery's long examples at their
# smoke sizes (each such script says so in its docstring).
os.environ.setdefault("MPLBACKEND", "Agg")
os.environ["KINRED_EXAMPLES_SMOKE"] = "1"

import kinred  # noqa: E402

# -- project -----------------------------------------------------------------------------------

project = "kinred"
author = "kinred authors"
copyright = "kinred authors"
version = release = kinred.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",   # MathJax 3 from the wheel: sets mathjax_path to a local copy
    "numpydoc",
    "sphinx_gallery.gen_gallery",
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
    (r"py:.*", r"(os|pathlib|json|tomllib|collections)(\..*)?"),
]
# kinred's own references must all resolve: nothing of kinred is ignored.
nitpick_ignore: list[tuple[str, str]] = []

# -- gallery (sphinx-gallery) -----------------------------------------------------------------

sphinx_gallery_conf = {
    "examples_dirs": "../examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"\.py$",          # run every script (not only plot_*.py)
    "ignore_pattern": r"/_[^/]*\.py$",      # private helpers (_name.py), if any
    "abort_on_example_error": True,         # a failing example fails the build
    "download_all_examples": False,
    "remove_config_comments": True,
    "capture_repr": (),                     # show printed output only
    "image_scrapers": ("matplotlib",),
    "write_computation_times": False,       # no sg_execution_times page in the tree
    "show_signature": False,
    "run_stale_examples": True,             # always re-run: outputs never lag the code
}

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
# an HTML comment on lines of its own (removed with its lines), or inside a line
_HTML_COMMENT = re.compile(r"^[ \t]*<!--.*?-->[ \t]*(?:\n|\Z)|<!--.*?-->", re.S | re.M)


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

    ``top_level`` shifts heading levels (0: ``#`` is the page title). HTML comments
    (``<!-- ... -->``, notes for the authors) are dropped.
    """
    text = _HTML_COMMENT.sub("", text)
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


def markdown_section(text: str, title: str) -> str | None:
    """The section of ``text`` under the ATX heading ``title`` (heading included), up to the
    next heading of the same or a higher level; None if there is no such heading."""
    lines = text.splitlines()
    start = level = None
    in_fence = False
    for i, line in enumerate(lines):
        if _FENCE.match(line):
            in_fence = not in_fence
            continue
        m = None if in_fence else _HEADING.match(line)
        if m is None:
            continue
        if start is None and m.group(2) == title:
            start, level = i, len(m.group(1))
        elif start is not None and len(m.group(1)) <= level:
            return "\n".join(lines[start:i]) + "\n"
    return None if start is None else "\n".join(lines[start:]) + "\n"


class IncludeMarkdown(Directive):
    """``.. include-markdown:: path.md`` (relative to this page), options ``:shift: N`` and
    ``:section: TITLE``."""

    required_arguments = 1
    option_spec = {"shift": directives.nonnegative_int, "section": directives.unchanged_required}

    def run(self):
        env = self.state.document.settings.env
        rel, path = env.relfn2path(self.arguments[0])
        env.note_dependency(rel)
        if not os.path.exists(path):
            raise self.severe(f"include-markdown: {self.arguments[0]} does not exist ({path})")
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
        if "section" in self.options:
            text = markdown_section(text, self.options["section"])
            if text is None:
                raise self.severe(f"include-markdown: {self.arguments[0]} has no heading "
                                  f"{self.options['section']!r}")
        rst = markdown_to_rst(text, top_level=self.options.get("shift", 0))
        self.state_machine.insert_input(StringList(rst, source=path), path)
        return []


# -- ``.. kinred-demo::`` ----------------------------------------------------------------------

_REPORT_FIGURE = re.compile(r'<figure><img alt="[^"]*" src="(data:image/png;base64,[^"]+)">'
                            r"<figcaption>(.*?)</figcaption></figure>", re.S)


def run_demo(args: list[str]) -> tuple[str, list[tuple[str, str]]]:
    """Run ``kinred demo ARGS`` into a temporary folder.

    Returns what it printed (the folder shown as ``results/demo``) and the figures of its
    ``report.html`` as ``(data URI, caption)``. Raises RuntimeError if the demo fails, warns,
    or its report is missing a figure.
    """
    from kinred.cli import main

    with tempfile.TemporaryDirectory(prefix="kinred-docs-demo-") as tmp:
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = main(["demo", *args, "--out", tmp])
        if status != 0 or "warning" in err.getvalue().lower():
            raise RuntimeError(f"kinred demo {' '.join(args)} exited with {status}:\n"
                               f"{out.getvalue()}\n{err.getvalue()}")
        with open(os.path.join(tmp, "report.html"), encoding="utf-8") as fh:
            report = fh.read()
        printed = out.getvalue().replace(tmp, "results/demo").rstrip()
    if 'class="figure-note"' in report:
        raise RuntimeError("kinred demo: the report is missing a figure (see its figure note)")
    figures = [(uri, html.unescape(cap)) for uri, cap in _REPORT_FIGURE.findall(report)]
    if not figures:
        raise RuntimeError("kinred demo: report.html has no figure")
    base64.b64decode(figures[0][0].split(",", 1)[1], validate=True)
    return printed, figures


class KinredDemo(Directive):
    """``.. kinred-demo::`` with option ``:args:`` (flags of ``kinred demo``): its printed
    summary as a console block, then every figure of its report with the report's caption."""

    has_content = False
    option_spec = {"args": directives.unchanged}

    def run(self):
        args = shlex.split(self.options.get("args", ""))
        try:
            printed, figures = run_demo(args)
        except RuntimeError as exc:
            raise self.error(str(exc)) from None
        command = " ".join(["kinred", "demo", *args])
        out: list[nodes.Node] = [nodes.literal_block(text=f"$ {command}\n{printed}",
                                                     language="text")]
        for uri, caption in figures:
            fig = nodes.figure()
            fig += nodes.image(uri=uri, alt=caption)
            fig += nodes.caption(text=caption)
            out.append(fig)
        return out


# -- numpydoc: its docstring template compiled once --------------------------------------------

def _numpydoc_template_once() -> None:
    """numpydoc's ``get_doc_object`` makes a jinja2 environment and compiles its docstring
    template for each of the ~1300 docstrings (about 2.5 s of CPU per build); this one does
    what it does, with the template of its first call (per builder) reused. The rendered text
    is the same: the template and its loader do not change during a build."""
    from numpydoc import docscrape_sphinx, numpydoc

    templates: dict = {}

    def get_doc_object(obj, what=None, doc=None, config=None, builder=None):
        config = {} if config is None else config
        if id(builder) not in templates:
            result = docscrape_sphinx.get_doc_object(obj, what, doc, config, builder)
            templates[id(builder)] = (builder, config["template"])   # keeps the builder alive
            return result
        config["template"] = templates[id(builder)][1]
        return docscrape_sphinx.get_doc_object_orig(
            obj, what=what, doc=doc, config=config, class_doc=docscrape_sphinx.SphinxClassDoc,
            func_doc=docscrape_sphinx.SphinxFunctionDoc, obj_doc=docscrape_sphinx.SphinxObjDoc)

    numpydoc.get_doc_object = get_doc_object


def setup(app):
    _numpydoc_template_once()
    app.add_directive("kinred-cli", KinredCLI)
    app.add_directive("include-markdown", IncludeMarkdown)
    app.add_directive("kinred-demo", KinredDemo)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
