"""One-dimensional measures: scipy-backed laws (optionally truncated), uniform, empirical."""

from __future__ import annotations

import math

import numpy as np

from .._validate import as_array, as_float
from ..errors import InvalidInput
from ._base import Atomic, Measure

__all__ = ["Univariate", "Uniform", "Empirical1D"]


def _levels(u, name: str = "u") -> np.ndarray:
    u = as_array(u, name)
    if u.size and (np.min(u) < 0.0 or np.max(u) > 1.0):
        bad = u[(u < 0) | (u > 1)].flat[0]
        raise InvalidInput(f"{name} must lie in [0, 1] (probability levels), got {bad}")
    return u


class Univariate(Measure):
    """A 1-D law given by a frozen :mod:`scipy.stats` continuous distribution, on a compact support.

    The paper works with compactly supported measures (§4.4, :math:`\\mu\\in\\mathcal P_c`):
    a law whose support is unbounded must be truncated explicitly with ``support=(a, b)``,
    which gives the renormalized restriction

    .. math:: F_{[a,b]}(x) = \\frac{F(x) - F(a)}{F(b) - F(a)},\\qquad
              F_{[a,b]}^{-1}(u) = F^{-1}\\bigl(F(a) + u\\,(F(b) - F(a))\\bigr).

    In the upper tail these are evaluated through the survival function (``sf``/``isf``) so
    that far-tail truncations keep their accuracy; a truncated normal uses scipy's own
    ``truncnorm``.

    Parameters
    ----------
    dist : frozen scipy.stats continuous distribution
        E.g. ``scipy.stats.beta(2, 3)``.
    support : (a, b), optional
        Truncation interval; required when ``dist`` has unbounded support. It is
        intersected with the distribution's own support.

    Attributes
    ----------
    dist : the (possibly replaced, for ``truncnorm``) frozen distribution
    support : tuple of two floats ``(a, b)`` -- finite, ``a < b``
    truncated : bool
    dim : int -- always 1

    Raises
    ------
    InvalidInput
        Unbounded support without ``support``; a support interval outside the law's support
        or carrying no probability mass; a distribution that is not a frozen continuous one.

    Examples
    --------
    >>> from scipy import stats
    >>> mu = Univariate(stats.beta(2, 2))
    >>> mu.support, float(mu.ppf(0.5))
    ((0.0, 1.0), 0.5)
    >>> nu = Univariate(stats.norm(), support=(-1, 1))
    >>> round(float(nu.cdf(0.0)), 12), nu.support_widths()
    (0.5, array([2.]))
    """

    dim = 1

    def __init__(self, dist, support=None):
        from scipy import stats  # imported here: scipy.stats takes ~1 s, half of `import kinred`

        if not (hasattr(dist, "dist") and isinstance(getattr(dist, "dist"), stats.rv_continuous)):
            raise InvalidInput(
                "dist must be a frozen scipy.stats continuous distribution such as "
                f"scipy.stats.beta(2, 3), got {dist!r}"
            )
        a0, b0 = (float(v) for v in dist.support())
        self.truncated = False
        self._generic_trunc = False
        if math.isnan(a0) or math.isnan(b0) or not a0 < b0:
            raise InvalidInput(
                f"dist {dist.dist.name} has no support: dist.support() = ({a0}, {b0}); its "
                f"parameters are invalid (args {dist.args}, kwds {dist.kwds}; e.g. scale = 0)")
        if support is None:
            if not (np.isfinite(a0) and np.isfinite(b0)):
                raise InvalidInput(
                    f"dist {dist.dist.name} has unbounded support ({a0}, {b0}); the paper assumes "
                    "compactly supported measures (section 4.4): pass support=(a, b) to truncate "
                    "and renormalize it"
                )
            a, b = a0, b0
        else:
            s = as_array(support, "support", shape=(2,))
            a, b = float(s[0]), float(s[1])
            if not a < b:
                raise InvalidInput(f"support must be (a, b) with a < b, got ({a}, {b})")
            a, b = max(a, a0), min(b, b0)
            if not a < b:
                raise InvalidInput(
                    f"support {tuple(float(v) for v in s)} does not overlap the support "
                    f"({a0}, {b0}) of {dist.dist.name}"
                )
            if a > a0 or b < b0:
                self.truncated = True
                if dist.dist.name == "norm":
                    _, loc, scale = dist.dist._parse_args(*dist.args, **dist.kwds)
                    dist = stats.truncnorm((a - loc) / scale, (b - loc) / scale, loc=loc, scale=scale)
                else:
                    self._generic_trunc = True
        self.dist = dist
        self.support = (a, b)
        if self._generic_trunc:
            pa, pb = float(dist.cdf(a)), float(dist.cdf(b))
            sa, sb = float(dist.sf(a)), float(dist.sf(b))
            mass = (pb - pa) if pa < 0.5 else (sa - sb)
            if not (mass > 0 and np.isfinite(mass)):
                raise InvalidInput(
                    f"support ({a}, {b}) carries no probability mass under {dist.dist.name} "
                    "(numerically zero); choose an interval where the law lives"
                )
            self._pa, self._pb, self._sa, self._sb, self._mass = pa, pb, sa, sb, mass

    # -- distribution functions -------------------------------------------------------------
    def ppf(self, u) -> np.ndarray:
        """Quantile function ``F⁻¹(u)`` for levels ``u ∈ [0, 1]`` (values in ``[a, b]``)."""
        u = _levels(u)
        a, b = self.support
        if not self._generic_trunc:
            x = self.dist.ppf(u)
        else:
            t = self._pa + u * self._mass
            lower = t <= 0.5
            x = np.empty_like(u, dtype=np.float64)
            x[lower] = self.dist.ppf(t[lower])
            x[~lower] = self.dist.isf(self._sb + (1.0 - u[~lower]) * self._mass)
            x = np.where(u == 0, a, np.where(u == 1, b, x))
        return np.clip(np.asarray(x, dtype=np.float64), a, b)

    def cdf(self, x) -> np.ndarray:
        """Distribution function ``F(x) = μ((−∞, x])``."""
        x = as_array(x, "x", finite=False)
        if np.any(np.isnan(x)):
            raise InvalidInput("x must not contain NaN")
        a, b = self.support
        xc = np.clip(x, a, b)
        if not self._generic_trunc:
            F = self.dist.cdf(xc)
        else:
            lower = self.dist.cdf(xc) <= 0.5
            F = np.where(
                lower,
                (self.dist.cdf(xc) - self._pa) / self._mass,
                1.0 - (self.dist.sf(xc) - self._sb) / self._mass,
            )
        F = np.where(x < a, 0.0, np.where(x >= b, 1.0, F))
        return np.clip(np.asarray(F, dtype=np.float64), 0.0, 1.0)

    def _sample(self, n, rng):
        return self.ppf(rng.random(n))[:, None]

    def support_box(self):
        a, b = self.support
        return np.array([a]), np.array([b])

    def __repr__(self):
        name = self.dist.dist.name
        return f"Univariate({name}{self.dist.args or ''}, support={self.support})"


