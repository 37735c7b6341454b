r"""Explicit Runge–Kutta steps and the adaptive embedded-pair loop.

The adaptive loop (step-to-hit save times, error per component scaled by
``atol + rtol·max(|y|, |y_new|)``, the RMS norm) ends in one of three ways besides success:

* the step budget ``max_steps`` (accepted plus rejected steps) is spent;
* the proposed step falls below the floor ``max(1e-12·span, 16 ulp(t))`` (the tolerance cannot
  be met, or the drift is non-finite however small the step);
* the problem is *stiff* and the budget cannot reach ``t1``: Hairer's test of DOPRI5
  (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.10; ``nstiff`` of ``dopri5.f``) estimates
  the local Lipschitz constant from the last two stages, which are evaluated at the same time,
  ``ρ̂ = ‖k_s − k_{s−1}‖ / ‖y_new − Y_{s−1}‖``; when ``h·ρ̂`` sits at the method's stability
  boundary on 15 consecutive tests the step is limited by stability, not accuracy, and it
  cannot grow while the stiffness lasts: at that step ``t1`` would need about
  ``(t1 − t)/h`` more steps. When that exceeds the budget the run stops at once.

The first two raise :class:`~kinred.errors.NotConverged` naming the time reached, the step,
the accepted and rejected steps and a hint; a non-finite drift at the current state raises
:class:`~kinred.errors.SimulationDiverged`.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import NotConverged
from ._guard import real_stability
from ._tables import RKTable

__all__ = ["rk_step", "Adaptive", "default_max_steps"]

#: The stiffness test runs on every ``_STIFF_EVERY``-th accepted step (and on every step while
#: it is positive); ``_STIFF_HITS`` consecutive positives declare the problem stiff, six
#: negatives reset the count (Hairer's constants, with 100 instead of 1000).
_STIFF_EVERY = 100
_STIFF_HITS = 15


def default_max_steps(span: float, dt: float) -> int:
    """Default step budget of the adaptive methods: ``max(100 000, 1000·⌈span/dt⌉)``."""
    return max(100_000, 1000 * int(math.ceil(span / dt - 1e-9)))


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


def rk_step(f, table: RKTable, t, x, v, h):
    """One explicit RK step of ``(x, v)``; returns new arrays."""
    if table.stages == 1:
        dx, dv = f(t, x, v)
        xn = x + h * dx
        vn = v + h * dv if v is not None else None
        return xn, vn
    return _combine(x, v, _stages(f, table, t, x, v, h), table.B, h)


def _sq(pair):
    return sum(float(np.sum(a * a)) for a in pair if a is not None)


class _Stiffness:
    """Hairer's stiffness test on the last two stages of an FSAL pair (module notes)."""

    def __init__(self, table: RKTable):
        self.limit = 0.98 * real_stability(table)
        self.weights = table.B - table.A[-2]     # y_new − Y_{s−1} = h Σ (B − A_{s−1}) k
        self.hits = self.misses = 0
        self.rho = math.nan

    def stiff(self, ks, h, n_acc) -> bool:
        """Run the test if it is due; True once it was positive 15 times in a row."""
        if not (self.hits or n_acc % _STIFF_EVERY == 0):
            return False
        (a1, b1), (a0, b0) = ks[-1], ks[-2]
        num = _sq((a1 - a0, None if b1 is None else b1 - b0))
        z = np.zeros_like(a1)
        den = _sq(_combine(z, None if b1 is None else np.zeros_like(b1), ks, self.weights, h))
        if den <= 0.0 or not math.isfinite(num):
            return False
        self.rho = math.sqrt(num / den)
        if h * self.rho > self.limit:
            self.hits += 1
            self.misses = 0
        else:
            self.misses += 1
            if self.misses >= 6:
                self.hits = 0
        return self.hits >= _STIFF_HITS


