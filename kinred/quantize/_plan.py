"""Entry points of quantization: plan the counts (integers), size them, then build.

:func:`quantize` never allocates before it knows what it will allocate: it first plans the
atom counts (budgets are pure integer arithmetic), prices the plan with the size model of
:mod:`._size`, compares with the memory limit and only then builds the per-coordinate quantile
arrays. :func:`preflight` returns the same prices without building anything.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .._validate import as_choice, as_float, as_int, check_alloc
from ..errors import InvalidInput
from ..measures import Atomic, Empirical1D, Measure, Mixture, PushForward, TensorProduct, Univariate
from ._budget import _TOL, RULE_CONSTANT, Budget, _ceil_ratio, budget
from ._quantization import (
    AtomicQuantization,
    MixtureQuantization,
    PushQuantization,
    Quantization,
    Quantization1D,
    TensorQuantization,
    _largest,
)
from ._size import LEVEL_CHUNK, fmt_count, materialize_bytes, max_bytes_limit, quantile_bytes

__all__ = ["Preflight", "preflight", "quantize", "quantize_1d"]

#: Branch-and-bound nodes of the budgets tried while searching the ε that fits a limit (the
#: answer is then checked once with the caller's ``node_limit``).
_SEARCH_NODES = 100


# ------------------------------------------------------------------------------------------
# plans: counts decided, nothing built
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Plan:
    """Atom counts of a quantization before anything is built.

    ``kind`` is ``"atomic"`` (the measure itself), ``"1d"`` (``n`` quantile atoms),
    ``"tensor"`` / ``"mixture"`` (``parts`` per factor / component) or ``"push"`` (``parts``
    holds the base plan).
    """

    measure: Measure
    kind: str
    n: int = 1
    budget: Budget | None = None
    parts: tuple = ()
    norm: float = 0.0

    @property
    def n_atoms(self) -> int:
        if self.kind == "atomic":
            return self.measure.n_atoms
        if self.kind == "1d":
            return self.n
        if self.kind == "tensor":
            return math.prod(p.n_atoms for p in self.parts)
        if self.kind == "push":
            return self.parts[0].n_atoms
        return sum(p.n_atoms for p in self.parts)

    @property
    def width(self) -> int:
        """As :attr:`Quantization._width`: the widest row of one block of atoms."""
        if self.kind == "push":
            return self.parts[0].width + self.measure.dim
        if self.kind == "mixture":
            return max(p.width for p in self.parts)
        return self.measure.dim

    def leaves(self):
        """The 1-D quantile quantizations the plan builds."""
        if self.kind == "1d":
            yield self
        for p in self.parts:
            yield from p.leaves()


@dataclass(frozen=True)
class _Need:
    points: int  # per-coordinate quantile points
    atoms: int
    bytes: int
    at_least: bool = False  # lower bounds (the exact plan was not needed to refuse)


class _Unfit(Exception):
    """A lower bound of the plan's bytes already exceeds the limit (raised while planning)."""

    def __init__(self, need: _Need):
        super().__init__()
        self.need = need


def _quantile_need(leaves, atoms: int, at_least: bool = False) -> _Need:
    """Price 1-D quantizations given as ``(measure, n)`` pairs (:func:`._size.quantile_bytes`)."""
    counts = [n for _, n in leaves]
    copies = sum(m.n_atoms for m, _ in leaves if isinstance(m, Atomic) and not isinstance(m, Empirical1D))
    return _Need(sum(counts), atoms, quantile_bytes(sum(counts), max(counts, default=0), copies), at_least)


def _need(plan: _Plan) -> _Need:
    return _quantile_need([(p.measure, p.n) for p in plan.leaves()], plan.n_atoms)


def _n_for_eps(sigma: float, eps: float, c: float) -> int:
    """Fewest atoms with ``c σ / n ≤ ε`` (exact integer arithmetic, any ε)."""
    return 1 if sigma <= 0 else _ceil_ratio(c * sigma, Fraction(eps) * Fraction(1 + _TOL))


