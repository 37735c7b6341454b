r"""Divergence guard of the explicit integrators and stable-step hints.

The guard
---------
For a second-order scene made of effects whose energy budget is known, the exact flow obeys
an a-priori bound on the velocity second moment

.. math:: Q(t) = \sum_i w_i \|v_i - \bar v\|^2,

with ``v̄`` the weighted mean velocity (then ``Q = Γ``, the velocity fluctuation of §3.4.1)
when no effect depends on absolute velocities, and ``v̄ = 0`` with self-propulsion. For every
``s ≤ t``

.. math::
    Q(t) \le Q(s) + \Delta + p\,(t - s) \quad (\kappa = 0), \qquad
    Q(t) + \tfrac{p}{2\kappa}
        \le \bigl(Q(s) + \Delta + \tfrac{p}{2\kappa}\bigr)\,e^{2\kappa(t - s)},

where each effect adds to ``(Δ, p, κ)`` (``C = Σⱼ cⱼ``, 1 for ``normalize="mean"``) what
it declares through its hooks (:mod:`kinred.dynamics.hooks`: a per-agent effect's
``energy_term``, a pairwise effect's kernel's ``is_nonnegative`` and ``potential_range``);
the built-in ones declare:

* alignment ``Σⱼ cⱼ g(‖·‖)(vⱼ − vᵢ)`` with ``g ≥ 0`` (eq. (2.13)):
  ``dQ/dt = −Σᵢⱼ wᵢ cⱼ gᵢⱼ ‖vᵢ − vⱼ‖² ≤ 0`` (``wᵢcⱼ`` is symmetric): nothing;
* attraction–repulsion with a bounded potential, e.g. Morse (eq. (3.14)): the
  kinetic energy ``Q/2`` trades with ``½ Σᵢⱼ wᵢcⱼ U(‖xᵢ − xⱼ‖) ∈ ½C·[inf U, sup U]``
  (Morse: ``[−C_a, C_r]``): ``Δ += C (sup U − inf U)``;
* self-propulsion ``(a − b‖v‖²) v``: ``p += a²/(2b)`` (``b > 0``), ``κ += a`` (``b = 0``);
* a drift ``c``: nothing for ``Γ``; ``2 Σᵢ wᵢ vᵢ·c ≤ |c|² + Q`` otherwise (``p += |c|²``,
  ``κ += ½``);
* noise ``σ dW``: ``p += σ² tr(M Mᵀ)`` (its expected rate; ``M = I`` unprojected).

The bound holds from every earlier time ``s``, so the guard keeps the best one over the
accepted steps (``O(1)`` per step on top of ``Q``, which costs ``O(N·d)``). A computed ``Q``
above :data:`GROWTH` (10; :data:`GROWTH_NOISE`, 100, with noise) times that bound is neither
round-off nor truncation error: the explicit step amplifies a mode (for alignment under
Euler, ``h·ρ(L) > 2`` with ``L`` the weighted graph Laplacian), and ``simulate`` stops with
:class:`~kinred.errors.SimulationDiverged`. Other scenes (first order, ``Field``, kernels of
unknown sign, effects without the hooks) are checked for non-finite states only.

Stable-step hints
-----------------
:func:`step_hint` bounds the spectral radius of the linearised field at given states by
Gershgorin's theorem, in ``O(N²·d)`` once (only when a run stops):

* alignment: ``ρ(L) ≤ 2 maxᵢ Σⱼ cⱼ |gᵢⱼ|`` (the diagonal gives ``ρ(L) ≥ maxᵢ Σⱼ cⱼ gᵢⱼ``);
* per-agent effects: what their hook ``step_radius(v)`` declares; self-propulsion: the
  Jacobian ``(a − b|v|²) I − 2b v vᵀ`` has radius ``max |a − 3b|vᵢ|²|`` (and ``2a`` on the
  attractor ``|v|² = a/b``), drift and noise: none;
* pair forces ``u(s)(xⱼ − xᵢ)``: the pair Jacobian has norm ``max(|u(s)|, |(s u)′(s)|)``, so
  ``ω̂² = 2 maxᵢ Σⱼ cⱼ ‖Jᵢⱼ‖`` bounds the squared frequency of the oscillations they drive
  (first-order scenes: a relaxation rate).

A method whose stability interval on the negative real axis is ``[−β_m, 0]``
(:func:`real_stability`: 2 for Euler and Heun, 2.79 for RK4, 3.31 for DOPRI5, 2.51 for BS32)
is stable on the dissipative part for ``dt < β_m/ρ̂``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import observables as _obs
from ..dynamics import hooks as _hooks
from ..errors import SimulationDiverged
from ._kernels import Moments, state_moments
from ._tables import RKTable

__all__ = ["GROWTH", "GROWTH_NOISE", "Guard", "DivergenceCheck", "diverged", "energy_budget",
           "real_stability", "step_hint"]

#: Factor by which a computed ``Q`` must exceed the a-priori bound of the exact flow before
#: the run is declared diverged: a stable explicit step stays within truncation error of the
#: bound (for pure alignment under Euler with ``h·ρ ≤ 2``, ``Γ`` never grows at all).
GROWTH = 10.0

#: The factor with noise, whose budget term is an expectation: a chi-square excursion of
#: 100 times it over any window of a 10⁶-step run has probability below 1e-10.
GROWTH_NOISE = 100.0

#: Relative allowance for round-off and truncation: ``Q`` may exceed the bound by this
#: fraction of the largest ``Q`` accepted so far (and, uncentred, of ``Σwᵢ|vᵢ|²``).
_ROUNDOFF = 1e-9

#: Round-off allowance of the centred ``Q``, relative to ``Σwᵢ|vᵢ|²``: ``Q`` is the weighted
#: mean of squared deviations (no cancellation: ``Σwᵢ|vᵢ|² − |v̄|²`` lost every digit of a
#: fluctuation of 1 beside a mean velocity of 1e8), so what remains is the rounding of the
#: velocities themselves, whose Γ after n steps is below ``n u² Σwᵢ|vᵢ|²/3``
#: (:func:`~kinred.observables.gamma_floor`, ``u = 2⁻⁵³``): 1e-20 covers 10¹² steps.
_ROUNDOFF_CENTRED = 1e-20


@dataclass
class Budget:
    """Constants of the a-priori bound (module notes): frame, ``Δ``, ``p``, ``κ`` and why."""

    centred: bool = True
    delta: float = 0.0
    p: float = 0.0
    kappa: float = 0.0
    why: list = field(default_factory=list)


def energy_budget(scene, n: int, dim: int) -> Budget | None:
    """The budget of ``scene`` for ``n`` agents in ``ℝ^dim`` (``None``: unknown or order 1).

    Every effect must declare its term (module notes): a pairwise effect through its kernel's
    hooks (``is_nonnegative()`` for alignment, ``potential_range()`` for a force of positions),
    any other through ``energy_term`` (:mod:`kinred.dynamics.hooks`). The centred frame (Γ) is
    used when every effect has a term there, else the absolute one (self-propulsion).
    """
    if scene.order != 2:
        return None
    total_c = float(np.sum(scene.coefficients(n)))
    for frame in _hooks.FRAMES:
        b = _budget_in(scene, frame, total_c, dim)
        if b is not None:
            return b
    return None


def _budget_in(scene, frame: str, total_c: float, dim: int) -> Budget | None:
    """The budget in ``frame`` (:data:`kinred.dynamics.hooks.FRAMES`), None if an effect has
    no term there."""
    b = Budget(centred=frame == "centred")
    for e in scene.effects:
        tgt = scene._tgt(e)
        if getattr(e, "pairwise", False):
            if e.carrier == "v" and tgt == "v" and _hooks.is_nonnegative(e.kernel):
                b.why.append("alignment with g >= 0 only dissipates it")
                continue
            spread = (_hooks.potential_range(e.kernel)
                      if e.source == "x" and e.carrier == "x" and tgt == "v" else None)
            if spread is None:
                return None
            dq = total_c * spread
            b.delta += dq
            b.why.append(f"the {type(e.kernel).__name__} potential trades at most "
                         f"Σⱼcⱼ·(sup U − inf U) = {dq:.3g}")
            continue
        term = _hooks.energy_term(e, frame=frame, target=tgt, dim=dim)
        if term is None:
            return None
        b.delta += term.delta
        b.p += term.p
        b.kappa += term.kappa
        if term.why:
            b.why.append(term.why)
    return b


class Guard:
    """Checks ``Q(t)`` against the best a-priori bound from the earlier accepted steps.

    Parameters
    ----------
    scene : Scene
    v0 : (N, d) ndarray
    w : (N,) ndarray
        Agent weights.
    t0 : float
    moments : Moments, optional
        The run's moments of ``v``, step after step (:class:`._kernels.Moments`); the moments
        of ``v0`` are taken with it (attribute ``m0``).
    """

    def __init__(self, scene, v0, w, t0, moments=None):
        self.budget = energy_budget(scene, *v0.shape)
        self.m0 = None
        self.active = self.budget is not None
        if not self.active:
            return
        self.w = w
        self.growth = GROWTH_NOISE if scene.stochastic else GROWTH
        b = self.budget
        self.delta = b.delta
        self.cstar = b.p / (2.0 * b.kappa) if b.kappa > 0 else 0.0
        self.lo = math.inf
        self.anchor = (t0, 0.0)
        # the moments of v0 (by the run's Moments when given: its centre is then the mean)
        self.m0 = moments(v0) if moments is not None else state_moments(v0, w)
        self.q0 = self._q(v0, self.m0)[0]
        self.qmax = self.q0
        if not math.isfinite(self.q0):
            # velocities so large that their squares overflow float64 (|v| ~ 1e154 and up):
            # the guard cannot compare energies; the non-finite check stays on
            self.active = False
            return
        self._update(t0, self.q0)

    def _q(self, v, moments=None):
        """``(Q, round-off allowance)`` at velocities ``v`` from their ``moments`` (computed
        when None: one compiled call, :func:`.state_moments`: ``Γ`` with the compensated
        centre and ``Σwᵢ|vᵢ|²``)."""
        fluct, sq, _ = state_moments(v, self.w) if moments is None else moments
        if self.budget.centred:
            return fluct, _ROUNDOFF_CENTRED * sq
        return sq, _ROUNDOFF * sq

    def _key(self, t, q):
        b = self.budget
        if b.kappa > 0:
            return math.log(q + self.delta + self.cstar) - 2.0 * b.kappa * t
        return q - b.p * t

    def bound(self, t: float) -> float:
        """The best a-priori bound on ``Q(t)`` from the steps seen so far."""
        b = self.budget
        if b.kappa > 0:
            e = self.lo + 2.0 * b.kappa * t
            return math.inf if e > 700.0 else math.exp(e) - self.cstar
        return self.lo + b.p * t + self.delta

    def _update(self, t, q):
        key = self._key(t, q)
        if key < self.lo:
            self.lo = key
            self.anchor = (t, q)

    def check(self, t: float, v, moments=None) -> str | None:
        """``None`` if ``Q(t)`` is within the bound, else the reason to stop (one sentence);
        ``moments``: those of ``v`` if known (:func:`.state_moments`)."""
        if not self.active:
            return None
        q, slack = self._q(v, moments)
        if not math.isfinite(q):
            return None                     # the non-finite check reports it
        bound = self.bound(t)
        if q <= self.growth * bound + _ROUNDOFF * self.qmax + slack:
            self._update(t, q)
            self.qmax = max(self.qmax, q)
            return None
        return self._reason(t, v, bound)

    def _reason(self, t, v, bound):
        if self.budget.centred:
            name, q = "the velocity fluctuation Γ = Σᵢwᵢ|vᵢ − v̄|²", _obs.gamma(v, self.w)
        else:
            name, q = "the velocity second moment Σᵢwᵢ|vᵢ|²", self._q(v)[0]
        ta, qa = self.anchor
        why = "; ".join(dict.fromkeys(self.budget.why)) or "nothing adds to it"
        return (f"{name} grew from {qa:.3g} (t={ta:.6g}) to {q:.3g}, more than {self.growth:g} "
                f"times the bound {bound:.3g} that the exact flow obeys ({why}): the explicit "
                f"step amplifies instead of damping")


_STABILITY: dict = {}


def real_stability(table: RKTable) -> float:
    """``β_m``: the method's stability interval on the negative real axis is ``[−β_m, 0]``.

    ``R(z) = 1 + z Bᵀ (I − zA)⁻¹ 1`` is scanned from 0 down to −10 and the first crossing of
    ``|R| = 1`` refined by bisection.

    Examples
    --------
    >>> from kinred.integrate import EULER, RK4
    >>> real_stability(EULER), round(real_stability(RK4), 3)
    (2.0, 2.785)
    """
    # cached by content: two tables with one name (a user's "rk4" that is Heun) differ
    A, B = np.asarray(table.A, dtype=float), np.asarray(table.B, dtype=float)
    key = (A.shape, A.tobytes(), B.tobytes())
    if key in _STABILITY:
        return _STABILITY[key]
    s = table.stages
    one = np.ones(s)

    def amp(z):
        return abs(1.0 + z * table.B @ np.linalg.solve(np.eye(s) - z * table.A, one))

    lo = 0.0
    z = 0.0
    while z > -10.0:
        z -= 0.01
        if amp(z) > 1.0 + 1e-12:
            break
        lo = z
    hi = z
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if amp(mid) <= 1.0 + 1e-12 else (lo, mid)
    val = round(-lo, 6)
    _STABILITY[key] = val
    return val


def _row_max(kernel, Y, c, kind: str) -> float:
    """``maxᵢ Σ_{j≠i} cⱼ a(‖Yᵢ − Yⱼ‖)``; ``a = |φ|`` (``"value"``) or ``max(|u|, |(s u)′|)``
    (``"force"``, the norm of the pair-force Jacobian, by central differences).

    Row blocks of a Gram product of centred rows: ``O(N²·d)`` time, ``O(N·b)`` memory.
    """
    Y = Y - Y.mean(axis=0)
    nrm = np.einsum("ij,ij->i", Y, Y)
    n = Y.shape[0]
    rows = max(1, min(n, 2 ** 20 // max(n, 1)))
    best = 0.0
    with np.errstate(all="ignore"):
        for i0 in range(0, n, rows):
            i1 = min(n, i0 + rows)
            q = nrm[i0:i1, None] + nrm[None, :] - 2.0 * (Y[i0:i1] @ Y.T)
            s = np.sqrt(np.maximum(q, 0.0))
            a = np.abs(np.asarray(kernel(s), dtype=float))
            if kind == "force":
                hs = 1e-6 * (1.0 + s)
                lo = np.maximum(s - hs, 0.0)
                up = s + hs
                dsu = (up * np.asarray(kernel(up), dtype=float)
                       - lo * np.asarray(kernel(lo), dtype=float)) / (up - lo)
                a = np.maximum(a, np.abs(dsu))
            a[np.arange(i1 - i0), np.arange(i0, i1)] = 0.0
            val = float(np.max(a @ c))
            if math.isfinite(val):
                best = max(best, val)
    return best


def _radii(scene, states):
    """Gershgorin radii: ``(ρ̂ dissipative, ω̂² oscillatory, parts, unknown)``.

    Positions are taken from every state; velocities from the first one only: when a run
    stops, the current velocities are the amplified ones (under Euler the positions lag one
    step behind them and still show, e.g., agents that have come close).
    """
    rho = om2 = 0.0
    parts, unknown = [], []
    c = scene.coefficients(states[0][1].shape[0])
    for e in scene.effects:
        if e.pairwise:
            tgt = scene._tgt(e)
            srcs = [st[1] for st in states] if e.source == "x" else [states[0][2]]
            if e.carrier == "v" and tgt == "v":
                r = max(2.0 * _row_max(e.kernel, y, c, "value") for y in srcs)
                rho += r
                parts.append(f"alignment 2·maxᵢ Σⱼ cⱼ gᵢⱼ = {r:.3g}")
            elif e.carrier == "x" and e.source == "x":
                r = max(2.0 * _row_max(e.kernel, y, c, "force") for y in srcs)
                if tgt == "x":
                    rho += r
                    parts.append(f"pair forces 2·maxᵢ Σⱼ cⱼ‖∂fᵢⱼ/∂x‖ = {r:.3g}")
                else:
                    om2 += r
            else:
                unknown.append(repr(e))
        else:
            r = _hooks.step_radius(e, states[0][2])
            if r is None:
                unknown.append(repr(e))
                continue
            rho += r.rho
            if r.why:
                parts.append(r.why)
    return rho, om2, parts, unknown


def step_hint(scene, table: RKTable, dt: float, states):
    """A stable step for ``scene`` estimated at ``states`` (module notes).

    Parameters
    ----------
    scene : Scene
    table : RKTable
        The method (its real stability interval ``β_m``).
    dt : float or None
        The step that failed (None for adaptive methods, whose step is not the user's).
    states : sequence of (t, x, v)
        The initial state, then e.g. the current one (only its positions are used, see
        :func:`_radii`); non-finite states are skipped.

    Returns
    -------
    hint : str
        One sentence.
    stable_dt : float or None
        The largest step it recommends (None without an estimate).
    """
    states = [st for st in states if np.all(np.isfinite(st[1]))]
    generic = ("reduce dt" + (f" (now {dt:g})" if dt is not None else "")
               + ", or use an adaptive method (method='rk45').")
    if not states:
        return generic, None
    rho, om2, parts, unknown = _radii(scene, states)
    beta = real_stability(table)
    at = " and ".join(f"t={st[0]:.6g}" for st in states[:2])
    out, cands = [], []
    if rho > 0:
        cands.append(beta / rho)
        out.append(f"{table.name} is stable on the damped modes for dt < {beta:.3g}/ρ̂ = "
                   f"{beta / rho:.3g} (ρ̂ = {rho:.3g}, Gershgorin bound of the linearised "
                   f"field at {at}: {'; '.join(parts)})")
    if om2 > 0:
        om = math.sqrt(om2)
        cands.append(0.2 / om)
        out.append(f"the pair forces drive oscillations up to ω̂ = {om:.3g} (ω̂² = 2·maxᵢ Σⱼ "
                   f"cⱼ‖∂fᵢⱼ/∂x‖ at {at}): resolve them with dt ≲ 0.2/ω̂ = {0.2 / om:.3g}; "
                   f"euler and heun amplify undamped oscillations by 1 + (ω̂·dt)² per step, "
                   f"rk4 or rk45 do not")
    if unknown:
        out.append(f"no estimate for {', '.join(unknown)}")
    if not cands:
        return generic, None
    head = f"dt = {dt:g} is too large: " if dt is not None else ""
    return head + "; ".join(out) + ".", min(cands)


def diverged(t, step, n_steps, method, dt, why, hint, stable_dt=None) -> SimulationDiverged:
    """The :class:`~kinred.errors.SimulationDiverged` of a run stopped at ``(t, step)``.

    ``n_steps`` is the total of a fixed-step run (None for adaptive ones), ``dt`` the user's
    step (the initial one of adaptive methods).
    """
    total = f" of {n_steps}" if n_steps is not None else ""
    return SimulationDiverged(
        f"simulation diverged at t={t:.6g} (step {step}{total}, method={method!r}, "
        f"dt={dt:g}): {why}. Hint: {hint}", t=float(t), step=int(step), stable_dt=stable_dt)


class DivergenceCheck:
    """The ``O(N·d)`` check of every accepted step: a finite state within the :class:`Guard`.

    Parameters
    ----------
    scene : Scene
    table : RKTable or None
        The method's table (stability interval of the hint; None: generic hint).
    method : str
    dt : float
        The user's step.
    n_steps : int or None
        Steps of a fixed-step run; None for adaptive runs (whose step is not the user's: the
        hint then gives no fixed ``dt``).
    t0 : float
    x0, v0 : ndarray
        The initial state as given (the hint's first state).
    w : (N,) ndarray
        Agent weights.
    v0_moments : ((F, S, T), (d,) ndarray), optional
        The moments of ``v0`` and their reference centre when already known
        (:func:`._kernels.copy_moments`); None: measured here.
    """

    def __init__(self, scene, table, method, dt, n_steps, t0, x0, v0, w, v0_moments=None):
        self.scene, self.table, self.method, self.dt = scene, table, method, dt
        self.n_steps, self.t0, self.x0, self.v0 = n_steps, t0, x0, v0
        self.moments = Moments(w)           # the compiled moments of v, step after step
        measure = self.moments
        if v0_moments is not None:
            self.moments.centre = v0_moments[1]
            measure = lambda v: v0_moments[0]       # noqa: E731 - taken with the copy of v0
        self.guard = Guard(scene, v0, w, t0, measure) if scene.order == 2 else None

    def __call__(self, t, step, x, v, known=None):
        """Raise :class:`~kinred.errors.SimulationDiverged` if the state at ``t`` diverged;
        returns the moments ``(Γ, Σwᵢ|vᵢ|², Σvᵢⱼ)`` of ``v`` (:func:`.state_moments`) when the
        guard measured them, else None. ``known``: the moments ``(of x, of v)`` of the state
        when the step gave them (:class:`._solvers.EulerMoments`): no pass of its own."""
        active = self.guard is not None and self.guard.active
        if known is not None:
            m = known[1] if active else None
            s = known[0][2] + (known[1][2] if known[1] is not None else 0.0)
        else:
            m = self.moments(v) if active else None
            s = float(np.sum(x)) + (m[2] if active else float(np.sum(v)) if v is not None
                                    else 0.0)
        if not math.isfinite(s):
            self._stop(t, step, x, v, "the state became non-finite (NaN/Inf/overflow)")
        why = self.guard.check(t, v, m) if self.guard is not None else None
        if why is not None:
            self._stop(t, step, x, v, why)
        return m

    def initial_moments(self, v):
        """The moments of the initial velocities ``v`` (equal to ``v0``: the run's working
        copy) as ``__call__`` gives them (None when the guard does not measure them), taken
        once by the :class:`Guard`; the next step then starts from their centre."""
        if self.guard is None or not self.guard.active:
            return None
        return self.guard.m0

    def _stop(self, t, step, x, v, why):
        fixed_dt = self.dt if self.n_steps is not None else None
        if self.table is None:
            hint, stable = step_hint(self.scene, None, fixed_dt, [])
        else:
            hint, stable = step_hint(self.scene, self.table, fixed_dt,
                                     [(self.t0, self.x0, self.v0), (t, x, v)])
        raise diverged(t, step, self.n_steps, self.method, self.dt, why, hint, stable)
