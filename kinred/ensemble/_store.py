"""The results store of an ensemble: a :class:`kinred.io.StageStore` whose stages are the
members, one archive each (arrays and a JSON ``__meta__`` entry)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import DamagedFile, StoreMismatch
from ..io import StageStore, atomic_write_npz, read_npz
from ._members import _META

# ----------------------------------------------------------------------------------------------
# Store: a kinred.io.StageStore whose stages are the members
# ----------------------------------------------------------------------------------------------
def _member_name(index: int) -> str:
    return f"members/{index:06d}"


def _write_member(path: Path, member: tuple, stamp=None) -> None:
    """Write ``(index, params, out, wall)`` as one archive (arrays + a ``__meta__`` JSON entry,
    + the store's ``stamp``: its digest, :meth:`kinred.io.StageStore.save`)."""
    index, params, out, wall = member
    arrays = {k: v for k, v in out.items() if isinstance(v, np.ndarray)}
    scalars = {k: v for k, v in out.items() if not isinstance(v, np.ndarray)}
    meta = {
        "index": index,
        "params": params,
        "wall_time": wall,
        "scalars": scalars,
        "order": list(out),
    }
    arrays[_META] = np.array(json.dumps(meta, allow_nan=True))
    arrays.update(stamp or {})
    atomic_write_npz(path, arrays)


def _decode_member(path: Path):
    """``(arrays, meta)`` of a member file; :class:`DamagedFile` if it cannot be decoded."""
    data = read_npz(path, what="member file")
    if _META not in data:
        raise DamagedFile(f"{path}: damaged member file: no {_META} entry", path=str(path))
    try:
        meta = json.loads(str(data.pop(_META)))
        if not isinstance(meta, dict) or not isinstance(meta.get("scalars"), dict):
            raise ValueError("not a JSON object with scalars")
        missing = [k for k in meta["order"] if k not in meta["scalars"] and k not in data]
        if missing:
            raise ValueError(f"no array {missing[0]!r}")
        float(meta["wall_time"])
    except (KeyError, ValueError, TypeError) as exc:
        raise DamagedFile(f"{path}: damaged member file: invalid {_META} ({type(exc).__name__}: "
                          f"{exc})", path=str(path)) from None
    return data, meta


def _member_loader(index: int, params: dict):
    """Loader of member ``index``'s file for :meth:`StageStore.load`: ``(out, wall)``."""

    def load(path: Path):
        data, meta = _decode_member(path)
        if meta.get("index") != index or meta.get("params") != params:
            raise StoreMismatch(
                f"store member file {path} holds member {meta.get('index')} with params "
                f"{meta.get('params')}, expected member {index} with params {params}",
                path=str(path), reason="member")
        out = {key: meta["scalars"][key] if key in meta["scalars"] else data[key]
               for key in meta["order"]}
        return out, float(meta["wall_time"])

    return load


def _open_store(store, *, resume: bool, chash: str, run_info: dict) -> StageStore:
    """The run's :class:`~kinred.io.StageStore` (``run.json`` + ``members/``; no folder: None)."""
    return StageStore(store, chash, resume=resume, describe=run_info, index="run.json",
                      digest_key="config_hash", store_name="ensemble store", item="member")


def _load_members(stages: StageStore, members: list[dict]):
    """``(results, walls, loaded)`` with the members already in the store filled in."""
    n = len(members)
    results: list[dict | None] = [None] * n
    walls = np.full(n, np.nan)
    loaded = np.zeros(n, dtype=bool)
    if stages.folder is not None:
        for i, params in enumerate(members):
            got = stages.load(_member_name(i), load=_member_loader(i, params),
                              label=f"member {i}")
            if got is not None:
                results[i], walls[i] = got
                loaded[i] = True
    return results, walls, loaded
