"""Hard cases: coincident agents, huge translations, extreme beta, N = 1, d = 1, k >= d, 1e-30."""

import numpy as np
import pytest

from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene,
                             SelfPropulsion)
from kinred.integrate import SaveAt, simulate
from kinred.observables import gamma


def _data(N, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (N, d)), rng.uniform(-1, 1, (N, d))


def test_coincident_agents_with_morse():
    x0, v0 = _data(20, 3)
    x0[5:10] = x0[0]                     # six agents at the same point
    sc = Scene([AttractionRepulsion(Morse()), SelfPropulsion(1.0, 0.5)], "mean", block=4)
    dv = sc.rhs(x0, v0)[1]
    ref = Scene([AttractionRepulsion(Morse()), SelfPropulsion(1.0, 0.5)], "mean",
                engine="numpy").rhs(x0, v0)[1]
    assert np.all(np.isfinite(dv)) and np.max(np.abs(dv - ref)) < 1e-12 * np.max(np.abs(ref))
    tr = simulate(sc, x0, v0, (0, 1), 0.01, save=SaveAt(every=100, states=True))
    assert np.all(np.isfinite(tr.x))


def test_huge_translation_changes_gamma_by_less_than_1e_8():
    x0, v0 = _data(150, 20, seed=1)
    shift = np.random.default_rng(2).normal(size=20)
    shift *= 1e6 / np.linalg.norm(shift)
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum")
    a = simulate(sc, x0, v0, (0, 30), 0.02, save=SaveAt(every=50))
    b = simulate(sc, x0 + shift, v0, (0, 30), 0.02, save=SaveAt(every=50))
    ga, gb = a.observables["gamma"], b.observables["gamma"]
    assert ga[-1] < 1e-20                              # it flocks far past 1e-8
    mask = ga > 1e-25
    assert np.max(np.abs(ga[mask] - gb[mask]) / ga[mask]) < 1e-8


@pytest.mark.parametrize("beta", [0.0, 0.5, 1.62, 5.0, 10.0])
def test_beta_range_and_far_agents(beta):
    x0, v0 = _data(30, 4)
    x0[0] += 1e8                         # one agent very far: g underflows to 0, no overflow
    sc = Scene([Alignment(CuckerSmale(0.8, beta))], "sum", block=8)
    fast = sc.rhs(x0, v0)[1]
    ref = Scene([Alignment(CuckerSmale(0.8, beta))], "sum", engine="numpy").rhs(x0, v0)[1]
    assert np.all(np.isfinite(fast))
    assert np.max(np.abs(fast - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_single_agent_and_one_dimension():
    sc = Scene([Alignment(CuckerSmale()), SelfPropulsion(1.0, 1.0)])
    tr = simulate(sc, np.zeros((1, 3)), np.full((1, 3), 0.1), (0, 1), 0.1,
                  save=SaveAt(states=True, every=10))
    assert tr.observables["gamma"][-1] == 0.0 and np.all(np.isfinite(tr.v))
    x0, v0 = _data(25, 1)
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5))], "mean", block=6)
    ref = Scene([Alignment(CuckerSmale(1.0, 1.5))], "mean", engine="numpy").rhs(x0, v0)[1]
    assert np.max(np.abs(sc.rhs(x0, v0)[1] - ref)) <= 1e-12 * np.max(np.abs(ref))


def test_projection_with_k_larger_than_d():
    # an isometric embedding R^3 -> R^5 preserves distances: trajectory = M x(t)
    x0, v0 = _data(20, 3)
    Q, _ = np.linalg.qr(np.random.default_rng(4).normal(size=(5, 3)))   # (5, 3), Q^T Q = I
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5)), SelfPropulsion(1.0, 0.5)], "sum")
    a = simulate(sc, x0, v0, (0, 1), 0.02, save=SaveAt(every=50, states=True))
    ps = sc.project(Q)
    b = simulate(ps, *ps.project_state(Q, x0, v0), (0, 1), 0.02,
                 save=SaveAt(every=50, states=True))
    assert np.max(np.abs(a.v @ Q.T - b.v)) < 1e-12


def test_gamma_decays_to_1e_30_and_matches_twin():
    # the paper's beta = 1.5 setting (sum normalization, G = 0.8) at reduced N
    x0, v0 = _data(60, 10, seed=5)
    kw = dict(save=SaveAt(every=25, states="v"))
    fast = simulate(Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum", block=16), x0, v0,
                    (0, 30), 0.02, **kw)
    twin = simulate(Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum", engine="numpy"), x0, v0,
                    (0, 30), 0.02, **kw)
    gf, gt = fast.observables["gamma"], twin.observables["gamma"]
    assert gf[-1] < 1e-28
    # Gamma recomputed from the saved states agrees with the recorded one
    assert gamma(fast.v[-1]) == pytest.approx(gf[-1], rel=1e-12)
    # the fast engine and its twin agree while Gamma decays over 28 decades
    assert np.max(np.abs(np.log10(gf) - np.log10(gt))) < 0.05
    mask = gt > 1e-12
    assert np.max(np.abs(gf[mask] - gt[mask]) / gt[mask]) < 1e-9


