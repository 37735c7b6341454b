"""Result objects of :mod:`kinred.distance`."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["W1Result", "SlicedW1Result"]


@dataclass(frozen=True, repr=False)
class W1Result:
    """The Wasserstein-1 distance between two measures and how it was obtained.

    An exact result *is* the distance: ``float(r)`` and ``r.value`` give it. A result with
    ``exact=False`` is a certified bracket ``lower ≤ W1 ≤ upper`` and never passes as a
    distance: ``float(r)`` raises :class:`~kinred.errors.InvalidInput` naming the bracket, its
    repr shows ``W1 in [lower, upper]``, and its centre is asked for by name,
    :attr:`midpoint` (``r.value`` holds the same midpoint, for code that checks ``exact``).

    Attributes
    ----------
    value : float
        The distance when ``exact``; otherwise the midpoint of the certified bracket
        ``[lower, upper]`` (so ``|W1 − value| ≤ (upper − lower)/2``; prefer :attr:`midpoint`).
    method : str
        The method that produced the numbers: ``"exact"``, ``"exact-lazy"``, ``"sparse"``,
        ``"exact-1d"``, ``"product-l1"`` or ``"bracket"`` (``"auto"`` is resolved to one of
        these).
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
    info : dict
        How it was obtained, for ``method="sparse"``: ``iterations``, ``edges``,
        ``seconds`` (and the time of each phase); empty otherwise.

    Examples
    --------
    >>> r = W1Result(1.0, "exact", True, 1.0, 1.0, (2, 2), "POT emd2")
    >>> float(r), r.width
    (1.0, 0.0)
    >>> b = W1Result(1.5, "bracket", False, 1.0, 2.0, (9, 9), "a bracket")
    >>> b
    W1Result(W1 in [1, 2], not exact, method='bracket', n_atoms=(9, 9))
    >>> b.midpoint
    1.5
    """

    value: float
    method: str
    exact: bool
    lower: float
    upper: float
    n_atoms: tuple
    note: str
    metric: str = "euclidean"
    info: dict = field(default_factory=dict, compare=False, hash=False)

    @property
    def width(self) -> float:
        """Width ``upper − lower`` of the certified bracket (0 when exact)."""
        return float(self.upper - self.lower)

    @property
    def midpoint(self) -> float:
        """Centre ``(lower + upper)/2`` of the bracket (the value itself when exact)."""
        return float(self.value) if self.exact else 0.5 * (float(self.lower) + float(self.upper))

    def __float__(self) -> float:
        if not self.exact:
            from ..errors import InvalidInput

            raise InvalidInput(
                f"float() of a W1Result that is not exact: W1 is only known to lie in "
                f"[{self.lower:.17g}, {self.upper:.17g}] (method={self.method!r}); use "
                ".lower/.upper, or .midpoint if the centre of the bracket is what you want")
        return float(self.value)

    def __repr__(self) -> str:
        if self.exact:
            head = f"W1 = {self.value:.17g}"
        else:
            head = f"W1 in [{self.lower:.17g}, {self.upper:.17g}], not exact"
        metric = "" if self.metric == "euclidean" else f", metric={self.metric!r}"
        return f"{type(self).__name__}({head}, method={self.method!r}, n_atoms={self.n_atoms}{metric})"


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
