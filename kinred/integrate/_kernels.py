r"""Private numba kernels of ``simulate``'s loop, each with a plain-numpy twin.

The loop's own work per step is a few passes over the state ``(N, d)``: the Euler update,
the divergence guard's moments and, at the save points, the fluctuations ``Γ`` and ``Λ``
(§3.4.1 of the paper). At ``N·d ~ 10⁷`` each numpy pass allocates a temporary of the state's
size (the update's ``h·dx``, the centred deviations), and the loop cost several right-hand
sides; these kernels do the same work in place, with no temporary.

Kernels
-------
``euler_pair(x, dx, v, dv, h)`` / ``euler_one(x, dx, h)``
    ``x ← x + dx·h`` then ``v ← v + dv·h`` in place, element by element (``dx`` may be ``v``
    itself: each element of ``x`` is updated from the old ``v`` before ``v`` changes). No
    fastmath: the product is rounded before the sum, so the result is *bit-identical* to
    numpy's ``tmp = dx·h; x += tmp`` of forward Euler (eq. (1.6)); :func:`euler` runs them
    over two row halves. Twin: :func:`euler_numpy`.
``sweep(z, w, shift, c, r, acc)``
    One pass over the rows of ``a = z + shift`` (``z (n, d)``, ``shift (d,)``; each entry
    rounded as numpy's ``z + shift``, without that array) with weights ``w``:
    ``r = Σᵢ wᵢ(aᵢ − c)`` and ``acc = [Σᵢ wᵢ‖aᵢ − c‖², Σᵢ wᵢ‖aᵢ‖², Σᵢⱼ aᵢⱼ, Σᵢ wᵢ]``, rows summed
    in blocks of :data:`BLOCK` (error growth ``O((d + n/BLOCK + BLOCK)·u)``, not ``O(n·d·u)``).

``euler_sweep(x, dx, v, dv, h, w, shift, c, r, acc)`` / ``euler_sweep_v`` / ``euler_sweep_one``
    :func:`euler_pair` (``euler_sweep_v``: with ``dx`` = ``v``, which vectorizes;
    ``euler_sweep_one``: :func:`euler_one`) and, row by row while the row is in cache, the
    sums of ``sweep`` of the *new* ``x + shift[0]`` and ``v + shift[1]`` about ``c[0]`` and
    ``c[1]`` into ``r[k], acc[k]``: one pass per step gives the state and its moments. The
    update is not under fastmath (bit-identical to :func:`euler_pair`), the sums re-associate
    only. :func:`euler_moments` runs them over two row halves and finishes the moments as
    :func:`moments` does. Twin: :func:`euler_moments_numpy`.

``shifted_copy(z, shift, out)``
    ``out = z − shift`` element by element (numpy's rounding). The run's fixed costs use it:
    :func:`frame` centres the initial positions (the centroid from :func:`moments`' sweeps,
    no temporary; one writing pass), :func:`add_shift` shifts the final positions back in
    place (``x − (−shift)``, numpy's ``x + shift`` bit for bit).

:func:`moments` ``(z, w, shift, c, out)`` joins the sweeps of two row halves into
``out = [F, S, T]``: the fluctuation ``F = Σᵢ wᵢ‖aᵢ − a_c‖²`` (``Γ`` or ``Λ`` of §3.4.1), the
second moment ``S = Σᵢ wᵢ‖aᵢ‖²`` and the plain sum ``T`` (non-finite iff a coordinate is, or
the sum overflows: the loop's finiteness test). ``F`` is taken about the reference centre
``c`` as :mod:`kinred.observables` takes it about its compensated centre: from one sweep,
``F = S₂ − 2‖r‖² + W‖r‖²`` (``S₂ = Σ wᵢ‖aᵢ − c‖²``, ``W = Σ wᵢ``), which is
``Σ wᵢ‖(aᵢ − c) − r‖²`` exactly. When ``c`` is far from the mean (``‖r‖² > RECENTRE·S₂``) a
second sweep starts from ``c + r``, the compensated centre; ``c`` is updated in place to the
mean, so that a caller passing it again on the next step (the state moved a little) needs
one sweep. Twin: :func:`moments_numpy` (the formulas of :func:`kinred.observables.gamma`),
equal to 1e-12 relative.

Flags: ``cache=True``, ``nogil=True``; no fastmath in the Euler update (numpy's rounding),
re-association and contraction only in :func:`moments` (vectorized sums; NaN and Inf
propagate as in IEEE arithmetic).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
from numba import njit

from .._rowsum_kernels import BLOCK
from .._rowsum_kernels import flush as _flush, moment as _moment, row as _row
from ..dynamics import get_num_threads

__all__ = ["euler_pair", "euler_one", "euler", "sweep", "moments", "euler_numpy",
           "moments_numpy", "euler_sweep", "euler_sweep_v", "euler_sweep_one", "euler_moments",
           "euler_moments_numpy", "step_moments", "shifted_copy", "frame", "add_shift",
           "copy_sweep", "copy_moments", "state_moments",
           "Moments", "BLOCK", "RECENTRE", "SPLIT_MIN"]

#: fastmath of :func:`moments`: re-association and contraction of its sums only (vectorized
#: reductions); NaN and Inf still propagate.
_FM = {"reassoc", "contract"}

#: From this many entries ``N·d`` on, :func:`moments` and :func:`euler` split the rows in two
#: halves, the second one in a worker thread when the engine has two threads or more
#: (:func:`kinred.dynamics.set_num_threads`); the halves are the same with one thread.
SPLIT_MIN = 2 ** 20

_POOL: list = [None, 0]

#: :func:`moments` sweeps a second time when its reference centre ``c`` is further from the
#: weighted mean ``m`` than ``‖m − c‖² > RECENTRE·Σ wᵢ‖aᵢ − c‖²``; below it the one sweep is
#: as accurate as two (the cancellation in ``S₂ − ‖r‖²`` loses at most a factor 1.001).
RECENTRE = 1e-3


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def euler_pair(x, dx, v, dv, h):  # pragma: no cover - compiled
    n, d = x.shape
    for i in range(n):
        for j in range(d):
            x[i, j] = x[i, j] + dx[i, j] * h
            v[i, j] = v[i, j] + dv[i, j] * h


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def euler_one(x, dx, h):  # pragma: no cover - compiled
    n, d = x.shape
    for i in range(n):
        for j in range(d):
            x[i, j] = x[i, j] + dx[i, j] * h


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def sweep(z, w, shift, c, r, acc):  # pragma: no cover - compiled
    """One pass: ``r = Σ w (a − c)``, ``acc = [Σ w|a − c|², Σ w|a|², Σ a, Σ w]``, ``a = z + shift``."""
    n, d = z.shape
    blk = np.zeros(d)
    part = np.zeros(4)
    for j in range(d):
        r[j] = 0.0
    for k in range(4):
        acc[k] = 0.0
    for i in range(n):
        wi = w[i]
        rc = 0.0
        rs = 0.0
        rt = 0.0
        for j in range(d):
            a = z[i, j] + shift[j]
            e = a - c[j]
            blk[j] += wi * e
            rc += e * e
            rs += a * a
            rt += a
        part[0] += wi * rc
        part[1] += wi * rs
        part[2] += rt
        part[3] += wi
        if (i + 1) % BLOCK == 0 or i == n - 1:
            for j in range(d):
                r[j] += blk[j]
                blk[j] = 0.0
            for k in range(4):
                acc[k] += part[k]
                part[k] = 0.0


#: fastmath of the fused kernels: re-association of their sums only. No contraction: the
#: update ``x + dx·h`` must stay a rounded product and a rounded sum (numpy's, bit for bit).
_FM_FUSED = {"reassoc"}


@njit(cache=True, nogil=True, fastmath=_FM_FUSED, boundscheck=False, error_model="numpy")
def euler_sweep(x, dx, v, dv, h, w, shift, c, r, acc):  # pragma: no cover - compiled
    """:func:`euler_pair` and, in the same pass, the sums of :func:`sweep` of the new
    ``x + shift[0]`` about ``c[0]`` into ``r[0], acc[0]`` and of the new ``v + shift[1]``
    about ``c[1]`` into ``r[1], acc[1]``. ``dx`` may be ``v`` (or ``dv`` be ``x``): each
    element of ``x`` is updated before the same element of ``v``, as in :func:`euler_pair`."""
    n, d = x.shape
    blk = np.zeros((2, d))
    part = np.zeros((2, 4))
    r[:, :] = 0.0
    acc[:, :] = 0.0
    sx, sv, cx, cv = shift[0], shift[1], c[0], c[1]
    for i in range(n):
        wi = w[i]
        qx = 0.0
        px = 0.0
        tx = 0.0
        qv = 0.0
        pv = 0.0
        tv = 0.0
        for j in range(d):
            xn = x[i, j] + dx[i, j] * h
            x[i, j] = xn
            vn = v[i, j] + dv[i, j] * h
            v[i, j] = vn
            a = xn + sx[j]
            e = a - cx[j]
            dq, dp, dt = _moment(a, e, wi, blk, 0, j)
            qx += dq
            px += dp
            tx += dt
            b = vn + sv[j]
            f = b - cv[j]
            dq, dp, dt = _moment(b, f, wi, blk, 1, j)
            qv += dq
            pv += dp
            tv += dt
        _row(part, 0, wi, qx, px, tx)
        _row(part, 1, wi, qv, pv, tv)
        if (i + 1) % BLOCK == 0 or i == n - 1:
            _flush(0, blk, part, r, acc)
            _flush(1, blk, part, r, acc)


@njit(cache=True, nogil=True, fastmath=_FM_FUSED, boundscheck=False, error_model="numpy")
def euler_sweep_v(x, v, dv, h, w, shift, c, r, acc):  # pragma: no cover - compiled
    """:func:`euler_sweep` of a second-order scene, whose ``dx`` is ``v`` itself (no
    ``dx`` argument: the kernel vectorizes, where the aliased ``dx`` and ``v`` prevent it)."""
    n, d = x.shape
    blk = np.zeros((2, d))
    part = np.zeros((2, 4))
    r[:, :] = 0.0
    acc[:, :] = 0.0
    sx, sv, cx, cv = shift[0], shift[1], c[0], c[1]
    for i in range(n):
        wi = w[i]
        qx = 0.0
        px = 0.0
        tx = 0.0
        qv = 0.0
        pv = 0.0
        tv = 0.0
        for j in range(d):
            vo = v[i, j]
            xn = x[i, j] + vo * h
            x[i, j] = xn
            vn = vo + dv[i, j] * h
            v[i, j] = vn
            a = xn + sx[j]
            e = a - cx[j]
            dq, dp, dt = _moment(a, e, wi, blk, 0, j)
            qx += dq
            px += dp
            tx += dt
            b = vn + sv[j]
            f = b - cv[j]
            dq, dp, dt = _moment(b, f, wi, blk, 1, j)
            qv += dq
            pv += dp
            tv += dt
        _row(part, 0, wi, qx, px, tx)
        _row(part, 1, wi, qv, pv, tv)
        if (i + 1) % BLOCK == 0 or i == n - 1:
            _flush(0, blk, part, r, acc)
            _flush(1, blk, part, r, acc)


@njit(cache=True, nogil=True, fastmath=_FM_FUSED, boundscheck=False, error_model="numpy")
def euler_sweep_one(x, dx, h, w, shift, c, r, acc):  # pragma: no cover - compiled
    """:func:`euler_one` and the sums of :func:`sweep` of the new ``x + shift[0]`` about
    ``c[0]`` into ``r[0], acc[0]`` (arrays of one row, as :func:`euler_sweep`'s)."""
    n, d = x.shape
    blk = np.zeros((1, d))
    part = np.zeros((1, 4))
    r[:, :] = 0.0
    acc[:, :] = 0.0
    sx, cx = shift[0], c[0]
    for i in range(n):
        wi = w[i]
        qx = 0.0
        px = 0.0
        tx = 0.0
        for j in range(d):
            xn = x[i, j] + dx[i, j] * h
            x[i, j] = xn
            a = xn + sx[j]
            e = a - cx[j]
            dq, dp, dt = _moment(a, e, wi, blk, 0, j)
            qx += dq
            px += dp
            tx += dt
        _row(part, 0, wi, qx, px, tx)
        if (i + 1) % BLOCK == 0 or i == n - 1:
            _flush(0, blk, part, r, acc)


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def shifted_copy(z, shift, out):  # pragma: no cover - compiled
    """``out = z − shift`` element by element (numpy's ``z - shift``, bit for bit)."""
    n, d = z.shape
    for i in range(n):
        for j in range(d):
            out[i, j] = z[i, j] - shift[j]


@njit(cache=True, nogil=True, fastmath=_FM, boundscheck=False, error_model="numpy")
def copy_sweep(z, w, c, r, acc, out):  # pragma: no cover - compiled
    """``out = z`` (a copy) and, in the same pass, the sums of :func:`sweep` of ``z`` (no
    shift) about ``c`` into ``r, acc``."""
    n, d = z.shape
    blk = np.zeros(d)
    part = np.zeros(4)
    r[:] = 0.0
    acc[:] = 0.0
    for i in range(n):
        wi = w[i]
        rc = 0.0
        rs = 0.0
        rt = 0.0
        for j in range(d):
            a = z[i, j]
            out[i, j] = a
            e = a - c[j]
            blk[j] += wi * e
            rc += e * e
            rs += a * a
            rt += a
        part[0] += wi * rc
        part[1] += wi * rs
        part[2] += rt
        part[3] += wi
        if (i + 1) % BLOCK == 0 or i == n - 1:
            for j in range(d):
                r[j] += blk[j]
                blk[j] = 0.0
            for k in range(4):
                acc[k] += part[k]
                part[k] = 0.0


def _pool() -> ThreadPoolExecutor:
    """The one worker thread that takes the second half of the rows (made anew in a forked
    process, where the parent's thread does not exist)."""
    if _POOL[0] is None or _POOL[1] != os.getpid():
        _POOL[:] = [ThreadPoolExecutor(max_workers=1, thread_name_prefix="kinred-loop"),
                    os.getpid()]
    return _POOL[0]


def _halves(n: int, d: int) -> list:
    """Row ranges of one call: two halves (at a multiple of :data:`BLOCK`) from
    :data:`SPLIT_MIN` entries on, whatever the thread count (the sums do not depend on it)."""
    if n * d < SPLIT_MIN or n < 2 * BLOCK:
        return [(0, n)]
    mid = (n // 2) // BLOCK * BLOCK
    return [(0, mid), (mid, n)]


def _each(fn, ranges) -> list:
    """``[fn(i0, i1)]`` over the row ranges: the second one in the worker thread when the
    engine has two threads or more (the kernels release the GIL)."""
    if len(ranges) == 1 or get_num_threads() < 2:
        return [fn(*rg) for rg in ranges]
    fut = _pool().submit(fn, *ranges[1])
    try:
        first = fn(*ranges[0])
    finally:
        wait([fut])         # never leave the worker writing into the caller's arrays
    return [first, fut.result()]


def _sweep_all(z, w, shift, c, ranges):
    """``(r, acc)`` of :func:`sweep` over all rows: the ranges' partial sums, added in order."""
    def part(i0, i1):
        r, acc = np.empty(z.shape[1]), np.empty(4)
        sweep(z[i0:i1], w[i0:i1], shift, c, r, acc)
        return r, acc
    parts = _each(part, ranges)
    r, acc = parts[0]
    for rp, ap in parts[1:]:
        r, acc = r + rp, acc + ap
    return r, acc


def moments(z, w, shift, c, out) -> None:
    """``out = [F, S, T]`` of ``z + shift`` about the reference centre ``c`` (updated in
    place to the mean): one :func:`sweep` when ``c`` is near the mean, two otherwise (module
    notes)."""
    ranges = _halves(*z.shape)
    with np.errstate(all="ignore"):         # NaN and Inf propagate to the caller's test
        c[~np.isfinite(c)] = 0.0
        r, acc = _sweep_all(z, w, shift, c, ranges)
        rr = float(r @ r)
        if not rr <= RECENTRE * acc[0]:     # c is not near the centre: sweep again from it
            c += r
            r, acc = _sweep_all(z, w, shift, c, ranges)
            rr = float(r @ r)
        c += r
        out[0] = acc[0] - 2.0 * rr + acc[3] * rr
        out[1] = acc[1]
        out[2] = acc[2]


def _finish(z, w, shift, c, r, acc) -> tuple:
    """``(F, S, T)`` from one sweep's ``(r, acc)`` about ``c`` (updated in place to the mean);
    when ``c`` was far from the mean, :func:`moments` sweeps again from ``c + r``."""
    out = np.empty(3)
    rr = float(r @ r)
    c += r
    if rr <= RECENTRE * acc[0]:
        out[:] = acc[0] - 2.0 * rr + acc[3] * rr, acc[1], acc[2]
    else:
        moments(z, w, shift, c, out)
    return float(out[0]), float(out[1]), float(out[2])


def euler_moments(x, dx, v, dv, h, w, shift, centres) -> tuple:
    """Forward Euler's in-place update of :func:`euler` and the moments ``(F, S, T)`` of
    :func:`moments` of the new ``x + shift`` (``shift`` None: 0) and the new ``v``, from one
    pass over the state (:func:`euler_sweep`; :func:`euler_sweep_v` when ``dx`` is ``v``;
    ``v`` None: :func:`euler_sweep_one`) over the
    row ranges of :func:`_halves`.

    ``centres``: the reference centres ``[c_x, c_v]`` (``(d,)`` arrays), updated in place to
    the means. Returns ``(moments of x, moments of v)`` (the latter None when ``v`` is None).
    The update is bit-identical to :func:`euler`'s, the moments equal :func:`moments`' to
    round-off (1e-12 relative). Twin: :func:`euler_moments_numpy`.
    """
    n, d = x.shape

    def sums(sh, c):
        k = sh.shape[0]

        def part(i0, i1):
            r, acc = np.empty((k, d)), np.empty((k, 4))
            if v is None:
                euler_sweep_one(x[i0:i1], dx[i0:i1], h, w[i0:i1], sh, c, r, acc)
            elif dx is v:
                euler_sweep_v(x[i0:i1], v[i0:i1], dv[i0:i1], h, w[i0:i1], sh, c, r, acc)
            else:
                euler_sweep(x[i0:i1], dx[i0:i1], v[i0:i1], dv[i0:i1], h, w[i0:i1], sh, c,
                            r, acc)
            return r, acc
        parts = _each(part, _halves(n, d))
        r, acc = parts[0]
        for rp, ap in parts[1:]:
            r, acc = r + rp, acc + ap
        return r, acc
    return step_moments(x, v, w, shift, centres, sums)


def step_moments(x, v, w, shift, centres, sums):
    """The moments ``(F, S, T)`` of the new ``x + shift`` and ``v`` of a step whose pass over
    the state also gives their sums: ``sums(sh, c)`` updates the state and returns ``(r, acc)``
    of :func:`kinred._rowsum_kernels.row_sums` (``(k, d)``, ``(k, 4)``; ``k = 1`` without ``v``)
    about the centres ``c (k, d)`` of the rows ``z + sh[k]``, or None when it cannot take the
    step (then this returns None and ``centres`` are unchanged). ``centres`` as in
    :func:`euler_moments`."""
    d = x.shape[1]
    k = 1 if v is None else 2
    sh = np.zeros((k, d))
    if shift is not None:
        sh[0] = shift
    with np.errstate(all="ignore"):             # NaN and Inf propagate to the caller's test
        c = np.array(centres[:k], dtype=float)
        c[~np.isfinite(c)] = 0.0
    got = sums(sh, c)       # outside: the drift's own warnings stay the caller's to see
    if got is None:
        return None
    r, acc = got
    with np.errstate(all="ignore"):
        out = []
        for a, z in enumerate((x, v)[:k]):
            centres[a][:] = c[a]
            out.append(_finish(z, w, sh[a], centres[a], r[a], acc[a]))
    return out[0], (out[1] if k == 2 else None)


def euler_moments_numpy(x, dx, v, dv, h, w, shift, tmp) -> tuple:
    """Twin of :func:`euler_moments`: :func:`euler_numpy`, then :func:`moments_numpy` of the
    new ``x + shift`` and ``v``."""
    euler_numpy(x, dx, v, dv, h, tmp)
    mx = tuple(float(a) for a in moments_numpy(x, w, shift))
    return mx, (None if v is None else tuple(float(a) for a in moments_numpy(v, w)))


def frame(z, w) -> tuple:
    """``(z − c, c, (F, S, T))``: a fresh copy of ``z (N, d)`` relative to its weighted
    centroid ``c``, the reference centre that :func:`moments` leaves from 0 (compensated when
    the centroid is far from 0, as :func:`kinred.observables.centre`; one or two sweeps, no
    ``(N, d)`` temporary), the copy written by :func:`shifted_copy` (one pass over the row
    ranges of :func:`_halves`), and the
    moments of ``z`` that came with ``c``."""
    n, d = z.shape
    c, m = np.zeros(d), np.empty(3)
    moments(z, w, np.zeros(d), c, m)
    out = np.empty((n, d))
    _each(lambda i0, i1: shifted_copy(z[i0:i1], c, out[i0:i1]), _halves(n, d))
    return out, c, (float(m[0]), float(m[1]), float(m[2]))


def copy_moments(z, w) -> tuple:
    """``(copy of z, (F, S, T), c)``: a fresh copy of ``z (N, d)`` and its moments of
    :func:`moments` about the reference centre ``c`` (from 0, updated to the mean), from one
    pass (:func:`copy_sweep` over the row ranges of :func:`_halves`; a second sweep when the
    mean is far from 0)."""
    n, d = z.shape
    out, c = np.empty((n, d)), np.zeros(d)

    def part(i0, i1):
        r, acc = np.empty(d), np.empty(4)
        copy_sweep(z[i0:i1], w[i0:i1], c, r, acc, out[i0:i1])
        return r, acc
    parts = _each(part, _halves(n, d))
    r, acc = parts[0]
    for rp, ap in parts[1:]:
        r, acc = r + rp, acc + ap
    with np.errstate(all="ignore"):
        m = _finish(out, w, np.zeros(d), c, r, acc)
    return out, m, c


def add_shift(x, shift) -> None:
    """``x ← x + shift`` in place (numpy's ``np.add(x, shift)``, bit for bit: the kernel
    :func:`shifted_copy` subtracts ``−shift``) over the row ranges of :func:`_halves`."""
    neg = -np.asarray(shift, dtype=float)
    _each(lambda i0, i1: shifted_copy(x[i0:i1], neg, x[i0:i1]), _halves(*x.shape))


def euler(x, dx, v, dv, h) -> None:
    """:func:`euler_pair` (``v`` None: :func:`euler_one`) over the row ranges of
    :func:`_halves` (element by element: the result does not depend on the split)."""
    def part(i0, i1):
        if v is None:
            euler_one(x[i0:i1], dx[i0:i1], h)
        else:
            euler_pair(x[i0:i1], dx[i0:i1], v[i0:i1], dv[i0:i1], h)
    _each(part, _halves(*x.shape))


def euler_numpy(x, dx, v, dv, h, tmp) -> None:
    """Twin of :func:`euler_pair` (``v`` None: of :func:`euler_one`): numpy's in-place Euler
    update through the scratch array ``tmp``."""
    np.multiply(dx, h, out=tmp)     # dx may be v itself: x first, then v
    x += tmp
    if v is not None:
        np.multiply(dv, h, out=tmp)
        v += tmp


def moments_numpy(z, w, shift=None) -> np.ndarray:
    """Twin of :func:`moments`: ``[F, S, T]`` by the formulas of :mod:`kinred.observables`."""
    z = z + shift if shift is not None else z
    m1 = w @ z
    dev = z - m1
    dev -= w @ dev
    return np.array([float(w @ np.einsum("ij,ij->i", dev, dev)),
                     float(w @ np.einsum("ij,ij->i", z, z)), float(np.sum(z))])


def _f64(a, shape) -> bool:
    return type(a) is np.ndarray and a.dtype == np.float64 and a.shape == shape


def state_moments(z, w, shift=None, centre=None) -> tuple:
    """``(F, S, T)`` of :func:`moments` for ``z (N, d) + shift (d,)`` (None: no shift) and
    weights ``w (N,)``: compiled for float64 arrays, the twin otherwise. ``centre (d,)``: the
    reference centre, updated in place (None: start from 0)."""
    z = np.asarray(z)
    if (z.ndim == 2 and _f64(z, z.shape) and _f64(w, z.shape[:1])
            and (shift is None or _f64(shift, z.shape[1:]))):
        out = np.empty(3)
        c = np.zeros(z.shape[1]) if centre is None else centre
        moments(z, w, np.zeros(z.shape[1]) if shift is None else shift, c, out)
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            out = moments_numpy(np.asarray(z, dtype=float), np.asarray(w, dtype=float),
                                None if shift is None else np.asarray(shift, dtype=float))
    return float(out[0]), float(out[1]), float(out[2])


class Moments:
    """:func:`state_moments` of one array of a run, step after step, with its reference
    centre carried over (one sweep per call while the mean moves little).

    Parameters
    ----------
    w : (N,) ndarray
        Agent weights.
    shift : (d,) ndarray, optional
        Added to the array (the run's working positions are relative to it).
    """

    def __init__(self, w, shift=None):
        self.w, self.shift, self.centre = w, shift, None

    def ready(self, z) -> np.ndarray:
        """The reference centre for ``z`` (made on the first call)."""
        if self.centre is None or self.centre.shape != z.shape[1:]:
            # positions relative to their centroid: the shift is the first guess of the centre
            self.centre = (np.array(self.shift, dtype=float) if self.shift is not None and
                           np.shape(self.shift) == z.shape[1:] else np.zeros(z.shape[1:]))
        return self.centre

    def __call__(self, z) -> tuple:
        """``(F, S, T)`` of ``z (+ shift)``."""
        return state_moments(z, self.w, self.shift, self.ready(z))
