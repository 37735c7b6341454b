"""One process at a time per result folder: the lock file ``.kinred.lock``.

A command (``kinred run``, ``kinred certify``, ...) owns its result folder while it runs, and a
:class:`~kinred.io.StageStore` owns its store folder while it is open. Ownership is an
exclusive ``flock`` on the hidden file ``<folder>/.kinred.lock``, which also holds a JSON line
naming the holder: its pid, host, start time (UTC) and command line. A second process asking
for the folder is refused at once with :class:`~kinred.errors.FolderInUse`, whose one-line
message names the holder.

* The kernel drops the ``flock`` when its process ends, however it ends (``SIGKILL`` too):
  the lock file of a dead process is *stale* and the next process takes it over (rewriting
  the holder line). Where ``flock`` is missing (Windows), the lock file is created
  exclusively and a file naming a pid that no longer runs on this host is stale.
* Within one process the lock is re-entrant (a command holds its folder, the run it starts
  opens its stage store in a sub-folder, a resumed store is opened twice in a test): it is
  released when every acquisition is released, and the file is removed then.
* Locks held by a process are released by :func:`release_all` (the ``kinred`` command calls
  it when a command returns) or at its exit; a forked worker holds none of them.
"""

from __future__ import annotations

import atexit
import datetime
import json
import os
import socket
import sys
import threading
from pathlib import Path

from .errors import FolderInUse, InvalidInput

try:  # pragma: no cover - the import itself
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = ["LOCK_NAME", "FolderLock", "lock_folder", "release_all", "is_lock_file"]

#: File name of the lock inside a folder.
LOCK_NAME = ".kinred.lock"

_MUTEX = threading.RLock()
#: ``{realpath of the folder: [fd, count, lock path]}`` of the locks this process holds.
_HELD: dict = {}


def is_lock_file(name: str) -> bool:
    """Whether the file name ``name`` is a folder lock (never part of a result)."""
    return name == LOCK_NAME


def _command_line() -> str:
    argv = [os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "python"]
    return " ".join(argv + list(sys.argv[1:]))[:400]


def _holder_text(holder: dict) -> str:
    if not holder:
        return "another process (its lock file names no holder yet)"
    pid, host = holder.get("pid", "?"), holder.get("host", "?")
    text = f"pid {pid} on {host}"
    if holder.get("started"):
        text += f", since {holder['started']}"
    if holder.get("command"):
        text += f": `{holder['command']}`"
    return text


def _read_holder(fd: int) -> dict:
    try:
        data = os.pread(fd, 4096, 0)
        holder = json.loads(data.decode("utf-8")) if data.strip() else {}
    except (OSError, ValueError):
        return {}
    return holder if isinstance(holder, dict) else {}


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, TypeError, ProcessLookupError):
        return False
    except (PermissionError, OSError):
        return True
    return True


