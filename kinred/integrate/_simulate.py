r"""``simulate``: one entry point for every integrator (Diffrax ``diffeqsolve`` style).

The run joins four objects: a solver from the registry (:mod:`._registry`, one step), a
step-size controller (:mod:`._controllers`, which steps are tried and kept), the save grid and
recorder (:mod:`._save`) and the per-step observers (:mod:`._observers`); every accepted step
is checked for divergence (:mod:`._guard`). :func:`simulate` validates its input, builds them
and runs the short loop :func:`_loop`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Any, Mapping

import numpy as np

from .._repr import brief, result_repr, sample_rows, table
from .._rng import as_generator
from .._validate import _short, as_array, as_float, as_int, as_span
from ..dynamics import Scene
from ..errors import InvalidInput
from ._controllers import AdaptiveStep, ConstantStep
from ._guard import DivergenceCheck
from ._observers import Progress, as_observers, frame_of, state_view
from ._registry import SOLVERS, method_name
from ._save import (FUSED_MIN, Recorder, SaveAt, SaveGrid, check_save_size, observable_list,
                    save_grid, save_points)
from ._solvers import EulerMoments, ExplicitRK, VectorField

__all__ = ["simulate", "Trajectory"]


@dataclass(frozen=True, repr=False)
class Trajectory:
    """Result of :func:`simulate`.

    Attributes
    ----------
    t : (T,) ndarray
        Saved times (always including ``t0`` and the final time).
    observables : mapping of str to ndarray
        ``(T,)`` or ``(T, ...)`` arrays, one per requested observable.
    x, v : (T_s, N, d) ndarray or None
        States at the times ``t_states``: at every save time when requested
        (``SaveAt(states=True)``, or ``"x"``/``"v"`` for one of them, the other None); by
        default the final state alone (``T_s = 1``, ``tr.x[-1]`` is the state at ``t1``, as
        Diffrax saves ``t1``). ``v`` is None for first-order scenes.
    method : str
    n_steps : int
        Accepted steps.
    n_rhs_evals : int
        Evaluations of the scene's drift.
    wall_time : float
        Seconds spent in :func:`simulate`.
    dt : float
        Step size (initial step for adaptive methods).
    n_rejected : int
        Rejected steps (adaptive methods).
    weights : (N,) ndarray or None
        Probability weights of the agents when the scene has them (None: uniform).
    scene : str
        Description of the scene (its effects and coupling convention).
    seed : None, int, SeedSequence or Generator
        The ``seed`` the run was given.
    t_states : (T_s,) ndarray
        Times of the saved states: ``t`` when states were requested, else ``[t1]``.
    """

    t: np.ndarray
    observables: Mapping[str, np.ndarray]
    x: np.ndarray | None
    v: np.ndarray | None
    method: str
    n_steps: int
    n_rhs_evals: int
    wall_time: float
    dt: float
    n_rejected: int = 0
    weights: np.ndarray | None = None
    scene: str = ""
    seed: Any = None
    t_states: np.ndarray | None = None

    def __repr__(self) -> str:
        ts = self.t_states if self.t_states is not None else np.empty(0)
        at = ("" if ts.size == 0 else f" at t={ts[0]:.4g}" if ts.size == 1 else
              f" at the {ts.size} save times")
        head = [("method", repr(self.method)), ("dt", self.dt), ("n_steps", self.n_steps),
                ("t", f"<{len(self.t)} saved times in [{self.t[0]:.4g}, {self.t[-1]:.4g}]>"),
                ("x", brief(self.x) + at if self.x is not None else "None"),
                ("v", brief(self.v) + at if self.v is not None else "None"),
                ("observables", self.observables), ("n_rhs_evals", self.n_rhs_evals),
                ("n_rejected", self.n_rejected), ("wall_time", self.wall_time),
                ("scene", brief(self.scene))]
        return result_repr(self, head, skip=[f.name for f in fields(self)])

    def summary(self, rows: int = 8) -> str:
        """A text table of the observables at ``rows`` save times (evenly spread, first and
        last included): scalar ones as they are, vector ones (``centre``,
        ``mean_velocity``) by their Euclidean norm ``|name|``.

        Examples
        --------
        >>> from kinred.dynamics import Scene, Alignment
        >>> tr = simulate(Scene([Alignment()]), np.zeros((3, 2)), np.eye(3)[:, :2], (0, 1), 0.5)
        >>> print(tr.summary())
          t    gamma  lambda
          0   0.4444       0
        0.5   0.1111  0.1111
          1  0.05221    0.25
        """
        rows = as_int(rows, "rows", low=2)
        cols = {"t": self.t}
        for name, a in self.observables.items():
            a = np.asarray(a, dtype=float)
            if a.ndim == 1:
                cols[name] = a
            else:
                cols[f"|{name}|"] = np.sqrt(np.sum(a.reshape(len(a), -1) ** 2, axis=1))
        return table(cols, sample_rows(len(self.t), rows))

    def to_xarray(self):
        """The trajectory as an ``xarray.Dataset`` (needs the optional extra ``xarray``).

        Dimensions ``time`` (coordinate: the saved times), ``agent`` and ``coordinate``
        (integer labels); data variables ``x`` and ``v`` ``(time, agent, coordinate)`` when
        the states were saved (``(state_time, agent, coordinate)`` with ``state_time = [t1]``
        when only the final state was kept, the default), ``weights`` ``(agent,)`` for a weighted scene, and one
        variable per observable (``(time,)``, or ``(time, <name>_dim1, ...)``); attributes:
        ``method``, ``dt``, ``n_steps``, ``n_rejected``, ``n_rhs_evals``, ``wall_time_s``,
        ``scene`` (its description), ``seed`` (as given; a non-integer seed as text) and
        ``kinred_version``. NetCDF or Zarr are then one call away
        (``ds.to_netcdf("run.nc")``, ``ds.to_zarr("run.zarr")``).

        Returns
        -------
        xarray.Dataset

        Raises
        ------
        MissingDependency
            xarray is not installed (``pip install 'kinred[xarray]'``).

        Examples
        --------
        >>> from kinred.dynamics import Scene, Alignment
        >>> tr = simulate(Scene([Alignment()]), np.zeros((3, 2)), np.eye(3)[:, :2], (0, 1),
        ...               0.5, save=SaveAt(states=True))
        >>> ds = tr.to_xarray()  # doctest: +SKIP
        >>> ds["x"].dims, ds.attrs["method"]  # doctest: +SKIP
        (('time', 'agent', 'coordinate'), 'euler')
        """
        from ._export import to_xarray

        return to_xarray(self)


@dataclass
class _Run:
    """Everything the loop needs, validated and built by :func:`_prepare`."""

    scene: Any
    method: str
    solver: Any
    control: Any            # the controller's run state
    f: VectorField
    rng: np.random.Generator | None
    grid: SaveGrid
    record: Recorder
    check: DivergenceCheck
    observers: list
    t0: float
    t1: float
    dt: float
    state: tuple
    shift: np.ndarray | None
    fused: Any = None       # EulerMoments: the step that gives the moments too, or None
    known0: Any = None      # the moments (of x0, of v0) the working frame gave (or None)


def simulate(scene: Scene, x0, v0=None, t_span=(0.0, 1.0), dt: float = 0.01, *,
             method: str = "euler", save: SaveAt | None = None, seed=None, progress: bool = False,
             rtol: float | None = None, atol: float | None = None, max_steps: int | None = None,
             observers=None, stepsize_controller=None) -> Trajectory:
    r"""Integrate a scene from ``(x0, v0)`` over ``t_span``.

    Forward Euler is the paper's scheme (eq. (1.6); on a projected scene
    it is eq. (2.4)–(2.5)). When every effect is translation invariant the run is carried out
    in coordinates relative to the initial centroid (positions are shifted back when saved),
    which keeps distances accurate for clouds far from the origin.

    Every accepted step is checked in ``O(N·d)``: the state must stay finite and, for scenes
    whose energy budget is known (alignment with ``g ≥ 0``, Morse attraction–repulsion,
    self-propulsion, drifts, noise), the velocity fluctuation ``Γ`` (or ``Σᵢwᵢ|vᵢ|²`` with
    self-propulsion) must stay within 10 times (100 with noise) an a-priori bound of the exact
    flow (for pure alignment: ``Γ`` never grows). An explicit step that is unstable for the
    scene (e.g. Euler with ``dt·ρ > 2``, ``ρ`` the spectral radius of the alignment Laplacian)
    is stopped within a few steps of the first amplification. See ``kinred.integrate._guard``.

    Parameters
    ----------
    scene : Scene
    x0 : (N, d) array_like
    v0 : (N, d) array_like or None
        None for first-order scenes.
    t_span : (float, float)
        ``(t0, t1)`` with ``t1 > t0``.
    dt : float
        Step (fixed-step methods; ``(t1 − t0)/dt`` must be an integer) or the initial step
        and save-grid unit of adaptive methods.
    method : str
        A name in :data:`SOLVERS` (:data:`METHODS`: the built-in ones) or an alias of one
        (:data:`ALIASES`: SciPy's ``"RK45"``/``"RK23"``, ``"dopri5"``, ``"bs23"``, ...; case,
        ``-`` and ``_`` ignored); :attr:`Trajectory.method` is the name. Scenes with noise
        require a stochastic method (``"euler_maruyama"``).
    save : SaveAt, optional
        Default ``SaveAt()`` (observables every step, no states).
    seed : None, int, SeedSequence or Generator
        Randomness of the run, converted once into one generator: the noise increments
        (Euler–Maruyama) draw from it, and the drift receives it (``scene._rhs(x, v, t,
        rng)``) when the scene has noise or its pair-sum backend has a true ``stochastic``
        attribute; other scenes are deterministic and their drift gets ``rng=None``.
    progress : bool
        Show a tqdm progress bar (steps for fixed-step methods; the time reached out of
        ``t1 − t0``, with its rate and remaining time, for adaptive ones).
    rtol, atol : float, optional
        Tolerances of adaptive methods (default ``1e-6`` and ``1e-9``).
    max_steps : int, optional
        Budget of accepted plus rejected steps of adaptive methods; default
        ``max(100 000, 1000·⌈(t1 − t0)/dt⌉)``.
    observers : callable, object or sequence of them, optional
        Called after every accepted step as ``obs(t, state, scene)`` (``obs.update`` if
        ``obs`` is not callable; ``obs.init(t0, state, scene)`` first if present), ``state``
        a read-only :class:`~kinred.integrate.StepState` (``.t``, ``.x``, ``.v``,
        ``.shift``, ``.step``, ``.h``): for quantities that need every step (certificates,
        energies, diagnostics). An observer with a ``methods`` attribute (tuple of names)
        accepts only those methods.
    stepsize_controller : ConstantStep or AdaptiveStep, optional
        Which steps are tried and kept (Diffrax's ``stepsize_controller``). Default: the
        method's own, ``ConstantStep()`` for fixed-step methods and ``AdaptiveStep(rtol,
        atol, max_steps)`` for adaptive ones (the same run as passing it). An
        :class:`AdaptiveStep` needs a method with an error estimate (``"rk45"``,
        ``"rk23"``); :class:`ConstantStep` runs any method at the fixed step ``dt``. With a
        controller, give the tolerances and the budget to it, not to ``simulate``.

    Returns
    -------
    Trajectory

    Raises
    ------
    SimulationDiverged
        The state became NaN/Inf or grew past the bound of the exact flow; the message names
        the time, the step, the quantity that grew and a hint with a stable step estimated
        from the states (also in the attribute ``stable_dt``).
    NotConverged
        An adaptive method spent ``max_steps``, its step fell below ``1e-12·(t1 − t0)``, or
        the problem is stiff and the budget cannot reach ``t1``; the message names the time
        reached, the step size, the accepted and rejected steps and a hint.
    TooLarge
        The saved observables and states (``T`` save points, ``(T, N, d)`` per state) would
        exceed the memory limit (environment variable ``KINRED_MAX_BYTES``, default 2 GiB);
        checked before the run allocates anything.

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment, CuckerSmale
    >>> rng = np.random.default_rng(0)
    >>> x0, v0 = rng.uniform(0, 1, (20, 3)), rng.uniform(-1, 1, (20, 3))
    >>> scene = Scene([Alignment(CuckerSmale(G=0.8, beta=1.5))], normalize="sum")
    >>> tr = simulate(scene, x0, v0, (0.0, 2.0), 0.02, save=SaveAt(every=50))
    >>> tr.t
    array([0., 1., 2.])
    >>> bool(tr.observables["gamma"][-1] < tr.observables["gamma"][0])
    True
    """
    t_start = time.perf_counter()
    run = _prepare(scene, x0, v0, t_span, dt, method, save, seed, rtol, atol, max_steps,
                   observers, stepsize_controller)
    bar = None
    if progress:
        bar = Progress(run.method, run.control.n_steps, run.t1 - run.t0)
        run.observers.insert(0, (bar.init, bar.update))
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            n_steps = _loop(run)
    finally:
        if bar is not None:
            bar.close()
    rec = run.record
    x, v, t_states = rec.states(run.grid.times)
    return Trajectory(t=np.asarray(run.grid.times, dtype=float), observables=rec.observables(),
                      x=x, v=v, t_states=t_states, method=run.method, n_steps=int(n_steps),
                      n_rhs_evals=run.f.n_evals, wall_time=time.perf_counter() - t_start,
                      dt=run.dt, n_rejected=int(run.control.n_rejected),
                      weights=None if scene.weights is None else np.array(scene.weights),
                      scene=_describe(scene), seed=seed)


def _describe(scene: Scene) -> str:
    """One line naming the scene's effects and coupling convention (weights not listed)."""
    text = f"Scene({list(scene.effects)!r}, normalize={scene.normalize!r}"
    if scene.weights is not None:
        text += ", weighted agents"
    return text + ")"


