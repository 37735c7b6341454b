"""The paper's Table 1 and Figures 1–3: flocking detected from projected simulations (§3.4.1).

Setting (§3.4.1 of the paper): N = 1000 agents in d = 200, x⁰ ~ U[0,1]ᵈ and v⁰ ~ U[−1,1]ᵈ
componentwise, Cucker–Smale alignment eq. (2.12)–(2.13) with g(s) = G/(1+s²)^β,
β ∈ {1.5, 1.62, 1.7}, 1500 forward-Euler steps of h = 0.02 (eq. (2.14)–(2.15)). For every β:
the original system in ℝ²⁰⁰ and, for each k ∈ {150, 100, 50, 25, 10, 5, 2}, twenty simulations
projected by independent Gaussian JL matrices (eq. (2.4)–(2.5)). Each run is classified by the
paper's rule on Γ(30): < 1e-10 flocking ("pos"), > 1e-3 no flocking ("neg"), otherwise "n/a".

Coupling convention
-------------------
The paper writes the mean 1/N in front of the sum in (2.13) but does not state G. With the mean
and G = 1 the original system never flocks in this setting (Γ stays ≈ 66). The paper's pattern
(flocking at β = 1.5 and 1.62, none at 1.7) is reproduced by the plain sum (coefficient 1 per
agent). ``kinred paper calibrate`` (docs/dynamics.md, "Calibrating G") scored 18 candidates
(G = 0.75 … 1.0, three initial-data seeds) against the paper's 24 cells; the best, G = 1.0
with data seed 2 (20/24 cells; the convention G = 1.0 averages 19.3 over the seeds, the former
default G = 0.8, seed 0 matched 18), is what :class:`Table1Config` uses by default
(``normalize="sum", G=1.0, data_seed=2``); both are recorded in ``table1.json``. The reduced
``quick`` configuration keeps the mean-field strength N·G of that setting (G = 1000/N).

Precision
---------
The study runs the engine with ``precision="mixed"`` by default (:class:`~kinred.dynamics.Scene`):
the pair sums in float32, state and integration in float64. That halves the time of the
BLAS products that make up most of the run (the full table: about 33 min in float64 on the
2-core reference machine, see the README for the measured mixed time), and it changes no
verdict: measured member by member against the float64 run, Γ(30) agrees to about 1e-4
relative or better while the verdict thresholds are decades apart. ``precision="double"``
(``kinred paper table1 --precision double``) runs everything in float64.

All members share the initial data (drawn from ``data_seed``); member ``i`` draws its projection
from ``kinred._rng.member_seed(seed, i)``, so the table does not depend on the executor or the
number of workers, and an interrupted run resumes from its results store.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._repr import result_repr
from .._validate import as_choice, as_float, as_int
from ..errors import InvalidInput

__all__ = ["Table1Config", "Table1Result", "run", "member", "PAPER_TABLE1", "format_table",
           "DEFAULT_COUPLING", "PAPER_N", "mean_field_strength", "coupling_G", "member_index"]

#: The paper's number of agents (§3.4.1); ``G`` in :data:`DEFAULT_COUPLING` is for this ``N``.
PAPER_N = 1000

#: The study's coupling convention (the paper does not state ``G``): the scene's ``normalize``,
#: ``G`` for ``N = PAPER_N`` agents, and the seed of the initial data. Chosen by ``kinred paper
#: calibrate`` (:mod:`kinred.experiments.calibrate_table1`, docs/dynamics.md "Calibrating G");
#: switching the study's convention is this one line (the docs quote it and must follow).
DEFAULT_COUPLING = ("sum", 1.0, 2)

#: Table 1 of the paper: {beta: {dim: (pos, neg, n/a)}}.
PAPER_TABLE1 = {
    1.5: {200: (1, 0, 0), 150: (20, 0, 0), 100: (20, 0, 0), 50: (20, 0, 0), 25: (20, 0, 0),
          10: (14, 0, 6), 5: (4, 4, 12), 2: (3, 8, 9)},
    1.62: {200: (1, 0, 0), 150: (20, 0, 0), 100: (20, 0, 0), 50: (13, 0, 7), 25: (1, 1, 18),
           10: (0, 18, 2), 5: (0, 19, 1), 2: (0, 18, 2)},
    1.7: {200: (0, 1, 0), 150: (0, 20, 0), 100: (0, 20, 0), 50: (0, 20, 0), 25: (0, 20, 0),
          10: (0, 20, 0), 5: (0, 20, 0), 2: (0, 20, 0)},
}


@dataclass(frozen=True)
class Table1Config:
    """Parameters of the Table 1 study (defaults: the paper's §3.4.1)."""

    N: int = 1000
    d: int = 200
    betas: tuple = (1.5, 1.62, 1.7)
    ks: tuple = (150, 100, 50, 25, 10, 5, 2)
    n_projections: int = 20
    steps: int = 1500
    dt: float = 0.02
    G: float = DEFAULT_COUPLING[1]
    normalize: str = DEFAULT_COUPLING[0]
    precision: str = "mixed"
    kind: str = "gaussian"
    seed: int = 20120101
    data_seed: int = DEFAULT_COUPLING[2]
    record_every: int = 10
    yes_below: float = 1e-10
    no_above: float = 1e-3
    figure_ks: dict = field(default_factory=lambda: {1.5: (100, 10), 1.62: (100, 25), 1.7: (100, 10)})

    def __post_init__(self):
        as_int(self.N, "N", low=1)
        as_int(self.d, "d", low=1)
        as_int(self.n_projections, "n_projections", low=1)
        as_int(self.steps, "steps", low=1)
        as_int(self.record_every, "record_every", low=1)
        as_float(self.dt, "dt", low=0.0, low_open=True)
        as_float(self.G, "G", low=0.0, low_open=True)
        as_choice(self.normalize, "normalize", ("sum", "mean"))
        as_choice(self.precision, "precision", ("mixed", "double"))
        if not self.betas:
            raise InvalidInput("betas must not be empty")
        for b in self.betas:
            as_float(b, "beta", low=0.0)
        for k in self.ks:
            as_int(k, "k", low=1)
        if self.steps % self.record_every:
            raise InvalidInput(
                f"steps must be a multiple of record_every={self.record_every}, got {self.steps}"
            )

    @classmethod
    def quick(cls, **overrides) -> "Table1Config":
        """A reduced version (N = 200, 5 projections per k) that runs in about a minute.

        G keeps the mean-field coupling strength of the full setting (:func:`coupling_G`:
        N·G with the plain sum, G itself with ``normalize="mean"``).
        """
        normalize = overrides.get("normalize", DEFAULT_COUPLING[0])
        strength = mean_field_strength(DEFAULT_COUPLING[0], DEFAULT_COUPLING[1], PAPER_N)
        base = dict(N=200, n_projections=5, ks=(100, 25, 10, 2),
                    G=coupling_G(normalize, strength, 200),
                    record_every=50,
                    figure_ks={1.5: (100, 10), 1.62: (100, 25), 1.7: (100, 10)})
        base.update(overrides)
        return cls(**base)

    def to_json(self) -> dict:
        out = dataclasses.asdict(self)
        out["betas"] = list(self.betas)
        out["ks"] = list(self.ks)
        out["figure_ks"] = {str(b): list(v) for b, v in self.figure_ks.items()}
        return out


def mean_field_strength(normalize: str, G: float, N: int) -> float:
    """The mean-field coupling strength ``K`` of ``G`` under ``normalize`` with ``N`` agents.

    Agent ``i`` feels ``Σⱼ cⱼ g(‖xᵢ − xⱼ‖)(vⱼ − vᵢ)`` (eq. (2.13)) with ``cⱼ = 1`` (``"sum"``)
    or ``1/N`` (``"mean"``), so ``"sum"`` with ``G`` is ``"mean"`` with ``K = N·G``: the same
    system in exact arithmetic. ``K`` is what stays fixed when ``N`` changes.

    Examples
    --------
    >>> mean_field_strength("sum", 0.8, 1000), mean_field_strength("mean", 800.0, 1000)
    (800.0, 800.0)
    """
    as_choice(normalize, "normalize", ("sum", "mean"))
    G = as_float(G, "G", low=0.0, low_open=True)
    N = as_int(N, "N", low=1)
    return G * N if normalize == "sum" else G


def coupling_G(normalize: str, strength: float, N: int) -> float:
    """``G`` giving the mean-field strength ``strength`` under ``normalize`` with ``N`` agents
    (the inverse of :func:`mean_field_strength`).

    Examples
    --------
    >>> coupling_G("sum", 800.0, 1000), coupling_G("sum", 800.0, 200), coupling_G("mean", 800.0, 200)
    (0.8, 4.0, 800.0)
    """
    as_choice(normalize, "normalize", ("sum", "mean"))
    K = as_float(strength, "strength", low=0.0, low_open=True)
    N = as_int(N, "N", low=1)
    return K / N if normalize == "sum" else K


def initial_data(N: int, d: int, data_seed: int):
    """§3.4.1: x⁰ ~ U[0,1]ᵈ, v⁰ ~ U[−1,1]ᵈ componentwise (the same draw for every member)."""
    rng = np.random.default_rng(data_seed)
    return rng.uniform(0.0, 1.0, (N, d)), rng.uniform(-1.0, 1.0, (N, d))


def member(params: dict, seed) -> dict:
    """One simulation of the study: the original system (``k = 0``) or a projected one.

    Top-level (picklable) member function for :func:`kinred.ensemble.run_ensemble`. A run whose
    forward Euler step blows up (:class:`~kinred.errors.SimulationDiverged`: strong couplings
    in k = 2, where projected agents crowd) has Γ = inf at every saved time and its time in
    ``diverged_at`` (NaN otherwise): it counts as "no flocking", the paper's rule on the Γ(30)
    its run would reach (as in :mod:`kinred.experiments.calibrate_table1`).
    """
    from ..dynamics import Alignment, CuckerSmale, Scene
    from ..errors import SimulationDiverged
    from ..integrate import SaveAt, simulate
    from ..projection import jl_matrix

    x0, v0 = initial_data(params["N"], params["d"], params["data_seed"])
    scene = Scene([Alignment(kernel=CuckerSmale(G=params["G"], beta=params["beta"]))],
                  normalize=params["normalize"], precision=params["precision"])
    if params["k"]:
        M = jl_matrix(params["k"], params["d"], kind=params["kind"], seed=seed)
        scene = scene.project(M)
        x0, v0 = M.apply(x0), M.apply(v0)
    t_end = params["steps"] * params["dt"]
    try:
        traj = simulate(scene, x0, v0, t_span=(0.0, t_end), dt=params["dt"], method="euler",
                        save=SaveAt(every=params["record_every"], observables=("gamma",)))
    except SimulationDiverged as exc:
        n_saved = params["steps"] // params["record_every"] + 1
        t = np.arange(n_saved) * (params["record_every"] * params["dt"])
        return {"t": t, "gamma": np.full(n_saved, np.inf), "diverged_at": float(exc.t)}
    return {"t": traj.t, "gamma": traj.observables["gamma"], "diverged_at": math.nan}


def _verdict(g: float, yes_below: float, no_above: float) -> str:
    from ..observables import flocking_verdict

    if math.isinf(g):           # a diverged run (member): the Γ(30) it would reach is > no_above
        return "neg"
    return flocking_verdict(g, yes_below=yes_below, no_above=no_above)


@dataclass(frozen=True)
class Table1Result:
    """Counts per (β, dimension), the Γ curves, and how they were obtained."""

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    config: Table1Config
    counts: dict          # {beta: {dim: (pos, neg, n/a)}}
    t: np.ndarray         # (T,)
    gamma: dict           # {beta: {dim: (n_runs, T) array}}
    wall_time: float
    executor: str
    workers: int | None
    n_loaded: int = 0     # members read back from the results store (resumed run)

    def to_json(self) -> dict:
        return {
            "config": self.config.to_json(),
            "coupling": f"normalize={self.config.normalize!r}, G={self.config.G}",
            "precision": self.config.precision,
            "counts": {str(b): {str(k): dict(zip(("pos", "neg", "n/a"), c)) for k, c in v.items()}
                       for b, v in self.counts.items()},
            "gamma_initial": {str(b): {str(k): g[:, 0].tolist() for k, g in v.items()}
                              for b, v in self.gamma.items()},
            "gamma_final": {str(b): {str(k): g[:, -1].tolist() for k, g in v.items()}
                            for b, v in self.gamma.items()},
            "wall_time_s": self.wall_time,
            "members_loaded_from_store": self.n_loaded,
            "executor": self.executor,
            "workers": self.workers,
            "paper": {str(b): {str(k): dict(zip(("pos", "neg", "n/a"), c)) for k, c in v.items()}
                      for b, v in PAPER_TABLE1.items()},
        }


def _members(cfg: Table1Config) -> list[dict]:
    common = dict(N=cfg.N, d=cfg.d, steps=cfg.steps, dt=cfg.dt, G=cfg.G, normalize=cfg.normalize,
                  precision=cfg.precision, kind=cfg.kind, data_seed=cfg.data_seed, record_every=cfg.record_every)
    out = []
    for beta in cfg.betas:
        out.append(dict(common, beta=float(beta), k=0, realization=0))
        for k in cfg.ks:
            for r in range(cfg.n_projections):
                out.append(dict(common, beta=float(beta), k=int(k), realization=r))
    return out


def member_index(cfg: Table1Config, beta: float, k: int, realization: int) -> int:
    """Index of member ``(beta, k, realization)`` in :func:`run`'s member list (``k = 0``: the
    original system, realization 0); that member projects with
    ``kinred._rng.member_seed(cfg.seed, index)``.

    Raises
    ------
    InvalidInput
        If the study has no such member.
    """
    want = (as_float(beta, "beta"), as_int(k, "k", low=0), as_int(realization, "realization", low=0))
    for i, m in enumerate(_members(cfg)):
        if (m["beta"], m["k"], m["realization"]) == want:
            return i
    raise InvalidInput(f"(beta, k, realization) must be a member of the study (betas {list(cfg.betas)}, "
                       f"ks {[0, *cfg.ks]}, realizations < {cfg.n_projections}), got {want}")


def run(cfg: Table1Config | None = None, *, out_dir=None, executor: str = "processes",
        workers: int | None = None, scheduler=None, resume: bool = False,
        progress: bool = True) -> Table1Result:
    """Run the study; with ``out_dir`` write the store, ``table1.json``, figures and report.

    Members are written to ``out_dir/store`` as they finish (resumable with ``resume=True``).
    """
    from ..ensemble import run_ensemble

    cfg = cfg or Table1Config()
    members = _members(cfg)
    store = None if out_dir is None else Path(out_dir) / "store"
    t0 = time.perf_counter()
    ens = run_ensemble(member, members, master_seed=cfg.seed, executor=executor, workers=workers,
                       scheduler=scheduler, store=store, resume=resume,
                       config=cfg.to_json(), progress=progress)
    wall = time.perf_counter() - t0
    counts: dict = {}
    gamma: dict = {}
    t = np.asarray(ens.results[0]["t"])
    for beta in cfg.betas:
        b = float(beta)
        counts[b], gamma[b] = {}, {}
        for dim, k in [(cfg.d, 0)] + [(int(k), int(k)) for k in cfg.ks]:
            idx = [i for i, m in enumerate(ens.members) if m["beta"] == b and m["k"] == k]
            g = np.stack([np.asarray(ens.results[i]["gamma"]) for i in idx])
            verdicts = [_verdict(float(gi[-1]), cfg.yes_below, cfg.no_above) for gi in g]
            counts[b][dim] = tuple(verdicts.count(v) for v in ("pos", "neg", "n/a"))
            gamma[b][dim] = g
    result = Table1Result(cfg, counts, t, gamma, wall, ens.executor, workers,
                          n_loaded=int(np.sum(ens.loaded)))
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def format_table(counts: dict, *, title: str = "") -> str:
    """The paper's layout: one block per β with columns dim | pos | neg | n/a, side by side."""
    betas = list(counts)
    blocks = []
    for b in betas:
        lines = [f"beta = {b:g}".ljust(24), "dim | pos | neg | n/a".ljust(24), "-" * 22 + "  "]
        for dim, (p, n, u) in counts[b].items():
            lines.append(f"{dim:>3} | {p:>3} | {n:>3} | {u:>3}".ljust(24))
        blocks.append(lines)
    height = max(len(b) for b in blocks)
    rows = ["".join(b[i] if i < len(b) else " " * 24 for b in blocks).rstrip() for i in range(height)]
    return ((title + "\n") if title else "") + "\n".join(rows)


def _figure(plt, result: Table1Result, n_fig: int, beta):
    cfg = result.config
    b = float(beta)
    ks = cfg.figure_ks.get(beta, cfg.figure_ks.get(b, tuple(cfg.ks[:2])))
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), layout="constrained")
    orig = result.gamma[b][cfg.d][0]
    for ax, k in zip(axes[0], ks):
        if k not in result.gamma[b]:
            ax.set_visible(False)
            continue
        for g in result.gamma[b][k]:
            ax.semilogy(result.t, np.maximum(g, 1e-300), lw=0.8, alpha=0.7)
        ax.semilogy(result.t, np.maximum(orig, 1e-300), "k--", lw=2.5, label=f"original d={cfg.d}")
        ax.set_title(f"beta={b:g}: Gamma(t), {len(result.gamma[b][k])} projections to k={k}")
        ax.set_xlabel("t")
        ax.legend(loc="best")
    dims = list(result.gamma[b])
    for ax, col, name in ((axes[1][0], 0, "initial Gamma(0)"),
                          (axes[1][1], -1, f"final Gamma({result.t[-1]:g})")):
        for pos, dim in enumerate(dims):
            vals = result.gamma[b][dim][:, col]
            ax.semilogy(np.full(vals.shape, pos), np.maximum(vals, 1e-300), "o", ms=4)
        if col == -1:
            ax.axhline(cfg.yes_below, ls="--", c="gray")
            ax.axhline(cfg.no_above, ls="--", c="gray")
        ax.set_xticks(range(len(dims)), [str(d) for d in dims])
        ax.set_xlabel("dimension")
        ax.set_title(f"beta={b:g}: {name} per dimension")
    fig.suptitle(f"Figure {n_fig} (paper §3.4.1), coupling normalize={cfg.normalize!r}, G={cfg.G:g}")
    return fig


