"""The Sphinx documentation builds without a single warning, and has its API and CLI pages,
the examples gallery, the tour's figures and Table 1, math that needs no network, and no
LaTeX label of the paper in its prose.

The build here does not execute the gallery's scripts (``-D plot_gallery=0``; ``make docs``
does): each script is run by tests/test_examples.py, which checks its printed lines and that
it draws its figure (what the gallery renders under its code)."""

from __future__ import annotations

import ast
import base64
import html as html_lib
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
EXAMPLES = ROOT / "examples"

# "(label ``eq:eul1``)", ", label ``delayed``", "labels ``CS1``–``CS2``", "label eq:dyn",
# "(4.22) ``delayed``" in a table: the LaTeX labels of the paper's source, which readers of
# the printed paper cannot look up (docs/architecture.md maps them for developers).
_LABEL_IN_SOURCE = re.compile(r"\blabels?\s+`{1,2}[^`\s]+`{1,2}|\(labels?\s*$"
                              r"|\(\d\.\d+\)\s+`{1,2}[A-Za-z][\w:-]*`{1,2}", re.M)
_LABEL_IN_PAGE = re.compile(r"\(labels?\s+\S|,\s*labels?\s+[^\s=]|\blabels?\s+[\w-]*:[\w:-]+")


def _git_untracked() -> set[str]:
    """Untracked files that are not git-ignored (what a build must not create)."""
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    return {line[3:] for line in out.splitlines() if line.startswith("??")}


def _page_text(path: Path, *, prose: bool = False) -> str:
    """The visible text of an HTML page (tags, scripts and styles removed); with ``prose``,
    without code blocks and signatures either (``label="..."`` there is Python, not prose)."""
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"<(script|style)\b.*?</\1>", " ", text, flags=re.S)
    if prose:
        text = re.sub(r"<pre\b.*?</pre>|<dt class=\"sig\b.*?</dt>", " ", text, flags=re.S)
    return html_lib.unescape(re.sub(r"<[^>]+>", "", text))


API_MODULES = ["measures", "quantize", "distance", "projection", "dynamics", "pairsum",
               "integrate", "observables", "recovery", "ensemble", "kinetic", "certify", "io",
               "scenefile", "report", "errors"]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    import sphinx  # noqa: F401  - a hard dependency of the test extra: fail, never skip
    import sphinx_gallery  # noqa: F401
    out = tmp_path_factory.mktemp("html")
    doctrees = tmp_path_factory.mktemp("doctrees")
    untracked_before = _git_untracked()
    # the build takes 1 min on a loaded 2-core machine (it runs `kinred demo` for the tour);
    # the gallery's scripts are not executed here: tests/test_examples.py runs each of them
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
         "-D", "plot_gallery=0", "-d", str(doctrees), str(DOCS), str(out)],
        capture_output=True, text=True, timeout=900, cwd=ROOT,
    )
    assert proc.returncode == 0, f"sphinx-build failed:\n{proc.stdout}\n{proc.stderr}"
    assert "WARNING" not in proc.stderr, proc.stderr
    return out, untracked_before


@pytest.fixture(scope="module")
def html(built):
    return built[0]


def test_build_leaves_only_git_ignored_files_in_the_tree(built):
    assert _git_untracked() == built[1], "the docs build created files git does not ignore"


@pytest.mark.parametrize("mod", API_MODULES)
def test_api_page_documents_every_public_name(html, mod):
    import importlib

    page = html / "api" / f"{mod}.html"
    assert page.exists(), f"missing API page {page}"
    text = page.read_text(encoding="utf-8")
    module = importlib.import_module(f"kinred.{mod}")
    for name in getattr(module, "__all__", []):
        anchor = f'id="kinred.{mod}.{name}"'
        assert anchor in text, f"kinred.{mod}.{name} is not documented in api/{mod}.html"


