"""`kinred paper calibrate`: scoring against the paper's Table 1, the study end to end, resume."""

import ast
import json
import math
from pathlib import Path

import numpy as np
import pytest

from kinred.cli import main
from kinred.errors import InvalidInput, KinredError
from kinred.experiments import calibrate_table1 as cal
from kinred.experiments import table1
from kinred.experiments.calibrate_table1 import CalibrationConfig, score_cell, score_table
from kinred.experiments.table1 import PAPER_TABLE1

#: kinred's full Table 1 under today's default (README, "Table 1, reproduced").
README_TABLE1 = {
    1.5: {200: (1, 0, 0), 150: (20, 0, 0), 100: (20, 0, 0), 50: (20, 0, 0), 25: (20, 0, 0),
          10: (1, 5, 14), 5: (0, 14, 6), 2: (0, 18, 2)},
    1.62: {200: (1, 0, 0), 150: (0, 0, 20), 100: (0, 0, 20), 50: (0, 13, 7), 25: (0, 19, 1),
           10: (0, 20, 0), 5: (0, 20, 0), 2: (0, 20, 0)},
    1.7: {200: (0, 1, 0), 150: (0, 20, 0), 100: (0, 20, 0), 50: (0, 20, 0), 25: (0, 20, 0),
          10: (0, 20, 0), 5: (0, 20, 0), 2: (0, 20, 0)},
}

#: Today's default candidate: mean-field strength K0 = N·G at the paper's N, data seed S0
#: (table1.DEFAULT_COUPLING, chosen by the calibration; the tests follow it).
K0 = table1.mean_field_strength(table1.DEFAULT_COUPLING[0], table1.DEFAULT_COUPLING[1],
                                table1.PAPER_N)
S0 = table1.DEFAULT_COUPLING[2]
S1 = 1 if S0 != 1 else 0                  # another data seed

#: A tiny study (seconds): N = 20 agents, 100 steps, two rows of k, two projections each.
TINY = dict(N=20, steps=100, ks=(25, 10), n_projections=2, betas=(1.5, 1.7),
            strengths=(60.0, 80.0), data_seeds=(0, 1))


# ----------------------------------------------------------------------------------------------
# The scoring rule on hand-made tables
# ----------------------------------------------------------------------------------------------
def test_the_papers_table_scores_24_of_24_at_any_number_of_runs():
    s = score_table(PAPER_TABLE1)
    assert (s.matches, s.n_cells, s.l1) == (24, 24, 0.0)
    tripled = {b: {k: tuple(3 * c for c in v) for k, v in rows.items()} for b, rows in PAPER_TABLE1.items()}
    s3 = score_table(tripled)
    assert (s3.matches, s3.n_cells) == (24, 24) and s3.l1 == pytest.approx(0.0, abs=1e-15)


def test_todays_full_table1_scores_17_of_24():
    s = score_table(README_TABLE1)
    # hand count: beta = 1.5 misses k = 10, 5, 2; beta = 1.62 misses k = 150, 100, 50, 25
    missed = {(c.beta, c.dim) for c in s.cells if not c.match}
    assert missed == {(1.5, 10), (1.5, 5), (1.5, 2), (1.62, 150), (1.62, 100), (1.62, 50), (1.62, 25)}
    assert (s.matches, s.n_cells) == (17, 24)
    # hand sum of the proportions' L1 distances: 1.3 + 1.0 + 1.0 (beta 1.5) + 2 + 2 + 1.3 + 1.8
    # + 0.2 + 0.1 + 0.2 (beta 1.62); every beta = 1.7 cell is exact
    assert s.l1 == pytest.approx(10.9, abs=1e-12)


