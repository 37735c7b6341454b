r"""Per-step observers: quantities that need every accepted step, outside the loop's code.

An observer is a callable ``obs(t, state, scene)`` (or, if not callable, an object with
``update(t, state, scene)``), called after every accepted step once its divergence checks
passed, with an optional ``init(t0, state, scene)`` called once at ``t0``.
``state`` is a :class:`StepState`, a small read-only view of the integrator's working arrays.
Error certificates, energies or custom diagnostics are observers; so is the progress bar.
An observer that is valid for some integrators only declares them in an attribute
``methods`` (a tuple of names of :data:`~kinred.integrate.SOLVERS`); ``simulate`` refuses a
run with any other method before the first step (an error certificate of forward Euler,
:class:`kinred.certify.CertificateObserver`, declares ``("euler",)``).

An exception raised by an observer propagates unchanged (an observer may stop a run).

Examples
--------
>>> from kinred.dynamics import Scene, Alignment
>>> from kinred.integrate import simulate
>>> steps = []
>>> tr = simulate(Scene([Alignment()]), np.zeros((2, 1)), np.eye(2)[:, :1], (0, 1), 0.25,
...               observers=lambda t, s, scene: steps.append((s.step, t)))
>>> steps
[(1, 0.25), (2, 0.5), (3, 0.75), (4, 1.0)]
"""

from __future__ import annotations

from typing import AbstractSet, Mapping, NamedTuple, Protocol, runtime_checkable

import numpy as np

from .. import observables as _obs
from ..errors import InvalidInput
from . import _kernels

__all__ = ["StepState", "Observer", "as_observers", "Progress", "working_frame"]


class StepState(NamedTuple):
    """The state after an accepted step, as observers see it.

    Attributes
    ----------
    t : float
        Time reached.
    x : (N, d) ndarray
        Working positions: relative to ``shift`` when it is not None (absolute positions are
        ``x + shift``). Read-only, and overwritten by later steps: copy what you keep.
    v : (N, d) ndarray or None
        Velocities (None for first-order scenes); read-only, overwritten by later steps.
    shift : (d,) ndarray or None
        The constant vector the working positions are relative to (the initial centroid of a
        translation-invariant scene), or None.
    step : int
        Accepted steps so far (0 at ``init``).
    h : float
        The accepted step's size (0 at ``init``); also ``dt``.
    """

    t: float
    x: np.ndarray
    v: np.ndarray | None
    shift: np.ndarray | None
    step: int
    h: float

    @property
    def dt(self) -> float:
        """The accepted step's size (same as ``h``)."""
        return self.h


@runtime_checkable
class Observer(Protocol):
    """A per-step observer of :func:`simulate`.

    A callable ``obs(t, state, scene)`` or an object with ``update(t, state, scene)`` (used
    when the object is not callable), and optionally ``init(t0, state, scene)``, called once
    at ``t0`` before the first step. ``update`` is called after every accepted step,
    once the step passed the divergence checks and was recorded; ``state`` is a read-only
    :class:`StepState`. An exception raised by an observer propagates unchanged (an
    observer may stop a run). An optional attribute ``methods`` (tuple of integrator names)
    restricts the runs the observer accepts: ``simulate`` refuses other methods before any
    work.
    """

    def __call__(self, t: float, state: StepState, scene) -> None: ...


def working_frame(scene, x0: np.ndarray, v0: np.ndarray | None) -> tuple:
    """``(x, v, shift)``: the working state a run of ``scene`` starts from (fresh arrays).

    For a translation-invariant scene the positions are taken relative to the initial
    weighted centroid ``shift`` (so that their rounding is relative to the cloud's spread,
    not to its distance from the origin); otherwise ``shift`` is None and ``x`` a copy of
    ``x0``. This is the frame of :class:`StepState` and of :func:`~kinred.integrate.simulate`.

    Parameters
    ----------
    scene : Scene
    x0 : (N, d) array_like
    v0 : (N, d) array_like or None
        None for first-order scenes.

    Examples
    --------
    >>> from kinred.dynamics import Scene, Alignment
    >>> x, v, shift = working_frame(Scene([Alignment()]), np.array([[1.0], [3.0]]),
    ...                             np.zeros((2, 1)))
    >>> x.ravel(), shift
    (array([-1.,  1.]), array([2.]))
    """
    from ..dynamics import Scene

    if not isinstance(scene, Scene):
        raise InvalidInput(f"scene must be a kinred.dynamics.Scene, got {type(scene).__name__}")
    x0, v0 = scene._check_state(x0, v0, ("x0", "v0"))
    return frame_of(scene, x0, v0, scene.agent_weights(x0.shape[0]))[:3]


