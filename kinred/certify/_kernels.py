"""Private numba kernels of the certificate's pair pass, each with a plain-numpy twin.

Only this module of :mod:`kinred.certify` imports numba; every kernel uses ``cache=True``.

``strip_term(i0, qrun, qtrue, qcar, c, pos, bz, bs, kind, par, margin, rnd, out, buf, scr,
phit, add)`` (``buf (10, ≥ N)``, ``scr (3, ≥ N)`` scratch)
    One row strip ``[i0, i0 + b)`` against the columns ``[i0, N)`` (squared distances of the
    projected run's source ``qrun``, of the projected-true source ``qtrue`` and of the
    projected-true carrier ``qcar``, as the engine's strips: each unordered pair ``i < j``
    once) for one pairwise term: the kernel ``φ(r′ᵢⱼ)`` of the projected run, the localized
    slope bound ``Λᵢⱼ = sup |φ′|`` over ``[min(ρᵢⱼ, r′ᵢⱼ), max(ρᵢⱼ, r′ᵢⱼ)]`` times
    ``1 + margin``, the kernel ``φ(ρᵢⱼ)`` at the projected-true distances written (``add = 0``)
    or added (``add = 1``) into the strip block ``phit (b, N − i0)`` at the pairs ``j > i``
    (the defect's pair sums ``Σⱼ cⱼ φ(ρᵢⱼ)(Mzⱼ − Mzᵢ)`` are its BLAS products, after
    :func:`square_fill`), and, accumulated into both rows ``i`` and ``j`` of ``out (9, N)``:

    ====  ==========================================================
    row   quantity
    ====  ==========================================================
    0     ``Σⱼ cⱼ φᵢⱼ``                       (signed degree)
    1     ``Σⱼ cⱼ max(−φᵢⱼ, 0)``              (negative part)
    2     ``Σⱼ cⱼ |φᵢⱼ| bzⱼ``                 (ℓ∞ Laplacian matvec)
    3     ``Σⱼ Kᵢⱼ``, ``Kᵢⱼ = cⱼ Λᵢⱼ |Mzᵢ − Mzⱼ|``
    4     ``Σⱼ Kᵢⱼ bsⱼ``                      (ℓ∞ matvec)
    5     ``Σⱼ cⱼ ψ(ρᵢⱼ)``                    (rounding of the kernel values at ``(Mx, Mv)``)
    6     ``minⱼ max(φᵢⱼ, 0)`` over ``j ≠ i`` with ``pos[j]`` (row minima; ``out[6]``
          must start at ``+inf``)
    7     ``Σⱼ cⱼ φᵢⱼ²``                      (row second moment)
    8     ``Σⱼ cⱼ ψ(r′ᵢⱼ)``                   (the same at the projected run)
    ====  ==========================================================

    ``ψ = g|φ| + a_e·ε_eval + a_s·σ`` (``rnd = (g, a_e, a_s)``, round-off allowance, see
    :mod:`kinred.certify._roundoff`): ``g|φ|`` the sums' rounding, ``ε_eval`` the scale of
    one kernel evaluation's rounding – ``φ + 0.6G`` for Cucker–Smale (the engine's pow has
    relative error ∝ ``1 + |log₂(G/φ)|`` and ``x log₂(G/x) ≤ 0.53G``), the sum of the moduli
    of Morse's two exponential terms times ``1 + r/ℓₐ + r/ℓ_r`` (their difference cancels),
    ``|c|`` for Quadratic – and ``σ ≥ s|φ′(s)|``, the sensitivity to a relative error of the
    distance (``2βφ q/(1+q)``, ``s²/r (P_a + P_r)``, 0).
 Kernel kinds: 1 Cucker–Smale ``(G, β)`` (values by the engine's vectorized
    ``pow_row64``; the slope ``2β s/(1+s²)·φ(s)``, peak at ``s* = 1/√(2β+1)``), 2 softened
    Morse ``(Cₐ/ℓₐ, ℓₐ, C_r/ℓ_r, ℓ_r, soft)`` (the envelope bound of
    :meth:`kinred.dynamics.Morse.slope_bound`), 3 Quadratic ``(c,)``.
    Twin: :func:`kinred.certify._aggregates.pair_pass_numpy` (full rows, kernels'
    ``__call__`` and ``slope_bound``).
``square_fill(phit)``
    The strip's square part of a kernel block written above its diagonal: the diagonal set to
    0, the part below it mirrored (``φ`` is symmetric), so that the block feeds the two BLAS
    products of the dense engine (``kinred.pairsum.dense``). Twin: ``np.triu(P, 1) +
    np.triu(P, 1).T`` on the square.
``pass_strips(strips, ...)``
    One thread's share of the pass in one compiled call without the GIL (as the dynamics
    engine's ``pair_strips``): per strip the squared distances of every point set (by
    differences, or BLAS ``−2 Y Yᵀ`` plus the close-pair fix-up), per carrier its terms'
    :func:`strip_term`, :func:`square_fill` and the two products ``acc += Φ Z``. Twin: the
    Python strip loop of :func:`kinred.certify._aggregates._fast_pass` (same calls, same
    order), used when numpy's BLAS symbols are not found.

The compiled functions inline kernels of :mod:`kinred.pairsum._kernels` (``pow_row64``, the
distance kernels, ``cblas_dgemm``); numba's cache of this file does not see changes there:
after editing them, touch this file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..pairsum.strips import compiled_blocks

_nb_gemm, sqdist_diff, sqdist_gram_fix, pow_row64 = compiled_blocks()

__all__ = ["strip_term", "square_fill", "pass_strips"]


@njit(cache=True, nogil=True, error_model="numpy")
def _cs_slope(s, q, phi, beta):  # pragma: no cover - compiled
    # |g'(s)| = 2 beta s/(1 + s^2) g(s)
    return 2.0 * beta * s / (1.0 + q) * phi


@njit(cache=True, nogil=True, error_model="numpy")
def _morse_at(r, A, la, B, lr):  # pragma: no cover - compiled
    # value u = U'(r)/r, envelopes P_a, P_r of g'(r) and the rounding scale at r
    ea = A * math.exp(-r / la)
    er = B * math.exp(-r / lr)
    inv = 1.0 / r
    u = (ea - er) * inv
    pa = ea * (inv / la + inv * inv)
    pr = er * (inv / lr + inv * inv)
    mag = (ea + er) * inv * (1.0 + r / la + r / lr)
    return u, pa, pr, mag


_FM = {"reassoc", "contract"}


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def _pairs_cs(q1, q2, qc, ph, pt, beta, G, s_star, f_star, fac, rg, re_, rs,
              V0, V1, V2, V3, V4, V5, V6, V7):  # pragma: no cover - compiled
    # per pair of one row: V = [phi, |phi|, max(-phi, 0), lam |Mz_i - Mz_j|, psi_true,
    # psi_run, max(phi, 0), phi(rho)] (branch-free, vectorizable); ph, pt: phi(r'), phi(rho)
    gev = 0.6 * G if beta > 0.0 else 0.0
    for l in range(q1.shape[0]):
        a1 = q1[l]
        a2 = q2[l]
        r1 = math.sqrt(a1)
        r2 = math.sqrt(a2)
        p1 = ph[l]
        p2 = pt[l]
        f1 = 2.0 * beta * r1 / (1.0 + a1) * p1
        f2 = 2.0 * beta * r2 / (1.0 + a2) * p2
        lo = min(r1, r2)
        hi = max(r1, r2)
        lam = f_star if (lo <= s_star and hi >= s_star) else max(f1, f2)
        V0[l] = p1
        V1[l] = p1
        V2[l] = 0.0
        V3[l] = lam * fac * math.sqrt(qc[l])
        V4[l] = rg * p2 + re_ * (p2 + gev) + rs * 2.0 * beta * p2 * a2 / (1.0 + a2)
        V5[l] = rg * p1 + re_ * (p1 + gev) + rs * 2.0 * beta * p1 * a1 / (1.0 + a1)
        V6[l] = p1
        V7[l] = p2


@njit(cache=True, nogil=True, error_model="numpy")
def _pairs_morse(q1, q2, qc, par, fac, rg, re_, rs, V0, V1, V2, V3, V4, V5,
                 V6, V7):  # pragma: no cover - compiled
    A = par[0]
    la = par[1]
    B = par[2]
    lr = par[3]
    e2 = par[4] * par[4]
    for l in range(q1.shape[0]):
        a1 = q1[l]
        a2 = q2[l]
        R1 = math.sqrt(a1 + e2)
        R2 = math.sqrt(a2 + e2)
        phi, pa1, pr1, ev1 = _morse_at(R1, A, la, B, lr)
        phi2, pa2, pr2, ev2 = _morse_at(R2, A, la, B, lr)
        g1 = max(abs(pr2 - pa1), abs(pr1 - pa2))
        lam = g1 * (math.sqrt(a2) / R2 if R1 <= R2 else math.sqrt(a1) / R1)
        V0[l] = phi
        V1[l] = abs(phi)
        V2[l] = -phi if phi < 0.0 else 0.0
        V3[l] = lam * fac * math.sqrt(qc[l])
        V4[l] = rg * abs(phi2) + re_ * ev2 + rs * a2 / R2 * (pa2 + pr2)
        V5[l] = rg * abs(phi) + re_ * ev1 + rs * a1 / R1 * (pa1 + pr1)
        V6[l] = phi if phi > 0.0 else 0.0
        V7[l] = phi2


@njit(cache=True, nogil=True, error_model="numpy")
def strip_term(i0, qrun, qtrue, qcar, c, pos, bz, bs, kind, par, margin, rnd, out, buf,
               scr, phit, add):  # pragma: no cover - compiled
    b, m = qrun.shape
    n = c.shape[0]
    # the helpers run without bounds checks: check the shapes once here
    if (buf.shape[0] < 10 or buf.shape[1] < m or scr.shape[0] < 3 or scr.shape[1] < m
            or out.shape[0] < 9 or out.shape[1] < n or i0 + m > n or qtrue.shape != qrun.shape
            or qcar.shape != qrun.shape or phit.shape != qrun.shape or bz.shape[0] < n
            or bs.shape[0] < n):
        raise ValueError("strip_term: inconsistent shapes of the blocks and buffers")
    beta = par[1] if kind == 1 else 0.0
    G = par[0]
    s_star = 1.0 / math.sqrt(2.0 * beta + 1.0)
    f_star = 0.0
    if kind == 1 and beta > 0.0:
        f_star = _cs_slope(s_star, s_star * s_star,
                           G * math.exp(-beta * math.log1p(s_star * s_star)), beta)
    fac = 1.0 + margin
    rg = rnd[0]
    re_ = rnd[1]
    rs = rnd[2]
    for a in range(b):
        i = i0 + a
        j0 = a + 1
        L = m - j0
        if L <= 0:
            continue
        V0 = buf[2, :L]
        V1 = buf[3, :L]
        V2 = buf[4, :L]
        V3 = buf[5, :L]
        V4 = buf[6, :L]
        V5 = buf[7, :L]
        V6 = buf[8, :L]
        V7 = buf[9, :L]
        if kind == 1:
            ph = buf[0, :L]
            pt = buf[1, :L]
            ph[:] = qrun[a, j0:]
            pow_row64(ph, G, beta, scr)
            pt[:] = qtrue[a, j0:]
            pow_row64(pt, G, beta, scr)
            _pairs_cs(qrun[a, j0:], qtrue[a, j0:], qcar[a, j0:], ph, pt, beta, G, s_star,
                      f_star, fac, rg, re_, rs, V0, V1, V2, V3, V4, V5, V6, V7)
        elif kind == 2:
            _pairs_morse(qrun[a, j0:], qtrue[a, j0:], qcar[a, j0:], par, fac, rg, re_, rs,
                         V0, V1, V2, V3, V4, V5, V6, V7)
        else:
            for l in range(L):
                V0[l] = par[0]
                V1[l] = abs(par[0])
                V2[l] = -par[0] if par[0] < 0.0 else 0.0
                V3[l] = 0.0
                V4[l] = (rg + re_) * abs(par[0])
                V5[l] = V4[l]
                V6[l] = par[0] if par[0] > 0.0 else 0.0
                V7[l] = par[0]
        _store_row(phit[a, j0:], V7, add)
        _accumulate(i, i0 + j0, c, pos, bz, bs, V0, V1, V2, V3, V4, V5, V6, out)
    return 0


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def _store_row(dst, src, add):  # pragma: no cover - compiled
    if add:
        for l in range(src.shape[0]):
            dst[l] += src[l]
    else:
        for l in range(src.shape[0]):
            dst[l] = src[l]


@njit(cache=True, nogil=True, error_model="numpy")
def square_fill(phit):  # pragma: no cover - compiled
    b = phit.shape[0]
    if phit.shape[1] < b:
        raise ValueError("square_fill: the block must hold its b x b square")
    for a in range(b):
        phit[a, a] = 0.0
        for a2 in range(a):
            phit[a, a2] = phit[a2, a]
    return 0


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def _accumulate(i, jstart, c, pos, bz, bs, V0, V1, V2, V3, V4, V5, V6,
                out):  # pragma: no cover - compiled
    # row i from the columns j = jstart.., and those columns from row i (each pair once);
    # contiguous 1-D views so that the loops vectorize
    L = V0.shape[0]
    je = jstart + L
    cj = c[jstart:je]
    pj = pos[jstart:je]
    bzj = bz[jstart:je]
    bsj = bs[jstart:je]
    o0 = out[0, jstart:je]
    o1 = out[1, jstart:je]
    o2 = out[2, jstart:je]
    o3 = out[3, jstart:je]
    o4 = out[4, jstart:je]
    o5 = out[5, jstart:je]
    o6 = out[6, jstart:je]
    o7 = out[7, jstart:je]
    o8 = out[8, jstart:je]
    ci = c[i]
    bzi = bz[i]
    bsi = bs[i]
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    s5 = 0.0
    s7 = 0.0
    s8 = 0.0
    for l in range(L):
        w = cj[l]
        phi = V0[l]
        t = V3[l]
        s0 += w * phi
        s1 += w * V2[l]
        s2 += w * V1[l] * bzj[l]
        s3 += w * t
        s4 += w * t * bsj[l]
        s5 += w * V4[l]
        s7 += w * phi * phi
        s8 += w * V5[l]
    for l in range(L):
        phi = V0[l]
        t = V3[l]
        o0[l] += ci * phi
        o1[l] += ci * V2[l]
        o2[l] += ci * V1[l] * bzi
        o3[l] += ci * t
        o4[l] += ci * t * bsi
        o5[l] += ci * V4[l]
        o7[l] += ci * phi * phi
        o8[l] += ci * V5[l]
    s6 = out[6, i]
    if pos[i]:
        for l in range(L):
            pp = V6[l]
            if pp < o6[l]:
                o6[l] = pp
    for l in range(L):
        pp = V6[l]
        if pj[l] and pp < s6:
            s6 = pp
    out[0, i] += s0
    out[1, i] += s1
    out[2, i] += s2
    out[3, i] += s3
    out[4, i] += s4
    out[5, i] += s5
    out[6, i] = s6
    out[7, i] += s7
    out[8, i] += s8


@njit(cache=True, nogil=True, error_model="numpy")
def pass_strips(strips, diff, YT, Yc, nrm, R, tau, sets, tkind, tpar, tbz, tbs, tcz, c, pos,
                margin, rnd, Z, acc, outs, qbuf, phbuf, buf, scr):  # pragma: no cover - compiled
    # strips (S, 2); point sets s: YT[s] (k, N) if diff else Yc[s] (N, k) centred, nrm[s],
    # R[s] raw (S, N, k); per term t: sets[t] = (run, true, carrier) point-set indices, kind,
    # params, bz/bs rows, carrier index tcz; Z (C, N, k+1), acc (C, N, k+1) zeroed here;
    # outs (T, 9, N) with outs[:, 6] = inf; qbuf (point sets, >= maxel), phbuf (>= maxel)
    N = c.shape[0]
    ns = qbuf.shape[0]
    nt = sets.shape[0]
    acc[:] = 0.0
    for st in range(strips.shape[0]):
        i0 = strips[st, 0]
        i1 = strips[st, 1]
        bb = i1 - i0
        m = N - i0
        for s in range(ns):
            q = qbuf[s, : bb * m].reshape((bb, m))
            if diff:
                sqdist_diff(YT[s], i0, i1, i0, q)
            else:
                Rs = R[s]
                _nb_gemm(-2.0, Yc[s, i0:i1], False, Yc[s, i0:], True, 0.0, q)
                sqdist_gram_fix(q, nrm[s, i0:i1], nrm[s, i0:], Rs[i0:i1], Rs[i0:], tau,
                                np.int64(0))
        ph = phbuf[: bb * m].reshape((bb, m))
        for cz in range(Z.shape[0]):
            add = np.int64(0)       # a literal 0 would compile a second strip_term
            for t in range(nt):
                if tcz[t] != cz:
                    continue
                strip_term(i0, qbuf[sets[t, 0], : bb * m].reshape((bb, m)),
                           qbuf[sets[t, 1], : bb * m].reshape((bb, m)),
                           qbuf[sets[t, 2], : bb * m].reshape((bb, m)), c, pos, tbz[t], tbs[t],
                           tkind[t], tpar[t], margin, rnd, outs[t], buf, scr, ph, add)
                add = np.int64(1)
            square_fill(ph)
            _nb_gemm(1.0, ph, False, Z[cz, i0:], False, 1.0, acc[cz, i0:i1])
            if i1 < N:
                _nb_gemm(1.0, ph[:, bb:], True, Z[cz, i0:i1], False, 1.0, acc[cz, i1:])
    return 0