def test_changing_known_cells_costs_exactly_those_cells():
    table = {b: dict(rows) for b, rows in PAPER_TABLE1.items()}
    table[1.7][200] = (1, 0, 0)            # the original at 1.7 flocks: one miss, L1 2
    table[1.62][50] = (2, 0, 1)            # 2/3 pos against 13/20: still a match, L1 1/30
    table[1.5][5] = (1, 1, 1)              # a tie never matches
    s = score_table(table)
    assert s.matches == 22
    assert s.l1 == pytest.approx(2 + 2 * (2 / 3 - 13 / 20) + (abs(1 / 3 - 4 / 20) + abs(1 / 3 - 4 / 20)
                                                              + abs(1 / 3 - 12 / 20)), abs=1e-12)
    by_cell = {(c.beta, c.dim): c for c in s.cells}
    assert by_cell[(1.5, 5)].verdict is None and not by_cell[(1.5, 5)].match
    assert by_cell[(1.62, 50)].match and by_cell[(1.62, 50)].paper_verdict == "pos"


def test_score_cell_closed_cases():
    assert score_cell((0, 0, 3), (20, 0, 0)).l1 == 2.0
    c = score_cell((1, 1, 1), (20, 0, 0))
    assert not c.match and c.l1 == pytest.approx(4 / 3, abs=1e-15)
    assert score_cell((0, 1, 0), (0, 18, 2)).match
    assert cal.plurality((0, 2, 2)) is None and cal.plurality((3, 8, 9)) == "n/a"


@pytest.mark.parametrize("call, match", [
    (lambda: score_cell((1, 2), (1, 0, 0)), "triple"),
    (lambda: score_cell((1, -1, 0), (1, 0, 0)), r"counts\[1\] must be >= 0"),
    (lambda: score_cell((0, 0, 0), (1, 0, 0)), "at least one run"),
    (lambda: score_cell((1, 0, 0), (2, 2, 0)), "unique plurality"),
    (lambda: score_cell("abc", (1, 0, 0)), "triple"),
    (lambda: score_table({}), "non-empty dict"),
    (lambda: score_table({1.6: {200: (1, 0, 0)}}), "beta of the reference table"),
    (lambda: score_table({1.5: {300: (1, 0, 0)}}), "dim must be a row"),
    (lambda: score_table({1.5: [(1, 0, 0)]}), "non-empty dict"),
])
def test_scoring_rejects_bad_input(call, match):
    with pytest.raises(InvalidInput, match=match):
        call()


# ----------------------------------------------------------------------------------------------
# Aggregation and recommendation on hand-made results (no simulation)
# ----------------------------------------------------------------------------------------------
def _fake_result(tables_by_candidate, **cfg_kw):
    cfg = CalibrationConfig(**cfg_kw)
    cands = cal.candidates(cfg)
    counts = [tables_by_candidate[(c.strength, c.data_seed)] for c in cands]
    finals = [{b: {k: [1.0] * sum(v) for k, v in rows.items()} for b, rows in t.items()} for t in counts]
    return cal.CalibrationResult(cfg, tuple(cands), tuple(counts), tuple(finals),
                                 tuple(score_table(t) for t in counts), 0.0, "serial", None)


def _one_miss():
    table = {b: dict(rows) for b, rows in PAPER_TABLE1.items()}
    table[1.7][200] = (0, 0, 1)
    return table