# ==========================================================================================
# CLI and files (issue 14): hostile inputs to `kinred run` / `kinred quantize` / `kinred paper`,
# damaged result folders on --resume, figures that cannot be drawn. Each test runs the CLI in
# this process and checks rc 2 with one line `kinred: error: ...` naming the path, or that the
# run finishes with its numbers on disk.
# ==========================================================================================
import json  # noqa: E402
import os  # noqa: E402
import re  # noqa: E402
from pathlib import Path  # noqa: E402

import kinred.cli as cli  # noqa: E402
from kinred.report import validate_report_html  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MEASURE = ROOT / "examples" / "measures" / "decaying-200.toml"
TINY_SCENE = """
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
reference_atoms = 16
[projection]
k = [1, 2]
[integrate]
dt = 0.1
t_final = 0.5
"""


def _cli(args, capsys):
    """(rc, stdout, stderr) of `kinred *args` run in this process."""
    capsys.readouterr()
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _one_error_line(err, *needles):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinred: error: "), err
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    return lines[0]


@pytest.mark.parametrize("command", [["run"], ["quantize", "--atoms", "5"]], ids=["run", "quantize"])
def test_cli_input_file_is_a_directory(command, tmp_path, capsys):
    # defect 8: `kinred run DIR` raised a raw IsADirectoryError (rc 1)
    d = tmp_path / "adir"
    d.mkdir()
    rc, _, err = _cli([command[0], d, *command[1:]], capsys)
    assert rc == 2
    _one_error_line(err, "ConfigError", d, "is a directory")


@pytest.mark.parametrize("command", [["run"], ["quantize", "--atoms", "5"]], ids=["run", "quantize"])
def test_cli_input_file_not_utf8(command, tmp_path, capsys):
    # defect 9: non-UTF-8 bytes raised a raw UnicodeDecodeError (rc 1)
    f = tmp_path / "b.toml"
    f.write_bytes(b'title = "ok"\ndescription = "\xff\xfe"\n')
    rc, _, err = _cli([command[0], f, *command[1:]], capsys)
    assert rc == 2
    _one_error_line(err, "ConfigError", f, "not UTF-8", "0xff", "offset 28", "line 2")


def test_cli_quantize_out_is_a_directory(tmp_path, capsys):
    # defect 10: `--out adir` raised a raw IsADirectoryError (rc 1) after quantizing
    d = tmp_path / "adir"
    d.mkdir()
    rc, out, err = _cli(["quantize", MEASURE, "--atoms", "10", "--out", d], capsys)
    assert rc == 2 and out == ""                          # refused before any work
    _one_error_line(err, "InvalidInput", d, "is a directory")
    assert os.listdir(d) == []


def test_cli_written_files_follow_the_umask(tmp_path, capsys):
    # defect 11: `kinred quantize --out` wrote mode 0600 (its own mkstemp) whatever the umask
    umask = os.umask(0)
    os.umask(umask)
    q = tmp_path / "q.npz"
    rc, _, _ = _cli(["quantize", MEASURE, "--atoms", "10", "--out", q], capsys)
    assert rc == 0
    assert (q.stat().st_mode & 0o777) == (0o666 & ~umask)
    with np.load(q) as z:
        assert z["points"].shape == (8, 200) and abs(z["weights"].sum() - 1.0) < 1e-12
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE)
    assert _cli(["run", scene, "--out", tmp_path / "o"], capsys)[0] == 0
    for p in (tmp_path / "o").rglob("*"):
        if p.is_file():
            assert (p.stat().st_mode & 0o777) == (0o666 & ~umask), p


def _huge_bound_scene(tmp_path):
    """examples/scenes/cucker-smale-200.toml with smoke sizes run to T = 100: the bound's C(t)
    overflows to inf at T (and is ~1e248 before), while W1 stays ~1e-15."""
    text = (ROOT / "examples" / "scenes" / "cucker-smale-200.toml").read_text()
    smoke = text.index("[smoke]")
    text = text[:smoke] + ("[smoke]\natoms = 8\nreference_atoms = 12\nk = [2]\nt_final = 100.0\n"
                           "dt = 0.5\nsave_every = 50\n")
    p = tmp_path / "huge.toml"
    p.write_text(text)
    return p


def test_cli_run_with_infinite_bound_writes_summary_and_report(tmp_path, capsys):
    # defect 12: matplotlib's OverflowError on the bound figure lost summary.json and report
    scene = _huge_bound_scene(tmp_path)
    out = tmp_path / "out"
    rc, _, err = _cli(["run", scene, "--out", out, "--smoke"], capsys)
    assert rc == 0, err
    res = np.load(out / "results.npz")
    assert np.isinf(res["k2_bound"][-1]) and 1e200 < res["k2_bound"][-2] < np.inf
    assert res["k2_w1"][-1] < 1e-12
    summary = json.loads((out / "summary.json").read_text())
    assert summary["per_k"]["2"]["bound_final"] == float("inf")
    # the bound figure is drawn without its non-finite point; all four figures are in the report
    assert validate_report_html((out / "report.html").read_text()) == 4
    assert (out / "bound.png").read_bytes().startswith(b"\x89PNG")
    # the numbers are written before anything is drawn
    mtime = {p.name: p.stat().st_mtime_ns for p in out.iterdir() if p.is_file()}
    assert mtime["results.npz"] <= mtime["summary.json"]
    assert mtime["summary.json"] <= min(t for n, t in mtime.items() if n.endswith((".png", ".html")))


