r"""Fast summation of smooth radial kernels at nonequispaced points (the math of :class:`NUFFT`).

For points ``sᵢ ∈ ℝᵏ`` (``k ≤ 3``), a smooth radial profile ``φ`` and several strength vectors
``α``, it computes

.. math:: f_i = \sum_j \alpha_j\, \varphi(\|s_i - s_j\|)

in ``O(N + n^k log n)`` instead of ``O(N²)`` (Potts, Steidl, Nieslony, *Fast convolution with
radial kernels at nonequispaced knots*, Numer. Math. 98 (2004); the ``fastsum`` module of
NFFT3). The design here, written for kinred:

1. **Box.** The cloud's per-axis extents ``eₐ = max sₐ − min sₐ`` bound the differences that
   occur, ``|rₐ| ≤ eₐ``. A grid keeps *flat extents* ``Eₐ ≥ eₐ`` (with headroom, so that a
   slowly growing cloud reuses it) and a transition width ``t``; the period of axis ``a`` is
   ``Pₐ = 2(Eₐ + t)``, and points are translated to the box centre and scaled to
   ``uₐ = 2π(sₐ − cₐ)/Pₐ ∈ (−π, π)`` (translation first: a cloud far from the origin loses
   nothing).
2. **Regularized kernel.** ``K_R(r) = C + W(r)(φ(|r|) − C)`` with the tensor window
   ``W(r) = ∏ₐ w(rₐ)``, ``w(ρ) = ½ erfc((|ρ| − Eₐ − t/2)/σ)``: ``w = 1`` on the flat region and
   ``0`` at the period's edge to a relative ``τ`` (``σ = t / (2 erfc⁻¹(2τ))``), so ``K_R = φ`` on
   every difference that occurs and ``K_R`` is smooth (Gaussian-decaying spectrum of the window)
   across the torus boundary. ``C`` is the middle of ``φ``'s range over the transition region
   (a constant kernel, e.g. ``Quadratic``, needs one mode).
3. **Coefficients.** ``K_R`` is sampled on the non-negative orthant of a grid and its Fourier
   coefficients ``b_m`` follow by a ``DCT-I`` (``K_R`` is even in every coordinate, so the
   coefficients are real and even). The number of modes is *measured on the coefficient
   array*: the smallest box ``|mₐ| ≤ Mₐ`` (equal physical bandwidth ``ξ`` on every axis,
   ``Mₐ = ⌊ξPₐ/2π⌋``) whose truncated series stays within ``target`` of ``K_R`` on every
   grid point of the flat region – the differences that occur; the transition region may
   ring – by bisection over ``ξ`` (the truncated series summed on those points only,
   :func:`truncated_series`). The sampling is refined while the ℓ1
   content of the spectrum above 2/3 of its Nyquist frequency exceeds ``target`` (aliasing),
   up to ``2·max_modes`` samples.
4. **Transforms.** ``â = NUFFT₁(α)`` (points → modes, ``isign = −1``), ``â_m ← b_m â_m``,
   ``f = NUFFT₂(â)`` (modes → points: the adjoint, ``isign = +1``, of the same finufft plan on
   the same points). Two real strength vectors travel as one complex one (the operator is
   real).

The transition width ``t`` is chosen per grid among ``t = 2ʲ·maxₐ Eₐ`` (``j = −10 … 3``): the
mode count falls as ``t`` shrinks (smaller period) until the window's own bandwidth dominates,
so the search starts at the candidate whose 1-D slice (along the longest axis) predicts the
fewest modes and walks in the falling direction while the measured count falls (by 10 %; a
candidate whose sampling would exceed twice the best count is abandoned). The slice also
gives each candidate's first bandwidth guess, and skips the k-D measurement of candidates that
exceed ``max_modes`` already in 1-D.

Accuracy (constants below; measured in docs/dynamics.md and ``NUFFT``'s docstring): with ``κ``
the mean of ``|φ(|sᵢ − sⱼ|)|`` over the cloud's pairs ``i ≠ j`` (a sample of 4096 pairs with a
fixed seed, floored at ``1e-4·‖φ‖∞``), the truncated kernel is within ``tol·κ`` of ``φ`` on the
flat region, finufft runs at ``ε = 0.3·tol·κ/‖φ‖∞`` (rounded down to a power of ten, at least
``1e-14``) and the window deviates from 1 by ``τ = 0.1·tol·κ/‖φ‖∞``. Relative to ``κ`` rather
than ``‖φ‖∞``: a row sum ``Σⱼ cⱼφᵢⱼ`` is about ``κ Σⱼ cⱼ``, so an error ``δ`` per kernel value
is a relative error ``δ/κ`` of the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy.special import erfc, erfcinv

from .._validate import fmt_bytes, fmt_count
from ..errors import InvalidInput, TooLarge
from . import _cost

__all__ = ["MAX_MODES", "Grid", "kernel_scales", "build_grid", "FastSum", "flat_extents"]

#: Default limit on the number of Fourier modes ``∏ₐ (2Mₐ + 1)`` of one grid (``1024²`` in
#: 2-D, ``101³`` in 3-D): finufft's work arrays then stay below about 300 MB
#: (:func:`grid_bytes`).
MAX_MODES = 2 ** 20

#: Truncation target ``SUP_FACTOR·tol·κ`` (sup-norm on the flat region), finufft
#: ``ε = EPS_FACTOR·tol·κ/‖φ‖∞``, window ``τ = WINDOW_FACTOR·tol·κ/‖φ‖∞`` (module notes);
#: chosen so that the measured relative field error stays below ``tol`` (docs/dynamics.md,
#: section "Pair sums for large N").
SUP_FACTOR = 1.0
EPS_FACTOR = 0.3
WINDOW_FACTOR = 0.1
EPS_MIN = 1e-14
#: ``κ`` is floored at ``KAPPA_FLOOR·‖φ‖∞``: beyond that spread the cost would explode.
KAPPA_FLOOR = 1e-4
#: Pairs sampled for ``κ`` (all pairs when ``N(N − 1) ≤ PAIR_SAMPLE``); a fixed seed keeps the
#: backend deterministic.
PAIR_SAMPLE = 4096
_PAIR_SEED = 0x5EED

#: A grid's flat extents are ``HEADROOM ×`` the cloud's (at least ``1/MIN_ASPECT`` of the
#: largest), and it is kept while the cloud fits and has not shrunk by more than ``SHRINK``.
HEADROOM = 1.25
#: The floor only keeps a cloud that thickens from rebuilding its grid at every step (each
#: rebuild adds 25 %); accuracy needs none, so per-axis periods follow a flat cloud's
#: extents down to 1/64 of its longest (it was 1/8: a 30 × 3 × 0.5 slab then needed 1.8×
#: the modes, measured at tol 1e-4 and 1e-6 with the same error bound).
MIN_ASPECT = 64.0
SHRINK = 4.0

#: finufft gets one OpenMP thread per this many points (at most the engine's threads): each
#: of its parallel regions waits for every thread, which on a busy machine costs a scheduler
#: time slice (measured on the loaded 2-core VM, N = 2·10⁴ in 2-D: 12–25 ms with one thread,
#: 150–170 ms with two).
POINTS_PER_THREAD = 100_000

#: The k-D cut's bandwidth over the 1-D slice's (measured 1.1–1.3: ``_measure``).
SLICE_TO_KD = 1.2

#: Candidate transition widths ``t = 2ʲ·maxₐ Eₐ``: the powers ``j``.
WIDTH_POWERS = tuple(range(-10, 4))


@dataclass(frozen=True, eq=False)
class Grid:
    """A regularized kernel on a periodic box and its truncated Fourier coefficients.

    Attributes
    ----------
    extents : (k,) ndarray
        Flat extents ``Eₐ``: differences with ``|rₐ| ≤ Eₐ`` see ``K_R = φ``.
    width : float
        Transition width ``t``.
    periods : (k,) ndarray
        ``Pₐ = 2(Eₐ + t)``.
    half_modes : tuple of int
        ``Mₐ``: modes ``−Mₐ … Mₐ`` on axis ``a``.
    coef : ndarray of shape ``(2M₁+1, …)``
        Real coefficients ``b_m`` in increasing ``m`` order (finufft's ``modeord = 0``).
    target, error : float
        The truncation target and the measured error: the largest ``|K_R − Σ_box b_m e_m|``
        on the grid points of the flat region (at most ``target``).
    kinf, kappa, eps : float
        ``‖φ‖∞`` on the differences, the pair scale ``κ``, finufft's ``ε``.
    """

    extents: np.ndarray
    width: float
    periods: np.ndarray
    half_modes: tuple
    coef: np.ndarray
    target: float
    error: float
    kinf: float
    kappa: float
    eps: float

    @property
    def modes(self) -> tuple:
        """Modes per axis, ``2Mₐ + 1``."""
        return tuple(2 * m + 1 for m in self.half_modes)

    def fits(self, ext: np.ndarray) -> bool:
        """Whether a cloud of extents ``ext`` may reuse this grid: it fits in the flat region
        and its largest extent has not shrunk by more than :data:`SHRINK`."""
        if np.any(ext > self.extents):
            return False
        big = float(self.extents.max())
        return big == 0.0 or float(ext.max()) * SHRINK * HEADROOM >= big


def flat_extents(ext: np.ndarray) -> np.ndarray:
    """Flat extents of a new grid for a cloud of extents ``ext``: :data:`HEADROOM` × each,
    and at least ``1/MIN_ASPECT`` of the largest (a flat cloud may thicken)."""
    return HEADROOM * np.maximum(ext, ext.max() / MIN_ASPECT)


def grid_bytes(modes: int, k: int, n_trans: int) -> int:
    """Rough memory of one transform pair with ``modes`` modes: coefficients, the mode array
    of ``n_trans`` transforms, and finufft's upsampled grids (``2ᵏ``× the modes, one per
    transform of a batch)."""
    return int(modes * (8 + 16 * n_trans * (1 + 2 ** k)))


def _profile(phi, s: np.ndarray, name: str) -> np.ndarray:
    """``φ(s)`` as a float64 array of ``s``'s shape, checked finite."""
    try:
        val = np.asarray(phi(s), dtype=np.float64)
    except Exception as exc:  # a user kernel: name it
        raise InvalidInput(f"the radial profile of {name} failed on an array of distances of "
                           f"shape {s.shape}: {type(exc).__name__}: {exc}") from None
    if val.shape != s.shape:
        val = np.broadcast_to(val, s.shape) if val.size == 1 else val
    if val.shape != s.shape or not np.all(np.isfinite(val)):
        raise InvalidInput(f"the radial profile of {name} must return finite values of the "
                           f"distances' shape {s.shape}; got shape {val.shape}"
                           + ("" if val.shape != s.shape else " with non-finite values"))
    return val


