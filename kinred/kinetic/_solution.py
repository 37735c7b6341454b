r"""Particle solutions of the mean-field equation and of its reduced (projected) version.

* :func:`solve` -- quantize a phase-space measure ``μ₀`` on ``ℝ²ᵈ`` (first ``d`` coordinates
  positions, last ``d`` velocities) with the delayed-curse budget (eq. (4.14)
  and eq. (4.22)), and run the *weighted* particle system
  (eq. (4.2)–(4.3)): atom weights become agent weights, so
  that ``μᴺ(t) = Σᵢ wᵢ δ_{(xᵢ(t), vᵢ(t))}`` is the measure solution of eq. (4.1)
  started from ``μ₀ᴺ``.
* :func:`reduce` -- the reduced solution ``νᴺ(t)`` of eq. (4.10) started from
  ``M#μ₀ᴺ`` (eq. (4.9)), where ``M`` acts on ``(x, v)`` as the block matrix
  ``diag(M, M)``; it is the particle system of the projected scene (eq. (3.5))
  with the same weights.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .._repr import result_repr
from .._validate import as_array, as_choice, as_float, as_int, as_span, check_alloc
from ..errors import InvalidInput
from ..measures import Atomic, Measure, Mixture, PushForward, TensorProduct
from ..projection import Projection, as_projection

__all__ = [
    "KineticSolution",
    "ReducedSolution",
    "solve",
    "reduce",
    "phase_space",
    "lift",
    "weighted_scene",
]


@dataclass(frozen=True)
class KineticSolution:
    """The particle solution ``μᴺ(t) = Σᵢ wᵢ δ_{(xᵢ(t), vᵢ(t))}`` on ``ℝ²ᵈ``.

    Attributes
    ----------
    t : (T,) ndarray
        Saved times.
    x, v : (T, N, d) ndarray
        Positions and velocities of the atoms at the saved times.
    weights : (N,) ndarray
        Atom weights (sum one), constant in time.
    eps : float
        Quantization bound: ``W1(μ₀, μ₀ᴺ) ≤ eps`` (eq. (4.14)), the a-priori
        bound of the quantizer (0 when ``μ₀`` was already atomic).
    n_atoms : int
        ``N``.
    quantization : object
        The :class:`kinred.quantize.Quantization` (None when atoms were given).
    quantize_time, simulate_time : float
        Seconds spent quantizing and simulating (the cost of the solution).
    scene : Scene
        The weighted scene that was integrated.
    method : str
    dt : float
    seed : object
        Noise seed (stochastic scenes only).
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    weights: np.ndarray
    eps: float
    n_atoms: int
    quantization: object
    quantize_time: float
    simulate_time: float
    scene: object
    method: str
    dt: float
    seed: object = None

    @property
    def dim(self) -> int:
        """``d`` (the phase space is ``ℝ²ᵈ``)."""
        return int(self.x.shape[2])

    @property
    def atoms(self) -> np.ndarray:
        """``(T, N, 2d)`` phase-space atoms ``[x | v]``."""
        return np.concatenate([self.x, self.v], axis=2)

    def measure(self, i: int = -1) -> Atomic:
        """``μᴺ(t_i)`` as an :class:`~kinred.measures.Atomic` measure on ``ℝ²ᵈ``."""
        return Atomic(np.concatenate([self.x[i], self.v[i]], axis=1), self.weights)