def _loop(r: _Run) -> int:
    """Step from ``t0`` through every save point; returns the number of accepted steps."""
    t, n, state = r.t0, 0, r.state
    f, rng, solver, control = r.f, r.rng, r.solver, r.control
    ss = solver.init(f, t, state, r.dt)
    r.record(0, t, *state, r.check.initial_moments(state[1]), r.known0)
    if r.observers:
        _notify(r, t, 0, 0.0, state, initial=True)
    times, steps = r.grid
    for j in range(1, len(times)):
        target_n = steps[j] if steps is not None else None
        lands = False
        while not lands:
            h, t_end, lands = control.propose(t, n, times[j], target_n)
            if r.fused is not None:         # Euler and the moments in one pass
                new, known = r.fused(f, t, state, h, ss, rng)
                err, new_ss = None, ss
            else:
                (new, err, new_ss), known = solver.step(f, t, state, h, ss, rng), None
            if not control.judge(t, state, new, err):
                lands = False
                continue
            t, state, ss, n = t_end, new, new_ss, n + 1
            moments = r.check(t, n, *state, known)
            if lands:
                r.record(j, times[j], *state, moments, known)
            if r.observers:
                _notify(r, t, n, h, state)
            control.accepted(t, solver, ss)
    return n


def _notify(r: _Run, t, n, h, state, initial=False):
    """Call the observers (their ``init`` at ``t0``) with a read-only view of the state."""
    view = state_view(t, state[0], state[1], r.shift, n, h)
    for init, update in r.observers:
        if not initial:
            update(t, view, r.scene)
        elif init is not None:
            init(t, view, r.scene)


