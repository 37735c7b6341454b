"""Screenshot of a report as headless Chromium shows it, for reviewers.

Usage::

    python -m kinred.report.screenshot results/demo/report.html --out shot.png
    python -m kinred.report.screenshot results/demo/report.html --out top.png --height 900

Without ``--height`` the whole page is captured (its height measured first); ``--width``
sets the window width in CSS pixels (default 1280). Needs Chromium (Debian/Ubuntu:
``apt-get install -y chromium``, or set ``CHROMIUM`` to its path). Errors are one line on
stderr (``kinred: error: ...``, exit status 2), as for the ``kinred`` command.
"""

from __future__ import annotations

import argparse
import sys

from ..errors import KinredError
from ._browser import screenshot

__all__ = ["main"]


def build_parser() -> argparse.ArgumentParser:
    """The command's argument parser."""
    p = argparse.ArgumentParser(prog="python -m kinred.report.screenshot",
                                description="Save a PNG of an HTML report rendered by headless "
                                            "Chromium.")
    p.add_argument("page", help="the HTML file (e.g. results/demo/report.html)")
    p.add_argument("--out", required=True, help="PNG file to write")
    p.add_argument("--width", type=int, default=1280, help="window width in CSS px (1280)")
    p.add_argument("--height", type=int, default=None,
                   help="window height in CSS px (default: the whole page, at most 16384)")
    return p


def main(argv=None) -> int:
    """Run the command; returns the exit status (0, or 2 on a
    :class:`~kinred.errors.KinredError`)."""
    args = build_parser().parse_args(argv)
    try:
        w, h = screenshot(args.page, args.out, width=args.width, height=args.height)
    except KinredError as exc:
        print(f"kinred: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    print(f"screenshot: {args.out} ({w} x {h} px)")
    return 0


if __name__ == "__main__":  # pragma: no cover - exercised through python -m in the tests
    sys.exit(main())
