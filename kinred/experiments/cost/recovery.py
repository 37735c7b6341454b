r"""Number of projections ``L`` and solver tolerance of the recovery.

The setting of the paper's Figure 4 right (§3.4.2): initial data with 80 % zero entries,
``L`` independent projections into ℝᵏ (eq. (3.17)), and the velocities
recovered at the saved times by basis pursuit (problem (3.16), with η = 0;
``k L < d`` so the stacked system is underdetermined) from the stacked data, one batched
:func:`kinred.recovery.basis_pursuit` solve per (L, tolerance). Error:

.. math:: \Big(\sum_{i,t}\|v^\sharp_i(t) - v_i(t)\|^2 \Big/ \sum_{i,t}\|v_i(t)\|^2\Big)^{1/2}.

Time: the ``L`` projected simulations plus the solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._validate import as_float, as_int
from ...errors import InvalidInput
from ._base import Study, StudyConfig, clock, draw_front, label_points


@dataclass(frozen=True)
class RecoveryConfig(StudyConfig):
    """Figure 4 right (§3.4.2): mean convention, ``G = 1``, ``β = 0.4`` (defaults: full)."""

    study = "recovery"
    _QUICK = dict(N=40, d=100, k=10, Ls=(1, 3, 5, 9), tols=(1e-2, 1e-4), steps=100, every=50)
    _SMOKE = dict(N=20, d=60, k=10, Ls=(1, 3, 5), tols=(1e-2, 1e-6), steps=50, every=25)

    N: int = 30
    d: int = 200
    k: int = 20
    Ls: tuple = (1, 2, 3, 5, 7, 9)
    tols: tuple = (1e-2, 1e-3, 1e-4)
    steps: int = 250
    dt: float = 0.02
    every: int = 125
    zero_fraction: float = 0.8

    def __post_init__(self):
        self._ints("N", "d", "k", "steps", "every", low=1)
        self._floats("dt", low=0.0, low_open=True)
        self._floats("zero_fraction", low=0.0, high=1.0, high_open=True)
        self._multiple("steps", "every")
        self._each("tols", as_float, low=0.0, low_open=True)
        for L in self._each("Ls", as_int, low=1):
            if L * self.k >= self.d:
                raise InvalidInput(f"recovery.Ls must keep L*k < d={self.d} (basis pursuit with "
                                   f"eta = 0 needs an underdetermined system), got L={L}")


def _projected_data(study: Study, cfg: RecoveryConfig, xs, vs, scene, save, seed: int):
    """The ``max(Ls)`` timed projected simulations: matrices, velocities, seconds."""
    from ...integrate import simulate
    from ...projection import jl_matrix

    T = cfg.steps * cfg.dt
    Ms, ws, t_sims = [], [], []
    for ell in range(max(cfg.Ls)):
        def one():
            M = jl_matrix(cfg.k, cfg.d, kind="gaussian", seed=study.seed_of(seed, ell))
            return M, simulate(scene.project(M), M.apply(xs), M.apply(vs), (0.0, T), cfg.dt,
                               save=save)

        (M, tr), secs = clock(one)
        Ms.append(M)
        ws.append(tr.v)
        t_sims.append(secs)
    return Ms, ws, t_sims


def _solves(cfg: RecoveryConfig, V, Ms, ws, t_sims, bar) -> list:
    """One timed batched basis-pursuit solve per (tolerance, L), with its error."""
    from ...recovery import basis_pursuit, stack_projections

    n_cols, k = V.shape[1], cfg.k
    rows = []
    for tol in cfg.tols:
        for L in cfg.Ls:
            A = stack_projections(Ms[:L])
            Y = np.vstack([w.reshape(n_cols, k).T for w in ws[:L]])
            res, secs = clock(lambda: basis_pursuit(A, Y, 0.0, tol=float(tol)), max_repeat=1)
            err = float(np.sqrt(np.sum((res.Z - V) ** 2) / np.sum(V ** 2)))
            t_sim = float(sum(t_sims[:L]))
            rows.append(dict(L=int(L), tol=float(tol), m=int(L * k), solve_s=secs,
                             simulate_s=t_sim, time_s=secs + t_sim,
                             error=err, converged_fraction=float(np.mean(res.converged)),
                             max_iterations=int(res.iterations.max(initial=0))))
            bar.update(1)
    return rows


class RecoveryStudy(Study):
    """Number of projections ``L`` and tolerance of the batched basis-pursuit solve."""

    name = "recovery"
    title = "Number of projections L and solver tolerance (recovery)"
    Config = RecoveryConfig
    key = 2

    def n_units(self, cfg: RecoveryConfig) -> int:
        return 1 + len(cfg.Ls) * len(cfg.tols)

    def run(self, cfg: RecoveryConfig, *, seed: int, bar) -> dict:
        from ...dynamics import Alignment, CuckerSmale, Scene
        from ...integrate import SaveAt, simulate
        from ...projection import jl_matrix
        from ...recovery import basis_pursuit

        rng = self.rng(seed)
        N, d, k = cfg.N, cfg.d, cfg.k
        xs = rng.standard_normal((N, d)) * (rng.random((N, d)) >= cfg.zero_fraction)
        vs = rng.standard_normal((N, d)) * (rng.random((N, d)) >= cfg.zero_fraction)
        scene = Scene([Alignment(kernel=CuckerSmale(G=1.0, beta=0.4))], normalize="mean")
        T = cfg.steps * cfg.dt
        save = SaveAt(every=cfg.every, observables=("gamma",), states="v")
        warm = (0.0, 2 * cfg.dt)  # warm-up: numba compilation, kernel choice for these shapes
        simulate(scene, xs, vs, warm, cfg.dt, save=save)
        M = jl_matrix(k, d, seed=0)
        simulate(scene.project(M), M.apply(xs), M.apply(vs), warm, cfg.dt, save=save)
        basis_pursuit(M.to_dense(), M.apply(vs[:2]).T)
        full, t_full = clock(lambda: simulate(scene, xs, vs, (0.0, T), cfg.dt, save=save))
        Ms, ws, t_sims = _projected_data(self, cfg, xs, vs, scene, save, seed)
        bar.update(1)
        n_t = full.v.shape[0]
        V = full.v.reshape(n_t * N, d).T  # (d, n_t·N): one column per (time, agent)
        rows = _solves(cfg, V, Ms, ws, t_sims, bar)
        return dict(setting=dict(N=N, d=d, k=k, steps=cfg.steps, dt=cfg.dt, T=T, beta=0.4,
                                 G=1.0, normalize="mean", zero_fraction=cfg.zero_fraction,
                                 saved_times=int(n_t), eta=0.0,
                                 solver="kinred.recovery.basis_pursuit (batched ADMM + certified "
                                        "polish)"),
                    full_time_s=t_full, rows=rows)

    def table(self, result: dict):
        from ...report import Table

        return Table(["L", "m = kL", "tol", "simulations [s]", "solve [s]", "total [s]", "error",
                      "converged [%]", "max iter"],
                     [[x["L"], x["m"], x["tol"], x["simulate_s"], x["solve_s"], x["time_s"],
                       x["error"], 100 * x["converged_fraction"], x["max_iterations"]]
                      for x in result["rows"]])

    def figure(self, result: dict, plt):
        r = result
        fig, ax = plt.subplots(figsize=(7.5, 5))
        ts, es, labels = [], [], []
        for tol in dict.fromkeys(x["tol"] for x in r["rows"]):
            rs = [x for x in r["rows"] if x["tol"] == tol]
            t, e = [x["time_s"] for x in rs], [x["error"] for x in rs]
            ts += t
            es += e
            line, = ax.loglog(t, e, "o-", label=f"tol = {tol:g}")
            labels.append((t, e, [f"L={x['L']}" for x in rs], line.get_color()))
        draw_front(ax, ts, es)
        for t, e, texts, color in labels:
            label_points(ax, t, e, texts, color=color)
        ax.set_xlabel("wall time: L projected simulations + batched basis pursuit [s]")
        ax.set_ylabel("relative recovery error of v(t)")
        ax.set_title(f"recovery: L projections into R^{r['setting']['k']}, d = {r['setting']['d']}")
        ax.legend(fontsize=8)
        return fig

    def headline(self, result: dict, cfg: RecoveryConfig) -> dict:
        r = result
        rows = [x for x in r["rows"] if x["tol"] == min(y["tol"] for y in r["rows"])]
        best = min(rows, key=lambda x: x["error"])
        return {"recovery": dict(
            L=best["L"], error=best["error"], time_s=best["time_s"],
            text=(f"L = {best['L']} projections into R^{r['setting']['k']} recover the sparse "
                  f"velocities in R^{r['setting']['d']} to {100 * best['error']:.2g}% in "
                  f"{best['time_s']:.2g} s (simulations + solve; the full simulation takes "
                  f"{r['full_time_s']:.2g} s)"))}


STUDY = RecoveryStudy()
