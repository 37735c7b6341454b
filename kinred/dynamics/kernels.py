r"""Interaction kernels: functions of the pairwise distance ``s = ‖xᵢ − xⱼ‖``.

A kernel is any object with ``__call__(s) -> φ(s)`` (vectorized over an ndarray of
distances). Built-in kernels also provide

* ``value_sq(q, out)`` – the fast path: ``φ(√q)`` from squared distances ``q`` into ``out``
  (``out`` may be ``q``), with numpy ufuncs on preallocated blocks;
* ``sup_norm()`` and ``lipschitz()`` – ``‖φ‖∞`` and ``‖φ′‖∞`` on ``[0, ∞)``, the constants that
  enter the bounds (1.2)–(1.4) of the paper;
* ``slope_bound(lo, hi)`` – elementwise an upper bound of ``sup |φ′|`` over ``[lo, hi]``
  (vectorized; exact for Cucker–Smale and Quadratic), the localized Lipschitz constant of the
  mean-value theorem used by the certificates of :mod:`kinred.certify`.

* ``radial_profile()`` – the kernel hook of the :class:`~kinred.pairsum.NUFFT` backend: a
  vectorized callable ``φ(s)`` such that ``r ↦ φ(|r|)`` is smooth (``φ`` an even smooth
  function of ``s``), or None when it is not; see :func:`kinred.pairsum.radial_profile`.
  Cucker–Smale, ``Morse`` with ``soft > 0`` and ``Quadratic`` have one; ``Morse`` with
  ``soft = 0`` (``u(s) ~ 1/s``) returns None.

* ``tail_bound()`` – the kernel hook of the truncating backends (the cell list, the cost
  model of ``pairsum="auto"``): a vectorized non-increasing ``B(s) ≥ |φ(s′)|`` for all
  ``s′ ≥ s``, or None (unknown, the default of kernels without the method); see
  :func:`kinred.pairsum.tail_bound`. Morse declares its exponential tails, Cucker–Smale its
  algebraic one, Quadratic a constant (no decay).

* ``compiled_form()`` – the kernel hook for compiled code: None, or ``(kind, a, b)`` naming
  a closed form of :data:`kinred.pairsum.COMPILED_KINDS` that equals the kernel (Cucker–Smale:
  ``("cs_halfint", G, 2β)`` or ``("cs_pow", G, β)``). The dense backend evaluates such
  kernels inside its compiled strip worker (no Python call per strip, no GIL); a scene whose
  pairwise kernels all have one uses it, any other scene a Python strip loop (same operations).

* ``is_nonnegative()``, ``potential_range()``, ``certificate_form()`` – what the divergence
  guard and the certificates need to know about the kernel (None or absent: unknown); see
  :mod:`kinred.dynamics.hooks`.

Custom kernels without ``value_sq`` still work: the backends evaluate ``kernel(np.sqrt(q))``.

Sign conventions (eq. (3.14) and eq. (4.3)): a
potential ``U`` acts on agent ``i`` by ``−∇_{xᵢ} U(‖xᵢ − xⱼ‖) = u(s)(xⱼ − xᵢ)`` with
``u(s) = U′(s)/s``, so the engine only ever needs the scalar ``u``.
"""

from __future__ import annotations

import math
import threading
from typing import Protocol, runtime_checkable

import numpy as np

from .._validate import as_float
from ..errors import InvalidInput
from ..pairsum import strips as _kernels
from .hooks import CertificateForm

__all__ = ["Kernel", "CuckerSmale", "Morse", "Quadratic"]


