r"""The per-step machinery of a certificate: an observer of the high-dimensional Euler run.

:class:`CertificateObserver` follows the observer protocol of
:func:`kinred.integrate.simulate` (``init(t0, state, scene)``, then ``update(t, state, scene)``
after every accepted step, ``state`` a read-only :class:`~kinred.integrate.StepState` with
``.x``, ``.v`` in the integrator's working coordinates – positions relative to
``state.shift`` when it is not None – and ``.step``, ``.h``). It steps the projected scene
alongside with :func:`~kinred.integrate.simulate`'s own pieces – its working frame
(:func:`~kinred.integrate.working_frame`), its Euler solver (``ExplicitRK(EULER)``) and the
times the run reports – so that the projected run is bit-identical to
``simulate(scene.project(M), *project_state(M, x0, v0))``, and propagates the bounds of
``docs/certificates.md``:

* the defects ``τₓ = PX⁺ − PX − h PV`` and ``τᵥ = PV⁺ − PV − h F′(PX, PV)`` of the projected
  high-dimensional trajectory ``(PX, PV) = (M x, M v)`` in the projected Euler scheme, kept
  as vectors (``F′(PX, PV)``'s pair sums from the pair pass below, its per-agent effects
  from the projected scene; ``M x``, ``M v`` projected once per step and reused as the next
  step's start);
* the stability of the projected Euler map between ``(PX, PV)`` and the projected run
  ``(Y, W)``, from the same pair pass (:mod:`kinred.certify._aggregates`);
* a weighted-RMS recursion (mean and fluctuation parts) and a per-agent (ℓ∞) recursion,
  each capped by the other after every step.

The recursion never uses the measured error: errors are measured at the saved steps only, to
be reported beside the bounds.
"""

from __future__ import annotations

import math

import numpy as np

from .._validate import as_array, as_choice
from .. import _parallel
from ..dynamics import Scene
from ..errors import InvalidInput, SimulationDiverged
from ..integrate import EULER, ExplicitRK, VectorField, working_frame
from ..projection import as_projection
from . import _roundoff as _ro
from ._aggregates import pair_pass, pair_pass_numpy
from ._paper import PaperTracker
from ._plan import make_plan

__all__ = ["CertificateObserver"]


