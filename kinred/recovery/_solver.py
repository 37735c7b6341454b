"""Batched ℓ1 recovery: basis pursuit, basis-pursuit denoising and LASSO for many right-hand sides.

The solver is ADMM in the C-SALSA splitting (Afonso, Bioucas-Dias, Figueiredo 2011) applied
column by column to

.. math::

    \\min_{z\\in\\mathbb R^d} \\|z\\|_{\\ell_1^d}
    \\quad\\text{s.t.}\\quad \\|Az - y\\|_{\\ell_2^m} \\le \\eta ,

problem (3.16) of the paper, for all columns ``y`` of ``Y (m, n_rhs)`` at
once, sharing one matrix ``A (m, d)``. With the variables ``u = z`` and ``v = Az``, one ADMM
iteration is

.. math::

    z &= (I + A^\\top A)^{-1}\\,\\big(u - p + A^\\top (v - q)\\big) \\\\
    u &= \\operatorname{soft}(z + p,\\ 1/\\mu), \\qquad
    v = \\Pi_{\\{\\|v-y\\|\\le\\eta\\}}(Az + q) \\\\
    p &\\leftarrow p + z - u, \\qquad q \\leftarrow q + Az - v

(with over-relaxation of ``z`` and ``Az``). By the matrix inversion lemma with
``G = I + AAᵀ (m × m)``, ``w = G⁻¹(b − Aa)``, ``z = a + Aᵀw``, ``Az = b − w``. With the
eigendecomposition ``AAᵀ = U diag(σ²) Uᵀ`` (once per solve) the iteration runs in rotated
``m``-coordinates (``b̃ = Uᵀb``, ``B = UᵀA``): ``w̃ = (b̃ − B a)/(1 + σ²)``, ``z = a + Bᵀw̃``,
``Uᵀ(Az) = b̃ − w̃`` – two products with ``(m, d)`` matrices per iteration and no ``m × m``
one (the ``v``-step, a ball around ``y`` or the LASSO average, commutes with ``U``). Columns
are independent problems: they are iterated in chunks of 128 rows that stay in cache, dealt to
the threads of :func:`kinred.dynamics.set_num_threads`. The penalty ``μ`` enters
only as the threshold of the ``u``-prox (``(I + AᵀA)⁻¹`` does not depend on it), so each
column has its own ``μ``, adapted by residual balancing without any re-factorization.

Per-column scaling: ``A`` is scaled to spectral norm ``ω = 10`` and every column ``y`` to unit
norm (``η`` and ``λ`` accordingly), so one starting penalty suits all columns.

The solve runs in phases: *setup* (spectral data of ``A``), *trivial columns* (``z = 0``
optimal, or the constraint infeasible: no iteration), the *sweep* over a batch of the other
columns (every ``check_every`` iterations: residuals, polish, residual balancing, and the
finished columns leave the batch), and *finalize* (residuals and objectives in the original
scaling).

Certified polish: at each check, columns whose sign pattern did not change since the previous
check are polished on their support ``S`` with signs ``s``. For BPDN the exact KKT point on
``S`` has a closed form,

.. math::

    z_S = (A_S^\\top A_S)^{-1}(A_S^\\top y - \\lambda s),\\qquad
    \\lambda = \\sqrt{\\eta^2 - \\|r_0\\|^2}\\,/\\,\\|A_S (A_S^\\top A_S)^{-1} s\\|

(``r₀`` the least-squares residual on ``S``), and the column is accepted as **optimal** when
the signs agree and the dual certificate ``‖Aᵀ(y − Az)‖∞ ≤ λ(1 + cert_tol)`` holds. For basis
pursuit (``η = 0``) the polished point is the least-squares solution on ``S`` (it must satisfy
``Az = y``) and the certificate is the ADMM dual vector corrected onto
``{ν : A_Sᵀν = s}`` or the minimum-norm ``ν`` with ``A_Sᵀν = s``, accepted when
``‖Aᵀν‖∞ ≤ 1 + cert_tol``. A certificate bounds the relative duality gap by ``cert_tol``; the
polished solution is exact up to round-off. Supports that fail the certificate are repaired
(expansion and pruning, :func:`kinred.recovery._polish.polish_with_repair`).
"""

