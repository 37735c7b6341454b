"""Hard cases: coincident agents, huge translations, extreme beta, N = 1, d = 1, k >= d, 1e-30;
unstable explicit steps and stiff adaptive runs (issue 14)."""

import math
import signal
import time
from contextlib import contextmanager

import numpy as np
import pytest

from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Field, Morse, Noise,
                             Scene, SelfPropulsion)
from kinred.errors import InvalidInput, KinredWarning, NotConverged, SimulationDiverged
from kinred.integrate import BS32, DOPRI5, EULER, HEUN, RK4, SaveAt, simulate
from kinred.integrate._guard import energy_budget, real_stability
from kinred.observables import above_floor, gamma, gamma_floor


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
    assert not above_floor(gf[-1], gamma_floor(v0, fast.n_steps), factor=1.0)   # at the floor
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
import shutil  # noqa: E402
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


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """``kinred run`` of TINY_SCENE into a fresh folder, once per module: (exit code, stderr,
    scene, folder, umask in effect). Tests only read the folder, or change a copy of it
    (``_copy_run``)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("tiny-run")
    scene, out = tmp / "s.toml", tmp / "out"
    scene.write_text(TINY_SCENE)
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        rc = cli.main(["run", str(scene), "--out", str(out)])
    umask = os.umask(0)
    os.umask(umask)
    return rc, err.getvalue(), scene, out, umask


def _copy_run(tiny_run, dest):
    """``dest`` as ``kinred run s.toml --out dest`` leaves it: a copy of the module's run."""
    rc, err, _, out, _ = tiny_run
    assert rc == 0, err
    shutil.copytree(out, dest)
    return dest


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


def test_cli_written_files_follow_the_umask(tmp_path, capsys, tiny_run):
    # defect 11: `kinred quantize --out` wrote mode 0600 (its own mkstemp) whatever the umask
    umask = os.umask(0)
    os.umask(umask)
    q = tmp_path / "q.npz"
    rc, _, _ = _cli(["quantize", MEASURE, "--atoms", "10", "--out", q], capsys)
    assert rc == 0
    assert (q.stat().st_mode & 0o777) == (0o666 & ~umask)
    with np.load(q) as z:
        assert z["points"].shape == (8, 200) and abs(z["weights"].sum() - 1.0) < 1e-12
    rc, err, _, out, run_umask = tiny_run                  # `kinred run` under run_umask
    assert rc == 0, err
    for p in out.rglob("*"):
        if p.is_file():
            assert (p.stat().st_mode & 0o777) == (0o666 & ~run_umask), p


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
    assert re.search(r"Figure bound\.png \([^<]*\) could not be drawn: OverflowError: cannot "
                     r"convert float infinity to integer", html), "no note in place of the figure"
    # --resume loads every stage and draws the same report again
    rc, _, err = _cli(["run", scene, "--out", out, "--resume"], capsys)
    assert rc == 0 and "bound.png could not be drawn" in err
    assert set(json.loads((out / "summary.json").read_text())["stages"].values()) == {"loaded"}


def _arrays(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files if not k.endswith("_time")}   # timings differ


