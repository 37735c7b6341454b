"""The public entry points :func:`w1` and :func:`sliced_w1`."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .._rng import as_generator
from .._validate import as_choice, as_int
from ..errors import InvalidInput, TooLarge
from ._bracket import bracket_atoms, mean_lower
from ._inputs import Prod, Pts, grid_marginals, marginal, normalize_pair
from ._oned import product_upper, w1_1d, w1_atoms_1d, w1_cont_atoms
from ._pot import emd_dense, emd_lazy
from ._result import SlicedW1Result, W1Result
from ._sparse import DEFAULT_K, run_sparse

__all__ = ["w1", "sliced_w1", "METHODS", "DEFAULT_MAX_DENSE_BYTES", "DEFAULT_MAX_EXACT_PAIRS"]

METHODS = ("auto", "exact", "exact-lazy", "sparse", "exact-1d", "product-l1", "bracket")

#: "auto" builds the dense N×M cost matrix (8·N·M bytes) only below this many bytes (128 MiB);
#: above it, it switches to POT's lazy solver ``ot.lp.emd2_lazy`` (memory O(N + M)).
DEFAULT_MAX_DENSE_BYTES = 2**27

#: "auto" uses the dense LP only up to this many pairs N·M (2000 × 2000 atoms); beyond, the
#: sparse method is faster (docs/w1.md; ``benchmarks/bench_w1.py --scaling``) and as exact.
AUTO_DENSE_PAIRS = 4_000_000

#: "auto" solves the exact LP only while N·M stays below this (6000 × 6000 atoms; its cost at
#: this size is in docs/performance.md, section W1); beyond it, it raises TooLarge with the cost
#: of the exact LP (a certified bracket is ``method="bracket"``).
DEFAULT_MAX_EXACT_PAIRS = 36_000_000

#: Measured cost of ``exact-lazy`` at N = M = 6000 (N·M = DEFAULT_MAX_EXACT_PAIRS) on the
#: loaded 2-core development VM, and the growth of the time with N·M (N = M = 2000, 4000, 6000:
#: 9.1 s, 72 s, 218 s, i.e. about (N·M)^1.4); docs/performance.md, section W1. Only used to
#: quote an order of magnitude when "auto" refuses a size.
_LAZY_SECONDS_AT_LIMIT = 218.0
_LAZY_TIME_EXPONENT = 1.4

_GRID_ATOMS = 2000

#: Largest tensor grid of an all-atomic ``TensorProduct`` that is ever materialized as atoms.
_MAX_MATERIALIZE = 10**6


def _n_atoms(m):
    return m.n if isinstance(m, Pts) else (m.grid_size() if isinstance(m, Prod) and m.all_atomic else None)


def _as_pts(m, max_pairs_side: float):
    """Atoms of ``m`` if it is atomic (or an all-atomic product small enough), else None."""
    if isinstance(m, Pts):
        return m
    if isinstance(m, Prod) and m.all_atomic and m.grid_size() <= max_pairs_side:
        return m.materialize()
    return None


def _marginals(m, product: bool):
    """1-D marginals if ``m`` is a product measure (known or detected), else None."""
    if isinstance(m, Prod):
        return list(m.factors)
    if isinstance(m, Pts):
        if m.dim == 1:
            return [m]
        if product:
            return [marginal(m, j) for j in range(m.dim)]
        return grid_marginals(m)
    return None


def _coord_marginal(m, j):
    if isinstance(m, Prod):
        return m.factors[j]
    if isinstance(m, Pts):
        return marginal(m, j)
    return m  # 1-D continuous


def _exact_result(value, method, n_atoms, note, metric="euclidean"):
    v = float(value)
    return W1Result(v, method, True, v, v, n_atoms, note, metric)


def _quantize_product(p: Prod, budget: int):
    """Grid of per-coordinate midpoint quantizers (levels (2i−1)/(2n)) with ≤ ``budget`` atoms.

    Returns the grid atoms and ``Σⱼ W1(μⱼ, Qⱼ)`` (exact 1-D errors), which bounds the
    Euclidean W1 between the product and its grid from above (Lemma 4.1,
    with |·|₂ ≤ |·|₁).
    """
    n = [f.n if isinstance(f, Pts) else 1 for f in p.factors]

    def quant(f, k):
        if isinstance(f, Pts):
            return f, 0.0
        u = (2.0 * np.arange(1, k + 1) - 1.0) / (2.0 * k)
        q = Pts(f.ppf(u)[:, None], np.full(k, 1.0 / k))
        err, _ = w1_cont_atoms(f, q.points[:, 0], q.weights)
        return q, err

    qs = [quant(f, k) for f, k in zip(p.factors, n)]
    while True:
        errs = [e if not isinstance(f, Pts) else -1.0 for f, (_, e) in zip(p.factors, qs)]
        j = int(np.argmax(errs))
        if errs[j] <= 0:
            break
        size = math.prod(n) // n[j] * (2 * n[j])
        if size > budget:
            break
        n[j] *= 2
        qs[j] = quant(p.factors[j], n[j])
    grid = Prod([q for q, _ in qs])
    l1, root = product_upper(p.factors, grid.factors)
    return grid.materialize(), min(l1, root), n


def w1(
    mu,
    nu,
    method: str = "auto",
    *,
    a=None,
    b=None,
    metric: str = "euclidean",
    product: bool = False,
    max_dense_bytes: int = DEFAULT_MAX_DENSE_BYTES,
    max_exact_pairs: int = DEFAULT_MAX_EXACT_PAIRS,
    num_iter_max: int | None = None,
    n_projections: int = 64,
    leaf_size: int = 512,
    dual_sample: int = 1000,
    grid_atoms: int = _GRID_ATOMS,
    neighbors: int = DEFAULT_K,
    rtol: float | None = None,
    max_iter: int = 30,
    max_edges: int | None = None,
    max_seconds: float | None = None,
    max_bytes=None,
    seed=None,
) -> W1Result:
    r"""Wasserstein-1 distance between two probability measures on ℝᵈ.

    .. math:: W_1(\mu,\nu) = \inf_{\pi\in\Pi(\mu,\nu)} \int |x - y|\,d\pi(x, y)

    eq. (4.5) of the paper, Euclidean ground metric unless
    ``metric="l1"``.

    Every method computes in one common frame ``x = c + s·z`` of both measures (``s`` a power
    of two of the order of the width of their joint bounding box, ``c`` its centre on the
    coordinates where subtracting it is exact) and multiplies its numbers back by ``s``: W1 is
    translation invariant and homogeneous, ``W1(c + sμ, c + sν) = s·W1(μ, ν)``, so the costs
    stay of order one for any finite input (no overflow near 1e160, no underflow near 1e-200)
    and the result keeps its relative accuracy.

    Parameters
    ----------
    mu, nu : kinred measure, quantization or (N, d) array_like
        ``Atomic`` (incl. ``Dirac``, ``Empirical1D``), ``Univariate``/``Uniform``,
        ``TensorProduct`` of 1-D measures, ``Mixture`` of atomic measures, a result of
        :func:`kinred.quantize.quantize` (a ``TensorQuantization`` is used as the product of its
        1-D factors, never enumerated; mixtures and push-forwards are materialized, up to
        10⁶ atoms), or raw points ``(N, d)`` (a 1-D array is ``N`` points of ℝ¹).
    method : {"auto", "exact", "exact-lazy", "sparse", "exact-1d", "product-l1", "bracket"}
        * ``"exact"`` -- two atomic measures: ``ot.emd2`` on the dense Euclidean cost matrix
          (8·N·M bytes), ``numItermax = max(100000, 50·N·M)``; raises
          :class:`~kinred.errors.NotConverged` if POT still stops early.
        * ``"exact-lazy"`` -- the same LP with ``ot.lp.emd2_lazy`` (costs computed on the fly,
          memory O(N + M), slower than the dense solver: docs/performance.md, section W1).
        * ``"sparse"`` -- two atomic measures, Euclidean: POT's network simplex (for ``N``
          equal weights on both sides: scipy's sparse assignment solver) on a sparse
          candidate graph (``neighbors`` nearest neighbours from each side plus one coupling of
          the full measures), certified by the c-transform of its duals over *all* pairs
          (a lower bound, Kantorovich–Rubinstein), with column generation until the plan's
          cost (an upper bound) and the lower bound meet to round-off: then ``exact=True``
          and the value is proved optimal. If a budget (``max_iter``, ``max_edges``,
          ``max_seconds``) runs out first: the certified bracket, ``exact=False``, the reason
          in ``note`` (a first solve stopped on corresponding atoms falls back on
          :func:`paired_w1_bracket` with its dual bound, within another ``max_seconds``, which
          can still prove the index coupling optimal: then ``exact=True``). Memory ``O(neighbors·(N + M))``, priced first (``max_bytes``); the
          method of choice beyond a few thousand atoms (docs/w1.md).
        * ``"exact-1d"`` -- d = 1: sorted merge for atoms, :math:`\int|F - G|` by quadrature for
          continuous laws (exact to ~1e-13).
        * ``"product-l1"`` -- two product measures (``TensorProduct``, a full tensor grid of
          atoms, or atoms declared ``product=True``): the exact W1 for the ℓ1 ground cost,
          :math:`\sum_j W_1(\mu_j,\nu_j)` (Lemma 4.1); it bounds the
          Euclidean W1 from above. The result has ``metric="l1"``.
        * ``"bracket"`` -- certified ``lower ≤ W1 ≤ upper`` (lower bounds from 1-D projections and a subsampled dual, upper bounds from explicit couplings).
        * ``"auto"`` -- an exact value, never a bracket: exact-1d in d = 1; for atomic measures
          (or tensor grids of at most 10⁶ atoms) exact (dense) up to
          ``N·M = AUTO_DENSE_PAIRS`` (4·10⁶) and ``max_dense_bytes``, beyond it ``sparse``
          (Euclidean; any size) and, should that not close, the dense or lazy LP while they
          fit (the ℓ1 metric: exact, then exact-lazy); product-l1 for ``metric="l1"`` and two product
          measures. Otherwise it raises (:class:`~kinred.errors.TooLarge` for sizes,
          :class:`~kinred.errors.InvalidInput` for continuous laws in d > 1) naming the sizes,
          the method that would be exact and its estimated cost, and ``method="bracket"``. Its
          ``method`` and ``note`` say which method ran.
    a, b : (N,) / (M,) array_like, optional
        Weights of raw point arrays ``mu``/``nu`` (uniform by default); must be None for
        measures. Non-negative with a positive total; both are divided by their totals (as
        SciPy does), which must be equal (relative 1e-9) when both are given.
    neighbors, rtol, max_iter, max_edges, max_seconds, max_bytes : optional
        ``method="sparse"``: nearest neighbours per atom from each side; the relative gap at
        which the bounds meet (default 1e-13 plus the duals' round-off, at most 1e-11); the
        budgets of the column generation (solves, edges -- default four times the first graph --,
        seconds -- default none); the memory limit of its preflight
        (``kinred._validate.check_alloc``, default ``KINRED_MAX_BYTES`` or 2 GiB).
    metric : {"euclidean", "l1"}
        Ground metric for the exact methods. The bracket is Euclidean only.
    product : bool
        Declare raw atoms to be product measures (their coordinate marginals are used by
        ``product-l1``). Full tensor grids are detected without it.
    max_dense_bytes, max_exact_pairs : int
        The "auto" thresholds (:data:`DEFAULT_MAX_DENSE_BYTES`, :data:`DEFAULT_MAX_EXACT_PAIRS`);
        ``max_dense_bytes`` also guards ``method="exact"`` (:class:`~kinred.errors.TooLarge`).
    num_iter_max : int, optional
        Network-simplex iteration cap (default ``max(100000, 50·N·M)``).
    n_projections, leaf_size, dual_sample, grid_atoms : int
        Bracket effort: random directions, leaf size of the hierarchical coupling, sub-sample
        size of the dual bound (0 disables it), grid size when a continuous product is compared
        with non-product atoms.
    seed : None, int, SeedSequence or Generator
        Randomness of the bracket (directions, sub-samples).

    Returns
    -------
    W1Result

    Raises
    ------
    InvalidInput
        NaN/Inf, dimension mismatch, bad weights, unknown method, a method that does not
        apply to the given measures, or a distance above the largest float64.
    NotConverged
        POT stopped before optimality.
    TooLarge
        ``method="exact"`` with a cost matrix above ``max_dense_bytes``; ``method="auto"``
        beyond ``max_exact_pairs`` (or a tensor grid of more than 10⁶ atoms) for the
        Euclidean metric; a quantization to materialize above 10⁶ atoms.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.0, 0.0], [1.0, 0.0]])
    >>> r = w1(x, x + [3.0, 4.0])
    >>> r.value, r.method, r.exact
    (5.0, 'exact', True)
    >>> from kinred.measures import Uniform
    >>> round(w1(Uniform(0, 1), np.array([[0.25], [0.75]])).value, 12)   # σ/(4N)
    0.125
    """
    method = as_choice(method, "method", METHODS)
    metric = as_choice(metric, "metric", ("euclidean", "l1"))
    if not isinstance(product, (bool, np.bool_)):
        raise InvalidInput(f"product must be True or False, got {product!r}")
    max_dense_bytes = as_int(max_dense_bytes, "max_dense_bytes", low=0)
    max_exact_pairs = as_int(max_exact_pairs, "max_exact_pairs", low=0)
    if num_iter_max is not None:
        num_iter_max = as_int(num_iter_max, "num_iter_max", low=1)
    n_projections = as_int(n_projections, "n_projections", low=0)
    leaf_size = as_int(leaf_size, "leaf_size", low=1)
    dual_sample = as_int(dual_sample, "dual_sample", low=0)
    grid_atoms = as_int(grid_atoms, "grid_atoms", low=1)
    sparse = _sparse_options(neighbors, rtol, max_iter, max_edges, max_seconds, max_bytes)
    A, B, unit = normalize_pair(mu, nu, a, b)
    A, B = _unwrap_1d(A), _unwrap_1d(B)
    problem = _Problem(
        A=A, B=B, d=A.dim, n_atoms=(_n_atoms(A), _n_atoms(B)), unit=unit, metric=metric,
        product=product, max_dense_bytes=max_dense_bytes, max_exact_pairs=max_exact_pairs,
        num_iter_max=num_iter_max, n_projections=n_projections, leaf_size=leaf_size,
        dual_sample=dual_sample, grid_atoms=grid_atoms, rng=_LazyRng(seed), sparse=sparse)
    chosen = method
    if method == "auto":
        chosen, problem = _resolve_auto(problem)
    res = _RUNNERS[chosen](problem)
    note = f"auto chose {res.method}: {res.note}" if method == "auto" else res.note
    return _in_units(res, unit, note)


def _sparse_options(neighbors, rtol, max_iter, max_edges, max_seconds, max_bytes) -> dict:
    """The validated options of ``method="sparse"``."""
    from .._validate import as_float, max_bytes_limit

    return dict(
        k=as_int(neighbors, "neighbors", low=1),
        rtol=None if rtol is None else as_float(rtol, "rtol", low=0.0),
        max_iter=as_int(max_iter, "max_iter", low=1),
        max_edges=None if max_edges is None else as_int(max_edges, "max_edges", low=1),
        max_seconds=None if max_seconds is None else as_float(max_seconds, "max_seconds",
                                                              low=0.0),
        max_bytes=max_bytes_limit(max_bytes))


class _LazyRng:
    """The bracket's generator, made from ``seed`` on first use (the exact methods draw nothing)."""

    def __init__(self, seed):
        self._seed = seed

    def __call__(self) -> np.random.Generator:
        if not isinstance(self._seed, np.random.Generator):
            self._seed = as_generator(self._seed)
        return self._seed


