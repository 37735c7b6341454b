r"""``simulate``: one entry point for every integrator (Diffrax ``diffeqsolve`` style)."""

from __future__ import annotations

import math
import time
import types
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .. import observables as _obs
from .._rng import as_generator
from .._validate import as_array, as_choice, as_float, as_int, as_span
from ..errors import InvalidInput, NotConverged, SimulationDiverged
from ..dynamics import Scene, SelfPropulsion
from ._tables import TABLES, RKTable

__all__ = ["simulate", "SaveAt", "Trajectory", "METHODS"]

#: Available methods: fixed-step ``"euler"`` (the paper's, eq. (1.6)), ``"heun"``, ``"rk4"``;
#: adaptive embedded pairs ``"rk45"`` (Dormand–Prince 5(4)) and ``"rk23"`` (Bogacki–Shampine
#: 3(2)); ``"euler_maruyama"`` for scenes with noise.
METHODS = ("euler", "heun", "rk4", "rk45", "rk23", "euler_maruyama")
_ADAPTIVE = ("rk45", "rk23")

_BUILTIN = {
    "gamma": (2, lambda t, x, v, w: _obs.gamma(v, w)),
    "lambda": (1, lambda t, x, v, w: _obs.lambda_(x, w)),
    "centre": (1, lambda t, x, v, w: _obs.centre(x, w)),
    "mean_velocity": (2, lambda t, x, v, w: _obs.mean_velocity(v, w)),
}


@dataclass(frozen=True)
class SaveAt:
    """What to record and when.

    Parameters
    ----------
    every : int, optional
        Save every ``every`` steps of size ``dt`` (times ``t0 + j·every·dt``); for adaptive
        methods the same time grid is hit exactly. Default: every step.
    t : (T,) array_like, optional
        Explicit save times in ``[t0, t1]`` (on the step grid for fixed-step methods).
        Exclusive with ``every``.
    observables : sequence or mapping, optional
        Names among ``"gamma"``, ``"lambda"``, ``"centre"``, ``"mean_velocity"`` and/or
        callables ``fn(t, x, v, weights) -> array`` (keyed by ``fn.__name__``; a mapping gives
        the keys). Default: ``("gamma", "lambda")`` (``("lambda",)`` for first-order scenes).
    states : bool or {"x", "v"}
        Record full states (``True``: both) – off by default.

    Examples
    --------
    >>> SaveAt(every=50, observables=("gamma",)).every
    50
    """

    every: int | None = None
    t: Any = None
    observables: Any = None
    states: Any = False

    def __post_init__(self):
        if self.every is not None and self.t is not None:
            raise InvalidInput("SaveAt takes either every or t, not both")
        if self.every is not None:
            object.__setattr__(self, "every", as_int(self.every, "every", low=1))
        if self.t is not None:
            t = np.sort(as_array(self.t, "t", ndim=1))
            object.__setattr__(self, "t", t)
        if self.states not in (True, False, "x", "v"):
            raise InvalidInput(f"states must be True, False, 'x' or 'v'; got {self.states!r}")


@dataclass(frozen=True)
class Trajectory:
    """Result of :func:`simulate`.

    Attributes
    ----------
    t : (T,) ndarray
        Saved times (always including ``t0`` and the final time).
    observables : mapping of str to ndarray
        ``(T,)`` or ``(T, ...)`` arrays, one per requested observable.
    x, v : (T, N, d) ndarray or None
        States when requested (``v`` None for first-order scenes).
    method : str
    n_steps : int
        Accepted steps.
    n_rhs_evals : int
        Evaluations of the scene's drift.
    wall_time : float
        Seconds spent in :func:`simulate`.
    dt : float
        Step size (initial step for adaptive methods).
    n_rejected : int
        Rejected steps (adaptive methods).
    """

    t: np.ndarray
    observables: Mapping[str, np.ndarray]
    x: np.ndarray | None
    v: np.ndarray | None
    method: str
    n_steps: int
    n_rhs_evals: int
    wall_time: float
    dt: float
    n_rejected: int = 0


def _observable_list(spec, order):
    if spec is None:
        spec = ("gamma", "lambda") if order == 2 else ("lambda",)
    items = list(spec.items()) if isinstance(spec, Mapping) else [
        (s if isinstance(s, str) else getattr(s, "__name__", f"obs{i}"), s) for i, s in enumerate(spec)]
    out = []
    for name, s in items:
        if isinstance(s, str):
            if s not in _BUILTIN:
                raise InvalidInput(f"observable {s!r} is unknown; valid names: "
                                   f"{', '.join(map(repr, _BUILTIN))} or a callable fn(t, x, v, weights)")
            need, fn = _BUILTIN[s]
            if need == 2 and order == 1:
                raise InvalidInput(f"observable {s!r} needs velocities; the scene is first-order")
            out.append((name, fn))
        elif callable(s):
            out.append((name, s))
        else:
            raise InvalidInput(f"observables must be names or callables, got {s!r}")
    return out