from __future__ import annotations

import numbers
import time
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, as_bool, as_float, as_int, check_alloc
from ..errors import InvalidInput
from ..projection import Projection, as_projection
from ._scaling import Scaling
from ._sweep import _start, _sweep

__all__ = [
    "RecoveryResult",
    "STATUSES",
    "stack_projections",
    "basis_pursuit",
    "lasso",
]

#: Per-column statuses of :class:`RecoveryResult`.
STATUSES = ("optimal", "converged", "max_iter", "zero", "infeasible")


@dataclass(frozen=True, repr=False)
class RecoveryResult:
    """Solutions of many ℓ1 problems sharing one matrix.

    Attributes
    ----------
    Z : (d, n_rhs) ndarray
        Solutions, one column per right-hand side (NaN for ``"infeasible"`` columns).
    status : (n_rhs,) ndarray of str
        ``"optimal"``: polished on its support and certified by a dual vector (relative duality
        gap ≤ ``cert_tol``); ``"converged"``: ADMM primal and dual residuals below ``tol`` (and
        the polished point kept if it is feasible and its objective exceeds ADMM's by at most
        the factor ``1 + 10·tol``); ``"max_iter"``: stopped at ``max_iter`` (best iterate
        returned); ``"zero"``: ``z = 0`` is optimal (``‖y‖ ≤ η``, or
        ``‖Aᵀy‖∞ ≤ λ`` for the LASSO); ``"infeasible"``: ``min_z ‖Az − y‖ > η``.
    iterations : (n_rhs,) ndarray of int
        ADMM iterations spent on each column.
    residual : (n_rhs,) ndarray
        ``‖A z − y‖₂`` of the returned solutions.
    objective : (n_rhs,) ndarray
        ``‖z‖₁`` (BPDN) or ``½‖Az − y‖² + λ‖z‖₁`` (LASSO).
    param : (n_rhs,) ndarray
        ``η`` (form ``"bpdn"``) or ``λ`` (form ``"lasso"``) of each column.
    gap : (n_rhs,) ndarray
        Certified relative duality gap of ``"optimal"``/``"zero"`` columns, NaN otherwise.
    primal_residual, dual_residual : (n_rhs,) ndarray
        Last ADMM residuals of the normalized problem (NaN if ADMM never ran on the column).
    form : str
        ``"bpdn"`` or ``"lasso"``.
    nonneg : bool
        Whether ``z ≥ 0`` was imposed.
    tol : float
        ADMM tolerance used.
    seconds : float
        Wall time of the solve.
    """

    Z: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray
    objective: np.ndarray
    param: np.ndarray
    gap: np.ndarray
    primal_residual: np.ndarray
    dual_residual: np.ndarray
    form: str
    nonneg: bool
    tol: float
    seconds: float

    @property
    def n_rhs(self) -> int:
        """Number of right-hand sides."""
        return int(self.Z.shape[1])

    @property
    def converged(self) -> np.ndarray:
        """``(n_rhs,)`` bool: status is ``"optimal"``, ``"converged"`` or ``"zero"``."""
        return np.isin(self.status, ("optimal", "converged", "zero"))

    def counts(self) -> dict:
        """Number of columns per status."""
        return {s: int(np.sum(self.status == s)) for s in STATUSES if np.any(self.status == s)}

    def __repr__(self) -> str:
        return (
            f"RecoveryResult(form={self.form!r}, nonneg={self.nonneg}, shape={self.Z.shape}, "
            f"status={self.counts()}, max_iterations={int(self.iterations.max(initial=0))}, "
            f"seconds={self.seconds:.3g})"
        )


# ---------------------------------------------------------------------------------------------
# input handling


def stack_projections(projections) -> np.ndarray:
    """Stack projections ``M¹, …, Mᴸ`` into the ``(kL, d)`` matrix ``[M¹; …; Mᴸ]``.

    Parameters
    ----------
    projections : Projection, (m, d) ndarray, or sequence of Projection / (k_ℓ, d) ndarrays
        One matrix, or the ``L`` projections of the parallel simulations (3.17) of the paper.
        All must share the source dimension ``d``.

    Returns
    -------
    (Σ k_ℓ, d) ndarray
        The stacked matrix 𝓜 of §3.3.1.

    Examples
    --------
    >>> stack_projections([np.eye(2, 3), np.ones((1, 3))]).shape
    (3, 3)
    """
    return _stack(projections, "projections")


