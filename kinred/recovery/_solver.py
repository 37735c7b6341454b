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
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from .._parallel import get_num_threads, run_parallel
from .._validate import as_array, as_bool, as_float, as_int, check_alloc
from ..errors import InvalidInput
from ..projection import Projection, as_projection
from ._kernels import admm_step
from ._polish import polish_with_repair

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


#: Spectral norm ``ω`` of the normalized matrix ``Â``: weighs the constraint ``v = Âz``
#: against ``u = z``.
_OMEGA = 10.0
#: Starting penalty ``μ = ω²/(κ ‖Âᵀŷ‖∞)`` per column.
_KAPPA = 0.1


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
    return _Spectrum(scale, U, rank, A * (_OMEGA / scale))


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
# phase 2: the normalized problem and the batch of columns being iterated


@dataclass(frozen=True)
class _System:
    """The normalized matrix and what the iterations and the polish need of it.

    ``ÂÂᵀ = U diag(σ²) Uᵀ``; the iterations run in rotated ``m``-coordinates with
    ``B = UᵀÂ`` (see the module docstring).
    """

    An: np.ndarray      # (m, d) Â
    AtA: np.ndarray     # (d, d) ÂᵀÂ, for the polish
    U: np.ndarray       # (m, m) eigenvectors of ÂÂᵀ
    Dg: np.ndarray      # (m,) 1/(1 + σ²)
    B: np.ndarray       # (m, d) UᵀÂ
    BT: np.ndarray      # (d, m) its transpose, contiguous

    @property
    def shape(self):
        return self.An.shape


@dataclass
class _Batch:
    """The columns still iterating, one row each: ADMM state and per-column data.

    Every attribute is an array with one row per column; :meth:`compact` keeps the same rows
    of all of them at once.
    """

    ids: np.ndarray         # (n,) column of Y
    back: np.ndarray        # (n,) ‖y‖ω/‖A‖: z = ẑ·back
    Yh: np.ndarray          # (n, m) ŷ
    Yr: np.ndarray          # (n, m) Uᵀŷ
    ph: np.ndarray          # (n,) η̂ or λ̂
    mu: np.ndarray          # (n,) penalty μ
    u: np.ndarray           # (n, d) ADMM iterates u, v and scaled duals p, q
    v: np.ndarray           # (n, m)   (v, q in rotated coordinates)
    p: np.ndarray           # (n, d)
    q: np.ndarray           # (n, m)
    a: np.ndarray           # (n, d) u − p
    b: np.ndarray           # (n, m) v − q
    prev_signs: np.ndarray  # (n, d) int8 sign pattern of u at the previous check
    fails: np.ndarray       # (n,) failed polish attempts (back off 2^fails checks)
    next_try: np.ndarray    # (n,) check at which the polish is tried again

    @property
    def size(self) -> int:
        return int(self.ids.size)

    def compact(self, keep) -> None:
        """Keep the rows ``keep`` (mask or index) of every per-column array."""
        for f in fields(self):
            setattr(self, f.name, getattr(self, f.name)[keep])


def _start(Y, param, form, spec: _Spectrum, active, ynorm, mu0):
    """The normalized problem of the ``active`` columns: ``Â = A/‖A‖`` (times ``ω``),
    ``ŷ = y/‖y‖``, ``η̂ = η/‖y‖``, ``λ̂ = λω/(‖A‖‖y‖)``; solutions ``z = ẑ ‖y‖ω/‖A‖``."""
    An = spec.An
    m, d = An.shape
    yn = ynorm[active]
    Yh = np.ascontiguousarray((Y[:, active] / yn).T)  # (na, m)
    ph = param[active] / yn if form == "bpdn" else param[active] * _OMEGA / (spec.scale * yn)
    AtA = An.T @ An
    sig2, U = np.linalg.eigh(An @ An.T)
    Dg = 1.0 / (1.0 + np.maximum(sig2, 0.0))
    B = np.ascontiguousarray(U.T @ An)
    system = _System(An=An, AtA=AtA, U=U, Dg=Dg, B=B, BT=np.ascontiguousarray(B.T))
    Yr = np.ascontiguousarray(Yh @ U)     # rotated right-hand sides (rows)
    na = active.size
    if mu0 is None:
        mu = _OMEGA**2 / (_KAPPA * np.max(np.abs(Yh @ An), axis=1))   # ‖Âᵀŷ‖∞
    else:
        mu = np.full(na, float(mu0))
    batch = _Batch(
        ids=active.copy(), back=yn * _OMEGA / spec.scale, Yh=Yh, Yr=Yr, ph=ph, mu=mu,
        u=np.zeros((na, d)), v=np.zeros((na, m)), p=np.zeros((na, d)), q=np.zeros((na, m)),
        a=np.zeros((na, d)), b=np.zeros((na, m)), prev_signs=np.zeros((na, d), dtype=np.int8),
        fails=np.zeros(na, dtype=np.int64), next_try=np.zeros(na, dtype=np.int64),
    )
    return system, batch


