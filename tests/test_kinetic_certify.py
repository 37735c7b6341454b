"""Certificates in the kinetic pipeline (issue 16): ``kinred run`` / ``demo`` / ``certify``.

Validity (measured ≤ certified at every saved time), tightness in a small demo-like scene,
the certificate is the one of ``kinred.certify`` for the pipeline's own runs, labels of every
array, diameters and the ``vacuous`` flag, the ``[certify]`` table, the notes of what is not
certified, ``kinred certify`` (output, resume, refusals) and old stage files.
"""

from __future__ import annotations

import copy
import json
import re
import textwrap

import numpy as np
import pytest

import kinred.cli as cli
from kinred.errors import ConfigError, KinredWarning
from kinred.experiments import demo, kinetic_certify, kinetic_run
from kinred.experiments.kinetic_certify import worst_ratio
from kinred.kinetic import diameter_bounds, max_pairwise_distance
from kinred.scenefile import SMALL_SCENE, config_from_dict

KINDS = {"measured", "certified bound", "a-priori bound", "estimate"}


def demo_like(d=20, atoms=60, ks=(2, 5), t_final=4.0, reference=None, **certify):
    """The demo's scene (Cucker–Smale G = 2, β = 0.5, widths 1.6·0.5ʲ) at small sizes."""
    sc = copy.deepcopy(demo.DEMO_SCENE)
    sc.pop("smoke")
    sc.pop("certify")
    sc["dynamics"]["d"] = d
    for part in ("positions", "velocities"):
        sc["initial"][part]["coordinate"][0]["repeat"] = d
    sc["quantize"] = {"atoms": atoms, **({"reference_atoms": reference} if reference else {})}
    sc["projection"]["k"] = list(ks)
    sc["integrate"].update(t_final=t_final, save_every=10)
    if certify:
        sc["certify"] = certify
    return config_from_dict(sc, source="demo-like.toml")


@pytest.fixture(scope="module")
def demo_run():
    return kinetic_run.run(demo_like(reference=90), progress=False)


# ------------------------------------------------------------------------------------------
# validity, tightness, the certificate certifies the pipeline's runs
# ------------------------------------------------------------------------------------------
def test_demo_like_scene_is_certified_valid_and_tight(demo_run):
    res = demo_run
    assert res.t[-1] == 4.0 and len(res.t) == 9
    for k, r in res.per_k.items():
        assert "bit-identical" in str(r["cert_note"]), r["cert_note"]
        # validity at every saved time: measured ≤ certified, and W1 ≤ coupling ≤ certified
        assert np.all(r["err_rms"] <= r["cert_rms"]) and np.all(r["err_max"] <= r["cert_max"])
        assert np.all(r["w1"] <= r["coupling"] + 1e-15)
        assert np.all(r["coupling"] <= r["cert_w1"]) and np.all(r["w1"] <= r["cert_w1"])
        assert not np.any(r["cert_saturated"])
        # tightness over t >= 1 (measured 1.2 and 1.7 for W1, 1.1 and 1.3 for the RMS norm)
        for cert, meas in (("cert_w1", "w1"), ("cert_rms", "err_rms"), ("cert_max", "err_max")):
            ratio = worst_ratio(r[cert], r[meas], res.t)
            assert 1.0 <= ratio <= 2.5, (k, cert, ratio)
        # the paper's a-priori bounds are billions of times larger, and vacuous
        assert r["paper_rms"][-1] > 1e6 * r["cert_rms"][-1]
        assert np.all(r["vacuous"]) and r["cert_w1"][-1] < res.high["diameter"][-1] / 10
        # the mixed bound of W1(μ_M, ν): a-priori quantization terms + certified middle term
        assert np.array_equal(r["bound_mixed"], r["term_quant"] + r["cert_w1"])