def _tensor_lower(mu: TensorProduct, eps: float, c: float, limit: int | None) -> None:
    """Raise :class:`_Unfit` before the budget when ``N_j ≥ c σⱼ / ε`` (each term of eq. (4.22))
    already exceeds ``limit``."""
    if limit is None:
        return
    leaves = [(f, _n_for_eps(float(w), eps, c)) for f, w in zip(mu.factors, mu.support_widths())
              if not (isinstance(f, Atomic) and f.n_atoms == 1)]
    need = _quantile_need(leaves, math.prod(n for _, n in leaves), at_least=True)
    if need.bytes > limit:
        raise _Unfit(need)


def _plan(mu, eps, atoms, rule, node_limit, limit=None) -> _Plan:
    """The counts :func:`quantize` would use (see its docstring); no array is built.

    With ``limit``, a tensor product whose per-coordinate lower bounds already exceed it
    raises :class:`_Unfit` before its budget is computed (fast for tiny ε).
    """
    c = RULE_CONSTANT[rule]
    if isinstance(mu, Atomic):
        if atoms is not None and atoms < mu.n_atoms:
            if mu.dim == 1:
                return _Plan(mu, "1d", n=atoms)
            raise InvalidInput(
                f"atoms={atoms} is fewer than the {mu.n_atoms} atoms of this {mu.dim}-D atomic "
                "measure; an atomic measure quantizes exactly to itself"
            )
        return _Plan(mu, "atomic")
    if isinstance(mu, Univariate):
        n = atoms if atoms is not None else _n_for_eps(float(mu.support_widths()[0]), eps, c)
        return _Plan(mu, "1d", n=n)
    if isinstance(mu, TensorProduct):
        if eps is not None:
            _tensor_lower(mu, eps, c, limit)
        b = budget(mu.support_widths(), eps=eps, atoms=atoms, rule=rule, node_limit=node_limit)
        parts = tuple(_Plan(f, "atomic") if isinstance(f, Atomic) and f.n_atoms == 1 else _Plan(f, "1d", n=n)
                      for f, n in zip(mu.factors, b.counts))
        return _Plan(mu, "tensor", budget=b, parts=parts)
    if isinstance(mu, PushForward):
        norm = float(mu.projection.norm())
        if eps is not None:
            eps = eps / norm if norm > 0 else _coarsest_eps(mu.base, rule)
        return _Plan(mu, "push", parts=(_plan(mu.base, eps, atoms, rule, node_limit, limit),), norm=norm)
    if isinstance(mu, Mixture):
        if atoms is not None:
            eps = _mixture_eps(mu, atoms, rule, node_limit)
        parts = tuple(_plan(m, eps, None, rule, node_limit, limit) for m in mu.components)
        return _Plan(mu, "mixture", parts=parts)
    raise InvalidInput(f"cannot quantize a measure of type {type(mu).__name__}")


def _coarsest_eps(mu, rule) -> float:
    """An ε at which every quantizer of ``mu`` uses its minimal atom count."""
    if isinstance(mu, Mixture):
        return max(_coarsest_eps(m, rule) for m in mu.components)
    if isinstance(mu, PushForward):  # the base is quantized to ε / ‖M‖
        return _coarsest_eps(mu.base, rule) * max(float(mu.projection.norm()), 1.0)
    return float(RULE_CONSTANT[rule] * np.sum(mu.support_widths()) * 2 + 1.0)


def _mixture_eps(mu: Mixture, atoms: int, rule: str, node_limit: int) -> float:
    """Smallest common component accuracy whose total count fits ``atoms`` (bisection)."""
    def count(e):
        return _plan(mu, e, None, rule, node_limit).n_atoms

    hi = _coarsest_eps(mu, rule)
    need = count(hi)
    if need > atoms:
        raise InvalidInput(
            f"atoms={atoms} is too small for this mixture: its {len(mu.components)} "
            f"components need at least {need} atoms together"
        )
    lo = hi * 1e-12
    if count(lo) <= atoms:
        return lo
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if count(mid) <= atoms:
            hi = mid
        else:
            lo = mid
    return hi


