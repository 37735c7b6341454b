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
kernel :func:`kinred.certify._kernels.strip_term`; memory ``O(N·block)``) and its plain-numpy
twin :func:`pair_pass_numpy` (full rows, distances by differences, the kernels' own
``__call__`` and ``slope_bound``), which also serves kernels without a compiled form.
"""

from __future__ import annotations

import numpy as np

from ..pairsum import _kernels as _dyn
from .. import _parallel
from ..pairsum.dense import SMALL_K as _SMALL_K, _pair_products, strips as _strips
from . import _kernels

__all__ = ["TermAgg", "pair_pass", "pair_pass_numpy"]

#: Agents from which the compiled pass deals its strips to the engine's threads.
_MIN_PARALLEL = 400

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
                    rnd=(0.0, 0.0, 0.0), block: int | None = None) -> list:
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
              rnd=(0.0, 0.0, 0.0), block: int | None = None) -> list:
    """The pair pass (compiled kernels; terms without a compiled kernel use the twin).

    Same parameters and result as :func:`pair_pass_numpy`, to 1e-12 relative.
    """
    fast = [t for t in terms if t.kind]
    slow = [t for t in terms if not t.kind]
    res = {}
    field = None
    for part, fn in ((slow, pair_pass_numpy), (fast, _fast_pass)):
        if part:
            aggs, f = fn(pts, c, part, bz, bs, margin, rnd, block)
            res.update({id(t): agg for t, agg in zip(part, aggs)})
            field = f if field is None else field + f
    if field is None:
        field = np.zeros((c.shape[0], next(iter(pts.values())).shape[1]))
    return [res[id(t)] for t in terms], field


def _fast_pass(pts, c, fast, bz, bs, margin, rnd, block):
    """The compiled pass: strips dealt to the engine's threads (each with its own
    accumulators, summed at the end), BLAS single-threaded inside the region."""
    n = c.shape[0]
    k = next(iter(pts.values())).shape[1]
    names = sorted({nm for t in fast for nm in _names(t)})
    geo = _geometry(pts, names)
    # per carrier (centred as the engine does): its terms and the operand Z = [c z~, c]
    by_car = {}
    for t, term in enumerate(fast):
        by_car.setdefault(_names(term)[2], []).append(t)
    cen = {car: _centred(geo[car], pts[car]) for car in by_car}
    zext = {car: _dyn.zext_rows(cen[car], c, np.empty((n, k + 1))) for car in by_car}
    # below a few hundred agents a thread hand-off costs more than the work it shares
    nthreads = _parallel.get_num_threads() if n >= _MIN_PARALLEL else 1
    strips = _strips(n, block, k, nthreads)
    nthreads = min(nthreads, len(strips))
    maxel = max((i1 - i0) * (n - i0) for i0, i1 in strips)
    pos = c > 0.0
    vecs = [tuple(np.ascontiguousarray(a) for a in _bvecs(t, bz, bs)) for t in fast]
    specs = [(np.int64(t.kind), np.array(t.params + (0.0,) * (5 - len(t.params)), dtype=float))
             for t in fast]
    margin = float(margin)
    rnd = np.asarray(rnd, dtype=float)

    def work(g, my_strips):
        q = {nm: np.empty(maxel) for nm in names}
        ph = np.empty(maxel)
        buf = np.empty((10, n))
        scr = np.empty((3, n))
        outs = [_new_out(n) for _ in fast]
        acc = {car: np.zeros((n, k + 1)) for car in by_car}
        for i0, i1 in my_strips:
            shape = (i1 - i0, n - i0)
            blk = {nm: _sqdist(geo[nm], i0, i1, q[nm][: shape[0] * shape[1]].reshape(shape))
                   for nm in names}
            phit = ph[: shape[0] * shape[1]].reshape(shape)
            for car, ts in by_car.items():
                for a, t in enumerate(ts):
                    run, true, _ = _names(fast[t])
                    kind, par = specs[t]
                    _kernels.strip_term(i0, blk[run], blk[true], blk[car], c, pos, vecs[t][0],
                                        vecs[t][1], kind, par, margin, rnd, outs[t], buf, scr,
                                        phit, int(a > 0))
                _kernels.square_fill(phit)
                _pair_products(phit, zext[car], acc[car], i0, i1, n)
        return outs, acc

    groups = [[] for _ in range(nthreads)]
    loads = [0] * nthreads
    for i0, i1 in sorted(strips, key=lambda st: (-(st[1] - st[0]) * (n - st[0]), st[0])):
        g = loads.index(min(loads))
        groups[g].append((i0, i1))
        loads[g] += (i1 - i0) * (n - i0)
    results = _parallel.run_parallel(work, [sorted(gr) for gr in groups])
    outs, acc = results[0]
    for o2, a2 in results[1:]:
        for t in range(len(fast)):
            outs[t][:6] += o2[t][:6]
            outs[t][7:] += o2[t][7:]
            np.minimum(outs[t][6], o2[t][6], out=outs[t][6])
        for car in by_car:
            acc[car] += a2[car]
    field = np.zeros((n, k))
    for car in by_car:
        field += _dyn.pair_finish(acc[car], cen[car], np.empty((n, k)))
    return [TermAgg(o) for o in outs], field


def _centred(g, Z: np.ndarray) -> np.ndarray:
    """``Z − mean(Z)`` as the engine centres carriers (reusing a Gram geometry's)."""
    if g[0] == "gram":
        return g[1]
    return _dyn.centre_rows(np.ascontiguousarray(Z), np.empty(Z.shape))