def test_stage_certificate_is_kinred_certify_of_the_pipeline_runs():
    from kinred.certify import certify
    from kinred.integrate import SaveAt
    from kinred.kinetic import compare, reduce, solve
    from kinred.projection import jl_matrix

    cfg = demo_like(d=10, atoms=30, t_final=2.0)
    sol = solve(cfg.scene(), cfg.initial_measure(), atoms=30, t_span=(0, 2), dt=0.05,
                save_every=10)
    M = jl_matrix(3, 10, seed=4)
    red = reduce(sol, M=M)
    w1 = compare(sol, red).w1
    T = len(sol.t)
    out = kinetic_certify.certify_stage(cfg, sol, red, M, kinetic_certify.decide(cfg, sol),
                                        w1=w1, term_quant=np.zeros(T), bound=np.zeros(T),
                                        diameter=np.ones(T))
    cert = certify(sol.scene, M, sol.x[0], sol.v[0], t_span=(0, 2), dt=0.05,
                   save=SaveAt(every=10))
    assert np.array_equal(cert.t, sol.t)
    for mine, theirs in (("cert_rms", "bound"), ("cert_max", "bound_max"), ("cert_w1", "w1_bound"),
                         ("err_rms", "error"), ("err_max", "error_max"),
                         ("paper_rms", "paper_bound")):
        assert np.array_equal(out[mine], getattr(cert, theirs)), mine
    # the measured errors agree with a direct evaluation from the two solutions
    rms, mx = kinetic_certify.measured_errors(sol, red)
    np.testing.assert_allclose(out["err_rms"], rms, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(out["err_max"], mx, rtol=1e-12, atol=1e-15)
    # a reduced run that is not the certificate's is refused, not certified
    other = reduce(sol, M=M, dt=0.025)
    bad = kinetic_certify.certify_stage(cfg, sol, other, M, kinetic_certify.decide(cfg, sol),
                                        w1=w1, term_quant=np.zeros(T), bound=np.zeros(T),
                                        diameter=np.ones(T))
    assert "differ from the pipeline's" in str(bad["cert_note"])
    assert np.all(np.isnan(bad["cert_w1"])) and np.all(np.isfinite(bad["err_rms"]))


# ------------------------------------------------------------------------------------------
# labels, summary, table
# ------------------------------------------------------------------------------------------
def test_every_array_has_a_label(demo_run, tmp_path):
    res = demo_run
    assert set(kinetic_run.LABELS.values()) == KINDS
    names = set(res.high) | {n for r in res.per_k.values() for n in r}
    missing = names - set(kinetic_run.LABELS) - set(kinetic_run.NOT_NUMBERS)
    assert not missing, missing
    assert kinetic_run.LABELS["cert_w1"] == "certified bound"
    assert kinetic_run.LABELS["w1"] == kinetic_run.LABELS["err_rms"] == "measured"
    assert kinetic_run.LABELS["bound"] == kinetic_run.LABELS["paper_rms"] == "a-priori bound"
    assert kinetic_run.LABELS["w1_reference"] == "estimate"
    # summary.json carries them and the certificate's numbers
    from kinred.io import ResultFolder

    folder = ResultFolder(tmp_path / "out")
    kinetic_run.write_outputs(res, folder, figures=False)
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["labels"] == {n: kinetic_run.LABELS[n] for n in names
                           if n not in kinetic_run.NOT_NUMBERS}
    for k, r in res.per_k.items():
        pk = s["per_k"][str(k)]
        assert pk["certified"] and pk["cert_valid"] and pk["vacuous"]
        assert pk["cert_w1_final"] == float(r["cert_w1"][-1])
        assert pk["cert_ratio_max"] == worst_ratio(r["cert_w1"], r["w1"], res.t) <= 2.5
    assert s["high"]["diameter_final"] == float(res.high["diameter"][-1])
    arrays = np.load(tmp_path / "out" / "results.npz")
    assert str(arrays["k2_cert_note"]).startswith("certified")
    # the terminal table: labelled columns, the a-priori bound marked vacuous
    text = res.table().to_text()
    for needle in ("W1(T) measured", "W1(T) certified bound", "certified/measured, max t≥1",
                   "eq. (4.17)(T) a-priori bound", "W1(μ_M,ν)(T) estimate", "(vacuous)"):
        assert needle in text, needle


# ------------------------------------------------------------------------------------------
# diameters
# ------------------------------------------------------------------------------------------
def test_diameter_bounds_bracket_the_diameter():
    lo, up = diameter_bounds(np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 1.0]]))
    assert lo == 5.0 and 5.0 <= up <= 5.0 * (1 + 1e-12)
    assert diameter_bounds(np.ones((1, 3))) == (0.0, 0.0)
    rng = np.random.default_rng(3)
    for n, m in ((50, 2), (300, 40), (200, 7)):
        Z = rng.standard_normal((n, m)) * rng.random(m) + 5.0
        exact = max_pairwise_distance(Z)
        lo, up = diameter_bounds(Z)
        assert lo <= exact * (1 + 1e-12) and exact <= up <= 2.0 * exact * (1 + 1e-12)
        assert lo >= 0.8 * exact         # the double sweep is close (measured ≥ 0.95)
    # a regular simplex: every pair at the same distance, upper at most 2x the diameter
    E = np.eye(6) * np.sqrt(0.5)
    lo, up = diameter_bounds(E)
    assert lo == pytest.approx(1.0) and 1.0 <= up <= 2.0


