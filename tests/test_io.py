"""Tests of kinred.io: atomic writes, result folders and the stage store."""

from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest

from kinred.errors import ConfigError, DamagedFile, InvalidInput, KinredWarning, StoreMismatch
from kinred.io import (
    ResultFolder,
    StageStore,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_npz,
    atomic_write_text,
    read_json,
    read_npz,
    read_text,
    read_toml,
)


def _names(d):
    return sorted(p.name for p in d.iterdir() if p.name != ".kinred.lock")  # (an open store's)


def test_roundtrips(tmp_path):
    atomic_write_bytes(tmp_path / "a.bin", b"\x00\x01")
    atomic_write_text(tmp_path / "sub" / "t.txt", "héllo")
    atomic_write_json(tmp_path / "j.json", {"x": np.float64(0.1), "n": np.int64(3), "v": np.arange(2),
                                            "inf": math.inf})
    atomic_write_npz(tmp_path / "z.npz", {"a": np.arange(6.0).reshape(2, 3)}, s=np.array("text"))
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "sub" / "t.txt").read_text(encoding="utf-8") == "héllo"
    j = read_json(tmp_path / "j.json")
    assert j == {"x": 0.1, "n": 3, "v": [0, 1], "inf": math.inf}
    z = read_npz(tmp_path / "z.npz")
    assert np.array_equal(z["a"], np.arange(6.0).reshape(2, 3)) and str(z["s"]) == "text"
    # no temporary files left behind
    assert _names(tmp_path) == ["a.bin", "j.json", "sub", "z.npz"]


def test_float_bits_survive_json(tmp_path):
    vals = np.random.default_rng(0).standard_normal(50)
    atomic_write_json(tmp_path / "f.json", {"v": vals})
    back = np.array(read_json(tmp_path / "f.json")["v"])
    assert back.tobytes() == vals.tobytes()


def test_permissions_follow_umask(tmp_path):
    p = atomic_write_bytes(tmp_path / "perm.bin", b"x")
    umask = os.umask(0)
    os.umask(umask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~umask)


class _Boom:
    """Array-like whose conversion fails: raised in the middle of writing an npz."""

    def __array__(self, dtype=None, copy=None):
        raise RuntimeError("boom while writing")


