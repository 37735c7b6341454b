"""Certified polish of the batched ℓ1 solver: exact KKT points on a support, their dual
certificates, and the repair of supports that fail the certificate.

All functions work on the normalized problem of :mod:`kinred.recovery._solver` (matrix
``Â (m, d)`` with Gram matrix ``ÂᵀÂ``, right-hand sides ``ŷ`` of unit norm), one row per
problem. For the formulas see the module docstring of :mod:`kinred.recovery._solver`
("Certified polish").
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ._kernels import support_solve

__all__ = ["Polish", "polish_with_repair"]

#: Basis pursuit: the polished point must reproduce ``ŷ`` to this residual.
_FEAS_TOL = 1e-9
#: Expansion threshold of the support repair (see :func:`polish_with_repair`).
_GROW_DELTA = 0.05
#: Rows polished together (supports of similar size: one Gram-system batch).
_POLISH_ROWS = 512


@dataclass
class Polish:
    """Polished points of ``n`` problems (rows) and what certifies them.

    Attributes
    ----------
    z : (n, d) ndarray
        Polished points (zeros where the polish was impossible).
    ok : (n,) bool ndarray
        Certified: feasible, signs agree with the support, dual certificate within
        ``cert_tol``.
    feasible : (n,) bool ndarray
        Polished point feasible with the support's signs.
    gap : (n,) ndarray
        Relative duality gap of the certificate (NaN where the polish was impossible).
    dual : (n, d) ndarray
        Where the polished point is feasible, the candidate certificate ``Âᵀν``; where it is
        not (the least-squares residual ``r₀`` on ``S`` exceeds ``η``), ``Âᵀr₀`` scaled so that
        its largest entry off ``S`` is 1 (zeros where the polish was impossible).
    """

    z: np.ndarray
    ok: np.ndarray
    feasible: np.ndarray
    gap: np.ndarray
    dual: np.ndarray

    @classmethod
    def empty(cls, n: int, d: int) -> "Polish":
        """``n`` rows on which the polish was impossible."""
        return cls(np.zeros((n, d)), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool),
                   np.full(n, np.nan), np.zeros((n, d)))

    def take(self, sel) -> "Polish":
        """The rows ``sel`` (index or mask)."""
        return Polish(*(getattr(self, f.name)[sel] for f in fields(self)))

    def put(self, rows, other: "Polish") -> None:
        """Overwrite the rows ``rows`` with ``other`` (one row each)."""
        for f in fields(self):
            getattr(self, f.name)[rows] = getattr(other, f.name)


# ---------------------------------------------------------------------------------------------
# one polish on given supports


def _polish(An, AtA, Yh, signs, form, param, nu0, nonneg, cert_tol) -> Polish:
    """Exact KKT point on the support given by ``signs`` and its dual certificate.

    Parameters
    ----------
    An : (m, d) normalized matrix ``Â``; AtA : (d, d) its Gram matrix ``ÂᵀÂ``.
    Yh : (n, m) right-hand sides; signs : (n, d) int8 in {-1, 0, 1}; param : (n,) η or λ.
    nu0 : (n, m) approximate dual vector (basis pursuit, ``η = 0``) or None.
    form, nonneg, cert_tol : as in :func:`polish_with_repair`.
    """
    n, d = signs.shape
    m = An.shape[0]
    out = Polish.empty(n, d)
    if n == 0:
        return out
    counts = np.count_nonzero(signs, axis=1)
    usable = np.flatnonzero((counts > 0) & (counts <= m))
    if usable.size == 0:
        return out
    rows_all = usable[np.argsort(counts[usable], kind="stable")]  # similar sizes together
    bp = form == "bpdn" and nu0 is not None
    for start in range(0, rows_all.size, _POLISH_ROWS):
        rows = rows_all[start : start + _POLISH_ROWS]
        out.put(rows, _polish_rows(An, AtA, Yh[rows], signs[rows], counts[rows], form,
                                   param[rows], nu0[rows] if bp else None, nonneg, cert_tol))
    return out


@dataclass(frozen=True)
class _Support:
    """Supports of ``nb`` rows, packed: row ``t`` lists its ``cnt[t]`` indices first."""

    idx: np.ndarray     # (nb, kmax) support indices first, then others
    cnt: np.ndarray     # (nb,) support sizes
    mask: np.ndarray    # (nb, kmax) True on the support entries
    s: np.ndarray       # (nb, kmax) signs on the support (float), 0 elsewhere

    @classmethod
    def of(cls, sg, cnt) -> "_Support":
        kmax = int(cnt.max())
        idx = np.argsort(sg == 0, axis=1, kind="stable")[:, :kmax]  # support first
        mask = np.arange(kmax)[None, :] < cnt[:, None]
        s = np.take_along_axis(sg, idx, axis=1).astype(float) * mask
        return cls(idx, cnt, mask, s)

    def gather(self, x):
        """``x`` (nb, d) restricted to the supports, packed (zeros beyond ``cnt``)."""
        return np.take_along_axis(x, self.idx, axis=1) * self.mask

    def scatter(self, x, d: int):
        """Packed ``x`` (nb, kmax) back to full rows (nb, d)."""
        out = np.zeros((x.shape[0], d))
        np.put_along_axis(out, self.idx, x, axis=1)
        return out


def _gram_solutions(An, AtA, y, sup: _Support, nu):
    """``(Â_SᵀÂ_S)⁻¹`` applied to ``Â_Sᵀy``, ``s`` and (basis pursuit) ``Â_Sᵀν``, as full rows.

    One compiled Cholesky per support; least squares where it breaks down (numerically
    singular Gram matrix). Returns ``[g1, g2]`` or ``[g1, g2, g3]``.
    """
    rhs = [sup.gather(y @ An), sup.s]
    if nu is not None:
        rhs.append(sup.gather(nu @ An))
    rhs = np.stack(rhs, axis=2)
    sol, solved = support_solve(AtA, sup.idx, sup.cnt, rhs)
    for t in np.flatnonzero(~solved):
        S = sup.idx[t, : sup.cnt[t]]
        sol[t, : sup.cnt[t]] = np.linalg.lstsq(AtA[np.ix_(S, S)], rhs[t, : sup.cnt[t]],
                                               rcond=None)[0]
    d = An.shape[1]
    return [sup.scatter(sol[:, :, j], d) for j in range(rhs.shape[2])]


def _multiplier(form, bp, r0, w, p):
    """The multiplier ``λ`` of the KKT point ``z = g1 − λ g2`` and whether it exists.

    LASSO: ``λ`` given. Basis pursuit: ``λ = 0``, the least-squares point must interpolate.
    BPDN: ``λ = √(η² − ‖r₀‖²)/‖Â_S(Â_SᵀÂ_S)⁻¹s‖`` puts the residual on the sphere ``‖r‖ = η``.
    """
    nb = r0.shape[0]
    r0n = np.linalg.norm(r0, axis=1)
    if form == "lasso":
        return p, np.ones(nb, dtype=bool)
    if bp:
        return np.zeros(nb), r0n <= _FEAS_TOL
    wn = np.linalg.norm(w, axis=1)
    good = (r0n <= p) & (wn > 0)
    lam = np.sqrt(np.maximum(p * p - r0n * r0n, 0.0)) / np.where(wn > 0, wn, 1.0)
    return lam, good


def _violation(c, nonneg):
    """``max_j (Âᵀν)_j − 1`` (nonneg) or ``‖Âᵀν‖∞ − 1`` per row."""
    return (np.max(c, axis=1) if nonneg else np.max(np.abs(c), axis=1)) - 1.0


def _certificate(An, bp, nu, g2, g3, r, lam, w, nonneg):
    """Candidate dual vector ``ν``, ``c = Âᵀν`` (rows) and its violation of ``‖c‖∞ ≤ 1``.

    BPDN / LASSO: ``ν = r/λ``. Basis pursuit: the ADMM dual corrected onto
    ``{ν : Â_Sᵀν = s}``, or the minimum-norm ``ν = Â_S(Â_SᵀÂ_S)⁻¹s`` (the classical
    certificate of exact recovery), whichever is less violated.
    """
    if bp:
        nu = nu + (g2 - g3) @ An.T
    else:
        nu = r / np.where(lam > 0, lam, 1.0)[:, None]
    c = nu @ An  # (nb, d) = (Âᵀν)ᵀ
    viol = _violation(c, nonneg)
    if bp:
        c2 = w @ An
        viol2 = _violation(c2, nonneg)
        pick = viol2 < viol
        nu[pick], c[pick], viol[pick] = w[pick], c2[pick], viol2[pick]
    return nu, c, viol


def _relative_gap(form, zS, r, lam, nu, viol, y, p):
    """Relative duality gap of the dual-feasible point ``ν / max(1, ‖Âᵀν‖∞)``."""
    l1 = np.sum(np.abs(zS), axis=1)
    sc = np.maximum(1.0, viol + 1.0)
    if form == "lasso":
        primal = 0.5 * np.sum(r * r, axis=1) + lam * l1
        tl = lam[:, None] * nu / sc[:, None]
        dual_obj = np.sum(tl * y, axis=1) - 0.5 * np.sum(tl * tl, axis=1)
    else:
        primal = l1
        dual_obj = (np.sum(nu * y, axis=1) - p * np.linalg.norm(nu, axis=1)) / sc
    return np.maximum(primal - dual_obj, 0.0) / np.maximum(np.abs(primal), 1e-300)


def _polish_rows(An, AtA, y, sg, cnt, form, p, nu, nonneg, cert_tol) -> Polish:
    """:func:`_polish` on rows whose supports all have ``1 ≤ |S| ≤ m``."""
    d = An.shape[1]
    bp = nu is not None
    sup = _Support.of(sg, cnt)
    g = _gram_solutions(An, AtA, y, sup, nu)
    r0 = y - g[0] @ An.T
    w = g[1] @ An.T
    lam, good = _multiplier(form, bp, r0, w, p)
    zS = g[0] - lam[:, None] * g[1]
    r = r0 + lam[:, None] * w
    sign_ok = np.all((np.take_along_axis(zS, sup.idx, axis=1) * sup.s > 0) | ~sup.mask, axis=1)
    nu, c, viol = _certificate(An, bp, nu, g[1], g[2] if bp else None, r, lam, w, nonneg)
    gap = _relative_gap(form, zS, r, lam, nu, viol, y, p)
    cert = good & sign_ok & (viol <= cert_tol) & (gap <= 10 * cert_tol + 1e-12)
    # where the least-squares point on S does not reach the constraint (r₀ too large),
    # the residual's correlations Âᵀr₀ point to the missing columns; else the certificate
    miss = ~good
    if np.any(miss):
        corr = r0[miss] @ An
        off = np.where(sg[miss] == 0, corr if nonneg else np.abs(corr), 0.0)
        c[miss] = corr / np.maximum(np.max(off, axis=1), 1e-300)[:, None]
    return Polish(zS, cert, good & sign_ok, gap, c)


def _polish_by_kind(An, AtA, Yh, signs, form, ph, nu0, nonneg, cert_tol) -> Polish:
    """:func:`_polish`, with the basis-pursuit rows (``η = 0``, which use ``nu0``) apart from
    the BPDN rows (``η > 0``)."""
    if form == "lasso" or nu0 is None:
        return _polish(An, AtA, Yh, signs, form, ph, None, nonneg, cert_tol)
    out = Polish.empty(*signs.shape)
    for sel, nu in ((ph == 0, nu0), (ph > 0, None)):
        rows = np.flatnonzero(sel)
        if rows.size:
            out.put(rows, _polish(An, AtA, Yh[rows], signs[rows], form, ph[rows],
                                  None if nu is None else nu[rows], nonneg, cert_tol))
    return out


# ---------------------------------------------------------------------------------------------
# support repair


def _expansion(best: Polish, signs, nonneg, expand, m):
    """Rows to expand and their grown sign patterns: off-support indices whose lead
    satisfies ``lead_j ≥ 1 − δ`` (at most 8, the largest) join with the sign of the lead."""
    dual = best.dual
    off = np.where(signs == 0, dual if nonneg else np.abs(dual), -np.inf)
    top = min(8, off.shape[1] - 1)
    near = np.zeros(signs.shape, dtype=bool)
    if top > 0:
        part = np.argpartition(-off, top, axis=1)[:, :top]
        np.put_along_axis(near, part,
                          np.take_along_axis(off, part, axis=1) >= 1.0 - _GROW_DELTA, axis=1)
    if expand is not None:
        near &= np.asarray(expand, dtype=bool)[:, None]
    grow = np.flatnonzero(~best.ok & np.any(near, axis=1)
                          & (np.count_nonzero(signs, axis=1) + np.count_nonzero(near, axis=1) <= m))
    grown = np.where(near[grow], np.sign(dual[grow]).astype(np.int8), signs[grow])
    return grow, grown


def _pruned(z, signs):
    """``signs`` without the entries whose polished sign disagrees or whose size is below
    ``1e-10`` of the row's largest."""
    big = np.abs(z) > 1e-10 * np.max(np.abs(z), axis=1, keepdims=True)
    return np.where((np.sign(z).astype(np.int8) == signs) & big, signs, np.int8(0))