def test_high_diameter_and_vacuous(demo_run):
    res = demo_run
    up, lo = res.high["diameter"], res.high["diameter_lower"]
    assert up.shape == lo.shape == res.t.shape and np.all(lo <= up) and np.all(up <= 2 * lo)
    for r in res.per_k.values():
        assert np.array_equal(r["vacuous"], r["bound"] > up)


def test_theorem_bound_above_the_exact_diameter_limit_stays_an_upper_bound(monkeypatch):
    from kinred.kinetic import _bounds, reduce, solve, theorem_bound
    from kinred.projection import jl_matrix

    cfg = demo_like(d=6, atoms=40, t_final=1.0)
    sol = solve(cfg.scene(), cfg.initial_measure(), atoms=40, t_span=(0, 1), dt=0.05,
                save_every=10)
    red = reduce(sol, M=jl_matrix(2, 6, seed=1))
    exact = theorem_bound(sol, red)
    monkeypatch.setattr(_bounds, "EXACT_DIAMETER_MAX", 10)
    upper = theorem_bound(sol, red)
    assert "O(N d) upper bounds" in upper.note and "O(N d)" not in exact.note
    assert np.all(upper.alpha >= exact.alpha) and np.all(upper.diam_v >= exact.diam_v)
    # eps_JL: the operator bound max(1 - s_min, s_max - 1) (k < d: s_min = 0), above every pair's
    assert "operator bound" in upper.note
    s = np.linalg.svd(np.asarray(jl_matrix(2, 6, seed=1)), compute_uv=False)
    assert np.allclose(upper.eps_jl, max(1.0, s.max() - 1.0), rtol=1e-9)
    assert np.all(upper.eps_jl >= exact.eps_jl) and np.all(exact.eps_jl > 0.01)
    assert np.all(upper.bound >= exact.bound) and np.all(upper.bound <= 1e3 * exact.bound)


# ------------------------------------------------------------------------------------------
# the [certify] table and what is not certified
# ------------------------------------------------------------------------------------------
def _small(**over):
    sc = copy.deepcopy(SMALL_SCENE)
    for key, val in over.items():
        sc[key] = {**sc.get(key, {}), **val} if isinstance(val, dict) else val
    return config_from_dict(sc, source="s.toml")


def _notes(res):
    return {k: str(r["cert_note"]) for k, r in res.per_k.items()}


