r"""``certify``: a high-dimensional Euler run observed by a :class:`CertificateObserver`."""

from __future__ import annotations

import math
import time
import types
from dataclasses import dataclass, field, fields
from typing import Mapping

import numpy as np

from .._repr import result_repr, sample_rows, table
from .._validate import as_choice, as_float, as_int, as_span
from ..dynamics import Scene
from ..errors import InvalidInput
from ..integrate import METHODS, ConstantStep, SaveAt, save_grid, simulate
from ..projection import as_projection
from ._observer import CertificateObserver
from ._plan import make_plan

__all__ = ["Certificate", "certify", "LABELS", "check_scene"]

#: What every number of a :class:`Certificate` is.
LABELS = types.MappingProxyType({
    "error": "measured",
    "error_max": "measured",
    "w1_coupling": "measured",
    "bound": "certified bound",
    "bound_max": "certified bound",
    "w1_bound": "certified bound",
    "error_v": "measured",
    "bound_v": "certified bound",
    "roundoff": "estimate",
    "paper_bound": "a-priori bound (paper's constants)",
    "paper_bound_max": "a-priori bound (paper's constants)",
})


def check_scene(scene, n_agents: int) -> None:
    """Refuse a scene of ``n_agents`` agents that certificates do not cover, before any work
    (what :func:`certify` and :class:`CertificateObserver` refuse first).

    Raises
    ------
    InvalidInput
        ``scene`` is no :class:`~kinred.dynamics.Scene`, ``n_agents < 1``, a first-order scene,
        an approximate pair-sum backend (:func:`kinred.pairsum.is_exact`).
    NotProjectable
        Noise, :class:`~kinred.dynamics.Field` or another effect outside class (1.1), a kernel
        without a usable ``slope_bound``.

    Examples
    --------
    >>> from kinred.dynamics import Alignment, Noise, Scene
    >>> check_scene(Scene([Alignment()]), 10)
    >>> check_scene(Scene([Alignment(), Noise(0.1)]), 10)
    Traceback (most recent call last):
    ...
    kinred.errors.NotProjectable: ...
    """
    if not isinstance(scene, Scene):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
    make_plan(scene, as_int(n_agents, "n_agents", low=1))


