r"""The certificate's pair pass: every per-pair quantity of one step in one blocked pass.

Besides the per-agent aggregates below, the pass returns the pair sums of the projected field
at the projected high-dimensional state, ``Σ_terms Σⱼ cⱼ φ(ρᵢⱼ)(Mzⱼ − Mzᵢ)`` (the defect
``τᵥ`` needs ``F′(Mx, Mv)``): it already has the distances ``ρ`` and the kernel values there,
so the defect costs the two BLAS products of the dense engine per strip
(``Φ Z`` with ``Z = [c z̃, c]``, ``z̃`` the carrier centred as the engine does, and the
transposed product for the columns beyond the strip) instead of a second engine call.

For each pairwise term (kernel ``φ``, source ``s``, carrier ``z``) and each agent ``i`` the
pass returns, with ``r′ᵢⱼ`` the source distance in the projected run, ``ρᵢⱼ`` the source
distance of the projected high-dimensional state ``(Mx, Mv)`` and
``Λᵢⱼ = (1 + margin)·sup |φ′|`` over ``[min(ρᵢⱼ, r′ᵢⱼ), max(ρᵢⱼ, r′ᵢⱼ)]``:

* ``dsum = Σⱼ cⱼ φ(r′ᵢⱼ)`` and ``dneg = Σⱼ cⱼ max(−φ(r′ᵢⱼ), 0)`` – the degrees of the
  projected run's weighted graph Laplacian and of its negative part;
* ``amv = Σⱼ cⱼ |φ(r′ᵢⱼ)| bzⱼ`` – its ℓ∞ matvec with the carrier-error bounds;
* ``kr = Σⱼ Kᵢⱼ`` and ``kmv = Σⱼ Kᵢⱼ bsⱼ`` with ``Kᵢⱼ = cⱼ Λᵢⱼ |Mzᵢ − Mzⱼ|`` – the mean-value
  coupling of the source error;
* ``mag_true = Σⱼ cⱼ ψ(ρᵢⱼ)`` and ``mag_run = Σⱼ cⱼ ψ(r′ᵢⱼ)``: the rounding of the kernel
  values and of their sums at both points (round-off allowance, ``rnd = (g, a_e, a_s)``; see
  :mod:`kinred.certify._kernels`; ``(g + a_e)|φ| + a_s r Λ`` for kernels without a compiled
  form);
* ``s2 = Σⱼ cⱼ φ(r′ᵢⱼ)²`` – with ``dsum`` the spread of row ``i`` around its mean;
* ``rowmin = minⱼ max(φ(r′ᵢⱼ), 0)`` over ``j ≠ i`` with ``cⱼ > 0`` (``inf`` if none): by the
  threshold argument of ``docs/certificates.md`` the spectral gap of the Laplacian is at
  least ``κ Σᵢ wᵢ rowminᵢ``.

Two implementations: :func:`pair_pass` (row strips of the upper triangle as in the dynamics
engine, squared distances by differences for ``k ≤ 3`` and BLAS Gram blocks of centred
coordinates with the engine's close-pair fix-up otherwise, the per-pair work in the numba
kernel :func:`kinred.certify._kernels.strip_term`; memory ``O(N·block)``; each engine thread's
strips in one compiled call without the GIL, :func:`kinred.certify._kernels.pass_strips`, or
the same calls from a Python loop when numpy's BLAS symbols are not found) and its plain-numpy
twin :func:`pair_pass_numpy` (full rows, distances by differences, the kernels' own
``__call__`` and ``slope_bound``), which also serves kernels without a compiled form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _parallel
from ..pairsum import dense as _dense
from ..pairsum import strips as _dyn
from ..pairsum.strips import SMALL_K as _SMALL_K, deal as _balance, pair_products as _pair_products
from ..pairsum.strips import row_strips as _strips
from . import _kernels

#: Whether a thread's share of the pass runs as one compiled call (numpy's BLAS symbols found).
_COMPILED = bool(_dyn.HAVE_COMPILED_FOR[np.dtype(np.float64)])

__all__ = ["TermAgg", "pair_pass", "pair_pass_numpy"]

#: One thread's seconds per pair and term of the pass (2-core VM, k = 2 and 10, 1–5 terms:
#: 24–33 ns). The pass deals its strips to the engine's threads from the dense engine's
#: thresholds on (``dense.PARALLEL_MIN_SECONDS``, ``PARALLEL_MIN_SECONDS_LOOP`` without the
#: compiled call): one term shares from about 210 agents, five from about 100.
PASS_PAIR_TERM_SECONDS = 2.7e-8


def pass_threads(n: int, terms: int) -> int:
    """The threads of a pass over the pairs of ``n`` agents with ``terms`` terms: the dense
    engine's rule (``dense.threads_for``) on the pass's one-thread estimate."""
    return _dense.threads_for(n * (n - 1) / 2.0 * max(terms, 1) * PASS_PAIR_TERM_SECONDS,
                              _COMPILED)

_ROWS = ("dsum", "dneg", "amv", "kr", "kmv", "mag_true", "rowmin", "s2", "mag_run")


class TermAgg:
    """Per-agent aggregates of one pairwise term (see the module docstring)."""

    __slots__ = _ROWS

    def __init__(self, arr: np.ndarray):
        for r, name in enumerate(_ROWS):
            setattr(self, name, arr[r])

    def stack(self) -> np.ndarray:
        """``(9, N)`` array of the per-agent rows (tests)."""
        return np.stack([getattr(self, n) for n in _ROWS])


def _new_out(n: int) -> np.ndarray:
    out = np.zeros((len(_ROWS), n))
    out[6] = np.inf
    return out


def _names(term):
    run = "Y" if term.source == "x" else "W"
    true = "PX" if term.source == "x" else "PV"
    car = "PX" if term.carrier == "x" else "PV"
    return run, true, car


def _bvecs(term, bz, bs):
    """The carrier and source vectors of a term: ``bz[carrier]``, ``bs[source]``."""
    return bz[term.carrier], bs[term.source]


def _rounding(term, r, lam, rnd):
    """Rounding scale ``ψ(r)`` of one kernel value and its sums (see ``_kernels``)."""
    from ._plan import KIND_CS, KIND_MORSE, KIND_QUAD

    g, ae, asens = rnd
    if term.kind == KIND_CS:
        G, beta = term.params
        phi = np.asarray(term.kernel(r), dtype=float)
        q = r * r
        return (g * phi + ae * (phi + (0.6 * G if beta > 0 else 0.0))
                + asens * 2.0 * beta * phi * q / (1.0 + q))
    if term.kind == KIND_MORSE:
        A, la, B, lr, soft = term.params
        R = np.sqrt(r * r + soft * soft)
        ea, er = A * np.exp(-R / la), B * np.exp(-R / lr)
        inv = 1.0 / R
        pa = ea * (inv / la + inv * inv)
        pr = er * (inv / lr + inv * inv)
        return (g * np.abs((ea - er) * inv) + ae * (ea + er) * inv * (1.0 + R / la + R / lr)
                + asens * r * r * inv * (pa + pr))
    if term.kind == KIND_QUAD:
        return np.full(np.shape(r), (g + ae) * abs(term.params[0]))
    return (g + ae) * np.abs(np.asarray(term.kernel(r), dtype=float)) + asens * r * lam


def pair_pass_numpy(pts: dict, c: np.ndarray, terms, bz: dict, bs: dict, margin: float,
                    rnd=(0.0, 0.0, 0.0), block: int | None = None, ws=None) -> list:
    """Plain-numpy twin of :func:`pair_pass` (any kernel with ``slope_bound``).

    Parameters
    ----------
    pts : dict
        ``{"PX", "Y", "PV", "W"}`` → ``(N, k)`` arrays (those the terms need).
    c : (N,) ndarray
        Pair coefficients ``cⱼ``.
    terms : sequence of PairTerm
    bz, bs : dict
        ``{"x": (N,), "v": (N,)}``: the vectors of the matvecs ``amv`` (by the term's
        carrier) and ``kmv`` (by its source).
    margin : float
        Relative inflation of ``Λ``.
    rnd : (float, float, float)
        ``(g, a_e, a_s)`` of the rounding scales (:func:`kinred.certify._roundoff.pass_constants`).
    block : int, optional
        Rows per block (default: about 65k entries per block).
    ws : dict, optional
        Ignored here (:func:`pair_pass` keeps its scratch arrays in it).

    Returns
    -------
    aggs : list of TermAgg
    field : (N, k) ndarray
        ``Σ_terms Σⱼ cⱼ φ(ρᵢⱼ)(Mzⱼ − Mzᵢ)``, the pair sums of the projected field at
        ``(PX, PV)``.
    """
    n = c.shape[0]
    pos = c > 0.0
    B = block or max(1, 65_536 // max(n, 1))
    outs = [_new_out(n) for _ in terms]
    cen = {nm: pts[nm] - pts[nm].mean(axis=0) for nm in {_names(t)[2] for t in terms}}
    field = np.zeros((n, next(iter(pts.values())).shape[1]))
    for i0 in range(0, n, B):
        i1 = min(n, i0 + B)
        dist = {}

        def d(name):
            if name not in dist:
                dist[name] = np.sqrt(_dyn.sqdist_numpy(pts[name][i0:i1], pts[name]))
            return dist[name]

        off = np.ones((i1 - i0, n), dtype=bool)
        off[np.arange(i1 - i0), np.arange(i0, i1)] = False
        cj = np.where(off, c[None, :], 0.0)
        partner = off & pos[None, :]
        for t, term in enumerate(terms):
            run, true, car = _names(term)
            rr, rho, zc = d(run), d(true), d(car)
            phi = np.asarray(term.kernel(rr), dtype=float)
            lam = np.asarray(term.kernel.slope_bound(np.minimum(rr, rho), np.maximum(rr, rho)),
                             dtype=float) * (1.0 + margin)
            vz, vs = _bvecs(term, bz, bs)
            K = cj * lam * zc
            o = outs[t]
            o[0, i0:i1] = np.sum(cj * phi, axis=1)
            o[1, i0:i1] = np.sum(cj * np.maximum(-phi, 0.0), axis=1)
            o[2, i0:i1] = (cj * np.abs(phi)) @ vz
            o[3, i0:i1] = np.sum(K, axis=1)
            o[4, i0:i1] = K @ vs
            o[5, i0:i1] = np.sum(cj * _rounding(term, rho, lam, rnd), axis=1)
            o[8, i0:i1] = np.sum(cj * _rounding(term, rr, lam, rnd), axis=1)
            o[6, i0:i1] = np.min(np.where(partner, np.maximum(phi, 0.0), np.inf), axis=1)
            o[7, i0:i1] = np.sum(cj * phi * phi, axis=1)
            a = cj * np.asarray(term.kernel(rho), dtype=float)
            field[i0:i1] += a @ cen[car] - np.sum(a, axis=1)[:, None] * cen[car][i0:i1]
    return [TermAgg(o) for o in outs], field


def _geometry(pts: dict, names) -> dict:
    """Per point set: ``("diff", Yᵀ)`` for ``k ≤ 3`` or ``("gram", centred, norms, raw)``."""
    geo = {}
    for name in names:
        Y = np.ascontiguousarray(pts[name])
        n, k = Y.shape
        if k <= _SMALL_K:
            geo[name] = ("diff", np.ascontiguousarray(Y.T))
        else:
            cen = _dyn.centre_rows(Y, np.empty((n, k)))
            nrm = _dyn.gram_rows(cen, cen, np.empty(n), False)
            geo[name] = ("gram", cen, nrm, Y)
    return geo


def _sqdist(g, i0, i1, out):
    if g[0] == "diff":
        return _dyn.sqdist_rows(g[1], i0, i1, i0, out)
    _, cen, nrm, raw = g
    return _dyn.sqdist_block(cen[i0:i1], cen[i0:], nrm[i0:i1], nrm[i0:], out, raw[i0:i1],
                             raw[i0:], diag=0)


def pair_pass(pts: dict, c: np.ndarray, terms, bz: dict, bs: dict, margin: float,
              rnd=(0.0, 0.0, 0.0), block: int | None = None, ws: dict | None = None) -> list:
    """The pair pass (compiled kernels; terms without a compiled kernel use the twin).

    Same parameters and result as :func:`pair_pass_numpy`, to 1e-12 relative. ``ws``: a dict
    the caller keeps from call to call (one per run), holding the scratch arrays – distance
    and kernel blocks, accumulators, centred coordinates, several megabytes at ``N = 1000``
    – for the next call instead of fresh ones (whose page faults cost about a tenth of a
    step); the returned aggregates then live in it until the next call.
    """
    fast = [t for t in terms if t.kind]
    slow = [t for t in terms if not t.kind]
    res = {}
    field = None
    for part, fn in ((slow, pair_pass_numpy), (fast, _fast_pass)):
        if part:
            aggs, f = fn(pts, c, part, bz, bs, margin, rnd, block, ws)
            res.update({id(t): agg for t, agg in zip(part, aggs)})
            field = f if field is None else field + f
    if field is None:
        field = np.zeros((c.shape[0], next(iter(pts.values())).shape[1]))
    return [res[id(t)] for t in terms], field


@dataclass
class _Strips:
    """The compiled pass's inputs, built once per pass: the point sets' geometry, stacked
    (``YT (S, k, N)`` transposed rows for ``k ≤ 3``; else ``Yc (S, N, k)`` centred rows,
    ``nrm (S, N)`` their squared norms and ``R (S, N, k)`` the raw rows), the per-term arrays
    and, per carrier, ``Z = [c z̃, c]`` (``(C, N, k+1)``) and the centred ``z̃``."""

    diff: bool
    YT: np.ndarray
    Yc: np.ndarray
    nrm: np.ndarray
    R: np.ndarray
    sets: np.ndarray       # (T, 3): run, true and carrier point-set indices of each term
    kind: np.ndarray
    par: np.ndarray        # (T, 5)
    bz: np.ndarray         # (T, N)
    bs: np.ndarray         # (T, N)
    tcz: np.ndarray        # (T,) carrier index of each term
    Z: np.ndarray
    cen: list

    def geo(self, s: int) -> tuple:
        """Point set ``s`` as :func:`_sqdist` takes it."""
        if self.diff:
            return ("diff", self.YT[s])
        return ("gram", self.Yc[s], self.nrm[s], self.R[s])


def _buf(ws, key, shape) -> np.ndarray:
    """An uninitialized array of ``shape``: ``ws[key]`` when it has that shape, else fresh
    (and kept in ``ws`` for the next call)."""
    if ws is None:
        return np.empty(shape)
    a = ws.get(key)
    if a is None or a.shape != shape:
        a = ws[key] = np.empty(shape)
    return a


def _prepare(pts, c, fast, bz, bs, ws) -> _Strips:
    """The :class:`_Strips` of the compiled terms ``fast`` (arrays from ``ws`` when given)."""
    n = c.shape[0]
    k = next(iter(pts.values())).shape[1]
    names = sorted({nm for t in fast for nm in _names(t)})
    # one C-contiguous stack of the raw rows (not a tuple, whose length, and not a
    # non-contiguous layout, would each compile another specialization of the pass)
    raw = _buf(ws, "raw", (len(names), n, k))
    for s_, nm in enumerate(names):
        raw[s_] = pts[nm]
    diff = k <= _SMALL_K
    YT = (np.ascontiguousarray(raw.transpose(0, 2, 1)) if diff
          else np.empty((len(names), 0, 0)))
    Yc = _buf(ws, "Yc", (len(names), n, k) if not diff else (len(names), 0, 0))
    nrm = _buf(ws, "nrm", (len(names), n) if not diff else (len(names), 0))
    for s_, Y in enumerate(raw if not diff else ()):
        _dyn.centre_rows(Y, Yc[s_])
        _dyn.gram_rows(Yc[s_], Yc[s_], nrm[s_], False)
    cars = list(dict.fromkeys(_names(t)[2] for t in fast))      # first-appearance order
    cen = [Yc[names.index(car)] if not diff else
           _dyn.centre_rows(raw[names.index(car)], np.empty((n, k))) for car in cars]
    vz = [np.ascontiguousarray(a, dtype=float) for t in fast for a in _bvecs(t, bz, bs)]
    return _Strips(
        diff, YT, Yc, nrm, raw,
        np.array([[names.index(nm) for nm in _names(t)] for t in fast], dtype=np.int64),
        np.array([t.kind for t in fast], dtype=np.int64),
        np.array([t.params + (0.0,) * (5 - len(t.params)) for t in fast], dtype=float),
        np.stack(vz[0::2]), np.stack(vz[1::2]),
        np.array([cars.index(_names(t)[2]) for t in fast], dtype=np.int64),
        _zext(cen, c, _buf(ws, "Z", (len(cen), n, k + 1))), cen)


def _zext(cen: list, c: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``Z[cz] = [c z̃, c]`` per centred carrier ``z̃`` (the engine's operand)."""
    for cz, z in enumerate(cen):
        _dyn.zext_rows(z, c, Z[cz])
    return Z