def test_cli_page_shows_every_subcommand(html):
    from kinred.cli import build_parser

    text = (html / "cli.html").read_text(encoding="utf-8")
    assert "usage: kinred" in text
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    for name in sub.choices:
        assert f"usage: kinred {name}" in text, f"kinred {name} missing from the CLI reference"


def test_user_pages_exist_and_show_equations(html):
    for page in ["index", "getting-started", "measures", "dynamics", "projections", "recovery",
                 "kinetic", "certificates", "cost", "scene-file", "measures-file",
                 "auto_examples/index", "architecture", "performance"]:
        assert (html / f"{page}.html").exists(), page
    # the equations are rendered as math (MathJax), with the paper's numbers next to them
    measures = (html / "measures.html").read_text(encoding="utf-8")
    assert re.search(r'class="math', measures) and "(4.22)" in measures
    assert "make demo" in (html / "getting-started.html").read_text(encoding="utf-8")


def test_every_markdown_page_is_rendered_and_linked_from_the_index(html):
    index = (html / "index.html").read_text(encoding="utf-8")
    for md in sorted(DOCS.glob("*.md")):
        page = html / f"{md.stem}.html"
        assert page.exists(), f"{md.name} is not rendered (no docs/{md.stem}.rst including it)"
        title = re.search(r"^#\s+(.+)$", md.read_text(encoding="utf-8"), re.M).group(1)
        title = re.sub(r"`", "", title)
        assert title in _page_text(page), f"{page.name} does not show {md.name}"
        assert f'href="{md.stem}.html"' in index, f"{md.stem} is not reachable from the index"


def test_math_is_rendered_without_network(html):
    mathjax = html / "_static" / "mathjax" / "tex-chtml.js"
    assert mathjax.is_file() and mathjax.stat().st_size > 100_000, "MathJax is not bundled"
    measures = (html / "measures.html").read_text(encoding="utf-8")
    assert 'src="_static/mathjax/tex-chtml.js"' in measures
    remote = re.compile(r"""<(?:script|img|iframe)\b[^>]*\bsrc=["'](?:https?:)?//"""
                        r"""|<link\b[^>]*\bhref=["'](?:https?:)?//[^"']*\.css"""
                        r"""|@import\s+url\(\s*["']?(?:https?:)?//""", re.I)
    pages = list(html.rglob("*.html")) + list((html / "_static").glob("*.css"))
    assert len(pages) > 30
    for page in pages:
        text = page.read_text(encoding="utf-8", errors="replace")
        hit = remote.search(text)
        assert hit is None, f"{page.relative_to(html)} loads {hit.group(0)!r} from the network"
        scripts = re.findall(r"<script\b[^>]*>", text)
        assert not [s for s in scripts if "cdn" in s.lower()], f"{page.name}: a CDN script"


def test_no_latex_label_in_the_pages(html):
    for page in html.rglob("*.html"):
        text = _page_text(page, prose=True)
        hit = _LABEL_IN_PAGE.search(text)
        assert hit is None, (f"{page.relative_to(html)} shows a LaTeX label: "
                             f"...{text[max(0, hit.start() - 60):hit.end() + 30]}...")


def test_no_latex_label_in_docstrings_pages_and_examples():
    files = ([ROOT / "README.md"] + sorted((ROOT / "kinred").rglob("*.py"))
             + sorted(DOCS.glob("*.md")) + sorted(DOCS.rglob("*.rst")) + sorted(EXAMPLES.glob("*.py")))
    files = [f for f in files if "_build" not in f.parts and "auto_examples" not in f.parts]
    hits = []
    for f in files:
        text = f.read_text(encoding="utf-8")
        hits += [f"{f.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0)}"
                 for m in _LABEL_IN_SOURCE.finditer(text)]
    assert not hits, "cite the paper's printed numbers, not its LaTeX labels:\n" + "\n".join(hits)