@dataclass(frozen=True, repr=False)
class Certificate:
    r"""Result of :func:`certify`: errors of a projected run, measured and certified.

    With ``e = y − Mx`` and ``ε = w − Mv`` per agent (``y, w`` the projected run, ``x, v`` the
    high-dimensional one; positions in the integrators' working frames, see
    ``docs/certificates.md``):

    Attributes
    ----------
    t : (T,) ndarray
        Saved times.
    error : (T,) ndarray
        Measured ``(Σᵢ wᵢ(|eᵢ|² + |εᵢ|²))^{1/2}``, the weighted least-squares norm of
        Theorem 2.3 (eq. (2.18)).
    error_max : (T,) ndarray
        Measured ``maxᵢ (|eᵢ|² + |εᵢ|²)^{1/2}``, the ℓ∞-over-agents norm of Theorems 2.2 and 3.1.
    bound, bound_max : (T,) ndarray
        Certified upper bounds of ``error`` and ``error_max`` for the Euler scheme that was run.
    roundoff : (T,) ndarray
        The part of ``bound``'s recursion driven by the round-off allowance (an estimate).
    w1_coupling : (T,) ndarray
        Measured ``Σᵢ wᵢ |(eᵢ, εᵢ)|`` ≥ ``W1((μᴺ)_M(t), νᴺ(t))`` (the middle term of Theorem 4.3).
    w1_bound : (T,) ndarray
        Certified bound of ``w1_coupling`` (hence of that W1).
    error_v, bound_v : (T,) ndarray
        The velocities alone: measured ``(Σᵢ wᵢ|εᵢ|²)^{1/2}`` and its certified bound (the
        relative projection error of Figure 4 is ``error_v`` over ``(Σᵢ wᵢ|Mvᵢ|²)^{1/2}``).
    paper_bound : (T,) ndarray
        The RHS of eq. (2.18) with its constants measured along the run (Cucker–Smale only,
        else NaN).
    paper_bound_max : (T,) ndarray
        ``√2`` × the RHS of eq. (2.11) (Theorem 2.2) with its constants.
    saturated : (T,) ndarray of bool
        Where the trivial size bound ``|yᵢ − Mxᵢ| ≤ |yᵢ| + |Mxᵢ|`` was below the propagated
        one at the last step: the projected run has lost the high-dimensional one there and
        ``bound`` says only that.
    labels : mapping
        What each number is: "measured", "certified bound", "a-priori bound (paper's
        constants)" or "estimate" (``kinred.certify.LABELS``).
    method : str
    dt : float
    n_steps : int
    n_agents, d, k : int
    wall_time : float
        Seconds for the whole call.
    note : str
    """

    t: np.ndarray
    error: np.ndarray
    error_max: np.ndarray
    bound: np.ndarray
    bound_max: np.ndarray
    roundoff: np.ndarray
    w1_coupling: np.ndarray
    w1_bound: np.ndarray
    error_v: np.ndarray
    bound_v: np.ndarray
    paper_bound: np.ndarray
    paper_bound_max: np.ndarray
    saturated: np.ndarray
    method: str
    dt: float
    n_steps: int
    n_agents: int
    d: int
    k: int
    wall_time: float
    labels: Mapping = field(default_factory=lambda: LABELS)
    note: str = ""

    @property
    def ratio(self) -> np.ndarray:
        """``bound / error`` at every saved time, ``(T,)`` (NaN where the error is 0)."""
        return _ratio(self.bound, self.error)

    @property
    def ratio_max(self) -> np.ndarray:
        """``bound_max / error_max`` at every saved time, ``(T,)`` (NaN where the error is 0)."""
        return _ratio(self.bound_max, self.error_max)

    def worst_ratio_after(self, t_min: float = 1.0, norm: str = "rms") -> float:
        """Largest ``bound / error`` (``norm="rms"``) or ``bound_max / error_max``
        (``"max"``) over the saved times ``t >= t_min`` (NaN if there is none with a nonzero
        error). Early times are left out by default: there the error is still tiny and the
        ratio says little."""
        t_min = as_float(t_min, "t_min")
        norm = as_choice(norm, "norm", ("rms", "max"))
        r = (self.ratio if norm == "rms" else self.ratio_max)[self.t >= t_min]
        r = r[np.isfinite(r)]
        return float(np.max(r)) if r.size else math.nan

    def __repr__(self) -> str:
        i = len(self.t) - 1
        head = [("N", self.n_agents), ("d", self.d), ("k", self.k), ("method", repr(self.method)),
                ("dt", self.dt), ("n_steps", self.n_steps),
                ("t", f"<{len(self.t)} saved times in [{self.t[0]:.4g}, {self.t[-1]:.4g}]>"),
                ("valid", self.valid),
                ("", f"at t={self.t[i]:.4g}: error {self.error[i]:.4g} ≤ bound "
                     f"{self.bound[i]:.4g}, error_max {self.error_max[i]:.4g} ≤ bound_max "
                     f"{self.bound_max[i]:.4g}"),
                ("worst_ratio_after(1.0)", self.worst_ratio_after(1.0)),
                ("", f"<{len(_SERIES)} series ({len(self.t)},) such as error, bound; "
                     "summary() tabulates them>"),
                ("wall_time", self.wall_time)]
        return result_repr(self, head, skip=[f.name for f in fields(self)])

    def summary(self, rows: int = 8) -> str:
        """A text table of the series at ``rows`` saved times (evenly spread, first and last
        included): ``t``, ``error``, ``bound``, ``ratio``, ``error_max``, ``bound_max``,
        ``ratio_max``, ``w1_coupling``, ``w1_bound``, ``paper_bound``; then the note."""
        rows = as_int(rows, "rows", low=2)
        cols = {"t": self.t, "error": self.error, "bound": self.bound, "ratio": self.ratio,
                "error_max": self.error_max, "bound_max": self.bound_max,
                "ratio_max": self.ratio_max, "w1_coupling": self.w1_coupling,
                "w1_bound": self.w1_bound, "paper_bound": self.paper_bound}
        head = (f"Certificate: N={self.n_agents}, d={self.d} → k={self.k}, {self.method} "
                f"dt={self.dt:g}, {self.n_steps} steps; valid={self.valid}")
        return "\n".join([head, table(cols, sample_rows(len(self.t), rows)), self.note])

    @property
    def valid(self) -> bool:
        """Whether ``bound >= error``, ``bound_max >= error_max`` and ``bound_v >= error_v``
        at every saved time."""
        return bool(np.all(self.bound >= self.error) and np.all(self.bound_max >= self.error_max)
                    and np.all(self.bound_v >= self.error_v))


