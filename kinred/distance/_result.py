"""Result objects of :mod:`kinred.distance`."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["W1Result", "SlicedW1Result"]


@dataclass(frozen=True)
class W1Result:
    """The Wasserstein-1 distance between two measures and how it was obtained.

    Attributes
    ----------
    value : float
        The distance when ``exact``; otherwise the midpoint of the certified bracket
        ``[lower, upper]`` (so ``|W1 − value| ≤ (upper − lower)/2``).
    method : str
        The method that produced the numbers: ``"exact"``, ``"exact-lazy"``, ``"exact-1d"``,
        ``"product-l1"`` or ``"bracket"`` (``"auto"`` is resolved to one of these).
    exact : bool
        True when ``value`` is the distance up to round-off (or quadrature tolerance) for the
        ground metric ``metric``.
    lower, upper : float
        Certified bounds ``lower ≤ W1 ≤ upper`` (a bracket's ends are widened by 1e-12
        relative to cover floating-point round-off); both equal ``value`` when ``exact``.
    n_atoms : tuple of (int or None, int or None)
        Atom counts of the two measures; ``None`` for a continuous (non-atomic) measure.
    note : str
        What was done, in one or two sentences (which solver, which bounds won).
    metric : str
        Ground metric of the distance: ``"euclidean"`` (the paper's W1, eq. (4.5))
        or ``"l1"`` (the ℓ1 ground cost of ``method="product-l1"``, an upper
        bound for the Euclidean W1).

    Examples
    --------
    >>> r = W1Result(1.0, "exact", True, 1.0, 1.0, (2, 2), "POT emd2")
    >>> float(r), r.width
    (1.0, 0.0)
    """

    value: float
    method: str
    exact: bool
    lower: float
    upper: float
    n_atoms: tuple
    note: str
    metric: str = "euclidean"

    @property
    def width(self) -> float:
        """Width ``upper − lower`` of the certified bracket (0 when exact)."""
        return float(self.upper - self.lower)

    def __float__(self) -> float:
        return float(self.value)


@dataclass(frozen=True)
class SlicedW1Result:
    """The sliced Wasserstein-1 distance, a *different* distance from W1.

    .. math:: SW_1(\\mu,\\nu) = \\int_{S^{d-1}} W_1(\\theta\\#\\mu, \\theta\\#\\nu)\\,d\\sigma(\\theta)
              \\le W_1(\\mu,\\nu).

    Attributes
    ----------
    value : float
        Monte Carlo estimate of :math:`SW_1` (mean over random unit directions).
    stderr : float
        Standard error of that mean.
    n_projections : int
        Number of directions drawn.
    note : str
        What was done.
    """

    value: float
    stderr: float
    n_projections: int
    note: str

    def __float__(self) -> float:
        return float(self.value)