def test_cli_resume_recomputes_damaged_stage_files(tmp_path, capsys, tiny_run):
    # defect 13: a truncated stage file made --resume die with a raw zipfile.BadZipFile
    scene, ref = tiny_run[2], tiny_run[3]                  # ref: the clean run, read only
    out = _copy_run(tiny_run, tmp_path / "out")
    stages = out / "stages"
    os.truncate(stages / "k2.npz", (stages / "k2.npz").stat().st_size // 2)
    os.truncate(stages / "solve.npz", 0)
    loaded_k1 = (stages / "k1.npz").read_bytes()
    rc, _, err = _cli(["run", scene, "--out", out, "--resume", "--no-figures"], capsys)
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
def test_cli_resume_refuses_damaged_stage_index(content, tmp_path, capsys, tiny_run):
    # defect 13: an empty stages/config.json made --resume die with a raw JSONDecodeError
    scene = tmp_path / "s.toml"
    scene.write_text(TINY_SCENE)
    out = _copy_run(tiny_run, tmp_path / "out")
    index = out / "stages" / "config.json"
    index.write_bytes(content)
    rc, _, err = _cli(["run", scene, "--out", out, "--resume"], capsys)
    assert rc == 2
    _one_error_line(err, "DamagedFile", index, "damaged" if content != b"\xff\xff" else "not UTF-8",
                    f"delete the folder {out}", "another output folder")


def test_cli_paper_table1_existing_folder_is_replaced_and_says_resume_flag(tmp_path, capsys,
                                                                          monkeypatch):
    # a re-run without --resume into a folder holding a run told CLI users "pass resume=True";
    # now (one rule for every long command) the previous run is replaced, and the one line
    # saying so names the --resume flag
    from kinred.experiments import table1

    out = tmp_path / "t1"
    (out / "store").mkdir(parents=True)
    (out / "store" / "run.json").write_text("{}")
    seen = {}

    def fake_run(cfg, *, out_dir, resume, **kw):
        seen["store"], seen["resume"] = (out_dir / "store").exists(), resume
        raise KeyboardInterrupt

    monkeypatch.setattr(table1, "run", fake_run)
    rc, stdout, err = _cli(["paper", "table1", "--quick", "--out", out, "--executor", "serial",
                            "--no-progress"], capsys)
    assert rc == 130 and seen == {"store": False, "resume": False}
    assert stdout == (f"kinred paper table1: replacing the previous run in {out}; use --resume "
                      "to continue it\n")
    assert "rerun with --resume to continue" in err


def test_a_closed_pipe_ends_quietly(tmp_path):
    """``kinred ... | head``: the reader leaves early; no traceback, exit status 141 (SIGPIPE)."""
    import subprocess
    import sys

    code = ("import sys, kinred.cli as c\n"
            "def boom(args):\n    raise BrokenPipeError(32, 'Broken pipe')\n"
            "p = c.build_parser()\n"
            "a = p.parse_args(['quantize', 'x.toml', '--atoms', '3'])\n"
            "a._run = boom\n"
            "sys.exit(c._run(a))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300, cwd=tmp_path)
    assert p.returncode == 141 and p.stderr == "", p.stderr


# ---------------------------------------------------------------------------------------
# Divergence and endless adaptive runs (issue 14): an explicit step that is unstable for the
# scene stops with SimulationDiverged as soon as the velocity fluctuation exceeds what the
# exact flow allows; a stiff adaptive run ends in NotConverged within seconds.


@contextmanager
def _deadline(seconds):
    """Fail (instead of hanging) when the block runs longer than ``seconds``."""
    def boom(signum, frame):
        raise TimeoutError(f"still running after {seconds} s")
    old = signal.signal(signal.SIGALRM, boom)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _stiff_alignment(beta):
    return Scene([Alignment(CuckerSmale(G=1e6, beta=beta))], normalize="sum")


@pytest.mark.parametrize("beta,t1", [(0.0, 15.0), (0.5, 5.0)])
def test_unstable_euler_alignment_stops_at_the_first_step(beta, t1):
    # the audit's reproducers: the old code returned Γ = 1.2, 8e14, ..., 1e296 (reached at
    # t = 10), inf for beta = 0 and Γ = 4e28 without error for beta = 0.5
    x0, v0 = _data(50, 4)
    with pytest.raises(SimulationDiverged) as info:
        simulate(_stiff_alignment(beta), x0, v0, (0, t1), 0.5)
    e = info.value
    msg = str(e)
    assert e.step == 1 and e.t == 0.5
    assert "velocity fluctuation Γ" in msg and "grew from 1.31" in msg and "dt < 2/ρ̂" in msg
    # the hint is the Gershgorin bound 2 max_i Σ_j c_j g_ij at the initial positions; for
    # beta = 0 it is 2 G (N - 1) in closed form, and 2/that is below 2/ρ(L) = 2/(G N)
    if beta == 0.0:
        assert e.stable_dt == pytest.approx(2.0 / (2.0 * 1e6 * 49), rel=1e-12)
        assert e.stable_dt < 2.0 / (1e6 * 50)
    assert f"{e.stable_dt:.3g}" in msg


@pytest.mark.parametrize("beta", [0.0, 0.5])
def test_following_the_stable_dt_hint_runs_and_dissipates(beta):
    x0, v0 = _data(50, 4)
    sc = _stiff_alignment(beta)
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, x0, v0, (0, 5), 0.5)
    dt = info.value.stable_dt
    tr = simulate(sc, x0, v0, (0, 200 * dt), dt)          # no error
    g = tr.observables["gamma"]
    assert np.all(np.diff(g) <= 1e-12 * g[0])               # Γ never grows
    assert g[-1] < 1e-20 * g[0]                              # the stiff coupling aligns at once


def test_marginally_unstable_euler_is_stopped_before_a_wrong_verdict():
    # Table-1 setting with dt = 0.2: h·ρ > 2 at the start, Γ grows 58x and then settles at
    # about 50 (no flocking) when the exact flow flocks; the old code returned that silently
    x0, v0 = _data(200, 20)
    sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], "sum")
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, x0, v0, (0, 30), 0.2, save=SaveAt(every=50))
    e = info.value
    assert e.step <= 3 and "velocity fluctuation Γ" in str(e)
    # the hint (0.035 here) holds: the paper's dt = 0.02 is below it, and dt = 0.03 runs
    assert 0.02 < e.stable_dt < 0.2
    dt = 30 / math.ceil(30 / e.stable_dt)
    tr = simulate(sc, x0, v0, (0, 30), dt, save=SaveAt(every=10))
    assert tr.observables["gamma"][-1] < 1e-20