@dataclass(frozen=True)
class _Problem:
    """One validated :func:`w1` call: both measures in the common frame and the options.

    ``A``, ``B`` are internal forms (:mod:`kinred.distance._inputs`) of dimension ``d``;
    ``n_atoms`` their atom counts (None for a continuous law); ``unit`` the scale of the
    common frame (it only scales the numbers quoted in notes; results are multiplied by it in
    :func:`w1`). The other fields are the validated keyword arguments of :func:`w1`.
    """

    A: object
    B: object
    d: int
    n_atoms: tuple
    unit: float
    metric: str
    product: bool
    max_dense_bytes: int
    max_exact_pairs: int
    num_iter_max: int | None
    n_projections: int
    leaf_size: int
    dual_sample: int
    grid_atoms: int
    rng: _LazyRng
    sparse: dict


def _unwrap_1d(m):
    """The factor of a one-factor product (d = 1 measures are compared as 1-D laws)."""
    return m.factors[0] if isinstance(m, Prod) and m.dim == 1 else m


def _resolve_auto(p: _Problem) -> tuple[str, _Problem]:
    """The exact method "auto" picks for ``p``, and ``p`` with its atoms materialized for an LP.

    exact-1d in d = 1; for atomic measures (or all-atomic products of at most 10⁶ atoms) the
    dense LP below ``max_dense_bytes``, above it the sparse method (Euclidean; falling back to
    the lazy LP while ``N·M ≤ max_exact_pairs``, :func:`_run_auto_sparse`), the lazy LP for the
    ℓ1 metric while ``N·M ≤ max_exact_pairs``; product-l1 for ``metric="l1"`` and two product
    measures. Otherwise no exact method fits: :func:`_no_exact_method` says why, what would
    be exact and at what cost.
    """
    if p.d == 1:
        return "exact-1d", p
    PA, PB = _as_pts(p.A, _MAX_MATERIALIZE), _as_pts(p.B, _MAX_MATERIALIZE)
    if PA is not None and PB is not None:
        q = replace(p, A=PA, B=PB, n_atoms=(PA.n, PB.n))
        pairs = PA.n * PB.n
        dense = pairs <= p.max_exact_pairs and 8 * pairs <= p.max_dense_bytes
        if dense and (pairs <= AUTO_DENSE_PAIRS or p.metric != "euclidean"):
            return "exact", q
        if p.metric == "euclidean":
            return "auto-sparse", q
        if pairs <= p.max_exact_pairs:
            return "exact-lazy", q
    products = _marginals(p.A, p.product) is not None and _marginals(p.B, p.product) is not None
    if p.metric == "l1" and products:
        return "product-l1", p
    raise _no_exact_method(p, products)


