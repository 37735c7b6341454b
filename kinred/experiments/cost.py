"""``kinred cost``: what accuracy costs in time, for every knob of the toolkit, on this machine.

Five studies, each a set of (wall time, error) points drawn as a Pareto plot (log-log) with its
numbers in a table:

``projection``
    Cucker–Smale alignment (eqs. (2.12)–(2.13), labels ``CS1``–``CS2``), forward Euler
    (eq. (2.14)), simulated in ℝᵈ and, for every projected dimension ``k`` and projection kind,
    in ℝᵏ (eq. (2.15), projected scheme (2.4)–(2.5)). The trajectory error is

    .. math:: e(t) = \\Big(\\sum_i \\|y_i(t) - Mx_i(t)\\|^2 \\Big/
              \\sum_i \\|Mx_i(t) - M\\bar x(t)\\|^2\\Big)^{1/2},

    relative to the spread of the projected cloud (the quantity bounded by eq. (3.15), label
    ``approxk``, made scale free; the spread, not ``Σ‖Mxᵢ‖²``, so that moving the whole cloud
    does not shrink it); reported at the final time and as the maximum over saved times,
    together with the agreement of the flocking verdict (the paper's rule on Γ(T), §3.4.1)
    with the full simulation's. The time of a projected run includes drawing ``M`` and
    projecting the initial data. The full simulation is also run with
    ``precision="mixed"`` (float32 pair sums, float64 state): its time and its error against
    the float64 run (same formula with ``M = I``) price the engine's precision knob.
``recovery``
    The setting of the paper's Figure 4 right (§3.4.2): initial data with 80 % zero entries,
    ``L`` independent projections into ℝᵏ (eq. (3.17), label ``eq:paral1``), and the
    velocities recovered at the saved times by basis pursuit (problem (3.16), label
    ``P1:eta``, with η = 0; ``k L < d`` so the stacked system is underdetermined) from the
    stacked data, one batched :func:`kinred.recovery.basis_pursuit` solve per (L, tolerance).
    Error: :math:`(\\sum_{i,t}\\|v^\\sharp_i(t) - v_i(t)\\|^2/\\sum_{i,t}\\|v_i(t)\\|^2)^{1/2}`.
    Time: the ``L`` projected simulations plus the solve.
``quantization``
    Atoms from :func:`kinred.quantize.quantize` with an atom budget for two tensor products in
    the same dimension ``d``: *isotropic*, ``U[0,1]ᵈ`` (the curse: a grid with ``N`` atoms has
    error ∝ ``N^(−1/d)``), and *decaying*, ``U[0, ρʲ]`` for ``j = 0..d−1`` (the delayed curse,
    eq. (4.22), label ``delayed``). The error is the product-ℓ1 W1 (exact: the sum of exact 1-D
    marginal errors, Lemma 4.1) -- an **upper bound** of the Euclidean W1 -- and, at small
    sizes, the exact Euclidean W1 (network simplex) to a much finer quantization. Time:
    budget + atoms (materialized).
``integrators``
    Cucker–Smale at fixed final time with Euler, Heun, RK4 over a range of steps and the
    adaptive RK45 / RK23 over a range of ``rtol``; error: the state at ``T`` against RK45 at
    ``rtol = 1e-12`` (max over agents of ``‖(x,v)ᵢ − (x,v)ᵢ^ref‖`` divided by the max of
    ``‖(x,v)ᵢ^ref‖`` after removing the centre).
``w1``
    Two Gaussian clouds in ℝᵈ, growing ``N``: exact dense, exact lazy, certified bracket
    (:func:`kinred.distance.w1`). Accuracy: ``|value − W1|/W1`` and, for the bracket, the
    certified relative width ``(upper − lower)/W1``.

Times are wall-clock seconds of single calls (the minimum of a few repetitions below 20 ms),
measured after a warm-up run (numba compilation excluded); on a shared machine they are noisy.
"""

from __future__ import annotations

import dataclasses
import math
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validate import as_choice, as_float, as_int
from ..errors import InvalidInput

__all__ = ["CostConfig", "CostResult", "run", "write_outputs", "headline", "pareto_front",
           "time_to_reach", "STUDIES"]

#: The studies of :func:`run`, in report order.
STUDIES = ("projection", "recovery", "quantization", "integrators", "w1")

_KINDS = ("gaussian", "rademacher", "achlioptas", "srht", "dct")
_FIXED = ("euler", "heun", "rk4")
_ADAPTIVE = ("rk45", "rk23")


