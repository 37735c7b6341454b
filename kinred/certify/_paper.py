r"""The paper's a-priori bounds for the projected Euler scheme, with their constants.

* Theorem 2.2 (eq. (2.11)), the ℓ∞-over-agents bound for the class
  (1.1), applied to the ``2N`` variables ``x₁..x_N, v₁..v_N`` (the arrangement of §3.3):

  .. math:: \mathcal E^n \le \varepsilon\, h n\, B\, e^{h n A}, \quad
            A = L' + 2(1+\varepsilon)(L + \alpha L''), \quad B = 2\alpha(1+\varepsilon)(L + \alpha L''),

  so an agent's error in ``ℝ²ᵏ`` is at most ``√2`` times it (``paper_bound_max``).
  ``L, L′, L″`` are the constants (1.2)–(1.4) of the effects
  (:func:`kinred.kinetic.effect_constants`, with ``S = Σⱼ cⱼ = κ``);
* Theorem 2.3 (eq. (2.18)), the least-squares bound for
  Cucker–Smale only (one alignment in positions whose kernel declares the ``"cucker_smale"``
  ``certificate_form()``; ``paper_bound``; NaN for any other scene):

  .. math:: \sqrt{\mathcal E_x^2 + \mathcal E_v^2} \le \varepsilon(1+\varepsilon)\, h n\,
            \kappa\|g\|_{\rm Lip} V X \exp(h n \|\mathcal A\|), \quad
            \mathcal A = \begin{pmatrix} 0 & 1 \\ 2(1+\varepsilon)\kappa\|g\|_{\rm Lip} V & 2\kappa G \end{pmatrix}

  (the paper's ``1/N`` is ``cⱼ = κ wⱼ``: ``G`` and ``‖g‖_Lip`` carry the factor ``κ``).

The a-priori quantities are *measured* at the saved steps as running maxima (the theorems
applied on ``[0, t]``): ``ε`` the distortion (2.6)–(2.8) of ``M`` on the pairs the effects
see (positions; velocities for kernels of velocity distances; speeds ``|vᵢ|`` – distances to
the paper's auxiliary zero particle – for self-propulsion; and ``|Mzⱼ| ≤ (1+ε)|zⱼ|``),
``α ≥ maxⱼ |zⱼ|`` over the variables (positions relative to the initial centroid),
``X, V`` the diameters. Between saved steps nothing is measured: these are evaluations of the
theorems' right-hand sides, labelled "a-priori bound (paper's constants)", not certificates.
"""

from __future__ import annotations

import math

import numpy as np

from ..kinetic import effect_constants
from ._aggregates import _geometry, _sqdist
from ._plan import KIND_CS
from ..pairsum.strips import row_strips as _strips

__all__ = ["PaperTracker", "pair_ratio_extremes"]


def pair_ratio_extremes(Z: np.ndarray, PZ: np.ndarray) -> tuple[float, float, float]:
    """``(min, max)`` of ``|PZᵢ − PZⱼ| / |Zᵢ − Zⱼ|`` over pairs ``i < j`` with ``Zᵢ ≠ Zⱼ``, and
    ``max |Zᵢ − Zⱼ|`` (row strips, BLAS Gram blocks with the engine's close-pair fix-up).

    Examples
    --------
    >>> Z = np.array([[0.0, 0.0, 0.0, 0.0], [3.0, 4.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    >>> pair_ratio_extremes(Z, 2.0 * Z)
    (2.0, 2.0, 5.0990195135927845)
    """
    n = Z.shape[0]
    if n < 2:
        return 1.0, 1.0, 0.0
    geo = _geometry({"Z": Z, "P": PZ}, ("Z", "P"))
    rmin, rmax, qmax = math.inf, -math.inf, 0.0
    for i0, i1 in _strips(n, None, max(Z.shape[1], PZ.shape[1])):
        shape = (i1 - i0, n - i0)
        qz = _sqdist(geo["Z"], i0, i1, np.empty(shape))
        qp = _sqdist(geo["P"], i0, i1, np.empty(shape))
        upper = np.triu(np.ones(shape, dtype=bool), k=1)
        ok = upper & (qz > 0)
        if np.any(ok):
            r = np.sqrt(qp[ok] / qz[ok])
            rmin, rmax = min(rmin, float(r.min())), max(rmax, float(r.max()))
            qmax = max(qmax, float(qz[ok].max()))
    if not math.isfinite(rmin):
        return 1.0, 1.0, 0.0
    return rmin, rmax, math.sqrt(qmax)


