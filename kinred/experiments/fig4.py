"""The paper's Figure 4 (§3.4.2).

Left panel: Cucker–Smale with N = d = 200, normally distributed initial data, β = 0.4
(flocking for any initial data since β ≤ 1/2), projected to k ∈ {20, 40, 60, 100, 140, 180};
the relative projection error of the velocities over time,

.. math:: e_{\\rm proj}(t) = \\Big(\\sum_i \\|M v_i(t) - w_i(t)\\|^2 \\big/ \\sum_i \\|M v_i(t)\\|^2\\Big)^{1/2},

with ``w`` the projected simulation (eq. (2.15)), and its certified bound: the projected runs are
stepped by :class:`kinred.certify.CertificateObserver` alongside the high-dimensional run
(bit-identical to ``simulate(scene.project(M), ...)``), whose bound ``bound_v`` of the weighted
RMS velocity error ``(Σᵢ wᵢ|Mvᵢ − wᵢ|²)^{1/2}`` is divided by the same
``(Σᵢ wᵢ|Mvᵢ|²)^{1/2}`` (uniform weights ``wᵢ = 1/N``: the same normalization as the measured
curve). See ``docs/certificates.md``.

Right panel: initial data with 80 % zero entries, L ∈ {1, 2, 3, 5, 7, 9} independent
projections into k = 20 (eq. (3.17)), the velocity trajectories recovered by ℓ1 minimization
(problem (3.16)) from the stacked system [M¹; …; Mᴸ] v = [w¹; …; wᴸ] − η,
one batched solve over all agents and saved times; the relative recovery error

.. math:: e_{\\rm rec}(t) = \\Big(\\sum_i \\|v^\\sharp_i(t) - v_i(t)\\|^2 \\big/ \\sum_i \\|v_i(t)\\|^2\\Big)^{1/2}.

Noise level: η = 0 by default, i.e. basis pursuit ``min ‖z‖₁ s.t. 𝓜z = y``. It is always
feasible here (Lk < d) and lets the projection error act as noise. The automatic rule
(``eta="auto"``, :func:`kinred.recovery.estimate_eta`) needs sparse velocities, and v(t) loses
its sparsity as the flock forms (the mean velocity of sparse vectors is dense), so it refuses
late times with a clear error.

Coupling convention: the mean-field form of eq. (2.13) (``normalize="mean"``, G = 1) is the
default here: with it the projection error first grows and then decreases once the flock
forms, as the paper describes; the sum convention that reproduces Table 1 is available
(``normalize="sum"``) and recorded in the output.

The run is cut into stages written as they finish (``OUT/stages``, resumable: see
:func:`run`), with a progress bar. The three recovery strategies of §3.3.1 on the same data
are in :mod:`kinred.experiments.recovery_strategies`.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._repr import result_repr
from .._validate import as_choice, as_float, as_int
from ..errors import InvalidInput
from ._staged import Staged

__all__ = ["Fig4Config", "Fig4Result", "run", "write_outputs", "config_json"]


@dataclass(frozen=True)
class Fig4Config:
    """Parameters of the Figure 4 study (defaults: the paper's §3.4.2)."""

    N: int = 200
    d: int = 200
    beta: float = 0.4
    G: float = 1.0
    normalize: str = "mean"
    steps: int = 1500
    dt: float = 0.02
    record_every: int = 50
    ks: tuple = (20, 40, 60, 100, 140, 180)
    k_recovery: int = 20
    Ls: tuple = (1, 2, 3, 5, 7, 9)
    zero_fraction: float = 0.8
    kind: str = "gaussian"
    seed: int = 2012
    eta: object = 0.0

    def __post_init__(self):
        as_int(self.N, "N", low=1)
        as_int(self.d, "d", low=1)
        as_int(self.steps, "steps", low=1)
        as_int(self.record_every, "record_every", low=1)
        as_int(self.k_recovery, "k_recovery", low=1)
        as_float(self.beta, "beta", low=0.0)
        as_float(self.G, "G", low=0.0, low_open=True)
        as_float(self.dt, "dt", low=0.0, low_open=True)
        as_float(self.zero_fraction, "zero_fraction", low=0.0, high=1.0, high_open=True)
        as_choice(self.normalize, "normalize", ("mean", "sum"))
        if self.steps % self.record_every:
            raise InvalidInput(f"steps must be a multiple of record_every={self.record_every}, "
                               f"got {self.steps}")
        if not self.ks or not self.Ls:
            raise InvalidInput("ks and Ls must not be empty")
        for k in self.ks:
            as_int(k, "k", low=1)
        for L in self.Ls:
            as_int(L, "L", low=1)

    @classmethod
    def quick(cls, **overrides) -> "Fig4Config":
        """Reduced sizes (N = d = 100, 750 steps) for tests; same qualitative picture."""
        base = dict(N=100, d=100, steps=750, record_every=50, ks=(10, 30, 90), Ls=(1, 3, 9),
                    k_recovery=10)
        base.update(overrides)
        return cls(**base)


def _scene(cfg: Fig4Config):
    from ..dynamics import Alignment, CuckerSmale, Scene

    return Scene([Alignment(kernel=CuckerSmale(G=cfg.G, beta=cfg.beta))], normalize=cfg.normalize)


def _simulate(scene, x0, v0, cfg: Fig4Config, *, states: bool, observers=None):
    from ..integrate import SaveAt, simulate

    return simulate(scene, x0, v0, t_span=(0.0, cfg.steps * cfg.dt), dt=cfg.dt, method="euler",
                    save=SaveAt(every=cfg.record_every, observables=("gamma",),
                                states="v" if states else False), observers=observers)


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per saved time: (Σᵢ‖aᵢ − bᵢ‖² / Σᵢ‖bᵢ‖²)^{1/2} for (T, N, m) arrays."""
    num = np.sum((a - b) ** 2, axis=(1, 2))
    den = np.sum(b ** 2, axis=(1, 2))
    return np.sqrt(num / den)


def _relative_bound(rms: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A bound of :func:`_relative` ``(a, b)`` from a bound ``rms (T,)`` of the uniformly
    weighted RMS ``(Σᵢ‖aᵢ − bᵢ‖²/N)^{1/2}``: ``rms·√N / (Σᵢ‖bᵢ‖²)^{1/2}``."""
    return rms * np.sqrt(b.shape[1]) / np.sqrt(np.sum(b ** 2, axis=(1, 2)))


@dataclass(frozen=True)
class Fig4Result:
    """Projection errors (left panel) and recovery errors (right panel) over time."""

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    config: Fig4Config
    t: np.ndarray
    projection_error: dict     # {k: (T,)}
    projection_bound: dict     # {k: (T,)}: certified bound of projection_error
    recovery_error: dict       # {L: (T,)}
    recovery_status: dict      # {L: fraction of converged problems}
    wall_time: float
    stages: dict = dataclasses.field(default_factory=dict)   # {stage: "loaded" | "computed"}

    def to_json(self) -> dict:
        return {
            "config": config_json(self.config),
            "coupling": f"normalize={self.config.normalize!r}, G={self.config.G}",
            "eta": self.config.eta,
            "t": self.t.tolist(),
            "projection_error": {str(k): v.tolist() for k, v in self.projection_error.items()},
            "projection_bound": {str(k): v.tolist() for k, v in self.projection_bound.items()},
            "recovery_error": {str(L): v.tolist() for L, v in self.recovery_error.items()},
            "recovery_converged_fraction": {str(L): f for L, f in self.recovery_status.items()},
            "wall_time_s": self.wall_time,
            "stages": dict(self.stages),
        }


def _projection(cfg, k, rng_seed, ell):
    from .._rng import member_seed
    from ..projection import jl_matrix

    return jl_matrix(k, cfg.d, kind=cfg.kind, seed=member_seed(cfg.seed, (rng_seed, k, ell)))


def _projected_runs(scene, x0, v0, cfg, k, n_proj, rng_seed):
    """``n_proj`` independent projections into ℝᵏ: (list of M, list of w-trajectories)."""
    Ms, ws = [], []
    for ell in range(n_proj):
        M = _projection(cfg, k, rng_seed, ell)
        tr = _simulate(scene.project(M), M.apply(x0), M.apply(v0), cfg, states=True)
        Ms.append(M)
        ws.append(tr.v)
    return Ms, ws


def _weights(cfg: Fig4Config) -> dict:
    """Work units of the stages (one unit: about one step of a full N x d run)."""
    per_left = 1 + 4 * len(cfg.ks)      # the full run steps one certificate observer per k
    return dict(left=cfg.steps * per_left, left_per_step=per_left, sparse=cfg.steps,
                projection=cfg.steps, recover={int(L): cfg.steps * (6 + int(L)) for L in cfg.Ls})


def _initial_data(cfg: Fig4Config):
    """``(x0, v0, xs, vs)``: the dense data of the left panel and the sparse data of the right."""
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(0,)))
    x0 = rng.standard_normal((cfg.N, cfg.d))
    v0 = rng.standard_normal((cfg.N, cfg.d))
    mask_x = rng.random((cfg.N, cfg.d)) >= cfg.zero_fraction
    mask_v = rng.random((cfg.N, cfg.d)) >= cfg.zero_fraction
    xs = rng.standard_normal((cfg.N, cfg.d)) * mask_x
    vs = rng.standard_normal((cfg.N, cfg.d)) * mask_v
    return x0, v0, xs, vs