def test_certify_table_decides(monkeypatch):
    # absent: certified when cheap
    res = kinetic_run.run(_small(), progress=False)
    assert all(n.startswith("certified") for n in _notes(res).values())
    # false: never, the measured errors are still there
    res = kinetic_run.run(_small(certify={"enabled": False}), progress=False)
    for r in res.per_k.values():
        assert str(r["cert_note"]) == "not certified: [certify] enabled = false"
        assert np.all(np.isnan(r["cert_rms"])) and np.all(np.isfinite(r["err_rms"]))
        assert r["err_rms"][0] < 1e-14 < r["err_rms"][-1]
    # absent and too many atoms: a note saying how to certify anyway; true: certified
    monkeypatch.setattr(kinetic_certify, "AUTO_MAX_ATOMS", 10)
    res = kinetic_run.run(_small(), progress=False)
    assert all("30 atoms > 10" in n and "enabled = true" in n for n in _notes(res).values())
    res = kinetic_run.run(_small(certify={"enabled": True}), progress=False)
    assert all(n.startswith("certified") for n in _notes(res).values())
    # a non-Euler method: a note when absent, refused when asked for
    res = kinetic_run.run(_small(integrate={"method": "rk4"}), progress=False)
    assert all("forward Euler only" in n for n in _notes(res).values())
    with pytest.raises(ConfigError, match="certify.enabled: the certificate covers the forward"):
        _small(integrate={"method": "rk4"}, certify={"enabled": True})


def test_uncertifiable_scenes_give_a_note_not_a_crash():
    morse = {"d": 3, "effect": [{"type": "morse", "Ca": 1.0, "la": 1.0, "Cr": 0.5, "lr": 0.5}]}
    res = kinetic_run.run(_small(dynamics=morse), progress=False)
    for r in res.per_k.values():
        assert "not covered by certificates" in str(r["cert_note"]), r["cert_note"]
        assert np.all(np.isnan(r["cert_w1"])) and np.all(np.isfinite(r["w1"]))
    with pytest.warns(KinredWarning, match=r"s\.toml: certify\.enabled: not certified: the scene "
                                           r"is not covered"):
        kinetic_run.run(_small(dynamics=morse, certify={"enabled": True}), progress=False)
    rbm = {"pairsum": {"method": "random_batch", "p": 2}}
    res = kinetic_run.run(_small(dynamics=rbm), progress=False)
    assert all("is approximate" in n for n in _notes(res).values())


def test_noise_is_not_certified():
    # scene files have no noise; the pipeline's functions on a noisy solution
    from kinred.dynamics import Alignment, CuckerSmale, Noise, Scene
    from kinred.kinetic import compare, reduce, solve
    from kinred.projection import jl_matrix

    cfg = _small()
    scene = Scene([Alignment(CuckerSmale(1.0, 0.5)), Noise(0.01)])
    sol = solve(scene, cfg.initial_measure(), atoms=20, t_span=(0, 1), dt=0.1, save_every=5,
                method="euler_maruyama", seed=1)
    M = jl_matrix(2, 3, seed=0)
    red = reduce(sol, M=M)
    decision = kinetic_certify.decide(cfg, sol)
    assert not decision.on and "noise is excluded" in decision.note
    T = len(sol.t)
    for dec in (decision, kinetic_certify.Decision(True, "", True)):   # forced: caught too
        out = kinetic_certify.certify_stage(cfg, sol, red, M, dec, w1=compare(sol, red).w1,
                                            term_quant=np.zeros(T), bound=np.zeros(T),
                                            diameter=np.ones(T))
        assert "noise is excluded" in str(out["cert_note"]), out["cert_note"]
        assert np.all(np.isnan(out["cert_rms"])) and np.all(np.isfinite(out["err_rms"]))


# ------------------------------------------------------------------------------------------
# the command line, resume, old stage files
# ------------------------------------------------------------------------------------------
SCENE = """
title = "tiny"
[dynamics]
d = 4
[[dynamics.effect]]
type = "alignment"
G = 2.0
beta = 0.5
[initial.positions]
[[initial.positions.coordinate]]
dist = "uniform"
params = {loc = -0.8, scale = 1.6}
repeat = 4
decay = 0.5
[initial.velocities]
[[initial.velocities.coordinate]]
dist = "uniform"
params = {loc = -0.8, scale = 1.6}
repeat = 4
decay = 0.5
[quantize]
atoms = 24
[projection]
k = [1, 2]
[integrate]
dt = 0.05
t_final = 2.0
save_every = 10
"""


