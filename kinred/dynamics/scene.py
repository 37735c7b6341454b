r"""Scenes: sums of effects, evaluated by a blocked pairwise engine.

A :class:`Scene` is the vector field of the sum of its effects on the phase space ``(x, v)``
of ``N`` agents in ``ℝᵈ`` (second order, eq. (4.2)–(4.3), labels ``eq:dyn4``–``eq:dyn5``), or
on positions only (first order, :class:`~kinred.dynamics.Aggregation`).

Normalization
-------------
Pairwise sums carry coefficients ``c_j``:

* ``normalize="mean"``: ``c_j = w_j`` (``1/N`` without weights) – the paper's written
  formulas (2.13) and (3.14), and the mean-field form (4.3);
* ``normalize="sum"``: ``c_j = N w_j`` (coefficient 1 per agent without weights).

With ``weights`` (probability weights of a quantized measure) ``w_j`` replaces ``1/N``.
The paper's numerical experiments (§3.4.1, Table 1 pattern: flocking at β = 1.5, mostly at
1.62, not at 1.7) are reproduced with ``normalize="sum"`` and ``G = 0.8``; with
``normalize="mean"`` and ``G = 1`` that setting never flocks (Γ stays ≈ 66).

The engine
----------
For each distance source needed by some effect (``x`` and/or ``v`` – never one that no
effect needs) the engine walks over row strips ``I = [i0, i1)`` against columns ``j ≥ i0``
(each unordered pair once, memory ``O(N·block)``; strips of about 64k entries, ≈ 512 kB, so
a block stays in L2):

1. squared distances: for ``k ≤ 3`` by differences (numba, vectorized over columns); else
   a BLAS Gram block ``−2 Y_I Y_Jᵀ`` of centred coordinates written straight into the strip,
   plus one numba pass that adds the norms and recomputes close pairs by differences
   (relative error ≤ 4e-13, see ``_kernels``);
2. kernel values in place on the block (the last effect of a source overwrites the
   distances): compiled for kernels that have a compiled form (Cucker–Smale), else numpy
   SIMD ufuncs (``value_sq``) or ``kernel(√q)``;
3. two in-place BLAS products per strip, ``A_I += Φ_I,[i0:] Z_[i0:]`` and, by symmetry,
   ``A_[i1:] += Φ_I,[i1:]ᵀ Z_I`` with ``Z = [c z, c]`` (``dgemm`` with ``β = 1`` on
   sub-blocks, no temporaries): one kernel block feeds both orientations, so every unordered
   pair's kernel is evaluated once. This gives ``Σⱼ cⱼ φᵢⱼ zⱼ`` and the row sums
   ``Σⱼ cⱼ φᵢⱼ``; the contribution is ``Σⱼ cⱼ φᵢⱼ zⱼ − (Σⱼ cⱼ φᵢⱼ) zᵢ`` with the carrier
   ``z`` centred (so velocity fluctuations near 1e-15 keep their relative accuracy).

With ``n`` engine threads (:func:`~kinred.dynamics.set_num_threads`) the strips are dealt
out to ``n`` threads (the calling thread and ``n − 1`` pooled ones; BLAS runs one thread per
engine thread), each with its own accumulator. When every pairwise kernel has a compiled
form, a thread's whole share (steps 1–3 for all its strips) is one compiled call that holds
no GIL (``_kernels.pair_strips``, BLAS called from numba); otherwise a Python loop makes the
same calls strip by strip, and each call's GIL hand-back can wait for the other thread
(measured 10–100 µs per hand-off on the 2-core VM: at k = 10 the loop gained nothing from a
second thread, the compiled worker 1.5–1.8×).

With ``precision="mixed"`` steps 1–3 (Gram blocks, kernel values, products and accumulators)
run in float32 (``sgemm``), with close pairs still recomputed from float64 differences; the
centring before and the combination after them stay in float64.

A scene without pairwise effects costs ``O(N·d)`` per evaluation.
"""