def _figures(result: Table1Result) -> list:
    """Figures 1-3, each drawn in a guarded call (a list of :class:`kinred.report.DrawnFigure`)."""
    from ..report import draw_figure

    figs = []
    for n_fig, beta in enumerate(result.config.betas, start=1):
        name = f"figure{n_fig}_beta{float(beta):g}.png"
        figs.append(draw_figure(name, name, _figure, result, n_fig, beta))
    return figs


def write_outputs(result: Table1Result, out_dir) -> Path:
    """Write ``gamma.npz``, ``table1.txt``, ``table1.json`` and ``summary.json``, then the
    figures and ``report.html`` to ``out_dir`` (a figure that cannot be drawn becomes a note
    in the report). Returns the path of ``summary.json``."""
    from ..io import ResultFolder
    from ..report import Report, Table

    folder = ResultFolder(out_dir)
    cfg = result.config
    folder.write_npz("gamma.npz", {f"beta{b:g}_dim{k}": g for b, v in result.gamma.items()
                                   for k, g in v.items()} | {"t": result.t})
    text = format_table(result.counts, title=f"Table 1 (kinred, coupling normalize={cfg.normalize!r}, "
                                             f"G={cfg.G:g}, precision={cfg.precision})")
    paper = format_table({b: v for b, v in PAPER_TABLE1.items() if b in result.counts},
                         title="Table 1 (paper)")
    folder.write_text("table1.txt", text + "\n\n" + paper + "\n")
    folder.write_json("table1.json", result.to_json())
    summary = folder.mark_complete({"study": "table1", "wall_time_s": result.wall_time,
                                    "counts": result.to_json()["counts"]})
    figs = _figures(result)
    rep = Report("kinred: the paper's Table 1 (§3.4.1)",
                 subtitle=f"N={cfg.N}, d={cfg.d}, {cfg.n_projections} {cfg.kind} projections per k, "
                          f"{cfg.steps} Euler steps of {cfg.dt}, coupling normalize={cfg.normalize!r}, "
                          f"G={cfg.G:g}, precision {cfg.precision}; wall time {result.wall_time:.1f} s "
                          f"({result.executor}).")
    sec = rep.section("Flocking verdicts", [
        "pos: Gamma(T) < %g, neg: Gamma(T) > %g, n/a otherwise (the paper's rule)." % (cfg.yes_below, cfg.no_above)])
    for b, v in result.counts.items():
        paper_b = PAPER_TABLE1.get(b, {})
        sec.tables.append(Table(["dim", "pos", "neg", "n/a", "paper pos", "paper neg", "paper n/a"],
                                [[k, *c, *paper_b.get(k, ("", "", ""))] for k, c in v.items()],
                                caption=f"beta = {b:g}"))
    figsec = rep.section("Figures 1-3")
    for drawn in figs:
        if drawn.png is not None:
            folder.write_bytes(drawn.name, drawn.png)
        figsec.add_drawn(drawn)
    folder.write_text("report.html", rep.to_html())
    return summary
