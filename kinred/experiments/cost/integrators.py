"""Time step and integrator.

Cucker–Smale at fixed final time with every fixed-step Runge–Kutta method of
:mod:`kinred.integrate` (Euler, eq. (1.6); Heun; RK4) over a range of steps, and every adaptive
pair (RK45, RK23) over a range of ``rtol`` (``atol = rtol · 1e-3``); error: the state at ``T``
against RK45 at ``rtol = 1e-12`` (max over agents of ``‖(x,v)ᵢ − (x,v)ᵢ^ref‖`` divided by
the max of ``‖(x,v)ᵢ^ref‖`` after removing the centre).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._validate import as_float, as_int
from ._base import Study, StudyConfig, clock, draw_front, time_to_reach


def methods() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(fixed, adaptive)``: the deterministic integrators of the registry
    :data:`kinred.integrate.SOLVERS`, in its order.

    Stochastic ones (``"euler_maruyama"``, for noise) are not part of the study; one registered
    with :func:`kinred.integrate.register_solver` is priced like the built-in ones.
    """
    from ...integrate import SOLVERS

    ms = [s for s in SOLVERS.values() if not s.stochastic]
    return (tuple(s.name for s in ms if not s.adaptive), tuple(s.name for s in ms if s.adaptive))


@dataclass(frozen=True)
class IntegratorsConfig(StudyConfig):
    """Cucker–Smale, mean convention, ``G = 1`` (defaults: the full study)."""

    study = "integrators"
    _QUICK = dict(N=30, steps=(10, 20, 40, 80, 160, 320), rtols=(1e-3, 1e-5, 1e-7, 1e-9))
    _SMOKE = dict(N=10, d=3, T=1.0, steps=(10, 20, 40, 80), rtols=(1e-4, 1e-7))

    N: int = 50
    d: int = 5
    T: float = 2.0
    beta: float = 0.4
    #: steps of the fixed-step methods
    steps: tuple = (10, 20, 40, 80, 160, 320, 640, 1280)
    #: relative tolerances of the adaptive methods
    rtols: tuple = (1e-3, 1e-5, 1e-7, 1e-9, 1e-11)

    def __post_init__(self):
        self._ints("N", "d", low=1)
        self._floats("T", low=0.0, low_open=True)
        self._floats("beta", low=0.0)
        self._each("steps", as_int, low=1)
        self._each("rtols", as_float, low=0.0, low_open=True)


def _runs(cfg: IntegratorsConfig, scene, x0, v0, err_of, bar) -> list:
    """Timed runs: every fixed method at every step count, every adaptive one at every rtol."""
    from ...integrate import SaveAt, simulate

    T = cfg.T
    save = SaveAt(t=[0.0, T], observables=(), states=True)
    fixed, adaptive = methods()
    rows = []
    for m in fixed:
        for n in cfg.steps:
            tr, secs = clock(lambda: simulate(scene, x0, v0, (0.0, T), T / n, method=m, save=save))
            rows.append(dict(method=m, steps=int(n), dt=T / n, rtol=None, time_s=secs,
                             error=err_of(tr), rhs_evals=int(tr.n_rhs_evals)))
            bar.update(1)
    for m in adaptive:
        for rtol in cfg.rtols:
            tr, secs = clock(lambda: simulate(scene, x0, v0, (0.0, T), T / 10, method=m,
                                              rtol=float(rtol), atol=float(rtol) * 1e-3, save=save))
            rows.append(dict(method=m, steps=int(tr.n_steps), dt=None, rtol=float(rtol),
                             time_s=secs, error=err_of(tr), rhs_evals=int(tr.n_rhs_evals)))
            bar.update(1)
    return rows