def _stack(projections, name: str) -> np.ndarray:
    """:func:`stack_projections`, naming the argument ``name`` in messages."""
    if isinstance(projections, Projection):
        return np.asarray(projections.to_dense(), dtype=float)
    if isinstance(projections, np.ndarray) and projections.ndim == 2:
        return as_array(projections, name, ndim=2)
    if isinstance(projections, (list, tuple)):
        if len(projections) == 0:
            raise InvalidInput(f"{name} must hold at least one projection, got an empty sequence")
        mats = []
        for i, P in enumerate(projections):
            if not isinstance(P, Projection):
                P = as_array(P, f"{name}[{i}]", ndim=2)
            M = np.asarray(as_projection(P).to_dense(), dtype=float)
            if not np.all(np.isfinite(M)):
                raise InvalidInput(f"{name}[{i}] must be finite")
            mats.append(M)
        d0 = mats[0].shape[1]
        for i, M in enumerate(mats):
            if M.shape[1] != d0:
                raise InvalidInput(
                    f"all {name} must have the same source dimension d; {name}[0] has "
                    f"d = {d0} but {name}[{i}] has shape {M.shape}"
                )
        return np.vstack(mats)
    return as_array(projections, name, ndim=2)


def _check_A(A) -> np.ndarray:
    A = _stack(A, "A")
    if A.shape[0] < 1 or A.shape[1] < 1:
        raise InvalidInput(f"A must have at least one row and one column, got shape {A.shape}")
    return np.ascontiguousarray(A, dtype=float)


def _check_Y(Y, m: int) -> np.ndarray:
    Y = as_array(Y, "Y", ndim=(1, 2))
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.shape[0] != m:
        raise InvalidInput(
            f"Y must have m = {m} rows (the number of rows of A), got shape {Y.shape}"
        )
    return Y


def _check_param(value, n: int, name: str) -> np.ndarray:
    if isinstance(value, (numbers.Number, np.generic)) or value is None:
        v = as_float(value, name, low=0.0)
        return np.full(n, v)
    arr = as_array(value, name, ndim=1)
    if arr.shape[0] != n:
        raise InvalidInput(
            f"{name} must be a scalar or have shape ({n},) (one value per right-hand side), "
            f"got shape {arr.shape}"
        )
    if np.any(arr < 0):
        i = int(np.argmin(arr))
        raise InvalidInput(f"{name} must be >= 0, got {arr[i]} at index {i}")
    return arr.astype(float)


# ---------------------------------------------------------------------------------------------
# options


@dataclass(frozen=True)
class _Options:
    """Validated solver options (see :func:`basis_pursuit`)."""

    nonneg: bool
    tol: float
    max_iter: int
    polish: bool
    relax: float
    check_every: int
    cert_tol: float
    mu0: float | None
    adaptive: bool

    @classmethod
    def validated(cls, *, nonneg, tol, max_iter, polish, relax, check_every, cert_tol, mu0,
                  adaptive) -> "_Options":
        tol = as_float(tol, "tol", low=0.0, low_open=True, high=1.0)
        max_iter = as_int(max_iter, "max_iter", low=1)
        relax = as_float(relax, "relax", low=0.0, low_open=True, high=2.0, high_open=True)
        check_every = as_int(check_every, "check_every", low=1)
        cert_tol = as_float(cert_tol, "cert_tol", low=0.0)
        if mu0 is not None:
            mu0 = as_float(mu0, "mu0", low=0.0, low_open=True)
        return cls(nonneg=as_bool(nonneg, "nonneg"), tol=tol, max_iter=max_iter,
                   polish=as_bool(polish, "polish"), relax=relax, check_every=check_every,
                   cert_tol=cert_tol, mu0=mu0, adaptive=as_bool(adaptive, "adaptive"))


