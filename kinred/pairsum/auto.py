r"""``pairsum="auto"``: the deterministic backend of least estimated cost for the cloud at hand.

:class:`Auto` chooses, per scene and state shape, among the deterministic backends – the
exact :class:`~kinred.pairsum.Dense`, :class:`~kinred.pairsum.NUFFT` (smooth kernels,
``k ≤ 3``) and :class:`~kinred.pairsum.CellList` (kernels with a declared decay, ``k ≤ 3``),
the latter two at the requested ``tol`` – by a cost model of one right-hand side
(``costs``) from ``N``, ``k``, the cloud's extents and pair distances and the kernels;
it never picks :class:`~kinred.pairsum.RandomBatch` (an approximation of another kind, which
stays explicit). The choice is re-made when the cloud's extents leave ``[1/1.25, 1.25]``
times those it was made for, and it is said: :meth:`AutoPlan.info`, ``Scene.info()``.

The cost model (seconds per right-hand side, :mod:`kinred.pairsum._cost`): Dense by its
pairs; CellList by the pairs within its cutoff (their fraction among 4096 sampled pairs) and
the candidates of its stencil; NUFFT by its transforms, with its grids built for the cloud
(kept if it is chosen) – including the near-field split when a kernel needs one or it is
cheaper – but first estimated without any grid (``nufft.group_estimate``: milliseconds),
and its grids are not built when that estimate loses clearly (:data:`CLEAR_LOSS`). When
even the cheapest candidate is estimated beyond ``max_seconds`` the size is refused.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from .._validate import as_float, max_bytes_limit
from .. import _parallel
from ..errors import InvalidInput, TooLarge
from . import _cost, _fastsum
from ._base import PairTerms, check_plan_args
from .cells import CellList, cell_carriers, source_cutoff
from .dense import Dense, one_thread_seconds
from .nufft import NUFFT, ensure_grid, group_estimate

__all__ = ["Auto", "AutoPlan", "costs"]

#: Fixed overheads per right-hand side (Python calls, plans, sorting setup).
OVERHEAD = {"dense": 0.0, "nufft": 2e-3, "cells": 1e-3}
REDECIDE = 1.25
#: Dense estimated below this many seconds is chosen without estimating the others (their
#: estimates would build NUFFT grids, which costs more than such a right-hand side).
DENSE_ENOUGH = 0.02
#: NUFFT grids are not built to estimate a candidate whose cheap estimate (no grid:
#: ``nufft.group_estimate``) exceeds this many times the best other estimate or
#: ``max_seconds`` (a grid measured for a candidate that loses anyway costs seconds).
CLEAR_LOSS = 2.0
#: Default ``max_seconds``: no candidate estimated within it is refused (TooLarge).
MAX_SECONDS = 60.0
_SEED = 0xA070


@dataclass(eq=False)
class AutoPlan:
    """The candidate backends' plans for one scene and shape, and the current choice."""

    n: int
    dim: int
    terms: PairTerms
    candidates: dict            # name -> (backend, plan or None, reason it cannot run)
    chosen: str | None = None
    estimates: dict = field(default_factory=dict)
    ext: dict | None = None
    decisions: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def info(self) -> dict:
        """What was chosen, the estimated seconds per right-hand side of each candidate
        (``inf``: it cannot run this scene or cloud, with the reason), and how many times
        the choice was made."""
        return {"chosen": self.chosen, "estimates": dict(self.estimates),
                "decisions": self.decisions,
                "excluded": {k: v[2] for k, v in self.candidates.items() if v[2]}}


