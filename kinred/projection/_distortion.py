"""Measured distortion of a projection on point clouds and along trajectories.

* :func:`distortion` — the worst :math:`1 \\pm \\varepsilon` of eq. (2.1)
  over all pairs of a point cloud, in **squared** distances, as Lemma 2.1 states it.
* :func:`trajectory_distortion` — condition (3.4) of Theorem 3.2 along a
  simulated trajectory, in **non-squared** distances, as (3.4) states it, for every saved time.

Pairwise differences are formed explicitly (never through the Gram identity
:math:`\\|x\\|^2 + \\|y\\|^2 - 2x\\cdot y`, which loses all relative precision for close pairs
far from the origin), in blocks of rows so that memory stays at
:math:`O(\\text{block} \\cdot n \\cdot d)` floats, with the block chosen so that one block holds
about ``2**22`` numbers (32 MB).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._repr import result_repr
from .._validate import as_array
from ..errors import InvalidInput
from ._base import Projection, as_projection

__all__ = [
    "DistortionResult",
    "TrajectoryDistortionResult",
    "distortion",
    "trajectory_distortion",
]

_BLOCK_BUDGET = 1 << 22  # numbers per block of pairwise differences


@dataclass(frozen=True)
class DistortionResult:
    """Worst pairwise distortion of a projection on a point cloud (eq. (2.1)).

    Attributes
    ----------
    eps : float
        :math:`\\max(1 - r_{\\min},\\, r_{\\max} - 1)`: the smallest ``ε`` for which eq. (2.1)
        holds on this cloud.
    ratio_min, ratio_max : float
        Extreme ratios :math:`\\|Mx_i - Mx_j\\|^2 / \\|x_i - x_j\\|^2` over pairs ``i < j``.
    argmin, argmax : tuple of int
        The pairs ``(i, j)`` attaining them.
    n_pairs : int
        Number of pairs compared (``i < j``, coincident pairs excluded).
    n_coincident : int
        Number of pairs with :math:`x_i = x_j` exactly (skipped: the ratio is undefined).
    squared : bool
        ``True``: the ratios are of squared distances.
    """

    eps: float
    ratio_min: float
    ratio_max: float
    argmin: tuple[int, int]
    argmax: tuple[int, int]
    n_pairs: int
    n_coincident: int
    squared: bool = True


@dataclass(frozen=True)
class TrajectoryDistortionResult:
    """Condition (3.4) measured along a trajectory.

    Attributes
    ----------
    eps : float
        Smallest ``ε`` with :math:`(1-\\varepsilon)\\|x_i-x_j\\| \\le \\|M x_i - M x_j\\| \\le
        (1+\\varepsilon)\\|x_i-x_j\\|` at all saved times and pairs.
    ratio_min, ratio_max : float
        Extremes over all times and pairs of :math:`\\|M(x_i - x_j)\\| / \\|x_i - x_j\\|`
        (non-squared).
    eps_t : (T,) ndarray
        The same ``ε`` per saved time.
    ratio_min_t, ratio_max_t : (T,) ndarray
        Per-time extremes (NaN at a time where all agents coincide).
    worst_time : int
        Index of the time attaining ``eps``.
    n_pairs : int
        Number of (time, pair) comparisons made.
    n_coincident : int
        Number of (time, pair) with coincident agents (skipped).
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    eps: float
    ratio_min: float
    ratio_max: float
    eps_t: np.ndarray
    ratio_min_t: np.ndarray
    ratio_max_t: np.ndarray
    worst_time: int
    n_pairs: int
    n_coincident: int


