"""Delayed-curse budgets: integer atoms per coordinate for a tensor-product quantization."""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from .._validate import as_array, as_choice, as_float, as_int
from ..errors import InvalidInput
from ._size import fmt_count
from ._trades import _UNIT_STEP, _pairs, _ratio, _trades_atoms, _trades_eps  # noqa: F401

__all__ = ["Budget", "Recipe", "budget", "paper_recipe", "RULE_CONSTANT"]

#: Per-coordinate error constant: a 1-D quantization with ``n`` atoms of a law of width ``σ``
#: has W1 error ≤ ``c σ / n`` (midpoint levels: c = 1/2; the paper's levels i/N, eq. (4.21): c = 1).
RULE_CONSTANT = {"midpoint": 0.5, "paper": 1.0}

_TOL = 1e-12
#: Largest ``d · Σ c σⱼ / ε`` the floating-point search accepts (every N_j stays below it).
_MAX_SCALE = 1e305
#: Suffixes up to this many coordinates are scanned by the relaxations; longer ones are bisected.
_SCAN = 32


def _ceil_ratio(x: float, y: Fraction) -> int:
    """``max(1, ⌈x / y⌉)`` in exact arithmetic, for any float ``x`` and rational ``y > 0``."""
    return max(1, math.ceil(Fraction(x) / y))


@dataclass(frozen=True, eq=False)
class Recipe:
    """The paper's simple recipe of §4.5 for eq. (4.22).

    With ``σ`` sorted decreasingly, ``k_bar`` is the smallest k̄ with
    :math:`\\sum_{k>\\bar k} c\\sigma_k \\le \\varepsilon/2`, and a common
    :math:`\\mathcal N = \\lceil 2\\sum_{k\\le\\bar k} c\\sigma_k/\\varepsilon\\rceil` is used on
    those k̄ coordinates, so :math:`N = \\mathcal N^{\\bar k}` (one atom if k̄ = 0).
    """

    eps: float
    k_bar: int
    n_common: int
    n_atoms: int
    bound: float

    def __repr__(self) -> str:
        return (f"Recipe(eps={self.eps!r}, k_bar={self.k_bar}, n_common={fmt_count(self.n_common)}, "
                f"n_atoms={fmt_count(self.n_atoms)}, bound={self.bound!r})")


@dataclass(frozen=True, eq=False)
class Budget:
    """Atoms per coordinate ``N_j`` for a tensor product, with the bound they guarantee.

    Attributes
    ----------
    widths : (d,) ndarray -- the σⱼ, in the caller's order
    counts : tuple of int -- ``N_j`` per coordinate (same order)
    n_atoms : int -- ``N = ∏ N_j`` (exact Python int)
    bound : float -- ``Σ c σⱼ / N_j``
    k_bar : int -- number of coordinates with ``N_j > 1``
    rule : str, c : float -- quantization rule and its constant (:data:`RULE_CONSTANT`)
    eps, atoms : the target that was given (the other is None)
    optimal : bool -- True when the branch and bound proved optimality
    lower_bound : float -- certified lower bound from the continuous relaxation: on the optimal
        atom count (eps mode) or on the optimal bound (atoms mode)
    recipe : Recipe -- the paper's recipe at the same ε (atoms mode: at ε = the bound reached)
    nodes : int -- branch-and-bound nodes visited
    """

    widths: np.ndarray
    counts: tuple
    n_atoms: int
    bound: float
    k_bar: int
    rule: str
    c: float
    eps: float | None
    atoms: int | None
    optimal: bool
    lower_bound: float
    recipe: Recipe
    nodes: int

    def __repr__(self) -> str:
        """One short line whatever ``d`` and ``N``: the target, ``N`` (exact up to 15 digits,
        else in scientific notation from its digits), the bound, ``k̄``, and the first and
        last widths and counts around an ellipsis."""
        target = f"eps={self.eps:.6g}" if self.eps is not None else f"atoms={fmt_count(self.atoms)}"
        return (f"Budget(d={len(self.counts)}, {target}, rule={self.rule!r}, "
                f"n_atoms={fmt_count(self.n_atoms)}, bound={self.bound:.6g}, k_bar={self.k_bar}, "
                f"counts={_ends(self.counts, str)}, widths={_ends(self.widths, '{:.3g}'.format)}, "
                f"optimal={self.optimal})")