def kernel_scales(phi, s: np.ndarray, ext: np.ndarray, name: str,
                  z: np.ndarray | None = None) -> tuple[float, float]:
    """``(‖φ‖∞, κ)`` for the cloud ``s (N, k)`` of extents ``ext``.

    ``‖φ‖∞`` is the maximum of ``|φ|`` over ``[0, |ext|]`` (4097 samples); ``κ`` the mean of
    ``|φ(|sᵢ − sⱼ|)|`` over pairs ``i ≠ j`` (all of them for small ``N``, else 4096 drawn with a
    fixed seed), floored at :data:`KAPPA_FLOOR` ``·‖φ‖∞``. With the carrier ``z``, pairs whose
    carrier difference is exactly zero are left out (they add nothing to the field
    ``Σⱼ cⱼ φᵢⱼ (zⱼ − zᵢ)``): half of 6918 agents on one point in 3-D under Morse put 25 % of
    the pairs at ``φ(0)``, 80× the mean of the others, and the field error at 7·tol.
    """
    dmax = float(np.sqrt(np.sum(ext * ext)))
    kinf = float(np.max(np.abs(_profile(phi, np.linspace(0.0, dmax, 4097), name))))
    n = s.shape[0]
    if n * (n - 1) <= PAIR_SAMPLE:
        i, j = np.divmod(np.arange(n * n), n)
    else:
        i, j = np.random.default_rng(_PAIR_SEED).integers(0, n, (2, PAIR_SAMPLE))
    i, j = i[i != j], j[i != j]          # the field has no self-pairs (they cancel exactly)
    if z is not None:
        z = np.asarray(z)
        moving = np.any(z[i] != z[j], axis=1)
        if moving.any():
            i, j = i[moving], j[moving]
    if i.size == 0:
        return kinf, kinf
    kappa = float(np.mean(np.abs(_profile(phi, np.sqrt(np.sum((s[i] - s[j]) ** 2, axis=1)),
                                          name))))
    return kinf, max(kappa, KAPPA_FLOOR * kinf)