def test_recommendation_adopts_a_convention_that_beats_todays_on_average():
    res = _fake_result({(K0, S0): README_TABLE1, (K0, S1): README_TABLE1,
                        (900.0, S0): _one_miss(), (900.0, S1): PAPER_TABLE1},
                       strengths=(K0, 900.0), data_seeds=(S0, S1))
    conv = res.conventions()
    assert [(e["strength"], e["mean_matches"], e["min_matches"], e["max_matches"]) for e in conv] == \
        [(900.0, 23.5, 23, 24), (K0, 17.0, 17, 17)]
    assert conv[1]["default"] and conv[0]["mean_l1"] == pytest.approx(1.0)
    rec = res.recommendation()
    assert rec["adopt"] and (rec["strength"], rec["data_seed"], rec["matches"]) == (900.0, S1, 24)
    assert rec["table1_line"] == f'DEFAULT_COUPLING = ("sum", 0.9, {S1})'
    assert (rec["default_matches"], rec["default_mean_matches"]) == (17, 17.0)
    assert [res.candidates[i].data_seed for i in res.ranking()[:2]] == [S1, S0]
    text = res.to_text()
    assert f"Recommendation: adopt sum K=900 data_seed {S1} (24/24" in text
    # the paper's row of the per-cell verdicts, in the paper's layout
    paper_row = next(line for line in text.splitlines() if line.startswith("paper "))
    assert paper_row.split()[1:] == (["P"] * 6 + ["U", "U", "|"] + ["P"] * 4 + ["U", "N", "N", "N", "|"]
                                     + ["N"] * 8)


def test_recommendation_keeps_todays_default_on_a_tie():
    res = _fake_result({(K0, S0): README_TABLE1, (900.0, S0): README_TABLE1},
                       strengths=(900.0, K0), data_seeds=(S0,))
    rec = res.recommendation()
    assert not rec["adopt"] and (rec["strength"], rec["data_seed"]) == (K0, S0)
    # ... which is the line in table1.py today (its numbers; G printed as %g)
    assert rec["table1_line"].startswith("DEFAULT_COUPLING = (")
    assert ast.literal_eval(rec["table1_line"].split("=", 1)[1].strip()) == table1.DEFAULT_COUPLING
    assert "DEFAULT_COUPLING = (" in Path(table1.__file__).read_text()
    assert "keep today's default" in res.to_text()


def test_todays_default_is_always_a_candidate():
    normalize, G, seed = table1.DEFAULT_COUPLING
    t1 = table1.Table1Config()
    assert (t1.normalize, t1.G, t1.data_seed) == (normalize, G, seed)
    cands = cal.candidates(CalibrationConfig(strengths=(900.0,), data_seeds=(1,)))
    assert len(cands) == 2 and cands[-1].default and not cands[0].default
    assert (cands[-1].normalize, cands[-1].G, cands[-1].data_seed) == (normalize, G, seed)
    in_grid = cal.candidates(CalibrationConfig())
    assert sum(c.default for c in in_grid) == 1 and len(in_grid) == 18
    # at N = 200 the default keeps its mean-field strength: G = 1.0 * 1000 / 200
    assert cal.default_candidate(200).G == 5.0 == table1.Table1Config.quick().G


def test_mean_field_strength_round_trips():
    for normalize in ("sum", "mean"):
        for N in (20, 1000):
            G = table1.coupling_G(normalize, 850.0, N)
            assert table1.mean_field_strength(normalize, G, N) == pytest.approx(850.0, rel=1e-15)
    with pytest.raises(InvalidInput, match="strength must be > 0"):
        table1.coupling_G("sum", 0.0, 10)


def test_estimate_reproduces_table1s_measured_time_and_the_full_grid_fits_an_hour():
    # the Table 1 study as a calibration (20 projections, today's default only): the model is
    # fitted on that run's 1039 s on 2 cores
    as_table1 = CalibrationConfig(n_projections=20, strengths=(K0,), data_seeds=(S0,))
    assert len(cal.candidates(as_table1)) == 1
    assert cal.estimate_seconds(as_table1, 2) == pytest.approx(1039.0, rel=1e-12)
    assert 40 * 60 < cal.estimate_seconds(CalibrationConfig(), 2) <= 60 * 60