class IntegratorsStudy(Study):
    """Steps of the fixed-step methods, tolerance of the adaptive ones."""

    name = "integrators"
    title = "Time step and integrator"
    Config = IntegratorsConfig
    key = 4

    def n_units(self, cfg: IntegratorsConfig) -> int:
        fixed, adaptive = methods()
        return len(fixed) * len(cfg.steps) + len(adaptive) * len(cfg.rtols)

    def run(self, cfg: IntegratorsConfig, *, seed: int, bar) -> dict:
        from ...dynamics import Alignment, CuckerSmale, Scene
        from ...integrate import SaveAt, simulate

        rng = self.rng(seed)
        N, d, T = cfg.N, cfg.d, cfg.T
        x0, v0 = rng.standard_normal((N, d)), rng.standard_normal((N, d))
        scene = Scene([Alignment(kernel=CuckerSmale(G=1.0, beta=cfg.beta))], normalize="mean")
        for m in sum(methods(), ()):  # warm-up
            simulate(scene, x0[:3], v0[:3], (0.0, 0.1), 0.05, method=m,
                     save=SaveAt(observables=(), states=True))
        ref = simulate(scene, x0, v0, (0.0, T), T / 100, method="rk45", rtol=1e-12, atol=1e-14,
                       save=SaveAt(t=[0.0, T], observables=(), states=True))
        zr = np.concatenate([ref.x[-1], ref.v[-1]], axis=1)
        scale = float(np.max(np.linalg.norm(zr - zr.mean(axis=0), axis=1)))

        def err_of(tr):
            z = np.concatenate([tr.x[-1], tr.v[-1]], axis=1)
            return float(np.max(np.linalg.norm(z - zr, axis=1)) / scale)

        return dict(setting=dict(N=N, d=d, T=T, beta=cfg.beta, G=1.0, normalize="mean",
                                 reference="rk45 with rtol=1e-12, atol=1e-14",
                                 error="max_i |(x,v)_i(T) - ref_i| / max_i |ref_i - centre|",
                                 atol="rtol * 1e-3 for adaptive runs"),
                    reference_steps=int(ref.n_steps), rows=_runs(cfg, scene, x0, v0, err_of, bar))

    def table(self, result: dict):
        from ...report import Table

        return Table(["method", "steps", "dt", "rtol", "rhs evals", "time [s]", "error"],
                     [[x["method"], x["steps"], "" if x["dt"] is None else x["dt"],
                       "" if x["rtol"] is None else x["rtol"], x["rhs_evals"], x["time_s"],
                       x["error"]] for x in result["rows"]])

    def figure(self, result: dict, plt):
        g = result
        fig, ax = plt.subplots(figsize=(7.5, 5))
        ts, es = [], []
        for m in dict.fromkeys(x["method"] for x in g["rows"]):
            rs = [x for x in g["rows"] if x["method"] == m]
            adaptive = rs[0]["rtol"] is not None
            t = [x["time_s"] for x in rs]
            e = [max(x["error"], 1e-16) for x in rs]
            ts += t
            es += e
            ax.loglog(t, e, "s--" if adaptive else "o-",
                      label=m + (" (rtol)" if adaptive else " (dt)"))
        draw_front(ax, ts, es)
        for y in (1e-3, 1e-8):
            ax.axhline(y, color="0.7", lw=0.8, ls=":")
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel("relative error of the state at T")
        ax.set_title(f"integrators: Cucker-Smale N={g['setting']['N']}, d={g['setting']['d']}, "
                     f"T={g['setting']['T']:g}")
        ax.legend(fontsize=8)
        return fig

    def headline(self, result: dict, cfg: IntegratorsConfig) -> dict:
        rows = result["rows"]

        def t_of(m, e):
            rs = [r for r in rows if r["method"] == m]
            return time_to_reach([r["time_s"] for r in rs], [r["error"] for r in rs], e)

        te, tr4, t45 = t_of("euler", 1e-3), t_of("rk4", 1e-8), t_of("rk45", 1e-8)
        best_rk4 = min(r["error"] for r in rows if r["method"] == "rk4")
        best_eu = min(r["error"] for r in rows if r["method"] == "euler")
        if te and tr4:
            text = f"RK4 reaches 1e-8 at {tr4 / te:.2g}x the cost of Euler at 1e-3"
        else:
            text = f"Euler at best {best_eu:.1e}, RK4 at best {best_rk4:.1e} in the measured range"
        if te and t45:
            text += f"; adaptive RK45 reaches 1e-8 at {t45 / te:.2g}x"
        eu_best_t = min(r["time_s"] for r in rows
                        if r["method"] == "euler" and r["error"] == best_eu)
        t_rk4_same = t_of("rk4", best_eu)
        if t_rk4_same:
            eu_steps = max(r["steps"] for r in rows if r["method"] == "euler")
            text += (f"; Euler's best ({best_eu:.1e}, {eu_steps} steps) costs "
                     f"{eu_best_t / t_rk4_same:.2g}x what RK4 needs for the same error")
        return {"integrators": dict(euler_1e3_s=te, rk4_1e8_s=tr4, rk45_1e8_s=t45,
                                    ratio_rk4_1e8_vs_euler_1e3=(tr4 / te) if te and tr4 else None,
                                    text=text)}


STUDY = IntegratorsStudy()
