"""The registry of ``[[dynamics.effect]]`` types: :data:`EFFECTS` (the pair-sum backends of
``[dynamics.pairsum]`` are :data:`kinred.pairsum.PAIRSUMS`, shared with ``Scene(pairsum=...)``)."""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .._schema import REQUIRED, Key, register_entry, unregister_entry, with_defaults
from ..errors import InvalidInput

__all__ = ["EffectType", "EFFECTS", "register_effect", "unregister_effect", "build_effect"]


@dataclass(frozen=True)
class EffectType:
    """A registered ``[[dynamics.effect]]`` type.

    Attributes
    ----------
    build : callable
        ``build(params, d) -> Effect`` with ``params`` the table's keys (defaults filled in)
        and ``d`` the dimension; an :class:`~kinred.errors.InvalidInput` it raises becomes a
        :class:`~kinred.errors.ConfigError` naming the table.
    keys : tuple of Key
    doc : str
    """

    build: Callable
    keys: tuple
    doc: str = ""


_EFFECTS: dict[str, EffectType] = {}
_BUILTIN: set = set()

#: Effect types of ``[[dynamics.effect]]``, in order (a live read-only view).
EFFECTS = types.MappingProxyType(_EFFECTS)


def register_effect(name: str, build: Callable, *, keys: tuple = (), doc: str = "") -> EffectType:
    """Register the effect type ``name`` for ``[[dynamics.effect]]`` tables.

    Parameters
    ----------
    name : str
        Lower-case identifier, not registered yet (the value of ``type``).
    build : callable
        ``build(params: dict, d: int) -> Effect``; ``params`` holds the table's keys with the
        defaults of absent optional keys filled in.
    keys : tuple of Key
        The table's keys besides ``type``.
    doc : str
        One line for the reference (``docs/scene-file.md``).

    Returns
    -------
    EffectType

    Raises
    ------
    InvalidInput
        A bad or taken name, ``build`` not callable, keys that are not :class:`Key` objects
        or repeat a name.
    """
    if not callable(build):
        raise InvalidInput(f"build must be callable as build(params, d), got {build!r}")
    return register_entry(_EFFECTS, "effect type", name, EffectType(build, keys, doc), "type")


def unregister_effect(name: str) -> None:
    """Remove an effect type added by :func:`register_effect` (the built-in ones stay)."""
    unregister_entry(_EFFECTS, "effect type", name, _BUILTIN)


def build_effect(typ: str, params: dict, d: int):
    """The effect of type ``typ`` with the table's ``params`` (defaults filled in)."""
    entry = EFFECTS[typ]
    return entry.build(with_defaults(entry.keys, params), d)


def _build_alignment(p, d):
    from ..dynamics import Alignment, CuckerSmale

    return Alignment(CuckerSmale(G=p["G"], beta=p["beta"]), on=p["on"])


def _build_morse(p, d):
    from ..dynamics import AttractionRepulsion, Morse

    return AttractionRepulsion(Morse(p["Ca"], p["la"], p["Cr"], p["lr"], soft=p["soft"]))


def _build_self_propulsion(p, d):
    from ..dynamics import SelfPropulsion

    return SelfPropulsion(p["a"], p["b"])


def _build_free(p, d):
    from ..dynamics import Drift

    return Drift(np.zeros(d))


def _register_builtins():
    number = "number"
    register_effect("alignment", _build_alignment, keys=(
        Key("G", number, REQUIRED, "coupling strength G", low=0.0),
        Key("beta", number, REQUIRED, "decay exponent β", low=0.0),
        Key("on", "string", "x", "distances in positions or in velocities", choices=("x", "v")),
    ), doc="Cucker–Smale alignment, g(s) = G/(1+s²)^β (eq. (2.13))")
    register_effect("morse", _build_morse, keys=(
        Key("Ca", number, REQUIRED, "attraction strength", low=0.0),
        Key("la", number, REQUIRED, "attraction length", low=0.0, low_open=True),
        Key("Cr", number, REQUIRED, "repulsion strength", low=0.0),
        Key("lr", number, REQUIRED, "repulsion length", low=0.0, low_open=True),
        Key("soft", number, 0.0, "softening (u bounded and Lipschitz when > 0)", low=0.0),
    ), doc="attraction–repulsion by the Morse potential, u(s) = U′(s)/s (eq. (3.14))")
    register_effect("self_propulsion", _build_self_propulsion, keys=(
        Key("a", number, REQUIRED, "propulsion a"),
        Key("b", number, REQUIRED, "friction b", low=0.0),
    ), doc="self-propulsion and friction (a − b|v|²) v (eq. (3.13))")
    register_effect("free", _build_free, doc="no force: free transport x′ = v")
    _BUILTIN.update(_EFFECTS)


_register_builtins()
