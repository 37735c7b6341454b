"""The resolved configuration of a scene: :class:`Config` and :class:`CertifyOptions`, both
derived from :data:`~kinred.scenefile.TABLES` (a key is written once, in its table), with the
digest that ties a result folder to its scene and the builders of the scene's objects."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np

from .._schema import REQUIRED
from .._validate import check_alloc, fmt_count
from ..errors import ConfigError, InvalidInput, TooLarge
from ..pairsum import make_pairsum
from ._effects import build_effect
from ._tables import GROUPED, TABLES

__all__ = ["CertifyOptions", "Config", "FIRST_FORMAT", "config_fields"]

#: Python types of the keys' types (annotations of the derived dataclasses).
_ANNOTATIONS = {"number": "float", "integer": "int", "string": "str", "boolean": "bool",
                "table": "Any", "array of integers": "tuple", "array of tables": "tuple"}

#: The attributes :meth:`Config.to_json` always writes: those of its first format. Attributes
#: added since (``pairsum``, ``certify``, and any key added to :data:`TABLES` from now on)
#: appear only when they differ from their default, so the digest of a scene that does not
#: use them is the one its result folders hold. Never edit this list.
FIRST_FORMAT = ("source", "title", "description", "seed", "d", "effects", "eps", "atoms",
                "rule", "reference_atoms", "max_atoms", "ks", "kind", "projection_seed",
                "method", "dt", "t_final", "save_every", "yes_below", "no_above", "lift_to",
                "lift_seed", "smoke", "precision")


def _field(key):
    """``(attribute, annotation, dataclasses.field)`` of a key."""
    kind = _ANNOTATIONS[key.type]
    if key.default is REQUIRED:
        return key.attribute, kind, dataclasses.field()
    if key.default is None:
        return key.attribute, f"{kind} | None", dataclasses.field(default=None)
    return key.attribute, kind, dataclasses.field(default=key.default)


def config_fields() -> dict:
    """``{attribute: (table, key name)}`` of every key that is an attribute of
    :class:`Config` (``table`` ``""``: the top level)."""
    return {key.attribute: (table, key.name) for table, keys in TABLES.items()
            if table not in GROUPED for key in keys if key.attribute is not None}


CertifyOptions = dataclasses.make_dataclass(
    "CertifyOptions", [_field(k) for k in TABLES["certify"]], frozen=True,
    namespace={"__module__": __name__, "__doc__": """The ``[certify]`` table: whether
    ``kinred run`` certifies each projected run (:func:`kinred.certify.certify`, per k in the k
    stage) and how; its fields are the keys of ``TABLES["certify"]``.

    ``enabled``: ``True`` certifies every k, ``False`` none, ``None`` (the key absent) when it
    is cheap and possible: forward Euler, a scene the certificate covers, an exact pair sum and
    at most ``kinred.experiments.kinetic_certify.AUTO_MAX_ATOMS`` atoms. Where a k is not
    certified its stage says why (``cert_note``). ``norm`` picks the norms the tables print
    (both are always computed); ``paper`` also evaluates the paper's bounds (eq. (2.11),
    (2.18))."""})


def _jsonable(value):
    if dataclasses.is_dataclass(value):
        return dataclasses.asdict(value)
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    return value


class _ConfigMethods:
    """What a :class:`Config` does: its JSON and digest, and the objects of the scene."""

    def to_json(self) -> dict:
        """The configuration as JSON (without ``data``; ``initial``: the measure tables). The
        attributes of ``FIRST_FORMAT`` are always written, the others (``pairsum``,
        ``certify``, any key added since) only when they differ from their default, so the
        digest of a scene without them is unchanged."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "data" or (f.name not in FIRST_FORMAT and f.default is not
                                    dataclasses.MISSING and value == f.default):
                continue
            out[f.name] = _jsonable(value)
        out["initial"] = self.data.get("initial")
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
        return make_pairsum(method, params, precision=self.precision)

    def scene(self):
        """The (unweighted) :class:`~kinred.dynamics.Scene` of the effects
        (``normalize="mean"``) with the pair-sum backend of :meth:`pair_sum`."""
        from ..dynamics import Scene

        effects = [build_effect(t, p, self.d) for t, p in self.effects]
        return Scene(effects, normalize="mean", pairsum=self.pair_sum())

    def initial_measure(self):
        """The phase-space measure ``μ₀`` on ``ℝ²ᵈ`` (lifted when ``lift_to`` is set)."""
        from ..kinetic import lift, phase_space
        from ..measures import measure_from_dict

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


def _config_class():
    fields = [("source", "str", dataclasses.field())]
    for table, keys in TABLES.items():
        fields += [_field(k) for k in keys if table not in GROUPED and k.attribute is not None]
    fields += [(name, "CertifyOptions", dataclasses.field(default=CertifyOptions()))
               for name in GROUPED]
    fields += [("data", "dict", dataclasses.field(repr=False, default_factory=dict)),
               ("smoke", "bool", dataclasses.field(default=False))]
    doc = """A resolved scene: every parameter of one ``kinred run`` (defaults applied).

    Its attributes are derived from :data:`~kinred.scenefile.TABLES`: one per key (named by
    ``Key.attr``, by default the key's name: ``projection.k`` is ``ks``, ``projection.seed``
    ``projection_seed``, ``dynamics.effect`` ``effects``), one options object per table of
    ``GROUPED`` (``certify``: :class:`CertifyOptions`), and ``source`` (the file), ``data``
    (the parsed TOML without ``smoke``, for the measure sections and the hash) and ``smoke``.
    ``effects`` (``((type, {params}), ...)``) and ``pairsum`` (``(method, {params})`` or None
    for the dense backend) hold the keys as given (defaults are applied when built).

    Build it from a file with :func:`load_config` or from a dict with :func:`config_from_dict`.
    """
    methods = {k: v for k, v in vars(_ConfigMethods).items() if not k.startswith("__")}
    return dataclasses.make_dataclass("Config", fields, frozen=True, kw_only=True,
                                      namespace={**methods, "__module__": __name__,
                                                 "__doc__": doc})


Config = _config_class()
