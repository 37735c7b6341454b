r"""The NUFFT pair-sum backend: fast summation of smooth radial kernels, ``O(N + n^k log n)``.

For positions (or velocities) in ``k ≤ 3`` dimensions – projected systems, physical 2-D/3-D
swarms – every pair term ``Σⱼ cⱼ φ(|sᵢ − sⱼ|)(zⱼ − zᵢ)`` (the paper's class (1.1),
with ``f_ij = c_j φ``; the Cucker–Smale kernel of eq. (2.13) and the soft Morse kernel of eq. (3.14)) is
computed as ``Σⱼ cⱼ φᵢⱼ z̃ⱼ − (Σⱼ cⱼ φᵢⱼ) z̃ᵢ`` with the carrier ``z̃`` centred by its
``c``-weighted mean (so the error is relative to the *fluctuations* of the carrier: velocities
that have flocked to 1e-15 keep their relative accuracy), each of the ``d + 1`` sums
``Σⱼ αⱼ φ(|sᵢ − sⱼ|)`` by a type-1 NUFFT of the strengths, a multiplication by the Fourier coefficients
of a smoothly windowed periodic version of ``φ``, and a type-2 NUFFT
(``kinred.pairsum._fastsum``; Potts–Steidl–Nieslony fast summation, transforms by ``finufft``).
Memory ``O(N + n^k)``, never ``N × N``.

The box, the window and the number of modes follow the cloud's extents from the requested
``tol``; they are kept while the cloud still fits (a moving cloud reuses them, a growing one
gets a new grid with 25 % headroom, one that shrank 4× a smaller one).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from .._validate import as_float, as_int
from .. import _parallel
from ..errors import InvalidInput, TooLarge
from . import _cost, _fastsum, _nearfield
from ._base import PairTerms, check_plan_args
from .cells import near_sums

__all__ = ["NUFFT", "NUFFTPlan", "radial_profile"]

#: The largest state dimension finufft transforms (its 1-, 2- and 3-D NUFFTs).
MAX_DIM = 3


def radial_profile(kernel, effect=None):
    """The smooth radial profile of ``kernel`` (the kernel hook of :class:`NUFFT`).

    A kernel opts in by a method ``radial_profile()`` returning a vectorized callable
    ``φ(s)`` (ndarray of distances ``s ≥ 0`` of any shape → values of that shape) such that
    ``r ↦ φ(|r|)`` is smooth on ``ℝᵏ`` – i.e. ``φ`` extends to an even smooth function of
    ``s`` (a smooth function of ``s²``) – or None when it is not (``Morse`` with ``soft = 0``:
    ``u(s) ~ 1/s``). The faster its Fourier transform decays (the wider its strip of
    analyticity around the real axis), the fewer modes it needs. ``CuckerSmale``, ``Morse``
    with ``soft > 0`` and ``Quadratic`` implement it.

    Raises
    ------
    InvalidInput
        No such method, None returned, or not a callable; the message names the kernel (and
        the effect) and what is needed.

    Examples
    --------
    >>> from kinred.dynamics import CuckerSmale, Morse
    >>> float(radial_profile(CuckerSmale(2.0, 1.0))(np.array([1.0]))[0])
    1.0
    >>> radial_profile(Morse(soft=0.0))
    Traceback (most recent call last):
    ...
    kinred.errors.InvalidInput: the NUFFT backend needs a smooth radial profile ...
    """
    where = f"{kernel!r}" + ("" if effect is None else f" (in {effect!r})")
    need = ("the NUFFT backend needs a smooth radial profile for every pairwise kernel: a "
            "method radial_profile() returning a vectorized callable phi(s) with phi(|r|) "
            "smooth in r (phi an even smooth function of s); ")
    fn = getattr(kernel, "radial_profile", None)
    if fn is None or not callable(fn):
        raise InvalidInput(need + f"{where} has no radial_profile() method (add one if "
                           "phi(|r|) is smooth, or use the Dense backend)")
    prof = fn()
    if prof is None:
        raise InvalidInput(need + f"{where}.radial_profile() returned None: the kernel is "
                           "not smooth where agents coincide (e.g. Morse with soft = 0, "
                           "u(s) ~ 1/s; use soft > 0) – use the Dense backend for it")
    if not callable(prof):
        raise InvalidInput(need + f"{where}.radial_profile() returned {prof!r}, not a callable")
    return prof


def _summed(profiles: tuple):
    """``s ↦ Σ φ(s)`` over ``profiles`` (the profile itself when there is one)."""
    if len(profiles) == 1:
        return profiles[0]
    return lambda s: sum(np.asarray(p(s), dtype=np.float64) for p in profiles)


@dataclass(eq=False)
class _Group:
    """The terms sharing ``(source, carrier, target)``: one summed kernel, one grid, one plan
    (mutable: the grid and the finufft plan are rebuilt when the cloud outgrows them)."""

    source: str
    carrier: str
    target: str
    phi: object
    name: str
    kernels: tuple = ()      # the raw kernels (the near part of a split evaluates them)
    smooth: bool = True      # every kernel has a smooth radial profile
    grid: _fastsum.Grid | None = None
    split: object = None     # a _nearfield.Split when the group is split
    near_pairs: int = 0      # pairs summed exactly (last call)
    fast: _fastsum.FastSum | None = None
    builds: int = 0          # grids built (coefficient FFTs)
    plans: int = 0           # finufft plans made
    #: the accuracy scale κ of the next grid is ``kappa_scale ×`` the sampled one (lowered
    #: by the field check, :func:`_check_rows`), and the last check's result
    kappa_scale: float = 1.0
    checked: bool = False
    check: dict | None = None


@dataclass(eq=False)
class NUFFTPlan:
    """Everything :meth:`NUFFT.evaluate` needs for one scene and state shape, and the
    per-group caches (grids, finufft plans) it keeps between calls.

    Attributes
    ----------
    n, dim : int
    terms : PairTerms
    c : (n,) ndarray
        The coefficients ``c_j``.
    tol : float
    max_modes, nthreads : int
    near_field : bool or None
    groups : tuple of _Group
        One per ``(source, carrier, target)`` of the scene's terms.
    """

    n: int
    dim: int
    terms: PairTerms
    c: np.ndarray
    tol: float
    max_modes: int
    nthreads: int
    groups: tuple
    near_field: bool | None = None
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def info(self) -> list:
        """Per group: source, carrier, target, kernel, modes, periods, transition width,
        finufft ``ε``, the measured kernel error and the counts of grids and plans built."""
        out = []
        for g in self.groups:
            gr = g.grid
            out.append({"source": g.source, "carrier": g.carrier, "target": g.target,
                        "kernel": g.name, "builds": g.builds, "plans": g.plans,
                        "modes": None if gr is None else gr.modes,
                        "periods": None if gr is None else gr.periods.tolist(),
                        "width": None if gr is None else gr.width,
                        "eps": None if gr is None else gr.eps,
                        "kernel_error": None if gr is None else gr.error,
                        "near_radius": None if g.split is None else g.split.radius,
                        "near_pairs": g.near_pairs, "field_check": g.check})
        return out


class NUFFT:
    r"""Fast summation pair-sum backend (``pairsum="nufft"``): smooth radial kernels, ``k ≤ 3``.

    Cost per right-hand side ``O(N·(d + 1)·w^k + n^k log n)`` (``w`` ≈ finufft's kernel width,
    about ``log₁₀(1/ε) + 1``), memory ``O(N·d + n^k)``; the modes ``n^k`` depend on the cloud's
    extent measured in the kernel's length scale and on ``tol``, not on ``N``.

    Parameters
    ----------
    tol : float
        Requested relative accuracy of each pair-sum field, ``0 < tol < 1``: the kernel's
        truncation tail, finufft's ``ε`` and the window are set from it (see
        ``kinred.pairsum._fastsum``). Measured relative field error
        ``‖F_nufft − F_dense‖ / ‖F_dense‖`` on random clouds (N = 500 and 1000; k = 1, 2, 3;
        diameters 1e-6 to 10; Cucker–Smale β = 1.5 and soft Morse; weighted, far from the
        origin): below about ``0.2·tol`` for ``tol`` from 1e-2 to 1e-8, typically ``tol/10``
        to ``tol/100``; two agents (one pair) up to ``0.5·tol``; at ``tol = 1e-10`` the
        transforms' float64 round-off (about 1e-11) takes up to ``0.75·tol`` (table in
        docs/dynamics.md, section "Pair sums for large N"). The first sums of every grid are
        checked against the exact ones on sampled rows and the grid is rebuilt finer while
        they miss ``0.5·tol`` (tight clusters: ``_check_rows``), with a
        :class:`~kinred.errors.KinredWarning` if three finer grids do not reach it.
    near_field : bool or None
        The near-field split (``kinred.pairsum._nearfield``): the kernel regularized inside a
        near radius ``ε_I`` on a coarse grid, the rest summed exactly over the pairs closer
        than ``ε_I`` (a cell list). False (default): never (today's single grid; kernels
        need a smooth radial profile); True: always; None: when needed or cheaper – a
        kernel without a smooth profile (its cusp goes to the near part, e.g. Morse with
        ``soft = 0``), a single grid beyond ``max_modes``, or a split estimated cheaper than
        the single grid (``_nearfield.prefer_split``: a soft core narrow against the cloud
        and few enough near pairs; ``pairsum="auto"`` uses None). ``ε_I`` is chosen by a
        cost model of near pairs against modes; the error control is the grid's.
    max_modes : int
        Limit on the Fourier modes of one grid (default ``2**20``: ``1024²`` in 2-D, ``101³``
        in 3-D, a few hundred MB of transform arrays). A cloud that needs more (e.g. a 3-D
        cloud of diameter 1000 with a kernel of width 1) raises
        :class:`~kinred.errors.TooLarge` naming the numbers, before any large allocation.

    Notes
    -----
    Kernels need a smooth radial profile (:func:`radial_profile`); distances must live in
    ``k ≤ 3`` dimensions. Both are checked in :meth:`plan` (one
    :class:`~kinred.errors.InvalidInput` each). Terms with the same source, carrier and
    target are summed into one kernel first. The transforms use finufft with the engine's
    threads (:func:`~kinred.dynamics.set_num_threads`); a finufft plan is reused while the
    modes and ``ε`` are unchanged (points are set on every call). Deterministic: ``rng`` is
    ignored (the pair sample that sets the accuracy scale uses a fixed seed).

    Examples
    --------
    >>> from kinred.dynamics import Alignment, CuckerSmale, Scene
    >>> rng = np.random.default_rng(0)
    >>> x, v = rng.uniform(0, 1, (300, 2)), rng.normal(size=(300, 2))
    >>> cs = [Alignment(CuckerSmale(0.8, 1.5))]
    >>> fast = Scene(cs, pairsum=NUFFT(tol=1e-8)).rhs(x, v)[1]
    >>> exact = Scene(cs).rhs(x, v)[1]
    >>> bool(np.linalg.norm(fast - exact) <= 1e-8 * np.linalg.norm(exact))
    True
    """

    #: Transforms run in float64.
    precision = "double"

    #: The pair sums are approximate (relative accuracy ``tol``): certificates refuse it.
    exact = False

    def __init__(self, tol: float = 1e-6, max_modes: int = _fastsum.MAX_MODES,
                 near_field: bool | None = False):
        self.tol = as_float(tol, "tol", low=0.0, high=1.0, low_open=True, high_open=True)
        self.max_modes = as_int(max_modes, "max_modes", low=1)
        if near_field not in (None, True, False):
            raise InvalidInput(f"near_field must be None (when needed), True or False, got "
                               f"{near_field!r}")
        self.near_field = near_field

    def __repr__(self) -> str:
        extra = "" if self.max_modes == _fastsum.MAX_MODES else f", max_modes={self.max_modes!r}"
        if self.near_field is not False:
            extra += f", near_field={self.near_field!r}"
        return f"NUFFT(tol={self.tol!r}{extra})"

    # ------------------------------------------------------------------ plan
    def plan(self, scene, n: int, dim: int) -> NUFFTPlan:
        """The plan of ``scene`` for states ``(n, dim)`` (see :class:`~kinred.pairsum.PairSum`).

        Raises
        ------
        InvalidInput
            ``dim > 3``, or a pairwise kernel without a smooth radial profile.
        """
        terms, n, dim = check_plan_args(scene, n, dim)
        if dim > MAX_DIM:
            raise InvalidInput(
                f"the NUFFT backend sums kernels of distances in k <= {MAX_DIM} dimensions "
                f"(finufft's 1-, 2- and 3-D transforms); the state has dim = {dim}: project "
                "the scene first (Scene.project to k <= 3) or use the Dense backend")
        keys, profiles, names, kernels, smooth = [], {}, {}, {}, {}
        for t in terms.terms:
            key = (t.source, t.carrier, t.target)
            if key not in profiles:
                keys.append(key)
                profiles[key], names[key], kernels[key], smooth[key] = [], [], [], True
            try:
                profiles[key].append(radial_profile(t.kernel, t.effect))
            except InvalidInput:
                if self.near_field is False:
                    raise
                profiles[key].append(t.kernel)     # its cusp goes to the near part
                smooth[key] = False
            names[key].append(repr(t.kernel))
            kernels[key].append(t.kernel)
        groups = tuple(_Group(*key, phi=_summed(tuple(profiles[key])),
                              name=" + ".join(names[key]), kernels=tuple(kernels[key]),
                              smooth=smooth[key]) for key in keys)
        return NUFFTPlan(n=n, dim=dim, terms=terms, c=scene.coefficients(n), tol=self.tol,
                         max_modes=self.max_modes, nthreads=_parallel.get_num_threads(),
                         groups=groups, near_field=self.near_field)

    # ------------------------------------------------------------------ evaluate
    def evaluate(self, plan: NUFFTPlan, x: np.ndarray, v: np.ndarray | None, rng=None) -> dict:
        """``{target: (n, dim) ndarray}``, summed over the plan's terms (fresh arrays; ``rng``
        is ignored).

        Raises
        ------
        TooLarge
            The cloud is too spread for ``max_modes`` at this ``tol``.
        """
        if not isinstance(plan, NUFFTPlan) or x.shape != (plan.n, plan.dim):
            raise InvalidInput(f"plan must be a NUFFTPlan for states of shape (n, dim) = "
                               f"{getattr(plan, 'n', '?'), getattr(plan, 'dim', '?')}; got "
                               f"{type(plan).__name__} and x of shape {x.shape}")
        state = {"x": x, "v": v}
        carriers = {}
        out = {}
        with plan.lock:
            for g in plan.groups:
                if g.carrier not in carriers:
                    carriers[g.carrier] = _strengths(state[g.carrier], plan.c)
                contrib = _group_sum(plan, g, state[g.source], *carriers[g.carrier])
                if g.target in out:
                    out[g.target] += contrib
                else:
                    out[g.target] = contrib
        return out


def _strengths(z: np.ndarray, c: np.ndarray) -> tuple:
    """The centred carrier ``z̃ = z − Σcz/Σc`` (compensated) and the strengths
    ``α = [c z̃₁, …, c z̃_d, c]`` packed two per complex vector: ``(z̃, (⌈(d+1)/2⌉, n))``."""
    n, d = z.shape
    csum = float(c.sum())
    m1 = (c @ z) / csum
    zt = z - m1
    zt -= (c @ zt) / csum
    alpha = np.empty((d + 1, n))
    np.multiply(zt.T, c, out=alpha[:d])
    alpha[d] = c
    packed = np.zeros(((d + 2) // 2, n), dtype=np.complex128)
    packed.real = alpha[0::2]
    packed.imag[: (d + 1) // 2] = alpha[1::2]
    return zt, packed


def ensure_grid(plan: NUFFTPlan, g: _Group, s: np.ndarray, lo=None, hi=None, z=None):
    """The group's grid for the cloud ``s`` (kept while the cloud fits it, else built; ``z``
    the carrier, for the accuracy scale of ``_fastsum.kernel_scales``):
    a :class:`_fastsum.Grid`, None when the kernel vanishes on every difference, or
    ``"nan"`` for a non-finite cloud.

    Raises
    ------
    TooLarge
        The cloud needs more than ``plan.max_modes`` modes at ``plan.tol``.
    """
    lo = s.min(axis=0) if lo is None else lo
    hi = s.max(axis=0) if hi is None else hi
    ext = hi - lo
    if not np.all(np.isfinite(ext)):
        return "nan"
    grid = g.grid
    if grid is None or not grid.fits(ext):
        kinf, kappa = _fastsum.kernel_scales(g.phi, s, ext, g.name, z)
        if kinf == 0.0:                      # the kernel vanishes on every difference
            return None
        # the field check's scale (below the floor of kernel_scales if it must)
        scale = g.kappa_scale
        split = plan.near_field is True or not g.smooth or (
            plan.near_field is None and _nearfield.prefer_split(
                g.phi, g.kernels, s, ext, plan.tol, kinf, kappa, plan.max_modes, g.name,
                plan.dim, scale))
        if not split:
            try:
                grid = _fastsum.build_grid(g.phi, ext, plan.tol, kinf, kappa * scale,
                                           plan.max_modes, g.name)
                g.split = None
            except TooLarge:
                if plan.near_field is False:
                    raise
                split = True
        if split:
            g.split = _nearfield.split(g.phi, g.kernels, s, ext, plan.tol, kappa,
                                       plan.max_modes, g.name, plan.dim, scale)
            grid = g.split.grid
        g.grid, g.builds, g.checked = grid, g.builds + 1, False
    return grid



def group_estimate(plan: NUFFTPlan, g: _Group, s: np.ndarray, z=None) -> float:
    """Estimated seconds of one group's sums on the cloud ``s`` without building a grid
    (milliseconds: the 1-D slices of the single grid, the near-field ladder's closed forms),
    the cheaper of what :func:`ensure_grid` may build; ``inf`` when neither fits."""
    ext = np.ptp(s, axis=0)
    if not np.all(np.isfinite(ext)):
        return 0.0
    kinf, kappa = _fastsum.kernel_scales(g.phi, s, ext, g.name, z)
    if kinf == 0.0:
        return 0.0
    n, k = s.shape
    best = math.inf
    if g.smooth and plan.near_field is not True:
        modes = _fastsum.estimate_modes(g.phi, ext, plan.tol, kinf, kappa, plan.max_modes,
                                        g.name)
        if modes is not None:
            best = _cost.nufft_seconds(n, plan.dim, modes,
                                       _fastsum.finufft_eps(plan.tol, kappa, kinf), k)
    if plan.near_field is not False or not g.smooth:
        best = min(best, _nearfield.estimate(g.phi, g.kernels, s, ext, plan.tol, kappa,
                                             plan.max_modes, g.name, plan.dim))
    return best


def _group_sum(plan: NUFFTPlan, g: _Group, s: np.ndarray, zt: np.ndarray,
               strengths: np.ndarray) -> np.ndarray:
    """``Σⱼ cⱼ φᵢⱼ z̃ⱼ − (Σⱼ cⱼ φᵢⱼ) z̃ᵢ`` of one group, ``(n, d)``, fresh; a new grid's first
    sums are checked against the exact ones on sampled rows (:func:`_check_rows`) and the
    grid rebuilt finer (at most :data:`CHECK_REBUILDS` times) while they miss."""
    for _ in range(CHECK_REBUILDS + 1):
        out = _group_sum_once(plan, g, s, zt, strengths)
        if g.checked or g.grid is None or not np.all(np.isfinite(out)):
            return out                       # (a diverging state: the integrator's guard)
        if _check_rows(plan, g, s, zt, out):
            return out
        keep = (g.grid, g.split, g.kappa_scale)
        g.kappa_scale *= min(0.5, CHECK_FACTOR * 0.5 * plan.tol / g.check["error"])
        g.grid = None
        try:
            ensure_grid(plan, g, s, z=zt)
        except TooLarge:                     # finer exceeds max_modes: keep the best one
            g.grid, g.split, g.kappa_scale = keep
            g.checked = True
            _warn_check(plan, g)
            return out
    g.checked = True
    _warn_check(plan, g)
    return out


def _group_sum_once(plan: NUFFTPlan, g: _Group, s: np.ndarray, zt: np.ndarray,
                    strengths: np.ndarray) -> np.ndarray:
    """One evaluation of :func:`_group_sum` on the group's current grid (built if needed)."""
    n, d = zt.shape
    lo, hi = s.min(axis=0), s.max(axis=0)
    grid = ensure_grid(plan, g, s, lo, hi, zt)
    if grid is None or isinstance(grid, str):
        # a diverging state (let the integrator's guard see it), or a vanishing kernel
        return np.full((n, d), np.nan) if grid == "nan" else np.zeros((n, d))
    if g.fast is None or not g.fast.matches(grid, n):
        g.fast = None                        # release the old plan's memory first
        g.fast = _fastsum.FastSum(grid, n, strengths.shape[0], plan.nthreads)
        g.plans += 1
    centre = 0.5 * (lo + hi)
    A = None
    if g.split is None:
        F = g.fast.apply(grid, s, centre, strengths)
    else:                                    # the near part, pair by pair
        zext = np.empty((n, d + 1))
        np.multiply(zt, plan.c[:, None], out=zext[:, :d])
        zext[:, d] = plan.c
        A = np.zeros((n, d + 1))
        got = []
        share = overlap_share(g.split, plan.nthreads, g.fast.nthreads)
        if share is None:
            got.append(g.fast.apply(grid, s, centre, strengths))
        g.near_pairs = near_sums(
            np.ascontiguousarray(s, dtype=np.float64), g.split.radius,
            [(g.split.near, zext, A)], side_share=share,
            side=None if share is None else lambda: got.append(
                g.fast.apply(grid, s, centre, strengths)))
        F = got[0]
    sums = np.empty((d + 1, n))
    sums[0::2] = F.real[: (d + 2) // 2]
    sums[1::2] = F.imag[: (d + 1) // 2]
    if A is not None:
        sums += A.T
    return sums[:d].T - sums[d][:, None] * zt


#: A new grid's sums are checked on sampled rows: relative error at most ``CHECK_FACTOR·tol``.
CHECK_FACTOR = 0.5
#: Rebuilds (each with ``κ`` scaled down by the miss) before the check gives up, with a
#: warning.
CHECK_REBUILDS = 3
#: Rows of the check: all of a small cloud, else ``CHECK_PAIRS/N`` (at least ``CHECK_ROWS``)
#: drawn with a fixed seed.
CHECK_ROWS = 8
CHECK_PAIRS = 1 << 21
_CHECK_SEED = 0xC4EC


def _check_rows(plan: NUFFTPlan, g: _Group, s: np.ndarray, zt: np.ndarray,
                out: np.ndarray) -> bool:
    """Whether the group's sums ``out`` are within ``CHECK_FACTOR·tol`` (relative, over the
    sampled rows) of the exact ``Σⱼ cⱼ φᵢⱼ (z̃ⱼ − z̃ᵢ)`` – the raw kernels summed directly,
    ``O(rows · N)``; records ``g.check``. The grid's accuracy scale ``κ`` is the mean of
    ``|φ|`` over random pairs: it sets a kernel error per value, and whether that error is a
    relative ``tol`` of the *field* depends on the cloud – on a ring it averages out (field
    error ``10⁻³·tol``), in tight clusters all pairs of two clusters share one distance and
    one error while the close pairs that set ``κ`` carry no carrier difference (five
    clusters in 2-D, Morse ``soft = 0.5``, ``tol = 1e-7``: ``5·tol``, found by a sweep of
    random clouds against Dense). So the first sums of each grid are measured, and ``κ``
    lowered where they miss."""
    from .cells import kernel_values

    n = s.shape[0]
    rows = _fastsum.sample_rows(n, CHECK_ROWS, CHECK_PAIRS, _CHECK_SEED)
    vals = [kernel_values(k) for k in g.kernels]
    exact = np.zeros((rows.size, zt.shape[1]))
    for a, e, q in _fastsum.row_blocks(s, rows):
        phi = vals[0](q.ravel())
        for v in vals[1:]:
            phi = phi + v(q.ravel())
        phi = phi.reshape(q.shape)
        phi[~np.isfinite(phi)] = 0.0         # a cusp on coincident agents (no carrier gap)
        self_ = (rows[:, None] == np.arange(a, e)[None, :])
        phi[self_] = 0.0
        cp = phi * plan.c[None, a:e]
        exact += cp @ zt[a:e] - cp.sum(axis=1)[:, None] * zt[rows]
    ref = float(np.linalg.norm(exact))
    err = float(np.linalg.norm(out[rows] - exact))
    # the transforms' own floor: finufft's ε relative to the strengths and the kernel's sup
    # (a field that cancels to round-off, e.g. coincident agents, says nothing about tol)
    ca = np.abs(plan.c)
    mag = float(ca @ np.sqrt(np.sum(zt * zt, axis=1))) + float(ca.sum()) * np.sqrt(
        np.sum(zt[rows] ** 2, axis=1))
    floor = (g.grid.eps + 64 * np.finfo(np.float64).eps) * g.grid.kinf * float(
        np.linalg.norm(mag))
    g.check = {"rows": int(rows.size), "error": err / ref if ref > 0 else 0.0,
               "kappa_scale": g.kappa_scale, "below_floor": bool(ref <= 10.0 * floor)}
    g.checked = ref <= 10.0 * floor or err <= CHECK_FACTOR * plan.tol * ref
    return g.checked


def _warn_check(plan: NUFFTPlan, g: _Group) -> None:
    import warnings

    from ..errors import KinredWarning

    warnings.warn(f"NUFFT: the pair sums of {g.name} miss the requested tol={plan.tol:g} on "
                  f"{g.check['rows']} sampled rows (relative error {g.check['error']:.2g}) "
                  f"after {CHECK_REBUILDS} finer grids (or max_modes={plan.max_modes}); "
                  "raise max_modes or use Dense/CellList", KinredWarning, stacklevel=4)


def overlap_share(split, nthreads: int, fft_threads: int) -> float | None:
    """The fraction of the near pairs the calling thread sums after running the transforms
    while the other threads sum the rest (None: no overlap – one engine thread, or finufft
    already on several threads). Balances the estimates (``split.grid_seconds`` of the
    transforms, ``split.near_seconds`` of the pairs, one thread each):
    ``G + x·P = (1 − x)·P/(T − 1)``, clipped to ``[0, 1/T]``."""
    if nthreads < 2 or fft_threads > 1:
        return None
    P, G = split.near_seconds, split.grid_seconds
    if not P > 0:
        return 0.0
    return min(max((P - (nthreads - 1) * G) / (nthreads * P), 0.0), 1.0 / nthreads)
