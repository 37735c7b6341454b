"""Results on disk: atomic writes and result folders.

Every file kinred writes goes through one pattern (the "write, fsync, rename" idiom):

1. the bytes go to a hidden temporary file **in the destination's directory**
   (``.<name>.<random>.tmp``), so that the final rename never crosses a file system;
2. the temporary file is flushed and ``fsync``-ed;
3. :func:`os.replace` renames it onto the destination, which is atomic on POSIX and Windows;
4. the directory is ``fsync``-ed (best effort, POSIX only) so the rename itself is durable.

A reader therefore sees either the old file or the complete new one, never a half-written
file; if anything fails (an exception, ``KeyboardInterrupt``) before step 3, the temporary
file is removed and the destination is untouched. Only a hard kill (``SIGKILL``, power loss)
between steps 1 and 3 can leave a hidden ``*.tmp`` file behind; :meth:`ResultFolder.clean_temporary`
removes such leftovers and :meth:`ResultFolder.list` never shows them.

:class:`ResultFolder` groups the files of one result (JSON, ``.npz``, PNG bytes, text) and
marks the result complete by writing ``summary.json`` last.
"""

from __future__ import annotations

import io as _io
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .errors import InvalidInput

__all__ = [
    "atomic_write_bytes",
    "atomic_write_text",
    "atomic_write_json",
    "atomic_write_npz",
    "read_json",
    "read_npz",
    "to_jsonable",
    "ResultFolder",
]

_TMP_SUFFIX = ".tmp"


def _current_umask() -> int:
    old = os.umask(0o022)
    os.umask(old)
    return old


_UMASK = _current_umask()


def _as_path(path, name: str = "path") -> Path:
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise InvalidInput(f"{name} must be a str or os.PathLike, got {path!r}")
    p = Path(path)
    if p.name in ("", ".", ".."):
        raise InvalidInput(f"{name} must name a file, got {str(path)!r}")
    return p


