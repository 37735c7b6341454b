"""Which terms of a scene the certificate handles, and how (see ``docs/certificates.md``).

A second-order, deterministic scene is split into

* pairwise terms ``vᵢ' += Σⱼ cⱼ φ(|sᵢ − sⱼ|)(zⱼ − zᵢ)`` (:class:`PairTerm`): source ``s`` and
  carrier ``z`` in ``{x, v}``, kernel ``φ`` with a ``slope_bound(lo, hi)``; a kernel whose
  ``certificate_form()`` declares one of the closed forms of
  :data:`kinred.dynamics.hooks.KERNEL_FORMS` runs in the compiled pass, any other in the
  numpy pass;
* one self-propulsion ``(a − b|vᵢ|²)vᵢ`` (the sum of all effects whose ``certificate_form()``
  is ``"self_propulsion"``, e.g. :class:`~kinred.dynamics.SelfPropulsion`, whose coefficients
  add);
* constant drifts (``certificate_form()`` ``"drift"``, e.g. :class:`~kinred.dynamics.Drift`),
  which cancel in the error.

Everything else is refused before any work, with the effect named: noise (the certificate is
for deterministic dynamics), :class:`~kinred.dynamics.Field` and any other effect outside the
paper's class (1.1), first-order scenes, kernels without ``slope_bound`` (or whose
``slope_bound`` refuses, e.g. Morse without softening).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..dynamics import Scene
from ..dynamics import hooks as _hooks
from ..errors import InvalidInput, NotProjectable
from ..pairsum import is_exact

__all__ = ["PairTerm", "Plan", "make_plan"]

#: Kernel kinds of the compiled pair pass (``_kernels``): anything else runs the numpy pass.
KIND_CS, KIND_MORSE, KIND_QUAD = 1, 2, 3


@dataclass(frozen=True)
class PairTerm:
    """One pairwise term of the velocity field.

    Attributes
    ----------
    kernel : object
        ``φ`` (``value_sq`` or ``__call__``, and ``slope_bound``).
    source, carrier : {"x", "v"}
    name : str
        ``repr`` of the effect (for messages).
    kind : int
        Compiled kernel kind, from the kernel's ``certificate_form()`` (0: none, numpy pass
        only).
    params : tuple of float
        Parameters of the compiled kernel.
    nonneg : bool
        ``φ >= 0`` everywhere, as the kernel's ``is_nonnegative()`` declares (Cucker–Smale,
        Quadratic with ``c >= 0``).
    """

    kernel: object
    source: str
    carrier: str
    name: str
    kind: int
    params: tuple
    nonneg: bool


@dataclass(frozen=True)
class Plan:
    """The certificate's view of a scene.

    Attributes
    ----------
    terms : tuple of PairTerm
    sp_a, sp_b : float
        Self-propulsion ``(a − b|v|²)v`` (sum over the effects); ``has_sp`` says whether any.
    has_sp : bool
    kappa : float
        ``cⱼ = κ wⱼ``: 1 (``"mean"``) or ``N`` (``"sum"``).
    """

    terms: tuple
    sp_a: float
    sp_b: float
    has_sp: bool
    kappa: float


def _compiled(kernel) -> tuple[int, tuple, bool]:
    """``(kind, params, nonneg)`` from the kernel's hooks (kind 0: the numpy pass evaluates it)."""
    nonneg = _hooks.is_nonnegative(kernel) is True
    form = _hooks.certificate_form(kernel, _hooks.KERNEL_FORMS)
    if form is None:
        return 0, (), nonneg
    if form.kind == "cucker_smale":
        return KIND_CS, form.params, nonneg
    if form.kind == "morse":
        Ca, la, Cr, lr, soft = form.params
        return KIND_MORSE, (Ca / la, la, Cr / lr, lr, soft), nonneg
    return KIND_QUAD, form.params, nonneg


def _check_slope(e, kernel):
    fn = getattr(kernel, "slope_bound", None)
    if not callable(fn):
        raise NotProjectable(
            f"{e!r}: its kernel {kernel!r} has no slope_bound(lo, hi) (sup |phi'| over an "
            "interval), which the certificate needs for the mean-value step; built-in kernels "
            "with one: CuckerSmale, Morse(soft > 0), Quadratic")
    try:
        out = np.asarray(fn(np.array([0.0, 1.0]), np.array([1.0, 2.0])), dtype=float)
    except InvalidInput as exc:
        raise NotProjectable(f"{e!r} cannot be certified: {exc}") from None
    if out.shape != (2,) or not np.all(np.isfinite(out)) or np.any(out < 0):
        raise NotProjectable(f"{e!r}: kernel.slope_bound returned {out!r} for two intervals; it "
                             "must return finite values >= 0 of the broadcast shape")


def make_plan(scene: Scene, n_agents: int) -> Plan:
    """Classify the effects of ``scene`` (see the module docstring); refuse what is not covered.

    Raises
    ------
    InvalidInput
        First-order scene; a pair-sum backend that is not exact
        (:func:`kinred.pairsum.is_exact`: NUFFT, RandomBatch, a backend without
        ``exact = True``).
    NotProjectable
        Noise, :class:`~kinred.dynamics.Field` or another effect outside class (1.1), a kernel
        without a usable ``slope_bound``.
    """
    backend = scene.pairsum
    if not is_exact(backend):
        raise InvalidInput(
            f"scene.pairsum = {backend!r} is an approximate pair-sum backend (it does not "
            "declare exact = True): certificates bound the error of the exact forward-Euler "
            "scheme, not the backend's own error; valid: an exact backend, Dense() (the "
            "default) or Numpy()")
    if scene.order != 2:
        raise InvalidInput("scene must be second order (positions and velocities): certificates "
                           "are derived for x' = v, v' = F(x, v) (docs/certificates.md); got a "
                           "first-order scene")
    terms = []
    a = b = 0.0
    has_sp = False
    for e in scene.effects:
        if getattr(e, "stochastic", False):
            raise NotProjectable(
                f"{e!r}: noise is excluded from certificates (they bound the deterministic "
                "Euler scheme; a noisy projected run differs by M times the noise increments, "
                "which no deterministic bound controls); remove the noise effect")
        if getattr(e, "pairwise", False):
            if scene._tgt(e) != "v":
                raise InvalidInput(f"{e!r}: pairwise effects on positions are not covered")
            _check_slope(e, e.kernel)
            kind, params, nonneg = _compiled(e.kernel)
            terms.append(PairTerm(e.kernel, e.source, e.carrier, repr(e), kind, params, nonneg))
            continue
        form = _hooks.certificate_form(e, _hooks.EFFECT_FORMS)
        if form is not None and form.kind == "self_propulsion":
            a += form.params[0]
            b += form.params[1]
            has_sp = True
        elif form is not None:
            if scene._tgt(e) != "v":
                raise InvalidInput(f"{e!r}: drifts on positions are not covered (target 'x')")
        else:
            raise NotProjectable(
                f"{e!r} is not covered by certificates: they are derived for pairwise effects "
                "(Alignment, AttractionRepulsion, PairwiseEffect with a kernel that has "
                "slope_bound), SelfPropulsion and Drift, the members of the paper's class (1.1), "
                "and effects declaring one of their forms by certificate_form(); Field and "
                "other custom effects have no projected error estimate")
    kappa = float(n_agents) if scene.normalize == "sum" else 1.0
    return Plan(tuple(terms), a, b, has_sp, kappa)
