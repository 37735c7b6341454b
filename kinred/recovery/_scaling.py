"""The one scaling of a batched ℓ1 problem: what the solver iterates on, and the way back.

Problems (3.16) of the paper and the LASSO are homogeneous: with ``A → aA``, ``y → by``,
``η → bη``, ``λ → abλ`` the solution maps as ``z → (b/a) z``. The solver uses this twice,
and :class:`Scaling` is the only place that knows how:

1. **Powers of two, whole problem** (exact: no rounding): ``A·2^−e_A`` and ``Y·2^−e_Y`` have
   entries below 1, so that ``AAᵀ``, norms and residuals neither overflow nor underflow
   (``η·2^−e_Y``, ``λ·2^−(e_A+e_Y)``). Back: ``z·2^(e_Y−e_A)``, residuals ``·2^e_Y``,
   objectives ``·2^(e_Y−e_A)`` (ℓ1 of BPDN) or ``·2^(2e_Y)`` (LASSO).
2. **Per column, normalized**: ``Â = A ω/‖A‖₂`` (spectral norm ``ω``), ``ŷ = y/‖y‖``,
   ``η̂ = η/‖y‖``, ``λ̂ = λω/(‖A‖‖y‖)``, so that one starting penalty suits every column.
   Back: ``z = ẑ·‖y‖ω/‖A‖`` (the column's ``back`` factor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Spectral norm ``ω`` of the normalized matrix ``Â``: weighs the constraint ``v = Âz``
#: against ``u = z``.
OMEGA = 10.0


def _exponent(X) -> int:
    """``e`` with ``max |X| · 2^−e`` in ``[1/2, 1)`` (0 for ``X = 0``)."""
    top = float(np.max(np.abs(X), initial=0.0))
    return int(np.frexp(top)[1]) if top > 0 else 0


@dataclass(frozen=True)
class Scaling:
    """The two scalings of one solve (``form`` ``"bpdn"`` or ``"lasso"``): see the module.

    Examples
    --------
    >>> A, Y = np.array([[3.0, 0.0], [0.0, 1.0]]), np.array([[6.0], [0.0]])
    >>> s, A2, Y2, p2 = Scaling.of(A, Y, np.array([0.0]), "bpdn")
    >>> (s.ea, s.ey), float(A2.max()), float(Y2.max())
    ((2, 3), 0.75, 0.75)
    >>> s.original_z(np.array([[0.25], [0.0]]))[:, 0].tolist()   # z = 2^(ey−ea)·z₂
    [0.5, 0.0]
    """

    form: str
    ea: int             # e_A: A is solved as A·2^−e_A
    ey: int             # e_Y: Y is solved as Y·2^−e_Y
    param: np.ndarray   # η or λ as the caller gave them

    @classmethod
    def of(cls, A, Y, param, form: str):
        """``(scaling, A·2^−e_A, Y·2^−e_Y, param scaled alike)``: layer 1."""
        ea, ey = _exponent(A), _exponent(Y)
        scaled = np.ldexp(param, -ey if form == "bpdn" else -ea - ey)
        return cls(form, ea, ey, param), np.ldexp(A, -ea), np.ldexp(Y, -ey), scaled

    # layer 2: per column ---------------------------------------------------------------
    @staticmethod
    def normalized_matrix(A, norm_A: float) -> np.ndarray:
        """``Â = A ω/‖A‖₂``."""
        return A * (OMEGA / norm_A)

    def normalized_param(self, param, ynorm, norm_A: float) -> np.ndarray:
        """``η̂ = η/‖y‖`` (BPDN) or ``λ̂ = λω/(‖A‖‖y‖)`` (LASSO), per column."""
        if self.form == "bpdn":
            return param / ynorm
        return param * OMEGA / (norm_A * ynorm)

    @staticmethod
    def back(ynorm, norm_A: float) -> np.ndarray:
        """Per column ``‖y‖ω/‖A‖``: ``z = ẑ·back``."""
        return ynorm * OMEGA / norm_A

    @staticmethod
    def from_normalized(z_hat, back) -> np.ndarray:
        """Rows ``ẑ (n, d)`` of normalized solutions → columns ``(d, n)`` of layer 1."""
        return (z_hat * back[:, None]).T

    # layer 1: the way back to the caller's numbers -------------------------------------
    def original_z(self, Z) -> np.ndarray:
        """``Z·2^(e_Y−e_A)`` (inf where the solution leaves the float64 range)."""
        with np.errstate(over="ignore"):
            return np.ldexp(Z, self.ey - self.ea)

    def original_residual(self, residual) -> np.ndarray:
        """``‖Az − y‖·2^e_Y``."""
        return np.ldexp(residual, self.ey)

    def original_objective(self, residual, l1, param, infeasible) -> np.ndarray:
        """BPDN: ``‖z‖₁·2^(e_Y−e_A)`` (NaN where infeasible); LASSO:
        ``(½‖Az − y‖² + λ‖z‖₁)·2^(2e_Y)`` — from layer-1 ``residual``, ``l1``, ``param``."""
        with np.errstate(over="ignore"):
            if self.form == "lasso":
                return np.ldexp(0.5 * residual**2 + param * l1, 2 * self.ey)
            return np.ldexp(np.where(~infeasible, l1, np.nan), self.ey - self.ea)
