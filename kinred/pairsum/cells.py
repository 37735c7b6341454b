r"""The cell-list pair-sum backend: short-range kernels truncated from ``tol``, ``O(N)`` memory.

For distances in ``k ≤ 3`` dimensions and kernels whose range is short against the cloud
(Morse's exponential tails), every pair term ``Σⱼ cⱼ φ(|sᵢ − sⱼ|)(zⱼ − zᵢ)`` (the paper's
class (1.1) with ``f_ij = c_j φ``; the Morse kernel of eq. (3.14)) is summed over the
pairs closer than a cutoff ``R`` found by a cell list (:mod:`kinred.pairsum._cells`), with
the carrier centred as in the other backends. ``R`` (:func:`term_cutoff`) is at least the
smallest distance with ``B(R) ≤ TRUNC_FACTOR · tol · κ`` for the kernel's declared tail
bound ``B`` (:func:`~kinred.pairsum.tail_bound`) and ``κ`` the mean of ``|φ|`` over the
cloud's pairs (the scale of a row sum per unit weight, as in :class:`~kinred.pairsum.NUFFT`):
each pair left out changes a row sum by at most ``B(R)``, a relative ``TRUNC_FACTOR·tol`` of
it; and at least the radius whose left-out pairs, on sampled rows, bound a relative
``TRUNC_FACTOR·tol`` of the field weighted by their carrier differences. The
compiled pass evaluates each kernel from its table on ``[0, R]`` (:mod:`kinred.pairsum._table`:
within ``0.01·tol·(κ + |φ|)`` per pair, measured when built); a fixed ``cutoff=`` sums the
kernel itself.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from .._validate import as_float, check_alloc
from .. import _parallel
from ..errors import InvalidInput
from . import _cells, _fastsum, _kernels, _table
from ._base import PairTerms, check_plan_args, pair_form, tail_bound

__all__ = ["CellList", "CellListPlan", "cutoff_radius"]

#: The cell list sums distances in at most this many dimensions (``3ᵏ/2`` neighbour cells).
MAX_DIM = 3
#: A pair left out changes a row sum by at most ``TRUNC_FACTOR · tol · κ``.
TRUNC_FACTOR = 0.1
#: The cutoff is re-derived when the cloud's extents leave ``[1/REDECIDE, REDECIDE]`` × those
#: it was derived for.
REDECIDE = 1.25


def cutoff_radius(bound, target: float, dmax: float) -> float:
    """The smallest ``R ∈ (0, dmax]`` with ``bound(R) ≤ target`` (to 1e-9 relative), or
    ``dmax`` when there is none (no truncation: every pair of the cloud is within ``dmax``).

    Examples
    --------
    >>> from kinred.dynamics import Morse
    >>> B = Morse(Ca=1.0, la=1.0, Cr=0.0, lr=1.0).tail_bound()    # e^(-s)/s
    >>> R = cutoff_radius(B, 1e-6, 100.0)
    >>> round(R, 4), bool(B(np.array([R]))[0] <= 1e-6)
    (11.3834, True)
    """
    def at(r):
        return float(np.asarray(bound(np.array([r], dtype=float)), dtype=float).ravel()[0])

    if dmax <= 0.0 or not at(dmax) <= target:
        return dmax
    lo, hi = 0.0, dmax
    while hi - lo > 1e-9 * hi:
        mid = 0.5 * (lo + hi)
        if at(mid) <= target:
            hi = mid
        else:
            lo = mid
    return hi


@dataclass(eq=False)
class _Source:
    """One distance source: its terms, the cutoff and the extents it was derived for."""

    name: str
    terms: tuple
    bounds: tuple
    R: float | None = None
    ext: np.ndarray | None = None
    pairs: int = 0
    cells: int = 0
    kappas: tuple | None = None    # per term: κ of the cloud the cutoff was derived for
    values: tuple | None = None    # (R, per term: q ↦ φ(√q) with its table) for that R


@dataclass(eq=False)
class CellListPlan:
    """What :meth:`CellList.evaluate` needs for one scene and shape, and the cutoffs it keeps.

    Attributes
    ----------
    n, dim : int
    terms : PairTerms
    c : (n,) ndarray
    tol : float
    sources : tuple of _Source
    """

    n: int
    dim: int
    terms: PairTerms
    c: np.ndarray
    tol: float
    cutoff: float | None
    compiled: bool
    sources: tuple
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def info(self) -> list:
        """Per distance source: its cutoff, the cells and the pairs within it (last call)."""
        return [{"source": s.name, "cutoff": s.R, "cells": s.cells, "pairs": s.pairs,
                 "kernels": [repr(t.kernel) for t in s.terms]} for s in self.sources]


class CellList:
    r"""Short-range pair-sum backend (``pairsum="cells"``): a cell list, ``k ≤ 3``.

    Cost per right-hand side ``O(N log N)`` (one sort) plus ``O(N · 3ᵏ/2 · ρ Rᵏ)`` candidate
    pairs (``ρ`` the density of agents: each agent meets the agents of ``3ᵏ/2`` cells of side
    ``R``), memory ``O(N·(d + 1))`` per thread. In ``k`` dimensions the stencil has ``3ᵏ``
    cells, so beyond ``k = 3`` the cost grows as ``3ᵏ`` and, for spread clouds, distances
    concentrate so that few pairs are short: the backend refuses ``k > 3``.

    Parameters
    ----------
    tol : float
        Requested relative accuracy, ``0 < tol < 1``: the cutoff ``R`` makes every pair
        left out change a row sum by at most ``0.1·tol·κ`` (module notes); kernels must
        declare a tail bound (:func:`~kinred.pairsum.tail_bound`).
    cutoff : float, optional
        A fixed cutoff instead (then the error is the user's): also for kernels whose tail is
        unknown.
    compiled : bool
        The compiled pass with every kernel through its table (default; within
        ``0.01·tol·(κ + |φ|)`` of the kernel, ``kinred/pairsum/_table.py``) or the numpy twin
        on the kernel itself (tests).

    Examples
    --------
    >>> from kinred.dynamics import AttractionRepulsion, Morse, Scene
    >>> rng = np.random.default_rng(0)
    >>> x = rng.uniform(0, 40, (400, 2))
    >>> eff = [AttractionRepulsion(Morse(1.0, 1.0, 1.5, 0.5, soft=0.1))]
    >>> fast = Scene(eff, pairsum=CellList(tol=1e-8)).rhs(x, x)[1]
    >>> exact = Scene(eff).rhs(x, x)[1]
    >>> bool(np.linalg.norm(fast - exact) <= 1e-8 * np.linalg.norm(exact))
    True
    """

    precision = "double"

    #: The pair sums are truncated at a cutoff set from ``tol``: approximate, certificates refuse it.
    exact = False

    def __init__(self, tol: float = 1e-6, cutoff: float | None = None, compiled: bool = True):
        self.tol = as_float(tol, "tol", low=0.0, high=1.0, low_open=True, high_open=True)
        self.cutoff = None if cutoff is None else as_float(cutoff, "cutoff", low=0.0,
                                                             low_open=True)
        if not isinstance(compiled, (bool, np.bool_)):
            raise InvalidInput(f"compiled must be True or False, got {compiled!r}")
        self.compiled = bool(compiled)

    def __repr__(self) -> str:
        opts = [f"tol={self.tol!r}"]
        if self.cutoff is not None:
            opts.append(f"cutoff={self.cutoff!r}")
        if not self.compiled:
            opts.append("compiled=False")
        return f"CellList({', '.join(opts)})"

    def plan(self, scene, n: int, dim: int) -> CellListPlan:
        """The plan of ``scene`` for states ``(n, dim)`` (see :class:`~kinred.pairsum.PairSum`).

        Raises
        ------
        InvalidInput
            ``dim > 3``, or (without ``cutoff``) a kernel that declares no tail bound.
        """
        terms, n, dim = check_plan_args(scene, n, dim)
        if dim > MAX_DIM:
            raise InvalidInput(
                f"the cell list sums distances in k <= {MAX_DIM} dimensions; the state has "
                f"dim = {dim}: its stencil would have 3^{dim} = {3 ** dim} cells and distances "
                "concentrate in high dimension; project the scene (Scene.project) or use Dense")
        sources = []
        for s in terms.sources:
            ts = terms.of_source(s)
            bounds = tuple(tail_bound(t.kernel) for t in ts)
            if self.cutoff is None:
                for t, b in zip(ts, bounds):
                    if b is None:
                        raise InvalidInput(
                            f"the cell list truncates kernels at a distance set from tol and "
                            f"their declared decay; {t.kernel!r} (in {t.effect!r}) declares "
                            "none (no tail_bound() method: unknown tail): add one, give "
                            "CellList(cutoff=...) yourself, or use Dense/NUFFT")
            sources.append(_Source(s, ts, bounds))
        check_alloc(8 * n * (dim + 1) * (len(terms.accumulators) * _parallel.get_num_threads()
                                         + len(terms.carriers) + 4),
                    f"CellList: the arrays of {n} agents")
        return CellListPlan(n=n, dim=dim, terms=terms, c=scene.coefficients(n), tol=self.tol,
                            cutoff=self.cutoff, compiled=self.compiled, sources=tuple(sources))

    def evaluate(self, plan: CellListPlan, x: np.ndarray, v: np.ndarray | None, rng=None) -> dict:
        """``{target: (n, dim) ndarray}`` summed over the plan's terms (fresh arrays)."""
        if not isinstance(plan, CellListPlan) or x.shape != (plan.n, plan.dim):
            raise InvalidInput(f"plan must be a CellListPlan for states of shape (n, dim) = "
                               f"{getattr(plan, 'n', '?'), getattr(plan, 'dim', '?')}; got "
                               f"{type(plan).__name__} and x of shape {x.shape}")
        state = {"x": x, "v": v}
        terms = plan.terms
        centred = cell_carriers(plan, state)
        zext = {key: _kernels.zext_rows(centred[key], plan.c, np.empty((plan.n, plan.dim + 1)))
                for key in terms.carriers}
        acc = {kk: np.zeros((plan.n, plan.dim + 1)) for kk in terms.accumulators}
        with plan.lock:
            for src in plan.sources:
                s = np.ascontiguousarray(state[src.name], dtype=np.float64)
                if not np.all(np.isfinite(s)):
                    return {t: np.full((plan.n, plan.dim), np.nan) for t, _ in acc}
                R = source_cutoff(plan, src, s, centred)
                if R == 0.0:
                    continue
                near_sums(s, R, [(fn, zext[t.carrier], acc[(t.target, t.carrier)])
                                 for fn, t in zip(_values(plan, src, s, R), src.terms)],
                          plan.compiled, src)
        out = {}
        for (tgt, carrier), A in acc.items():
            contrib = _kernels.pair_finish(A, centred[carrier], np.empty((plan.n, plan.dim)))
            out[tgt] = out[tgt] + contrib if tgt in out else contrib
        return out


def _values(plan: CellListPlan, src: _Source, s: np.ndarray, R: float) -> tuple:
    """Per term of the source, ``q ↦ φ(√q)`` (:func:`kernel_values`) with, for the compiled
    pass and a cutoff derived from ``tol``, its table on ``[0, R]``
    (:mod:`kinred.pairsum._table`, within ``TABLE_FACTOR·tol·(κ + |φ|)`` with the ``κ`` the
    cutoff was derived with: the truncation's own target is ``TRUNC_FACTOR·tol·κ``), kept
    while the cutoff is. A fixed ``cutoff=`` sums the kernel itself (exact within it)."""
    if src.values is not None and src.values[0] == R:
        return src.values[1]
    fns = tuple(kernel_values(t.kernel) for t in src.terms)
    if plan.compiled and plan.cutoff is None and src.kappas is not None:
        for fn, kappa in zip(fns, src.kappas):
            if kappa > 0.0:
                fn.table = _table.tabulate(lambda r, fn=fn: fn(np.asarray(r, dtype=float) ** 2),
                                           R, _table.TABLE_FACTOR * plan.tol, kappa)
    src.values = (R, fns)
    return fns


def kernel_values(kernel):
    """``q ↦ φ(√q)`` as a fresh array (``value_sq``, on ``(1, m)`` blocks as the dense
    backend calls it, when the kernel has it); its attribute ``fused`` is the kernel's
    :func:`~kinred.pairsum.pair_form` (or None) for the compiled pass."""
    value_sq = getattr(kernel, "value_sq", None)
    if value_sq is not None:
        def values(q):
            q2 = q.reshape(1, -1)
            return value_sq(q2, np.empty_like(q2)).reshape(-1)
    else:
        def values(q):
            return np.asarray(kernel(np.sqrt(q)), dtype=np.float64) * np.ones_like(q)
    values.fused = pair_form(kernel)
    values.split = None
    values.table = None
    return values


def near_sums(s: np.ndarray, R: float, terms: list, compiled: bool = True, record=None,
              side=None, side_share: float = 0.0):
    """Add ``Σ_{j: |sᵢ−sⱼ|<R} φ_t(|sᵢ − sⱼ|) Z_t[j]`` to ``A_t[i]`` for the terms
    ``(q ↦ φ_t(√q), Z_t (n, d+1), A_t (n, d+1))`` (original order); ``record`` (if given)
    gets ``.pairs`` and ``.cells``; ``side``: other work the calling thread does first,
    overlapping the other threads' pairs, then the fraction ``side_share`` of the pairs
    (``_cells.accumulate``). Returns the number of pairs within ``R``."""
    grid = _cells.build(s, R)
    zs, accs, evals = [], [], []
    for kern, Z, A in terms:
        fn = kern
        zi = next((i for i, z in enumerate(zs) if z[0] is Z), None)
        if zi is None:
            zs.append((Z, Z[grid.perm]))
            zi = len(zs) - 1
        ai = next((i for i, a in enumerate(accs) if a is A), None)
        if ai is None:
            accs.append(A)
            ai = len(accs) - 1
        evals.append((fn, zi, ai))
    parts, pairs = _cells.accumulate(grid, evals, [z[1] for z in zs], len(accs),
                                     _parallel.get_num_threads(), compiled, side, side_share)
    total = parts[0]
    for p in parts[1:]:
        total += p
    for a, A in enumerate(accs):
        A[grid.perm] += total[a]
    if record is not None:
        record.pairs, record.cells = pairs, grid.cells
    return pairs


#: The largest ``TRIM`` fraction of the sampled ``|φ|`` values is left out of ``κ``.
TRIM = 0.1


def cell_scales(kernel, s: np.ndarray, ext: np.ndarray) -> tuple:
    """``(‖φ‖∞, κ)`` as in the NUFFT backend (``_fastsum.kernel_scales``: 4096 sampled pairs
    or all of them) but with ``κ`` the mean of ``|φ|`` over the sampled pairs *without their
    largest 10 %*: a kernel's cusp (Morse with ``soft = 0``, ``u ~ 1/s``) on a few close pairs
    would otherwise inflate ``κ`` – the carrier difference ``zⱼ − zᵢ`` tames it in the field –
    and shrink the cutoff (found by hypothesis: 15 agents on a line, error 3.4·tol). Never
    larger than the plain mean, so the cutoff only grows."""
    name = repr(kernel)
    kinf, kappa = _fastsum.kernel_scales(kernel, s, ext, name)
    n = s.shape[0]
    if n * (n - 1) <= _fastsum.PAIR_SAMPLE:
        i, j = np.triu_indices(n, 1)
    else:
        i, j = np.random.default_rng(_fastsum._PAIR_SEED).integers(0, n,
                                                                   (2, _fastsum.PAIR_SAMPLE))
        i, j = i[i != j], j[i != j]
    if i.size == 0:
        return kinf, kappa
    vals = np.sort(np.abs(_fastsum._profile(kernel, np.sqrt(np.sum((s[i] - s[j]) ** 2, axis=1)),
                                            name)))
    keep = vals[: max(1, int(math.ceil((1.0 - TRIM) * vals.size)))]
    return kinf, min(kappa, max(float(keep.mean()), _fastsum.KAPPA_FLOOR * kinf))


#: Rows of the field whose every pair :func:`term_cutoff` checks (fixed seed): all of them
#: up to ``√ROW_PAIRS`` agents, then about :data:`ROW_PAIRS` pairs in all, at least
#: ``ROW_SAMPLE`` rows (a sparse cloud's field lives on a few pairs per row, which a sample
#: of rows can miss entirely: 200 agents spread over 344 kernel widths).
ROW_SAMPLE = 4
ROW_PAIRS = 1 << 22
_ROW_SEED = 0xCE11
#: Distance bins of :func:`term_cutoff`'s tail sums.
CUTOFF_BINS = 4096


def term_cutoff(kernel, bound, s: np.ndarray, ext: np.ndarray, z: np.ndarray | None,
                c: np.ndarray | None, tol: float) -> tuple[float, float, float]:
    """``(R, ‖φ‖∞, κ)`` of one term: its cutoff, sup and accuracy scale on the cloud ``s``
    with carrier ``z`` and coefficients ``c``.

    ``R`` is the larger of two radii:

    1. ``B(R₀) ≤ TRUNC_FACTOR·tol·κ₀`` with ``κ₀`` of :func:`cell_scales` (4096 sampled pairs,
       floored at ``10⁻⁴‖φ‖∞``): each pair left out changes a row sum by at most ``B(R₀)``;
    2. on sampled rows ``i`` (:data:`ROW_PAIRS`; all rows of a small cloud) and *all* their
       pairs, the smallest ``R₁`` (to ``dmax/4096``) whose left-out pairs are bounded by the
       tail bound at their own distances within a ``TRUNC_FACTOR·tol`` of the field's scale:
       ``Σᵢ Σ_{j: rᵢⱼ>R₁} cⱼ B(rᵢⱼ)|zⱼ − zᵢ| ≤ TRUNC_FACTOR·tol·Σᵢ Σⱼ cⱼ|φᵢⱼ||zⱼ − zᵢ|``.
       A row loses ``Σ_{left} cⱼ φᵢⱼ (zⱼ − zᵢ)``: the pairs left out are those of largest
       carrier difference (for positions, their distance), which a scale per *pair* misses –
       with (1) alone, a 3-D Gaussian cloud of extents 240 × 1600 × 0.02 under Morse
       (``‖φ‖∞ = 62``, field scale ``5·10⁻⁷`` per unit of carrier) had a field error of
       7.6·tol at tol = 1e-8, a 2-D ring 2.3·tol at 1e-7 (a sweep of random clouds against
       Dense). Rows see their near neighbours however sparse the cloud.

    ``κ`` (the scale of the tables, ``_values``) is the smaller of ``κ₀`` and the rows'
    ``Σ cⱼ|φᵢⱼ||zⱼ − zᵢ| / Σ_{rᵢⱼ<R} cⱼ|zⱼ − zᵢ|``."""
    name = repr(kernel)
    dmax = float(np.sqrt(np.sum(ext * ext)))
    kinf, kappa = cell_scales(kernel, s, ext)
    if kinf == 0.0 or dmax == 0.0:
        return 0.0, kinf, kappa
    top = dmax * (1 + 1e-9)               # a hair beyond the diameter: every pair is within
    R = cutoff_radius(bound, TRUNC_FACTOR * tol * kappa, top)
    rows = _rows(s, z, c, top, kernel, bound, name)
    if rows is None:
        return R, kinf, kappa
    num, edges, tail, wsum = rows
    beyond = np.append(np.cumsum(tail[::-1])[::-1], 0.0)     # beyond[b] = Σ_{bins ≥ b}
    b = int(np.flatnonzero(beyond <= TRUNC_FACTOR * tol * num)[0])
    R = max(R, float(edges[b]))
    within = float(np.sum(wsum[: int(np.searchsorted(edges, R, side="right"))]))
    if within > 0.0:
        kappa = min(kappa, max(num / within, np.finfo(np.float64).tiny))
    return R, kinf, kappa


def _rows(s, z, c, top, kernel, bound, name):
    """``(num, edges, tail, wsum)`` over the sampled rows: the field scale
    ``Σ cⱼ|φᵢⱼ||zⱼ − zᵢ|`` and, per distance bin of ``[0, top]``, ``Σ cⱼ B(rᵢⱼ)|zⱼ − zᵢ|`` and
    ``Σ cⱼ|zⱼ − zᵢ|``; None without a carrier or when every weight vanishes."""
    if z is None:
        return None
    n = s.shape[0]
    rows = _fastsum.sample_rows(n, ROW_SAMPLE, ROW_PAIRS, _ROW_SEED)
    z = np.asarray(z, dtype=np.float64)
    cw = np.ones(n) if c is None else np.abs(np.asarray(c, dtype=np.float64))
    edges = np.linspace(0.0, top, CUTOFF_BINS + 1)
    tail, wsum = np.zeros(CUTOFF_BINS), np.zeros(CUTOFF_BINS)
    num = 0.0
    zr = z[rows]
    for a, e, q in _fastsum.row_blocks(s, rows):
        d = np.sqrt(q).ravel()
        w = (cw[None, a:e] * np.sqrt(_fastsum.sq_distances(zr, z[a:e]))).ravel()
        num += float(np.dot(np.abs(_fastsum._profile(kernel, d, name)), w))
        bins = np.minimum((d * (CUTOFF_BINS / top)).astype(np.int64), CUTOFF_BINS - 1)
        pos = d > 0.0
        bd = np.zeros_like(d)
        bd[pos] = np.asarray(bound(d[pos]), dtype=np.float64)
        tail += np.bincount(bins, bd * w, CUTOFF_BINS)
        wsum += np.bincount(bins, w, CUTOFF_BINS)
    if not (num > 0.0 and np.isfinite(num) and np.all(np.isfinite(tail))):
        return None
    return num, edges, tail, wsum


def cell_carriers(plan: CellListPlan, state: dict) -> dict:
    """Each carrier's state, rows centred (``_kernels.centre_rows``): what
    :meth:`CellList.evaluate` sums and :func:`source_cutoff` derives the cutoff from."""
    return {key: _kernels.centre_rows(np.ascontiguousarray(state[key]),
                                      np.empty((plan.n, plan.dim)))
            for key in plan.terms.carriers}


def source_cutoff(plan: CellListPlan, src: _Source, s: np.ndarray, carriers: dict) -> float:
    """The source's cutoff for the cloud ``s`` (``carriers``: :func:`cell_carriers`, for the
    cutoff of :func:`term_cutoff`): kept on ``src`` while its extents stay within
    :data:`REDECIDE` of those it was derived for (``pairsum="auto"`` prices the cell list
    with it, and the evaluation after the choice reuses it). Call under ``plan.lock``."""
    ext = s.max(axis=0) - s.min(axis=0)
    dmax = float(np.sqrt(np.sum(ext * ext)))
    if plan.cutoff is not None:
        src.R = plan.cutoff
        return src.R
    if src.R is not None and np.all(ext <= REDECIDE * src.ext) and np.all(ext >= src.ext / REDECIDE):
        return src.R
    R = 0.0 if dmax > 0 else 1.0          # coincident agents: every pair at distance 0 < R
    kappas = []
    for t, bound in zip(src.terms, src.bounds):
        r, kinf, kappa = term_cutoff(t.kernel, bound, s, ext, carriers[t.carrier], plan.c,
                                     plan.tol)
        kappas.append(kappa)
        R = max(R, r)
    src.R, src.ext = (math.nextafter(R, math.inf) if R > 0 else 0.0), ext
    src.kappas = tuple(kappas)
    return src.R