def config_json(cfg: Fig4Config) -> dict:
    """The configuration as JSON (tuples as lists)."""
    out = dataclasses.asdict(cfg)
    out["ks"], out["Ls"] = list(cfg.ks), list(cfg.Ls)
    return out


def run(cfg: Fig4Config | None = None, *, out_dir=None, resume: bool = False,
        progress: bool | None = None) -> Fig4Result:
    """Run both panels; with ``out_dir`` write ``fig4.json``, the figure and ``report.html``.

    The stages (``left``: the projection errors and their bounds; ``sparse``: the full run
    from sparse data; ``projection{l}``: the l-th projected run into k_recovery;
    ``recover{L}``: the recovery from L projections) are written to ``out_dir/stages`` as they
    finish; ``resume=True`` loads those present (:class:`kinred.io.StageStore`), so an
    interrupted run resumes with the same numbers. ``progress`` shows a tqdm bar with the
    time remaining (None: when stderr is a terminal).
    """
    cfg = cfg or Fig4Config()
    if not isinstance(cfg, Fig4Config):
        raise InvalidInput(f"cfg must be a Fig4Config, got {type(cfg).__name__}")
    t0 = time.perf_counter()
    w = _weights(cfg)
    total = w["left"] + w["sparse"] + max(cfg.Ls) * w["projection"] + sum(w["recover"].values())
    st = Staged(config_json(cfg), out_dir, resume=resume, total=total, desc="kinred paper fig4",
                progress=progress)
    try:
        x0, v0, xs, vs = _initial_data(cfg)
        scene = _scene(cfg)
        # Left panel: dense normal initial data, projection error per k and its certified bound.
        left = st.stage("left", w["left"], lambda: _left_arrays(
            scene, x0, v0, cfg, st.ticker(w["left_per_step"])),
            keys=("t",) + tuple(f"{a}{k}" for k in cfg.ks for a in ("error", "bound")))
        proj_err = {int(k): left[f"error{k}"] for k in cfg.ks}
        proj_bound = {int(k): left[f"bound{k}"] for k in cfg.ks}
        rec_err, rec_ok = _right_panel(st, scene, xs, vs, cfg, w)
    finally:
        st.close()
    result = Fig4Result(cfg, np.asarray(left["t"]), proj_err, proj_bound, rec_err, rec_ok,
                        time.perf_counter() - t0, st.status)
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def _left_arrays(scene, x0, v0, cfg, tick) -> dict:
    full, err, bound = _left_panel(scene, x0, v0, cfg, tick=tick)
    out = {"t": np.asarray(full.t)}
    for k in err:
        out[f"error{k}"], out[f"bound{k}"] = err[k], bound[k]
    return out