@dataclass(frozen=True)
class ReducedSolution:
    """The reduced particle solution ``νᴺ(t) = Σᵢ wᵢ δ_{(yᵢ(t), wᵢ(t))}`` on ``ℝ²ᵏ``.

    Attributes
    ----------
    t : (T,) ndarray
    y, w : (T, N, k) ndarray
        Positions and velocities of the reduced system.
    weights : (N,) ndarray
    projection : Projection
        ``M`` (``k × d``); the phase-space map is ``diag(M, M)``.
    eps : float
        Quantization bound of the initial atoms (copied from the solution).
    simulate_time : float
    scene : Scene
        The projected weighted scene.
    """

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

    t: np.ndarray
    y: np.ndarray
    w: np.ndarray
    weights: np.ndarray
    projection: Projection
    eps: float
    simulate_time: float
    scene: object

    @property
    def k(self) -> int:
        return int(self.y.shape[2])

    def measure(self, i: int = -1) -> Atomic:
        """``νᴺ(t_i)`` as an :class:`~kinred.measures.Atomic` measure on ``ℝ²ᵏ``."""
        return Atomic(np.concatenate([self.y[i], self.w[i]], axis=1), self.weights)


def _check_scene(scene):
    from ..dynamics import Scene

    if not isinstance(scene, Scene):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
    if scene.order != 2:
        raise InvalidInput("scene must be second order (positions and velocities, eq. (4.2)-(4.3)) "
                           "for a kinetic solution; got a first-order scene")
    if scene.normalize != "mean":
        raise InvalidInput(
            f"scene.normalize must be 'mean' for a mean-field (kinetic) solution: the field "
            f"H[mu] of eq. (4.1) integrates against mu, i.e. coefficients w_j; got "
            f"{scene.normalize!r} (coupling growing with N)")
    return scene


def weighted_scene(scene, weights):
    """A copy of ``scene`` whose agents carry the probability ``weights`` (atom weights)."""
    from ..dynamics import Scene

    scene = _check_scene(scene)
    return Scene(scene.effects, normalize=scene.normalize, weights=weights, pairsum=scene.pairsum)


def _save_spec(t_span, dt, method, times, save_every):
    from ..integrate import SaveAt

    if times is not None and save_every is not None:
        raise InvalidInput("give at most one of times and save_every")
    if times is not None:
        times = as_array(times, "times", ndim=1)
        return SaveAt(t=times, states=True, observables=())
    if save_every is not None:
        return SaveAt(every=as_int(save_every, "save_every", low=1), states=True, observables=())
    return SaveAt(states=True, observables=())


def _check_trajectory(n: int, d: int, t_span, dt, method, save) -> None:
    """The preflight of the states ``(T, n, d)`` that :func:`solve` saves (as
    :func:`~kinred.integrate.simulate` will check them), before the atoms are built."""
    from ..integrate import SOLVERS
    from ..integrate import check_save_size, save_points

    spec = SOLVERS.get(method) if isinstance(method, str) else None
    t0, t1 = t_span
    steps = (t1 - t0) / dt
    if spec is None or not steps <= 2.0**53:
        return  # simulate names the bad method or step
    n_steps = None if spec.adaptive else max(1, int(round(steps)))
    check_save_size(save, save_points(save, t0, t1, dt, n_steps), (n, d), 2, 0,
                    f"solve(mu0 quantized to {n} atoms in R^(2·{d}), t_span=({t0:g}, {t1:g}), "
                    f"dt={dt:g}, times/save_every: {save.describe()})",
                    "save fewer times (save_every=, times=), fewer atoms (larger eps, smaller "
                    "atoms) or a shorter t_span")


