r"""The one registry of integrators: ``SOLVERS``, ordered name → :class:`SolverSpec`.

``simulate(method=...)``, :data:`METHODS`, the scene-file loader (``[integrate] method``) and
the cost study (``kinred cost``, study ``integrators``) all read it. Adding an integrator is one
file: a solver class (``init``/``step``, see :class:`~kinred.integrate.Solver`) and one call::

    register_solver("ralston", lambda: ExplicitRK(RALSTON))

``aliases=("ralston2",)`` adds other names; :func:`method_name` resolves a name or an alias
(case, ``-`` and ``_`` ignored: SciPy's ``"RK45"`` and Diffrax's ``"Dopri5"`` are ``"rk45"``).
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

__all__ = ["SolverSpec", "SOLVERS", "METHODS", "ALIASES", "register_solver", "unregister_solver",
           "method_name"]


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
_ALIASES: dict = {}
_BUILTIN: tuple = ()

#: Registered integrators in order (a live read-only view of the registry).
SOLVERS = types.MappingProxyType(_SOLVERS)

#: Other names of registered integrators, alias → name in :data:`SOLVERS` (a live read-only
#: view). :func:`method_name` matches them, and the names, ignoring case, ``-`` and ``_``.
ALIASES = types.MappingProxyType(_ALIASES)


def _fold(name: str) -> str:
    return name.lower().replace("-", "").replace("_", "")


def method_name(method, name: str = "method") -> str:
    """The registered name of the integrator ``method``: a name of :data:`SOLVERS` or an alias
    (:data:`ALIASES`), case, ``-`` and ``_`` ignored: ``"RK45"``, ``"dopri5"`` and
    ``"Dormand-Prince"`` are ``"rk45"``.

    Raises
    ------
    InvalidInput
        ``method`` is not a string or names no registered integrator (the message, naming the
        argument ``name``, lists the names and the aliases).

    Examples
    --------
    >>> method_name("RK45"), method_name("bs23"), method_name("Euler")
    ('rk45', 'rk23', 'euler')
    """
    if isinstance(method, str):
        if method in _SOLVERS:
            return method
        key = _fold(method)
        for canon in _SOLVERS:
            if _fold(canon) == key:
                return canon
        for alias, canon in _ALIASES.items():
            if _fold(alias) == key:
                return canon
    by: dict = {}
    for alias, canon in _ALIASES.items():
        by.setdefault(canon, []).append(alias)
    also = "; ".join(f"{c} = {', '.join(a)}" for c, a in by.items())
    raise InvalidInput(f"{name} must be one of {', '.join(map(repr, _SOLVERS))}; got "
                       f"{method!r}" + (f" (or an alias, case, '-' and '_' ignored: {also})"
                                        if also else ""))

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def register_solver(name: str, make: Callable, *, adaptive: bool = False,
                    stochastic: bool = False, summary: str = "",
                    aliases: tuple = ()) -> SolverSpec:
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
    aliases : tuple of str
        Other names :func:`method_name` accepts for it (each matching no registered name or
        alias, case, ``-`` and ``_`` ignored).

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
    aliases = (aliases,) if isinstance(aliases, str) else aliases
    if not isinstance(aliases, (tuple, list)) or not all(
            isinstance(a, str) and a.strip() for a in aliases):
        raise InvalidInput(f"aliases must be a tuple of non-empty strings, got {aliases!r}")
    taken = {_fold(n): n for n in (*_SOLVERS, *_ALIASES)}
    clash = [a for a in (name, *aliases) if _fold(a) in taken]
    seen = [_fold(a) for a in (name, *aliases)]
    if clash or len(set(seen)) < len(seen):
        bad = clash[0] if clash else next(a for a in aliases if seen.count(_fold(a)) > 1)
        raise InvalidInput(f"aliases: {bad!r} would name two integrators (it matches "
                           f"{taken.get(_fold(bad), name)!r}; case, '-' and '_' ignored)")
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
    _ALIASES.update((a, name) for a in aliases)
    return spec


def unregister_solver(name: str) -> None:
    """Remove an integrator added by :func:`register_solver` (the built-in ones stay)."""
    if name in _BUILTIN:
        raise InvalidInput(f"{name!r} is a built-in integrator and cannot be removed")
    if name not in _SOLVERS:
        raise InvalidInput(f"name {name!r} is not registered; registered: {', '.join(_SOLVERS)}")
    del _SOLVERS[name]
    for alias in [a for a, c in _ALIASES.items() if c == name]:
        del _ALIASES[alias]


_SUMMARY = {
    "euler": "forward Euler, the paper's scheme (eq. (1.6))",
    "heun": "Heun's method (explicit trapezoidal rule), order 2",
    "rk4": "classical Runge–Kutta, order 4",
    "rk45": "Dormand–Prince 5(4), adaptive, FSAL",
    "rk23": "Bogacki–Shampine 3(2), adaptive, FSAL",
}

#: Other names of the built-in integrators: SciPy's (``RK45``, ``RK23``), Diffrax's (``Dopri5``,
#: ``Bosh3``, ``Euler``, ``Heun``), MATLAB's (``ode45``, ``ode23``), Julia's (``DP5``, ``BS3``,
#: ``RK4``) and the authors' names, matched ignoring case, ``-`` and ``_``.
_BUILTIN_ALIASES = {
    "euler": ("forward_euler", "explicit_euler"),
    "heun": ("explicit_trapezoid",),
    "rk4": ("classical_rk4",),
    "rk45": ("dopri5", "dopri", "dp45", "dp5", "dormand_prince", "ode45"),
    "rk23": ("bs23", "bs32", "bs3", "bosh3", "bogacki_shampine", "ode23"),
    "euler_maruyama": ("em",),
}

for _name, _table in TABLES.items():
    register_solver(_name, (lambda tb=_table: ExplicitRK(tb)), adaptive=_table.E is not None,
                    summary=_SUMMARY.get(_name, ""), aliases=_BUILTIN_ALIASES.get(_name, ()))
register_solver("euler_maruyama", EulerMaruyama, stochastic=True,
                summary="Euler–Maruyama, required for scenes with noise",
                aliases=_BUILTIN_ALIASES["euler_maruyama"])
_BUILTIN = tuple(_SOLVERS)

#: The built-in method names, ``tuple(SOLVERS)`` at import: fixed-step ``"euler"`` (the
#: paper's, eq. (1.6)), ``"heun"``, ``"rk4"``; adaptive embedded pairs ``"rk45"``
#: (Dormand–Prince 5(4)) and ``"rk23"`` (Bogacki–Shampine 3(2)); ``"euler_maruyama"`` for scenes
#: with noise. Integrators registered later appear in :data:`SOLVERS`.
METHODS = _BUILTIN