@dataclass(frozen=True)
class CostConfig:
    """Sizes of the five studies (defaults: the full run, a few minutes on 2 cores).

    Use :meth:`quick` (about a minute) or :meth:`smoke` (seconds, for tests).
    """

    seed: int = 7
    studies: tuple = STUDIES
    # projection (Table 1 setting of §3.4.1, sum convention, N·G kept at 800)
    proj_N: int = 200
    proj_d: int = 200
    proj_beta: float = 1.5
    proj_G: float = 4.0
    proj_steps: int = 1500
    proj_dt: float = 0.02
    proj_every: int = 50
    proj_ks: tuple = (2, 5, 10, 25, 50, 100, 150)
    proj_kinds: tuple = ("gaussian", "achlioptas", "srht")
    proj_reps: int = 2
    headline_k: int = 25
    # recovery (Figure 4 right, §3.4.2, mean convention, beta 0.4)
    rec_N: int = 30
    rec_d: int = 200
    rec_k: int = 20
    rec_Ls: tuple = (1, 2, 3, 5, 7, 9)
    rec_tols: tuple = (1e-2, 1e-3, 1e-4)
    rec_steps: int = 250
    rec_dt: float = 0.02
    rec_every: int = 125
    rec_zero_fraction: float = 0.8
    # quantization
    q_d: int = 8
    q_rho: float = 0.5
    q_atoms: tuple = (1, 4, 16, 64, 256, 1024, 4096, 16384, 65536, 262144)
    q_fine: int = 4096
    q_exact_max: int = 256
    q_eps: float = 0.05
    # integrators
    int_N: int = 50
    int_d: int = 5
    int_T: float = 2.0
    int_beta: float = 0.4
    int_steps: tuple = (10, 20, 40, 80, 160, 320, 640, 1280)
    int_rtols: tuple = (1e-3, 1e-5, 1e-7, 1e-9, 1e-11)
    # W1 methods
    w1_d: int = 5
    w1_sizes: tuple = (100, 200, 400, 800, 1600, 3200)
    w1_lazy_max: int = 1600

    def __post_init__(self):
        for name in ("proj_N", "proj_d", "proj_steps", "proj_every", "proj_reps", "rec_N", "rec_d",
                     "rec_k", "rec_steps", "rec_every", "q_d", "q_fine", "int_N", "int_d", "w1_d",
                     "headline_k"):
            as_int(getattr(self, name), name, low=1)
        as_int(self.q_exact_max, "q_exact_max", low=0)
        as_int(self.w1_lazy_max, "w1_lazy_max", low=0)
        for name in ("proj_dt", "rec_dt", "int_T", "q_eps", "proj_G"):
            as_float(getattr(self, name), name, low=0.0, low_open=True)
        as_float(self.proj_beta, "proj_beta", low=0.0)
        as_float(self.int_beta, "int_beta", low=0.0)
        as_float(self.q_rho, "q_rho", low=0.0, high=1.0, low_open=True)
        as_float(self.rec_zero_fraction, "rec_zero_fraction", low=0.0, high=1.0, high_open=True)
        for s in self.studies:
            as_choice(s, "studies", STUDIES)
        for k in self.proj_ks:
            as_int(k, "proj_ks", low=1)
        for kind in self.proj_kinds:
            as_choice(kind, "proj_kinds", _KINDS)
        for name, every, steps in (("proj", self.proj_every, self.proj_steps),
                                   ("rec", self.rec_every, self.rec_steps)):
            if steps % every:
                raise InvalidInput(f"{name}_steps must be a multiple of {name}_every={every}, "
                                   f"got {steps}")
        for L in self.rec_Ls:
            as_int(L, "rec_Ls", low=1)
            if L * self.rec_k >= self.rec_d:
                raise InvalidInput(f"rec_Ls must keep L*rec_k < rec_d={self.rec_d} (basis pursuit "
                                   f"with eta = 0 needs an underdetermined system), got L={L}")
        for t in self.rec_tols:
            as_float(t, "rec_tols", low=0.0, low_open=True)
        for n in self.q_atoms:
            as_int(n, "q_atoms", low=1)
        for n in self.int_steps:
            as_int(n, "int_steps", low=1)
        for r in self.int_rtols:
            as_float(r, "int_rtols", low=0.0, low_open=True)
        for n in self.w1_sizes:
            as_int(n, "w1_sizes", low=2)
        if not (self.proj_ks and self.rec_Ls and self.rec_tols and self.q_atoms
                and self.int_steps and self.w1_sizes):
            raise InvalidInput("every list of knob values must be non-empty")

    @classmethod
    def quick(cls, **overrides) -> "CostConfig":
        """About a minute on 2 cores: smaller systems, fewer knob values."""
        base = dict(proj_N=100, proj_d=200, proj_G=8.0, proj_ks=(2, 5, 10, 25, 50, 100),
                    proj_kinds=("gaussian", "srht"), proj_reps=2,
                    rec_N=40, rec_d=100, rec_k=10, rec_Ls=(1, 3, 5, 9),
                    rec_tols=(1e-2, 1e-4), rec_steps=100, rec_every=50,
                    q_d=6, q_atoms=(1, 4, 16, 64, 256, 1024, 4096, 16384), q_fine=2048,
                    q_exact_max=128,
                    int_N=30, int_steps=(10, 20, 40, 80, 160, 320), int_rtols=(1e-3, 1e-5, 1e-7, 1e-9),
                    w1_sizes=(100, 200, 400, 800), w1_lazy_max=800)
        base.update(overrides)
        return cls(**base)

    @classmethod
    def smoke(cls, **overrides) -> "CostConfig":
        """A few seconds: for the test suite (tiny systems, every code path)."""
        base = dict(proj_N=30, proj_d=40, proj_G=8.0, proj_steps=200, proj_every=50,
                    proj_ks=(2, 10, 30), proj_kinds=("gaussian", "srht"), proj_reps=2, headline_k=10,
                    rec_N=20, rec_d=60, rec_k=10, rec_Ls=(1, 3, 5), rec_tols=(1e-2, 1e-6),
                    rec_steps=50, rec_every=25,
                    q_d=3, q_atoms=(1, 8, 64, 512), q_fine=512, q_exact_max=64,
                    int_N=10, int_d=3, int_T=1.0, int_steps=(10, 20, 40, 80),
                    int_rtols=(1e-4, 1e-7), w1_sizes=(50, 100, 200), w1_lazy_max=200)
        base.update(overrides)
        return cls(**base)

    def to_json(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}


# ---------------------------------------------------------------------------------------------
# helpers


def _clock(fn, *, min_time: float = 0.02, max_repeat: int = 5):
    """``(result, seconds)``: one call, or the minimum of up to ``max_repeat`` when it is fast."""
    t0 = time.perf_counter()
    out = fn()
    best = time.perf_counter() - t0
    n = 1
    while best < min_time and n < max_repeat:
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        n += 1
    return out, best


