r"""Compiled row sums of the state's moments, shared by the loop's kernels
(:mod:`kinred.integrate._kernels`) and the random batch backend's fused Euler step
(:mod:`kinred.pairsum._rbm_kernels`): one definition of the blocked sums, whichever pass
visits the rows.

For rows ``aᵢ = zᵢ + shift`` with weights ``wᵢ`` and a reference centre ``c`` the sums are
``r = Σᵢ wᵢ(aᵢ − c)`` and ``acc = [Σᵢ wᵢ‖aᵢ − c‖², Σᵢ wᵢ‖aᵢ‖², Σᵢⱼ aᵢⱼ, Σᵢ wᵢ]``, accumulated
per block of :data:`BLOCK` rows (``blk``, ``part``) and flushed into ``r, acc`` at the end of
each block: the error grows like ``O((d + n/BLOCK + BLOCK)·u)``, not ``O(n·d·u)``. Index
``k`` selects the variable (0: positions, 1: velocities) in the ``(2, d)`` / ``(2, 4)`` arrays.
"""

from __future__ import annotations

from numba import njit

__all__ = ["BLOCK", "flush", "moment", "row", "row_sums"]

#: Rows per partial sum.
BLOCK = 256


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def flush(k, blk, part, r, acc):  # pragma: no cover - compiled
    """Add the block's partial sums ``blk[k], part[k]`` to ``r[k], acc[k]`` and clear them."""
    for j in range(blk.shape[1]):
        r[k, j] += blk[k, j]
        blk[k, j] = 0.0
    for m in range(4):
        acc[k, m] += part[k, m]
        part[k, m] = 0.0


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy", inline="always")
def moment(a, e, wi, blk, k, j):  # pragma: no cover - compiled
    """One element: ``blk[k, j] += wᵢ·e``; returns the element's ``e²``, ``a²`` and ``a``
    for the row's sums."""
    blk[k, j] += wi * e
    return e * e, a * a, a


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy", inline="always")
def row(part, k, wi, q, p, t):  # pragma: no cover - compiled
    """A finished row into the block's partial sums ``part[k]``."""
    part[k, 0] += wi * q
    part[k, 1] += wi * p
    part[k, 2] += t
    part[k, 3] += wi


@njit(cache=True, nogil=True, fastmath={"reassoc"}, boundscheck=False, error_model="numpy")
def row_sums(z, i, k, wi, shift, c, blk, part):  # pragma: no cover - compiled
    """The sums of row ``z[i] + shift[k]`` about ``c[k]`` into ``blk[k], part[k]`` (the
    caller counts the rows and :func:`flush` es every :data:`BLOCK` of them)."""
    q = 0.0
    p = 0.0
    t = 0.0
    for j in range(z.shape[1]):
        a = z[i, j] + shift[k, j]
        e = a - c[k, j]
        dq, dp, dt = moment(a, e, wi, blk, k, j)
        q += dq
        p += dp
        t += dt
    row(part, k, wi, q, p, t)
