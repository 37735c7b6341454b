r"""Round-off allowance of the certificates: an *estimate* (labelled so everywhere).

The certificate's inequalities hold for the computed arrays in exact arithmetic; what the
floating-point evaluation of the two Euler steps and of the defect adds is bounded here with
the standard model ``fl(a ∘ b) = (a ∘ b)(1 + δ)``, ``|δ| ≤ u`` (``u = 2⁻⁵³``, or ``2⁻²⁴`` for
the float32 pair stage of ``precision="mixed"``) and ``γₙ = n u/(1 − n u)`` for sums of ``n``
terms, from the magnitudes of the states (per-agent Euclidean norms, maxima over agents) –
then doubled. It is an estimate, not a proof: it trusts the libraries' documented accuracy
(the engine's squared distances to ``1e-12`` relative, kernels to ``1e-13``, BLAS to ``γₙ``).

Per step ``n → n+1`` (``h`` the step, ``Y, W`` the projected run, ``PX, PV`` the projected
high-dimensional state, ``F′`` the projected field; all norms per agent, max over agents):

* positions: the projected update ``Y + h W`` (``u(h|W| + |Y⁺|)``) and the defect
  ``τₓ = PX⁺ − PX − h PV`` formed from three arrays (``2u(|PX⁺| + |PX| + h|PV|)``);
* velocities: the update ``W + h F′(Y, W)`` (``u(h|F′| + |W⁺|)``), the defect
  ``τᵥ = PV⁺ − PV − h F′(PX, PV)`` (``2u(|PV⁺| + |PV| + h|F′(PX, PV)|)``), and ``h`` times the
  rounding of the projected field at both points: per pairwise term
  ``max_i Σⱼ cⱼ ψᵢⱼ · 2 max_j |zⱼ − z̄|`` with ``ψ = γ_{N+4}|φ| + 16u ε_eval + a_s σ``
  (:func:`pass_constants`; ``ε_eval`` the rounding scale of one kernel evaluation, ``σ`` its
  sensitivity to the relative error ``a_s`` of the distances, see
  :mod:`kinred.certify._kernels`), self-propulsion
  ``γ_{k+6}(|a| + 3b|v|²)|v|``, and ``u |F′|`` for the final sums.

Coefficients computed from rounded distances (the slope bounds ``Λ``, the smallest kernel
value) are inflated (deflated) by :data:`COEF_MARGIN`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["U64", "U32", "COEF_MARGIN", "gamma", "row_max", "spread", "pass_constants",
           "step_allowance", "field_rounding"]

#: Unit round-off of float64 and float32.
U64 = 2.0 ** -53
U32 = 2.0 ** -24
#: Relative inflation of coefficients computed from rounded distances (``Λ``, ``λ₂``, ``ρ_L``).
COEF_MARGIN = 1e-9
#: Relative error of the engine's pairwise distances (float64 Gram blocks with the close-pair
#: fix-up; float32 blocks of ``precision="mixed"``).
DIST64 = 1e-12
DIST32 = 1e-3
#: Safety factor on every allowance.
SAFETY = 2.0


def gamma(n: int, u: float = U64) -> float:
    """``γₙ = n u / (1 − n u)`` (Higham, *Accuracy and Stability of Numerical Algorithms*, §3.1).

    Examples
    --------
    >>> gamma(0)
    0.0
    >>> round(gamma(1000) / 1000 / 2.0 ** -53, 9)
    1.0
    """
    nu = n * u
    return nu / (1.0 - nu) if nu < 0.5 else math.inf


def row_max(A: np.ndarray) -> float:
    """``maxᵢ |Aᵢ|`` (Euclidean norms of the rows of an ``(N, k)`` array)."""
    if A.size == 0:
        return 0.0
    return float(np.sqrt(np.max(np.einsum("ij,ij->i", A, A))))


def spread(Z: np.ndarray) -> float:
    """``maxᵢ |Zᵢ − Z̄|`` with the plain mean ``Z̄`` (the engine centres carriers by it)."""
    return row_max(Z - Z.mean(axis=0))


def pass_constants(n: int, mixed: bool) -> tuple[float, float, float]:
    """``(g, a_e, a_s)`` of the pair pass's rounding scales ``ψ = g|φ| + a_e ε_eval + a_s σ``:
    ``g = γ_{N+4}`` (BLAS sums of ``N`` products), ``a_e = 16u`` (one kernel evaluation) and
    ``a_s`` the relative error of the engine's distances (``1e-12``: Gram blocks with the
    close-pair fix-up, see :mod:`kinred.pairsum._kernels`; ``1e-3`` in float32)."""
    u = U32 if mixed else U64
    return gamma(n + 4, u), 16.0 * u, (DIST32 if mixed else DIST64)


def field_rounding(plan, aggs, spreads: dict, speed: float, n: int, k: int, fmax: float,
                   mixed: bool, which: str) -> float:
    """Estimated ``maxᵢ |F̂′ᵢ − F′ᵢ|`` of one projected-field evaluation (see the module notes).

    ``which``: ``"run"`` (at ``(Y, W)``) or ``"true"`` (at ``(PX, PV)``), selecting the pass's
    rounding scales ``Σⱼ cⱼ μᵢⱼ ≥ Σⱼ cⱼ|φᵢⱼ|`` there. ``spreads`` maps ``(which, carrier)`` to
    the carrier spread.
    """
    out = U64 * fmax
    for term, agg in zip(plan.terms, aggs):
        psi = agg.mag_true if which == "true" else agg.mag_run
        out += float(np.max(psi)) * 2.0 * spreads[(which, term.carrier)]
    if plan.has_sp:
        out += gamma(k + 6) * (abs(plan.sp_a) + 3.0 * plan.sp_b * speed ** 2) * speed
    return out


def step_allowance(h: float, *, Y1: float, W0: float, W1: float, PX0: float, PX1: float,
                   PV0: float, PV1: float, dW: float, Fd: float, eng_run: float,
                   eng_true: float) -> tuple[float, float]:
    """``(αₓ, αᵥ)``: the per-step round-off allowance of positions and velocities.

    Arguments are maxima of per-agent norms at the start (``0``) and end (``1``) of the step:
    ``Y1 = max|Y⁺|``, ``W0``, ``W1``, ``PX0``, ``PX1``, ``PV0``, ``PV1``; ``dW = max|F′(Y, W)|``,
    ``Fd = max|F′(PX, PV)|``; ``eng_run``, ``eng_true`` from ``field_rounding`` (this module).

    Examples
    --------
    >>> ax, av = step_allowance(0.1, Y1=1, W0=1, W1=1, PX0=1, PX1=1, PV0=1, PV1=1, dW=1, Fd=1,
    ...                         eng_run=0, eng_true=0)
    >>> bool(0 < ax < 1e-14 and 0 < av < 1e-14)
    True
    """
    u = U64
    ax = u * (h * W0 + Y1) + 2.0 * u * (PX1 + PX0 + h * PV0)
    av = u * (h * dW + W1) + 2.0 * u * (PV1 + PV0 + h * Fd) + h * (eng_run + eng_true)
    return SAFETY * ax, SAFETY * av
