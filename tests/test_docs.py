"""The Sphinx documentation builds without a single warning, and has its API and CLI pages."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

API_MODULES = ["measures", "quantize", "distance", "projection", "dynamics", "pairsum",
               "integrate", "observables", "recovery", "ensemble", "kinetic", "certify", "io",
               "report", "errors"]


@pytest.fixture(scope="module")
def html(tmp_path_factory):
    import sphinx  # noqa: F401  - a hard dependency of the test extra: fail, never skip
    out = tmp_path_factory.mktemp("html")
    doctrees = tmp_path_factory.mktemp("doctrees")
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html",
         "-d", str(doctrees), str(DOCS), str(out)],
        capture_output=True, text=True, timeout=600, cwd=ROOT,
    )
    assert proc.returncode == 0, f"sphinx-build failed:\n{proc.stdout}\n{proc.stderr}"
    assert "WARNING" not in proc.stderr, proc.stderr
    return out


def test_build_writes_nothing_into_the_tree(html):
    assert not (DOCS / "_build").exists()


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
                 "kinetic", "certificates", "cost", "scene-file", "measures-file", "examples",
                 "architecture"]:
        assert (html / f"{page}.html").exists(), page
    # the equations are rendered as math (MathJax), with the paper's numbers next to them
    measures = (html / "measures.html").read_text(encoding="utf-8")
    assert re.search(r'class="math', measures) and "(4.22)" in measures
    assert "make demo" in (html / "getting-started.html").read_text(encoding="utf-8")


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