def _validated_solve(form: str, A, Y, param, param_name: str, **options) -> RecoveryResult:
    """The body of :func:`basis_pursuit` (``form="bpdn"``) and :func:`lasso`: validate
    everything, then solve."""
    A = _check_A(A)
    Y = _check_Y(Y, A.shape[0])
    param = _check_param(param, Y.shape[1], param_name)
    opts = _Options.validated(**options)
    _check_size(A.shape, Y.shape[1], "basis_pursuit" if form == "bpdn" else "lasso")
    return _solve(A, Y, param, form, opts)


def _check_size(shape: tuple, n_rhs: int, call: str) -> None:
    """Preflight of the solver's arrays: ``ÂᵀÂ (d, d)``, ``U (m, m)``, ``Â, UᵀÂ`` and its
    transpose ``(m, d)`` each, the iterates ``(n_rhs, 6d + 5m)`` and their sign patterns."""
    m, d = shape
    need = 8 * (d * d + m * m + 3 * m * d) + n_rhs * (8 * (6 * d + 5 * m) + d)
    check_alloc(need, f"{call}: A of shape ({m}, {d}) with {n_rhs} right-hand sides",
                "the solver keeps A^T A (d, d) and iterates (n_rhs, d): pass fewer columns of Y "
                "per call or a matrix with fewer columns d",
                detail=" (A^T A, the factorization and the ADMM iterates)")


# ---------------------------------------------------------------------------------------------
# phase 1: spectral data of A, and the columns that need no iteration


@dataclass(frozen=True)
class _Spectrum:
    """Spectral data of ``A (m, d)``."""

    scale: float        # ‖A‖₂ (0 for A = 0)
    U: np.ndarray       # left singular vectors, by decreasing singular value
    rank: int           # numerical rank
    An: np.ndarray      # Â = A ω/‖A‖ (A itself if A = 0)


def _spectrum(A) -> _Spectrum:
    """Singular values and left singular vectors of ``A``, its rank and ``Â``."""
    m, d = A.shape
    # from the m×m Gram matrix (cheaper than an SVD of A when m ≤ d)
    if m <= d:
        ev, U = np.linalg.eigh(A @ A.T)
        ev, U = ev[::-1], U[:, ::-1]
        sv = np.sqrt(np.maximum(ev, 0.0))
    else:
        U, sv, _ = np.linalg.svd(A, full_matrices=False)
    scale = float(sv[0]) if sv.size else 0.0
    if scale == 0.0:
        return _Spectrum(scale, U, 0, A)
    # eigenvalues of AAᵀ carry round-off of size eps·‖A‖², i.e. singular values ~sqrt(eps)
    rank = int(np.sum(sv > scale * max(m, d) * np.sqrt(np.finfo(float).eps)))
    return _Spectrum(scale, U, rank, Scaling.normalized_matrix(A, scale))


def _trivial_columns(A, Y, param, form, spec: _Spectrum, ynorm):
    """``(zero, infeasible)`` column masks: ``z = 0`` is optimal (``‖y‖ ≤ η``, or
    ``‖Aᵀy‖∞ ≤ λ``), or ``min_z ‖Az − y‖ > η`` (BPDN)."""
    if form == "lasso":
        zero = np.max(np.abs(A.T @ Y), axis=0, initial=0.0) <= param
        return zero, np.zeros(Y.shape[1], dtype=bool)
    zero = ynorm <= param
    Ur = spec.U[:, : spec.rank]
    ls_res = np.linalg.norm(Y - Ur @ (Ur.T @ Y), axis=0)
    return zero, (~zero) & (ls_res > param + 1e-10 * ynorm)


class _Columns:
    """Per-column results in the caller's column order, filled in as columns finish."""

    def __init__(self, d: int, n: int):
        self.Z = np.zeros((d, n))
        self.status = np.full(n, "max_iter", dtype="<U10")
        self.iterations = np.zeros(n, dtype=np.int64)
        self.gap = np.full(n, np.nan)
        self.primal = np.full(n, np.nan)
        self.dual = np.full(n, np.nan)

    def mark_trivial(self, zero, infeasible) -> None:
        self.status[zero] = "zero"
        self.gap[zero] = 0.0
        self.status[infeasible] = "infeasible"
        self.Z[:, infeasible] = np.nan


