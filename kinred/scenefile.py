r"""Scene files: the schema of ``kinred run``'s input, registries, loader and :class:`Config`.

A scene file (TOML, ``docs/scene-file.md``, examples in ``examples/scenes/``) names the
effects, the initial phase-space measure, the quantization, the projections, the integrator
and the outputs of one ``kinred run``. Every table and key is described once, here, by a
:class:`Key` (type, default, valid range or choices, one line of documentation):

* :func:`config_from_dict` / :func:`load_config` validate with them: an unknown, missing,
  mistyped, non-finite or out-of-range key is a :class:`~kinred.errors.ConfigError` whose one
  line names the file, the table and key, the bad value and what is valid;
* the reference section of ``docs/scene-file.md`` is generated from them
  (:func:`reference_markdown`; ``python -m kinred.scenefile docs/scene-file.md`` rewrites it,
  and ``tests/test_scenefile.py`` fails when the page is out of date).

Two tables are open-ended and read registries: ``[[dynamics.effect]]`` (its ``type`` is a key
of :data:`EFFECTS`) and ``[dynamics.pairsum]`` (its ``method`` is a key of :data:`PAIRSUMS`).
Adding an effect type or a pair-sum backend is one call, e.g.::

    register_effect("quadratic", lambda p, d: Alignment(Quadratic(p["c"])),
                    keys=(Key("c", "number", REQUIRED, "coupling strength", low=0.0),),
                    doc="linear alignment, phi(s) = c")

after which scene files may use ``type = "quadratic"`` with the key ``c``, the loader checks
it, and the generated reference lists it. The integrator (``[integrate] method``) is read from
:data:`kinred.integrate.SOLVERS` (deterministic integrators).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import types
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ._validate import _short, check_alloc, fmt_count
from .errors import ConfigError, InvalidInput, TooLarge

__all__ = ["Key", "REQUIRED", "EffectType", "PairSumType", "EFFECTS", "PAIRSUMS", "TABLES",
           "register_effect", "unregister_effect", "register_pairsum", "unregister_pairsum",
           "CertifyOptions", "Config", "config_from_dict", "load_config", "reference_markdown",
           "SMALL_SCENE"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Default of a key that must be given.
REQUIRED = _Required()

#: Value types of keys: checker and how messages and the reference name the type.
_TYPES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "number": (lambda v: isinstance(v, (int, float)) and not isinstance(v, bool), "a number"),
    "integer": (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
    "string": (lambda v: isinstance(v, str), "a string"),
    "boolean": (lambda v: isinstance(v, bool), "true or false"),
    "table": (lambda v: isinstance(v, dict), "a table"),
    "array of integers": (lambda v: isinstance(v, list) and all(
        isinstance(x, int) and not isinstance(x, bool) for x in v), "an array of integers"),
    "array of tables": (lambda v: isinstance(v, list), "an array of tables"),
}


@dataclass(frozen=True)
class Key:
    """One key of a scene-file table: what the loader checks and the reference documents.

    Parameters
    ----------
    name : str
    type : str
        ``"number"``, ``"integer"``, ``"string"``, ``"boolean"``, ``"table"``,
        ``"array of integers"`` or ``"array of tables"``.
        Numbers must be finite (integers are accepted and converted to float); arrays must
        not be empty.
    default : object
        :data:`REQUIRED`, ``None`` (optional, no value when absent) or the value used when
        the key is absent.
    doc : str
        One line for the reference.
    low, high : float, optional
        Valid range (closed unless ``low_open`` / ``high_open``).
    normalize : callable, optional
        Applied to the value before the choices are checked (e.g. an alias to its name).
    choices : tuple or callable, optional
        Valid values, or a function returning them (a live registry).
    shown_default, shown_choices : str, optional
        How the reference shows a default computed by the loader, or open-ended choices.
    """

    name: str
    type: str
    default: Any = REQUIRED
    doc: str = ""
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple | Callable[[], tuple] | None = None
    shown_default: str | None = None
    shown_choices: str | None = None
    normalize: Callable[[Any], Any] | None = None

    def __post_init__(self):
        if self.type not in _TYPES:
            raise InvalidInput(f"Key {self.name!r}: type must be one of {', '.join(_TYPES)}, "
                               f"got {self.type!r}")
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise InvalidInput(f"Key name must be an identifier (letters, digits, '_'), got "
                               f"{self.name!r}")

    def valid_choices(self) -> tuple | None:
        """The valid values now (a registry's current names), or None."""
        return self.choices() if callable(self.choices) else self.choices

    def range_text(self) -> str:
        """The valid range in words (``"> 0"``, ``"in [0, 1)"``, ``""``)."""
        lo = None if self.low is None else ("> " if self.low_open else ">= ") + f"{self.low:g}"
        hi = None if self.high is None else ("< " if self.high_open else "<= ") + f"{self.high:g}"
        if lo and hi:
            return (f"in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}"
                    f"{')' if self.high_open else ']'}")
        return lo or hi or ""

    def check(self, value, source: str, where: str):
        """``value`` typed (numbers as float), or :class:`~kinred.errors.ConfigError` naming
        ``where``."""
        ok, tname = _TYPES[self.type]
        if not ok(value):
            raise ConfigError(f"{source}: {where}: must be {tname}, got {_short(value)}")
        if self.type.startswith("array") and not value:
            raise ConfigError(f"{source}: {where}: must be a non-empty {tname[3:]}, got []")
        if self.type == "number":
            try:
                value = float(value)
            except OverflowError:
                value = math.inf
            if not math.isfinite(value):
                raise ConfigError(f"{source}: {where}: must be finite, got {_short(value)}")
        if self.type in ("number", "integer") and not self._in_range(value):
            raise ConfigError(f"{source}: {where}: must be {self.range_text()}, got {value!r}")
        if self.normalize is not None:
            value = self.normalize(value)
        choices = self.valid_choices()
        if choices is not None and value not in choices:
            raise ConfigError(f"{source}: {where}: must be {_one_of(choices)}, got {_short(value)}")
        return value

    def _in_range(self, v) -> bool:
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            return False
        hi = self.high
        return not (hi is not None and (v > hi or (self.high_open and v == hi)))


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _one_of(choices) -> str:
    if len(choices) == 2:
        return f"{choices[0]!r} or {choices[1]!r}"
    return "one of " + ", ".join(map(str, choices))


def _key_text(key) -> str:
    """A key as TOML writes it (quoted when it is not bare), so messages stay on one line."""
    if isinstance(key, str) and _BARE_KEY.match(key):
        return key
    return json.dumps(key) if isinstance(key, str) else repr(key)


def _read_table(data, keys, source: str, where: str, *, defaults: bool = True,
                context: str = "") -> dict:
    """The typed values of table ``data`` (``where`` is its dotted name; ``""`` at the top).

    Unknown keys first, then each key in schema order: missing, type, range, choices.
    With ``defaults`` the defaults of absent optional keys are filled in. ``context`` follows
    "unknown key" and "required" in messages (``" for type 'morse'"``).
    """
    prefix = f"{where}." if where else ""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: {where}: must be a table, got {_short(data)}")
    names = {k.name for k in keys}
    unknown = sorted((k for k in data if k not in names), key=str)
    if unknown:
        raise ConfigError(f"{source}: {prefix}{_key_text(unknown[0])}: unknown key{context}; "
                          f"valid keys are {', '.join(sorted(names)) or '(none)'}")
    out = {}
    for key in keys:
        if key.name in data:
            out[key.name] = key.check(data[key.name], source, prefix + key.name)
        elif key.default is REQUIRED:
            raise ConfigError(f"{source}: {prefix}{key.name}: missing (required{context}, "
                              f"{_TYPES[key.type][1]})")
        elif defaults and key.default is not None:
            out[key.name] = key.default
    return out


# ------------------------------------------------------------------------------------------
# registries: effect types and pair-sum backends
# ------------------------------------------------------------------------------------------
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


@dataclass(frozen=True)
class PairSumType:
    """A registered ``[dynamics.pairsum]`` method (a :mod:`kinred.pairsum` backend).

    Attributes
    ----------
    make : callable
        ``make(**params) -> PairSum`` (absent optional keys are not passed); with ``mixed``
        also ``precision=`` (``dynamics.precision``).
    keys : tuple of Key
    doc : str
    mixed : bool
        The backend has a ``precision`` option (``"mixed"``: float32 pair sums); the others
        compute in float64 and refuse ``dynamics.precision = "mixed"``.
    """

    make: Callable
    keys: tuple
    doc: str = ""
    mixed: bool = False


_EFFECTS: dict[str, EffectType] = {}
_PAIRSUMS: dict[str, PairSumType] = {}
_BUILTIN: set = set()

#: Effect types of ``[[dynamics.effect]]``, in order (a live read-only view).
EFFECTS = types.MappingProxyType(_EFFECTS)
#: Methods of ``[dynamics.pairsum]``, in order (a live read-only view).
PAIRSUMS = types.MappingProxyType(_PAIRSUMS)

_ENTRY_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def _register(registry: dict, what: str, name, entry, tag: str):
    if not isinstance(name, str) or not _ENTRY_NAME.match(name):
        raise InvalidInput(f"name must be a lower-case identifier (letters, digits, '_'), got "
                           f"{name!r}")
    if name in registry:
        raise InvalidInput(f"{what} {name!r} is already registered; registered: "
                           f"{', '.join(registry)}")
    keys = entry.keys
    if not isinstance(keys, tuple) or not all(isinstance(k, Key) for k in keys):
        raise InvalidInput(f"keys must be a tuple of kinred.scenefile.Key, got {keys!r}")
    names = [k.name for k in keys]
    if tag in names or len(set(names)) != len(names):
        raise InvalidInput(f"keys must have distinct names other than {tag!r}, got {names}")
    if not isinstance(entry.doc, str):
        raise InvalidInput(f"doc must be a str, got {entry.doc!r}")
    registry[name] = entry
    return entry


def _unregister(registry: dict, what: str, name) -> None:
    if (what, name) in _BUILTIN:
        raise InvalidInput(f"{name!r} is a built-in {what} and cannot be removed")
    if name not in registry:
        raise InvalidInput(f"{what} {name!r} is not registered; registered: {', '.join(registry)}")
    del registry[name]


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
    return _register(_EFFECTS, "effect type", name, EffectType(build, keys, doc), "type")


def unregister_effect(name: str) -> None:
    """Remove an effect type added by :func:`register_effect` (the built-in ones stay)."""
    _unregister(_EFFECTS, "effect type", name)


def register_pairsum(name: str, make: Callable, *, keys: tuple = (), doc: str = "",
                     mixed: bool = False) -> PairSumType:
    """Register the pair-sum backend ``name`` for ``[dynamics.pairsum]`` (see
    :class:`PairSumType` for ``make`` and ``mixed``; errors as :func:`register_effect`)."""
    if not callable(make):
        raise InvalidInput(f"make must be callable as make(**params), got {make!r}")
    if not isinstance(mixed, bool):
        raise InvalidInput(f"mixed must be True or False, got {mixed!r}")
    return _register(_PAIRSUMS, "pair-sum method", name, PairSumType(make, keys, doc, mixed),
                     "method")


def unregister_pairsum(name: str) -> None:
    """Remove a pair-sum backend added by :func:`register_pairsum` (the built-in ones stay)."""
    _unregister(_PAIRSUMS, "pair-sum method", name)


def _with_defaults(keys, params: dict) -> dict:
    out = {k.name: k.default for k in keys if k.default not in (REQUIRED, None)}
    out.update(params)
    return out


def _build_alignment(p, d):
    from .dynamics import Alignment, CuckerSmale

    return Alignment(CuckerSmale(G=p["G"], beta=p["beta"]), on=p["on"])


def _build_morse(p, d):
    from .dynamics import AttractionRepulsion, Morse

    return AttractionRepulsion(Morse(p["Ca"], p["la"], p["Cr"], p["lr"], soft=p["soft"]))


def _build_self_propulsion(p, d):
    from .dynamics import SelfPropulsion

    return SelfPropulsion(p["a"], p["b"])


def _build_free(p, d):
    from .dynamics import Drift

    return Drift(np.zeros(d))


def _dense(**kw):
    from .pairsum import Dense

    return Dense(**kw)


def _numpy():
    from .pairsum import Numpy

    return Numpy()


def _random_batch(**kw):
    from .pairsum import RandomBatch

    return RandomBatch(**kw)


def _nufft(**kw):
    from .pairsum import NUFFT

    return NUFFT(**kw)


def _cells(**kw):
    from .pairsum import CellList

    return CellList(**kw)


def _auto(**kw):
    from .pairsum import Auto

    return Auto(**kw)


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
    register_pairsum("dense", _dense, mixed=True, keys=(
        Key("block", "integer", None, "rows per block", low=1,
            shown_default="chosen from N, d and the threads"),
    ), doc="exact: blocked BLAS products and numba kernels (the default)")
    register_pairsum("numpy", _numpy, doc="exact: the plain-numpy twin, float64 (reference)")
    register_pairsum("random_batch", _random_batch, keys=(
        Key("p", "integer", 2, "agents per random batch", low=2),
        Key("block", "integer", None, "batches per block of the kernel", low=1,
            shown_default="the backend's"),
    ), doc="random batch method: pair sums inside random batches of p agents, unbiased, "
           "O(N p d) per step; the run's seed draws the batches (use euler)")
    register_pairsum("nufft", _nufft, keys=(
        Key("tol", number, 1e-6, "target relative accuracy of the pair sums", low=0.0,
            high=1.0, low_open=True, high_open=True),
        Key("max_modes", "integer", 2**20, "largest number of Fourier modes (TooLarge beyond)",
            low=1),
    ), doc="fast summation by non-equispaced FFTs (finufft) of smooth radial kernels, "
           "distances in k ≤ 3 dimensions, O(N + n^k log n) per step")
    register_pairsum("cells", _cells, keys=(
        Key("tol", number, 1e-6, "target relative accuracy (sets the cutoff from the kernels' "
            "declared tails)", low=0.0, high=1.0, low_open=True, high_open=True),
    ), doc="cell list: short-range kernels truncated at a distance set from tol, distances "
           "in k ≤ 3 dimensions, O(N) memory")
    register_pairsum("auto", _auto, keys=(
        Key("tol", number, 1e-6, "target relative accuracy of the approximate candidates",
            low=0.0, high=1.0, low_open=True, high_open=True),
    ), doc="the deterministic backend (dense, nufft, cells) of least estimated cost for each "
           "system and cloud, re-chosen when the cloud changes shape; never random_batch")
    _BUILTIN.update(("effect type", n) for n in _EFFECTS)
    _BUILTIN.update(("pair-sum method", n) for n in _PAIRSUMS)


_register_builtins()


# ------------------------------------------------------------------------------------------
# the tables
# ------------------------------------------------------------------------------------------
def _deterministic_methods() -> tuple:
    from .integrate import SOLVERS

    return tuple(m for m, spec in SOLVERS.items() if not spec.stochastic)  # scene files: no noise


def _method_alias(value):
    """The registered name of an integrator alias (``"RK45"``, ``"dopri5"``), else ``value``."""
    from .integrate import method_name

    try:
        return method_name(value)
    except InvalidInput:
        return value


def _projection_kinds() -> tuple:
    from .projection import KINDS

    return tuple(KINDS)


#: The tables of a scene file and their keys (``""``: the top level). ``dynamics.effect`` and
#: ``dynamics.pairsum`` are read through :data:`EFFECTS` and :data:`PAIRSUMS`, the measure
#: tables of ``initial`` by :func:`kinred.measures.measure_from_dict`.
TABLES: dict[str, tuple] = {
    "": (
        Key("title", "string", None, "title of the report", shown_default="the file name"),
        Key("description", "string", "", "text under the title"),
        Key("seed", "integer", 0, "seed of the run's random draws (random batches); recorded",
            low=0),
        Key("dynamics", "table", REQUIRED, "the effects"),
        Key("initial", "table", REQUIRED, "the initial phase-space measure μ₀"),
        Key("quantize", "table", REQUIRED, "μ₀ → μ₀ᴺ"),
        Key("projection", "table", REQUIRED, "the JL projections"),
        Key("integrate", "table", REQUIRED, "the integrator"),
        Key("output", "table", None, "the flocking rule"),
        Key("certify", "table", None, "certified error bounds per k (kinred.certify)"),
        Key("smoke", "table", None, "tiny sizes for --smoke"),
    ),
    "dynamics": (
        Key("d", "integer", REQUIRED, "dimension of positions (and of velocities)", low=1),
        Key("precision", "string", "double", '"mixed": float32 pair sums, float64 state '
            "(dense backend)", choices=("double", "mixed")),
        Key("effect", "array of tables", REQUIRED, "one [[dynamics.effect]] table per effect; "
            'the scene is their sum, normalize = "mean"'),
        Key("pairsum", "table", None, "the pair-sum backend", shown_default='`method = "dense"`'),
    ),
    "initial": (
        Key("positions", "table", None, "a measure table on R^d (docs/measures-file.md)"),
        Key("velocities", "table", None,
            "idem for the velocities; μ₀ = positions ⊗ velocities"),
        Key("phase", "table", None, "or: a joint measure on R^(2d), d positions then d "
            "velocities"),
        Key("lift_to", "integer", None, "embed by a random isometry diag(Q, Q) into "
            "R^(2·lift_to); must equal dynamics.d", low=1),
        Key("lift_seed", "integer", 0, "seed of the isometry", low=0),
    ),
    "quantize": (
        Key("eps", "number", None, "target W1(μ₀, μ₀ᴺ) ≤ eps (delayed-curse budget, "
            "eq. (4.22)); exactly one of eps and atoms", low=0.0, low_open=True),
        Key("atoms", "integer", None, "or: the atom budget N", low=1),
        Key("rule", "string", "midpoint", '"midpoint" (σ/2N) or "paper" (σ/N, eq. (4.21))',
            choices=("midpoint", "paper")),
        Key("reference_atoms", "integer", None, "finer reference for estimates of "
            "W1(μ_M(t), ν(t)); more than atoms (with eps: more than the N the budget "
            "picks, checked when the run has quantized)", low=1),
        Key("max_atoms", "integer", 200_000, "refusal limit of the atom count", low=1),
    ),
    "projection": (
        Key("k", "array of integers", REQUIRED, "target dimensions, 1 ≤ k ≤ d, each once"),
        Key("kind", "string", "gaussian", "the JL family", choices=_projection_kinds),
        Key("seed", "integer", 0, "M for k uses member_seed(seed, k)", low=0),
    ),
    "integrate": (
        Key("method", "string", "euler", "the integrator", choices=_deterministic_methods,
            shown_choices="a deterministic integrator of kinred.integrate.SOLVERS: euler (the "
                          "paper's), heun, rk4, rk45, rk23 or a registered one, or an alias "
                          "of kinred.integrate.ALIASES (dopri5, RK45, bs23, RK23, ...)",
            normalize=_method_alias),
        Key("dt", "number", REQUIRED, "time step", low=0.0, low_open=True),
        Key("t_final", "number", REQUIRED, "final time, a multiple of dt", low=0.0,
            low_open=True),
        Key("save_every", "integer", None, "save (and compare) every this many steps", low=1,
            shown_default="steps // 20"),
    ),
    "output": (
        Key("yes_below", "number", 1e-10, "flocking if Γ(T) < yes_below (§3.4.1)", low=0.0),
        Key("no_above", "number", 1e-3, "no flocking if Γ(T) > no_above", low=0.0),
    ),
    "certify": (
        Key("enabled", "boolean", None, "true: certify every k (kinred.certify); false: never; "
            "absent: when cheap (Euler, certifiable scene, exact pair sum, N ≤ 2000 atoms)",
            shown_default="absent (auto)"),
        Key("norm", "string", "both", "certified norms printed by kinred certify: weighted "
            "RMS over agents (eq. (2.18)), maximum over agents (eq. (2.11)) or both (both are "
            "computed and stored)",
            choices=("rms", "max", "both")),
        Key("paper", "boolean", True, "also evaluate the paper's bounds (eq. (2.11), (2.18); "
            "one high-dimensional pair pass per saved time)"),
    ),
}

#: ``[smoke]``: the keys it may replace with ``--smoke`` (``smoke.atoms`` replaces
#: ``quantize.eps`` too), each checked as the key it replaces.
SMOKE_TARGETS = {"atoms": "quantize", "reference_atoms": "quantize", "k": "projection",
                 "t_final": "integrate", "dt": "integrate", "save_every": "integrate"}


def _smoke_keys() -> tuple:
    out = []
    for name, table in SMOKE_TARGETS.items():
        key = next(k for k in TABLES[table] if k.name == name)
        doc = f"replaces {table}.{name}" + (" (and quantize.eps)" if name == "atoms" else "")
        out.append(Key(name, key.type, None, doc + " with --smoke", key.low,
                       key.high, key.low_open, key.high_open, key.choices))
    return tuple(out)


TABLES["smoke"] = _smoke_keys()


# ------------------------------------------------------------------------------------------
# the resolved configuration
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CertifyOptions:
    """The ``[certify]`` table: whether ``kinred run`` certifies each projected run
    (:func:`kinred.certify.certify`, per k in the k stage) and how.

    ``enabled``: ``True`` certifies every k, ``False`` none, ``None`` (the key absent) when it
    is cheap and possible: forward Euler, a scene the certificate covers, an exact pair sum and
    at most ``kinred.experiments.kinetic_certify.AUTO_MAX_ATOMS`` atoms. Where a k is not
    certified its stage says why (``cert_note``). ``norm`` picks the norms the tables print
    (both are always computed); ``paper`` also evaluates the paper's bounds (eq. (2.11),
    (2.18))."""

    enabled: bool | None = None
    norm: str = "both"
    paper: bool = True


@dataclass(frozen=True)
class Config:
    """A resolved scene: every parameter of one ``kinred run`` (defaults applied).

    Build it from a file with :func:`load_config` or from a dict with :func:`config_from_dict`.
    ``data`` keeps the parsed TOML (without ``smoke``) for the measure sections and the hash.
    ``effects`` and ``pairsum`` hold the keys as given (defaults are applied when built).
    """

    source: str
    title: str
    description: str
    seed: int
    d: int
    effects: tuple            # ((type, {params}), ...)
    eps: float | None
    atoms: int | None
    rule: str
    reference_atoms: int | None
    max_atoms: int
    ks: tuple
    kind: str
    projection_seed: int
    method: str
    dt: float
    t_final: float
    save_every: int
    yes_below: float
    no_above: float
    lift_to: int | None
    lift_seed: int
    data: dict = field(repr=False, default_factory=dict)
    smoke: bool = False
    precision: str = "double"
    pairsum: tuple | None = None  # (method, {params}); None: the dense backend
    certify: CertifyOptions = CertifyOptions()

    def to_json(self) -> dict:
        """The configuration as JSON. ``pairsum`` and ``certify`` (added after the first
        format) appear only when set (``certify``: when it differs from the defaults), so the
        digest of a scene without them is unchanged."""
        skip = ("data", "pairsum", "certify")
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in skip}
        out["effects"] = [[t, p] for t, p in self.effects]
        out["ks"] = list(self.ks)
        out["initial"] = self.data.get("initial")
        if self.pairsum is not None:
            out["pairsum"] = [self.pairsum[0], self.pairsum[1]]
        if self.certify != CertifyOptions():
            out["certify"] = asdict(self.certify)
        return out

    def digest(self) -> str:
        """SHA-256 of the resolved configuration (what a resumed run must match)."""
        blob = json.dumps({k: v for k, v in self.to_json().items() if k != "source"},
                          sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()

    # -- builders ----------------------------------------------------------------------
    def pair_sum(self):
        """The :mod:`kinred.pairsum` backend of ``[dynamics.pairsum]`` (default: ``Dense``
        with ``dynamics.precision``)."""
        method, params = self.pairsum if self.pairsum is not None else ("dense", {})
        entry = PAIRSUMS[method]
        kwargs = _with_defaults(entry.keys, params)
        if entry.mixed:
            kwargs["precision"] = self.precision
        return entry.make(**kwargs)

    def scene(self):
        """The (unweighted) :class:`~kinred.dynamics.Scene` of the effects
        (``normalize="mean"``) with the pair-sum backend of :meth:`pair_sum`."""
        from .dynamics import Scene

        effects = [_build_effect(t, p, self.d) for t, p in self.effects]
        return Scene(effects, normalize="mean", pairsum=self.pair_sum())

    def initial_measure(self):
        """The phase-space measure ``μ₀`` on ``ℝ²ᵈ`` (lifted when ``lift_to`` is set)."""
        from .kinetic import lift, phase_space
        from .measures import measure_from_dict

        ini = self.data["initial"]
        if "phase" in ini:
            mu = measure_from_dict(ini["phase"], source=f"{self.source}: initial.phase")
            if mu.dim % 2:
                raise ConfigError(f"{self.source}: initial.phase: must have an even number of "
                                  f"coordinates (d positions, then d velocities), got {mu.dim}")
        else:
            pos = measure_from_dict(ini["positions"], source=f"{self.source}: initial.positions")
            vel = measure_from_dict(ini["velocities"], source=f"{self.source}: initial.velocities")
            try:
                mu = phase_space(pos, vel)
            except InvalidInput as exc:
                raise ConfigError(f"{self.source}: initial: {exc}") from None
        if self.lift_to is not None:
            try:
                mu = lift(mu, self.lift_to, seed=self.lift_seed)
            except InvalidInput as exc:
                raise ConfigError(f"{self.source}: initial.lift_to: {exc}") from None
            except TooLarge as exc:
                raise TooLarge(f"{self.source}: initial.lift_to: {exc}") from None
        if mu.dim != 2 * self.d:
            raise ConfigError(f"{self.source}: dynamics.d: is {self.d} but the initial measure "
                              f"lives on R^{mu.dim // 2} (positions) after lifting")
        return mu

    def times(self) -> np.ndarray:
        """The saved times: every ``save_every`` steps of ``dt``, and ``t_final``."""
        n = int(round(self.t_final / self.dt))
        count = n // self.save_every + 2  # times, indices and unique's copies: 32 bytes each
        check_alloc(32 * count, f"{self.source}: integrate.save_every = {self.save_every}: "
                    f"{fmt_count(count)} saved times", "a larger integrate.save_every")
        idx = np.unique(np.r_[np.arange(0, n + 1, self.save_every), n])
        return idx * self.dt


def _build_effect(typ: str, params: dict, d: int):
    entry = EFFECTS[typ]
    return entry.build(_with_defaults(entry.keys, params), d)


# ------------------------------------------------------------------------------------------
# the loader
# ------------------------------------------------------------------------------------------
def _tagged(table, registry, tag: str, noun: str, source: str, where: str):
    """``(name, params)`` of a table whose ``tag`` key selects its registry entry; params as
    given (typed), the entry's defaults not filled in."""
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: {where}: must be a table, got {_short(table)}")
    if tag not in table:
        raise ConfigError(f"{source}: {where}.{tag}: missing (one of {', '.join(registry)})")
    name = table[tag]
    if not isinstance(name, str) or name not in registry:
        raise ConfigError(f"{source}: {where}.{tag}: unknown {noun} {_short(name)}; valid: "
                          f"{', '.join(registry)}")
    body = {k: v for k, v in table.items() if k != tag}
    params = _read_table(body, registry[name].keys, source, where, defaults=False,
                         context=f" for {tag} {name!r}")
    return name, params


def _read_effects(tables, d: int, source: str) -> tuple:
    effects = []
    for i, table in enumerate(tables):
        where = f"dynamics.effect[{i}]"
        typ, params = _tagged(table, EFFECTS, "type", "effect", source, where)
        try:  # value checks beyond the schema by the dynamics constructors
            _build_effect(typ, params, d)
        except InvalidInput as exc:
            raise ConfigError(f"{source}: {where}: {exc}") from None
        effects.append((typ, params))
    return tuple(effects)


def _read_pairsum(table, precision: str, source: str):
    if table is None:
        return None
    method, params = _tagged(table, PAIRSUMS, "method", "pair-sum method", source,
                             "dynamics.pairsum")
    entry = PAIRSUMS[method]
    if precision == "mixed" and not entry.mixed:
        mixed = ", ".join(m for m, e in PAIRSUMS.items() if e.mixed)
        raise ConfigError(f"{source}: dynamics.precision: 'mixed' is an option of the pair-sum "
                          f"methods {mixed}; dynamics.pairsum.method = {method!r} computes in "
                          "double: remove precision or choose another method")
    try:
        entry.make(**_with_defaults(entry.keys, params),
                   **({"precision": precision} if entry.mixed else {}))
    except InvalidInput as exc:
        raise ConfigError(f"{source}: dynamics.pairsum: {exc}") from None
    return method, params


def _read_tables(data: dict, source: str, smoke: bool):
    """Typed tables (defaults filled in, ``[smoke]`` applied with ``smoke``) and, per key,
    the name of the file key that gave its value (``smoke.k`` for ``projection.k``)."""
    top = _read_table(data, TABLES[""], source, "")
    tables = {name: _read_table(top.get(name, {}), keys, source, name)
              for name, keys in TABLES.items() if name}
    origin = {}
    if smoke:
        for key, value in tables["smoke"].items():
            dest = tables[SMOKE_TARGETS[key]]
            dest[key] = value
            origin[f"{SMOKE_TARGETS[key]}.{key}"] = f"smoke.{key}"
            if key == "atoms":
                dest.pop("eps", None)
    return top, tables, origin


def _check_quantize(qu: dict, source: str, at) -> None:
    if ("eps" in qu) == ("atoms" in qu):
        raise ConfigError(f"{source}: quantize.eps: give exactly one of quantize.eps and "
                          "quantize.atoms")
    ref, atoms = qu.get("reference_atoms"), qu.get("atoms")
    if ref is not None and atoms is not None and ref <= atoms:
        raise ConfigError(f"{source}: {at('quantize.reference_atoms')}: the reference must be "
                          f"finer than the run's quantization: need reference_atoms > "
                          f"{at('quantize.atoms')} = {atoms}, got {ref}")


def _check_ks(ks: list, d: int, source: str, at) -> tuple:
    if any(not 1 <= k <= d for k in ks):
        raise ConfigError(f"{source}: {at('projection.k')}: must be a non-empty array of "
                          f"integers in [1, dynamics.d = {d}], got {_short(ks)}")
    twice = sorted({k for k in ks if ks.count(k) > 1})
    if twice:
        raise ConfigError(f"{source}: {at('projection.k')}: each k must appear once (one stage "
                          f"per k), got {_short(ks)} with {', '.join(map(str, twice))} twice "
                          "or more")
    return tuple(int(k) for k in ks)


def _check_time_grid(it: dict, source: str, at) -> int:
    """``save_every`` (default: a twentieth of the steps) after checking the grid."""
    dt, tf = it["dt"], it["t_final"]
    n = tf / dt
    if not n <= 2.0**53:  # beyond it k·dt is not a float64 grid (and n may be inf)
        raise ConfigError(f"{source}: {at('integrate.dt')}: t_final/dt = {n:.3g} steps, more "
                          f"than 2**53 (t_final = {tf}, dt = {dt})")
    if abs(n - round(n)) > 1e-9 * max(1.0, n):
        raise ConfigError(f"{source}: {at('integrate.t_final')}: must be a multiple of "
                          f"dt={dt}, got {tf}")
    return int(it.get("save_every", max(1, int(round(n)) // 20)))


def _check_initial(ini: dict, d: int, source: str) -> None:
    if ("phase" in ini) == ("positions" in ini or "velocities" in ini):
        raise ConfigError(f"{source}: initial.phase: give either initial.phase (a measure on "
                          "R^(2d)) or both initial.positions and initial.velocities")
    if "phase" not in ini:
        for key in ("positions", "velocities"):
            if key not in ini:
                raise ConfigError(f"{source}: initial.{key}: missing (a measure table on R^d)")
    lift_to = ini.get("lift_to")
    if lift_to is not None and lift_to != d:
        raise ConfigError(f"{source}: initial.lift_to: must equal dynamics.d = {d}, got {lift_to}")


def _check_certify(options: CertifyOptions, method: str, source: str) -> None:
    if options.enabled and method != "euler":
        raise ConfigError(f"{source}: certify.enabled: the certificate covers the forward Euler "
                          f"scheme only; set integrate.method = 'euler', got {method!r}")


def config_from_dict(data: dict, source: str = "<scene>", *, smoke: bool = False) -> Config:
    """Validate a parsed scene file (format in ``docs/scene-file.md``) and resolve defaults.

    Parameters
    ----------
    data : dict
        The parsed TOML.
    source : str
        Names the scene in messages (the file's path).
    smoke : bool
        Apply the ``[smoke]`` table (tiny sizes).

    Raises
    ------
    ConfigError
        Unknown, missing, mistyped, non-finite or out-of-range key, or keys that do not fit
        together; the one-line message names ``source``, the key, the bad value and what is
        valid.

    Examples
    --------
    >>> cfg = config_from_dict(SMALL_SCENE)
    >>> cfg.d, cfg.ks, cfg.effects[0][0]
    (3, (1, 2), 'alignment')
    >>> config_from_dict({**SMALL_SCENE, "colour": 1})
    Traceback (most recent call last):
    ...
    kinred.errors.ConfigError: <scene>: colour: unknown key; valid keys are ...
    """
    if not isinstance(source, str):
        raise InvalidInput(f"source must be a str naming the scene, got {source!r}")
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the scene must be a TOML table")
    top, tables, origin = _read_tables(data, source, smoke)
    dyn, ini, qu, pr, it, out = (tables[s] for s in ("dynamics", "initial", "quantize",
                                                     "projection", "integrate", "output"))

    def at(key):
        return origin.get(key, key)

    d = dyn["d"]
    effects = _read_effects(dyn["effect"], d, source)
    pairsum = _read_pairsum(dyn.get("pairsum"), dyn["precision"], source)
    _check_quantize(qu, source, at)
    ks = _check_ks(pr["k"], d, source, at)
    save_every = _check_time_grid(it, source, at)
    if not out["yes_below"] <= out["no_above"]:
        raise ConfigError(f"{source}: output.yes_below: need 0 <= yes_below <= no_above, got "
                          f"{out['yes_below']}, {out['no_above']}")
    _check_initial(ini, d, source)
    certify = CertifyOptions(**tables["certify"])
    _check_certify(certify, it["method"], source)
    return Config(source=source, title=top.get("title", Path(source).stem),
                  description=top["description"], seed=top["seed"], d=d, effects=effects,
                  eps=qu.get("eps"), atoms=qu.get("atoms"), rule=qu["rule"],
                  reference_atoms=qu.get("reference_atoms"), max_atoms=qu["max_atoms"], ks=ks,
                  kind=pr["kind"], projection_seed=pr["seed"], method=it["method"],
                  dt=it["dt"], t_final=it["t_final"], save_every=save_every,
                  yes_below=out["yes_below"], no_above=out["no_above"],
                  lift_to=ini.get("lift_to"), lift_seed=ini["lift_seed"],
                  data={k: v for k, v in data.items() if k != "smoke"}, smoke=smoke,
                  precision=dyn["precision"], pairsum=pairsum, certify=certify)


def load_config(path, *, smoke: bool = False) -> Config:
    """Read and validate a scene file (:class:`~kinred.errors.ConfigError` on any problem).

    Raises
    ------
    ConfigError
        The file is missing, a directory, not UTF-8, not TOML, or has an invalid key or value;
        the one-line message names the file (and the key).
    """
    from .io import read_toml

    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise InvalidInput(f"path must be a str or os.PathLike, got {path!r}")
    path = os.fspath(path)
    data = read_toml(path, what="scene file")
    cfg = config_from_dict(data, source=path, smoke=smoke)
    cfg.initial_measure()  # validate the measure sections now (one-line ConfigError)
    return cfg


#: A tiny scene used in docstrings and tests.
SMALL_SCENE = {
    "dynamics": {"d": 3, "effect": [{"type": "alignment", "G": 1.0, "beta": 0.5}]},
    "initial": {
        "positions": {"coordinate": [{"dist": "uniform", "params": {"loc": 0.0, "scale": 1.0},
                                      "repeat": 3, "decay": 0.5}]},
        "velocities": {"coordinate": [{"dist": "uniform", "params": {"loc": -1.0, "scale": 2.0},
                                       "repeat": 3, "decay": 0.5}]},
    },
    "quantize": {"atoms": 30},
    "projection": {"k": [1, 2]},
    "integrate": {"dt": 0.1, "t_final": 1.0, "save_every": 5},
}


# ------------------------------------------------------------------------------------------
# the reference page
# ------------------------------------------------------------------------------------------
def _cell(text: str) -> str:
    return text.replace("|", "/")


def _key_rows(keys) -> list[str]:
    rows = ["| key | type | default | valid | meaning |", "|---|---|---|---|---|"]
    for k in keys:
        if k.default is REQUIRED:
            default = "required"
        elif k.shown_default is not None:
            default = k.shown_default
        elif k.default is None:
            default = "–"
        else:
            default = f"`{json.dumps(k.default, ensure_ascii=False)}`"
        choices = k.valid_choices() if k.shown_choices is None else None
        valid = (k.shown_choices or (", ".join(f"`{json.dumps(c)}`" for c in choices)
                                     if choices else k.range_text()))
        if k.type.startswith("array") and not valid:
            valid = "non-empty"
        rows.append(f"| `{k.name}` | {k.type} | {_cell(default)} | {_cell(valid)} | "
                    f"{_cell(k.doc)} |")
    return rows


def _tagged_section(title: str, registry, tag: str) -> list[str]:
    out = [f"### {title}", ""]
    for name, entry in registry.items():
        out += [f"`{tag} = \"{name}\"`: {entry.doc}.", ""]
        out += (_key_rows(entry.keys) if entry.keys else ["(no other keys)"]) + [""]
    return out


def reference_markdown() -> str:
    """The reference section of ``docs/scene-file.md``: every table and key of
    :data:`TABLES`, every effect type of :data:`EFFECTS` and pair-sum method of
    :data:`PAIRSUMS` (Markdown, generated)."""
    out = []
    for name, keys in TABLES.items():
        out += [f"### {'Top level' if not name else f'`[{name}]`'}", ""] + _key_rows(keys) + [""]
        if name == "dynamics":
            out += _tagged_section("`[[dynamics.effect]]`", EFFECTS, "type")
            out += _tagged_section("`[dynamics.pairsum]`", PAIRSUMS, "method")
    return "\n".join(out).rstrip() + "\n"


BEGIN = "<!-- BEGIN reference generated by kinred.scenefile.reference_markdown() -->"
END = "<!-- END reference generated by kinred.scenefile.reference_markdown() -->"


def _update_page(path: str) -> bool:
    """Rewrite the generated reference of the page at ``path``; True if it changed."""
    from .io import atomic_write_text, read_text

    text = read_text(path, what="Markdown page")
    head, sep, rest = text.partition(BEGIN)
    _, sep2, tail = rest.partition(END)
    if not sep or not sep2:
        raise InvalidInput(f"{path}: no {BEGIN} ... {END} markers")
    new = f"{head}{BEGIN}\n{reference_markdown()}{END}{tail}"
    if new != text:
        atomic_write_text(path, new)
    return new != text


if __name__ == "__main__":  # python -m kinred.scenefile docs/scene-file.md
    import sys

    for page in sys.argv[1:]:
        print(f"{page}: {'updated' if _update_page(page) else 'up to date'}")
