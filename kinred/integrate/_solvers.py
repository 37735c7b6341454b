r"""Solvers: one step of an integrator as an object (Diffrax ``AbstractSolver`` style).

A solver advances the state ``(x, v)`` (``v`` None for first-order scenes) by one step of a
given size; *which* step sizes are tried and whether a step is kept is the business of a
step-size controller (:mod:`._controllers`), *what* is recorded that of the save grid and the
observers. The protocol (:class:`Solver`)::

    solver_state = solver.init(f, t0, (x0, v0), dt)
    (x, v), error, solver_state = solver.step(f, t, (x, v), h, solver_state, rng)

``f`` is the scene as the solvers see it (:class:`VectorField`): ``f(t, x, v, rng) ->
(dx, dv)`` evaluates the drift with the run's generator (stochastic pair sums need it),
``f.noise(rng, n, dim, h) -> (ΔX, ΔV)`` draws the noise increments of a step. ``error`` is
the local error estimate ``(ex, ev)`` of an embedded pair (None without one); the controller
measures it. A step that returns no error estimate cannot be rejected, so it may update the
state arrays in place; a step with one must leave them untouched (the controller may retry
from the same state).

Two solvers cover kinred's methods:

* :class:`ExplicitRK` — any explicit Runge–Kutta method given by its Butcher table
  (:mod:`._tables`): forward Euler (the paper's, eq. (1.6); eq. (2.4)–(2.5) on a projected
  scene), Heun, RK4, and the embedded pairs Dormand–Prince 5(4) and Bogacki–Shampine 3(2),
  whose first stage reuses the last one of the previous step (FSAL, kept in the solver
  state; a retried step reuses its first stage too) and whose last two stages give the
  stiffness estimate of the adaptive controller;
* :class:`EulerMaruyama` — the Euler step of the drift plus the noise increments
  ``σ ΔW`` (strong order 1 for kinred's additive noise).
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import numpy as np

from . import _kernels
from ._guard import real_stability
from ._tables import EULER, RKTable

__all__ = ["Solver", "VectorField", "ExplicitRK", "EulerMaruyama", "EulerMoments"]


@runtime_checkable
class Solver(Protocol):
    """One step of an integrator.

    Attributes
    ----------
    order : int
        Convergence order of the method.
    error_order : int or None, optional
        Order of the embedded solution of a solver that returns error estimates (default
        ``order − 1``); the adaptive controller's exponent is ``1/(min(order, error_order) + 1)``.
    table : RKTable or None, optional
        The Butcher table whose stability interval the divergence hints use (absent or None:
        generic hints only).
    stability : float, optional
        ``β``: stability interval ``[−β, 0]`` on the negative real axis; with
        ``stiffness_estimate(solver_state) -> float | None`` (the local Lipschitz estimate of
        the last step) it enables the adaptive controller's stiffness test.
    """

    order: int

    def init(self, f, t0: float, state: tuple, dt: float):
        """The solver state before the first step (e.g. the first stage of an FSAL pair)."""

    def step(self, f, t: float, state: tuple, h: float, solver_state, rng):
        """``(new_state, error_estimate | None, new_solver_state)`` of a step ``t → t + h``."""


class VectorField:
    """The scene as the solvers see it: the drift with an evaluation count, and the noise.

    Parameters
    ----------
    scene : Scene

    Attributes
    ----------
    n_evals : int
        Evaluations of the drift so far.
    """

    def __init__(self, scene):
        self.scene = scene
        self.n_evals = 0
        self._out = None

    def __call__(self, t, x, v, rng=None):
        """``(dx, dv)``: the scene's drift at ``(t, x, v)`` in arrays the caller keeps; for
        order 2 ``dx`` is ``v``."""
        return self._evaluate(t, x, v, rng, None)

    def transient(self, t, x, v, rng=None):
        """The drift as a call of the field gives it (the same values), in arrays valid
        only until the next ``transient`` call: a pair-sum backend that ``accepts_out``
        writes into arrays kept for the whole run instead of fresh ones. For a step that
        consumes its one stage at once (forward Euler in place): at N = 10⁵, d = 200 the
        fresh pages of the sums cost about 10 % of a random batch evaluation."""
        if type(self).__call__ is not VectorField.__call__:
            return self(t, x, v, rng)       # a subclass's own evaluation (fresh arrays)
        out = None
        if getattr(self.scene.pairsum, "accepts_out", False) is True:
            if self._out is None or self._out[0] != x.shape:      # once per run and shape
                self._out = (x.shape, {term.target: np.empty(x.shape)
                                       for term in self.scene.pair_terms.terms})
            out = self._out[1]
        return self._evaluate(t, x, v, rng, out)

    def _evaluate(self, t, x, v, rng, out):
        """The one evaluation both calls go through (the hook for subclasses that watch
        every evaluation, as the certificate's field does)."""
        self.n_evals += 1
        return self.scene._rhs(x, v, t, rng, out=out)

    def euler_step(self, t, x, v, h, rng, w, shift, centres):
        """Forward Euler's step in place by the pair-sum backend's fused step
        (``Scene._euler_fused``): the row sums ``(r, acc)`` of the new state, or None
        (nothing done) when the backend has none or a subclass watches the evaluations."""
        if (type(self).__call__ is not VectorField.__call__
                or type(self)._evaluate is not VectorField._evaluate):
            return None
        got = self.scene._euler_fused(x, v, t, h, rng, w, shift, centres)
        if got is not None:
            self.n_evals += 1
        return got

    def noise(self, rng, n: int, dim: int, h: float):
        """``(ΔX, ΔV)`` of all noise effects over a step ``h`` (None where absent)."""
        return self.scene.noise_increment(rng, n, dim, h)


def _transient(f, t, x, v, rng):
    """The drift of a step that consumes it at once: :meth:`VectorField.transient` when ``f``
    has it, else ``f(t, x, v, rng)``."""
    fn = getattr(f, "transient", None)
    return fn(t, x, v, rng) if fn is not None else f(t, x, v, rng)


def _stages(f, table: RKTable, t, x, v, h, k_first, rng):
    """Stage derivatives ``[(dxₛ, dvₛ)]`` of one explicit RK step of size ``h`` from ``(x, v)``.

    ``k_first`` reuses a known first stage (FSAL pairs, or a retried step).
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
        dx, dv = f(t + table.C[s] * h, xs, vs, rng)
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


def _euler_in_place(x, dx, v, dv, h, solver_state):
    """``x ← x + h·dx``, then ``v ← v + h·dv``, in place: by the compiled kernel
    (:mod:`._kernels`, one pass, no temporary) for float64 arrays of one shape, else through
    numpy and a scratch array; the same rounding either way."""
    if _f64_like(x, (x, dx) if v is None else (x, dx, v, dv)):
        _kernels.euler(x, dx, v, dv, float(h))
        return
    if solver_state.scratch is None:
        solver_state.scratch = np.empty_like(x)
    _kernels.euler_numpy(x, dx, v, dv, h, solver_state.scratch)


def _f64_like(x, arrays) -> bool:
    return x.ndim == 2 and all(type(a) is np.ndarray and a.dtype == np.float64 and
                               a.shape == x.shape for a in arrays)


class EulerMoments:
    """Forward Euler's in-place step (:class:`ExplicitRK` of ``EULER``) that also gives the
    moments ``(F, S, T)`` (:func:`._kernels.state_moments`) of the new positions and
    velocities, from the same pass over the state (:func:`._kernels.euler_moments`; with a
    backend that takes the step itself, its fused step: :meth:`VectorField.euler_step`,
    :func:`._kernels.step_moments`): the loop's finiteness test, the divergence guard's
    ``Γ`` and the recorded ``Γ`` and ``Λ`` need no pass of their own. The state is
    bit-identical to :class:`ExplicitRK`'s step.

    Parameters
    ----------
    w : (N,) ndarray
        Agent weights.
    mx, mv : Moments
        The run's moments of ``x (+ shift)`` and of ``v`` (their reference centres are
        carried over and updated).
    """

    def __init__(self, w, mx, mv):
        self.w, self.mx, self.mv = w, mx, mv

    def __call__(self, f, t, state, h, solver_state, rng):
        """``((x, v), (moments of x, moments of v or None))`` after one step ``t → t + h``."""
        x, v = state
        step = getattr(f, "euler_step", None)
        if step is not None and _f64_like(x, (x,) if v is None else (x, v)):
            m = _kernels.step_moments(
                x, v, self.w, self.mx.shift, [self.mx.ready(x)] +
                ([] if v is None else [self.mv.ready(v)]),
                lambda sh, c: step(t, x, v, h, rng, self.w, sh, c))
            if m is not None:           # the backend's fused step: one pass over the state
                return (x, v), m
        dx, dv = _transient(f, t, x, v, rng)
        if _f64_like(x, (x, dx) if v is None else (x, dx, v, dv)):
            centres = [self.mx.ready(x)] + ([] if v is None else [self.mv.ready(v)])
            m = _kernels.euler_moments(x, dx, v, dv, float(h), self.w, self.mx.shift, centres)
        else:
            _euler_in_place(x, dx, v, dv, h, solver_state)
            m = self.mx(x), (None if v is None else self.mv(v))
        return (x, v), m


def _sq(pair):
    return sum(float(np.sum(a * a)) for a in pair if a is not None)


class _RKState:
    """Solver state of :class:`ExplicitRK`: ``k0``, the derivative at the current state when
    known (the last stage of an FSAL pair, or the first stage of a rejected try), the stages
    and size of the last step (stiffness estimate), or the scratch array of the in-place
    one-stage step."""

    __slots__ = ("k0", "ks", "h", "scratch")

    def __init__(self, k0=None, ks=None, h=0.0, scratch=None):
        self.k0, self.ks, self.h, self.scratch = k0, ks, h, scratch


class ExplicitRK:
    """An explicit Runge–Kutta method from its Butcher table.

    A stage ``s`` evaluates ``kₛ = f(t + Cₛh, y + h Σ_{j<s} A_{sj} kⱼ)``; the step is
    ``y + h Σₛ Bₛ kₛ`` and, for an embedded pair, the error estimate ``h Σₛ Eₛ kₛ``.

    A one-stage table without error estimate (forward Euler, eq. (1.6)) updates the state in
    place in one compiled pass (``x ← x + dx·h``, then ``v``; the same rounding as numpy's
    ``tmp = dx·h; x += tmp``; no fresh array per step).

    Parameters
    ----------
    table : RKTable

    Examples
    --------
    >>> from kinred.integrate import RK4
    >>> rk4 = ExplicitRK(RK4)
    >>> f = lambda t, x, v, rng: (-x, None)          # x' = -x
    >>> y0 = (np.ones((1, 1)), None)
    >>> (x, _), err, _ = rk4.step(f, 0.0, y0, 0.1, rk4.init(f, 0.0, y0, 0.1), None)
    >>> R = 1 - 0.1 + 0.1**2 / 2 - 0.1**3 / 6 + 0.1**4 / 24     # R(z), z = -0.1
    >>> bool(abs(x[0, 0] - R) < 1e-15), err
    (True, None)
    """

    def __init__(self, table: RKTable):
        self.table = table
        self.name = table.name
        self.order = table.order
        self.error_order = table.error_order
        self._in_place = table.stages == 1 and table.E is None
        # y_new − Y_{s−1} = h Σ (B − A_{s−1}) k (stiffness estimate of FSAL pairs)
        self._stiff_weights = table.B - table.A[-2] if table.fsal else None

    @property
    def stability(self) -> float:
        """``β``: the stability interval on the negative real axis is ``[−β, 0]``."""
        return real_stability(self.table)

    def init(self, f, t0, state, dt):
        """An empty state (the in-place one-stage step makes its scratch array if needed)."""
        return _RKState()

    def step(self, f, t, state, h, solver_state, rng):
        """One step of size ``h`` from ``(t, state)``; see :class:`Solver`."""
        x, v = state
        if self._in_place:
            dx, dv = _transient(f, t, x, v, rng)
            _euler_in_place(x, dx, v, dv, h, solver_state)
            return (x, v), None, solver_state
        table = self.table
        ks = _stages(f, table, t, x, v, h, solver_state.k0, rng)
        solver_state.k0 = ks[0]         # f(t, y): a retry from the same state reuses it
        new = _combine(x, v, ks, table.B, h)
        err = None
        if table.E is not None:
            err = _combine(np.zeros_like(x), np.zeros_like(v) if v is not None else None, ks,
                           table.E, h)
        k0 = ks[-1] if table.fsal else None
        return new, err, _RKState(k0=k0, ks=ks if table.fsal else None, h=h)

    def stiffness_estimate(self, solver_state) -> float | None:
        """``ρ̂ = ‖k_s − k_{s−1}‖ / ‖y_new − Y_{s−1}‖`` of the last step of an FSAL pair.

        The last two stages are evaluated at the same time, so ``ρ̂`` estimates the local
        Lipschitz constant of the drift (the stiffness test of :class:`AdaptiveStep`). None
        when the table is not FSAL or the estimate is undefined.
        """
        ks = solver_state.ks
        if ks is None:
            return None
        (a1, b1), (a0, b0) = ks[-1], ks[-2]
        num = _sq((a1 - a0, None if b1 is None else b1 - b0))
        z = np.zeros_like(a1)
        den = _sq(_combine(z, None if b1 is None else np.zeros_like(b1), ks, self._stiff_weights,
                           solver_state.h))
        if den <= 0.0 or not math.isfinite(num):
            return None
        return math.sqrt(num / den)

    def __repr__(self) -> str:
        return f"ExplicitRK({self.table.name})"


class EulerMaruyama:
    """Euler–Maruyama: the forward-Euler step of the drift plus the noise increments.

    ``x ← x + h·dx``, ``v ← v + h·dv`` (in place, as :class:`ExplicitRK` for Euler), then
    ``x ← x + ΔX``, ``v ← v + ΔV`` with the increments ``σ√h ξ`` (``M σ√h ξ`` on a projected
    scene) of the scene's noise effects, drawn from ``rng`` in the order of the effects.
    Strong order 1 for additive noise (1/2 in general); a scene without noise gets Euler.

    Examples
    --------
    >>> em = EulerMaruyama()
    >>> em.table.name, em.error_order
    ('euler', None)
    """

    order = 1
    error_order = None

    def __init__(self):
        self._drift = ExplicitRK(EULER)
        self.table = EULER
        self.name = "euler_maruyama"

    def init(self, f, t0, state, dt):
        """The scratch array of the in-place Euler step."""
        return self._drift.init(f, t0, state, dt)

    def step(self, f, t, state, h, solver_state, rng):
        """One Euler–Maruyama step; see :class:`Solver`."""
        (x, v), _, solver_state = self._drift.step(f, t, state, h, solver_state, rng)
        dX, dV = f.noise(rng, x.shape[0], x.shape[1], h)
        if dX is not None:
            x += dX
        if dV is not None:
            v += dV
        return (x, v), None, solver_state

    def __repr__(self) -> str:
        return "EulerMaruyama()"