def test_gallery_shows_every_example_with_its_code(html):
    # (each script's output and figure: tests/test_examples.py::test_example_smoke)
    index = (html / "auto_examples" / "index.html").read_text(encoding="utf-8")
    scripts = sorted(EXAMPLES.glob("*.py"))
    assert scripts
    for script in scripts:
        name = script.stem
        assert f'href="{name}.html' in index, f"{name} is missing from the gallery index"
        page = html / "auto_examples" / f"{name}.html"
        text = _page_text(page)
        title = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))).splitlines()[0]
        assert "sphx-glr-example-title" in page.read_text(encoding="utf-8") and title in text, \
            f"{name}: the gallery page does not show the script's title {title!r}"
        # the code of its last section, as written
        code = script.read_text(encoding="utf-8").rsplit("\n# %%\n", 1)[1]
        last = [ln for ln in code.splitlines() if ln.strip() and not ln.startswith("#")][-1]
        assert last.strip() in text, f"{name}: the gallery page does not show {last!r}"


def test_tour_shows_the_demo_figures_and_table1(html):
    raw = (html / "getting-started.html").read_text(encoding="utf-8")
    text = _page_text(html / "getting-started.html")
    # the report's figures, drawn at build time (PNG data), each with the report's caption
    figures = re.findall(r'<figure\b[^>]*>\s*<img [^>]*src="data:image/png;base64,([^"]+)"[^>]*>'
                         r'\s*<figcaption>\s*<p><span class="caption-text">([^<]+)<', raw)
    assert len(figures) >= 3, "the demo's report figures are missing from the tour"
    for data, caption in figures:
        assert base64.b64decode(data).startswith(b"\x89PNG") and len(data) > 5_000
        assert len(caption.strip()) > 10, caption
    assert "$ kinred demo --atoms 100 --k 2 10" in text and "k=10" in text
    assert "Reading the demo output" in text and "TODO" not in text
    # Table 1 beside the paper's, and Figure 2
    assert "Table 1, reproduced" in text
    for cell in ("0/8/12", "14/0/6", "11/0/9", "13/0/7"):     # kinred and the paper (README)
        assert cell in text, cell
    assert (html / "_images" / "table1_beta1.62.png").is_file()
    assert "_images/table1_beta1.62.png" in raw


def test_markdown_converter_handles_the_subset():
    sys.path.insert(0, str(DOCS))
    try:
        import conf
    finally:
        sys.path.remove(str(DOCS))
    md = ("# Title\n\nText with `code`s and [a link](https://example.org) and a|b.\n\n"
          "| a | b |\n|---|---|\n| `x` | 2 |\n\n* one\n  more\n* two\n\n```toml\nk = 1\n```\n")
    rst = conf.markdown_to_rst(md)
    assert rst[1:3] == ["Title", "====="]
    assert "Text with ``code``\\ s and `a link <https://example.org>`__ and a\\|b." in rst
    assert ".. list-table::" in rst and "   * - ``x``" in rst and "     - 2" in rst
    assert "- one more" in rst and "- two" in rst
    assert ".. code-block:: toml" in rst and "   k = 1" in rst
    # notes for the authors are dropped, whole lines or inside a line
    rst = conf.markdown_to_rst("a\n<!-- TODO: x\n y -->\nb <!-- z --> c\n\n  <!-- w -->\n* i\n")
    assert rst[:2] == ["a b  c", ""] and "- i" in rst and not any("<!--" in r for r in rst)
    # one section of a page: from its heading to the next heading of the same level
    md = "# T\n\n## A\n\nx\n\n```\n## not a heading\n```\n\n### A1\n\ny\n\n## B\n\nz\n"
    sec = conf.markdown_section(md, "A")
    assert sec.startswith("## A\n") and "## not a heading" in sec and "y" in sec
    assert "## B" not in sec and "z" not in sec
    assert conf.markdown_section(md, "B") == "## B\n\nz\n"
    assert conf.markdown_section(md, "missing") is None
