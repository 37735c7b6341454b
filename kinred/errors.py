"""One exception family for kinred.

Every error kinred raises on purpose derives from :class:`KinredError`. Messages name the
argument, the bad value and what would be valid, e.g.
``InvalidInput: beta must be >= 0, got -1.0``.

The subclasses also derive from the closest built-in exception (``ValueError``,
``FloatingPointError``, ...) so that generic ``except ValueError`` code keeps working.
"""

from __future__ import annotations

import re

__all__ = [
    "KinredError",
    "InvalidInput",
    "ConfigError",
    "SimulationDiverged",
    "NotConverged",
    "TooLarge",
    "NotProjectable",
    "DamagedFile",
    "StoreMismatch",
    "FolderInUse",
    "DiskFull",
    "MissingDependency",
    "KinredWarning",
]


class KinredError(Exception):
    """Base class of every error raised by kinred.

    The message is one line: a line break and the spaces around it (e.g. from the ``repr``
    of an array named in the message) become one space.
    """

    def __init__(self, *args):
        if len(args) == 1 and isinstance(args[0], str) and ("\n" in args[0] or "\r" in args[0]):
            args = (_LINE_BREAK.sub(" ", args[0]),)
        super().__init__(*args)


_LINE_BREAK = re.compile(r"\s*[\r\n]\s*")


class InvalidInput(KinredError, ValueError):
    """An argument has the wrong type, shape or value (NaN/Inf, negative width, ...)."""


class ConfigError(InvalidInput):
    """A scene or measure file is malformed: unknown, missing or mistyped key."""


class DamagedFile(InvalidInput):
    """A file exists but its content cannot be read back: truncated, empty, not UTF-8, not a
    valid JSON document or ``.npz`` archive, or missing entries kinred wrote into it.

    Attributes
    ----------
    path : str
        The damaged file.
    """

    def __init__(self, message: str, *, path: str = ""):
        super().__init__(message)
        self.path = path

    def __reduce__(self):
        return (_rebuild_damaged, (str(self), self.path))


def _rebuild_damaged(message, path):
    return DamagedFile(message, path=path)


class StoreMismatch(InvalidInput):
    """A result store (:class:`kinred.io.StageStore`: an ensemble's store, the stage files of
    ``kinred run``, a paper study's store) cannot take this run.

    Attributes
    ----------
    path : str
        The store's folder.
    reason : {"resume", "different", "foreign", "member"}
        ``"resume"``: the folder holds a run and ``resume=True`` (``--resume``) was not given;
        ``"different"``: it holds a run of a different configuration (digest differs);
        ``"foreign"``: it holds other files and no store index; ``"member"``: a stored file
        holds another item than its name says.
    """

    def __init__(self, message: str, *, path: str = "", reason: str = ""):
        super().__init__(message)
        self.path = path
        self.reason = reason

    def __reduce__(self):
        return (_rebuild_mismatch, (str(self), self.path, self.reason))


def _rebuild_mismatch(message, path, reason):
    return StoreMismatch(message, path=path, reason=reason)


class FolderInUse(InvalidInput):
    """A result folder (or store) is owned by another running process (its lock file
    ``.kinred.lock`` is held); the message names the holder: pid, host, start time, command.

    Attributes
    ----------
    path : str
        The folder.
    holder : dict
        What the lock file says about its holder (``pid``, ``host``, ``started``, ``command``).
    """

    def __init__(self, message: str, *, path: str = "", holder: dict | None = None):
        super().__init__(message)
        self.path = path
        self.holder = dict(holder or {})

    def __reduce__(self):
        return (_rebuild_in_use, (str(self), self.path, self.holder))


def _rebuild_in_use(message, path, holder):
    return FolderInUse(message, path=path, holder=holder)


class DiskFull(KinredError, OSError):
    """A file could not be written because the device is full (``ENOSPC``) or the disk quota
    is exhausted (``EDQUOT``); the message names the file and says "no space left on device".
    Nothing was replaced: the destination keeps its previous content.

    Attributes
    ----------
    path : str
        The file that could not be written.
    """

    def __init__(self, message: str, *, path: str = ""):
        super().__init__(message)
        self.path = path

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""

    def __reduce__(self):
        return (_rebuild_disk_full, (str(self), self.path))


def _rebuild_disk_full(message, path):
    return DiskFull(message, path=path)


class SimulationDiverged(KinredError, FloatingPointError):
    """A simulation produced NaN/Inf, overflowed, or grew past a bound of the exact flow.

    Attributes
    ----------
    t : float
        Time at which the divergence was detected.
    step : int
        Index of the step that produced it.
    stable_dt : float or None
        A step the message recommends (estimated from the states), when one is known.
    """

    def __init__(self, message: str, *, t: float | None = None, step: int | None = None,
                 stable_dt: float | None = None):
        super().__init__(message)
        self.t = t
        self.step = step
        self.stable_dt = stable_dt


class NotConverged(KinredError, RuntimeError):
    """An iterative solver stopped before reaching its tolerance (e.g. POT's ``numItermax``)."""


class TooLarge(KinredError, MemoryError):
    """A request would materialize more memory than the configured limit allows."""


class NotProjectable(KinredError, TypeError):
    """An effect does not belong to the paper's class (1.1) and cannot be projected exactly."""


class MissingDependency(KinredError, ImportError):
    """An optional package a call needs is not installed; the message names the package and
    the ``pip install`` line (e.g. ``pip install 'kinred[xarray]'``)."""


class KinredWarning(UserWarning):
    """Something went wrong but kinred carried on: a damaged stage file recomputed on resume,
    a figure that could not be drawn (the report has a note instead). The ``kinred`` command
    prints these as one line, ``kinred: warning: ...``."""
