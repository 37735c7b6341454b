"""The k stages of ``kinred run`` are typed (issue 23, item 4): :class:`KStage` fields carry
their labels, and a run hands on the same objects on a first run and on resume."""

import dataclasses
import json

import numpy as np
import pytest

from kinred.experiments import kinetic_certify, kinetic_run
from kinred.experiments.kinetic_run import LABELS, NOT_NUMBERS, KStage
from kinred.io import read_npz
from kinred.scenefile import SMALL_SCENE, config_from_dict

KINDS = {"measured", "certified bound", "a-priori bound", "estimate"}


@pytest.fixture(scope="module")
def scene():
    return config_from_dict({**SMALL_SCENE, "quantize": {"atoms": 30, "reference_atoms": 40}})


@pytest.fixture(scope="module")
def runs(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "out"
    memory = kinetic_run.run(scene)
    first = kinetic_run.run(scene, out_dir=out, figures=False)
    resumed = kinetic_run.run(scene, out_dir=out, resume=True, figures=False)
    return memory, first, resumed, out


def test_every_field_carries_its_label():
    names = [f.name for f in dataclasses.fields(KStage)]
    for name in names:
        label = KStage.label(name)
        assert (label in KINDS and LABELS[name] == label) or (label is None
                                                               and name in NOT_NUMBERS), name
    assert KStage.label("w1") == "measured" and KStage.label("cert_w1") == "certified bound"
    assert KStage.label("bound") == "a-priori bound" and KStage.label("term_jl") == \
        "a-priori bound"
    assert KStage.label("w1_reference") == "estimate" and KStage.label("k") is None
    # the certificate's arrays are the fields of its group; the stage file's are the fields
    assert kinetic_certify.CERT_KEYS == KStage.names("cert")
    assert KStage.keys_for(reference=True) == tuple(names)
    assert set(names) - set(KStage.keys_for(reference=False)) == {"w1_reference",
                                                                  "w1_quantization"}


def test_a_run_holds_kstages_equal_on_a_first_run_and_on_resume(runs, scene):
    memory, first, resumed, out = runs
    assert set(resumed.stages.values()) == {"loaded"}
    for k in scene.ks:
        stages = [r.per_k[k] for r in (memory, first, resumed)]
        assert all(isinstance(s, KStage) for s in stages)
        for name in KStage.names():
            a, b, c = (s[name] for s in stages)
            assert type(a) is type(b) is type(c) is np.ndarray, name
            assert a.dtype == b.dtype == c.dtype and a.shape == b.shape == c.shape, name
            if not name.endswith("_time") and name != "cert_note":   # timings differ
                assert a.tobytes() == b.tobytes() == c.tobytes(), name
        assert stages[1] == stages[2]
        assert int(stages[0].k) == k and stages[0]["k"] is stages[0].k
        # the stage file holds the fields, nothing else (besides the digest)
        held = set(read_npz(out / "stages" / f"k{k}.npz")) - {"__digest__"}
        assert held == set(KStage.names())


def test_the_mapping_view_and_the_labels_of_summary_json(runs):
    memory, first, _, out = runs
    stage = memory.per_k[1]
    assert "w1_reference" in stage and stage.get("nope") is None and len(stage) == len(
        KStage.names())
    plain = dataclasses.replace(stage, w1_reference=None, w1_quantization=None)
    assert "w1_reference" not in plain and len(plain) == len(stage) - 2
    with pytest.raises(KeyError):
        plain["w1_reference"]
    assert KStage.from_arrays(stage.arrays()) == stage and stage != plain
    summary = json.loads((out / "summary.json").read_text())
    names = {n for r in first.per_k.values() for n in r} | set(first.high)
    assert summary["labels"] == {n: LABELS[n] for n in sorted(names) if n not in NOT_NUMBERS}