def _hint(scene, dt, v):
    for e in scene.effects:
        if isinstance(e, SelfPropulsion) and e.b > 0 and v is not None:
            vmax = float(np.max(np.einsum("ij,ij->i", v, v))) if np.all(np.isfinite(v)) else float("nan")
            return (f"explicit step too large for self-propulsion with b={e.b}: stability of "
                    f"(a - b|v|^2) v needs dt*b*max|v|^2 small (<~1); at the start "
                    f"dt*b*max|v0|^2 = {dt * e.b * vmax:.3g}. Reduce dt or use method='rk45'.")
    return "reduce dt, or use an adaptive method (method='rk45') with rtol/atol."


def simulate(scene: Scene, x0, v0=None, t_span=(0.0, 1.0), dt: float = 0.01, *,
             method: str = "euler", save: SaveAt | None = None, seed=None, progress: bool = False,
             rtol: float = 1e-6, atol: float = 1e-9) -> Trajectory:
    r"""Integrate a scene from ``(x0, v0)`` over ``t_span``.

    Forward Euler is the paper's scheme (eq. (1.6), label ``eq:eul1``; on a projected scene
    it is eq. (2.4)–(2.5)). When every effect is translation invariant the run is carried out
    in coordinates relative to the initial centroid (positions are shifted back when saved),
    which keeps distances accurate for clouds far from the origin.

    Parameters
    ----------
    scene : Scene
    x0 : (N, d) array_like
    v0 : (N, d) array_like or None
        None for first-order scenes.
    t_span : (float, float)
        ``(t0, t1)`` with ``t1 > t0``.
    dt : float
        Step (fixed-step methods; ``(t1 − t0)/dt`` must be an integer) or the initial step
        and save-grid unit of adaptive methods.
    method : str
        One of :data:`METHODS`. Scenes with noise require ``"euler_maruyama"``.
    save : SaveAt, optional
        Default ``SaveAt()`` (observables every step, no states).
    seed : None, int, SeedSequence or Generator
        Noise seed (Euler–Maruyama).
    progress : bool
        Show a tqdm progress bar.
    rtol, atol : float
        Tolerances of adaptive methods.

    Returns
    -------
    Trajectory

    Raises
    ------
    SimulationDiverged
        The state became NaN/Inf; the message names the time, the step and a hint.

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> rng = np.random.default_rng(0)
    >>> x0, v0 = rng.uniform(0, 1, (20, 3)), rng.uniform(-1, 1, (20, 3))
    >>> scene = Scene([Alignment(CuckerSmale(G=0.8, beta=1.5))], normalize="sum")
    >>> tr = simulate(scene, x0, v0, (0.0, 2.0), 0.02, save=SaveAt(every=50))
    >>> tr.t
    array([0., 1., 2.])
    >>> bool(tr.observables["gamma"][-1] < tr.observables["gamma"][0])
    True
    """
    t_start = time.perf_counter()
    if not isinstance(scene, Scene):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
    x0, v0 = scene._check_state(x0, v0)
    t0, t1 = as_span(t_span)
    dt = as_float(dt, "dt", low=0.0, low_open=True)
    method = as_choice(method, "method", METHODS)
    if scene.stochastic and method != "euler_maruyama":
        raise InvalidInput(f"method={method!r} cannot integrate a scene with noise; use "
                           "method='euler_maruyama'")
    save = SaveAt() if save is None else save
    if not isinstance(save, SaveAt):
        raise InvalidInput(f"save must be a SaveAt, got {save!r}")
    rtol = as_float(rtol, "rtol", low=0.0, low_open=True)
    atol = as_float(atol, "atol", low=0.0)
    rng = as_generator(seed) if scene.stochastic else None
    obs = _observable_list(save.observables, scene.order)
    n_agents, dim = x0.shape
    w = scene.agent_weights(n_agents)

    shift = _obs.centre(x0, w) if scene.translation_invariant else None
    x = x0 - shift if shift is not None else x0.copy()
    v = v0.copy() if v0 is not None else None

    adaptive = method in _ADAPTIVE
    span = t1 - t0
    if not adaptive:
        nf = span / dt
        n_steps = int(round(nf))
        if n_steps < 1 or abs(n_steps - nf) > 1e-9 * max(1.0, nf):
            raise InvalidInput(f"(t1 - t0)/dt must be a positive integer for method={method!r}, "
                               f"got {span!r}/{dt!r} = {nf!r}")
        if save.t is not None:
            idx = np.rint((save.t - t0) / dt).astype(np.int64)
            off = np.abs(t0 + idx * dt - save.t)
            if np.any(off > 1e-9 * max(1.0, abs(t1))) or np.any(idx < 0) or np.any(idx > n_steps):
                bad = save.t[int(np.argmax(off))] if np.any(off > 1e-9 * max(1.0, abs(t1))) else \
                    save.t[(idx < 0) | (idx > n_steps)][0]
                raise InvalidInput(f"SaveAt t must lie on the step grid t0 + n*dt within t_span "
                                   f"for method={method!r}; got t={bad!r}")
            save_idx = np.unique(np.concatenate([[0], idx, [n_steps]]))
        else:
            every = save.every or 1
            save_idx = np.unique(np.concatenate([np.arange(0, n_steps + 1, every), [n_steps]]))
        save_times = t0 + save_idx * dt
        save_times[-1] = t1
    else:
        if save.t is not None:
            if save.t[0] < t0 or save.t[-1] > t1:
                raise InvalidInput(f"SaveAt t must lie in t_span [{t0}, {t1}], got "
                                   f"[{save.t[0]}, {save.t[-1]}]")
            save_times = np.unique(np.concatenate([[t0], save.t, [t1]]))
        else:
            every = save.every or 1
            m = int(math.floor(span / (every * dt) + 1e-9))
            save_times = np.unique(np.concatenate([t0 + np.arange(m + 1) * every * dt, [t1]]))
            save_times = save_times[save_times <= t1]
        n_steps = None
        save_idx = None

    T = len(save_times)
    rec = {name: [] for name, _ in obs}
    want_x = save.states in (True, "x")
    want_v = save.states in (True, "v") and scene.order == 2
    X = np.empty((T, n_agents, dim)) if want_x else None
    V = np.empty((T, n_agents, dim)) if want_v else None
    counter = {"rhs": 0}

    def record(j, tt, xs, vs):
        xt = xs + shift if shift is not None else xs
        for name, fn in obs:
            rec[name].append(np.asarray(fn(tt, xt, vs, w), dtype=float))
        if want_x:
            X[j] = xt
        if want_v:
            V[j] = vs

    def f(tt, xs, vs):
        counter["rhs"] += 1
        return scene._rhs(xs, vs, tt)

    def diverged(tt, step, total):
        total_s = f" of {total}" if total is not None else ""
        raise SimulationDiverged(
            f"simulation diverged at t={tt:.6g} (step {step}{total_s}, method={method!r}, "
            f"dt={dt:g}): the state became non-finite (NaN/Inf/overflow). Hint: "
            f"{_hint(scene, dt, v0)}", t=float(tt), step=int(step))

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_steps if n_steps is not None else T - 1, desc=f"simulate[{method}]")

    record(0, t0, x, v)
    n_rej = 0
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        if not adaptive:
            table = TABLES["euler" if method == "euler_maruyama" else method]
            # one-stage methods update the (private) state in place through one scratch
            # array: the same rounding as x + dt·dx, no fresh multi-megabyte array per step
            tmp = np.empty_like(x) if table.stages == 1 else None
            j = 1
            for n in range(1, n_steps + 1):
                tn = t0 + (n - 1) * dt
                if tmp is not None:
                    dx, dv = f(tn, x, v)
                    np.multiply(dx, dt, out=tmp)     # dx may be v itself: x first, then v
                    x += tmp
                    if v is not None:
                        np.multiply(dv, dt, out=tmp)
                        v += tmp
                else:
                    x, v = _rk_step(f, table, tn, x, v, dt)
                if rng is not None:
                    dX, dV = scene.noise_increment(rng, n_agents, dim, dt)
                    if dX is not None:
                        x += dX
                    if dV is not None:
                        v += dV
                s = float(np.sum(x)) + (float(np.sum(v)) if v is not None else 0.0)
                if not math.isfinite(s):
                    diverged(t0 + n * dt, n, n_steps)
                if j < T and n == save_idx[j]:
                    record(j, save_times[j], x, v)
                    j += 1
                if bar is not None:
                    bar.update(1)
            n_done = n_steps
        else:
            table = TABLES[method]
            x, v, n_done, n_rej = _adaptive(f, table, t0, t1, x, v, dt, rtol, atol, save_times,
                                            record, diverged, bar)
    if bar is not None:
        bar.close()
    observables = types.MappingProxyType({k: np.array(vals) for k, vals in rec.items()})
    return Trajectory(t=np.asarray(save_times, dtype=float), observables=observables, x=X, v=V,
                      method=method, n_steps=int(n_done), n_rhs_evals=counter["rhs"],
                      wall_time=time.perf_counter() - t_start, dt=dt, n_rejected=int(n_rej))


