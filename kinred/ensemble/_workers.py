"""Running members: one member in whatever process (one engine thread), and the three
executors that stream finished members back (serial, a spawned process pool, Dask)."""

from __future__ import annotations

import contextlib
import numbers
import os
import sys
import time
import traceback
from collections.abc import Mapping

import numpy as np

from .. import _parallel
from .._rng import member_seed
from ..errors import KinredError
from ._members import THREAD_ENV, MemberFailed

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
