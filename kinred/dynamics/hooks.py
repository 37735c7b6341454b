r"""How kernels and effects describe themselves to the guard, the certificates and the bounds.

The engines only need a kernel's values (``__call__``, optionally ``value_sq``,
``compiled_form()``, …). Three other parts of kinred need to *know* something about it: the
divergence guard of :func:`kinred.integrate.simulate` (an a-priori bound on the velocities),
the certificates of :func:`kinred.certify.certify` (a closed form of the error propagation)
and the theorem bound of :func:`kinred.kinetic.theorem_bound` (the constants (1.2)–(1.4)).
They ask through the optional methods below, never by the class's name, so a kernel or an
effect written outside kinred is guarded, certified and bounded as soon as it declares them.
A missing method (or one returning None) means *unknown*: the guard then checks for
non-finite states only, the certificate refuses the effect with
:class:`~kinred.errors.NotProjectable`, the theorem bound is not finite (its constants are
``inf``) and says it is not covered. The readers of this
module call the hooks and check what they return (:class:`~kinred.errors.InvalidInput`
naming the object, the hook and the value otherwise).

**Kernel hooks** (a kernel ``φ`` of a pairwise effect ``Σⱼ cⱼ φ(‖sᵢ − sⱼ‖)(zⱼ − zᵢ)``):

* ``is_nonnegative()`` – True when ``φ ≥ 0`` everywhere: alignment with it only dissipates
  (eq. (2.13)); the guard's budget. CuckerSmale; Quadratic with ``c ≥ 0``.
* ``potential_range()`` – ``sup U − inf U ≥ 0`` of the potential with ``φ = U′(s)/s``
  (eq. (3.14)) when bounded: the energy a pair force trades with the velocities; the guard's
  budget. Morse: ``Cₐ + C_r``.
* ``certificate_form()`` – a :class:`CertificateForm` of :data:`KERNEL_FORMS`, the closed form
  of the certificate's compiled pass (without it, the plain numpy pass evaluates ``φ``).
  CuckerSmale, Morse, Quadratic.
* ``slope_bound(lo, hi)`` – ``sup |φ′|`` over ``[lo, hi]``: required by the certificate.
  CuckerSmale, Morse with ``soft > 0``, Quadratic.
* ``sup_norm()``, ``lipschitz()`` – ``‖φ‖∞`` and ``‖φ′‖∞``: the theorem bound's constants
  (``inf`` without them). CuckerSmale, Morse, Quadratic.

**Effect hooks** (per-agent effects; a pairwise effect is described by its kernel):

* ``energy_term(frame, target, dim)`` – an :class:`EnergyTerm`, what the effect adds to the
  guard's bound on ``Q`` in that frame (:data:`FRAMES`). SelfPropulsion (absolute frame
  only), Drift, Noise.
* ``step_radius(v)`` – a :class:`StepRadius`, the spectral radius of its Jacobian at the
  velocities ``v`` (the stable-step hint of a stopped run). SelfPropulsion, Drift, Noise.
* ``certificate_form()`` – a :class:`CertificateForm` of :data:`EFFECT_FORMS`. SelfPropulsion,
  Drift.
* ``theorem_constants(speed=, diam_x=, diam_v=)`` – :class:`TheoremConstants`.
  SelfPropulsion, Drift (noise is outside the theorems whatever it declares).

A subclass inherits its parent's hooks: a subclass that changes the field must override
them (or set them to None).

Examples
--------
>>> from kinred.dynamics import CuckerSmale, Morse, SelfPropulsion
>>> is_nonnegative(CuckerSmale()), is_nonnegative(Morse()), potential_range(Morse(1.0, 2.0, 1.5))
(True, None, 2.5)
>>> certificate_form(CuckerSmale(0.8, 1.5), KERNEL_FORMS)
CertificateForm(kind='cucker_smale', params=(0.8, 1.5))
>>> energy_term(SelfPropulsion(1.0, 0.5), frame="centred", target="v", dim=2) is None
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidInput

__all__ = ["EnergyTerm", "StepRadius", "CertificateForm", "TheoremConstants", "FRAMES",
           "KERNEL_FORMS", "EFFECT_FORMS", "is_nonnegative", "potential_range", "energy_term",
           "step_radius", "certificate_form", "theorem_constants"]

#: The frames of the guard's quantity ``Q``: ``"centred"``, ``Q = Σᵢ wᵢ‖vᵢ − v̄‖²`` (the
#: velocity fluctuation Γ, unchanged by a common velocity), or ``"absolute"``,
#: ``Q = Σᵢ wᵢ‖vᵢ‖²``. The guard uses the centred frame when every effect has a term there.
FRAMES = ("centred", "absolute")

#: The closed forms a kernel may declare through ``certificate_form()``, with their
#: parameters: ``G (1 + s²)^(−β)``; ``U′(r)/r`` of the Morse potential with
#: ``r = √(s² + soft²)`` (eq. (3.14)); the constant ``c``.
KERNEL_FORMS = {"cucker_smale": ("G", "beta"), "morse": ("Ca", "la", "Cr", "lr", "soft"),
                "quadratic": ("c",)}

#: The per-agent forms an effect may declare through ``certificate_form()``:
#: ``(a − b‖vᵢ‖²) vᵢ`` (eq. (3.14)) and a constant drift (which cancels in the error).
EFFECT_FORMS = {"self_propulsion": ("a", "b"), "drift": ()}

_SOURCES = ("x", "v", "speed")
_POSITIVE = {"la", "lr"}                                   # lengths; all others >= 0 but c, a
_SIGNED = {"c", "a"}


@dataclass(frozen=True)
class EnergyTerm:
    r"""What one effect adds to the a-priori bound of the divergence guard.

    The guard bounds ``Q(t)`` (see :data:`FRAMES`) of the exact flow from every earlier
    time ``s``: ``Q(t) ≤ Q(s) + Δ + p (t − s)`` when ``κ = 0``, else
    ``Q(t) + p/(2κ) ≤ (Q(s) + Δ + p/(2κ)) e^{2κ(t − s)}``, with ``(Δ, p, κ)`` the sums of the
    effects' terms. An effect whose contribution obeys ``dQ/dt ≤ 2κ Q + p`` up to an
    exchange of at most ``Δ`` with a bounded energy returns these three numbers.

    Attributes
    ----------
    delta : float
        ``Δ ≥ 0``: energy traded with a bounded potential.
    p : float
        ``p ≥ 0``: energy added per unit time (noise: in expectation).
    kappa : float
        ``κ ≥ 0``: growth rate (``dQ/dt ≤ 2κQ``).
    why : str
        One clause for the guard's message ("" adds none).
    """

    delta: float = 0.0
    p: float = 0.0
    kappa: float = 0.0
    why: str = ""


@dataclass(frozen=True)
class StepRadius:
    """A Gershgorin bound of the spectral radius of an effect's Jacobian at the given state.

    Attributes
    ----------
    rho : float
        ``ρ̂ ≥ 0``; an explicit method is stable on it for ``dt < β_m/ρ̂``.
    why : str
        How it was obtained ("" for effects with no Jacobian, e.g. a constant drift).
    """

    rho: float = 0.0
    why: str = ""


@dataclass(frozen=True)
class CertificateForm:
    """A closed form known to the certificates: ``kind`` in :data:`KERNEL_FORMS` (kernels) or
    :data:`EFFECT_FORMS` (per-agent effects), ``params`` its parameters in that order.

    Declaring one promises that the kernel (effect) equals that closed form.
    """

    kind: str
    params: tuple = ()


@dataclass(frozen=True)
class TheoremConstants:
    """Constants one per-agent effect contributes to (1.2)–(1.4) and to the stability rate Λ
    of the theorem bound (see :class:`kinred.kinetic.EffectConstants`).

    Attributes
    ----------
    L, Lp, Lpp : float
        Contributions to ``L`` (1.2), to a velocity row of (1.3) and to ``L″`` (1.4).
    lip_state, lip_measure : float
        Lipschitz constants of the field in the particle state and in the measure (W1).
    sources : tuple of str
        Distances the effect depends on: ``"x"``, ``"v"``, ``"speed"`` (``‖vᵢ‖``).
    formula : str
        How the numbers were obtained.
    """

    L: float
    Lp: float
    Lpp: float
    lip_state: float
    lip_measure: float
    sources: tuple = ()
    formula: str = ""


def _ask(obj, hook: str, what: str, *args, **kwargs):
    """``obj.hook(*args, **kwargs)``, or None when ``obj`` has no such method."""
    fn = getattr(obj, hook, None)
    if fn is None:
        return None
    if not callable(fn):
        raise InvalidInput(f"{obj!r}.{hook} must be a method returning None or {what}, "
                           f"got {fn!r}")
    return fn(*args, **kwargs)


def _bad(obj, hook: str, got, what: str) -> InvalidInput:
    return InvalidInput(f"{obj!r}.{hook}() returned {got!r}; valid: None (unknown) or {what}")


def _nonneg_numbers(obj, hook, out, names, what, *, inf=False) -> None:
    for name in names:
        val = getattr(out, name)
        ok = isinstance(val, (int, float, np.floating, np.integer)) and not isinstance(val, bool)
        if not ok or math.isnan(val) or val < 0 or (not inf and math.isinf(val)):
            raise _bad(obj, hook, out, f"{what} ({name} must be a number >= 0"
                                       f"{'' if inf else ', finite'})")


def is_nonnegative(kernel) -> bool | None:
    """True when the kernel declares ``φ ≥ 0`` everywhere (``kernel.is_nonnegative()``);
    False when it declares a sign change; None when unknown."""
    out = _ask(kernel, "is_nonnegative", "True/False")
    if out is None or isinstance(out, (bool, np.bool_)):
        return None if out is None else bool(out)
    raise _bad(kernel, "is_nonnegative", out, "True or False")


def potential_range(kernel) -> float | None:
    """``sup U − inf U`` of the kernel's potential (``kernel.potential_range()``), or None."""
    out = _ask(kernel, "potential_range", "a float >= 0")
    if out is None:
        return None
    ok = isinstance(out, (int, float, np.floating, np.integer)) and not isinstance(out, bool)
    if not ok or not math.isfinite(out) or out < 0:
        raise _bad(kernel, "potential_range", out, "a finite float >= 0")
    return float(out)


