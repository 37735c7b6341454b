"""Entry points of quantization: plan the counts (integers), size them, then build.

:func:`quantize` never allocates before it knows what it will allocate: it first plans the
atom counts (budgets are pure integer arithmetic), prices the plan with the size model of
:mod:`._size`, compares with the memory limit and only then builds the per-coordinate quantile
arrays. :func:`preflight` returns the same prices without building anything.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_choice, as_float, as_int, check_alloc
from ..errors import InvalidInput
from ..measures import Measure
from ._budget import RULE_CONSTANT
from ._planning import _as_1d, _check_1d, _fit_text, _Need, _plan, _Plan, _need, _Unfit
from ._quantization import (
    AtomicQuantization,
    MixtureQuantization,
    PushQuantization,
    Quantization,
    Quantization1D,
    TensorQuantization,
)
from ._size import LEVEL_CHUNK, fmt_count, largest, materialize_bytes, max_bytes_limit

__all__ = ["Preflight", "preflight", "quantize", "quantize_1d"]

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
        k = largest(lambda m: _need(_Plan(mu, "1d", n=m)).bytes <= limit, min(n, limit))
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
