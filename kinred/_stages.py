"""The stage store: :class:`StageStore`, the one resumable store (``kinred run``'s stages,
ensemble members, the paper studies). Public as :class:`kinred.io.StageStore`; it lives here
to keep :mod:`kinred.io` small, on the files layer (``kinred._files``) it shares with it."""

from __future__ import annotations

import inspect
import json
import os
import tempfile
import warnings
import weakref
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ._lock import FolderLock, is_lock_file
from .errors import DamagedFile, InvalidInput, KinredWarning, StoreMismatch
from ._files import (_NPZ_DAMAGE, ResultFolder, _is_temporary, atomic_write_npz, read_npz,
                 to_jsonable)

__all__ = ["STAGE_DIGEST", "StageStore"]


def _article(noun: str) -> str:
    return "an" if noun[:1].lower() in "aeiou" else "a"


def _differences(old, new, prefix: str = "") -> list[str]:
    """Dotted keys where two JSON descriptions differ (tables compared key by key)."""
    if isinstance(old, dict) and isinstance(new, dict):
        out: list[str] = []
        for key in sorted(set(old) | set(new), key=str):
            if key not in old or key not in new:
                out.append(f"{prefix}{key}")
            elif old[key] != new[key]:
                out += _differences(old[key], new[key], f"{prefix}{key}.")
        return out
    return [] if old == new else [prefix.rstrip(".") or "(the description)"]


def _takes_stamp(save) -> bool:
    """Whether the saver ``save`` takes a third argument (the stamp)."""
    try:
        params = inspect.signature(save).parameters.values()
    except (TypeError, ValueError):
        return False
    kinds = [p.kind for p in params]
    return (inspect.Parameter.VAR_POSITIONAL in kinds
            or sum(k in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
                   for k in kinds) >= 3)


#: Array of a stage file holding the digest of the configuration that wrote it.
STAGE_DIGEST = "__digest__"


