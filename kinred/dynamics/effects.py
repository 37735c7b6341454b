r"""Effects: the terms whose sum is a scene's vector field.

Every effect is a small object satisfying the :class:`Effect` protocol. Two kinds exist:

* **pairwise effects** (:class:`PairwiseEffect`): a scalar kernel ``φ`` of the distance
  between agents in ``x`` or in ``v`` (``source``) weights the differences of a carrier
  ``z ∈ {x, v}``:

  .. math:: \bigl(\text{target}\bigr)_i \mathrel{+}= \sum_j c_j\, \varphi(\|s_i - s_j\|)\,(z_j - z_i),

  exactly the paper's class (1.1) with ``f_ij = c_j φ(D)``; they are
  evaluated by the blocked pairwise engine of :class:`~kinred.dynamics.Scene`.
  ``c_j`` is the normalization: ``w_j`` (``normalize="mean"``) or ``N w_j`` (``"sum"``).
* **per-agent effects**: ``drift(x, v, t) -> (N, d)`` added to the target (O(N·d)), and
  **noise** effects (``stochastic = True``) that add ``σ dW``.

Writing a new effect
--------------------
Subclass :class:`Effect` (or just provide its attributes) and implement ``drift``::

    class Friction(Effect):
        target = "v"
        projectable = True              # -γ v_i is linear in v_i: f_ii = -γ in eq. (1.1)
        translation_invariant = True    # does not depend on x
        def __init__(self, gamma): self.gamma = gamma
        def drift(self, x, v, t): return -self.gamma * v
        def project(self, M): return self

or subclass :class:`PairwiseEffect` with any kernel callable ``φ(s)``; no engine change is
needed (custom kernels without ``value_sq`` are evaluated as ``φ(√q)`` on the blocks).
The divergence guard, the certificates and the theorem bound know an effect (a kernel) by
its optional hooks ``energy_term``, ``step_radius``, ``certificate_form``,
``theorem_constants`` (kernels: ``is_nonnegative``, ``potential_range``,
``certificate_form``, ``slope_bound``, ``sup_norm``, ``lipschitz``); without them it is
unknown to them (:mod:`kinred.dynamics.hooks`).

Projection (eq. (2.4)–(2.5); eq. (3.5))
---------------------------------------------------------------------------------------------
Pairwise effects project as themselves (the kernels see projected distances); ``fᵢ`` terms
are multiplied by ``M`` (``Noise``: ``σ dW ↦ M σ dW``, ``Drift``: ``c ↦ M c``);
:class:`SelfPropulsion` depends on ``‖vᵢ‖`` only, i.e. on the distance to the paper's
auxiliary zero particle (§3.3.2), and projects as itself. :class:`Field` (a general
nonlinearity, e.g. acting on a single coordinate) is not in class (1.1) and is refused with
:class:`~kinred.errors.NotProjectable`.
"""

from __future__ import annotations

import math

from typing import Callable, Protocol, runtime_checkable

import numpy as np

from .._validate import as_array, as_bool, as_choice, as_float
from ..errors import InvalidInput, NotProjectable
from .hooks import CertificateForm, EnergyTerm, StepRadius, TheoremConstants
from .kernels import CuckerSmale, Morse

__all__ = [
    "Effect",
    "PairwiseEffect",
    "Alignment",
    "AttractionRepulsion",
    "Aggregation",
    "SelfPropulsion",
    "Noise",
    "Drift",
    "Field",
]


@runtime_checkable
class Effect(Protocol):
    """Protocol of an effect (a term of the vector field).

    Attributes
    ----------
    target : {"x", "v", None}
        Which derivative the effect contributes to; ``None`` means ``"v"`` in a second-order
        scene and ``"x"`` in a first-order one.
    pairwise : bool
        True for :class:`PairwiseEffect` (handled by the pairwise engine).
    projectable : bool
        Whether the effect belongs to the paper's class (1.1) and projects exactly.
    translation_invariant : bool
        Whether the effect is unchanged when all positions move by the same vector (lets the
        integrator work in coordinates relative to the initial centroid).
    stochastic : bool
        True for noise (integrated by Euler–Maruyama).
    """

    target: str | None = "v"
    pairwise: bool = False
    projectable: bool = False
    translation_invariant: bool = False
    stochastic: bool = False

    def drift(self, x: np.ndarray, v: np.ndarray | None, t: float) -> np.ndarray:
        """Contribution ``(N, dim)`` to the target derivative (per-agent effects)."""
        raise NotImplementedError

    def project(self, M) -> "Effect":
        """The effect of the projected system (default: refuse)."""
        raise NotProjectable(
            f"{type(self).__name__} does not declare how it projects: it is not known to belong "
            "to the paper's class (1.1) (x_i' = f_i(Dx) + sum_j f_ij(Dx) x_j); implement "
            "project(M) to allow scene.project(M)"
        )