def _stages(f, table: RKTable, t, x, v, h, k_first=None):
    """Stage derivatives ``[(dxₛ, dvₛ)]`` of one explicit RK step of size ``h`` from ``(x, v)``.

    ``k_first`` reuses a known first stage (FSAL pairs, or a rejected adaptive step).
    """
    ks = []
    for s in range(table.stages):
        if s == 0 and k_first is not None:
            ks.append(k_first)
            continue
        xs, vs = x, v
        if s:
            xs = x.copy()
            vs = v.copy() if v is not None else None
            for j in range(s):
                a = table.A[s, j]
                if a:
                    xs += (h * a) * ks[j][0]
                    if v is not None:
                        vs += (h * a) * ks[j][1]
        dx, dv = f(t + table.C[s] * h, xs, vs)
        if dx is vs:
            dx = dx.copy()
        ks.append((dx, dv))
    return ks


def _combine(x, v, ks, weights, h):
    """``(x + h Σ wₛ dxₛ, v + h Σ wₛ dvₛ)`` as new arrays."""
    xn = x.copy()
    vn = v.copy() if v is not None else None
    for s, w in enumerate(weights):
        if w:
            xn += (h * w) * ks[s][0]
            if v is not None:
                vn += (h * w) * ks[s][1]
    return xn, vn