def energy_term(effect, *, frame: str, target: str, dim: int) -> EnergyTerm | None:
    """The effect's :class:`EnergyTerm` in ``frame`` (:data:`FRAMES`) when it acts on
    ``target`` (``"x"`` or ``"v"``) in ``ℝ^dim`` (``effect.energy_term(...)``), or None."""
    if frame not in FRAMES:
        raise InvalidInput(f"frame must be one of {FRAMES}, got {frame!r}")
    out = _ask(effect, "energy_term", "an EnergyTerm", frame=frame, target=target, dim=dim)
    if out is None:
        return None
    if not isinstance(out, EnergyTerm) or not isinstance(out.why, str):
        raise _bad(effect, "energy_term", out, "an EnergyTerm")
    _nonneg_numbers(effect, "energy_term", out, ("delta", "p", "kappa"), "an EnergyTerm")
    return out


def step_radius(effect, v) -> StepRadius | None:
    """The effect's :class:`StepRadius` at velocities ``v (N, d)`` (None in first-order
    scenes) (``effect.step_radius(v)``), or None."""
    out = _ask(effect, "step_radius", "a StepRadius", v)
    if out is None:
        return None
    if not isinstance(out, StepRadius) or not isinstance(out.why, str):
        raise _bad(effect, "step_radius", out, "a StepRadius")
    _nonneg_numbers(effect, "step_radius", out, ("rho",), "a StepRadius", inf=True)
    return out


