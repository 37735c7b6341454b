"""The schema of kinred's TOML inputs: :class:`Key` (one key of a table: type, default, valid
range or choices, one line of documentation), :func:`read_table` (a table checked against its
keys) and :func:`register_entry` (the checks of an open-ended registry such as
:data:`kinred.pairsum.PAIRSUMS` or :data:`kinred.scenefile.EFFECTS`).

Public through :mod:`kinred.scenefile` (``Key``, ``REQUIRED``); it lives on this low layer so
that a package below the scene files (:mod:`kinred.pairsum`) can describe its own options.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any, Callable

from ._validate import _short
from .errors import ConfigError, InvalidInput

__all__ = ["Key", "REQUIRED", "TYPES", "read_table", "register_entry", "unregister_entry",
           "with_defaults", "one_of"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Default of a key that must be given.
REQUIRED = _Required()

#: Value types of keys: checker and how messages and the reference name the type.
TYPES: dict[str, tuple[Callable[[Any], bool], str]] = {
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
    attr : str or None
        Keys of the scene file's :data:`~kinred.scenefile.TABLES`: the attribute of
        :class:`~kinred.scenefile.Config` that holds the value (``""``: the key's name;
        ``None``: none, the value is read by the loader).
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
    attr: str | None = ""

    def __post_init__(self):
        if self.type not in TYPES:
            raise InvalidInput(f"Key {self.name!r}: type must be one of {', '.join(TYPES)}, "
                               f"got {self.type!r}")
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise InvalidInput(f"Key name must be an identifier (letters, digits, '_'), got "
                               f"{self.name!r}")
        if self.attr is not None and (not isinstance(self.attr, str)
                                      or not (self.attr == "" or _NAME.match(self.attr))):
            raise InvalidInput(f"Key {self.name!r}: attr must be an identifier, '' or None, got "
                               f"{self.attr!r}")

    @property
    def attribute(self) -> str | None:
        """The name of the :class:`~kinred.scenefile.Config` attribute of the key, or None."""
        return self.name if self.attr == "" else self.attr

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
        ok, tname = TYPES[self.type]
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
            raise ConfigError(f"{source}: {where}: must be {one_of(choices)}, got {_short(value)}")
        return value

    def _in_range(self, v) -> bool:
        if self.low is not None and (v < self.low or (self.low_open and v == self.low)):
            return False
        hi = self.high
        return not (hi is not None and (v > hi or (self.high_open and v == hi)))


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def one_of(choices) -> str:
    if len(choices) == 2:
        return f"{choices[0]!r} or {choices[1]!r}"
    return "one of " + ", ".join(map(str, choices))


def _key_text(key) -> str:
    """A key as TOML writes it (quoted when it is not bare), so messages stay on one line."""
    if isinstance(key, str) and _BARE_KEY.match(key):
        return key
    return json.dumps(key) if isinstance(key, str) else repr(key)


def read_table(data, keys, source: str, where: str, *, defaults: bool = True,
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
                              f"{TYPES[key.type][1]})")
        elif defaults and key.default is not None:
            out[key.name] = key.default
    return out


_ENTRY_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


def register_entry(registry: dict, what: str, name, entry, tag: str):
    """Add ``entry`` (with attributes ``keys`` and ``doc``) to ``registry`` under ``name``
    after checking them; ``what`` names the registry in messages (``"pair-sum method"``) and
    ``tag`` is the key that selects an entry in a table (``"method"``), which no key may use."""
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


def unregister_entry(registry: dict, what: str, name, builtin) -> None:
    """Remove ``name`` from ``registry`` unless it is one of ``builtin``."""
    if name in builtin:
        raise InvalidInput(f"{name!r} is a built-in {what} and cannot be removed")
    if name not in registry:
        raise InvalidInput(f"{what} {name!r} is not registered; registered: {', '.join(registry)}")
    del registry[name]


def with_defaults(keys, params: dict) -> dict:
    """``params`` with the defaults of the absent optional ``keys`` filled in."""
    out = {k.name: k.default for k in keys if k.default not in (REQUIRED, None)}
    out.update(params)
    return out
