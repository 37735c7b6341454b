r"""The right-hand side of Theorem 4.3 (eq. (4.17)) with the proof's constants.

The proof of Theorem 4.3 splits

.. math::
    W_1(\mu_M(t), \nu(t)) \le
    \underbrace{W_1(\mu_M(t), (\mu^N(t))_M)}_{\le\, C(t)\|M\|\varepsilon}
    + \underbrace{W_1((\mu^N(t))_M, \nu^N(t))}_{\le\, \sqrt2\, D(t)\,\varepsilon_{JL}}
    + \underbrace{W_1(\nu^N(t), \nu(t))}_{\le\, C(t)\|M\|\varepsilon}

so kinred evaluates :math:`B(t) = 2C(t)\|M\|\varepsilon + \sqrt2\,D(t)\varepsilon_{JL}` with

* ``ε`` -- the quantizer's bound ``W1(μ₀, μ₀ᴺ) ≤ ε`` (eq. (4.14));
* ``ε_JL`` -- the distortion (3.4) of ``M`` measured along the particle
  trajectories with :func:`kinred.projection.trajectory_distortion`, on the distances the
  effects depend on (positions for kernels of ``‖xᵢ − xⱼ‖``, velocities for kernels of
  ``‖vᵢ − vⱼ‖``, speeds ``‖vᵢ‖`` -- distances to the paper's auxiliary zero particle, §3.3.2 --
  for self-propulsion): the Lipschitz conditions (1.2)–(1.4) only see those distances, so
  (3.3) and (3.4) are only needed on them;
* ``D(t) ε_JL`` -- Theorem 3.1's estimate, the RHS of eq. (3.7):

  .. math:: D(t)\,\varepsilon_{JL} = \varepsilon_{JL}\,\alpha\, t\,(L\|M\| + L''\beta)
            \exp\bigl[(2L\|M\| + 2\beta L'' + L')\,t\bigr],

  applied to the ``2N`` variables ``x₁..x_N, v₁..v_N`` of ``ℝᵈ`` (the arrangement of §2.3),
  so a particle's error in ``ℝ²ᵏ`` is at most ``√2·E(t)`` -- hence the factor ``√2``;
* ``C(t)`` -- the W1 stability constant of eq. (4.6). kinred uses
  Dobrushin's estimate (F. Golse, *On the dynamics of large particle systems in the mean
  field limit*, 2016, Thm. 3.3; the paper's reference [CCR], §3–4): if the particle field
  ``F(z, μ) = (v, H[μ](x, v))`` satisfies
  ``|F(z, μ) − F(z′, μ′)| ≤ Λ_z |z − z′| + Λ_μ W1(μ, μ′)`` on the supports, then for two
  measure solutions (in particular atomic ones, and their forward-Euler updates, since
  ``(1 + hΛ)ⁿ ≤ e^{Λt}``)

  .. math:: W_1(\mu(t), \mu'(t)) \le e^{\Lambda t}\, W_1(\mu(0), \mu'(0)), \qquad
            \Lambda = \Lambda_z + \Lambda_\mu ,

  by following the characteristics from an optimal coupling of the initial data. So
  ``C(t) = exp(Λ t)``.

A-priori quantities (``α`` of (3.3), ``β`` of (3.6), the speed bound ``β_v`` of §3.3.2, the
support diameters used by ``Λ``) are *measured* on the simulated trajectories of both
systems at the saved times, as running maxima over ``[0, t]`` (the theorem applied on
``[0, t]``); diameters (``α`` included) exactly up to :data:`EXACT_DIAMETER_MAX` atoms, above
by the O(N·d) upper bound of :func:`diameter_bounds` (the bound grows with them, so it stays
an upper bound); positions are taken relative to the initial centroid (every supported effect is
translation invariant, and ``y − Mx`` is unchanged by the shift). Between saved times nothing
is checked: this is an a-posteriori evaluation, not a certificate.

Per-effect constants (``S = Σⱼ cⱼ``, 1 for ``normalize="mean"``)
---------------------------------------------------------------
=====================  =========  ======================  ====================  ===============================
effect                 L (1.2)    L′ (1.3), v-rows        L″ (1.4)              Λ_z + Λ_μ
=====================  =========  ======================  ====================  ===============================
pairwise φ (any)       0          2S‖φ‖∞                  2S‖φ‖_Lip             2S(‖φ‖∞ + ‖φ‖_Lip·diam(carrier))
SelfPropulsion(a, b)   0          |a| + b β_v²            2 b β_v               max(|a|, |a − 3bβ_v²|)
Drift(c)               0          0                       0                     0
ẋ = v (x-rows)         0          1                       0                     1
=====================  =========  ======================  ====================  ===============================

``L′ = max(1, Σ v-row contributions)`` (the max over rows of (1.3)), ``L″`` is the sum. For
Cucker–Smale this is the paper's ``L′ ≥ max(1, 2G)`` and ``L″ ≤ 2‖g‖_Lip`` (§2.3); for the
self-propulsion model the paper's §3.3.2 values (with the max over rows instead of their sum).
The pairwise Lipschitz bound: ``ψ(r, q) = φ(|r|) q`` with ``r`` the source difference and
``q`` the carrier difference has ``|Δψ| ≤ ‖φ‖_Lip·|q|·|Δr| + ‖φ‖∞·|Δq|``, and
``|q| ≤ diam(carrier)``; both the dependence on the particle (Λ_z) and on the measure (Λ_μ,
through a coupling) have this constant. Self-propulsion ``h(v) = (a − b|v|²)v`` has Jacobian
eigenvalues ``a − b|v|²`` and ``a − 3b|v|²``. Noise is not covered (the theorems are
deterministic); kernels without ``sup_norm``/``lipschitz`` give ``inf``. A per-agent effect
declares its row of the table by its hook ``theorem_constants(speed=, diam_x=, diam_v=)``
(:class:`kinred.dynamics.hooks.TheoremConstants`; SelfPropulsion and Drift do); without it
its constants are unknown (``inf``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._repr import result_repr
from .._validate import as_float
from ..dynamics import hooks as _hooks
from ..errors import InvalidInput

__all__ = [
    "EffectConstants",
    "TheoremBound",
    "effect_constants",
    "d_estimate",
    "stability_constant",
    "theorem_bound",
    "max_pairwise_distance",
    "diameter_bounds",
    "EXACT_DIAMETER_MAX",
]

#: Up to this many points :func:`theorem_bound` takes diameters exactly
#: (:func:`max_pairwise_distance`, O(N²m)); above, the O(N·m) upper bound of
#: :func:`diameter_bounds` (an upper bound of a diameter keeps the bound an upper bound).
EXACT_DIAMETER_MAX = 4096

_U = 2.0 ** -53


@dataclass(frozen=True)
class EffectConstants:
    """Constants one effect contributes to (1.2)–(1.4) and to the stability rate Λ.

    Attributes
    ----------
    effect : str
    L : float
        Contribution to ``L`` of (1.2).
    Lp : float
        Contribution to ``Σⱼ|fᵢⱼ|`` of a velocity row, (1.3).
    Lpp : float
        Contribution to ``L″`` of (1.4).
    lip_state, lip_measure : float
        Lipschitz constants of the velocity field in the particle state and in the measure
        (W1), entering ``Λ = Λ_z + Λ_μ``.
    sources : tuple of str
        Distances the effect depends on: ``"x"``, ``"v"`` (pairwise), ``"speed"`` (``‖vᵢ‖``).
    formula : str
        How the numbers were obtained.
    """

    effect: str
    L: float
    Lp: float
    Lpp: float
    lip_state: float
    lip_measure: float
    sources: tuple
    formula: str


def _kernel_norms(kernel):
    sup = getattr(kernel, "sup_norm", None)
    lip = getattr(kernel, "lipschitz", None)
    s = float(sup()) if callable(sup) else math.inf
    l = float(lip()) if callable(lip) else math.inf
    return s, l


def effect_constants(effect, *, coef_sum: float = 1.0, speed: float = 0.0, diam_x: float = 0.0,
                     diam_v: float = 0.0) -> EffectConstants:
    r"""Constants of one effect (table in ``docs/kinetic.md`` and the ``kinred.kinetic._bounds`` module docstring).

    Parameters
    ----------
    effect : Effect
    coef_sum : float
        ``S = Σⱼ cⱼ`` of the scene's pairwise coefficients (1 for ``normalize="mean"``).
    speed : float
        ``β_v ≥ maxᵢ ‖vᵢ‖`` over both systems (self-propulsion).
    diam_x, diam_v : float
        Support diameters in positions and velocities (pairwise Lipschitz bounds).

    Examples
    --------
    >>> from kinred.dynamics import Alignment, CuckerSmale, SelfPropulsion
    >>> c = effect_constants(Alignment(CuckerSmale(G=2.0, beta=0.0)), diam_v=3.0)
    >>> c.Lp, c.Lpp, c.lip_state + c.lip_measure      # 2G, 2·0, 2·(G + 0·3)
    (4.0, 0.0, 4.0)
    >>> s = effect_constants(SelfPropulsion(1.0, 0.5), speed=2.0)
    >>> s.Lp, s.Lpp, s.lip_state                      # 1 + 0.5·4, 2·0.5·2, |1 − 3·0.5·4|
    (3.0, 2.0, 5.0)
    """
    S = as_float(coef_sum, "coef_sum", low=0.0)
    speed = as_float(speed, "speed", low=0.0)
    diam_x = as_float(diam_x, "diam_x", low=0.0)
    diam_v = as_float(diam_v, "diam_v", low=0.0)
    name = repr(effect)
    if getattr(effect, "stochastic", False):
        return EffectConstants(name, math.nan, math.nan, math.nan, math.nan, math.nan, (),
                               "noise: not covered by Theorems 3.1/4.3 (deterministic dynamics)")
    if getattr(effect, "pairwise", False):
        if getattr(effect, "target", "v") != "v":
            raise InvalidInput(f"{effect!r}: pairwise effects on positions (first-order) are not "
                               "part of the second-order kinetic setting")
        sup, lip = _kernel_norms(effect.kernel)
        diam = diam_x if effect.carrier == "x" else diam_v
        lipz = S * (sup + (lip * diam if lip > 0 else 0.0))
        return EffectConstants(
            name, 0.0, 2.0 * S * sup, 2.0 * S * lip, lipz, lipz, (effect.source,),
            f"phi={effect.kernel!r}: ||phi||inf={sup:.6g}, ||phi||Lip={lip:.6g}, S={S:g}, "
            f"diam({effect.carrier})={diam:.6g}; L'+=2S||phi||inf, L''+=2S||phi||Lip, "
            f"Lip=S(||phi||inf+||phi||Lip*diam)")
    tc = _hooks.theorem_constants(effect, speed=speed, diam_x=diam_x, diam_v=diam_v)
    if tc is None:
        return EffectConstants(name, math.inf, math.inf, math.inf, math.inf, math.inf, (),
                               "effect outside the documented table: constants unknown (inf)")
    return EffectConstants(name, tc.L, tc.Lp, tc.Lpp, tc.lip_state, tc.lip_measure,
                           tuple(tc.sources), tc.formula)


def d_estimate(t, eps_jl, alpha, beta, L, Lp, Lpp, norm_M):
    r"""Theorem 3.1's estimate, the RHS of eq. (3.7).

    .. math:: \mathcal E(t) \le \varepsilon\,\alpha\,t\,(L\|M\| + L''\beta)
              \exp\bigl[(2L\|M\| + 2\beta L'' + L')\,t\bigr]

    All arguments broadcast (arrays of times with running-max constants).

    Examples
    --------
    >>> round(float(d_estimate(1.0, 0.1, 2.0, 3.0, 0.0, 1.0, 0.5, 1.0)), 10)   # 0.1·2·1·1.5·e^(3+1)
    16.3794450099
    """
    t = np.asarray(t, float)
    lin = L * norm_M + np.asarray(Lpp, float) * beta
    with np.errstate(over="ignore", invalid="ignore"):
        rate = 2.0 * L * norm_M + 2.0 * np.asarray(beta, float) * Lpp + Lp
        out = np.asarray(eps_jl, float) * alpha * t * lin * np.exp(rate * t)
    out = np.where(t == 0.0, 0.0, out)
    return out if out.ndim else float(out)


def stability_constant(t, Lambda):
    r"""``C(t) = exp(Λ t)``: Dobrushin's W1 stability constant (eq. (4.6)).

    Examples
    --------
    >>> stability_constant(0.0, 5.0), round(stability_constant(2.0, 0.5), 12)
    (1.0, 2.718281828459)
    >>> stability_constant(0.0, float("inf")), stability_constant(1.0, float("inf"))
    (1.0, inf)
    """
    t = np.asarray(t, float)
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.exp(np.asarray(Lambda, float) * t)
    out = np.where(t == 0.0, 1.0, out)            # C(0) = 1 even for an unknown Λ = inf
    return out if np.ndim(out) else float(out)


def max_pairwise_distance(Z) -> float:
    """``max_{i,j} ‖zᵢ − zⱼ‖`` for ``Z (N, m)`` (centred Gram matrix, blocks of rows).

    Examples
    --------
    >>> max_pairwise_distance(np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 1.0]]))
    5.0
    """
    Z = np.asarray(Z, float)
    if Z.shape[0] < 2:
        return 0.0
    Z = Z - Z.mean(axis=0)
    nn = np.einsum("ij,ij->i", Z, Z)
    best = 0.0
    b = max(1, int(4_000_000 // max(Z.shape[0], 1)))
    for i0 in range(0, Z.shape[0], b):
        G = Z[i0:i0 + b] @ Z.T
        q = nn[i0:i0 + b, None] + nn[None, :] - 2.0 * G
        best = max(best, float(q.max()))
    return math.sqrt(max(best, 0.0))


def diameter_bounds(Z) -> tuple[float, float]:
    r"""``(lower, upper)`` with ``lower ≤ max_{i,j} ‖zᵢ − zⱼ‖ ≤ upper`` for ``Z (N, m)``, in O(N·m).

    * ``upper = 2 minₖ maxᵢ ‖zᵢ − cₖ‖`` over two centres ``cₖ`` (the mean and the centre of
      the bounding box), since ``‖zᵢ − zⱼ‖ ≤ ‖zᵢ − c‖ + ‖c − zⱼ‖``; enlarged by the rounding of
      the subtraction and of the norms, so it is an upper bound of the exact diameter of the
      stored points. At most twice the diameter (the mean lies in the convex hull, so
      ``maxᵢ ‖zᵢ − mean‖ ≤ diameter``).
    * ``lower``: a double sweep, the largest distance seen from the point farthest from the
      mean and from the point farthest from that one (a distance between two points: a
      lower bound, in practice close to the diameter).

    Examples
    --------
    >>> lo, up = diameter_bounds(np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 1.0]]))
    >>> lo, bool(5.0 <= up <= 5.0 * (1 + 1e-12))
    (5.0, True)
    """
    Z = np.asarray(Z, float)
    if Z.ndim != 2:
        raise InvalidInput(f"Z must be a 2-D array (points, coordinates), got shape {Z.shape}")
    n, m = Z.shape
    if n < 2 or m == 0:
        return 0.0, 0.0
    lo_box, hi_box = Z.min(axis=0), Z.max(axis=0)
    best = math.inf
    far = 0
    for c in (Z.mean(axis=0), 0.5 * (lo_box + hi_box)):
        r = np.sqrt(np.einsum("ij,ij->i", Z - c, Z - c))
        i = int(np.argmax(r))
        scale = float(np.max(np.abs(Z))) + float(np.max(np.abs(c)))
        # |fl(z − c) − (z − c)| ≤ u(|z| + |c|) per coordinate; the norm adds (m + 2)u relative
        rad = float(r[i]) * (1.0 + 2.0 * (m + 4) * _U) + 2.0 * _U * math.sqrt(m) * scale
        if rad < best:
            best, far = rad, i
    upper = 2.0 * best * (1.0 + 4.0 * _U)
    lower = 0.0
    p = far
    for _ in range(2):
        r = np.sqrt(np.einsum("ij,ij->i", Z - Z[p], Z - Z[p]))
        q = int(np.argmax(r))
        lower = max(lower, float(r[q]))
        p = q
    return lower, max(upper, lower)


def _diameter(Z) -> float:
    """The diameter exactly up to :data:`EXACT_DIAMETER_MAX` points, else an upper bound."""
    if Z.shape[0] <= EXACT_DIAMETER_MAX:
        return max_pairwise_distance(Z)
    return diameter_bounds(Z)[1]


@dataclass(frozen=True)
class TheoremBound:
    r"""Theorem 4.3's bound at the saved times, with every piece.

    Attributes
    ----------
    t : (T,) ndarray
    eps : float
        Quantization bound ``ε``.
    norm_M : float
        ``‖M‖`` (operator norm; also that of ``diag(M, M)``).
    eps_jl, alpha, beta, speed, diam_x, diam_v : (T,) ndarray
        Measured running maxima: distortion (3.4), (3.3), (3.6), ``β_v``, diameters.
    L : float
    Lp, Lpp, Lambda : (T,) ndarray
        ``L′``, ``L″`` and the stability rate ``Λ`` (they depend on the running maxima).
    C : (T,) ndarray
        ``C(t) = exp(Λ t)``.
    D_eps : (T,) ndarray
        ``D(t) ε_JL``, the RHS of eq. (3.7): bounds ``maxᵢ ‖M zᵢ − ζᵢ‖`` over the ``2N``
        variables.
    term_quant : (T,) ndarray
        ``2 C(t) ‖M‖ ε`` (first and third terms of the proof).
    term_jl : (T,) ndarray
        ``√2 D(t) ε_JL``: bounds ``W1(M#μᴺ(t), νᴺ(t))`` (second term).
    bound : (T,) ndarray
        ``term_quant + term_jl``: bounds ``W1(μ_M(t), ν(t))`` (the proof of Theorem 4.3).
    bound_stated : (T,) ndarray
        The statement's form ``𝒞(t)‖M‖ε̄`` with ``𝒞 = 2C‖M‖ + √2 D``, ``ε̄ = max(ε, ε_JL)``
        (the statement carries one more factor ``‖M‖`` than the proof yields).
    effects : tuple of EffectConstants
        Per-effect constants at the final time.
    covered : bool
        False when an effect is outside the theorems (noise, unknown effects).
    note : str
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    t: np.ndarray
    eps: float
    norm_M: float
    eps_jl: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    speed: np.ndarray
    diam_x: np.ndarray
    diam_v: np.ndarray
    L: float
    Lp: np.ndarray
    Lpp: np.ndarray
    Lambda: np.ndarray
    C: np.ndarray
    D_eps: np.ndarray
    term_quant: np.ndarray
    term_jl: np.ndarray
    bound: np.ndarray
    bound_stated: np.ndarray
    effects: tuple
    covered: bool
    note: str


def _speed_distortion(P, V) -> np.ndarray:
    """``maxᵢ |‖M vᵢ‖/‖vᵢ‖ − 1|`` per time for ``V (T, N, d)`` (zero vectors skipped)."""
    out = np.zeros(V.shape[0])
    for t in range(V.shape[0]):
        n = np.linalg.norm(V[t], axis=1)
        m = np.linalg.norm(P.apply(V[t]), axis=1)
        ok = n > 0
        if np.any(ok):
            out[t] = float(np.max(np.abs(m[ok] / n[ok] - 1.0)))
    return out


def theorem_bound(solution, reduced, *, eps: float | None = None) -> TheoremBound:
    r"""Evaluate the RHS of eq. (4.17) with the proof's constants.

    See the module documentation for every constant and where it comes from.

    Parameters
    ----------
    solution : KineticSolution
    reduced : ReducedSolution
        Its reduced solution (same save times).
    eps : float, optional
        Quantization bound ``ε`` (default ``solution.eps``).

    Returns
    -------
    TheoremBound

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> from kinred.measures import Atomic
    >>> from kinred.kinetic import solve, reduce
    >>> mu0 = Atomic(np.random.default_rng(1).random((6, 8)))
    >>> sc = Scene([Alignment(CuckerSmale(1.0, 0.0))])        # constant kernel: L'' = 0
    >>> sol = solve(sc, mu0, t_span=(0, 1), dt=0.1, save_every=5)
    >>> tb = theorem_bound(sol, reduce(sol, M=np.eye(2, 4)), eps=0.1)
    >>> tb.term_jl                                             # D = 0: exact projection
    array([0., 0., 0.])
    """
    P = reduced.projection
    if not np.array_equal(solution.t, reduced.t):
        raise InvalidInput("solution and reduced must share their save times")
    eps = solution.eps if eps is None else as_float(eps, "eps", low=0.0)
    norm_M = P.norm()
    measured = _measure_a_priori(solution, reduced)
    rates = _effect_rates(solution.scene, len(solution.weights), measured)
    return _assemble(np.asarray(solution.t, float), float(eps), norm_M, measured, rates,
                     n_atoms=len(solution.weights))


@dataclass(frozen=True)
class _APriori:
    """A-priori quantities of Theorems 3.1/4.3 measured at the saved times, as running maxima.

    Each field is a ``(T,)`` array; see :class:`TheoremBound` for their meaning.
    """

    eps_jl: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    speed: np.ndarray
    diam_x: np.ndarray
    diam_v: np.ndarray


def _distance_sources(scene) -> set:
    """The distances the scene's effects depend on: ``"x"``, ``"v"`` (pairwise), ``"speed"``."""
    sources = set()
    for e in scene.effects:
        if getattr(e, "pairwise", False):
            sources.add(e.source)
            continue
        # what an effect depends on does not depend on the measured values
        tc = _hooks.theorem_constants(e, speed=0.0, diam_x=0.0, diam_v=0.0)
        if tc is not None:
            sources.update(tc.sources)
    return sources


def _operator_distortion(P) -> float:
    """An upper bound of every pair's distortion ``| |M(xᵢ − xⱼ)| / |xᵢ − xⱼ| − 1 |`` from
    ``M`` alone: the ratio lies in ``[σ_min, σ_max]`` (``σ_min = 0`` when ``k < d``), so the
    distortion is at most ``max(1 − σ_min, σ_max − 1)`` (rounded up). Used above
    :data:`EXACT_DIAMETER_MAX` atoms, where the ``O(N²)`` pairs of (3.4) are not measured; it
    keeps the a-priori bound an upper bound (larger, and vacuous as it mostly is anyway)."""
    A = np.asarray(P.matrix if hasattr(P, "matrix") else P, dtype=float)
    s = np.linalg.svd(A, compute_uv=False)
    lo = float(s.min()) if A.shape[0] >= A.shape[1] else 0.0
    return max(1.0 - lo, float(s.max()) - 1.0) * (1.0 + 1e-12) + 1e-15


def _measure_a_priori(solution, reduced) -> _APriori:
    """``α`` (3.3), ``ε_JL`` (3.4), ``β`` (3.6), ``β_v`` and the support diameters.

    ``α`` and ``ε_JL`` are taken on the distances the effects depend on
    (:func:`_distance_sources`); positions relative to the initial centroid when the scene is
    translation invariant. Each quantity is the running maximum over the saved times up to t.
    """
    from ..projection import trajectory_distortion

    P = reduced.projection
    T = len(solution.t)
    scene = solution.scene
    c0 = solution.weights @ solution.x[0]
    X = solution.x - c0[None, None, :] if scene.translation_invariant else solution.x
    Y = reduced.y - P.apply(c0)[None, None, :] if scene.translation_invariant else reduced.y
    V, W = solution.v, reduced.w
    sources = _distance_sources(scene)
    n = X.shape[1]
    alpha_t = np.zeros(T)
    eps_t = np.zeros(T)
    def distortion(Z):
        if n > EXACT_DIAMETER_MAX:                 # O(T N² d) pairs: the operator bound instead
            return np.full(T, _operator_distortion(P))
        return np.nan_to_num(trajectory_distortion(P, Z).eps_t)

    if "x" in sources and n > 1:
        alpha_t = np.maximum(alpha_t, [_diameter(X[i]) for i in range(T)])
        eps_t = np.maximum(eps_t, distortion(X))
    if "v" in sources and n > 1:
        alpha_t = np.maximum(alpha_t, [_diameter(V[i]) for i in range(T)])
        eps_t = np.maximum(eps_t, distortion(V))
    if "speed" in sources:
        alpha_t = np.maximum(alpha_t, np.linalg.norm(V, axis=2).max(axis=1))
        eps_t = np.maximum(eps_t, _speed_distortion(P, V))
    beta_t = np.maximum(np.linalg.norm(Y, axis=2).max(axis=1), np.linalg.norm(W, axis=2).max(axis=1))
    speed_t = np.maximum(np.linalg.norm(V, axis=2).max(axis=1), np.linalg.norm(W, axis=2).max(axis=1))
    dx_t = np.array([max(_diameter(X[i]), _diameter(Y[i])) for i in range(T)])
    dv_t = np.array([max(_diameter(V[i]), _diameter(W[i])) for i in range(T)])
    run = np.maximum.accumulate
    return _APriori(eps_jl=run(eps_t), alpha=run(alpha_t), beta=run(beta_t), speed=run(speed_t),
                    diam_x=run(dx_t), diam_v=run(dv_t))


@dataclass(frozen=True)
class _Rates:
    """The scene's constants (1.2)–(1.4) and stability rate Λ at each saved time."""

    L: float
    Lp: np.ndarray
    Lpp: np.ndarray
    Lambda: np.ndarray
    effects: tuple
    covered: bool


def _effect_rates(scene, n_agents: int, measured: _APriori) -> _Rates:
    """Sum of the per-effect constants (:func:`effect_constants`) at each time's running maxima.

    ``L′ = max(1, Σ)`` (the x-rows contribute 1), ``Λ = 1 + Σ (Λ_z + Λ_μ)`` (``ẋ = v`` adds 1);
    ``effects`` are the constants at the final time, ``covered`` is False when one of them is
    not finite (noise, unknown effects).
    """
    S = float(np.sum(scene.coefficients(n_agents)))
    T = len(measured.speed)
    Lp = np.empty(T)
    Lpp = np.empty(T)
    Lam = np.empty(T)
    L = 0.0
    consts = ()
    for i in range(T):
        consts = tuple(effect_constants(e, coef_sum=S, speed=float(measured.speed[i]),
                                        diam_x=float(measured.diam_x[i]),
                                        diam_v=float(measured.diam_v[i])) for e in scene.effects)
        L = float(sum(c.L for c in consts))
        Lp[i] = max(1.0, float(sum(c.Lp for c in consts)))
        Lpp[i] = float(sum(c.Lpp for c in consts))
        Lam[i] = 1.0 + float(sum(c.lip_state + c.lip_measure for c in consts))
    covered = not any(not np.isfinite(c.Lp) for c in consts)
    return _Rates(L=L, Lp=Lp, Lpp=Lpp, Lambda=Lam, effects=consts, covered=covered)


def _assemble(times: np.ndarray, eps: float, norm_M: float, m: _APriori, r: _Rates,
              n_atoms: int = 0) -> TheoremBound:
    """``2 C(t) ‖M‖ ε + √2 D(t) ε_JL`` (the proof of Theorem 4.3) and the statement's form."""
    t = times - float(times[0])
    D_eps = np.atleast_1d(d_estimate(t, m.eps_jl, m.alpha, m.beta, r.L, r.Lp, r.Lpp, norm_M))
    C = np.atleast_1d(stability_constant(t, r.Lambda))
    with np.errstate(over="ignore", invalid="ignore"):
        term_quant = 2.0 * C * norm_M * eps
        term_jl = math.sqrt(2.0) * D_eps
        bound = term_quant + term_jl
        jl_part = math.sqrt(2.0) * D_eps / np.where(m.eps_jl > 0, m.eps_jl, 1.0)   # √2 D(t)
        bound_stated = (2.0 * C * norm_M + jl_part) * norm_M * np.maximum(eps, m.eps_jl)
    note = ("bound = 2 C(t) ||M|| eps + sqrt(2) D(t) eps_JL (proof of Theorem 4.3); constants "
            "measured at saved times as running maxima")
    if n_atoms > EXACT_DIAMETER_MAX:
        note += (f"; diameters and alpha: O(N d) upper bounds, eps_JL: the operator bound "
                 f"max(1 - s_min(M), s_max(M) - 1) (N = {n_atoms} > {EXACT_DIAMETER_MAX})")
    if not r.covered:
        note += "; some effect is outside Theorems 3.1/4.3 (noise or unknown): bound is nan/inf"
    return TheoremBound(t=times, eps=eps, norm_M=norm_M, eps_jl=m.eps_jl, alpha=m.alpha,
                        beta=m.beta, speed=m.speed, diam_x=m.diam_x, diam_v=m.diam_v, L=r.L,
                        Lp=r.Lp, Lpp=r.Lpp, Lambda=r.Lambda, C=C, D_eps=D_eps,
                        term_quant=term_quant, term_jl=term_jl, bound=bound,
                        bound_stated=bound_stated, effects=r.effects, covered=r.covered, note=note)