class PairwiseEffect(Effect):
    r"""Generic pairwise effect ``targetᵢ += Σⱼ cⱼ φ(‖sᵢ − sⱼ‖)(zⱼ − zᵢ)``.

    Parameters
    ----------
    kernel : callable
        ``φ(s)`` on an ndarray of distances (a :class:`~kinred.dynamics.kernels.Kernel`).
    source : {"x", "v"}
        Where distances are measured.
    carrier : {"x", "v"}
        The vectors ``z`` whose differences are weighted.
    target : {"x", "v"}
        The derivative that receives the contribution.

    Examples
    --------
    >>> e = PairwiseEffect(lambda s: np.exp(-s), source="x", carrier="v", target="v")
    >>> e.pairwise, e.projectable
    (True, True)
    """

    pairwise = True
    projectable = True
    translation_invariant = True

    def __init__(self, kernel: Callable, *, source: str = "x", carrier: str = "v",
                 target: str = "v"):
        if not callable(kernel):
            raise InvalidInput(f"kernel must be callable (phi(s) on an ndarray), got {kernel!r}")
        self.kernel = kernel
        self.source = as_choice(source, "source", ("x", "v"))
        self.carrier = as_choice(carrier, "carrier", ("x", "v"))
        self.target = as_choice(target, "target", ("x", "v"))

    def drift(self, x, v, t):  # pragma: no cover - the engine handles pairwise effects
        raise TypeError("pairwise effects are evaluated by the Scene engine")

    def project(self, M) -> "PairwiseEffect":
        """Pairwise effects project as themselves: the kernel sees projected distances."""
        return self

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(kernel={self.kernel!r}, source={self.source!r}, "
                f"carrier={self.carrier!r}, target={self.target!r})")


class Alignment(PairwiseEffect):
    r"""Alignment (Cucker–Smale, eq. (2.13)).

    .. math:: \dot v_i \mathrel{+}= \sum_j c_j\, g(\|x_i - x_j\|)\,(v_j - v_i)

    Parameters
    ----------
    kernel : Kernel
        Communication rate ``g``; default ``CuckerSmale(G=1, beta=1.5)``.
    on : {"x", "v"}
        Distances in positions (the paper) or in velocities.

    Examples
    --------
    >>> Alignment(kernel=CuckerSmale(G=0.8, beta=1.5)).source
    'x'
    """

    def __init__(self, kernel: Callable | None = None, *, on: str = "x"):
        on = as_choice(on, "on", ("x", "v"))
        super().__init__(CuckerSmale() if kernel is None else kernel, source=on, carrier="v",
                         target="v")

    def __repr__(self) -> str:
        return f"Alignment(kernel={self.kernel!r}, on={self.source!r})"


class AttractionRepulsion(PairwiseEffect):
    r"""Attraction–repulsion through a radial potential (eq. (3.14)).

    .. math:: \dot v_i \mathrel{+}= -\sum_j c_j \nabla_{x_i} U(\|x_i - x_j\|)
              = \sum_j c_j\, u(\|x_i - x_j\|)\,(x_j - x_i), \qquad u(s) = U'(s)/s.

    Parameters
    ----------
    potential : Morse or any kernel giving ``u(s)``
        Default ``Morse()``. See :class:`~kinred.dynamics.kernels.Morse` for coincident agents.

    Examples
    --------
    >>> AttractionRepulsion(Morse(soft=0.1)).carrier
    'x'
    """

    def __init__(self, potential: Callable | None = None):
        _check_potential(potential)
        super().__init__(Morse() if potential is None else potential, source="x", carrier="x",
                         target="v")
        self.potential = self.kernel

    def __repr__(self) -> str:
        return f"AttractionRepulsion(potential={self.kernel!r})"


