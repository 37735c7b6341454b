"""``kinred run``: shipped scenes in smoke mode, malformed scene files, interrupt and resume."""

import contextlib
import io
import json
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import kinred.cli as cli
from kinred.errors import ConfigError
from kinred.experiments import kinetic_run
from kinred.report import validate_report_html

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "examples" / "scenes").glob("*.toml"))
REGISTERED = "kinred.commands.run" in cli.COMMAND_MODULES   # before any monkeypatching


@pytest.fixture
def main(monkeypatch):
    if "kinred.commands.run" not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("kinred.commands.run",))
    return cli.main


def test_four_scenes_are_shipped():
    names = {p.stem for p in SCENES}
    assert {"cucker-smale-200", "dorsogna-mill-2d", "dorsogna-mill-lift-200", "delayed-curse"} <= names


@pytest.mark.parametrize("scene", SCENES, ids=lambda p: p.stem)
def test_shipped_scene_smoke(scene, tmp_path, main, capsys):
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out), "--smoke"]) == 0
    printed = capsys.readouterr().out
    assert f"report: {out / 'report.html'}" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["smoke"] is True
    assert set(summary["stages"].values()) == {"computed"}
    for k, r in summary["per_k"].items():
        assert r["all_exact"]
        assert r["under_bound"] and r["under_term_jl"], (scene.stem, k, r)
    html = (out / "report.html").read_text()
    assert validate_report_html(html) == 4            # every figure embedded and non-empty
    for name in ("w1_vs_time.png", "bound.png", "observables.png", "positions_final.png"):
        assert (out / name).read_bytes().startswith(b"\x89PNG")
    res = np.load(out / "results.npz")
    k0 = summary["ks"][0]
    assert res[f"k{k0}_w1"][0] < 1e-12                # W1(M#μᴺ(0), νᴺ(0)) = 0
    # the full-size configuration of every shipped scene is valid too
    cfg = kinetic_run.load_config(scene)
    assert not cfg.smoke and cfg.d >= 2


def test_delayed_curse_scene_uses_few_coordinates():
    cfg = kinetic_run.load_config(ROOT / "examples" / "scenes" / "delayed-curse.toml")
    from kinred.quantize import quantize

    q = quantize(cfg.initial_measure(), eps=cfg.eps)
    assert q.k_bar <= 6 < 2 * cfg.d and q.bound <= cfg.eps * (1 + 1e-12)


def test_mill_scene_mills():
    # the 2-D mill scene at reduced size still forms one mill (normalized angular momentum)
    cfg = kinetic_run.load_config(ROOT / "examples" / "scenes" / "dorsogna-mill-2d.toml")
    from kinred.kinetic import milling_index, solve

    sol = solve(cfg.scene(), cfg.initial_measure(), atoms=64, t_span=(0.0, 10.0), dt=0.05,
                save_every=200)
    assert milling_index(sol.x[-1], sol.v[-1], sol.weights) > 0.9


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
repeat = 2
[quantize]
atoms = 9
[projection]
k = [1]
[integrate]
dt = 0.1
t_final = 0.5
"""


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    """``kinred run tiny.toml`` of BASE, run once per module in a fresh directory without
    ``--out`` (so into the default folder results/run-tiny): its exit code, its stdout, its
    folder and that directory (tests that change the folder work on a copy, ``_copy_run``)."""
    tmp = tmp_path_factory.mktemp("base-run")
    scene = tmp / "tiny.toml"
    scene.write_text(BASE)
    printed = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(printed):
        if "kinred.commands.run" not in cli.COMMAND_MODULES:
            mp.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("kinred.commands.run",))
        mp.chdir(tmp)
        code = cli.main(["run", str(scene)])
    return code, printed.getvalue(), tmp / "results" / "run-tiny", tmp


def _copy_run(base_run, dest):
    """A copy of the module's BASE run at ``dest`` (what ``kinred run BASE --out dest`` left)."""
    code, _, out, _ = base_run
    assert code == 0
    shutil.copytree(out, dest)
    return dest