# ---------------------------------------------------------------------------------------------
# the solver: setup, trivial columns, sweep, finalize


def _finalize(A, Y, param, scaling: Scaling, opts: _Options, out: _Columns, infeasible,
              t0) -> RecoveryResult:
    """Residuals and objectives of the layer-1 problem, then everything in the caller's
    numbers (:class:`Scaling`)."""
    R = A @ np.where(np.isfinite(out.Z), out.Z, 0.0) - Y
    residual = np.linalg.norm(R, axis=0)
    residual[infeasible] = np.nan
    l1 = np.sum(np.abs(out.Z), axis=0)
    objective = scaling.original_objective(residual, l1, param, infeasible)
    Z = scaling.original_z(out.Z)
    if np.any(np.isinf(Z)):
        raise InvalidInput(f"A (entries up to 2^{scaling.ea}) and Y (up to 2^{scaling.ey}) have "
                           "a solution beyond the float64 range: rescale A or Y (z scales as Y/A)")
    return RecoveryResult(
        Z=Z,
        status=out.status,
        iterations=out.iterations,
        residual=scaling.original_residual(residual),
        objective=objective,
        param=scaling.param,
        gap=out.gap,
        primal_residual=out.primal,
        dual_residual=out.dual,
        form=scaling.form,
        nonneg=opts.nonneg,
        tol=float(opts.tol),
        seconds=time.perf_counter() - t0,
    )


def _solve(A, Y, param, form: str, opts: _Options) -> RecoveryResult:
    """Solve all columns of ``Y`` (validated inputs; ``form`` ``"bpdn"`` or ``"lasso"``)."""
    t0 = time.perf_counter()
    m, d = A.shape
    scaling, A, Y, param = Scaling.of(A, Y, param, form)
    out = _Columns(d, Y.shape[1])
    spec = _spectrum(A)
    ynorm = np.linalg.norm(Y, axis=0)
    zero, infeasible = _trivial_columns(A, Y, param, form, spec, ynorm)
    out.mark_trivial(zero, infeasible)
    active = np.flatnonzero(~zero & ~infeasible)
    if active.size:
        system, batch = _start(Y, param, scaling, spec, active, ynorm, opts.mu0)
        _sweep(system, batch, out, form, opts)
    return _finalize(A, Y, param, scaling, opts, out, infeasible, t0)


_COMMON_DOC = """
    nonneg : bool, default False
        Impose ``z ≥ 0``.
    tol : float, default 1e-6
        Relative tolerance of the ADMM primal and dual residuals (Boyd et al. 2011, §3.3.1).
    max_iter : int, default 5000
        Maximum number of ADMM iterations per column.
    polish : bool, default True
        Polish on the detected support and certify (see the module docstring). Without it
        the ADMM iterate ``u`` (exactly sparse) is returned.
    relax : float, default 1.6
        Over-relaxation parameter in ``(0, 2)``.
    check_every : int, default 10
        Iterations between residual checks, polish attempts and batch compaction.
    cert_tol : float, default 1e-9
        Tolerance of the dual certificate (bound on the relative duality gap).
    mu0 : float or None
        Starting penalty of the normalized problem; ``None`` picks ``ω²/(0.1 ‖Âᵀŷ‖∞)`` per
        column (``ω = 10`` the spectral norm of the normalized matrix ``Â``, which weighs the
        constraint ``v = Âz`` against ``u = z``).
    adaptive : bool, default False
        Residual balancing (Wohlberg 2017): every check during the first
        ``max(20·check_every, 300)`` iterations, ``μ`` of a column is doubled (halved) when its
        relative primal residual exceeds its relative dual residual tenfold (or vice versa). No
        re-factorization is needed (``μ`` only scales the ``u``-threshold). Off by default: on
        Gaussian compressed-sensing problems the scale-invariant starting ``μ`` converges
        faster (docs/performance.md).
"""


