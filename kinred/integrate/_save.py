r"""What a run records and when: :class:`SaveAt`, the save grid and the recorder.

Record what is asked, not everything (Diffrax ``SaveAt``): observables at the save times,
full states only on request. The save grid always holds ``t0`` and ``t1``; on a fixed-step run
it lies on the step grid (its points are step indices), an adaptive run steps to hit each of
its times exactly.
"""

from __future__ import annotations

import math
import types
from dataclasses import dataclass
from typing import Any, Mapping, NamedTuple

import numpy as np

from .. import observables as _obs
from .._validate import _short, as_array, as_int, check_alloc, fmt_count
from ..errors import InvalidInput
from ._kernels import Moments, add_shift

__all__ = ["SaveAt", "SaveGrid", "save_grid", "Recorder", "save_points", "check_save_size"]

#: Bytes per save point of the grid (times, step indices and their sorting temporaries) and
#: per recorded observable value (a small array object and its list slot) besides its data.
GRID_POINT_BYTES = 64
OBS_VALUE_BYTES = 128

#: From this many state entries ``N·d`` on, the built-in ``"gamma"`` and ``"lambda"`` are
#: recorded from the loop's compiled pass (:func:`._kernels.state_moments`: no copy of the
#: state, ``Γ`` shared with the divergence guard); they agree with
#: :func:`kinred.observables.gamma` and :func:`~kinred.observables.lambda_` of the saved
#: state to 1e-12 relative. Below it they are those functions' values, bit for bit.
FUSED_MIN = 2 ** 18

#: The built-ins the compiled pass gives: name -> (state index 0 = x, 1 = v).
_FUSED = {"gamma": 1, "lambda": 0}

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
        From ``N·d ≥ 2¹⁸`` on, ``"gamma"`` and ``"lambda"`` are taken from
        the loop's compiled pass over the state (equal to :func:`kinred.observables.gamma`
        and :func:`~kinred.observables.lambda_` to 1e-12 relative; below, bit for bit).
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
        if not (isinstance(self.states, (bool, np.bool_)) or
                (isinstance(self.states, str) and self.states in ("x", "v"))):
            raise InvalidInput(f"states must be True, False, 'x' or 'v'; got {self.states!r}")

    def describe(self) -> str:
        """A one-line summary for messages (``SaveAt(t=<500 times>, states=True)``)."""
        parts = [f"every={self.every}"] if self.every is not None else []
        parts += [f"t=<{len(self.t)} times>"] if self.t is not None else []
        parts += [f"states={self.states!r}"] if self.states is not False else []
        return f"SaveAt({', '.join(parts)})"


def observable_list(spec, order: int) -> list:
    """``[(name, fn(t, x, v, weights))]`` of a :class:`SaveAt`'s ``observables``."""
    if spec is None:
        spec = ("gamma", "lambda") if order == 2 else ("lambda",)
    if isinstance(spec, str) or callable(spec):
        spec = (spec,)
    try:
        items = list(spec.items()) if isinstance(spec, Mapping) else [
            (s if isinstance(s, str) else getattr(s, "__name__", f"obs{i}"), s)
            for i, s in enumerate(spec)]
    except TypeError:
        raise InvalidInput(f"observables must be a sequence or mapping of names and callables, "
                           f"got {_short(spec)}") from None
    out = []
    for name, s in items:
        if isinstance(s, str):
            if s not in _BUILTIN:
                raise InvalidInput(f"observables: {s!r} is unknown; valid names: "
                                   f"{', '.join(map(repr, _BUILTIN))} or a callable "
                                   f"fn(t, x, v, weights)")
            need, fn = _BUILTIN[s]
            if need == 2 and order == 1:
                raise InvalidInput(f"observables: {s!r} needs velocities; the scene is "
                                   "first-order")
            out.append((name, fn))
        elif callable(s):
            out.append((name, s))
        else:
            raise InvalidInput(f"observables must be names or callables, got {s!r}")
    return out


def _check_save(save) -> None:
    if not isinstance(save, SaveAt):
        raise InvalidInput(f"save must be a kinred.integrate.SaveAt, got {_short(save)}")