def _norm_ratio(Z, PZ) -> tuple[float, float]:
    nz = np.sqrt(np.einsum("ij,ij->i", Z, Z))
    npz = np.sqrt(np.einsum("ij,ij->i", PZ, PZ))
    ok = nz > 0
    if not np.any(ok):
        return 1.0, 1.0
    r = npz[ok] / nz[ok]
    return float(r.min()), float(r.max())


class PaperTracker:
    """Measures the a-priori quantities at saved steps and evaluates eq. (2.11) and (2.18)."""

    def __init__(self, scene, P, plan, w):
        self.scene, self.P, self.plan, self.w = scene, P, plan, w
        self.sources = {t.source for t in plan.terms}
        eff = scene.effects
        self.cs = None
        if (len(eff) == 1 and getattr(eff[0], "pairwise", False)
                and plan.terms[0].kind == KIND_CS and eff[0].source == "x"
                and eff[0].carrier == "v"):
            self.cs = eff[0].kernel
        self.rows = []

    def record(self, t, x, v, PX, PV, Y, W) -> None:
        """Measure at one saved step (``x, v`` high-dimensional, working coordinates)."""
        eps = 0.0
        rx = pair_ratio_extremes(x, PX)
        rv = pair_ratio_extremes(v, PV)
        used = []
        if "x" in self.sources or self.cs is not None:
            used.append(rx[:2])
        if "v" in self.sources or self.cs is not None:
            used.append(rv[:2])
        if self.plan.has_sp:
            used.append(_norm_ratio(v, PV))
        for lo, hi in used:
            eps = max(eps, 1.0 - lo, hi - 1.0)
        # (2.7): |M z_j| <= (1 + eps)|z_j| for the variables
        eps = max(eps, _norm_ratio(x, PX)[1] - 1.0, _norm_ratio(v, PV)[1] - 1.0)
        nx = float(np.sqrt(np.max(np.einsum("ij,ij->i", x, x))))
        nv = float(np.sqrt(np.max(np.einsum("ij,ij->i", v, v))))
        speed = max(nv, float(np.sqrt(np.max(np.einsum("ij,ij->i", W, W)))))
        self.rows.append((t, eps, max(nx, nv), rx[2], rv[2], speed))

    def bounds(self) -> dict:
        """``paper_bound`` (eq. (2.18)) and ``paper_bound_max`` (√2 × eq. (2.11)) per saved step."""
        if not self.rows:
            return {"paper_bound": np.zeros(0), "paper_bound_max": np.zeros(0)}
        a = np.array(self.rows, dtype=float)
        run = np.maximum.accumulate
        t = a[:, 0]
        eps, alpha, X, V, speed = (run(a[:, i]) for i in range(1, 6))
        kappa = self.plan.kappa
        out_max = np.empty(len(t))
        for i in range(len(t)):
            consts = [effect_constants(e, coef_sum=kappa, speed=float(speed[i]),
                                       diam_x=float(X[i]), diam_v=float(V[i]))
                      for e in self.scene.effects]
            L = sum(c.L for c in consts)
            Lp = max(1.0, sum(c.Lp for c in consts))
            Lpp = sum(c.Lpp for c in consts)
            inner = L + alpha[i] * Lpp
            A = Lp + 2.0 * (1.0 + eps[i]) * inner
            B = 2.0 * alpha[i] * (1.0 + eps[i]) * inner
            with np.errstate(over="ignore", invalid="ignore"):
                val = eps[i] * t[i] * B * np.exp(t[i] * A) if t[i] > 0 else 0.0
            out_max[i] = math.sqrt(2.0) * val
        if self.cs is None:
            ls = np.full(len(t), np.nan)
        else:
            G, lip = kappa * self.cs.sup_norm(), kappa * self.cs.lipschitz()
            ls = np.empty(len(t))
            for i in range(len(t)):
                Am = np.array([[0.0, 1.0], [2.0 * (1.0 + eps[i]) * lip * V[i], 2.0 * G]])
                nrm = float(np.linalg.norm(Am, 2))
                with np.errstate(over="ignore", invalid="ignore"):
                    ls[i] = eps[i] * (1.0 + eps[i]) * t[i] * lip * V[i] * X[i] * np.exp(t[i] * nrm)
        return {"paper_bound": ls, "paper_bound_max": out_max}
