"""A scene-file key is written once (issue 23, item 3): :class:`Config` is derived from
``TABLES``, every key travels file -> Config -> ``to_json`` -> digest, the digests of older
scenes stay, and one pair-sum registry serves ``Scene(pairsum=...)`` and scene files."""

import dataclasses

import numpy as np
import pytest

import kinred.pairsum as pairsum
from kinred import scenefile
from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.errors import ConfigError, InvalidInput
from kinred.scenefile import (GROUPED, REQUIRED, SMALL_SCENE, TABLES, CertifyOptions, Config,
                              config_from_dict)
from kinred.scenefile._config import config_fields

#: Config attributes that are no key: the file, the parsed TOML, --smoke.
NOT_KEYS = {"source", "data", "smoke"}


def test_every_key_is_a_config_attribute_and_every_attribute_a_key():
    attrs = {f.name for f in dataclasses.fields(Config)}
    from_keys = {k.attribute for t, keys in TABLES.items() if t not in GROUPED
                 for k in keys if k.attribute is not None}
    assert attrs == from_keys | set(GROUPED) | NOT_KEYS
    assert [f.name for f in dataclasses.fields(CertifyOptions)] == [k.name for k in
                                                                     TABLES["certify"]]
    # the attribute's default is the key's (required keys have none)
    fields = {f.name: f for f in dataclasses.fields(Config)}
    for attr, (table, name) in config_fields().items():
        key = next(k for k in TABLES[table] if k.name == name)
        want = dataclasses.MISSING if key.default is REQUIRED else key.default
        assert fields[attr].default == want, attr
    # table keys (and the [smoke] keys, applied to their targets) are read by the loader
    assert all(k.attribute is None for k in TABLES["smoke"])
    assert {k.name for k in TABLES[""] if k.attribute is None} == {n for n in TABLES if n}


#: A valid non-default value for every key that is a Config attribute, and what the Config
#: holds then (None: the value as written). Adding a key to TABLES must add it here.
def _changed():
    dyn = SMALL_SCENE["dynamics"]
    return {
        "title": ({"title": "T"}, "T"),
        "description": ({"description": "D"}, "D"),
        "seed": ({"seed": 7}, 7),
        "d": ({"dynamics": {**dyn, "d": 4}}, 4),
        "precision": ({"dynamics": {**dyn, "precision": "mixed"}}, "mixed"),
        "effects": ({"dynamics": {**dyn, "effect": [{"type": "free"}]}}, (("free", {}),)),
        "pairsum": ({"dynamics": {**dyn, "pairsum": {"method": "numpy"}}}, ("numpy", {})),
        "lift_to": ({"dynamics": {**dyn, "d": 4},
                     "initial": {**SMALL_SCENE["initial"], "lift_to": 4}}, 4),
        "lift_seed": ({"initial": {**SMALL_SCENE["initial"], "lift_seed": 3}}, 3),
        "eps": ({"quantize": {"eps": 0.25}}, 0.25),
        "atoms": ({"quantize": {"atoms": 31}}, 31),
        "rule": ({"quantize": {"atoms": 30, "rule": "paper"}}, "paper"),
        "reference_atoms": ({"quantize": {"atoms": 30, "reference_atoms": 60}}, 60),
        "max_atoms": ({"quantize": {"atoms": 30, "max_atoms": 100}}, 100),
        "ks": ({"projection": {"k": [2]}}, (2,)),
        "kind": ({"projection": {"k": [1, 2], "kind": "achlioptas"}}, "achlioptas"),
        "projection_seed": ({"projection": {"k": [1, 2], "seed": 9}}, 9),
        "method": ({"integrate": {**SMALL_SCENE["integrate"], "method": "rk4"}}, "rk4"),
        "dt": ({"integrate": {**SMALL_SCENE["integrate"], "dt": 0.05}}, 0.05),
        "t_final": ({"integrate": {**SMALL_SCENE["integrate"], "t_final": 2.0}}, 2.0),
        "save_every": ({"integrate": {**SMALL_SCENE["integrate"], "save_every": 2}}, 2),
        "yes_below": ({"output": {"yes_below": 1e-9}}, 1e-9),
        "no_above": ({"output": {"no_above": 1e-2}}, 1e-2),
        "certify": ({"certify": {"enabled": False, "norm": "max"}},
                    CertifyOptions(enabled=False, norm="max")),
    }


def _json(value):
    if dataclasses.is_dataclass(value):
        return dataclasses.asdict(value)
    return [_json(v) for v in value] if isinstance(value, tuple) else value


