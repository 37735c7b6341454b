"""The three recovery strategies of §3.3.1 at equal work (``kinred paper strategies``).

On the sparse initial data of the paper's Figure 4 (right panel,
:mod:`kinred.experiments.fig4`): 80 % zero entries, Cucker–Smale with the Figure 4 coupling,
velocities recovered by ℓ1 minimization (problem (3.16)) from

1. one projection into ℝᵏ (simulate k·N² per step, recover from k rows);
2. one projection into ℝᴸᵏ (simulate L·k·N², recover from L·k rows);
3. L independent projections into ℝᵏ (L simulations of k·N², parallelizable; recover from
   the stacked L·k rows, eq. (3.17)).

Measured: the relative recovery error of v(t) (largest over the saved times and at the final
time) and the wall time of the simulations and of the recovery (serial; strategy 3's
simulations are independent, so its parallel time is its serial time / L).

Stages (``truth``: the full run; ``strategy{i}``: the simulations and the recovery of strategy
i with their wall times) are written to ``OUT/stages`` as they finish; ``resume=True`` loads
them (a loaded stage keeps the times measured when it was computed).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._repr import result_repr
from .._validate import as_int
from ..errors import InvalidInput
from ._staged import Staged
from .fig4 import Fig4Config, _scene, _simulate, config_json

__all__ = ["StrategiesResult", "strategies", "write_outputs"]

#: The strategies: (name, projected dimensions as a function of (L, k)).
_STRATEGIES = (("1 projection into R^k", lambda L, k: [k]),
               ("1 projection into R^(Lk)", lambda L, k: [L * k]),
               ("L projections into R^k", lambda L, k: [k] * L))


@dataclass(frozen=True)
class StrategiesResult:
    """The §3.3.1 table with measured columns.

    Attributes
    ----------
    rows : list of dict
        Per strategy: ``strategy``, ``sim_dim``, ``rows`` (rows of the stacked matrix),
        ``simulate_s``, ``recover_s`` (measured wall times), ``max_error``, ``final_error``
        (measured relative recovery errors of v).
    stages : dict
        ``{stage: "loaded" | "computed"}``.
    wall_time : float
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    rows: list
    stages: dict = field(default_factory=dict)
    wall_time: float = 0.0

    def table(self):
        """The rows as a :class:`kinred.report.Table`."""
        from ..report import Table

        return Table(["strategy", "projected dim", "rows of A", "simulate [s]", "recover [s]",
                      "max error", "final error"],
                     [[r["strategy"], r["sim_dim"], r["rows"], r["simulate_s"], r["recover_s"],
                       r["max_error"], r["final_error"]] for r in self.rows],
                     caption="relative recovery error of v (measured) and wall times (measured, "
                             "serial)")

    def to_text(self) -> str:
        return self.table().to_text()


def strategies(cfg: Fig4Config | None = None, *, L: int = 5, k: int | None = None, out_dir=None,
               resume: bool = False, progress: bool | None = None) -> StrategiesResult:
    """Compare the three strategies of §3.3.1 (module docstring) on Figure 4's sparse data.

    Parameters
    ----------
    cfg : Fig4Config, optional
        Sizes and coupling (default: the paper's).
    L : int
        Number of projections of strategies 2 and 3.
    k : int, optional
        Projected dimension (default ``cfg.k_recovery``).
    out_dir : path, optional
        Result folder: stages in ``out_dir/stages``, then ``strategies.json``,
        ``strategies.txt`` and ``summary.json``.
    resume : bool
        Load the stages already in ``out_dir/stages``.
    progress : bool or None
        tqdm bar with the time remaining on stderr (None: when stderr is a terminal).

    Returns
    -------
    StrategiesResult
    """
    from ..recovery import recover

    cfg = cfg or Fig4Config()
    if not isinstance(cfg, Fig4Config):
        raise InvalidInput(f"cfg must be a Fig4Config, got {type(cfg).__name__}")
    L = as_int(L, "L", low=1)
    k = as_int(cfg.k_recovery if k is None else k, "k", low=1)
    t_start = time.perf_counter()
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(3,)))
    xs = rng.standard_normal((cfg.N, cfg.d)) * (rng.random((cfg.N, cfg.d)) >= cfg.zero_fraction)
    vs = rng.standard_normal((cfg.N, cfg.d)) * (rng.random((cfg.N, cfg.d)) >= cfg.zero_fraction)
    scene = _scene(cfg)
    n_sims = [len(dims(L, k)) for _, dims in _STRATEGIES]
    weights = [cfg.steps * (n + 6 + n) for n in n_sims]      # simulations + recovery
    st = Staged({"fig4": config_json(cfg), "L": L, "k": k}, out_dir, resume=resume,
                total=cfg.steps + sum(weights), desc="kinred paper strategies", progress=progress)
    try:
        truth = st.stage("truth", cfg.steps, lambda: {"v": _simulate(
            scene, xs, vs, cfg, states=True, observers=[st.ticker()]).v}, keys=("v",))["v"]
        rows = []
        for i, (name, dims) in enumerate(_STRATEGIES):
            r = st.stage(f"strategy{i}", weights[i], lambda i=i, dims=dims(L, k): _strategy(
                cfg, scene, xs, vs, truth, i, dims, st, recover),
                keys=("simulate_s", "recover_s", "error"))
            err = np.asarray(r["error"])
            dd = dims(L, k)
            rows.append(dict(strategy=name, sim_dim=dd[0] if len(dd) == 1 else f"{L} x {k}",
                             rows=sum(dd), simulate_s=float(r["simulate_s"]),
                             recover_s=float(r["recover_s"]), max_error=float(err.max()),
                             final_error=float(err[-1])))
    finally:
        st.close()
    result = StrategiesResult(rows, st.status, time.perf_counter() - t_start)
    if out_dir is not None:
        write_outputs(result, out_dir, cfg, L=L, k=k)
    return result


def _strategy(cfg, scene, xs, vs, truth, i, dims, st, recover) -> dict:
    """Simulate the projected runs of strategy ``i`` and recover: times and errors."""
    from .._rng import member_seed
    from ..projection import jl_matrix

    t0 = time.perf_counter()
    Ms, ws = [], []
    for ell, kk in enumerate(dims):
        M = jl_matrix(kk, cfg.d, kind=cfg.kind, seed=member_seed(cfg.seed, (4, i, ell)))
        tr = _simulate(scene.project(M), M.apply(xs), M.apply(vs), cfg, states=True,
                       observers=[st.ticker()])
        Ms.append(M)
        ws.append(tr.v)
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = recover(Ms, ws, eta=cfg.eta, original=truth)
    return {"simulate_s": t_sim, "recover_s": time.perf_counter() - t0,
            "error": np.asarray(res.relative_error)}


def write_outputs(result: StrategiesResult, out_dir, cfg: Fig4Config, *, L: int, k: int) -> Path:
    """Write ``strategies.json``, ``strategies.txt`` and ``summary.json``; returns the last."""
    from ..io import ResultFolder

    folder = ResultFolder(out_dir)
    folder.write_json("strategies.json", {"config": config_json(cfg), "L": L, "k": k,
                                          "rows": result.rows, "stages": result.stages,
                                          "wall_time_s": result.wall_time})
    folder.write_text("strategies.txt", result.to_text() + "\n")
    return folder.mark_complete({"study": "strategies", "wall_time_s": result.wall_time})