# ---------------------------------------------------------------------------------------------
# phase 3: the sweep (iterations, checks, polish, balancing, retirement)


#: Rows per chunk of the ADMM iterations: every chunk runs ``check_every`` iterations with its
#: arrays in cache (a whole batch of 10⁴ rows streams ≈ 80 MB per iteration through memory),
#: and the threads of :func:`kinred.dynamics.set_num_threads` (one inside ensemble members)
#: take the chunks, BLAS one thread each; the numba step releases the GIL.
_CHUNK_ROWS = 128


def _run_chunks(run, nrow: int) -> None:
    """Call ``run(slice)`` on row chunks of ``[0, nrow)``, dealt round-robin to the threads
    (rows are independent problems: the results do not depend on the split or the number of
    threads, bit for bit, as a test checks)."""
    nchunks = -(-nrow // _CHUNK_ROWS)
    nthreads = min(get_num_threads(), nchunks)
    bounds = [nrow * i // nchunks for i in range(nchunks + 1)]
    slices = [slice(bounds[i], bounds[i + 1]) for i in range(nchunks)]
    if nthreads <= 1:
        for sl in slices:
            run(sl)
        return

    run_parallel(lambda g, part: [run(sl) for sl in part],
                 [slices[g::nthreads] for g in range(nthreads)])


def _rownorm(x, y=None):
    """Euclidean norms of the rows of ``x`` (of ``[x, y]`` if ``y`` is given)."""
    s = np.einsum("ij,ij->i", x, x)
    return np.sqrt(s if y is None else s + np.einsum("ij,ij->i", y, y))


def _iterate_rows(system: _System, batch: _Batch, sl, steps, thr, norms, relax, lasso_form,
                  nonneg):
    """``steps`` ADMM iterations on the rows ``sl`` (independent problems, in cache), then
    their residual norms into ``norms[:, sl]``: primal residual, ``‖Δu + ΔvB‖`` (dual
    residual / μ), ``‖(z, Âz)‖``, ``‖(u, v)‖``, ``‖p + qB‖`` (Boyd et al. 2011, §3.3;
    rotation-invariant)."""
    B, BT, Dg = system.B, system.BT, system.Dg
    m, d = system.shape
    nr = sl.stop - sl.start
    a_, b_, u_, v_ = batch.a[sl], batch.b[sl], batch.u[sl], batch.v[sl]
    p_, q_ = batch.p[sl], batch.q[sl]
    z_, w_, Az_ = np.empty((nr, d)), np.empty((nr, m)), np.empty((nr, m))
    for j in range(steps):
        np.matmul(a_, BT, out=w_)
        np.subtract(b_, w_, out=w_)
        w_ *= Dg                     # w̃ = (b̃ − B a)/(1 + σ²)
        np.matmul(w_, B, out=z_)
        z_ += a_                     # z = a + Bᵀw̃
        np.subtract(b_, w_, out=Az_)  # Uᵀ Â z
        if j == steps - 1:
            u_old, v_old = u_.copy(), v_.copy()
        admm_step(z_, Az_, u_, v_, p_, q_, a_, b_, thr[sl], batch.Yr[sl], batch.ph[sl],
                  relax, lasso_form, nonneg)
    nb = norms[:, sl]
    nb[2] = _rownorm(z_, Az_)
    z_ -= u_
    Az_ -= v_
    nb[0] = _rownorm(z_, Az_)
    nb[3] = _rownorm(u_, v_)
    np.subtract(v_, v_old, out=v_old)
    np.matmul(v_old, B, out=z_)      # Δv B
    z_ += u_
    z_ -= u_old                       # Δu + Δv B
    nb[1] = _rownorm(z_)
    np.matmul(q_, B, out=z_)
    z_ += p_
    nb[4] = _rownorm(z_)


class _Check(NamedTuple):
    """Residuals of one check, per row of the batch."""

    r: np.ndarray        # primal residual
    ds: np.ndarray       # dual residual
    eps_p: np.ndarray    # primal tolerance
    eps_d: np.ndarray    # dual tolerance
    conv: np.ndarray     # both below their tolerance


def _iterate(system: _System, batch: _Batch, steps: int, form: str, opts: _Options) -> _Check:
    """``steps`` iterations on every row of the batch (chunks in threads); the residuals."""
    m, d = system.shape
    thr = 1.0 / batch.mu
    norms = np.empty((5, batch.size))
    _run_chunks(lambda sl: _iterate_rows(system, batch, sl, steps, thr, norms, opts.relax,
                                         form == "lasso", opts.nonneg), batch.size)
    tol = opts.tol
    r, ds, nBz, nx = norms[0], batch.mu * norms[1], norms[2], norms[3]
    eps_p = tol * (np.sqrt(d + m) * 1e-2 + np.maximum(nBz, nx))
    eps_d = tol * (np.sqrt(d) * 1e-2 + batch.mu * norms[4])
    return _Check(r, ds, eps_p, eps_d, (r <= eps_p) & (ds <= eps_d))


class _Accepted(NamedTuple):
    """What a check accepts, per row of the batch."""

    z: np.ndarray          # the point to return if the row finishes now
    certified: np.ndarray  # polished and certified
    gap: np.ndarray        # certified relative duality gap (NaN where not polished)

    @classmethod
    def admm(cls, batch: _Batch) -> "_Accepted":
        """The ADMM iterates ``u``, nothing certified."""
        return cls(batch.u.copy(), np.zeros(batch.size, dtype=bool), np.full(batch.size, np.nan))


def _polish_stable(system: _System, batch: _Batch, signs, conv, n_check, form, opts) -> _Accepted:
    """Polish the rows whose sign pattern has not changed since the previous check (and is
    not backed off after failed attempts), and the converged rows.

    A failed attempt backs the row off ``2^fails`` checks (at most 64). A converged row that
    is not certified keeps the polished point if it is feasible and (BPDN) its ℓ1 norm
    exceeds ADMM's by at most the factor ``1 + 10·tol`` (``u`` is feasible only to the
    tolerance).
    """
    acc = _Accepted.admm(batch)
    stable = (np.all(signs == batch.prev_signs, axis=1) & (batch.next_try <= n_check)) | conv
    cand = np.flatnonzero(stable & np.any(signs != 0, axis=1))
    if not cand.size:
        return acc
    nu0 = None
    if form == "bpdn" and not np.all(batch.ph[cand] > 0):      # basis-pursuit rows: ADMM's dual
        nu0 = -batch.mu[cand, None] * (batch.q[cand] @ system.U.T)
    pol = polish_with_repair(system.An, system.AtA, batch.Yh[cand], signs[cand], form,
                             batch.ph[cand], nu0, opts.nonneg, opts.cert_tol, conv[cand])
    acc.certified[cand] = pol.ok
    bad = cand[~pol.ok]
    batch.fails[bad] += 1
    batch.next_try[bad] = n_check + 2 ** np.minimum(batch.fails[bad], 6)
    acc.gap[cand] = pol.gap
    acc.z[cand[pol.ok]] = pol.z[pol.ok]
    keep = np.flatnonzero(conv[cand] & ~pol.ok & pol.feasible)
    if keep.size and form == "bpdn":
        kk = cand[keep]
        better = (np.sum(np.abs(pol.z[keep]), axis=1)
                  <= (1.0 + 10.0 * opts.tol) * np.sum(np.abs(batch.u[kk]), axis=1))
        acc.z[kk[better]] = pol.z[keep[better]]
    return acc


def _balance(batch: _Batch, chk: _Check) -> None:
    """Residual balancing (Wohlberg 2017): ``μ`` doubled (halved) where the relative primal
    residual exceeds the relative dual one tenfold (or vice versa); the scaled duals follow."""
    ratio = (chk.r / chk.eps_p) / np.maximum(chk.ds / chk.eps_d, 1e-300)
    fac = np.ones(batch.size)
    fac[ratio > 10.0] = 2.0
    fac[ratio < 0.1] = 0.5
    if np.any(fac != 1.0):
        batch.mu = batch.mu * fac
        batch.p /= fac[:, None]
        batch.q /= fac[:, None]
        batch.a = batch.u - batch.p
        batch.b = batch.v - batch.q


def _retire(out: _Columns, batch: _Batch, fin, acc: _Accepted, chk: _Check, it_done, tol) -> None:
    """Write the rows ``fin`` into the results (original scaling) and drop them."""
    cols = batch.ids[fin]
    out.Z[:, cols] = (acc.z[fin] * batch.back[fin][:, None]).T
    out.status[cols] = np.where(acc.certified[fin], "optimal",
                                np.where(chk.conv[fin], "converged", "max_iter"))
    out.iterations[cols] = it_done
    out.gap[cols] = np.where(acc.certified[fin], acc.gap[fin], np.nan)
    out.primal[cols] = chk.r[fin] / np.maximum(chk.eps_p[fin] / tol, 1e-300)
    out.dual[cols] = chk.ds[fin] / np.maximum(chk.eps_d[fin] / tol, 1e-300)
    batch.compact(~fin)


def _sweep(system: _System, batch: _Batch, out: _Columns, form: str, opts: _Options) -> None:
    """Iterate until every row is certified, converged or at ``max_iter``: every
    ``check_every`` iterations check the residuals, polish, balance ``μ`` (``adaptive``, during
    the first ``max(20·check_every, 300)`` iterations) and retire the finished rows."""
    adapt_until = max(20 * opts.check_every, 300) if opts.adaptive else 0
    n_check = 0
    it_done = 0
    while batch.size and it_done < opts.max_iter:
        steps = min(opts.check_every, opts.max_iter - it_done)
        chk = _iterate(system, batch, steps, form, opts)
        it_done += steps
        signs = np.sign(batch.u).astype(np.int8)
        if opts.polish:
            acc = _polish_stable(system, batch, signs, chk.conv, n_check, form, opts)
        else:
            acc = _Accepted.admm(batch)
        done = chk.conv | acc.certified
        batch.prev_signs = signs
        n_check += 1
        if it_done <= adapt_until:
            _balance(batch, chk)
        if np.any(done) or it_done >= opts.max_iter:
            _retire(out, batch, done | (it_done >= opts.max_iter), acc, chk, it_done, opts.tol)


# ---------------------------------------------------------------------------------------------
# the solver: setup, trivial columns, sweep, finalize


def _exponent(X) -> int:
    """``e`` with ``max |X| · 2^−e`` in ``[1/2, 1)`` (0 for ``X = 0``)."""
    top = float(np.max(np.abs(X), initial=0.0))
    return int(np.frexp(top)[1]) if top > 0 else 0


def _finalize(A, Y, param, form, opts: _Options, out: _Columns, infeasible, t0,
              scaling) -> RecoveryResult:
    """Residuals and objectives of the scaled problem, then everything in the original
    scaling ``(ea, ey, param)``: ``Z·2^(ey−ea)``, residuals ``·2^ey``, objectives
    ``·2^(ey−ea)`` (BPDN) or ``·2^(2ey)`` (LASSO)."""
    ea, ey, param0 = scaling
    R = A @ np.where(np.isfinite(out.Z), out.Z, 0.0) - Y
    residual = np.linalg.norm(R, axis=0)
    residual[infeasible] = np.nan
    l1 = np.sum(np.abs(out.Z), axis=0)
    with np.errstate(over="ignore"):
        if form == "lasso":
            objective = np.ldexp(0.5 * residual**2 + param * l1, 2 * ey)
        else:
            objective = np.ldexp(np.where(~infeasible, l1, np.nan), ey - ea)
        Z = np.ldexp(out.Z, ey - ea)
    if np.any(np.isinf(Z)):
        raise InvalidInput(f"A (entries up to 2^{ea}) and Y (up to 2^{ey}) have a solution "
                           "beyond the float64 range: rescale A or Y (z scales as Y/A)")
    return RecoveryResult(
        Z=Z,
        status=out.status,
        iterations=out.iterations,
        residual=np.ldexp(residual, ey),
        objective=objective,
        param=param0,
        gap=out.gap,
        primal_residual=out.primal,
        dual_residual=out.dual,
        form=form,
        nonneg=opts.nonneg,
        tol=float(opts.tol),
        seconds=time.perf_counter() - t0,
    )


def _solve(A, Y, param, form: str, opts: _Options) -> RecoveryResult:
    """Solve all columns of ``Y`` (validated inputs; ``form`` ``"bpdn"`` or ``"lasso"``)."""
    t0 = time.perf_counter()
    m, d = A.shape
    # the problem is homogeneous: solve it for A, Y scaled by powers of two (exact) to
    # entries below 1, so that A Aᵀ, norms and residuals neither overflow nor underflow
    ea, ey, param0 = _exponent(A), _exponent(Y), param
    A, Y = np.ldexp(A, -ea), np.ldexp(Y, -ey)
    param = np.ldexp(param, -ey if form == "bpdn" else -ea - ey)
    out = _Columns(d, Y.shape[1])
    spec = _spectrum(A)
    ynorm = np.linalg.norm(Y, axis=0)
    zero, infeasible = _trivial_columns(A, Y, param, form, spec, ynorm)
    out.mark_trivial(zero, infeasible)
    active = np.flatnonzero(~zero & ~infeasible)
    if active.size:
        system, batch = _start(Y, param, form, spec, active, ynorm, opts.mu0)
        _sweep(system, batch, out, form, opts)
    return _finalize(A, Y, param, form, opts, out, infeasible, t0, (ea, ey, param0))


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