@pytest.mark.parametrize("kw, match", [
    (dict(n_projections=21), "n_projections must be <= 20"),
    (dict(n_projections=0), "n_projections must be >= 1"),
    (dict(ks=(150, 30)), "ks must be target dimensions"),
    (dict(d=100, ks=(150, 50)), "below d=100"),
    (dict(strengths=(800.0, 800.0)), "distinct"),
    (dict(strengths=(800.0, -1.0)), "strengths must be > 0"),
    (dict(strengths=()), "non-empty"),
    (dict(data_seeds=(0, -1)), "data_seeds must be >= 0"),
    (dict(normalizes=("sum", "median")), "normalizes must be one of"),
    (dict(normalizes="sum"), "non-empty sequence"),
    (dict(betas=(1.5, 1.6)), "betas must be betas of the paper"),
    (dict(steps=1501), "record_every"),
    (dict(yes_below=1e-2, no_above=1e-3), "no_above must be >="),
    (dict(precision="single"), "precision"),
])
def test_config_rejects_bad_input(kw, match):
    with pytest.raises(InvalidInput, match=match):
        CalibrationConfig(**kw)


def test_run_and_member_index_reject_bad_input(tmp_path):
    with pytest.raises(InvalidInput, match="cfg must be a CalibrationConfig"):
        cal.run(table1.Table1Config(), out_dir=tmp_path)
    with pytest.raises(InvalidInput, match="cfg must be a CalibrationConfig"):
        cal.estimate_seconds({"N": 10})
    with pytest.raises(InvalidInput, match="workers must be >= 1"):
        cal.estimate_seconds(CalibrationConfig(), 0)
    assert not any(tmp_path.iterdir())          # refused before anything is written
    with pytest.raises(InvalidInput, match="must be a member of the study"):
        table1.member_index(table1.Table1Config(), 1.5, 150, 20)
    with pytest.raises(InvalidInput, match="k must be >= 0"):
        table1.member_index(table1.Table1Config(), 1.5, -1, 0)


# ----------------------------------------------------------------------------------------------
# The study end to end (tiny sizes)
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """The TINY study, run once for the tests that read it: ``(result, its folder)``."""
    out = tmp_path_factory.mktemp("calibration")
    return cal.run(CalibrationConfig(**TINY), out_dir=out, executor="serial", progress=False), out


def test_smoke_run_writes_its_outputs(tiny_run):
    res, tmp_path = tiny_run
    assert {"calibration.json", "calibration.txt", "summary.json", "calibration.png"} <= \
        {p.name for p in tmp_path.iterdir()}
    data = json.loads((tmp_path / "calibration.json").read_text())
    n_cand = len(TINY["strengths"]) * len(TINY["data_seeds"]) + 1     # + today's default
    assert len(data["candidates"]) == n_cand == len(res.candidates)
    for c in data["candidates"]:
        for b in ("1.5", "1.7"):
            assert sum(c["counts"][b]["200"].values()) == 1
            assert [sum(c["counts"][b][k].values()) for k in ("25", "10")] == [2, 2]
        # the stored score is the score of the stored counts
        counts = {float(b): {int(k): tuple(v[x] for x in cal.VERDICTS) for k, v in rows.items()}
                  for b, rows in c["counts"].items()}
        again = score_table(counts)
        assert (again.matches, again.l1) == (c["score"]["matches"], c["score"]["l1"])
        assert c["score"]["n_cells"] == 6
    assert json.loads((tmp_path / "summary.json").read_text())["recommendation"] == data["recommendation"]
    text = (tmp_path / "calibration.txt").read_text()
    assert text == res.to_text() and f"sum K={K0:g} (G={K0 / 20:g}) seed {S0} *" in text


def test_todays_candidate_reruns_table1s_first_projections_exactly(tiny_run):
    # common random numbers: projection r of (beta, k) is Table 1's projection r of (beta, k)
    res = tiny_run[0]
    d = res.default_index
    t1 = table1.run(table1.Table1Config(N=20, steps=100, ks=(25, 10), betas=(1.5, 1.7),
                                        G=K0 / 20, data_seed=S0, record_every=50),
                    executor="serial", progress=False)
    for b in (1.5, 1.7):
        assert res.gamma_final[d][b][200] == [float(t1.gamma[b][200][0, -1])]
        for k in (25, 10):
            assert res.gamma_final[d][b][k] == [float(g) for g in t1.gamma[b][k][:2, -1]]