def _run_sparse(p: _Problem) -> W1Result:
    """The sparse network simplex certified by its dual (:mod:`kinred.distance._sparse`)."""
    if p.metric != "euclidean":
        raise InvalidInput("method='sparse' is for the Euclidean ground metric; got metric='l1' "
                           "(use 'exact' or 'exact-lazy')")
    PA, PB = _atoms_for_lp(p, "sparse")
    return run_sparse(PA, PB, p.rng(), num_iter_max=p.num_iter_max, n_atoms=(PA.n, PB.n),
                      unit=p.unit, **p.sparse)


def _run_auto_sparse(p: _Problem) -> W1Result:
    """"auto" beyond :data:`AUTO_DENSE_PAIRS`: the sparse method; if it does not close, the
    dense LP where it fits ``max_dense_bytes``, the lazy LP while ``N·M ≤ max_exact_pairs``,
    else TooLarge carrying the certified bracket (``.result``)."""
    try:
        res = _run_sparse(p)
    except TooLarge:                               # its memory preflight: the lazy LP if allowed
        if p.n_atoms[0] * p.n_atoms[1] > p.max_exact_pairs:
            raise
        return _run_exact_lazy(p)
    if res.exact:
        return res
    n, m = res.n_atoms
    if n * m <= p.max_exact_pairs and 8 * n * m <= p.max_dense_bytes:
        dense = _run_exact(p)
        return replace(dense, note=f"{dense.note} (the sparse method did not close: {res.note})")
    if n * m <= p.max_exact_pairs:
        lazy = _run_exact_lazy(p)
        return replace(lazy, note=f"{lazy.note} (the sparse method did not close: {res.note})")
    err = TooLarge(
        f"w1(method='auto'): the sparse method did not reach the exact W1 of {n} x {m} atoms "
        f"(certified bracket [{res.lower * p.unit:.17g}, {res.upper * p.unit:.17g}]: "
        f"{res.note}), and N·M = {n * m} > max_exact_pairs = {p.max_exact_pairs} rules out the "
        "exact lazy LP; ask method='sparse' for the bracket, or raise its budgets (max_iter, "
        "max_edges, max_seconds) or max_exact_pairs")
    err.result = _in_units(res, p.unit, res.note)
    raise err


