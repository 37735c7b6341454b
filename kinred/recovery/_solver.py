"""Batched ℓ1 recovery: basis pursuit, basis-pursuit denoising and LASSO for many right-hand sides.

The solver is ADMM in the C-SALSA splitting (Afonso, Bioucas-Dias, Figueiredo 2011) applied
column by column to

.. math::

    \\min_{z\\in\\mathbb R^d} \\|z\\|_{\\ell_1^d}
    \\quad\\text{s.t.}\\quad \\|Az - y\\|_{\\ell_2^m} \\le \\eta ,

problem (3.16) of the paper (label ``P1:eta``), for all columns ``y`` of ``Y (m, n_rhs)`` at
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
the engine's threads (:func:`kinred.dynamics.set_num_threads`). The penalty ``μ`` enters
only as the threshold of the ``u``-prox (``(I + AᵀA)⁻¹`` does not depend on it), so each
column has its own ``μ``, adapted by residual balancing without any re-factorization.

Per-column scaling: ``A`` is divided by its spectral norm and every column ``y`` by its norm
(``η`` and ``λ`` accordingly), so one starting penalty suits all columns. Converged columns are
dropped from the batch at every check (every ``check_every`` iterations).

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
``{ν : A_Sᵀν = s}``, accepted when ``‖Aᵀν‖∞ ≤ 1 + cert_tol``. A certificate bounds the relative
duality gap by ``cert_tol``; the polished solution is exact up to round-off.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .._parallel import get_num_threads, run_parallel
from .._validate import as_array, as_float, as_int
from ..errors import InvalidInput
from ..projection import Projection, as_projection
from ._kernels import admm_step, support_solve

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
        One matrix, or the ``L`` projections of the parallel simulations (3.17) of the paper
        (label ``eq:paral1``). All must share the source dimension ``d``.

    Returns
    -------
    (Σ k_ℓ, d) ndarray
        The stacked matrix 𝓜 of §3.3.1.

    Examples
    --------
    >>> stack_projections([np.eye(2, 3), np.ones((1, 3))]).shape
    (3, 3)
    """
    if isinstance(projections, Projection):
        return np.asarray(projections.to_dense(), dtype=float)
    if isinstance(projections, np.ndarray) and projections.ndim == 2:
        return as_array(projections, "A", ndim=2)
    if isinstance(projections, (list, tuple)):
        if len(projections) == 0:
            raise InvalidInput("projections must hold at least one projection, got an empty sequence")
        mats = []
        for i, P in enumerate(projections):
            if not isinstance(P, Projection):
                P = as_array(P, f"projections[{i}]", ndim=2)
            M = np.asarray(as_projection(P).to_dense(), dtype=float)
            if not np.all(np.isfinite(M)):
                raise InvalidInput(f"projections[{i}] must be finite")
            mats.append(M)
        d0 = mats[0].shape[1]
        for i, M in enumerate(mats):
            if M.shape[1] != d0:
                raise InvalidInput(
                    f"all projections must have the same source dimension d; projections[0] has "
                    f"d = {d0} but projections[{i}] has shape {M.shape}"
                )
        return np.vstack(mats)
    A = as_array(projections, "A", ndim=2)
    return A


def _check_A(A) -> np.ndarray:
    A = stack_projections(A)
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
    if np.ndim(value) == 0:
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
# the certified polish


