"""A kernel and an effect written outside kinred, as a newcomer would (values plus the hooks of
:mod:`kinred.dynamics.hooks`), are guarded by ``simulate``, certified by ``certify`` and
bounded by ``theorem_bound`` end to end; without the hooks they are honestly unknown.

The file to copy for a new kernel (see docs/architecture.md, "Extension points").
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinred.certify import certify
from kinred.dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Effect, Field, Scene,
                             SelfPropulsion, hooks)
from kinred.dynamics.hooks import CertificateForm, EnergyTerm, StepRadius, TheoremConstants
from kinred.errors import InvalidInput, NotProjectable, SimulationDiverged
from kinred.integrate import SaveAt, simulate
from kinred.integrate._guard import energy_budget
from kinred.kinetic import compare, effect_constants, reduce, solve, theorem_bound
from kinred.measures import Atomic
from kinred.projection import jl_matrix


class Gauss:
    r"""``φ(s) = A exp(−s²/ℓ²)``: a kernel kinred does not know, with its hooks."""

    def __init__(self, A: float, ell: float):
        self.A, self.ell = float(A), float(ell)

    def __call__(self, s):
        s = np.asarray(s, dtype=float)
        return self.A * np.exp(-(s / self.ell) ** 2)

    def _slope(self, s):
        s = np.asarray(s, dtype=float)
        with np.errstate(invalid="ignore", over="ignore"):
            out = 2.0 * self.A * s / self.ell ** 2 * np.exp(-(s / self.ell) ** 2)
        return np.where(np.isfinite(s), out, 0.0)

    # -- the guard: alignment with φ ≥ 0 dissipates; U(s) = −(Aℓ²/2) e^{−s²/ℓ²}, U′ = s φ
    def is_nonnegative(self):
        return True

    def potential_range(self):
        return 0.5 * self.A * self.ell ** 2

    # -- the certificate: |φ′| = 2As/ℓ² e^{−s²/ℓ²} is unimodal with its peak at ℓ/√2
    def slope_bound(self, lo, hi):
        lo, hi = np.broadcast_arrays(np.asarray(lo, float), np.asarray(hi, float))
        peak = self.ell / math.sqrt(2.0)
        return np.where((lo <= peak) & (peak <= hi), self.lipschitz(),
                        np.maximum(self._slope(lo), self._slope(hi)))

    # -- the theorem bound: ‖φ‖∞ and ‖φ′‖∞
    def sup_norm(self):
        return self.A

    def lipschitz(self):
        return float(self._slope(self.ell / math.sqrt(2.0)))

    def __repr__(self):
        return f"Gauss(A={self.A}, ell={self.ell})"


class Bare:
    """The same values without any hook: a kernel of unknown sign and constants."""

    def __init__(self, kernel):
        self.kernel = kernel

    def __call__(self, s):
        return self.kernel(s)

    def __repr__(self):
        return f"Bare({self.kernel!r})"


class Rational:
    """``A/(1 + s²)``, declaring that it is Cucker–Smale with ``β = 1`` to the certificates."""

    def __init__(self, A):
        self.A = float(A)

    def __call__(self, s):
        s = np.asarray(s, dtype=float)
        return self.A / (1.0 + s * s)

    def slope_bound(self, lo, hi):
        return CuckerSmale(self.A, 1.0).slope_bound(lo, hi)

    def sup_norm(self):
        return self.A

    def lipschitz(self):
        return CuckerSmale(self.A, 1.0).lipschitz()

    def certificate_form(self):
        return CertificateForm("cucker_smale", (self.A, 1.0))


class Friction(Effect):
    """``v̇ᵢ += −γ vᵢ``: a per-agent effect kinred does not know, with its hooks."""

    target = "v"
    projectable = True
    translation_invariant = True

    def __init__(self, gamma):
        self.gamma = float(gamma)

    def drift(self, x, v, t):
        return -self.gamma * v

    def project(self, M):
        return self

    def energy_term(self, *, frame, target, dim):
        return EnergyTerm(why="friction only dissipates it")     # dQ/dt = −2γQ in both frames

    def step_radius(self, v):
        return StepRadius(self.gamma, f"friction γ = {self.gamma:g}")

    def certificate_form(self):
        return CertificateForm("self_propulsion", (-self.gamma, 0.0))   # (a − b|v|²)v, b = 0

    def theorem_constants(self, *, speed, diam_x, diam_v):
        g = self.gamma
        return TheoremConstants(0.0, g, 0.0, g, 0.0, ("speed",), f"friction: L'+={g}, Lip={g}")

    def __repr__(self):
        return f"Friction({self.gamma})"


class BareFriction(Friction):
    """The same field with every hook set to None (unknown)."""

    energy_term = step_radius = certificate_form = theorem_constants = None


def _data(N, d, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (N, d)), rng.uniform(-1, 1, (N, d))


# ------------------------------------------------------------------------------ guarded
def test_a_new_kernel_is_guarded_and_its_hint_runs():
    # Euler with h·ρ(L) > 2: Γ of the exact flow never grows, the computed one does. Known
    # kernel: stopped at the first step; the hint's step runs and Γ never grows.
    x0, v0 = _data(100, 20)
    sc = Scene([Alignment(Gauss(0.3, 2.0)), Friction(0.1)], "sum")
    b = energy_budget(sc, 100, 20)
    assert b.centred and (b.delta, b.p, b.kappa) == (0.0, 0.0, 0.0)
    with pytest.raises(SimulationDiverged) as info:
        simulate(sc, x0, v0, (0, 30), 0.2, save=SaveAt(every=10))
    e = info.value
    msg = str(e)
    assert e.step <= 3 and "velocity fluctuation Γ" in msg
    assert "alignment with g >= 0 only dissipates it" in msg and "friction only dissipates" in msg
    # the hint: Gershgorin 2 maxᵢ Σⱼ cⱼ gᵢⱼ of the alignment plus the friction's γ
    assert "friction γ = 0.1" in msg and 0.01 < e.stable_dt < 0.2
    dt = 30 / math.ceil(30 / e.stable_dt)
    g = simulate(sc, x0, v0, (0, 30), dt, save=SaveAt(every=10)).observables["gamma"]
    assert np.all(np.diff(g) <= 1e-12 * g[0]) and g[-1] < 1e-3 * g[0]


def test_a_new_potential_enters_the_energy_budget():
    # AttractionRepulsion(Gauss): Δ = Σⱼcⱼ·(sup U − inf U) = N·Aℓ²/2 under "sum"
    sc = Scene([AttractionRepulsion(Gauss(2.0, 1.5)), Friction(0.5)], "sum")
    b = energy_budget(sc, 30, 3)
    assert b.delta == pytest.approx(30 * 0.5 * 2.0 * 1.5 ** 2, rel=1e-15)
    x0, v0 = _data(30, 3)
    tr = simulate(sc, x0, v0, (0, 5), 0.01, save=SaveAt(every=100))       # stable: runs
    assert tr.observables["gamma"][-1] <= tr.observables["gamma"][0] + b.delta
    # a huge amplitude: one Euler step flings the agents far beyond the energy budget
    big = Scene([AttractionRepulsion(Gauss(1e6, 1.5))], "mean")
    with pytest.raises(SimulationDiverged) as info:
        simulate(big, x0, v0, (0, 5), 0.5)
    assert info.value.step == 1 and "Gauss potential trades at most" in str(info.value)


def test_unknown_kernels_and_effects_are_checked_for_non_finite_states_only():
    # the same fields without hooks: no budget, so the guard cannot tell; the unstable run
    # returns a Γ that grew (what happens for every unknown scene, kept)
    x0, v0 = _data(100, 20)
    for sc in (Scene([Alignment(Bare(Gauss(0.3, 2.0))), Friction(0.1)], "sum"),
               Scene([Alignment(Gauss(0.3, 2.0)), BareFriction(0.1)], "sum")):
        assert energy_budget(sc, 100, 20) is None
        g = simulate(sc, x0, v0, (0, 30), 0.2, save=SaveAt(every=10)).observables["gamma"]
        assert g.max() > 10 * g[0]
    # and the hint says it has no estimate for the unknown effect
    sc = Scene([Alignment(Gauss(1e3, 2.0)), BareFriction(0.1)], "sum")
    big_v = 1e150 * v0
    with pytest.raises(SimulationDiverged, match=r"no estimate for BareFriction|"
                                                 r"no estimate for Friction"):
        simulate(sc, x0, big_v, (0, 30), 0.2)


# ----------------------------------------------------------------------------- certified
def test_a_new_kernel_and_effect_are_certified():
    rng = np.random.default_rng(3)
    N, d, k = 40, 20, 5
    x0, v0 = rng.normal(size=(N, d)), rng.normal(size=(N, d))
    M = rng.normal(0, 1 / np.sqrt(k), (k, d))
    run = dict(t_span=(0, 2), dt=0.05, save=SaveAt(every=10))
    cert = certify(Scene([Alignment(Gauss(1.0, 3.0)), Friction(0.2)]), M, x0, v0, **run)
    assert cert.valid and np.all(cert.bound >= cert.error) and np.all(cert.error[1:] > 0)
    assert 1.0 <= cert.worst_ratio_after(1.0) < 1.5              # measured 1.23
    # the friction declares itself as self-propulsion (a, b) = (−γ, 0): the same numbers
    ref = certify(Scene([Alignment(Gauss(1.0, 3.0)), SelfPropulsion(-0.2, 0.0)]), M, x0, v0,
                  **run)
    for name in ("bound", "error", "bound_max", "paper_bound_max"):
        assert np.array_equal(getattr(cert, name), getattr(ref, name)), name
    # a kernel declaring the Cucker–Smale form runs in the compiled pass and gets the paper's
    # Cucker–Smale bound (2.18): the numbers of CuckerSmale(A, 1) up to the engines' rounding
    mine = certify(Scene([Alignment(Rational(1.0))]), M, x0, v0, **run)
    cs = certify(Scene([Alignment(CuckerSmale(1.0, 1.0))]), M, x0, v0, **run)
    assert np.all(np.isfinite(mine.paper_bound[1:]))
    assert np.allclose(mine.paper_bound, cs.paper_bound, rtol=1e-9, atol=0)
    assert np.allclose(mine.bound, cs.bound, rtol=1e-9, atol=0)


def test_uncertifiable_without_hooks():
    x0, v0 = _data(8, 4)
    M = jl_matrix(2, 4, seed=1)
    with pytest.raises(NotProjectable, match="BareFriction|not covered by certificates"):
        certify(Scene([Alignment(), BareFriction(0.1)]), M, x0, v0, t_span=(0, 1), dt=0.1)
    with pytest.raises(NotProjectable, match="slope_bound"):
        certify(Scene([Alignment(Bare(Gauss(1.0, 1.0)))]), M, x0, v0, t_span=(0, 1), dt=0.1)
    # no Cucker–Smale form: no paper bound (2.18), NaN as for any other kernel
    cert = certify(Scene([Alignment(Gauss(1.0, 3.0))]), M, x0, v0, t_span=(0, 1), dt=0.1)
    assert np.all(np.isnan(cert.paper_bound))


# ------------------------------------------------------------------------------- bounded
def test_a_new_kernel_and_effect_are_bounded():
    rng = np.random.default_rng(2)
    mu0 = Atomic(np.hstack([rng.uniform(0, 1, (12, 6)), rng.uniform(-1, 1, (12, 6))]))
    sc = Scene([Alignment(Gauss(1.0, 2.0)), Friction(0.3)])
    sol = solve(sc, mu0, t_span=(0, 1), dt=0.05, save_every=5)
    red = reduce(sol, M=jl_matrix(2, 6, seed=4))
    tb = theorem_bound(sol, red)
    assert tb.covered and np.all(np.isfinite(tb.bound))
    measured = compare(sol, red).w1
    assert np.all(measured <= tb.term_jl + 1e-14) and np.all(measured[1:] > 0)
    # the constants: L′ = max(1, 2‖φ‖∞ + γ), L″ = 2‖φ′‖∞ (Friction adds 0), Λ = 1 + Σ
    g = Gauss(1.0, 2.0)
    assert np.allclose(tb.Lp, max(1.0, 2.0 * g.A + 0.3), rtol=1e-15)
    assert np.allclose(tb.Lpp, 2.0 * g.lipschitz(), rtol=1e-15)
    want = 1.0 + 2.0 * (g.A + g.lipschitz() * tb.diam_v) + 0.3
    assert np.allclose(tb.Lambda, want, rtol=1e-14)
    # the speed ‖vᵢ‖ is a distance the friction depends on: ε_JL includes the speeds' distortion
    free = theorem_bound(*(lambda s: (s, reduce(s, M=jl_matrix(2, 6, seed=4))))(
        solve(Scene([Alignment(Gauss(1.0, 2.0))]), mu0, t_span=(0, 1), dt=0.05,
              save_every=5)))
    assert np.all(tb.eps_jl >= free.eps_jl) and np.any(tb.eps_jl > free.eps_jl)


def test_unknown_effects_have_unknown_constants():
    c = effect_constants(BareFriction(0.3), speed=2.0)
    assert math.isinf(c.Lp) and "unknown" in c.formula
    c = effect_constants(Friction(0.3), speed=2.0)
    assert (c.Lp, c.lip_state, c.sources) == (0.3, 0.3, ("speed",))
    rng = np.random.default_rng(2)
    mu0 = Atomic(np.hstack([rng.uniform(0, 1, (6, 4)), rng.uniform(-1, 1, (6, 4))]))
    sol = solve(Scene([Alignment(), BareFriction(0.3)]), mu0, t_span=(0, 1), dt=0.1,
                save_every=5)
    tb = theorem_bound(sol, reduce(sol, M=jl_matrix(2, 4, seed=4)))
    assert not tb.covered and not np.any(np.isfinite(tb.bound[1:])) and "unknown" in tb.note
    assert tb.C[0] == 1.0                         # was exp(inf·0) = nan with a RuntimeWarning


# --------------------------------------------------------------------- the hooks' contract
def test_built_in_hooks_declare_todays_numbers():
    from kinred.dynamics import Drift, Morse, Noise, Quadratic

    assert hooks.is_nonnegative(CuckerSmale()) is True
    assert hooks.is_nonnegative(Quadratic(-1.0)) is False
    assert hooks.is_nonnegative(Morse()) is None and hooks.potential_range(Quadratic()) is None
    assert hooks.potential_range(Morse(1.0, 2.0, 1.5, 0.5)) == 2.5
    assert hooks.certificate_form(Morse(1.0, 2.0, 1.5, 0.5, soft=0.1), hooks.KERNEL_FORMS) == \
        CertificateForm("morse", (1.0, 2.0, 1.5, 0.5, 0.1))
    sp = SelfPropulsion(1.0, 0.5)
    assert hooks.energy_term(sp, frame="centred", target="v", dim=3) is None
    assert hooks.energy_term(sp, frame="absolute", target="v", dim=3).p == 1.0   # a²/(2b)
    assert hooks.energy_term(SelfPropulsion(2.0, 0.0), frame="absolute", target="v",
                             dim=3).kappa == 2.0
    # a subnormal b: a²/(2b) overflows; the growth-rate bound κ = a holds for every b ≥ 0
    # (hypothesis found b = 2.2250738585e-313 in test_certify, where the hook returned p = inf)
    tiny = hooks.energy_term(SelfPropulsion(1.0, 2.2250738585e-313), frame="absolute",
                             target="v", dim=1)
    assert (tiny.p, tiny.kappa) == (0.0, 1.0)
    assert hooks.energy_term(Noise(0.5), frame="centred", target="v", dim=4).p == 1.0
    assert hooks.energy_term(Noise(0.5), frame="centred", target="x", dim=4) is None
    dr = Drift([3.0, 4.0])
    assert hooks.energy_term(dr, frame="centred", target="v", dim=2) == EnergyTerm()
    assert hooks.energy_term(dr, frame="absolute", target="v", dim=2).p == 25.0
    v = np.array([[2.0, 0.0]])
    assert hooks.step_radius(sp, v).rho == 5.0               # |a − 3b|v|²| = |1 − 6|
    assert hooks.step_radius(dr, v) == StepRadius() and hooks.step_radius(Field(abs), v) is None
    assert hooks.theorem_constants(dr, speed=1.0, diam_x=0.0, diam_v=0.0).Lp == 0.0


class _Liar:
    def __init__(self, **answers):
        for name, val in answers.items():
            setattr(self, name, (lambda val: lambda *a, **k: val)(val))


@pytest.mark.parametrize("reader,answer,match", [
    (lambda o: hooks.is_nonnegative(o), {"is_nonnegative": "yes"}, "True or False"),
    (lambda o: hooks.potential_range(o), {"potential_range": -1.0}, "finite float >= 0"),
    (lambda o: hooks.potential_range(o), {"potential_range": math.inf}, "finite float >= 0"),
    (lambda o: hooks.energy_term(o, frame="centred", target="v", dim=2),
     {"energy_term": EnergyTerm(p=-1.0)}, "p must be a number >= 0"),
    (lambda o: hooks.energy_term(o, frame="centred", target="v", dim=2),
     {"energy_term": (0.0, 0.0, 0.0)}, "an EnergyTerm"),
    (lambda o: hooks.step_radius(o, np.zeros((1, 2))), {"step_radius": 3.0}, "a StepRadius"),
    (lambda o: hooks.certificate_form(o, hooks.KERNEL_FORMS),
     {"certificate_form": CertificateForm("gauss", (1.0,))}, "of kind: cucker_smale"),
    (lambda o: hooks.certificate_form(o, hooks.KERNEL_FORMS),
     {"certificate_form": CertificateForm("morse", (1.0, 0.0, 1.0, 1.0, 0.0))}, "la, lr > 0"),
    (lambda o: hooks.certificate_form(o, hooks.EFFECT_FORMS),
     {"certificate_form": CertificateForm("self_propulsion", (1.0,))}, r"\('a', 'b'\)"),
    (lambda o: hooks.theorem_constants(o, speed=1.0, diam_x=0.0, diam_v=0.0),
     {"theorem_constants": TheoremConstants(0, 1, 0, 1, 0, ("y",))}, "sources among"),
    (lambda o: hooks.theorem_constants(o, speed=1.0, diam_x=0.0, diam_v=0.0),
     {"theorem_constants": TheoremConstants(0, math.nan, 0, 1, 0)}, "Lp must be a number"),
])
def test_a_hook_returning_nonsense_is_named(reader, answer, match):
    with pytest.raises(InvalidInput, match=match) as info:
        reader(_Liar(**answer))
    assert next(iter(answer)) in str(info.value)


def test_a_hook_that_is_not_a_method_is_refused_and_frames_are_checked():
    class K:
        is_nonnegative = True

    with pytest.raises(InvalidInput, match=r"is_nonnegative must be a method"):
        hooks.is_nonnegative(K())
    with pytest.raises(InvalidInput, match=r"frame must be one of \('centred', 'absolute'\)"):
        hooks.energy_term(Friction(1.0), frame="lab", target="v", dim=2)