def _rk_step(f, table: RKTable, t, x, v, h):
    """One explicit RK step of ``(x, v)``; returns new arrays."""
    if table.stages == 1:
        dx, dv = f(t, x, v)
        xn = x + h * dx
        vn = v + h * dv if v is not None else None
        return xn, vn
    return _combine(x, v, _stages(f, table, t, x, v, h), table.B, h)


def _adaptive(f, table, t0, t1, x, v, h, rtol, atol, save_times, record, diverged, bar):
    """Embedded-pair integration hitting every save time exactly (step-to-hit)."""
    q = min(table.order, table.error_order) + 1
    t = t0
    j = 1
    n_acc = n_rej = 0
    k_first = None
    max_steps = 10_000_000
    while j < len(save_times):
        target = save_times[j]
        hh = min(h, target - t)
        hit = hh >= target - t
        ks = _stages(f, table, t, x, v, hh, k_first)
        xn, vn = _combine(x, v, ks, table.B, hh)
        ex, ev = _combine(np.zeros_like(x), np.zeros_like(v) if v is not None else None, ks,
                          table.E, hh)
        sc = atol + rtol * np.maximum(np.abs(x), np.abs(xn))
        err2 = float(np.sum((ex / sc) ** 2))
        cnt = ex.size
        if v is not None:
            scv = atol + rtol * np.maximum(np.abs(v), np.abs(vn))
            err2 += float(np.sum((ev / scv) ** 2))
            cnt += ev.size
        err = math.sqrt(err2 / cnt)
        if not math.isfinite(err):
            if hh < 1e-12 * max(1.0, abs(t)):
                diverged(t, n_acc + 1, None)
            h = hh * 0.2
            n_rej += 1
            k_first = ks[0]
            continue
        if err <= 1.0:
            t = target if hit else t + hh
            x, v = xn, vn
            n_acc += 1
            k_first = (ks[-1][0], ks[-1][1]) if table.fsal else None
            if k_first is not None and k_first[0] is None:
                k_first = None
            s_ = float(np.sum(x)) + (float(np.sum(v)) if v is not None else 0.0)
            if not math.isfinite(s_):
                diverged(t, n_acc, None)
            if hit:
                record(j, target, x, v)
                j += 1
                if bar is not None:
                    bar.update(1)
            fac = 5.0 if err == 0 else min(5.0, max(0.2, 0.9 * err ** (-1.0 / q)))
            if hit:
                h = max(h, hh * fac) if hh < h else hh * fac
            else:
                h = hh * fac
        else:
            n_rej += 1
            h = hh * max(0.2, 0.9 * err ** (-1.0 / q))
            k_first = ks[0]
        if h < 1e-14 * max(1.0, abs(t)):
            diverged(t, n_acc + 1, None)
        if n_acc + n_rej > max_steps:
            raise NotConverged(f"adaptive integration exceeded {max_steps} steps at t={t:.6g}; "
                               "loosen rtol/atol or check the scene")
    return x, v, n_acc, n_rej