def _polish(An, AtA, Yh, signs, form, param, nu0, nonneg, cert_tol, feas_tol):
    """Exact KKT point on the support given by ``signs`` and its dual certificate.

    Parameters (normalized problem, rows = problems)
    ----------
    An : (m, d) normalized matrix; AtA : (d, d) its Gram matrix ``ÂᵀÂ``.
    Yh : (n, m); signs : (n, d) int8 in {-1, 0, 1}; param : (n,) η or λ;
    nu0 : (n, m) approximate dual vector (basis pursuit only) or None.

    Returns
    -------
    z : (n, d) polished points (zeros where the polish was impossible),
    ok : (n,) certified, feasible : (n,) polished point feasible with the right signs,
    gap : (n,) relative duality gap of the certificate,
    dual : (n, d) where the polished point is feasible, the candidate certificate ``Âᵀν``;
    where it is not (the least-squares residual ``r₀`` on ``S`` exceeds ``η``), ``Âᵀr₀``
    scaled so that its largest entry off ``S`` is 1 (zeros where the polish was impossible).
    """
    n, d = signs.shape
    m = An.shape[0]
    z = np.zeros((n, d))
    ok = np.zeros(n, dtype=bool)
    feas = np.zeros(n, dtype=bool)
    gap = np.full(n, np.nan)
    dual = np.zeros((n, d))
    if n == 0:
        return z, ok, feas, gap, dual
    counts = np.count_nonzero(signs, axis=1)
    usable = np.flatnonzero((counts > 0) & (counts <= m))
    if usable.size == 0:
        return z, ok, feas, gap, dual
    rows_all = usable[np.argsort(counts[usable], kind="stable")]  # similar sizes together
    bp = form == "bpdn" and nu0 is not None
    chunk = 512
    for start in range(0, rows_all.size, chunk):
        rows = rows_all[start : start + chunk]
        sg = signs[rows]
        cnt = counts[rows]
        nb = rows.size
        kmax = int(cnt.max())
        idx = np.argsort(sg == 0, axis=1, kind="stable")[:, :kmax]  # support first
        mask = np.arange(kmax)[None, :] < cnt[:, None]
        s = np.take_along_axis(sg, idx, axis=1).astype(float) * mask
        y = Yh[rows]
        rhs = [np.take_along_axis(y @ An, idx, axis=1) * mask, s]
        if bp:
            nu = nu0[rows]
            rhs.append(np.take_along_axis(nu @ An, idx, axis=1) * mask)
        rhs = np.stack(rhs, axis=2)
        sol, solved = support_solve(AtA, idx, cnt, rhs)
        for t in np.flatnonzero(~solved):  # numerically singular Gram matrix: least squares
            sup = idx[t, : cnt[t]]
            sol[t, : cnt[t]] = np.linalg.lstsq(AtA[np.ix_(sup, sup)], rhs[t, : cnt[t]], rcond=None)[0]

        def full(x):
            out = np.zeros((nb, d))
            np.put_along_axis(out, idx, x, axis=1)
            return out

        g1, g2 = full(sol[:, :, 0]), full(sol[:, :, 1])
        r0 = y - g1 @ An.T
        w = g2 @ An.T
        p = param[rows]
        r0n = np.linalg.norm(r0, axis=1)
        if form == "lasso":
            lam = p
            good = np.ones(nb, dtype=bool)
        elif bp:  # basis pursuit: the polished point must interpolate
            lam = np.zeros(nb)
            good = r0n <= feas_tol
        else:
            wn = np.linalg.norm(w, axis=1)
            good = (r0n <= p) & (wn > 0)
            lam = np.sqrt(np.maximum(p * p - r0n * r0n, 0.0)) / np.where(wn > 0, wn, 1.0)
        zS = g1 - lam[:, None] * g2
        r = r0 + lam[:, None] * w
        sign_ok = np.all((np.take_along_axis(zS, idx, axis=1) * s > 0) | ~mask, axis=1)
        if bp:
            nu = nu + (g2 - full(sol[:, :, 2])) @ An.T
        else:
            nu = r / np.where(lam > 0, lam, 1.0)[:, None]
        c = nu @ An  # (nb, d) = (Âᵀν)ᵀ
        viol = (np.max(c, axis=1) if nonneg else np.max(np.abs(c), axis=1)) - 1.0
        if bp:
            # second candidate: the minimum-norm ν with Â_Sᵀν = s, i.e. w = Â_S(Â_SᵀÂ_S)⁻¹s
            # (the classical certificate of exact recovery); keep the less violated one
            c2 = w @ An
            viol2 = (np.max(c2, axis=1) if nonneg else np.max(np.abs(c2), axis=1)) - 1.0
            pick = viol2 < viol
            nu[pick], c[pick], viol[pick] = w[pick], c2[pick], viol2[pick]
        l1 = np.sum(np.abs(zS), axis=1)
        # relative duality gap of the dual-feasible point ν / max(1, ‖Âᵀν‖∞)
        sc = np.maximum(1.0, viol + 1.0)
        if form == "lasso":
            primal = 0.5 * np.sum(r * r, axis=1) + lam * l1
            tl = lam[:, None] * nu / sc[:, None]
            dual_obj = np.sum(tl * y, axis=1) - 0.5 * np.sum(tl * tl, axis=1)
        else:
            primal = l1
            dual_obj = (np.sum(nu * y, axis=1) - p * np.linalg.norm(nu, axis=1)) / sc
        g = np.maximum(primal - dual_obj, 0.0) / np.maximum(np.abs(primal), 1e-300)
        cert = good & sign_ok & (viol <= cert_tol) & (g <= 10 * cert_tol + 1e-12)
        z[rows] = zS
        ok[rows] = cert
        feas[rows] = good & sign_ok
        gap[rows] = g
        # where the least-squares point on S does not reach the constraint (r₀ too large),
        # the residual's correlations Âᵀr₀ point to the missing columns; else the certificate
        miss = ~good
        if np.any(miss):
            corr = r0[miss] @ An
            off = np.where(sg[miss] == 0, corr if nonneg else np.abs(corr), 0.0)
            c[miss] = corr / np.maximum(np.max(off, axis=1), 1e-300)[:, None]
        dual[rows] = c
    return z, ok, feas, gap, dual


