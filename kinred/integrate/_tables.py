r"""Explicit Runge–Kutta methods as coefficient tables (scipy ``_ivp/rk.py`` style).

A stage ``s`` evaluates ``k_s = f(t + C_s h, y + h Σ_{j<s} A_{sj} k_j)``; the step is
``y + h Σ_s B_s k_s``. Embedded pairs also carry ``E`` (the difference of the two weight
vectors) for the local error estimate ``h Σ_s E_s k_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RKTable", "EULER", "HEUN", "RK4", "DOPRI5", "BS32", "TABLES"]


@dataclass(frozen=True)
class RKTable:
    """Butcher table of an explicit Runge–Kutta method.

    Attributes
    ----------
    name : str
    C : (s,) ndarray
        Nodes.
    A : (s, s) ndarray
        Strictly lower-triangular stage matrix.
    B : (s,) ndarray
        Weights of the propagated solution.
    order : int
        Order of the propagated solution.
    E : (s,) ndarray or None
        Error weights (propagated minus embedded) of an embedded pair.
    error_order : int or None
        Order of the embedded solution.
    fsal : bool
        First same as last (the last stage is ``f`` at the new point).

    Examples
    --------
    >>> float(RK4.B.sum()), RK4.order
    (1.0, 4)
    """

    name: str
    C: np.ndarray
    A: np.ndarray
    B: np.ndarray
    order: int
    E: np.ndarray | None = None
    error_order: int | None = None
    fsal: bool = False

    @property
    def stages(self) -> int:
        return len(self.B)


EULER = RKTable("euler", np.array([0.0]), np.array([[0.0]]), np.array([1.0]), 1)
HEUN = RKTable("heun", np.array([0.0, 1.0]), np.array([[0.0, 0.0], [1.0, 0.0]]),
               np.array([0.5, 0.5]), 2)
RK4 = RKTable(
    "rk4",
    np.array([0.0, 0.5, 0.5, 1.0]),
    np.array([[0.0, 0, 0, 0], [0.5, 0, 0, 0], [0, 0.5, 0, 0], [0, 0, 1.0, 0]]),
    np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
    4,
)

# Dormand–Prince 5(4) (as in scipy.integrate.RK45), FSAL: 7 stages, the 7th is f(y_new).
_DP_A = np.array([
    [0, 0, 0, 0, 0, 0, 0],
    [1 / 5, 0, 0, 0, 0, 0, 0],
    [3 / 40, 9 / 40, 0, 0, 0, 0, 0],
    [44 / 45, -56 / 15, 32 / 9, 0, 0, 0, 0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0, 0, 0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0, 0],
    [35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0],
])
_DP_B = np.array([35 / 384, 0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0])
_DP_Bhat = np.array([5179 / 57600, 0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100,
                     1 / 40])
DOPRI5 = RKTable("rk45", np.array([0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1, 1]), _DP_A, _DP_B, 5,
                 E=_DP_B - _DP_Bhat, error_order=4, fsal=True)

# Bogacki–Shampine 3(2), FSAL.
_BS_A = np.array([[0, 0, 0, 0], [1 / 2, 0, 0, 0], [0, 3 / 4, 0, 0], [2 / 9, 1 / 3, 4 / 9, 0]])
_BS_B = np.array([2 / 9, 1 / 3, 4 / 9, 0])
_BS_Bhat = np.array([7 / 24, 1 / 4, 1 / 3, 1 / 8])
BS32 = RKTable("rk23", np.array([0, 1 / 2, 3 / 4, 1]), _BS_A, _BS_B, 3, E=_BS_B - _BS_Bhat,
               error_order=2, fsal=True)

TABLES = {"euler": EULER, "heun": HEUN, "rk4": RK4, "rk45": DOPRI5, "rk23": BS32}