def _fmt_count(n) -> str:
    """An atom count (exact int, possibly astronomically large) in a few characters."""
    s = str(int(n))
    return s if len(s) <= 12 else f"{s[0]}.{s[1:3]}e+{len(s) - 1}"


def _fmt_seconds(s: float) -> str:
    for unit, size in (("days", 86400.0), ("hours", 3600.0), ("minutes", 60.0)):
        if s >= 2 * size:
            return f"{s / size:.2g} {unit}"
    return f"{s:.2g} s"


def _no_exact_method(p: _Problem, products: bool) -> Exception:
    """The error of "auto" when no exact method fits ``p``: sizes, the exact method and its cost,
    and the explicit alternatives (a bracket, the l1 W1 of products, raising the limit)."""
    alt = ("ask method='bracket' for a certified bracket lower <= W1 <= upper (its W1Result "
           "has exact=False unless the bounds meet)")
    if products:
        alt += (", or method='product-l1' for the exact W1 for the l1 ground cost (Lemma 4.1; an "
                "upper bound of the Euclidean W1)")
    if None in p.n_atoms:
        which = [n for n, c in zip(("mu", "nu"), p.n_atoms) if c is None]
        what = "mu and nu are continuous laws" if len(which) == 2 else f"{which[0]} is a continuous law"
        return InvalidInput(
            f"w1(method='auto'): {what} in d = {p.d}, and no method computes their "
            f"{p.metric} W1 exactly; {alt}; or quantize (kinred.quantize) and compare the atoms "
            "exactly")
    n, m = p.n_atoms
    pairs = n * m
    sizes = f"mu has {_fmt_count(n)} atoms and nu {_fmt_count(m)} (N·M = {_fmt_count(pairs)})"
    if max(n, m) > _MAX_MATERIALIZE:
        return TooLarge(
            f"w1(method='auto'): {sizes}; the exact LP needs the atoms of a tensor grid of more "
            f"than {_MAX_MATERIALIZE:.0e} atoms, which kinred never builds; {alt}")
    seconds = _LAZY_SECONDS_AT_LIMIT * (pairs / DEFAULT_MAX_EXACT_PAIRS) ** _LAZY_TIME_EXPONENT
    return TooLarge(
        f"w1(method='auto'): {sizes} > max_exact_pairs = {p.max_exact_pairs}. The exact W1 is "
        f"method='exact-lazy' (POT network simplex, memory O(N + M), time roughly "
        f"{_fmt_seconds(seconds)} on the loaded 2-core reference VM, docs/performance.md) or method='exact' (a dense "
        f"{8 * pairs / 2**30:.3g} GiB cost matrix, 2-3x faster); pass max_exact_pairs >= "
        f"{pairs} to let 'auto' run it, or {alt}")