# ---------------------------------------------------------------------------------------------
# the solver


def _solve(A, Y, param, form, *, weight=10.0, adaptive=False, kappa=0.1, nonneg, tol, max_iter, polish, relax, check_every, cert_tol, mu0):
    t0 = time.perf_counter()
    m, d = A.shape
    n = Y.shape[1]
    Z = np.zeros((d, n))
    status = np.full(n, "max_iter", dtype="<U10")
    iters = np.zeros(n, dtype=np.int64)
    gap = np.full(n, np.nan)
    pres = np.full(n, np.nan)
    dres = np.full(n, np.nan)

    # spectral data from the m×m Gram matrix (cheaper than an SVD of A when m ≤ d)
    if m <= d:
        ev, U = np.linalg.eigh(A @ A.T)
        ev, U = ev[::-1], U[:, ::-1]
        sv = np.sqrt(np.maximum(ev, 0.0))
    else:
        U, sv, _ = np.linalg.svd(A, full_matrices=False)
    scale = float(sv[0]) if sv.size else 0.0
    ynorm = np.linalg.norm(Y, axis=0)
    if scale == 0.0:
        An = A
        rank = 0
    else:
        An = A * (weight / scale)
        # eigenvalues of AAᵀ carry round-off of size eps·‖A‖², i.e. singular values ~sqrt(eps)
        rank = int(np.sum(sv > scale * max(m, d) * np.sqrt(np.finfo(float).eps)))

    # trivial columns ---------------------------------------------------------------------
    if form == "bpdn":
        zero = ynorm <= param
        Ur = U[:, :rank]
        ls_res = np.linalg.norm(Y - Ur @ (Ur.T @ Y), axis=0)
        infeasible = (~zero) & (ls_res > param + 1e-10 * ynorm)
    else:
        zero = np.max(np.abs(A.T @ Y), axis=0, initial=0.0) <= param
        infeasible = np.zeros(n, dtype=bool)
    status[zero] = "zero"
    gap[zero] = 0.0
    status[infeasible] = "infeasible"
    Z[:, infeasible] = np.nan
    active = np.flatnonzero(~zero & ~infeasible)

    if active.size:
        # normalized problem: Â = A/‖A‖, ŷ = y/‖y‖, η̂ = η/‖y‖, λ̂ = λ/(‖A‖‖y‖); z = ẑ ‖y‖/‖A‖
        yn = ynorm[active]
        Yh = np.ascontiguousarray((Y[:, active] / yn).T)  # (na, m)
        # the weight ω (‖Â‖ = ω) balances the two ADMM constraints u = z and v = Âz
        ph = param[active] / yn if form == "bpdn" else param[active] * weight / (scale * yn)
        AtA = An.T @ An  # (d, d), for the polish
        # rotated m-space: ÂÂᵀ = U diag(σ²) Uᵀ. With B = UᵀÂ and b̃ = Uᵀb the z-update is
        # w̃ = (b̃ − B a)/(1 + σ²), z = a + Bᵀw̃, Uᵀ(Âz) = b̃ − w̃: two (m, d) products and no
        # m×m one; the v-step (a ball around ŷ, or the LASSO average) commutes with U.
        sig2, U = np.linalg.eigh(An @ An.T)
        Dg = 1.0 / (1.0 + np.maximum(sig2, 0.0))
        B = np.ascontiguousarray(U.T @ An)    # (m, d)
        BT = np.ascontiguousarray(B.T)        # (d, m)
        Yr = np.ascontiguousarray(Yh @ U)     # rotated right-hand sides (rows)
        na = active.size
        ids = active.copy()
        u = np.zeros((na, d))
        v = np.zeros((na, m))
        p = np.zeros((na, d))
        q = np.zeros((na, m))
        a = np.zeros((na, d))  # u − p
        b = np.zeros((na, m))  # v − q
        c0 = np.max(np.abs(Yh @ An), axis=1)  # ‖Âᵀŷ‖∞
        if mu0 is None:
            mu = weight**2 / (kappa * c0)
        else:
            mu = np.full(na, float(mu0))
        prev_signs = np.zeros((na, d), dtype=np.int8)
        fails = np.zeros(na, dtype=np.int64)  # failed polish attempts: back off 2^fails checks
        next_try = np.zeros(na, dtype=np.int64)
        n_check = 0
        adapt_until = max(20 * check_every, 300) if adaptive else 0
        sq_dm = np.sqrt(d + m)
        lasso_form = form == "lasso"
        it_done = 0
        while ids.size and it_done < max_iter:
            steps = min(check_every, max_iter - it_done)
            thr = 1.0 / mu
            nrow = ids.size
            # per row: primal residual, ‖Δu + ΔvB‖ (dual residual / μ), ‖(z, Âz)‖, ‖(u, v)‖,
            # ‖p + qB‖ – computed by each chunk while its arrays are in cache
            norms = np.empty((5, nrow))

            def run(sl, steps=steps, thr=thr):
                # `steps` iterations on the rows `sl` (independent problems), in cache
                nr = sl.stop - sl.start
                a_, b_, u_, v_, p_, q_ = a[sl], b[sl], u[sl], v[sl], p[sl], q[sl]
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
                    admm_step(z_, Az_, u_, v_, p_, q_, a_, b_, thr[sl], Yr[sl], ph[sl],
                              relax, lasso_form, nonneg)
                # residuals (Boyd et al. 2011, §3.3), rotation-invariant norms
                nb = norms[:, sl]
                nb[2] = np.sqrt(np.einsum("ij,ij->i", z_, z_) + np.einsum("ij,ij->i", Az_, Az_))
                z_ -= u_
                Az_ -= v_
                nb[0] = np.sqrt(np.einsum("ij,ij->i", z_, z_) + np.einsum("ij,ij->i", Az_, Az_))
                nb[3] = np.sqrt(np.einsum("ij,ij->i", u_, u_) + np.einsum("ij,ij->i", v_, v_))
                np.subtract(v_, v_old, out=v_old)
                np.matmul(v_old, B, out=z_)      # Δv B
                z_ += u_
                z_ -= u_old                       # Δu + Δv B
                nb[1] = np.sqrt(np.einsum("ij,ij->i", z_, z_))
                np.matmul(q_, B, out=z_)
                z_ += p_
                nb[4] = np.sqrt(np.einsum("ij,ij->i", z_, z_))

            _run_chunks(run, nrow)
            it_done += steps
            r, ds, nBz, nx = norms[0], mu * norms[1], norms[2], norms[3]
            eps_p = tol * (sq_dm * 1e-2 + np.maximum(nBz, nx))
            eps_d = tol * (np.sqrt(d) * 1e-2 + mu * norms[4])
            conv = (r <= eps_p) & (ds <= eps_d)
            done = conv.copy()
            final_z = u.copy()
            cert_ok = np.zeros(ids.size, dtype=bool)
            gp = np.full(ids.size, np.nan)
            signs = np.sign(u).astype(np.int8)
            if polish:
                stable = (np.all(signs == prev_signs, axis=1) & (next_try <= n_check)) | conv
                cand = np.flatnonzero(stable & np.any(signs != 0, axis=1))
                if cand.size:
                    nu0 = -mu[cand, None] * (q[cand] @ U.T) if (form == "bpdn") else None
                    if form == "bpdn" and np.all(ph[cand] > 0):
                        nu0 = None
                    zc, okc, feasc, gc = _polish_split(
                        An, AtA, Yh[cand], signs[cand], form, ph[cand], nu0, nonneg, cert_tol,
                        conv[cand],
                    )
                    cert_ok[cand] = okc
                    bad = cand[~okc]
                    fails[bad] += 1
                    next_try[bad] = n_check + 2 ** np.minimum(fails[bad], 6)
                    gp[cand] = gc
                    final_z[cand[okc]] = zc[okc]
                    # converged but not certified: keep the polished point if feasible, no worse
                    keep = np.flatnonzero(conv[cand] & ~okc & feasc)
                    if keep.size and form == "bpdn":
                        kk = cand[keep]
                        # u is feasible only to the tolerance: allow its ℓ1 to be lower by as much
                        better = (np.sum(np.abs(zc[keep]), axis=1)
                                  <= (1.0 + 10.0 * tol) * np.sum(np.abs(u[kk]), axis=1))
                        final_z[kk[better]] = zc[keep[better]]
                done |= cert_ok
            prev_signs = signs
            n_check += 1
            # residual balancing (Wohlberg 2017): only early, so that ADMM still converges
            if it_done <= adapt_until:
                ratio = (r / eps_p) / np.maximum(ds / eps_d, 1e-300)
                fac = np.ones(ids.size)
                fac[ratio > 10.0] = 2.0
                fac[ratio < 0.1] = 0.5
                if np.any(fac != 1.0):
                    mu = mu * fac
                    p /= fac[:, None]
                    q /= fac[:, None]
                    a = u - p
                    b = v - q
            if np.any(done) or it_done >= max_iter:
                fin = done | (it_done >= max_iter)
                cols = ids[fin]
                Z[:, cols] = (final_z[fin] * (yn[np.searchsorted(active, cols)] * weight / scale)[:, None]).T
                status[cols] = np.where(cert_ok[fin], "optimal", np.where(conv[fin], "converged", "max_iter"))
                iters[cols] = it_done
                gap[cols] = np.where(cert_ok[fin], gp[fin], np.nan)
                pres[cols] = r[fin] / np.maximum(eps_p[fin] / tol, 1e-300)
                dres[cols] = ds[fin] / np.maximum(eps_d[fin] / tol, 1e-300)
                keep = ~fin
                ids = ids[keep]
                u, v, p, q, mu = u[keep], v[keep], p[keep], q[keep], mu[keep]
                a, b = a[keep], b[keep]
                Yh, Yr, ph, prev_signs = Yh[keep], Yr[keep], ph[keep], prev_signs[keep]
                fails, next_try = fails[keep], next_try[keep]

    # final quantities in the original scaling ---------------------------------------------
    fin = ~infeasible
    R = A @ np.where(np.isfinite(Z), Z, 0.0) - Y
    residual = np.linalg.norm(R, axis=0)
    residual[infeasible] = np.nan
    l1 = np.sum(np.abs(Z), axis=0)
    if form == "lasso":
        objective = 0.5 * residual**2 + param * l1
    else:
        objective = np.where(fin, l1, np.nan)
    return RecoveryResult(
        Z=Z,
        status=status,
        iterations=iters,
        residual=residual,
        objective=objective,
        param=param,
        gap=gap,
        primal_residual=pres,
        dual_residual=dres,
        form=form,
        nonneg=bool(nonneg),
        tol=float(tol),
        seconds=time.perf_counter() - t0,
    )