def _pair_extremes(X: np.ndarray, Y: np.ndarray):
    """Min/max over ``i < j`` of ``‖Yi − Yj‖² / ‖Xi − Xj‖²``, skipping ``Xi = Xj``.

    Returns ``(rmin, rmax, argmin, argmax, n_pairs, n_coincident)``; ``rmin = nan`` when no
    pair is usable.
    """
    n, d = X.shape
    k = Y.shape[1]
    block = max(1, _BLOCK_BUDGET // max(1, n * max(d, k)))
    rmin, rmax = np.inf, -np.inf
    amin = amax = (-1, -1)
    n_pairs = n_coinc = 0
    for a in range(0, n - 1, block):
        b = min(a + block, n - 1)
        # rows a..b-1 against columns a+1..n-1; keep only j > i
        DX = X[a:b, None, :] - X[None, a + 1:, :]
        dx = np.einsum("ijk,ijk->ij", DX, DX)
        del DX
        DY = Y[a:b, None, :] - Y[None, a + 1:, :]
        dy = np.einsum("ijk,ijk->ij", DY, DY)
        del DY
        ii = np.arange(a, b)[:, None]
        jj = np.arange(a + 1, n)[None, :]
        upper = jj > ii
        coinc = upper & (dx == 0.0)
        valid = upper & ~coinc
        n_coinc += int(coinc.sum())
        nv = int(valid.sum())
        if nv == 0:
            continue
        n_pairs += nv
        ratio = np.full(dx.shape, np.nan)
        np.divide(dy, dx, out=ratio, where=valid)
        lo = np.where(valid, ratio, np.inf)
        hi = np.where(valid, ratio, -np.inf)
        p = np.unravel_index(int(np.argmin(lo)), lo.shape)
        q = np.unravel_index(int(np.argmax(hi)), hi.shape)
        if lo[p] < rmin:
            rmin, amin = float(lo[p]), (a + int(p[0]), a + 1 + int(p[1]))
        if hi[q] > rmax:
            rmax, amax = float(hi[q]), (a + int(q[0]), a + 1 + int(q[1]))
    if n_pairs == 0:
        rmin = rmax = np.nan
    return rmin, rmax, amin, amax, n_pairs, n_coinc


def distortion(M, points) -> DistortionResult:
    """Worst distortion of ``M`` over all pairs of ``points`` (eq. (2.1)).

    .. math::

        r_{ij} = \\frac{\\|Mx_i - Mx_j\\|^2}{\\|x_i - x_j\\|^2},\\qquad
        \\varepsilon = \\max\\bigl(1 - \\min_{i<j} r_{ij},\\ \\max_{i<j} r_{ij} - 1\\bigr).

    Parameters
    ----------
    M : Projection or (k, d) array_like
        The map.
    points : (n, d) array_like
        The cloud, ``n >= 2`` with at least one pair of distinct points. Pairs of identical
        points are skipped and counted in ``n_coincident``.

    Returns
    -------
    DistortionResult

    Examples
    --------
    An orthogonal matrix has no distortion; dropping a coordinate shrinks some pair:

    >>> x = np.random.default_rng(1).random((6, 4))
    >>> r = distortion(np.eye(4), x)
    >>> r.eps, r.n_pairs, r.squared
    (0.0, 15, True)
    >>> bool(distortion(np.eye(4)[:3], x).ratio_min < 1.0)
    True
    """
    P: Projection = as_projection(M)
    X = as_array(points, "points", ndim=2)
    if X.shape[1] != P.d:
        raise InvalidInput(
            f"points must have {P.d} columns (the projection's source dimension), got shape {X.shape}"
        )
    if X.shape[0] < 2:
        raise InvalidInput(f"points must hold at least 2 points, got {X.shape[0]}")
    Y = P.apply(X)
    rmin, rmax, amin, amax, n_pairs, n_coinc = _pair_extremes(X, Y)
    if n_pairs == 0:
        raise InvalidInput("points must contain at least two distinct points; all pairs coincide")
    return DistortionResult(
        eps=float(max(1.0 - rmin, rmax - 1.0)),
        ratio_min=rmin,
        ratio_max=rmax,
        argmin=amin,
        argmax=amax,
        n_pairs=n_pairs,
        n_coincident=n_coinc,
    )


def trajectory_distortion(M, traj_x) -> TrajectoryDistortionResult:
    """Condition (3.4) of Theorem 3.2 measured along a trajectory.

    .. math::

        \\varepsilon = \\max_{t}\\ \\max_{i<j}\\
        \\Bigl|\\frac{\\|Mx_i(t) - Mx_j(t)\\|}{\\|x_i(t) - x_j(t)\\|} - 1\\Bigr|

    (non-squared distances, as (3.4) is stated), with the per-time worst ``eps_t``. Only the
    saved times are checked; Theorem 3.3 bounds what happens between
    them through the ratio γ of condition (3.12). Cost
    :math:`O(T N^2 d)` — subsample times (``traj_x[::s]``) for long runs.

    Parameters
    ----------
    M : Projection or (k, d) array_like
    traj_x : (T, N, d) array_like
        Positions at ``T`` saved times, ``N >= 2`` agents.

    Returns
    -------
    TrajectoryDistortionResult

    Examples
    --------
    >>> traj = np.random.default_rng(0).random((3, 4, 2))
    >>> r = trajectory_distortion(np.diag([1.0, 1.0]), traj)
    >>> r.eps, r.eps_t.shape
    (0.0, (3,))
    """
    P: Projection = as_projection(M)
    X = as_array(traj_x, "traj_x", ndim=3)
    T, N, d = X.shape
    if d != P.d:
        raise InvalidInput(
            f"traj_x must have last axis {P.d} (the projection's source dimension), got shape {X.shape}"
        )
    if T < 1 or N < 2:
        raise InvalidInput(f"traj_x must hold at least one time and two agents, got shape {X.shape}")
    rmin_t = np.full(T, np.nan)
    rmax_t = np.full(T, np.nan)
    n_pairs = n_coinc = 0
    for t in range(T):
        Y = P.apply(X[t])
        rmin, rmax, _, _, npairs, ncoinc = _pair_extremes(X[t], Y)
        n_pairs += npairs
        n_coinc += ncoinc
        if npairs:
            rmin_t[t], rmax_t[t] = np.sqrt(rmin), np.sqrt(rmax)
    if n_pairs == 0:
        raise InvalidInput("traj_x must contain two distinct agents at some time; all coincide")
    with np.errstate(invalid="ignore"):
        eps_t = np.maximum(1.0 - rmin_t, rmax_t - 1.0)
    worst = int(np.nanargmax(eps_t))
    return TrajectoryDistortionResult(
        eps=float(eps_t[worst]),
        ratio_min=float(np.nanmin(rmin_t)),
        ratio_max=float(np.nanmax(rmax_t)),
        eps_t=eps_t,
        ratio_min_t=rmin_t,
        ratio_max_t=rmax_t,
        worst_time=worst,
        n_pairs=n_pairs,
        n_coincident=n_coinc,
    )