#: From this many entries ``N·d`` on, :func:`working_frame` centres the positions by compiled
#: passes (:func:`._kernels.frame`: the centroid summed in blocks, compensated, no
#: temporary; equal to :func:`kinred.observables.centre` to round-off); below, by numpy.
FRAME_MIN = 2 ** 18


def frame_of(scene, x0, v0, w) -> tuple:
    """``(x, v, shift, (mx, mv))``: :func:`working_frame` of a validated state ``(x0, v0)``
    with agent weights ``w``, and what the compiled passes gave besides (else None): the
    moments ``mx`` of ``x0`` (:func:`._kernels.state_moments`) and ``mv = (moments of v0,
    reference centre)`` (:func:`._kernels.copy_moments`: the copy and ``Γ(v0)`` in one
    pass)."""
    mx = mv = None
    large = x0.size >= FRAME_MIN and x0.ndim == 2
    if v0 is None:
        v = None
    elif large:
        v, m, c = _kernels.copy_moments(v0, w)
        mv = (m, c)
    else:
        v = v0.copy()
    if not large or not scene.translation_invariant:
        shift = _obs.centre(x0, w) if scene.translation_invariant else None
        x = x0 - shift if shift is not None else x0.copy()
    else:
        x, shift, mx = _kernels.frame(x0, w)
    return x, v, shift, (mx, mv)


def _readonly(a):
    if a is None:
        return None
    view = a.view()
    view.flags.writeable = False
    return view


def state_view(t, x, v, shift, step, h) -> StepState:
    """A :class:`StepState` of read-only views of the working arrays."""
    return StepState(float(t), _readonly(x), _readonly(v), shift, int(step), float(h))


def as_observers(observers, method: str | None = None) -> list:
    """``[(init or None, update)]`` of ``None``, one observer or a sequence of them; with
    ``method``, an observer whose ``methods`` attribute does not name it is refused."""
    if observers is None:
        return []
    if isinstance(observers, (Mapping, AbstractSet, str, bytes)):  # dict.update is no observer
        raise InvalidInput(f"observers must be a callable obs(t, state, scene), an object with "
                           f"update(t, state, scene), or a sequence of them; got a "
                           f"{type(observers).__name__} {observers!r}")
    if callable(observers) or hasattr(observers, "update") or hasattr(observers, "init"):
        observers = [observers]
    try:
        items = list(observers)
    except TypeError:
        raise InvalidInput(f"observers must be a callable obs(t, state, scene), an object with "
                           f"update(t, state, scene), or a sequence of them; got "
                           f"{observers!r}") from None
    out = []
    for i, o in enumerate(items):
        update = o if callable(o) else getattr(o, "update", None)
        update = update if callable(update) and not isinstance(o, (Mapping, AbstractSet)) else None
        init = getattr(o, "init", None)
        if update is None or (init is not None and not callable(init)):
            raise InvalidInput(f"observers[{i}] = {o!r} is not an observer: it must be callable "
                               f"as obs(t, state, scene) or have a method update(t, state, "
                               f"scene) (and optionally init(t0, state, scene))")
        allowed = getattr(o, "methods", None)
        if method is not None and allowed is not None and method not in tuple(allowed):
            raise InvalidInput(f"observers[{i}] = {o!r} is valid only for method in "
                               f"{tuple(allowed)!r}; got method={method!r}")
        out.append((init, update))
    return out


class Progress:
    """A tqdm progress bar as an observer: steps of a fixed-step run (``n_steps``), or the
    time reached out of ``t1 − t0`` with its rate and remaining time (``n_steps`` None)."""

    def __init__(self, method: str, n_steps: int | None, span: float):
        from tqdm import tqdm

        desc = f"simulate[{method}]"
        self.by_time = n_steps is None
        self.bar = (tqdm(total=n_steps, desc=desc) if not self.by_time else
                    tqdm(total=span, desc=desc, unit="t",
                         bar_format="{l_bar}{bar}| t-t0={n:.4g}/{total:.4g} "
                                    "[{elapsed}<{remaining}]"))
        self.t = None

    def init(self, t0, state, scene):
        self.t = t0

    def update(self, t, state, scene):
        self.bar.update(t - self.t if self.by_time else 1)
        self.t = t

    def close(self):
        self.bar.close()