class Uniform(Univariate):
    """Uniform law on ``[a, b]`` (closed-form quantiles ``a + u (b − a)``).

    Examples
    --------
    >>> mu = Uniform(0.0, 2.0)
    >>> mu.ppf([0.0, 0.25, 1.0])
    array([0. , 0.5, 2. ])
    """

    def __init__(self, a: float = 0.0, b: float = 1.0):
        a = as_float(a, "a")
        b = as_float(b, "b")
        if not a < b:
            raise InvalidInput(f"Uniform needs a < b, got a={a}, b={b} (use Dirac for a point mass)")
        from scipy import stats

        super().__init__(stats.uniform(loc=a, scale=b - a))
        self.a, self.b = a, b
        self.support = (a, b)

    def ppf(self, u) -> np.ndarray:
        u = _levels(u)
        return np.clip(self.a + u * (self.b - self.a), self.a, self.b)

    def cdf(self, x) -> np.ndarray:
        x = as_array(x, "x", finite=False)
        return np.clip((x - self.a) / (self.b - self.a), 0.0, 1.0)

    def __repr__(self):
        return f"Uniform({self.a}, {self.b})"


class Empirical1D(Atomic):
    """A discrete measure on ℝ given by values and weights; quantiles are step functions.

    Zero-weight values are dropped; the values are stored sorted.

    .. math:: F^{-1}(u) = \\min\\{x_i : F(x_i) \\ge u\\}.

    Parameters
    ----------
    values : (N,) array_like
    weights : (N,) array_like, optional -- probability weights, uniform by default.

    Examples
    --------
    >>> mu = Empirical1D([3.0, 1.0, 2.0])
    >>> mu.values, mu.support
    (array([1., 2., 3.]), (1.0, 3.0))
    >>> mu.ppf([0.0, 0.34, 1.0])
    array([1., 2., 3.])
    """

    def __init__(self, values, weights=None):
        v = as_array(values, "values", ndim=1)
        if v.size < 1:
            raise InvalidInput("values must hold at least one value, got an empty array")
        from .._validate import as_weights

        w = as_weights(weights, "weights", v.size)
        keep = w > 0
        v, w = v[keep], w[keep]
        order = np.argsort(v, kind="stable")
        v, w = v[order], w[order] / w.sum()
        super().__init__(v[:, None], w)
        self.values = v
        cum = np.cumsum(w)
        cum[-1] = 1.0
        self._cum = cum
        self.support = (float(v[0]), float(v[-1]))

    def ppf(self, u) -> np.ndarray:
        """Step quantile ``min{xᵢ : F(xᵢ) ≥ u}``."""
        u = _levels(u)
        idx = np.searchsorted(self._cum, u, side="left")
        return self.values[np.minimum(idx, self.values.size - 1)]

    def cdf(self, x) -> np.ndarray:
        """``F(x) = Σ_{xᵢ ≤ x} wᵢ``."""
        x = as_array(x, "x", finite=False)
        idx = np.searchsorted(self.values, x, side="right")
        cum0 = np.concatenate([[0.0], self._cum])
        return cum0[idx]

    def __repr__(self):
        return f"Empirical1D(n_atoms={self.n_atoms}, support={self.support})"
