r"""Projected dimension ``k``, projection kind, and the engine's precision.

Cucker–Smale alignment (eqs. (2.12)–(2.13)), forward Euler
(eq. (2.14)), simulated in ℝᵈ and, for every projected dimension ``k`` and projection kind,
in ℝᵏ (eq. (2.15), projected scheme (2.4)–(2.5)); the setting of Table 1 (§3.4.1, sum
convention, ``N·G`` kept at 800). The trajectory error is

.. math:: e(t) = \Big(\sum_i \|y_i(t) - Mx_i(t)\|^2 \Big/
          \sum_i \|Mx_i(t) - M\bar x(t)\|^2\Big)^{1/2},

relative to the spread of the projected cloud (the quantity bounded by eq. (3.15),
made scale free; the spread, not ``Σ‖Mxᵢ‖²``, so that moving the whole cloud
does not shrink it); reported at the final time and as the maximum over saved times, together
with the agreement of the flocking verdict (the paper's rule on Γ(T), §3.4.1) with the full
simulation's. The time of a projected run includes drawing ``M`` and projecting the initial
data. The full simulation is also run with ``precision="mixed"`` (float32 pair sums, float64
state): its time and its error against the float64 run (same formula with ``M = I``) price the
engine's precision knob.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._validate import as_choice, as_int
from ...observables import above_floor
from ...projection import KINDS
from ...report import tidy_log_axes
from ._base import Study, StudyConfig, clock, draw_front, label_points


@dataclass(frozen=True)
class ProjectionConfig(StudyConfig):
    """Cucker–Smale in ℝᵈ vs ℝᵏ (defaults: the full study)."""

    study = "projection"
    _QUICK = dict(N=100, d=200, G=8.0, ks=(2, 5, 10, 25, 50, 100), kinds=("gaussian", "srht"),
                  reps=2)
    _SMOKE = dict(N=30, d=40, G=8.0, steps=200, every=50, ks=(2, 10, 30),
                  kinds=("gaussian", "srht"), reps=2, headline_k=10)

    N: int = 200
    d: int = 200
    beta: float = 1.5
    G: float = 4.0
    steps: int = 1500
    dt: float = 0.02
    every: int = 50
    ks: tuple = (2, 5, 10, 25, 50, 100, 150)
    kinds: tuple = ("gaussian", "achlioptas", "srht")
    reps: int = 2
    #: the ``k`` quoted in the headline (the nearest measured one)
    headline_k: int = 25

    def __post_init__(self):
        self._ints("N", "d", "steps", "every", "reps", "headline_k", low=1)
        self._floats("dt", "G", low=0.0, low_open=True)
        self._floats("beta", low=0.0)
        self._each("ks", as_int, low=1)
        self._each("kinds", as_choice, KINDS)
        self._multiple("steps", "every")


def spread_relative(y: np.ndarray, Mx: np.ndarray) -> np.ndarray:
    """Per saved time: (Σᵢ‖yᵢ − Mxᵢ‖² / Σᵢ‖Mxᵢ − M x̄‖²)^{1/2} for (T, N, k) arrays."""
    num = np.sum((y - Mx) ** 2, axis=(1, 2))
    dev = Mx - Mx.mean(axis=1, keepdims=True)
    den = np.sum(dev ** 2, axis=(1, 2))
    return np.sqrt(num / den)


def _shapes(cfg: ProjectionConfig):
    """The measured (kind, k) pairs (a DCT cannot have k > d)."""
    return [(kind, int(k)) for kind in cfg.kinds for k in cfg.ks
            if not (kind == "dct" and k > cfg.d)]


class _Setup:
    """Initial data, scene, save schedule of the study; :meth:`sim` runs one simulation."""

    def __init__(self, cfg: ProjectionConfig, rng):
        from ...dynamics import Alignment, CuckerSmale, Scene
        from ...integrate import SaveAt

        self.cfg = cfg
        self.x0 = rng.uniform(0.0, 1.0, (cfg.N, cfg.d))
        self.v0 = rng.uniform(-1.0, 1.0, (cfg.N, cfg.d))
        self.scene = Scene([Alignment(kernel=CuckerSmale(G=cfg.G, beta=cfg.beta))],
                           normalize="sum")
        self.T = cfg.steps * cfg.dt
        self.save = SaveAt(every=cfg.every, observables=("gamma",), states="x")

    def sim(self, scene, x0, v0, warm: bool = False):
        from ...integrate import simulate

        span = (0.0, 2 * self.cfg.dt) if warm else (0.0, self.T)
        return simulate(scene, x0, v0, span, self.cfg.dt, save=self.save)


def _warm_up(s: _Setup) -> None:
    """Two steps of every run shape (numba compilation, kernel choice for these shapes)."""
    from ...projection import jl_matrix

    s.sim(s.scene, s.x0, s.v0, warm=True)
    for kind, k in _shapes(s.cfg):
        M = jl_matrix(k, s.cfg.d, kind=kind, seed=0)
        s.sim(s.scene.project(M), M.apply(s.x0), M.apply(s.v0), warm=True)


def _full_mixed(s: _Setup, full, t_full: float) -> dict:
    """The full run with ``precision="mixed"``: its time and error against float64."""
    from ...dynamics import Scene
    from ...observables import flocking_verdict

    mixed_scene = Scene(s.scene.effects, normalize="sum", precision="mixed")
    s.sim(mixed_scene, s.x0, s.v0, warm=True)
    mixed, t_mixed = clock(lambda: s.sim(mixed_scene, s.x0, s.v0))
    err = spread_relative(mixed.x, full.x)
    g_full = float(full.observables["gamma"][-1])
    g = float(mixed.observables["gamma"][-1])
    return dict(time_s=t_mixed, error_final=float(err[-1]), error_max=float(err.max()),
                gamma_T=g, gamma_rel_diff=abs(g - g_full) / g_full if g_full else 0.0,
                agrees=flocking_verdict(g) == flocking_verdict(g_full), speedup=t_full / t_mixed)


def _projected_runs(study: Study, s: _Setup, full, verdict_full: str, seed: int, bar) -> list:
    """``reps`` timed projected runs per (kind, k), each with its own ``M``."""
    from ...observables import flocking_verdict
    from ...projection import jl_matrix

    N, d = s.cfg.N, s.cfg.d
    rows = []
    for kind, k in _shapes(s.cfg):
        for r in range(s.cfg.reps):
            m_seed = study.seed_of(seed, KINDS.index(kind), k, r)

            def one():
                M = jl_matrix(k, d, kind=kind, seed=m_seed)
                return M, s.sim(s.scene.project(M), M.apply(s.x0), M.apply(s.v0))

            (M, tr), secs = clock(one)
            Mx = M.apply(full.x.reshape(-1, d)).reshape(full.x.shape[0], N, k)
            err = spread_relative(tr.x, Mx)
            g = float(tr.observables["gamma"][-1])
            rows.append(dict(kind=kind, k=k, rep=r, time_s=secs, error_final=float(err[-1]),
                             error_max=float(err.max()), gamma_T=g, verdict=flocking_verdict(g),
                             agrees=flocking_verdict(g) == verdict_full))
            bar.update(1)
    return rows


def _summary(cfg: ProjectionConfig, rows: list, t_full: float) -> list:
    """Per (kind, k): median time, mean errors and verdict agreement over the repetitions."""
    out = []
    for kind, k in _shapes(cfg):
        rs = [r for r in rows if r["kind"] == kind and r["k"] == k]
        t = float(np.median([r["time_s"] for r in rs]))
        out.append(dict(kind=kind, k=k, time_s=t,
                        error_final=float(np.mean([r["error_final"] for r in rs])),
                        error_max=float(np.mean([r["error_max"] for r in rs])),
                        verdict_agreement=float(np.mean([r["agrees"] for r in rs])),
                        verdict_agrees=int(sum(bool(r["agrees"]) for r in rs)), runs=len(rs),
                        speedup=t_full / t))
    return out


class ProjectionStudy(Study):
    """Projected dimension ``k`` and projection kind (and the precision of the full run)."""

    name = "projection"
    title = "Projected dimension k and projection kind"
    Config = ProjectionConfig
    key = 1

    def n_units(self, cfg: ProjectionConfig) -> int:
        return 1 + cfg.reps * len(cfg.ks) * len(cfg.kinds)

    def run(self, cfg: ProjectionConfig, *, seed: int, bar) -> dict:
        from ...observables import flocking_verdict, gamma_floor

        s = _Setup(cfg, self.rng(seed))
        _warm_up(s)
        full, t_full = clock(lambda: s.sim(s.scene, s.x0, s.v0))
        bar.update(1)
        g_full = float(full.observables["gamma"][-1])
        verdict_full = flocking_verdict(g_full)
        full_mixed = _full_mixed(s, full, t_full)
        rows = _projected_runs(self, s, full, verdict_full, seed, bar)
        setting = dict(N=cfg.N, d=cfg.d, beta=cfg.beta, G=cfg.G, normalize="sum",
                       steps=cfg.steps, dt=cfg.dt, T=s.T, method="euler",
                       error="spread-relative trajectory error of positions, "
                             "(sum_i |y_i - M x_i|^2 / sum_i |M x_i - M xbar|^2)^(1/2)")
        full_out = dict(time_s=t_full, gamma_T=g_full, verdict=verdict_full,
                        gamma_floor=gamma_floor(s.v0, cfg.steps))
        return dict(setting=setting, full=full_out, full_mixed=full_mixed, runs=rows, summary=_summary(cfg, rows, t_full))

    def table(self, result: dict):
        from ...report import Table

        p = result
        rows = [["full", p["setting"]["d"], p["full"]["time_s"], 0.0, 0.0, "(reference)", 1.0]]
        fm = p.get("full_mixed")
        if fm:
            rows.append(["full, precision mixed", p["setting"]["d"], fm["time_s"],
                         fm["error_final"], fm["error_max"], f"{int(bool(fm['agrees']))}/1",
                         fm["speedup"]])
        rows += [[r["kind"], r["k"], r["time_s"], r["error_final"], r["error_max"],
                  _agree_text(r), r["speedup"]] for r in p["summary"]]
        return Table(["kind", "k", "time [s]", "error at T", "max error",
                      "verdict agrees (runs)", "speed-up"], rows,
                     caption="median time and mean errors over repetitions (measured); verdict: "
                             "runs whose flocking verdict is the full run's, of all runs")

    def figure(self, result: dict, plt):
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
        _draw_errors(axes[0], result)
        _draw_verdicts(axes[1], result)
        return fig

    def headline(self, result: dict, cfg: ProjectionConfig) -> dict:
        p = result
        s = [r for r in p["summary"] if r["kind"] == cfg.kinds[0]]
        k = min((r["k"] for r in s), key=lambda kk: abs(kk - cfg.headline_k))
        r = next(r for r in s if r["k"] == k)
        out = {"projection": dict(
            k=k, d=p["setting"]["d"], kind=r["kind"], error_final=r["error_final"],
            speedup=r["speedup"], verdict_agreement=r["verdict_agreement"],
            text=(f"k = {k} ({r['kind']}) gives {100 * r['error_final']:.2g}% trajectory error "
                  f"(final time; {100 * r['error_max']:.2g}% max over time) "
                  f"{_time_ratio(r['speedup'])} of d = {p['setting']['d']} "
                  f"(N = {p['setting']['N']}, {p['setting']['steps']} Euler steps); "
                  f"flocking verdict agrees in {_agree_text(r)} runs"))}
        fm = p.get("full_mixed")
        if fm:
            out["precision"] = dict(
                speedup=fm["speedup"], error_max=fm["error_max"],
                gamma_rel_diff=fm["gamma_rel_diff"],
                text=(f"precision='mixed' (float32 pair sums) runs the full d = "
                      f"{p['setting']['d']} simulation {_time_ratio(fm['speedup'])} at "
                      f"{fm['error_max']:.1e} relative trajectory error (max over time); "
                      + (f"{fm['gamma_rel_diff']:.1e} relative change of Gamma(T)"
                         if above_floor(p["full"]["gamma_T"], p["full"]["gamma_floor"]) else
                         f"Gamma(T) near float64's round-off floor "
                         f"({p['full']['gamma_floor']:.1g}) in both")))
        return out


def _agree_text(r: dict) -> str:
    """``"2/2"``: runs whose verdict is the full run's, of all runs (older results: from the
    fraction and the repetitions)."""
    if "verdict_agrees" in r:
        return f"{r['verdict_agrees']}/{r['runs']}"
    return f"{100 * r['verdict_agreement']:.0f}%"


def _time_ratio(speedup: float) -> str:
    """``"in 1/3.2 the time"`` or ``"in 1.4x the time"`` for a measured speed-up."""
    if speedup >= 1.0:
        return f"in 1/{speedup:.2g} the time"
    return f"in {1.0 / speedup:.2g}x the time (slower)"


def _draw_errors(ax, p: dict) -> None:
    """Left panel: trajectory error against time per kind, the full runs as references."""
    alls_t, alls_e, labels = [], [], []
    for kind in dict.fromkeys(r["kind"] for r in p["summary"]):
        rs = [r for r in p["summary"] if r["kind"] == kind]
        t = [r["time_s"] for r in rs]
        e = [r["error_final"] for r in rs]
        alls_t += t
        alls_e += e
        line, = ax.loglog(t, e, "o-", label=f"{kind}: error at T")
        ax.loglog(t, [r["error_max"] for r in rs], "x:", color=line.get_color(), alpha=0.6,
                  label=f"{kind}: max over t")
        labels.append((t, e, [f"k={r['k']}" for r in rs], line.get_color()))
    draw_front(ax, alls_t, alls_e)
    ax.axvline(p["full"]["time_s"], color="k", ls="--", lw=1,
               label=f"full d={p['setting']['d']}: {p['full']['time_s']:.2g} s")
    fm = p.get("full_mixed")
    if fm and fm["error_max"] > 0:
        ax.loglog([fm["time_s"]], [fm["error_max"]], "k*", ms=10,
                  label=f"full, precision='mixed': {fm['time_s']:.2g} s (max error)")
    for t, e, texts, color in labels:
        label_points(ax, t, e, texts, color=color)
    tidy_log_axes(ax)
    ax.set_xlabel("wall time of one simulation [s]")
    ax.set_ylabel("relative trajectory error (positions)")
    ax.set_title(f"projected dimension k: N={p['setting']['N']}, d={p['setting']['d']}")
    ax.legend(fontsize=7)


def _draw_verdicts(ax, p: dict) -> None:
    """Right panel: per k, how many projected runs give the full run's flocking verdict."""
    kinds = list(dict.fromkeys(r["kind"] for r in p["summary"]))
    runs = max(r.get("runs", 1) for r in p["summary"])
    for i, kind in enumerate(kinds):
        rs = [r for r in p["summary"] if r["kind"] == kind]
        shift = 1.0 + 0.06 * (i - (len(kinds) - 1) / 2)        # side by side, same k
        agree = [r.get("verdict_agrees", r["verdict_agreement"] * runs) for r in rs]
        ax.semilogx([r["k"] * shift for r in rs], agree, "o-", label=kind)
    ax.set_ylim(-0.3, runs + 0.3)
    ax.set_yticks(range(runs + 1), [f"{j}/{runs}" for j in range(runs + 1)])
    ks = sorted({r["k"] for r in p["summary"]})
    ax.set_xticks(ks, [str(k) for k in ks])
    ax.minorticks_off()
    ax.set_xlabel("projected dimension k")
    ax.set_ylabel("runs whose verdict is the full run's")
    ax.set_title(f"flocking verdict; full run: {p['full']['verdict']} "
                 f"(Gamma(T) = {p['full']['gamma_T']:.2g})")
    ax.legend(fontsize=8)


STUDY = ProjectionStudy()