def save_points(save: SaveAt, t0: float, t1: float, dt: float, n_steps: int | None) -> int:
    """An upper bound of the number of save points of a run (nothing is built)."""
    _check_save(save)
    if save.t is not None:
        return len(save.t) + 2
    every = save.every or 1
    if n_steps is not None:
        return n_steps // every + 2
    return int(math.floor((t1 - t0) / (every * dt) + 1e-9)) + 2


_SAVE_HINT = ("save fewer points (SaveAt(every=...) or fewer times t), fewer states "
              "(SaveAt(states=False, 'x' or 'v')) or a shorter t_span")


def check_save_size(save: SaveAt, n_save: int, shape: tuple, order: int, n_obs: int,
                    call: str, hint: str = _SAVE_HINT) -> None:
    """The memory preflight (``kinred._validate.check_alloc``) of what a run records: the save
    grid, the observables (scalars counted; ``centre`` and ``mean_velocity`` have ``d``
    entries) and the states ``(T, N, d)`` requested by ``save.states`` (none requested: the
    final state); ``call`` names the run's arguments in the message."""
    _check_save(save)
    n, d = shape
    n_states = int(save.states in (True, "x")) + int(save.states in (True, "v") and order == 2)
    per_point = GRID_POINT_BYTES + n_obs * (OBS_VALUE_BYTES + 16 * d) + 8 * n * d * n_states
    states = f", states (T, N, d) = ({fmt_count(n_save)}, {n}, {d}) x {n_states}" if n_states else ""
    final = 0 if isinstance(save.states, str) or save.states else 8 * n * d * order
    if final:                                      # the final state kept by default
        states = f", the final state (N, d) = ({n}, {d}) x {order}"
    check_alloc(n_save * per_point + final, f"{call}: recording {fmt_count(n_save)} save points",
                hint, detail=f" ({n_obs} observables{states})")


class SaveGrid(NamedTuple):
    """Save points: ``times (T,)`` from ``t0`` to ``t1``; ``steps (T,)`` their step indices on a
    fixed grid (None for adaptive runs)."""

    times: np.ndarray
    steps: np.ndarray | None


def save_grid(save: SaveAt, t0: float, t1: float, dt: float, n_steps: int | None,
              method: str) -> SaveGrid:
    """The save points of a run of ``n_steps`` fixed steps (None: adaptive) of ``save``.

    Examples
    --------
    >>> save_grid(SaveAt(every=3), 0.0, 1.0, 0.1, 10, "euler").steps
    array([ 0,  3,  6,  9, 10])
    >>> save_grid(SaveAt(every=3), 0.0, 1.0, 0.1, None, "rk45").times
    array([0. , 0.3, 0.6, 0.9, 1. ])
    """
    _check_save(save)
    if n_steps is not None:
        return _fixed_grid(save, t0, t1, dt, n_steps, method)
    if save.t is not None:
        if save.t[0] < t0 or save.t[-1] > t1:
            raise InvalidInput(f"SaveAt t must lie in t_span [{t0}, {t1}], got "
                               f"[{save.t[0]}, {save.t[-1]}]")
        times = np.unique(np.concatenate([[t0], save.t, [t1]]))
    else:
        every = save.every or 1
        m = int(math.floor((t1 - t0) / (every * dt) + 1e-9))
        times = np.unique(np.concatenate([t0 + np.arange(m + 1) * every * dt, [t1]]))
        times = times[times <= t1]
    return SaveGrid(times, None)


def _fixed_grid(save, t0, t1, dt, n_steps, method):
    if save.t is not None:
        idx = np.rint((save.t - t0) / dt).astype(np.int64)
        off = np.abs(t0 + idx * dt - save.t)
        if np.any(off > 1e-9 * max(1.0, abs(t1))) or np.any(idx < 0) or np.any(idx > n_steps):
            bad = save.t[int(np.argmax(off))] if np.any(off > 1e-9 * max(1.0, abs(t1))) else \
                save.t[(idx < 0) | (idx > n_steps)][0]
            raise InvalidInput(f"SaveAt t must lie on the step grid t0 + n*dt within t_span "
                               f"for method={method!r}; got t={bad!r}")
        steps = np.unique(np.concatenate([[0], idx, [n_steps]]))
    else:
        every = save.every or 1
        steps = np.unique(np.concatenate([np.arange(0, n_steps + 1, every), [n_steps]]))
    times = t0 + steps * dt
    times[-1] = t1
    return SaveGrid(times, steps)


