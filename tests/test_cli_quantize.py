"""``kinred quantize`` and ``kinred demo`` through kinred.cli.main, and one subprocess run."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import kinred.cli as cli

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "measures"


@pytest.fixture(autouse=True)
def _commands(monkeypatch):
    monkeypatch.setattr(cli, "COMMAND_MODULES", ("kinred.commands.quantize", "kinred.commands.demo"))
    monkeypatch.delenv("KINRED_MAX_BYTES", raising=False)  # the documented default limit, 2 GiB


def _write(tmp_path, text, name="m.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


UNIFORM3 = """
[[coordinate]]
dist = "uniform"
params = {loc = 0.0, scale = 1.0}

[[coordinate]]
dist = "uniform"
params = {loc = 0.0, scale = 0.5}

[[coordinate]]
dist = "dirac"
at = 2.0
"""


def test_quantize_prints_budget_and_writes_npz(tmp_path, capsys):
    f = _write(tmp_path, UNIFORM3)
    out = tmp_path / "atoms.npz"
    assert cli.main(["quantize", f, "--atoms", "20", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "k̄" in text and "paper recipe" in text and "proven optimal" in text
    with np.load(out) as z:
        P, W = z["points"], z["weights"]
    # optimal split of 20 atoms for σ = (1, 0.5, 0): N = (5, 4, 1) → 20 atoms (beats (10, 2, 1))
    assert P.shape == (20, 3) and W.sum() == pytest.approx(1.0)
    assert np.all(P[:, 2] == 2.0)
    assert sorted(set(np.round(P[:, 0], 12))) == pytest.approx([0.1, 0.3, 0.5, 0.7, 0.9])
    assert sorted(set(np.round(P[:, 1], 12))) == pytest.approx([0.0625, 0.1875, 0.3125, 0.4375])
    # uniform midpoint: exact marginal errors σ/(4N): 1/20 + 0.5/16
    assert f"{1 / 20 + 0.5 / 16:.6g}" in text
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_quantize_example_files(capsys):
    assert cli.main(["quantize", str(EXAMPLES / "decaying-200.toml"), "--eps", "0.1"]) == 0
    text = capsys.readouterr().out
    assert "d = 200" in text and "3.815e+30" in text  # the paper recipe's 50^18 atoms
    assert cli.main(["quantize", str(EXAMPLES / "sparse-grid-mixture.toml"), "--eps", "0.02",
                     "--rule", "paper"]) == 0
    text = capsys.readouterr().out
    assert "mixture of 2 components" in text and "component 1" in text
    assert cli.main(["quantize", str(EXAMPLES / "mixed-coordinates.toml"), "--atoms", "100"]) == 0


def test_refuses_too_many_atoms(tmp_path, capsys):
    out = tmp_path / "a.npz"
    code = cli.main(["quantize", str(EXAMPLES / "decaying-200.toml"), "--eps", "0.1", "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    # the 3.3e24 atoms are refused by the memory limit, which names what would fit instead
    assert err.count("\n") == 1 and "TooLarge" in err and "3.297e+24 atoms" in err
    assert "max_bytes = 2 GiB" in err and "eps >= " in err and "iter_chunks" in err
    assert not out.exists()
    # an explicit count limit is honoured too
    code = cli.main(["quantize", str(EXAMPLES / "decaying-200.toml"), "--eps", "0.1", "--out", str(out),
                     "--max-atoms", "1000"])
    err = capsys.readouterr().err
    assert code == 2 and "max_atoms=1000" in err and not out.exists()


@pytest.mark.parametrize("body,needle", [
    ('[[coordinate]]\ndist = "nosuchlaw"\n', "coordinate[0].dist: unknown distribution 'nosuchlaw'"),
    ('[[coordinate]]\ndist = "uniform"\nsupport = [1.0, 0.0]\n', "coordinate[0].support: needs a < b"),
    ('[[coordinate]]\ndist = "norm"\n', "unbounded support"),
    ('[[coordinate]]\ndist = "uniform"\nparams = {loc = nan}\n', "coordinate[0].params.loc: must be finite"),
    ('[[coordinate]]\ndist = "uniform"\ncolour = 3\n', "coordinate[0].colour: unknown key"),
    ('[[coordinate]]\ndist = "beta"\nparams = {a = -1.0, b = 2.0}\n', "invalid parameter values"),
    ('[[component]]\nweight = 0.5\n[[component.coordinate]]\ndist = "uniform"\n'
     '[[component]]\nweight = 0.6\n[[component.coordinate]]\ndist = "uniform"\n', "sum to one"),
    ('[[coordinate]]\ndist = "uniform"\nrepeat = 0\n', "coordinate[0].repeat"),
    ('dist = "uniform"\n', "dist: unknown key"),
    ('[[coordinate]\n', "invalid TOML"),
])
def test_bad_measure_files(tmp_path, capsys, body, needle):
    f = _write(tmp_path, body, "bad.toml")
    assert cli.main(["quantize", f, "--eps", "0.1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "ConfigError" in err and "bad.toml" in err and needle in err


def test_missing_file(capsys):
    assert cli.main(["quantize", "/nonexistent/m.toml", "--eps", "0.1"]) == 2
    assert "not found" in capsys.readouterr().err


def test_python_m_kinred_quantize(tmp_path):
    f = _write(tmp_path, UNIFORM3)
    r = subprocess.run([sys.executable, "-m", "kinred", "quantize", f, "--eps", "0.1"],
                       capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "budget" in r.stdout and "N_j" in r.stdout
    bad = _write(tmp_path, '[[coordinate]]\ndist = "nosuchlaw"\n', "bad.toml")
    r = subprocess.run([sys.executable, "-m", "kinred", "quantize", bad, "--eps", "0.1"],
                       capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "unknown distribution" in r.stderr


# ------------------------------------------------------------------ sizes (issue 14)
# A wrapper process runs the command and reports the command's own peak RSS, so the figure
# is not the maximum over every child this test session has waited for.
_RSS = (
    "import resource, subprocess, sys, time\n"
    "t = time.perf_counter()\n"
    "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
    "print(r.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, "
    "time.perf_counter() - t)\n"
    "sys.stderr.write(r.stderr)\n"
)

UNIFORM200 = '[[coordinate]]\ndist = "uniform"\nparams = {loc = 0.0, scale = 1.0}\nrepeat = 200\n'


@pytest.mark.parametrize("case,eps", [("uniform-200", "1e-12"), ("decaying-200", "1e-6"),
                                      ("decaying-200", "1e-300")])
def test_tiny_eps_answers_too_large_in_seconds_with_little_memory(tmp_path, case, eps):
    """Defects 3 and 4 through the command: a raw traceback (rc 1), then 18.6 GB in 60 s."""
    f = _write(tmp_path, UNIFORM200) if case == "uniform-200" else str(EXAMPLES / "decaying-200.toml")
    env = {k: v for k, v in os.environ.items() if k != "KINRED_MAX_BYTES"}
    cmd = [sys.executable, "-m", "kinred", "quantize", f, "--eps", eps]
    r = subprocess.run([sys.executable, "-c", _RSS, *cmd], capture_output=True, text=True, cwd=ROOT, env=env,
                       timeout=300)
    code, rss_kib, seconds = r.stdout.split()
    assert int(code) == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("kinred: error: TooLarge: ")
    assert f"quantize(eps={float(eps):g}) would allocate" in r.stderr and "eps >= " in r.stderr
    assert "max_bytes = 2 GiB" in r.stderr and "atoms in dimension 200" in r.stderr
    # ~7 s and ~170 MB (interpreter, numpy, scipy) measured on a loaded 2-core machine
    assert int(rss_kib) < 500 * 1024 and float(seconds) < 100


def test_max_bytes_option_is_the_limit(tmp_path, capsys, monkeypatch):
    from kinred.measures import load_measure
    from kinred.quantize import preflight

    f = str(EXAMPLES / "decaying-200.toml")
    need = preflight(load_measure(f), eps=1e-3).quantize_bytes
    assert cli.main(["quantize", f, "--eps", "1e-3", "--max-bytes", str(need - 1)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "TooLarge" in err and "eps >= " in err
    assert cli.main(["quantize", f, "--eps", "1e-3", "--max-bytes", str(need)]) == 0
    monkeypatch.setenv("KINRED_MAX_BYTES", str(need - 1))  # the environment, when no option
    assert cli.main(["quantize", f, "--eps", "1e-3"]) == 2
    assert "TooLarge" in capsys.readouterr().err
    assert cli.main(["quantize", f, "--eps", "1e-3", "--max-bytes", "2G"]) == 0
    capsys.readouterr()
    assert cli.main(["quantize", f, "--eps", "0.1", "--max-bytes", "a lot"]) == 2
    assert "--max-bytes must be a byte count" in capsys.readouterr().err
