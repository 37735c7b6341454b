"""The tables of a scene file and their keys: :data:`TABLES` (each key written once; the
attributes of :class:`~kinred.scenefile.Config` are derived from it, ``Key.attr``)."""

from __future__ import annotations

from .._schema import REQUIRED, Key
from ..errors import InvalidInput

__all__ = ["TABLES", "SMOKE_TARGETS", "GROUPED"]


def _deterministic_methods() -> tuple:
    from ..integrate import SOLVERS

    return tuple(m for m, spec in SOLVERS.items() if not spec.stochastic)  # scene files: no noise


def _method_alias(value):
    """The registered name of an integrator alias (``"RK45"``, ``"dopri5"``), else ``value``."""
    from ..integrate import method_name

    try:
        return method_name(value)
    except InvalidInput:
        return value


def _projection_kinds() -> tuple:
    from ..projection import KINDS

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
        Key("dynamics", "table", REQUIRED, "the effects", attr=None),
        Key("initial", "table", REQUIRED, "the initial phase-space measure μ₀", attr=None),
        Key("quantize", "table", REQUIRED, "μ₀ → μ₀ᴺ", attr=None),
        Key("projection", "table", REQUIRED, "the JL projections", attr=None),
        Key("integrate", "table", REQUIRED, "the integrator", attr=None),
        Key("output", "table", None, "the flocking rule", attr=None),
        Key("certify", "table", None, "certified error bounds per k (kinred.certify)",
            attr=None),
        Key("smoke", "table", None, "tiny sizes for --smoke", attr=None),
    ),
    "dynamics": (
        Key("d", "integer", REQUIRED, "dimension of positions (and of velocities)", low=1),
        Key("precision", "string", "double", '"mixed": float32 pair sums, float64 state '
            "(dense backend)", choices=("double", "mixed")),
        Key("effect", "array of tables", REQUIRED, "one [[dynamics.effect]] table per effect; "
            'the scene is their sum, normalize = "mean"', attr="effects"),
        Key("pairsum", "table", None, "the pair-sum backend", shown_default='`method = "dense"`'),
    ),
    "initial": (
        Key("positions", "table", None, "a measure table on R^d (docs/measures-file.md)",
            attr=None),
        Key("velocities", "table", None,
            "idem for the velocities; μ₀ = positions ⊗ velocities", attr=None),
        Key("phase", "table", None, "or: a joint measure on R^(2d), d positions then d "
            "velocities", attr=None),
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
        Key("k", "array of integers", REQUIRED, "target dimensions, 1 ≤ k ≤ d, each once",
            attr="ks"),
        Key("kind", "string", "gaussian", "the JL family", choices=_projection_kinds),
        Key("seed", "integer", 0, "M for k uses member_seed(seed, k)", low=0,
            attr="projection_seed"),
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
                       key.high, key.low_open, key.high_open, key.choices, attr=None))
    return tuple(out)


TABLES["smoke"] = _smoke_keys()

#: Tables whose keys are the fields of one options object, the :class:`Config` attribute named
#: as the table (``certify`` -> :class:`~kinred.scenefile.CertifyOptions`).
GROUPED = ("certify",)