# ------------------------------------------------------------------------------------------
# building
# ------------------------------------------------------------------------------------------
def _as_1d(mu) -> Measure:
    if isinstance(mu, Atomic) and mu.dim == 1 and not isinstance(mu, Empirical1D):
        return Empirical1D(mu.points[:, 0], mu.weights)
    return _check_1d(mu)


def _check_1d(mu) -> Measure:
    if isinstance(mu, (Univariate, Empirical1D)) or (isinstance(mu, Atomic) and mu.dim == 1):
        return mu
    raise InvalidInput(
        "mu must be a 1-D Univariate, Uniform, Empirical1D or 1-D Atomic/Dirac measure to be "
        f"quantized by quantile levels, got {mu!r}"
    )


def _build_1d(mu, n: int, rule: str) -> Quantization1D:
    """Quantile atoms, filled :data:`LEVEL_CHUNK` levels at a time (bounded temporaries)."""
    mu = _as_1d(mu)
    levels, points = np.empty(n), np.empty(n)
    for i0 in range(0, n, LEVEL_CHUNK):
        i = np.arange(i0, min(n, i0 + LEVEL_CHUNK), dtype=np.float64)
        lv = i / n if rule == "paper" else (2 * i + 1) / (2 * n)
        levels[i0:i0 + i.size] = lv
        points[i0:i0 + i.size] = mu.ppf(lv)
    np.maximum.accumulate(points, out=points)  # guard monotonicity against ppf round-off
    sigma = float(mu.support_widths()[0])
    return Quantization1D(measure=mu, rule=rule, levels=levels, points=points,
                          weights=np.full(n, 1.0 / n), bound=RULE_CONSTANT[rule] * sigma / n)


def _build(plan: _Plan, rule: str) -> Quantization:
    mu, parts = plan.measure, plan.parts
    if plan.kind == "atomic":
        return AtomicQuantization(mu)
    if plan.kind == "1d":
        return _build_1d(mu, plan.n, rule)
    if plan.kind == "tensor":
        return TensorQuantization(measure=mu, rule=rule, factors=tuple(_build(p, rule) for p in parts),
                                  budget=plan.budget)
    if plan.kind == "push":
        return PushQuantization(measure=mu, base=_build(parts[0], rule), projection=mu.projection,
                                norm=plan.norm)
    return MixtureQuantization(measure=mu, rule=rule, components=tuple(_build(p, rule) for p in parts),
                               weights=mu.weights.copy())


# ------------------------------------------------------------------------------------------
# what fits a limit
# ------------------------------------------------------------------------------------------
def _fits(mu, eps, atoms, rule, node_limit, limit, stage: str) -> bool:
    """Whether the quantization (and, for ``stage="materialize"``, its atom array) fits."""
    try:
        plan = _plan(mu, eps, atoms, rule, node_limit, limit)
    except (_Unfit, InvalidInput):
        return False
    if _need(plan).bytes > limit:
        return False
    return stage == "quantize" or materialize_bytes(plan.n_atoms, mu.dim, plan.width) <= limit


def _round_up(x: float) -> float:
    """``x`` rounded up to 3 significant digits (a value that prints as it is)."""
    m, e = f"{x:.2e}".split("e")
    y = float(f"{m}e{e}")
    return y if y >= x else float(f"{float(m) + 0.01:.2f}e{e}")


def _fit_eps(mu, rule, node_limit, limit, stage, bad: float) -> float | None:
    """Smallest ε (to 1 %, 3 digits) whose quantization fits ``limit``; None if none does.

    A geometric bisection between ``bad`` and the coarsest ε with cheap budgets
    (:data:`_SEARCH_NODES` nodes), then the answer is checked with ``node_limit``.
    """
    good = _coarsest_eps(mu, rule)
    if not _fits(mu, good, None, rule, node_limit, limit, stage):
        return None
    cheap = min(node_limit, _SEARCH_NODES)
    while good > bad * 1.01:
        mid = math.exp(0.5 * (math.log(good) + math.log(bad)))
        if _fits(mu, mid, None, rule, cheap, limit, stage):
            good = mid
        else:
            bad = mid
    for _ in range(30):
        good = _round_up(good)
        if _fits(mu, good, None, rule, node_limit, limit, stage):
            return good
        good *= 1.01
    return None  # pragma: no cover - the coarsest ε fits


