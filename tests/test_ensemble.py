"""Tests of kinred.ensemble: seeds, executors (serial / processes / Dask), results store, resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from kinred._rng import member_seed
from kinred.ensemble import (
    EnsembleResult,
    MemberFailed,
    StoreMismatch,
    grid,
    run_ensemble,
)
from kinred.errors import DamagedFile, InvalidInput, KinredError, KinredWarning
from kinred.projection import jl_matrix

REPO = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------------------------
# Member functions (top level: picklable by reference for processes / Dask)
# ----------------------------------------------------------------------------------------------
def jl_member(params, seed):
    """Cheap but seed-dependent: draw a JL matrix and a cloud, project, summarize."""
    rng = np.random.default_rng(seed)
    d = 24
    X = rng.random((6, d))
    M = jl_matrix(params["k"], d, params["kind"], seed=rng)
    Y = M.apply(X)
    return {
        "Y": Y,
        "first": float(rng.standard_normal()),
        "count": int(rng.integers(0, 1000)),
        "ok": bool(Y.sum() > 0),
        "label": f"{params['kind']}-{params['k']}",
        "ints": rng.integers(0, 10, size=3),
    }


def env_member(params, seed):
    """Reports the thread limits seen by the process running the member."""
    from kinred.dynamics import get_num_threads

    keys = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
    out = {k: os.environ.get(k, "unset") for k in keys}
    out["engine_threads"] = str(get_num_threads())  # row strips of the dynamics engine
    return out


def failing_member(params, seed):
    if params["i"] == 3:
        raise ValueError("deliberate failure")
    return {"v": float(np.random.default_rng(seed).random())}


def bad_output_member(params, seed):
    return [1, 2, 3]


def interrupting_member(params, seed):
    if params["i"] == 2:
        raise KeyboardInterrupt
    return {"v": np.random.default_rng(seed).random(3)}


MEMBERS = grid(kind=["gaussian", "srht", "achlioptas"], k=[3, 5], realization=range(2))


def assert_bitwise_equal(a: EnsembleResult, b: EnsembleResult):
    assert a.members == b.members and len(a) == len(b)
    for ra, rb in zip(a.results, b.results):
        assert list(ra) == list(rb)
        for key in ra:
            va, vb = ra[key], rb[key]
            if isinstance(va, np.ndarray):
                assert isinstance(vb, np.ndarray) and va.dtype == vb.dtype and va.shape == vb.shape
                assert va.tobytes() == vb.tobytes(), key
            else:
                assert type(va) is type(vb) and va == vb, key


@pytest.fixture(scope="module")
def serial_result():
    return run_ensemble(jl_member, MEMBERS, master_seed=2024, progress=False)


# ----------------------------------------------------------------------------------------------
# grid and seeds
# ----------------------------------------------------------------------------------------------
def test_grid_order_and_types():
    g = grid(k=[10, 5], realization=range(3), beta=np.array([1.5]), kind="gaussian")
    assert len(g) == 6
    assert [(m["k"], m["realization"]) for m in g] == [(10, 0), (10, 1), (10, 2), (5, 0), (5, 1), (5, 2)]
    assert all(type(m["beta"]) is float and m["kind"] == "gaussian" for m in g)
    with pytest.raises(InvalidInput, match="at least one value"):
        grid(k=[])
    assert grid() == [{}]


def test_member_seeds_follow_convention(serial_result):
    for i in (0, 5, len(MEMBERS) - 1):
        rng = np.random.default_rng(member_seed(2024, i))
        X = rng.random((6, 24))
        M = jl_matrix(MEMBERS[i]["k"], 24, MEMBERS[i]["kind"], seed=rng)
        np.testing.assert_array_equal(serial_result.results[i]["Y"], M.apply(X))
    r = serial_result
    assert r.executor == "serial" and r.workers == 1 and not r.loaded.any()
    assert r.wall_times.shape == (len(MEMBERS),) and np.all(r.wall_times >= 0)
    assert r.results[0]["label"] == "gaussian-3" and isinstance(r.results[0]["count"], int)
    # different master seed -> different numbers
    other = run_ensemble(jl_member, MEMBERS[:2], master_seed=2025, progress=False)
    assert other.results[0]["first"] != r.results[0]["first"]


def test_result_helpers(serial_result):
    idx = serial_result.indices(kind="srht", k=5)
    assert [serial_result.members[i] for i in idx] == [
        {"kind": "srht", "k": 5, "realization": 0}, {"kind": "srht", "k": 5, "realization": 1}]
    assert serial_result.stack("Y", idx).shape == (2, 6, 5)
    assert serial_result.stack("first").shape == (len(MEMBERS),)
    with pytest.raises(InvalidInput, match="result key"):
        serial_result.stack("nope")
    np.testing.assert_array_equal(serial_result.computed, np.arange(len(MEMBERS)))


# ----------------------------------------------------------------------------------------------
# Executors give bit-identical results
# ----------------------------------------------------------------------------------------------
def test_processes_bitwise_identical_to_serial(serial_result):
    res = run_ensemble(jl_member, MEMBERS, master_seed=2024, executor="processes", workers=2,
                       progress=False)
    assert res.executor == "processes" and res.workers == 2
    assert_bitwise_equal(serial_result, res)


def test_dask_bitwise_identical_to_serial(serial_result, tmp_path):
    # a LocalCluster with 2 worker processes, created and closed by run_ensemble; with a store,
    # so the Dask results also go through the member files
    res = run_ensemble(jl_member, MEMBERS, master_seed=2024, executor="dask", workers=2,
                       store=tmp_path / "store", progress=False)
    assert res.executor == "dask" and res.workers == 2
    assert_bitwise_equal(serial_result, res)
    back = run_ensemble(jl_member, MEMBERS, master_seed=2024, store=tmp_path / "store",
                        resume=True, progress=False)
    assert back.loaded.all()
    assert_bitwise_equal(serial_result, back)


def test_serial_members_run_the_engine_single_threaded():
    from kinred.dynamics import get_num_threads, set_num_threads

    old = get_num_threads()
    set_num_threads(2)
    try:
        res = run_ensemble(env_member, grid(i=range(2)), master_seed=0, executor="serial",
                           progress=False)
        assert [r["engine_threads"] for r in res.results] == ["1", "1"]
        assert get_num_threads() == 2          # restored after the run
    finally:
        set_num_threads(old)


@pytest.mark.parametrize("executor", ["processes", "dask"])
def test_workers_run_single_threaded(executor):
    res = run_ensemble(env_member, grid(i=range(2)), master_seed=0, executor=executor, workers=2,
                       progress=False)
    for r in res.results:
        assert set(r.values()) == {"1"}, r


def test_dask_existing_scheduler_address(serial_result):
    import logging

    import distributed

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        res = run_ensemble(jl_member, MEMBERS, master_seed=2024, executor="dask",
                           scheduler=cluster.scheduler_address, progress=False)
        with distributed.Client(cluster) as client:
            res2 = run_ensemble(jl_member, MEMBERS[:3], master_seed=2024, executor="dask",
                                scheduler=client, progress=False)
            assert client.status == "running"        # a client we were given is not closed
    assert_bitwise_equal(serial_result, res)
    assert all(res2.results[i]["first"] == serial_result.results[i]["first"] for i in range(3))


def test_dask_missing_gives_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # makes `import distributed` fail
    with pytest.raises(KinredError, match=r"kinred\[dask\]"):
        run_ensemble(jl_member, MEMBERS[:1], master_seed=0, executor="dask", progress=False)


# ----------------------------------------------------------------------------------------------
# Store and resume
# ----------------------------------------------------------------------------------------------
def test_store_layout_and_resume_loads_everything(tmp_path, serial_result):
    store = tmp_path / "run"
    first = run_ensemble(jl_member, MEMBERS, master_seed=2024, store=store, progress=False,
                         config={"note": "test"})
    assert_bitwise_equal(serial_result, first)
    names = sorted(p.name for p in (store / "members").iterdir())
    assert names == [f"{i:06d}.npz" for i in range(len(MEMBERS))]
    run = json.loads((store / "run.json").read_text())
    assert run["master_seed"] == 2024 and run["members"] == MEMBERS and run["config"] == {"note": "test"}
    assert run["fn"].endswith("jl_member")
    summary = json.loads((store / "summary.json").read_text())
    assert summary["n_computed"] == len(MEMBERS) and summary["config_hash"] == run["config_hash"]

    again = run_ensemble(jl_member, MEMBERS, master_seed=2024, store=store, resume=True,
                         progress=False, config={"note": "test"})
    assert again.loaded.all() and again.computed.size == 0
    np.testing.assert_array_equal(again.wall_times, first.wall_times)
    assert_bitwise_equal(serial_result, again)


def test_store_refuses_other_runs(tmp_path):
    store = tmp_path / "run"
    run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=store, progress=False)
    with pytest.raises(StoreMismatch, match="resume=True"):
        run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=store, progress=False)
    with pytest.raises(StoreMismatch, match="config hash"):
        run_ensemble(jl_member, MEMBERS[:2], master_seed=2, store=store, resume=True, progress=False)
    with pytest.raises(StoreMismatch, match="config hash"):
        run_ensemble(jl_member, MEMBERS[:3], master_seed=1, store=store, resume=True, progress=False)
    with pytest.raises(StoreMismatch, match="config hash"):
        run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=store, resume=True,
                     config={"N": 5}, progress=False)
    other = tmp_path / "not_a_store"
    other.mkdir()
    (other / "x.txt").write_text("x")
    with pytest.raises(StoreMismatch, match="not an ensemble store"):
        run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=other, progress=False)
    # resume on a missing store simply starts it
    res = run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=tmp_path / "new", resume=True,
                       progress=False)
    assert not res.loaded.any()


def test_resume_recomputes_damaged_member_files(tmp_path, serial_result):
    store = tmp_path / "run"
    run_ensemble(jl_member, MEMBERS, master_seed=2024, store=store, progress=False)
    members = store / "members"
    os.truncate(members / "000003.npz", (members / "000003.npz").stat().st_size // 2)
    (members / "000005.npz").write_bytes(b"")
    np.savez(members / "000007.npz", Y=np.zeros(2))          # a valid archive, but no __meta__
    with pytest.warns(KinredWarning) as rec:
        again = run_ensemble(jl_member, MEMBERS, master_seed=2024, store=store, resume=True,
                             progress=False)
    texts = sorted(str(w.message) for w in rec if issubclass(w.category, KinredWarning))
    assert len(texts) == 3
    for text, i in zip(texts, (3, 5, 7)):
        assert text.startswith(f"{members / f'{i:06d}.npz'}: damaged member file: ")
        assert text.endswith(f"; recomputing member {i}")
    assert "no __meta__ entry" in texts[2]
    assert sorted(np.flatnonzero(~again.loaded)) == [3, 5, 7]
    assert_bitwise_equal(serial_result, again)


@pytest.mark.parametrize("content", [b"", b'{"format": "kinred-ens', b"[1, 2]"])
def test_resume_refuses_damaged_run_json(tmp_path, content):
    store = tmp_path / "run"
    run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=store, progress=False)
    (store / "run.json").write_bytes(content)
    with pytest.raises(DamagedFile, match=r"run\.json: damaged store description: .*; it ties the "
                                          r"member files to a run.*delete the store") as ei:
        run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=store, resume=True, progress=False)
    assert ei.value.path == str(store / "run.json")
    # without resume the store is refused as before, naming the command-line flag too
    with pytest.raises(StoreMismatch, match=r"resume=True \(--resume on the command line\)"):
        run_ensemble(jl_member, MEMBERS[:2], master_seed=1, store=store, progress=False)


def test_member_error_names_member_and_keeps_finished(tmp_path):
    members = grid(i=range(6))
    store = tmp_path / "run"
    with pytest.raises(MemberFailed, match=r"member 3 with params \{'i': 3\}.*deliberate failure") as ei:
        run_ensemble(failing_member, members, master_seed=0, store=store, progress=False)
    assert ei.value.index == 3 and ei.value.params == {"i": 3}
    assert "ValueError" in ei.value.remote_traceback
    assert sorted(p.name for p in (store / "members").iterdir()) == [f"{i:06d}.npz" for i in range(3)]
    assert not (store / "summary.json").exists()
    # on processes the error surfaces the same way
    with pytest.raises(MemberFailed, match="member 3") as ei:
        run_ensemble(failing_member, members, master_seed=0, executor="processes", workers=2,
                     progress=False)
    assert ei.value.index == 3
    with pytest.raises(MemberFailed, match="must return a dict"):
        run_ensemble(bad_output_member, members[:1], master_seed=0, progress=False)


def test_interrupt_leaves_no_partial_member_files(tmp_path):
    store = tmp_path / "run"
    members = grid(i=range(5))
    with pytest.raises(KeyboardInterrupt):
        run_ensemble(interrupting_member, members, master_seed=3, store=store, progress=False)
    files = sorted(p.name for p in (store / "members").iterdir())
    assert files == ["000000.npz", "000001.npz"]          # complete files only, no temp files
    res = run_ensemble(interrupting_member, members[:2], master_seed=3,
                       progress=False)
    assert res.results[1]["v"].shape == (3,)


_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    import numpy as np
    from kinred.ensemble import grid, run_ensemble

    def member(params, seed):
        with open(os.environ["KINRED_TEST_LOG"], "a") as fh:
            fh.write(f"{params['i']}\\n")
        if params["i"] == int(os.environ.get("KINRED_TEST_KILL_AT", "-1")):
            os.kill(os.getpid(), signal.SIGKILL)      # hard kill: no cleanup at all
        rng = np.random.default_rng(seed)
        return {"x": rng.standard_normal(5), "s": float(rng.random()), "tag": "m%d" % params["i"]}

    MEMBERS = grid(i=range(8), beta=[1.5])

    if __name__ == "__main__":
        run_ensemble(member, MEMBERS, master_seed=99, store=sys.argv[1], resume=True, progress=False)
    """
)