class Adaptive:
    """Embedded-pair integration hitting every save time exactly (step-to-hit).

    Parameters
    ----------
    f : callable
        ``f(t, x, v) -> (dx, dv)``.
    table : RKTable
        An embedded FSAL pair (``E`` set).
    rtol, atol : float
    max_steps : int
        Budget of accepted plus rejected steps.
    on_accept : callable
        ``on_accept(t, n_acc, x, v)`` after every accepted step (divergence checks; raises).
    on_nonfinite : callable
        ``on_nonfinite(t, n_acc, x, v)`` when the drift stays non-finite down to the step
        floor (raises SimulationDiverged).
    bar : tqdm or None
        Advanced by the accepted time increments (``total = t1 − t0``).
    """

    def __init__(self, f, table, rtol, atol, max_steps, on_accept, on_nonfinite, bar=None):
        self.f, self.table, self.rtol, self.atol = f, table, rtol, atol
        self.max_steps = max_steps
        self.on_accept, self.on_nonfinite, self.bar = on_accept, on_nonfinite, bar
        self.q = min(table.order, table.error_order) + 1
        self.n_acc = self.n_rej = 0
        self.stiffness = _Stiffness(table)

    def _error(self, x, v, xn, vn, ks, hh):
        ex, ev = _combine(np.zeros_like(x), np.zeros_like(v) if v is not None else None, ks,
                          self.table.E, hh)
        sc = self.atol + self.rtol * np.maximum(np.abs(x), np.abs(xn))
        err2 = float(np.sum((ex / sc) ** 2))
        cnt = ex.size
        if v is not None:
            scv = self.atol + self.rtol * np.maximum(np.abs(v), np.abs(vn))
            err2 += float(np.sum((ev / scv) ** 2))
            cnt += ev.size
        return math.sqrt(err2 / cnt)

    def run(self, t0, t1, x, v, h, save_times, record):
        """Integrate from ``(t0, x, v)`` with first step ``h``; returns ``(x, v)`` at ``t1``."""
        table = self.table
        span = t1 - t0
        floor = max(1e-12 * span, 16.0 * np.spacing(max(abs(t0), abs(t1))))
        t, j, k_first = t0, 1, None
        while j < len(save_times):
            target = save_times[j]
            hh = min(h, target - t)
            hit = hh >= target - t
            ks = _stages(self.f, table, t, x, v, hh, k_first)
            xn, vn = _combine(x, v, ks, table.B, hh)
            err = self._error(x, v, xn, vn, ks, hh)
            if not math.isfinite(err):
                h = hh * 0.2
                self.n_rej += 1
                k_first = ks[0]
                if h < floor:
                    self.on_nonfinite(t, self.n_acc + 1, x, v)
                self._budget(t, t1, h)
                continue
            if err <= 1.0:
                t_old, t = t, (target if hit else t + hh)
                x, v = xn, vn
                self.n_acc += 1
                k_first = (ks[-1][0], ks[-1][1]) if table.fsal else None
                if k_first is not None and k_first[0] is None:
                    k_first = None
                self.on_accept(t, self.n_acc, x, v)
                if self.bar is not None:
                    self.bar.update(t - t_old)
                if hit:
                    record(j, target, x, v)
                    j += 1
                fac = 5.0 if err == 0 else min(5.0, max(0.2, 0.9 * err ** (-1.0 / self.q)))
                if hit:
                    h = max(h, hh * fac) if hh < h else hh * fac
                else:
                    h = hh * fac
                if table.fsal and self.stiffness.stiff(ks, hh, self.n_acc):
                    self._stiff(t, t1, hh)
            else:
                self.n_rej += 1
                h = hh * max(0.2, 0.9 * err ** (-1.0 / self.q))
                k_first = ks[0]
            if h < floor:
                self._stop(t, t1, h, f"the step size fell to {h:.3g}, below the floor "
                           f"{floor:.3g} (1e-12 of the span): the tolerances cannot be met")
            self._budget(t, t1, h)
        return x, v

    def _budget(self, t, t1, h):
        if self.n_acc + self.n_rej >= self.max_steps:
            self._stop(t, t1, h, f"the step budget max_steps={self.max_steps} is spent")

    def _stiff(self, t, t1, h):
        need = (t1 - t) / h
        if self.n_acc + self.n_rej + need <= self.max_steps:
            return
        rho = self.stiffness.rho
        self._stop(t, t1, h, (
            f"the problem is stiff: the step h={h:.3g} is limited by stability, not accuracy "
            f"(h·ρ̂ = {h * rho:.3g} on {_STIFF_HITS} consecutive tests, ρ̂ = {rho:.3g} the "
            f"local Lipschitz estimate of the drift, relaxation time 1/ρ̂ = {1 / rho:.3g}), so "
            f"reaching t1 would take about {need:.3g} more steps, more than max_steps="
            f"{self.max_steps}"), stiff=True)

    def _stop(self, t, t1, h, why, stiff=False):
        method = self.table.name
        if stiff:
            hint = (f"kinred's methods are explicit and need about "
                    f"span·ρ̂/{self.stiffness.limit:.3g} steps for it: shorten t_span (the fast modes relax within about "
                    f"10/ρ̂), weaken the coupling that makes ρ̂ large, or raise max_steps")
        else:
            hint = (f"loosen rtol={self.rtol:g}/atol={self.atol:g}, raise max_steps, or check "
                    f"the scene for a stiff or singular drift (a fixed-step method with a "
                    f"stable dt reports a SimulationDiverged with a stable step)")
        raise NotConverged(
            f"adaptive integration (method={method!r}) stopped at t={t:.6g} of t1={t1:.6g}: "
            f"{why} ({self.n_acc} accepted and {self.n_rej} rejected steps, step size "
            f"{h:.3g}). Hint: {hint}.")
