"""kinred.scenefile: one schema and one registry for scene files (issue 15), the
[dynamics.pairsum] table (issue 17), the [certify] table (issue 16), and the loader's
validation of every key (type, range, finiteness, unknown keys, wrong table types)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import kinred.cli as cli
from kinred import scenefile
from kinred.errors import ConfigError, InvalidInput
from kinred.scenefile import (EFFECTS, PAIRSUMS, REQUIRED, SMALL_SCENE, TABLES, Key,
                              config_from_dict, load_config, register_effect, register_pairsum,
                              unregister_effect, unregister_pairsum)

ROOT = Path(__file__).resolve().parents[1]

BASE = """
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
params = {loc = -1.0, scale = 2.0}
repeat = 2
[quantize]
atoms = 9
reference_atoms = 16
[projection]
k = [1, 2]
[integrate]
dt = 0.1
t_final = 0.5
save_every = 1
"""


@pytest.fixture
def main(monkeypatch):
    if "kinred.commands.run" not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("kinred.commands.run",))
    return cli.main


def _arrays(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files if not k.endswith("_time")}   # timings differ


def _run(main, tmp_path, text, name, *extra):
    """``kinred run`` of the scene ``text`` into ``tmp_path/name``; figures are not drawn
    (this module checks numbers; test_run_cli.py and test_report_kinetic.py the figures)."""
    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    out = tmp_path / name
    assert main(["run", str(scene), "--out", str(out), "--no-figures", *extra]) == 0
    return out


# ------------------------------------------------------------------------------------------
# adding an effect type is one registry entry
# ------------------------------------------------------------------------------------------
@pytest.fixture
def friction():
    # a new table type mapped onto the engine's effects: dv/dt = -gamma v (SelfPropulsion with
    # a = -gamma, b = 0), built by the entry's builder from the table's keys
    from kinred.dynamics import SelfPropulsion

    entry = register_effect("linear_friction", lambda p, d: SelfPropulsion(-p["gamma"], 0.0), keys=(
        Key("gamma", "number", REQUIRED, "friction rate", low=0.0),
        Key("label", "string", "toy", "a name"),
    ), doc="toy linear friction")
    yield entry
    unregister_effect("linear_friction")
    assert "linear_friction" not in EFFECTS


TOY = BASE.replace('type = "alignment"\nG = 1.0\nbeta = 0.5', 'type = "linear_friction"\ngamma = 0.5')


def test_registered_effect_type_is_loaded_simulated_and_documented(friction, tmp_path, main):
    cfg = config_from_dict(__import__("tomllib").loads(TOY), source="toy.toml")
    assert cfg.effects == (("linear_friction", {"gamma": 0.5}),)      # as given: digest stable
    (effect,) = cfg.scene().effects
    assert (effect.a, effect.b) == (-0.5, 0.0)
    out = _run(main, tmp_path, TOY, "toy")
    res = _arrays(out / "results.npz")
    # Euler: v_n = (1 - gamma dt)^n v_0 for every agent, so Gamma(t_n) = (1 - gamma dt)^(2n) Gamma(0)
    n = np.round(res["t"] / 0.1)
    g = res["gamma_high"]
    np.testing.assert_allclose(g / g[0], (1 - 0.5 * 0.1) ** (2 * n), rtol=1e-12)
    for k in (1, 2):        # the reduced system is exactly M applied to the linear flow
        assert np.max(res[f"k{k}_w1"]) < 1e-12
        np.testing.assert_allclose(res[f"k{k}_gamma"] / res[f"k{k}_gamma"][0],
                                   (1 - 0.5 * 0.1) ** (2 * n), rtol=1e-12)
    # its keys are checked from the registry entry, and the reference lists them
    with pytest.raises(ConfigError, match=r"toy\.toml: dynamics\.effect\[0\]\.gamma: must be >= 0, "
                                          r"got -1\.0$"):
        config_from_dict(__import__("tomllib").loads(TOY.replace("0.5\n[init", "-1.0\n[init")),
                         source="toy.toml")
    with pytest.raises(ConfigError, match=r"dynamics\.effect\[0\]\.G: unknown key for type "
                                          r"'linear_friction'; valid keys are gamma, label$"):
        config_from_dict(__import__("tomllib").loads(TOY.replace("gamma = 0.5", "gamma = 0.5\nG = 1")),
                         source="toy.toml")
    ref = scenefile.reference_markdown()
    assert '`type = "linear_friction"`: toy linear friction.' in ref
    assert "| `gamma` | number | required | >= 0 | friction rate |" in ref


def test_registry_validation(friction):
    with pytest.raises(InvalidInput, match="already registered"):
        register_effect("linear_friction", lambda p, d: None)
    with pytest.raises(InvalidInput, match="lower-case identifier"):
        register_effect("Bad Name", lambda p, d: None)
    with pytest.raises(InvalidInput, match="build must be callable"):
        register_effect("x1", 3)
    with pytest.raises(InvalidInput, match="distinct names other than 'type'"):
        register_effect("x2", lambda p, d: None, keys=(Key("type", "string"),))
    with pytest.raises(InvalidInput, match="tuple of kinred.scenefile.Key"):
        register_effect("x3", lambda p, d: None, keys=[Key("a", "number")])
    with pytest.raises(InvalidInput, match="built-in effect type"):
        unregister_effect("alignment")
    with pytest.raises(InvalidInput, match="built-in pair-sum method"):
        unregister_pairsum("dense")
    with pytest.raises(InvalidInput, match="type must be one of"):
        Key("a", "float")
    assert "x1" not in EFFECTS and "x2" not in EFFECTS and "x3" not in EFFECTS


# ------------------------------------------------------------------------------------------
# [dynamics.pairsum] (issue 17)
# ------------------------------------------------------------------------------------------
def test_pairsum_table_builds_the_backends():
    from kinred.pairsum import Numpy, RandomBatch

    def cfg(table, precision="double"):
        dyn = {**SMALL_SCENE["dynamics"], "precision": precision}
        if table is not None:
            dyn["pairsum"] = table
        return config_from_dict({**SMALL_SCENE, "dynamics": dyn})

    assert repr(cfg(None).pair_sum()) == "Dense()" and cfg(None).pairsum is None
    assert repr(cfg({"method": "dense", "block": 64}, "mixed").scene().pairsum) == \
        "Dense(block=64, precision='mixed')"
    assert isinstance(cfg({"method": "numpy"}).scene().pairsum, Numpy)
    rb = cfg({"method": "random_batch", "p": 3}).scene().pairsum
    assert isinstance(rb, RandomBatch) and rb.p == 3
    assert cfg({"method": "random_batch"}).scene().pairsum.p == 2          # the key's default
    assert cfg({"method": "nufft", "tol": 1e-8}).scene().pairsum.tol == 1e-8
    assert tuple(PAIRSUMS) == ("dense", "numpy", "random_batch", "nufft", "cells", "auto")
    assert cfg({"method": "cells", "tol": 1e-8}).scene().pairsum.tol == 1e-8
    assert repr(cfg({"method": "auto"}).scene().pairsum) == "Auto(tol=1e-06)"
    # a scene without the table keeps its digest (old result folders resume); with it, it changes
    assert cfg(None).digest() == config_from_dict(SMALL_SCENE).digest()
    assert "pairsum" not in cfg(None).to_json()
    assert cfg({"method": "dense"}).digest() != cfg(None).digest()
    for table, needle in [
        ({"method": "fmm", "tol": 1e-6}, r"dynamics\.pairsum\.method: unknown pair-sum method "
                                         r"'fmm'; valid: dense, numpy, random_batch, nufft, cells, "
                                         r"auto"),
        ({"p": 2}, r"dynamics\.pairsum\.method: missing \(one of dense, numpy, random_batch, "
                   r"nufft, cells, auto\)"),
        ({"method": "nufft", "tol": 1.0}, r"dynamics\.pairsum\.tol: must be in \(0, 1\), got 1\.0"),
        ({"method": "random_batch", "p": 1}, r"dynamics\.pairsum\.p: must be >= 2, got 1"),
        ({"method": "random_batch", "p": 2.5}, r"dynamics\.pairsum\.p: must be an integer, got 2\.5"),
        ({"method": "numpy", "p": 2}, r"dynamics\.pairsum\.p: unknown key for method 'numpy'; "
                                      r"valid keys are \(none\)"),
        ("dense", r"dynamics\.pairsum: must be a table, got 'dense'"),
    ]:
        with pytest.raises(ConfigError, match="^<scene>: " + needle + "$"):
            cfg(table)
    with pytest.raises(ConfigError, match=r"dynamics\.precision: 'mixed' is an option of the "
                                          r"pair-sum methods dense; dynamics\.pairsum\.method = "
                                          r"'random_batch' computes in double"):
        cfg({"method": "random_batch"}, "mixed")


def test_registered_pairsum_method_is_one_entry(tmp_path, main):
    from kinred.pairsum import Numpy

    register_pairsum("twin_copy", Numpy, doc="the numpy twin under another name")
    try:
        a = _run(main, tmp_path, BASE.replace("[quantize]", '[dynamics.pairsum]\nmethod = '
                                              '"twin_copy"\n[quantize]'), "copy")
        assert '`method = "twin_copy"`' in scenefile.reference_markdown()
    finally:
        unregister_pairsum("twin_copy")
    b = _run(main, tmp_path, BASE.replace("[quantize]", '[dynamics.pairsum]\nmethod = "numpy"\n'
                                          "[quantize]"), "numpy")
    ra, rb = _arrays(a / "results.npz"), _arrays(b / "results.npz")
    assert ra.keys() == rb.keys()
    for key in ra:
        assert ra[key].tobytes() == rb[key].tobytes(), key


def test_random_batch_scene_is_reproducible_and_resumes_bit_identically(tmp_path, main):
    rb = BASE.replace("[quantize]", '[dynamics.pairsum]\nmethod = "random_batch"\np = 3\n'
                                    "[quantize]")
    one = _run(main, tmp_path, "seed = 5\n" + rb, "one")
    two = _run(main, tmp_path, "seed = 5\n" + rb, "two")
    other = _run(main, tmp_path, "seed = 6\n" + rb, "other")
    a, b, c = (_arrays(p / "results.npz") for p in (one, two, other))
    for key in a:
        assert a[key].tobytes() == b[key].tobytes(), key
    assert not np.array_equal(a["gamma_high"], c["gamma_high"])          # the seed draws batches
    # a k stage recomputed from the loaded solve stage equals the one computed after solving
    (one / "stages" / "k2.npz").unlink()
    assert main(["run", str(tmp_path / "one.toml"), "--out", str(one), "--resume",
                 "--no-figures"]) == 0
    summary = json.loads((one / "summary.json").read_text())
    assert summary["stages"] == {"solve": "loaded", "reference": "loaded", "k1": "loaded",
                                 "k2": "computed"}
    again = _arrays(one / "results.npz")
    for key in a:
        assert a[key].tobytes() == again[key].tobytes(), key


# ------------------------------------------------------------------------------------------
# [certify] (issue 16): carried by the Config (the pipeline: tests/test_kinetic_certify.py)
# ------------------------------------------------------------------------------------------
def test_certify_table_is_carried_by_the_config():
    plain = config_from_dict(SMALL_SCENE)
    assert plain.certify == scenefile.CertifyOptions(enabled=None, norm="both", paper=True)
    assert "certify" not in plain.to_json()
    cfg = config_from_dict({**SMALL_SCENE, "certify": {"enabled": True, "norm": "rms",
                                                       "paper": False}})
    assert cfg.certify == scenefile.CertifyOptions(True, "rms", False)
    assert cfg.to_json()["certify"] == {"enabled": True, "norm": "rms", "paper": False}
    assert cfg.digest() != plain.digest()
    # absent (auto) and false certify differently: different digests; defaults spelled out: same
    off = config_from_dict({**SMALL_SCENE, "certify": {"enabled": False, "norm": "max"}})
    assert off.digest() != plain.digest()
    same = config_from_dict({**SMALL_SCENE, "certify": {"norm": "both", "paper": True}})
    assert same.digest() == plain.digest()
    for table, needle in [
        ({"enabled": "yes"}, r"certify\.enabled: must be true or false, got 'yes'"),
        ({"enabled": True, "norm": "l2"}, r"certify\.norm: must be one of rms, max, both, got 'l2'"),
        ({"enable": True}, r"certify\.enable: unknown key; valid keys are enabled, norm, paper"),
        (True, r"certify: must be a table, got True"),
    ]:
        with pytest.raises(ConfigError, match="^<scene>: " + needle + "$"):
            config_from_dict({**SMALL_SCENE, "certify": table})
    with pytest.raises(ConfigError, match=r"certify\.enabled: the certificate covers the forward "
                                          r"Euler scheme only; set integrate\.method = 'euler', "
                                          r"got 'rk4'"):
        config_from_dict({**SMALL_SCENE, "certify": {"enabled": True},
                          "integrate": {**SMALL_SCENE["integrate"], "method": "rk4"}})


def test_certify_enabled_runs_the_certificate(tmp_path):
    from kinred.experiments import kinetic_run

    cfg = config_from_dict({**SMALL_SCENE, "certify": {"enabled": True}}, source="c.toml")
    res = kinetic_run.run(cfg, progress=False)
    assert set(res.stages.values()) == {"computed"}
    for r in res.per_k.values():
        assert str(r["cert_note"]).startswith("certified")
        assert np.all(r["err_rms"] <= r["cert_rms"]) and np.all(r["w1"] <= r["cert_w1"])


# ------------------------------------------------------------------------------------------
# validation: every key, one line naming the file, the key, the value and what is valid
# ------------------------------------------------------------------------------------------
def _with(section, **values):
    """SMALL_SCENE with ``values`` set in table ``section`` (``""``: the top level)."""
    data = json.loads(json.dumps(SMALL_SCENE))
    table = data if not section else data.setdefault(section, {})
    table.update(values)
    return data


@pytest.mark.parametrize("data, needle", [
    (_with("", seed=-1), r"seed: must be >= 0, got -1"),
    (_with("", title=3), r"title: must be a string, got 3"),
    (_with("", dynamics=[1]), r"dynamics: must be a table, got \[1\]"),
    (_with("", output=1.0), r"output: must be a table, got 1\.0"),
    ({**SMALL_SCENE, 3: 1}, r"3: unknown key; valid keys are certify, description, .*"),
    ({**SMALL_SCENE, "a b\nc": 1}, r'"a b\\nc": unknown key; valid keys are .*'),
    (_with("dynamics", d=0), r"dynamics\.d: must be >= 1, got 0"),
    (_with("dynamics", d=True), r"dynamics\.d: must be an integer, got True"),
    (_with("dynamics", d=2.0), r"dynamics\.d: must be an integer, got 2\.0"),
    (_with("dynamics", effect=[]), r"dynamics\.effect: must be a non-empty array of tables, got \[\]"),
    (_with("dynamics", effect={"type": "free"}), r"dynamics\.effect: must be an array of tables, got"
                                                  r" \{'type': 'free'\}"),
    (_with("dynamics", effect=[3]), r"dynamics\.effect\[0\]: must be a table, got 3"),
    (_with("dynamics", effect=[{"G": 1.0}]), r"dynamics\.effect\[0\]\.type: missing \(one of "
                                             r"alignment, morse, self_propulsion, free\)"),
    (_with("dynamics", effect=[{"type": ["alignment"]}]),
     r"dynamics\.effect\[0\]\.type: unknown effect \['alignment'\]; valid: alignment, morse, "
     r"self_propulsion, free"),
    (_with("dynamics", effect=[{"type": "alignment", "G": -1.0, "beta": 0.5}]),
     r"dynamics\.effect\[0\]\.G: must be >= 0, got -1\.0"),
    (_with("dynamics", effect=[{"type": "alignment", "G": 1.0, "beta": float("nan")}]),
     r"dynamics\.effect\[0\]\.beta: must be finite, got nan"),
    (_with("dynamics", effect=[{"type": "alignment", "G": 10**400, "beta": 0.5}]),
     r"dynamics\.effect\[0\]\.G: must be finite, got inf"),
    (_with("dynamics", effect=[{"type": "alignment", "G": 1.0, "beta": 0.5, "on": "y"}]),
     r"dynamics\.effect\[0\]\.on: must be 'x' or 'v', got 'y'"),
    (_with("dynamics", effect=[{"type": "morse", "Ca": 1.0, "la": 0.0, "Cr": 1.0, "lr": 1.0}]),
     r"dynamics\.effect\[0\]\.la: must be > 0, got 0\.0"),
    (_with("dynamics", effect=[{"type": "morse", "Ca": 1.0, "la": 1.0, "Cr": 1.0}]),
     r"dynamics\.effect\[0\]\.lr: missing \(required for type 'morse', a number\)"),
    (_with("dynamics", effect=[{"type": "free", "G": 1.0}]),
     r"dynamics\.effect\[0\]\.G: unknown key for type 'free'; valid keys are \(none\)"),
    (_with("dynamics", precision="single"), r"dynamics\.precision: must be 'double' or 'mixed', "
                                            r"got 'single'"),
    (_with("quantize", atoms=None), r"quantize\.atoms: must be an integer, got None"),
    (_with("quantize", eps=-0.5), r"quantize\.eps: must be > 0, got -0\.5"),
    (_with("quantize", atoms=0), r"quantize\.atoms: must be >= 1, got 0"),
    (_with("quantize", max_atoms=float("inf")), r"quantize\.max_atoms: must be an integer, got inf"),
    (_with("quantize", rule="Paper"), r"quantize\.rule: must be 'midpoint' or 'paper', got 'Paper'"),
    (_with("projection", k=[1, 7]), r"projection\.k: must be a non-empty array of integers in "
                                    r"\[1, dynamics\.d = 3\], got \[1, 7\]"),
    (_with("projection", k=[]), r"projection\.k: must be a non-empty array of integers, got \[\]"),
    (_with("projection", k=[1, True]), r"projection\.k: must be an array of integers, got \[1, True\]"),
    (_with("projection", k=2), r"projection\.k: must be an array of integers, got 2"),
    (_with("projection", seed=-3), r"projection\.seed: must be >= 0, got -3"),
    (_with("projection", kind="normal"), r"projection\.kind: must be one of gaussian, rademacher, "
                                         r"achlioptas, srht, dct, got 'normal'"),
    (_with("integrate", dt=0.0), r"integrate\.dt: must be > 0, got 0\.0"),
    (_with("integrate", t_final=-1), r"integrate\.t_final: must be > 0, got -1\.0"),
    (_with("integrate", t_final=1.05), r"integrate\.t_final: must be a multiple of dt=0\.1, got 1\.05"),
    (_with("integrate", t_final=1e300, dt=1e-300), r"integrate\.dt: t_final/dt = inf steps, more "
                                                   r"than 2\*\*53 .*"),
    (_with("integrate", save_every=0), r"integrate\.save_every: must be >= 1, got 0"),
    (_with("integrate", method=1), r"integrate\.method: must be a string, got 1"),
    (_with("output", yes_below=1.0, no_above=0.1), r"output\.yes_below: need 0 <= yes_below <= "
                                                   r"no_above, got 1\.0, 0\.1"),
    (_with("output", no_above=-1.0), r"output\.no_above: must be >= 0, got -1\.0"),
    (_with("initial", lift_seed=-1), r"initial\.lift_seed: must be >= 0, got -1"),
    (_with("initial", lift_to=5), r"initial\.lift_to: must equal dynamics\.d = 3, got 5"),
    (_with("initial", phase={}), r"initial\.phase: give either initial\.phase .* or both .*"),
    (_with("smoke", colour=1), r"smoke\.colour: unknown key; valid keys are atoms, dt, k, "
                               r"reference_atoms, save_every, t_final"),
    (_with("smoke", k=[0]), r"smoke\.k: must be a non-empty array of integers in \[1, dynamics\.d "
                            r"= 3\], got \[0\]"),
])
def test_every_key_is_validated(data, needle):
    smoke = "smoke" in data
    with pytest.raises(ConfigError) as ei:
        config_from_dict(data, source="s.toml", smoke=smoke)
    msg = str(ei.value)
    assert "\n" not in msg
    assert re.match("s\\.toml: " + needle + "$", msg), msg


def test_lift_that_cannot_embed_is_a_config_error():
    # was a raw InvalidInput "d must be >= 5, got 3" naming no file or key
    data = _with("initial", lift_to=3)
    for part in ("positions", "velocities"):
        data["initial"][part]["coordinate"][0]["repeat"] = 5
    with pytest.raises(ConfigError, match=r"^s\.toml: initial\.lift_to: d must be >= 5, got 3$"):
        config_from_dict(data, source="s.toml").initial_measure()


def test_smoke_values_are_named_as_smoke_keys():
    data = _with("smoke", t_final=1.05, k=[1])
    with pytest.raises(ConfigError, match=r"^s\.toml: smoke\.t_final: must be a multiple of dt=0\.1, "
                                          r"got 1\.05$"):
        config_from_dict(data, source="s.toml", smoke=True)
    assert config_from_dict(data, source="s.toml").t_final == 1.0        # not applied without --smoke
    cfg = config_from_dict(_with("smoke", atoms=4, k=[3]), smoke=True)
    assert cfg.atoms == 4 and cfg.ks == (3,) and cfg.smoke


def test_the_loader_reads_the_schema():
    # every key of every table is in TABLES and nothing else is accepted
    for name, keys in TABLES.items():
        assert all(isinstance(k, Key) for k in keys) and len({k.name for k in keys}) == len(keys)
    top = {k.name for k in TABLES[""]}
    assert {n for n in TABLES if n} <= top
    # the method list is the integrate registry's (deterministic ones)
    from kinred.integrate import SOLVERS

    method = next(k for k in TABLES["integrate"] if k.name == "method")
    assert method.valid_choices() == tuple(m for m, s in SOLVERS.items() if not s.stochastic)
    # defaults of absent keys come from the schema
    cfg = config_from_dict(SMALL_SCENE)
    assert (cfg.rule, cfg.kind, cfg.method, cfg.max_atoms, cfg.yes_below, cfg.no_above,
            cfg.precision, cfg.seed, cfg.projection_seed) == \
        ("midpoint", "gaussian", "euler", 200000, 1e-10, 1e-3, "double", 0, 0)


def test_shipped_scenes_keep_their_digest():
    # the digests recorded in result folders before the schema moved to kinred.scenefile
    # (stages/config.json): old folders must still resume
    digests = {p.stem: load_config(p).digest()
               for p in sorted((ROOT / "examples" / "scenes").glob("*.toml"))}
    assert {k: v for k, v in digests.items() if k != "delayed-curse-1e6"} == {
        "cucker-smale-200": "cc05cffd2d933ca136bc2b4c146275b66467dfbe41c8af05472e8985b5262d04",
        "delayed-curse": "0efc59096edc170b580acf7f1e0d9badf45621c2da89cc5efbdd3ec9c02a7669",
        "dorsogna-mill-2d": "e26d232b498d63d0a9206229a71d998f61d666d4dbfd8441f04ea2eb85f02c4f",
        "dorsogna-mill-lift-200": "3233c4b05e41a09ed2fc0574faf16e7f3cfd1e9a568a8543e768f1af455777e0",
    }


# ------------------------------------------------------------------------------------------
# the reference page is generated from the registry
# ------------------------------------------------------------------------------------------
def test_scene_file_page_holds_the_current_reference():
    page = (ROOT / "docs" / "scene-file.md").read_text(encoding="utf-8")
    head, sep, rest = page.partition(scenefile.BEGIN)
    body, sep2, _ = rest.partition(scenefile.END)
    assert sep and sep2, "docs/scene-file.md lost its generated-reference markers"
    assert body == "\n" + scenefile.reference_markdown(), (
        "docs/scene-file.md is out of date: run `python -m kinred.scenefile docs/scene-file.md`")
    for name in EFFECTS:
        assert f'`type = "{name}"`' in body
    for name in PAIRSUMS:
        assert f'`method = "{name}"`' in body
    for table, keys in TABLES.items():
        for key in keys:
            assert f"| `{key.name}` |" in body, (table, key.name)


@pytest.mark.parametrize("table", [
    {"dist": "beta", "params": {"a": 2.0, "b": 3.0, "loc": -0.5, "scale": 2.0}, "repeat": 6,
     "decay": 0.8, "support": [-0.4, 1.2]},
    {"dist": "uniform", "params": {"a": -1.0, "b": 1.0}, "repeat": 4, "decay": 1.0},
    {"dist": "norm", "params": {"loc": 0.25, "scale": 0.5}, "repeat": 5, "decay": 1.5,
     "support": [-1.0, 2.0]},
], ids=["beta", "uniform", "norm"])
def test_repeated_coordinates_are_the_laws_frozen_one_by_one(table):
    # the copies of a [[coordinate]] table share one frozen scipy law's generator (freezing
    # 400 laws took most of a second): each copy is the law frozen afresh, decay**r·X
    from scipy import stats

    from kinred.measures import Univariate, measure_from_dict

    coords = measure_from_dict({"coordinate": [table]}).factors
    gen, p = getattr(stats, table["dist"]), dict(table["params"])
    if table["dist"] == "uniform":
        p = {"loc": p["a"], "scale": p["b"] - p["a"]}
    loc, scale = p.pop("loc", 0.0), p.pop("scale", 1.0)
    u = np.linspace(0.0, 1.0, 41)
    assert len(coords) == table["repeat"]
    for r, c in enumerate(coords):
        f = table["decay"] ** r
        sup = table.get("support")
        fresh = Univariate(gen(**p, loc=loc * f, scale=scale * f),
                           support=None if sup is None else (sup[0] * f, sup[1] * f))
        x = fresh.ppf(u)
        assert np.array_equal(c.ppf(u), x) and np.array_equal(c.cdf(x), fresh.cdf(x)), r
        assert c.support == fresh.support and c.dist.support() == fresh.dist.support()
        assert (c.dist.mean(), c.dist.std()) == (fresh.dist.mean(), fresh.dist.std())
    assert len({id(c.dist) for c in coords}) == table["repeat"]    # each copy its own law


def test_mixture_accuracy_is_the_bisection_over_every_component():
    # _mixture_eps counts equal-shape tensor components once per ε; the accuracy it finds is
    # the plain bisection's, which plans every component (clouds of two shapes, one of them
    # twice as the mill scenes' four equal clouds)
    import math

    from kinred.measures import Dirac, Mixture, TensorProduct, Uniform
    from kinred.quantize import _planning as pl

    def plain_eps(mu, atoms, rule="midpoint", node_limit=500):
        def count(e):
            return sum(pl._plan(m, e, None, rule, node_limit).n_atoms for m in mu.components)
        hi = pl._coarsest_eps(mu, rule)
        lo = hi * 1e-12
        if count(lo) <= atoms:
            return lo
        for _ in range(60):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if count(mid) <= atoms else (mid, hi)
        return hi

    def cloud(*widths, dirac=False):
        return TensorProduct([Uniform(0.0, w) for w in widths] + ([Dirac(0.5)] if dirac else []))

    mu = Mixture([cloud(1.0, 2.0), cloud(3.0, 1.0), cloud(1.0, 2.0)],
                 [0.3, 0.3, 0.4])
    assert pl._mixture_eps(mu, 50, "midpoint", 500) == plain_eps(mu, 50)
