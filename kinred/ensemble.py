"""Ensembles: many independent members through one API and three executors.

An *ensemble* is a list of members — e.g. projections × realizations × target dimensions ×
parameter values, built with :func:`grid` — and one function ``fn(params, seed) -> dict``
computing a member. :func:`run_ensemble` runs them

* ``executor="serial"``: in this process, in member order;
* ``executor="processes"``: on a local :class:`concurrent.futures.ProcessPoolExecutor` with the
  ``"spawn"`` start method;
* ``executor="dask"``: on Dask distributed — a fresh ``distributed.LocalCluster``
  (``n_workers=workers, threads_per_worker=1, processes=True``) or an existing scheduler
  (``scheduler="tcp://host:port"`` or a ``distributed.Client``). Dask is the optional extra
  ``pip install kinred[dask]``.

**Seeds.** Member ``i`` receives ``kinred._rng.member_seed(master_seed, i)``, a
:class:`numpy.random.SeedSequence` that depends only on ``(master_seed, i)``. Results are
therefore identical, bit for bit, whatever the executor, the number of workers and the order
in which members complete (provided ``fn`` itself is deterministic given its seed, e.g. runs
single-threaded — see below).

**One thread per worker.** Multi-threaded BLAS or numba inside several worker processes would
oversubscribe the cores (and threaded reductions may change round-off). Worker processes are
therefore started with ``OMP_NUM_THREADS = OPENBLAS_NUM_THREADS = MKL_NUM_THREADS =
NUMBA_NUM_THREADS = "1"`` (:data:`THREAD_ENV`): for ``"processes"`` these variables are placed
in the environment the spawned interpreters inherit (they must be set *before* numpy / numba
are imported, which happens when the child unpickles its first task) and set again by the
worker initializer; for a LocalCluster they are passed as the nannies' ``env``. Workers of an
existing scheduler are not under our control: start them with these variables. Every member,
in every executor (the serial one included), runs the dynamics engine with one thread
(:func:`kinred.dynamics.set_num_threads`): the engine's round-off depends on its number of
threads, and the results must not depend on the executor.

**Results store.** With ``store=path`` each finished member is written at once, atomically,
by the calling process (workers need no shared file system). The store is a
:class:`kinred.io.StageStore` whose stages are the members::

    path/run.json              format, master seed, members, fn name, config, config hash
    path/members/000123.npz    one archive per finished member (written last-to-first: a
                               member file exists only once complete)
    path/summary.json          written when the whole run has finished

Each member archive holds the member's arrays and a ``__meta__`` entry (JSON: index, params,
wall time, scalar and string results), so one atomic rename commits a member.
``resume=True`` loads the members already present and computes only the others. The store's
rules are those of every :class:`~kinred.io.StageStore`: a store holding a run is refused
without ``resume=True``, one holding a run with a different config hash always
(:class:`~kinred.errors.StoreMismatch`); a killed run (even ``SIGKILL``) loses at most the
members that were in flight; a damaged member file (truncated, not an ``.npz`` archive,
missing entries) is reported by a :class:`~kinred.errors.KinredWarning` naming it and
recomputed; a damaged ``run.json`` is refused (:class:`~kinred.errors.DamagedFile`): it is
what ties the member files to the run, so the message says to delete the store or to choose
a new directory.

**Functions must be picklable** for ``"processes"`` and ``"dask"``: define ``fn`` at the top
level of an importable module (or of the ``__main__`` script, guarded by
``if __name__ == "__main__":`` because ``"spawn"`` re-imports the main module).

Examples
--------
>>> def member(params, seed):
...     rng = np.random.default_rng(seed)
...     return {"x": rng.standard_normal(params["n"]), "label": f"n={params['n']}"}
>>> res = run_ensemble(member, grid(n=[2, 3], rep=range(2)), master_seed=7, progress=False)
>>> len(res), res.members[1], res.results[1]["x"].shape, res.executor
(4, {'n': 2, 'rep': 1}, (2,), 'serial')
>>> again = run_ensemble(member, grid(n=[2, 3], rep=range(2)), master_seed=7, progress=False)
>>> all(np.array_equal(a["x"], b["x"]) for a, b in zip(res.results, again.results))
True
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import numbers
import os
import pickle
import sys
import time
import traceback
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ._repr import result_repr
from ._rng import member_seed
from ._validate import as_bool, as_choice, as_int, check_alloc, fmt_bytes
from . import _parallel
from .errors import DamagedFile, InvalidInput, KinredError, StoreMismatch
from .io import StageStore, atomic_write_npz, read_npz, to_jsonable

__all__ = [
    "THREAD_ENV",
    "EXECUTORS",
    "MemberFailed",
    "StoreMismatch",
    "EnsembleResult",
    "grid",
    "run_ensemble",
    "config_hash",
]

#: Environment given to worker processes: one thread each.
THREAD_ENV: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}

#: Executors accepted by :func:`run_ensemble`.
EXECUTORS: tuple[str, ...] = ("serial", "processes", "dask")

_FORMAT = "kinred-ensemble/1"
_META = "__meta__"


class MemberFailed(KinredError, RuntimeError):
    """A member's function raised (or returned something invalid).

    Attributes
    ----------
    index : int
        The member's index in the member list.
    params : dict
        The member's parameters.
    remote_traceback : str
        The traceback text from the process that ran the member.
    """

    def __init__(self, message: str, *, index: int, params: dict, remote_traceback: str = ""):
        super().__init__(message)
        self.index = index
        self.params = params
        self.remote_traceback = remote_traceback

    def __reduce__(self):
        return (_rebuild_member_failed, (str(self), self.index, self.params, self.remote_traceback))


def _rebuild_member_failed(message, index, params, tb):
    return MemberFailed(message, index=index, params=params, remote_traceback=tb)


# ----------------------------------------------------------------------------------------------
# Members
# ----------------------------------------------------------------------------------------------
def _plain(value, name: str):
    """JSON-safe plain Python value (numpy scalars → Python; tuples → lists)."""
    try:
        out = to_jsonable(value)
    except InvalidInput as exc:
        raise InvalidInput(f"{name} must be JSON-serializable: {exc}") from None
    return out


def grid(**axes) -> list[dict]:
    """All combinations of the given parameter axes, as a list of member dicts.

    The order is the cartesian product in keyword order with the **last axis varying
    fastest** (``itertools.product``; nested loops written in keyword order), e.g.
    ``grid(k=[10, 5], realization=range(3))`` gives ``k=10`` with realizations 0, 1, 2, then
    ``k=5``. A string or any non-iterable value is a single-value axis. Values are converted
    to plain JSON types (numpy scalars to Python numbers).

    Parameters
    ----------
    **axes : iterable or scalar
        One axis per parameter name.

    Returns
    -------
    list of dict

    Examples
    --------
    >>> grid(beta=[1.5, 1.7], k=[10, 5], kind="gaussian")
    ... # doctest: +NORMALIZE_WHITESPACE
    [{'beta': 1.5, 'k': 10, 'kind': 'gaussian'}, {'beta': 1.5, 'k': 5, 'kind': 'gaussian'},
     {'beta': 1.7, 'k': 10, 'kind': 'gaussian'}, {'beta': 1.7, 'k': 5, 'kind': 'gaussian'}]
    """
    names = list(axes)
    values = []
    for name in names:
        v = axes[name]
        if isinstance(v, (str, bytes)) or not isinstance(v, Iterable) or isinstance(v, Mapping):
            v = [v]
        v = [_plain(x, f"grid axis {name!r}") for x in v]
        if not v:
            raise InvalidInput(f"grid axis {name!r} must hold at least one value, got an empty iterable")
        values.append(v)
    return [dict(zip(names, combo)) for combo in itertools.product(*values)]


def _check_members(members) -> list[dict]:
    if isinstance(members, (str, bytes, Mapping)) or not isinstance(members, Iterable):
        raise InvalidInput(f"members must be a list of dicts, got {type(members).__name__}")
    try:
        members = list(members)
    except TypeError:  # a 0-d array
        raise InvalidInput(f"members must be a list of dicts, got {members!r}") from None
    out = []
    for i, m in enumerate(members):
        if not isinstance(m, Mapping):
            raise InvalidInput(f"members[{i}] must be a dict of parameters, got {m!r}")
        out.append(_plain(dict(m), f"members[{i}]"))
    if not out:
        raise InvalidInput("members must hold at least one member, got an empty list")
    return out


def _fn_name(fn) -> str:
    return f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', repr(fn))}"


def _fn_identity(fn) -> str:
    """``module.qualname`` of a member function, as :func:`config_hash` hashes it.

    The module tells apart functions of one name (``table1.member`` and
    ``calibrate_table1.member`` are both ``member``). A function of the script being run
    (module ``__main__``) is named by the module it is when imported: ``python -m pkg.mod``
    gives ``pkg.mod``, ``python path/run.py`` gives ``run``, so a run started as a script
    resumes from ``import run``.
    """
    module = getattr(fn, "__module__", None) or "?"
    if module == "__main__":
        main = sys.modules.get("__main__")
        spec = getattr(main, "__spec__", None)
        if spec is not None and getattr(spec, "name", None):
            module = spec.name
        elif getattr(main, "__file__", None):
            module = Path(main.__file__).stem
    return f"{module}.{getattr(fn, '__qualname__', repr(fn))}"


def config_hash(master_seed: int, members: list[dict], fn_qualname: str, config=None) -> str:
    """SHA-256 of the canonical JSON of what determines a run's results.

    Hashed: the master seed, the member list, the function's name ``fn_qualname`` (as
    :func:`run_ensemble` calls it: ``_fn_identity``, ``module.qualname``, so a store does
    not resume with another module's function of the same name) and the optional user
    ``config``.

    Examples
    --------
    >>> config_hash(1, [{"k": 2}], "f") == config_hash(1, [{"k": 2}], "f")
    True
    >>> config_hash(1, [{"k": 2}], "f") == config_hash(2, [{"k": 2}], "f")
    False
    """
    payload = {
        "format": _FORMAT,
        "master_seed": int(master_seed),
        "members": members,
        "fn": fn_qualname,
        "config": _plain(config, "config"),
    }
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# ----------------------------------------------------------------------------------------------
# Running one member (in whatever process)
# ----------------------------------------------------------------------------------------------
def _normalize_output(out) -> dict:
    if not isinstance(out, Mapping):
        raise TypeError(f"fn must return a dict of results, got {type(out).__name__}")
    res = {}
    for key, value in out.items():
        if not isinstance(key, str) or not key or key.startswith("__") or "/" in key:
            raise TypeError(
                f"result names must be non-empty str without '/' not starting with '__', got {key!r}"
            )
        if isinstance(value, str):
            res[key] = value
        elif isinstance(value, (bool, np.bool_)):
            res[key] = bool(value)
        elif isinstance(value, (numbers.Integral, np.integer)):
            res[key] = int(value)
        elif isinstance(value, (numbers.Real, np.floating)):
            res[key] = float(value)
        else:
            arr = np.asarray(value)
            if arr.dtype == object:
                raise TypeError(
                    f"result {key!r} must be a str, a number or a numeric array, got {type(value).__name__}"
                )
            res[key] = arr
    return res


def _run_member(fn, params: dict, master_seed: int, index: int):
    """Run one member; never raises for errors of ``fn`` (they are returned as text)."""
    seed = member_seed(master_seed, index)
    t0 = time.perf_counter()
    try:
        # one engine thread in every executor: the engine's round-off depends on its thread
        # count, the results must not depend on the executor
        with _parallel.num_threads(1):
            out = _normalize_output(fn(dict(params), seed))
    except Exception as exc:  # reported to the caller with the member's identity
        return ("error", index, f"{type(exc).__name__}: {exc}", traceback.format_exc())
    return ("ok", index, out, time.perf_counter() - t0)


def _exit_with_parent() -> None:
    """Block until the parent process is gone, then end this worker (daemon thread)."""
    import multiprocessing

    parent = multiprocessing.parent_process()
    if parent is not None:
        parent.join()           # waits on the parent's sentinel: portable, no polling
        os._exit(1)


def _worker_init() -> None:
    """Initializer of worker processes: one thread for BLAS/OpenMP/numba, and a watcher
    thread that ends the worker when its parent dies (a killed run leaves no orphan still
    computing its member)."""
    os.environ.update(THREAD_ENV)
    import threading

    threading.Thread(target=_exit_with_parent, name="kinred-parent-watch", daemon=True).start()
    numba = sys.modules.get("numba")
    if numba is not None:  # already imported (e.g. by unpickling): limit it explicitly
        try:
            numba.set_num_threads(1)
        except Exception:  # pragma: no cover - numba without a threading layer
            pass


@contextlib.contextmanager
def _thread_env():
    """Temporarily put :data:`THREAD_ENV` into ``os.environ`` (inherited by spawned children)."""
    saved = {k: os.environ.get(k) for k in THREAD_ENV}
    os.environ.update(THREAD_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


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


# ----------------------------------------------------------------------------------------------
# Executors
# ----------------------------------------------------------------------------------------------
def _make_bar(total: int, initial: int, progress: bool):
    from tqdm import tqdm

    disable = (not progress) or not (hasattr(sys.stderr, "isatty") and sys.stderr.isatty())
    return tqdm(total=total, initial=initial, disable=disable, desc="members", unit="member",
                dynamic_ncols=True)


def _failed(index: int, params: dict, message: str, tb: str) -> MemberFailed:
    return MemberFailed(
        f"ensemble member {index} with params {params} failed: {message} "
        "(full traceback in the exception's .remote_traceback)",
        index=index, params=params, remote_traceback=tb,
    )


def _iter_serial(fn, todo, members, master_seed):
    for i in todo:
        yield _run_member(fn, members[i], master_seed, i)


def _iter_processes(fn, todo, members, master_seed, workers):
    import concurrent.futures as cf
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
    try:
        with _thread_env():  # children are spawned during submit and inherit this environment
            futures = [pool.submit(_run_member, fn, members[i], master_seed, i) for i in todo]
        for fut in cf.as_completed(futures):
            yield fut.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _import_distributed():
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        raise KinredError(
            "executor='dask' needs Dask distributed, which is not installed: "
            "pip install 'kinred[dask]'  (or: pip install dask distributed)"
        ) from exc
    return distributed


def _iter_dask(fn, todo, members, master_seed, workers, scheduler):
    distributed = _import_distributed()
    import logging

    own_cluster = None
    if scheduler is None:
        own_cluster = distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True,
            dashboard_address=None, silence_logs=logging.ERROR, env=dict(THREAD_ENV),
        )
        client = distributed.Client(own_cluster)
        own_client = True
    elif isinstance(scheduler, distributed.Client):
        client, own_client = scheduler, False
    else:
        client, own_client = distributed.Client(scheduler), True
    try:
        futures = [
            client.submit(_run_member, fn, members[i], master_seed, i, pure=False,
                          key=f"kinred-member-{i}-{os.getpid()}-{time.time_ns()}")
            for i in todo
        ]
        try:
            for fut in distributed.as_completed(futures):
                yield fut.result()
        finally:
            client.cancel(futures)
    finally:
        if own_client:
            client.close()
        if own_cluster is not None:
            own_cluster.close()


def _stream(fn, todo, members, master_seed, executor, n_workers, scheduler):
    """The executor's generator of ``(status, index, payload, extra)`` for the members ``todo``."""
    if executor == "serial":
        return _iter_serial(fn, todo, members, master_seed)
    if executor == "processes":
        return _iter_processes(fn, todo, members, master_seed, n_workers)
    return _iter_dask(fn, todo, members, master_seed, n_workers, scheduler)


def _n_workers(executor: str, workers: int | None, n_todo: int) -> int:
    """Workers used: 1 for serial; else ``workers`` (default the cores), at most ``n_todo``."""
    if executor == "serial":
        return 1
    n = workers if workers is not None else (os.cpu_count() or 1)
    return max(1, min(n, n_todo)) if n_todo else n


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