def _fit_atoms(mu, rule, node_limit, limit, stage, bad: int) -> int:
    """Largest atom budget (to 1 %) below ``bad`` that fits ``limit``; 0 if none does.

    As :func:`_fit_eps`: cheap budgets while bisecting, the answer checked with ``node_limit``
    and shown exactly (below 1e12) or floored to 3 significant digits.
    """
    if not _fits(mu, None, 1, rule, node_limit, limit, stage):
        return 0
    good, cheap = 1, min(node_limit, _SEARCH_NODES)
    while bad > good * 1.01 + 1:
        mid = min(max(math.isqrt(good * bad), good + 1), bad - 1)
        good, bad = (mid, bad) if _fits(mu, None, mid, rule, cheap, limit, stage) else (good, mid)
    for _ in range(30):
        if good >= 10**12:  # fmt_count shows 3 significant digits: floor to them
            step = 10 ** (int(math.log10(good)) - 2)
            good = good // step * step
        if good <= 1 or _fits(mu, None, good, rule, node_limit, limit, stage):
            return good
        good = good * 99 // 100
    return 1  # pragma: no cover - one atom fits


def _fit_text(mu, eps, atoms, rule, node_limit, limit, stage) -> str:
    if atoms is not None:
        k = _fit_atoms(mu, rule, node_limit, limit, stage, atoms)
        return f"atoms <= {fmt_count(k)} fits" if k else "no atom budget fits: raise max_bytes"
    e = _fit_eps(mu, rule, node_limit, limit, stage, eps)
    return f"eps >= {e:g} fits" if e else "no eps fits (not even one atom per coordinate): raise max_bytes"


def materialize_fit(q: Quantization, limit: int) -> str:
    """What would fit instead of materializing ``q`` under ``limit`` (for TooLarge messages)."""
    dim, width = q.dim, q._width
    k = _largest(lambda n: materialize_bytes(n, dim, width) <= limit, min(q.n_atoms, limit))
    if not k:
        return "not even one atom fits: raise max_bytes"
    text = f"at most {fmt_count(k)} atoms fit (quantize(..., atoms={k}))"
    mu = q.measure
    if isinstance(mu, Atomic):
        return text
    e = _fit_eps(mu, q.rule, 20000, limit, "materialize", max(q.bound, 1e-300))
    return text + (f", eps >= {e:g} fits" if e else "")


def _check_need(call: str, need: _Need, dim: int, limit: int, fit) -> None:
    """:func:`~kinred._validate.check_alloc` of a planned quantization (``fit()``: what would
    fit, computed only past the limit)."""
    least = "at least " if need.at_least else ""
    check_alloc(need.bytes, call,
                lambda: f"{fit()} (kinred.quantize.budget and preflight size it without arrays)",
                max_bytes=limit, keyword="max_bytes", at_least=need.at_least,
                detail=f" before any atom is built: {least}{fmt_count(need.points)} per-coordinate "
                       f"quantile points (levels, points, weights) for {least}"
                       f"{fmt_count(need.atoms)} atoms in dimension {dim}")


# ------------------------------------------------------------------------------------------
# entry points
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Preflight:
    """What :func:`quantize` and its ``materialize()`` would allocate (exact integers).

    Attributes
    ----------
    points : int -- per-coordinate quantile points of all 1-D quantizations (``Σ N_j``)
    atoms : int -- atoms of the quantization (``∏ N_j`` for a tensor grid)
    dim : int
    quantize_bytes : int -- peak bytes of :func:`quantize` (quantile arrays and one chunk)
    materialize_bytes : int -- peak bytes of :meth:`Quantization.materialize`
    """

    points: int
    atoms: int
    dim: int
    quantize_bytes: int
    materialize_bytes: int

    def __repr__(self) -> str:
        return (f"Preflight(points={fmt_count(self.points)}, atoms={fmt_count(self.atoms)}, "
                f"dim={self.dim}, quantize_bytes={fmt_count(self.quantize_bytes)}, "
                f"materialize_bytes={fmt_count(self.materialize_bytes)})")