def test_killed_run_resumes_without_recomputing(tmp_path):
    script = tmp_path / "ens_script.py"
    script.write_text(_SCRIPT)
    log = tmp_path / "calls.log"
    store = tmp_path / "store"
    env = dict(os.environ, KINRED_TEST_LOG=str(log), KINRED_TEST_KILL_AT="4")
    proc = subprocess.run([sys.executable, str(script), str(store)], env=env, cwd=REPO,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    done = sorted(p.name for p in (store / "members").iterdir())
    assert done == [f"{i:06d}.npz" for i in range(4)]      # members 0-3 finished, nothing partial
    assert not (store / "summary.json").exists()

    # resume in this process with the same function (same qualname, same config hash)
    import importlib.util

    spec = importlib.util.spec_from_file_location("ens_script", script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    os.environ["KINRED_TEST_LOG"] = str(log)
    try:
        resumed = run_ensemble(mod.member, mod.MEMBERS, master_seed=99, store=store, resume=True,
                               progress=False)
        clean = run_ensemble(mod.member, mod.MEMBERS, master_seed=99, progress=False)
    finally:
        del os.environ["KINRED_TEST_LOG"]
    np.testing.assert_array_equal(resumed.loaded, [True] * 4 + [False] * 4)
    assert_bitwise_equal(clean, resumed)
    calls = [int(s) for s in log.read_text().split()]
    # killed run: 0..4 (4 was killed mid-way); resume: 4..7; clean run: 0..7
    assert calls == [0, 1, 2, 3, 4] + [4, 5, 6, 7] + list(range(8))
    assert (store / "summary.json").exists()


_ORPHAN_SCRIPT = textwrap.dedent("""
    import os, sys, time
    import multiprocessing, concurrent.futures as cf
    from kinred.ensemble import _worker_init

    def member(path):
        with open(path, "w") as fh:
            fh.write(str(os.getpid()))
        time.sleep(600)        # far beyond the test's deadline: only the watcher ends it

    if __name__ == "__main__":
        pool = cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                      initializer=_worker_init)
        pool.submit(member, sys.argv[1])
        while not os.path.exists(sys.argv[1]) or not open(sys.argv[1]).read():
            time.sleep(0.05)
        os.kill(os.getpid(), 9)            # the run is killed mid-member
""")


def test_killed_run_leaves_no_orphan_worker(tmp_path):
    import time

    script = tmp_path / "orphan.py"
    script.write_text(_ORPHAN_SCRIPT)
    pidfile, logfile = tmp_path / "worker.pid", tmp_path / "orphan.log"
    # output to a file, not a pipe: a surviving worker would hold a pipe open and keep
    # subprocess.run waiting, instead of failing at the deadline below
    with open(logfile, "w") as log:
        proc = subprocess.run([sys.executable, str(script), str(pidfile)], cwd=REPO,
                              stdout=log, stderr=subprocess.STDOUT, timeout=600)
    assert proc.returncode == -signal.SIGKILL, logfile.read_text()
    pid = int(pidfile.read_text())
    # The watcher thread ends the worker within 1.1-1.7 s of the parent's death (measured at
    # load 5.6 on 2 cores); 60 s leaves room for a loaded machine, and an orphan sleeping its
    # 600 s member still fails the test.
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        os.kill(pid, signal.SIGKILL)
        pytest.fail("the worker outlived its killed parent")


# ----------------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(members=[]), "at least one member"),
        (dict(members=[1, 2]), r"members\[0\] must be a dict"),
        (dict(members=[{"a": object()}]), "JSON"),
        (dict(master_seed=-1), "master_seed must be >= 0"),
        (dict(executor="threads"), "executor must be one of"),
        (dict(workers=0, executor="processes"), "workers must be >= 1"),
        (dict(scheduler="tcp://127.0.0.1:1"), "only used with executor='dask'"),
        (dict(resume=True), "needs a store"),
        (dict(fn=lambda p, s: {}, executor="processes"), "picklable"),
        (dict(fn=3), "callable"),
    ],
)
def test_run_ensemble_validation(kwargs, match):
    args = dict(fn=jl_member, members=MEMBERS[:1], master_seed=0, progress=False)
    args.update(kwargs)
    fn = args.pop("fn")
    members = args.pop("members")
    with pytest.raises(InvalidInput, match=match):
        run_ensemble(fn, members, **args)
