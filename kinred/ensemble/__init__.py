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

import numpy as np  # noqa: F401  (the examples above)

from ..errors import StoreMismatch
from ._members import EXECUTORS, THREAD_ENV, MemberFailed, _fn_identity, config_hash, grid
from ._run import EnsembleResult, run_ensemble
from ._workers import _worker_init  # noqa: F401  (used by tests, as _fn_identity)

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
