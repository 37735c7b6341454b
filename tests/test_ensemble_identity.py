"""An ensemble store belongs to one member function (issue 21, item 4b): the config hash names
the function's module, not only its ``__qualname__`` (``table1.member`` and
``calibrate_table1.member`` are both "member")."""

import importlib.util
import textwrap

import numpy as np
import pytest

from kinred.errors import StoreMismatch
from kinred.ensemble import grid, run_ensemble

_MODULE = textwrap.dedent("""
    import numpy as np

    def member(params, seed):
        return {"x": np.full(3, VALUE) * params["i"]}
""")


def _module(tmp_path, name, value):
    path = tmp_path / f"{name}.py"
    path.write_text(_MODULE.replace("VALUE", repr(value)))
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_a_store_does_not_resume_with_another_modules_function_of_the_same_name(tmp_path):
    a, b = _module(tmp_path, "study_a", 1.0), _module(tmp_path, "study_b", 2.0)
    assert a.member.__qualname__ == b.member.__qualname__ == "member"
    members = grid(i=range(3))
    store = tmp_path / "store"
    ra = run_ensemble(a.member, members, master_seed=5, store=store, progress=False)
    rb = run_ensemble(b.member, members, master_seed=5, progress=False)
    assert ra.config_hash != rb.config_hash
    # main resumed here and returned study_a's numbers as study_b's
    with pytest.raises(StoreMismatch):
        run_ensemble(b.member, members, master_seed=5, store=store, resume=True, progress=False)
    again = run_ensemble(a.member, members, master_seed=5, store=store, resume=True,
                         progress=False)
    assert again.loaded.all() and again.config_hash == ra.config_hash
    np.testing.assert_array_equal(again.results[2]["x"], [2.0, 2.0, 2.0])


def test_the_papers_two_member_functions_hash_apart():
    from kinred.ensemble import config_hash
    from kinred.experiments import calibrate_table1, table1

    ens = importlib.import_module("kinred.ensemble")
    assert table1.member.__qualname__ == calibrate_table1.member.__qualname__
    names = [ens._fn_identity(f) for f in (table1.member, calibrate_table1.member)]
    assert names == ["kinred.experiments.table1.member",
                     "kinred.experiments.calibrate_table1.member"]
    assert config_hash(0, [{}], names[0]) != config_hash(0, [{}], names[1])