class Auto:
    """Automatic choice of a deterministic pair-sum backend (``pairsum="auto"``).

    Parameters
    ----------
    tol : float
        The accuracy asked of the approximate candidates (NUFFT, CellList), ``0 < tol < 1``.
        Dense is exact.
    max_seconds : float
        When even the cheapest candidate is estimated beyond this many seconds per
        right-hand side (default 60), :meth:`choose` refuses (:class:`~kinred.errors.TooLarge`,
        naming every estimate) instead of starting it – e.g. the 2-D D'Orsogna ring of
        radius 20 at N = 10⁶, tol 1e-6 (issue 24): a near field of about 7·10⁹ pairs, some
        200 s per right-hand side, which used to run unannounced. Raise it to run such a
        size anyway, or pick the backend explicitly.

    Examples
    --------
    >>> from kinred.dynamics import Alignment, CuckerSmale, Scene
    >>> sc = Scene([Alignment(CuckerSmale(0.8, 1.5))], pairsum="auto")
    >>> x = np.random.default_rng(0).uniform(0, 1, (200, 2))
    >>> _ = sc.rhs(x, x)
    >>> sc.info()["pairsum"]["chosen"]      # small N: the exact sum is cheapest
    'dense'
    """

    precision = "double"

    #: It may choose an approximate backend (NUFFT, CellList): certificates refuse it.
    exact = False

    def __init__(self, tol: float = 1e-6, max_seconds: float = MAX_SECONDS):
        self.tol = as_float(tol, "tol", low=0.0, high=1.0, low_open=True, high_open=True)
        self.max_seconds = as_float(max_seconds, "max_seconds", low=0.0, low_open=True)

    def __repr__(self) -> str:
        extra = "" if self.max_seconds == MAX_SECONDS else f", max_seconds={self.max_seconds!r}"
        return f"Auto(tol={self.tol!r}{extra})"

    def plan(self, scene, n: int, dim: int) -> AutoPlan:
        """The candidates' plans (a candidate that cannot run the scene is kept with why)."""
        terms, n, dim = check_plan_args(scene, n, dim)
        cands = {}
        for name, backend in (("dense", Dense()), ("nufft", NUFFT(tol=self.tol, near_field=None,
                                                        max_modes=auto_max_modes(dim))),
                              ("cells", CellList(tol=self.tol))):
            try:
                cands[name] = (backend, backend.plan(scene, n, dim), "")
            except (InvalidInput, TooLarge) as exc:
                cands[name] = (backend, None, str(exc))
        return AutoPlan(n=n, dim=dim, terms=terms, candidates=cands)

    def evaluate(self, plan: AutoPlan, x: np.ndarray, v: np.ndarray | None, rng=None) -> dict:
        """The chosen backend's pair sums (the choice re-made when the cloud changed shape)."""
        if not isinstance(plan, AutoPlan) or x.shape != (plan.n, plan.dim):
            raise InvalidInput(f"plan must be an AutoPlan for states of shape (n, dim) = "
                               f"{getattr(plan, 'n', '?'), getattr(plan, 'dim', '?')}; got "
                               f"{type(plan).__name__} and x of shape {x.shape}")
        name = self.choose(plan, x, v)
        backend, sub, _ = plan.candidates[name]
        return backend.evaluate(sub, x, v, rng)

    def choose(self, plan: AutoPlan, x: np.ndarray, v: np.ndarray | None = None) -> str:
        """The backend for the state ``(x, v)``: the last choice while the cloud keeps its
        shape, else the candidate of least estimated cost (``costs``; Dense on ties).

        Raises
        ------
        TooLarge
            No candidate can run it (e.g. ``N = 10⁷`` in dimension 10), naming why.
        """
        if all(c[1] is None for c in plan.candidates.values()):
            _refuse(plan)                    # before touching the state
        state = {"x": x, "v": v}
        with plan.lock:
            ext = {s: np.ptp(state[s], axis=0) for s in plan.terms.sources}
            if not all(np.all(np.isfinite(e)) for e in ext.values()):
                # non-finite positions (a diverging run's stage): no choice is made on them;
                # every candidate's sums carry the NaN to the integrator's guard (pricing
                # them raised InvalidInput about the kernel's profile instead). Before any
                # choice, a candidate that returns the NaN without summing (the cell list and
                # the NUFFT test the positions first; Dense would sum every pair)
                return plan.chosen if plan.chosen is not None else next(
                    k for k in ("cells", "nufft", "dense") if plan.candidates[k][1] is not None)
            if plan.chosen is None or not _same_shape(ext, plan.ext):
                plan.estimates = costs(plan, state, self.max_seconds)
                plan.chosen = min(plan.estimates, key=lambda k: (plan.estimates[k], k != "dense"))
                plan.ext, plan.decisions = ext, plan.decisions + 1
                if not math.isfinite(plan.estimates[plan.chosen]):
                    _refuse(plan)
                if plan.estimates[plan.chosen] > self.max_seconds:
                    est = ", ".join(f"{k} {v:.3g} s" for k, v in plan.estimates.items())
                    plan.chosen = None
                    raise TooLarge(f"pairsum='auto': every deterministic backend is estimated "
                                   f"beyond max_seconds={self.max_seconds:g} per right-hand "
                                   f"side for {plan.n} agents in dimension {plan.dim} ({est}); "
                                   "raise tol or max_seconds (Auto(max_seconds=...)), choose "
                                   "a backend explicitly, or ask for pairsum='random_batch'")
            return plan.chosen