class FolderLock:
    """The lock of one folder held by this process (see the module docstring).

    Parameters
    ----------
    folder : str or os.PathLike
        An existing directory.
    what : str
        How messages call the folder (``"result folder"``, ``"stage store"``).
    command : str, optional
        The holder's command line written into the lock (default: this process's).

    Attributes
    ----------
    path : Path
        The lock file.
    previous : dict
        The holder line of a stale lock this one took over (empty if none).
    """

    def __init__(self, folder, *, what: str = "result folder", command: str | None = None):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.what = what
        self.command = _command_line() if command is None else str(command)
        self.previous: dict = {}
        self._key = os.path.realpath(self.folder)
        self._held = False

    def __repr__(self) -> str:
        return f"FolderLock({str(self.folder)!r}, held={self._held})"

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()

    # -- acquire ------------------------------------------------------------------------------
    def acquire(self) -> "FolderLock":
        """Take the lock (re-entrant within the process); :class:`FolderInUse` if another
        process holds it."""
        if self._held:
            return self
        with _MUTEX:
            entry = _HELD.get(self._key)
            if entry is not None:
                entry[1] += 1
            else:
                fd = self._take()
                _HELD[self._key] = [fd, 1, self.path]
            self._held = True
        return self

    def _busy(self, holder: dict) -> FolderInUse:
        return FolderInUse(
            f"{self.folder}: this {self.what} is in use by {_holder_text(holder)}; wait for "
            f"it to finish or choose another folder (a lock of a process that has ended is "
            f"taken over: {self.path})", path=str(self.folder), holder=holder)

    def _open(self, flags: int) -> int:
        try:
            return os.open(self.path, flags, 0o644)
        except FileExistsError:
            raise
        except OSError as exc:
            raise InvalidInput(f"{self.folder}: cannot lock the {self.what}: "
                               f"{exc.strerror or exc}") from None

    def _take(self) -> int:
        for _ in range(20):
            if fcntl is None:  # pragma: no cover - Windows
                fd = self._take_exclusive()
            else:
                fd = self._open(os.O_RDWR | os.O_CREAT)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    holder = _read_holder(fd)
                    os.close(fd)
                    raise self._busy(holder) from None
                except OSError as exc:      # e.g. a file system without locks
                    os.close(fd)
                    raise InvalidInput(f"{self.folder}: cannot lock the {self.what}: "
                                       f"{exc.strerror or exc}") from None
            try:  # the file we locked must still be the folder's lock (not one just released)
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except OSError:
                same = False
            if not same:
                os.close(fd)
                continue
            self.previous = _read_holder(fd)
            self._write_holder(fd)
            return fd
        raise self._busy({})  # pragma: no cover - 20 lost races in a row

    def _take_exclusive(self) -> int:  # pragma: no cover - Windows
        try:
            return self._open(os.O_RDWR | os.O_CREAT | os.O_EXCL)
        except FileExistsError:
            fd = self._open(os.O_RDWR)
            holder = _read_holder(fd)
            os.close(fd)
            if holder.get("host") == socket.gethostname() and not _pid_alive(holder.get("pid")):
                os.unlink(self.path)
                return self._open(os.O_RDWR | os.O_CREAT | os.O_EXCL)
            raise self._busy(holder) from None

    def _write_holder(self, fd: int) -> None:
        now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
        line = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": now,
                           "command": self.command}) + "\n"
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, line.encode("utf-8"), 0)
        except OSError as exc:
            _unlock(fd, self.path)
            raise InvalidInput(f"{self.folder}: cannot lock the {self.what}: "
                               f"{exc.strerror or exc}") from None

    # -- release ------------------------------------------------------------------------------
    def release(self) -> None:
        """Give the lock back (the file is removed when the last acquisition is released)."""
        if not self._held:
            return
        with _MUTEX:
            self._held = False
            entry = _HELD.get(self._key)
            if entry is None:
                return
            entry[1] -= 1
            if entry[1] <= 0:
                del _HELD[self._key]
                _unlock(entry[0], entry[2])

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._held


def _unlock(fd: int, path: Path) -> None:
    try:
        if os.path.samestat(os.fstat(fd), os.stat(path)):
            os.unlink(path)   # while still locked: a waiter then sees another inode and retries
    except OSError:
        pass
    try:
        os.close(fd)          # drops the flock
    except OSError:  # pragma: no cover
        pass


def lock_folder(folder, *, what: str = "result folder", command: str | None = None) -> FolderLock:
    """Acquire and return the :class:`FolderLock` of ``folder`` (an existing directory).

    Raises
    ------
    FolderInUse
        Another process holds it (the message names the holder).
    InvalidInput
        The lock file cannot be created (no permission, ...).

    Examples
    --------
    >>> import tempfile
    >>> lock = lock_folder(tempfile.mkdtemp())
    >>> lock.held, lock.path.name, lock.path.is_file()
    (True, '.kinred.lock', True)
    >>> lock.release(); lock.path.exists()
    False
    """
    return FolderLock(folder, what=what, command=command).acquire()


def release_all() -> None:
    """Release every folder lock this process holds (the ``kinred`` command calls it when a
    command returns, however it returns)."""
    with _MUTEX:
        entries = list(_HELD.values())
        _HELD.clear()
    for fd, _, path in entries:
        _unlock(fd, path)


def _forget_in_child() -> None:
    """A forked child (a worker process) holds nothing: it must not remove its parent's locks."""
    _HELD.clear()


atexit.register(release_all)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_in_child)