def _fsync_dir(directory: Path) -> None:
    if os.name != "posix":  # pragma: no cover - directories cannot be opened on Windows
        return
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # pragma: no cover - e.g. exotic file systems
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def _atomic_write(path, writer: Callable[[Any], None]) -> Path:
    """Write through ``writer(binary_file)`` to a temp file, fsync, then ``os.replace``."""
    path = _as_path(path)
    directory = path.parent
    directory.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{path.name}.", suffix=_TMP_SUFFIX)
    try:
        with os.fdopen(fd, "wb") as fh:
            writer(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(directory)
    return path


def atomic_write_bytes(path, data: bytes) -> Path:
    """Atomically write ``data`` to ``path`` (temp file in the same directory + fsync + rename).

    Parent directories are created. Returns the destination as a :class:`pathlib.Path`.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> p = atomic_write_bytes(d / "a.bin", b"abc")
    >>> p.read_bytes(), sorted(x.name for x in d.iterdir())
    (b'abc', ['a.bin'])
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise InvalidInput(f"data must be bytes, got {type(data).__name__}")
    return _atomic_write(path, lambda fh: fh.write(data))


def atomic_write_text(path, text: str, *, encoding: str = "utf-8") -> Path:
    """Atomically write the string ``text`` to ``path`` (see :func:`atomic_write_bytes`)."""
    if not isinstance(text, str):
        raise InvalidInput(f"text must be a str, got {type(text).__name__}")
    return atomic_write_bytes(path, text.encode(encoding))


def to_jsonable(obj):
    """Convert numpy scalars/arrays, tuples, sets and paths to plain JSON types (recursively).

    Floats keep their exact value (JSON numbers are written with Python's shortest
    round-trip ``repr``); non-finite floats are written as ``NaN``/``Infinity`` as Python's
    :mod:`json` does.

    Examples
    --------
    >>> to_jsonable({"a": np.float64(0.5), "b": np.arange(3), "c": (1, 2)})
    {'a': 0.5, 'b': [0, 1, 2], 'c': [1, 2]}
    """
    if isinstance(obj, Mapping):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise InvalidInput(f"JSON object keys must be str, got {k!r}")
            out[k] = to_jsonable(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, (set, frozenset)):
        return [to_jsonable(v) for v in sorted(obj)]
    if isinstance(obj, np.ndarray):
        if obj.dtype == object:
            raise InvalidInput("object arrays cannot be written as JSON")
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    raise InvalidInput(f"cannot write a {type(obj).__name__} as JSON: {obj!r}")


def atomic_write_json(path, obj, *, indent: int | None = 2) -> Path:
    """Atomically write ``obj`` (converted by :func:`to_jsonable`) as UTF-8 JSON.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = atomic_write_json(pathlib.Path(tempfile.mkdtemp()) / "r.json", {"w1": np.float64(0.25)})
    >>> read_json(p)
    {'w1': 0.25}
    """
    text = json.dumps(to_jsonable(obj), indent=indent, sort_keys=False, ensure_ascii=False)
    return atomic_write_text(path, text + "\n")


def atomic_write_npz(path, arrays: Mapping[str, Any] | None = None, /, *, compress: bool = False,
                     **kwargs) -> Path:
    """Atomically write arrays to an ``.npz`` archive (``numpy.savez`` semantics).

    Arrays come from the mapping ``arrays`` and/or keyword arguments. Object arrays are
    refused (they would need pickling to load). The file name is used as given (no ``.npz``
    is appended).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = atomic_write_npz(pathlib.Path(tempfile.mkdtemp()) / "x.npz", {"a": np.arange(3)}, b=2.0)
    >>> r = read_npz(p); r["a"], float(r["b"])
    (array([0, 1, 2]), 2.0)
    """
    data = dict(arrays or {})
    overlap = set(data) & set(kwargs)
    if overlap:
        raise InvalidInput(f"arrays given twice (mapping and keyword): {sorted(overlap)}")
    data.update(kwargs)
    for key in data:
        if not isinstance(key, str) or not key or "/" in key:
            raise InvalidInput(f"npz array names must be non-empty str without '/', got {key!r}")
    save = np.savez_compressed if compress else np.savez

    def writer(fh):
        # Convert lazily, one entry at a time, inside the atomic section: a failure on any
        # array leaves no file behind.
        converted = {}
        for key, value in data.items():
            arr = np.asanyarray(value)
            if arr.dtype == object:
                raise InvalidInput(f"array {key!r} has dtype object; npz files must not need pickle")
            converted[key] = arr
        buf = _io.BytesIO()
        save(buf, **converted)
        fh.write(buf.getbuffer())

    return _atomic_write(path, writer)


def read_json(path):
    """Read a JSON file written by :func:`atomic_write_json`."""
    path = _as_path(path)
    with open(path, "r", encoding="utf-8") as fh:
        return json.load(fh)


def read_npz(path) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` file into memory (no pickle); returns a dict."""
    path = _as_path(path)
    with np.load(path, allow_pickle=False) as z:
        return {key: z[key] for key in z.files}


class ResultFolder:
    """A directory holding one result, written file by file, atomically.

    Files are addressed by names relative to the folder (``"table.json"``,
    ``"members/000003.npz"``); sub-directories are created on demand. The result is marked
    complete by :meth:`mark_complete`, which writes ``summary.json`` **last**: a folder
    without it is an unfinished (or interrupted) result.

    Parameters
    ----------
    path : str or os.PathLike
        The folder; created (with parents) if missing.

    Examples
    --------
    >>> import tempfile
    >>> rf = ResultFolder(tempfile.mkdtemp())
    >>> _ = rf.write_json("config.json", {"N": 10})
    >>> _ = rf.write_npz("data/x.npz", x=np.zeros(2))
    >>> rf.list(), rf.is_complete
    (['config.json', 'data/x.npz'], False)
    >>> _ = rf.mark_complete({"ok": True})
    >>> rf.is_complete, rf.read_json("summary.json")
    (True, {'ok': True})
    """

    SUMMARY = "summary.json"

    def __init__(self, path):
        if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
            raise InvalidInput(f"path must be a str or os.PathLike, got {path!r}")
        self.path = Path(path)
        if self.path.exists() and not self.path.is_dir():
            raise InvalidInput(f"path must be a directory, got the file {str(self.path)!r}")
        self.path.mkdir(parents=True, exist_ok=True)

    def __repr__(self) -> str:
        return f"ResultFolder({str(self.path)!r})"

    def __truediv__(self, name: str) -> Path:
        return self._resolve(name)

    def _resolve(self, name: str) -> Path:
        if not isinstance(name, str) or not name:
            raise InvalidInput(f"name must be a non-empty relative path str, got {name!r}")
        rel = Path(name)
        if rel.is_absolute() or any(part in ("..", "") for part in rel.parts):
            raise InvalidInput(f"name must be a relative path inside the folder (no '..'), got {name!r}")
        return self.path / rel

    # -- writing ------------------------------------------------------------------------------
    def write_bytes(self, name: str, data: bytes) -> Path:
        """Atomically write raw bytes (e.g. a PNG rendered to memory)."""
        return atomic_write_bytes(self._resolve(name), data)

    def write_text(self, name: str, text: str) -> Path:
        """Atomically write UTF-8 text."""
        return atomic_write_text(self._resolve(name), text)

    def write_json(self, name: str, obj) -> Path:
        """Atomically write JSON (see :func:`atomic_write_json`)."""
        return atomic_write_json(self._resolve(name), obj)

    def write_npz(self, name: str, arrays: Mapping[str, Any] | None = None, /, **kwargs) -> Path:
        """Atomically write an ``.npz`` archive (see :func:`atomic_write_npz`)."""
        return atomic_write_npz(self._resolve(name), arrays, **kwargs)

    def mark_complete(self, summary: Mapping[str, Any] | None = None) -> Path:
        """Write ``summary.json`` (last); afterwards :attr:`is_complete` is ``True``."""
        return self.write_json(self.SUMMARY, dict(summary or {}))

    # -- reading ------------------------------------------------------------------------------
    def exists(self, name: str) -> bool:
        """Whether the file ``name`` exists in the folder."""
        return self._resolve(name).is_file()

    def read_json(self, name: str):
        """Read a JSON file of the folder."""
        return read_json(self._resolve(name))

    def read_npz(self, name: str) -> dict[str, np.ndarray]:
        """Read an ``.npz`` file of the folder into a dict of arrays."""
        return read_npz(self._resolve(name))

    def read_bytes(self, name: str) -> bytes:
        """Read a file's raw bytes."""
        return self._resolve(name).read_bytes()

    def read_text(self, name: str) -> str:
        """Read a UTF-8 text file."""
        return self._resolve(name).read_text(encoding="utf-8")

    def list(self, under: str | None = None) -> list[str]:
        """Sorted relative names (``/``-separated) of the folder's files, temp files excluded."""
        root = self.path if under is None else self._resolve(under)
        if not root.is_dir():
            return []
        names = []
        for p in root.rglob("*"):
            if p.is_file() and not _is_temporary(p.name):
                names.append(p.relative_to(self.path).as_posix())
        return sorted(names)

    @property
    def is_complete(self) -> bool:
        """``True`` once :meth:`mark_complete` has written ``summary.json``."""
        return (self.path / self.SUMMARY).is_file()

    def clean_temporary(self) -> int:
        """Remove temporary files left by a hard-killed writer; return how many were removed."""
        n = 0
        for p in self.path.rglob(f".*{_TMP_SUFFIX}"):
            if p.is_file():
                p.unlink()
                n += 1
        return n


def _is_temporary(name: str) -> bool:
    return name.startswith(".") and name.endswith(_TMP_SUFFIX)