def _right_panel(st: Staged, scene, xs, vs, cfg, w):
    """80 % zero entries, L projections into k_recovery, l1 recovery of v(t), stage by stage:
    ``({L: relative error (T,)}, {L: fraction of converged problems})``."""
    from ..recovery import recover

    sparse = st.stage("sparse", w["sparse"], lambda: {
        "v": _simulate(scene, xs, vs, cfg, states=True, observers=[st.ticker()]).v}, keys=("v",))
    Ms, ws = [], []
    for ell in range(max(cfg.Ls)):
        M = _projection(cfg, cfg.k_recovery, 2, ell)
        ws.append(st.stage(f"projection{ell}", w["projection"], lambda M=M: {
            "w": _simulate(scene.project(M), M.apply(xs), M.apply(vs), cfg, states=True,
                           observers=[st.ticker()]).v}, keys=("w",))["w"])
        Ms.append(M)
    rec_err, rec_ok = {}, {}
    for L in cfg.Ls:
        def solve(L=int(L)):
            res = recover(Ms[:L], ws[:L], eta=cfg.eta, original=sparse["v"])
            return {"error": np.asarray(res.relative_error),
                    "converged": np.mean(res.status == "converged")}

        r = st.stage(f"recover{int(L)}", w["recover"][int(L)], solve, keys=("error", "converged"))
        rec_err[int(L)] = np.asarray(r["error"])
        rec_ok[int(L)] = float(r["converged"])
    return rec_err, rec_ok