def _to_units(value: float, unit: float, what: str) -> float:
    """``value`` (a distance in the frame of :func:`normalize_pair`) times the frame's scale."""
    out = float(value) * unit
    if not math.isfinite(out):
        raise InvalidInput(
            f"{what}(mu, nu) = {float(value)!r} x {unit!r} exceeds the largest float64 "
            f"({np.finfo(np.float64).max:.3g}); rescale mu and nu ({what}(s mu, s nu) = "
            f"s {what}(mu, nu))"
        )
    return out


def _in_units(res: W1Result, unit: float, note: str) -> W1Result:
    """``res``, computed in the common frame, in the units of the input (bounds included)."""
    value = _to_units(res.value, unit, "W1")
    lower, upper = float(res.lower) * unit, float(res.upper) * unit
    return W1Result(value, res.method, res.exact, lower, upper, res.n_atoms, note, res.metric,
                    res.info)


def _atoms_for_lp(p: _Problem, method: str):
    """Both measures as atoms for the exact LP ``method``, or InvalidInput naming the fix."""
    PA, PB = _as_pts(p.A, _MAX_MATERIALIZE), _as_pts(p.B, _MAX_MATERIALIZE)
    if PA is None or PB is None:
        raise InvalidInput(
            f"method={method!r} needs two atomic measures (Atomic, Dirac, Empirical1D, arrays "
            "of points, or a TensorProduct of atomic factors); use 'exact-1d' for a continuous "
            "law in d = 1 or 'bracket'/'auto' otherwise"
        )
    return PA, PB


