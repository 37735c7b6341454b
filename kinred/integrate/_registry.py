r"""The one registry of integrators: ``SOLVERS``, ordered name → :class:`SolverSpec`.

``simulate(method=...)``, :data:`METHODS`, the scene-file loader (``[integrate] method``) and
the cost study (``kinred cost``, study ``integrators``) all read it. Adding an integrator is one
file: a solver class (``init``/``step``, see :class:`~kinred.integrate.Solver`) and one call::

    register_solver("ralston", lambda: ExplicitRK(RALSTON))

An adaptive solver (one returning error estimates) runs under the adaptive step-size
controller with ``rtol``/``atol``/``max_steps``; a stochastic one integrates scenes with noise.
"""

from __future__ import annotations

import re
import types
from dataclasses import dataclass
from typing import Callable

from ..errors import InvalidInput
from ._solvers import EulerMaruyama, ExplicitRK
from ._tables import TABLES

__all__ = ["SolverSpec", "SOLVERS", "METHODS", "register_solver", "unregister_solver"]


@dataclass(frozen=True)
class SolverSpec:
    """A registered integrator.

    Attributes
    ----------
    name : str
    make : callable
        ``make() -> Solver``: a fresh solver for one run.
    order : int
        Convergence order (Euler–Maruyama: strong order 1 for additive noise).
    adaptive : bool
        It returns error estimates and runs under the adaptive controller.
    stochastic : bool
        It integrates scenes with noise (the others refuse them).
    summary : str
        One line for listings.
    """

    name: str
    make: Callable
    order: int
    adaptive: bool
    stochastic: bool
    summary: str = ""


_SOLVERS: dict = {}
_BUILTIN: tuple = ()

#: Registered integrators in order (a live read-only view of the registry).
SOLVERS = types.MappingProxyType(_SOLVERS)

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def register_solver(name: str, make: Callable, *, adaptive: bool = False,
                    stochastic: bool = False, summary: str = "") -> SolverSpec:
    """Register an integrator under ``name`` (see the module notes).

    Parameters
    ----------
    name : str
        Lower-case identifier (letters, digits, ``_``), not registered yet.
    make : callable
        ``make() -> Solver``, called once here to check the protocol and once per run.
    adaptive, stochastic : bool
        See :class:`SolverSpec`.
    summary : str

    Returns
    -------
    SolverSpec
        ``order`` is the made solver's ``order`` attribute.

    Raises
    ------
    InvalidInput
        A bad or taken name, or ``make()`` does not give a solver.
    """
    if not isinstance(name, str) or not _NAME.match(name):
        raise InvalidInput(f"name must be a lower-case identifier (letters, digits, '_'), "
                           f"got {name!r}")
    if name in _SOLVERS:
        raise InvalidInput(f"name {name!r} is already registered; registered: "
                           f"{', '.join(_SOLVERS)}")
    for flag, val in (("adaptive", adaptive), ("stochastic", stochastic)):
        if not isinstance(val, bool):
            raise InvalidInput(f"{flag} must be True or False, got {val!r}")
    if not callable(make):
        raise InvalidInput(f"make must be a callable returning a solver, got {make!r}")
    probe = make()
    missing = [m for m in ("init", "step") if not callable(getattr(probe, m, None))]
    order = getattr(probe, "order", None)
    if missing or isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise InvalidInput(f"make() must return a solver with methods init(f, t0, state, dt) "
                           f"and step(f, t, state, h, solver_state, rng) and an integer "
                           f"attribute order >= 1; got {probe!r} (missing: "
                           f"{', '.join(missing) or 'none'}, order={order!r})")
    spec = SolverSpec(name, make, order, adaptive, stochastic, str(summary))
    _SOLVERS[name] = spec
    return spec


def unregister_solver(name: str) -> None:
    """Remove an integrator added by :func:`register_solver` (the built-in ones stay)."""
    if name in _BUILTIN:
        raise InvalidInput(f"{name!r} is a built-in integrator and cannot be removed")
    if name not in _SOLVERS:
        raise InvalidInput(f"name {name!r} is not registered; registered: {', '.join(_SOLVERS)}")
    del _SOLVERS[name]


_SUMMARY = {
    "euler": "forward Euler, the paper's scheme (eq. (1.6))",
    "heun": "Heun's method (explicit trapezoidal rule), order 2",
    "rk4": "classical Runge–Kutta, order 4",
    "rk45": "Dormand–Prince 5(4), adaptive, FSAL",
    "rk23": "Bogacki–Shampine 3(2), adaptive, FSAL",
}

for _name, _table in TABLES.items():
    register_solver(_name, (lambda tb=_table: ExplicitRK(tb)), adaptive=_table.E is not None,
                    summary=_SUMMARY.get(_name, ""))
register_solver("euler_maruyama", EulerMaruyama, stochastic=True,
                summary="Euler–Maruyama, required for scenes with noise")
_BUILTIN = tuple(_SOLVERS)

#: The built-in method names, ``tuple(SOLVERS)`` at import: fixed-step ``"euler"`` (the
#: paper's, eq. (1.6)), ``"heun"``, ``"rk4"``; adaptive embedded pairs ``"rk45"``
#: (Dormand–Prince 5(4)) and ``"rk23"`` (Bogacki–Shampine 3(2)); ``"euler_maruyama"`` for scenes
#: with noise. Integrators registered later appear in :data:`SOLVERS`.
METHODS = _BUILTIN
