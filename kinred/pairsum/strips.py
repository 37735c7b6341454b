r"""The strip walker of the exact pair sums, public for other passes over all pairs.

:class:`~kinred.pairsum.Dense` walks the unordered pairs of ``N`` agents in row strips
``I = [i0, i1)`` of the upper triangle (rows ``i0:i1`` against columns ``i0:N``). Another pass
over the same pairs – the certificate's pair pass (:mod:`kinred.certify`), which needs the
engine's distances, kernel values and products to the last bit – walks them with the same
pieces, from this module:

* the strips and their threads: :func:`row_strips` (about :data:`STRIP_ELEMS` entries each),
  :func:`deal` (largest first to the least-loaded thread);
* squared distances of a strip: :func:`sqdist_rows` by differences (dimensions up to
  :data:`SMALL_K`, coordinates transposed) or :func:`sqdist_block`, a BLAS Gram block of
  centred rows (:func:`centre_rows`, norms :func:`gram_rows`) whose close pairs are recomputed
  by differences (threshold :func:`tau_for`); plain-numpy twin :func:`sqdist_numpy`;
* kernel values on a block from a kernel's compiled form: :func:`cs_halfint`;
* the pair sums: ``Z = [c z, c]`` (:func:`zext_rows`), both orientations of a strip's products
  (:func:`pair_products`), and ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ`` (:func:`pair_finish`);
* compiled passes (numba, in another package's ``_kernels.py``) call the same steps from
  compiled code: :func:`compiled_blocks` hands them the compiled pieces; they run when
  numpy's BLAS symbols were found (:data:`HAVE_COMPILED_FOR`).

Every function here validates its arguments (types, dimensions, dtypes and shapes) and then
calls the engine's own kernel, so a caller gets the engine's numbers.

Examples
--------
>>> row_strips(10, 4)
[(0, 4), (4, 8), (8, 10)]
>>> Y = np.array([[0.0, 0.0], [3.0, 4.0], [6.0, 8.0]])
>>> sqdist_rows(np.ascontiguousarray(Y.T), 0, 2, 0, np.empty((2, 3)))
array([[  0.,  25., 100.],
       [ 25.,   0.,  25.]])
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import _parallel
from .._validate import as_float, as_int
from ..errors import InvalidInput
from . import _kernels

__all__ = ["SMALL_K", "STRIP_ELEMS", "BIG_K", "HAVE_COMPILED_FOR", "row_strips", "deal",
           "sqdist_rows", "sqdist_block", "sqdist_numpy", "tau_for", "centre_rows", "gram_rows",
           "zext_rows", "pair_products", "pair_finish", "cs_halfint", "CompiledBlocks",
           "compiled_blocks"]

#: Dimensions up to which distances are computed by differences (numba, vectorized over
#: columns) rather than by the Gram product plus fix-up.
SMALL_K = 3

#: Target number of pairwise entries per strip: ≈ 512 kB of float64 for small dimensions (the
#: block stays in L2 for the elementwise kernel passes) and 2× more from ``BIG_K`` on, where
#: the BLAS products dominate and thin strips would spend their time packing ``Z`` (a
#: ``(m, k+1)`` operand re-packed for every strip: overhead ≈ 1/(2·rows) of the flops).
STRIP_ELEMS = 65_536
#: Dimension from which strips hold twice :data:`STRIP_ELEMS` entries.
BIG_K = 48

#: Whether compiled passes can run, per stage dtype (numpy's BLAS symbols were found).
HAVE_COMPILED_FOR = _kernels.HAVE_COMPILED_FOR

_FLOATS = (np.float64, np.float32)


def _arr(a, name: str, ndim: int, *, dtypes=_FLOATS, writable: bool = False) -> np.ndarray:
    """``a`` itself when it is an ndarray of ``ndim`` dimensions and one of ``dtypes``."""
    if not isinstance(a, np.ndarray) or a.ndim != ndim or a.dtype.type not in dtypes:
        got = (f"an array of shape {a.shape} and dtype {a.dtype}" if isinstance(a, np.ndarray)
               else type(a).__name__)
        kinds = " or ".join(np.dtype(d).name for d in dtypes)
        raise InvalidInput(f"{name} must be a {ndim}-d numpy array of {kinds}, got {got}")
    if writable and not a.flags.writeable:
        raise InvalidInput(f"{name} must be writable (it receives the result)")
    return a


def _shape(name: str, a: np.ndarray, shape: tuple) -> None:
    if a.shape != shape:
        raise InvalidInput(f"{name} must have shape {shape}, got {a.shape}")


def row_strips(n: int, block: int | None = None, dim: int = 1, nthreads: int = 1,
               itemsize: int = 8) -> list:
    """Row strips ``[(i0, i1)]`` of the upper triangle ``j >= i0`` of ``n`` agents.

    With ``block`` given: fixed ``block`` rows per strip. Otherwise strips of about
    :data:`STRIP_ELEMS` entries each (2× that for ``dim >= BIG_K``; rows ``i0:i1`` against
    columns ``i0:n``, at most ``entries/512`` rows), so later strips (shorter rows) get more
    rows and every strip costs about the same (float32 blocks, ``itemsize = 4``: twice the
    entries, the same bytes). With ``nthreads > 1`` strips are made small enough that there
    are at least four per thread (load balance).

    Examples
    --------
    >>> row_strips(1000)[:2]
    [(0, 65), (65, 135)]
    """
    n = as_int(n, "n", low=0)
    block = None if block is None else as_int(block, "block", low=1)
    dim = as_int(dim, "dim", low=1)
    nthreads = as_int(nthreads, "nthreads", low=1)
    if itemsize not in (4, 8):
        raise InvalidInput(f"itemsize must be 4 (float32) or 8 (float64), got {itemsize!r}")
    return _row_strips(n, block, dim, nthreads, itemsize)


def _row_strips(n, block, dim, nthreads, itemsize):
    if block is not None:
        return [(i0, min(n, i0 + block)) for i0 in range(0, n, block)]
    elems = STRIP_ELEMS * (2 if dim >= BIG_K else 1) * 8 // itemsize
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


def deal(strip_list, n: int, nthreads: int) -> tuple:
    """Strips dealt to ``nthreads`` groups: largest first to the least-loaded (deterministic);
    a group's strips in order.

    Examples
    --------
    >>> deal([(0, 2), (2, 4), (4, 6)], 6, 2)
    (((0, 2),), ((2, 4), (4, 6)))
    """
    n = as_int(n, "n", low=0)
    nthreads = as_int(nthreads, "nthreads", low=1)
    try:
        strip_list = [(int(i0), int(i1)) for i0, i1 in strip_list]
    except (TypeError, ValueError):
        raise InvalidInput(f"strip_list must be a sequence of (i0, i1) pairs, got "
                           f"{strip_list!r}") from None
    if any(not 0 <= i0 <= i1 <= n for i0, i1 in strip_list):
        raise InvalidInput(f"strip_list must hold pairs 0 <= i0 <= i1 <= n = {n}, got "
                           f"{strip_list!r}")
    return _deal(strip_list, n, nthreads)


def _deal(strip_list: list, n: int, nthreads: int) -> tuple:
    groups = [[] for _ in range(nthreads)]
    loads = [0] * nthreads
    for i0, i1 in sorted(strip_list, key=lambda st: (-(st[1] - st[0]) * (n - st[0]), st[0])):
        g = loads.index(min(loads))
        groups[g].append((i0, i1))
        loads[g] += (i1 - i0) * (n - i0)
    return tuple(tuple(sorted(gr)) for gr in groups)


def sqdist_rows(YT: np.ndarray, i0: int, i1: int, j0: int, out: np.ndarray) -> np.ndarray:
    """Squared distances by differences, rows ``i0:i1`` against columns ``j0:N``, into ``out``.

    ``YT (k, N)`` holds the coordinates transposed (contiguous float64), ``out (i1 − i0,
    N − j0)``. Exact to rounding (no cancellation), vectorized over columns; the engine's path
    for small dimensions. Twin: :func:`sqdist_numpy`.
    """
    YT = _arr(YT, "YT", 2, dtypes=(np.float64,))
    N = YT.shape[1]
    i0, i1, j0 = as_int(i0, "i0", low=0), as_int(i1, "i1", low=0), as_int(j0, "j0", low=0)
    if not (i0 <= i1 <= N and j0 <= N):
        raise InvalidInput(f"rows i0:i1 = {i0}:{i1} and columns j0 = {j0} must lie in 0..N = {N}")
    _shape("out", _arr(out, "out", 2, writable=True), (i1 - i0, N - j0))
    return _kernels.sqdist_rows(np.ascontiguousarray(YT), i0, i1, j0, out)


def sqdist_block(Yi: np.ndarray, Yj: np.ndarray, ni: np.ndarray, nj: np.ndarray,
                 out: np.ndarray, Xi: np.ndarray | None = None,
                 Xj: np.ndarray | None = None, diag: int = -1) -> np.ndarray:
    """Squared distances between the rows of ``Yi (b, k)`` and ``Yj (m, k)`` into ``out (b, m)``.

    ``Yi``/``Yj`` are centred coordinates (:func:`centre_rows`), ``ni``/``nj`` their squared row
    norms (:func:`gram_rows`), all of the dtype of ``out`` (float64, or float32 for
    ``precision="mixed"``). BLAS Gram product (``−2 Yi Yjᵀ`` straight into ``out``) plus the
    compiled fix-up, which adds the norms and recomputes close pairs (below
    :func:`tau_for` relative) by differences of the raw rows ``Xi``/``Xj`` (default ``Yi``/``Yj``).
    ``diag >= 0`` says that row ``a`` and column ``a + diag`` are the same agent (set to 0).
    """
    Yi, Yj = _arr(Yi, "Yi", 2), _arr(Yj, "Yj", 2)
    out = _arr(out, "out", 2, writable=True)
    if Yj.shape[1] != Yi.shape[1]:
        raise InvalidInput(f"Yi and Yj must have the same columns, got {Yi.shape} and {Yj.shape}")
    _shape("out", out, (Yi.shape[0], Yj.shape[0]))
    for name, a, ref in (("ni", ni, Yi), ("nj", nj, Yj)):
        _shape(name, _arr(a, name, 1), (ref.shape[0],))
    for name, a, ref in (("Xi", Xi, Yi), ("Xj", Xj, Yj)):
        if a is not None:
            _shape(name, _arr(a, name, 2, dtypes=(np.float64,)), ref.shape)
    if len({Yi.dtype, Yj.dtype, ni.dtype, nj.dtype, out.dtype}) != 1:
        raise InvalidInput(f"Yi, Yj, ni, nj and out must share one dtype, got {Yi.dtype}, "
                           f"{Yj.dtype}, {ni.dtype}, {nj.dtype}, {out.dtype}")
    return _kernels.sqdist_block(Yi, Yj, ni, nj, out, Xi, Xj, as_int(diag, "diag", low=-1))


def sqdist_numpy(Yi, Yj) -> np.ndarray:
    """Twin of :func:`sqdist_block` and :func:`sqdist_rows`: ``Σₗ (Yi[a, l] − Yj[j, l])²`` by
    differences, a fresh ``(b, m)`` array."""
    Yi, Yj = _arr(np.asarray(Yi, dtype=float), "Yi", 2), _arr(np.asarray(Yj, dtype=float), "Yj", 2)
    if Yj.shape[1] != Yi.shape[1]:
        raise InvalidInput(f"Yi and Yj must have the same columns, got {Yi.shape} and {Yj.shape}")
    return _kernels.sqdist_numpy(Yi, Yj)


def tau_for(k: int, dtype=np.float64) -> float:
    """The relative threshold below which :func:`sqdist_block` recomputes a squared distance by
    differences, for dimension ``k``: ``2.5e-4·(k+2)`` capped at 1/8 in float64 (relative
    error of the kept Gram entries below 1e-12), ``1.2e-3·(k+2)`` capped at 1/4 in float32.

    Examples
    --------
    >>> tau_for(10)
    0.003
    """
    k = as_int(k, "k", low=1)
    if np.dtype(dtype) not in (np.float64, np.float32):
        raise InvalidInput(f"dtype must be float64 or float32, got {dtype!r}")
    return _kernels.tau_for(k, dtype)


def centre_rows(z: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out = z − mean(z, axis=0)`` (float64; the column mean accumulated row by row, as
    numpy does)."""
    z = _arr(z, "z", 2, dtypes=(np.float64,))
    _shape("out", _arr(out, "out", 2, dtypes=(np.float64,), writable=True), z.shape)
    return _kernels.centre_rows(z, out)