def solve(scene, mu0, *, eps: float | None = None, atoms: int | None = None,
          t_span=(0.0, 1.0), dt: float = 0.01, method: str = "euler", times=None,
          save_every: int | None = None, rule: str = "midpoint", max_atoms: int = 200_000,
          seed=None) -> KineticSolution:
    r"""Particle solution ``μᴺ(t)`` of the mean-field equation started from quantized ``μ₀``.

    ``μ₀`` is quantized by :func:`kinred.quantize.quantize` (tensor products with the
    delayed-curse budget, eq. (4.22); mixtures by Lemma 4.2), so that

    .. math:: W_1(\mu_0, \mu_0^N) \le \varepsilon, \qquad
              \mu_0^N = \sum_{i=1}^N w_i\,\delta_{(x_i^0, v_i^0)}

    (eq. (4.14)), and the weighted particle system
    ``ẋᵢ = vᵢ, v̇ᵢ = H[μᴺ](xᵢ, vᵢ)`` (eq. (4.2)–(4.3)) is integrated.

    Parameters
    ----------
    scene : Scene
        Second-order scene with ``normalize="mean"`` (the mean-field coupling). Its own
        ``weights`` are replaced by the atom weights.
    mu0 : Measure
        Phase-space measure on ``ℝ²ᵈ`` (``dim`` even; e.g. :func:`phase_space`), or an
        :class:`~kinred.measures.Atomic` measure (used as is, ``eps = 0``).
    eps, atoms : float or int, optional
        Target W1 bound or atom budget of the quantization (exactly one, unless ``mu0`` is
        atomic).
    t_span : (float, float)
    dt : float
    method : str
        Integrator (:data:`kinred.integrate.METHODS`); ``"euler"`` is the paper's.
    times : (T,) array_like, optional
        Save times (on the step grid for fixed-step methods). Exclusive with ``save_every``.
    save_every : int, optional
        Save every this many steps (default: every step).
    rule : {"midpoint", "paper"}
        Quantile levels of the quantizer.
    max_atoms : int
        Refuse quantizations with more atoms (:class:`~kinred.errors.TooLarge`).
    seed : None, int, SeedSequence or Generator
        Noise seed (stochastic scenes).

    Returns
    -------
    KineticSolution

    Raises
    ------
    TooLarge
        The atoms or the saved states ``(T, N, 2d)`` would exceed the memory limit
        (environment variable ``KINRED_MAX_BYTES``, default 2 GiB); checked before the atoms
        are built.

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> from kinred.measures import TensorProduct, Uniform
    >>> mu0 = TensorProduct([Uniform(0, 1), Uniform(0, 0.1), Uniform(-1, 1), Uniform(-0.1, 0.1)])
    >>> sol = solve(Scene([Alignment(CuckerSmale(1.0, 0.5))]), mu0, eps=0.5,
    ...             t_span=(0, 1), dt=0.1, save_every=5)
    >>> sol.x.shape == (3, sol.n_atoms, 2), sol.t, bool(sol.eps <= 0.5)
    (True, array([0. , 0.5, 1. ]), True)
    """
    from ..integrate import simulate
    from ..quantize import quantize

    scene = _check_scene(scene)
    if not isinstance(mu0, Measure):
        raise InvalidInput(f"mu0 must be a kinred Measure on R^(2d), got {type(mu0).__name__}")
    if mu0.dim % 2:
        raise InvalidInput(f"mu0 must live on the phase space R^(2d) (even dimension: positions "
                           f"then velocities), got dim {mu0.dim}")
    t_span = as_span(t_span)
    dt = as_float(dt, "dt", low=0.0, low_open=True)
    max_atoms = as_int(max_atoms, "max_atoms", low=1)
    rule = as_choice(rule, "rule", ("midpoint", "paper"))
    t0 = time.perf_counter()
    if isinstance(mu0, Atomic) and eps is None and atoms is None:
        q = None
        at = mu0
        bound = 0.0
    else:
        q = quantize(mu0, eps=eps, atoms=atoms, rule=rule)
        if q.n_atoms <= max_atoms:  # the trajectory's size, before the atoms are built
            _check_trajectory(int(q.n_atoms), mu0.dim // 2, t_span, dt, method,
                              _save_spec(t_span, dt, method, times, save_every))
        at = q.materialize(max_atoms=max_atoms)
        bound = float(q.bound)
    t_quant = time.perf_counter() - t0
    d = mu0.dim // 2
    P = at.points
    x0, v0 = P[:, :d], P[:, d:]
    wsc = weighted_scene(scene, at.weights)
    save = _save_spec(t_span, dt, method, times, save_every)
    tr = simulate(wsc, x0, v0, t_span, dt, method=method, save=save, seed=seed)
    return KineticSolution(t=tr.t, x=tr.x, v=tr.v, weights=np.asarray(at.weights, float),
                           eps=bound, n_atoms=int(at.n_atoms), quantization=q,
                           quantize_time=t_quant, simulate_time=tr.wall_time, scene=wsc,
                           method=method, dt=dt, seed=seed)