def _controller(given, spec, rtol, atol, max_steps):
    """The step-size controller of the run: ``given`` (validated against the method and the
    tolerance arguments) or the method's default."""
    if given is None:           # the tolerances are validated whatever the method
        adaptive = AdaptiveStep(rtol=1e-6 if rtol is None else rtol,
                                atol=1e-9 if atol is None else atol, max_steps=max_steps)
        return adaptive if spec.adaptive else ConstantStep()
    if not isinstance(given, (ConstantStep, AdaptiveStep)):
        raise InvalidInput(f"stepsize_controller must be a kinred.integrate.ConstantStep or "
                           f"AdaptiveStep (or None: the method's own), got {_short(given)}")
    named = [f"{k}={v!r}" for k, v in (("rtol", rtol), ("atol", atol),
                                       ("max_steps", max_steps)) if v is not None]
    if named:
        where = ("pass them to AdaptiveStep(...)" if isinstance(given, AdaptiveStep) else
                 "ConstantStep keeps every step and has no tolerances")
        raise InvalidInput(f"simulate got stepsize_controller={given!r} and "
                           f"{', '.join(named)}: with a controller the tolerances and the step "
                           f"budget belong to it ({where})")
    if given.adaptive and not spec.adaptive:
        adaptive = sorted(m for m, sp in SOLVERS.items() if sp.adaptive)
        raise InvalidInput(f"stepsize_controller={given!r} needs a method with an error "
                           f"estimate, got method={spec.name!r}; use one of "
                           f"{', '.join(map(repr, adaptive))}, or ConstantStep()")
    return given


