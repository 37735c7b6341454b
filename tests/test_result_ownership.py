"""A result folder belongs to one process at a time, and its stages to one configuration
(issue 21, item 2): the folder lock, the digest of every stage file, no loading without
``--resume``; a full disk is its own error (item 12)."""

import contextlib
import errno
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import kinred.cli as cli
import kinred.io as kio
from kinred._lock import LOCK_NAME, lock_folder, release_all
from kinred.errors import DiskFull, FolderInUse, InvalidInput, KinredError, KinredWarning
from kinred.io import StageStore, atomic_write_json, atomic_write_npz, read_npz

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 300           # seconds for a child interpreter (imports + a smoke run take ~10 s)

SCENE = """
[dynamics]
d = 2
[[dynamics.effect]]
type = "alignment"
G = 1.0
beta = 0.5
[initial.positions]
[[initial.positions.coordinate]]
dist = "uniform"
repeat = 2
[initial.velocities]
[[initial.velocities.coordinate]]
dist = "uniform"
repeat = 2
[quantize]
atoms = 9
[projection]
k = [1, 2]
seed = SEED
[integrate]
dt = 0.1
t_final = 0.5
"""


@pytest.fixture
def main(monkeypatch):
    if "kinred.commands.run" not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("kinred.commands.run",))
    return cli.main


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory):
    """``clean_run(name, seed)``: the folder of ``kinred run NAME --out FOLDER`` for SCENE with
    ``projection.seed = seed`` (a fresh folder), run once per module; tests only read it or
    copy it."""
    runs = {}

    def get(name, seed):
        if (name, seed) not in runs:
            tmp = tmp_path_factory.mktemp(f"clean-{seed}")
            scene, out = _scene(tmp, name, seed), tmp / "out"
            with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(io.StringIO()):
                if "kinred.commands.run" not in cli.COMMAND_MODULES:
                    mp.setattr(cli, "COMMAND_MODULES",
                               cli.COMMAND_MODULES + ("kinred.commands.run",))
                assert cli.main(["run", str(scene), "--out", str(out), "--no-progress",
                                 "--no-figures"]) == 0
            runs[name, seed] = out
        return runs[name, seed]

    return get


def _child(code: str) -> subprocess.Popen:
    """A Python child running ``code`` (stdout piped, line-buffered)."""
    return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _holder(folder) -> subprocess.Popen:
    """A child process that takes the lock of ``folder``, says so, and sleeps."""
    p = _child(f"""
        import sys, time
        from kinred._lock import lock_folder
        lock_folder({str(folder)!r})
        print("held", flush=True)
        time.sleep({TIMEOUT})
        """)
    assert p.stdout.readline().strip() == "held", p.stderr.read()
    return p


def _stop(p: subprocess.Popen) -> None:
    """Kill the child and close its pipes: ``wait`` alone leaves them open, and their
    ResourceWarning at a later garbage collection fails whichever test turns warnings into
    errors at that moment."""
    p.kill()
    p.communicate()


def _files(folder):
    return sorted(p.relative_to(folder).as_posix() for p in Path(folder).rglob("*"))


# -------------------------------------------------------------------------- the lock itself
def test_a_second_process_is_refused_naming_the_holder(tmp_path):
    p = _holder(tmp_path)
    try:
        with pytest.raises(FolderInUse) as info:
            lock_folder(tmp_path)
        msg = str(info.value)
        assert f"pid {p.pid} on {socket.gethostname()}" in msg and "since 20" in msg
        assert "lock_folder" in msg or "-c" in msg           # the holder's command line
        assert "\n" not in msg and info.value.holder["pid"] == p.pid
        # a stage store there is refused too, and the folder is left as it was
        before = _files(tmp_path)
        with pytest.raises(FolderInUse):
            StageStore(tmp_path, "d1")
        assert _files(tmp_path) == before == [LOCK_NAME]
    finally:
        _stop(p)