#: Expansion threshold of the polish repair (see :func:`_polish_split`).
_GROW_DELTA = 0.05


#: Rows per chunk of the ADMM iterations: every chunk runs ``check_every`` iterations with its
#: arrays in cache (a whole batch of 10⁴ rows streams ≈ 80 MB per iteration through memory),
#: and the engine's threads (:func:`kinred.dynamics.set_num_threads`, one inside ensemble
#: members) take the chunks, BLAS one thread each; the numba step releases the GIL.
_CHUNK_ROWS = 128


def _run_chunks(run, nrow: int) -> None:
    """Call ``run(slice)`` on row chunks of ``[0, nrow)``, dealt round-robin to the engine's
    threads (rows are independent problems: the results do not depend on the split or the
    number of threads, bit for bit, as a test checks)."""
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


def _polish_split(An, AtA, Yh, signs, form, ph, nu0, nonneg, cert_tol, expand=None):
    """Polish columns on the ADMM support, repairing it where the certificate fails.

    Two repairs, each followed by a new polish of the columns it changes:

    1. *expansion*: indices outside the support whose lead (see :func:`_polish`) satisfies
       ``|lead_j| ≥ 1 − δ`` (``δ = 0.05``, at most 8, the largest) join it with the sign of
       ``lead_j``. For a feasible polish the lead is the candidate certificate ``Âᵀν`` (the KKT
       conditions put every support index at ``|(Âᵀν)_j| = 1``); for an infeasible one it is
       the correlation ``Âᵀr₀`` of the least-squares residual (an orthogonal-matching-pursuit
       step: with one coefficient ``x_j`` missing, ``r₀ = x_j P⊥a_j``). This recovers
       coefficients that ADMM's soft threshold has not yet released, e.g. a true entry of
       relative size 1e-5 (measured: 15 of the benchmark's 10⁴ problems; ADMM alone needs
       2000–4000 more iterations). An index added in error gets a polished coefficient of
       about zero and is removed by
    2. *pruning*: entries whose polished sign disagrees with the support's, or whose size is
       below ``1e-10`` of the largest, are removed.

    Each repair only proposes a support; acceptance is by the certificate as before. The
    expansion is tried only on the rows flagged by ``expand`` (default all; the solver flags
    the columns whose ADMM has converged: on the others ADMM is still moving its support).
    """
    m = An.shape[0]
    z, ok, feas, gap, dual = _polish_split1(An, AtA, Yh, signs, form, ph, nu0, nonneg, cert_tol)

    def attempt(rows, new_signs):
        """Polish ``rows`` on ``new_signs``; keep a result that is certified, or feasible
        where the current one is not. Returns the raw polished points."""
        res = _polish_split1(
            An, AtA, Yh[rows], new_signs, form, ph[rows],
            None if nu0 is None else nu0[rows], nonneg, cert_tol,
        )
        better = res[1] | (res[2] & ~feas[rows] & ~ok[rows])
        rr = rows[better]
        z[rr], ok[rr], feas[rr], gap[rr], dual[rr] = (x[better] for x in res)
        return res[0]

    # 1. expansion: off-support indices with |lead_j| ≥ 1 − δ, at most `top` (the largest)
    base_z, base_signs = z.copy(), signs.copy()      # what the pruning starts from
    off = np.where(signs == 0, dual if nonneg else np.abs(dual), -np.inf)
    top = min(8, off.shape[1] - 1)
    near = np.zeros(signs.shape, dtype=bool)
    if top > 0:
        part = np.argpartition(-off, top, axis=1)[:, :top]
        np.put_along_axis(near, part,
                          np.take_along_axis(off, part, axis=1) >= 1.0 - _GROW_DELTA, axis=1)
    if expand is not None:
        near &= np.asarray(expand, dtype=bool)[:, None]
    grow = np.flatnonzero(~ok & np.any(near, axis=1)
                          & (np.count_nonzero(signs, axis=1) + np.count_nonzero(near, axis=1) <= m))
    if grow.size:
        grown = np.where(near[grow], np.sign(dual[grow]).astype(np.int8), signs[grow])
        base_z[grow] = attempt(grow, grown)
        base_signs[grow] = grown
    # 2. pruning: entries whose polished sign disagrees, or that came out negligibly small
    big = np.abs(base_z) > 1e-10 * np.max(np.abs(base_z), axis=1, keepdims=True)
    pruned = np.where((np.sign(base_z).astype(np.int8) == base_signs) & big, base_signs, np.int8(0))
    retry = np.flatnonzero(~ok & np.any(pruned != base_signs, axis=1) & np.any(pruned != 0, axis=1))
    if retry.size:
        attempt(retry, pruned[retry])
    return z, ok, feas, gap