#: The per-saved-time series of a :class:`Certificate`.
_SERIES = ("error", "error_max", "bound", "bound_max", "roundoff", "w1_coupling", "w1_bound",
           "error_v", "bound_v", "paper_bound", "paper_bound_max", "saturated")


def _ratio(b: np.ndarray, e: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(e > 0, b / np.where(e > 0, e, 1.0), np.nan)


def certify(scene, M, x0, v0=None, *, t_span, dt, method: str = "euler", save=None,
            engine: str = "fast", paper: bool = True) -> Certificate:
    r"""Run a scene and its projection by ``M`` side by side and certify the projection error.

    The high-dimensional forward-Euler run is ``simulate(scene, x0, v0, t_span, dt,
    method="euler")`` itself, observed by a :class:`CertificateObserver`, which steps the
    projected run – bit-identical to ``simulate(scene.project(M), *project_state(M, x0, v0),
    t_span, dt)`` (eq. (2.4)–(2.5); eq. (2.14)–(2.15)) – after every step. At
    every step the proofs of Theorems 2.2 and 2.3 (eq. (2.11), (2.18)) are applied with what
    is measured at that step instead of worst cases: the defect of the projected
    high-dimensional trajectory in the projected scheme as a vector (the JL distortion of
    exactly the pairs each effect sees, cancellations kept), the projected run's graph
    Laplacian and its spectral gap, slope bounds of the kernels on the interval between the
    two distances of each pair, the one-sided bounds of self-propulsion along both runs
    (derivation: ``docs/certificates.md``). The result bounds the error of the discrete
    scheme that was run (forward Euler), including an estimated round-off allowance.

    Parameters
    ----------
    scene : Scene
        Second order and deterministic: pairwise effects whose kernels have
        ``slope_bound`` (Alignment on ``x`` or ``v``, softened Morse attraction–repulsion,
        Quadratic, custom :class:`~kinred.dynamics.PairwiseEffect`), self-propulsion,
        drifts; weights and ``normalize="mean"``/``"sum"``.
    M : (k, d) ndarray or Projection
    x0, v0 : (N, d) array_like
        Initial positions and velocities (``v0`` is required).
    t_span : (float, float)
    dt : float
        Step; ``(t1 − t0)/dt`` must be an integer.
    method : str
        Only ``"euler"`` (the scheme the derivation covers).
    save : SaveAt, optional
        Saved steps (``every=`` or ``t=``; other fields are ignored). Default: every step.
    engine : {"fast", "numpy"}
        Pair pass of the certificate: compiled or the plain-numpy twin.
    paper : bool
        Also evaluate the paper's bounds (one high-dimensional pair pass per saved step: save
        sparingly, or pass ``False``, for large runs).

    Returns
    -------
    Certificate

    Raises
    ------
    InvalidInput
        Bad arguments; ``method`` other than ``"euler"``; first-order scenes; an approximate
        pair-sum backend (``NUFFT``, ``RandomBatch``, any backend without ``exact = True``:
        :func:`kinred.pairsum.is_exact`).
    NotProjectable
        Noise, :class:`~kinred.dynamics.Field` or other uncovered effects, kernels without
        a slope bound (e.g. Morse with ``soft = 0``).
    SimulationDiverged
        The high-dimensional run diverged (``simulate``'s checks: a non-finite state, or
        growth past the bound of the exact flow, e.g. an unstable step), or the projected
        run became non-finite.

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> rng = np.random.default_rng(0)
    >>> x0, v0 = rng.normal(size=(30, 20)), rng.normal(size=(30, 20))
    >>> M = rng.normal(0, 1 / np.sqrt(5), (5, 20))
    >>> cert = certify(Scene([Alignment(CuckerSmale(1.0, 0.4))]), M, x0, v0,
    ...                t_span=(0, 2), dt=0.05, save=SaveAt(every=10))
    >>> cert.t
    array([0. , 0.5, 1. , 1.5, 2. ])
    >>> cert.valid, bool(cert.worst_ratio_after(1.0) < 10)
    (True, True)
    >>> cert.labels["bound"], cert.labels["error"]
    ('certified bound', 'measured')
    >>> print(cert.summary(rows=2).splitlines()[1])
      t     error     bound  ratio  error_max  bound_max  ratio_max  w1_coupling  w1_bound  paper_bound
    """
    start = time.perf_counter()
    if not isinstance(scene, Scene):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
    if not isinstance(method, str) or method not in METHODS:
        raise InvalidInput(f"method must be 'euler' (the only scheme certificates cover); got "
                           f"{method!r}")
    if method != "euler":
        raise InvalidInput(
            f"method={method!r} is not supported by certificates: the derivation "
            "(docs/certificates.md) is written for forward Euler, eq. (1.6), the "
            "paper's scheme; supported: 'euler'")
    engine = as_choice(engine, "engine", ("fast", "numpy"))
    P = as_projection(M)
    t0, t1 = as_span(t_span)
    dt = as_float(dt, "dt", low=0.0, low_open=True)
    n_steps = ConstantStep().init(None, t0, t1, dt, method).n_steps
    save = SaveAt() if save is None else save
    if not isinstance(save, SaveAt):
        raise InvalidInput(f"save must be a kinred.SaveAt (every= or t=) or None, got {save!r}")
    steps = save_grid(save, t0, t1, dt, n_steps, method).steps
    obs = CertificateObserver(scene, P, x0, v0, save_steps=steps, engine=engine, paper=paper)
    # the observer records; simulate only keeps the save times
    tr = simulate(scene, obs.x0, obs.v0, (t0, t1), dt, method=method,
                  save=SaveAt(every=save.every, t=save.t, observables=()), observers=[obs])
    rec = obs.records()
    t = np.asarray(tr.t, dtype=float)
    note = ("bound, bound_max, w1_bound: certified for the forward-Euler runs (round-off "
            "allowance estimated, docs/certificates.md); noise is excluded")
    if np.isnan(rec["paper_bound"]).all() and paper:
        note += "; paper_bound (eq. (2.18)) is for a pure Cucker-Smale scene only: NaN here"
    if np.any(rec["saturated"] > 0):
        note += ("; saturated at some saved times: there the bound is the trivial |y| + |Mx| "
                 "(the projected run has lost the high-dimensional one)")
    return Certificate(t=t, error=rec["error"], error_max=rec["error_max"], bound=rec["bound"],
                       bound_max=rec["bound_max"], roundoff=rec["roundoff"],
                       w1_coupling=rec["w1_coupling"], w1_bound=rec["w1_bound"],
                       error_v=rec["error_v"], bound_v=rec["bound_v"],
                       paper_bound=rec["paper_bound"], paper_bound_max=rec["paper_bound_max"],
                       saturated=rec["saturated"].astype(bool), method=method, dt=dt,
                       n_steps=n_steps, n_agents=obs.x0.shape[0],
                       d=obs.x0.shape[1], k=P.k, wall_time=time.perf_counter() - start, note=note)
