"""The entry point :func:`run_ensemble` and its result :class:`EnsembleResult`."""

from __future__ import annotations

import os
import pickle
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .._repr import result_repr
from .._validate import as_bool, as_choice, as_int, check_alloc, fmt_bytes
from ..errors import InvalidInput
from ._members import EXECUTORS, _FORMAT, _check_members, _fn_identity, _fn_name, _plain, config_hash
from ._store import _load_members, _member_name, _open_store, _write_member
from ._workers import _failed, _import_distributed, _make_bar, _n_workers, _stream

# ----------------------------------------------------------------------------------------------
# Result
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EnsembleResult:
    """Members and their results, in member order.

    Attributes
    ----------
    members : tuple of dict
        Parameters of each member.
    results : tuple of dict
        What ``fn`` returned for each member (arrays as ndarrays, numbers as ``int`` /
        ``float`` / ``bool``, strings as ``str``), whatever the completion order.
    wall_times : (n,) ndarray
        Seconds spent in ``fn`` per member (for loaded members: when they were computed).
    total_time : float
        Wall time of the whole :func:`run_ensemble` call.
    loaded : (n,) ndarray of bool
        ``True`` for members read from the store, ``False`` for members computed in this call.
    executor : str
        ``"serial"``, ``"processes"`` or ``"dask"``.
    workers : int
        Number of workers used (1 for serial).
    master_seed : int
    store : str or None
        Path of the results store.
    config_hash : str
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    members: tuple
    results: tuple
    wall_times: np.ndarray
    total_time: float
    loaded: np.ndarray
    executor: str
    workers: int
    master_seed: int
    store: str | None = None
    config_hash: str = ""

    def __len__(self) -> int:
        return len(self.members)

    @property
    def computed(self) -> np.ndarray:
        """Indices of the members computed in this call."""
        return np.flatnonzero(~self.loaded)

    def indices(self, **params) -> np.ndarray:
        """Indices of the members whose parameters include ``params`` (e.g. ``k=10``)."""
        want = _plain(params, "params")
        return np.array(
            [i for i, m in enumerate(self.members) if all(k in m and m[k] == v for k, v in want.items())],
            dtype=np.intp,
        )

    def stack(self, name: str, indices=None) -> np.ndarray:
        """``np.stack`` of result ``name`` over members (all, or ``indices``)."""
        idx = range(len(self)) if indices is None else indices
        try:
            return np.stack([np.asarray(self.results[i][name]) for i in idx])
        except KeyError:
            raise InvalidInput(
                f"name must be a result key, got {name!r}; available: {sorted(self.results[0])}"
            ) from None


def _check_run(fn, members, master_seed, executor, workers, scheduler, store, resume):
    """Validated ``(members, master_seed, executor, workers)`` of a :func:`run_ensemble` call."""
    if not callable(fn):
        raise InvalidInput(f"fn must be callable, got {fn!r}")
    resume = as_bool(resume, "resume")
    members = _check_members(members)
    master_seed = as_int(master_seed, "master_seed", low=0)
    executor = as_choice(executor, "executor", EXECUTORS)
    if workers is not None:
        workers = as_int(workers, "workers", low=1)
    if scheduler is not None and executor != "dask":
        raise InvalidInput(f"scheduler is only used with executor='dask', got executor={executor!r}")
    if scheduler is not None and not isinstance(scheduler, str):
        dist = _import_distributed()
        if not isinstance(scheduler, dist.Client):
            raise InvalidInput(f"scheduler must be an address str or a distributed.Client, got {scheduler!r}")
    if resume and store is None:
        raise InvalidInput("resume=True needs a store directory, got store=None")
    if store is not None and (isinstance(store, bytes) or not isinstance(store, (str, os.PathLike))):
        raise InvalidInput(f"store must be a directory path (str or os.PathLike), got {store!r}")
    if executor != "serial":
        try:
            pickle.dumps(fn)
        except Exception as exc:
            raise InvalidInput(
                f"fn must be picklable for executor={executor!r} (a top-level function of an "
                f"importable module), got {fn!r}: {exc}"
            ) from None
    return members, master_seed, executor, workers


def _result_bytes(res: dict) -> int:
    """Bytes one member's results keep in memory (arrays by size, other values as small
    objects)."""
    return 256 + sum(v.nbytes + 112 if isinstance(v, np.ndarray) else 64 for v in res.values())


class _Kept:
    """The preflight of the results kept in memory: after every computed member the bytes
    of all ``n`` members, projected from the mean of those held so far, go through
    :func:`~kinred._validate.check_alloc` (before the remaining members are computed)."""

    def __init__(self, results: list, n: int, store):
        held = [r for r in results if r is not None]
        self.count, self.total = len(held), sum(map(_result_bytes, held))
        self.n, self.store = n, store

    def add(self, res: dict) -> None:
        self.count += 1
        self.total += _result_bytes(res)
        per = self.total // self.count
        where = ("the finished members are in the store: continue with resume=True after the "
                 "change" if self.store is not None else "pass store= to keep finished members")
        check_alloc(per * self.n, f"run_ensemble: keeping the results of {self.n} members",
                    f"fn returns about {fmt_bytes(per)} per member: return smaller results "
                    f"(summaries instead of trajectories) or split the member list; {where}",
                    detail=f" (about {fmt_bytes(per)} per member, measured on {self.count})")


# ----------------------------------------------------------------------------------------------
# Entry point
# ----------------------------------------------------------------------------------------------
def run_ensemble(
    fn: Callable[[dict, np.random.SeedSequence], Mapping[str, Any]],
    members,
    *,
    master_seed: int,
    executor: str = "serial",
    workers: int | None = None,
    scheduler=None,
    store=None,
    resume: bool = False,
    config: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> EnsembleResult:
    """Run ``fn`` on every member; results in member order, independent of the executor.

    Member ``i`` calls ``fn(members[i], kinred._rng.member_seed(master_seed, i))``.

    Parameters
    ----------
    fn : callable ``(params: dict, seed: SeedSequence) -> dict``
        Returns a dict of results: ndarrays, numbers or strings (names not starting with
        ``"__"``). Must be a picklable top-level function for ``"processes"`` / ``"dask"``.
    members : list of dict
        JSON-serializable parameters, one dict per member (see :func:`grid`).
    master_seed : int
        Non-negative; member seeds derive from it.
    executor : {"serial", "processes", "dask"}
    workers : int, optional
        Worker processes for ``"processes"`` / a new LocalCluster (default: ``os.cpu_count()``,
        at most the number of members to compute). Ignored by ``"serial"``.
    scheduler : str or distributed.Client, optional
        ``"dask"`` only: address of an existing scheduler (``"tcp://host:port"``) or a client;
        default is a new LocalCluster, closed at the end.
    store : str or os.PathLike, optional
        Results-store directory (see the module docstring); each member is written as it
        finishes.
    resume : bool
        Continue the run found in ``store``: load finished members, compute the rest. An
        absent store is simply created. Without ``resume`` a store holding a run is refused.
    config : dict, optional
        Extra JSON description of the run (e.g. an experiment's Config), recorded in
        ``run.json`` and included in the config hash.
    progress : bool
        tqdm progress bar with time remaining on stderr (only when stderr is a terminal).

    Returns
    -------
    EnsembleResult

    Raises
    ------
    MemberFailed
        ``fn`` raised for a member (the message names the index and params); members that
        finished before are in the store.
    StoreMismatch
        ``store`` holds a different run (or any run, without ``resume``).
    DamagedFile
        ``resume=True`` and the store's ``run.json`` is damaged (damaged member files are
        recomputed, with a :class:`~kinred.errors.KinredWarning`).
    TooLarge
        The results of all members, projected from those computed so far, would exceed the
        memory limit (environment variable ``KINRED_MAX_BYTES``, default 2 GiB); finished
        members are in ``store``.
    KinredError
        ``executor="dask"`` without Dask installed.
    """
    members, master_seed, executor, workers = _check_run(
        fn, members, master_seed, executor, workers, scheduler, store, resume)
    progress = as_bool(progress, "progress")
    config_json = _plain(config, "config") if config is not None else None
    chash = config_hash(master_seed, members, _fn_identity(fn), config_json)

    t_start = time.perf_counter()
    n = len(members)
    run_info = {"format": _FORMAT, "master_seed": master_seed, "n_members": n,
                "fn": _fn_name(fn), "config": config_json, "members": members}
    stages = _open_store(store, resume=resume, chash=chash, run_info=run_info)
    results, walls, loaded = _load_members(stages, members)
    todo = [i for i in range(n) if not loaded[i]]
    n_workers = _n_workers(executor, workers, len(todo))
    if todo:
        stream = _stream(fn, todo, members, master_seed, executor, n_workers, scheduler)
        bar = _make_bar(n, int(loaded.sum()), progress)
        kept = _Kept(results, n, store)
        try:
            for status, i, payload, extra in stream:
                if status == "error":
                    raise _failed(i, members[i], payload, extra)
                stages.save(_member_name(i), (i, members[i], payload, extra), save=_write_member)
                kept.add(payload)
                results[i], walls[i] = payload, extra
                bar.update(1)
        finally:
            bar.close()
            stream.close()  # shut executors down (cancels pending members on error/interrupt)

    total = time.perf_counter() - t_start
    if stages.folder is not None:
        stages.folder.mark_complete({
            "config_hash": chash,
            "n_members": n,
            "n_loaded": int(loaded.sum()),
            "n_computed": int(n - loaded.sum()),
            "executor": executor,
            "workers": n_workers,
            "total_time": total,
            "member_time_sum": float(np.sum(walls)),
        })
    stages.close()                # release the store folder's lock
    return EnsembleResult(
        members=tuple(members),
        results=tuple(results),
        wall_times=walls,
        total_time=total,
        loaded=loaded,
        executor=executor,
        workers=n_workers,
        master_seed=master_seed,
        store=None if store is None else os.fspath(store),
        config_hash=chash,
    )
