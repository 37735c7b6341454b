r"""Observables of agent configurations: fluctuations, centres, the flocking verdict.

The fluctuations of §3.4.1 of the paper (the flocking theorem before Fig. 1):

.. math::
    \Lambda(t) = \sum_i w_i \|x_i - x_c\|^2, \qquad \Gamma(t) = \sum_i w_i \|v_i - v_c\|^2,
    \qquad x_c = \sum_i w_i x_i,\; v_c = \sum_i w_i v_i,

with ``w_i = 1/N`` by default. They are computed as means of squared deviations from a
compensated centre (first pass ``m₁ = Σ wᵢ zᵢ``, correction ``r = Σ wᵢ (zᵢ − m₁)``, deviations
``(zᵢ − m₁) − r``), never as ``E|z|² − |E z|²``: values near 1e-30 next to centres of size
1 keep full relative accuracy.
"""

from __future__ import annotations

import numpy as np

from ._validate import as_array, as_float, as_weights
from .errors import InvalidInput

__all__ = ["gamma", "lambda_", "centre", "mean_velocity", "fluctuation", "flocking_verdict",
           "relative_error"]


def _prep(z, weights, name):
    z = as_array(z, name, ndim=2)
    if z.shape[0] < 1:
        raise InvalidInput(f"{name} must have at least one row, got shape {z.shape}")
    w = as_weights(weights, "weights", z.shape[0])
    return z, w


def _deviations(z, w):
    m1 = w @ z
    dev = z - m1
    r = w @ dev
    dev -= r
    return dev


def fluctuation(z, weights=None) -> float:
    r"""``Σᵢ wᵢ ‖zᵢ − z_c‖²`` for ``z (N, d)`` (mean of squared deviations, compensated centre).

    Examples
    --------
    >>> fluctuation(np.array([[0.0], [2.0]]))
    1.0
    """
    z, w = _prep(z, weights, "z")
    dev = _deviations(z, w)
    return float(w @ np.einsum("ij,ij->i", dev, dev))


def gamma(v, weights=None) -> float:
    r"""Velocity fluctuation ``Γ = Σᵢ wᵢ ‖vᵢ − v_c‖²`` (§3.4.1 of the paper).

    Parameters
    ----------
    v : (N, d) array_like
    weights : (N,) array_like, optional
        Probability weights (default ``1/N``).

    Examples
    --------
    >>> gamma(np.array([[1.0, 0.0], [-1.0, 0.0]]))
    1.0
    >>> gamma(np.array([[1.0 + 1e-15], [1.0 - 1e-15]])) > 0
    True
    """
    z, w = _prep(v, weights, "v")
    dev = _deviations(z, w)
    return float(w @ np.einsum("ij,ij->i", dev, dev))


def lambda_(x, weights=None) -> float:
    r"""Position fluctuation ``Λ = Σᵢ wᵢ ‖xᵢ − x_c‖²`` (§3.4.1 of the paper).

    Examples
    --------
    >>> lambda_(np.array([[0.0, 0.0], [0.0, 2.0]]))
    1.0
    """
    z, w = _prep(x, weights, "x")
    dev = _deviations(z, w)
    return float(w @ np.einsum("ij,ij->i", dev, dev))


def centre(x, weights=None) -> np.ndarray:
    """Centre of mass ``x_c = Σᵢ wᵢ xᵢ`` (d,), compensated.

    Examples
    --------
    >>> centre(np.array([[0.0, 1.0], [2.0, 3.0]]))
    array([1., 2.])
    """
    z, w = _prep(x, weights, "x")
    m1 = w @ z
    return m1 + w @ (z - m1)


def mean_velocity(v, weights=None) -> np.ndarray:
    """Mean velocity ``v_c = Σᵢ wᵢ vᵢ`` (d,), conserved by Cucker–Smale.

    Examples
    --------
    >>> mean_velocity(np.array([[1.0], [3.0]]))
    array([2.])
    """
    z, w = _prep(v, weights, "v")
    m1 = w @ z
    return m1 + w @ (z - m1)


def flocking_verdict(gamma_T: float, yes_below: float = 1e-10, no_above: float = 1e-3) -> str:
    """The paper's heuristic rule (§3.4.1): ``"pos"`` if ``Γ(T) < yes_below``, ``"neg"`` if
    ``Γ(T) > no_above``, otherwise ``"n/a"`` (undecided).

    Examples
    --------
    >>> flocking_verdict(1e-29), flocking_verdict(0.6), flocking_verdict(1e-5)
    ('pos', 'neg', 'n/a')
    """
    g = as_float(gamma_T, "gamma_T", low=0.0)
    lo = as_float(yes_below, "yes_below", low=0.0)
    hi = as_float(no_above, "no_above", low=lo)
    if g < lo:
        return "pos"
    if g > hi:
        return "neg"
    return "n/a"


def relative_error(a, b, *, floor: float = 0.0) -> float:
    """``max |a − b| / max(max |b|, floor)`` (``0`` when both are zero).

    Examples
    --------
    >>> relative_error([1.0, 2.0], [1.0, 2.5])
    0.2
    """
    a = as_array(a, "a", finite=False)
    b = as_array(b, "b", finite=False)
    if a.shape != b.shape:
        raise InvalidInput(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    floor = as_float(floor, "floor", low=0.0)
    num = float(np.max(np.abs(a - b))) if a.size else 0.0
    den = max(float(np.max(np.abs(b))) if b.size else 0.0, floor)
    if den == 0.0:
        return 0.0 if num == 0.0 else float("inf")
    return num / den