def pareto_front(times, errors) -> np.ndarray:
    """Indices of the non-dominated points (no other point is both faster and more accurate).

    Sorted by time; NaN errors are ignored.

    Examples
    --------
    >>> pareto_front([1.0, 2.0, 3.0, 1.5], [0.5, 0.1, 0.2, 0.6]).tolist()
    [0, 1]
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(errors, dtype=float)
    order = np.argsort(t, kind="stable")
    keep, best = [], math.inf
    for i in order:
        if np.isfinite(e[i]) and e[i] < best:
            keep.append(int(i))
            best = e[i]
    return np.array(keep, dtype=int)


def time_to_reach(times, errors, target: float) -> float | None:
    """Smallest measured time whose error is ``<= target`` (None if no point reaches it).

    Examples
    --------
    >>> time_to_reach([1.0, 2.0, 4.0], [1e-2, 1e-4, 1e-6], 1e-3)
    2.0
    >>> time_to_reach([1.0], [1e-2], 1e-3) is None
    True
    """
    t = np.asarray(times, dtype=float)
    e = np.asarray(errors, dtype=float)
    ok = np.isfinite(e) & (e <= target)
    return float(t[ok].min()) if np.any(ok) else None


def _spread_relative(y: np.ndarray, Mx: np.ndarray) -> np.ndarray:
    """Per saved time: (Σᵢ‖yᵢ − Mxᵢ‖² / Σᵢ‖Mxᵢ − M x̄‖²)^{1/2} for (T, N, k) arrays."""
    num = np.sum((y - Mx) ** 2, axis=(1, 2))
    dev = Mx - Mx.mean(axis=1, keepdims=True)
    den = np.sum(dev ** 2, axis=(1, 2))
    return np.sqrt(num / den)


def _tqdm(total: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, disable=not enabled, desc="kinred cost", unit="run", leave=True,
                dynamic_ncols=True, mininterval=0.5)


# ---------------------------------------------------------------------------------------------
# the five studies; each returns a dict of JSON-ready numbers


def _study_projection(cfg: CostConfig, bar) -> dict:
    from .._rng import member_seed
    from ..dynamics import Alignment, CuckerSmale, Scene
    from ..integrate import SaveAt, simulate
    from ..observables import flocking_verdict, gamma_floor
    from ..projection import jl_matrix

    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(1,)))
    N, d = cfg.proj_N, cfg.proj_d
    x0, v0 = rng.uniform(0.0, 1.0, (N, d)), rng.uniform(-1.0, 1.0, (N, d))
    scene = Scene([Alignment(kernel=CuckerSmale(G=cfg.proj_G, beta=cfg.proj_beta))], normalize="sum")
    T = cfg.proj_steps * cfg.proj_dt
    save = SaveAt(every=cfg.proj_every, observables=("gamma",), states="x")
    # warm-up (numba compilation, kernel choice for these shapes): two steps of every run shape
    warm = (0.0, 2 * cfg.proj_dt)
    simulate(scene, x0, v0, warm, cfg.proj_dt, save=save)
    for kind in cfg.proj_kinds:
        for k in cfg.proj_ks:
            if not (kind == "dct" and k > d):
                M = jl_matrix(int(k), d, kind=kind, seed=0)
                simulate(scene.project(M), M.apply(x0), M.apply(v0), warm, cfg.proj_dt, save=save)
    full, t_full = _clock(lambda: simulate(scene, x0, v0, (0.0, T), cfg.proj_dt, save=save))
    bar.update(1)
    g_full = float(full.observables["gamma"][-1])
    verdict_full = flocking_verdict(g_full)
    # the precision knob: the same full run with float32 pair sums
    scene_mixed = Scene(scene.effects, normalize="sum", precision="mixed")
    simulate(scene_mixed, x0, v0, warm, cfg.proj_dt, save=save)
    mixed, t_mixed = _clock(lambda: simulate(scene_mixed, x0, v0, (0.0, T), cfg.proj_dt,
                                             save=save))
    err_mixed = _spread_relative(mixed.x, full.x)
    g_mixed = float(mixed.observables["gamma"][-1])
    full_mixed = dict(time_s=t_mixed, error_final=float(err_mixed[-1]),
                      error_max=float(err_mixed.max()), gamma_T=g_mixed,
                      gamma_rel_diff=abs(g_mixed - g_full) / g_full if g_full else 0.0,
                      agrees=flocking_verdict(g_mixed) == verdict_full,
                      speedup=t_full / t_mixed)
    rows = []
    for kind in cfg.proj_kinds:
        for k in cfg.proj_ks:
            if kind == "dct" and k > d:
                continue
            for r in range(cfg.proj_reps):
                seed = member_seed(cfg.seed, (11, _KINDS.index(kind), int(k), r))

                def one():
                    M = jl_matrix(int(k), d, kind=kind, seed=seed)
                    y0, w0 = M.apply(x0), M.apply(v0)
                    return M, simulate(scene.project(M), y0, w0, (0.0, T), cfg.proj_dt, save=save)

                (M, tr), secs = _clock(one)
                Mx = M.apply(full.x.reshape(-1, d)).reshape(full.x.shape[0], N, int(k))
                err = _spread_relative(tr.x, Mx)
                g = float(tr.observables["gamma"][-1])
                rows.append(dict(kind=kind, k=int(k), rep=r, time_s=secs,
                                 error_final=float(err[-1]), error_max=float(err.max()),
                                 gamma_T=g, verdict=flocking_verdict(g),
                                 agrees=flocking_verdict(g) == verdict_full))
                bar.update(1)
    summary = []
    for kind in cfg.proj_kinds:
        for k in cfg.proj_ks:
            rs = [r for r in rows if r["kind"] == kind and r["k"] == int(k)]
            if not rs:
                continue
            summary.append(dict(
                kind=kind, k=int(k), time_s=float(np.median([r["time_s"] for r in rs])),
                error_final=float(np.mean([r["error_final"] for r in rs])),
                error_max=float(np.mean([r["error_max"] for r in rs])),
                verdict_agreement=float(np.mean([r["agrees"] for r in rs])),
                speedup=t_full / float(np.median([r["time_s"] for r in rs]))))
    return dict(setting=dict(N=N, d=d, beta=cfg.proj_beta, G=cfg.proj_G, normalize="sum",
                             steps=cfg.proj_steps, dt=cfg.proj_dt, T=T, method="euler",
                             error="spread-relative trajectory error of positions, "
                                   "(sum_i |y_i - M x_i|^2 / sum_i |M x_i - M xbar|^2)^(1/2)"),
                full=dict(time_s=t_full, gamma_T=g_full, verdict=verdict_full,
                          gamma_floor=gamma_floor(v0, cfg.proj_steps)),
                full_mixed=full_mixed, runs=rows, summary=summary)


def _study_recovery(cfg: CostConfig, bar) -> dict:
    from .._rng import member_seed
    from ..dynamics import Alignment, CuckerSmale, Scene
    from ..integrate import SaveAt, simulate
    from ..projection import jl_matrix
    from ..recovery import basis_pursuit, stack_projections

    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(2,)))
    N, d, k = cfg.rec_N, cfg.rec_d, cfg.rec_k
    xs = rng.standard_normal((N, d)) * (rng.random((N, d)) >= cfg.rec_zero_fraction)
    vs = rng.standard_normal((N, d)) * (rng.random((N, d)) >= cfg.rec_zero_fraction)
    scene = Scene([Alignment(kernel=CuckerSmale(G=1.0, beta=0.4))], normalize="mean")
    T = cfg.rec_steps * cfg.rec_dt
    save = SaveAt(every=cfg.rec_every, observables=("gamma",), states="v")
    warm = (0.0, 2 * cfg.rec_dt)  # warm-up: numba compilation, kernel choice for these shapes
    simulate(scene, xs, vs, warm, cfg.rec_dt, save=save)
    M = jl_matrix(k, d, seed=0)
    simulate(scene.project(M), M.apply(xs), M.apply(vs), warm, cfg.rec_dt, save=save)
    basis_pursuit(M.to_dense(), M.apply(vs[:2]).T)
    full, t_full = _clock(lambda: simulate(scene, xs, vs, (0.0, T), cfg.rec_dt, save=save))
    Ms, ws, t_sims = [], [], []
    for ell in range(max(cfg.rec_Ls)):
        def one():
            M = jl_matrix(k, d, kind="gaussian", seed=member_seed(cfg.seed, (21, ell)))
            return M, simulate(scene.project(M), M.apply(xs), M.apply(vs), (0.0, T), cfg.rec_dt,
                               save=save)

        (M, tr), secs = _clock(one)
        Ms.append(M)
        ws.append(tr.v)
        t_sims.append(secs)
    bar.update(1)
    n_t = full.v.shape[0]
    V = full.v.reshape(n_t * N, d).T  # (d, n_t·N): one column per (time, agent)
    rows = []
    for tol in cfg.rec_tols:
        for L in cfg.rec_Ls:
            A = stack_projections(Ms[:L])
            Y = np.vstack([w.reshape(n_t * N, k).T for w in ws[:L]])
            res, secs = _clock(lambda: basis_pursuit(A, Y, 0.0, tol=float(tol)), max_repeat=1)
            err = float(np.sqrt(np.sum((res.Z - V) ** 2) / np.sum(V ** 2)))
            rows.append(dict(L=int(L), tol=float(tol), m=int(L * k), solve_s=secs,
                             simulate_s=float(sum(t_sims[:L])), time_s=secs + float(sum(t_sims[:L])),
                             error=err, converged_fraction=float(np.mean(res.converged)),
                             max_iterations=int(res.iterations.max(initial=0))))
            bar.update(1)
    return dict(setting=dict(N=N, d=d, k=k, steps=cfg.rec_steps, dt=cfg.rec_dt, T=T, beta=0.4,
                             G=1.0, normalize="mean", zero_fraction=cfg.rec_zero_fraction,
                             saved_times=int(n_t), eta=0.0,
                             solver="kinred.recovery.basis_pursuit (batched ADMM + certified polish)"),
                full_time_s=t_full, rows=rows)


def _study_quantization(cfg: CostConfig, bar) -> dict:
    from ..distance import w1
    from ..measures import TensorProduct, Uniform
    from ..quantize import budget, quantize

    d, rho = cfg.q_d, cfg.q_rho
    measures = {
        "isotropic": TensorProduct([Uniform(0.0, 1.0) for _ in range(d)]),
        "decaying": TensorProduct([Uniform(0.0, rho ** j) for j in range(d)]),
    }
    fine = {}
    for name, mu in measures.items():
        if cfg.q_exact_max:
            fine[name] = quantize(mu, atoms=cfg.q_fine).materialize()
    out = {}
    for name, mu in measures.items():
        rows = []
        for n in cfg.q_atoms:
            def one():
                q = quantize(mu, atoms=int(n))
                return q, q.materialize(max_atoms=max(int(n), 1))

            (q, atoms), secs = _clock(one)
            err, t_err = _clock(lambda: q.error)
            row = dict(atoms_budget=int(n), n_atoms=int(q.n_atoms), counts=list(q.counts),
                       time_s=secs, product_l1=float(err), product_l1_time_s=t_err,
                       bound=float(q.bound))
            if q.n_atoms <= cfg.q_exact_max and name in fine:
                ref = fine[name]
                r, t_ex = _clock(lambda: w1(atoms.points, ref.points, "exact", a=atoms.weights,
                                            b=ref.weights), max_repeat=1)
                row.update(euclidean_to_fine=float(r.value), euclidean_time_s=t_ex)
            rows.append(row)
            bar.update(1)
        out[name] = rows
    b_iso = budget(np.ones(d), eps=cfg.q_eps)
    b_dec = budget(rho ** np.arange(d), eps=cfg.q_eps)
    return dict(setting=dict(d=d, rho=rho, isotropic="U[0,1]^d",
                             decaying="prod_j U[0, rho^j], j = 0..d-1", rule="midpoint",
                             fine_atoms=cfg.q_fine,
                             error="product-l1: exact W1 for the l1 ground cost (sum of exact 1-D "
                                   "marginal errors), an upper bound of the Euclidean W1"),
                rows=out,
                eps_target=cfg.q_eps,
                atoms_for_eps=dict(isotropic=str(b_iso.n_atoms), decaying=str(b_dec.n_atoms),
                                   isotropic_counts=list(b_iso.counts)[:3],
                                   decaying_counts=list(b_dec.counts)))


def _study_integrators(cfg: CostConfig, bar) -> dict:
    from ..dynamics import Alignment, CuckerSmale, Scene
    from ..integrate import SaveAt, simulate

    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(4,)))
    N, d, T = cfg.int_N, cfg.int_d, cfg.int_T
    x0, v0 = rng.standard_normal((N, d)), rng.standard_normal((N, d))
    scene = Scene([Alignment(kernel=CuckerSmale(G=1.0, beta=cfg.int_beta))], normalize="mean")
    save = SaveAt(t=[0.0, T], observables=(), states=True)
    for m in _FIXED + _ADAPTIVE:  # warm-up
        simulate(scene, x0[:3], v0[:3], (0.0, 0.1), 0.05, method=m,
                 save=SaveAt(observables=(), states=True))
    ref = simulate(scene, x0, v0, (0.0, T), T / 100, method="rk45", rtol=1e-12, atol=1e-14,
                   save=save)
    zr = np.concatenate([ref.x[-1], ref.v[-1]], axis=1)
    scale = float(np.max(np.linalg.norm(zr - zr.mean(axis=0), axis=1)))

    def err_of(tr):
        z = np.concatenate([tr.x[-1], tr.v[-1]], axis=1)
        return float(np.max(np.linalg.norm(z - zr, axis=1)) / scale)

    rows = []
    for m in _FIXED:
        for n in cfg.int_steps:
            tr, secs = _clock(lambda: simulate(scene, x0, v0, (0.0, T), T / n, method=m, save=save))
            rows.append(dict(method=m, steps=int(n), dt=T / n, rtol=None, time_s=secs,
                             error=err_of(tr), rhs_evals=int(tr.n_rhs_evals)))
            bar.update(1)
    for m in _ADAPTIVE:
        for rtol in cfg.int_rtols:
            tr, secs = _clock(lambda: simulate(scene, x0, v0, (0.0, T), T / 10, method=m,
                                               rtol=float(rtol), atol=float(rtol) * 1e-3, save=save))
            rows.append(dict(method=m, steps=int(tr.n_steps), dt=None, rtol=float(rtol),
                             time_s=secs, error=err_of(tr), rhs_evals=int(tr.n_rhs_evals)))
            bar.update(1)
    return dict(setting=dict(N=N, d=d, T=T, beta=cfg.int_beta, G=1.0, normalize="mean",
                             reference="rk45 with rtol=1e-12, atol=1e-14",
                             error="max_i |(x,v)_i(T) - ref_i| / max_i |ref_i - centre|",
                             atol="rtol * 1e-3 for adaptive runs"),
                reference_steps=int(ref.n_steps), rows=rows)


def _study_w1(cfg: CostConfig, bar) -> dict:
    from ..distance import w1

    d = cfg.w1_d
    rows = []
    w1(np.zeros((2, d)), np.ones((2, d)), "exact")  # warm-up (POT import)
    for n in cfg.w1_sizes:
        rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(5, int(n))))
        x = rng.standard_normal((n, d))
        y = rng.standard_normal((n, d)) + 0.3
        ex, t_ex = _clock(lambda: w1(x, y, "exact"))
        W = ex.value
        rows.append(dict(N=int(n), method="exact", time_s=t_ex, value=W, rel_error=0.0,
                         rel_width=0.0))
        if n <= cfg.w1_lazy_max:
            lz, t_lz = _clock(lambda: w1(x, y, "exact-lazy"))
            rows.append(dict(N=int(n), method="exact-lazy", time_s=t_lz, value=lz.value,
                             rel_error=abs(lz.value - W) / W, rel_width=0.0))
        br, t_br = _clock(lambda: w1(x, y, "bracket", seed=cfg.seed))
        rows.append(dict(N=int(n), method="bracket", time_s=t_br, value=br.value,
                         lower=br.lower, upper=br.upper, rel_error=abs(br.value - W) / W,
                         rel_width=(br.upper - br.lower) / W))
        bar.update(1)
    return dict(setting=dict(d=d, clouds="N(0, I) vs N(0.3, I), N = M atoms"), rows=rows)


def _n_units(cfg: CostConfig) -> int:
    n = 0
    if "projection" in cfg.studies:
        n += 1 + cfg.proj_reps * len(cfg.proj_ks) * len(cfg.proj_kinds)
    if "recovery" in cfg.studies:
        n += 1 + len(cfg.rec_Ls) * len(cfg.rec_tols)
    if "quantization" in cfg.studies:
        n += 2 * len(cfg.q_atoms)
    if "integrators" in cfg.studies:
        n += len(_FIXED) * len(cfg.int_steps) + len(_ADAPTIVE) * len(cfg.int_rtols)
    if "w1" in cfg.studies:
        n += len(cfg.w1_sizes)
    return n


# ---------------------------------------------------------------------------------------------
# result


@dataclass(frozen=True)
class CostResult:
    """Numbers of the cost study (``studies``: one JSON-ready dict per study), headline, machine."""

    config: CostConfig
    studies: dict
    headline: dict
    machine: dict
    wall_time: float
    study_times: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"config": self.config.to_json(), "machine": self.machine,
                "wall_time_s": self.wall_time, "study_wall_time_s": self.study_times,
                "headline": self.headline, **self.studies}


def machine_info() -> dict:
    """CPU model, logical cores, Python and NumPy versions of this machine."""
    import os

    model = platform.processor() or ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:  # pragma: no cover - non-Linux
        pass
    return {"cpu": model, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "platform": platform.platform()}


def headline(studies: dict, cfg: CostConfig) -> dict:
    """Quotable sentences (and their numbers) from the studies that were run."""
    from ..observables import above_floor

    out: dict = {}
    p = studies.get("projection")
    if p:
        s = [r for r in p["summary"] if r["kind"] == cfg.proj_kinds[0]]
        k = min((r["k"] for r in s), key=lambda kk: abs(kk - cfg.headline_k))
        r = next(r for r in s if r["k"] == k)
        out["projection"] = dict(
            k=k, d=p["setting"]["d"], kind=r["kind"], error_final=r["error_final"],
            speedup=r["speedup"], verdict_agreement=r["verdict_agreement"],
            text=(f"k = {k} ({r['kind']}) gives {100 * r['error_final']:.2g}% trajectory error "
                  f"(final time; {100 * r['error_max']:.2g}% max over time) at "
                  f"{r['speedup']:.1f}x less time than d = {p['setting']['d']} "
                  f"(N = {p['setting']['N']}, {p['setting']['steps']} Euler steps); "
                  f"flocking verdict agrees in {100 * r['verdict_agreement']:.0f}% of runs"))
        fm = p.get("full_mixed")
        if fm:
            out["precision"] = dict(
                speedup=fm["speedup"], error_max=fm["error_max"],
                gamma_rel_diff=fm["gamma_rel_diff"],
                text=(f"precision='mixed' (float32 pair sums) runs the full d = "
                      f"{p['setting']['d']} simulation {fm['speedup']:.2g}x faster at "
                      f"{fm['error_max']:.1e} relative trajectory error (max over time); "
                      + (f"{fm['gamma_rel_diff']:.1e} relative change of Gamma(T)"
                         if above_floor(p["full"]["gamma_T"], p["full"]["gamma_floor"]) else
                         f"Gamma(T) near float64's round-off floor "
                         f"({p['full']['gamma_floor']:.1g}) in both")))
    g = studies.get("integrators")
    if g:
        def t_of(m, e):
            rs = [r for r in g["rows"] if r["method"] == m]
            return time_to_reach([r["time_s"] for r in rs], [r["error"] for r in rs], e)

        te = t_of("euler", 1e-3)
        tr4 = t_of("rk4", 1e-8)
        t45 = t_of("rk45", 1e-8)
        best_rk4 = min(r["error"] for r in g["rows"] if r["method"] == "rk4")
        best_eu = min(r["error"] for r in g["rows"] if r["method"] == "euler")
        if te and tr4:
            text = f"RK4 reaches 1e-8 at {tr4 / te:.2g}x the cost of Euler at 1e-3"
        else:
            text = (f"Euler at best {best_eu:.1e}, RK4 at best {best_rk4:.1e} in the measured range")
        if te and t45:
            text += f"; adaptive RK45 reaches 1e-8 at {t45 / te:.2g}x"
        eu_best_t = min(r["time_s"] for r in g["rows"]
                        if r["method"] == "euler" and r["error"] == best_eu)
        t_rk4_same = t_of("rk4", best_eu)
        if t_rk4_same:
            text += (f"; Euler's best ({best_eu:.1e}, {max(r['steps'] for r in g['rows'] if r['method'] == 'euler')}"
                     f" steps) costs {eu_best_t / t_rk4_same:.2g}x what RK4 needs for the same error")
        out["integrators"] = dict(euler_1e3_s=te, rk4_1e8_s=tr4, rk45_1e8_s=t45,
                                  ratio_rk4_1e8_vs_euler_1e3=(tr4 / te) if te and tr4 else None,
                                  text=text)
    q = studies.get("quantization")
    if q:
        a = q["atoms_for_eps"]
        iso, dec = int(a["isotropic"]), int(a["decaying"])
        out["quantization"] = dict(eps=q["eps_target"], d=q["setting"]["d"], atoms_isotropic=a["isotropic"],
                                   atoms_decaying=a["decaying"],
                                   text=(f"the delayed-curse budget reaches eps = {q['eps_target']:g} "
                                         f"(product-l1 bound) with N = {dec} atoms for widths "
                                         f"{q['setting']['rho']:g}^j in d = {q['setting']['d']}, "
                                         f"where the isotropic grid needs N = {_fmt_int(iso)}"))
    r = studies.get("recovery")
    if r:
        rows = [x for x in r["rows"] if x["tol"] == min(y["tol"] for y in r["rows"])]
        best = min(rows, key=lambda x: x["error"])
        out["recovery"] = dict(L=best["L"], error=best["error"], time_s=best["time_s"],
                               text=(f"L = {best['L']} projections into R^{r['setting']['k']} "
                                     f"recover the sparse velocities in R^{r['setting']['d']} to "
                                     f"{100 * best['error']:.2g}% in {best['time_s']:.2g} s "
                                     f"(simulations + solve; the full simulation takes "
                                     f"{r['full_time_s']:.2g} s)"))
    w = studies.get("w1")
    if w:
        n = max(x["N"] for x in w["rows"])
        by = {x["method"]: x for x in w["rows"] if x["N"] == n}
        text = f"at N = {n} in d = {w['setting']['d']}: exact {by['exact']['time_s']:.2g} s"
        if "exact-lazy" in by:
            text += f", exact-lazy {by['exact-lazy']['time_s'] / by['exact']['time_s']:.2g}x that"
        b = by["bracket"]
        text += (f", certified bracket {b['time_s'] / by['exact']['time_s']:.2g}x the exact time "
                 f"with relative width {100 * b['rel_width']:.2g}%")
        out["w1"] = dict(N=n, text=text)
    return out


def _fmt_int(n: int) -> str:
    return str(n) if n < 10**9 else f"{float(n):.2e}"


def run(cfg: CostConfig | None = None, *, out_dir=None, progress: bool = True) -> CostResult:
    """Run the studies of ``cfg``; with ``out_dir`` write the result folder (see :func:`write_outputs`).

    Parameters
    ----------
    cfg : CostConfig, optional
        Default: the full study (:class:`CostConfig`).
    out_dir : path, optional
    progress : bool
        tqdm bar on stderr (with time remaining).

    Returns
    -------
    CostResult
    """
    cfg = cfg or CostConfig()
    if not isinstance(cfg, CostConfig):
        raise InvalidInput(f"cfg must be a CostConfig, got {type(cfg).__name__}")
    fns = {"projection": _study_projection, "recovery": _study_recovery,
           "quantization": _study_quantization, "integrators": _study_integrators, "w1": _study_w1}
    t0 = time.perf_counter()
    studies, times = {}, {}
    with _tqdm(_n_units(cfg), progress) as bar:
        for name in STUDIES:
            if name in cfg.studies:
                bar.set_postfix_str(name)
                ts = time.perf_counter()
                studies[name] = fns[name](cfg, bar)
                times[name] = time.perf_counter() - ts
    result = CostResult(cfg, studies, headline(studies, cfg), machine_info(),
                        time.perf_counter() - t0, times)
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


# ---------------------------------------------------------------------------------------------
# figures and report


def _front(ax, times, errors):
    idx = pareto_front(times, errors)
    if idx.size > 1:
        t = np.asarray(times)[idx]
        e = np.asarray(errors)[idx]
        ax.step(t, e, where="post", color="0.6", lw=4, alpha=0.35, zorder=0, label="Pareto front")


def _fig_projection(p: dict, plt):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    ax = axes[0]
    alls_t, alls_e = [], []
    for kind in dict.fromkeys(r["kind"] for r in p["summary"]):
        rs = [r for r in p["summary"] if r["kind"] == kind]
        t = [r["time_s"] for r in rs]
        e = [r["error_final"] for r in rs]
        alls_t += t
        alls_e += e
        ax.loglog(t, e, "o-", label=f"{kind}: error at T")
        ax.loglog(t, [r["error_max"] for r in rs], "x:", alpha=0.6, label=f"{kind}: max over t")
        if kind == rs[0]["kind"]:
            for r in rs:
                ax.annotate(f"k={r['k']}", (r["time_s"], r["error_final"]), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
    _front(ax, alls_t, alls_e)
    ax.axvline(p["full"]["time_s"], color="k", ls="--", lw=1,
               label=f"full d={p['setting']['d']}: {p['full']['time_s']:.2g} s")
    fm = p.get("full_mixed")
    if fm and fm["error_max"] > 0:
        ax.loglog([fm["time_s"]], [fm["error_max"]], "k*", ms=10,
                  label=f"full, precision='mixed': {fm['time_s']:.2g} s (max error)")
    ax.set_xlabel("wall time of one simulation [s]")
    ax.set_ylabel("relative trajectory error (positions)")
    ax.set_title(f"projected dimension k: N={p['setting']['N']}, d={p['setting']['d']}")
    ax.legend(fontsize=7)
    ax = axes[1]
    for kind in dict.fromkeys(r["kind"] for r in p["summary"]):
        rs = [r for r in p["summary"] if r["kind"] == kind]
        ax.semilogx([r["time_s"] for r in rs], [100 * r["verdict_agreement"] for r in rs], "o-",
                    label=kind)
    ax.axvline(p["full"]["time_s"], color="k", ls="--", lw=1)
    ax.set_ylim(-5, 105)
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("flocking verdict agrees with full [%]")
    ax.set_title(f"verdict of the full run: {p['full']['verdict']} "
                 f"(Gamma(T) = {p['full']['gamma_T']:.2g})")
    ax.legend(fontsize=8)
    return fig


def _fig_recovery(r: dict, plt):
    fig, ax = plt.subplots(figsize=(7.5, 5))
    ts, es = [], []
    for tol in dict.fromkeys(x["tol"] for x in r["rows"]):
        rs = [x for x in r["rows"] if x["tol"] == tol]
        t, e = [x["time_s"] for x in rs], [x["error"] for x in rs]
        ts += t
        es += e
        ax.loglog(t, e, "o-", label=f"tol = {tol:g}")
    for x in r["rows"]:
        if x["tol"] == r["rows"][0]["tol"]:
            ax.annotate(f"L={x['L']}", (x["time_s"], x["error"]), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
    _front(ax, ts, es)
    ax.set_xlabel("wall time: L projected simulations + batched basis pursuit [s]")
    ax.set_ylabel("relative recovery error of v(t)")
    ax.set_title(f"recovery: L projections into R^{r['setting']['k']}, d = {r['setting']['d']}")
    ax.legend(fontsize=8)
    return fig


def _fig_quantization(q: dict, plt):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    d = q["setting"]["d"]
    ax = axes[0]
    for name, style in (("isotropic", "o-"), ("decaying", "s-")):
        rs = q["rows"][name]
        n = np.array([x["n_atoms"] for x in rs], dtype=float)
        e = np.array([x["product_l1"] for x in rs])
        ax.loglog(n, e, style, label=f"{name}: product-l1 (upper bound of W1)")
        ex = [(x["n_atoms"], x["euclidean_to_fine"]) for x in rs if "euclidean_to_fine" in x]
        if ex:
            ax.loglog(*zip(*ex), style[0] + ":", mfc="none",
                      label=f"{name}: exact Euclidean W1 to {q['setting']['fine_atoms']} atoms")
        ax.loglog(n, [x["bound"] for x in rs], "--", lw=1, alpha=0.7,
                  label=f"{name}: budget bound (4.22)")
        if name == "isotropic":
            m = n > 1
            if np.any(m):
                c = e[m][0] * n[m][0] ** (1.0 / d)
                ax.loglog(n[m], c * n[m] ** (-1.0 / d), "k-", lw=0.8,
                          label=f"slope -1/d = -1/{d} (the curse)")
    ax.set_xlabel("atoms N")
    ax.set_ylabel("W1 error")
    ax.set_title(f"atoms: d = {d}, widths 1 vs {q['setting']['rho']:g}^j")
    ax.legend(fontsize=7)
    ax = axes[1]
    for name, style in (("isotropic", "o-"), ("decaying", "s-")):
        rs = q["rows"][name]
        t = [x["time_s"] for x in rs]
        e = [x["product_l1"] for x in rs]
        ax.loglog(t, e, style, label=name)
        if name == "decaying":
            _front(ax, t, e)
    ax.set_xlabel("wall time: budget + materialized atoms [s]")
    ax.set_ylabel("product-l1 W1 error (upper bound)")
    ax.set_title("error vs time")
    ax.legend(fontsize=8)
    return fig


def _fig_integrators(g: dict, plt):
    fig, ax = plt.subplots(figsize=(7.5, 5))
    ts, es = [], []
    for m in _FIXED + _ADAPTIVE:
        rs = [x for x in g["rows"] if x["method"] == m]
        if not rs:
            continue
        t = [x["time_s"] for x in rs]
        e = [max(x["error"], 1e-16) for x in rs]
        ts += t
        es += e
        ax.loglog(t, e, "o-" if m in _FIXED else "s--", label=m + (" (rtol)" if m in _ADAPTIVE else " (dt)"))
    _front(ax, ts, es)
    for y in (1e-3, 1e-8):
        ax.axhline(y, color="0.7", lw=0.8, ls=":")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("relative error of the state at T")
    ax.set_title(f"integrators: Cucker-Smale N={g['setting']['N']}, d={g['setting']['d']}, "
                 f"T={g['setting']['T']:g}")
    ax.legend(fontsize=8)
    return fig


def _fig_w1(w: dict, plt):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for m, style in (("exact", "o-"), ("exact-lazy", "s-"), ("bracket", "^-")):
        rs = [x for x in w["rows"] if x["method"] == m]
        if rs:
            axes[0].loglog([x["N"] for x in rs], [x["time_s"] for x in rs], style, label=m)
    axes[0].set_xlabel("atoms N = M")
    axes[0].set_ylabel("wall time [s]")
    axes[0].set_title(f"W1 methods, d = {w['setting']['d']}")
    axes[0].legend(fontsize=8)
    rs = [x for x in w["rows"] if x["method"] == "bracket"]
    axes[1].loglog([x["time_s"] for x in rs], [x["rel_width"] for x in rs], "^-",
                   label="bracket: certified (upper-lower)/W1")
    axes[1].loglog([x["time_s"] for x in rs], [max(x["rel_error"], 1e-16) for x in rs], "v:",
                   label="bracket: |value - W1|/W1")
    for x in rs:
        axes[1].annotate(f"N={x['N']}", (x["time_s"], x["rel_width"]), fontsize=7, xytext=(3, 3),
                         textcoords="offset points")
    ex = [x for x in w["rows"] if x["method"] == "exact"]
    for x in ex:
        axes[1].axvline(x["time_s"], color="0.8", lw=0.8)
    axes[1].set_xlabel("wall time [s] (grey lines: exact at each N)")
    axes[1].set_ylabel("relative accuracy")
    axes[1].set_title("bracket accuracy vs time (exact methods: 0 error)")
    axes[1].legend(fontsize=8)
    return fig


def _tables(result: CostResult):
    from ..report import Table

    s = result.studies
    out = {}
    if "projection" in s:
        p = s["projection"]
        rows = [["full", p["setting"]["d"], p["full"]["time_s"], 0.0, 0.0, 100.0, 1.0]]
        fm = p.get("full_mixed")
        if fm:
            rows.append(["full, precision mixed", p["setting"]["d"], fm["time_s"],
                         fm["error_final"], fm["error_max"], 100.0 * fm["agrees"], fm["speedup"]])
        rows += [[r["kind"], r["k"], r["time_s"], r["error_final"], r["error_max"],
                  100 * r["verdict_agreement"], r["speedup"]] for r in p["summary"]]
        out["projection"] = Table(["kind", "k", "time [s]", "error at T", "max error",
                                   "verdict agrees [%]", "speed-up"], rows,
                                  caption="median time and mean errors over repetitions")
    if "recovery" in s:
        out["recovery"] = Table(["L", "m = kL", "tol", "simulations [s]", "solve [s]", "total [s]",
                                 "error", "converged [%]", "max iter"],
                                [[x["L"], x["m"], x["tol"], x["simulate_s"], x["solve_s"], x["time_s"],
                                  x["error"], 100 * x["converged_fraction"], x["max_iterations"]]
                                 for x in s["recovery"]["rows"]])
    if "quantization" in s:
        q = s["quantization"]
        rows = []
        for name, rs in q["rows"].items():
            for x in rs:
                rows.append([name, x["n_atoms"], " ".join(map(str, x["counts"])), x["time_s"],
                             x["product_l1"], x["bound"], x.get("euclidean_to_fine", "")])
        out["quantization"] = Table(["measure", "N", "N_j", "time [s]", "product-l1 (≥ W1)",
                                     "bound", "exact W1 to fine"], rows)
    if "integrators" in s:
        out["integrators"] = Table(["method", "steps", "dt", "rtol", "rhs evals", "time [s]", "error"],
                                   [[x["method"], x["steps"], "" if x["dt"] is None else x["dt"],
                                     "" if x["rtol"] is None else x["rtol"], x["rhs_evals"],
                                     x["time_s"], x["error"]] for x in s["integrators"]["rows"]])
    if "w1" in s:
        out["w1"] = Table(["N", "method", "time [s]", "value", "|value-W1|/W1", "certified width/W1"],
                          [[x["N"], x["method"], x["time_s"], x["value"], x["rel_error"],
                            x["rel_width"]] for x in s["w1"]["rows"]])
    return out


_TITLES = {
    "projection": "Projected dimension k and projection kind",
    "recovery": "Number of projections L and solver tolerance (recovery)",
    "quantization": "Atoms: the curse and the delayed curse",
    "integrators": "Time step and integrator",
    "w1": "W1 method",
}


def write_outputs(result: CostResult, out_dir) -> Path:
    """Write ``cost.json``, ``cost_<study>.png``, ``cost.txt``, ``report.html``; ``summary.json`` last."""
    from ..io import ResultFolder
    from ..report import Report, figure_png
    from ..report._figures import pyplot

    plt = pyplot()
    folder = ResultFolder(out_dir)
    makers = {"projection": _fig_projection, "recovery": _fig_recovery,
              "quantization": _fig_quantization, "integrators": _fig_integrators, "w1": _fig_w1}
    tables = _tables(result)
    m = result.machine
    rep = Report("kinred cost: what accuracy costs in time",
                 subtitle=f"{m['cpu']}, {m['cores']} logical cores, Python {m['python']}, "
                          f"NumPy {m['numpy']}; total wall time {result.wall_time:.1f} s. "
                          "Timings are wall-clock on this machine (noisy if it is shared).")
    rep.section("Headline", [h["text"] for h in result.headline.values()])
    text_lines = ["kinred cost -- headline", ""] + [f"- {h['text']}" for h in result.headline.values()]
    for name in STUDIES:
        if name not in result.studies:
            continue
        st = result.studies[name]
        setting = ", ".join(f"{k}={v}" for k, v in st.get("setting", {}).items())
        sec = rep.section(_TITLES[name], [setting, f"wall time of this study: "
                                                   f"{result.study_times.get(name, 0.0):.1f} s"])
        sec.tables.append(tables[name])
        png = figure_png(makers[name](st, plt))
        folder.write_bytes(f"cost_{name}.png", png)
        sec.add_figure(_TITLES[name], png)
        text_lines += ["", _TITLES[name], tables[name].to_text()]
    folder.write_text("cost.txt", "\n".join(text_lines) + "\n")
    folder.write_text("report.html", rep.to_html())
    folder.write_json("cost.json", _jsonable(result.to_json()))
    return folder.mark_complete({"study": "cost", "wall_time_s": result.wall_time,
                                 "headline": {k: v["text"] for k, v in result.headline.items()},
                                 "machine": result.machine})


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj
