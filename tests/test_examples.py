"""Every script of examples/ runs in its smoke mode and prints its expected lines."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"

# script -> regular expressions that must match its smoke output (numbers that could fail)
EXPECTED = {
    "quantize_delayed_curse.py": [
        r"d = 8;",
        # the delayed curse: 5 active coordinates at eps = 0.2 for widths 0.5**j (paper rule)
        r"decay 0\.5\s+0\.200\s+5\s",
        r"isotropic\s+0\.500\s+8\s",
        r"^done",
    ],
    "w1_methods.py": [
        r"^\s+exact\s+0\.4\d+\s+0\.4\d+\s+0\.4\d+\s+True",
        r"^\s+exact-lazy\s+0\.4\d+",
        r"^\s+sliced\s+0\.\d+",
        r"^done",
    ],
    "jl_distortion.py": [r"^\s+128\s+0\.[0-4]\d+\s+0\.[0-4]\d+\s+0\.\d+", r"^done"],
    "recovery_l1.py": [r"^\s+3\s+60\s+\S+\s+20/20", r"^done"],
    "ensemble_dask.py": [r"identical: True"],
    "flocking_projected.py": [r"^\s+full\s+\S+\s+pos", r"^\s+20\s+\S+\s+pos", r"^done"],
    "certify_projection.py": [
        r"error \(measured\)\s+bound \(certified bound\)\s+ratio",
        # at T = 3: error and bound of the same size, ratio in [1, 1.5) (measured 1.13)
        r"^\s+3\.00\s+\d\.\d{3}e-0[12]\s+\d\.\d{3}e-0[12]\s+1\.[0-4]\d\s+\d\.\d{3}e\+\d+$",
        r"^valid: True; worst ratio over t >= 1: 1\.[0-4]\d \(max over agents: 1\.[0-4]\d\)",
        r"^figure: certify_projection\.png",
        r"^done",
    ],
}


def _scripts():
    return sorted(p.name for p in EXAMPLES.glob("*.py"))


def test_every_example_is_covered():
    assert _scripts(), "examples/ holds no scripts"
    assert set(_scripts()) == set(EXPECTED), "update EXPECTED when adding an example"


@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_example_smoke(script, tmp_path):
    path = EXAMPLES / script
    assert path.exists(), f"{path} is missing"
    env = dict(os.environ, PYTHONHASHSEED="0", MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(path), "--smoke"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"{script} failed:\n{proc.stdout}\n{proc.stderr}"
    for pattern in EXPECTED[script]:
        assert re.search(pattern, proc.stdout, re.MULTILINE), \
            f"{script}: no line matching {pattern!r} in\n{proc.stdout}"