def _ends(values, fmt, head: int = 4, tail: int = 2) -> str:
    """``(v0, v1, v2, v3, …, v[-2], v[-1])``, or every value when there are at most 8."""
    if len(values) <= head + tail + 2:
        parts = [fmt(v) for v in values]
    else:
        parts = [fmt(v) for v in values[:head]] + ["…"] + [fmt(v) for v in values[-tail:]]
    return "(" + ", ".join(parts) + ")"


def paper_recipe(widths, eps: float, *, rule: str = "midpoint") -> Recipe:
    """The paper's recipe for eq. (4.22); see :class:`Recipe`.

    Examples
    --------
    >>> r = paper_recipe([1.0, 0.5, 0.01], 0.5, rule="paper")
    >>> r.k_bar, r.n_common, r.n_atoms
    (2, 6, 36)
    """
    widths = _widths(widths)
    eps = as_float(eps, "eps", low=0.0, low_open=True)
    rule = as_choice(rule, "rule", RULE_CONSTANT)
    c = RULE_CONSTANT[rule]
    s = np.sort(c * widths)[::-1]
    tail = np.concatenate([np.cumsum(s[::-1])[::-1], [0.0]])  # tail[k] = Σ_{i>=k} s_i
    k_bar = int(np.argmax(tail <= eps / 2 * (1 + _TOL)))
    if k_bar == 0:
        return Recipe(eps, 0, 1, 1, float(tail[0]))
    head = float(s[:k_bar].sum())
    n = _ceil_ratio(head, Fraction(eps) / 2 * Fraction(1 + _TOL))  # exact for any ε
    return Recipe(eps, k_bar, n, n**k_bar, _ratio(head, n) + float(tail[k_bar]))


def _check_scale(s: np.ndarray, eps: float) -> None:
    """Refuse an ε so small that the counts leave the float range of the search (N_j ≤ d Σ s / ε)."""
    total = float(s.sum()) * s.size
    if total / eps > _MAX_SCALE:
        raise InvalidInput(
            f"eps={eps!r} is too small for these widths: counts per coordinate could reach "
            f"{s.size} × {float(s.sum()):.6g} / eps = {total / eps:.3g}, beyond the floating-point "
            f"range of the budget search ({_MAX_SCALE:.0e}); eps must be >= {total / _MAX_SCALE:.3g}"
        )


def _check_atoms_scale(s: np.ndarray, atoms: int, nu: float) -> None:
    """Refuse an atom budget whose relaxed count of the widest coordinate, s₀/ν, leaves the float range."""
    if nu == 0 or float(s[0]) / nu > _MAX_SCALE:
        raise InvalidInput(
            f"atoms={fmt_count(atoms)} is too large for {s.size} coordinate(s) of these widths: the "
            f"widest coordinate alone would get more than {_MAX_SCALE:.0e} atoms, beyond the "
            "floating-point range of the budget search; ask for fewer atoms"
        )


def _widths(widths) -> np.ndarray:
    w = as_array(widths, "widths", ndim=1)
    if w.size < 1:
        raise InvalidInput("widths must hold at least one width, got an empty array")
    if np.any(w < 0):
        i = int(np.argmin(w))
        raise InvalidInput(f"widths must be >= 0, got {w[i]} at index {i}")
    return w


class _Abort(Exception):
    pass


