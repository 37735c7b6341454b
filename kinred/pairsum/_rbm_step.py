"""The fused Euler step of the random batch backend (:meth:`RandomBatch.euler_step
<kinred.pairsum.RandomBatch.euler_step>`): the step taken inside the batches.

A batch's rows are read and written by that batch alone, so forward Euler's update of a
batch right after its pair sums is the update from the whole right-hand side (eq. (1.6)). The
plan's chunks are walked in pieces of about :data:`PIECE_BYTES` of state rows: per piece the
squared distances and every term's kernel values (vectorized, as the right-hand side
computes them), then :func:`kinred.pairsum._rbm_kernels.batch_euler` – per batch its sums,
the in-place update and the row sums of the new rows for the moments – while the piece's rows
are in cache. The pieces are dealt to the threads in equal runs and their sums added in the
pieces' order: the result does not depend on the thread count.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from .. import _parallel
from . import _rbm_kernels

__all__ = ["euler_step", "split", "term_values", "PIECE_BYTES"]


def euler_step(plan, x: np.ndarray, v: np.ndarray | None, h: float, perm: np.ndarray,
               local: tuple, w: np.ndarray, shift: np.ndarray, centres: np.ndarray) -> tuple:
    """The step of :meth:`kinred.pairsum.RandomBatch.euler_step` (validated there) for the
    partition ``perm``: updates ``x, v`` in place, returns the row sums ``(r, acc)``.
    ``local = (drifts of x, drifts of v)``, two tuples of arrays (possibly empty)."""
    k = 1 if v is None else 2
    pieces = _pieces(plan, k)
    npieces = len(pieces)
    terms = [t for _, ts in plan.by_source for t, _ in ts]
    code = {"x": 0, "v": 1}
    step = _EulerStep(
        x=x, v=x if v is None else v, order=k, h=float(h),
        locx=tuple(local[0]) or (x,), nlx=len(local[0]), locv=tuple(local[1]) or (x,),
        nlv=len(local[1]), px=any(t.target == "x" for t in terms),
        pv=any(t.target == "v" for t in terms),
        carriers=np.array([code[t.carrier] for t in terms], dtype=np.int64),
        targets=np.array([code[t.target] for t in terms], dtype=np.int64),
        w=np.ascontiguousarray(w, dtype=np.float64), shift=np.ascontiguousarray(shift[:k]),
        c=np.ascontiguousarray(centres[:k]),
        r=np.zeros((npieces, k, plan.dim)), acc=np.zeros((npieces, k, 4)))
    state = {"x": x, "v": v}
    nthreads = max(1, min(_parallel.get_num_threads(), npieces))
    _parallel.run_parallel(partial(_share_step, plan, state, perm, step),
                           split(tuple(enumerate(pieces)), nthreads))
    r, acc = step.r[0].copy(), step.acc[0].copy()
    for i in range(1, len(step.r)):             # in the pieces' order, whatever the threads
        r += step.r[i]
        acc += step.acc[i]
    return r, acc


@dataclass(eq=False)
class _EulerStep:
    """The arguments of :func:`_rbm_kernels.batch_euler` common to all pieces
    (:func:`_pieces`), and the pieces' row sums ``r[piece], acc[piece]``."""

    x: np.ndarray
    v: np.ndarray
    order: int
    h: float
    locx: tuple
    nlx: int
    locv: tuple
    nlv: int
    px: bool
    pv: bool
    carriers: np.ndarray
    targets: np.ndarray
    w: np.ndarray
    shift: np.ndarray
    c: np.ndarray
    r: np.ndarray
    acc: np.ndarray


#: The fused Euler step walks a chunk in pieces whose state rows (``x`` and ``v``) take about
#: this many bytes, so that the rows its distances and kernel values were computed from are
#: still in cache when the pieces' sums and update read them again.
PIECE_BYTES = 2 ** 21


def _pieces(plan, k: int) -> list:
    """``[(b0, b1), ...]``: the chunks' batches in consecutive pieces of about
    :data:`PIECE_BYTES` of state rows, in the order of the chunks (fixed by the plan: the
    sums do not depend on the threads, among which the pieces are dealt in equal runs)."""
    per = max(1, PIECE_BYTES // (plan.p * plan.dim * 8 * k))
    return [(s0, min(s0 + per, b1)) for b0, b1 in plan.chunks for s0 in range(b0, b1, per)]


def _share_step(plan, state: dict, perm: np.ndarray, step: _EulerStep,
                g: int, pieces) -> None:
    """Thread ``g``'s pieces ``(index, (b0, b1))`` of :func:`euler_step`: per piece the
    squared distances and every term's kernel values (as ``random_batch._share``), then
    the piece's fused sums, update and row sums."""
    nterms = len(step.carriers)
    mmax = max(_rbm_kernels.pairs_in(plan.n, plan.p, b0, b1) for _, (b0, b1) in pieces)
    qbuf = np.empty(max(mmax, 1))
    phis = np.empty((nterms, max(mmax, 1)))
    n, p = plan.n, plan.p
    for i, (b0, b1) in pieces:
        m = _rbm_kernels.pairs_in(n, p, b0, b1)
        if m:       # every term's values into its row of phis
            for _ in term_values(plan, state, perm, b0, b1, qbuf[:m],
                                 lambda t, q, last: phis[t, :m]):
                pass
        _rbm_kernels.batch_euler(step.x, step.v, step.order, plan.cs, perm, p, b0, b1,
                                 phis[:, :max(m, 1)], step.carriers, step.targets, step.h,
                                 step.locx, step.nlx, step.locv, step.nlv, step.px, step.pv,
                                 step.w, step.shift, step.c, step.r[i], step.acc[i])


def term_values(plan, state: dict, perm: np.ndarray, b0: int, b1: int, q: np.ndarray,
                dest):
    """Per source the squared distances of the pairs of batches ``[b0, b1)`` into ``q``, then
    per term (in ``plan.by_source`` order) its kernel values into ``dest(t, q, last)`` (``t``
    the term's index, ``last``: the source's last term, which may take ``q`` itself); yields
    ``(term, values)`` before the next term or source overwrites them. The one computation
    of the kernel values of ``random_batch._share`` and of :func:`euler_step`."""
    m, t = q.shape[0], 0
    for s, terms in plan.by_source:
        _rbm_kernels.batch_sqdist(state[s], perm, plan.p, b0, b1, q)
        for idx, (term, value_sq) in enumerate(terms):
            phi = dest(t, q, idx == len(terms) - 1)
            if value_sq is not None:
                value_sq(q.reshape(1, m), phi.reshape(1, m))
            else:
                phi[...] = term.kernel(np.sqrt(q))
            yield term, phi
            t += 1


def split(items: tuple, k: int) -> list:
    """``items`` in ``k`` contiguous groups of near-equal length (the first ones longer)."""
    n = len(items)
    bounds = [n * g // k for g in range(k + 1)]
    return [items[bounds[g]:bounds[g + 1]] for g in range(k)]