def test_failure_leaves_no_partial_file(tmp_path):
    target = tmp_path / "res.npz"
    with pytest.raises(RuntimeError, match="boom"):
        atomic_write_npz(target, {"a": np.ones(1000), "b": _Boom()})
    assert _names(tmp_path) == []          # neither the target nor a temp file

    # an existing file is left untouched by a failed overwrite
    atomic_write_npz(target, {"a": np.arange(3)})
    before = target.read_bytes()
    with pytest.raises(RuntimeError):
        atomic_write_npz(target, {"a": np.zeros(5), "b": _Boom()})
    assert target.read_bytes() == before and _names(tmp_path) == ["res.npz"]

    # same for JSON that cannot be serialized, and for an interrupt inside the writer
    with pytest.raises(InvalidInput):
        atomic_write_json(tmp_path / "x.json", {"f": object()})
    import kinred.io as kio

    def interrupted(fh):
        fh.write(b"partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        kio._atomic_write(tmp_path / "y.bin", interrupted)
    assert _names(tmp_path) == ["res.npz"]


def test_npz_rejects_object_arrays_and_bad_names(tmp_path):
    with pytest.raises(InvalidInput, match="object"):
        atomic_write_npz(tmp_path / "o.npz", {"a": np.array([{}, 1], dtype=object)})
    with pytest.raises(InvalidInput, match="names"):
        atomic_write_npz(tmp_path / "o.npz", {"a/b": np.ones(1)})
    with pytest.raises(InvalidInput, match="twice"):
        atomic_write_npz(tmp_path / "o.npz", {"a": 1}, a=2)
    assert _names(tmp_path) == []
    with pytest.raises(InvalidInput):
        atomic_write_bytes(tmp_path / "s.bin", "not bytes")
    with pytest.raises(InvalidInput):
        atomic_write_bytes(123, b"x")


def test_result_folder(tmp_path):
    rf = ResultFolder(tmp_path / "run")
    rf.write_json("config.json", {"N": 3})
    rf.write_npz("data/x.npz", x=np.arange(3))
    png = b"\x89PNG\r\n\x1a\n" + bytes(10)
    rf.write_bytes("figs/f.png", png)
    rf.write_text("notes.txt", "ok")
    assert rf.list() == ["config.json", "data/x.npz", "figs/f.png", "notes.txt"]
    assert rf.list("figs") == ["figs/f.png"] and rf.list("missing") == []
    assert not rf.is_complete
    assert rf.read_bytes("figs/f.png") == png and rf.read_text("notes.txt") == "ok"
    assert rf.read_json("config.json") == {"N": 3} and rf.exists("data/x.npz")
    assert np.array_equal(rf.read_npz("data/x.npz")["x"], np.arange(3))
    rf.mark_complete({"done": True})
    assert rf.is_complete and rf.read_json("summary.json") == {"done": True}
    # a stale temp file from a hard-killed writer is hidden and can be cleaned
    (rf.path / "data" / ".x.npz.abc123.tmp").write_bytes(b"half")
    assert "data/.x.npz.abc123.tmp" not in rf.list()
    assert rf.clean_temporary() == 1 and rf.clean_temporary() == 0
    # reopening an existing folder works
    assert ResultFolder(rf.path).is_complete


def test_result_folder_validation(tmp_path):
    rf = ResultFolder(tmp_path)
    for bad in ["", "../escape.json", "/abs.json", "a/../../b"]:
        with pytest.raises(InvalidInput):
            rf.write_json(bad, {})
    (tmp_path / "file").write_text("x")
    with pytest.raises(InvalidInput, match="directory"):
        ResultFolder(tmp_path / "file")
    with pytest.raises(InvalidInput):
        ResultFolder(None)


# -- hostile files: every read and write names the path and what is wrong ---------------------
def test_writing_onto_a_directory_or_under_a_file_is_refused(tmp_path):
    d = tmp_path / "adir"
    d.mkdir()
    (d / "keep.txt").write_text("x")
    for write in (lambda p: atomic_write_bytes(p, b"x"), lambda p: atomic_write_npz(p, a=1),
                  lambda p: atomic_write_json(p, {})):
        with pytest.raises(InvalidInput, match=f"^{re.escape(str(d))}: is a directory; give the name"):
            write(d)
    assert _names(d) == ["keep.txt"]
    with pytest.raises(InvalidInput, match="^.*adir: is a directory"):
        ResultFolder(tmp_path).write_json("adir", {})
    (tmp_path / "f.txt").write_text("x")
    with pytest.raises(InvalidInput, match=r"f\.txt/x\.bin: cannot write the file: "):
        atomic_write_bytes(tmp_path / "f.txt" / "x.bin", b"x")
    assert _names(tmp_path) == ["adir", "f.txt"]


def test_reading_missing_files_and_directories(tmp_path):
    missing = tmp_path / "none.json"
    here = re.escape(str(tmp_path))
    with pytest.raises(InvalidInput, match=f"^{re.escape(str(missing))}: JSON file not found$"):
        read_json(missing)
    with pytest.raises(InvalidInput, match=f"^{here}: is a directory, not a stage file$"):
        read_npz(tmp_path, what="stage file")
    with pytest.raises(InvalidInput, match=f"^{here}: is a directory, not a JSON file$"):
        read_json(tmp_path)
    with pytest.raises(InvalidInput, match="not found"):
        read_npz(tmp_path / "none.npz")
    # TOML files (scenes, measures) report everything as ConfigError
    with pytest.raises(ConfigError, match=f"^{here}: is a directory, not a scene file$"):
        read_toml(tmp_path, what="scene file")


def test_reading_damaged_text_and_json(tmp_path):
    p = tmp_path / "t.json"
    p.write_bytes(b'{"a":\n "\xc3("}')
    with pytest.raises(DamagedFile, match=r"t\.json: not UTF-8 text: byte 0xc3 at offset 8 "
                                          r"\(line 2\); a JSON file must be UTF-8") as ei:
        read_json(p)
    assert ei.value.path == str(p)
    with pytest.raises(DamagedFile, match="offset 8"):
        read_text(p)
    with pytest.raises(ConfigError, match="not UTF-8 text: byte 0xc3"):
        read_toml(p)
    for content, needle in [(b"", r"empty \(0 bytes\)"), (b" \n", r"empty \(2 bytes\)"),
                            (b'{"digest": "ab',
                             r"not valid JSON \(Unterminated string .* line 1, column 12\)")]:
        p.write_bytes(content)
        with pytest.raises(DamagedFile, match=f"^{re.escape(str(p))}: damaged stage index: {needle}"):
            read_json(p, what="stage index")
    p.write_text("a = [1,")
    with pytest.raises(ConfigError, match="invalid TOML"):
        read_toml(p)


def test_reading_damaged_npz(tmp_path):
    good = atomic_write_npz(tmp_path / "g.npz", {"x": np.arange(2000.0), "n": 3})
    raw = good.read_bytes()
    bad = tmp_path / "b.npz"
    for cut in (0, 1, 10, 1000, len(raw) // 2, len(raw) - 1):
        bad.write_bytes(raw[:cut])
        with pytest.raises(DamagedFile, match=f"^{re.escape(str(bad))}: damaged stage file: "
                           r"truncated or not an \.npz archive \((EOFError|BadZipFile|ValueError): "):
            read_npz(bad, what="stage file")
    flipped = bytearray(raw)
    flipped[len(raw) // 3] ^= 0xFF                     # inside x's data: the CRC check fails
    bad.write_bytes(bytes(flipped))
    with pytest.raises(DamagedFile, match="Bad CRC-32"):
        read_npz(bad)
    np.save(tmp_path / "a.npy", np.arange(3))
    with pytest.raises(DamagedFile, match=r"a single \.npy array"):
        read_npz(tmp_path / "a.npy")
    assert np.array_equal(read_npz(good)["x"], np.arange(2000.0))


def test_read_npz_required_keys(tmp_path):
    p = atomic_write_npz(tmp_path / "s.npz", {"a": np.zeros(2)})
    assert list(read_npz(p, keys=("a",))) == ["a"]
    with pytest.raises(DamagedFile, match=r"s\.npz: damaged stage file: no array 'b'$") as ei:
        read_npz(p, what="stage file", keys=("a", "b"))
    assert ei.value.path == str(p)


# ----------------------------------------------------------------------------------------------
# StageStore
# ----------------------------------------------------------------------------------------------
def _counting(value):
    calls = []

    def compute():
        calls.append(1)
        return value

    return compute, calls


def test_stage_store_computes_once_and_resumes(tmp_path):
    store = StageStore(tmp_path / "st", "abc", describe={"config": {"n": 1}})
    assert read_json(tmp_path / "st" / "config.json") == {"digest": "abc", "config": {"n": 1}}
    compute, calls = _counting({"x": np.arange(3.0), "s": np.float64(0.5)})
    first = store.get_or_compute("solve", compute)
    assert calls == [1] and store.status == {"solve": "computed"}
    assert _names(tmp_path / "st") == ["config.json", "solve.npz"]
    again = StageStore(tmp_path / "st", "abc", resume=True, describe={"config": {"n": 1}})
    got = again.get_or_compute("solve", compute)
    assert calls == [1] and again.status == {"solve": "loaded"}
    assert got["x"].tobytes() == first["x"].tobytes() and float(got["s"]) == 0.5
    # nested names, custom formats
    again.get_or_compute("members/000001", lambda: "text",
                         save=lambda p, v: atomic_write_text(p, v), load=lambda p: read_text(p))
    assert (tmp_path / "st" / "members" / "000001.npz").read_text() == "text"
    assert StageStore(tmp_path / "st", "abc", resume=True).load(
        "members/000001", load=lambda p: read_text(p)) == "text"
    # no folder: every stage is computed, nothing is written
    mem = StageStore(None, "abc")
    mem.get_or_compute("solve", compute)
    mem.get_or_compute("solve", compute)
    assert calls == [1, 1, 1] and mem.folder is None and mem.path("solve") is None


def _same(a, b) -> bool:
    """Equal values of the same types, dtypes and shapes (dicts key by key)."""
    if isinstance(a, dict):
        return (isinstance(b, dict) and a.keys() == b.keys()
                and all(_same(a[k], b[k]) for k in a))
    if isinstance(a, np.ndarray):
        return (isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
                and a.tobytes() == b.tobytes())
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("folder", [True, False])
def test_stage_store_returns_on_a_first_run_what_a_resume_loads(tmp_path, folder):
    # issue 23 item 4: computed Python scalars, lists and str come back as the arrays a
    # resumed run loads, so code after a stage sees the same objects either way
    value = {"x": [1.0, 2.0], "s": 0.5, "n": 3, "flag": True, "note": "certified",
             "a": np.arange(4, dtype=np.float32)[::2]}
    path = tmp_path / "st"
    store = StageStore(path if folder else None, "abc")
    first = store.get_or_compute("k1", lambda: dict(value))
    assert store.status == {"k1": "computed"}
    store.close()
    disk = StageStore(tmp_path / "disk", "abc")
    disk.get_or_compute("k1", lambda: dict(value))
    disk.close()
    resumed = StageStore(tmp_path / "disk", "abc", resume=True)
    loaded = resumed.get_or_compute("k1", lambda: 1 / 0)
    assert resumed.status == {"k1": "loaded"}
    assert _same(first, loaded), (first, loaded)
    assert float(first["s"]) == 0.5 and first["a"].tolist() == [0.0, 2.0]
    assert str(first["note"]) == "certified" and int(first["n"]) == 3
    # a saver of its own format keeps its value (a text stage reads back as written)
    got = StageStore(None, "abc").get_or_compute(
        "t", lambda: "text", save=lambda p, v: atomic_write_text(p, v),
        load=lambda p: read_text(p))
    assert got == "text"


def test_stage_store_refusals(tmp_path):
    path = tmp_path / "st"
    StageStore(path, "a" * 64, describe={"config": {"dt": 0.1, "k": [1]}, "seed": 1})
    with pytest.raises(StoreMismatch) as ei:
        StageStore(path, "a" * 64)
    assert ei.value.reason == "resume" and ei.value.path == str(path)
    assert str(ei.value) == (f"stage store {path} already holds a run; continue it with "
                             "resume=True (--resume on the command line) or choose another folder")
    with pytest.raises(StoreMismatch) as ei:
        StageStore(path, "b" * 64, resume=True, describe={"config": {"dt": 0.2, "k": [1]},
                                                          "seed": 1})
    assert ei.value.reason == "different"
    assert str(ei.value) == (f"stage store {path} holds a run of a different configuration "
                             f"(config hash {'a' * 12}… != {'b' * 12}… of this run; differs: "
                             "config.dt); resume it with the same configuration or choose "
                             "another folder")
    # a folder holding other files and no index is not a store (stale stage files included)
    StageStore(path, "a" * 64, resume=True).get_or_compute("solve", lambda: {"x": np.ones(1)})
    (path / "config.json").unlink()
    for resume in (False, True):
        with pytest.raises(StoreMismatch, match=r"exists and is not a stage store \(no "
                                                r"config\.json\); choose a new or empty "
                                                r"directory") as ei:
            StageStore(path, "a" * 64, resume=resume)
        assert ei.value.reason == "foreign"
    (tmp_path / "afile").write_text("x")
    with pytest.raises(StoreMismatch, match="is not an ensemble store"):
        StageStore(tmp_path / "afile", "a", store_name="ensemble store")
    # an empty folder, or one holding only a killed writer's temporary file, is a new store
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / ".config.json.x1y2.tmp").write_bytes(b"half")
    StageStore(empty, "d")
    assert _names(empty) == ["config.json"]


@pytest.mark.parametrize("content", [b"", b'{"digest": "ab', b"\xff", b"[1]", b'{"digest": 3}'])
def test_stage_store_refuses_a_damaged_index(tmp_path, content):
    path = tmp_path / "st"
    StageStore(path, "d")
    (path / "config.json").write_bytes(content)
    with pytest.raises(DamagedFile) as ei:
        StageStore(path, "d", resume=True)
    msg = str(ei.value)
    assert msg.startswith(f"{path / 'config.json'}: ") and ei.value.path == str(path / "config.json")
    assert msg.endswith(f"; it ties the stage files to a run, so they cannot be resumed: delete "
                        f"the store, i.e. delete the folder {path} and run again, or run into "
                        "another output folder")


def test_stage_store_recomputes_damaged_stages(tmp_path):
    path = tmp_path / "st"
    store = StageStore(path, "d")
    for name in ("a", "b", "c"):
        store.get_or_compute(name, lambda: {"x": np.ones(4)})
    os.truncate(path / "a.npz", 10)
    (path / "b.npz").write_bytes(b"")
    again = StageStore(path, "d", resume=True)
    with pytest.warns(KinredWarning) as rec:
        a = again.get_or_compute("a", lambda: {"x": np.zeros(4)})
        b = again.get_or_compute("b", lambda: {"x": np.zeros(4)}, label="member 7")
        c = again.get_or_compute("c", lambda: {"x": np.zeros(4)},
                                 load=lambda p: read_npz(p, what="stage file", keys=("y",)))
    texts = [str(w.message) for w in rec]
    assert len(texts) == 3
    assert texts[0].startswith(f"{path / 'a.npz'}: damaged stage file: truncated or not an .npz")
    assert texts[0].endswith("; recomputing the stage")
    assert texts[1].endswith("; recomputing member 7")
    assert texts[2] == f"{path / 'c.npz'}: damaged stage file: no array 'y'; recomputing the stage"
    assert again.status == {"a": "computed", "b": "computed", "c": "computed"}
    assert not a["x"].any() and not b["x"].any() and not c["x"].any()
    assert not read_npz(path / "a.npz")["x"].any()              # rewritten


def test_stage_store_validation(tmp_path):
    for kwargs, needle in [
        (dict(folder=b"x", digest="d"), "folder must be a directory path"),
        (dict(folder=tmp_path, digest=""), "digest must be a non-empty str"),
        (dict(folder=tmp_path, digest="d", resume="yes"), "resume must be True or False"),
        (dict(folder=tmp_path, digest="d", describe=[1]), "describe must be a mapping"),
        (dict(folder=tmp_path, digest="d", index=3), "index must be a non-empty str"),
    ]:
        folder = kwargs.pop("folder")
        with pytest.raises(InvalidInput, match=needle):
            StageStore(folder, **kwargs)
    with pytest.raises(InvalidInput, match="name must be a non-empty str"):
        StageStore(None, "d").get_or_compute("", lambda: {})
    assert not any(tmp_path.iterdir())                   # nothing written by refused calls


# ----------------------------------------------------------------------------------------------
# One store, one error: ensembles, kinred run and the paper studies
# ----------------------------------------------------------------------------------------------
def _member(params, seed):
    return {"x": np.random.default_rng(seed).random(2)}


def test_every_store_refuses_the_same_way(tmp_path):
    from kinred.ensemble import run_ensemble
    from kinred.experiments import kinetic_run, table1
    from kinred.scenefile import SMALL_SCENE, config_from_dict

    def ensemble(path, seed, resume=False):
        run_ensemble(_member, [{"i": 0}], master_seed=seed, store=path, resume=resume,
                     progress=False)

    def kinetic(path, seed, resume=False):
        cfg = config_from_dict({**SMALL_SCENE, "projection": {"k": [1], "seed": seed}})
        kinetic_run.run(cfg, out_dir=path, resume=resume, progress=False, figures=False)

    def paper(path, seed, resume=False):
        cfg = table1.Table1Config.quick(N=8, d=4, n_projections=1, steps=10, record_every=10,
                                        ks=(2,), betas=(1.5,), seed=seed)
        table1.run(cfg, out_dir=path, executor="serial", resume=resume, progress=False)

    for run, sub, name in ((ensemble, "", "ensemble store"), (kinetic, "stages", "stage store"),
                           (paper, "store", "ensemble store")):
        out = tmp_path / run.__name__
        run(out, 1)
        store = out / sub if sub else out
        with pytest.raises(StoreMismatch) as ei:
            run(out, 1)
        assert ei.value.reason == "resume" and ei.value.path == str(store)
        assert str(ei.value) == (f"{name} {store} already holds a run; continue it with "
                                 "resume=True (--resume on the command line) or choose another "
                                 "folder")
        with pytest.raises(StoreMismatch) as ei:
            run(out, 2, resume=True)
        assert ei.value.reason == "different" and ei.value.path == str(store)
        assert re.fullmatch(rf"{re.escape(name)} {re.escape(str(store))} holds a run of a "
                            r"different configuration \(config hash [0-9a-f]{12}… != "
                            r"[0-9a-f]{12}… of this run; differs: [^)]*seed[^)]*\); resume it "
                            r"with the same configuration or choose another folder",
                            str(ei.value)), str(ei.value)
        run(out, 1, resume=True)
