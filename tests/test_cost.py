"""Tests of the cost study (``kinred cost``): numbers checked against closed forms and theory."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from kinred.errors import InvalidInput, StoreMismatch
from kinred.experiments import cost
from kinred.experiments.cost import (REGISTRY, STUDIES, CostConfig, pareto_front, run,
                                     time_to_reach)
from kinred.experiments.cost._base import registry
from kinred.io import ResultFolder
from kinred.observables import FLOOR_FACTOR, above_floor, gamma_floor
from kinred.report import validate_report_html


class _CountingBar:
    """Stands in for the progress bar: counts the updates of each study."""

    def __init__(self, total, enabled):
        self.total, self.counts, self.study, self.n = total, {}, None, 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def set_postfix_str(self, name):
        self.study = name

    def update(self, n):
        self.counts[self.study] = self.counts.get(self.study, 0) + n
        self.n += n


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cost-smoke")
    bars = []

    def counting_bar(total, enabled):
        bars.append(_CountingBar(total, enabled))
        return bars[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cost, "progress_bar", counting_bar)
        result = run(CostConfig.smoke(), out_dir=out, progress=False)
    return result, ResultFolder(out), bars[0]


@pytest.fixture(scope="module")
def smoke(smoke_run):
    return smoke_run[:2]


def _slope(x, y):
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def test_result_folder_complete(smoke):
    result, folder = smoke
    assert folder.is_complete
    names = folder.list()
    for study in ("projection", "recovery", "quantization", "integrators", "w1"):
        assert f"cost_{study}.png" in names
        assert folder.read_bytes(f"cost_{study}.png").startswith(b"\x89PNG")
    assert validate_report_html(folder.read_text("report.html")) == 5
    data = folder.read_json("cost.json")
    assert set(data["headline"]) == {"projection", "precision", "recovery", "quantization",
                                     "integrators", "w1"}
    assert data["machine"]["cores"] >= 1 and data["wall_time_s"] > 0
    assert data["config"]["configs"]["recovery"]["Ls"] == [1, 3, 5]
    summary = folder.read_json("summary.json")
    assert summary["study"] == "cost" and summary["headline"]["quantization"].startswith("the delayed")
    # summary.json follows the data files and precedes the figures and the report
    mtimes = {n: (folder / n).stat().st_mtime_ns for n in names}
    assert mtimes["cost.json"] <= mtimes["cost.txt"] <= mtimes["summary.json"]
    assert mtimes["summary.json"] <= min(t for n, t in mtimes.items() if n.endswith((".png", ".html")))


def test_projection_error_decreases_with_k(smoke):
    result, _ = smoke
    p = result.studies["projection"]
    for kind in ("gaussian", "srht"):
        rs = sorted((r for r in p["summary"] if r["kind"] == kind), key=lambda r: r["k"])
        errs = [r["error_final"] for r in rs]
        assert errs[0] > errs[-1] > 0
        # JL scaling: error ~ k^(-1/2); from k = 2 to k = 30 at least a factor 2
        assert errs[0] / errs[-1] > 2.0
        for r in rs:
            assert r["error_max"] >= r["error_final"] - 1e-15
            assert 0.0 <= r["verdict_agreement"] <= 1.0 and r["time_s"] > 0
            # agreement is reported as a count of runs: "2/2", not a percentage of 2 runs
            runs = [x for x in p["runs"] if x["kind"] == kind and x["k"] == r["k"]]
            assert r["runs"] == len(runs) == 2
            assert r["verdict_agrees"] == sum(x["agrees"] for x in runs)
            assert r["verdict_agreement"] == r["verdict_agrees"] / r["runs"]
    table = REGISTRY["projection"].table(p).to_text()
    assert "verdict agrees (runs)" in table and "%" not in table
    assert f"{p['summary'][0]['verdict_agrees']}/2" in table
    assert "runs" in result.headline["projection"]["text"]
    assert "% of runs" not in result.headline["projection"]["text"]


def test_precision_knob_is_priced(smoke):
    result, _ = smoke
    fm = result.studies["projection"]["full_mixed"]
    # float32 pair sums: a small but nonzero trajectory error, the same verdict
    g_full = result.studies["projection"]["full"]["gamma_T"]
    assert 0.0 < fm["error_max"] < 1e-4, fm
    # Gamma(T) agrees relatively well above float64's round-off floor, else both sit at it
    floor = result.studies["projection"]["full"]["gamma_floor"]
    cfg = result.config.configs["projection"]
    assert floor == gamma_floor(_projection_v0(result.config), cfg.steps)
    if above_floor(g_full, floor):
        assert fm["gamma_rel_diff"] < 1e-3, (fm, g_full, floor)
    else:
        assert not above_floor(fm["gamma_T"], floor, factor=2 * FLOOR_FACTOR), (fm, floor)
    assert fm["agrees"] and fm["time_s"] > 0
    assert "precision='mixed'" in result_headline(result)


def _projection_v0(cfg):
    """The initial velocities of the projection study (the draw of its ``_Setup``)."""
    from kinred.experiments.cost import REGISTRY

    pc = cfg.configs["projection"]
    rng = REGISTRY["projection"].rng(cfg.seed)
    rng.uniform(0.0, 1.0, (pc.N, pc.d))
    return rng.uniform(-1.0, 1.0, (pc.N, pc.d))


def result_headline(result):
    from kinred.experiments.cost import headline
    return headline(result.studies, result.config)["precision"]["text"]


def test_recovery_improves_with_L(smoke):
    result, _ = smoke
    rows = result.studies["recovery"]["rows"]
    for tol in {r["tol"] for r in rows}:
        rs = sorted((r for r in rows if r["tol"] == tol), key=lambda r: r["L"])
        assert rs[-1]["error"] < 0.5 * rs[0]["error"]
        # one projection into R^10 of a vector with ~12 nonzeros in R^60 cannot recover it
        assert rs[0]["error"] > 0.3
        assert all(r["time_s"] >= r["solve_s"] > 0 for r in rs)


def test_quantization_closed_forms(smoke):
    result, _ = smoke
    q = result.studies["quantization"]
    d, rho = q["setting"]["d"], q["setting"]["rho"]
    widths = {"isotropic": np.ones(d), "decaying": rho ** np.arange(d)}
    for name, rows in q["rows"].items():
        for r in rows:
            # midpoint quantization of U[0, s] with n atoms: W1 = s/(4n); product-l1 sums them
            expect = float(np.sum(widths[name] / (4.0 * np.asarray(r["counts"]))))
            assert r["product_l1"] == pytest.approx(expect, rel=1e-9)
            assert r["n_atoms"] == int(np.prod(r["counts"])) <= r["atoms_budget"]
            if "euclidean_to_fine" in r:
                # triangle inequality + |.|_2 <= |.|_1: W1(coarse, fine) <= pl1(coarse) + pl1(fine)
                fine_n = round(q["setting"]["fine_atoms"] ** (1.0 / d))
                fine_err = float(np.sum(widths[name])) / (4.0 * fine_n) if name == "isotropic" else 1.0
                assert 0.0 < r["euclidean_to_fine"] <= r["product_l1"] + fine_err + 1e-12
    iso = [r for r in q["rows"]["isotropic"] if r["n_atoms"] > 1]
    # the curse: error ∝ N^(-1/d) on the isotropic grid
    assert _slope([r["n_atoms"] for r in iso], [r["product_l1"] for r in iso]) == pytest.approx(-1.0 / d, abs=1e-9)
    a = q["atoms_for_eps"]
    assert int(a["decaying"]) < int(a["isotropic"])


def test_integrator_orders(smoke):
    result, _ = smoke
    rows = result.studies["integrators"]["rows"]
    for method, order in (("euler", 1), ("heun", 2), ("rk4", 4)):
        rs = sorted((r for r in rows if r["method"] == method), key=lambda r: r["steps"])
        errs = [r["error"] for r in rs]
        assert all(a > b for a, b in zip(errs, errs[1:]))
        assert -_slope([r["steps"] for r in rs], errs) == pytest.approx(order, abs=0.35)
    for method in ("rk45", "rk23"):
        rs = sorted((r for r in rows if r["method"] == method), key=lambda r: -r["rtol"])
        assert rs[-1]["error"] < rs[0]["error"]
        assert rs[-1]["error"] < 100 * rs[-1]["rtol"]


def test_every_deterministic_integrator_is_priced(smoke):
    from kinred.integrate import TABLES

    result, _ = smoke
    rows = result.studies["integrators"]["rows"]
    assert {r["method"] for r in rows} == set(TABLES)
    # adaptive (swept over rtol) exactly when the Butcher table has an error estimate
    for r in rows:
        assert (r["rtol"] is not None) == (TABLES[r["method"]].E is not None), r


def test_progress_total_is_the_work_done(smoke_run):
    result, _, bar = smoke_run
    cfg = result.config
    assert bar.counts == {n: REGISTRY[n].n_units(cfg.configs[n]) for n in STUDIES}
    assert bar.total == sum(bar.counts.values()) > len(STUDIES)


def test_w1_methods_agree(smoke):
    result, _ = smoke
    rows = result.studies["w1"]["rows"]
    for n in {r["N"] for r in rows}:
        by = {r["method"]: r for r in rows if r["N"] == n}
        W = by["exact"]["value"]
        assert by["exact-lazy"]["value"] == pytest.approx(W, rel=1e-9)
        b = by["bracket"]
        assert b["lower"] <= W * (1 + 1e-9) and W <= b["upper"] * (1 + 1e-9)
        sp = by["sparse"]                                   # the sparse method's row (issue 22)
        assert sp["lower"] <= W * (1 + 1e-12) and W <= sp["upper"] * (1 + 1e-12)
        assert not sp["exact"] or sp["value"] == pytest.approx(W, rel=1e-12)


def test_pareto_and_time_to_reach():
    t = [3.0, 1.0, 2.0, 4.0]
    e = [0.01, 0.5, 0.02, 0.05]
    assert pareto_front(t, e).tolist() == [1, 2, 0]
    assert pareto_front([1.0, 2.0], [np.nan, 1.0]).tolist() == [1]
    assert time_to_reach(t, e, 0.03) == 2.0
    assert time_to_reach(t, e, 1e-3) is None


def test_config_validation():
    with pytest.raises(InvalidInput, match=r"recovery\.Ls"):
        CostConfig.smoke(recovery={"Ls": (1, 6)})
    with pytest.raises(InvalidInput, match="studies"):
        CostConfig.smoke(studies=("nope",))
    with pytest.raises(InvalidInput, match=r"projection\.steps"):
        CostConfig.smoke(projection={"steps": 55})
    with pytest.raises(InvalidInput, match="cfg"):
        run({"quick": True}, progress=False)


def test_study_settings_are_validated():
    from kinred.experiments.cost.recovery import RecoveryConfig

    with pytest.raises(InvalidInput, match="recovery has no setting 'nope'"):
        CostConfig.smoke(recovery={"nope": 1})
    with pytest.raises(InvalidInput, match="study must be one of"):
        CostConfig.smoke(recover={"Ls": (1,)})
    with pytest.raises(InvalidInput, match=r"projection\.kinds must be non-empty"):
        CostConfig.smoke(projection={"kinds": ()})
    with pytest.raises(InvalidInput, match=r"integrators\.rtols must be a tuple"):
        CostConfig.smoke(integrators={"rtols": 1e-3})
    with pytest.raises(InvalidInput, match="seed must be >= 0, got -1"):
        CostConfig(seed=-1)
    with pytest.raises(InvalidInput, match=r"configs\['w1'\] must be a W1Config"):
        CostConfig(configs={"w1": RecoveryConfig()})
    with pytest.raises(InvalidInput, match="preset must be one of"):
        CostConfig.preset("medium")
    # a per-study config replaces the preset of that study only
    cfg = CostConfig.smoke(recovery=RecoveryConfig.smoke(Ls=(1, 3)))
    assert cfg.configs["recovery"].Ls == (1, 3) and cfg.configs["w1"] == CostConfig.smoke().configs["w1"]


def test_registry_rejects_repeated_names_and_streams():
    w1 = REGISTRY["w1"]
    with pytest.raises(InvalidInput, match="repeats"):
        registry(w1, w1)
    with pytest.raises(InvalidInput, match="Study objects"):
        registry(w1, "pairsum")

    class HalfWritten(cost.Study):  # a new knob that forgot its figure and its random streams
        name, title, Config = "pairsum", "Pair sums", w1.Config
        n_units = run = table = headline = lambda self, *a, **k: None

    with pytest.raises(InvalidInput, match="HalfWritten does not define key, figure"):
        registry(w1, HalfWritten())
    assert STUDIES == tuple(registry(*REGISTRY.values()))
    assert len({s.key for s in REGISTRY.values()}) == len(REGISTRY)


def test_cli_smoke(tmp_path, capsys):
    from kinred import cli

    assert "kinred.commands.cost" in cli.COMMAND_MODULES
    argv = ["cost", "--smoke", "--only", "quantization", "w1", "--no-progress",
            "--out", str(tmp_path / "c")]
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert "delayed-curse budget" in out and "exact-lazy" in out
    # the last line says where the results went
    assert out.strip().splitlines()[-1].startswith(f"results: {(tmp_path / 'c').resolve()} ")
    folder = ResultFolder(tmp_path / "c")
    assert folder.is_complete
    assert sorted(n for n in folder.list() if n.endswith(".png")) == ["cost_quantization.png", "cost_w1.png"]
    assert validate_report_html(folder.read_text("report.html")) == 2
    first = folder.read_json("cost.json")
    assert first["stages"] == {"quantization": "computed", "w1": "computed"}
    # --resume after losing one study's stage: the other is loaded, the numbers are the same
    (tmp_path / "c" / "stages" / "w1.npz").unlink()
    (tmp_path / "c" / "summary.json").unlink()
    assert cli.main(argv + ["--resume"]) == 0
    out = capsys.readouterr().out
    again = folder.read_json("cost.json")
    assert again["stages"] == {"quantization": "loaded", "w1": "computed"}
    assert "studies loaded from the previous run: quantization" in out
    assert again["quantization"] == first["quantization"]           # bit for bit (JSON)
    assert again["study_wall_time_s"]["quantization"] == first["study_wall_time_s"]["quantization"]
    assert [r["N"] for r in again["w1"]["rows"]] == [r["N"] for r in first["w1"]["rows"]]
    assert np.allclose([r["value"] for r in again["w1"]["rows"] if r["method"] == "exact"],
                       [r["value"] for r in first["w1"]["rows"] if r["method"] == "exact"],
                       rtol=1e-12, atol=0)
    # without --resume the previous run is replaced, and the command says so
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0] == (f"kinred cost: replacing the previous run in {tmp_path / 'c'}; "
                                   "use --resume to continue it")
    assert folder.read_json("cost.json")["stages"] == {"quantization": "computed",
                                                       "w1": "computed"}


def test_resumed_run_numbers_equal(tmp_path):
    """The API: a study loaded from the store gives the numbers it was stored with."""
    cfg = CostConfig.smoke(studies=("quantization",))
    first = run(cfg, out_dir=tmp_path, progress=False)
    again = run(cfg, out_dir=tmp_path, progress=False, resume=True)
    assert again.stages == {"quantization": "loaded"} and first.stages == {"quantization": "computed"}
    assert again.studies == first.studies and again.study_times == first.study_times
    with pytest.raises(StoreMismatch, match="already holds a run"):
        run(cfg, out_dir=tmp_path, progress=False)
    with pytest.raises(StoreMismatch, match="different configuration"):
        run(CostConfig.smoke(studies=("w1",)), out_dir=tmp_path, progress=False, resume=True)


@pytest.mark.parametrize("make", [CostConfig, CostConfig.quick, CostConfig.smoke],
                         ids=["full", "quick", "smoke"])
def test_every_preset_is_a_valid_config(make):
    # each preset passes its own validation (a quick preset once did not: rec_steps=100 with
    # rec_every=125), so `kinred cost`, `--quick` and `--smoke` all start
    cfg = make()
    rec, proj = cfg.configs["recovery"], cfg.configs["projection"]
    assert rec.steps % rec.every == 0 and proj.steps % proj.every == 0
    assert pickle.loads(pickle.dumps(cfg)) == cfg