def _check_request(mu, eps, atoms, rule):
    if not isinstance(mu, Measure):
        raise InvalidInput(f"mu must be a kinred Measure, got {type(mu).__name__}")
    rule = as_choice(rule, "rule", RULE_CONSTANT)
    if (eps is None) == (atoms is None):
        raise InvalidInput("give exactly one of eps (target W1 bound) and atoms (atom budget)")
    if eps is not None:
        eps = as_float(eps, "eps", low=0.0, low_open=True)
    else:
        atoms = as_int(atoms, "atoms", low=1)
    return eps, atoms, rule


def preflight(mu: Measure, *, eps: float | None = None, atoms: int | None = None,
              rule: str = "midpoint", node_limit: int = 20000) -> Preflight:
    """Sizes of ``quantize(mu, ...)`` and its ``materialize()``, without building anything.

    The counts come from the same plan as :func:`quantize` (budgets of eq. (4.22), are integer arithmetic); the bytes from the size model: 24 bytes per
    per-coordinate quantile point, ``9·dim + 24`` per materialized atom, plus one bounded chunk
    of temporaries and 1 MiB of Python objects. Both calls refuse when their figure exceeds
    the memory limit.

    Examples
    --------
    >>> from kinred.measures import TensorProduct, Uniform
    >>> p = preflight(TensorProduct([Uniform(0, 1)] * 200), eps=1.0)
    >>> p.points, p.atoms == 100**200, p.quantize_bytes < 2**30
    (20000, True, True)
    """
    eps, atoms, rule = _check_request(mu, eps, atoms, rule)
    plan = _plan(mu, eps, atoms, rule, as_int(node_limit, "node_limit", low=0))
    need = _need(plan)
    return Preflight(points=need.points, atoms=need.atoms, dim=mu.dim, quantize_bytes=need.bytes,
                     materialize_bytes=materialize_bytes(need.atoms, mu.dim, plan.width))


def quantize_1d(mu, n: int, *, rule: str = "midpoint", max_bytes=None) -> Quantization1D:
    """``n`` equal-weight atoms at quantile levels of a 1-D measure.

    ``rule="paper"``: levels ``i/N``, ``i = 0..N−1`` (so ``x₀ = a``), eq. (4.20) of the paper, with bound ``σ/N`` (eq. (4.21)).
    ``rule="midpoint"`` (default, W1-optimal): levels ``(2i−1)/(2N)``, ``i = 1..N``, the medians
    of the N quantile cells, with bound ``σ/(2N)``:

    .. math:: W_1(\\mu, \\mu^N) = \\int_0^1 |F^{-1}(u) - Q(u)|\\,du \\le \\frac{c\\,\\sigma}{N},
              \\quad c = \\tfrac12 \\text{ (midpoint)},\\ 1 \\text{ (paper)} .

    The result's ``error`` is this exact W1 (lazy).

    Raises
    ------
    TooLarge
        If the quantile arrays (24 bytes per atom, plus one chunk) exceed ``max_bytes``
        (default: ``KINRED_MAX_BYTES``, else :data:`~kinred.quantize.DEFAULT_MAX_BYTES`).

    Examples
    --------
    >>> from kinred.measures import Uniform
    >>> q = quantize_1d(Uniform(0, 1), 4)
    >>> q.points, q.bound, round(q.error, 12)
    (array([0.125, 0.375, 0.625, 0.875]), 0.125, 0.0625)
    >>> round(quantize_1d(Uniform(0, 1), 4, rule="paper").error, 12)
    0.125
    """
    mu = _check_1d(mu)
    n = as_int(n, "n", low=1)
    rule = as_choice(rule, "rule", RULE_CONSTANT)
    limit = max_bytes_limit(max_bytes)

    def fit():
        k = _largest(lambda m: _need(_Plan(mu, "1d", n=m)).bytes <= limit, min(n, limit))
        return f"n <= {k} fits" if k else "no n fits: raise max_bytes"

    _check_need(f"quantize_1d(n={fmt_count(n)})", _need(_Plan(mu, "1d", n=n)), 1, limit, fit)
    return _build_1d(mu, n, rule)