def _interval(lo, hi):
    """Validated, broadcast interval ends ``0 <= lo <= hi`` (``hi`` may be ``+inf``)."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    try:
        lo, hi = np.broadcast_arrays(lo, hi)
    except ValueError:
        raise InvalidInput(f"lo and hi must broadcast together, got shapes {np.shape(lo)} and "
                           f"{np.shape(hi)}") from None
    if lo.size:
        if np.isnan(lo).any() or np.isnan(hi).any() or np.isinf(lo).any():
            raise InvalidInput("lo must be finite and hi must not be NaN (hi may be +inf)")
        if np.min(lo) < 0.0:
            raise InvalidInput(f"lo must be >= 0 (distances), got {float(np.min(lo))!r}")
        if np.any(hi < lo):
            i = np.flatnonzero((hi < lo).ravel())[0]
            raise InvalidInput(f"hi must be >= lo elementwise, got lo={lo.ravel()[i]!r} > "
                               f"hi={hi.ravel()[i]!r}")
    return lo, hi


@runtime_checkable
class Kernel(Protocol):
    """Protocol of a pairwise kernel ``φ: [0, ∞) → ℝ``.

    Only ``__call__`` is required; ``value_sq``, ``compiled_form``, ``radial_profile``,
    ``sup_norm`` and ``lipschitz`` are optional (the backends fall back to ``φ(√q)``; the
    NUFFT backend needs ``radial_profile``; see the module notes).
    """

    def __call__(self, s): ...


class CuckerSmale:
    r"""Cucker–Smale communication rate (eq. (2.13)).

    .. math:: g(s) = \frac{G}{(1 + s^2)^{\beta}} = G\,\exp\bigl(-\beta\,\operatorname{log1p}(s^2)\bigr)

    evaluated in the exp–log1p form (``__call__``, the reference), which never overflows
    (large ``s``, ``β`` up to any size underflow gracefully to 0). The numpy path
    (:meth:`value_sq`) uses numpy's SIMD ufuncs on cache-sized blocks (in float32 blocks
    the form ``G·2^(−β·log₂(1 + s²))``), and for half-integer ``β ≤ 5/2`` a numba kernel with
    one square root and one division per entry; :meth:`compiled_form` lets the dense
    backend's compiled worker evaluate it without Python calls.

    Parameters
    ----------
    G : float
        Coupling strength ``g(0) = G >= 0``. The paper does not state ``G``; with
        ``normalize="sum"`` and ``G = 0.8`` the engine reproduces the paper's Table 1
        pattern (see docs/dynamics.md).
    beta : float
        Decay exponent ``β >= 0``.

    Examples
    --------
    >>> g = CuckerSmale(G=2.0, beta=1.5)
    >>> float(g(np.array([0.0, 1.0]))[1])   # 2 / 2**1.5
    0.7071067811865476
    >>> g.sup_norm(), round(g.lipschitz(), 6)
    (2.0, 1.7173)
    """

    def __init__(self, G: float = 1.0, beta: float = 1.5):
        self.G = as_float(G, "G", low=0.0)
        self.beta = as_float(beta, "beta", low=0.0)
        n2 = 2.0 * self.beta
        self._n2 = int(n2) if (n2 <= 5 and n2 == int(n2)) else None  # 2β may be inf

    def compiled_form(self) -> tuple[str, float, float]:
        """The closed form for compiled backends (see :data:`kinred.pairsum.COMPILED_KINDS`):
        ``("cs_halfint", G, 2β)`` for half-integer ``β ≤ 5/2``, else ``("cs_pow", G, β)``.

        Examples
        --------
        >>> CuckerSmale(G=0.8, beta=1.62).compiled_form()
        ('cs_pow', 0.8, 1.62)
        """
        if self._n2 is not None:
            return ("cs_halfint", self.G, float(self._n2))
        return ("cs_pow", self.G, self.beta)

    def __call__(self, s):
        s = np.asarray(s, dtype=float)
        return self.G * np.exp(-self.beta * np.log1p(s * s))

    def is_nonnegative(self) -> bool:
        """True: ``g ≥ 0`` (alignment with it only dissipates the velocity fluctuation)."""
        return True

    def certificate_form(self) -> CertificateForm:
        """``("cucker_smale", (G, β))`` (see :data:`kinred.dynamics.hooks.KERNEL_FORMS`)."""
        return CertificateForm("cucker_smale", (self.G, self.beta))

    def radial_profile(self):
        """The kernel itself: ``G (1 + s²)^(−β)`` is a smooth function of ``s²`` (analytic for
        ``|Im s| < 1``), so it qualifies for the NUFFT backend."""
        return self.__call__

    def tail_bound(self):
        """``g`` itself: ``G (1 + s²)^(−β)`` is non-increasing (an algebraic tail)."""
        return self.__call__

    def value_sq(self, q: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``g(√q)`` for squared distances ``q (b, m)`` into ``out (b, m)``.

        General β, with numpy's SIMD ufuncs in place: float64 blocks use
        ``G·exp(−β·log1p(q))`` (the reference form); the float32 blocks of
        ``precision="mixed"`` use ``G·2^(−β·log₂(1 + q))``, which is faster there
        (docs/performance.md). Rounding ``1 + q`` first costs a relative error of only
        ``β·u`` in ``g``. Never overflows: the exponent is ≤ 0.
        """
        if self._n2 is not None:
            return _kernels.cs_halfint(q, self.G, self._n2, out)
        if out.dtype == np.float32:
            np.add(q, 1.0, out=out)
            np.log2(out, out=out)
            np.multiply(out, -self.beta, out=out)
            np.exp2(out, out=out)
        else:
            np.log1p(q, out=out)
            np.multiply(out, -self.beta, out=out)
            np.exp(out, out=out)
        if self.G != 1.0:
            np.multiply(out, self.G, out=out)
        return out

    def sup_norm(self) -> float:
        """``‖g‖∞ = g(0) = G``."""
        return self.G

    def lipschitz(self) -> float:
        r"""``‖g′‖∞``, attained at ``s* = 1/√(2β+1)``:

        .. math:: \|g'\|_\infty = \frac{2 G \beta s^*}{(1 + s^{*2})^{\beta + 1}}.
        """
        b = self.beta
        if b == 0.0 or self.G == 0.0:
            return 0.0
        s = 1.0 / math.sqrt(2.0 * b + 1.0)
        return 2.0 * self.G * b * s * math.exp(-(b + 1.0) * math.log1p(s * s))

    def slope(self, s):
        r"""``|g′(s)| = 2Gβ s (1 + s²)^{−β−1}`` elementwise (0 at ``s = ∞``)."""
        s = np.asarray(s, dtype=float)
        if self.beta == 0.0 or self.G == 0.0:
            return np.zeros(s.shape)
        with np.errstate(over="ignore", invalid="ignore"):
            out = 2.0 * self.G * self.beta * s * np.exp(-(self.beta + 1.0) * np.log1p(s * s))
        return np.where(np.isfinite(s), out, 0.0)

    def slope_bound(self, lo, hi):
        r"""``sup_{s∈[lo, hi]} |g′(s)|`` elementwise (exact).

        ``|g′(s)| = 2Gβ s (1+s²)^{−β−1}`` is unimodal with its peak at ``s* = 1/√(2β+1)``
        (its derivative has the sign of ``1 − (2β+1)s²``), so the supremum is the peak when
        ``lo ≤ s* ≤ hi`` and the larger end value otherwise.

        Parameters
        ----------
        lo, hi : array_like
            Interval ends, ``0 <= lo <= hi`` (``hi`` may be ``inf``), broadcast together.

        Examples
        --------
        >>> g = CuckerSmale(G=1.0, beta=1.0)           # peak at s* = 1/√3
        >>> [round(float(v), 6) for v in g.slope_bound([0.0, 2.0], [1.0, 3.0])]
        [0.649519, 0.16]
        """
        lo, hi = _interval(lo, hi)
        if self.beta == 0.0 or self.G == 0.0:
            return np.zeros(lo.shape)
        s_star = 1.0 / math.sqrt(2.0 * self.beta + 1.0)
        out = np.maximum(self.slope(lo), self.slope(hi))
        return np.where((lo <= s_star) & (hi >= s_star), self.lipschitz(), out)

    def __repr__(self) -> str:
        return f"CuckerSmale(G={self.G!r}, beta={self.beta!r})"