def certificate_form(obj, forms: dict) -> CertificateForm | None:
    """The :class:`CertificateForm` of a kernel or effect (``obj.certificate_form()``), checked
    against ``forms`` (:data:`KERNEL_FORMS` or :data:`EFFECT_FORMS`), or None."""
    out = _ask(obj, "certificate_form", "a CertificateForm")
    if out is None:
        return None
    valid = ", ".join(f"{k}{v}" for k, v in forms.items())
    if not isinstance(out, CertificateForm) or out.kind not in forms:
        raise _bad(obj, "certificate_form", out, f"a CertificateForm of kind: {valid}")
    params, names = tuple(out.params), forms[out.kind]
    if (len(params) != len(names)
            or not all(isinstance(p, (int, float, np.floating, np.integer))
                       and not isinstance(p, bool) and math.isfinite(p) for p in params)
            or any(p < 0 or (p == 0 and n in _POSITIVE)
                   for p, n in zip(params, names) if n not in _SIGNED)):
        raise _bad(obj, "certificate_form", out,
                   f"{out.kind!r} with the finite parameters {names} (la, lr > 0; all others "
                   f"but c and a >= 0)")
    return CertificateForm(out.kind, tuple(float(p) for p in params))


def theorem_constants(effect, *, speed: float, diam_x: float,
                      diam_v: float) -> TheoremConstants | None:
    """The effect's :class:`TheoremConstants` given the speed bound ``β_v`` and the support
    diameters (``effect.theorem_constants(...)``), or None."""
    out = _ask(effect, "theorem_constants", "TheoremConstants", speed=speed, diam_x=diam_x,
               diam_v=diam_v)
    if out is None:
        return None
    if (not isinstance(out, TheoremConstants) or not isinstance(out.formula, str)
            or not all(s in _SOURCES for s in out.sources)):
        raise _bad(effect, "theorem_constants", out,
                   f"TheoremConstants with sources among {_SOURCES}")
    _nonneg_numbers(effect, "theorem_constants", out,
                    ("L", "Lp", "Lpp", "lip_state", "lip_measure"), "TheoremConstants",
                    inf=True)
    return out
