r"""The ``kinred run`` study: a scene file → kinetic and reduced solutions → W1, bound, report.

A scene file (TOML, reference in ``docs/scene-file.md``) gives the effects, the initial
phase-space measure, the quantization (``eps`` or ``atoms``), the projections (``k`` values,
kind), the integrator and the outputs. :func:`run` then

1. quantizes ``μ₀`` and solves the weighted particle system: ``μᴺ(t)``
   (:func:`kinred.kinetic.solve`; stage file ``stages/solve.npz``);
2. optionally solves a finer reference ``μᴺ′(t)`` (``stages/reference.npz``);
3. for every ``k``: draws ``M`` (seed ``member_seed(projection.seed, k)``), solves the reduced
   system ``νᴺ(t)``, computes ``W1(M#μᴺ(t), νᴺ(t))`` exactly, Theorem 4.3's bound with the
   proof's constants, the reference estimate and the flocking / milling observables
   (``stages/k{k}.npz``);
4. writes ``results.npz`` and ``summary.json`` (the run's numbers: the run is complete),
   then the figures and ``report.html``. Each figure is drawn in a guarded call
   (:func:`kinred.report.draw_figure`): a figure that cannot be drawn is replaced by a note in
   the report, never loses the run.

Every stage file is written atomically as soon as it is computed, together with the hash of
the resolved configuration (``stages/config.json``); ``resume=True`` loads the finished
stages and computes only the missing ones (a configuration mismatch is refused). On resume,
a damaged stage file (truncated, not an ``.npz`` archive, missing arrays) is reported by a
:class:`~kinred.errors.KinredWarning` naming it and recomputed. A damaged
``stages/config.json`` is refused (:class:`~kinred.errors.DamagedFile` naming it): it is
what ties the stage files to a configuration, so without it they cannot be trusted; the
message says to delete the folder or to run into another one.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._rng import member_seed
from ..errors import ConfigError, DamagedFile, InvalidInput, KinredWarning

__all__ = ["Config", "RunResult", "run", "load_config", "config_from_dict", "STAGE_HOOK_ENV"]

#: Test hook: ``"<n>:kill"`` makes the process SIGKILL itself right after the n-th stage file is
#: written (deterministic hard interruption for the resume tests). Never set it otherwise.
STAGE_HOOK_ENV = "KINRED_TEST_KILL_AFTER_STAGE"

_EFFECTS = {
    "alignment": {"G": float, "beta": float, "on": str},
    "morse": {"Ca": float, "la": float, "Cr": float, "lr": float, "soft": float},
    "self_propulsion": {"a": float, "b": float},
    "free": {},
}
_EFFECT_REQUIRED = {
    "alignment": ("G", "beta"),
    "morse": ("Ca", "la", "Cr", "lr"),
    "self_propulsion": ("a", "b"),
    "free": (),
}

# section -> {key: (type, required)}
_SCHEMA = {
    "": {"title": (str, False), "description": (str, False), "seed": (int, False),
         "dynamics": (dict, True), "initial": (dict, True), "quantize": (dict, True),
         "projection": (dict, True), "integrate": (dict, True), "output": (dict, False),
         "smoke": (dict, False)},
    "dynamics": {"d": (int, True), "effect": (list, True), "precision": (str, False)},
    "initial": {"positions": (dict, False), "velocities": (dict, False), "phase": (dict, False),
                "lift_to": (int, False),
                "lift_seed": (int, False)},
    "quantize": {"eps": (float, False), "atoms": (int, False), "rule": (str, False),
                 "reference_atoms": (int, False), "max_atoms": (int, False)},
    "projection": {"k": (list, True), "kind": (str, False), "seed": (int, False)},
    "integrate": {"method": (str, False), "dt": (float, True), "t_final": (float, True),
                  "save_every": (int, False)},
    "output": {"yes_below": (float, False), "no_above": (float, False)},
    "smoke": {"atoms": (int, False), "reference_atoms": (int, False), "k": (list, False),
              "t_final": (float, False), "dt": (float, False), "save_every": (int, False)},
}


def _tname(t) -> str:
    return {float: "a number", int: "an integer", str: "a string", dict: "a table",
            list: "an array"}[t]


def _check(value, typ, source, key):
    if typ is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok and not math.isfinite(float(value)):
            raise ConfigError(f"{source}: {key}: must be finite, got {value!r}")
    elif typ is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, typ)
    if not ok:
        raise ConfigError(f"{source}: {key}: must be {_tname(typ)}, got {value!r}")
    return float(value) if typ is float else value


def _table(data, section, source):
    schema = _SCHEMA[section]
    prefix = f"{section}." if section else ""
    unknown = sorted(set(data) - set(schema))
    if unknown:
        raise ConfigError(f"{source}: {prefix}{unknown[0]}: unknown key; valid keys are "
                          f"{', '.join(sorted(schema))}")
    out = {}
    for key, (typ, req) in schema.items():
        if key not in data:
            if req:
                raise ConfigError(f"{source}: {prefix}{key}: missing (required, {_tname(typ)})")
            continue
        out[key] = _check(data[key], typ, source, prefix + key)
    return out


@dataclass(frozen=True)
class Config:
    """A resolved scene: every parameter of one ``kinred run`` (defaults applied).

    Build it from a file with :func:`load_config` or from a dict with :func:`config_from_dict`.
    ``data`` keeps the parsed TOML (without ``smoke``) for the measure sections and the hash.
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

    def to_json(self) -> dict:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k not in ("data",)}
        out["effects"] = [[t, p] for t, p in self.effects]
        out["ks"] = list(self.ks)
        out["initial"] = self.data.get("initial")
        return out

    def digest(self) -> str:
        """SHA-256 of the resolved configuration (what a resumed run must match)."""
        blob = json.dumps({k: v for k, v in self.to_json().items() if k != "source"},
                          sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()

    # -- builders ----------------------------------------------------------------------
    def scene(self):
        """The (unweighted) :class:`~kinred.dynamics.Scene` of the effects (``normalize="mean"``)."""
        from ..dynamics import (Alignment, AttractionRepulsion, CuckerSmale, Drift, Morse, Scene,
                                SelfPropulsion)

        effects = []
        for typ, p in self.effects:
            if typ == "alignment":
                effects.append(Alignment(CuckerSmale(G=p["G"], beta=p["beta"]), on=p.get("on", "x")))
            elif typ == "morse":
                effects.append(AttractionRepulsion(Morse(p["Ca"], p["la"], p["Cr"], p["lr"],
                                                         soft=p.get("soft", 0.0))))
            elif typ == "self_propulsion":
                effects.append(SelfPropulsion(p["a"], p["b"]))
            else:  # free transport: x' = v, v' = 0
                effects.append(Drift(np.zeros(self.d)))
        return Scene(effects, normalize="mean", precision=getattr(self, "precision", "double"))

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
            mu = lift(mu, self.lift_to, seed=self.lift_seed)
        if mu.dim != 2 * self.d:
            raise ConfigError(f"{self.source}: dynamics.d: is {self.d} but the initial measure "
                              f"lives on R^{mu.dim // 2} (positions) after lifting")
        return mu

    def times(self) -> np.ndarray:
        n = int(round(self.t_final / self.dt))
        idx = np.unique(np.r_[np.arange(0, n + 1, self.save_every), n])
        return idx * self.dt


def config_from_dict(data: dict, source: str = "<scene>", *, smoke: bool = False) -> Config:
    """Validate a parsed scene file (format in ``docs/scene-file.md``) and resolve defaults.

    Raises
    ------
    ConfigError
        Unknown, missing or mistyped key; the one-line message names ``source`` and the key.

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
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the scene must be a TOML table")
    top = _table(data, "", source)
    sec = {s: _table(top.get(s, {}), s, source) for s in _SCHEMA if s}
    dyn, ini, qu, pr, it, out, sm = (sec[s] for s in ("dynamics", "initial", "quantize",
                                                     "projection", "integrate", "output", "smoke"))
    if smoke:
        for key, dest in (("atoms", qu), ("reference_atoms", qu), ("k", pr), ("t_final", it),
                          ("dt", it), ("save_every", it)):
            if key in sm:
                dest[key] = sm[key]
                if key == "atoms":
                    dest.pop("eps", None)
    d = dyn["d"]
    precision = dyn.get("precision", "double")
    if precision not in ("double", "mixed"):
        raise ConfigError(f"{source}: dynamics.precision: must be 'double' or 'mixed', got "
                          f"{precision!r}")
    if d < 1:
        raise ConfigError(f"{source}: dynamics.d: must be >= 1, got {d}")
    effects = []
    if not dyn["effect"]:
        raise ConfigError(f"{source}: dynamics.effect: must list at least one [[dynamics.effect]]")
    for i, e in enumerate(dyn["effect"]):
        key = f"dynamics.effect[{i}]"
        if not isinstance(e, dict):
            raise ConfigError(f"{source}: {key}: must be a table, got {e!r}")
        if "type" not in e:
            raise ConfigError(f"{source}: {key}.type: missing (one of {', '.join(_EFFECTS)})")
        typ = e["type"]
        if typ not in _EFFECTS:
            raise ConfigError(f"{source}: {key}.type: unknown effect {typ!r}; valid: "
                              f"{', '.join(_EFFECTS)}")
        allowed = _EFFECTS[typ]
        unknown = sorted(set(e) - set(allowed) - {"type"})
        if unknown:
            raise ConfigError(f"{source}: {key}.{unknown[0]}: unknown key for type {typ!r}; valid "
                              f"keys are {', '.join(sorted(allowed)) or '(none)'}")
        for req in _EFFECT_REQUIRED[typ]:
            if req not in e:
                raise ConfigError(f"{source}: {key}.{req}: missing (required for type {typ!r})")
        params = {k: _check(v, allowed[k], source, f"{key}.{k}") for k, v in e.items() if k != "type"}
        try:  # value checks (ranges) by the dynamics constructors
            Config.scene(_Stub(d, ((typ, params),)))
        except InvalidInput as exc:
            raise ConfigError(f"{source}: {key}: {exc}") from None
        effects.append((typ, params))
    if ("eps" in qu) == ("atoms" in qu):
        raise ConfigError(f"{source}: quantize.eps: give exactly one of quantize.eps and quantize.atoms")
    if "eps" in qu and not qu["eps"] > 0:
        raise ConfigError(f"{source}: quantize.eps: must be > 0, got {qu['eps']}")
    for key in ("atoms", "reference_atoms", "max_atoms"):
        if key in qu and qu[key] < 1:
            raise ConfigError(f"{source}: quantize.{key}: must be >= 1, got {qu[key]}")
    rule = qu.get("rule", "midpoint")
    if rule not in ("midpoint", "paper"):
        raise ConfigError(f"{source}: quantize.rule: must be 'midpoint' or 'paper', got {rule!r}")
    ks = pr["k"]
    if not ks or any(isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= d for k in ks):
        raise ConfigError(f"{source}: projection.k: must be a non-empty array of integers in "
                          f"[1, d={d}], got {ks!r}")
    from ..projection import KINDS

    kind = pr.get("kind", "gaussian")
    if kind not in KINDS:
        raise ConfigError(f"{source}: projection.kind: must be one of {', '.join(KINDS)}, got {kind!r}")
    from ..integrate import SOLVERS

    method = it.get("method", "euler")
    methods = [m for m, spec in SOLVERS.items() if not spec.stochastic]   # scene files: no noise
    if method not in methods:
        raise ConfigError(f"{source}: integrate.method: must be one of "
                          f"{', '.join(methods)}, got {method!r}")
    dt, tf = it["dt"], it["t_final"]
    if not dt > 0 or not tf > 0:
        raise ConfigError(f"{source}: integrate.dt: dt and t_final must be > 0, got dt={dt}, "
                          f"t_final={tf}")
    n = tf / dt
    if abs(n - round(n)) > 1e-9 * max(1.0, n):
        raise ConfigError(f"{source}: integrate.t_final: must be a multiple of dt={dt}, got {tf}")
    save_every = it.get("save_every", max(1, int(round(n)) // 20))
    if save_every < 1:
        raise ConfigError(f"{source}: integrate.save_every: must be >= 1, got {save_every}")
    yes, no = out.get("yes_below", 1e-10), out.get("no_above", 1e-3)
    if not 0 <= yes <= no:
        raise ConfigError(f"{source}: output.yes_below: need 0 <= yes_below <= no_above, got "
                          f"{yes}, {no}")
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
    clean = {k: v for k, v in data.items() if k != "smoke"}
    return Config(source=source, title=top.get("title", Path(source).stem),
                  description=top.get("description", ""), seed=top.get("seed", 0), d=d,
                  effects=tuple(effects), eps=qu.get("eps"), atoms=qu.get("atoms"), rule=rule,
                  reference_atoms=qu.get("reference_atoms"), max_atoms=qu.get("max_atoms", 200_000),
                  ks=tuple(int(k) for k in ks), kind=kind, projection_seed=pr.get("seed", 0),
                  method=method, dt=dt, t_final=tf, save_every=int(save_every), yes_below=yes,
                  no_above=no, lift_to=lift_to, lift_seed=ini.get("lift_seed", 0), data=clean,
                  smoke=smoke, precision=precision)


class _Stub:
    def __init__(self, d, effects):
        self.d, self.effects = d, effects


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


# ------------------------------------------------------------------------------------------
# the study
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunResult:
    """What a run produced (also on disk in ``out_dir``).

    Attributes
    ----------
    config : Config
    t : (T,) ndarray
    n_atoms, eps : int, float
    per_k : dict
        ``{k: {name: array}}``: ``w1``, ``exact``, ``coupling``, ``uniform``, ``term_jl``,
        ``term_quant``, ``bound``, ``C``, ``D_eps``, ``eps_jl``, ``alpha``, ``beta``, ``Lp``,
        ``Lpp``, ``Lambda``, ``gamma``, ``milling``, optional ``w1_reference``, ``norm_M``.
    high : dict
        ``gamma``, ``milling`` of ``μᴺ(t)``; ``w1_quantization`` with a reference.
    stages : dict
        ``{stage: "computed" | "loaded"}``.
    wall_time : float
    out_dir : Path or None
    """

    config: Config
    t: np.ndarray
    n_atoms: int
    eps: float
    per_k: dict
    high: dict
    stages: dict
    wall_time: float
    out_dir: Path | None

    def table(self):
        """The per-k summary table (a :class:`kinred.report.Table`)."""
        from ..report import Table

        cfg = self.config
        rows = []
        g_high = self.high["gamma"][-1]
        rows.append([f"d={cfg.d}", "", "", "", "", f"{g_high:.3g}",
                     _verdict(g_high, cfg), f"{self.high['milling'][-1]:.3f}"])
        for k, r in self.per_k.items():
            i = int(np.argmax(r["w1"]))
            ratio = r["w1"][i] / r["term_jl"][i] if r["term_jl"][i] > 0 else float("nan")
            rows.append([f"k={k}", float(r["w1"][-1]), float(np.max(r["w1"])),
                         float(r["bound"][-1]), ratio, f"{r['gamma'][-1]:.3g}",
                         _verdict(r["gamma"][-1], cfg), f"{r['milling'][-1]:.3f}"])
        return Table(["system", "W1(T)", "max_t W1", "bound(T)", "W1/(√2·D·ε_JL) at max",
                      "Γ(T)", "verdict", "milling(T)"], rows,
                     caption=f"W1(M#μᴺ(t), νᴺ(t)) (exact, POT) and Theorem 4.3's bound; N = "
                             f"{self.n_atoms}, ε = {self.eps:.4g}, T = {cfg.t_final:g}")


def _verdict(g, cfg):
    from ..observables import flocking_verdict

    return flocking_verdict(float(max(g, 0.0)), yes_below=cfg.yes_below, no_above=cfg.no_above)


#: Arrays of a solve / reference stage file and of a k stage file (a file missing one is damaged).
_SOL_KEYS = ("t", "x", "v", "weights", "eps", "n_atoms", "quantize_time", "simulate_time",
             "gamma", "milling")
_K_KEYS = ("k", "w1", "exact", "lower", "upper", "coupling", "uniform", "term_jl", "term_quant",
           "bound", "bound_stated", "C", "D_eps", "eps_jl", "alpha", "beta", "Lp", "Lpp",
           "Lambda", "norm_M", "L", "gamma", "milling", "y_final", "w_final", "simulate_time",
           "wall_time")
_REF_KEYS = ("w1_reference", "w1_quantization")


class _Stages:
    """Per-stage files with a configuration hash (resume support; see the module docstring)."""

    INDEX = "stages/config.json"

    def __init__(self, folder, cfg: Config, resume: bool):
        self.folder = folder
        self.count = 0
        hook = os.environ.get(STAGE_HOOK_ENV, "")
        self.kill_after = int(hook.split(":")[0]) if hook else None
        digest = cfg.digest()
        if folder is None:
            return
        have = folder.exists(self.INDEX)
        if have and not resume:
            raise InvalidInput(f"{folder.path} already holds a run; continue it with resume=True "
                               "(--resume on the command line) or choose another output folder")
        if have:
            if self._stored_digest() != digest:
                raise ConfigError(f"{cfg.source}: the folder {folder.path} holds a run of a "
                                  "different configuration; use another --out folder")
        else:
            folder.clean_temporary()
            folder.write_json(self.INDEX, {"digest": digest, "config": cfg.to_json()})

    def _stored_digest(self):
        path = self.folder / self.INDEX
        try:
            index = self.folder.read_json(self.INDEX, what="stage index")
            if not isinstance(index, dict) or not isinstance(index.get("digest"), str):
                raise DamagedFile(f"{path}: damaged stage index: no configuration digest",
                                  path=str(path))
        except DamagedFile as exc:
            raise DamagedFile(f"{exc}; it ties the stage files to a configuration, so they cannot "
                              f"be resumed: delete the folder {self.folder.path} and run again, "
                              "or run into another output folder", path=str(path)) from None
        return index["digest"]

    def load(self, name, keys):
        """The arrays of stage ``name``; ``None`` if absent or damaged (then it is recomputed)."""
        if self.folder is None or not self.folder.exists(f"stages/{name}.npz"):
            return None
        path = self.folder / f"stages/{name}.npz"
        try:
            arrays = self.folder.read_npz(f"stages/{name}.npz", what="stage file")
            missing = [key for key in keys if key not in arrays]
            if missing:
                raise DamagedFile(f"{path}: damaged stage file: no array {missing[0]!r}",
                                  path=str(path))
        except DamagedFile as exc:
            warnings.warn(f"{exc}; recomputing the stage", KinredWarning, stacklevel=2)
            return None
        return arrays

    def save(self, name, arrays):
        if self.folder is not None:
            self.folder.write_npz(f"stages/{name}.npz", arrays)
        self.count += 1
        if self.kill_after is not None and self.count >= self.kill_after:
            import signal

            os.kill(os.getpid(), signal.SIGKILL)


def _solve_stage(cfg: Config, atoms, eps):
    from ..kinetic import solve

    mu0 = cfg.initial_measure()
    sol = solve(cfg.scene(), mu0, eps=eps, atoms=atoms, t_span=(0.0, cfg.t_final), dt=cfg.dt,
                method=cfg.method, times=cfg.times(), rule=cfg.rule, max_atoms=cfg.max_atoms)
    return sol


def _sol_arrays(sol):
    from ..kinetic import milling_index
    from ..observables import gamma

    g = np.array([gamma(sol.v[i], sol.weights) for i in range(len(sol.t))])
    m = np.array([milling_index(sol.x[i], sol.v[i], sol.weights) for i in range(len(sol.t))])
    return dict(t=sol.t, x=sol.x, v=sol.v, weights=sol.weights, eps=sol.eps, n_atoms=sol.n_atoms,
                quantize_time=sol.quantize_time, simulate_time=sol.simulate_time, gamma=g,
                milling=m)


def _sol_from_arrays(a, cfg: Config):
    from ..kinetic import KineticSolution, weighted_scene

    return KineticSolution(t=a["t"], x=a["x"], v=a["v"], weights=a["weights"], eps=float(a["eps"]),
                           n_atoms=int(a["n_atoms"]), quantization=None,
                           quantize_time=float(a["quantize_time"]),
                           simulate_time=float(a["simulate_time"]),
                           scene=weighted_scene(cfg.scene(), a["weights"]), method=cfg.method,
                           dt=cfg.dt)


def _k_stage(cfg: Config, k: int, sol, ref):
    from ..kinetic import compare, milling_index, reduce, reference_estimate, theorem_bound
    from ..observables import gamma
    from ..projection import jl_matrix

    M = jl_matrix(k, cfg.d, kind=cfg.kind, seed=member_seed(cfg.projection_seed, k))
    t0 = time.perf_counter()
    red = reduce(sol, M=M)
    c = compare(sol, red)
    tb = theorem_bound(sol, red)
    T = len(sol.t)
    out = dict(k=k, w1=c.w1, exact=c.exact, lower=c.lower, upper=c.upper, coupling=c.coupling,
               uniform=c.uniform, term_jl=tb.term_jl, term_quant=tb.term_quant, bound=tb.bound,
               bound_stated=tb.bound_stated, C=tb.C, D_eps=tb.D_eps, eps_jl=tb.eps_jl,
               alpha=tb.alpha, beta=tb.beta, Lp=tb.Lp, Lpp=tb.Lpp, Lambda=tb.Lambda,
               norm_M=tb.norm_M, L=tb.L,
               gamma=np.array([gamma(red.w[i], red.weights) for i in range(T)]),
               milling=np.array([milling_index(red.y[i], red.w[i], red.weights) for i in range(T)]),
               y_final=red.y[-1], w_final=red.w[-1], simulate_time=red.simulate_time)
    if ref is not None:
        rred = reduce(ref, M=M)
        est = reference_estimate(sol, ref, rred)
        out["w1_reference"] = est.w1_reference
        out["w1_quantization"] = est.w1_quantization
    out["wall_time"] = time.perf_counter() - t0
    return out


def run(cfg: Config, *, out_dir=None, resume: bool = False, progress: bool | None = None) -> RunResult:
    """Run a scene (see the module docstring); with ``out_dir`` write the result folder."""
    from ..io import ResultFolder

    if not isinstance(cfg, Config):
        raise InvalidInput(f"cfg must be a kinetic_run.Config, got {type(cfg).__name__}")
    t_start = time.perf_counter()
    folder = None if out_dir is None else ResultFolder(out_dir)
    stages = _Stages(folder, cfg, resume)
    names = ["solve"] + (["reference"] if cfg.reference_atoms else []) + [f"k{k}" for k in cfg.ks]
    if progress is None:
        progress = sys.stderr.isatty()
    from tqdm import tqdm

    bar = tqdm(total=len(names), desc=f"kinred run {Path(cfg.source).name}", unit="stage",
               disable=not progress, file=sys.stderr)
    status = {}
    a = stages.load("solve", _SOL_KEYS)
    if a is None:
        bar.set_postfix_str("solve")
        a = _sol_arrays(_solve_stage(cfg, cfg.atoms, cfg.eps))
        stages.save("solve", a)
        status["solve"] = "computed"
    else:
        status["solve"] = "loaded"
    bar.update(1)
    sol = _sol_from_arrays(a, cfg)
    ref = None
    if cfg.reference_atoms:
        r = stages.load("reference", _SOL_KEYS)
        if r is None:
            bar.set_postfix_str("reference")
            r = _sol_arrays(_solve_stage(cfg, cfg.reference_atoms, None))
            stages.save("reference", r)
            status["reference"] = "computed"
        else:
            status["reference"] = "loaded"
        bar.update(1)
        ref = _sol_from_arrays(r, cfg)
    per_k = {}
    for k in cfg.ks:
        name = f"k{k}"
        res = stages.load(name, _K_KEYS + (_REF_KEYS if ref is not None else ()))
        if res is None:
            bar.set_postfix_str(name)
            res = _k_stage(cfg, k, sol, ref)
            stages.save(name, res)
            status[name] = "computed"
        else:
            status[name] = "loaded"
        per_k[k] = res
        bar.update(1)
    bar.close()
    high = {"gamma": a["gamma"], "milling": a["milling"]}
    if ref is not None:
        high["w1_quantization"] = per_k[cfg.ks[0]]["w1_quantization"]
        high["n_atoms_reference"] = int(r["n_atoms"])
        high["eps_reference"] = float(r["eps"])
    result = RunResult(config=cfg, t=sol.t, n_atoms=sol.n_atoms, eps=sol.eps, per_k=per_k,
                       high=high, stages=status, wall_time=time.perf_counter() - t_start,
                       out_dir=None if folder is None else folder.path)
    if folder is not None:
        write_outputs(result, folder)
    return result


# ------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------
def _fig_w1(plt, result: RunResult):
    from ..report import fit_log_axis, legend, log_plot

    t = result.t
    fig, ax = plt.subplots(figsize=(8, 5))
    for k, r in result.per_k.items():
        line = log_plot(ax, t[1:], r["w1"][1:], "-o", ms=3, label=f"W1, k={k}")
        color = None if line is None else line.get_color()
        log_plot(ax, t[1:], r["term_jl"][1:], "--", color=color, lw=1, label=f"√2·D(t)·ε_JL, k={k}")
        if "w1_reference" in r:
            log_plot(ax, t[1:], r["w1_reference"][1:], ":", color=color, lw=1.5,
                     label=f"reference N'={result.high.get('n_atoms_reference')}, k={k}")
    fit_log_axis(ax)
    ax.set_xlabel("t")
    ax.set_ylabel("W1 on R^{2k}")
    ax.set_title("W1(M#μᴺ(t), νᴺ(t)) (exact) and Theorem 3.1's term of the bound")
    legend(ax, fontsize=7, ncol=2)
    return fig


def _fig_bound(plt, result: RunResult):
    from ..report import fit_log_axis, legend, log_plot

    k0 = result.config.ks[0]
    fig, ax = plt.subplots(figsize=(8, 5))
    for k, r in result.per_k.items():
        log_plot(ax, result.t, r["bound"], label=f"bound, k={k}")
    log_plot(ax, result.t, result.per_k[k0]["term_quant"], "k:", label=f"2C(t)‖M‖ε, k={k0}")
    fit_log_axis(ax)
    ax.set_xlabel("t")
    ax.set_title("Theorem 4.3: 2C(t)‖M‖ε + √2·D(t)·ε_JL")
    legend(ax, fontsize=8)
    return fig


def _fig_observables(plt, result: RunResult):
    from ..report import finite_values, fit_log_axis, legend, log_plot

    cfg, t = result.config, result.t
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    log_plot(axes[0], t, result.high["gamma"], "k-", lw=2, label=f"μᴺ, d={cfg.d}")
    for k, r in result.per_k.items():
        log_plot(axes[0], t, r["gamma"], label=f"νᴺ, k={k}")
        axes[1].plot(t, finite_values(r["milling"]), label=f"νᴺ, k={k}")
    axes[1].plot(t, finite_values(result.high["milling"]), "k-", lw=2, label=f"μᴺ, d={cfg.d}")
    fit_log_axis(axes[0])
    axes[0].set_title("velocity fluctuation Γ(t)")
    axes[1].set_title("milling index (angular momentum)")
    for ax in axes:
        ax.set_xlabel("t")
        legend(ax, fontsize=7)
    return fig


def _fig_positions(plt, result: RunResult):
    k0 = result.config.ks[0]
    y = np.asarray(result.per_k[k0]["y_final"], dtype=float)
    y = y[np.all(np.isfinite(y), axis=1)]
    fig, ax = plt.subplots(figsize=(5.5, 5))
    ax.scatter(y[:, 0], y[:, 1] if y.shape[1] > 1 else np.zeros(len(y)), s=6)
    ax.set_title(f"reduced positions at T, k={k0} (first two coordinates)")
    ax.set_aspect("equal", adjustable="datalim")
    return fig


def _figures(result: RunResult):
    """The report's figures, each drawn in a guarded call (a list of DrawnFigure)."""
    from ..report import draw_figure

    k0 = result.config.ks[0]
    return [
        draw_figure("w1_vs_time.png", "W1 between projected and reduced solutions, with the "
                    "bound's √2·D(t)·ε_JL term (dashed)", _fig_w1, result),
        draw_figure("bound.png", "The right-hand side of eq. (4.17) with the proof's constants",
                    _fig_bound, result),
        draw_figure("observables.png", "Flocking (Γ) and milling observables", _fig_observables,
                    result),
        draw_figure("positions_final.png", f"Reduced particle positions at T (k={k0})",
                    _fig_positions, result),
    ]


def _summary(result: RunResult) -> dict:
    cfg = result.config
    return {
        "study": "kinetic_run", "scene": cfg.source, "title": cfg.title, "smoke": cfg.smoke,
        "d": cfg.d, "n_atoms": result.n_atoms, "eps": result.eps, "ks": list(cfg.ks),
        "t_final": cfg.t_final, "wall_time_s": result.wall_time, "stages": result.stages,
        "digest": cfg.digest(),
        "per_k": {str(k): {"w1_final": float(r["w1"][-1]), "w1_max": float(np.max(r["w1"])),
                           "all_exact": bool(np.all(r["exact"])),
                           "bound_final": float(r["bound"][-1]),
                           "term_jl_final": float(r["term_jl"][-1]),
                           "under_bound": bool(np.all(r["w1"] <= r["bound"] + 1e-12)),
                           "under_term_jl": bool(np.all(r["w1"] <= r["term_jl"] + 1e-12)),
                           "gamma_final": float(r["gamma"][-1]),
                           "verdict": _verdict(r["gamma"][-1], cfg),
                           "milling_final": float(r["milling"][-1])}
                   for k, r in result.per_k.items()},
        "high": {"gamma_final": float(result.high["gamma"][-1]),
                 "verdict": _verdict(result.high["gamma"][-1], cfg),
                 "milling_final": float(result.high["milling"][-1])},
    }


def _k_table(result: RunResult, k, r):
    from ..report import Table

    rows = []
    for i, ti in enumerate(result.t):
        row = [float(ti), float(r["w1"][i]), bool(r["exact"][i]), float(r["coupling"][i]),
               float(r["uniform"][i]), float(r["term_jl"][i]), float(r["term_quant"][i]),
               float(r["bound"][i]), float(r["eps_jl"][i]), float(r["C"][i])]
        if "w1_reference" in r:
            row += [float(r["w1_reference"][i]), float(r["w1_quantization"][i])]
        rows.append(row)
    head = ["t", "W1 (exact)", "exact", "coupling ≥ W1", "E(t)", "√2·D·ε_JL", "2C‖M‖ε",
            "bound", "ε_JL", "C(t)"]
    if "w1_reference" in r:
        head += ["W1 ref (estimate of W1(μ_M,ν))", "W1(μᴺ, μᴺ′) on R^{2d}"]
    return Table(head, rows, caption=f"k = {k}: measured vs bound over time")


def _report(result: RunResult, figures):
    from ..report import Report

    cfg = result.config
    rep = Report(f"kinred run: {cfg.title}",
                 subtitle=(cfg.description + " " if cfg.description else "") +
                 f"d = {cfg.d}, N = {result.n_atoms} atoms (quantization bound ε = {result.eps:.4g}), "
                 f"k ∈ {list(cfg.ks)} ({cfg.kind}), {cfg.method} dt = {cfg.dt:g}, T = {cfg.t_final:g}"
                 + (" [smoke sizes]" if cfg.smoke else "") + f"; wall time {result.wall_time:.1f} s.")
    s = rep.section("Summary", [
        "W1(M#μᴺ(t), νᴺ(t)) is exact (POT network simplex on the two atomic measures on R^{2k}). "
        "The bound is the right-hand side of eq. (4.17) as its proof yields it: "
        "2C(t)‖M‖ε + √2·D(t)·ε_JL with C(t) = exp(Λt) (Dobrushin stability), D(t)·ε_JL the RHS of "
        "eq. (3.7) with α, β, ε_JL measured on the trajectories (running maxima at saved times) "
        "and L, L′, L″ from the effects' kernels (docs/kinetic.md). The bound is not tuned.",
        "Flocking verdict: the paper's rule on Γ(T): pos if < %g, neg if > %g, n/a otherwise."
        % (cfg.yes_below, cfg.no_above)])
    s.tables.append(result.table())
    for k, r in result.per_k.items():
        sec = rep.section(f"k = {k}", [
            f"‖M‖ = {float(r['norm_M']):.4g}; final constants: α = {float(r['alpha'][-1]):.4g}, "
            f"β = {float(r['beta'][-1]):.4g}, L = {float(r['L']):g}, L′ = {float(r['Lp'][-1]):.4g}, "
            f"L″ = {float(r['Lpp'][-1]):.4g}, Λ = {float(r['Lambda'][-1]):.4g}."])
        sec.tables.append(_k_table(result, k, r))
    fsec = rep.section("Figures")
    for drawn in figures:
        fsec.add_drawn(drawn)
    return rep


def write_outputs(result: RunResult, folder) -> Path:
    """``results.npz`` and ``summary.json`` first, then the PNG figures and ``report.html``.

    The numbers are on disk (and the folder complete) before anything is drawn; each figure is
    drawn in a guarded call, and one that fails is replaced by a note in the report. Returns
    the path of ``summary.json``.
    """
    arrays = {"t": result.t, "gamma_high": result.high["gamma"], "milling_high": result.high["milling"]}
    skip = {"y_final", "w_final"}
    for k, r in result.per_k.items():
        for name, val in r.items():
            if name not in skip:
                arrays[f"k{k}_{name}"] = np.asarray(val)
    folder.write_npz("results.npz", arrays)
    summary = folder.mark_complete(_summary(result))
    figures = _figures(result)
    for drawn in figures:
        if drawn.png is not None:
            folder.write_bytes(drawn.name, drawn.png)
    folder.write_text("report.html", _report(result, figures).to_html())
    return summary
