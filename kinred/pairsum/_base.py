r"""The pair-sum protocol and what a scene's pairwise effects call for.

A scene's pairwise effects (:class:`~kinred.dynamics.PairwiseEffect`, the paper's class
(1.1), with ``f_ij = c_j φ(D)``) all reduce to pair sums

.. math:: \bigl(\text{target}\bigr)_i \mathrel{+}= \sum_j c_j\, \varphi(\|s_i - s_j\|)\,(z_j - z_i)

for a kernel ``φ``, a distance source ``s ∈ {x, v}``, a carrier ``z ∈ {x, v}`` and a target.
:class:`PairTerms` lists them once per scene; a :class:`PairSum` backend evaluates them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from .._validate import as_int
from ..errors import InvalidInput

__all__ = ["PairSum", "PairTerm", "PairTerms", "COMPILED_KINDS", "compiled_form", "is_exact",
           "tail_bound", "pair_form"]

#: The closed forms of :func:`pair_form` and their number of parameters.
PAIR_FORMS = {"morse": 5, "cs": 2}

#: The compiled forms a kernel may declare through ``kernel.compiled_form()``, i.e. the
#: closed forms ``φ(√q)`` of squared distances ``q`` that the dense backend evaluates inside
#: its compiled strip worker (no Python call per strip):
#:
#: * ``("cs_halfint", G, n2)``: ``G (1 + q)^(−n2/2)`` with ``n2`` a non-negative integer
#:   (square roots and divisions only);
#: * ``("cs_pow", G, beta)``: ``G (1 + q)^(−β)`` for any ``β`` (vectorized ``2^(−β log₂(1+q))``
#:   with bit-level range reduction, as accurate as ``G·exp(−β·log1p(q))``).
COMPILED_KINDS = ("cs_halfint", "cs_pow")


def compiled_form(kernel) -> tuple[str, float, float] | None:
    """The validated compiled form ``(kind, a, b)`` of ``kernel``, or None.

    The kernel hook: a kernel may define ``compiled_form()`` returning None or a tuple
    ``(kind, a, b)`` with ``kind`` in :data:`COMPILED_KINDS` and finite parameters; it then
    promises that ``kernel(s)`` equals that closed form (backends may evaluate either).
    Kernels without the method (Morse, Quadratic, plain callables) have no compiled form.

    Raises
    ------
    InvalidInput
        If ``compiled_form()`` returns anything else.

    Examples
    --------
    >>> from kinred.dynamics import CuckerSmale, Morse
    >>> compiled_form(CuckerSmale(G=0.8, beta=1.5)), compiled_form(Morse()) is None
    (('cs_halfint', 0.8, 3.0), True)
    """
    fn = getattr(kernel, "compiled_form", None)
    if fn is None:
        return None
    if not callable(fn):
        raise InvalidInput(f"{kernel!r}.compiled_form must be a method returning None or "
                           f"(kind, a, b), got {fn!r}")
    form = fn()
    if form is None:
        return None
    ok = (isinstance(form, tuple) and len(form) == 3 and isinstance(form[0], str)
          and form[0] in COMPILED_KINDS)
    if ok:
        try:
            a, b = float(form[1]), float(form[2])
        except (TypeError, ValueError):
            ok = False
        else:
            ok = bool(np.isfinite(a) and np.isfinite(b))
            if form[0] == "cs_halfint":
                ok = ok and b >= 0 and b == int(b)
    if not ok:
        raise InvalidInput(
            f"{kernel!r}.compiled_form() returned {form!r}; valid: None or (kind, a, b) with "
            f"kind in {COMPILED_KINDS} and finite a, b (b a non-negative integer for "
            "'cs_halfint')")
    return (form[0], a, b)


def tail_bound(kernel):
    """The kernel's declared decay bound, a vectorized callable ``B(s)``, or None (unknown).

    The kernel hook of the truncating backends (:class:`~kinred.pairsum.CellList`, the cost
    model of ``pairsum="auto"``): a kernel may define ``tail_bound()`` returning a callable
    ``B`` with ``|φ(s′)| ≤ B(s)`` for every ``s′ ≥ s`` (``B`` non-increasing; ``inf``
    allowed), or None. Kernels without the method have an unknown tail: nothing is
    truncated for them.

    Raises
    ------
    InvalidInput
        If ``tail_bound`` is not a method returning None or a callable.

    Examples
    --------
    >>> from kinred.dynamics import Morse
    >>> B = tail_bound(Morse(Ca=1.0, la=1.0, Cr=0.0, lr=1.0))
    >>> round(float(B(np.array([2.0]))[0]), 6)    # e^(-2)/2
    0.067668
    >>> tail_bound(lambda s: s) is None
    True
    """
    fn = getattr(kernel, "tail_bound", None)
    if fn is None:
        return None
    bound = fn() if callable(fn) else fn
    if bound is not None and not callable(bound):
        raise InvalidInput(f"{kernel!r}.tail_bound must be a method returning None or a "
                           f"vectorized callable B(s) >= |phi(s')| for s' >= s, got {bound!r}")
    return bound


def pair_form(kernel) -> tuple | None:
    """The kernel's closed form for the cell list's fused compiled pass, or None.

    A kernel may define ``pair_form()`` returning None or ``(kind, params)`` with ``kind`` in
    ``PAIR_FORMS`` – ``("morse", (Cₐ, ℓₐ, C_r, ℓ_r, soft))`` for
    ``u(s) = U′(r)/r``, ``r = √(s² + soft²)`` (0 at ``r = 0``), as ``Morse`` does – and finite
    parameters; a kernel with a Cucker–Smale :func:`compiled_form` gets ``("cs", (G, β))``.

    Raises
    ------
    InvalidInput
        If ``pair_form()`` returns anything else.

    Examples
    --------
    >>> from kinred.dynamics import CuckerSmale, Morse
    >>> pair_form(Morse(1.0, 2.0, 1.5, 0.5)), pair_form(CuckerSmale(0.8, 1.5))
    (('morse', (1.0, 2.0, 1.5, 0.5, 0.0)), ('cs', (0.8, 1.5)))
    """
    fn = getattr(kernel, "pair_form", None)
    if fn is None:
        form = compiled_form(kernel)
        if form is None:
            return None
        return ("cs", (form[1], form[2] / 2.0 if form[0] == "cs_halfint" else form[2]))
    form = fn() if callable(fn) else fn
    if form is None:
        return None
    try:
        kind, params = form
        params = tuple(float(p) for p in params)
        ok = kind in PAIR_FORMS and len(params) == PAIR_FORMS[kind] and all(
            np.isfinite(params))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InvalidInput(f"{kernel!r}.pair_form() returned {form!r}; valid: None or (kind, "
                           f"params) with kind in {tuple(PAIR_FORMS)} and that many finite "
                           f"parameters {PAIR_FORMS}")
    return (kind, params)


@dataclass(frozen=True)
class PairTerm:
    """One pair sum: ``targetᵢ += Σⱼ cⱼ kernel(‖sourceᵢ − sourceⱼ‖)(carrierⱼ − carrierᵢ)``.

    Attributes
    ----------
    effect : PairwiseEffect
        The effect it comes from.
    kernel : callable
        ``φ(s)``; may also have ``value_sq(q, out)`` and ``compiled_form()``.
    source, carrier, target : {"x", "v"}
        ``target`` is resolved (an effect's ``None`` means ``"v"`` in a second-order scene,
        ``"x"`` in a first-order one).
    compiled : (str, float, float) or None
        The kernel's validated compiled form (:func:`compiled_form`).
    """

    effect: Any
    kernel: Callable
    source: str
    carrier: str
    target: str
    compiled: tuple | None = None


@dataclass(frozen=True)
class PairTerms:
    """What a scene's pairwise effects call for, computed once per scene.

    Backends compute only these: distances of the listed sources (never of one that no
    effect needs), one centred carrier per listed carrier, one accumulator per
    ``(target, carrier)``. A scene without pairwise terms (``bool(terms)`` False) needs no
    pair sum at all and costs ``O(N·d)`` per evaluation.

    Attributes
    ----------
    terms : tuple of PairTerm
        In the order of the scene's effects.
    sources : tuple of str
        Distance sources needed, in the order ``("x", "v")``.
    carriers : tuple of str
        Carriers needed, sorted.
    accumulators : tuple of (str, str)
        The ``(target, carrier)`` pairs, sorted: terms sharing one are summed before the
        final ``Σⱼ cⱼφᵢⱼ zⱼ − (Σⱼ cⱼφᵢⱼ) zᵢ``.
    normalize : {"mean", "sum"}
        How the coefficients ``c`` follow from the agent weights (:meth:`coefficients`).

    Examples
    --------
    >>> from kinred.dynamics import Alignment, AttractionRepulsion, Scene, SelfPropulsion
    >>> pt = Scene([Alignment(on="v"), AttractionRepulsion(), SelfPropulsion()]).pair_terms
    >>> pt.sources, pt.carriers, pt.accumulators
    (('x', 'v'), ('v', 'x'), (('v', 'v'), ('v', 'x')))
    """

    terms: tuple
    sources: tuple
    carriers: tuple
    accumulators: tuple
    normalize: str

    @classmethod
    def from_effects(cls, effects, order: int, normalize: str) -> "PairTerms":
        """The pair terms of ``effects`` (the pairwise ones) in a scene of ``order``; kernels'
        compiled forms are validated here, once."""
        default = "v" if order == 2 else "x"
        terms = tuple(PairTerm(e, e.kernel, e.source, e.carrier,
                               e.target if e.target is not None else default,
                               compiled_form(e.kernel))
                      for e in effects if e.pairwise)
        return cls(terms=terms,
                   sources=tuple(s for s in ("x", "v") if any(t.source == s for t in terms)),
                   carriers=tuple(sorted({t.carrier for t in terms})),
                   accumulators=tuple(sorted({(t.target, t.carrier) for t in terms})),
                   normalize=normalize)

    def __bool__(self) -> bool:
        return bool(self.terms)

    def of_source(self, source: str) -> tuple:
        """The terms whose distances are measured in ``source``, in scene order."""
        return tuple(t for t in self.terms if t.source == source)

    def coefficients(self, weights: np.ndarray) -> np.ndarray:
        """The coefficient vector ``c``: ``w`` (``"mean"``) or ``N w`` (``"sum"``), a new array."""
        return weights * weights.shape[0] if self.normalize == "sum" else weights.copy()


@runtime_checkable
class PairSum(Protocol):
    """Protocol of a pair-sum backend (one file per backend, e.g. :class:`~kinred.pairsum.Dense`).

    A backend is a configuration object, shareable between scenes; everything that depends on
    a scene and a state shape goes into the plan, which the scene builds once per
    ``(n, dim, engine threads)`` and keeps.

    Methods
    -------
    plan(scene, n, dim)
        Everything that depends only on the scene (``scene.pair_terms``,
        ``scene.coefficients(n)``) and the shape: raise :class:`~kinred.errors.InvalidInput`
        here if the backend cannot evaluate the scene (a capability check before any work).
    evaluate(plan, x, v, rng)
        The per-step work: a dict ``target -> (n, dim) ndarray`` with the summed contribution
        of the plan's terms for each target, fresh arrays the caller keeps. ``v`` is None in
        first-order scenes; ``rng`` (a ``numpy.random.Generator`` or None) is for stochastic
        backends; exact ones ignore it.

    A backend whose ``evaluate`` also takes ``out={target: array}`` (C-contiguous float64
    ``(n, dim)`` arrays it overwrites and returns instead of fresh ones, with the same values)
    declares ``accepts_out = True``; :meth:`kinred.integrate.VectorField.transient` then
    reuses two arrays for the whole run of a one-stage method (:class:`RandomBatch` at large
    ``N·d``, where fresh pages cost about 10 % of an evaluation).

    A backend may offer forward Euler's step itself, taken inside its pair sums:
    ``euler_step(plan, x, v, h, rng, local, w, shift, centres)`` updates ``x, v`` in place to
    the step from the drift ``evaluate`` plus the local drifts ``local`` would give and returns
    the row sums of the new state's moments (:meth:`RandomBatch.euler_step`, whose batches
    touch only their own rows); ``simulate``'s Euler loop then calls it instead of
    ``evaluate`` and the update (``Scene._euler_fused``).

    A backend that draws random numbers declares the attribute ``stochastic = True``:
    :func:`~kinred.integrate.simulate` then passes the run's generator (from its ``seed``) to
    every evaluation; without it a scene without noise is deterministic and gets ``rng=None``.

    A backend that computes the pair sums exactly (up to floating-point round-off, which
    certificates account for) declares ``exact = True`` (:class:`~kinred.pairsum.Dense`,
    :class:`~kinred.pairsum.Numpy`); approximate ones (:class:`~kinred.pairsum.NUFFT`,
    :class:`~kinred.pairsum.RandomBatch`) declare ``exact = False``, and a backend that says
    nothing counts as approximate (:func:`is_exact`). :func:`kinred.certify.certify` and
    ``kinred certify`` refuse scenes whose backend is not exact.
    """

    def plan(self, scene, n: int, dim: int) -> Any: ...

    def evaluate(self, plan, x: np.ndarray, v: np.ndarray | None, rng=None) -> dict: ...


def is_exact(backend) -> bool:
    """Whether the pair-sum ``backend`` declares exact pair sums (``exact = True``); a backend
    without the attribute is not exact (see :class:`PairSum`).

    Examples
    --------
    >>> from kinred.pairsum import Dense, NUFFT, RandomBatch
    >>> is_exact(Dense()), is_exact(NUFFT()), is_exact(RandomBatch()), is_exact(object())
    (True, False, False, False)
    """
    return getattr(backend, "exact", False) is True


def check_plan_args(scene, n, dim) -> tuple[PairTerms, int, int]:
    """Validated ``(scene.pair_terms, n, dim)`` of a ``plan`` call (for backends)."""
    terms = getattr(scene, "pair_terms", None)
    if not isinstance(terms, PairTerms):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene (with pair_terms), got "
                           f"{type(scene).__name__}")
    return terms, as_int(n, "n", low=1), as_int(dim, "dim", low=1)