def _left_panel(scene, x0, v0, cfg, tick=None):
    """The high-dimensional run with one certificate observer per ``k`` (each steps its
    projected run): ``(trajectory, {k: relative error}, {k: its certified bound})``;
    ``tick`` is an extra observer (the progress bar)."""
    from ..certify import CertificateObserver

    steps = range(0, cfg.steps + 1, cfg.record_every)
    Ms = {int(k): _projection(cfg, k, 1, 0) for k in cfg.ks}
    obs = {k: CertificateObserver(scene, M, x0, v0, save_steps=steps, paper=False, states="v")
           for k, M in Ms.items()}
    full = _simulate(scene, x0, v0, cfg, states=True,
                     observers=list(obs.values()) + ([tick] if tick is not None else []))
    err, bound = {}, {}
    for k, M in Ms.items():
        rec = obs[k].records()
        Mv = np.einsum("tnd,kd->tnk", full.v, M.to_dense())
        err[k] = _relative(rec["w"], Mv)
        bound[k] = _relative_bound(rec["bound_v"], Mv)
    return full, err, bound


def _figure(plt, result: Fig4Result):
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    for k, e in result.projection_error.items():
        line, = a.plot(result.t, e, label=f"k={k}")
        a.plot(result.t, result.projection_bound[k], "--", color=line.get_color())
    a.plot([], [], "--", color="0.3", label="certified bound")
    a.set_xlabel("t")
    a.set_ylabel("relative projection error of v")
    a.set_title("Figure 4 (left): projection error")
    a.legend()
    for L, e in result.recovery_error.items():
        b.plot(result.t, e, label=f"L={L}")
    b.set_xlabel("t")
    b.set_ylabel("relative l1-recovery error of v")
    b.set_title(f"Figure 4 (right): recovery from L projections into k={result.config.k_recovery}")
    b.legend()
    return fig


def _worst_ratio(t, bound, err) -> float:
    sel = (t >= 1.0) & (err > 0)
    return float(np.max(bound[sel] / err[sel])) if np.any(sel) else float("nan")


def write_outputs(result: Fig4Result, out_dir) -> Path:
    """Write ``fig4.json`` and ``summary.json``, then ``fig4.png`` and ``report.html`` (a figure
    that cannot be drawn becomes a note in the report). Returns the path of ``summary.json``."""
    from ..io import ResultFolder
    from ..report import Report, Table, draw_figure

    folder = ResultFolder(out_dir)
    folder.write_json("fig4.json", result.to_json())
    summary = folder.mark_complete({"study": "fig4", "wall_time_s": result.wall_time})
    drawn = draw_figure("fig4.png", "Figure 4", _figure, result)
    if drawn.png is not None:
        folder.write_bytes(drawn.name, drawn.png)
    cfg = result.config
    rep = Report("kinred: the paper's Figure 4 (§3.4.2)",
                 subtitle=f"N={cfg.N}, d={cfg.d}, beta={cfg.beta}, coupling normalize="
                          f"{cfg.normalize!r}, G={cfg.G}, {cfg.steps} Euler steps of {cfg.dt}")
    s = rep.section("Errors over time")
    s.add_drawn(drawn)
    s.tables.append(Table(["k", "max error", "final error", "final bound",
                           "worst bound/error (t >= 1)"],
                          [[k, float(e.max()), float(e[-1]), float(result.projection_bound[k][-1]),
                            _worst_ratio(result.t, result.projection_bound[k], e)]
                           for k, e in result.projection_error.items()],
                          caption="relative projection error of v and its certified bound"))
    s.tables.append(Table(["L", "max error", "final error", "converged"],
                          [[L, float(e.max()), float(e[-1]), result.recovery_status[L]]
                           for L, e in result.recovery_error.items()],
                          caption="relative recovery error of v"))
    folder.write_text("report.html", rep.to_html())
    return summary
