"""The loader: :func:`config_from_dict` and :func:`load_config` check a scene against
:data:`~kinred.scenefile.TABLES` and the registries and resolve it into a :class:`Config`."""

from __future__ import annotations

import os
from pathlib import Path

from .._schema import read_table
from .._validate import _short
from ..errors import ConfigError, InvalidInput
from ..pairsum import PAIRSUMS, make_pairsum
from ._config import CertifyOptions, Config, config_fields
from ._effects import EFFECTS, build_effect
from ._tables import SMOKE_TARGETS, TABLES

__all__ = ["config_from_dict", "load_config", "SMALL_SCENE"]


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
    params = read_table(body, registry[name].keys, source, where, defaults=False,
                         context=f" for {tag} {name!r}")
    return name, params


def _read_effects(tables, d: int, source: str) -> tuple:
    effects = []
    for i, table in enumerate(tables):
        where = f"dynamics.effect[{i}]"
        typ, params = _tagged(table, EFFECTS, "type", "effect", source, where)
        try:  # value checks beyond the schema by the dynamics constructors
            build_effect(typ, params, d)
        except InvalidInput as exc:
            raise ConfigError(f"{source}: {where}: {exc}") from None
        effects.append((typ, params))
    return tuple(effects)


def _read_pairsum(table, precision: str, source: str):
    if table is None:
        return None
    method, params = _tagged(table, PAIRSUMS, "method", "pair-sum method", source,
                             "dynamics.pairsum")
    if precision == "mixed" and not PAIRSUMS[method].mixed:
        mixed = ", ".join(m for m, e in PAIRSUMS.items() if e.mixed)
        raise ConfigError(f"{source}: dynamics.precision: 'mixed' is an option of the pair-sum "
                          f"methods {mixed}; dynamics.pairsum.method = {method!r} computes in "
                          "double: remove precision or choose another method")
    try:
        make_pairsum(method, params, precision=precision)
    except InvalidInput as exc:
        raise ConfigError(f"{source}: dynamics.pairsum: {exc}") from None
    return method, params


def _read_tables(data: dict, source: str, smoke: bool):
    """Typed tables (defaults filled in, ``[smoke]`` applied with ``smoke``) and, per key,
    the name of the file key that gave its value (``smoke.k`` for ``projection.k``)."""
    top = read_table(data, TABLES[""], source, "")
    tables = {name: read_table(top.get(name, {}), keys, source, name)
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
    values = {attr: (top if table == "" else tables[table]).get(name)
              for attr, (table, name) in config_fields().items()}
    values.update(title=top.get("title", Path(source).stem), effects=effects, pairsum=pairsum,
                  ks=ks, save_every=save_every)       # the keys resolved above
    return Config(source=source, certify=certify, smoke=smoke, **values,
                  data={k: v for k, v in data.items() if k != "smoke"})


def load_config(path, *, smoke: bool = False) -> Config:
    """Read and validate a scene file (:class:`~kinred.errors.ConfigError` on any problem).

    Raises
    ------
    ConfigError
        The file is missing, a directory, not UTF-8, not TOML, or has an invalid key or value;
        the one-line message names the file (and the key).
    """
    from ..io import read_toml

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
