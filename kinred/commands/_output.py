"""The one output rule of the long commands: where results go, and what a rerun does.

Default folder
    ``results/<command>[-<scene>][-quick|-smoke]``: the sub-command's words joined by ``-``,
    then the scene file's stem for ``kinred run``, then the size preset when one is chosen.
    ``kinred demo`` → ``results/demo``, ``kinred run examples/scenes/cucker-smale-200.toml``
    → ``results/run-cucker-smale-200``, ``kinred paper fig4 --quick`` →
    ``results/paper-fig4-quick``, ``kinred cost --quick`` → ``results/cost-quick``.

Rerun
    A folder that holds a previous result of the **same command** (every file in it is one
    kinred writes for that command) is

    * continued with ``--resume`` (finished stages are loaded, the rest is computed);
    * replaced without it: its files are removed first and the command says so in one line,
      ``kinred <command>: replacing the previous run in DIR; use --resume to continue it``.

    A folder holding anything else -- files kinred does not write for this command, or the
    result of another command -- is refused with :class:`~kinred.errors.InvalidInput`
    (``kinred: error: ...``, exit status 2) and left untouched.

One process at a time: :func:`prepare` takes the folder's lock (``kinred._lock``, the
hidden file ``.kinred.lock`` naming the holder's pid, host, start and command line) before it
looks at, clears or writes anything, and holds it until :func:`record` (or the end of the
command, however it ends). A second command into a folder in use is refused with one line
naming the holder (:class:`~kinred.errors.FolderInUse`, exit status 2), without touching the
folder; the lock of a process that has ended is taken over.

How a folder is recognized: every command writes the marker file ``.kinred-result.json``
(``{"command": ..., "files": [...]}``) into its folder before its first result and updates
its list of files when it finishes. A folder is the command's own when its marker names the
command (or, written before markers existed, it holds the command's summary or stage index)
and each of its files matches the command's :class:`Layout` or the marker's list.
"""

from __future__ import annotations

import errno
import fnmatch
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from .._lock import FolderLock, is_lock_file
from ..errors import DiskFull, InvalidInput
from ..io import atomic_write_json

__all__ = ["RESULTS", "MARKER", "Layout", "default_out", "prepare", "record", "LAYOUTS",
           "add_scene_arguments"]

#: Parent of every default result folder.
RESULTS = Path("results")
#: The marker file a command writes into its result folder.
MARKER = ".kinred-result.json"


@dataclass(frozen=True)
class Layout:
    """What one command writes into its result folder.

    Attributes
    ----------
    command : str
        The command's words as typed, e.g. ``"paper fig4"``.
    files : tuple of str
        Glob patterns (``fnmatch``, ``/``-separated, relative to the folder) of its files.
    identify : tuple of str
        Files that identify a result of the command written before the marker existed.
    """

    command: str
    files: tuple
    identify: tuple = ("summary.json",)


_KINETIC = ("stages/*", "results.npz", "summary.json", "report.html", "*.png")
_ENSEMBLE = ("store/*", "summary.json", "report.html", "*.png")

#: The layouts of the long commands, by command.
LAYOUTS = {
    "demo": Layout("demo", _KINETIC, ("summary.json", "stages/config.json")),
    "run": Layout("run", _KINETIC, ("summary.json", "stages/config.json")),
    "certify": Layout("certify", _KINETIC, ("summary.json", "stages/config.json")),
    "paper table1": Layout("paper table1", _ENSEMBLE + ("gamma.npz", "table1.txt", "table1.json"),
                           ("summary.json", "store/run.json")),
    "paper calibrate": Layout("paper calibrate",
                              _ENSEMBLE + ("calibration.json", "calibration.txt"),
                              ("summary.json", "store/run.json")),
    "paper fig4": Layout("paper fig4", ("stages/*", "fig4.json", "summary.json", "report.html",
                                        "fig4.png"), ("summary.json", "stages/config.json")),
    "paper strategies": Layout("paper strategies", ("stages/*", "strategies.json",
                                                    "strategies.txt", "summary.json"),
                               ("summary.json", "stages/config.json")),
    "cost": Layout("cost", ("stages/*", "cost.json", "cost.txt", "summary.json", "report.html",
                            "cost_*.png"), ("summary.json", "stages/config.json")),
}


def default_out(command: str, *, scene: str | None = None, size: str | None = None) -> Path:
    """``results/<command words joined by ->[-<scene>][-<size>]`` (see the module docstring).

    Examples
    --------
    >>> default_out("paper fig4", size="quick").as_posix()
    'results/paper-fig4-quick'
    >>> default_out("run", scene="cucker-smale-200").as_posix()
    'results/run-cucker-smale-200'
    """
    name = "-".join(command.split())
    for part in (scene, size):
        if part:
            name += f"-{part}"
    return RESULTS / name


def _is_temporary(name: str) -> bool:
    return name.startswith(".") and name.endswith(".tmp")


def _files(out: Path) -> list[str]:
    """Relative ``/``-names of the folder's files (temporary files of a killed writer excluded)."""
    return sorted(p.relative_to(out).as_posix() for p in out.rglob("*")
                  if (p.is_file() or p.is_symlink()) and not _is_temporary(p.name)
                  and not is_lock_file(p.name))


def _read_marker(out: Path) -> dict | None:
    """The folder's marker, or None when it has none (or one that cannot be read)."""
    try:
        data = json.loads((out / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("command"), str) else None


def _listing(names: list[str], limit: int = 4) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f", … ({len(names)} files)" if len(names) > limit else "")