def _fast_pass(pts, c, fast, bz, bs, margin, rnd, block, ws=None):
    """The compiled pass: strips dealt to the engine's threads (each with its own
    accumulators, summed at the end), BLAS single-threaded inside the region; each thread's
    share is one compiled call (:func:`_kernels.pass_strips`, no GIL) when numpy's BLAS
    symbols are found, else the same calls from a Python loop (:func:`_loop_share`)."""
    n = c.shape[0]
    k = next(iter(pts.values())).shape[1]
    sp = _prepare(pts, c, fast, bz, bs, ws)
    nthreads = pass_threads(n, len(fast))
    strips = _strips(n, block, k, nthreads)
    nthreads = min(nthreads, len(strips))
    maxel = max((i1 - i0) * (n - i0) for i0, i1 in strips)
    groups = _balance(strips, n, nthreads)
    args = (sp, c, c > 0.0, float(margin), np.asarray(rnd, dtype=float), maxel)
    share = _compiled_share if _COMPILED else _loop_share
    results = _parallel.run_parallel(
        lambda g, grp: share(grp, *args, _Scratch(ws, g, len(sp.kind), sp.Z.shape,
                                                   len(sp.R), maxel)), groups)
    outs, acc = results[0]
    for o2, a2 in results[1:]:
        outs[:, :6] += o2[:, :6]
        outs[:, 7:] += o2[:, 7:]
        np.minimum(outs[:, 6], o2[:, 6], out=outs[:, 6])
        acc += a2
    field = _buf(ws, "field", (n, k))
    for cz, z in enumerate(sp.cen):
        if cz == 0:
            _dyn.pair_finish(acc[0], z, field)
        else:
            field += _dyn.pair_finish(acc[cz], z, _buf(ws, "fin", (n, k)))
    return [TermAgg(o) for o in outs], field