def test_sum_and_mean_at_the_same_strength_are_the_same_system():
    cfg = CalibrationConfig(**(TINY | dict(normalizes=("sum", "mean"), strengths=(80.0,),
                                           data_seeds=(0,), precision="double")))
    res = cal.run(cfg, executor="serial", progress=False)
    s, m = res.candidates[:2]
    assert (s.normalize, s.G, m.normalize, m.G) == ("sum", 4.0, "mean", 80.0)
    assert res.counts[0] == res.counts[1]
    for b in (1.5, 1.7):
        for row in (200, 25, 10):
            np.testing.assert_allclose(res.gamma_final[1][b][row], res.gamma_final[0][b][row], rtol=1e-9)


def test_a_diverged_run_counts_as_no_flocking(tmp_path):
    # N = 20 with today's K (G = K/20): in k = 2 the projected agents crowd and Euler's
    # h = 0.02 is unstable (the member would raise SimulationDiverged)
    cfg = CalibrationConfig(N=20, steps=100, ks=(2,), n_projections=1, betas=(1.5,),
                            strengths=(K0,), data_seeds=(S0,))
    res = cal.run(cfg, out_dir=tmp_path, executor="serial", progress=False)
    assert res.n_diverged(0) == 1
    assert res.gamma_final[0][1.5][2] == [math.inf] and res.counts[0][1.5][2] == (0, 1, 0)
    assert res.gamma_final[0][1.5][200][0] < math.inf          # the original did not diverge
    assert json.loads((tmp_path / "calibration.json").read_text())["candidates"][0]["diverged"] == 1
    # a diverged member is stored like any other and resumes as such
    again = cal.run(cfg, out_dir=tmp_path, executor="serial", progress=False, resume=True)
    assert again.n_loaded == 2 and again.gamma_final == res.gamma_final


def test_interrupted_calibration_resumes_with_the_same_numbers(tmp_path):
    cfg = CalibrationConfig(**(TINY | dict(strengths=(80.0,), data_seeds=(1,))))
    first = cal.run(cfg, out_dir=tmp_path, executor="serial", progress=False)
    members = sorted((tmp_path / "store" / "members").glob("*.npz"))
    assert len(members) == 2 * 2 * (1 + 2 * 2)
    for p in members[2:7]:
        p.unlink()
    (tmp_path / "summary.json").unlink()
    again = cal.run(cfg, out_dir=tmp_path, executor="serial", progress=False, resume=True)
    assert again.n_loaded == len(members) - 5
    assert again.counts == first.counts and again.gamma_final == first.gamma_final
    assert [s.to_json() for s in again.scores] == [s.to_json() for s in first.scores]
    assert (tmp_path / "summary.json").exists()
    with pytest.raises(KinredError):
        cal.run(cfg, out_dir=tmp_path, executor="serial", progress=False)


def test_cli_calibrate(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(CalibrationConfig, "quick",
                        classmethod(lambda cls, **kw: cls(**(TINY | dict(strengths=(80.0,),
                                                                         data_seeds=(0,)) | kw))))
    code = main(["paper", "calibrate", "--quick", "--out", str(tmp_path), "--executor", "serial",
                 "--no-progress", "--projections", "1"])
    out = capsys.readouterr().out
    assert code == 0
    assert "estimated wall time" in out and "its numbers are not the paper's" in out
    assert "Candidates, best first" in out and (tmp_path / "calibration.json").exists()
    assert json.loads((tmp_path / "calibration.json").read_text())["config"]["n_projections"] == 1
    assert main(["paper", "calibrate", "--quick", "--out", str(tmp_path / "x"), "--projections", "0"]) == 2
    assert "n_projections must be >= 1" in capsys.readouterr().err
