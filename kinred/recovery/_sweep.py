"""Phases 2 and 3 of the batched ℓ1 solver (:mod:`kinred.recovery._solver`): the normalized
problem of the columns that need iterating, and the sweep over them (ADMM iterations in
cache-sized chunks over the threads, residual checks, certified polish, residual balancing,
retirement of finished columns). The formulas are in the module docstring of ``_solver``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .._parallel import get_num_threads, run_parallel
from ._kernels import admm_step
from ._polish import polish_with_repair
from ._scaling import OMEGA, Scaling

if TYPE_CHECKING:   # the solver's option and result holders (no import cycle at run time)
    from ._solver import _Columns, _Options, _Spectrum

#: Starting penalty ``μ = ω²/(κ ‖Âᵀŷ‖∞)`` per column.
_KAPPA = 0.1


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


def _start(Y, param, scaling: Scaling, spec: _Spectrum, active, ynorm, mu0):
    """The normalized problem of the ``active`` columns (:class:`Scaling`, layer 2)."""
    An = spec.An
    m, d = An.shape
    yn = ynorm[active]
    Yh = np.ascontiguousarray((Y[:, active] / yn).T)  # (na, m)
    ph = scaling.normalized_param(param[active], yn, spec.scale)
    AtA = An.T @ An
    sig2, U = np.linalg.eigh(An @ An.T)
    Dg = 1.0 / (1.0 + np.maximum(sig2, 0.0))
    B = np.ascontiguousarray(U.T @ An)
    system = _System(An=An, AtA=AtA, U=U, Dg=Dg, B=B, BT=np.ascontiguousarray(B.T))
    Yr = np.ascontiguousarray(Yh @ U)     # rotated right-hand sides (rows)
    na = active.size
    if mu0 is None:
        mu = OMEGA**2 / (_KAPPA * np.max(np.abs(Yh @ An), axis=1))   # ‖Âᵀŷ‖∞
    else:
        mu = np.full(na, float(mu0))
    batch = _Batch(
        ids=active.copy(), back=Scaling.back(yn, spec.scale), Yh=Yh, Yr=Yr, ph=ph, mu=mu,
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
    out.Z[:, cols] = Scaling.from_normalized(acc.z[fin], batch.back[fin])
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
