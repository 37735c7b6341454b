"""``report.html`` in a real browser: headless Chromium (Debian package ``chromium``).

A smoke-size demo is run, its report loaded at two window widths, and the layout measured
(kinred.report._browser.inspect_page): every figure loads and is visible inside the page, no
text overflows its box, the page never scrolls sideways, figures come before tables.
The checker itself is shown to catch a broken page. Without Chromium the tests FAIL, saying
how to install it (`make test` installs it).
"""

import subprocess
import sys
import pytest

from kinred.report import validate_report_html
from kinred.report._browser import BrowserMissing, find_chromium, inspect_page, png_size

@pytest.fixture(scope="module")
def chromium():
    try:
        return find_chromium()
    except BrowserMissing as exc:
        pytest.fail(f"headless Chromium is needed for the report's browser tests: {exc}")


@pytest.fixture(scope="module")
def report(tmp_path_factory, chromium):
    from kinred.experiments import demo

    out = tmp_path_factory.mktemp("demo")
    demo.run(demo.DemoConfig(smoke=True), out_dir=out, progress=False)
    return out / "report.html"


@pytest.mark.parametrize("width", [1280, 720])
def test_report_figures_load_and_text_fits(report, width):
    page = report
    n_figures = validate_report_html(page.read_text(encoding="utf-8"))
    r = inspect_page(page, width=width, height=900)
    assert n_figures == 4 and len(r["images"]) == n_figures and r["figureNotes"] == 0
    for im in r["images"]:
        assert im["complete"] and im["naturalWidth"] > 0 and im["naturalHeight"] > 0, im
        assert im["visible"] and im["width"] > 0.4 * min(width, 1100) - 40, im
        assert im["left"] >= 0 and im["right"] <= r["viewportWidth"] + 0.5, im
    assert r["overflow"] == [], r["overflow"]
    assert r["pageWidth"] <= r["viewportWidth"], "the page scrolls sideways"
    # figures first, and the first one starts on the first screen; per-time tables folded
    assert r["firstFigureTop"] < r["firstTableTop"]
    assert r["firstFigureTop"] < r["viewportHeight"]
    assert r["details"] == page.read_text(encoding="utf-8").count("<details>") >= 2


def test_checker_catches_a_broken_page(tmp_path, chromium):
    page = tmp_path / "broken.html"
    page.write_text(
        "<!DOCTYPE html><html><body style='margin:0'>"
        "<p style='width:120px'>" + "x" * 200 + "</p>"
        "<div style='overflow-x:auto;width:120px'><table><tr><td style='white-space:nowrap'>"
        + "y" * 200 + "</td></tr></table></div>"
        "<img alt='broken' src='data:image/png;base64,AAAA'>"
        "<img alt='hidden' style='display:none' src='data:image/png;base64,AAAA'>"
        "</body></html>", encoding="utf-8")
    r = inspect_page(page, width=800, height=600)
    assert [(o["tag"], o["text"][:3]) for o in r["overflow"]] == [("p", "xxx")]  # not the td
    broken, hidden = r["images"]
    assert broken["naturalWidth"] == 0 and not hidden["visible"]


def test_screenshot_command(report, tmp_path):
    shot = tmp_path / "top.png"
    p = subprocess.run([sys.executable, "-m", "kinred.report.screenshot", str(report),
                        "--out", str(shot), "--width", "1000", "--height", "700"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert png_size(shot.read_bytes()) == (1000, 700)
    assert p.stdout.strip() == f"screenshot: {shot} (1000 x 700 px)"


def test_screenshot_errors_are_one_line(tmp_path, capsys):
    from kinred.report.screenshot import main

    assert main([str(tmp_path / "missing.html"), "--out", str(tmp_path / "s.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("kinred: error: InvalidInput: page") and err.count("\n") == 1


def _fake_browser(tmp_path, body):
    exe = tmp_path / "fake-chromium"
    exe.write_text("#!/bin/sh\n" + body)
    exe.chmod(0o755)
    return str(exe)


def test_a_helper_holding_the_output_does_not_stall_the_run(tmp_path, monkeypatch):
    """The browser exits while a helper it started keeps the inherited stdout open (as a
    crashpad handler can): the run returns when the browser exits, and the helper is killed."""
    import time
    from kinred.report._browser import _run

    monkeypatch.setenv("CHROMIUM", _fake_browser(tmp_path, "sleep 60 &\necho page-dom\n"))
    t0 = time.perf_counter()
    p = _run(["--dump-dom", "x"], timeout=30)
    assert time.perf_counter() - t0 < 15
    assert p.returncode == 0 and p.stdout.strip() == "page-dom"


def test_a_hung_browser_is_retried_once_then_named(tmp_path, monkeypatch):
    from kinred.report._browser import BrowserFailed, _run

    mark = tmp_path / "tried"
    # hangs on the first call only
    monkeypatch.setenv("CHROMIUM", _fake_browser(
        tmp_path, f"if [ ! -e {mark} ]; then touch {mark}; sleep 60; fi\necho second\n"))
    p = _run(["--dump-dom", "x"], timeout=1.0)
    assert p.stdout.strip() == "second" and mark.exists()
    monkeypatch.setenv("CHROMIUM", _fake_browser(tmp_path, "sleep 60\n"))
    with pytest.raises(BrowserFailed, match=r"within 1 s \(2 attempts\): --dump-dom x"):
        _run(["--dump-dom", "x"], timeout=1.0)