class _Solver:
    """Branch and bound over non-increasing integer vectors for decreasing s > 0.

    The search is depth-first with an explicit stack (one frame per coordinate: a scene of
    d = 10⁴ coordinates is 10⁴ levels deep, far beyond Python's recursion limit), and the
    relaxation of a suffix finds its active set by bisection (:meth:`cont_eps`,
    :meth:`cont_atoms`), so one level costs O(log d) instead of O(d).
    """

    def __init__(self, s: np.ndarray, node_limit: int):
        # Python floats: the search is scalar code, and numpy scalars cost several times more
        self.s = s.tolist()
        self.d = s.size
        self.T = np.concatenate([np.cumsum(s[::-1])[::-1], [0.0]]).tolist()
        self.L = np.concatenate([[0.0], np.cumsum(np.log(s))]).tolist()
        self.logs = np.log(s).tolist()
        self.nodes = 0
        self.node_limit = node_limit

    def _tick(self):
        self.nodes += 1
        if self.nodes > self.node_limit:
            raise _Abort

    def _first(self, n: int, cond, crossed) -> int | None:
        """First ``m`` in 1..n with ``cond(m)``, as the scan ``for m in range(1, n + 1)`` finds it.

        Suffixes of at most :data:`_SCAN` coordinates are scanned. Longer ones bisect the
        monotone ``crossed(m)`` (the m-th coordinate of the suffix is inactive at the optimum:
        exactly where ``cond`` holds, up to rounding), then test ``cond`` on a few ``m``
        around the crossing; the full scan is the fallback if none holds there.
        """
        if n > _SCAN:
            lo, hi = 1, n + 1  # crossed(n + 1) is True by convention
            while lo < hi:
                mid = (lo + hi) // 2
                if crossed(mid):
                    hi = mid
                else:
                    lo = mid + 1
            m0 = lo - 1  # last active coordinate
            window = range(max(1, m0 - 2), min(n, m0 + 2) + 1)
            hit = next((m for m in window if cond(m)), None)
            if hit is not None and not any(cond(m) for m in range(max(1, hit - 4), hit)):
                return hit
        return next((m for m in range(1, n + 1) if cond(m)), None)

    # ---- eps mode: min Σ log N s.t. Σ s/N ≤ e --------------------------------------------
    def cont_eps(self, j: int, e: float) -> tuple[float, float]:
        """Continuous relaxation on suffix j: (min Σ log N_i, multiplier μ); N_i = max(1, μ s_i).

        Coordinate ``j + m − 1`` is active iff ``H = (m − 1) s_{j+m−1} + T_{j+m−1} > e`` (H is
        non-increasing in m), and μ = m / (e − T_{j+m}) for the m active ones.
        """
        T, s, d = self.T, self.s, self.d
        if T[j] <= e * (1 + _TOL):
            return 0.0, 0.0
        if e <= 0:
            return math.inf, math.inf

        def cond(m):
            rest = e - T[j + m]
            if rest <= 0:
                return False
            mu = m / rest
            return mu * s[j + m - 1] >= 1 - 1e-12 and (j + m == d or mu * s[j + m] <= 1 + 1e-12)

        def crossed(m):
            return m > d - j or (m - 1) * s[j + m - 1] + T[j + m - 1] <= e

        m = self._first(d - j, cond, crossed)
        if m is None:
            return 0.0, 0.0  # numerical corner: trivial (valid) lower bound
        mu = m / (e - T[j + m])
        return m * math.log(mu) + (self.L[j + m] - self.L[j]), mu

    def solve_eps(self, eps: float, incumbent: list[int]) -> tuple[list[int], bool]:
        self.best = list(incumbent)
        self.best_P = math.prod(incumbent)
        try:
            path, stack = [], []
            self._node_eps(stack, path, 0, eps, None, 1)
            while stack:
                j, e, prod, cands = stack[-1]
                if not cands:
                    stack.pop()
                    continue
                v, n = cands.pop()  # cands are sorted decreasingly: the most promising first
                if v > math.log(self.best_P - 1) + 1e-9:
                    continue
                del path[j:]
                path.append(n)
                self._node_eps(stack, path, j + 1, e - self.s[j] / n, n, prod * n)
            return self.best, True
        except _Abort:
            return self.best, False

    def _node_eps(self, stack, path, j, e, cap, prod):
        """Visit node (j, e): record a leaf, or push its children (n, lower bound) for the search."""
        self._tick()
        s, T = self.s, self.T
        if T[j] <= e * (1 + _TOL):
            if prod < self.best_P:
                self.best_P, self.best = prod, path[:j] + [1] * (self.d - j)
            return
        if j == self.d:
            return
        if self.best_P - 1 < prod * 2:
            return
        thresh = math.log(self.best_P - 1) + 1e-9
        lo = max(2, _ceil_ratio(T[j], Fraction(e) * Fraction(1 + _TOL)))  # N_j ≥ T_j / e (exact)
        if cap is None:
            hi = (self.best_P - 1) // prod
        else:  # min(cap, (best_P − 1) // prod) without dividing two huge integers
            hi = cap if prod * cap <= self.best_P - 1 else (self.best_P - 1) // prod
        if lo > hi:
            return
        _, mu = self.cont_eps(j, e)
        start = min(max(int(mu * s[j]), lo), hi)
        lp = math.log(prod)

        def f(n):
            e2 = e - s[j] / n
            if e2 < -1e-15:
                return math.inf
            self._tick()
            return lp + math.log(n) + self.cont_eps(j + 1, max(e2, 0.0))[0]

        cands = _scan(f, start, lo, hi, lambda v: v > thresh)
        stack.append((j, e, prod, sorted(cands, reverse=True)))

    # ---- atoms mode: min Σ s/N s.t. Π N ≤ P ------------------------------------------------
    def cont_atoms(self, j: int, logR: float) -> tuple[float, float]:
        """Continuous relaxation on suffix j with product ≤ e^logR: (min Σ s_i/N_i, ν), N_i = max(1, s_i/ν).

        Coordinate ``k = j + m − 1`` is active iff ``Σ_{j≤i≤k} log(s_i / s_k) < logR`` (non-decreasing
        in m), and log ν = (Σ_{i<j+m} log s_i − logR) / m for the m active ones.
        """
        T, s, d, L = self.T, self.s, self.d, self.L
        if j >= d:
            return 0.0, math.inf
        if logR <= 1e-15:
            return float(T[j]), math.inf

        def cond(m):
            nu = math.exp((L[j + m] - L[j] - logR) / m)
            return s[j + m - 1] >= nu * (1 - 1e-12) and (j + m == d or s[j + m] <= nu * (1 + 1e-12))

        def crossed(m):
            return m > d - j or L[j + m] - L[j] - m * self.logs[j + m - 1] >= logR

        m = self._first(d - j, cond, crossed)
        if m is None:
            return 0.0, math.inf
        nu = math.exp((L[j + m] - L[j] - logR) / m)
        return m * nu + float(T[j + m]), nu

    def solve_atoms(self, P: int, incumbent: list[int]) -> tuple[list[int], bool]:
        self.best = list(incumbent)
        self.best_v = self.value(incumbent)
        try:
            path, stack = [], []
            self._node_atoms(stack, path, 0, P, None, 0.0)
            while stack:
                j, R, cur, cands = stack[-1]
                if not cands:
                    stack.pop()
                    continue
                v, n = cands.pop()
                if v >= self.best_v * (1 - 1e-13):
                    continue
                del path[j:]
                path.append(n)
                self._node_atoms(stack, path, j + 1, R // n, n, cur + _ratio(self.s[j], n))
            return self.best, True
        except _Abort:
            return self.best, False

    def value(self, N) -> float:
        return float(sum(_ratio(si, ni) for si, ni in zip(self.s, N)))

    def _node_atoms(self, stack, path, j, R, cap, cur):
        """Visit node (j, R): record a leaf, or push its children (n, lower bound) for the search."""
        self._tick()
        s, T = self.s, self.T
        if j == self.d or R == 1 or cap == 1:
            v = cur + float(T[j])
            if v < self.best_v * (1 - 1e-13):
                self.best_v, self.best = v, path[:j] + [1] * (self.d - j)
            return
        thresh = self.best_v * (1 - 1e-13)
        hi = R if cap is None else min(cap, R)
        if j == self.d - 1:
            v = cur + _ratio(s[j], hi)
            if v < thresh:
                self.best_v, self.best = v, path[:j] + [hi]
            return
        logR = math.log(R)
        _, nu = self.cont_atoms(j, logR)
        x = float(s[j]) / nu if 0 < nu < math.inf else 1.0  # a Python float: compares with any int
        start = hi if x >= hi else min(max(int(x), 1), hi)

        def f(n):
            self._tick()
            rest = self.cont_atoms(j + 1, logR - math.log(n))[0]
            return cur + _ratio(s[j], n) + max(rest, _ratio(float(T[j + 1]), n))

        cands = _scan(f, start, 1, hi, lambda v: v >= thresh)
        stack.append((j, R, cur, sorted(cands, reverse=True)))


def _scan(f, start, lo, hi, stop):
    """``(f(n), n)`` for n = start, start − 1, … ≥ lo, then start + 1, … ≤ hi, each run ending
    at the first n with ``stop(f(n))``."""
    cands = []
    n = start
    while n >= lo:
        v = f(n)
        if stop(v):
            break
        cands.append((v, n))
        n -= 1
    n = start + 1
    while n <= hi:
        v = f(n)
        if stop(v):
            break
        cands.append((v, n))
        n += 1
    return cands


def _local_eps(s, N, eps, max_moves):
    """Local improvement: lower each N_j as far as the bound allows, then trade (N_i−1, N_j+1).

    Lowering is in closed form (one step per coordinate, whatever the size of N_j); unit trades
    are tried only where N_j ≤ 2**30 (a float sum resolves them) and at most ``max_moves``
    times, so the cost does not grow with the counts.
    """
    lim = eps * (1 + _TOL)
    N = list(N)
    moves = 0
    changed = True
    while changed:
        changed = False
        tot = math.fsum(si / ni for si, ni in zip(s, N))
        for j in sorted(range(len(N)), key=lambda i: N[i]):
            room = lim - (tot - s[j] / N[j])  # what coordinate j may spend
            if N[j] > 1 and room > s[j] / N[j]:
                n = min(N[j], _ceil_ratio(s[j], Fraction(room)))  # least n with s_j/n ≤ room
                if n < N[j]:
                    tot, N[j] = tot - s[j] / N[j] + s[j] / n, n
                    changed = True
        tot, moves, traded = _trades_eps(s, N, tot, lim, moves, max_moves)
        changed = changed or traded
    return N


def _round_eps(s, eps, mu):
    """Smallest scaling t ≤ 1 of the continuous solution whose ceiling is still feasible."""
    if not 0 < mu < math.inf:  # numerical corner of the relaxation: μ = d/ε is always feasible
        mu = len(s) / eps

    def vec(t):
        return [max(1, math.ceil(t * mu * si - 1e-9)) for si in s]

    def ok(N):
        return sum(si / ni for si, ni in zip(s, N)) <= eps * (1 + _TOL)

    t_hi = 1.0
    while not ok(vec(t_hi)):
        t_hi *= 1.5
    t_lo = 0.0
    for _ in range(60):
        t = 0.5 * (t_lo + t_hi)
        if ok(vec(t)):
            t_hi = t
        else:
            t_lo = t
    return vec(t_hi)


def _floor_atoms(s, P, nu):
    """Round the continuous optimum ``N_j = max(1, s_j/ν)`` down (feasible: ∏ ≤ P)."""
    N = []
    for sj in s:
        x = math.inf if nu == 0 else float(sj) / nu * (1 + 1e-12) if nu < math.inf else 1.0
        N.append(P if x >= P else max(1, int(x)))
    prod = math.prod(N)
    while prod > P:  # the tolerance rounded up: lower the largest N_j just enough
        j = max(range(len(N)), key=lambda i: N[i])
        rest = prod // N[j]
        N[j] = max(1, P // rest)
        prod = rest * N[j]
    return N


def _local_atoms(s, N, P, max_moves):
    """Local improvement: raise N_j while ∏ ≤ P, then trade pairs (at most ``max_moves``)."""
    N = list(N)
    moves = 0
    changed = True
    while changed:
        changed = False
        prod = math.prod(N)
        for j in range(len(N)):  # add atoms while the product allows
            if prod // N[j] * (N[j] + 1) <= P:
                N2 = P // (prod // N[j])  # raise N_j as far as the product allows
                prod = prod // N[j] * N2
                N[j] = N2
                changed = True
            if N[j] == 1:
                break
        prod, moves, traded = _trades_atoms(s, N, P, prod, moves, max_moves)
        changed = changed or traded
    return N


def budget(widths, *, eps: float | None = None, atoms: int | None = None,
           rule: str = "midpoint", node_limit: int = 20000) -> Budget:
    """Atoms per coordinate for the delayed curse of dimension, eq. (4.22) of the paper.

    A tensor product of 1-D laws of widths σⱼ, each quantized with ``N_j`` atoms, has
    (Lemma 4.1, with the 1-D bound ``c σ / N``)

    .. math:: W_1(\\mu, \\mu^N) \\le \\sum_j \\frac{c\\,\\sigma_j}{N_j}, \\qquad N = \\prod_j N_j,

    with ``c = 1/2`` for midpoint levels and ``c = 1`` for the paper's levels (eq. (4.21)).
    With ``eps`` this returns integer ``N_j ≥ 1`` minimizing ``N`` subject to the bound
    ``≤ eps``; with ``atoms`` it minimizes the bound subject to ``N ≤ atoms``.

    Method and guarantee: the continuous relaxation (``N_j = max(1, λ c σⱼ)``, solved exactly
    through its KKT conditions) gives a certified lower bound; an integer solution is built by
    rounding it (and, in eps mode, compared with the paper's recipe, which is always feasible),
    improved by local moves, and then a branch and bound over non-increasing vectors (some
    optimum sorts like σ, by an exchange argument) pruned with the continuous relaxation of
    every sub-problem proves it optimal or improves it. When the search finishes within
    ``node_limit`` nodes ``optimal`` is True and the result is an exact optimum; otherwise it
    is the best vector found (never worse than the paper's recipe) and ``lower_bound`` bounds
    the gap. Coordinates with σⱼ = 0 cost one atom.

    Cost: the counts are exact Python integers of any size and nothing loops once per atom
    (lowering a count is done in closed form, unit trades only where a float sum resolves
    them), so ``eps=1e-300`` on 200 coordinates (counts of 58 000 digits) takes about as long
    as ``eps=0.1``. The branch and bound keeps its own stack (no recursion), and a node costs
    ``O(log d)`` on top of the candidates it scores, so any number of coordinates works:
    10⁴ unit widths at ``eps=100`` take a few seconds (the node limit bounds the search, the
    local improvement filters its trades with numpy; atoms mode at d = 10⁴ takes seconds
    too, though equal widths, whose trades tie, still test most pairs one by one). The
    search works in floating point, so it refuses
    (``InvalidInput``) an ``eps`` below ``d · Σ c σⱼ / 1e305`` or an atom budget that would
    give one coordinate more than 1e305 atoms.

    Parameters
    ----------
    widths : (d,) array_like -- σⱼ ≥ 0
    eps : float, optional -- target bound (> 0)
    atoms : int, optional -- atom budget (≥ 1); give exactly one of eps and atoms
    rule : {"midpoint", "paper"}
    node_limit : int -- branch-and-bound nodes before giving up the optimality proof (also the
        most trades the local improvement makes)

    Returns
    -------
    Budget

    Examples
    --------
    >>> b = budget([1.0, 0.5, 0.25, 0.0], eps=0.25)
    >>> b.counts, b.n_atoms, round(b.bound, 4), b.k_bar, b.optimal
    ((5, 3, 2, 1), 30, 0.2458, 3, True)
    >>> b.recipe.n_atoms
    36
    >>> budget([1.0, 0.5], atoms=10).counts
    (5, 2)
    """
    w = _widths(widths)
    rule = as_choice(rule, "rule", RULE_CONSTANT)
    c = RULE_CONSTANT[rule]
    node_limit = as_int(node_limit, "node_limit", low=0)
    if (eps is None) == (atoms is None):
        raise InvalidInput("give exactly one of eps (target W1 bound) and atoms (atom budget)")
    d = w.size
    order = np.argsort(-w, kind="stable")
    pos = order[w[order] > 0]
    s = c * w[pos]
    counts = [1] * d
    if eps is not None:
        eps = as_float(eps, "eps", low=0.0, low_open=True)
        _check_scale(s, eps)
        recipe = paper_recipe(w, eps, rule=rule)
        if s.size == 0 or s.sum() <= eps * (1 + _TOL):
            nodes, optimal, lower, N = 0, True, 1.0, [1] * s.size
        else:
            solver = _Solver(s, node_limit)
            logLB, mu = solver.cont_eps(0, eps)
            cand = _local_eps(solver.s, _round_eps(solver.s, eps, mu), eps, node_limit)
            rec = [recipe.n_common] * recipe.k_bar + [1] * (s.size - recipe.k_bar)
            if math.prod(rec) < math.prod(cand):
                cand = _local_eps(solver.s, rec, eps, node_limit)
            cand = sorted(cand, reverse=True)  # some optimum is non-increasing along s
            N, optimal = solver.solve_eps(eps, cand)
            nodes = solver.nodes
            # the relaxation's optimum can exceed the float range (the curse: N ~ 1e400)
            lower = math.exp(logLB) if logLB < 709.0 else math.inf
    else:
        atoms = as_int(atoms, "atoms", low=1)
        if s.size == 0:
            N, optimal, nodes, lower = [], True, 0, 0.0
        else:
            solver = _Solver(s, node_limit)
            lower, nu = solver.cont_atoms(0, math.log(atoms))
            _check_atoms_scale(s, atoms, nu)
            cand = sorted(_local_atoms(solver.s, _floor_atoms(solver.s, atoms, nu), atoms, node_limit),
                          reverse=True)
            N, optimal = solver.solve_atoms(atoms, cand)
            nodes = solver.nodes
    for p, n in zip(pos, N):
        counts[int(p)] = int(n)
    bound = float(sum(_ratio(c * wi, ni) for wi, ni in zip(w, counts)))
    if atoms is not None:
        recipe = paper_recipe(w, bound, rule=rule) if bound > 0 else Recipe(0.0, 0, 1, 1, 0.0)
    n_atoms = math.prod(counts)
    return Budget(
        widths=w, counts=tuple(counts), n_atoms=n_atoms, bound=bound,
        k_bar=sum(1 for n in counts if n > 1), rule=rule, c=c, eps=eps, atoms=atoms,
        optimal=bool(optimal), lower_bound=float(lower), recipe=recipe, nodes=int(nodes),
    )
