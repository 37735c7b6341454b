"""The ``kinred`` command: a thin layer over :mod:`kinred.experiments` and friends.

Each sub-command lives in a module of :mod:`kinred.commands` exposing

* ``NAME`` -- the sub-command's name,
* ``HELP`` -- one line of help,
* ``add_arguments(parser)`` -- declare its options,
* ``run(args) -> int`` -- do the work, return the exit code.

Errors derived from :class:`kinred.errors.KinredError` are printed as one line on stderr
(``kinred: error: ...``) with exit code 2 and no traceback; an interrupt exits with 130 and
says how to resume where the command supports it. Warnings of the
:class:`kinred.errors.KinredWarning` family (a damaged stage file recomputed, a figure that
could not be drawn) are printed as one line each, ``kinred: warning: ...``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys
import warnings

from .errors import KinredError, KinredWarning

__all__ = ["main", "build_parser"]

#: Modules of :mod:`kinred.commands`, in the order ``kinred --help`` lists them.
COMMAND_MODULES: tuple[str, ...] = (
    "kinred.commands.demo",
    "kinred.commands.quantize",
    "kinred.commands.run",
    "kinred.commands.certify",
    "kinred.commands.paper",
    "kinred.commands.cost",
)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (sub-commands loaded from :data:`COMMAND_MODULES`)."""
    from ._version import __version__

    parser = argparse.ArgumentParser(
        prog="kinred",
        description="Interacting agents in high dimension, random projections and kinetic limits.",
    )
    parser.add_argument("--version", action="version", version=f"kinred {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for modname in COMMAND_MODULES:
        mod = importlib.import_module(modname)
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


@contextlib.contextmanager
def _one_line_warnings():
    """Within the block, every KinredWarning is printed as one line ``kinred: warning: ...``."""
    with warnings.catch_warnings():
        default_show = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, KinredWarning):
                print(f"kinred: warning: {message}", file=sys.stderr)
            else:
                default_show(message, category, filename, lineno, file, line)

        warnings.simplefilter("always", KinredWarning)
        warnings.showwarning = show
        yield


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``kinred`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    with _one_line_warnings():
        return _run(args)


def _run(args) -> int:
    from ._lock import release_all

    try:
        code = args._run(args)
    except KinredError as exc:
        print(f"kinred: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("kinred: interrupted; finished results are on disk (rerun with --resume to "
              "continue)", file=sys.stderr)
        return 130
    except BrokenPipeError:                   # e.g. `kinred ... | head`: the reader left
        try:
            sys.stdout = open(os.devnull, "w")    # no second error when Python flushes at exit
        except OSError:
            pass
        return 141
    finally:
        release_all()                         # the result folders the command held
    return 0 if code is None else int(code)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