def polish_with_repair(An, AtA, Yh, signs, form, ph, nu0, nonneg, cert_tol, expand=None) -> Polish:
    """Polish rows on the ADMM support, repairing it where the certificate fails.

    Parameters
    ----------
    An, AtA : (m, d), (d, d) ndarray
        Normalized matrix ``Â`` and its Gram matrix.
    Yh : (n, m) ndarray
        Normalized right-hand sides.
    signs : (n, d) int8 ndarray
        Sign patterns of the ADMM iterates (the supports).
    form : {"bpdn", "lasso"}
    ph : (n,) ndarray
        Normalized ``η`` or ``λ``.
    nu0 : (n, m) ndarray or None
        ADMM dual vectors, used by the basis-pursuit rows (``η = 0``); None if there are none.
    nonneg : bool
    cert_tol : float
        Tolerance of the certificate (bound on the relative duality gap).
    expand : (n,) bool ndarray, optional
        Rows on which the expansion is tried (default all; the solver flags the rows whose
        ADMM has converged: on the others ADMM is still moving its support).

    Returns
    -------
    Polish

    Notes
    -----
    Two repairs, each followed by a new polish of the rows it changes:

    1. *expansion*: indices outside the support whose lead (:attr:`Polish.dual`) satisfies
       ``|lead_j| ≥ 1 − δ`` (``δ = 0.05``, at most 8, the largest) join it with the sign of
       ``lead_j``. For a feasible polish the lead is the candidate certificate ``Âᵀν`` (the KKT
       conditions put every support index at ``|(Âᵀν)_j| = 1``); for an infeasible one it is
       the correlation ``Âᵀr₀`` of the least-squares residual (an orthogonal-matching-pursuit
       step: with one coefficient ``x_j`` missing, ``r₀ = x_j P⊥a_j``). This recovers
       coefficients that ADMM's soft threshold has not yet released (e.g. a true entry of
       relative size 1e-5, which ADMM takes thousands of iterations more to release). An
       index added in error gets a polished coefficient of about zero and is removed by
    2. *pruning*: entries whose polished sign disagrees with the support's, or whose size is
       below ``1e-10`` of the largest, are removed.

    Each repair only proposes a support; a row takes the new polish where it is certified,
    or feasible where the current one is not.
    """
    m = An.shape[0]
    best = _polish_by_kind(An, AtA, Yh, signs, form, ph, nu0, nonneg, cert_tol)

    def attempt(rows, new_signs):
        """Polish ``rows`` on ``new_signs``, keep the better rows; the raw polished points."""
        res = _polish_by_kind(An, AtA, Yh[rows], new_signs, form, ph[rows],
                              None if nu0 is None else nu0[rows], nonneg, cert_tol)
        better = res.ok | (res.feasible & ~best.feasible[rows] & ~best.ok[rows])
        best.put(rows[better], res.take(better))
        return res.z

    base_z, base_signs = best.z.copy(), signs.copy()      # what the pruning starts from
    grow, grown = _expansion(best, signs, nonneg, expand, m)
    if grow.size:
        base_z[grow] = attempt(grow, grown)
        base_signs[grow] = grown
    pruned = _pruned(base_z, base_signs)
    retry = np.flatnonzero(~best.ok & np.any(pruned != base_signs, axis=1)
                           & np.any(pruned != 0, axis=1))
    if retry.size:
        attempt(retry, pruned[retry])
    return best