def _check_finite(x0, v0, x_moments, v_moments) -> None:
    """The NaN/Inf test of ``x0`` and ``v0`` (their shapes were validated): the plain sum
    ``T`` of the moments that the working frame's compiled pass gave (non-finite iff an entry
    is, or the sum overflows) clears an array without a pass of its own; an array without
    them, or with a non-finite sum, is tested entry by entry (the error names the entry)."""
    sums = (x_moments, None if v_moments is None else v_moments[0])
    for z, m, name in zip((x0, v0), sums, ("x0", "v0")):
        if z is not None and not (m is not None and np.isfinite(m[2])):
            as_array(z, name)


def _prepare(scene, x0, v0, t_span, dt, method, save, seed, rtol, atol, max_steps,
             observers, stepsize_controller=None) -> _Run:
    """Validate the arguments of :func:`simulate` (before any allocation) and build the run."""
    if not isinstance(scene, Scene):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
    x0, v0 = scene._check_state(x0, v0, ("x0", "v0"), finite=False)
    t0, t1 = as_span(t_span)
    dt = as_float(dt, "dt", low=0.0, low_open=True)
    if not (t1 - t0) / dt <= 2.0**53:  # beyond it t0 + n·dt is no grid (and may be inf)
        raise InvalidInput(f"dt must be at least (t1 - t0)/2**53 = {(t1 - t0) / 2.0**53:.3g} "
                           f"for t_span = ({t0!r}, {t1!r}), got dt = {dt!r}")
    method = method_name(method)
    spec = SOLVERS[method]
    if scene.stochastic and not spec.stochastic:
        noisy = " or ".join(f"method={m!r}" for m, s in SOLVERS.items() if s.stochastic)
        raise InvalidInput(f"method={method!r} cannot integrate a scene with noise; use {noisy}")
    save = SaveAt() if save is None else save
    if not isinstance(save, SaveAt):
        raise InvalidInput(f"save must be a SaveAt, got {save!r}")
    controller = _controller(stepsize_controller, spec, rtol, atol, max_steps)
    rng = as_generator(seed)
    if not (scene.stochastic or getattr(scene.pairsum, "stochastic", False) is True):
        rng = None              # deterministic scenes: the drift gets rng=None
    obs = observable_list(save.observables, scene.order)
    w = scene.agent_weights(x0.shape[0])
    solver = spec.make()
    control = controller.init(solver, t0, t1, dt, method)
    n_steps = None if controller.adaptive else control.n_steps
    check_save_size(save, save_points(save, t0, t1, dt, n_steps), x0.shape, scene.order,
                    len(obs), f"simulate(x0 of shape {x0.shape}, t_span=({t0:g}, {t1:g}), "
                              f"dt={dt:g}, save={save.describe()})")
    grid = save_grid(save, t0, t1, dt, n_steps, method)
    observers = as_observers(observers, method)

    x, v, shift, (x_moments, v_moments) = frame_of(scene, x0, v0, w)
    _check_finite(x0, v0, x_moments, v_moments)
    record = Recorder(save, obs, scene, w, shift, x0.shape, len(grid.times))
    check = DivergenceCheck(scene, getattr(solver, "table", None), method, dt, n_steps, t0,
                            x0, v0, w, v_moments)
    fused = None
    if (type(solver) is ExplicitRK and solver.table.stages == 1 and solver.table.E is None
            and not controller.adaptive and x0.size >= FUSED_MIN):
        fused = EulerMoments(w, record.moments[0], check.moments)
    return _Run(scene, method, solver, control, VectorField(scene), rng, grid, record, check,
                observers, t0, t1, dt, (x, v), shift, fused,
                (x_moments, None if v_moments is None else v_moments[0]))