def _check_potential(potential) -> None:
    if potential is not None and not callable(potential):
        raise InvalidInput(f"potential must be callable (u(s) on an ndarray, e.g. Morse()), "
                           f"got {potential!r}")


class Aggregation(PairwiseEffect):
    r"""First-order aggregation ``ẋᵢ = −Σⱼ cⱼ ∇W(xᵢ − xⱼ)`` for a radial ``W(x) = U(‖x‖)``.

    .. math:: \dot x_i = \sum_j c_j\, u(\|x_i - x_j\|)\,(x_j - x_i), \qquad u(s) = U'(s)/s.

    A scene made of aggregation (and first-order per-agent effects) has ``order == 1``.

    Examples
    --------
    >>> from kinred.dynamics.kernels import Quadratic
    >>> Aggregation(Quadratic(1.0)).target
    'x'
    """

    def __init__(self, potential: Callable | None = None):
        _check_potential(potential)
        super().__init__(Morse() if potential is None else potential, source="x", carrier="x",
                         target="x")
        self.potential = self.kernel

    def __repr__(self) -> str:
        return f"Aggregation(potential={self.kernel!r})"


class SelfPropulsion(Effect):
    r"""Self-propulsion and friction (eq. (3.14)): O(N·d), no pairs.

    .. math:: \dot v_i \mathrel{+}= (a - b\,\|v_i\|^2)\, v_i

    It is in class (1.1) through the paper's auxiliary zero particle (§3.3.2), so it projects
    as itself (with the projected norm). Explicit methods are stable only for
    ``dt·b·max‖vᵢ‖² ≲ 1``.

    Examples
    --------
    >>> SelfPropulsion(1.0, 0.5).drift(None, np.array([[2.0, 0.0]]), 0.0)
    array([[-2.,  0.]])
    """

    target = "v"
    projectable = True
    translation_invariant = True

    def __init__(self, a: float = 1.0, b: float = 0.5):
        self.a = as_float(a, "a")
        self.b = as_float(b, "b", low=0.0)

    def drift(self, x, v, t):
        sq = np.einsum("ij,ij->i", v, v)
        return (self.a - self.b * sq)[:, None] * v

    def project(self, M) -> "SelfPropulsion":
        return self

    def energy_term(self, *, frame, target, dim) -> EnergyTerm | None:
        """``d/dt Σᵢwᵢ|vᵢ|² ≤ 2 Σᵢwᵢ(a|vᵢ|² − b|vᵢ|⁴)``: ``p = a²/(2b)`` (``b > 0``), ``κ = a``
        (``b = 0``, or ``a²/(2b)`` beyond the floats: a subnormal ``b``; ``−b|vᵢ|⁴ ≤ 0`` makes
        it a bound for every ``b ≥ 0``), nothing for ``a ≤ 0``; absolute frame only (it is not
        Galilean invariant)."""
        if frame != "absolute":
            return None
        a, b = self.a, self.b
        p = a * a / (2.0 * b) if b > 0 else math.inf
        if a > 0 and math.isfinite(p):
            return EnergyTerm(p=p, why=f"self-propulsion adds at most a²/(2b) "
                                       f"= {p:.3g} per unit time")
        if a > 0:
            return EnergyTerm(kappa=a, why=f"self-propulsion grows it at most at the rate 2a "
                                           f"= {2 * a:.3g}")
        return EnergyTerm()

    def step_radius(self, v) -> StepRadius:
        """The Jacobian ``(a − b|v|²) I − 2b v vᵀ`` has radius ``max |a − 3b|vᵢ|²|`` (and
        ``2a`` on the attractor ``|v|² = a/b``)."""
        q = float(np.max(np.einsum("ij,ij->i", v, v)))
        r = max(abs(self.a - 3.0 * self.b * q), abs(self.a - self.b * q), 2.0 * abs(self.a))
        return StepRadius(r, f"self-propulsion max|a − 3b|vᵢ|²| = {r:.3g}, i.e. "
                             f"dt*b*max|v|^2 must stay below about 2/3")

    def certificate_form(self) -> CertificateForm:
        """``("self_propulsion", (a, b))``."""
        return CertificateForm("self_propulsion", (self.a, self.b))

    def theorem_constants(self, *, speed, diam_x=0.0, diam_v=0.0) -> TheoremConstants:
        """``L′ = |a| + bβ_v²``, ``L″ = 2bβ_v``, ``Λ_z = max(|a|, |a − 3bβ_v²|)``, ``Λ_μ = 0``
        with ``β_v`` the ``speed`` (§3.3.2)."""
        a, b = self.a, self.b
        lz = max(abs(a), abs(a - 3.0 * b * speed ** 2))
        return TheoremConstants(
            0.0, abs(a) + b * speed ** 2, 2.0 * b * speed, lz, 0.0, ("speed",),
            f"a={a:g}, b={b:g}, beta_v={speed:.6g}: L'+=|a|+b beta_v^2, L''+=2b beta_v, "
            f"Lip=max(|a|,|a-3b beta_v^2|)")

    def __repr__(self) -> str:
        return f"SelfPropulsion(a={self.a!r}, b={self.b!r})"


