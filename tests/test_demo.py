"""``kinred demo`` (the main job) at smoke size, and its built-in configuration."""

import json
import subprocess
import sys

import numpy as np

import kinred.cli as cli
from kinred.experiments import demo
from kinred.quantize import quantize
from kinred.report import validate_report_html


def test_demo_smoke_through_cli(tmp_path, capsys):
    assert "kinred.commands.demo" in cli.COMMAND_MODULES
    out = tmp_path / "demo"
    assert cli.main(["demo", "--smoke", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.strip().splitlines()[-1] == f"report: {out / 'report.html'}"
    assert "What this shows:" in text and "certified bound" in text and "flocking verdicts" in text
    assert validate_report_html((out / "report.html").read_text()) == 4
    s = json.loads((out / "summary.json").read_text())
    assert s["ks"] == [2, 5] and s["high"]["verdict"] in ("pos", "neg", "n/a")
    for r in s["per_k"].values():
        assert r["all_exact"] and r["under_term_jl"] and r["under_bound"]
    # running it again (`make demo` twice) replaces the previous demo, and says so; so does a
    # demo folder written before the marker file existed
    (out / ".kinred-result.json").unlink()
    assert cli.main(["demo", "--smoke", "--out", str(out)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == (
        f"kinred demo: replacing the previous run in {out}; use --resume to continue it")
    s2 = json.loads((out / "summary.json").read_text())
    assert set(s2["stages"].values()) == {"computed"}
    assert np.isclose(s2["per_k"]["2"]["w1_final"], s["per_k"]["2"]["w1_final"], rtol=0, atol=0)
    # --resume loads every stage of the finished demo
    assert cli.main(["demo", "--smoke", "--out", str(out), "--resume"]) == 0
    assert "replacing" not in capsys.readouterr().out
    s3 = json.loads((out / "summary.json").read_text())
    assert set(s3["stages"].values()) == {"loaded"} and s3["per_k"] == s2["per_k"]
    # a folder with a file kinred did not write is refused and left alone
    (out / "my-notes.md").write_text("keep")
    assert cli.main(["demo", "--smoke", "--out", str(out)]) == 2
    assert "my-notes.md" in capsys.readouterr().err
    assert (out / "my-notes.md").read_text() == "keep" and (out / "summary.json").exists()


def test_demo_defaults_are_high_dimensional_and_budgeted():
    cfg = demo.scene_config()
    assert cfg.d == 100 and cfg.ks == (2, 5, 10, 25) and cfg.reference_atoms > cfg.atoms
    q = quantize(cfg.initial_measure(), atoms=cfg.atoms)
    assert q.n_atoms <= cfg.atoms and q.k_bar < 20          # the delayed curse: few coordinates
    assert cfg.scene().normalize == "mean"


def test_python_m_kinred_demo_subprocess(tmp_path):
    # the default folder: results/demo-smoke (results/demo without --smoke), in the cwd
    p = subprocess.run([sys.executable, "-m", "kinred", "demo", "--smoke"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().endswith("report.html")
    assert (tmp_path / "results" / "demo-smoke" / "summary.json").is_file()