def test_the_lock_of_a_killed_process_is_taken_over(tmp_path):
    p = _holder(tmp_path)
    os.kill(p.pid, signal.SIGKILL)
    p.communicate()                 # waits, and closes the pipes (no ResourceWarning later)
    assert (tmp_path / LOCK_NAME).is_file()                   # left behind by SIGKILL
    lock = lock_folder(tmp_path)
    try:
        assert lock.previous["pid"] == p.pid                  # the stale holder, taken over
        assert json.loads((tmp_path / LOCK_NAME).read_text())["pid"] == os.getpid()
    finally:
        lock.release()
    assert not (tmp_path / LOCK_NAME).exists()


def test_the_lock_is_reentrant_within_a_process(tmp_path):
    a = lock_folder(tmp_path)
    b = lock_folder(tmp_path)
    a.release()
    assert (tmp_path / LOCK_NAME).is_file()                   # b still holds it
    b.release()
    assert not (tmp_path / LOCK_NAME).exists()
    with StageStore(tmp_path / "st", "d1") as store:
        assert (tmp_path / "st" / LOCK_NAME).is_file()
        store.get_or_compute("a", lambda: {"x": np.arange(2)})
    assert sorted(p.name for p in (tmp_path / "st").iterdir()) == ["a.npz", "config.json"]


# ------------------------------------------------------------------- stages and their digest
def test_stage_files_carry_the_digest_and_foreign_ones_are_recomputed(tmp_path):
    with StageStore(tmp_path / "a", "digest-a") as a:
        a.get_or_compute("k1", lambda: {"w1": np.array([1.0, 2.0])})
    assert str(read_npz(tmp_path / "a" / "k1.npz")["__digest__"]) == "digest-a"
    with StageStore(tmp_path / "b", "digest-b") as b:
        b.get_or_compute("solve", lambda: {"x": np.zeros(1)})
    # a stage of run A lands in run B's store (the race): B does not load it
    (tmp_path / "b" / "k1.npz").write_bytes((tmp_path / "a" / "k1.npz").read_bytes())
    with StageStore(tmp_path / "b", "digest-b", resume=True) as b:
        with pytest.warns(KinredWarning, match=r"k1\.npz: stage file of another configuration "
                                               r"\(digest digest-a… != digest-b…"):
            got = b.get_or_compute("k1", lambda: {"w1": np.array([7.0])})
        assert b.status == {"k1": "computed"} and got["w1"].tolist() == [7.0]
        assert b.get_or_compute("solve", lambda: 1 / 0)["x"].tolist() == [0.0]
        assert b.status["solve"] == "loaded" and "__digest__" not in b.load("solve")
    # a stage file without a digest cannot be tied to the run either
    atomic_write_npz(tmp_path / "b" / "old.npz", {"x": np.ones(1)})
    with StageStore(tmp_path / "b", "digest-b", resume=True) as b:
        with pytest.warns(KinredWarning, match="without a configuration digest"):
            assert b.load("old") is None


def test_a_fresh_store_never_loads(tmp_path):
    with StageStore(tmp_path / "s", "d1") as store:
        # a file appears under the fresh store's feet (written by another run, or left over)
        atomic_write_npz(tmp_path / "s" / "k2.npz", {"x": np.ones(1), "__digest__": "d1"})
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = store.get_or_compute("k2", lambda: {"x": np.full(1, 5.0)})
        assert store.status == {"k2": "computed"} and got["x"].tolist() == [5.0]
        # what this store wrote itself it may read back within the run
        assert store.get_or_compute("k2", lambda: 1 / 0)["x"].tolist() == [5.0]
    assert float(read_npz(tmp_path / "s" / "k2.npz")["x"][0]) == 5.0


# --------------------------------------------------------------- the A-then-B story
_PAUSED_RUN = """
    import pathlib, sys, time
    import kinred.cli as c
    from kinred.experiments import kinetic_run
    if "kinred.commands.run" not in c.COMMAND_MODULES:
        c.COMMAND_MODULES += ("kinred.commands.run",)
    go, _stage = pathlib.Path(GO), kinetic_run._k_stage
    def k_stage(*args, **kwargs):          # pause before the first k stage (solve is on disk)
        print("paused", flush=True)
        while not go.exists():
            time.sleep(0.01)
        return _stage(*args, **kwargs)
    kinetic_run._k_stage = k_stage
    sys.argv = ["kinred", *ARGS]              # what the holder's lock line shows
    sys.exit(c.main(ARGS))
"""