class _Scratch:
    """One thread's arrays of a pass (from ``ws`` when given): ``outs (T, 9, N)`` (zero,
    row 6 at ``+inf``), ``acc (C, N, k+1)``, the distance blocks ``q (sets, maxel)``, the
    kernel block ``ph``, the kernels' row buffers ``buf (10, N)``, ``scr (3, N)``."""

    def __init__(self, ws, g, nt, zshape, nsets, maxel):
        n = zshape[1]
        self.outs = _buf(ws, ("outs", g), (nt, len(_ROWS), n))
        self.outs.fill(0.0)
        self.outs[:, 6] = np.inf
        self.acc = _buf(ws, ("acc", g), zshape)
        self.q = _buf(ws, ("q", g), (nsets, maxel))
        self.ph = _buf(ws, ("ph", g), (maxel,))
        self.buf = _buf(ws, ("buf", g), (10, n))
        self.scr = _buf(ws, ("scr", g), (3, n))


def _compiled_share(grp, sp, c, pos, margin, rnd, maxel, w):
    """One thread's strips ``grp`` in one compiled call: ``(outs, acc)``."""
    _kernels.pass_strips(np.array(grp, dtype=np.int64).reshape(-1, 2), sp.diff, sp.YT, sp.Yc,
                         sp.nrm, sp.R, _dyn.tau_for(sp.Z.shape[2] - 1), sp.sets, sp.kind,
                         sp.par, sp.bz, sp.bs, sp.tcz, c, pos, margin, rnd, sp.Z, w.acc, w.outs,
                         w.q, w.ph, w.buf, w.scr)
    return w.outs, w.acc


def _loop_share(grp, sp, c, pos, margin, rnd, maxel, w):
    """Twin of :func:`_compiled_share`: the same calls, strip by strip from Python."""
    n = c.shape[0]
    q, ph, buf, scr, outs, acc = w.q, w.ph, w.buf, w.scr, w.outs, w.acc
    acc.fill(0.0)
    for i0, i1 in grp:
        shape = (i1 - i0, n - i0)
        size = shape[0] * shape[1]
        blk = [_sqdist(sp.geo(j), i0, i1, q[j, :size].reshape(shape)) for j in range(len(sp.R))]
        phit = ph[:size].reshape(shape)
        for cz in range(sp.Z.shape[0]):
            add = 0
            for t in np.flatnonzero(sp.tcz == cz):
                r, tr, car = sp.sets[t]
                _kernels.strip_term(i0, blk[r], blk[tr], blk[car], c, pos, sp.bz[t], sp.bs[t],
                                    sp.kind[t], sp.par[t], margin, rnd, outs[t], buf, scr,
                                    phit, add)
                add = 1
            _kernels.square_fill(phit)
            _pair_products(phit, sp.Z[cz], acc[cz], i0, i1, n)
    return outs, acc