class Noise(Effect):
    r"""Additive noise ``σ dWᵢ`` (independent Brownian motions), integrated by Euler–Maruyama.

    In a projected scene the increment is ``M σ dWᵢ`` with ``dWᵢ`` drawn in the original
    dimension (so a projected run is path-wise comparable with ``M`` times the original).

    Parameters
    ----------
    sigma : float
        Noise intensity ``>= 0``.
    target : {"x", "v", None}
        ``None``: velocities in a second-order scene, positions in a first-order one.
    matrix : (k, d) ndarray, optional
        Set by projection; increments are ``σ √dt ξ Mᵀ`` with ``ξ (N, d)`` standard normal.

    Examples
    --------
    >>> Noise(0.1).stochastic
    True
    """

    stochastic = True
    projectable = True
    translation_invariant = True

    def __init__(self, sigma: float = 0.1, *, target: str | None = None, matrix=None):
        self.sigma = as_float(sigma, "sigma", low=0.0)
        self.target = None if target is None else as_choice(target, "target", ("x", "v"))
        self.matrix = None if matrix is None else as_array(matrix, "matrix", ndim=2)

    def drift(self, x, v, t):
        return None

    def increment(self, rng: np.random.Generator, n: int, dim: int, dt: float) -> np.ndarray:
        """``σ ΔW`` over a step ``dt`` for ``n`` agents in ``ℝ^dim``: ``(n, dim)``."""
        if self.matrix is None:
            return (self.sigma * np.sqrt(dt)) * rng.standard_normal((n, dim))
        if self.matrix.shape[0] != dim:
            raise InvalidInput(f"matrix must have {dim} rows (the dimension of the state it "
                               f"perturbs), got shape {self.matrix.shape}")
        xi = rng.standard_normal((n, self.matrix.shape[1]))
        return (self.sigma * np.sqrt(dt)) * (xi @ self.matrix.T)

    def energy_term(self, *, frame, target, dim) -> EnergyTerm | None:
        """``p = σ² tr(M Mᵀ)`` (``M = I`` unprojected), the expected rate, on velocities."""
        if target != "v":
            return None
        rate = self.sigma * self.sigma * (dim if self.matrix is None
                                          else float(np.sum(self.matrix ** 2)))
        return EnergyTerm(p=rate, why=f"noise adds σ²·tr(MMᵀ) = {rate:.3g} per unit time in "
                                      f"expectation")

    def step_radius(self, v) -> StepRadius:
        """Nothing: the increments do not depend on the state."""
        return StepRadius()

    def project(self, M) -> "Noise":
        Md = M.to_dense()
        mat = Md if self.matrix is None else Md @ self.matrix
        return Noise(self.sigma, target=self.target, matrix=mat)

    def __repr__(self) -> str:
        extra = "" if self.matrix is None else f", matrix=<{self.matrix.shape}>"
        return f"Noise(sigma={self.sigma!r}, target={self.target!r}{extra})"


