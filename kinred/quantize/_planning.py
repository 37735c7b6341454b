"""Plans of quantization: the atom counts decided and priced before anything is built.

Pure integer arithmetic over the measure's structure (:mod:`._budget` for tensor products) and
the size model of :mod:`._size`; nothing here builds atoms, so both the entry points
(:mod:`._plan`) and the quantization objects (:mod:`._quantization`, for the "what would fit"
of their refusals) use it without an import cycle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InvalidInput
from ..measures import Atomic, Empirical1D, Measure, Mixture, PushForward, TensorProduct, Univariate
from ._budget import _TOL, RULE_CONSTANT, Budget, _ceil_ratio, budget
from ._size import fmt_count, largest, materialize_bytes, quantile_bytes

if TYPE_CHECKING:
    from ._quantization import Quantization


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
    """Smallest common component accuracy whose total count fits ``atoms`` (bisection).

    Tensor-product components of one shape (equal support widths, the same one-atom factors)
    get equal counts at every ε: their count is computed once per ε (a mixture of four equal
    clouds took four budgets per bisection step).
    """
    memo: dict = {}

    def component_count(m, e):
        if not isinstance(m, TensorProduct):
            return _plan(m, e, None, rule, node_limit).n_atoms
        key = (e, tuple(float(w) for w in m.support_widths()),
               tuple(isinstance(f, Atomic) and f.n_atoms == 1 for f in m.factors))
        if key not in memo:
            memo[key] = _plan(m, e, None, rule, node_limit).n_atoms
        return memo[key]

    def count(e):
        return sum(component_count(m, e) for m in mu.components)

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
    k = largest(lambda n: materialize_bytes(n, dim, width) <= limit, min(q.n_atoms, limit))
    if not k:
        return "not even one atom fits: raise max_bytes"
    text = f"at most {fmt_count(k)} atoms fit (quantize(..., atoms={k}))"
    mu = q.measure
    if isinstance(mu, Atomic):
        return text
    e = _fit_eps(mu, q.rule, 20000, limit, "materialize", max(q.bound, 1e-300))
    return text + (f", eps >= {e:g} fits" if e else "")
