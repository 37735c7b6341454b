"""Private numba kernels of the certificate's pair pass, each with a plain-numpy twin.

Only this module of :mod:`kinred.certify` imports numba; every kernel uses ``cache=True``.

``strip_term(i0, qrun, qtrue, qcar, c, pos, bz, bs, kind, par, margin, rnd, out, buf, scr)``
    One row strip ``[i0, i0 + b)`` against the columns ``[i0, N)`` (squared distances of the
    projected run's source ``qrun``, of the projected-true source ``qtrue`` and of the
    projected-true carrier ``qcar``, as the engine's strips: each unordered pair ``i < j``
    once) for one pairwise term: the kernel ``φ(r′ᵢⱼ)`` of the projected run, the localized
    slope bound ``Λᵢⱼ = sup |φ′|`` over ``[min(ρᵢⱼ, r′ᵢⱼ), max(ρᵢⱼ, r′ᵢⱼ)]`` times
    ``1 + margin``, and, accumulated into both rows ``i`` and ``j`` of ``out (9, N)``:

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
"""

from __future__ import annotations

import math

from numba import njit

from ..dynamics._kernels import pow_row64

__all__ = ["strip_term"]


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


@njit(cache=True, nogil=True, error_model="numpy")
def strip_term(i0, qrun, qtrue, qcar, c, pos, bz, bs, kind, par, margin, rnd, out, buf,
               scr):  # pragma: no cover - compiled
    b, m = qrun.shape
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
    gev = 0.6 * G if (kind == 1 and beta > 0.0) else 0.0
    for a in range(b):
        i = i0 + a
        j0 = a + 1
        L = m - j0
        if L <= 0:
            continue
        ph = buf[0, :L]
        pt = buf[1, :L]
        if kind == 1:
            ph[:] = qrun[a, j0:]
            pow_row64(ph, G, beta, scr)
            pt[:] = qtrue[a, j0:]
            pow_row64(pt, G, beta, scr)
        ci = c[i]
        bzi = bz[i]
        bsi = bs[i]
        posi = pos[i]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        s4 = 0.0
        s5 = 0.0
        s6 = out[6, i]
        s7 = 0.0
        s8 = 0.0
        for l in range(L):
            jj = j0 + l
            j = i0 + jj
            q1 = qrun[a, jj]
            q2 = qtrue[a, jj]
            r1 = math.sqrt(q1)
            r2 = math.sqrt(q2)
            zc = math.sqrt(qcar[a, jj])
            if kind == 1:
                phi = ph[l]
                mag1 = rg * ph[l] + re_ * (ph[l] + gev) + rs * 2.0 * beta * ph[l] * q1 / (1.0 + q1)
                mag2 = rg * pt[l] + re_ * (pt[l] + gev) + rs * 2.0 * beta * pt[l] * q2 / (1.0 + q2)
                if beta > 0.0:
                    f1 = _cs_slope(r1, q1, ph[l], beta)
                    f2 = _cs_slope(r2, q2, pt[l], beta)
                    lam = max(f1, f2)
                    if min(r1, r2) <= s_star and max(r1, r2) >= s_star:
                        lam = f_star
                else:
                    lam = 0.0
            elif kind == 2:
                A = par[0]
                la = par[1]
                B = par[2]
                lr = par[3]
                e2 = par[4] * par[4]
                R1 = math.sqrt(q1 + e2)
                R2 = math.sqrt(q2 + e2)
                phi, pa1, pr1, ev1 = _morse_at(R1, A, la, B, lr)
                phi2, pa2, pr2, ev2 = _morse_at(R2, A, la, B, lr)
                mag1 = rg * abs(phi) + re_ * ev1 + rs * q1 / R1 * (pa1 + pr1)
                mag2 = rg * abs(phi2) + re_ * ev2 + rs * q2 / R2 * (pa2 + pr2)
                if R1 <= R2:
                    g1 = max(abs(pr2 - pa1), abs(pr1 - pa2))
                    lam = g1 * (r2 / R2)
                else:
                    g1 = max(abs(pr1 - pa2), abs(pr2 - pa1))
                    lam = g1 * (r1 / R1)
            else:
                phi = par[0]
                lam = 0.0
                mag1 = (rg + re_) * abs(phi)
                mag2 = mag1
            lam *= fac
            aphi = abs(phi)
            nphi = -phi if phi < 0.0 else 0.0
            t = lam * zc
            cj = c[j]
            s0 += cj * phi
            s1 += cj * nphi
            s2 += cj * aphi * bz[j]
            s3 += cj * t
            s4 += cj * t * bs[j]
            s5 += cj * mag2
            s8 += cj * mag1
            s7 += cj * phi * phi
            out[0, j] += ci * phi
            out[1, j] += ci * nphi
            out[2, j] += ci * aphi * bzi
            out[3, j] += ci * t
            out[4, j] += ci * t * bsi
            out[5, j] += ci * mag2
            out[8, j] += ci * mag1
            out[7, j] += ci * phi * phi
            pp = phi if phi > 0.0 else 0.0
            if pos[j] and pp < s6:
                s6 = pp
            if posi and pp < out[6, j]:
                out[6, j] = pp
        out[0, i] += s0
        out[1, i] += s1
        out[2, i] += s2
        out[3, i] += s3
        out[4, i] += s4
        out[5, i] += s5
        out[6, i] = s6
        out[7, i] += s7
        out[8, i] += s8
    return 0
