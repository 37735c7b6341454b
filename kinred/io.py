"""Results on disk: atomic writes and result folders.

Every file kinred writes goes through one pattern (the "write, fsync, rename" idiom):

1. the bytes go to a hidden temporary file **in the destination's directory**
   (``.<name>.<random>.tmp``), so that the final rename never crosses a file system;
2. the temporary file is flushed and ``fsync``-ed;
3. :func:`os.replace` renames it onto the destination, which is atomic on POSIX and Windows;
4. the directory is ``fsync``-ed (best effort, POSIX only) so the rename itself is durable.

A reader therefore sees either the old file or the complete new one, never a half-written
file; if anything fails (an exception, ``KeyboardInterrupt``) before step 3, the temporary
file is removed and the destination is untouched. The file gets the usual permissions
(``0o666`` minus the umask, e.g. ``0644``). A destination that is an existing directory, or
that cannot be written (permission, missing parent that cannot be created) raises
:class:`~kinred.errors.InvalidInput` naming the path; a full device (``ENOSPC``, or an
exhausted quota) raises :class:`~kinred.errors.DiskFull` ("no space left on device"). Only a hard kill (``SIGKILL``, power loss)
between steps 1 and 3 can leave a hidden ``*.tmp`` file behind; :meth:`ResultFolder.clean_temporary`
removes such leftovers and :meth:`ResultFolder.list` never shows them.

:class:`ResultFolder` groups the files of one result (JSON, ``.npz``, PNG bytes, text) and
marks the result complete by writing ``summary.json`` once its data files are on disk
(figures and reports, which only render those data, may follow it).

Every file kinred *reads* goes through :func:`read_bytes`, :func:`read_text`,
:func:`read_json`, :func:`read_npz` or :func:`read_toml`. They turn what can go wrong into
one-line :class:`~kinred.errors.KinredError` messages naming the path: a missing file, a
directory, no permission (:class:`~kinred.errors.InvalidInput`); an empty or truncated file,
bytes that are not UTF-8 (with their offset and line), invalid JSON, a damaged ``.npz``
archive (:class:`~kinred.errors.DamagedFile`); invalid TOML
(:class:`~kinred.errors.ConfigError`).

:class:`StageStore` is the one resumable store: the stage files of a computation tied to its
configuration by a digest, loaded when present and computed when missing
(:meth:`StageStore.get_or_compute`). ``kinred run``, ensembles and, through them, the paper
studies use it, with the same rules and messages.
"""

from . import _files
from ._files import (ResultFolder, _atomic_write, atomic_write_bytes, atomic_write_json,  # noqa: F401
                     atomic_write_npz, atomic_write_text, read_bytes, read_json, read_npz,
                     read_text, read_toml, to_jsonable)
from ._stages import STAGE_DIGEST, StageStore  # noqa: F401

__all__ = [*_files.__all__, "StageStore"]
