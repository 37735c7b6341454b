r"""Headless Chromium for reports: inspect a page's layout, take a screenshot.

No Python dependency: Chromium's command line does the work. :func:`inspect_page` loads a
copy of the page with a small script appended that measures, once the page has loaded, every
figure (loaded? visible? inside the page?) and every text box (does its text overflow?), and
writes the result as JSON into the page; ``chromium --dump-dom`` prints the page, and the JSON
is read back from it. :func:`screenshot` is ``chromium --screenshot`` (with the page's full
height measured first when asked).

Chromium is found as ``chromium``, ``chromium-browser``, ``google-chrome`` or ``$CHROMIUM``;
on Debian/Ubuntu ``apt-get install -y chromium``.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

from .._validate import as_int
from ..errors import InvalidInput, KinredError

__all__ = ["BrowserMissing", "BrowserFailed", "find_chromium", "inspect_page", "screenshot"]

_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
INSTALL_HINT = ("install Chromium (Debian/Ubuntu: `apt-get install -y chromium`; `make test` "
                "does it when run as root) or set CHROMIUM to its path")


class BrowserMissing(KinredError, RuntimeError):
    """No Chromium executable was found."""


class BrowserFailed(KinredError, RuntimeError):
    """Chromium ran but did not produce what was asked (exit status, timeout, no output)."""


def find_chromium() -> str:
    """Path of the Chromium executable (``$CHROMIUM`` first), or :class:`BrowserMissing`."""
    env = os.environ.get("CHROMIUM")
    if env:
        if shutil.which(env):
            return shutil.which(env)
        raise BrowserMissing(f"CHROMIUM={env!r} is not an executable; {INSTALL_HINT}")
    for name in _NAMES:
        path = shutil.which(name)
        if path:
            return path
    raise BrowserMissing(f"no Chromium found (looked for {', '.join(_NAMES)}); {INSTALL_HINT}")


def _page(path) -> Path:
    p = Path(path)
    if not p.is_file():
        raise InvalidInput(f"page {str(path)!r} is not a file")
    return p.resolve()


def _run(args: list, timeout: float, attempts: int = 2) -> subprocess.CompletedProcess:
    """Run Chromium with ``args``; the result's ``stdout``/``stderr`` are text.

    Chromium's output goes to files, not pipes, and only the browser process is waited for:
    a helper it leaves behind (crashpad handler, zygote) that still holds an inherited pipe
    would otherwise keep ``communicate`` waiting until the timeout although the work is done.
    Each attempt runs in its own process group, killed whole when the browser has exited or
    timed out. A timed-out attempt (a headless browser can hang on a loaded machine) is
    retried once with a fresh profile before :class:`BrowserFailed` is raised.
    """
    exe = find_chromium()
    for _ in range(attempts):
        p = _run_once(exe, args, timeout)
        if p is not None:
            break
    else:
        raise BrowserFailed(f"chromium did not finish within {timeout:g} s ({attempts} "
                            f"attempts): {' '.join(args)}")
    if p.returncode != 0:
        raise BrowserFailed(f"chromium exited with status {p.returncode}: "
                            f"{p.stderr.strip()[-500:]}")
    return p


def _run_once(exe: str, args: list, timeout: float):
    """One Chromium run; its CompletedProcess, or None when it did not exit within timeout."""
    with tempfile.TemporaryDirectory(prefix="kinred-chromium-") as profile:
        # --test-type: no "unsupported flag" info bar over the page; compositor stages run
        # before the screenshot is taken (else a loaded machine can leave tiles unpainted)
        # no background networking: this machine's network is closed, and a headless page
        # load must not wait on (or be slowed by) refused connections
        cmd = [exe, "--headless", "--disable-gpu", "--no-sandbox", "--test-type",
               "--disable-background-networking", "--disable-component-update",
               "--disable-sync", "--disable-quic", "--disable-breakpad",
               "--hide-scrollbars", "--no-first-run", "--disable-extensions", "--mute-audio",
               "--run-all-compositor-stages-before-draw", f"--user-data-dir={profile}", *args]
        with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
            proc = subprocess.Popen(cmd, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                    start_new_session=True)
            try:
                code = proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                code = None
            finally:
                _kill_group(proc)
            if code is None:
                return None
            out.seek(0)
            err.seek(0)
            stdout = out.read().decode("utf-8", "replace")
            stderr = err.read().decode("utf-8", "replace")
    return subprocess.CompletedProcess(cmd, code, stdout, stderr)


def _kill_group(proc: subprocess.Popen) -> None:
    """Kill the process group of ``proc`` (the browser and every helper it started)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:  # pragma: no cover - a process that ignores SIGKILL
        pass