def sample_rows(n: int, min_rows: int, pairs: int, seed: int) -> np.ndarray:
    """Sorted rows of an ``n``-agent field to check against exact sums: all of them when
    ``n ≤ max(min_rows, pairs/n)``, else that many drawn with ``seed`` (about ``pairs`` pairs
    in all). Used by the NUFFT's field check and the cell list's cutoff."""
    m = max(min_rows, pairs // max(n, 1))
    if n <= m:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, m, replace=False))


def row_blocks(s: np.ndarray, rows: np.ndarray, elems: int = 1 << 20):
    """``(a, e, q)`` over column blocks ``[a, e)`` of about ``elems`` pairs: ``q`` the squared
    distances ``|s_{rows} − s_{a:e}|²``, shape ``(rows.size, e − a)`` (the exact row sums of
    :func:`sample_rows`' rows, without an ``N × N`` array)."""
    n = s.shape[0]
    step = max(1, elems // max(rows.size, 1))
    sr = s[rows]
    for a in range(0, n, step):
        e = min(n, a + step)
        yield a, e, sq_distances(sr, s[a:e])


def sq_distances(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``|pᵢ − qⱼ|²``, shape ``(len(p), len(q))``: summed coordinate by coordinate in
    coordinate order -- for fewer than 8 coordinates (the callers have ``k ≤ 3``) the bits of
    ``np.sum((q[None] − p[:, None])**2, axis=2)``, whose reduction over a short last axis took
    0.4 of the 1.4 s of the cell list's cutoff rows at N = 2000 (numpy sums 8 or more
    elements pairwise, in another order)."""
    out = np.zeros((p.shape[0], q.shape[0]))
    diff = np.empty_like(out)
    for c in range(p.shape[1]):
        np.subtract(q[None, :, c], p[:, c, None], out=diff)
        np.multiply(diff, diff, out=diff)
        out += diff
    return out


def _window(rho: np.ndarray, E: float, t: float, xt: float) -> np.ndarray:
    """``½ erfc((|ρ| − E − t/2)/σ)``, ``σ = t/(2·xt)``: ``1 − τ`` at ``E``, ``τ`` at ``E + t``."""
    return 0.5 * erfc((np.abs(rho) - E - 0.5 * t) * (2.0 * xt / t))


def _tail_cut(mag: np.ndarray, target: float) -> int | None:
    """Smallest ``M`` with ``Σ_{m > M} mag[m] ≤ target`` if it lies in the first two thirds
    of ``mag`` (else None: too close to Nyquist to trust)."""
    tail = np.append(np.cumsum(mag[::-1])[::-1][1:], 0.0)   # tail[m] = Σ_{m' > m}
    ok = np.flatnonzero(tail <= target)
    if ok.size == 0 or ok[0] > (2 * mag.size) // 3:
        return None
    return int(ok[0])


def _bandwidth_1d(phi, E: float, t: float, xt: float, C: float, target: float, cap: int,
                  name: str, xi_min: float = 0.0) -> float | None:
    """A first guess of the bandwidth ``ξ`` at width ``t``: where the ℓ1 tail of the Fourier
    coefficients of the axis slice ``ρ ↦ C + w(ρ)(φ(|ρ|) − C)`` falls below ``target``;
    None beyond ``cap`` half-modes."""
    P = 2.0 * (E + t)
    n = 64
    while xi_min > 0 and n < 3.0 * xi_min * P / math.pi and n // 3 <= 2 * cap + 64:
        n *= 2         # sample finer than the profile's known finest feature
    while n // 3 <= 2 * cap + 64:
        rho = np.arange(n // 2 + 1) * (P / n)
        f = C + _window(rho, E, t, xt) * (_profile(phi, rho, name) - C)
        mag = np.abs(sfft.dct(f, type=1)) / n
        mag[1:] *= 2.0
        M = _tail_cut(mag, target)
        if M is not None:
            return 2.0 * math.pi * M / P if M <= cap else None
        n *= 2
    return None


def _centre_value(phi, ext: np.ndarray, t: float, name: str) -> float:
    """``C``: the middle of ``φ``'s range over the distances of the transition region."""
    s = np.linspace(float(ext.min()), float(np.sqrt(np.sum((ext + t) ** 2))), 257)
    v = _profile(phi, s, name)
    return 0.5 * (float(v.max()) + float(v.min()))


def _orthant(phi, E, t, xt, C, P, L, name):
    """Samples ``f`` of ``K_R`` on the orthant grid ``rₐ = iₐ Pₐ/(2(Lₐ − 1))``, ``0 ≤ iₐ < Lₐ``,
    and its Fourier coefficients ``b_m`` (``0 ≤ mₐ < Lₐ``) by a DCT-I."""
    k = E.size
    axes = [np.arange(La) * (Pa / (2 * (La - 1))) for La, Pa in zip(L, P)]
    mesh = np.meshgrid(*axes, indexing="ij", sparse=True)
    r2 = sum(m * m for m in mesh)
    W = np.ones((1,) * k)
    for a in range(k):
        W = W * _window(mesh[a], float(E[a]), t, xt)
    f = C + W * (_profile(phi, np.sqrt(r2), name) - C)
    return f, sfft.dctn(f, type=1) / math.prod(2 * (La - 1) for La in L), axes


def _axis_shells(shape, P) -> list:
    """Per axis, the shell of each coefficient index ``m`` on the ladder ``ξⱼ = j·2π/max P``:
    the smallest ``j`` with ``m ≤ ⌊j Pₐ/max P⌋`` (non-decreasing in ``m``)."""
    pmax = float(max(P))
    return [np.ceil(np.arange(n) * (pmax / Pa) - 1e-9).astype(np.int64)
            for n, Pa in zip(shape, P)]


def _shells(shape, P) -> np.ndarray:
    """Shell index of each orthant coefficient: the smallest ``j`` whose box
    ``|mₐ| ≤ ⌊j Pₐ/max P⌋`` contains it (the largest of its axes' shells)."""
    shell = np.zeros((1,) * len(shape), dtype=np.int64)
    for a, m in enumerate(_axis_shells(shape, P)):
        sh = [1] * len(shape)
        sh[a] = -1
        shell = np.maximum(shell, m.reshape(sh))
    return np.broadcast_to(shell, shape)


def _l1_tails(b, P):
    """``(shell, tails, step, jmax)``: the shells of the orthant coefficients, the ℓ1 norm of
    the full (mirrored) spectrum outside each ladder box, the ladder step ``2π/max P`` and the
    last index below 2/3 of the sampling's Nyquist frequency."""
    shell = _shells(b.shape, P)
    mult = np.ones((1,) * b.ndim)
    for a, n in enumerate(b.shape):
        sh = [1] * b.ndim
        sh[a] = -1
        mult = mult * np.where(np.arange(n) > 0, 2.0, 1.0).reshape(sh)
    per = np.bincount(shell.ravel(), weights=(np.abs(b) * mult).ravel())
    tails = np.append(np.cumsum(per[::-1])[::-1][1:], 0.0)      # ℓ1 over shells > j
    step = 2.0 * math.pi / float(max(P))
    nyq = min(2.0 * math.pi * (n - 1) / p for n, p in zip(b.shape, P))
    return shell, tails, step, min(int(nyq * 2.0 / 3.0 / step), tails.size - 1)


#: :func:`truncated_series` sums an axis as a matrix product while ``points × coefficients``
#: is at most this many times ``L log₂ L`` (and :data:`SERIES_MATRIX_ELEMS`), else by the
#: axis' inverse DCT: measured per axis, the product 1.3–3.8× faster at ratios 7–74, the DCT
#: 3.7–12× faster at 144–190 (a 1-D grid of 10⁴ points would take 10⁸ products in all).
SERIES_MATRIX_RATIO = 48.0
SERIES_MATRIX_ELEMS = 1 << 22


def truncated_series(b: np.ndarray, counts, rows) -> np.ndarray:
    """The series of the DCT-I coefficients ``b`` (orthant, ``Lₐ = b.shape[a]``; as
    ``sfft.dctn(f, type=1)/Πₐ 2(Lₐ − 1)``) truncated to ``mₐ < counts[a]``, at the grid points
    ``rows[a]`` of each axis only: ``Σ_m b_m Πₐ wₘ cos(π nₐ mₐ/(Lₐ − 1))`` (``wₘ = 1`` at
    ``m = 0`` and ``m = Lₐ − 1``, else 2), axis by axis (a matrix product, or the axis'
    inverse DCT-I where that is cheaper: :data:`SERIES_MATRIX_RATIO`) -- ``sfft.idctn`` of
    the masked coefficients on the whole orthant, then the flat region's points, took 3.4 of
    the 4.9 s of the 3-D slab's grid of issue 24 (429 × 127 × 69 modes)."""
    rec = b[tuple(slice(0, c) for c in counts)]
    for n, r in zip(b.shape, rows):
        c = rec.shape[0]
        if r.size * c <= min(SERIES_MATRIX_RATIO * n * math.log2(n), SERIES_MATRIX_ELEMS):
            m = np.arange(c)
            w = np.where((m == 0) | (m == n - 1), 1.0, 2.0)
            # the phase reduced mod 2π in integers: exact for any grid size
            C = w[None, :] * np.cos((np.pi / (n - 1)) * (np.outer(r, m) % (2 * (n - 1))))
            rec = np.tensordot(rec, C, axes=([0], [1]))      # this axis becomes the last
        else:                   # many points of a long axis: its inverse DCT, then the rows
            pad = np.zeros((n,) + rec.shape[1:])
            pad[:c] = rec
            pad *= 2 * (n - 1)
            rec = np.moveaxis(sfft.idct(pad, type=1, axis=0)[r], 0, -1)
    return rec


def _sup_cut(f, b, axes, E, P, target):
    """The measured cut: ``(j, err)`` of the smallest ladder index ``j`` whose truncated
    series is within ``target`` of ``K_R`` on every grid point of the flat region
    (``|rₐ| ≤ Eₐ``: the differences that occur), found by bisection on the series of the
    coefficients in the ladder's box ``j`` summed at those points (:func:`truncated_series`);
    ``(None, ξ_pred)`` when the ℓ1 content above 2/3 of the
    sampling's Nyquist frequency exceeds ``target`` (aliasing not negligible), with
    ``ξ_pred`` an extrapolation of its exponential decay."""
    shell, tails, step, jmax = _l1_tails(b, P)
    if tails[jmax] > target:
        j0 = max(jmax // 2, 0)
        t0, t1 = tails[j0], tails[jmax]
        if jmax > j0 and 0.0 < t1 < t0:
            jpred = jmax + math.log(t1 / target) / (math.log(t0 / t1) / (jmax - j0))
        else:
            jpred = 2.0 * max(jmax, 1)
        return None, float(min(jpred, 4.0 * max(jmax, 1)) * step)
    rows = [np.flatnonzero(ax <= e * (1 + 1e-12)) for ax, e in zip(axes, E)]
    fflat = f[np.ix_(*rows)]
    axis_shells = _axis_shells(b.shape, P)     # box j: on each axis, the m of shell <= j

    def err(j):
        counts = [int(np.count_nonzero(sh <= j)) for sh in axis_shells]
        return float(np.max(np.abs(truncated_series(b, counts, rows) - fflat)))

    # the ℓ1 tail bounds the sup error: its cut is an upper bound; bisect below it, first
    # probing 0.8 of it (the sup cut is usually close)
    hi = int(np.flatnonzero(tails <= target)[0])
    e_hi = float(tails[hi])
    lo = -1
    probe = int(0.8 * hi)
    while hi - lo > 1:
        mid = probe if lo < probe < hi else (lo + hi) // 2
        probe = -1
        e_mid = err(mid)
        if e_mid <= target:
            hi, e_hi = mid, e_mid
        else:
            lo = mid
    return hi, e_hi


def _measure(phi, E, t, xt, C, xi, target, max_modes, name, budget=None):
    """The k-D cut at width ``t``: sampling from bandwidth ``2·ξ`` up, finer (at least 1.5×
    per axis, up to the extrapolated content) until the spectrum above 2/3 of Nyquist is
    negligible. Returns ``(modes, M, coef, err)``, or ``(modes_low, None, None, None)`` when
    the modes exceed ``max_modes`` or the sampling would exceed ``2·max_modes`` (or
    ``budget`` samples: a candidate that cannot beat one already measured)."""
    P = 2.0 * (E + t)

    def sampling(bandwidth):
        return [int(math.ceil(1.5 * bandwidth * Pa / (2.0 * math.pi))) + 2 for Pa in P]

    L = sampling(1.3 * xi)     # the k-D cut usually lies 10–30 % beyond the slice's
    limit = 2 * max_modes if budget is None else min(2 * max_modes, budget)
    while math.prod(L) <= limit:
        f, b, axes = _orthant(phi, E, t, xt, C, P, L, name)
        j, err = _sup_cut(f, b, axes, E, P, target)
        if j is not None:
            M = tuple(int(math.floor(j * Pa / float(max(P)) + 1e-9)) for Pa in P)
            modes = math.prod(2 * m + 1 for m in M)
            if modes > max_modes:
                return modes, None, None, None
            coef = np.ascontiguousarray(b[np.ix_(*[np.abs(np.arange(-m, m + 1)) for m in M])])
            return modes, M, coef, err
        L = [max(new, int(math.ceil(1.5 * (old - 1))) + 1)
             for new, old in zip(sampling(1.1 * err), L)]
    # the spectrum still matters beyond 2/3 of the last sampling's Nyquist frequency
    return math.prod(2 * int((La - 1) // 3) + 1 for La in L), None, None, None


def _too_large(name, ext, tol, modes, max_modes, k) -> TooLarge:
    # ``modes`` is a lower estimate, or inf when the 1-D slices alone need more than
    # ``max_modes`` (the 1-D search stops there, :func:`_slice_cap`): only that bound is known
    need = (f"more than max_modes={fmt_count(max_modes)} Fourier modes for tol={tol:g}: the "
            "axes' 1-D slices alone need more" if not math.isfinite(modes) else
            f"at least {fmt_count(int(modes))} Fourier modes for tol={tol:g}, more than "
            f"max_modes={fmt_count(max_modes)}")
    return TooLarge(
        f"NUFFT: a {k}-D cloud of extents {np.array2string(ext, precision=4)} (diameter "
        f"<= {float(np.sqrt(np.sum(ext * ext))):.4g}) with kernel {name} needs {need} "
        f"(max_modes means about {fmt_bytes(grid_bytes(max_modes, k, 2))} of transform "
        "arrays); raise tol or max_modes, or use the Dense backend for so spread a "
        "cloud")


def _slice_count(E: np.ndarray, t: float, m: int) -> int:
    """The grid's modes when the widest axis' slice needs ``m`` half-modes."""
    big = float(E.max()) + t
    return math.prod(2 * math.floor(m * ((float(e) + t) / big)) + 1 for e in E)


def _slice_cap(E: np.ndarray, t: float, max_modes: int) -> int:
    """The smallest half-mode count ``M`` of the widest axis' slice (period ``2(max E + t)``)
    whose grid, ``Πₐ (2⌊M (Eₐ + t)/(max E + t)⌋ + 1)`` modes, exceeds ``max_modes``: the 1-D
    search need not sample beyond it (the other axes count too: a 3-D cloud at 2²⁰ modes
    stops near 50 half-modes, not at 2²⁰)."""
    lo, hi = 0, max(1, int(max_modes))       # count(hi) ≥ 2·hi + 1 > max_modes
    while lo < hi:
        mid = (lo + hi) // 2
        if _slice_count(E, t, mid) > max_modes:
            hi = mid
        else:
            lo = mid + 1
    return lo


def _width_search(phi, E, target, xt, max_modes, name, xi_min=0.0):
    """The grid of the best transition width ``t = 2ʲ·max E`` (``j`` in
    :data:`WIDTH_POWERS`): the mode count falls as ``t`` shrinks (smaller period) until the
    window's own bandwidth dominates, so from the ``j`` whose 1-D slice estimate is lowest
    the search walks in the falling direction while the measured count falls by 10 %. Returns
    ``(modes, t, M, coef, err)``, ``M`` None when even the best needs more than
    ``max_modes`` (``modes`` is then a lower estimate)."""
    big = float(E.max())
    guess, seen = {}, {}

    def estimate(j):      # the 1-D slice's mode count: (count, t, C, ξ), cheap
        if j not in guess:
            t = big * 2.0 ** j
            C = _centre_value(phi, E, t, name)
            cap = _slice_cap(E, t, max_modes)
            xi = _bandwidth_1d(phi, big, t, xt, C, target, cap, name, xi_min)
            # beyond the cap: the grid at the cap is a lower estimate (it exceeds max_modes)
            est = _slice_count(E, t, cap) if xi is None else math.prod(
                2 * math.floor(xi * (e + t) / math.pi) + 1 for e in E)
            guess[j] = (est, t, C, xi)
        return guess[j][0]

    def at(j):            # the k-D measurement: (modes, t, M, coef, err)
        if j not in seen:
            est = estimate(j)
            _, t, C, xi = guess[j]
            if est > max_modes:
                seen[j] = (est, t, None, None, None)
            else:
                done = [r[0] for r in seen.values() if r[2] is not None]
                budget = 2 * min(done) if done else None
                modes, M, coef, err = _measure(phi, E, t, xt, C, xi, target, max_modes, name,
                                               budget)
                seen[j] = (modes, t, M, coef, err)
        return seen[j]

    def key(j):     # measured grids before estimates, then fewer modes
        r = at(j)
        return (r[2] is None, r[0])

    def better(a, b):     # a clearly better than b (by 10 %: the optimum is flat)
        ka, kb = key(a), key(b)
        return ka[0] < kb[0] or (ka[0] == kb[0] and ka[1] < 0.9 * kb[1])

    lo, hi = min(WIDTH_POWERS), max(WIDTH_POWERS)
    j = min(WIDTH_POWERS, key=lambda jj: (estimate(jj), -jj))
    step = -1 if j > lo and (j == hi or better(j - 1, j)) else 1
    while lo <= j + step <= hi and better(j + step, j):
        j += step
    return at(j)


def finufft_eps(tol: float, kappa: float, kinf: float) -> float:
    """finufft's ``ε = EPS_FACTOR·tol·κ/‖φ‖∞`` rounded down to a power of ten, at least
    :data:`EPS_MIN`."""
    return max(EPS_MIN, 10.0 ** math.floor(math.log10(EPS_FACTOR * tol * kappa / kinf)))


def estimate_modes(phi, ext: np.ndarray, tol: float, kinf: float, kappa: float,
                   max_modes: int, name: str) -> int | None:
    """The modes of :func:`build_grid`'s grid estimated from the 1-D slices only (no k-D
    sampling: milliseconds), the slice's bandwidth raised by :data:`SLICE_TO_KD` per axis;
    None beyond ``max_modes``."""
    E = flat_extents(ext)
    big = float(E.max())
    if big == 0.0:
        return 1
    rel = tol * kappa / kinf
    xt = float(erfcinv(2.0 * min(0.25, WINDOW_FACTOR * rel)))
    best = math.inf
    for j in WIDTH_POWERS:
        t = big * 2.0 ** j
        C = _centre_value(phi, E, t, name)
        # the slice need not be sampled beyond the half-modes whose grid exceeds max_modes
        # (with max_modes as its cap, a flat 3-D cloud sampled 10⁸ points per slice: 33 s
        # of "cheap" estimate before a 0.1 s dense sum, found by a sweep of random clouds)
        xi = _bandwidth_1d(phi, big, t, xt, C, SUP_FACTOR * tol * kappa,
                           _slice_cap(E, t, max_modes), name)
        if xi is not None:
            best = min(best, math.prod(2 * math.floor(SLICE_TO_KD * xi * (e + t) / math.pi) + 1
                                       for e in E))
    return None if best > max_modes else int(best)


def build_grid(phi, ext: np.ndarray, tol: float, kinf: float, kappa: float, max_modes: int,
               name: str, xi_min: float = 0.0) -> Grid:
    """A :class:`Grid` for a cloud of extents ``ext`` (its flat extents from
    :func:`flat_extents`), kernel ``φ`` at relative accuracy ``tol``.

    Raises
    ------
    TooLarge
        When the modes needed exceed ``max_modes`` (no sampling beyond ``2·max_modes``
        samples is attempted).
    """
    k = ext.size
    E = flat_extents(ext)
    rel = tol * kappa / kinf
    eps = finufft_eps(tol, kappa, kinf)
    target = SUP_FACTOR * tol * kappa
    if float(E.max()) == 0.0:            # all agents coincide: K_R = φ(0), one mode
        c0 = float(_profile(phi, np.zeros(1), name)[0])
        return Grid(E, 0.0, np.ones(k), (0,) * k, np.full((1,) * k, c0), target, 0.0, kinf,
                    kappa, eps)
    xt = float(erfcinv(2.0 * min(0.25, WINDOW_FACTOR * rel)))
    modes, t, M, coef, err = _width_search(phi, E, target, xt, max_modes, name, xi_min)
    if M is None:
        raise _too_large(name, ext, tol, modes, max_modes, k)
    return Grid(E, t, 2.0 * (E + t), M, coef, target, err, kinf, kappa, eps)


class FastSum:
    """The transforms of one :class:`Grid`: a finufft type-1 plan (its adjoint is the type 2)
    for ``n`` points and ``n_trans`` complex strength vectors, reused while the grid's modes
    and ``ε`` stay the same (:meth:`matches`); points are set on every call.

    Parameters
    ----------
    grid : Grid
    n, n_trans, nthreads : int
    """

    def __init__(self, grid: Grid, n: int, n_trans: int, nthreads: int):
        try:
            import finufft
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise InvalidInput(f"the NUFFT backend needs the finufft package (pip install "
                               f"finufft): {exc}") from None
        self.grid = grid
        self.n = n
        self.n_trans = n_trans
        self.nthreads = max(1, min(nthreads, -(-n // POINTS_PER_THREAD)))
        modes = math.prod(grid.modes)
        k = len(grid.modes)
        # Small mode grids stay in cache: sorting the points costs more than it saves there
        # (measured: 41² modes, 10⁶ points, 2.1× faster unsorted).
        sort = 0 if modes * 2 ** k <= 2 ** 16 else 2
        #: finufft's upsampling factor, chosen by the cost model (:func:`_cost.upsampling`)
        self.upsampfac = _cost.upsampling(n, modes, grid.eps, k)
        try:
            self.plan = finufft.Plan(1, grid.modes, n_trans=n_trans, eps=grid.eps, isign=-1,
                                     nthreads=self.nthreads, modeord=0, spread_sort=sort,
                                     upsampfac=self.upsampfac)
        except MemoryError:
            raise TooLarge(f"NUFFT: finufft could not allocate a plan for {grid.modes} modes "
                           f"and {n_trans} transforms") from None
        except Exception as exc:  # pragma: no cover - defensive: name finufft's complaint
            raise InvalidInput(f"NUFFT: finufft refused a plan for {grid.modes} modes, "
                               f"{n_trans} transforms, eps={grid.eps:g}: {exc}") from None
        self.out = np.empty((n_trans, n), dtype=np.complex128)

    def matches(self, grid: Grid, n: int) -> bool:
        """Whether this plan serves ``grid`` for ``n`` points (same modes and ``ε``)."""
        return self.n == n and self.grid.modes == grid.modes and self.grid.eps == grid.eps

    def apply(self, grid: Grid, s: np.ndarray, centre: np.ndarray,
              strengths: np.ndarray) -> np.ndarray:
        """``Σⱼ αⱼ K_R(sᵢ − sⱼ)`` for the ``(n_trans, n)`` complex ``strengths`` at the points
        ``s (n, k)`` (box centre ``centre``), in this plan's output buffer ``(n_trans, n)``
        (overwritten by the next call)."""
        self.grid = grid
        k = s.shape[1]
        u = np.empty((k, s.shape[0]))
        for a in range(k):
            np.subtract(s[:, a], centre[a], out=u[a])
            u[a] *= 2.0 * math.pi / grid.periods[a]
        self.plan.setpts(*u)
        modes = self.plan.execute(strengths)
        modes *= grid.coef
        return self.plan.execute_adjoint(modes, out=self.out)
