"""The README's two commands: ``make test`` brings what the suite needs beyond pip.

A fresh machine has only what ``make demo`` / ``make test`` install; the report's browser test
needs Debian's ``chromium``, so the ``test`` target installs it (as root, with apt) or says in
one line how to (otherwise), and ``.ci/run`` is nothing but ``make test``.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)


def _make(*args, env=None, check=False):
    if shutil.which("make") is None:
        pytest.fail("make is needed for the README's commands")
    return subprocess.run(["make", "--no-print-directory", f"VENV={VENV}",
                           "-o", f"{VENV}/.installed-base", "-o", f"{VENV}/.installed-test",
                           *args], cwd=ROOT, capture_output=True, text=True, env=env,
                          timeout=120, check=check)


def test_ci_runs_exactly_the_readme_test_command():
    lines = [ln.strip() for ln in (ROOT / ".ci/run").read_text().splitlines()]
    commands = [ln for ln in lines if ln and not ln.startswith("#")]
    assert commands[-1] == "make test"
    assert all(c.startswith(("set ", "cd ")) for c in commands[:-1]), commands
    assert "make test" in (ROOT / "README.md").read_text().split("\n## ")[0]


def test_make_test_brings_chromium_and_uses_every_core():
    plan = _make("-n", "test", check=True).stdout
    assert "find_chromium" in plan and "apt-get install -y -qq chromium" in plan
    assert "pytest -n auto" in plan and "--durations" in plan
    # the kernels are compiled once, in two processes, before pytest starts
    warm = [plan.index(f"tests/_warm_kernels.py {g}") for g in ("demo", "fig4")]
    assert max(warm) < plan.index("pytest -n auto")
    assert "demo w1 steps" in plan and "fig4 twins" in plan


def test_warm_up_twins_name_tests_that_exist():
    """A renamed twin test would make the warm-up fail quietly (its failure is ignored)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("warm", ROOT / "tests" / "_warm_kernels.py")
    warm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(warm)
    for node in warm.TWINS:
        path, _, name = node.partition("::")
        assert (ROOT / path).is_file(), node
        assert not name or f"def {name}(" in (ROOT / path).read_text(), node


def test_without_chromium_and_root_one_clear_line(tmp_path):
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "id").write_text("#!/bin/sh\necho 1000\n")
    (fake / "id").chmod(0o755)
    env = dict(os.environ, PATH=f"{fake}{os.pathsep}{os.environ['PATH']}",
               CHROMIUM=str(tmp_path / "no-such-browser"))
    p = _make("-s", "chromium", env=env)
    assert p.returncode != 0
    out = p.stdout.strip().splitlines()
    assert out == ["make test: tests/test_report_browser.py needs Chromium; install it with: "
                   "sudo apt-get install chromium"], p.stdout + p.stderr
