"""The public API's shape (issue 21): names, flags, result objects and their reprs."""

import importlib
import pkgutil
import types

import numpy as np
import pytest

import kinred
from kinred.certify import Certificate, certify
from kinred.dynamics import Alignment, CuckerSmale, Scene
from kinred.integrate import SaveAt

MODULES = sorted(m.name for m in pkgutil.iter_modules(kinred.__path__)
                 if not m.name.startswith("_"))


# ------------------------------------------------------------------ names: one rule (item 8)
def test_the_package_has_the_modules_the_rule_is_about():
    assert {"quantize", "certify", "kinetic", "integrate", "distance"} <= set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_kinred_dot_module_is_the_module(name):
    mod = importlib.import_module(f"kinred.{name}")
    assert isinstance(mod, types.ModuleType) and mod.__name__ == f"kinred.{name}"
    assert getattr(kinred, name) is mod
    scope = {}
    exec(f"import kinred.{name} as alias", scope)                     # noqa: S102
    assert scope["alias"] is mod


def test_no_top_level_export_shadows_a_module():
    for name in kinred.__all__:
        obj = getattr(kinred, name)
        assert name not in MODULES or isinstance(obj, types.ModuleType), name


def test_namesake_functions_are_reached_through_their_module():
    from kinred.measures import TensorProduct, Uniform

    q = kinred.quantize.quantize(TensorProduct([Uniform(0, 1)] * 2), atoms=9)
    assert q.n_atoms == 9 and isinstance(q, kinred.quantize.Quantization)
    assert callable(kinred.certify.certify) and kinred.certify.Certificate is Certificate
