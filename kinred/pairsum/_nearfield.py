r"""The near-field split of the NUFFT backend (Potts–Steidl–Nieslony fast summation).

A kernel with a sharp feature at ``s = 0`` – the cusp ``u(s) ~ 1/s`` of Morse with
``soft = 0``, or a soft core much narrower than the cloud – would need its finest feature
resolved by one Fourier grid spanning the whole cloud. Split it instead, for a near radius
``ε_I`` and ``a = ε_I/4``:

.. math::
    \varphi_F(s) = G(s)\,\varphi(\max(s, a)), \qquad
    G(s) = \tfrac12 \operatorname{erfc}\Bigl(\frac{(a + ε_I)/2 - s}{σ}\Bigr), \qquad
    \varphi_N = \varphi - \varphi_F,

with ``σ = (ε_I − a)/(2 erfc⁻¹(2τ))`` so that ``G(a) = τ`` and ``G(ε_I) = 1 − τ``. The far
part ``φ_F`` is bounded and smooth (its finest scale is ``σ ≈ ε_I/8``, not the kernel's), so a
coarse grid sums it (``kinred.pairsum._fastsum``, the NUFFT's own machinery and error
control); the near part is summed exactly, pair by pair, over the pairs closer than ``ε_I``
found by the cell list (:mod:`kinred.pairsum._cells`). Beyond ``ε_I``, ``|φ_N| = (1 − G)|φ|
≤ τ|φ|``, left out: with ``τ = 0.1·tol·κ/max|φ|_{[ε_I, ∞)}`` each pair left out changes a row
sum by at most ``0.1·tol·κ`` (``κ`` the mean ``|φ|`` over the cloud's pairs, as for the grid).

``ε_I`` is chosen by a cost model over the ladder ``ε_I = D·2^{−j}`` (``D`` the cloud's
diameter): near pairs (their fraction among 4096 sampled pairs, times ``N(N − 1)/2``) at the
cell list's cost per pair, against the grid's transforms (its modes estimated from the 1-D
bandwidth of ``φ_F``); the grid is then measured as usual and, should it exceed
``max_modes``, the next larger ``ε_I`` tried.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.special import erfc, erfcinv

from ..errors import TooLarge
from . import _cost, _fastsum, _table
from .cells import kernel_values

__all__ = ["Split", "split", "prefer_split", "estimate"]

#: The regularized region starts at ``A_FRACTION · ε_I``.
A_FRACTION = 0.25
#: The ladder ``ε_I = D·2^{−j}``, ``j`` in this range.
LADDER = tuple(range(1, 16))
_SEED = 0x4EA2
#: The measured grids' bandwidth is about half the closed-form one of :func:`_modes_estimate`
#: (e.g. 2-D ring of radius 5, Morse, tol 1e-6, ε_I = 1.88: 295 × 293 modes measured).
XI_CALIBRATION = 0.5
#: Grids measured (cheapest estimate first) before giving up.
TRIES = 4


@dataclass(frozen=True, eq=False)
class Split:
    """A near-field split: the grid of ``φ_F``, the near radius and the near kernel."""

    radius: float
    grid: _fastsum.Grid
    near: object          # q ↦ φ_N(√q) (fresh array)
    tau: float
    #: Estimated seconds on one thread of the near pairs and of the grid's transforms.
    near_seconds: float = 0.0
    grid_seconds: float = 0.0


def _transition(eps_i: float, tau: float):
    """``(a, G)``: the start of the regularized region and the transition ``s ↦ G(s)``."""
    a = A_FRACTION * eps_i
    mid = 0.5 * (a + eps_i)
    sigma = _sigma(eps_i, tau)
    return a, lambda s: 0.5 * erfc((mid - s) / sigma)


def far_profile(phi, eps_i: float, tau: float):
    """``s ↦ φ_F(s)`` for the near radius ``eps_i`` (module notes)."""
    a, G = _transition(eps_i, tau)

    def phi_f(s):
        s = np.asarray(s, dtype=np.float64)
        return G(s) * np.asarray(phi(np.maximum(s, a)), dtype=np.float64)

    phi_f.eps_i, phi_f.tau = eps_i, tau
    return phi_f


def near_kernel(kernels: tuple, phi_f, table_rtol: float | None = None,
                table_kappa: float = 1.0):
    """``q ↦ Σ φ_t(√q) − φ_F(√q)``: the exact kernels (their ``value_sq``) minus the far part,
    ``φ(s)(1 − G(s))`` for ``s ≥ a`` and ``φ(s) − G(s) φ(a)`` below (one kernel evaluation).

    With ``table_rtol``, its attribute ``table`` is the function tabulated on ``[0, ε_I]``
    within ``table_rtol·(table_kappa + |φ_N|)`` (:func:`kinred.pairsum._table.tabulate`;
    None if no table reaches it), which the compiled pass then uses."""
    vals = [kernel_values(k) for k in kernels]
    a, G = _transition(phi_f.eps_i, phi_f.tau)
    phi_a = float(sum(v(np.array([a * a]))[0] for v in vals))

    def phi_n(q):
        out = vals[0](q)
        for v in vals[1:]:
            out = out + v(q)
        s = np.sqrt(q)
        g = G(s)
        return np.where(s >= a, out * (1.0 - g), out - g * phi_a)

    # the compiled pass: the table of φ_N (any kernels), else one kernel's closed form
    phi_n.fused = vals[0].fused if len(vals) == 1 else None
    phi_n.split = np.array([1.0, a, 0.5 * (a + phi_f.eps_i), _sigma(phi_f.eps_i, phi_f.tau),
                            phi_a])
    phi_n.table = None
    if table_rtol is not None:
        phi_n.table = _table.tabulate(lambda s: phi_n(np.asarray(s, dtype=float) ** 2),
                                      math.nextafter(phi_f.eps_i, math.inf),
                                      table_rtol, table_kappa)
    return phi_n


def _far_kappa(phi, dist: np.ndarray, eps_i: float, kappa: float, name: str) -> float:
    """The accuracy scale of a split: the mean of ``|φ(max(s, a))|`` over the sampled pair
    distances (the far part's size; a kernel's cusp, which the near part sums exactly and
    the carrier difference tames, must not loosen the far part's target), at most ``κ``."""
    if dist.size == 0:
        return kappa
    vals = np.abs(_fastsum._profile(phi, np.maximum(dist, A_FRACTION * eps_i), name))
    return min(kappa, max(float(vals.mean()), _fastsum.KAPPA_FLOOR * float(vals.max())))


def _tau(phi, eps_i, dmax, tol, kappa, name):
    far = np.abs(_fastsum._profile(phi, np.linspace(eps_i, max(dmax, eps_i), 1025), name))
    return min(0.25, max(1e-300, _fastsum.WINDOW_FACTOR * tol * kappa / max(float(far.max()),
                                                                          kappa)))


class _Rung(NamedTuple):
    """One radius of the ladder: estimated seconds (one thread; ``inf`` for a grid estimated
    beyond ``max_modes``), of which the near pairs' ``near``; ``φ_F``, its accuracy scale
    ``κ_F`` and sup ``‖φ_F‖∞``."""

    cost: float
    eps_i: float
    tau: float
    phi_f: object
    kappa: float
    kinf: float
    near: float


def _ranked(phi, s, ext, tol, kappa, max_modes, name, dim, scale=1.0) -> list:
    """The ladder's radii as :class:`_Rung`, cheapest first: the near pairs at the compiled
    pass's cost of a tabulated near part (:func:`near_kernel`), the far grid's transforms at
    the finufft ``ε`` it will get (``_fastsum.finufft_eps`` of ``κ_F`` and ``‖φ_F‖∞``; it
    was priced at ``tol·τ``, which finufft's widths cap, and a grid cost twice its price)."""
    n, k = s.shape
    dmax = float(np.sqrt(np.sum(ext * ext)))
    ladder = [1.0] if dmax == 0.0 else [dmax * 2.0 ** -j for j in LADDER]
    dist = _pair_distances(s)
    npairs = n * (n - 1) / 2.0
    ranked = []
    for eps_i in ladder:
        frac = float(np.mean(dist < eps_i)) if dist.size else 0.0
        kap = _far_kappa(phi, dist, eps_i, kappa, name) * scale
        tau = _tau(phi, eps_i, dmax, tol, kap, name)
        phi_f = far_profile(phi, eps_i, tau)
        kinf = max(float(np.max(np.abs(_fastsum._profile(phi_f, np.linspace(0.0, dmax, 4097),
                                                           name)))), kap)
        modes = _modes_estimate(eps_i, tau, ext, tol, max_modes)
        near = _cost.cell_seconds(frac * npairs, k, fused=True, near=True)
        cost = near + (_cost.nufft_seconds(n, dim, modes, _fastsum.finufft_eps(tol, kap, kinf),
                                           k) if modes else math.inf)
        ranked.append(_Rung(cost, eps_i, tau, phi_f, kap, kinf, near))
    ranked.sort(key=lambda r: r.cost)
    return ranked


def estimate(phi, kernels: tuple, s: np.ndarray, ext: np.ndarray, tol: float, kappa: float,
             max_modes: int, name: str, dim: int) -> float:
    """The estimated seconds of the cheapest radius of the ladder (no grid built)."""
    return _ranked(phi, s, ext, tol, kappa, max_modes, name, dim)[0].cost


def prefer_split(phi, kernels: tuple, s: np.ndarray, ext: np.ndarray, tol: float, kinf: float,
                 kappa: float, max_modes: int, name: str, dim: int, scale: float = 1.0) -> bool:
    """Whether the split's cheapest radius is estimated cheaper than one grid of the whole
    kernel (its modes from the 1-D slices, ``_fastsum.estimate_modes``): a kernel whose soft
    core is narrow against the cloud (the 2-D D'Orsogna ring of issue 24 at N = 2·10⁴) is
    cheaper split; at N = 10⁶ its near pairs cost more than the single grid."""
    n, k = s.shape
    single = _fastsum.estimate_modes(phi, ext, tol, kinf, kappa * scale, max_modes, name)
    if single is None:
        return True
    eps = _fastsum.finufft_eps(tol, kappa * scale, kinf)
    best = _ranked(phi, s, ext, tol, kappa, max_modes, name, dim, scale)[0].cost
    return best < _cost.nufft_seconds(n, dim, single, eps, k)


def split(phi, kernels: tuple, s: np.ndarray, ext: np.ndarray, tol: float, kappa: float,
          max_modes: int, name: str, dim: int, scale: float = 1.0) -> Split:
    """The near-field split of least estimated cost for the cloud ``s`` (module notes).

    Raises
    ------
    TooLarge
        When no radius of the ladder gives a grid within ``max_modes`` (the last error).
    """
    dmax = float(np.sqrt(np.sum(ext * ext)))
    ranked = _ranked(phi, s, ext, tol, kappa, max_modes, name, dim, scale)
    last = None
    for r in [r for r in ranked if math.isfinite(r.cost)][:TRIES]:
        try:
            grid = _fastsum.build_grid(r.phi_f, ext, tol, r.kinf, r.kappa, max_modes,
                                       f"the far part (outside {r.eps_i:.3g}) of {name}",
                                       xi_min=1.0 / _sigma(r.eps_i, r.tau))
        except TooLarge as exc:
            last = exc
            continue
        return Split(r.eps_i, grid, near_kernel(kernels, r.phi_f, _table.TABLE_FACTOR * tol,
                                                r.kappa), r.tau, r.near,
                     _cost.nufft_seconds(s.shape[0], dim, math.prod(grid.modes), grid.eps,
                                         s.shape[1]))
    raise TooLarge(f"NUFFT with a near-field split: no near radius of the ladder {LADDER[0]}"
                   f"..{LADDER[-1]} halvings of the diameter {dmax:.4g} gives a grid of the far "
                   f"part of {name} within max_modes={max_modes} at tol={tol:g}"
                   + (f" (the cheapest: {last})" if last else " (all estimated beyond it)")
                   + "; raise tol or max_modes, or use Dense/CellList (pairsum='auto')")


def _pair_distances(s: np.ndarray) -> np.ndarray:
    """Distances of the cloud's pairs ``i ≠ j``: all for small clouds, else 4096 drawn with a
    fixed seed."""
    n = s.shape[0]
    if n * (n - 1) <= _fastsum.PAIR_SAMPLE:
        i, j = np.triu_indices(n, 1)
    else:
        i, j = np.random.default_rng(_SEED).integers(0, n, (2, _fastsum.PAIR_SAMPLE))
        i, j = i[i != j], j[i != j]
    return np.sqrt(np.sum((s[i] - s[j]) ** 2, axis=1))


def _sigma(eps_i: float, tau: float) -> float:
    """The width ``σ`` of the transition ``G``."""
    return (1.0 - A_FRACTION) * eps_i / (2.0 * float(erfcinv(2.0 * tau)))


def _modes_estimate(eps_i, tau, ext, tol, max_modes) -> int | None:
    """A closed-form estimate of the grid's modes for ``φ_F`` (for the ranking only; the grid
    is measured): the transition ``G`` has a Gaussian spectrum, ``exp(−(ξσ)²/4)``, so its
    bandwidth at relative accuracy ``tol·τ`` is ``ξ = 2 √(ln(1/(tol·τ)))/σ``; the period of
    axis ``a`` is about ``2(Eₐ + max E/4)``. None beyond ``max_modes``."""
    E = _fastsum.flat_extents(ext)
    sigma = _sigma(eps_i, tau)
    xi = XI_CALIBRATION * 2.0 * math.sqrt(math.log(1.0 / (tol * tau))) / sigma
    t = 0.25 * float(E.max())
    est = math.prod(2 * math.floor(xi * (e + t) / math.pi) + 1 for e in E)
    return est if est <= max_modes else None