def _run_exact(p: _Problem) -> W1Result:
    """``ot.emd2`` on the dense cost matrix, refused above ``max_dense_bytes`` (TooLarge)."""
    PA, PB = _atoms_for_lp(p, "exact")
    need = 8 * PA.n * PB.n
    if need > p.max_dense_bytes:
        raise TooLarge(
            f"method='exact' needs a dense {PA.n} x {PB.n} cost matrix ({need / 2**20:.0f} MiB) "
            f"above max_dense_bytes={p.max_dense_bytes} ({p.max_dense_bytes / 2**20:.0f} MiB); "
            "use method='exact-lazy' or raise max_dense_bytes"
        )
    v = emd_dense(PA.points, PA.weights, PB.points, PB.weights, metric=p.metric,
                  num_iter_max=p.num_iter_max)
    note = f"POT ot.emd2 on the dense {p.metric} cost matrix (network simplex, optimal)"
    return _exact_result(v, "exact", (PA.n, PB.n), note, p.metric)


def _run_exact_lazy(p: _Problem) -> W1Result:
    """``ot.lp.emd2_lazy``: the same LP with costs computed on the fly (memory O(N + M))."""
    PA, PB = _atoms_for_lp(p, "exact-lazy")
    v = emd_lazy(PA.points, PA.weights, PB.points, PB.weights, metric=p.metric,
                 num_iter_max=p.num_iter_max)
    return _exact_result(v, "exact-lazy", (PA.n, PB.n),
                         f"POT ot.lp.emd2_lazy, {p.metric} costs computed on the fly (optimal)",
                         p.metric)


def _run_exact_1d(p: _Problem) -> W1Result:
    """Exact W1 on ℝ¹: sorted merge of atoms, ``∫|F − G|`` by quadrature for laws."""
    if p.d != 1:
        raise InvalidInput(f"method='exact-1d' needs measures on ℝ¹, got dim {p.d}")
    v, err, how = w1_1d(p.A, p.B)
    note = f"exact 1-D W1 ({how})"
    if err > 0:
        note += f"; quadrature error estimate {err * p.unit:.1e}"
    return _exact_result(v, "exact-1d", p.n_atoms, note, p.metric)


def _run_product_l1(p: _Problem) -> W1Result:
    """Σⱼ W1(μⱼ, νⱼ) of the coordinate marginals: the exact ℓ1 W1 of two products (Lemma 4.1)."""
    ma, mb = _marginals(p.A, p.product), _marginals(p.B, p.product)
    if ma is None or mb is None:
        which = "mu" if ma is None else "nu"
        raise InvalidInput(
            f"method='product-l1' needs two product measures; {which} is neither a "
            "TensorProduct nor a full tensor grid of atoms with product weights (pass "
            "product=True to use the coordinate marginals of atoms you know to be a product)"
        )
    parts = [w1_1d(fa, fb)[0] for fa, fb in zip(ma, mb)]
    v = float(sum(parts))
    return _exact_result(
        v, "product-l1", p.n_atoms,
        f"sum of {p.d} exact marginal W1s = exact W1 for the l1 ground cost (Lemma 4.1); an "
        "upper bound for the Euclidean W1", "l1")


