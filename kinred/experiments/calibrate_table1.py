"""Calibrating Table 1's coupling: which convention matches the most of the paper's cells.

The paper (§3.4.1) writes the mean 1/N in front of the Cucker–Smale sum, eq. (2.13), but does
not state G, nor its initial data beyond their law. This study runs the Table 1 setting
(:mod:`kinred.experiments.table1`) for a grid of *candidates* and scores each against the
paper's 24 cells (8 rows × 3 β), so that the study's default
(:data:`~kinred.experiments.table1.DEFAULT_COUPLING`) is the best-matching convention
measured, not a guess.

Candidates
----------
A candidate is a coupling convention — the scene's ``normalize`` and the mean-field strength
``K`` — and the seed of the initial data. Its ``G`` is ``K/N`` with ``normalize="sum"`` and
``K`` with ``"mean"`` (:func:`~kinred.experiments.table1.coupling_G`). Because agent ``i``
feels ``Σⱼ cⱼ g(‖xᵢ − xⱼ‖)(vⱼ − vᵢ)`` with ``cⱼ = 1`` (sum) or ``1/N`` (mean), "sum" at
``K`` and "mean" at ``K`` are *the same system* (they differ only in rounding): the default
grid therefore spells every strength once, as ``"sum"`` (``normalizes=("sum", "mean")`` runs
both spellings, at twice the cost, and reports them side by side). Today's default
(:data:`~kinred.experiments.table1.DEFAULT_COUPLING`: ``K = 1000``, sum, ``G = 1.0`` for
``N = 1000``, ``data_seed = 2``, adopted from this study's run; before it ``K = 800``,
``data_seed = 0``) is always a candidate.

The default grid, ``K ∈ {750, 800, 850, 900, 950, 1000}`` × ``data_seed ∈ {0, 1, 2}``, brackets
the two crossings that bound the paper's pattern, measured on the original systems
(``data_seed = 0``): β = 1.62 flocks from ``K ≈ 800`` on (Γ(30) = 1.5e-7 at 750, 1.5e-11 at
800), β = 1.7 stops being "no flocking" between 900 and 1000 (Γ(30) = 0.018 at 900, 6e-6 at
1000).

Members and seeds
-----------------
For every candidate and β: the original system in ℝᵈ and ``P = n_projections`` Gaussian
projections per k. Projection ``r`` of ``(β, k)`` is Table 1's projection ``r`` of ``(β, k)``
for every candidate (seed ``member_seed(seed, table1.member_index(...))``): common random
numbers, so candidates differ only in their coupling and initial data, and today's default
candidate reruns exactly the first ``P`` projections of ``kinred paper table1``. The numbers do
not depend on the executor or the workers; members are stored as they finish (resumable).

Scoring
-------
A cell (β, row) holds the verdict counts (pos, neg, n/a) of its runs (one for the original
system, ``P`` for a projected row) by the paper's rule on Γ(30). With ``p`` the runs'
proportions and ``q`` the paper's (counts / 1 or / 20):

* the cell **matches** when the paper's plurality verdict is the *unique* plurality verdict of
  the runs (a tie among the runs never matches; the paper's 24 cells have no ties);
* its **L1 distance** is ``‖p − q‖₁ = Σ_v |p_v − q_v|`` (0 … 2).

A run whose forward Euler step (h = 0.02, as the paper's) blows up counts as "neg" — the
paper's rule on the Γ(30) its run would have reached (> 1e-3) — and is reported in the
``diverged`` column: strong couplings can make h = 0.02 unstable in k = 2, where projected
agents crowd.

A candidate scores ``matches / n_cells`` and ``L1 = Σ_cells ‖p − q‖₁``; candidates rank by
more matches, then smaller L1. A *convention* (normalize, K) aggregates its candidates over
the data seeds: mean, min and max matches, mean L1. The recommendation adopts the best
convention (by mean matches, then mean L1) only if its mean matches exceed today's
convention's, with its best data seed; otherwise today's default stays.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._validate import as_choice, as_float, as_int
from ..errors import InvalidInput
from ..projection import KINDS
from . import table1

__all__ = ["CalibrationConfig", "CalibrationResult", "Candidate", "CellScore", "TableScore",
           "ORIGINAL_ROW", "PAPER_PROJECTIONS", "default_candidate",
           "VERDICTS", "candidates", "estimate_seconds", "member", "plurality", "run",
           "score_cell", "score_table", "write_outputs"]

#: The verdicts of the paper's rule, in the order of a count triple.
VERDICTS = ("pos", "neg", "n/a")

#: The paper's original dimension: its row holds the original system (in ℝᵈ of the config).
ORIGINAL_ROW = 200

#: Projections per (β, k) in the paper (and in Table 1's member layout).
PAPER_PROJECTIONS = 20

# Cost model of one simulation, from Table 1's full run (423 simulations at N = 1000, 1500
# steps: 1039 s on 2 cores, mixed precision; README): seconds ≈ c·(dim + _DIM_OFFSET)·(N/1000)²
# ·steps/1500 + _MEMBER_OVERHEAD, with c fitted on that run.
_DIM_OFFSET = 15
_MEMBER_OVERHEAD = 0.3
_TABLE1_SECONDS, _TABLE1_CORES = 1039.0, 2


# ----------------------------------------------------------------------------------------------
# Scoring
# ----------------------------------------------------------------------------------------------
def _as_counts(counts, name: str) -> tuple[int, int, int]:
    if isinstance(counts, (str, bytes)) or not hasattr(counts, "__len__") or len(counts) != 3:
        raise InvalidInput(f"{name} must be a (pos, neg, n/a) triple of counts, got {counts!r}")
    out = tuple(as_int(c, f"{name}[{i}]", low=0) for i, c in enumerate(counts))
    if sum(out) == 0:
        raise InvalidInput(f"{name} must count at least one run, got {counts!r}")
    return out


def plurality(counts) -> str | None:
    """The verdict most runs got (``"pos"``, ``"neg"`` or ``"n/a"``), ``None`` on a tie.

    Examples
    --------
    >>> plurality((13, 0, 7)), plurality((1, 1, 1)), plurality((0, 2, 2))
    ('pos', None, None)
    """
    c = _as_counts(counts, "counts")
    top = max(c)
    return VERDICTS[c.index(top)] if c.count(top) == 1 else None


@dataclass(frozen=True)
class CellScore:
    """One cell (β, row): the runs' counts against the paper's, and how they compare."""

    beta: float
    dim: int
    counts: tuple
    paper: tuple
    verdict: str | None        # the runs' unique plurality verdict (None: a tie)
    paper_verdict: str
    match: bool
    l1: float

    def to_json(self) -> dict:
        return {"beta": self.beta, "dim": self.dim, "counts": dict(zip(VERDICTS, self.counts)),
                "paper": dict(zip(VERDICTS, self.paper)), "verdict": self.verdict,
                "paper_verdict": self.paper_verdict, "match": self.match, "l1": self.l1}


def score_cell(counts, paper, *, beta: float = math.nan, dim: int = 0) -> CellScore:
    """Compare one cell's verdict counts with the paper's (module docstring, "Scoring").

    Parameters
    ----------
    counts, paper : (pos, neg, n/a) triples of non-negative integers, at least one run each
        Any totals: proportions are compared (e.g. 3 runs against the paper's 20).
    beta, dim : float, int
        Recorded in the result only.

    Returns
    -------
    CellScore
        ``match``: the paper's plurality verdict is the runs' unique plurality verdict;
        ``l1``: the L1 distance of the proportions, in [0, 2].

    Examples
    --------
    >>> s = score_cell((2, 0, 1), (13, 0, 7))
    >>> s.match, round(s.l1, 4)
    (True, 0.0333)
    >>> score_cell((0, 0, 3), (20, 0, 0)).l1
    2.0
    """
    c, q = _as_counts(counts, "counts"), _as_counts(paper, "paper")
    pv = plurality(q)
    if pv is None:
        raise InvalidInput(f"paper must have a unique plurality verdict, got the tie {q}")
    v = plurality(c)
    l1 = float(sum(abs(a / sum(c) - b / sum(q)) for a, b in zip(c, q)))
    return CellScore(float(beta), int(dim), c, q, v, pv, v == pv, l1)


@dataclass(frozen=True)
class TableScore:
    """A table's score: matching cells out of ``n_cells`` and the summed L1 distance."""

    matches: int
    n_cells: int
    l1: float
    cells: tuple              # CellScore, in table order

    def to_json(self) -> dict:
        return {"matches": self.matches, "n_cells": self.n_cells, "l1": self.l1,
                "cells": [c.to_json() for c in self.cells]}


def score_table(counts: dict, paper: dict | None = None) -> TableScore:
    """Score a table of verdict counts against the paper's Table 1, cell by cell.

    Parameters
    ----------
    counts : dict
        ``{beta: {dim: (pos, neg, n/a)}}``; the original system in row ``200`` (the paper's
        layout, as :data:`~kinred.experiments.table1.PAPER_TABLE1`). Any subset of the
        paper's cells; each cell's runs may number anything from 1 up.
    paper : dict, optional
        The reference table, same layout (default:
        :data:`~kinred.experiments.table1.PAPER_TABLE1`).

    Returns
    -------
    TableScore

    Examples
    --------
    >>> s = score_table(table1.PAPER_TABLE1)
    >>> s.matches, s.n_cells, s.l1
    (24, 24, 0.0)
    """
    paper = table1.PAPER_TABLE1 if paper is None else paper
    if not isinstance(counts, dict) or not counts:
        raise InvalidInput(f"counts must be a non-empty dict {{beta: {{dim: (pos, neg, n/a)}}}}, "
                           f"got {counts!r}")
    cells = []
    for beta, rows in counts.items():
        b = as_float(beta, "beta")
        ref = paper.get(b) if isinstance(paper, dict) else None
        if ref is None or not isinstance(rows, dict) or not rows:
            raise InvalidInput(f"counts must hold, for a beta of the reference table "
                               f"({sorted(paper) if isinstance(paper, dict) else paper!r}), a "
                               f"non-empty dict {{dim: (pos, neg, n/a)}}; got beta={beta!r}: {rows!r}")
        for dim, c in rows.items():
            if dim not in ref:
                raise InvalidInput(f"dim must be a row of the reference table at beta={b:g} "
                                   f"({sorted(ref)}), got {dim!r}")
            cells.append(score_cell(c, ref[dim], beta=b, dim=dim))
    return TableScore(sum(c.match for c in cells), len(cells), float(sum(c.l1 for c in cells)),
                      tuple(cells))


# ----------------------------------------------------------------------------------------------
# Configuration and candidates
# ----------------------------------------------------------------------------------------------
def _distinct(values, name: str, check) -> tuple:
    if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
        raise InvalidInput(f"{name} must be a non-empty sequence, got {values!r}")
    out = tuple(check(v, name) for v in values)
    if not out or len(set(out)) != len(out):
        raise InvalidInput(f"{name} must be a non-empty sequence of distinct values, got {values!r}")
    return out


@dataclass(frozen=True)
class CalibrationConfig:
    """Parameters of the calibration study (defaults: the full grid on the paper's setting).

    ``strengths`` are mean-field strengths ``K`` (sum ``G = K/N``, mean ``G = K``); the grid
    is ``normalizes × strengths × data_seeds``, plus today's default if it is not in it.
    ``n_projections`` (``P``) projections per (β, k), at most :data:`PAPER_PROJECTIONS`.
    """

    N: int = 1000
    d: int = 200
    betas: tuple = (1.5, 1.62, 1.7)
    ks: tuple = (150, 100, 50, 25, 10, 5, 2)
    n_projections: int = 3
    normalizes: tuple = ("sum",)
    strengths: tuple = (750.0, 800.0, 850.0, 900.0, 950.0, 1000.0)
    data_seeds: tuple = (0, 1, 2)
    steps: int = 1500
    dt: float = 0.02
    precision: str = "mixed"
    kind: str = "gaussian"
    seed: int = 20120101
    record_every: int = 50
    yes_below: float = 1e-10
    no_above: float = 1e-3

    def __post_init__(self):
        as_int(self.N, "N", low=1)
        d = as_int(self.d, "d", low=1)
        as_int(self.n_projections, "n_projections", low=1, high=PAPER_PROJECTIONS)
        as_int(self.seed, "seed", low=0)
        as_float(self.dt, "dt", low=0.0, low_open=True)
        as_choice(self.precision, "precision", ("mixed", "double"))
        as_choice(self.kind, "kind", KINDS)
        _distinct(self.normalizes, "normalizes", lambda v, n: as_choice(v, n, ("sum", "mean")))
        _distinct(self.strengths, "strengths", lambda v, n: as_float(v, n, low=0.0, low_open=True))
        _distinct(self.data_seeds, "data_seeds", lambda v, n: as_int(v, n, low=0))
        betas = _distinct(self.betas, "betas", as_float)
        for b in betas:
            if b not in table1.PAPER_TABLE1:
                raise InvalidInput(f"betas must be betas of the paper's Table 1 "
                                   f"({sorted(table1.PAPER_TABLE1)}), got {b}")
        paper_ks = sorted(k for k in table1.PAPER_TABLE1[betas[0]] if k != ORIGINAL_ROW)
        for k in _distinct(self.ks, "ks", as_int):
            if k not in paper_ks or k >= d:
                raise InvalidInput(f"ks must be target dimensions of the paper's Table 1 "
                                   f"({paper_ks}) below d={d}, got {k}")
        steps, every = as_int(self.steps, "steps", low=1), as_int(self.record_every, "record_every", low=1)
        if steps % every:
            raise InvalidInput(f"steps must be a multiple of record_every={every}, got {steps}")
        lo = as_float(self.yes_below, "yes_below", low=0.0)
        as_float(self.no_above, "no_above", low=lo)

    @classmethod
    def quick(cls, **overrides) -> "CalibrationConfig":
        """A reduced study (N = 200, 4 rows of k, P = 2, 3 strengths × 2 data seeds) that runs
        in about a minute. Its numbers are not the paper's (N = 200 agents, not 1000)."""
        base = dict(N=200, ks=(100, 25, 10, 2), n_projections=2, strengths=(700.0, 800.0, 900.0),
                    data_seeds=(0, 1))
        base.update(overrides)
        return cls(**base)

    def to_json(self) -> dict:
        out = dataclasses.asdict(self)
        for key in ("betas", "ks", "normalizes", "strengths", "data_seeds"):
            out[key] = list(out[key])
        return out


@dataclass(frozen=True)
class Candidate:
    """A coupling convention (``normalize``, mean-field strength ``K``) and an initial-data
    seed; ``G`` is the scene's coupling for the study's ``N``."""

    normalize: str
    strength: float
    data_seed: int
    G: float
    default: bool = False

    @property
    def convention(self) -> tuple[str, float]:
        return (self.normalize, self.strength)

    def label(self) -> str:
        return f"{self.normalize} K={self.strength:g} (G={self.G:g}) seed {self.data_seed}"

    def to_json(self) -> dict:
        return dataclasses.asdict(self) | {"label": self.label(),
                                           "G_at_paper_N": table1.coupling_G(
                                               self.normalize, self.strength, table1.PAPER_N)}


def default_candidate(N: int) -> Candidate:
    """Today's default of the Table 1 study
    (:data:`~kinred.experiments.table1.DEFAULT_COUPLING`) at ``N`` agents."""
    normalize, G, data_seed = table1.DEFAULT_COUPLING
    K = table1.mean_field_strength(normalize, G, table1.PAPER_N)
    return Candidate(normalize, K, data_seed, table1.coupling_G(normalize, K, N), True)


def _as_config(cfg) -> CalibrationConfig:
    if not isinstance(cfg, CalibrationConfig):
        raise InvalidInput(f"cfg must be a CalibrationConfig, got {type(cfg).__name__}")
    return cfg


def candidates(cfg: CalibrationConfig) -> list[Candidate]:
    """The study's candidates: ``normalizes × strengths × data_seeds`` in that order (data seed
    fastest), then today's default if the grid does not hold it."""
    cfg = _as_config(cfg)
    today = default_candidate(cfg.N)
    out = []
    for normalize in cfg.normalizes:
        for K in cfg.strengths:
            for s in cfg.data_seeds:
                is_default = (normalize, s) == (today.normalize, today.data_seed) and \
                    math.isclose(K, today.strength, rel_tol=1e-12)
                out.append(Candidate(normalize, float(K), int(s),
                                     table1.coupling_G(normalize, K, cfg.N), is_default))
    if not any(c.default for c in out):
        out.append(today)
    return out


def _layout(cfg: CalibrationConfig) -> table1.Table1Config:
    """Table 1's member layout (20 projections per (β, k)): where projection seeds come from."""
    return table1.Table1Config(betas=cfg.betas, ks=cfg.ks, n_projections=PAPER_PROJECTIONS,
                               seed=cfg.seed)


def _members(cfg: CalibrationConfig, cands: list[Candidate]) -> list[dict]:
    layout = _layout(cfg)
    keys = [(float(b), 0, 0) for b in cfg.betas] + [
        (float(b), int(k), r) for b in cfg.betas for k in cfg.ks for r in range(cfg.n_projections)]
    index = {key: table1.member_index(layout, *key) for key in keys}
    out = []
    for ci, c in enumerate(cands):
        common = dict(candidate=ci, N=cfg.N, d=cfg.d, steps=cfg.steps, dt=cfg.dt, G=c.G,
                      normalize=c.normalize, precision=cfg.precision, kind=cfg.kind,
                      data_seed=c.data_seed, record_every=cfg.record_every, seed=cfg.seed)
        for b in cfg.betas:
            for k in (0, *cfg.ks):
                for r in range(cfg.n_projections if k else 1):
                    key = (float(b), int(k), r)
                    out.append(dict(common, beta=key[0], k=key[1], realization=r,
                                    table1_index=index[key]))
    return out


def estimate_seconds(cfg: CalibrationConfig, workers: int | None = None) -> float:
    """Rough wall time of the study on ``workers`` processes (default: the cores), from the
    measured full Table 1 run (module constants): ``c·(dim + 15)·(N/1000)²·steps/1500`` per
    simulation plus a fixed overhead, ``dim`` = d for the original system and k otherwise."""
    cfg = _as_config(cfg)
    w = as_int(workers if workers is not None else (os.cpu_count() or 1), "workers", low=1)
    ref = table1.Table1Config()
    ref_units = len(ref.betas) * (ref.d + _DIM_OFFSET + ref.n_projections * sum(
        k + _DIM_OFFSET for k in ref.ks))
    ref_members = len(ref.betas) * (1 + ref.n_projections * len(ref.ks))
    c = (_TABLE1_SECONDS * _TABLE1_CORES - _MEMBER_OVERHEAD * ref_members) / ref_units
    members = _members(cfg, candidates(cfg))
    scale = (cfg.N / table1.PAPER_N) ** 2 * cfg.steps / ref.steps
    total = sum(c * scale * ((m["k"] or cfg.d) + _DIM_OFFSET) + _MEMBER_OVERHEAD for m in members)
    return total / min(w, len(members))


def member(params: dict, seed) -> dict:
    """One simulation: :func:`~kinred.experiments.table1.member` with Table 1's projection
    seed for the member's ``(β, k, realization)``,
    ``member_seed(params["seed"], params["table1_index"])``.

    The ensemble's own ``seed`` is not used: every candidate projects with the same matrices
    (common random numbers). A run whose forward Euler step blows up
    (:class:`~kinred.errors.SimulationDiverged`, possible for strong couplings in k = 2) returns
    empty ``t``/``gamma`` and the time in ``diverged_at`` (NaN otherwise). Top-level (picklable)
    for :func:`kinred.ensemble.run_ensemble`.
    """
    from .._rng import member_seed
    from ..errors import SimulationDiverged

    try:
        out = table1.member(params, member_seed(params["seed"], params["table1_index"]))
    except SimulationDiverged as exc:
        return {"t": np.zeros(0), "gamma": np.zeros(0), "diverged_at": float(exc.t)}
    return out | {"diverged_at": math.nan}


# ----------------------------------------------------------------------------------------------
# Running and summarizing
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CalibrationResult:
    """Counts, final Γ and scores per candidate, the aggregation over seeds, and the run."""

    config: CalibrationConfig
    candidates: tuple          # Candidate
    counts: tuple              # per candidate: {beta: {row: (pos, neg, n/a)}}
    gamma_final: tuple         # per candidate: {beta: {row: [Γ(T) of each run]}}
    scores: tuple              # TableScore per candidate
    wall_time: float
    executor: str
    workers: int | None
    n_loaded: int = 0

    def n_diverged(self, i: int) -> int:
        """How many runs of candidate ``i`` diverged (counted as "neg")."""
        return sum(math.isinf(g) for per in self.gamma_final[i].values() for v in per.values()
                   for g in v)

    def ranking(self) -> list[int]:
        """Candidate indices, best first (more matches, then smaller L1, then grid order)."""
        return sorted(range(len(self.candidates)),
                      key=lambda i: (-self.scores[i].matches, self.scores[i].l1, i))

    @property
    def default_index(self) -> int:
        return next(i for i, c in enumerate(self.candidates) if c.default)

    def conventions(self) -> list[dict]:
        """One entry per convention (normalize, K) over its data seeds, best first (mean
        matches, then mean L1)."""
        groups: dict = {}
        for c, s in zip(self.candidates, self.scores):
            groups.setdefault(c.convention, []).append((c, s))
        out = []
        for (normalize, K), members in groups.items():
            m = [s.matches for _, s in members]
            out.append({"normalize": normalize, "strength": K, "G": members[0][0].G,
                        "G_at_paper_N": table1.coupling_G(normalize, K, table1.PAPER_N),
                        "data_seeds": [c.data_seed for c, _ in members], "matches": m,
                        "mean_matches": float(np.mean(m)), "min_matches": min(m),
                        "max_matches": max(m), "mean_l1": float(np.mean([s.l1 for _, s in members])),
                        "default": any(c.default for c, _ in members)})
        return sorted(out, key=lambda e: (-e["mean_matches"], e["mean_l1"]))

    def recommendation(self) -> dict:
        """The convention to adopt: the best one if its mean matches beat today's convention's,
        with its best data seed; otherwise today's default unchanged."""
        conv = self.conventions()
        today = self.candidates[self.default_index]
        today_conv = next(e for e in conv if (e["normalize"], e["strength"]) == today.convention)
        adopt = conv[0]["mean_matches"] > today_conv["mean_matches"]
        chosen = conv[0] if adopt else today_conv
        if adopt:
            pool = [i for i in self.ranking()
                    if self.candidates[i].convention == (chosen["normalize"], chosen["strength"])]
            pick = self.candidates[pool[0]]
        else:
            pick = today
        G = table1.coupling_G(pick.normalize, pick.strength, table1.PAPER_N)
        i = self.candidates.index(pick)
        return {"adopt": adopt, "normalize": pick.normalize, "strength": pick.strength,
                "G_at_paper_N": G, "data_seed": pick.data_seed,
                "matches": self.scores[i].matches, "l1": self.scores[i].l1,
                "mean_matches": chosen["mean_matches"],
                "default_matches": self.scores[self.default_index].matches,
                "default_l1": self.scores[self.default_index].l1,
                "default_mean_matches": today_conv["mean_matches"],
                "table1_line": f'DEFAULT_COUPLING = ("{pick.normalize}", {G:g}, {pick.data_seed})'}

    def to_json(self) -> dict:
        def rows(v, f):
            return {str(b): {str(k): f(c) for k, c in per.items()} for b, per in v.items()}

        return {
            "config": self.config.to_json(),
            "rule": {"match": "the paper's plurality verdict is the unique plurality verdict of "
                              "the runs (ties never match)",
                     "l1": "sum over verdicts of |runs' proportion - paper's proportion| (0..2 per cell)"},
            "recommendation": self.recommendation(),
            "conventions": self.conventions(),
            "ranking": self.ranking(),
            "candidates": [c.to_json() | {"counts": rows(n, lambda t: dict(zip(VERDICTS, t))),
                                          "gamma_final": rows(g, list), "score": s.to_json(),
                                          "diverged": self.n_diverged(i)}
                           for i, (c, n, g, s) in enumerate(zip(self.candidates, self.counts,
                                                                self.gamma_final, self.scores))],
            "wall_time_s": self.wall_time,
            "members_loaded_from_store": self.n_loaded,
            "executor": self.executor,
            "workers": self.workers,
            "paper": rows(table1.PAPER_TABLE1, lambda t: dict(zip(VERDICTS, t))),
        }

    def to_text(self) -> str:
        """The calibration table: candidates, conventions, recommendation, per-cell verdicts."""
        return _format_text(self)


def _tabulate(cfg: CalibrationConfig, n_cand: int, ens) -> tuple[list, list]:
    """Per candidate: {beta: {row: counts}} and {beta: {row: [Γ(T)]}} from the ensemble
    (Γ(T) = inf for a run that diverged)."""
    finals: list = [{float(b): {} for b in cfg.betas} for _ in range(n_cand)]
    for m, res in zip(ens.members, ens.results):
        row = m["k"] or ORIGINAL_ROW
        g = math.inf if np.isfinite(res["diverged_at"]) else float(res["gamma"][-1])
        finals[m["candidate"]][m["beta"]].setdefault(row, []).append(g)
    counts = []
    for per_cand in finals:
        counts.append({b: {row: _count(g, cfg) for row, g in per.items()}
                       for b, per in per_cand.items()})
    return counts, finals


def _count(gammas: list, cfg: CalibrationConfig) -> tuple[int, int, int]:
    """Verdict counts by the paper's rule; a diverged run (Γ = inf) counts as "neg"."""
    from ..observables import flocking_verdict

    v = [flocking_verdict(g, yes_below=cfg.yes_below, no_above=cfg.no_above)
         if math.isfinite(g) else "neg" for g in gammas]
    return tuple(v.count(x) for x in VERDICTS)


def run(cfg: CalibrationConfig | None = None, *, out_dir=None, executor: str = "processes",
        workers: int | None = None, scheduler=None, resume: bool = False,
        progress: bool = True) -> CalibrationResult:
    """Run the calibration; with ``out_dir`` write the store, ``calibration.json``,
    ``calibration.txt``, ``summary.json`` and the figure.

    Members are written to ``out_dir/store`` as they finish (resumable with ``resume=True``);
    see :func:`kinred.ensemble.run_ensemble` for ``executor``, ``workers``, ``scheduler``.
    """
    from ..ensemble import run_ensemble

    cfg = CalibrationConfig() if cfg is None else _as_config(cfg)
    cands = candidates(cfg)
    members = _members(cfg, cands)
    store = None if out_dir is None else Path(out_dir) / "store"
    t0 = time.perf_counter()
    ens = run_ensemble(member, members, master_seed=cfg.seed, executor=executor, workers=workers,
                       scheduler=scheduler, store=store, resume=resume, config=cfg.to_json(),
                       progress=progress)
    counts, finals = _tabulate(cfg, len(cands), ens)
    result = CalibrationResult(cfg, tuple(cands), tuple(counts), tuple(finals),
                               tuple(score_table(c) for c in counts), time.perf_counter() - t0,
                               ens.executor, workers, int(np.sum(ens.loaded)))
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


# ----------------------------------------------------------------------------------------------
# Text, files and the figure
# ----------------------------------------------------------------------------------------------
_LETTER = {"pos": "p", "neg": "n", "n/a": "u", None: "t"}


def _cell_letter(cell: CellScore) -> str:
    letter = _LETTER[cell.verdict]
    return letter.upper() if cell.match else letter


def _verdict_rows(result: CalibrationResult) -> list[str]:
    cells0 = result.scores[0].cells
    betas = list(dict.fromkeys(c.beta for c in cells0))
    width = max(len(c.label()) for c in result.candidates) + 2
    head = " " * width + " | ".join(
        " ".join(f"{c.dim:>3}" for c in cells0 if c.beta == b) for b in betas)
    title = " " * width + " | ".join(
        f"beta = {b:g}".ljust(4 * sum(c.beta == b for c in cells0) - 1) for b in betas)

    def row(label, cells, letter):
        return label.ljust(width) + " | ".join(
            " ".join(f"{letter(c):>3}" for c in cells if c.beta == b) for b in betas)

    lines = [title, head, row("paper", cells0, lambda c: _LETTER[c.paper_verdict].upper())]
    for i in result.ranking():
        lines.append(row(result.candidates[i].label(), result.scores[i].cells, _cell_letter))
    return lines


def _format_text(result: CalibrationResult) -> str:
    cfg = result.config
    rec = result.recommendation()
    n = result.scores[0].n_cells
    out = [f"Table 1 calibration (kinred paper calibrate): N={cfg.N}, d={cfg.d}, "
           f"P={cfg.n_projections} projections per k (Table 1's first {cfg.n_projections}), "
           f"{cfg.steps} Euler steps of {cfg.dt}, precision {cfg.precision}; "
           f"K = mean-field strength (sum G = K/N, mean G = K).",
           "match: the paper's plurality verdict is the runs' unique plurality verdict; "
           "L1 = sum over cells of |p_runs - p_paper|_1 (0..2 per cell).", "",
           "Candidates, best first (* = today's default)",
           f"{'rank':>4}  {'candidate':<36} {'matches':>8} {'L1':>7} {'diverged':>9}"]
    for r, i in enumerate(result.ranking(), start=1):
        c, s = result.candidates[i], result.scores[i]
        out.append(f"{r:>4}  {c.label() + (' *' if c.default else ''):<36} "
                   f"{s.matches:>5}/{n:<2} {s.l1:>7.2f} {result.n_diverged(i):>9}")
    out += ["", f"Conventions over data seeds {list(cfg.data_seeds)}, best first",
            f"{'normalize':<9} {'K':>7} {'G':>9} {'mean':>6} {'min':>4} {'max':>4} {'mean L1':>8}"]
    for e in result.conventions():
        out.append(f"{e['normalize']:<9} {e['strength']:>7g} {e['G']:>9g} {e['mean_matches']:>6.2f} "
                   f"{e['min_matches']:>4} {e['max_matches']:>4} {e['mean_l1']:>8.2f}"
                   + ("  (today's)" if e["default"] else ""))
    today = result.candidates[result.default_index]
    out += ["", f"Today's default: {today.label()}: {rec['default_matches']}/{n} (L1 "
                f"{rec['default_l1']:.2f}); its convention: {rec['default_mean_matches']:.2f} on average.",
            (f"Recommendation: adopt {rec['normalize']} K={rec['strength']:g} data_seed "
             f"{rec['data_seed']} ({rec['matches']}/{n}, L1 {rec['l1']:.2f}; convention mean "
             f"{rec['mean_matches']:.2f}): in kinred/experiments/table1.py {rec['table1_line']}"
             if rec["adopt"] else "Recommendation: keep today's default (no convention beats it "
                                  "on mean matches over the data seeds)."),
            "", "Per-cell verdicts (plurality of the runs: p = flocking, n = no flocking, "
                "u = undecided, t = tie; UPPER CASE = matches the paper)"]
    return "\n".join(out + _verdict_rows(result)) + "\n"


def _figure(plt, result: CalibrationResult):
    cfg = result.config
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    n = result.scores[0].n_cells
    n_grid = len(cfg.normalizes) * len(cfg.strengths) * len(cfg.data_seeds)
    for normalize in cfg.normalizes:
        for s in cfg.data_seeds:
            idx = [i for i, c in enumerate(result.candidates[:n_grid])
                   if (c.normalize, c.data_seed) == (normalize, s)]
            K = [result.candidates[i].strength for i in idx]
            axes[0].plot(K, [result.scores[i].matches for i in idx], "o-", label=f"{normalize}, seed {s}")
            axes[1].plot(K, [result.scores[i].l1 for i in idx], "o-", label=f"{normalize}, seed {s}")
    d = result.default_index
    axes[0].plot([result.candidates[d].strength], [result.scores[d].matches], "k*", ms=14,
                 label="today's default")
    axes[0].set_ylabel(f"cells matching the paper (of {n})")
    axes[1].set_ylabel("L1 distance to the paper (summed over cells)")
    for ax in axes:
        ax.set_xlabel("mean-field strength K (sum: G = K/N)")
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"Table 1 calibration: N={result.config.N}, P={result.config.n_projections} "
                 "projections per k")
    return fig


def write_outputs(result: CalibrationResult, out_dir) -> Path:
    """Write ``calibration.json``, ``calibration.txt`` and ``summary.json``, then the figure
    ``calibration.png`` (a figure that cannot be drawn is skipped with a warning). Returns the
    path of ``summary.json``."""
    from ..io import ResultFolder
    from ..report import draw_figure

    folder = ResultFolder(out_dir)
    data = result.to_json()
    folder.write_json("calibration.json", data)
    folder.write_text("calibration.txt", result.to_text())
    summary = folder.mark_complete({"study": "calibrate_table1", "wall_time_s": result.wall_time,
                                    "recommendation": data["recommendation"],
                                    "best_conventions": data["conventions"][:3]})
    drawn = draw_figure("calibration.png", "matches and L1 against K", _figure, result)
    if drawn.png is not None:
        folder.write_bytes(drawn.name, drawn.png)
    return summary
