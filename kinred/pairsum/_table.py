r"""Tabulated radial kernels for the compiled pair passes: one table lookup instead of the
kernel's closed form.

The near part of a NUFFT split (:mod:`kinred.pairsum._nearfield`), ``φ_N(s) = φ(s) − φ_F(s)``
on ``0 ≤ s < ε_I``, costs two exponentials, two square roots, a division and an ``erfc`` per
pair evaluated directly (about 50 ns per pair and thread: the near pairs were 85 % of a
right-hand side of the 2-D D'Orsogna ring at N = 2·10⁴). A piecewise cubic of the same
function costs a square root, four loads and a Horner step (about 4 ns), whatever the
kernel: a sum of kernels or a plain callable too.

Representation. On ``m`` equal intervals ``[ih, (i + 1)h)`` of ``[0, R]`` the function
``g`` is interpolated by the cubic through its values at the four Chebyshev points of the
interval (``g(s) ≈ Σₖ C[i, k] wᵏ``, ``w = s/h − i ∈ [0, 1)``), where ``g = φ`` for a kernel
bounded at 0, and ``g(s) = s·φ(s)`` (then ``φ = g/s``) for a kernel with a ``1/s`` cusp
(Morse with ``soft = 0``: ``s·φ(s)`` is smooth, so the *relative* error stays small near 0).
``s = 0`` exactly takes ``φ(0)`` as the kernel defines it (0 where it is not finite).

Accuracy, measured not assumed. ``m`` doubles from :data:`M_MIN` until the table is within
``atol + rtol·|φ(s)|`` of the kernel at seven points of every interval (the Chebyshev
interpolant's error peaks between its nodes, and the test points sit between them), with
``atol = rtol·κ`` from the caller (:data:`TABLE_FACTOR` × the tolerance the backend sets for
its kernel values); no table (direct evaluation) when :data:`M_MAX` intervals do not reach
it, or when the kernel is not finite on ``(0, R]``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["Table", "tabulate", "evaluate", "TABLE_FACTOR"]

#: The table's error budget as a fraction of the accuracy the backend asks of its kernel
#: values (``tol·κ`` per pair): it adds at most 1 % to the error of the sums.
TABLE_FACTOR = 0.01
#: Intervals: from ``M_MIN``, doubled up to ``M_MAX`` (``4·8·M_MAX`` bytes: 4 MiB).
M_MIN = 256
M_MAX = 2 ** 17

# Chebyshev points of [0, 1] and the inverse Vandermonde matrix of the cubic through them.
_NODES = 0.5 * (1.0 - np.cos(np.pi * (np.arange(4) + 0.5) / 4.0))
_INV = np.linalg.inv(np.vander(_NODES, 4, increasing=True))
# the test points of an interval (seven, distinct): its start, midway between the ends and
# the outer nodes and between consecutive nodes, and just before its end (1 − 2⁻¹⁰: a
# distinct double in the interval for every m ≤ M_MAX)
_TESTS = np.sort(np.r_[0.0, 0.5 * _NODES[0], 0.5 * (_NODES[:-1] + _NODES[1:]),
                       0.5 * (1.0 + _NODES[-1]), 1.0 - 2.0 ** -10])


@dataclass(frozen=True, eq=False)
class Table:
    """A tabulated kernel on ``[0, R]``: ``C`` of shape ``(m, 4)``, ``inv_h = m/R`` (an ``s``
    whose ``s·inv_h`` rounds to ``m`` or beyond stays on the last cubic, ``w`` slightly above
    1), ``singular`` (``C`` tabulates ``s·φ``), ``at_zero = φ(0)`` (0 where the kernel is not
    finite at 0, Morse's convention for its cusp), the measured ``error`` relative to the
    budget (≤ 1), and ``m``."""

    C: np.ndarray
    inv_h: float
    singular: bool
    at_zero: float
    error: float
    m: int

    @property
    def params(self) -> np.ndarray:
        """``(inv_h, singular, φ(0))`` as the compiled pass reads them."""
        return np.array([self.inv_h, 1.0 if self.singular else 0.0, self.at_zero])


def _coefficients(g, R: float, m: int) -> np.ndarray:
    h = R / m
    s = (np.arange(m)[:, None] + _NODES[None, :]) * h
    return g(s.ravel()).reshape(m, 4) @ _INV.T


def evaluate(table: Table, s: np.ndarray) -> np.ndarray:
    """The table at distances ``0 ≤ s < R`` (numpy twin of the compiled lookup)."""
    s = np.asarray(s, dtype=np.float64)
    u = s * table.inv_h
    i = np.minimum(u.astype(np.int64), table.C.shape[0] - 1)
    w = u - i
    C = table.C
    val = ((C[i, 3] * w + C[i, 2]) * w + C[i, 1]) * w + C[i, 0]
    if table.singular:
        with np.errstate(divide="ignore", invalid="ignore"):
            val = val / s
    return np.where(s > 0.0, val, table.at_zero)


def tabulate(phi, R: float, rtol: float, kappa: float) -> Table | None:
    """The table of ``φ`` (``s ↦ φ(s)``, vectorized) on ``[0, R]`` within
    ``kappa·rtol + rtol·|φ|`` (module notes), or None."""
    if not (R > 0.0 and np.isfinite(R) and rtol > 0.0 and kappa > 0.0):
        return None
    with np.errstate(all="ignore"):
        at_zero = float(np.asarray(phi(np.zeros(1)), dtype=np.float64)[0])
    if not np.isfinite(at_zero):
        at_zero = 0.0
    atol = rtol * kappa
    with np.errstate(all="ignore"):
        near0, near1 = np.abs(np.asarray(phi(np.array([1e-6 * R, 1e-3 * R])), dtype=float))
    # a 1/s cusp grows by 1000 between the two: try s·φ first
    order = (True, False) if near0 > 100.0 * near1 else (False, True)
    for singular in order:
        def g(s, singular=singular):
            with np.errstate(all="ignore"):
                v = np.asarray(phi(s), dtype=np.float64) * np.ones_like(s)
                return s * v if singular else v
        m = M_MIN
        while m <= M_MAX:
            C = _coefficients(g, R, m)
            if not np.all(np.isfinite(C)):
                break
            t = ((np.arange(m)[:, None] + _TESTS[None, :]) * (R / m)).ravel()
            t = t[(t > 0.0) & (t < R)]
            with np.errstate(all="ignore"):
                exact = np.asarray(phi(t), dtype=np.float64) * np.ones_like(t)
            tab = Table(C, m / R, singular, at_zero, 0.0, m)
            got = evaluate(tab, t)
            err = float(np.max(np.abs(got - exact) / (atol + rtol * np.abs(exact))))
            if not np.isfinite(err):
                break
            if err <= 1.0:
                return replace(tab, error=err)
            m *= 2
    return None
