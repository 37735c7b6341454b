"""Recovery of high-dimensional trajectories from L projected simulations (§3.3.1, §3.4.2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, as_choice
from ..errors import InvalidInput
from ..projection import Projection
from ._eta import EtaEstimate, estimate_eta
from ._solver import RecoveryResult, _check_param, basis_pursuit, stack_projections

__all__ = ["TrajectoryRecovery", "recover", "relative_error"]


@dataclass(frozen=True, repr=False)
class TrajectoryRecovery:
    """High-dimensional trajectories recovered by ℓ1 minimization.

    Attributes
    ----------
    X : (T, N, d) ndarray
        Recovered ``x♯ᵢ(t)`` for every saved time and agent.
    eta : (T, N) ndarray
        ``η`` used for each right-hand side.
    status : (T, N) ndarray of str
        Solver status per right-hand side (see :class:`RecoveryResult`).
    iterations : (T, N) ndarray of int
    relative_error : (T,) ndarray or None
        ``(Σᵢ‖x♯ᵢ(t) − xᵢ(t)‖² / Σᵢ‖xᵢ(t)‖²)^{1/2}`` per saved time when ``original`` was given
        (the recovery error of §3.4.2, Figure 4 right).
    L, k, d : int
        Number of projections, total rows ``kL`` of the stacked matrix, dimension.
    eta_rule : str
        ``"given"`` or the automatic rule used.
    solve : RecoveryResult
        The batched solve (columns ordered ``t * N + i``).
    eta_estimate : EtaEstimate or None
    """

    X: np.ndarray
    eta: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    relative_error: np.ndarray | None
    L: int
    k: int
    d: int
    eta_rule: str
    solve: RecoveryResult
    eta_estimate: EtaEstimate | None

    def __repr__(self) -> str:
        err = "" if self.relative_error is None else f", max_relative_error={np.max(self.relative_error):.3g}"
        return (
            f"TrajectoryRecovery(shape={self.X.shape}, L={self.L}, kL={self.k}, "
            f"status={self.solve.counts()}{err})"
        )


def relative_error(recovered, original) -> np.ndarray:
    """Per-time relative error ``(Σᵢ‖x♯ᵢ − xᵢ‖² / Σᵢ‖xᵢ‖²)^{1/2}`` of ``(T, N, d)`` arrays (§3.4.2).

    Examples
    --------
    >>> x = np.ones((2, 3, 4))
    >>> relative_error(1.1 * x, x).round(12)
    array([0.1, 0.1])
    """
    Xr = as_array(recovered, "recovered", ndim=3)
    X0 = as_array(original, "original", ndim=3)
    if Xr.shape != X0.shape:
        raise InvalidInput(f"original must have shape {Xr.shape} like recovered, got {X0.shape}")
    num = np.sum((Xr - X0) ** 2, axis=(1, 2))
    den = np.sum(X0**2, axis=(1, 2))
    return np.where(den > 0, np.sqrt(num / np.where(den > 0, den, 1.0)), np.nan)


def recover(
    projections,
    projected_trajectories,
    *,
    eta="auto",
    original=None,
    nonneg: bool = False,
    safety: float = 2.0,
    tol: float = 1e-6,
    max_iter: int = 5000,
) -> TrajectoryRecovery:
    """Recover ``x♯ᵢ(t) ∈ ℝᵈ`` from ``L`` projected simulations by ℓ1 minimization.

    The ``L`` parallel systems (3.17) give, for each agent ``i`` and saved
    time ``t``, the stacked data ``(y¹ᵢ(t); …; yᴸᵢ(t)) = 𝓜xᵢ(t) + eᵢ(t)`` with
    ``𝓜 = [M¹; …; Mᴸ]``; each is solved as (3.16)

    .. math::

        x^\\sharp_i(t) = \\arg\\min_z \\|z\\|_1 \\ \\text{s.t.}\\ \\|\\mathcal M z - y_i(t)\\|_2 \\le \\eta

    in one batched solve over all ``T·N`` right-hand sides (:func:`basis_pursuit`). The error
    bound is (3.19)/(3.21).

    Parameters
    ----------
    projections : sequence of L Projections or (k_ℓ, d) ndarrays (or one of them)
    projected_trajectories : sequence of L (T, N, k_ℓ) ndarrays (or one of them)
        The saved trajectories (x or v) of the projected simulations, same ``T`` and ``N``.
    eta : "auto", float or (T, N) ndarray, default "auto"
        Noise level(s) ``η ≥ 0``; ``0`` is basis pursuit. ``"auto"`` pools all agents at each
        saved time and estimates ``η`` from the data (:func:`estimate_eta`, cross-validation
        over the ``L`` blocks).
    original : (T, N, d) ndarray, optional
        The original trajectory; if given, the relative error per time is returned.
    nonneg : bool, default False
    safety : float, default 2
        Safety factor ``c`` of the automatic rule ``η = σ̂ √(m + c√(2m))``.
    tol, max_iter
        Solver options (see :func:`basis_pursuit`).

    Returns
    -------
    TrajectoryRecovery

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> Ms = [rng.standard_normal((10, 50)) / np.sqrt(10) for _ in range(3)]
    >>> X = np.zeros((2, 4, 50)); X[:, :, :5] = rng.standard_normal((2, 4, 5))
    >>> Ys = [X @ M.T for M in Ms]
    >>> rec = recover(Ms, Ys, eta=0.0, original=X)
    >>> bool(rec.relative_error.max() < 1e-8)
    True
    """
    projections, projected_trajectories = _as_sequences(projections, projected_trajectories)
    A = stack_projections(list(projections))
    d = A.shape[1]
    ks = [int(stack_projections([P]).shape[0]) for P in projections]
    trajs = _check_trajectories(projected_trajectories, ks)
    T, N = trajs[0].shape[:2]
    eta_cols = _check_eta(eta, T, N)
    X0 = None if original is None else as_array(original, "original", shape=(T, N, d))
    Y = np.vstack([Yl.reshape(T * N, -1).T for Yl in trajs])  # (m, T*N), column t*N + i
    est, rule = None, "given"
    if eta_cols is None:   # "auto": one group per saved time, the L blocks as folds
        est = estimate_eta(A, Y, groups=np.repeat(np.arange(T), N), blocks=ks, safety=safety)
        eta_cols, rule = est.eta, est.rule
    res = basis_pursuit(A, Y, eta_cols, nonneg=nonneg, tol=tol, max_iter=max_iter)
    X = res.Z.T.reshape(T, N, d)
    return TrajectoryRecovery(
        X=X,
        eta=res.param.reshape(T, N),
        status=res.status.reshape(T, N),
        iterations=res.iterations.reshape(T, N),
        relative_error=None if X0 is None else relative_error(X, X0),
        L=len(projections),
        k=A.shape[0],
        d=d,
        eta_rule=rule,
        solve=res,
        eta_estimate=est,
    )


def _as_sequences(projections, projected_trajectories):
    """Both arguments as sequences of the same length ``L`` (one array each wrapped)."""
    if isinstance(projections, (Projection, np.ndarray)):
        projections = [projections]
    if isinstance(projected_trajectories, np.ndarray):
        projected_trajectories = [projected_trajectories]
    if not isinstance(projections, (list, tuple)) or not isinstance(projected_trajectories, (list, tuple)):
        raise InvalidInput(
            "projections and projected_trajectories must be sequences (one entry per projected "
            f"simulation), got {type(projections).__name__} and {type(projected_trajectories).__name__}"
        )
    if len(projections) != len(projected_trajectories):
        raise InvalidInput(
            f"projections and projected_trajectories must have the same length L, got "
            f"{len(projections)} and {len(projected_trajectories)}"
        )
    return projections, projected_trajectories


def _check_trajectories(projected_trajectories, ks) -> list:
    """The ``L`` arrays ``(T, N, k_ℓ)``, checked against the projections' row counts ``ks``
    and against each other."""
    trajs = []
    for ell, (Yl, k) in enumerate(zip(projected_trajectories, ks)):
        Yl = as_array(Yl, f"projected_trajectories[{ell}]", ndim=3)
        if Yl.shape[2] != k:
            raise InvalidInput(
                f"projected_trajectories[{ell}] must have last axis k = {k} (rows of projections[{ell}]), "
                f"got shape {Yl.shape}"
            )
        if not trajs and 0 in Yl.shape[:2]:
            raise InvalidInput(
                f"projected_trajectories[{ell}] must hold at least one saved time and one agent, "
                f"got shape {Yl.shape}"
            )
        if trajs and Yl.shape[:2] != trajs[0].shape[:2]:
            raise InvalidInput(
                f"projected_trajectories[{ell}] must have shape (T, N) = {trajs[0].shape[:2]} in its "
                f"first two axes like projected_trajectories[0], got {Yl.shape}"
            )
        trajs.append(Yl)
    return trajs


def _check_eta(eta, T: int, N: int):
    """``η`` per column ``t·N + i`` (validated, so that its errors come before any work), or
    None for ``"auto"``."""
    if isinstance(eta, str):
        as_choice(eta, "eta", ("auto",))
        return None
    if np.ndim(eta) != 0:
        eta = as_array(eta, "eta", shape=(T, N)).reshape(-1)
    return _check_param(eta, T * N, "eta")