@pytest.mark.parametrize("edit, key", [
    (lambda s: s.replace("[quantize]\n", "[quantize]\ncolour = 1\n"), "quantize.colour"),
    (lambda s: s.replace("dt = 0.1\n", ""), "integrate.dt"),
    (lambda s: s.replace("t_final = 0.5", 't_final = "long"'), "integrate.t_final"),
    (lambda s: s.replace("G = 1.0\n", ""), "dynamics.effect[0].G"),
    (lambda s: s.replace("k = [1]", "k = [7]"), "projection.k"),
    (lambda s: s.replace('dist = "uniform"\nrepeat = 2\n[initial.velocities]',
                         'dist = "nope"\nrepeat = 2\n[initial.velocities]'), "initial.positions"),
])
def test_malformed_scene_one_line(edit, key, tmp_path, main, capsys, base_run):
    assert base_run[0] == 0                         # BASE itself runs (module fixture)
    bad = tmp_path / "bad.toml"
    bad.write_text(edit(BASE))
    capsys.readouterr()
    assert main(["run", str(bad), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "ConfigError" in err and str(bad) in err and key in err


def test_config_errors_directly():
    with pytest.raises(ConfigError, match="quantize.eps: give exactly one"):
        kinetic_run.config_from_dict({**kinetic_run.SMALL_SCENE, "quantize": {}})
    with pytest.raises(ConfigError, match="not found"):
        kinetic_run.load_config("/nonexistent/scene.toml")
    dyn = dict(kinetic_run.SMALL_SCENE["dynamics"])
    with pytest.raises(ConfigError, match="dynamics.precision: must be 'double' or 'mixed'"):
        kinetic_run.config_from_dict({**kinetic_run.SMALL_SCENE,
                                      "dynamics": {**dyn, "precision": "single"}})
    cfg = kinetic_run.config_from_dict({**kinetic_run.SMALL_SCENE,
                                        "dynamics": {**dyn, "precision": "mixed"}})
    assert cfg.scene().precision == "mixed" and cfg.to_json()["precision"] == "mixed"
    assert kinetic_run.config_from_dict(kinetic_run.SMALL_SCENE).scene().precision == "double"


def _cli_cmd(args, kill_after_stage=None):
    """The command running ``kinred *args`` in a new interpreter; with ``kill_after_stage=n``
    the process SIGKILLs itself right after the n-th stage file is written (the test's hook
    wraps :meth:`kinred.io.StageStore.save`: a deterministic hard interruption)."""
    if kill_after_stage is None and REGISTERED:
        return [sys.executable, "-m", "kinred", *args]
    code = "import sys, kinred.cli as c\n"
    if not REGISTERED:
        code += "c.COMMAND_MODULES += ('kinred.commands.run',)\n"
    if kill_after_stage is not None:
        code += textwrap.dedent(f"""
            import os, signal
            from kinred.io import StageStore
            _save, _count = StageStore.save, [0]
            def save(self, *args, **kwargs):
                _save(self, *args, **kwargs)
                _count[0] += 1
                if _count[0] >= {kill_after_stage}:
                    os.kill(os.getpid(), signal.SIGKILL)
            StageStore.save = save
            """)
    code += f"sys.exit(c.main({list(args)!r}))\n"
    return [sys.executable, "-c", code]


def _arrays(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files if not k.endswith("_time")}   # timings differ


def test_interrupt_and_resume(tmp_path, main, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(BASE.replace("k = [1]", "k = [1, 2]").replace("atoms = 9", "atoms = 9\nreference_atoms = 16"))
    out = tmp_path / "out"
    p = subprocess.run(_cli_cmd(["run", str(scene), "--out", str(out)], kill_after_stage=2),
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == -signal.SIGKILL, p.stderr
    done = sorted(x.name for x in (out / "stages").iterdir())
    assert done == [".kinred.lock", "config.json", "reference.npz", "solve.npz"]  # lock: stale
    assert not (out / "summary.json").exists()
    before = {n: (out / "stages" / n).stat().st_mtime_ns for n in ("solve.npz", "reference.npz")}
    content = {n: (out / "stages" / n).read_bytes() for n in before}
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0
    assert "replacing" not in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stages"] == {"solve": "loaded", "reference": "loaded", "k1": "computed",
                                 "k2": "computed"}
    for n, m in before.items():
        assert (out / "stages" / n).stat().st_mtime_ns == m
        assert (out / "stages" / n).read_bytes() == content[n]
    validate_report_html((out / "report.html").read_text())
    # the resumed run's numbers are those of an uninterrupted run, bit for bit
    assert main(["run", str(scene), "--out", str(tmp_path / "clean"), "--no-figures"]) == 0
    a, b = _arrays(tmp_path / "clean" / "results.npz"), _arrays(out / "results.npz")
    assert a.keys() == b.keys() and len(a) > 40
    for key in a:
        assert a[key].tobytes() == b[key].tobytes(), key
    # a changed configuration is not resumed into the same folder
    scene.write_text(scene.read_text().replace("t_final = 0.5", "t_final = 0.6"))
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "different configuration" in err
    assert "StoreMismatch" in err and "differs: config.t_final" in err
    # without --resume the previous run is replaced, in one line, and computed afresh
    assert main(["run", str(scene), "--out", str(out), "--no-figures"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == (f"kinred run: replacing the previous run in {out}; use --resume to "
                        "continue it")
    assert json.loads((out / "summary.json").read_text())["t_final"] == 0.6
    assert set(json.loads((out / "summary.json").read_text())["stages"].values()) == {"computed"}


def test_rerun_rule(tmp_path, main, capsys, base_run):
    """One rule: a previous `kinred run` is replaced (said so), files kinred did not write are
    refused and left alone (exit 2), the result of another command is refused."""
    scene = tmp_path / "s.toml"
    scene.write_text(BASE)
    assert base_run[0] == 0 and "replacing" not in base_run[1]    # a first run into a new folder
    out = _copy_run(base_run, tmp_path / "out")                   # ... left this folder
    assert main(["run", str(scene), "--out", str(out), "--no-figures"]) == 0
    assert capsys.readouterr().out.startswith(f"kinred run: replacing the previous run in {out};")
    (out / "notes.txt").write_text("mine")
    assert main(["run", str(scene), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"kinred: error: InvalidInput: --out {out}")
    assert "notes.txt" in err and "kinred did not write" in err
    assert (out / "notes.txt").read_text() == "mine" and (out / "summary.json").exists()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 2    # --resume too
    # a folder holding the result of another command
    other = tmp_path / "other"
    other.mkdir()
    (other / ".kinred-result.json").write_text('{"command": "cost", "files": []}')
    (other / "cost.json").write_text("{}")
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(other)]) == 2
    assert "holds the result of `kinred cost`" in capsys.readouterr().err
    assert (other / "cost.json").exists()
    # an output path that is a file
    assert main(["run", str(scene), "--out", str(scene)]) == 2
    assert "is a file" in capsys.readouterr().err


def test_header_explains_the_atom_count(base_run):
    """The header names N and why it is not the requested count (a tensor grid's N = ∏ N_j),
    labels ε as the a-priori quantization bound and gives T, dt, the k's and the backend."""
    from kinred.commands.run import header_lines
    from kinred.quantize import quantize

    cfg = kinetic_run.load_config(ROOT / "examples" / "scenes" / "cucker-smale-200.toml")
    q = quantize(cfg.initial_measure(), atoms=cfg.atoms)
    lines = header_lines(cfg)
    assert max(len(line) for line in lines[1:]) <= 96          # wrapped for a terminal
    text = " ".join(" ".join(lines).split())                   # wrapped lines joined back
    assert cfg.atoms == 300 and q.n_atoms < 300
    big = [c for c in q.counts if c > 1]
    assert int(np.prod(big)) == q.n_atoms
    assert f"N {q.n_atoms} atoms, asked for 300" in text
    assert f"N = ∏ N_j = " in text and f"= {q.n_atoms} ({len(big)} of 400 coordinates" in text
    assert f"ε {q.bound:.4g} (a-priori quantization bound" in text
    assert "T 30, euler dt = 0.05" in text and "k 2, 10, 50 (gaussian" in text
    assert "backend dense pair sums, precision double" in text
    assert "phase space R^400" in text
    # a mixture: the components share one accuracy, N is their sum
    cfg = kinetic_run.load_config(ROOT / "examples" / "scenes" / "dorsogna-mill-2d.toml")
    q = quantize(cfg.initial_measure(), atoms=cfg.atoms)
    text = " ".join(" ".join(header_lines(cfg)).split())
    sizes = [c.n_atoms for c in q.components]
    assert f"{len(sizes)} × {sizes[0]} = {q.n_atoms}" in text and q.n_atoms == sum(sizes)
    # the command prints it first (before the table), at the requested size
    assert base_run[0] == 0
    lines = base_run[1].splitlines()
    assert lines[0].startswith("kinred run: ") and lines[1].startswith("  d        2")
    assert any(line.startswith("  N        8 atoms, asked for 9: a tensor grid") for line in lines)
    assert "N = ∏ N_j = 2^3 = 8 (3 of 4 coordinates" in " ".join(" ".join(lines).split())


def test_default_folder(base_run):
    code, printed, _, cwd = base_run           # `kinred run tiny.toml` without --out, in cwd
    assert code == 0
    assert f"report: {Path('results/run-tiny/report.html')}" in printed
    assert (cwd / "results" / "run-tiny" / "summary.json").exists()


def test_python_m_kinred_run_subprocess(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(BASE)
    p = subprocess.run(_cli_cmd(["run", str(scene), "--out", str(tmp_path / "o")]),
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert "report:" in p.stdout and p.stderr == ""    # no progress bar when not a TTY


def test_stage_files_without_their_index_are_not_trusted(tmp_path, main, capsys, base_run):
    # stages/config.json deleted: the old loader wrote a new index for the changed scene and
    # loaded the stale stage files (a T = 0.5 run reported for a T = 1.0 scene)
    scene = tmp_path / "s.toml"
    scene.write_text(BASE)
    out = _copy_run(base_run, tmp_path / "out")      # `kinred run s.toml --out out` finished
    (out / "stages" / "config.json").unlink()
    scene.write_text(BASE.replace("t_final = 0.5", "t_final = 1.0"))
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"kinred: error: StoreMismatch: {out / 'stages'} exists and is not a stage "
                   "store (no config.json); choose a new or empty directory")
    assert sorted(p.name for p in (out / "stages").iterdir()) == ["k1.npz", "solve.npz"]


def test_no_figures_writes_the_same_numbers_and_a_note_per_figure(tmp_path, main, capsys,
                                                                    base_run):
    """``--no-figures``: the numbers of a full run bit for bit, no PNG, the report says per
    figure why it is missing; a resumed run with it removes the PNGs of the earlier run."""
    from kinred.experiments.kinetic_report import NOT_DRAWN

    scene = tmp_path / "tiny.toml"
    scene.write_text(BASE)
    out = tmp_path / "plain"
    assert main(["run", str(scene), "--out", str(out), "--no-figures"]) == 0
    full = base_run[2]
    a, b = _arrays(full / "results.npz"), _arrays(out / "results.npz")
    assert a.keys() == b.keys() and all(a[k].tobytes() == b[k].tobytes() for k in a)
    assert not list(out.glob("*.png")) and len(list(full.glob("*.png"))) == 4
    html = (out / "report.html").read_text()
    assert validate_report_html(html) == 0 and html.count(NOT_DRAWN) == 4
    resumed = _copy_run(base_run, tmp_path / "resumed")
    assert main(["run", str(scene), "--out", str(resumed), "--resume", "--no-figures"]) == 0
    assert not list(resumed.glob("*.png"))
    assert (resumed / "report.html").read_text().count(NOT_DRAWN) == 4
    assert main(["run", str(scene), "--out", str(resumed), "--resume"]) == 0   # drawn again
    assert len(list(resumed.glob("*.png"))) == 4