def reduce(solution, scene=None, M=None, *, t_span=None, dt=None, method=None, times=None,
           seed=None) -> ReducedSolution:
    r"""Reduced solution ``νᴺ(t)`` of eq. (4.10) started from ``M#μ₀ᴺ``.

    .. math:: \nu^N(0) = \sum_i w_i\,\delta_{(M x_i^0,\, M v_i^0)}, \qquad
              \dot y_i = w_i,\quad \dot w_i = H_M[\nu^N](y_i, w_i)

    with the projected scene (pairwise kernels see projected distances, per-agent terms are
    multiplied by ``M``; eq. (3.5)).

    Parameters
    ----------
    solution : KineticSolution or Atomic
        A solution (its initial atoms, weights, save times, step and method are reused), or
        an atomic phase-space measure ``μ₀ᴺ`` on ``ℝ²ᵈ`` (then ``scene``, ``t_span``, ``dt``
        are required).
    scene : Scene, optional
        The (unweighted) scene; default the solution's weighted scene.
    M : (k, d) ndarray or Projection
        The projection; it acts on ``(x, v)`` as ``diag(M, M)``.
    t_span, dt, method, times : optional
        Only for atomic input (or to override the solution's).
    seed : optional
        Noise seed; default the solution's, so that noise paths are comparable
        (``M σ dW`` with ``dW`` drawn in ``ℝᵈ``).

    Returns
    -------
    ReducedSolution

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> from kinred.measures import Atomic
    >>> mu0 = Atomic(np.random.default_rng(0).random((5, 6)))
    >>> red = reduce(mu0, Scene([Alignment(CuckerSmale(1.0, 0.0))]), np.eye(2, 3),
    ...              t_span=(0, 1), dt=0.5)
    >>> red.y.shape
    (3, 5, 2)
    """
    from ..integrate import simulate
    from ..integrate import SaveAt

    if M is None:
        raise InvalidInput("M must be given: a (k, d) ndarray or a Projection")
    P = as_projection(M)
    if isinstance(solution, KineticSolution):
        sc = solution.scene if scene is None else weighted_scene(scene, solution.weights)
        x0, v0, w = solution.x[0], solution.v[0], solution.weights
        eps = solution.eps
        span = (float(solution.t[0]), float(solution.t[-1])) if t_span is None else as_span(t_span)
        dt = solution.dt if dt is None else as_float(dt, "dt", low=0.0, low_open=True)
        method = solution.method if method is None else method
        save_t = solution.t if times is None else as_array(times, "times", ndim=1)
        seed = solution.seed if seed is None else seed
    elif isinstance(solution, Atomic):
        if scene is None or t_span is None or dt is None:
            raise InvalidInput("reduce(atoms, ...) needs scene, t_span and dt")
        if solution.dim % 2:
            raise InvalidInput(f"atoms must live on R^(2d), got dim {solution.dim}")
        d = solution.dim // 2
        x0, v0, w = solution.points[:, :d], solution.points[:, d:], solution.weights
        sc = weighted_scene(scene, w)
        eps = 0.0
        span = as_span(t_span)
        dt = as_float(dt, "dt", low=0.0, low_open=True)
        method = "euler" if method is None else method
        save_t = None if times is None else as_array(times, "times", ndim=1)
    else:
        raise InvalidInput(f"solution must be a KineticSolution or an Atomic measure, got "
                           f"{type(solution).__name__}")
    if P.d != x0.shape[1]:
        raise InvalidInput(f"M must map from d = {x0.shape[1]}, got shape {P.shape}")
    psc = sc.project(P)
    y0, w0 = P.apply(x0), P.apply(v0)
    save = SaveAt(states=True, observables=()) if save_t is None else SaveAt(t=save_t, states=True,
                                                                             observables=())
    tr = simulate(psc, y0, w0, span, dt, method=method, save=save, seed=seed)
    return ReducedSolution(t=tr.t, y=tr.x, w=tr.v, weights=np.asarray(w, float), projection=P,
                           eps=float(eps), simulate_time=tr.wall_time, scene=psc)