def test_cli_figure_that_cannot_be_drawn_becomes_a_note(tmp_path, capsys, monkeypatch):
    # defect 12, the guard: whatever makes a figure fail, the run and the report are kept
    import matplotlib.figure

    real_savefig = matplotlib.figure.Figure.savefig

    def savefig(fig, *args, **kwargs):
        if any("Theorem 4.3" in ax.get_title() for ax in fig.axes):
            raise OverflowError("cannot convert float infinity to integer")
        return real_savefig(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE)
    out = tmp_path / "out"
    rc, _, err = _cli(["run", scene, "--out", out], capsys)
    assert rc == 0, err
    assert re.search(r"^kinred: warning: figure bound\.png could not be drawn \(OverflowError: "
                     r"cannot convert float infinity to integer\)", err, re.M), err
    assert (out / "summary.json").exists() and (out / "results.npz").exists()
    assert not (out / "bound.png").exists() and (out / "w1_vs_time.png").exists()
    html = (out / "report.html").read_text()
    assert validate_report_html(html) == 3                 # the other three are embedded
    assert ("Figure bound.png (The right-hand side of eq. (4.17) with the proof&#x27;s constants) "
            "could not be drawn: OverflowError: cannot convert float infinity to integer") in html
    # --resume loads every stage and draws the same report again
    rc, _, err = _cli(["run", scene, "--out", out, "--resume"], capsys)
    assert rc == 0 and "bound.png could not be drawn" in err
    assert set(json.loads((out / "summary.json").read_text())["stages"].values()) == {"loaded"}


def _arrays(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files if not k.endswith("_time")}   # timings differ


def test_cli_resume_recomputes_damaged_stage_files(tmp_path, capsys):
    # defect 13: a truncated stage file made --resume die with a raw zipfile.BadZipFile
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE)
    ref, out = tmp_path / "ref", tmp_path / "out"
    assert _cli(["run", scene, "--out", ref], capsys)[0] == 0
    assert _cli(["run", scene, "--out", out], capsys)[0] == 0
    stages = out / "stages"
    os.truncate(stages / "k2.npz", (stages / "k2.npz").stat().st_size // 2)
    os.truncate(stages / "solve.npz", 0)
    loaded_k1 = (stages / "k1.npz").read_bytes()
    rc, _, err = _cli(["run", scene, "--out", out, "--resume"], capsys)
    assert rc == 0, err
    warned = [line for line in err.splitlines() if line.startswith("kinred: warning: ")]
    assert len(warned) == 2, err
    for line, name in zip(warned, ("solve.npz", "k2.npz")):
        assert str(stages / name) in line and "damaged stage file" in line
        assert line.endswith("; recomputing the stage")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stages"] == {"solve": "computed", "reference": "loaded", "k1": "loaded",
                                 "k2": "computed"}
    assert (stages / "k1.npz").read_bytes() == loaded_k1
    a, b = _arrays(ref / "results.npz"), _arrays(out / "results.npz")
    assert a.keys() == b.keys() and len(a) > 40
    for key in a:                                          # bitwise equal to the clean run
        assert a[key].tobytes() == b[key].tobytes(), key


@pytest.mark.parametrize("content", [b"", b'{"digest": "ab', b"\xff\xff"], ids=["empty", "cut", "bytes"])
def test_cli_resume_refuses_damaged_stage_index(content, tmp_path, capsys):
    # defect 13: an empty stages/config.json made --resume die with a raw JSONDecodeError
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE)
    out = tmp_path / "out"
    assert _cli(["run", scene, "--out", out], capsys)[0] == 0
    index = out / "stages" / "config.json"
    index.write_bytes(content)
    rc, _, err = _cli(["run", scene, "--out", out, "--resume"], capsys)
    assert rc == 2
    _one_error_line(err, "DamagedFile", index, "damaged" if content != b"\xff\xff" else "not UTF-8",
                    f"delete the folder {out}", "another output folder")


def test_cli_paper_table1_existing_folder_says_resume_flag(tmp_path, capsys):
    # a re-run without --resume into a folder holding a run told CLI users "pass resume=True"
    out = tmp_path / "t1"
    (out / "store").mkdir(parents=True)
    (out / "store" / "run.json").write_text("{}")
    rc, _, err = _cli(["paper", "table1", "--quick", "--out", out, "--executor", "serial",
                       "--no-progress"], capsys)
    assert rc == 2
    _one_error_line(err, "StoreMismatch", out / "store", "--resume")