_L1_UPPER = "product-l1 (sum of marginal W1s, |.|_2 <= |.|_1)"
_ROOT_UPPER = "the product of the monotone marginal couplings, (sum_j W2_j^2)^(1/2)"
_L1_LOWER = "product-l1 / sqrt(d)"


def _run_bracket(p: _Problem) -> W1Result:
    """Certified ``lower ≤ W1 ≤ upper`` (Euclidean): atoms, or a continuous product in d > 1.

    Two products also contribute their marginal bounds: ``Σⱼ W1ⱼ`` and ``(Σⱼ W2ⱼ²)^(1/2)``
    from above (couplings of the whole), ``Σⱼ W1ⱼ / √d`` from below.
    """
    if p.metric != "euclidean":
        raise InvalidInput("method='bracket' is for the Euclidean ground metric; got metric='l1'")
    if p.d == 1:
        v, err, how = w1_1d(p.A, p.B)
        return W1Result(v, "bracket", False, v, v, p.n_atoms, f"d = 1: exact 1-D W1 ({how})")
    PA, PB = _as_pts(p.A, _MAX_MATERIALIZE), _as_pts(p.B, _MAX_MATERIALIZE)
    mA, mB = _marginals(p.A, False), _marginals(p.B, False)
    marginal_bounds = product_upper(mA, mB) if mA is not None and mB is not None else None
    if PA is not None and PB is not None:
        return _bracket_of_atoms(p, PA, PB, marginal_bounds)
    return _bracket_of_continuous(p, marginal_bounds)


def _bracket_of_atoms(p: _Problem, PA, PB, marginal_bounds) -> W1Result:
    """:func:`bracket_atoms` on two atomic measures, with the marginal bounds if any."""
    extra = extra_lo = None
    if marginal_bounds is not None:
        l1, root = marginal_bounds
        extra = (_ROOT_UPPER, root) if root < l1 else (_L1_UPPER, l1)
        extra_lo = (_L1_LOWER, l1 / math.sqrt(p.d))
    lower, upper, note = bracket_atoms(PA, PB, p.rng(), n_projections=p.n_projections,
                                       leaf_size=p.leaf_size, dual_sample=p.dual_sample,
                                       extra_upper=extra, extra_lower=extra_lo)
    return _bracket_result(lower, upper, p.n_atoms, note)


def _bracket_of_continuous(p: _Problem, marginal_bounds) -> W1Result:
    """Bracket with at least one continuous product in d > 1: the best of named bounds.

    From below: the largest coordinate-marginal W1 and the difference of means (both
    1-Lipschitz tests); from above and below, the marginal bounds of two products, or else the
    triangle inequality through a grid quantization of the product side
    (:func:`_via_grid`).
    """
    coord = [w1_1d(_coord_marginal(p.A, j), _coord_marginal(p.B, j))[0] for j in range(p.d)]
    lows = {"exact W1 of the coordinate marginals": max(coord),
            "mean difference": mean_lower(p.A.mean(), p.B.mean())}
    ups = {}
    if marginal_bounds is not None:
        l1, root = marginal_bounds
        ups[_L1_UPPER] = l1
        ups[_ROOT_UPPER] = root
        lows[_L1_LOWER] = l1 / math.sqrt(p.d)
    else:
        lo, up, grid = _via_grid(p)
        ups[f"triangle inequality via {grid}"] = up
        lows["triangle inequality via the grid"] = lo
    lo_name = max(lows, key=lows.get)
    up_name = min(ups, key=ups.get)
    lower, upper = max(0.0, lows[lo_name]), ups[up_name]
    return _bracket_result(min(lower, upper), upper, p.n_atoms,
                           f"lower bound from {lo_name}, upper bound from {up_name}")