def basis_pursuit(
    A,
    Y,
    eta=0.0,
    *,
    nonneg: bool = False,
    tol: float = 1e-6,
    max_iter: int = 5000,
    polish: bool = True,
    relax: float = 1.6,
    check_every: int = 10,
    cert_tol: float = 1e-9,
    mu0: float | None = None,
    adaptive: bool = False,
) -> RecoveryResult:
    """Basis pursuit (``η = 0``) and basis-pursuit denoising for many right-hand sides.

    Solves, for every column ``y`` of ``Y``, problem (3.16) of the paper

    .. math::

        \\min_{z\\in\\mathbb R^d} \\|z\\|_{1} \\quad\\text{s.t.}\\quad \\|Az - y\\|_2 \\le \\eta

    with one shared matrix ``A`` (e.g. the stacked 𝓜 = [M¹; …; Mᴸ] of the ``L`` parallel
    projected simulations (3.17)), by batched ADMM with certified polish.

    Parameters
    ----------
    A : (m, d) ndarray, Projection, or sequence of L Projections / (k, d) ndarrays
        The matrix, or the projections to stack (:func:`stack_projections`).
    Y : (m, n_rhs) or (m,) ndarray
        Right-hand sides, one per column.
    eta : float or (n_rhs,) ndarray, default 0
        Noise levels ``η ≥ 0`` (per column allowed); ``0`` is basis pursuit.
%s
    Returns
    -------
    RecoveryResult
        ``Z (d, n_rhs)`` and per-column status, iterations, residuals, objective.

    Raises
    ------
    TooLarge
        ``AᵀA (d, d)`` and the iterates would exceed the memory limit (environment variable
        ``KINRED_MAX_BYTES``, default 2 GiB); checked before the solve.

    Notes
    -----
    The problem is homogeneous: it is solved for ``A`` and ``Y`` scaled by powers of two to
    entries below one (exactly), so entries anywhere in the float64 range work.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> A = rng.standard_normal((40, 100)) / np.sqrt(40)
    >>> X = np.zeros((100, 5)); X[rng.integers(0, 100, 25), np.arange(25) %% 5] = 1.0
    >>> res = basis_pursuit(A, A @ X)
    >>> bool(np.allclose(res.Z, X, atol=1e-8)), res.counts()
    (True, {'optimal': 5})
    """
    return _validated_solve(
        "bpdn", A, Y, eta, "eta", nonneg=nonneg, tol=tol, max_iter=max_iter, polish=polish,
        relax=relax, check_every=check_every, cert_tol=cert_tol, mu0=mu0, adaptive=adaptive,
    )


def lasso(
    A,
    Y,
    lam,
    *,
    nonneg: bool = False,
    tol: float = 1e-6,
    max_iter: int = 5000,
    polish: bool = True,
    relax: float = 1.6,
    check_every: int = 10,
    cert_tol: float = 1e-9,
    mu0: float | None = None,
    adaptive: bool = False,
) -> RecoveryResult:
    """LASSO ``min ½‖Az − y‖² + λ‖z‖₁`` for many right-hand sides sharing ``A``.

    The Lagrangian form of (3.16): for each ``η`` there is a ``λ`` with the
    same solution. Same batched ADMM as :func:`basis_pursuit`, with the ``v``-step
    ``v = (y + μ t)/(1 + μ)``.

    .. math::

        \\min_{z\\in\\mathbb R^d} \\tfrac12\\|Az - y\\|_2^2 + \\lambda \\|z\\|_1

    Parameters
    ----------
    A : (m, d) ndarray, Projection, or sequence of Projections / (k, d) ndarrays
    Y : (m, n_rhs) or (m,) ndarray
    lam : float or (n_rhs,) ndarray
        Regularization ``λ ≥ 0`` (per column allowed).
%s
    Returns
    -------
    RecoveryResult

    Examples
    --------
    >>> A = np.eye(3)
    >>> res = lasso(A, np.array([3.0, -0.5, 1.0]), 1.0)
    >>> np.round(res.Z[:, 0], 8) + 0.0
    array([2., 0., 0.])
    """
    return _validated_solve(
        "lasso", A, Y, lam, "lam", nonneg=nonneg, tol=tol, max_iter=max_iter, polish=polish,
        relax=relax, check_every=check_every, cert_tol=cert_tol, mu0=mu0, adaptive=adaptive,
    )


basis_pursuit.__doc__ = basis_pursuit.__doc__ % _COMMON_DOC
lasso.__doc__ = lasso.__doc__ % _COMMON_DOC
