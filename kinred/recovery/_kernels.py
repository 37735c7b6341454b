"""numba kernel of the elementwise part of one batched ADMM iteration, and its numpy twin.

One call performs, row by row (one row = one right-hand side of the normalized problem),

.. math::

    \\hat z &= \\alpha z + (1-\\alpha) u, \\qquad \\widehat{Az} = \\alpha Az + (1-\\alpha) v \\\\
    u &\\leftarrow \\operatorname{soft}(\\hat z + p, \\tau)\\ \\ (\\text{or } \\max(\\hat z + p - \\tau, 0)),
    \\qquad p \\leftarrow p + \\hat z - u \\\\
    v &\\leftarrow y + \\Pi_{\\|\\cdot\\| \\le \\eta}(\\widehat{Az} + q - y)
    \\ \\ (\\text{BPDN})\\quad\\text{or}\\quad v \\leftarrow \\frac{y + (\\lambda/\\tau)(\\widehat{Az} + q)}{1 + \\lambda/\\tau}
    \\ \\ (\\text{LASSO}), \\qquad q \\leftarrow q + \\widehat{Az} - v

and writes the next linear-step inputs ``a = u − p`` and ``b = v − q``, in one pass over each
row instead of a chain of numpy passes over the whole arrays (the measured difference is in
docs/performance.md, "Recovery").
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["admm_step", "admm_step_numpy", "support_solve"]


@numba.njit(cache=True, nogil=True)
def _admm_step_nb(z, Az, u, v, p, q, a, b, thr, Y, param, relax, lasso, nonneg):
    n, d = z.shape
    m = Az.shape[1]
    om = 1.0 - relax
    for i in range(n):
        th = thr[i]
        for j in range(d):
            zh = relax * z[i, j] + om * u[i, j]
            t = zh + p[i, j]
            if nonneg:
                un = t - th
                if un < 0.0:
                    un = 0.0
            else:
                if t > th:
                    un = t - th
                elif t < -th:
                    un = t + th
                else:
                    un = 0.0
            pn = p[i, j] + zh - un
            u[i, j] = un
            p[i, j] = pn
            a[i, j] = un - pn
        if lasso:
            mu = param[i] / th  # objective ‖u‖₁ + ‖v − y‖²/(2λ)
            for j in range(m):
                azh = relax * Az[i, j] + om * v[i, j]
                vn = (Y[i, j] + mu * (azh + q[i, j])) / (1.0 + mu)
                qn = q[i, j] + azh - vn
                v[i, j] = vn
                q[i, j] = qn
                b[i, j] = vn - qn
        else:
            s = 0.0
            for j in range(m):
                azh = relax * Az[i, j] + om * v[i, j]
                t = azh + q[i, j] - Y[i, j]
                s += t * t
            nrm = np.sqrt(s)
            eta = param[i]
            fac = 1.0
            if nrm > eta:
                fac = eta / nrm
            for j in range(m):
                azh = relax * Az[i, j] + om * v[i, j]
                t = azh + q[i, j] - Y[i, j]
                vn = Y[i, j] + fac * t
                qn = q[i, j] + azh - vn
                v[i, j] = vn
                q[i, j] = qn
                b[i, j] = vn - qn


def admm_step_numpy(z, Az, u, v, p, q, a, b, thr, Y, param, relax, lasso, nonneg):
    """Plain-numpy twin of :func:`admm_step` (same arguments, same in-place updates)."""
    zh = relax * z + (1.0 - relax) * u
    t = zh + p
    th = thr[:, None]
    if nonneg:
        un = np.maximum(t - th, 0.0)
    else:
        un = np.sign(t) * np.maximum(np.abs(t) - th, 0.0)
    p += zh - un
    u[...] = un
    a[...] = u - p
    azh = relax * Az + (1.0 - relax) * v
    t = azh + q
    if lasso:
        mu = param[:, None] / th
        vn = (Y + mu * t) / (1.0 + mu)
    else:
        t = t - Y
        nrm = np.linalg.norm(t, axis=1, keepdims=True)
        eta = param[:, None]
        fac = np.where(nrm > eta, eta / np.where(nrm > 0, nrm, 1.0), 1.0)
        vn = Y + fac * t
    q += azh - vn
    v[...] = vn
    b[...] = v - q


def admm_step(z, Az, u, v, p, q, a, b, thr, Y, param, relax, lasso, nonneg):
    """Elementwise part of one ADMM iteration, in place (numba).

    Parameters
    ----------
    z, u, p, a : (n, d) float64 C-contiguous arrays
        ``z`` is read; ``u`` and the scaled dual ``p`` are updated; ``a = u − p`` is written.
    Az, v, q, b : (n, m) float64 C-contiguous arrays
        Same for the ``v = Az`` block.
    thr : (n,) ndarray
        Thresholds ``τ = 1/μ`` per row.
    Y : (n, m) ndarray
        Normalized right-hand sides (rows).
    param : (n,) ndarray
        ``η`` (BPDN) or ``λ`` (LASSO) per row.
    relax : float
        Over-relaxation ``α``.
    lasso, nonneg : bool
        LASSO ``v``-step instead of the ball projection; non-negative soft threshold.
    """
    _admm_step_nb(z, Az, u, v, p, q, a, b, thr, Y, param, float(relax), bool(lasso), bool(nonneg))


@numba.njit(cache=True, nogil=True)
def _support_solve_nb(AtA, idx, cnt, rhs, sol, rel_pivot):
    nb, kmax, r = rhs.shape
    ok = np.ones(nb, dtype=np.bool_)
    L = np.empty((kmax, kmax))
    for t in range(nb):
        k = cnt[t]
        for i in range(k):
            ii = idx[t, i]
            for j in range(i + 1):
                L[i, j] = AtA[ii, idx[t, j]]
        good = True
        for j in range(k):                     # Cholesky, lower triangle, in place
            s = L[j, j]
            for l in range(j):
                s -= L[j, l] * L[j, l]
            if not s > rel_pivot * AtA[idx[t, j], idx[t, j]]:
                good = False
                break
            dj = np.sqrt(s)
            L[j, j] = dj
            for i in range(j + 1, k):
                s2 = L[i, j]
                for l in range(j):
                    s2 -= L[i, l] * L[j, l]
                L[i, j] = s2 / dj
        for c in range(r):
            for i in range(kmax):
                sol[t, i, c] = 0.0
        if not good:
            ok[t] = False
            continue
        for c in range(r):
            for i in range(k):                 # L y = b
                s = rhs[t, i, c]
                for l in range(i):
                    s -= L[i, l] * sol[t, l, c]
                sol[t, i, c] = s / L[i, i]
            for i in range(k - 1, -1, -1):     # Lᵀ x = y
                s = sol[t, i, c]
                for l in range(i + 1, k):
                    s -= L[l, i] * sol[t, l, c]
                sol[t, i, c] = s / L[i, i]
    return ok


def support_solve(AtA, idx, cnt, rhs, rel_pivot=1e-12):
    """Solve the Gram systems of many supports: ``(AᵀA)_{S_t S_t} x = rhs_t``.

    Parameters
    ----------
    AtA : (d, d) symmetric positive semi-definite matrix ``AᵀA``.
    idx : (nb, kmax) int array; row ``t`` lists the support ``S_t`` in its first ``cnt[t]``
        entries.
    cnt : (nb,) int array of support sizes.
    rhs : (nb, kmax, r) right-hand sides (entries beyond ``cnt[t]`` ignored).
    rel_pivot : float
        A Cholesky pivot at or below ``rel_pivot`` times its diagonal entry marks the system
        as (numerically) singular.

    Returns
    -------
    sol : (nb, kmax, r) solutions (zero beyond ``cnt[t]`` and on failed rows).
    ok : (nb,) bool, False where the Cholesky factorization broke down (use least squares).

    One compiled loop (gather, Cholesky, two triangular solves per right-hand side); twin:
    ``np.linalg.solve`` on the gathered matrices (tested).
    """
    rhs = np.ascontiguousarray(rhs, dtype=float)
    sol = np.empty_like(rhs)
    ok = _support_solve_nb(np.ascontiguousarray(AtA, dtype=float), np.ascontiguousarray(idx, dtype=np.int64),
                           np.ascontiguousarray(cnt, dtype=np.int64), rhs, sol, float(rel_pivot))
    return sol, ok
