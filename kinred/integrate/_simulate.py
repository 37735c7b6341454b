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
from ..errors import InvalidInput, SimulationDiverged
from ..dynamics import Scene
from ._guard import Guard, step_hint
from ._rk import Adaptive, default_max_steps, rk_step
from ._tables import TABLES

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


def _save_plan(save, t0, t1, dt, method, adaptive):
    """``(n_steps, save_idx, save_times)``; fixed steps: indices on the grid, adaptive: times."""
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
        return n_steps, save_idx, save_times
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
    return None, None, save_times


def simulate(scene: Scene, x0, v0=None, t_span=(0.0, 1.0), dt: float = 0.01, *,
             method: str = "euler", save: SaveAt | None = None, seed=None, progress: bool = False,
             rtol: float = 1e-6, atol: float = 1e-9, max_steps: int | None = None) -> Trajectory:
    r"""Integrate a scene from ``(x0, v0)`` over ``t_span``.

    Forward Euler is the paper's scheme (eq. (1.6); on a projected scene
    it is eq. (2.4)–(2.5)). When every effect is translation invariant the run is carried out
    in coordinates relative to the initial centroid (positions are shifted back when saved),
    which keeps distances accurate for clouds far from the origin.

    Every accepted step is checked in ``O(N·d)``: the state must stay finite and, for scenes
    whose energy budget is known (alignment with ``g ≥ 0``, Morse attraction–repulsion,
    self-propulsion, drifts, noise), the velocity fluctuation ``Γ`` (or ``Σᵢwᵢ|vᵢ|²`` with
    self-propulsion) must stay within 100 times an a-priori bound of the exact flow (for pure
    alignment: ``Γ`` never grows). An explicit step that is unstable for the scene (e.g. Euler
    with ``dt·ρ > 2``, ``ρ`` the spectral radius of the alignment Laplacian) is stopped within
    a few steps of the first amplification. See ``kinred.integrate._guard``.

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
        Show a tqdm progress bar (steps for fixed-step methods; the time reached out of
        ``t1 − t0``, with its rate and remaining time, for adaptive ones).
    rtol, atol : float
        Tolerances of adaptive methods.
    max_steps : int, optional
        Budget of accepted plus rejected steps of adaptive methods; default
        ``max(100 000, 1000·⌈(t1 − t0)/dt⌉)``.

    Returns
    -------
    Trajectory

    Raises
    ------
    SimulationDiverged
        The state became NaN/Inf or grew past the bound of the exact flow; the message names
        the time, the step, the quantity that grew and a hint with a stable step estimated
        from the states (also in the attribute ``stable_dt``).
    NotConverged
        An adaptive method spent ``max_steps``, its step fell below ``1e-12·(t1 − t0)``, or
        the problem is stiff and the budget cannot reach ``t1``; the message names the time
        reached, the step size, the accepted and rejected steps and a hint.

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
    adaptive = method in _ADAPTIVE
    max_steps = (default_max_steps(t1 - t0, dt) if max_steps is None
                 else as_int(max_steps, "max_steps", low=1))
    rng = as_generator(seed) if scene.stochastic else None
    obs = _observable_list(save.observables, scene.order)
    n_agents, dim = x0.shape
    w = scene.agent_weights(n_agents)
    n_steps, save_idx, save_times = _save_plan(save, t0, t1, dt, method, adaptive)

    shift = _obs.centre(x0, w) if scene.translation_invariant else None
    x = x0 - shift if shift is not None else x0.copy()
    v = v0.copy() if v0 is not None else None

    T = len(save_times)
    rec = {name: [] for name, _ in obs}
    want_x = save.states in (True, "x")
    want_v = save.states in (True, "v") and scene.order == 2
    X = np.empty((T, n_agents, dim)) if want_x else None
    V = np.empty((T, n_agents, dim)) if want_v else None
    counter = {"rhs": 0}
    table = TABLES["euler" if method == "euler_maruyama" else method]
    guard = Guard(scene, v0, w, t0) if scene.order == 2 else None

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

    def diverged(tt, step, xs, vs, why=None, hint=None):
        total_s = f" of {n_steps}" if n_steps is not None else ""
        stable = None
        if hint is None:
            hint, stable = step_hint(scene, table, None if adaptive else dt,
                                     [(t0, x0, v0), (tt, xs, vs)])
        why = why or "the state became non-finite (NaN/Inf/overflow)"
        raise SimulationDiverged(
            f"simulation diverged at t={tt:.6g} (step {step}{total_s}, method={method!r}, "
            f"dt={dt:g}): {why}. Hint: {hint}", t=float(tt), step=int(step), stable_dt=stable)

    def check(tt, step, xs, vs):
        s = float(np.sum(xs)) + (float(np.sum(vs)) if vs is not None else 0.0)
        if not math.isfinite(s):
            diverged(tt, step, xs, vs)
        why = guard.check(tt, vs) if guard is not None else None
        if why is not None:
            diverged(tt, step, xs, vs, why)

    bar = None
    if progress:
        from tqdm import tqdm
        bar = (tqdm(total=n_steps, desc=f"simulate[{method}]") if not adaptive else
               tqdm(total=t1 - t0, desc=f"simulate[{method}]", unit="t",
                    bar_format="{l_bar}{bar}| t-t0={n:.4g}/{total:.4g} "
                               "[{elapsed}<{remaining}]"))

    record(0, t0, x, v)
    n_rej = 0
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            if not adaptive:
                x, v = _fixed(f, table, scene, rng, t0, dt, n_steps, x, v, save_idx,
                              save_times, record, check, bar)
                n_done = n_steps
            else:
                def on_nonfinite(tt, step, xs, vs):
                    diverged(tt, step, xs, vs, "the drift is non-finite at the current state "
                             "however small the step", "the scene's field is singular or "
                             "undefined there: check its effects (a Field, a custom kernel)")

                run = Adaptive(f, table, rtol, atol, max_steps, check, on_nonfinite, bar)
                x, v = run.run(t0, t1, x, v, dt, save_times, record)
                n_done, n_rej = run.n_acc, run.n_rej
    finally:
        if bar is not None:
            bar.close()
    observables = types.MappingProxyType({k: np.array(vals) for k, vals in rec.items()})
    return Trajectory(t=np.asarray(save_times, dtype=float), observables=observables, x=X, v=V,
                      method=method, n_steps=int(n_done), n_rhs_evals=counter["rhs"],
                      wall_time=time.perf_counter() - t_start, dt=dt, n_rejected=int(n_rej))


def _fixed(f, table, scene, rng, t0, dt, n_steps, x, v, save_idx, save_times, record, check,
           bar):
    """The fixed-step loop (explicit RK, Euler–Maruyama); returns the final ``(x, v)``."""
    n_agents, dim = x.shape
    T = len(save_times)
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
            x, v = rk_step(f, table, tn, x, v, dt)
        if rng is not None:
            dX, dV = scene.noise_increment(rng, n_agents, dim, dt)
            if dX is not None:
                x += dX
            if dV is not None:
                v += dV
        check(t0 + n * dt, n, x, v)
        if j < T and n == save_idx[j]:
            record(j, save_times[j], x, v)
            j += 1
        if bar is not None:
            bar.update(1)
    return x, v
