"""`kinred paper fig4 --quick`: the qualitative facts of the paper's Figure 4 (§3.4.2)."""

import json
import shutil

import numpy as np
import pytest

from kinred.cli import main
from kinred.errors import InvalidInput
from kinred.experiments import fig4
from kinred.experiments.fig4 import Fig4Config, _relative
from kinred.experiments.recovery_strategies import strategies
from kinred.report import validate_report_html


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("fig4")
    assert main(["paper", "fig4", "--quick", "--out", str(out)]) == 0
    return out, json.loads((out / "fig4.json").read_text())


def test_projection_error_grows_as_k_falls_and_far_below_exponential(quick):
    _, res = quick
    t = np.array(res["t"])
    errs = {int(k): np.array(v) for k, v in res["projection_error"].items()}
    ks = sorted(errs)
    assert all(errs[k][0] < 1e-12 for k in ks)          # y(0) = M x(0) exactly
    # smaller k, larger error, at every saved time after the start
    for a, b in zip(ks, ks[1:]):
        assert np.all(errs[a][1:] > errs[b][1:]), (a, b)
    # "far below exponential growth": the error grows sublinearly (concave in t), unlike the
    # t exp(At) of Theorem 3.1 -- the increments over equal time steps shrink.
    for k in ks:
        inc = np.diff(errs[k][1:])
        assert np.all(inc[1:] <= inc[:-1] * (1 + 1e-9)), k
        assert errs[k][-1] < 2 * errs[k][len(t) // 2], k
    assert errs[ks[0]].max() < 0.15  # the paper: ~14 % at its smallest k


def test_certified_bound_covers_the_projection_error(quick):
    """Left panel: each curve's certified bound (relative in the same way) is above the
    measured error at every saved time and within a factor 10 of it for t >= 1."""
    _, res = quick
    t = np.array(res["t"])
    assert set(res["projection_bound"]) == set(res["projection_error"])
    for k, e in res["projection_error"].items():
        e, b = np.array(e), np.array(res["projection_bound"][k])
        assert np.all(b >= e), k
        assert np.max(b[t >= 1] / e[t >= 1]) <= 10.0, k
        assert np.max(b[t >= 1] / e[t >= 1]) <= 2.0, k      # measured 1.27-1.50 (quick)
        assert b[0] < 1e-12                                  # round-off only at t = 0


def test_measured_curves_are_those_of_plain_projected_runs():
    """Stepping the projected runs inside the certificate observers leaves the measured
    curves bit-identical to simulating each projected scene on its own."""
    cfg = Fig4Config.quick(N=30, d=40, steps=100, record_every=20, ks=(4, 12))
    rng = np.random.default_rng(1)
    x0, v0 = rng.standard_normal((30, 40)), rng.standard_normal((30, 40))
    scene = fig4._scene(cfg)
    full, err, bound = fig4._left_panel(scene, x0, v0, cfg)
    plain = fig4._simulate(scene, x0, v0, cfg, states=True)
    assert np.array_equal(full.v, plain.v)
    for k in cfg.ks:
        (M,), (w,) = fig4._projected_runs(scene, x0, v0, cfg, k, 1, 1)
        Mv = np.einsum("tnd,kd->tnk", plain.v, M.to_dense())
        assert np.array_equal(err[k], _relative(w, Mv))
        assert np.all(bound[k] >= err[k]) and np.all(bound[k][1:] <= 3 * err[k][1:])


def test_recovery_error_decreases_as_L_grows(quick):
    _, res = quick
    errs = {int(L): np.array(v) for L, v in res["recovery_error"].items()}
    Ls = sorted(errs)
    means = [errs[L].mean() for L in Ls]
    assert all(a > b for a, b in zip(means, means[1:])), dict(zip(Ls, means))
    assert errs[Ls[-1]][0] < 1e-6  # enough rows: the sparse initial velocities are recovered exactly
    assert res["eta"] == 0.0 and res["coupling"] == "normalize='mean', G=1.0"


def test_fig4_report(quick):
    out, _ = quick
    assert validate_report_html((out / "report.html").read_text()) == 1
    assert (out / "summary.json").exists()


def test_interrupted_fig4_resumes_with_the_same_numbers(quick, tmp_path, capsys):
    """A run that lost its summary and one stage (as an interruption leaves it) resumes with
    --resume: the other stages are loaded (and said so), the numbers are those of the run."""
    src, before = quick
    out = tmp_path / "fig4"
    shutil.copytree(src, out)
    (out / "summary.json").unlink()
    (out / "stages" / "recover3.npz").unlink()
    stamp = (out / "stages" / "left.npz").stat().st_mtime_ns
    capsys.readouterr()
    assert main(["paper", "fig4", "--quick", "--out", str(out), "--resume"]) == 0
    printed = capsys.readouterr().out
    assert "stages: 13 loaded from the previous run (left, sparse, projection0" in printed
    assert "1 computed" in printed
    after = json.loads((out / "fig4.json").read_text())
    assert after["stages"]["recover3"] == "computed" and after["stages"]["left"] == "loaded"
    assert set(before["stages"].values()) == {"computed"}
    for key in ("t", "projection_error", "projection_bound", "recovery_error",
                "recovery_converged_fraction"):
        assert after[key] == before[key], key                  # bit for bit (JSON floats)
    assert (out / "stages" / "left.npz").stat().st_mtime_ns == stamp   # loaded, not rewritten
    assert (out / "summary.json").exists()


def test_relative_error_formula():
    a = np.zeros((2, 3, 4))
    b = np.ones((2, 3, 4))
    assert np.allclose(_relative(a, b), 1.0)
    assert np.allclose(_relative(2 * b, b), 1.0)
    assert np.allclose(_relative(b, b), 0.0)


def test_config_validation():
    with pytest.raises(InvalidInput, match="zero_fraction"):
        Fig4Config(zero_fraction=1.0)
    with pytest.raises(InvalidInput, match="record_every"):
        Fig4Config(steps=1501)


def test_three_strategies_table():
    """§3.3.1's three strategies at equal measurement count: L·k rows (one projection into
    ℝᴸᵏ, or L into ℝᵏ) recover far better than k rows; the table has the paper's columns."""
    res = strategies(Fig4Config.quick(N=40, d=60, steps=100), L=3, k=10)
    assert [r["rows"] for r in res.rows] == [10, 30, 30]
    e1, e2, e3 = (r["final_error"] for r in res.rows)
    assert e1 > 0.8                      # 10 rows for ~12 nonzeros in R^60: no recovery
    assert e2 < 0.5 * e1 and e3 < 0.6 * e1
    assert all(r["simulate_s"] > 0 and r["recover_s"] > 0 for r in res.rows)
    assert "L projections into R^k" in res.to_text()


def test_strategies_resume(tmp_path):
    """Strategies in stages: a lost stage is recomputed on resume, the others are loaded with
    their measured times; the errors equal the first run's."""
    cfg = Fig4Config.quick(N=30, d=40, steps=100)
    first = strategies(cfg, L=2, k=6, out_dir=tmp_path, progress=False)
    assert first.stages == {"truth": "computed", "strategy0": "computed",
                            "strategy1": "computed", "strategy2": "computed"}
    (tmp_path / "stages" / "strategy1.npz").unlink()
    again = strategies(cfg, L=2, k=6, out_dir=tmp_path, progress=False, resume=True)
    assert again.stages == {"truth": "loaded", "strategy0": "loaded", "strategy1": "computed",
                            "strategy2": "loaded"}
    for a, b in zip(first.rows, again.rows):
        assert (a["max_error"], a["final_error"]) == (b["max_error"], b["final_error"])
    assert again.rows[0]["simulate_s"] == first.rows[0]["simulate_s"]      # loaded
    assert json.loads((tmp_path / "strategies.json").read_text())["stages"] == again.stages