def _polish_split1(An, AtA, Yh, signs, form, ph, nu0, nonneg, cert_tol):
    """Polish columns, separating basis pursuit (η = 0) from BPDN (η > 0)."""
    feas_tol = 1e-9
    if form == "lasso" or nu0 is None:
        return _polish(An, AtA, Yh, signs, form, ph, None, nonneg, cert_tol, feas_tol)
    n, d = signs.shape
    z = np.zeros((n, d))
    ok = np.zeros(n, dtype=bool)
    feas = np.zeros(n, dtype=bool)
    gap = np.full(n, np.nan)
    dual = np.zeros((n, d))
    for sel, nu in ((ph == 0, nu0), (ph > 0, None)):
        rows = np.flatnonzero(sel)
        if rows.size:
            res = _polish(
                An, AtA, Yh[rows], signs[rows], form, ph[rows],
                None if nu is None else nu[rows], nonneg, cert_tol, feas_tol,
            )
            z[rows], ok[rows], feas[rows], gap[rows], dual[rows] = res
    return z, ok, feas, gap, dual


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
        Gaussian compressed-sensing problems the scale-invariant starting ``μ`` converges 2–4×
        faster than the balanced one (measured, see docs/recovery.md).
"""


def _check_opts(tol, max_iter, relax, check_every, cert_tol, mu0):
    tol = as_float(tol, "tol", low=0.0, low_open=True, high=1.0)
    max_iter = as_int(max_iter, "max_iter", low=1)
    relax = as_float(relax, "relax", low=0.0, low_open=True, high=2.0, high_open=True)
    check_every = as_int(check_every, "check_every", low=1)
    cert_tol = as_float(cert_tol, "cert_tol", low=0.0)
    if mu0 is not None:
        mu0 = as_float(mu0, "mu0", low=0.0, low_open=True)
    return tol, max_iter, relax, check_every, cert_tol, mu0


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

    Solves, for every column ``y`` of ``Y``, problem (3.16) of the paper (label ``P1:eta``)

    .. math::

        \\min_{z\\in\\mathbb R^d} \\|z\\|_{1} \\quad\\text{s.t.}\\quad \\|Az - y\\|_2 \\le \\eta

    with one shared matrix ``A`` (e.g. the stacked 𝓜 = [M¹; …; Mᴸ] of the ``L`` parallel
    projected simulations (3.17), label ``eq:paral1``), by batched ADMM with certified polish.

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

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> A = rng.standard_normal((40, 100)) / np.sqrt(40)
    >>> X = np.zeros((100, 5)); X[rng.integers(0, 100, 25), np.arange(25) %% 5] = 1.0
    >>> res = basis_pursuit(A, A @ X)
    >>> bool(np.allclose(res.Z, X, atol=1e-8)), res.counts()
    (True, {'optimal': 5})
    """
    A = _check_A(A)
    Y = _check_Y(Y, A.shape[0])
    eta = _check_param(eta, Y.shape[1], "eta")
    opts = _check_opts(tol, max_iter, relax, check_every, cert_tol, mu0)
    return _solve(
        A, Y, eta, "bpdn", nonneg=bool(nonneg), tol=opts[0], max_iter=opts[1], polish=bool(polish),
        relax=opts[2], check_every=opts[3], cert_tol=opts[4], mu0=opts[5], adaptive=bool(adaptive),
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

    The Lagrangian form of (3.16) (label ``P1:eta``): for each ``η`` there is a ``λ`` with the
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
    A = _check_A(A)
    Y = _check_Y(Y, A.shape[0])
    lam = _check_param(lam, Y.shape[1], "lam")
    opts = _check_opts(tol, max_iter, relax, check_every, cert_tol, mu0)
    return _solve(
        A, Y, lam, "lasso", nonneg=bool(nonneg), tol=opts[0], max_iter=opts[1], polish=bool(polish),
        relax=opts[2], check_every=opts[3], cert_tol=opts[4], mu0=opts[5], adaptive=bool(adaptive),
    )


basis_pursuit.__doc__ = basis_pursuit.__doc__ % _COMMON_DOC
lasso.__doc__ = lasso.__doc__ % _COMMON_DOC
