"""Tests of kinred.io: atomic writes and result folders."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from kinred.errors import InvalidInput
from kinred.io import (
    ResultFolder,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_npz,
    atomic_write_text,
    read_json,
    read_npz,
)


def _names(d):
    return sorted(p.name for p in d.iterdir())


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