@pytest.fixture
def main(monkeypatch):
    if "kinred.commands.certify" not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES",
                            cli.COMMAND_MODULES + ("kinred.commands.certify",))
    return cli.main


def test_kinred_certify_prints_verdicts_and_resumes(tmp_path, main, capsys):
    scene = tmp_path / "tiny.toml"
    scene.write_text(textwrap.dedent(SCENE))
    out = tmp_path / "out"
    assert main(["certify", str(scene), "--out", str(out)]) == 0
    first = capsys.readouterr().out
    for needle in ("kinred certify: tiny: d = 4, N = 24 atoms", "weighted RMS error",
                   "max error over atoms", "Theorem 4.3's middle term", "certified bound",
                   "a-priori bound eq. (2.18)", "k=1: valid: measured ≤ certified bound at all "
                   "5 saved times", "k=2: valid:", ": tight (≤ 10×)",
                   f"report: {out / 'report.html'}"):
        assert needle in first, (needle, first)
    s = json.loads((out / "summary.json").read_text())
    assert all(r["cert_valid"] and r["cert_ratio_max"] <= 10 for r in s["per_k"].values())
    # --resume loads every stage and prints the same numbers; --norm picks what is printed
    assert main(["certify", str(scene), "--out", str(out), "--resume", "--norm", "rms",
                 "--no-figures"]) == 0
    again = capsys.readouterr().out
    assert "solve: loaded, k1: loaded, k2: loaded" in again
    assert "max error over atoms" not in again
    verdicts = [ln for ln in first.splitlines() if re.match(r"k=\d+: ", ln)]
    assert len(verdicts) == 2
    assert verdicts == [ln for ln in again.splitlines() if re.match(r"k=\d+: ", ln)]
    # without --resume the previous run is replaced (said in one line); a scene it cannot
    # certify: status 2, no work
    assert main(["certify", str(scene), "--out", str(out), "--no-figures"]) == 0
    assert "replacing the previous run" in capsys.readouterr().out
    bad = tmp_path / "rk4.toml"
    bad.write_text(textwrap.dedent(SCENE).replace("dt = 0.05", 'method = "rk4"\ndt = 0.05'))
    assert main(["certify", str(bad), "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert "cannot certify: the certificate covers forward Euler only" in err
    assert not (tmp_path / "o2").exists()


def test_scene_file_certify_table_through_kinred_run(tmp_path, monkeypatch, capsys):
    scene = tmp_path / "tiny.toml"
    scene.write_text(textwrap.dedent(SCENE) + "\n[certify]\nenabled = true\nnorm = \"rms\"\n")
    if "kinred.commands.run" not in cli.COMMAND_MODULES:
        monkeypatch.setattr(cli, "COMMAND_MODULES", cli.COMMAND_MODULES + ("kinred.commands.run",))
    assert cli.main(["run", str(scene), "--out", str(tmp_path / "o"), "--no-figures"]) == 0
    printed = capsys.readouterr().out
    assert "W1(T) certified bound" in printed and "not certified" not in printed
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert all(r["certified"] and r["cert_valid"] for r in s["per_k"].values())


def test_old_k_stage_files_are_recomputed(tmp_path):
    from kinred.io import atomic_write_npz, read_npz

    cfg = _small()
    out = tmp_path / "o"
    kinetic_run.run(cfg, out_dir=out, progress=False, figures=False)
    stage = out / "stages" / "k1.npz"
    old = {k: v for k, v in read_npz(stage).items() if k not in kinetic_certify.CERT_KEYS}
    atomic_write_npz(stage, old)                        # a k stage written before issue 16
    with pytest.warns(KinredWarning, match=r"k1\.npz"):
        res = kinetic_run.run(cfg, out_dir=out, resume=True, progress=False, figures=False)
    assert res.stages == {"solve": "loaded", "k1": "computed", "k2": "loaded"}
    assert str(res.per_k[1]["cert_note"]).startswith("certified")
