"""Scene-file rules of issue 21 (item 12): each k once; a reference finer than the run."""

import pytest

from kinred.errors import ConfigError
from kinred.experiments import kinetic_run
from kinred.scenefile import SMALL_SCENE, config_from_dict, load_config


def _scene(**tables):
    return {**SMALL_SCENE, **tables}


@pytest.mark.parametrize("ks, twice", [([2, 2], "2"), ([1, 2, 1, 2], "1, 2"), ([3, 1, 3], "3")])
def test_duplicate_ks_are_refused(ks, twice):
    with pytest.raises(ConfigError, match=rf"projection\.k: each k must appear once .* with "
                                          rf"{twice} twice"):
        config_from_dict(_scene(projection={"k": ks}))
    assert config_from_dict(_scene(projection={"k": sorted(set(ks))})).ks == tuple(sorted(set(ks)))


def test_duplicate_ks_from_the_smoke_table_name_it(tmp_path):
    text = ("[dynamics]\nd = 2\n[[dynamics.effect]]\ntype = \"alignment\"\nG = 1.0\nbeta = 0.5\n"
            "[initial.positions]\n[[initial.positions.coordinate]]\ndist = \"uniform\"\nrepeat = 2\n"
            "[initial.velocities]\n[[initial.velocities.coordinate]]\ndist = \"uniform\"\nrepeat = 2\n"
            "[quantize]\natoms = 9\n[projection]\nk = [1, 2]\n[integrate]\ndt = 0.1\nt_final = 0.5\n"
            "[smoke]\nk = [1, 1]\n")
    path = tmp_path / "s.toml"
    path.write_text(text)
    assert load_config(path).ks == (1, 2)
    with pytest.raises(ConfigError, match=r"smoke\.k: each k must appear once"):
        load_config(path, smoke=True)


@pytest.mark.parametrize("ref", [1, 29, 30])
def test_reference_atoms_not_above_atoms_are_refused(ref):
    with pytest.raises(ConfigError, match=rf"quantize\.reference_atoms: the reference must be "
                                          rf"finer .* need reference_atoms > quantize\.atoms = 30, "
                                          rf"got {ref}$"):
        config_from_dict(_scene(quantize={"atoms": 30, "reference_atoms": ref}))
    assert config_from_dict(_scene(quantize={"atoms": 30, "reference_atoms": 31})).reference_atoms == 31


def test_reference_atoms_with_eps_are_checked_against_the_run_n(tmp_path):
    cfg = config_from_dict(_scene(quantize={"eps": 1.5, "reference_atoms": 2}))
    with pytest.raises(ConfigError) as info:
        kinetic_run.run(cfg)
    msg = str(info.value)
    n = int(msg.split("N = ")[1].split(" atoms")[0])
    assert n > 2 and msg.endswith(f"got reference_atoms = 2 (valid: > {n})")
    # the N named is the run's: a reference just above it is accepted
    from kinred.quantize import quantize

    assert quantize(cfg.initial_measure(), eps=1.5).n_atoms == n == 12