def auto_max_modes(dim: int) -> int:
    """The NUFFT candidate's mode limit: the largest power of two whose transform arrays
    (``_fastsum.grid_bytes``) take at most half the memory limit, at least the NUFFT default
    (a single grid of a few million modes beats a near field of 10⁸ pairs: the 2-D
    D'Orsogna ring of radius 5 needs 1.1–1.9·10⁶ modes)."""
    k = min(max(dim, 1), 3)
    limit = max_bytes_limit(None) // 2
    m = _fastsum.MAX_MODES
    while _fastsum.grid_bytes(2 * m, k, (dim + 2) // 2) <= limit and m < 2 ** 24:
        m *= 2
    return m


def _same_shape(ext: dict, old: dict | None) -> bool:
    if old is None:
        return False
    return all(np.all(ext[s] <= REDECIDE * old[s]) and np.all(ext[s] >= old[s] / REDECIDE)
               for s in ext)


def _refuse(plan: AutoPlan) -> None:
    why = "; ".join(f"{k}: {v[2]}" for k, v in plan.candidates.items() if v[2])
    raise TooLarge(f"pairsum='auto': no deterministic backend fits {plan.n} agents in "
                   f"dimension {plan.dim} ({why}); project the scene to k <= 3, or ask for "
                   "pairsum='random_batch' (an unbiased approximation, explicit only)")


def costs(plan: AutoPlan, state: dict, max_seconds: float = MAX_SECONDS) -> dict:
    """Estimated seconds of one right-hand side per candidate (``inf``: cannot run); the
    NUFFT's grids are built only when its cheap estimate may win (:data:`CLEAR_LOSS`)."""
    n, dim, terms = plan.n, plan.dim, plan.terms
    nt = max(1, _parallel.get_num_threads())
    out = {"dense": math.inf}
    if plan.candidates["dense"][1] is not None:
        # the threads its plan runs in (dense.engine_threads: one for a small right-hand side)
        out["dense"] = one_thread_seconds(n, dim, terms) / len(plan.candidates["dense"][1].groups)
    if out["dense"] <= DENSE_ENOUGH:     # nothing to gain: do not build the others' grids
        out["nufft"] = out["cells"] = math.inf
        return out
    out["cells"] = _cells_cost(plan, state, nt)
    bound = CLEAR_LOSS * min(out["dense"], out["cells"], max_seconds)
    out["nufft"] = _nufft_cost(plan, state, nt, bound)
    return {k: (v + OVERHEAD[k] if math.isfinite(v) else v) for k, v in out.items()}


def _nufft_cost(plan: AutoPlan, state: dict, nt: int, bound: float = math.inf) -> float:
    backend, sub, why = plan.candidates["nufft"]
    if sub is None:
        return math.inf
    cheap = 0.0
    for g in sub.groups:         # groups whose grid would be built: estimate without it
        s = np.asarray(state[g.source], dtype=float)
        if g.grid is None or not g.grid.fits(np.ptp(s, axis=0)):
            cheap += group_estimate(sub, g, s, state[g.carrier])
    if cheap / nt > bound:
        return cheap / nt
    total = 0.0
    for g in sub.groups:
        s = np.asarray(state[g.source], dtype=float)
        try:
            grid = ensure_grid(sub, g, s, z=state[g.carrier])
        except TooLarge as exc:
            plan.candidates["nufft"] = (backend, sub, str(exc))
            return math.inf
        if grid is None or isinstance(grid, str):
            continue
        total += _cost.nufft_seconds(plan.n, plan.dim, math.prod(grid.modes), grid.eps, plan.dim)
        if g.split is not None:
            frac = float(np.mean(_pair_d2(s) < g.split.radius ** 2))
            total += _cost.cell_seconds(frac * plan.n * (plan.n - 1) / 2.0, plan.dim,
                                        fused=(g.split.near.fused is not None
                                               or g.split.near.table is not None), near=True)
    plan.candidates["nufft"] = (backend, sub, "")
    return total / nt


def _pair_d2(s: np.ndarray) -> np.ndarray:
    """Squared distances of 4096 pairs drawn with a fixed seed."""
    i, j = np.random.default_rng(_SEED).integers(0, s.shape[0], (2, 4096))
    return np.sum((s[i] - s[j]) ** 2, axis=1)


def _cells_cost(plan: AutoPlan, state: dict, nt: int) -> float:
    backend, sub, why = plan.candidates["cells"]
    if sub is None:
        return math.inf
    n, k = plan.n, plan.dim
    total = 0.0
    # the cutoffs the cell list itself derives (cells.source_cutoff, kept on its plan): the
    # evaluation that follows the choice reuses them (they cost 0.3-0.7 s per term at
    # N = 5000, for the rows of term_cutoff)
    carriers = cell_carriers(sub, state)
    for src in sub.sources:
        s = np.ascontiguousarray(state[src.name], dtype=np.float64)
        with sub.lock:
            R = source_cutoff(sub, src, s, carriers)
        if R == 0.0:
            continue
        frac = max(float(np.mean(_pair_d2(s) < R * R)), 1.0 / 4096)
        # every kernel through its table (cells._values); a kernel no table reaches (rare:
        # a kink or spike finer than 2¹⁷ intervals) runs slower than this estimate
        fused = sub.compiled
        total += _cost.cell_seconds(frac * n * (n - 1) / 2.0, k, len(src.terms), fused)
    return total / nt