def _check(out: Path, layout: Layout, files: list[str]) -> None:
    """Refuse a folder that is not a previous result of ``layout.command``."""
    marker = _read_marker(out)
    if marker is not None and marker["command"] != layout.command:
        raise InvalidInput(
            f"--out {out}: holds the result of `kinred {marker['command']}`, not of `kinred "
            f"{layout.command}`; choose another folder with --out (or delete this one)")
    listed = set(marker.get("files", ())) if marker else set()
    foreign = [f for f in files if f != MARKER and f not in listed
               and not any(fnmatch.fnmatchcase(f, p) for p in layout.files)]
    if marker is None and not any(f in files for f in layout.identify):
        foreign = [f for f in files if f != MARKER]
    if foreign:
        raise InvalidInput(
            f"--out {out}: holds files kinred did not write for `kinred {layout.command}` "
            f"({_listing(foreign)}); choose a new or empty folder with --out, or move them "
            "away (kinred replaces only its own previous results)")


def _clear(out: Path, files: list[str]) -> None:
    """Remove the previous result's files (and the folders they leave empty)."""
    for name in files:
        (out / name).unlink(missing_ok=True)
    for p in sorted((p for p in out.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
        if not any(p.iterdir()):
            p.rmdir()
    for p in out.rglob(".*.tmp"):
        p.unlink(missing_ok=True)


def prepare(out, layout: Layout, *, resume: bool, stream=None) -> Path:
    """Apply the rerun rule to the result folder ``out`` before ``layout.command`` runs.

    Parameters
    ----------
    out : str or os.PathLike
        The result folder (created when missing).
    layout : Layout
        What the command writes.
    resume : bool
        ``--resume``: keep the previous result so that the command continues it.
    stream : file, optional
        Where the one-line notice of a replaced run goes (default ``sys.stdout``).

    Returns
    -------
    Path
        The folder, holding the command's marker and, with ``resume``, the previous result;
        this process holds its lock until :func:`record` (or ``kinred._lock.release_all()``).

    Raises
    ------
    InvalidInput
        ``out`` is a file, or holds files kinred does not write for this command, or the
        result of another command.
    FolderInUse
        Another process holds the folder (the message names it).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InvalidInput(f"--out {out}: is a file; give a folder for the results")
    if out.is_dir() and _files(out):
        _check(out, layout, _files(out))          # refuse a foreign folder before touching it
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if exc.errno == errno.ENOSPC:
            raise DiskFull(f"--out {out}: cannot create the folder: no space left on device",
                           path=str(out)) from None
        raise InvalidInput(f"--out {out}: cannot create the folder: {exc.strerror}") from None
    lock = FolderLock(out, what="result folder").acquire()
    try:
        _replace(out, layout, resume, stream)
    except BaseException:
        lock.release()
        raise
    _HELD.setdefault(str(out.resolve()), []).append(lock)
    return out


#: The locks :func:`prepare` took, by folder, until :func:`record` releases them.
_HELD: dict = {}


def _replace(out: Path, layout: Layout, resume: bool, stream) -> None:
    """The rerun rule, once the folder is ours: keep (resume) or clear it, write the marker."""
    files = _files(out)
    if files:
        _check(out, layout, files)
        if not resume:
            _clear(out, files)
        if not resume and files != [MARKER]:       # (only a marker: nothing was computed)
            print(f"kinred {layout.command}: replacing the previous run in {out}; use --resume "
                  "to continue it", file=stream or sys.stdout, flush=True)
    out.mkdir(parents=True, exist_ok=True)    # (_clear removes it when it empties it)
    if resume and (out / MARKER).is_file() and _read_marker(out) is not None:
        return
    atomic_write_json(out / MARKER, {"command": layout.command, "files": []})


def record(out, layout: Layout) -> None:
    """Write the list of the folder's files into its marker (once the command has finished)
    and release the folder's lock taken by :func:`prepare`."""
    out = Path(out)
    files = [f for f in _files(out) if f != MARKER and not f.startswith(("stages/", "store/"))]
    atomic_write_json(out / MARKER, {"command": layout.command, "files": files})
    for lock in _HELD.pop(str(out.resolve()), []):
        lock.release()


def add_scene_arguments(parser, command: str) -> None:
    """The arguments every scene-file command shares (``kinred run``, ``kinred certify``):
    ``SCENE.toml``, ``--out`` (default ``results/<command>-<scene name>``), ``--resume``,
    ``--smoke``, ``--no-progress`` and ``--no-figures``."""
    parser.add_argument("scene", metavar="SCENE.toml", help="scene file (see docs/scene-file.md)")
    parser.add_argument("--out", metavar="DIR",
                        help=f"result folder (default results/{command}-<scene name>; a previous "
                             f"`kinred {command}` there is replaced unless --resume)")
    parser.add_argument("--resume", action="store_true",
                        help="continue an interrupted run in --out (finished stages are loaded)")
    parser.add_argument("--smoke", action="store_true",
                        help="tiny sizes from the scene's [smoke] table (seconds)")
    parser.add_argument("--no-progress", action="store_true",
                        help="hide the progress bar (shown on stderr when it is a terminal)")
    parser.add_argument("--no-figures", action="store_true",
                        help="write the report without drawing its figures (each is a note; "
                             "about 2 s less per run, for sweeps that read summary.json)")
