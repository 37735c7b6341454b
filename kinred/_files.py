"""Files on disk, the implementation behind :mod:`kinred.io` (see its docstring): atomic
writes, checked reads and :class:`ResultFolder`. A module of its own so that the stage store
(``kinred._stages``) and ``kinred.io`` both build on it without an import cycle."""

from __future__ import annotations

import errno
import io as _io
import json
import os
import tempfile
import tomllib
import zipfile
import zlib
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ._lock import is_lock_file
from .errors import ConfigError, DamagedFile, DiskFull, InvalidInput

__all__ = [
    "atomic_write_bytes",
    "atomic_write_text",
    "atomic_write_json",
    "atomic_write_npz",
    "read_bytes",
    "read_text",
    "read_json",
    "read_npz",
    "read_toml",
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


def _os_reason(exc: OSError) -> str:
    """Short reason of an OSError, without the path (the caller names it)."""
    if isinstance(exc, FileNotFoundError):
        return "no such file or directory"
    if isinstance(exc, IsADirectoryError):
        return "is a directory"
    if isinstance(exc, NotADirectoryError):
        return "a parent in the path is a file, not a directory"
    if isinstance(exc, PermissionError):
        return "permission denied"
    return exc.strerror or str(exc)


#: errno values of a full device or an exhausted quota (:class:`~kinred.errors.DiskFull`).
_NO_SPACE = {errno.ENOSPC} | ({errno.EDQUOT} if hasattr(errno, "EDQUOT") else set())


def _write_error(path: Path, exc: OSError) -> InvalidInput | DiskFull:
    if exc.errno in _NO_SPACE:
        what = ("no space left on device" if exc.errno == errno.ENOSPC
                else "no space left on device (disk quota exceeded)")
        return DiskFull(f"{path}: cannot write the file: {what}; free some space (or choose "
                        "another folder) and run again", path=os.fspath(path))
    return InvalidInput(f"{path}: cannot write the file: {_os_reason(exc)}")


def _atomic_write(path, writer: Callable[[Any], None]) -> Path:
    """Write through ``writer(binary_file)`` to a temp file, fsync, then ``os.replace``."""
    path = _as_path(path)
    if path.is_dir():
        raise InvalidInput(f"{path}: is a directory; give the name of a file to write")
    directory = path.parent
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{path.name}.", suffix=_TMP_SUFFIX)
    except OSError as exc:
        raise _write_error(path, exc) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            writer(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):
            raise _write_error(path, exc) from None
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


def read_bytes(path, *, what: str = "file") -> bytes:
    """The bytes of the file ``path``.

    ``what`` names the file in messages (``"scene file"``, ``"stage file"``, ...).

    Raises
    ------
    InvalidInput
        The file does not exist, is a directory or cannot be read (the message names it).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> read_bytes(d, what="scene file")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kinred.errors.InvalidInput: ...: is a directory, not a scene file
    """
    path = _as_path(path)
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InvalidInput(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise InvalidInput(f"{path}: is a directory, not a {what}") from None
    except OSError as exc:
        raise InvalidInput(f"{path}: cannot read the {what}: {_os_reason(exc)}") from None


def read_text(path, *, what: str = "file") -> str:
    """The UTF-8 text of the file ``path`` (see :func:`read_bytes` for ``what`` and errors).

    Raises
    ------
    DamagedFile
        The bytes are not UTF-8; the message gives the first bad byte, its offset and line.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = atomic_write_bytes(pathlib.Path(tempfile.mkdtemp()) / "b.toml", b"a = 1\\nb = '\\xff'")
    >>> read_text(p, what="scene file")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kinred.errors.DamagedFile: ...b.toml: not UTF-8 text: byte 0xff at offset 11 (line 2); ...
    """
    data = read_bytes(path, what=what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise DamagedFile(f"{path}: not UTF-8 text: byte 0x{data[exc.start]:02x} at offset "
                          f"{exc.start} (line {line}); a {what} must be UTF-8",
                          path=os.fspath(path)) from None


def read_json(path, *, what: str = "JSON file"):
    """Read a JSON file written by :func:`atomic_write_json`.

    Raises
    ------
    InvalidInput
        Missing file, directory, no permission (:func:`read_bytes`).
    DamagedFile
        Empty file, not UTF-8, or not a valid JSON document (the message says which, and
        where).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = atomic_write_text(pathlib.Path(tempfile.mkdtemp()) / "c.json", "")
    >>> read_json(p)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kinred.errors.DamagedFile: ...c.json: damaged JSON file: empty (0 bytes)
    """
    text = read_text(path, what=what)
    if not text.strip():
        raise DamagedFile(f"{path}: damaged {what}: empty ({len(text.encode())} bytes)",
                          path=os.fspath(path))
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        where = (f"{exc.msg} at line {exc.lineno}, column {exc.colno}"
                 if isinstance(exc, json.JSONDecodeError) else "nested too deeply")
        raise DamagedFile(f"{path}: damaged {what}: not valid JSON ({where})",
                          path=os.fspath(path)) from None


#: What a damaged or foreign ``.npz`` file makes numpy/zipfile raise while loading it.
_NPZ_DAMAGE = (zipfile.BadZipFile, EOFError, ValueError, KeyError, zlib.error, OSError)


def read_npz(path, *, what: str = ".npz file", keys=()) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` file into memory (no pickle); returns a dict.

    ``keys`` lists arrays the file must hold (kinred wrote them): a file missing one is damaged.

    Raises
    ------
    InvalidInput
        Missing file, directory, no permission.
    DamagedFile
        Truncated, empty or otherwise not an ``.npz`` archive of plain arrays (the message
        names the file and what the decoder reported), or without one of ``keys``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = atomic_write_bytes(pathlib.Path(tempfile.mkdtemp()) / "s.npz", b"PK\\x03\\x04 cut")
    >>> read_npz(p, what="stage file")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kinred.errors.DamagedFile: ...s.npz: damaged stage file: truncated or not an .npz archive ...
    """
    path = _as_path(path)
    try:
        with open(path, "rb") as fh:  # closed here even when numpy fails to decode it
            z = np.load(fh, allow_pickle=False)
            if not isinstance(z, np.lib.npyio.NpzFile):  # a bare .npy array
                raise ValueError("a single .npy array")
            with z:
                arrays = {key: z[key] for key in z.files}
    except FileNotFoundError:
        raise InvalidInput(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise InvalidInput(f"{path}: is a directory, not a {what}") from None
    except (PermissionError, NotADirectoryError) as exc:
        raise InvalidInput(f"{path}: cannot read the {what}: {_os_reason(exc)}") from None
    except _NPZ_DAMAGE as exc:
        detail = str(exc).split("\n")[0][:120]
        if "pickle" in detail:  # np.load's guess for bytes that are neither .npz nor .npy
            detail = "unknown format"
        raise DamagedFile(f"{path}: damaged {what}: truncated or not an .npz archive "
                          f"({type(exc).__name__}: {detail})", path=os.fspath(path)) from None
    missing = [key for key in keys if key not in arrays]
    if missing:
        raise DamagedFile(f"{path}: damaged {what}: no array {missing[0]!r}", path=os.fspath(path))
    return arrays


#: Most ``.`` characters on one line of a TOML file kinred reads. A dotted key of ``n`` parts
#: costs tomllib ``O(n²)`` memory (4 GB at 30 000 parts, a 60 kB line); scene and measure
#: files have a few.
TOML_MAX_DOTS_PER_LINE = 256


def read_toml(path, *, what: str = "TOML file") -> dict:
    """Parse a UTF-8 TOML file (scene and measure files).

    Raises
    ------
    ConfigError
        Everything that keeps the file from being read and parsed -- missing, a directory, not
        UTF-8 (offset and line of the first bad byte), invalid TOML, an integer of more than
        4300 digits, nesting deeper than Python's recursion limit, a line with more than
        ``TOML_MAX_DOTS_PER_LINE`` (256) dots -- as one line naming the file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = atomic_write_text(pathlib.Path(tempfile.mkdtemp()) / "m.toml", "a = [1,")
    >>> read_toml(p, what="measure file")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kinred.errors.ConfigError: ...m.toml: invalid TOML: ...
    """
    try:
        text = read_text(path, what=what)
    except InvalidInput as exc:
        raise ConfigError(str(exc)) from None
    for lineno, line in enumerate(text.splitlines(), 1):
        if line.count(".") > TOML_MAX_DOTS_PER_LINE:
            raise ConfigError(f"{path}: line {lineno} has {line.count('.')} dots, more than "
                              f"{TOML_MAX_DOTS_PER_LINE} (a key of that many dotted parts is "
                              f"not a {what}); split the line")
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ConfigError(f"{path}: invalid TOML: arrays or tables nested too deeply") from None
    except ValueError as exc:  # TOMLDecodeError, and int() of more than 4300 digits
        raise ConfigError(f"{path}: invalid TOML: {str(exc).splitlines()[0][:200]}") from None


class ResultFolder:
    """A directory holding one result, written file by file, atomically.

    Files are addressed by names relative to the folder (``"table.json"``,
    ``"members/000003.npz"``); sub-directories are created on demand. The result is marked
    complete by :meth:`mark_complete`, which writes ``summary.json`` **after its data files**:
    a folder without it is an unfinished (or interrupted) result. Renderings of the data
    (figures, ``report.html``) may follow it, so that a failure to draw never loses a result.

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
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            if exc.errno in _NO_SPACE:
                raise DiskFull(f"{self.path}: cannot create the result folder: no space left "
                               "on device", path=str(self.path)) from None
            raise InvalidInput(f"{self.path}: cannot create the result folder: "
                               f"{_os_reason(exc)}") from None

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
        """Write ``summary.json`` (after the data files); afterwards :attr:`is_complete` is ``True``."""
        return self.write_json(self.SUMMARY, dict(summary or {}))

    # -- reading ------------------------------------------------------------------------------
    def exists(self, name: str) -> bool:
        """Whether the file ``name`` exists in the folder."""
        return self._resolve(name).is_file()

    def read_json(self, name: str, *, what: str = "JSON file"):
        """Read a JSON file of the folder (errors as :func:`read_json`)."""
        return read_json(self._resolve(name), what=what)

    def read_npz(self, name: str, *, what: str = ".npz file") -> dict[str, np.ndarray]:
        """Read an ``.npz`` file of the folder into a dict of arrays (errors as :func:`read_npz`)."""
        return read_npz(self._resolve(name), what=what)

    def read_bytes(self, name: str) -> bytes:
        """Read a file's raw bytes (errors as :func:`read_bytes`)."""
        return read_bytes(self._resolve(name))

    def read_text(self, name: str) -> str:
        """Read a UTF-8 text file (errors as :func:`read_text`)."""
        return read_text(self._resolve(name))

    def list(self, under: str | None = None) -> list[str]:
        """Sorted relative names (``/``-separated) of the folder's files, temp files excluded."""
        root = self.path if under is None else self._resolve(under)
        if not root.is_dir():
            return []
        names = []
        for p in root.rglob("*"):
            if p.is_file() and not _is_temporary(p.name) and not is_lock_file(p.name):
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