def test_morse_overshoot_stops_at_the_first_step():
    # Ca = 1e6: one Euler step flings the agents out of the potential (old code: Γ = 1.2e10
    # returned without error); the energy bound Γ <= Γ(0) + Ca + Cr is exceeded 10^4 times
    x0, v0 = _data(50, 4)
    sc = Scene([AttractionRepulsion(Morse(Ca=1e6))], "mean")
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, x0, v0, (0, 5), 0.5)
    msg = str(info.value)
    assert info.value.step == 1
    assert "velocity fluctuation Γ" in msg and "Morse" in msg and "dt ≲ 0.2/ω̂" in msg
    assert 0 < info.value.stable_dt < 1e-3


def test_self_propulsion_blow_up_is_caught_before_overflow():
    # old code: non-finite at step 5; now at step 1 with the quantity that grew
    x0, v0 = _data(50, 4)
    sc = Scene([AttractionRepulsion(Morse(Ca=1e6)), SelfPropulsion()], "sum")
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, x0, v0, (0, 5), 0.05)
    msg = str(info.value)
    assert info.value.step == 1 and "velocity second moment" in msg
    assert "self-propulsion" in msg and "dt*b*max|v|^2" in msg


def test_stiff_rk45_ends_in_not_converged_within_seconds():
    # the old code ran on (h ~ 7e-8, max_steps = 10^7 hard-coded): nothing after 120 s
    x0, v0 = _data(50, 4)
    t = time.perf_counter()
    with _deadline(60.0), pytest.raises(NotConverged) as info:
        simulate(_stiff_alignment(0.0), x0, v0, (0, 1), 0.5, method="rk45")
    assert time.perf_counter() - t < 30.0                   # measured 0.2-0.4 s
    msg = str(info.value)
    assert "stopped at t=" in msg and "stiff" in msg and "max_steps=100000" in msg
    assert "accepted" in msg and "rejected" in msg and "Hint:" in msg
    # the Lipschitz estimate is the spectral radius G N = 5e7 of the alignment Laplacian
    assert "ρ̂ = 5e+07" in msg


def test_adaptive_step_budget_and_floor():
    x0, v0 = _data(8, 2)
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5)), SelfPropulsion(0.5, 0.2)], "mean")
    with pytest.raises(NotConverged,
                       match=r"stopped at t=0\.\d+ of t1=1: the step budget max_steps=20 is spent"):
        simulate(sc, x0, v0, (0, 1), 0.1, method="rk45", rtol=1e-10, atol=1e-12, max_steps=20)
    # a jump of the drift at t = 0.5 cannot be stepped over within rtol = 100 eps (the floor
    # of rtol, issue 21): the step shrinks to the floor 1e-12·span
    jump = Scene([Field(lambda t, x, v: np.full_like(x, 1.0 if t < 0.5 else -1.0))])
    with pytest.warns(KinredWarning, match="below 100 machine epsilons"):
        with pytest.raises(NotConverged, match=r"at t=0\.5 of t1=1: the step size fell to "
                                               r".* below the floor 1e-12"):
            simulate(jump, np.ones((3, 2)), np.zeros((3, 2)), (0, 1), 0.1, method="rk23",
                     rtol=1e-30, atol=0.0)
    with pytest.raises(InvalidInput, match="max_steps must be >= 1, got 0"):
        simulate(sc, x0, v0, (0, 1), 0.1, method="rk45", max_steps=0)