def phase_space(positions: Measure, velocities: Measure) -> Measure:
    """The product measure ``positions ⊗ velocities`` on ``ℝ²ᵈ`` (positions first).

    Tensor products concatenate their factors; mixtures expand into the mixture of the
    pairwise products (weights multiply), so the result stays quantizable by
    :func:`kinred.quantize.quantize` (Lemmas 4.1–4.2).

    Examples
    --------
    >>> from kinred.measures import TensorProduct, Uniform
    >>> mu = phase_space(TensorProduct([Uniform(0, 1)] * 2), TensorProduct([Uniform(-1, 1)] * 2))
    >>> mu.dim, mu.support_widths()
    (4, array([1., 1., 2., 2.]))
    """
    for name, m in (("positions", positions), ("velocities", velocities)):
        if not isinstance(m, (TensorProduct, Mixture)):
            raise InvalidInput(f"{name} must be a TensorProduct or a Mixture of them, got "
                               f"{type(m).__name__}")
    if positions.dim != velocities.dim:
        raise InvalidInput(f"positions and velocities must have the same dimension d, got "
                           f"{positions.dim} and {velocities.dim}")

    def parts(m):
        return list(zip(m.components, m.weights)) if isinstance(m, Mixture) else [(m, 1.0)]

    prods, weights = [], []
    for a, wa in parts(positions):
        for b, wb in parts(velocities):
            if not (isinstance(a, TensorProduct) and isinstance(b, TensorProduct)):
                raise InvalidInput("mixture components must be TensorProducts")
            prods.append(TensorProduct(list(a.factors) + list(b.factors)))
            weights.append(wa * wb)
    if len(prods) == 1:
        return prods[0]
    w = np.asarray(weights, float)
    return Mixture(prods, w / w.sum())


def lift(mu: Measure, d: int, seed=None) -> PushForward:
    r"""Embed a phase-space measure on ``ℝ²ᵈ⁰`` into ``ℝ²ᵈ`` by a random isometry.

    ``Q (d × d₀)`` has orthonormal columns (QR of a Gaussian matrix) and acts on ``(x, v)`` as
    ``diag(Q, Q)``; rotation-invariant dynamics (alignment, Morse, self-propulsion) then move
    the lifted particles exactly as ``Q`` times the low-dimensional ones.

    Examples
    --------
    >>> from kinred.measures import TensorProduct, Uniform
    >>> big = lift(TensorProduct([Uniform(0, 1)] * 4), 10, seed=0)
    >>> big.dim
    20
    """
    from .._rng import as_generator

    if not isinstance(mu, Measure) or mu.dim % 2:
        raise InvalidInput(f"mu must be a phase-space Measure of even dimension, got {mu!r}")
    d0 = mu.dim // 2
    d = as_int(d, "d", low=d0)
    # the Gaussian draw, QR (Q, R, workspace), the signed copy and B = diag(Q, Q) (2d, 2d0)
    check_alloc(96 * d * d0, f"lift(mu, d={d}): the isometry ({d}, {d0}) and diag(Q, Q)",
                "a smaller d")
    rng = as_generator(seed)
    Q, R = np.linalg.qr(rng.standard_normal((d, d0)))
    Q = Q * np.sign(np.diag(R))[None, :]
    B = np.zeros((2 * d, 2 * d0))
    B[:d, :d0] = Q
    B[d:, d0:] = Q
    return PushForward(mu, B)