def _scene(tmp_path, name, seed):
    path = tmp_path / name
    path.write_text(SCENE.replace("SEED", str(seed)))
    return path


def _numbers(folder):
    with np.load(folder / "results.npz") as z:
        return {k: z[k] for k in z.files if not k.endswith("_time")}


def test_two_runs_into_one_folder(tmp_path, main, capsys, clean_run):
    a_scene, b_scene = _scene(tmp_path, "A.toml", 1), _scene(tmp_path, "B.toml", 2)
    out, go = tmp_path / "R", tmp_path / "go"
    args = ["run", str(a_scene), "--out", str(out), "--no-progress", "--no-figures"]
    a = _child(_PAUSED_RUN.replace("GO", repr(str(go))).replace("ARGS", repr(args)))
    try:
        line = a.stdout.readline()
        while line and "paused" not in line:
            line = a.stdout.readline()
        assert "paused" in line, a.stderr.read()
        before = {f: (out / f).read_bytes() for f in _files(out) if (out / f).is_file()}
        assert "stages/solve.npz" in before
        # B, differing only in projection.seed, while A runs: refused in one line, R untouched
        assert main(["run", str(b_scene), "--out", str(out), "--no-progress",
                     "--no-figures"]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip()
        assert len(err.splitlines()) == 1 and "replacing" not in captured.out
        assert err.startswith(f"kinred: error: FolderInUse: {out}: this result folder is in use "
                              f"by pid {a.pid} on {socket.gethostname()}")
        assert "A.toml" in err                                # the holder's command line
        assert {f: (out / f).read_bytes() for f in _files(out) if (out / f).is_file()} == before
    finally:
        go.touch()
        a_out, a_err = a.communicate(timeout=TIMEOUT)
    assert a.returncode == 0, a_err
    a_summary = json.loads((out / "summary.json").read_text())
    a_numbers = _numbers(out)
    assert set(a_summary["stages"].values()) == {"computed"}
    # B after A finished: replaces A's run, loads nothing, and its numbers are its own
    assert main(["run", str(b_scene), "--out", str(out), "--no-progress",
                 "--no-figures"]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith(f"kinred run: replacing the previous run in {out}")
    assert "loaded" not in printed
    b_summary = json.loads((out / "summary.json").read_text())
    assert set(b_summary["stages"].values()) == {"computed"}
    assert b_summary["digest"] != a_summary["digest"]
    alone, b_numbers = _numbers(clean_run("B.toml", 2)), _numbers(out)   # B in a new folder
    assert alone.keys() == b_numbers.keys()
    for key in alone:
        assert alone[key].tobytes() == b_numbers[key].tobytes(), key
    assert not np.array_equal(a_numbers["k2_w1"], b_numbers["k2_w1"])   # another projection
    assert not (out / LOCK_NAME).exists() and not (out / "stages" / LOCK_NAME).exists()


def test_kinetic_run_api_owns_its_folder(tmp_path):
    from kinred.experiments import kinetic_run

    cfg = kinetic_run.load_config(_scene(tmp_path, "A.toml", 1), smoke=False)
    (tmp_path / "R").mkdir()
    p = _holder(tmp_path / "R")
    try:
        with pytest.raises(FolderInUse, match=f"pid {p.pid}"):
            kinetic_run.run(cfg, out_dir=tmp_path / "R", figures=False)
        assert _files(tmp_path / "R") == [LOCK_NAME]
    finally:
        _stop(p)
    # the stale lock is taken over
    res = kinetic_run.run(cfg, out_dir=tmp_path / "R", figures=False)
    assert set(res.stages.values()) == {"computed"}
    assert not (tmp_path / "R" / LOCK_NAME).exists()


# ------------------------------------------------------------------------------ a full disk
def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("where", ["fsync", "mkstemp"])
def test_a_full_disk_is_its_own_error(tmp_path, monkeypatch, where):
    target = tmp_path / "r.json"
    atomic_write_json(target, {"old": 1})
    if where == "fsync":
        monkeypatch.setattr(os, "fsync", _enospc)
    else:
        monkeypatch.setattr(tempfile, "mkstemp", _enospc)
    with pytest.raises(DiskFull) as info:
        atomic_write_json(target, {"new": 2})
    assert not isinstance(info.value, InvalidInput) and isinstance(info.value, KinredError)
    assert str(info.value).startswith(f"{target}: cannot write the file: no space left on device")
    assert info.value.path == str(target)
    monkeypatch.undo()
    assert json.loads(target.read_text()) == {"old": 1}       # untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]   # no temporary left


def test_a_result_folder_on_a_full_disk(tmp_path, monkeypatch):
    monkeypatch.setattr(Path, "mkdir", _enospc)
    with pytest.raises(DiskFull, match=r"x: cannot create the result folder: no space left on "
                                       r"device$"):
        kio.ResultFolder(tmp_path / "x")


def test_a_full_disk_in_a_command_is_one_line(tmp_path, monkeypatch, main, capsys):
    scene = _scene(tmp_path, "A.toml", 1)
    real = os.fsync
    calls = [0]

    def fsync(fd):                        # the disk fills up after a few files
        calls[0] += 1
        if calls[0] > 3:
            _enospc()
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    assert main(["run", str(scene), "--out", str(tmp_path / "R"), "--no-progress",
                 "--no-figures"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("kinred: error: DiskFull: ") and "no space left on device" in err
    assert not (tmp_path / "R" / LOCK_NAME).exists()          # released however it ends
    release_all()


# ------------------------------------------------ kinred certify after kinred run (item 13)
def _counting(monkeypatch):
    from kinred.experiments import kinetic_run

    calls = []
    for name in ("_solve_stage", "_k_stage"):
        real = getattr(kinetic_run, name)

        def wrapped(*args, _real=real, _name=name, **kwargs):
            calls.append(_name)
            return _real(*args, **kwargs)

        monkeypatch.setattr(kinetic_run, name, wrapped)
    return calls


def test_certify_reuses_the_stages_of_kinred_run(tmp_path, monkeypatch, capsys, clean_run):
    monkeypatch.chdir(tmp_path)
    scene = _scene(tmp_path, "s.toml", 1)
    # `kinred run s.toml` → results/run-s (a copy of that run in a fresh folder)
    shutil.copytree(clean_run("s.toml", 1), tmp_path / "results" / "run-s")
    run_numbers = _numbers(tmp_path / "results" / "run-s")
    calls = _counting(monkeypatch)
    capsys.readouterr()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert cli.main(["certify", str(scene), "--no-figures"]) == 0  # → results/certify-s
    captured = capsys.readouterr()
    assert calls == []                                             # nothing recomputed
    summary = json.loads((tmp_path / "results" / "certify-s" / "summary.json").read_text())
    assert summary["stages"] == {"solve": "shared", "k1": "shared", "k2": "shared"}
    assert "stages: solve: shared, k1: shared, k2: shared (shared: taken from `kinred run` in " \
           "results/run-s" in captured.out
    # its progress bar is its own
    assert "kinred certify s.toml" in captured.err and "kinred run" not in captured.err
    # the shared numbers are those certify computes by itself, bit for bit
    assert cli.main(["certify", str(scene), "--out", "alone", "--from-run", "nowhere",
                     "--no-progress", "--no-figures"]) == 0
    assert calls == ["_solve_stage", "_k_stage", "_k_stage"]
    alone, shared = _numbers(tmp_path / "alone"), _numbers(tmp_path / "results" / "certify-s")
    assert alone.keys() == shared.keys() and "k2_cert_w1" in alone
    for key in alone:
        assert alone[key].tobytes() == shared[key].tobytes(), key
    assert run_numbers["k2_w1"].tobytes() == shared["k2_w1"].tobytes()
    # a run of another configuration (projection.seed) shares nothing
    shutil.copytree(clean_run("B.toml", 2), tmp_path / "other-run")   # `kinred run` of seed 2
    del calls[:]
    assert cli.main(["certify", str(scene), "--out", "c2", "--from-run", "other-run",
                     "--no-progress", "--no-figures"]) == 0
    assert calls == ["_solve_stage", "_k_stage", "_k_stage"]
    summary = json.loads((tmp_path / "c2" / "summary.json").read_text())
    assert set(summary["stages"].values()) == {"computed"}