def quantize(mu: Measure, *, eps: float | None = None, atoms: int | None = None,
             rule: str = "midpoint", node_limit: int = 20000, max_bytes=None) -> Quantization:
    """Atoms for a measure with a guaranteed W1 bound: the one entry point.

    * 1-D laws: :func:`quantize_1d` with the fewest atoms meeting ``eps`` (or ``atoms``).
    * :class:`~kinred.measures.TensorProduct`: a grid whose per-coordinate counts come from
      :func:`~kinred.quantize.budget` (delayed curse, eq. (4.22)).
    * :class:`~kinred.measures.Mixture`: a union of component quantizations (Lemma 4.2); with
      ``eps`` every component gets accuracy ``eps`` (so ``Σ wₗ εₗ ≤ eps``), with ``atoms`` the
      smallest common component accuracy whose total count fits is found by bisection (the
      split of accuracy across components is not optimized).
    * :class:`~kinred.measures.PushForward`: quantize the base to ``eps/‖M‖`` and push the
      atoms (eq. (4.8)–(4.9)).
    * :class:`~kinred.measures.Atomic` / Dirac: the identity (exact). A 1-D atomic measure asked
      for fewer ``atoms`` than it has is re-quantized at quantile levels.

    The counts are planned first (integers only), then priced (:func:`preflight`), and the
    per-coordinate quantile arrays are built only if they fit the memory limit.

    Parameters
    ----------
    mu : Measure
    eps : float, optional -- target bound (> 0)
    atoms : int, optional -- atom budget (≥ 1); give exactly one of ``eps``, ``atoms``
    rule : {"midpoint", "paper"}
    node_limit : int -- branch-and-bound limit passed to :func:`~kinred.quantize.budget`
    max_bytes : int or str, optional -- memory limit (default: the environment variable
        ``KINRED_MAX_BYTES``, else :data:`~kinred.quantize.DEFAULT_MAX_BYTES`, 2 GiB)

    Returns
    -------
    Quantization -- knows ``n_atoms``, ``bound``, ``error`` without materializing.

    Raises
    ------
    TooLarge
        If the quantile arrays would exceed the limit; the message names the atoms, the
        bytes, the limit and the ε (or atom budget) that would fit. A tiny ε is refused from
        the per-coordinate lower bounds ``N_j ≥ c σⱼ / ε`` before any budget is computed.

    Examples
    --------
    >>> from kinred.measures import TensorProduct, Uniform
    >>> mu = TensorProduct([Uniform(0, 1), Uniform(0, 0.5), Uniform(0, 0.01)])
    >>> q = quantize(mu, eps=0.1)
    >>> q.counts, q.n_atoms, round(q.bound, 4), round(q.error, 4)
    ((10, 6, 1), 60, 0.0967, 0.0483)
    """
    eps, atoms, rule = _check_request(mu, eps, atoms, rule)
    node_limit = as_int(node_limit, "node_limit", low=0)
    limit = max_bytes_limit(max_bytes)
    try:
        plan = _plan(mu, eps, atoms, rule, node_limit, limit)
        need = _need(plan)
    except _Unfit as exc:
        plan, need = None, exc.need
    call = f"quantize(eps={eps:g})" if eps is not None else f"quantize(atoms={fmt_count(atoms)})"
    _check_need(call, need, mu.dim, limit,
                lambda: _fit_text(mu, eps, atoms, rule, node_limit, limit, "quantize"))
    return _build(plan, rule)