#: Runs in the page on ``load``: opens every ``<details>`` (when asked), then measures.
_SCRIPT = r"""
<script>
window.addEventListener("load", function () {
  var openDetails = %(open)s;
  if (openDetails) document.querySelectorAll("details").forEach(function (d) { d.open = true; });
  var de = document.documentElement, vw = de.clientWidth;
  function scrolls(el) {
    for (var a = el.parentElement; a && a !== document.body; a = a.parentElement) {
      var o = getComputedStyle(a).overflowX;
      if (o === "auto" || o === "scroll") return true;
    }
    return false;
  }
  function shown(el) {
    for (var a = el; a && a !== document; a = a.parentElement) {
      var s = getComputedStyle(a);
      if (s.display === "none" || s.visibility === "hidden" || +s.opacity === 0) return false;
    }
    var r = el.getBoundingClientRect();
    return r.width > 0 && r.height > 0;
  }
  var images = [].map.call(document.images, function (im) {
    var r = im.getBoundingClientRect();
    return {alt: (im.alt || "").slice(0, 80), complete: im.complete,
            naturalWidth: im.naturalWidth, naturalHeight: im.naturalHeight,
            width: r.width, height: r.height, top: r.top + scrollY, left: r.left,
            right: r.right, visible: shown(im)};
  });
  var overflow = [];
  document.querySelectorAll("%(text)s").forEach(function (el) {
    if (!shown(el) || scrolls(el)) return;
    var r = el.getBoundingClientRect();
    if (el.scrollWidth > el.clientWidth + 1 || r.right > vw + 1)
      overflow.push({tag: el.tagName.toLowerCase(), text: el.textContent.slice(0, 80),
                     scrollWidth: el.scrollWidth, clientWidth: el.clientWidth,
                     right: r.right});
  });
  function firstTop(sel) {
    var el = document.querySelector(sel);
    return el && shown(el) ? el.getBoundingClientRect().top + scrollY : null;
  }
  var out = {viewportWidth: vw, viewportHeight: innerHeight, pageWidth: de.scrollWidth,
             pageHeight: de.scrollHeight, images: images, overflow: overflow,
             firstFigureTop: firstTop("figure"), firstTableTop: firstTop("table"),
             details: document.querySelectorAll("details").length,
             figureNotes: document.querySelectorAll(".figure-note").length};
  var pre = document.createElement("pre");
  pre.id = "kinred-inspect";
  pre.style.display = "none";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>
"""

#: Elements whose text must fit their box (outside sideways-scrolling containers).
TEXT_ELEMENTS = "h1,h2,h3,h4,p,li,figcaption,caption,summary,td,th,pre,small,label,a,span"


def inspect_page(path, *, width: int = 1280, height: int = 900, open_details: bool = True,
                 timeout: float = 60.0) -> dict:
    """Load an HTML page in headless Chromium and measure its figures and text boxes.

    Parameters
    ----------
    path : path-like
        The page (a self-contained file such as a ``report.html``; it is not modified: a copy
        with the measuring script is loaded).
    width, height : int
        Window size in CSS pixels.
    open_details : bool
        Open every ``<details>`` element before measuring (folded tables are checked too).
    timeout : float
        Seconds Chromium may take.

    Returns
    -------
    dict
        ``images`` (per ``<img>``: ``complete``, ``naturalWidth``, ``naturalHeight``,
        ``width``, ``height``, ``top``, ``left``, ``right``, ``visible``), ``overflow`` (text
        elements not in a sideways-scrolling box whose content is wider than the box or that
        reach past the window: ``tag``, ``text``, ``scrollWidth``, ``clientWidth``),
        ``viewportWidth``, ``pageWidth``, ``pageHeight``, ``firstFigureTop``,
        ``firstTableTop`` (page coordinates, None if absent or hidden), ``details``,
        ``figureNotes``.

    Raises
    ------
    BrowserMissing, BrowserFailed, InvalidInput
    """
    page = _page(path)
    width = as_int(width, "width", low=200)
    height = as_int(height, "height", low=200)
    text = page.read_text(encoding="utf-8")
    script = _SCRIPT % {"open": "true" if open_details else "false", "text": TEXT_ELEMENTS}
    cut = text.lower().rfind("</body>")
    text = text[:cut] + script + text[cut:] if cut >= 0 else text + script
    with tempfile.TemporaryDirectory(prefix="kinred-inspect-") as tmp:
        copy = Path(tmp) / page.name
        copy.write_text(text, encoding="utf-8")
        p = _run([f"--window-size={width},{height}", "--virtual-time-budget=5000",
                  "--dump-dom", copy.as_uri()], timeout)
    m = re.search(r'<pre id="kinred-inspect"[^>]*>(.*?)</pre>', p.stdout, re.S)
    if not m:
        raise BrowserFailed(f"chromium loaded {page} but the measuring script left no result "
                            f"(stderr: {p.stderr.strip()[-300:]})")
    return json.loads(html.unescape(m.group(1)))


def screenshot(path, out, *, width: int = 1280, height: int | None = None,
               timeout: float = 60.0) -> tuple:
    """Save a PNG of an HTML page as headless Chromium renders it.

    ``height`` None: the page's full height (measured first, at most 16384 px). Returns the
    ``(width, height)`` of the PNG.
    """
    page = _page(path)
    width = as_int(width, "width", low=200)
    if height is None:
        height = min(int(inspect_page(page, width=width, open_details=False,
                                      timeout=timeout)["pageHeight"]), 16384)
    height = as_int(height, "height", low=200)
    out = Path(out).resolve()
    if not out.parent.is_dir():
        raise InvalidInput(f"out: folder {str(out.parent)!r} does not exist")
    if out.exists():
        out.unlink()
    _run([f"--window-size={width},{height}", "--virtual-time-budget=5000",
          f"--screenshot={out}", page.as_uri()], timeout)
    if not out.is_file():
        raise BrowserFailed(f"chromium wrote no screenshot to {out}")
    return png_size(out.read_bytes())


def png_size(data: bytes) -> tuple:
    """``(width, height)`` from a PNG's header."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or len(data) < 24:
        raise InvalidInput("not a PNG")
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