class Recorder:
    """Records the observables and requested states at the save points.

    Parameters
    ----------
    save : SaveAt
    obs : list of (name, fn)
        From :func:`observable_list`.
    scene : Scene
    w : (N,) ndarray
        Agent weights (passed to the observables).
    shift : (d,) ndarray or None
        Working positions are relative to it (added back before recording).
    shape : (int, int)
        ``(N, d)``.
    n_save : int
        Number of save points.
    """

    def __init__(self, save, obs, scene, w, shift, shape, n_save):
        self.obs, self.w, self.shift = obs, w, shift
        self.rec = {name: [] for name, _ in obs}
        fused = shape[0] * shape[1] >= FUSED_MIN
        # (name, state index) of the observables taken from the compiled pass
        self.fused = [(name, _FUSED[name]) for name, fn in obs
                      if fused and name in _FUSED and fn is _BUILTIN[name][1]]
        self.plain = [(name, fn) for name, fn in obs if (name, _FUSED.get(name)) not in
                      self.fused]
        self.moments = (Moments(w, shift), Moments(w))     # of x (+ shift), of v
        want_x = save.states in (True, "x")
        want_v = save.states in (True, "v") and scene.order == 2
        self.X = np.empty((n_save, *shape)) if want_x else None
        self.V = np.empty((n_save, *shape)) if want_v else None
        # no states requested: keep the final one (Diffrax's default, SaveAt(t1=True)), one
        # copy at the last save point and nothing per step
        self.last = n_save - 1 if not isinstance(save.states, str) and not save.states else -1
        self.final = None
        self.pending = None         # the shift still to be added to the final positions

    def __call__(self, j, t, x, v, v_moments=None, known=None):
        """Record save point ``j`` at time ``t`` from the working state ``(x, v)``;
        ``v_moments``: :func:`._kernels.state_moments` of ``v`` if known (the guard's);
        ``known``: those ``(of x + shift, of v)`` when the step gave them."""
        if known is not None:
            v_moments = known[1] if known[1] is not None else v_moments
        for name, k in self.fused:
            if k == 1 and v_moments is None:
                v_moments = self.moments[1](v)
            val = (v_moments[0] if k == 1 else known[0][0] if known is not None and
                   known[0] is not None else self.moments[0](x)[0])
            self.rec[name].append(np.asarray(val, dtype=float))
        xt = x
        if self.shift is not None and (self.plain or self.X is not None):
            xt = np.add(x, self.shift, out=self.X[j] if self.X is not None else None)
        elif self.shift is not None and j == self.last:
            # the final state alone: the shift is added in place once the run is over
            # (:meth:`states`; observers still see the working positions)
            self.final = (x[None], None if v is None else v[None])
            self.pending = self.shift
            return
        for name, fn in self.plain:
            self.rec[name].append(np.asarray(fn(t, xt, v, self.w), dtype=float))
        if self.X is not None and xt is x:
            self.X[j] = x
        if self.V is not None:
            self.V[j] = v
        if j == self.last:
            # the run ends here: the working arrays become the result (no copy)
            self.final = (xt[None], None if v is None else v[None])

    def states(self, times: np.ndarray) -> tuple:
        """``(x, v, t_states)``: the recorded states and their times (the save times), or,
        when none were requested, the final state ``(1, N, d)`` at ``times[-1]``."""
        if self.pending is not None:
            x = self.final[0][0]
            if x.ndim == 2 and x.dtype == np.float64 and x.flags.writeable:
                add_shift(x, self.pending)      # np.add(x, shift)'s rounding, in place
            else:
                x += self.pending
            self.pending = None
        if self.final is not None:
            return self.final[0], self.final[1], np.asarray(times[-1:], dtype=float)
        if self.X is None and self.V is None:
            return None, None, np.empty(0)
        return self.X, self.V, np.asarray(times, dtype=float)

    def observables(self) -> Mapping[str, np.ndarray]:
        """The recorded observables, ``(T, ...)`` arrays in a read-only mapping."""
        return types.MappingProxyType({k: np.array(vals) for k, vals in self.rec.items()})
