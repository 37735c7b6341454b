"""Every script of examples/ runs in its smoke mode, prints its expected lines and draws its
figure, and is a sphinx-gallery script (the documentation renders them as a gallery,
tests/test_docs.py, whose build does not run them again)."""

from __future__ import annotations

import ast
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
    "dorsogna_mill_large.py": [
        r"^D'Orsogna mill: N=2000, 40 Euler steps",
        # at N = 2000 the NUFFT's near-field split wins (measured 8 ms against Dense's 23)
        r"^backend chosen: nufft \(estimated seconds per right-hand side: dense \d",
        r"^time per step: \d+\.\d+ s",
        # the ring relaxes to a mill: the index stays high (measured 0.90-0.98 at smoke size)
        r"^\s+2\.00\s+0\.9\d\d$",
        r"^done",
    ],
    "flocking_projected.py": [r"^\s+full\s+\S+\s+pos", r"^\s+20\s+\S+\s+pos", r"^done"],
    "certify_projection.py": [
        r"error \(measured\)\s+bound \(certified bound\)\s+ratio",
        # at T = 3: error and bound of the same size, ratio in [1, 1.5) (measured 1.13)
        r"^\s+3\.00\s+\d\.\d{3}e-0[12]\s+\d\.\d{3}e-0[12]\s+1\.[0-4]\d\s+\d\.\d{3}e\+\d+$",
        r"^valid: True; worst ratio over t >= 1: 1\.[0-4]\d \(max over agents: 1\.[0-4]\d\)",
        r"^figure: cert\.png",
        r"^done",
    ],
}


#: extra smoke arguments: certify_projection.py saves its figure only when asked
EXTRA_ARGS = {"certify_projection.py": ("--out", "cert.png")}


def _scripts():
    return sorted(p.name for p in EXAMPLES.glob("*.py"))


def test_every_example_is_covered():
    assert _scripts(), "examples/ holds no scripts"
    assert set(_scripts()) == set(EXPECTED), "update EXPECTED when adding an example"


def _run(script, args, cwd, *, smoke_variable=False):
    # Agg, and the figures open at the end saved into cwd (tests/_example_figures.py)
    path = os.pathsep.join(p for p in (str(ROOT / "tests"), os.environ.get("PYTHONPATH")) if p)
    env = dict(os.environ, PYTHONHASHSEED="0", MPLBACKEND="module://_example_figures",
               PYTHONPATH=path)
    env.pop("KINRED_EXAMPLES_SMOKE", None)
    if smoke_variable:
        env["KINRED_EXAMPLES_SMOKE"] = "1"
    # timeouts: the slowest smoke run (Dask cluster start) takes 25 s on a loaded machine
    return subprocess.run([sys.executable, str(EXAMPLES / script), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_example_is_a_gallery_script(script):
    """A docstring that opens with an underlined title, ``# %%`` sections, and a figure."""
    source = (EXAMPLES / script).read_text(encoding="utf-8")
    doc = ast.get_docstring(ast.parse(source), clean=False) or ""
    lines = doc.strip("\n").splitlines()
    assert len(lines) > 2 and lines[1] == "=" * len(lines[0]) and lines[0].strip(), \
        f"{script}: the docstring must open with a title underlined by '=' (the gallery's title)"
    assert source.count("\n# %%\n") >= 2, f"{script}: split it into '# %%' sections"
    assert "plt.subplots(" in source and "set_xlabel(" in source and "set_ylabel(" in source, \
        f"{script}: draw at least one figure with labelled axes"


@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_example_smoke(script, tmp_path):
    path = EXAMPLES / script
    assert path.exists(), f"{path} is missing"
    proc = _run(script, ["--smoke", *EXTRA_ARGS.get(script, ())], tmp_path)
    assert proc.returncode == 0, f"{script} failed:\n{proc.stdout}\n{proc.stderr}"
    for pattern in EXPECTED[script]:
        assert re.search(pattern, proc.stdout, re.MULTILINE), \
            f"{script}: no line matching {pattern!r} in\n{proc.stdout}"
    # the figure the gallery shows under the code (a PNG over 5 kB, as the gallery page had)
    figures = sorted(tmp_path.glob("figure_*.png"))
    assert figures, f"{script}: no matplotlib figure open at the end of the script"
    png = figures[0].read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 5_000, f"{script}: no figure drawn"


def test_gallery_variable_selects_the_smoke_sizes(tmp_path):
    """docs/conf.py sets KINRED_EXAMPLES_SMOKE=1 so that the gallery runs the long examples
    at their smoke sizes: without arguments, recovery_l1.py then prints the smoke table."""
    conf = (ROOT / "docs" / "conf.py").read_text(encoding="utf-8")
    assert 'os.environ["KINRED_EXAMPLES_SMOKE"] = "1"' in conf
    proc = _run("recovery_l1.py", [], tmp_path, smoke_variable=True)
    assert proc.returncode == 0, proc.stderr
    assert "20 vectors in R^200 with 8 non-zeros" in proc.stdout
    for pattern in EXPECTED["recovery_l1.py"]:
        assert re.search(pattern, proc.stdout, re.MULTILINE), proc.stdout