def gram_rows(centred: np.ndarray, Y: np.ndarray, nrm: np.ndarray, cast: bool) -> np.ndarray:
    """Squared row norms of the Gram operand into ``nrm (N,)``; with ``cast`` the operand ``Y``
    is first written as ``centred`` rounded to ``Y``'s dtype (float32) and the norms are those
    of the rounded rows (accumulated in float64), so that the Gram formula stays consistent;
    without, ``Y`` is ``centred`` itself."""
    centred = _arr(centred, "centred", 2, dtypes=(np.float64,))
    _shape("Y", _arr(Y, "Y", 2, writable=bool(cast)), centred.shape)
    _shape("nrm", _arr(nrm, "nrm", 1, writable=True), (centred.shape[0],))
    if not isinstance(cast, (bool, np.bool_)):
        raise InvalidInput(f"cast must be True or False, got {cast!r}")
    return _kernels.gram_rows(centred, Y, nrm, bool(cast))


def zext_rows(centred: np.ndarray, c: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """``Z = [c·z, c]``: the carrier operand of the pair-sum products (``Z (N, d+1)``, float64
    or float32; ``centred (N, d)`` the carrier, centred; ``c (N,)`` the coefficients)."""
    centred = _arr(centred, "centred", 2, dtypes=(np.float64,))
    _shape("c", _arr(c, "c", 1, dtypes=(np.float64,)), (centred.shape[0],))
    _shape("Z", _arr(Z, "Z", 2, writable=True), (centred.shape[0], centred.shape[1] + 1))
    return _kernels.zext_rows(centred, c, Z)


def pair_products(phi: np.ndarray, Z: np.ndarray, A: np.ndarray, i0: int, i1: int,
                  n: int) -> None:
    """Both orientations of a strip's pair sums, in place: the strip's rows
    ``A_I += Φ_I,[i0:] Z_[i0:]`` and, by symmetry, the columns beyond it
    ``A_[i1:] += Φ_I,[i1:]ᵀ Z_I`` (each unordered pair's kernel value used twice).

    ``phi (i1 − i0, n − i0)`` holds the strip's kernel values, ``Z (n, d+1)`` the carrier
    operand (:func:`zext_rows`), ``A (n, d+1)`` the accumulator, all of one dtype.
    """
    n, i0, i1 = as_int(n, "n", low=0), as_int(i0, "i0", low=0), as_int(i1, "i1", low=0)
    if not i0 <= i1 <= n:
        raise InvalidInput(f"the strip i0:i1 = {i0}:{i1} must lie in 0..n = {n}")
    _shape("phi", _arr(phi, "phi", 2), (i1 - i0, n - i0))
    Z = _arr(Z, "Z", 2)
    if Z.shape[0] != n:
        raise InvalidInput(f"Z must have n = {n} rows, got shape {Z.shape}")
    _shape("A", _arr(A, "A", 2, writable=True), Z.shape)
    if len({phi.dtype, Z.dtype, A.dtype}) != 1:
        raise InvalidInput(f"phi, Z and A must share one dtype, got {phi.dtype}, {Z.dtype}, "
                           f"{A.dtype}")
    _products(phi, Z, A, i0, i1, n)


def _products(phi: np.ndarray, Z: np.ndarray, A: np.ndarray, i0: int, i1: int, n: int):
    """:func:`pair_products` without the checks (the engine's strip loop)."""
    _parallel.gemm(1.0, phi, Z[i0:], 1.0, A[i0:i1])
    if i1 < n:
        _parallel.gemm(1.0, phi[:, i1 - i0:], Z[i0:i1], 1.0, A[i1:], trans_a=True)


def pair_finish(A: np.ndarray, centred: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out = A[:, :d] − A[:, d]·z`` in float64: the pair sums ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ``
    from the accumulator ``A (N, d+1)`` of :func:`pair_products` and the centred carrier
    ``centred (N, d)``."""
    centred = _arr(centred, "centred", 2, dtypes=(np.float64,))
    n, d = centred.shape
    _shape("A", _arr(A, "A", 2), (n, d + 1))
    _shape("out", _arr(out, "out", 2, dtypes=(np.float64,), writable=True), (n, d))
    return _kernels.pair_finish(A, centred, out)


def cs_halfint(Q: np.ndarray, G: float, n2: int, out: np.ndarray) -> np.ndarray:
    """The compiled form ``("cs_halfint", G, n2)`` on a block: the Cucker–Smale kernel
    ``G (1 + q)^(−n2/2)`` of squared distances ``Q (b, m)`` into ``out`` (``Q`` itself for the
    in-place kernel, which vectorizes), in ``out``'s dtype.

    Examples
    --------
    >>> cs_halfint(np.array([[0.0, 3.0]]), 2.0, 2, np.empty((1, 2)))
    array([[2. , 0.5]])
    """
    Q = _arr(Q, "Q", 2)
    _shape("out", _arr(out, "out", 2, writable=True), Q.shape)
    if Q.dtype != out.dtype:
        raise InvalidInput(f"Q and out must share one dtype, got {Q.dtype} and {out.dtype}")
    return _kernels.cs_halfint(Q, as_float(G, "G"), as_int(n2, "n2", low=0), out)


class CompiledBlocks(NamedTuple):
    """The engine's compiled pieces, for numba code of other packages (call them from compiled
    code only: they do not validate):

    * ``gemm(alpha, A, trans_a, B, trans_b, beta, C)``: ``C ← α op(A) op(B) + β C`` with
      numpy's BLAS (float64 or float32 by ``C``), where :data:`HAVE_COMPILED_FOR` says so;
    * ``sqdist_diff(YT, i0, i1, j0, out)``: the kernel of :func:`sqdist_rows`;
    * ``sqdist_gram_fix(G, ni, nj, Yi, Yj, tau, diag)``: the fix-up of :func:`sqdist_block`;
    * ``pow_row64(q, G, beta, scr)``: ``q ← G (1 + q)^(−β)`` in place on a float64 row.
    """

    gemm: object
    sqdist_diff: object
    sqdist_gram_fix: object
    pow_row64: object


def compiled_blocks() -> CompiledBlocks:
    """The compiled pieces of the strip walker, for compiled passes of other packages.

    Examples
    --------
    >>> compiled_blocks()._fields
    ('gemm', 'sqdist_diff', 'sqdist_gram_fix', 'pow_row64')
    """
    return CompiledBlocks(_kernels._nb_gemm, _kernels.sqdist_diff, _kernels.sqdist_gram_fix,
                          _kernels.pow_row64)