class Drift(Effect):
    """Constant drift ``c ∈ ℝᵈ`` added to every agent (an ``fᵢ`` term; projects to ``M c``).

    Examples
    --------
    >>> Drift([1.0, 0.0]).drift(None, np.zeros((2, 2)), 0.0)
    array([[1., 0.],
           [1., 0.]])
    """

    projectable = True
    translation_invariant = True

    def __init__(self, c, *, target: str | None = None):
        self.c = as_array(c, "c", ndim=1)
        self.target = None if target is None else as_choice(target, "target", ("x", "v"))

    def drift(self, x, v, t):
        ref = v if v is not None else x
        if ref.shape[1] != self.c.shape[0]:
            raise InvalidInput(
                f"Drift c has dimension {self.c.shape[0]} but the state has {ref.shape[1]} columns")
        return np.broadcast_to(self.c, ref.shape)

    def project(self, M) -> "Drift":
        return Drift(M.apply(self.c), target=self.target)

    def energy_term(self, *, frame, target, dim) -> EnergyTerm | None:
        """Nothing for ``Γ``; ``2Σᵢwᵢvᵢ·c ≤ |c|² + Q`` in the absolute frame (``p = |c|²``,
        ``κ = ½``); on velocities only."""
        if target != "v":
            return None
        if frame == "centred":
            return EnergyTerm()
        return EnergyTerm(p=float(self.c @ self.c), kappa=0.5,
                          why="a drift c adds at most |c|² + Q per unit time")

    def step_radius(self, v) -> StepRadius:
        """Nothing: a constant has no Jacobian."""
        return StepRadius()

    def certificate_form(self) -> CertificateForm:
        """``("drift", ())``: a constant ``fᵢ`` cancels in the certified error."""
        return CertificateForm("drift")

    def theorem_constants(self, *, speed=0.0, diam_x=0.0, diam_v=0.0) -> TheoremConstants:
        """All zero: a constant ``fᵢ``."""
        return TheoremConstants(0.0, 0.0, 0.0, 0.0, 0.0, (), "constant f_i: all zero")

    def __repr__(self) -> str:
        return f"Drift(c=<{self.c.shape[0]}>, target={self.target!r})"


class Field(Effect):
    """A general per-agent field ``fn(t, x, v) -> (N, d)`` (not projectable).

    A general nonlinearity (e.g. one acting on a single coordinate, ``fn = lambda t, x, v:
    -np.sin(x[:, :1]) * e₁``) is not of the form (1.1), so :meth:`project` raises
    :class:`~kinred.errors.NotProjectable`.

    Parameters
    ----------
    fn : callable
        ``fn(t, x, v)`` returning an ``(N, d)`` array (``v`` is None in first-order scenes).
    target : {"x", "v", None}
    translation_invariant : bool
        Declare True only if ``fn`` does not depend on absolute positions.

    Examples
    --------
    >>> f = Field(lambda t, x, v: -x)
    >>> f.drift(np.ones((1, 2)), np.zeros((1, 2)), 0.0)
    array([[-1., -1.]])
    """

    def __init__(self, fn: Callable, *, target: str | None = None,
                 translation_invariant: bool = False):
        if not callable(fn):
            raise InvalidInput(f"fn must be callable fn(t, x, v) -> (N, d) array, got {fn!r}")
        self.fn = fn
        self.target = None if target is None else as_choice(target, "target", ("x", "v"))
        self.translation_invariant = as_bool(translation_invariant, "translation_invariant")

    def drift(self, x, v, t):
        return np.asarray(self.fn(t, x, v), dtype=float)

    def project(self, M):
        raise NotProjectable(
            f"Field({getattr(self.fn, '__name__', self.fn)!r}) is a general per-agent field, "
            "not of the paper's class (1.1) (x_i' = f_i(Dx) + sum_j f_ij(Dx) x_j with f_i, f_ij "
            "functions of pairwise distances only): M f(x) != f(M x) in general, so the projected "
            "system would not approximate M x(t). Use pairwise effects, SelfPropulsion, Drift or Noise."
        )

    def __repr__(self) -> str:
        return f"Field({getattr(self.fn, '__name__', self.fn)!r}, target={self.target!r})"