from __future__ import annotations

import threading
from typing import Sequence

import numpy as np

from .. import _parallel
from .._validate import as_array, as_choice, as_float, as_int, as_weights
from ..errors import InvalidInput, NotProjectable
from ..projection import as_projection
from . import _kernels
from .effects import Effect

__all__ = ["Scene", "project_state"]


#: Dimensions up to which distances are computed by differences (numba, vectorized over
#: columns) rather than by the Gram product plus fix-up.
_SMALL_K = 3

#: Whether the engine runs a thread's strip loop as one compiled call when every pairwise
#: kernel has a compiled form (``kernel._compiled``); tests switch it off to compare with the
#: Python strip loop, which remains the path for any other kernel.
_USE_COMPILED = True

#: Target number of pairwise entries per strip: ≈ 512 kB of float64 for small dimensions (the
#: block stays in L2 for the elementwise kernel passes) and 2× more from ``_BIG_K`` on, where
#: the BLAS products dominate and thin strips would spend their time packing ``Z`` (a
#: ``(m, k+1)`` operand re-packed for every strip: overhead ≈ 1/(2·rows) of the flops).
_STRIP_ELEMS = 65_536
_BIG_K = 48

#: Per calling thread: the engine's scratch buffers, reused from step to step (fresh
#: multi-megabyte arrays every step cost more in page faults than the arithmetic on them).
_SCRATCH = threading.local()
_SCRATCH_KEEP = 2                  # signatures kept per thread (e.g. an original and a projection)
_SCRATCH_MAX_BYTES = 256 * 2**20   # larger workspaces are not kept between calls


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