def _wnorm(A: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """``(|Σᵢ wᵢ Aᵢ|, (Σᵢ wᵢ |Aᵢ − Ā|²)^{1/2})``: weighted mean size and fluctuation norm."""
    m = w @ A
    dev = A - m
    dev -= w @ dev
    return float(np.sqrt(m @ m)), float(np.sqrt(w @ np.einsum("ij,ij->i", dev, dev)))


def _project(P, X: np.ndarray) -> np.ndarray:
    """``P.apply(X)`` by row blocks on the engine's threads, BLAS single-threaded (outside
    the engine's parallel regions a multithreaded BLAS contends with the engine's pool)."""
    n = X.shape[0]
    nt = min(_parallel.get_num_threads(), max(1, n * X.shape[1] * P.k // 2_000_000))
    if nt <= 1:
        with _parallel.blas_threads(1):
            return P.apply(X)
    out = np.empty((n, P.k))
    cuts = np.linspace(0, n, nt + 1).astype(int)

    def work(g, rows):
        out[rows[0]:rows[1]] = P.apply(X[rows[0]:rows[1]])

    _parallel.run_parallel(work, [(cuts[g], cuts[g + 1]) for g in range(nt)])
    return out


def _rows(A: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", A, A))


def _segment_min(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Per row, the distance from 0 to the segment ``[Pᵢ, Qᵢ]``."""
    D = Q - P
    dd = np.einsum("ij,ij->i", D, D)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(dd > 0, -np.einsum("ij,ij->i", P, D) / dd, 0.0)
    s = np.clip(s, 0.0, 1.0)
    return _rows(P + s[:, None] * D)


class _Field(VectorField):
    """The projected scene's field, keeping its last evaluation ``(dy, dw)`` (the certificate's
    round-off allowance needs ``|dw|`` of the step)."""

    last = None

    def _evaluate(self, t, x, v, rng, out):
        self.last = super()._evaluate(t, x, v, rng, out)
        return self.last


class CertificateObserver:
    """Certificate of a projected run, as an observer of the high-dimensional Euler run.

    Attach it to ``simulate(scene, x0, v0, t_span, dt, method="euler",
    observers=[obs])`` (what :func:`~kinred.certify.certify` does), then read
    :meth:`records`.

    Parameters
    ----------
    scene : Scene
        The high-dimensional scene (second order, deterministic, covered effects only).
    M : (k, d) ndarray or Projection
    x0, v0 : (N, d) array_like
        The run's initial positions and velocities (absolute): the projected run starts from
        ``M x0``, ``M v0``.
    save_steps : array_like of int, optional
        Step indices at which to record (default: every step).
    engine : {"fast", "numpy"}
        Pair pass: compiled kernels or the plain-numpy twin.
    paper : bool
        Also evaluate the paper's a-priori bounds (eq. (2.11) and (2.18)) at the saved steps
        (one high-dimensional pair pass per saved step).
    states : bool or {"x", "v"}
        Also keep the projected run's states at the saved steps (``True``: both;
        ``records()["y"]``, absolute positions, and ``["w"]``, velocities), as
        ``simulate(scene.project(M), ..., save=SaveAt(states=...))`` would record them.

    Attributes
    ----------
    methods : tuple of str
        ``("euler",)``: the derivation covers forward Euler with a fixed step only;
        ``simulate`` refuses other methods, and :meth:`update` refuses steps of changing
        size.

    Raises
    ------
    InvalidInput
        Bad arguments, first-order scenes.
    NotProjectable
        Effects the certificate does not cover (see :func:`~kinred.certify.certify`).

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> from kinred.integrate import simulate
    >>> rng = np.random.default_rng(0)
    >>> x0, v0 = rng.normal(size=(30, 20)), rng.normal(size=(30, 20))
    >>> M = rng.normal(0, 1 / np.sqrt(5), (5, 20))
    >>> scene = Scene([Alignment(CuckerSmale(1.0, 0.4))])
    >>> obs = CertificateObserver(scene, M, x0, v0, save_steps=[0, 40], paper=False)
    >>> tr = simulate(scene, x0, v0, (0, 2), 0.05, observers=[obs])
    >>> rec = obs.records()
    >>> rec["step"].tolist(), bool(np.all(rec["bound"] >= rec["error"]))
    ([0, 40], True)
    """

    methods = ("euler",)

    def __init__(self, scene, M, x0, v0, *, save_steps=None, engine: str = "fast",
                 paper: bool = True, states=False):
        if not isinstance(scene, Scene):
            raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
        self.scene = scene
        self.P = as_projection(M)
        self.engine = as_choice(engine, "engine", ("fast", "numpy"))
        x0 = as_array(x0, "x0", ndim=2)
        if x0.shape[0] < 1 or x0.shape[1] < 1:
            raise InvalidInput(f"x0 must have at least one agent and one dimension, got "
                               f"{x0.shape}")
        self.plan = make_plan(scene, x0.shape[0])     # refuse uncovered effects before work
        if v0 is None:
            raise InvalidInput("v0 must be given: certificates are for second-order scenes "
                               "(positions and velocities)")
        self.x0, self.v0 = x0, as_array(v0, "v0", shape=x0.shape)
        if self.P.d != x0.shape[1]:
            raise InvalidInput(f"M must have d = {x0.shape[1]} columns (x0's dimension), got "
                               f"shape {self.P.shape}")
        scene._check_state(self.x0, self.v0)
        self.save_steps = None if save_steps is None else {int(s) for s in save_steps}
        if not isinstance(paper, (bool, np.bool_)):
            raise InvalidInput(f"paper must be True or False, got {paper!r}")
        self.paper = bool(paper)
        if states not in (True, False, "x", "v"):
            raise InvalidInput(f"states must be True, False, 'x' or 'v'; got {states!r}")
        self.keep = {"y": states in (True, "x"), "w": states in (True, "v")}

    def __repr__(self) -> str:
        return (f"CertificateObserver(N={self.x0.shape[0]}, d={self.P.d}, k={self.P.k}, "
                f"engine={self.engine!r})")

    # ------------------------------------------------------------------ set-up
    def init(self, t0: float, state, scene) -> None:
        """Start from the working state ``state`` (step 0) of the initial data."""
        P, scene = self.P, self._check_run(state, scene)
        if state.step != 0:
            raise InvalidInput(f"init must see step 0, got step {state.step}")
        n, d = self.x0.shape
        self.pscene = scene.project(P)
        self.w = scene.agent_weights(n)
        self.c = scene.coefficients(n)
        self.t0 = self.t = float(t0)
        self.h = None
        self.n, self.k = n, P.k
        self.mixed = scene.precision == "mixed"
        # the projected run, as simulate(pscene, M x0, M v0) starts and steps it
        self.Y, self.W, self.shift_y = working_frame(self.pscene, P.apply(self.x0),
                                                     P.apply(self.v0))
        self.field, self.solver = _Field(self.pscene), ExplicitRK(EULER)
        self.solver_state = self.solver.init(self.field, self.t0, (self.Y, self.W), None)
        # constant offset between the working frames: e = (Y − PX) + (c_y − M c_x)
        pf = math.sqrt(float(np.sum(P.to_dense() ** 2)))     # ‖M‖_F ≥ ‖ |M| ‖₂
        self.proj_round = _ro.gamma(d) * pf                   # |fl(M z) − M z| ≤ this·|z|
        if state.shift is not None and self.shift_y is not None:
            pc = P.apply(state.shift)
            self.delta_c = self.shift_y - pc
            self.rho_c = (self.proj_round * float(np.linalg.norm(state.shift))
                          + 2 * _ro.U64 * (float(np.linalg.norm(self.shift_y))
                                           + float(np.linalg.norm(pc))))
        else:
            self.delta_c = np.zeros(self.k)
            self.rho_c = 0.0
        self.PX = _project(P, state.x)
        self.PV = _project(P, state.v)
        e0 = self.Y - self.PX + self.delta_c
        v0e = self.W - self.PV
        u4 = 4.0 * _ro.U64
        self.bx = _rows(e0) * (1 + u4) + self.rho_c
        self.bv = _rows(v0e) * (1 + u4)
        xm, xf = _wnorm(e0, self.w)
        vm, vf = _wnorm(v0e, self.w)
        self.fx = _rows(e0 - self.w @ e0) * (1 + u4) + 2 * u4 * self.bx.max(initial=0.0)
        self.fv = _rows(v0e - self.w @ v0e) * (1 + u4) + 2 * u4 * self.bv.max(initial=0.0)
        self.saturated = False
        nx = math.sqrt(float(self.w @ self.bx ** 2))
        nv = math.sqrt(float(self.w @ self.bv ** 2))
        self.L2 = [xm * (1 + u4) + self.rho_c + u4 * nx, xf * (1 + u4) + u4 * nx,
                   vm * (1 + u4) + u4 * nv, vf * (1 + u4) + u4 * nv]
        self.R2 = [0.0, 0.0, 0.0, 0.0]          # the round-off share of the L2 recursion
        self.rec = {key: [] for key in ("t", "step", "error", "error_max", "bound", "bound_max",
                                        "roundoff", "w1_bound", "w1_coupling", "saturated",
                                        "error_v", "bound_v")}
        self.kept = {key: [] for key, on in self.keep.items() if on}
        self.tracker = PaperTracker(scene, P, self.plan, self.w) if self.paper else None
        self._ws = {}                           # the pair pass's scratch arrays, step to step
        self._step = 0
        if self._saving(0):
            self._record(self.t0, state)

    def _saving(self, step: int) -> bool:
        return self.save_steps is None or step in self.save_steps

    def _check_run(self, state, scene):
        """The run fed to the observer is the one it was built for."""
        if scene is not self.scene:
            raise InvalidInput(f"{self!r} was built for another scene than the run's ({scene!r})")
        if state.x.shape != self.x0.shape or state.v is None:
            raise InvalidInput(f"{self!r} was built for states of shape {self.x0.shape}; the "
                               f"run's are {state.x.shape}")
        return scene

    def _check_step(self, t: float, state) -> float:
        """The step size, refusing steps out of order, backwards or of changing size
        (fixed-step Euler); the step starts where the previous one ended (``self.t``)."""
        if state.step != self._step + 1:
            raise InvalidInput(f"observer fed step {state.step} after step {self._step}: every "
                               "accepted step must be observed, in order")
        h = float(state.h)
        if self.h is None:
            self.h = h
        if h != self.h or not t > self.t:
            raise InvalidInput(
                f"step {state.step} ends at t={t!r} with size {h!r} after steps of {self.h!r} "
                f"ending at t={self.t!r}: certificates cover forward Euler with a fixed step "
                "only (method='euler', docs/certificates.md); adaptive step sizes are not "
                "supported")
        return h

    # ------------------------------------------------------------------ one step
    def update(self, t, state, scene) -> None:
        """Advance by one accepted high-dimensional step (``state`` after it)."""
        self._check_run(state, scene)
        h = self._check_step(t, state)
        tn = self.t                                             # the step's start
        PX, PV, Y, W = self.PX, self.PV, self.Y, self.W
        # the projected Euler step, by simulate's solver (in place: on copies, the step's
        # start is needed below)
        (Yn, Wn), _, self.solver_state = self.solver.step(
            self.field, tn, (Y.copy(), W.copy()), h, self.solver_state, None)
        dW = self.field.last[1]                                 # the projected step's field
        aggs, Fd = self._pass(PX, PV, Y, W)
        Fd = self._local_field(Fd, PX, PV, tn)                  # F'(PX, PV): the defect's
        coef = self._coefficients(aggs, PV, W, h)
        pre = self._allowance_inputs(aggs, PX, PV, Y, W, Fd, dW)
        self.Y, self.W, Y, W = Yn, Wn, Yn, Wn
        s = float(np.sum(Y)) + float(np.sum(W))
        if not math.isfinite(s):
            raise SimulationDiverged(
                f"the projected run diverged at t={float(t):.6g} (step {state.step}): its "
                "state became non-finite; reduce dt", t=float(t), step=int(state.step))
        PXn = _project(self.P, state.x)
        PVn = _project(self.P, state.v)
        tau_x = PXn - PX - h * PV
        tau_v = PVn - PV - h * Fd
        alpha = _ro.step_allowance(h, Y1=_ro.row_max(Y), W1=_ro.row_max(W),
                                   PX1=_ro.row_max(PXn), PV1=_ro.row_max(PVn), **pre)
        self._advance(coef, aggs, tau_x, tau_v, alpha, h, self._sizes(Y, W, PXn, PVn))
        self.PX, self.PV = PXn, PVn
        self._step, self.t = state.step, float(t)
        if self._saving(state.step):
            self._record(float(t), state)

    def _sizes(self, Y, W, PX, PV) -> dict:
        """The trivial bounds ``|y − Mx| ≤ |y| + |Mx|`` (per agent, of the fluctuations, of the
        means and in the weighted RMS norm) from the sizes of the two states (docs §6)."""
        w = self.w
        g = 1.0 + 2.0 * _ro.gamma(self.n + self.k + 8)        # rounding of the norms and sums
        dc = float(np.linalg.norm(self.delta_c)) + self.rho_c
        out = {}
        for key, A, B, extra in (("x", Y, PX, dc), ("v", W, PV, 0.0)):
            ma, mb = w @ A, w @ B
            ra, rb = _rows(A), _rows(B)
            nma, nmb = float(np.linalg.norm(ma)), float(np.linalg.norm(mb))
            # the centring itself rounds at the scale of the rows and the means
            fa = _rows(A - ma) + 4.0 * _ro.U64 * (ra + nma)
            fb = _rows(B - mb) + 4.0 * _ro.U64 * (rb + nmb)
            out["b" + key] = (ra + rb + extra) * g
            out["f" + key] = (fa + fb) * g
            out[key + "m"] = (nma + nmb + extra) * g
            out[key + "f"] = (math.sqrt(float(w @ fa ** 2)) + math.sqrt(float(w @ fb ** 2))) * g
            out[key + "l2"] = (math.sqrt(float(w @ ra ** 2)) + math.sqrt(float(w @ rb ** 2))
                               + extra) * g
        return out

    def _pass(self, PX, PV, Y, W):
        """The pair pass: per-term aggregates and the pair sums of ``F′(PX, PV)``."""
        pts = {"PX": PX, "PV": PV, "Y": Y, "W": W}
        fn = pair_pass if self.engine == "fast" else pair_pass_numpy
        if not self.plan.terms:
            return [], np.zeros_like(PV)
        bz = {"x": self.fx, "v": self.bv}
        bs = {"x": self.fx, "v": self.fv}
        args = (pts, self.c, self.plan.terms, bz, bs, _ro.COEF_MARGIN,
                _ro.pass_constants(self.n, self.mixed))
        return fn(*args, ws=self._ws)

    def _local_field(self, F, PX, PV, t) -> np.ndarray:
        """``F′(PX, PV)`` from its pair sums ``F``: the projected scene's per-agent effects
        (self-propulsion, drifts) added in place, as its own field adds them."""
        for e in self.pscene._local:
            F += e.drift(PX, PV, t)
        return F

    def _coefficients(self, aggs, PV, W, h) -> dict:
        """Contraction and coupling factors of the projected Euler map (docs/certificates.md §3)."""
        plan, n = self.plan, self.n
        m = 1.0 + _ro.COEF_MARGIN
        dsum_v = np.zeros(n)
        dneg_v = np.zeros(n)
        kstd = np.zeros(n)
        lam2 = 0.0
        have_v = False
        A_lx = A_x = A_v = 0.0
        for term, agg in zip(plan.terms, aggs):
            if term.carrier == "v":
                have_v = True
                dsum_v += agg.dsum
                dneg_v += agg.dneg
                # κ·(weighted std of row i of φ): |Σⱼ aᵢⱼ ε̃ⱼ| ≤ this·‖ε̃‖_w (docs §5)
                ks2 = plan.kappa * agg.s2
                # rounding: relative errors η of dᵢ and s2ᵢ move κ s2 − d² by ≤ 3η κ s2
                kstd += np.sqrt(np.maximum(ks2 - agg.dsum ** 2, 0.0)
                                + (1e-11 + 3.0 * _ro.gamma(2 * n + 8)) * ks2)
                # spectral gap >= κ Σᵢ wᵢ minⱼ φᵢⱼ (threshold decomposition, docs §2)
                rm = np.where(np.isfinite(agg.rowmin), agg.rowmin, 0.0)
                lam2 += plan.kappa * float(self.w @ rm)
            else:
                A_lx += float(np.max(np.abs(agg.dsum) + agg.dsum + 2.0 * agg.dneg))
            if term.source == "x":
                A_x += 2.0 * float(np.max(agg.kr))
            else:
                A_v += 2.0 * float(np.max(agg.kr))
        lam2 *= 1.0 - _ro.COEF_MARGIN
        if plan.has_sp:
            a, b = plan.sp_a, plan.sp_b
            big = np.maximum(_rows(PV), _rows(W))
            small = _segment_min(PV, W)
            base = 1.0 - h * dsum_v
            p = np.maximum(np.abs(base + h * (a - b * small ** 2)),
                           np.abs(base + h * (a - 3.0 * b * big ** 2)))
            q = float(np.max(p)) + h * float(np.max(dsum_v + 2.0 * dneg_v))
        else:
            p = np.abs(1.0 - h * dsum_v)
            if have_v:
                rho_l = 2.0 * float(np.max(dsum_v + dneg_v)) * m
                q = max(abs(1.0 - h * lam2), abs(1.0 - h * rho_l)) + 2.0 * h * float(np.max(dneg_v))
            else:
                q = 1.0
        return {"q": q * m, "p": p * m, "A_lx": A_lx * m, "A_x": A_x * m, "A_v": A_v * m,
                "kstd": kstd}

    def _allowance_inputs(self, aggs, PX, PV, Y, W, Fd, dW) -> dict:
        """Magnitudes at the start of the step for :func:`_roundoff.step_allowance`."""
        plan = self.plan
        spreads = {}
        for term in plan.terms:
            z_run, z_true = (Y, PX) if term.carrier == "x" else (W, PV)
            spreads[("run", term.carrier)] = _ro.spread(z_run)
            spreads[("true", term.carrier)] = _ro.spread(z_true)
        W0, PV0, fd, dw = _ro.row_max(W), _ro.row_max(PV), _ro.row_max(Fd), _ro.row_max(dW)
        speed = max(PV0, W0)
        eng_run = _ro.field_rounding(plan, aggs, spreads, speed, self.n, self.k, dw, self.mixed,
                                     "run")
        eng_true = _ro.field_rounding(plan, aggs, spreads, speed, self.n, self.k, fd, self.mixed,
                                      "true")
        return dict(W0=W0, PX0=_ro.row_max(PX), PV0=PV0, dW=dw, Fd=fd, eng_run=eng_run,
                    eng_true=eng_true)

    def _advance(self, coef, aggs, tau_x, tau_v, alpha, h, sizes) -> None:
        """One step of the recursions (docs/certificates.md §3–§5), then the caps."""
        lap_x, lap_v, r_x, r_v = self._couplings(aggs)
        L2 = self._l2_step(coef, tau_x, tau_v, alpha, h, lap_x, r_x, r_v)
        agents = self._agent_step(coef, tau_x, tau_v, alpha, h, lap_v, lap_x + r_x + r_v)
        L2, nbx, nbv, nfx, nfv, saturated = self._caps(L2, *agents, sizes)
        if not (all(math.isfinite(s) for s in L2) and np.all(np.isfinite(nbx))
                and np.all(np.isfinite(nbv))):
            raise SimulationDiverged(
                f"the certificate's bounds left the float64 range at step {self._step + 1} "
                f"(|w_i| + |M v_i| up to {float(np.max(sizes['bv'])):.3g}): a run is blowing up "
                "(explicit Euler unstable?); reduce dt", step=int(self._step + 1))
        self.L2, self.bx, self.bv, self.fx, self.fv = L2, nbx, nbv, nfx, nfv
        self.saturated = bool(saturated)

    def _couplings(self, aggs):
        """Per agent couplings (§2), with the coefficient margin: ``(lap_x, lap_v, r_x, r_v)``;
        ``|Rᵢ| ≤ Σⱼ Kᵢⱼ(fᵢ + fⱼ)``, ``|(L e)ᵢ| ≤ |dᵢ| fxᵢ + Σⱼ|aᵢⱼ| fxⱼ``."""
        n, fx, fv = self.n, self.fx, self.fv
        m = 1.0 + _ro.COEF_MARGIN
        lap_v, lap_x, r_x, r_v = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
        for term, agg in zip(self.plan.terms, aggs):
            if term.source == "x":
                r_x += agg.kr * fx + agg.kmv
            else:
                r_v += agg.kr * fv + agg.kmv
            if term.carrier == "v":
                lap_v += agg.amv
            else:
                lap_x += np.abs(agg.dsum) * fx + agg.amv
        return lap_x * m, lap_v * m, r_x * m, r_v * m

    def _wn(self, a) -> float:
        """The w-weighted ℓ2 norm of ``a``, rounded up (a sum of N terms)."""
        return math.sqrt(float(self.w @ (a * a))) * (1.0 + 2.0 * _ro.gamma(self.n + 4))

    def _l2_step(self, coef, tau_x, tau_v, alpha, h, lap_x, r_x, r_v) -> list:
        """The weighted-ℓ2 recursion (§3) of the mean and fluctuation parts; also advances the
        round-off-only recursion ``self.R2``. Returns the new ``[X_m, X_f, V_m, V_f]``."""
        ax, av = alpha
        sp, q = self.plan.has_sp, coef["q"]
        rnd = 1.0 + 2.0 * _ro.gamma(self.n + 4)
        nlx, nrx, nrv = self._wn(lap_x), self._wn(r_x), self._wn(r_v)
        # norms of the defects, with room for their own rounding (sums of N·k terms)
        txm, txf, tvm, tvf = (a * rnd * (1.0 + 2.0 * _ro.gamma(self.k + 2))
                              for a in _wnorm(tau_x, self.w) + _wnorm(tau_v, self.w))

        def l2(S, inx_m, inx_f, inv_m, inv_f, cap):
            xm_, xf_, vm_, vf_ = S
            if sp:
                vf_, vm_ = math.hypot(vm_, vf_), 0.0
            inf = math.inf
            c = (min(coef["A_lx"] * xf_, nlx if cap else inf)
                 + min(coef["A_x"] * xf_, nrx if cap else inf)
                 + min(coef["A_v"] * vf_, nrv if cap else inf))
            if sp:
                return [xm_ + h * vf_ + inx_m + ax, xf_ + h * vf_ + inx_f + ax, 0.0,
                        q * vf_ + h * c + math.hypot(inv_m, inv_f) + av]
            return [xm_ + h * vm_ + inx_m + ax, xf_ + h * vf_ + inx_f + ax,
                    vm_ + inv_m + av, q * vf_ + h * c + inv_f + av]

        out = l2(self.L2, txm, txf, tvm, tvf, True)
        self.R2 = l2(self.R2, 0.0, 0.0, 0.0, 0.0, False)
        up = 1.0 + 8.0 * _ro.U64        # the recursion's own arithmetic: a few positive terms
        return [s * up for s in out]

    def _agent_step(self, coef, tau_x, tau_v, alpha, h, lap_v, mixed):
        """The per-agent recursions of whole errors (§4) and fluctuations (§5):
        ``(nbx, nfx, nbv, nfv)`` (``nfv`` None with self-propulsion, set by the caps)."""
        ax, av = alpha
        w = self.w
        bx, bv, fx, fv = self.bx, self.bv, self.fx, self.fv
        rk = 1.0 + 2.0 * _ro.gamma(self.k + 2)
        gn = 2.0 * _ro.gamma(self.n + 2)               # rounding of the weighted mean removed
        rtx, rtv = _rows(tau_x) * rk, _rows(tau_v) * rk
        dtx = _rows(tau_x - w @ tau_x) * rk + gn * float(np.max(rtx, initial=0.0))
        dtv = _rows(tau_v - w @ tau_v) * rk + gn * float(np.max(rtv, initial=0.0))
        up = 1.0 + 8.0 * _ro.U64
        nbx = (bx + h * bv + rtx + ax) * up
        nfx = (fx + h * fv + dtx + 2.0 * ax) * up
        nbv = (coef["p"] * bv + h * (lap_v + mixed) + rtv + av) * up
        nfv = None
        if not self.plan.has_sp:
            m = 1.0 + _ro.COEF_MARGIN
            vf = self.L2[3]                     # the previous step's ‖ε̃‖_w bound
            nfv = (coef["p"] * fv + h * (m * coef["kstd"] * vf + mixed) + dtv + 2.0 * av) * up
        return nbx, nfx, nbv, nfv

    def _caps(self, L2, nbx, nfx, nbv, nfv, sizes):
        """The trivial size caps ``|y − Mx| ≤ |y| + |Mx|`` (docs §6), then each bound caps the
        others (``‖e‖_w ≤ ‖bx‖_w``, ``|ẽᵢ| ≤ |eᵢ| + |ē|``, ``|ẽᵢ| ≤ ‖ẽ‖_w/√wᵢ``, ...).
        Returns ``(L2, nbx, nbv, nfx, nfv, saturated)``."""
        sp, w = self.plan.has_sp, self.w
        X_m, X_f, V_m, V_f = L2
        np.minimum(nbx, sizes["bx"], out=nbx)
        np.minimum(nfx, sizes["fx"], out=nfx)
        np.minimum(nbv, sizes["bv"], out=nbv)
        before = math.hypot(math.hypot(X_m, X_f), math.hypot(V_m, V_f))
        X_m, X_f = min(X_m, sizes["xm"]), min(X_f, sizes["xf"])
        if sp:
            V_f = min(V_f, sizes["vl2"])
        else:
            np.minimum(nfv, sizes["fv"], out=nfv)
            V_m, V_f = min(V_m, sizes["vm"]), min(V_f, sizes["vf"])
        # saturated: the size caps, not the recursion, decide the RMS bound
        saturated = math.hypot(math.hypot(X_m, X_f), math.hypot(V_m, V_f)) < 0.99 * before
        wbx, wfx, wbv = self._wn(nbx), self._wn(nfx), self._wn(nbv)
        X_m, X_f = min(X_m, wbx), min(X_f, wfx, wbx)
        if sp:
            V_f = min(V_f, wbv)
            nfv = (nbv + V_f) * (1.0 + 3.0 * _ro.U64)   # |ε̃ᵢ| ≤ |εᵢ| + |ε̄|, |ε̄| ≤ ‖ε‖_w
        else:
            wfv = self._wn(nfv)
            V_m, V_f = min(V_m, wbv), min(V_f, wfv, wbv)
        pos = w > 0
        inv = np.zeros(self.n)
        inv[pos] = (1.0 + 4.0 * _ro.U64) / np.sqrt(w[pos])
        up2 = 1.0 + 3.0 * _ro.U64             # a rounded sum of two bounds is still one
        np.minimum(nfx, (nbx + X_m) * up2, out=nfx)
        np.minimum(nfv, (nbv + V_m + (V_f if sp else 0.0)) * up2, out=nfv)
        nfx[pos] = np.minimum(nfx[pos], X_f * inv[pos])
        nfv[pos] = np.minimum(nfv[pos], V_f * inv[pos])
        np.minimum(nbx, (X_m + nfx) * up2, out=nbx)
        if not sp:
            np.minimum(nbv, (V_m + nfv) * up2, out=nbv)
        else:
            nbv[pos] = np.minimum(nbv[pos], V_f * inv[pos])
        return [X_m, X_f, V_m, V_f], nbx, nbv, nfx, nfv, saturated

    # ------------------------------------------------------------------ records
    def _record(self, t: float, state) -> None:
        w = self.w
        e = (self.Y - self.PX) + self.delta_c
        ev = self.W - self.PV
        ex2 = np.einsum("ij,ij->i", e, e)
        ev2 = np.einsum("ij,ij->i", ev, ev)
        mu_x = self.proj_round * _ro.row_max(state.x) + self.rho_c
        mu_v = self.proj_round * _ro.row_max(state.v)
        # the measured norms are sums of N·k terms: compare with room for their rounding
        grow = 1.0 + 2.0 * _ro.gamma(self.n + self.k + 8)
        l2 = math.sqrt(sum(s * s for s in self.L2))
        l2 = min(l2, math.sqrt(float(w @ (self.bx ** 2 + self.bv ** 2))))
        per = np.hypot(self.bx + mu_x, self.bv + mu_v) * grow
        rec = self.rec
        rec["t"].append(t)
        rec["step"].append(self._step)
        rec["error"].append(math.sqrt(float(w @ (ex2 + ev2))))
        rec["error_max"].append(math.sqrt(float(np.max(ex2 + ev2))))
        rec["bound"].append((l2 + math.hypot(mu_x, mu_v)) * grow)
        rec["bound_max"].append(float(np.max(per)))
        rec["roundoff"].append(math.sqrt(sum(s * s for s in self.R2)))
        rec["saturated"].append(float(self.saturated))
        rec["w1_coupling"].append(float(w @ np.sqrt(ex2 + ev2)))
        rec["w1_bound"].append(min(rec["bound"][-1], float(w @ per)))
        # the velocities alone: ‖ε‖_w ≤ (|ε̄|² + ‖ε̃‖²)^½ and ≤ ‖bᵛ‖_w
        lv = min(math.hypot(self.L2[2], self.L2[3]), math.sqrt(float(w @ self.bv ** 2)))
        rec["error_v"].append(math.sqrt(float(w @ ev2)))
        rec["bound_v"].append((lv + mu_v) * grow)
        if "y" in self.kept:
            self.kept["y"].append(self.Y + self.shift_y if self.shift_y is not None
                                  else self.Y.copy())
        if "w" in self.kept:
            self.kept["w"].append(self.W.copy())
        if self.tracker is not None:
            with _parallel.blas_threads(1):
                self.tracker.record(t - self.t0, state.x, state.v, self.PX, self.PV, self.Y,
                                    self.W)

    def records(self) -> dict:
        """The recorded series as arrays: those of :class:`~kinred.certify.Certificate`
        (``error``, ``bound``, ..., ``error_v``, ``bound_v``, the paper's bounds, NaN unless
        requested), ``t`` and ``step``, and the projected states ``y``, ``w`` (``(T, N, k)``)
        when kept."""
        out = {key: np.asarray(val, dtype=float) for key, val in self.rec.items()}
        out.update({key: np.array(val) for key, val in self.kept.items()})
        out["step"] = out["step"].astype(np.int64)
        if self.tracker is not None:
            out.update(self.tracker.bounds())
        else:
            nan = np.full(len(out["t"]), np.nan)
            out["paper_bound"], out["paper_bound_max"] = nan, nan.copy()
        return out