def test_every_key_goes_from_the_file_to_the_config_its_json_and_its_digest():
    changed = _changed()
    assert set(changed) == set(config_fields()) | set(GROUPED), \
        "a key was added to TABLES: give it a non-default value here"
    plain = config_from_dict(SMALL_SCENE)
    for attr, (patch, held) in changed.items():
        cfg = config_from_dict({**SMALL_SCENE, **patch})
        assert getattr(cfg, attr) == held != getattr(plain, attr), attr
        assert cfg.to_json()[attr] == _json(held), attr
        assert cfg.digest() != plain.digest(), attr
        # and back: the Config rebuilt from its attributes is the same configuration
        again = Config(**{f.name: getattr(cfg, f.name) for f in dataclasses.fields(Config)})
        assert again == cfg and again.digest() == cfg.digest(), attr


def test_digests_of_older_scenes_stay():
    # recorded on main before Config was derived from TABLES (result folders hold them);
    # keys added after the first format (pairsum, certify) enter only when not at default
    plain = config_from_dict(SMALL_SCENE)
    assert plain.digest() == "69a6f48c2299984a00c9dbf45779af3621a82afc2e27d1859a28afe9818f9293"
    assert set(plain.to_json()) == set(scenefile.FIRST_FORMAT) | {"initial"}
    spelled = config_from_dict({**SMALL_SCENE, "certify": {"norm": "both", "paper": True}})
    assert spelled.digest() == plain.digest()


# ------------------------------------------------------------------------------------------
# one pair-sum registry
# ------------------------------------------------------------------------------------------
class _Twin(pairsum.Numpy):
    """The numpy twin with an option (a backend defined outside the package)."""

    def __init__(self, scale=1.0):
        super().__init__()
        self.scale = scale


@pytest.fixture
def twin():
    pairsum.register_pairsum("twin_scaled", lambda scale: _Twin(scale), doc="a test twin",
                             keys=(scenefile.Key("scale", "number", 2.0, "a scale", low=0.0),))
    yield "twin_scaled"
    pairsum.unregister_pairsum("twin_scaled")


def test_one_pairsum_registry_for_scenes_and_scene_files(twin):
    assert scenefile.PAIRSUMS is pairsum.PAIRSUMS
    assert scenefile.register_pairsum is pairsum.register_pairsum
    # registered once: Scene(pairsum=name) builds it with the key's default ...
    scene = Scene([Alignment(CuckerSmale(1.0, 0.5))], pairsum=twin)
    assert type(scene.pairsum) is _Twin and scene.pairsum.scale == 2.0
    # ... and a scene file names it, with its option checked and passed
    dyn = {**SMALL_SCENE["dynamics"], "pairsum": {"method": twin, "scale": 3.0}}
    cfg = config_from_dict({**SMALL_SCENE, "dynamics": dyn})
    assert type(cfg.scene().pairsum) is _Twin and cfg.scene().pairsum.scale == 3.0
    with pytest.raises(ConfigError, match=r"dynamics\.pairsum\.scale: must be >= 0, got -1\.0"):
        config_from_dict({**SMALL_SCENE, "dynamics": {**dyn, "pairsum": {"method": twin,
                                                                         "scale": -1.0}}})
    # the twin computes what the numpy backend computes
    rng = np.random.default_rng(0)
    x, v = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    ref = Scene([Alignment(CuckerSmale(1.0, 0.5))], pairsum="numpy")
    assert np.array_equal(scene.rhs(x, v)[1], ref.rhs(x, v)[1])


def test_unregistered_backend_is_gone_from_both():
    pairsum.register_pairsum("twin_gone", _Twin)
    Scene([Alignment(CuckerSmale(1.0, 0.5))], pairsum="twin_gone")
    pairsum.unregister_pairsum("twin_gone")
    with pytest.raises(InvalidInput, match="pairsum must be a PairSum backend or one of"):
        Scene([Alignment(CuckerSmale(1.0, 0.5))], pairsum="twin_gone")
    dyn = {**SMALL_SCENE["dynamics"], "pairsum": {"method": "twin_gone"}}
    with pytest.raises(ConfigError, match="unknown pair-sum method 'twin_gone'"):
        config_from_dict({**SMALL_SCENE, "dynamics": dyn})
    with pytest.raises(InvalidInput, match="built-in pair-sum method"):
        pairsum.unregister_pairsum("nufft")


def test_a_backend_with_required_options_is_named_from_scene_files_only():
    pairsum.register_pairsum("twin_needs", lambda scale: _Twin(scale),
                             keys=(scenefile.Key("scale", "number", REQUIRED, "a scale"),))
    try:
        with pytest.raises(InvalidInput, match="'twin_needs' needs the options scale; build"):
            Scene([Alignment(CuckerSmale(1.0, 0.5))], pairsum="twin_needs")
        dyn = {**SMALL_SCENE["dynamics"], "pairsum": {"method": "twin_needs", "scale": 0.5}}
        assert config_from_dict({**SMALL_SCENE, "dynamics": dyn}).pair_sum().scale == 0.5
    finally:
        pairsum.unregister_pairsum("twin_needs")