def _via_grid(p: _Problem) -> tuple[float, float, str]:
    """``W1(G, other) ∓ e_G``: ``G`` a grid of the product side, ``e_G ≥ W1(product, G)``.

    One side is a product with continuous factors, the other non-product atoms; ``G`` has at
    most ``grid_atoms`` atoms (:func:`_quantize_product`), ``W1(G, other)`` is exact while
    ``N·M ≤ max_exact_pairs`` (dense or lazy by ``max_dense_bytes``) and bracketed beyond.
    Returns the lower bound, the upper bound and a description of ``G``.
    """
    prod_side, other = (p.A, p.B) if isinstance(p.A, Prod) else (p.B, p.A)
    if not isinstance(other, Pts):
        raise InvalidInput("bracket: unsupported pair of measures")  # pragma: no cover
    G, eG, _ = _quantize_product(prod_side, p.grid_atoms)
    if G.n * other.n <= p.max_exact_pairs:
        emd = emd_dense if 8 * G.n * other.n <= p.max_dense_bytes else emd_lazy
        rlo = rup = emd(G.points, G.weights, other.points, other.weights)
    else:
        rlo, rup, _ = bracket_atoms(G, other, p.rng(), n_projections=p.n_projections,
                                    leaf_size=p.leaf_size, dual_sample=p.dual_sample)
    return rlo - eG, rup + eG, f"a {G.n}-atom grid quantization (grid error <= {eG * p.unit:.3g})"


#: The runner of each resolved method (every entry of :data:`METHODS` but "auto", and the
#: sparse method with the fallbacks of "auto").
_RUNNERS = {
    "exact": _run_exact,
    "exact-lazy": _run_exact_lazy,
    "sparse": _run_sparse,
    "auto-sparse": _run_auto_sparse,
    "exact-1d": _run_exact_1d,
    "product-l1": _run_product_l1,
    "bracket": _run_bracket,
}


#: Relative widening of every bracket, so that it stays certified despite floating-point
#: round-off in the sums that produce its ends.
_ROUNDOFF = 1e-12


def _bracket_result(lower, upper, n_atoms, note):
    lower, upper = float(lower) * (1 - _ROUNDOFF), float(upper) * (1 + _ROUNDOFF)
    if upper - lower <= 4 * _ROUNDOFF * abs(upper):
        v = 0.5 * (lower + upper)
        return W1Result(v, "bracket", True, v, v, n_atoms, note + " (bounds meet to round-off)")
    return W1Result(0.5 * (lower + upper), "bracket", False, lower, upper, n_atoms,
                    note + f"; value is the midpoint, relative width {(upper - lower) / upper:.2g}")


def sliced_w1(mu, nu, n_projections: int = 256, *, a=None, b=None, seed=None) -> SlicedW1Result:
    r"""Sliced Wasserstein-1 distance -- a different distance from W1, never an estimate of it.

    .. math:: SW_1(\mu,\nu) = \int_{S^{d-1}} W_1(\theta\#\mu,\theta\#\nu)\,d\sigma(\theta)

    estimated by the mean over ``n_projections`` uniformly random unit directions (exact 1-D
    W1 for each). :math:`SW_1 \le W_1`, and the ratio can be small in high dimension: for a
    translation by ``t``, :math:`SW_1 = |t|\,\mathbb E|\theta_1| = |t|\,\Gamma(d/2) /
    (\sqrt\pi\,\Gamma((d+1)/2))`, about ``0.26 |t|`` in d = 10 while ``W1 = |t|``.

    Parameters
    ----------
    mu, nu : atomic kinred measures or (N, d) array_like
    n_projections : int
    a, b : optional weights of raw point arrays
    seed : None, int, SeedSequence or Generator

    Returns
    -------
    SlicedW1Result

    Examples
    --------
    >>> import numpy as np
    >>> x = np.zeros((1, 10))
    >>> r = sliced_w1(x, x + 1.0 / np.sqrt(10), n_projections=4000, seed=0)
    >>> abs(r.value - 0.2587) < 4 * r.stderr
    True
    """
    n_projections = as_int(n_projections, "n_projections", low=1)
    A, B, unit = normalize_pair(mu, nu, a, b)
    PA, PB = _as_pts(A, _MAX_MATERIALIZE), _as_pts(B, _MAX_MATERIALIZE)
    if PA is None or PB is None:
        raise InvalidInput("sliced_w1 needs atomic measures (quantize continuous ones first)")
    rng = as_generator(seed)
    th = rng.standard_normal((n_projections, PA.dim))
    th /= np.linalg.norm(th, axis=1, keepdims=True)
    px = PA.points @ th.T
    py = PB.points @ th.T
    vals = np.array([w1_atoms_1d(px[:, k], PA.weights, py[:, k], PB.weights)
                     for k in range(n_projections)])
    se = float(vals.std(ddof=1) / math.sqrt(n_projections)) if n_projections > 1 else float("nan")
    return SlicedW1Result(_to_units(vals.mean(), unit, "SW1"), se * unit, n_projections,
                          f"mean of exact 1-D W1 over {n_projections} random directions; "
                          "sliced W1 <= W1, NOT an estimate of W1")