class StageStore:
    """The stage files of one computation, tied to its configuration by a digest.

    :meth:`get_or_compute` loads a stage whose file exists and computes (then writes, atomically)
    one that does not, so an interrupted run -- even ``SIGKILL`` -- resumes where it stopped
    and loses only the stage in flight. ``kinred run`` keeps its stages in ``OUT/stages``
    (index ``config.json``), :func:`kinred.ensemble.run_ensemble` its members in its store
    (index ``run.json``, stage names ``members/000123``), and the paper studies their
    ensembles there; the rules and messages are the same for all:

    ``folder/<index>``
        JSON: the digest (under ``digest_key``) and ``describe``; written when the store is
        created, before any stage.
    ``folder/<name>.npz``
        One file per finished stage (``name`` may contain ``/``), holding the digest of the
        configuration that wrote it (array ``__digest__``).

    An open store owns its folder: it holds the folder's lock (``kinred._lock``, the file
    ``.kinred.lock``) until :meth:`close` (or ``with``, or the end of the process), and another
    process opening it is refused (:class:`~kinred.errors.FolderInUse`, naming the holder).

    Opening a folder:

    * without an index and empty (or missing): a new store; temporary files of a killed writer
      are removed;
    * holding a run (its index exists): refused without ``resume=True``
      (:class:`~kinred.errors.StoreMismatch`, ``reason="resume"``); with it, the stored digest
      must equal ``digest`` (else ``reason="different"``, naming the keys of ``describe`` that
      differ);
    * holding other files and no index: refused (``reason="foreign"``);
    * a damaged index (empty, cut, not UTF-8, no digest): refused
      (:class:`~kinred.errors.DamagedFile`): it is what ties the stage files to a
      configuration, so they cannot be trusted without it.

    Loading: a stage file is loaded only with ``resume=True`` (or when this store wrote it):
    a new run computes every stage. A stage file whose digest is not this store's (or that has
    none) and a damaged one (truncated, not an ``.npz`` archive, missing arrays: whatever makes
    the loader raise :class:`~kinred.errors.DamagedFile`) are named in a
    :class:`~kinred.errors.KinredWarning` and recomputed.

    Parameters
    ----------
    folder : str, os.PathLike or None
        The store's directory (created with its parents); ``None`` stores nothing and computes
        every stage.
    digest : str
        Hash of everything that determines the stages' contents.
    resume : bool
        Continue the run the folder holds (a missing store is simply created).
    describe : mapping, optional
        JSON description of the run written into the index next to the digest; on a digest
        mismatch the message names its keys that differ.
    index : str
        File name of the index inside ``folder``.
    digest_key : str
        Key of the digest in the index.
    store_name, item : str
        How messages call the store (``"stage store"``, ``"ensemble store"``) and one stage
        (``"stage"``, ``"member"``).

    Attributes
    ----------
    folder : ResultFolder or None
    status : dict
        ``{name: "loaded" | "computed"}`` for every stage asked for, in order.

    Examples
    --------
    >>> import tempfile
    >>> path = tempfile.mkdtemp()
    >>> store = StageStore(path, "d1")
    >>> store.get_or_compute("a", lambda: {"x": np.arange(3)})["x"]
    array([0, 1, 2])
    >>> again = StageStore(path, "d1", resume=True)
    >>> again.get_or_compute("a", lambda: 1 / 0)["x"], again.status
    (array([0, 1, 2]), {'a': 'loaded'})
    >>> store.close(); again.close()
    >>> StageStore(path, "d2", resume=True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    kinred.errors.StoreMismatch: stage store ... holds a run of a different configuration ...
    """

    def __init__(self, folder, digest: str, *, resume: bool = False,
                 describe: Mapping[str, Any] | None = None, index: str = "config.json",
                 digest_key: str = "digest", store_name: str = "stage store",
                 item: str = "stage"):
        if folder is not None and (isinstance(folder, bytes)
                                   or not isinstance(folder, (str, os.PathLike))):
            raise InvalidInput(f"folder must be a directory path (str or os.PathLike) or None, "
                               f"got {folder!r}")
        for name, value in (("digest", digest), ("index", index), ("digest_key", digest_key),
                            ("store_name", store_name), ("item", item)):
            if not isinstance(value, str) or not value:
                raise InvalidInput(f"{name} must be a non-empty str, got {value!r}")
        if not isinstance(resume, (bool, np.bool_)):
            raise InvalidInput(f"resume must be True or False, got {resume!r}")
        if describe is not None and not isinstance(describe, Mapping):
            raise InvalidInput(f"describe must be a mapping (JSON object) or None, got {describe!r}")
        self.digest, self.index, self.digest_key = digest, index, digest_key
        self.store_name, self.item = store_name, item
        self.describe = to_jsonable(dict(describe or {}))
        self.status: dict[str, str] = {}
        self.resume = bool(resume)
        self._written: set[str] = set()
        self._lock = None
        self.folder = None if folder is None else self._open(Path(folder), bool(resume))

    def __repr__(self) -> str:
        where = None if self.folder is None else str(self.folder.path)
        return f"StageStore({where!r}, {self.digest[:12]!r}…)"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Release the folder's lock (the stage files stay); loading and saving still work."""
        if self._lock is not None:
            self._lock.release()

    # -- opening ----------------------------------------------------------------------------
    def _refuse(self, path: Path, resume: bool) -> bool:
        """Raise if the folder cannot take this run; ``True`` when it holds a run (its index)."""
        if (path / self.index).is_file():
            if not resume:
                raise StoreMismatch(
                    f"{self.store_name} {path} already holds a run; continue it with resume=True "
                    "(--resume on the command line) or choose another folder",
                    path=str(path), reason="resume")
            return True
        if path.exists() and (not path.is_dir() or any(
                not _is_temporary(p.name) and not is_lock_file(p.name) for p in path.iterdir())):
            raise StoreMismatch(
                f"{path} exists and is not {_article(self.store_name)} {self.store_name} (no "
                f"{self.index}); choose a new or empty directory", path=str(path),
                reason="foreign")
        return False

    def _open(self, path: Path, resume: bool) -> ResultFolder:
        self._refuse(path, resume)              # before touching the folder
        folder = ResultFolder(path)
        self._lock = FolderLock(path, what=self.store_name).acquire()
        weakref.finalize(self, self._lock.release)
        try:
            if self._refuse(path, resume):      # again, now that the folder is ours
                self._check_digest(folder)
            else:
                folder.write_json(self.index, {self.digest_key: self.digest, **self.describe})
            folder.clean_temporary()
        except BaseException:
            self._lock.release()
            raise
        return folder

    def _stored_index(self, folder: ResultFolder) -> dict:
        path = folder / self.index
        try:
            stored = folder.read_json(self.index, what="store description")
            if not isinstance(stored, dict) or not isinstance(stored.get(self.digest_key), str):
                raise DamagedFile(f"{path}: damaged store description: no configuration digest",
                                  path=str(path))
        except DamagedFile as exc:
            raise DamagedFile(
                f"{exc}; it ties the {self.item} files to a run, so they cannot be resumed: "
                f"delete the store, i.e. delete the folder {folder.path} and run again, or run "
                "into another output folder", path=str(path)) from None
        return stored

    def _check_digest(self, folder: ResultFolder) -> None:
        stored = self._stored_index(folder)
        if stored[self.digest_key] == self.digest:
            return
        now = json.loads(json.dumps(self.describe))
        differ = _differences({k: v for k, v in stored.items() if k != self.digest_key}, now)
        detail = ""
        if differ:
            detail = "; differs: " + ", ".join(differ[:4]) + (", …" if len(differ) > 4 else "")
        raise StoreMismatch(
            f"{self.store_name} {folder.path} holds a run of a different configuration (config "
            f"hash {stored[self.digest_key][:12]}… != {self.digest[:12]}… of this run{detail}); "
            "resume it with the same configuration or choose another folder",
            path=str(folder.path), reason="different")

    # -- stages -----------------------------------------------------------------------------
    def path(self, name: str) -> Path | None:
        """The file of stage ``name`` (``None`` without a folder)."""
        if not isinstance(name, str) or not name:
            raise InvalidInput(f"name must be a non-empty str, got {name!r}")
        return None if self.folder is None else self.folder / f"{name}.npz"

    def _stamp_problem(self, path: Path) -> str:
        """Why the stage file ``path`` is not this run's ("" if its digest is this store's, or
        if it cannot be decoded: the loader then reports the damage)."""
        try:
            with open(path, "rb") as fh:
                z = np.load(fh, allow_pickle=False)
                if not isinstance(z, np.lib.npyio.NpzFile):
                    return ""
                with z:
                    stored = str(z[STAGE_DIGEST]) if STAGE_DIGEST in z.files else None
        except _NPZ_DAMAGE:
            return ""
        if stored is None:
            return (f"{path}: {self.item} file without a configuration digest (not written by "
                    "this version of kinred): it cannot be tied to this run")
        if stored != self.digest:
            return (f"{path}: {self.item} file of another configuration (digest {stored[:12]}… "
                    f"!= {self.digest[:12]}… of this run)")
        return ""

    def load(self, name: str, *, load: Callable[[Path], Any] | None = None,
             label: str | None = None):
        """The stored value of stage ``name``, or ``None`` if it is absent, damaged, of another
        configuration, or the store was not opened with ``resume=True`` (and did not write it).

        ``load(path)`` reads the file (default: :func:`read_npz`); a
        :class:`~kinred.errors.DamagedFile` it raises, and a file whose digest is not the
        store's, become a :class:`~kinred.errors.KinredWarning`
        ``"<path>: ...; recomputing <label>"`` and ``None``, with ``label`` by default
        ``"the <item>"``. A dict value is returned without its ``__digest__`` entry.
        """
        path = self.path(name)
        if path is None or not path.is_file() or not (self.resume or name in self._written):
            return None
        try:
            return self._read(path, load)
        except DamagedFile as exc:
            warnings.warn(f"{exc}; recomputing {label or 'the ' + self.item}", KinredWarning,
                          stacklevel=3)
            return None

    def _read(self, path: Path, load):
        """The value of the stage file ``path`` (:class:`~kinred.errors.DamagedFile` if it is
        damaged or not this store's)."""
        value = read_npz(path, what=f"{self.item} file") if load is None else load(path)
        problem = self._stamp_problem(path)       # a sound file: is it this run's?
        if problem:
            raise DamagedFile(problem, path=str(path))
        if isinstance(value, dict):
            value.pop(STAGE_DIGEST, None)
        return value

    def save(self, name: str, value, *,
             save: Callable[[Path, Any, Mapping[str, Any]], Any] | None = None) -> None:
        """Write stage ``name`` atomically with the store's digest: by default
        :func:`atomic_write_npz` of the mapping ``value`` plus ``__digest__``; else
        ``save(path, value, stamp)``, which must write the arrays of ``stamp`` into its
        ``.npz`` archive (a two-argument ``save(path, value)`` writes a format of its own,
        without the digest: such an ``.npz`` file is recomputed on resume)."""
        path = self.path(name)
        if path is None:
            return
        stamp = {STAGE_DIGEST: np.array(self.digest)}
        if save is None:
            atomic_write_npz(path, {**value, **stamp})
        elif _takes_stamp(save):
            save(path, value, stamp)
        else:                     # a saver of its own format: its files carry no digest
            save(path, value)
        self._written.add(name)

    def get_or_compute(self, name: str, compute: Callable[[], Any], *,
                       load: Callable[[Path], Any] | None = None,
                       save: Callable[[Path, Any], Any] | None = None, label: str | None = None):
        """The value of stage ``name``: loaded if its file is there and sound, else ``compute()``
        written at once (see :meth:`load` and :meth:`save` for ``load``, ``save``, ``label``).

        Either way the value is what a resume loads: a computed stage is read back from the
        file just written (without a folder, from a temporary one), so a first run and a
        resumed one continue from the same objects (e.g. 0-d arrays, not Python floats). With a
        saver of its own format (two arguments, no digest) the computed value is returned.
        ``status[name]`` records which of the two happened.
        """
        value = self.load(name, load=load, label=label)
        if value is not None:
            self.status[name] = "loaded"
            return value
        value = compute()
        if self.folder is None:
            value = self._round_trip(name, value, load, save)
        else:
            self.save(name, value, save=save)
            value = self._read_back(self.path(name), value, load, save)
        self.status[name] = "computed"
        return value

    def _read_back(self, path: Path, value, load, save):
        """What a resume loads from ``path`` (just written from ``value``)."""
        if save is not None and not _takes_stamp(save):
            return value                            # a format of its own: kept as computed
        try:
            return self._read(path, load)
        except DamagedFile:                         # a saver that did not write it readably
            return value

    def _round_trip(self, name: str, value, load, save):
        """``value`` written to and read back from a temporary stage file (no folder)."""
        with tempfile.TemporaryDirectory(prefix="kinred-stage-") as tmp:
            path = Path(tmp) / "stage.npz"
            stamp = {STAGE_DIGEST: np.array(self.digest)}
            if save is None:
                if not isinstance(value, Mapping):
                    return value                    # not a stage a file could hold
                atomic_write_npz(path, {**value, **stamp})
            elif _takes_stamp(save):
                save(path, value, stamp)
            else:
                return value
            return self._read_back(path, value, load, save)