_SCRATCH = threading.local()

#: Exponents of :meth:`Morse.value_sq` are floored here: ``e^−600 ≈ 2.6e-261`` stays a normal
#: number through the products and the division by ``r`` (no subnormal slow paths).
EXP_FLOOR = -600.0


def _scratch(shape: tuple, dtype) -> tuple:
    """Two arrays of ``shape`` and ``dtype``: views of two flat buffers kept per thread and
    grown to the largest size asked (the dense strips' blocks change shape at every call),
    for the in-place kernel evaluations, which then allocate nothing per call. Above
    :data:`SCRATCH_MAX` entries fresh arrays (numpy maps those in huge pages)."""
    size = math.prod(shape)
    dtype = np.dtype(dtype)
    if size > SCRATCH_MAX:
        return np.empty(shape, dtype), np.empty(shape, dtype)
    got = getattr(_SCRATCH, "bufs", None)
    if got is None or got[0].dtype != dtype or got[0].size < size:
        got = (np.empty(size, dtype), np.empty(size, dtype))
        _SCRATCH.bufs = got
    return got[0][:size].reshape(shape), got[1][:size].reshape(shape)


#: The largest scratch (entries per array) kept per thread: 8 MB in float64.
SCRATCH_MAX = 2 ** 20


class Morse:
    r"""Morse potential of the self-propulsion model (§3.3.2 of the paper, eq. (3.14)).

    .. math::
        U(s) = -C_a e^{-s/\ell_a} + C_r e^{-s/\ell_r}, \qquad
        U'(s) = \frac{C_a}{\ell_a} e^{-s/\ell_a} - \frac{C_r}{\ell_r} e^{-s/\ell_r},

    and the engine uses ``u(s) = U′(r)/r`` with ``r = √(s² + soft²)``.

    Coincident agents. Standard Morse has ``U′(0) = C_a/ℓ_a − C_r/ℓ_r ≠ 0`` so
    ``u(s) = U′(s)/s`` blows up like ``1/s``. Two documented choices:

    * ``soft = 0`` (default, the exact potential): the pair force ``u(s)(xⱼ − xᵢ)`` has norm
      ``|U′(s)| ≤ max(C_a/ℓ_a, C_r/ℓ_r)`` (:meth:`force_sup`), bounded for every ``s > 0``;
      at ``s = 0`` (coincident agents) the direction is undefined and the force is set to
      exactly 0 (``u(0) := 0``, the symmetric subgradient choice). ``u`` itself is unbounded,
      so :meth:`sup_norm` and :meth:`lipschitz` return ``inf`` (the paper's assumption that
      ``u`` is bounded and Lipschitz fails).
    * ``soft = ε > 0``: the softened potential ``U_ε(s) = U(√(s² + ε²))`` with
      ``u_ε(s) = U′(r)/r`` finite at 0, bounded and Lipschitz, as the paper assumes.

    Parameters
    ----------
    Ca, la : float
        Attraction strength (>= 0) and length (> 0).
    Cr, lr : float
        Repulsion strength (>= 0) and length (> 0).
    soft : float
        Softening length ``ε >= 0``.

    Examples
    --------
    >>> m = Morse(Ca=1.0, la=2.0, Cr=1.5, lr=0.5, soft=0.1)
    >>> bool(np.isfinite(m(np.array([0.0]))[0]))
    True
    >>> float(Morse(1.0, 2.0, 1.5, 0.5)(np.array([0.0]))[0])   # coincident agents: zero force
    0.0
    """

    def __init__(self, Ca: float = 1.0, la: float = 2.0, Cr: float = 1.5, lr: float = 0.5,
                 soft: float = 0.0):
        self.Ca = as_float(Ca, "Ca", low=0.0)
        self.la = as_float(la, "la", low=0.0, low_open=True)
        self.Cr = as_float(Cr, "Cr", low=0.0)
        self.lr = as_float(lr, "lr", low=0.0, low_open=True)
        self.soft = as_float(soft, "soft", low=0.0)

    def U(self, s):
        """The potential ``U(s)`` (unsoftened)."""
        s = np.asarray(s, dtype=float)
        return -self.Ca * np.exp(-s / self.la) + self.Cr * np.exp(-s / self.lr)

    def dU(self, s):
        """``U′(s)``."""
        s = np.asarray(s, dtype=float)
        return self.Ca / self.la * np.exp(-s / self.la) - self.Cr / self.lr * np.exp(-s / self.lr)

    def __call__(self, s):
        """``u(s) = U′(r)/r``, ``r = √(s² + soft²)``; ``u(0) = 0`` when ``soft = 0``."""
        s = np.asarray(s, dtype=float)
        return self.value_sq(s * s, np.empty_like(s))

    def value_sq(self, q: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``u(√q)`` for squared distances ``q`` into ``out`` (may alias ``q``).

        In place: ``r`` and one exponential in two scratch arrays of the calling thread
        (``_scratch``), the rest in ``out`` – the same operations as :meth:`dU` followed
        by ``U′(r)/r`` (bit for bit), without the eight temporaries of those expressions, except
        that the exponents are floored at ``EXP_FLOOR = −600`` (numpy's ``exp`` takes a slow path
        where its result would be subnormal or zero, 6–35× slower: a cloud spread over 1000
        Morse lengths took 4× as long; the floor changes a value by at most
        ``e^−600·(C_a/ℓ_a + C_r/ℓ_r)/r``, about 1e-261 of the kernel's scale). Each
        temporary of a dense strip (about 1.6 MB) was a fresh ``mmap`` whose pages faulted in
        on every call: the dense backend's Morse took 1.8 s per right-hand side at N = 2·10⁴
        in a fresh process, 0.8 s once malloc had raised its mmap threshold."""
        if not (isinstance(q, np.ndarray) and isinstance(out, np.ndarray)
                and q.shape == out.shape and q.dtype == out.dtype == np.float64):
            return self._value_sq(q, out)
        r, e = _scratch(q.shape, q.dtype)
        np.sqrt(np.add(q, self.soft * self.soft, out=r) if self.soft else q, out=r)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
            np.negative(r, out=e)               # Ca/la · exp(−r/la) − Cr/lr · exp(−r/lr)
            np.divide(e, self.la, out=e)
            np.maximum(e, EXP_FLOOR, out=e)
            np.exp(e, out=e)
            np.multiply(self.Ca / self.la, e, out=e)
            np.negative(r, out=out)             # q is not needed past r: out may alias it
            np.divide(out, self.lr, out=out)
            np.maximum(out, EXP_FLOOR, out=out)
            np.exp(out, out=out)
            np.multiply(self.Cr / self.lr, out, out=out)
            np.subtract(e, out, out=out)
            np.divide(out, r, out=out)
        if not self.soft:
            out[r == 0.0] = 0.0
        return out

    def _value_sq(self, q, out):
        """:meth:`value_sq` by plain expressions (other array types; float32 blocks of
        ``precision="mixed"``, whose ``U′`` :meth:`dU` takes in float64)."""
        if self.soft:
            r = np.sqrt(q + self.soft * self.soft)
        else:
            r = np.sqrt(q)
        du = self.dU(r)
        with np.errstate(divide="ignore", invalid="ignore"):
            np.divide(du, r, out=out)
        if not self.soft:
            out[r == 0.0] = 0.0
        return out

    def radial_profile(self):
        """``u`` itself when ``soft > 0`` (a smooth function of ``s² + soft²``, analytic for
        ``|Im s| < soft``: the smaller ``soft``, the more Fourier modes the NUFFT backend
        needs); None when ``soft = 0``, where ``u(s) = U′(s)/s`` is singular (``~ 1/s``, or
        a cone ``|r|`` when ``U′(0) = 0``) at coincident agents."""
        return self.__call__ if self.soft > 0 else None

    def potential_range(self) -> float:
        """``C_a + C_r``: ``U`` (softened or not) takes its values in ``[−C_a, C_r]``."""
        return self.Ca + self.Cr

    def certificate_form(self) -> CertificateForm:
        """``("morse", (Ca, la, Cr, lr, soft))`` (see
        :data:`kinred.dynamics.hooks.KERNEL_FORMS`)."""
        return CertificateForm("morse", (self.Ca, self.la, self.Cr, self.lr, self.soft))

    def pair_form(self):
        """The closed form for the cell list's compiled pass (see
        :func:`kinred.pairsum.pair_form`): ``("morse", (Ca, la, Cr, lr, soft))``."""
        return ("morse", (self.Ca, self.la, self.Cr, self.lr, self.soft))

    def tail_bound(self):
        r"""The exponential tails: for ``s′ ≥ s``, with ``r = √(s² + soft²)``,

        .. math:: |u(s')| \le \frac{(C_a/\ell_a) e^{-r/\ell_a} + (C_r/\ell_r) e^{-r/\ell_r}}{r}

        (``|U′(r)| ≤`` the sum of its two terms, both decreasing, divided by ``r′ ≥ r``);
        ``inf`` at ``s = 0`` when ``soft = 0``.

        Examples
        --------
        >>> m = Morse(1.0, 2.0, 1.5, 0.5, soft=0.1)
        >>> s = np.linspace(3.0, 30.0, 1000)
        >>> bool(np.all(np.abs(m(s)) <= m.tail_bound()(np.array([3.0]))))
        True
        """
        Ca, la, Cr, lr, e2 = self.Ca, self.la, self.Cr, self.lr, self.soft ** 2

        def bound(s):
            r = np.sqrt(np.asarray(s, dtype=float) ** 2 + e2)
            with np.errstate(divide="ignore", invalid="ignore"):
                out = (Ca / la * np.exp(-r / la) + Cr / lr * np.exp(-r / lr)) / r
            return np.where(r > 0, out, np.inf)

        return bound

    def force_sup(self) -> float:
        """``sup_{s>0} |U′(s)| <= max(Ca/la, Cr/lr)`` (a difference of two positive decreasing terms)."""
        return max(self.Ca / self.la, self.Cr / self.lr)

    def _grid_max(self, f) -> float:
        from scipy.optimize import minimize_scalar

        L = max(self.la, self.lr)
        head = [0.0] if self.soft else []
        s = np.concatenate([head, np.geomspace(1e-6 * L, 60.0 * L, 4000)])
        vals = np.abs(f(s))
        i = int(np.argmax(vals))
        lo, hi = s[max(i - 1, 0)], s[min(i + 1, len(s) - 1)]
        if hi > lo:
            res = minimize_scalar(lambda t: -abs(float(f(np.array([t]))[0])), bounds=(lo, hi),
                                  method="bounded", options={"xatol": 1e-12 * L})
            return float(max(vals[i], -res.fun))
        return float(vals[i])

    def _du_ds(self, s):
        # derivative of u(s) = U'(r)/r with r = sqrt(s^2 + eps^2): u'(s) = (U''(r)/r - U'(r)/r^2) s/r
        r = np.sqrt(s * s + self.soft ** 2)
        d2 = (-self.Ca / self.la ** 2 * np.exp(-r / self.la)
              + self.Cr / self.lr ** 2 * np.exp(-r / self.lr))
        return (d2 / r - self.dU(r) / r ** 2) * s / r

    def _envelopes(self, r):
        r"""``(P_a(r), P_r(r))``: the positive, decreasing parts of ``g′(r) = P_r(r) − P_a(r)``
        for ``g(r) = U′(r)/r``: ``P_a = (C_a/ℓ_a) e^{−r/ℓ_a}(1/(ℓ_a r) + 1/r²)``, likewise
        ``P_r`` with ``C_r, ℓ_r`` (0 at ``r = ∞``)."""
        r = np.asarray(r, dtype=float)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            inv = 1.0 / r
            pa = self.Ca / self.la * np.exp(-r / self.la) * (inv / self.la + inv * inv)
            pr = self.Cr / self.lr * np.exp(-r / self.lr) * (inv / self.lr + inv * inv)
        fin = np.isfinite(r)
        return np.where(fin, pa, 0.0), np.where(fin, pr, 0.0)

    def slope_bound(self, lo, hi):
        r"""An upper bound of ``sup_{s∈[lo, hi]} |u′(s)|`` elementwise (softened potential only).

        With ``r = √(s² + soft²)`` and ``g(r) = U′(r)/r``, ``u′(s) = g′(r)·s/r`` and

        .. math:: g'(r) = P_r(r) - P_a(r), \quad
                  P_a(r) = \tfrac{C_a}{\ell_a} e^{-r/\ell_a}
                  \bigl(\tfrac{1}{\ell_a r} + \tfrac{1}{r^2}\bigr),
                  \quad P_r \text{ likewise},

        both ``P`` positive and decreasing, so on ``r ∈ [r_lo, r_hi]``
        ``g′ ∈ [P_r(r_hi) − P_a(r_lo), P_r(r_lo) − P_a(r_hi)]``; ``s/r`` increases with ``s``.
        Hence ``|u′| ≤ max(|P_r(r_hi) − P_a(r_lo)|, |P_r(r_lo) − P_a(r_hi)|)·hi/r_hi``, which
        tends to ``|u′(s)|`` as the interval shrinks to ``s``.

        Raises
        ------
        InvalidInput
            For ``soft = 0``: ``u(s) = U′(s)/s`` is unbounded near ``s = 0`` (and set to 0 at
            ``s = 0``), so no slope bound exists on intervals reaching 0.

        Examples
        --------
        >>> m = Morse(1.0, 2.0, 1.5, 0.5, soft=0.5)
        >>> s = np.linspace(1.0, 1.01, 101)
        >>> bool(m.slope_bound(1.0, 1.01) >= np.max(np.abs(m._du_ds(s))))
        True
        """
        if not self.soft:
            raise InvalidInput(
                f"{self!r}: slope_bound needs soft > 0: with soft = 0, u(s) = U'(s)/s is "
                "unbounded near s = 0 (coincident agents), so no Lipschitz bound exists; use "
                "Morse(..., soft=eps)")
        lo, hi = _interval(lo, hi)
        e2 = self.soft * self.soft
        r_lo = np.sqrt(lo * lo + e2)
        r_hi = np.sqrt(hi * hi + e2)
        pa_lo, pr_lo = self._envelopes(r_lo)
        pa_hi, pr_hi = self._envelopes(r_hi)
        g1 = np.maximum(np.abs(pr_hi - pa_lo), np.abs(pr_lo - pa_hi))
        with np.errstate(invalid="ignore"):
            frac = np.where(np.isfinite(hi), hi / r_hi, 1.0)
        return g1 * frac

    def sup_norm(self) -> float:
        """``‖u‖∞`` (``inf`` when ``soft = 0`` and ``U′(0) ≠ 0``), by a bracketed 1-D maximization."""
        if not self.soft and self.Ca / self.la != self.Cr / self.lr:
            return math.inf
        return self._grid_max(self)

    def lipschitz(self) -> float:
        """``‖u′‖∞`` (``inf`` when ``soft = 0`` and ``U′(0) ≠ 0``), by a bracketed 1-D maximization."""
        if not self.soft and self.Ca / self.la != self.Cr / self.lr:
            return math.inf
        return self._grid_max(self._du_ds)

    def __repr__(self) -> str:
        return (f"Morse(Ca={self.Ca!r}, la={self.la!r}, Cr={self.Cr!r}, lr={self.lr!r}, "
                f"soft={self.soft!r})")


class Quadratic:
    r"""Quadratic potential ``U(s) = c s²/2``, so ``u(s) = c`` (linear attraction).

    With :class:`~kinred.dynamics.Aggregation` it gives ``ẋᵢ = c Σⱼ wⱼ (xⱼ − xᵢ)``, whose
    solution is known in closed form (used by the tests).

    Examples
    --------
    >>> Quadratic(2.0)(np.array([0.0, 3.0]))
    array([2., 2.])
    """

    def __init__(self, c: float = 1.0):
        self.c = as_float(c, "c")

    def __call__(self, s):
        return np.full(np.shape(s), self.c)

    def value_sq(self, q: np.ndarray, out: np.ndarray) -> np.ndarray:
        out[...] = self.c
        return out

    def is_nonnegative(self) -> bool:
        """``c ≥ 0``."""
        return self.c >= 0.0

    def certificate_form(self) -> CertificateForm:
        """``("quadratic", (c,))`` (see :data:`kinred.dynamics.hooks.KERNEL_FORMS`)."""
        return CertificateForm("quadratic", (self.c,))

    def radial_profile(self):
        """The constant itself (one Fourier mode in the NUFFT backend)."""
        return self.__call__

    def tail_bound(self):
        """``|c|``: no decay (nothing may be truncated)."""
        c = abs(self.c)
        return lambda s: np.full(np.shape(s), c)

    def sup_norm(self) -> float:
        return abs(self.c)

    def lipschitz(self) -> float:
        return 0.0

    def slope_bound(self, lo, hi):
        """``sup |u′| = 0`` on every interval (``u`` is constant).

        Examples
        --------
        >>> Quadratic(2.0).slope_bound([0.0, 1.0], [1.0, 5.0])
        array([0., 0.])
        """
        lo, hi = _interval(lo, hi)
        return np.zeros(lo.shape)

    def __repr__(self) -> str:
        return f"Quadratic(c={self.c!r})"