def test_adaptive_progress_bar_counts_time(capsys):
    x0, v0 = _data(8, 2)
    sc = Scene([Alignment(CuckerSmale(1.0, 1.5))], "mean")
    simulate(sc, x0, v0, (0, 2), 0.5, method="rk45", progress=True)
    err = capsys.readouterr().err
    assert "t-t0=2/2" in err


def test_real_stability_intervals():
    # closed forms: Euler and Heun 2; every 3-stage order-3 method (BS32) 2.5127;
    # RK4 2.7853; Dormand–Prince 5(4) 3.3066
    assert real_stability(EULER) == 2.0 and real_stability(HEUN) == 2.0
    assert real_stability(BS32) == pytest.approx(2.5127, abs=1e-4)
    assert real_stability(RK4) == pytest.approx(2.7853, abs=1e-4)
    assert real_stability(DOPRI5) == pytest.approx(3.3066, abs=1e-4)


def test_legitimate_runs_pass_the_guard():
    # Table-1-like (N = 200, d = 20, G = 0.8, sum, dt = 0.02, 300 steps), a softened
    # D'Orsogna mill and self-propulsion with alignment: the guard is active and silent
    x0, v0 = _data(200, 20)
    for beta in (1.5, 1.7):
        sc = Scene([Alignment(CuckerSmale(0.8, beta))], "sum")
        assert energy_budget(sc, 200, 20) is not None
        g = simulate(sc, x0, v0, (0, 6), 0.02, save=SaveAt(every=30)).observables["gamma"]
        assert np.all(np.diff(g) <= 0)
    x0, v0 = _data(100, 2, seed=3)
    mill = Scene([AttractionRepulsion(Morse(25.0, 2.0, 50.0, 0.5, soft=0.25)),
                  SelfPropulsion(1.0, 0.5)], "mean")
    assert energy_budget(mill, 100, 2) is not None
    for method in ("euler", "rk4"):
        tr = simulate(mill, x0, v0, (0, 20), 0.05, method=method, save=SaveAt(every=100))
        # a mill: speeds near sqrt(a/b) = 1.41 around a resting centre, so Γ near a/b = 2
        assert abs(tr.observables["gamma"][-1] - 2.0) < 0.1
    sp = Scene([Alignment(CuckerSmale(1.0, 0.5)), SelfPropulsion(1.0, 0.5)], "mean")
    tr = simulate(sp, x0, 3 * v0, (0, 10), 0.01, save=SaveAt(every=100, states="v"))
    assert np.allclose(np.linalg.norm(tr.v[-1], axis=1), np.sqrt(2.0), rtol=0.05)


def test_noise_does_not_trigger_the_guard():
    # a few agents and a long Euler–Maruyama run: the noise term of the budget is an
    # expectation, the realized Γ fluctuates around it
    rng = np.random.default_rng(1)
    sc = Scene([Alignment(CuckerSmale(1.0, 0.5)), Noise(1.0)], "mean")
    assert energy_budget(sc, 3, 1) is not None
    for seed in range(3):
        simulate(sc, rng.normal(size=(3, 1)), rng.normal(size=(3, 1)), (0, 100), 0.01,
                 method="euler_maruyama", seed=seed, save=SaveAt(every=1000))


def test_adaptive_non_finite_drift_is_a_divergence():
    from kinred.dynamics import Field
    field = Field(lambda t, x, v: np.where(t > 0.3, np.nan, -v), translation_invariant=True)
    sc = Scene([Alignment(CuckerSmale(1.0, 1.0)), field])
    with pytest.raises(SimulationDiverged, match=r"t=0\.3 .*non-finite at the current state "
                                                 r"however small the step.*Field"):
        simulate(sc, *_data(3, 2), (0, 1), 0.1, method="rk45")
