r"""Step-size controllers: which steps a run tries and which it keeps.

A controller is a small frozen configuration; ``controller.init(solver, t0, t1, dt, method)``
validates it against the run and returns the per-run state, which the loop of ``simulate``
asks three things::

    h, t_end, lands = run.propose(t, n, target_t, target_n)   # the next step
    keep = run.judge(t, state, new_state, error)              # after the solver's step
    run.accepted(t, solver, solver_state)                     # after the accepted step's checks

``target_t`` is the next save time (``target_n`` its step index on a fixed grid, else None);
``lands`` says that the step ends on it.

:class:`ConstantStep` takes ``(t1 − t0)/dt`` steps of size ``dt`` (step ``n`` ends at
``t0 + n·dt``) and keeps them all.

:class:`AdaptiveStep` is the integral controller of embedded pairs (Hairer, Nørsett & Wanner,
*Solving ODEs I*, §II.4): the error of a step is the RMS of its estimate scaled per component
by ``atol + rtol·max(|y|, |y_new|)``; a step with error ``≤ 1`` is kept; the next step is
``h·min(max_factor, max(min_factor, safety·err^(−1/q)))`` with ``q = min(p, p̂) + 1``; steps
are shortened to hit every save time exactly (step-to-hit). Besides success a run ends in
one of three ways:

* the step budget ``max_steps`` (accepted plus rejected steps) is spent;
* the proposed step falls below the floor ``max(floor·(t1 − t0), 16 ulp(t))`` (the tolerance
  cannot be met, or the drift is non-finite however small the step);
* the problem is *stiff* and the budget cannot reach ``t1``: Hairer's test of DOPRI5
  (*Solving ODEs I*, §II.10; ``nstiff`` of ``dopri5.f``) estimates the local Lipschitz
  constant from the last two stages, which are evaluated at the same time,
  ``ρ̂ = ‖k_s − k_{s−1}‖ / ‖y_new − Y_{s−1}‖`` (``solver.stiffness_estimate``); when
  ``h·ρ̂`` sits at the method's stability boundary on 15 consecutive tests the step is limited
  by stability, not accuracy, and it cannot grow while the stiffness lasts: at that step
  ``t1`` would need about ``(t1 − t)/h`` more steps. When that exceeds the budget the run
  stops at once.

The first two raise :class:`~kinred.errors.NotConverged` naming the time reached, the step,
the accepted and rejected steps and a hint; a drift that stays non-finite down to the floor
raises :class:`~kinred.errors.SimulationDiverged`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from .._validate import as_float, as_int
from ..errors import InvalidInput, KinredWarning, NotConverged
from ._guard import diverged

__all__ = ["ConstantStep", "AdaptiveStep", "default_max_steps"]

#: The stiffness test runs on every ``_STIFF_EVERY``-th accepted step (and on every step while
#: it is positive); ``_STIFF_HITS`` consecutive positives declare the problem stiff, six
#: negatives reset the count (Hairer's constants, with 100 instead of 1000).
_STIFF_EVERY = 100
#: Smallest relative tolerance (SciPy's ``solve_ivp``: 100 machine epsilons); below it the
#: error of a step is round-off, not truncation.
RTOL_MIN = 100 * float(np.finfo(float).eps)
_STIFF_HITS = 15


def default_max_steps(span: float, dt: float) -> int:
    """Default step budget of the adaptive methods: ``max(100 000, 1000·⌈span/dt⌉)``."""
    return max(100_000, 1000 * int(math.ceil(span / dt - 1e-9)))


@dataclass(frozen=True)
class ConstantStep:
    """Fixed steps of size ``dt``; ``(t1 − t0)/dt`` must be an integer.

    Step ``n`` ends at ``t0 + n·dt``; every step is kept.

    Examples
    --------
    >>> ConstantStep().init(None, 0.0, 1.0, 0.25, "euler").n_steps
    4
    """

    adaptive = False

    def init(self, solver, t0: float, t1: float, dt: float, method: str) -> "_Constant":
        """Per-run state; refuses a span that is not a whole number of steps."""
        span = t1 - t0
        nf = span / dt
        n_steps = int(round(nf))
        if n_steps < 1 or abs(n_steps - nf) > 1e-9 * max(1.0, nf):
            raise InvalidInput(f"t_span and dt: (t1 - t0)/dt must be a positive integer for "
                               f"method={method!r}, got {span!r}/{dt!r} = {nf!r}")
        return _Constant(t0, dt, n_steps)


class _Constant:
    """Run state of :class:`ConstantStep`: step ``n`` covers ``[t0 + (n−1)dt, t0 + n·dt]``."""

    n_rejected = 0

    def __init__(self, t0, dt, n_steps):
        self.t0, self.dt, self.n_steps = t0, dt, n_steps
        self.n = 0

    def propose(self, t, n, target_t, target_n):
        self.n = n + 1
        return self.dt, self.t0 + self.n * self.dt, self.n == target_n

    def judge(self, t, state, new, err):
        return True

    def accepted(self, t, solver, solver_state):
        pass


@dataclass(frozen=True)
class AdaptiveStep:
    """Integral step-size control of embedded pairs with a step budget.

    The error of a step is the RMS of the solver's estimate scaled per component by
    ``atol + rtol·max(|y|, |y_new|)``; a step with error ``≤ 1`` is kept; the next step is
    ``h·min(max_factor, max(min_factor, safety·err^(−1/q)))``, ``q = min(p, p̂) + 1`` (``p``,
    ``p̂`` the orders of the solution and of the embedded one); steps are shortened to end
    exactly on the save times. The run stops with :class:`~kinred.errors.NotConverged` when
    ``max_steps`` accepted plus rejected steps are spent, when the step falls below
    ``max(floor·(t1 − t0), 16 ulp(t))``, or when Hairer's stiffness test (for solvers with a
    ``stiffness_estimate``: ``h·ρ̂`` at the stability boundary on 15 consecutive tests)
    shows that the budget cannot reach ``t1``; a drift that stays non-finite down to the
    floor raises :class:`~kinred.errors.SimulationDiverged`.

    Parameters
    ----------
    rtol, atol : float
        Relative (``> 0``) and absolute (``≥ 0``) tolerances. As in SciPy's ``solve_ivp``,
        an ``rtol`` below 100 machine epsilons (``2.2e-14``) is raised to it with a
        :class:`~kinred.errors.KinredWarning`; with ``atol = 0`` a component whose error is
        exactly 0 meets the tolerance even where its scale is 0 (a coordinate that stays 0),
        and a non-zero error over a zero scale rejects the step.
    max_steps : int, optional
        Budget of accepted plus rejected steps; default ``max(100 000, 1000·⌈(t1 − t0)/dt⌉)``.
    safety : float
        Factor in ``(0, 1]`` on the optimal step.
    min_factor, max_factor : float
        Bounds of the step change per step (``0 < min_factor < 1 < max_factor``); a step with
        a non-finite error is retried at ``min_factor`` times its size.
    floor : float
        Relative step floor in ``(0, 1)``: the run stops when the step falls below
        ``max(floor·(t1 − t0), 16 ulp(t))``.

    Examples
    --------
    >>> AdaptiveStep(rtol=1e-8, atol=1e-10).safety
    0.9
    """

    rtol: float = 1e-6
    atol: float = 1e-9
    max_steps: int | None = None
    safety: float = 0.9
    min_factor: float = 0.2
    max_factor: float = 5.0
    floor: float = 1e-12

    adaptive = True

    def __post_init__(self):
        fix = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        fix("rtol", as_float(self.rtol, "rtol", low=0.0, low_open=True))
        if self.rtol < RTOL_MIN:
            warnings.warn(f"rtol={self.rtol!r} is below 100 machine epsilons, where the error "
                          f"estimate is round-off; using rtol={RTOL_MIN!r}", KinredWarning,
                          stacklevel=3)
            fix("rtol", RTOL_MIN)
        fix("atol", as_float(self.atol, "atol", low=0.0))
        if self.max_steps is not None:
            fix("max_steps", as_int(self.max_steps, "max_steps", low=1))
        fix("safety", as_float(self.safety, "safety", low=0.0, low_open=True, high=1.0))
        fix("min_factor", as_float(self.min_factor, "min_factor", low=0.0, low_open=True,
                                   high=1.0, high_open=True))
        fix("max_factor", as_float(self.max_factor, "max_factor", low=1.0, low_open=True))
        fix("floor", as_float(self.floor, "floor", low=0.0, low_open=True, high=1.0,
                              high_open=True))

    def init(self, solver, t0: float, t1: float, dt: float, method: str) -> "_Adaptive":
        """Per-run state for ``solver`` (its order and the order of its error estimate)."""
        return _Adaptive(self, solver, t0, t1, dt, method)


def _sq_ratio(e, scale, atol) -> float:
    """``Σ (e/scale)²``, where an exact zero error counts 0 even over a zero scale (``atol = 0``
    on a component that stays 0: ``0/0``, which met the tolerance, not a non-finite drift)."""
    if atol > 0:
        return float(np.sum((e / scale) ** 2))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return float(np.sum(np.where(e == 0, 0.0, (e / scale) ** 2)))


def _finite(new, err) -> bool:
    """Whether the proposed state and its error estimate are finite (else the drift is not)."""
    return all(a is None or bool(np.isfinite(a).all()) for a in (*new, *err))


class _Stiffness:
    """Hairer's stiffness test on the solver's Lipschitz estimates (module notes)."""

    def __init__(self, beta):
        self.limit = 0.98 * beta if beta is not None else math.inf
        self.hits = self.misses = 0
        self.rho = math.nan

    def stiff(self, estimate, h, n_acc) -> bool:
        """Run the test if it is due; True once it was positive 15 times in a row."""
        if not (self.hits or n_acc % _STIFF_EVERY == 0):
            return False
        rho = estimate()
        if rho is None:
            return False
        self.rho = rho
        if h * rho > self.limit:
            self.hits += 1
            self.misses = 0
        else:
            self.misses += 1
            if self.misses >= 6:
                self.hits = 0
        return self.hits >= _STIFF_HITS


class _Adaptive:
    """Run state of :class:`AdaptiveStep`: the next step, counters, stiffness test."""

    n_steps = None

    def __init__(self, cfg: AdaptiveStep, solver, t0, t1, dt, method):
        self.cfg, self.method, self.dt = cfg, method, dt
        self.t1 = t1
        self.max_steps = cfg.max_steps or default_max_steps(t1 - t0, dt)
        order = solver.order
        err_order = getattr(solver, "error_order", None) or order - 1
        self.q = min(order, err_order) + 1
        self.floor_at = max(cfg.floor * (t1 - t0), 16.0 * np.spacing(max(abs(t0), abs(t1))))
        self.h = dt
        self.n_acc = self.n_rejected = 0
        self.stiffness = (_Stiffness(getattr(solver, "stability", None))
                          if hasattr(solver, "stiffness_estimate") else None)

    def propose(self, t, n, target_t, target_n):
        hh = min(self.h, target_t - t)
        self.hh, self.hit = hh, hh >= target_t - t
        return hh, (target_t if self.hit else t + hh), self.hit

    def _norm(self, state, new, err):
        cfg = self.cfg
        (x, v), (xn, vn), (ex, ev) = state, new, err
        sc = cfg.atol + cfg.rtol * np.maximum(np.abs(x), np.abs(xn))
        err2 = _sq_ratio(ex, sc, cfg.atol)
        cnt = ex.size
        if v is not None:
            scv = cfg.atol + cfg.rtol * np.maximum(np.abs(v), np.abs(vn))
            err2 += _sq_ratio(ev, scv, cfg.atol)
            cnt += ev.size
        return math.sqrt(err2 / cnt)

    def judge(self, t, state, new, err):
        """Keep the step? Sets the next step; a rejection may end the run (module notes)."""
        cfg, hh = self.cfg, self.hh
        if err is None:
            raise InvalidInput(f"method={self.method!r} is registered as adaptive but its step "
                               f"returned no error estimate")
        e = self._norm(state, new, err)
        if not math.isfinite(e) and _finite(new, err):
            e = math.inf  # a finite error beyond a zero scale (atol = 0): an ordinary rejection
        elif not math.isfinite(e):
            self.h = hh * cfg.min_factor
            self.n_rejected += 1
            if self.h < self.floor_at:
                raise diverged(t, self.n_acc + 1, None, self.method, self.dt,
                               "the drift is non-finite at the current state however small "
                               "the step", "the scene's field is singular or undefined there: "
                               "check its effects (a Field, a custom kernel)")
            self._budget(t)
            return False
        if e <= 1.0:
            self.n_acc += 1
            fac = cfg.max_factor if e == 0 else min(
                cfg.max_factor, max(cfg.min_factor, cfg.safety * e ** (-1.0 / self.q)))
            if self.hit:
                self.h = max(self.h, hh * fac) if hh < self.h else hh * fac
            else:
                self.h = hh * fac
            return True
        self.n_rejected += 1
        self.h = hh * max(cfg.min_factor, cfg.safety * e ** (-1.0 / self.q))
        self._limits(t)
        return False

    def accepted(self, t, solver, solver_state):
        """The stiffness test, the step floor and the budget after an accepted step."""
        st = self.stiffness
        if st is not None and st.stiff(lambda: solver.stiffness_estimate(solver_state),
                                       self.hh, self.n_acc):
            self._stiff(t, self.hh)
        self._limits(t)

    def _limits(self, t):
        if self.h < self.floor_at:
            self._stop(t, f"the step size fell to {self.h:.3g}, below the floor "
                          f"{self.floor_at:.3g} ({self.cfg.floor:g} of the span): the tolerances "
                          f"cannot be met")
        self._budget(t)

    def _budget(self, t):
        if self.n_acc + self.n_rejected >= self.max_steps:
            self._stop(t, f"the step budget max_steps={self.max_steps} is spent")

    def _stiff(self, t, h):
        need = (self.t1 - t) / h
        if self.n_acc + self.n_rejected + need <= self.max_steps:
            return
        rho = self.stiffness.rho
        self._stop(t, (
            f"the problem is stiff: the step h={h:.3g} is limited by stability, not accuracy "
            f"(h·ρ̂ = {h * rho:.3g} on {_STIFF_HITS} consecutive tests, ρ̂ = {rho:.3g} the "
            f"local Lipschitz estimate of the drift, relaxation time 1/ρ̂ = {1 / rho:.3g}), so "
            f"reaching t1 would take about {need:.3g} more steps, more than max_steps="
            f"{self.max_steps}"), stiff=True)

    def _stop(self, t, why, stiff=False):
        cfg, h = self.cfg, self.h if not stiff else self.hh
        if stiff:
            hint = (f"kinred's methods are explicit and need about "
                    f"span·ρ̂/{self.stiffness.limit:.3g} steps for it: shorten t_span (the fast "
                    f"modes relax within about 10/ρ̂), weaken the coupling that makes ρ̂ large, "
                    f"or raise max_steps")
        else:
            hint = (f"loosen rtol={cfg.rtol:g}/atol={cfg.atol:g}, raise max_steps, or check "
                    f"the scene for a stiff or singular drift (a fixed-step method with a "
                    f"stable dt reports a SimulationDiverged with a stable step)")
        raise NotConverged(
            f"adaptive integration (method={self.method!r}) stopped at t={t:.6g} of "
            f"t1={self.t1:.6g}: {why} ({self.n_acc} accepted and {self.n_rejected} rejected "
            f"steps, step size {h:.3g}). Hint: {hint}.")
