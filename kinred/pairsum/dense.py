r"""The exact dense pair-sum backend: blocked BLAS products and numba kernels.

:class:`Dense` evaluates every pair sum of a scene (see :class:`~kinred.pairsum.PairTerms`)
exactly, walking over row strips ``I = [i0, i1)`` against columns ``j ≥ i0`` (each unordered
pair once, memory ``O(N·block)``; strips of about 64k entries, ≈ 512 kB, so a block stays in
L2), for each distance source the scene needs (``x`` and/or ``v``, never one it does not):

1. squared distances: for ``k ≤ 3`` by differences (numba, vectorized over columns); else
   a BLAS Gram block ``−2 Y_I Y_Jᵀ`` of centred coordinates written straight into the strip,
   plus one numba pass that adds the norms and recomputes close pairs by differences
   (relative error ≤ 4e-13, see ``_kernels``);
2. kernel values in place on the block (the last term of a source overwrites the
   distances): the kernel's compiled form if it has one (Cucker–Smale), else its numpy
   ``value_sq`` or ``kernel(√q)``;
3. two in-place BLAS products per strip, ``A_I += Φ_I,[i0:] Z_[i0:]`` and, by symmetry,
   ``A_[i1:] += Φ_I,[i1:]ᵀ Z_I`` with ``Z = [c z, c]`` (``gemm`` with ``β = 1`` on
   sub-blocks, no temporaries): one kernel block feeds both orientations, so every unordered
   pair's kernel is evaluated once. This gives ``Σⱼ cⱼ φᵢⱼ zⱼ`` and the row sums
   ``Σⱼ cⱼ φᵢⱼ``; the contribution is ``Σⱼ cⱼ φᵢⱼ zⱼ − (Σⱼ cⱼ φᵢⱼ) zᵢ`` with the carrier
   ``z`` centred (so velocity fluctuations near 1e-15 keep their relative accuracy).

With ``n`` engine threads (:func:`~kinred.dynamics.set_num_threads`) the strips are dealt
out to ``n`` threads (the calling thread and ``n − 1`` pooled ones; BLAS runs one thread per
engine thread), each with its own accumulator; a right-hand side estimated below
:data:`PARALLEL_MIN_SECONDS` on one thread (:data:`PARALLEL_MIN_SECONDS_LOOP` for the Python
strip loop) runs in one (the hand-off costs more). When every term's kernel has a compiled form,
a thread's whole share (steps 1–3 for all its strips) is one compiled call that holds no GIL
(``_kernels.pair_strips``, BLAS called from numba); otherwise a Python loop makes the same
calls strip by strip, and each call's GIL hand-back can wait for the other thread.

With ``precision="mixed"`` steps 1–3 (Gram blocks, kernel values, products and accumulators)
run in float32 (``sgemm``), with close pairs still recomputed from float64 differences; the
centring before and the combination after them stay in float64.

The strips, their threads, the distance blocks and the products are the strip walker of
:mod:`kinred.pairsum.strips` (public for other passes over all pairs, the certificate's).

Timings behind these choices (strip sizes, the compiled worker, variants not kept):
docs/performance.md, section "Pair-sum engine".
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import partial

import numpy as np

from .._validate import as_choice, as_float, as_int, check_alloc
from .. import _parallel
from ..errors import InvalidInput, TooLarge
from . import _cost, _kernels
from ._base import PairTerms, check_plan_args
from .strips import BIG_K, SMALL_K, STRIP_ELEMS  # noqa: F401  (the strip walker's constants)
from .strips import _deal as _balance, _products as _pair_products, _row_strips as strips

__all__ = ["Dense", "DensePlan"]

#: Per calling thread: the scratch buffers, reused from step to step (fresh multi-megabyte
#: arrays every step cost more in page faults than the arithmetic on them).
_SCRATCH = threading.local()
_SCRATCH_KEEP = 2                  # signatures kept per thread (e.g. an original and a projection)
_SCRATCH_MAX_BYTES = 256 * 2**20   # larger workspaces are not kept between calls

#: Optimistic pair throughputs of the whole engine (pairs per second, all threads; measured
#: about 5e8 with compiled kernels and 8e7 with numpy kernels in 2-D on 2 cores): the time
#: estimate of :meth:`Dense.plan` divides by them, so it is a lower bound of the real time.
PAIRS_PER_SECOND_COMPILED = 2e9
PAIRS_PER_SECOND_NUMPY = 5e8
#: Default ``max_seconds``: a right-hand side estimated (optimistically) beyond it is refused.
MAX_SECONDS = 3600.0
#: A right-hand side that one thread does in less than this (by the cost model's
#: :func:`~kinred.pairsum._cost.dense_seconds`) runs in one thread: handing half of it to a
#: second thread costs about 0.2 ms (wake-up, a second accumulator), which two threads win
#: back only from about 0.6 ms of work (docs/performance.md, "Threads for small N").
PARALLEL_MIN_SECONDS = 6e-4
#: The same for the Python strip loop (a kernel without compiled form, e.g. Morse): each of
#: its 6–10 calls per strip hands the GIL back to the other thread, so two threads win only
#: from about 5 ms of one-thread work on (at N = 200 they were 4.7× slower than one).
PARALLEL_MIN_SECONDS_LOOP = 5e-3

_KIND_CODE = {"cs_halfint": _kernels.KIND_CS_HALFINT, "cs_pow": _kernels.KIND_CS_POW}


def _scratch(sig: tuple, make) -> dict:
    """The scratch buffers of signature ``sig`` for the calling thread (``make()`` on first use).

    ``make()`` returns ``(buffers, nbytes)``; workspaces above :data:`_SCRATCH_MAX_BYTES` are
    used once and released (at that size the arithmetic dwarfs the allocation).
    """
    cache = getattr(_SCRATCH, "cache", None)
    if cache is None:
        cache = _SCRATCH.cache = {}
    ws = cache.pop(sig, None)
    if ws is None:
        ws, nbytes = make()
        if nbytes > _SCRATCH_MAX_BYTES:
            return ws
        while len(cache) >= _SCRATCH_KEEP:
            cache.pop(next(iter(cache)))
    cache[sig] = ws        # most recently used last
    return ws


@dataclass(frozen=True, eq=False)
class _Worker:
    """The per-term arrays of the compiled strip worker (``_kernels.pair_strips``)."""

    esrc: np.ndarray      # source index of each term
    elast: np.ndarray     # last term of its source: may overwrite the distance block
    ekind: np.ndarray     # compiled kind code
    epar: np.ndarray      # (a, b) in the stage dtype
    ez: np.ndarray        # carrier index
    eacc: np.ndarray      # accumulator index
    tau: np.floating      # Gram fix-up threshold in the stage dtype
    groups: tuple         # per thread: (strips, 2) int64


@dataclass(frozen=True, eq=False)
class DensePlan:
    """Everything :meth:`Dense.evaluate` needs that depends only on the scene and the shape.

    Attributes
    ----------
    n, dim : int
    terms : PairTerms
    c : (n,) ndarray
        The coefficients ``c_j``.
    dtype : numpy.dtype
        Of the pairwise stage (float32 with ``precision="mixed"``).
    strips : tuple of (int, int)
    groups : tuple of tuple of (int, int)
        The strips of each engine thread.
    small : bool
        Distances by differences (``dim <= 3``) rather than Gram blocks.
    centred : tuple of str
        State arrays centred per call (carriers, and Gram sources).
    maxel, need_phi, signature, nbytes
        Workspace size, whether a second kernel block is needed (a source with two terms),
        the workspace's cache key and size in bytes.
    loop : tuple
        Per source (in ``terms.sources`` order), its terms as ``(term, value_sq or None)``
        for the Python strip loop.
    worker : _Worker or None
        The compiled worker's arrays, when it applies.
    """

    n: int
    dim: int
    terms: PairTerms
    c: np.ndarray
    dtype: np.dtype
    strips: tuple
    groups: tuple
    small: bool
    centred: tuple
    maxel: int
    need_phi: bool
    signature: tuple
    nbytes: int
    loop: tuple
    worker: _Worker | None


class Dense:
    """The exact dense pair-sum backend (the default): blocked BLAS products, numba kernels.

    Parameters
    ----------
    block : int, optional
        Rows per strip (default: strips of about 64k pairwise entries, at most 128 rows;
        memory ``O(N·block)``).
    precision : {"double", "mixed"}
        ``"double"`` (default): everything in float64. ``"mixed"``: the pairwise stage (Gram
        blocks, kernel values, the two pair-sum products and their accumulators) runs in
        float32 – about twice the BLAS throughput – while the state, the centring, the fix-up
        of close pairs (by float64 differences), the final ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ`` and
        the integrator stay in float64. Carriers are centred before rounding, so the error of
        a pair sum is relative to the *fluctuation* size (velocity fluctuations near 1e-15
        keep about 6 digits). Accuracy measured on the paper's runs: docs/dynamics.md.
    compiled : bool
        Run a thread's strips as one compiled call when every kernel has a compiled form
        (default True); False forces the Python strip loop (same operations), for comparison
        (its threshold for sharing a right-hand side between threads is higher,
        ``dense.PARALLEL_MIN_SECONDS_LOOP``, so below it the strips, and the round-off, may
        differ from the compiled run's).
    max_seconds : float
        :meth:`plan` refuses (:class:`~kinred.errors.TooLarge`, before any work) a size whose
        estimated time per right-hand side exceeds it (default one hour). The estimate
        (``kinred.pairsum.dense.estimate_seconds``) is optimistic – a lower bound of the real time – so
        that only sizes surely out of reach are refused (e.g. ``N = 10⁷`` in 2-D: about 7
        hours at best); the message names the backend that fits. The workspace is checked
        against the memory limit (``kinred._validate.check_alloc``) as well.

    Examples
    --------
    >>> from kinred.dynamics import Alignment, CuckerSmale, Scene
    >>> from kinred.pairsum import Dense
    >>> sc = Scene([Alignment(CuckerSmale(1.0, 0.0))], pairsum=Dense(block=1))
    >>> sc.rhs(np.array([[0.0], [1.0]]), np.array([[1.0], [-1.0]]))[1].ravel()
    array([-1.,  1.])
    """

    #: The pair sums are exact up to round-off (float32 round-off of ``"mixed"`` included, which
    #: certificates account for): certificates cover this backend.
    exact = True

    def __init__(self, block: int | None = None, precision: str = "double", compiled: bool = True,
                 max_seconds: float = MAX_SECONDS):
        self.block = None if block is None else as_int(block, "block", low=1)
        self.max_seconds = as_float(max_seconds, "max_seconds", low=0.0, low_open=True)
        self.precision = as_choice(precision, "precision", ("double", "mixed"))
        if not isinstance(compiled, (bool, np.bool_)):
            raise InvalidInput(f"compiled must be True or False, got {compiled!r}")
        self.compiled = bool(compiled)

    def __repr__(self) -> str:
        opts = []
        if self.block is not None:
            opts.append(f"block={self.block!r}")
        if self.precision != "double":
            opts.append(f"precision={self.precision!r}")
        if not self.compiled:
            opts.append("compiled=False")
        if self.max_seconds != MAX_SECONDS:
            opts.append(f"max_seconds={self.max_seconds!r}")
        return f"Dense({', '.join(opts)})"

    # ------------------------------------------------------------------ plan
    def plan(self, scene, n: int, dim: int) -> DensePlan:
        """The plan of ``scene`` for states of shape ``(n, dim)`` with the current engine
        threads, or one for a small one (``dense.engine_threads``; see
        :class:`~kinred.pairsum.PairSum`)."""
        terms, n, dim = check_plan_args(scene, n, dim)
        forms = [t.compiled for t in terms.terms]
        secs = estimate_seconds(n, dim, terms)
        if secs > self.max_seconds:
            raise TooLarge(f"Dense: one right-hand side of {n} agents in dimension {dim} "
                           f"({len(terms.sources)} distance source(s), {n * (n - 1) // 2:.3g} "
                           f"pairs) takes an estimated {_fmt_seconds(secs)} at best, more than "
                           f"max_seconds={self.max_seconds:g}; {_fits(dim)}")
        ft = np.dtype(np.float32 if self.precision == "mixed" else np.float64)
        use_worker = (self.compiled and _kernels.HAVE_COMPILED_FOR.get(ft, False)
                      and all(f is not None for f in forms))
        nthreads = engine_threads(n, dim, terms, use_worker)
        st = strips(n, self.block, dim, nthreads, ft.itemsize)
        nthreads = min(nthreads, len(st))
        small = dim <= SMALL_K
        centred = tuple(sorted(set(terms.carriers) | (set() if small else set(terms.sources))))
        gram = () if small or ft == np.float64 else terms.sources
        maxel = max((i1 - i0) * (n - i0) for i0, i1 in st)
        need_phi = any(len(terms.of_source(s)) > 1 for s in terms.sources)
        nbytes = (8 * n * dim * len(centred) + ft.itemsize * (
            n * dim * len(gram) + n * (dim + 1) * len(terms.carriers)
            + nthreads * (n * (dim + 1) * len(terms.accumulators) + maxel * (1 + need_phi)))
            + 24 * n * nthreads)
        check_alloc(nbytes, f"Dense: the workspace of the pair sums of {n} agents in dimension "
                    f"{dim}", _fits(dim))
        groups = _balance(st, n, nthreads)
        return DensePlan(
            n=n, dim=dim, terms=terms, c=scene.coefficients(n), dtype=ft, strips=tuple(st),
            groups=groups, small=small, centred=centred, maxel=maxel, need_phi=need_phi,
            signature=(n, dim, centred, terms.carriers, terms.accumulators, nthreads, maxel,
                       need_phi, ft.char),
            nbytes=nbytes,
            loop=tuple(tuple((t, getattr(t.kernel, "value_sq", None)) for t in terms.of_source(s))
                       for s in terms.sources),
            worker=_worker(terms, forms, ft, dim, groups) if use_worker else None)

    # ------------------------------------------------------------------ evaluate
    def evaluate(self, plan: DensePlan, x: np.ndarray, v: np.ndarray | None, rng=None) -> dict:
        """The pair sums of the plan's scene at ``(x, v)``: ``{target: (n, dim) ndarray}``
        (fresh arrays; ``rng`` is ignored: the backend is exact)."""
        if not isinstance(plan, DensePlan) or x.shape != (plan.n, plan.dim):
            raise InvalidInput(f"plan must be a DensePlan for states of shape (n, dim) = "
                               f"{getattr(plan, 'n', '?'), getattr(plan, 'dim', '?')}; got "
                               f"{type(plan).__name__} and x of shape {x.shape}")
        state = {"x": x, "v": v}
        ws = _scratch(plan.signature, partial(_workspace, plan))
        for key in plan.centred:
            _kernels.centre_rows(np.ascontiguousarray(state[key]), ws["centred"][key])
        geo = _geometry(plan, state, ws)
        for key in plan.terms.carriers:
            _kernels.zext_rows(ws["centred"][key], plan.c, ws["zext"][key])
        if plan.worker is not None:
            work = partial(_compiled_share, plan, ws, _stacked(plan, state, geo, ws))
        else:
            work = partial(_loop_share, plan, ws, state, geo)
        # group 0 in the calling thread, BLAS single-threaded for the whole region
        accs = _parallel.run_parallel(work, list(plan.groups))
        if plan.worker is not None:
            for s in plan.terms.sources:
                _kernels.count(s, len(plan.strips))
        return _finish(plan, accs, ws["centred"])


def estimate_seconds(n: int, dim: int, terms: PairTerms) -> float:
    """An optimistic estimate (a lower bound) of the seconds of one dense right-hand side:
    ``n(n − 1)/2`` pairs per distance source at :data:`PAIRS_PER_SECOND_COMPILED` (every kernel
    compiled) or :data:`PAIRS_PER_SECOND_NUMPY`, times ``max(1, (dim + 1)/4)`` (the products'
    width).

    Examples
    --------
    >>> from kinred.dynamics import Alignment, Scene
    >>> round(estimate_seconds(10**7, 2, Scene([Alignment()]).pair_terms))
    25000
    """
    rate = (PAIRS_PER_SECOND_COMPILED if all(t.compiled is not None for t in terms.terms)
            else PAIRS_PER_SECOND_NUMPY)
    return len(terms.sources) * (n * (n - 1) / 2.0) * max(1.0, (dim + 1) / 4.0) / rate


def one_thread_seconds(n: int, dim: int, terms: PairTerms) -> float:
    """The cost model's seconds of one dense right-hand side on one engine thread
    (:func:`kinred.pairsum._cost.dense_seconds`, by each term's compiled kind).

    Examples
    --------
    >>> from kinred.dynamics import Alignment, Scene
    >>> terms = Scene([Alignment()]).pair_terms
    >>> [round(one_thread_seconds(n, 2, terms) * 1e3, 3) for n in (200, 2000)]   # ms
    [0.078, 7.796]
    """
    return _cost.dense_seconds(n, dim, [None if t.compiled is None else t.compiled[0]
                                        for t in terms.terms])


def threads_for(seconds: float, compiled: bool = True) -> int:
    """The threads of a pass over all pairs estimated at ``seconds`` on one thread: the
    engine's (:func:`~kinred.dynamics.set_num_threads`), or one below
    :data:`PARALLEL_MIN_SECONDS` (one compiled call per thread, ``compiled``) or
    :data:`PARALLEL_MIN_SECONDS_LOOP` (a Python loop over strips). Also the certificate's
    pair pass, with its own estimate."""
    least = PARALLEL_MIN_SECONDS if compiled else PARALLEL_MIN_SECONDS_LOOP
    return _parallel.get_num_threads() if seconds >= least else 1


def engine_threads(n: int, dim: int, terms: PairTerms, compiled: bool = True) -> int:
    """The threads of one dense right-hand side: :func:`threads_for` of
    :func:`one_thread_seconds` (``compiled``: the compiled strip worker runs it)."""
    return threads_for(one_thread_seconds(n, dim, terms), compiled)


def _fmt_seconds(secs: float) -> str:
    if secs < 120:
        return f"{secs:.3g} s"
    if secs < 7200:
        return f"{secs / 60:.3g} min"
    return f"{secs / 3600:.3g} h"


def _fits(dim: int) -> str:
    """The backends that fit a size Dense refuses."""
    if dim <= 3:
        return ("use a fast summation: pairsum='auto' (chooses among the deterministic backends "
                "by their cost), 'nufft' (smooth kernels) or 'cells' (short-range kernels)")
    return ("distances in dimension > 3 have no fast exact summation: project the scene to "
            "k <= 3 (Scene.project) for pairsum='auto'/'nufft'/'cells', or use "
            "pairsum='random_batch' (an unbiased approximation, explicit only)")


def _worker(terms: PairTerms, forms: list, ft: np.dtype, dim: int, groups: tuple) -> _Worker:
    """The compiled worker's per-term arrays (built once per plan)."""
    tt = terms.terms
    elast = np.zeros(len(tt), dtype=np.bool_)
    for s in terms.sources:
        elast[max(i for i, t in enumerate(tt) if t.source == s)] = True
    return _Worker(
        esrc=np.array([terms.sources.index(t.source) for t in tt], dtype=np.int64),
        elast=elast,
        ekind=np.array([_KIND_CODE[f[0]] for f in forms], dtype=np.int64),
        epar=np.array([[f[1], f[2]] for f in forms], dtype=ft),
        ez=np.array([terms.carriers.index(t.carrier) for t in tt], dtype=np.int64),
        eacc=np.array([terms.accumulators.index((t.target, t.carrier)) for t in tt],
                      dtype=np.int64),
        tau=ft.type(_kernels.tau_for(dim, ft)),
        groups=tuple(np.array(g, dtype=np.int64).reshape(-1, 2) for g in groups))


def _workspace(plan: DensePlan):
    """Fresh scratch buffers of ``plan`` and their size: ``(buffers, nbytes)``."""
    n, dim, ft, terms = plan.n, plan.dim, plan.dtype, plan.terms
    nthreads = len(plan.groups)
    gram = () if plan.small or ft == np.float64 else terms.sources
    acc3 = [np.empty((len(terms.accumulators), n, dim + 1), ft) for _ in range(nthreads)]
    return {
        "centred": {key: np.empty((n, dim)) for key in plan.centred},
        "single": {key: np.empty((n, dim), ft) for key in gram},
        "zext": {key: np.empty((n, dim + 1), ft) for key in terms.carriers},
        # per thread: accumulators (one (n, dim+1) block per (target, carrier)), distance
        # block, second kernel block, scratch rows of the compiled kernels
        "acc3": acc3,
        "acc": [{kk: A[i] for i, kk in enumerate(terms.accumulators)} for A in acc3],
        "q": [np.empty(plan.maxel, ft) for _ in range(nthreads)],
        "phi": [np.empty(plan.maxel, ft) if plan.need_phi else np.empty(1, ft)
                for _ in range(nthreads)],
        "scr": [np.empty((3, n)) for _ in range(nthreads)],
    }, plan.nbytes


def _geometry(plan: DensePlan, state: dict, ws: dict) -> dict:
    """Per source: transposed raw rows (differences, small dimension) or the Gram operand
    (centred rows; with "mixed" rounded to float32) and its squared row norms (float64 norms
    of the rounded rows, so that the Gram formula is consistent)."""
    geo = {}
    ft = plan.dtype
    for s in plan.terms.sources:
        if plan.small:
            geo[s] = (np.ascontiguousarray(state[s].T), None)
        else:
            Y = ws["centred"][s] if ft == np.float64 else ws["single"][s]
            nrm = _kernels.gram_rows(ws["centred"][s], Y, np.empty(plan.n, ft), ft != np.float64)
            geo[s] = (Y, nrm)
    return geo


def _stacked(plan: DensePlan, state: dict, geo: dict, ws: dict) -> tuple:
    """The compiled worker's per-source operands, stacked: ``(YT, Y, nrm, R, Z)``."""
    sources, ft = plan.terms.sources, plan.dtype
    ns = len(sources)

    def stack(arrs):
        return arrs[0][None] if len(arrs) == 1 else np.stack(arrs)

    if plan.small:
        YT = stack([geo[s][0] for s in sources])
        Yg, nrm, Rg = np.empty((ns, 0, 0), ft), np.empty((ns, 0), ft), np.empty((ns, 0, 0))
    else:
        YT = np.empty((ns, 0, 0))
        Yg = stack([geo[s][0] for s in sources])
        nrm = stack([geo[s][1] for s in sources])
        Rg = stack([np.ascontiguousarray(state[s]) for s in sources])
    return YT, Yg, nrm, Rg, stack([ws["zext"][key] for key in plan.terms.carriers])


def _compiled_share(plan: DensePlan, ws: dict, ops: tuple, g: int, my_strips) -> dict:
    """Thread ``g``'s strips in one compiled call without the GIL (``_kernels.pair_strips``:
    the same operations as :func:`_loop_share`)."""
    w = plan.worker
    YT, Yg, nrm, Rg, Zs = ops
    _kernels.pair_strips(w.groups[g], plan.small, YT, Yg, nrm, Rg, w.tau, w.esrc, w.elast,
                         w.ekind, w.epar, w.ez, w.eacc, Zs, ws["acc3"][g], ws["q"][g],
                         ws["phi"][g], ws["scr"][g], plan.dtype.type(1.0))
    return ws["acc"][g]


def _loop_share(plan: DensePlan, ws: dict, state: dict, geo: dict, g: int, my_strips) -> dict:
    """Thread ``g``'s strips, strip by strip from Python (kernels without compiled form)."""
    acc = ws["acc"][g]
    for A in acc.values():
        A.fill(0.0)
    n = plan.n
    qbuf, pbuf = ws["q"][g], ws["phi"][g]
    done = 0
    for i0, i1 in my_strips:
        bb, m = i1 - i0, n - i0
        for s, terms in zip(plan.terms.sources, plan.loop):
            q = qbuf[: bb * m].reshape(bb, m)
            Y, nn = geo[s]
            if nn is None:
                _kernels.sqdist_rows(Y, i0, i1, i0, q)
            else:
                R = state[s]
                _kernels.sqdist_block(Y[i0:i1], Y[i0:], nn[i0:i1], nn[i0:], q, R[i0:i1], R[i0:],
                                      diag=0)
            for idx, (t, value_sq) in enumerate(terms):
                # the last term of a source may overwrite the distances
                phi = q if idx == len(terms) - 1 else pbuf[: bb * m].reshape(bb, m)
                if value_sq is not None:
                    value_sq(q, phi)
                else:
                    phi[...] = t.kernel(np.sqrt(q))
                _pair_products(phi, ws["zext"][t.carrier], acc[(t.target, t.carrier)], i0, i1, n)
        done += 1
    for s in plan.terms.sources:  # once per call: one lock per source, not per strip
        _kernels.count(s, done)
    return acc


def _finish(plan: DensePlan, accs: list, centred: dict) -> dict:
    """Sum the threads' accumulators and form ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ`` per
    ``(target, carrier)``, summed per target into fresh arrays."""
    out = {}
    for kk in plan.terms.accumulators:
        A = accs[0][kk]
        for other in accs[1:]:
            A += other[kk]
        tgt, carrier = kk
        contrib = _kernels.pair_finish(A, centred[carrier], np.empty((plan.n, plan.dim)))
        if tgt in out:
            out[tgt] += contrib
        else:
            out[tgt] = contrib
    return out