def _strips(n: int, block: int | None, dim: int = 1, nthreads: int = 1, itemsize: int = 8) -> list:
    """Row strips ``[(i0, i1)]`` of the upper triangle ``j >= i0``.

    With ``block`` given: fixed ``block`` rows per strip. Otherwise strips of about
    ``_STRIP_ELEMS`` entries each (2× that for ``dim >= _BIG_K``; rows ``i0:i1`` against
    columns ``i0:n``, at most ``entries/512`` rows), so later strips
    (shorter rows) get more rows and every strip costs about the same (float32 blocks,
    ``itemsize = 4``: twice the entries, the same bytes). With ``nthreads > 1``
    strips are made small enough that there are at least four per thread (load balance).
    """
    if block is not None:
        return [(i0, min(n, i0 + block)) for i0 in range(0, n, block)]
    elems = _STRIP_ELEMS * (2 if dim >= _BIG_K else 1) * 8 // itemsize
    if nthreads > 1:
        elems = max(4096, min(elems, (n * (n + 1) // 2) // (4 * nthreads)))
    out = []
    i0 = 0
    while i0 < n:
        bb = min(elems // 512, max(8, elems // max(n - i0, 1)))
        i1 = min(n, i0 + bb)
        out.append((i0, i1))
        i0 = i1
    return out


class Scene:
    """The vector field of a sum of effects.

    Parameters
    ----------
    effects : sequence of Effect
        The terms (see :class:`kinred.dynamics.Effect` and its subclasses).
    normalize : {"mean", "sum"}
        Pairwise coefficients ``c_j = w_j`` or ``N w_j`` (see the module notes; ``"sum"``
        with ``G = 0.8`` reproduces the paper's §3.4 experiments).
    weights : (N,) array_like, optional
        Probability weights of the agents (validated: finite, >= 0, sum 1); default ``1/N``.
    block : int, optional
        Rows per strip of the pairwise engine (default: strips of about 64k pairwise
        entries, at most 128 rows; memory ``O(N·block)``).
    engine : {"fast", "numpy"}
        ``"fast"``: the blocked BLAS/numba engine; ``"numpy"``: the plain-numpy twin (direct
        differences, kernels evaluated by ``kernel(s)``), for reference and tests.
    precision : {"double", "mixed"}
        ``"double"`` (default): everything in float64. ``"mixed"``: the pairwise stage of the
        fast engine (Gram blocks, kernel values, the two pair-sum products and their
        accumulators) runs in float32 – about twice the BLAS throughput – while the state,
        the centring, the fix-up of close pairs (by float64 differences), the final
        ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ`` and the integrator stay in float64. Carriers are
        centred before rounding, so the error of a pair sum is relative to the *fluctuation*
        size (velocity fluctuations near 1e-15 keep about 6 digits). Measured: Γ(t) within
        2e-6 (d = 200) to 7e-5 (k = 10) relative of ``"double"`` before flocking, Table 1's
        423 verdicts unchanged; the mean velocity conserved to float32 round-off of the pair
        sums. See docs/dynamics.md.

    Attributes
    ----------
    order : int
        2 (state ``(x, v)``) or 1 (state ``x`` only).
    stochastic : bool
        True if any effect is noise.

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> scene = Scene([Alignment(kernel=CuckerSmale(G=1.0, beta=0.0))], normalize="mean")
    >>> x = np.array([[0.0], [1.0]]); v = np.array([[1.0], [-1.0]])
    >>> dx, dv = scene.rhs(x, v)
    >>> dv.ravel()          # (1/2)·(v_j − v_i)
    array([-1.,  1.])
    """

    def __init__(self, effects: Sequence[Effect], normalize: str = "mean", weights=None, *,
                 block: int | None = None, engine: str = "fast", precision: str = "double"):
        if isinstance(effects, Effect) or not hasattr(effects, "__iter__"):
            effects = [effects]
        effects = tuple(effects)
        if not effects:
            raise InvalidInput("effects must contain at least one effect, got an empty sequence")
        for i, e in enumerate(effects):
            for attr in ("target", "pairwise", "projectable", "translation_invariant", "stochastic"):
                if not hasattr(e, attr):
                    raise InvalidInput(
                        f"effects[{i}] = {e!r} is not an Effect: it lacks the attribute {attr!r} "
                        "(see kinred.dynamics.Effect)")
        self.effects = effects
        self.normalize = as_choice(normalize, "normalize", ("mean", "sum"))
        self.weights = None if weights is None else as_weights(weights, "weights",
                                                               len(np.atleast_1d(weights)))
        self.block = None if block is None else as_int(block, "block", low=1)
        self.engine = as_choice(engine, "engine", ("fast", "numpy"))
        self.precision = as_choice(precision, "precision", ("double", "mixed"))
        targets = {e.target for e in effects}
        if "x" in targets:
            bad = [e for e in effects if e.target == "v"]
            if bad:
                raise InvalidInput(
                    f"a scene mixes first-order effects (target 'x', e.g. Aggregation) with "
                    f"second-order ones (target 'v'): {bad!r}; use one kind")
            self.order = 1
        else:
            self.order = 2
        for e in effects:
            if e.pairwise and self.order == 1 and (e.source == "v" or e.carrier == "v"):
                raise InvalidInput(f"{e!r} needs velocities, which a first-order scene has not")
        self.stochastic = any(e.stochastic for e in effects)
        self.translation_invariant = all(e.translation_invariant for e in effects)
        self._pair = [e for e in effects if e.pairwise]
        self._local = [e for e in effects if not e.pairwise and not e.stochastic]
        self._noise = [e for e in effects if e.stochastic]
        self._coef_cache: dict = {}

    # ------------------------------------------------------------------ helpers
    @property
    def needs(self) -> frozenset:
        """Distance sources the pairwise effects need: a subset of ``{"x", "v"}``."""
        return frozenset(e.source for e in self._pair)

    def _tgt(self, e) -> str:
        return e.target if e.target is not None else ("v" if self.order == 2 else "x")

    def agent_weights(self, n: int) -> np.ndarray:
        """Probability weights ``(n,)`` of the agents (uniform when none were given)."""
        if self.weights is None:
            return np.full(n, 1.0 / n)
        if self.weights.shape[0] != n:
            raise InvalidInput(f"the scene has {self.weights.shape[0]} weights but the state has "
                               f"{n} agents")
        return self.weights

    def coefficients(self, n: int) -> np.ndarray:
        """Pairwise coefficients ``c_j``: ``w_j`` (mean) or ``N w_j`` (sum), shape ``(n,)``."""
        c = self._coef_cache.get(n)
        if c is None:
            w = self.agent_weights(n)
            c = w * n if self.normalize == "sum" else w.copy()
            self._coef_cache = {n: c}
        return c

    def _check_state(self, x, v):
        x = as_array(x, "x", ndim=2)
        if x.shape[0] < 1 or x.shape[1] < 1:
            raise InvalidInput(f"x must have at least one agent and one dimension, got {x.shape}")
        if self.order == 2:
            if v is None:
                raise InvalidInput("v must be given for a second-order scene (order 2)")
            v = as_array(v, "v", shape=x.shape)
        elif v is not None:
            raise InvalidInput("v must be None for a first-order scene (order 1), got an array")
        if self.weights is not None:
            self.agent_weights(x.shape[0])
        return x, v

    # ------------------------------------------------------------------ the field
    def rhs(self, x, v=None, t: float = 0.0):
        """Deterministic drift ``(dx, dv)``.

        Parameters
        ----------
        x, v : (N, d) ndarray
            State; ``v`` must be None for first-order scenes.
        t : float

        Returns
        -------
        dx : (N, d) ndarray
        dv : (N, d) ndarray or None (order 1)
        """
        x, v = self._check_state(x, v)
        t = as_float(t, "t")
        dx, dv = self._rhs(x, v, t)
        if self.order == 2 and dx is v:
            dx = v.copy()
        return dx, dv

    def _rhs(self, x, v, t):
        """Unvalidated drift; for order 2 ``dx`` is ``v`` itself (no copy)."""
        n = x.shape[0]
        dv = dxe = None   # arrays owned by this call (the pairwise results are fresh arrays)
        if self._pair and n > 1:
            contrib = self._pairwise(x, v) if self.engine == "fast" else self._pairwise_numpy(x, v)
            dv = contrib.get("v")
            dxe = contrib.get("x")
        for e in self._local:
            f = e.drift(x, v, t)
            if self._tgt(e) == "v":
                if dv is None:
                    dv = np.array(f, dtype=float)
                else:
                    dv += f
            elif dxe is None:
                dxe = np.array(f, dtype=float)
            else:
                dxe += f
        if self.order == 2:
            if dv is None:
                dv = np.zeros_like(v)
            dx = v if dxe is None else v + dxe
        else:
            dv = None
            dx = np.zeros_like(x) if dxe is None else dxe
        return dx, dv

    def noise_increment(self, rng, n: int, dim: int, dt: float):
        """``(ΔX, ΔV)`` of all noise effects over a step ``dt`` (None where absent)."""
        dX = dV = None
        for e in self._noise:
            inc = e.increment(rng, n, dim, dt)
            if self._tgt(e) == "v":
                dV = inc if dV is None else dV + inc
            else:
                dX = inc if dX is None else dX + inc
        return dX, dV

    # ------------------------------------------------------------------ pairwise engine
    def _pairwise(self, x, v):
        n = x.shape[0]
        c = self.coefficients(n)
        state = {"x": x, "v": v}
        dim = x.shape[1]
        sources = [s for s in ("x", "v") if any(e.source == s for e in self._pair)]
        carriers = sorted({e.carrier for e in self._pair})
        need_centred = sorted(set(carriers) | {s for s in sources if dim > _SMALL_K})
        keys = sorted({(self._tgt(e), e.carrier) for e in self._pair})
        nthreads = _parallel.get_num_threads()
        # pairwise-stage dtype: float64, or float32 with precision="mixed"
        ft = np.dtype(np.float32 if self.precision == "mixed" else np.float64)
        strips = _strips(n, self.block, dim, nthreads, ft.itemsize)
        nthreads = min(nthreads, len(strips))
        maxel = max((i1 - i0) * (n - i0) for i0, i1 in strips)
        need_phi = any(sum(e.source == s for e in self._pair) > 1 for s in sources)
        gram = [s for s in sources if dim > _SMALL_K] if ft != np.float64 else []

        def make():
            nbytes = (8 * n * dim * len(need_centred) + ft.itemsize * (
                n * dim * len(gram) + n * (dim + 1) * len(carriers)
                + nthreads * (n * (dim + 1) * len(keys) + maxel * (1 + need_phi)))
                + 24 * n * nthreads)
            acc3 = [np.empty((len(keys), n, dim + 1), ft) for _ in range(nthreads)]
            return {
                "centred": {key: np.empty((n, dim)) for key in need_centred},
                "single": {key: np.empty((n, dim), ft) for key in gram},
                "zext": {key: np.empty((n, dim + 1), ft) for key in carriers},
                # per thread: accumulators (one (n, dim+1) block per (target, carrier)),
                # distance block, second kernel block, scratch rows of the compiled kernels
                "acc3": acc3,
                "acc": [{kk: A[i] for i, kk in enumerate(keys)} for A in acc3],
                "q": [np.empty(maxel, ft) for _ in range(nthreads)],
                "phi": [np.empty(maxel, ft) if need_phi else np.empty(1, ft)
                        for _ in range(nthreads)],
                "scr": [np.empty((3, n)) for _ in range(nthreads)],
            }, nbytes

        ws = _scratch((n, dim, tuple(need_centred), tuple(carriers), tuple(keys), nthreads,
                       maxel, need_phi, ft.char), make)
        centred = ws["centred"]
        for key in need_centred:
            _kernels.centre_rows(np.ascontiguousarray(state[key]), centred[key])
        # source geometry: transposed raw rows (differences, small dimension) or centred rows
        # and their squared norms (Gram path; with "mixed" the centred rows rounded to
        # float32 and the float64 norms of the rounded rows, so the Gram formula is
        # consistent)
        geo = {}
        for s in sources:
            if dim <= _SMALL_K:
                geo[s] = (np.ascontiguousarray(state[s].T), None)
            else:
                Y = centred[s] if ft == np.float64 else ws["single"][s]
                nrm = _kernels.gram_rows(centred[s], Y, np.empty(n, ft), ft != np.float64)
                geo[s] = (Y, nrm)
        zext = ws["zext"]
        for key in carriers:
            _kernels.zext_rows(centred[key], c, zext[key])
        by_source = {s: [(e, getattr(e.kernel, "value_sq", None), zext[e.carrier],
                          (self._tgt(e), e.carrier)) for e in self._pair if e.source == s]
                     for s in sources}

        compiled = (_USE_COMPILED and _kernels.HAVE_COMPILED_FOR.get(ft, False)
                    and all(getattr(e.kernel, "_compiled", None) is not None for e in self._pair))
        if compiled:
            # the whole strip loop of a thread in one compiled call, without the GIL
            # (_kernels.pair_strips: the same operations as ``work`` below)
            small = dim <= _SMALL_K
            srcs = {s: i for i, s in enumerate(sources)}
            stack = (lambda arrs: arrs[0][None] if len(arrs) == 1 else np.stack(arrs))
            if small:
                YT = stack([geo[s][0] for s in sources])
                Yg = np.empty((len(sources), 0, 0), ft)
                nrm = np.empty((len(sources), 0), ft)
                Rg = np.empty((len(sources), 0, 0))
            else:
                YT = np.empty((len(sources), 0, 0))
                Yg = stack([geo[s][0] for s in sources])
                nrm = stack([geo[s][1] for s in sources])
                Rg = stack([np.ascontiguousarray(state[s]) for s in sources])
            Zs = stack([zext[key] for key in carriers])
            specs = [e.kernel._compiled for e in self._pair]
            esrc = np.array([srcs[e.source] for e in self._pair], dtype=np.int64)
            elast = np.zeros(len(self._pair), dtype=np.bool_)
            for s in sources:
                elast[max(i for i, e in enumerate(self._pair) if e.source == s)] = True
            ekind = np.array([sp[0] for sp in specs], dtype=np.int64)
            epar = np.array([[sp[1], sp[2]] for sp in specs], dtype=ft)
            ez = np.array([carriers.index(e.carrier) for e in self._pair], dtype=np.int64)
            eacc = np.array([keys.index((self._tgt(e), e.carrier)) for e in self._pair],
                            dtype=np.int64)
            tau = ft.type(_kernels.tau_for(dim, ft))

            def cwork(g, my_strips):
                _kernels.pair_strips(np.array(my_strips, dtype=np.int64).reshape(-1, 2),
                                     small, YT, Yg, nrm, Rg, tau, esrc, elast, ekind, epar,
                                     ez, eacc, Zs, ws["acc3"][g], ws["q"][g], ws["phi"][g],
                                     ws["scr"][g], ft.type(1.0))
                return ws["acc"][g]

        def work(g, my_strips):
            if compiled:
                return cwork(g, my_strips)
            acc = ws["acc"][g]
            for A in acc.values():
                A.fill(0.0)
            qbuf, pbuf = ws["q"][g], ws["phi"][g]
            for i0, i1 in my_strips:
                bb, m = i1 - i0, n - i0
                for s in sources:
                    q = qbuf[: bb * m].reshape(bb, m)
                    Y, nn = geo[s]
                    if nn is None:
                        _kernels.sqdist_rows(Y, i0, i1, i0, q)
                    else:
                        R = state[s]
                        _kernels.sqdist_block(Y[i0:i1], Y[i0:], nn[i0:i1], nn[i0:], q,
                                              R[i0:i1], R[i0:], diag=0)
                    _kernels.COUNTERS[s] += 1
                    effs = by_source[s]
                    for idx, (e, vs, Z, kk) in enumerate(effs):
                        # the last effect of a source may overwrite the distances
                        phi = q if idx == len(effs) - 1 else pbuf[: bb * m].reshape(bb, m)
                        if vs is not None:
                            vs(q, phi)
                        else:
                            phi[...] = e.kernel(np.sqrt(q))
                        A = acc[kk]
                        # rows of the strip: Φ_I,[i0:] @ Z[i0:]; columns beyond it, by
                        # symmetry: Φ_I,[i1:]ᵀ @ Z_I (each unordered pair's φ used twice)
                        _parallel.gemm(1.0, phi, Z[i0:], 1.0, A[i0:i1])
                        if i1 < n:
                            _parallel.gemm(1.0, phi[:, bb:], Z[i0:i1], 1.0, A[i1:],
                                           trans_a=True)
            return acc

        # balance: largest strip first to the least-loaded thread (deterministic)
        groups = [[] for _ in range(nthreads)]
        loads = [0] * nthreads
        for i0, i1 in sorted(strips, key=lambda st: (-(st[1] - st[0]) * (n - st[0]), st[0])):
            g = loads.index(min(loads))
            groups[g].append((i0, i1))
            loads[g] += (i1 - i0) * (n - i0)
        # group 0 in the calling thread, BLAS single-threaded for the whole region
        accs = _parallel.run_parallel(work, [sorted(gr) for gr in groups])
        if compiled:
            for s in sources:
                _kernels.COUNTERS[s] += len(strips)
        out = {}
        for kk in keys:
            A = accs[0][kk]
            for other in accs[1:]:
                A += other[kk]
            tgt, carrier = kk
            # a fresh array (the caller keeps it): Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ
            contrib = _kernels.pair_finish(A, centred[carrier], np.empty((n, dim)))
            if tgt in out:
                out[tgt] += contrib
            else:
                out[tgt] = contrib
        return out

    def _pairwise_numpy(self, x, v):
        """Plain-numpy twin of the engine: direct differences, kernels by ``kernel(s)``."""
        n = x.shape[0]
        c = self.coefficients(n)
        state = {"x": x, "v": v}
        out = {}
        for e in self._pair:
            S = np.sqrt(_kernels.sqdist_numpy(state[e.source], state[e.source]))
            phi = np.asarray(e.kernel(S), dtype=float)
            z = state[e.carrier] - state[e.carrier].mean(axis=0)
            contrib = (phi * c[None, :]) @ z - (phi @ c)[:, None] * z
            tgt = self._tgt(e)
            out[tgt] = contrib if tgt not in out else out[tgt] + contrib
        return out

    # ------------------------------------------------------------------ projection
    def project(self, M) -> "Scene":
        """The projected system (eq. (2.4)–(2.5), labels ``eq:eul2``–``eq:eul3``; eq. (3.5)).

        Pairwise kernels see projected distances, per-agent ``fᵢ`` terms are multiplied by
        ``M``. Effects outside the paper's class (1.1) raise
        :class:`~kinred.errors.NotProjectable`.

        Parameters
        ----------
        M : (k, d) ndarray or Projection

        Returns
        -------
        Scene
            On ``ℝᵏ``; start it from :meth:`project_state`.

        Examples
        --------
        >>> from kinred.dynamics import Scene, Alignment, Field
        >>> Scene([Alignment()]).project(np.eye(2, 3)).order
        2
        >>> Scene([Field(lambda t, x, v: np.sin(x))]).project(np.eye(2, 3))
        Traceback (most recent call last):
        ...
        kinred.errors.NotProjectable: Field('<lambda>') is a general per-agent field, ...
        """
        P = as_projection(M)
        new = []
        for e in self.effects:
            if not getattr(e, "projectable", False):
                try:
                    pe = e.project(P)
                except NotProjectable:
                    raise
                else:
                    raise NotProjectable(f"{e!r} declares projectable=False but project() returned "
                                         f"{pe!r}")
            new.append(e.project(P))
        sc = Scene(new, normalize=self.normalize, weights=self.weights, block=self.block,
                   engine=self.engine, precision=self.precision)
        sc.projection = P
        return sc

    def project_state(self, M, x0, v0=None):
        """Initial state of the projected system: ``(M x⁰, M v⁰)`` (``v0`` None for order 1)."""
        return project_state(M, x0, v0)

    def __repr__(self) -> str:
        w = "None" if self.weights is None else f"<{self.weights.shape[0]}>"
        prec = "" if self.precision == "double" else f", precision={self.precision!r}"
        return f"Scene({list(self.effects)!r}, normalize={self.normalize!r}, weights={w}{prec})"


def project_state(M, x0, v0=None):
    """``(M x⁰, M v⁰)`` row-wise (eq. (2.4), label ``eq:eul2``).

    Parameters
    ----------
    M : (k, d) ndarray or Projection
    x0 : (N, d) array_like
    v0 : (N, d) array_like or None

    Returns
    -------
    y0 : (N, k) ndarray
    w0 : (N, k) ndarray or None

    Examples
    --------
    >>> y0, w0 = project_state(np.eye(1, 2), [[1.0, 2.0]], [[3.0, 4.0]])
    >>> y0, w0
    (array([[1.]]), array([[3.]]))
    """
    P = as_projection(M)
    x0 = as_array(x0, "x0", ndim=2)
    y0 = P.apply(x0)
    w0 = None if v0 is None else P.apply(as_array(v0, "v0", shape=x0.shape))
    return y0, w0
