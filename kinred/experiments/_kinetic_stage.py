"""One k stage of ``kinred run``: :class:`KStage`, whose fields carry their label.

Every array of a k stage is a field of :class:`KStage`, written once with what it is
("measured", "certified bound", "a-priori bound" or "estimate"; ``None`` for what is not a
number); the stage file's arrays (:meth:`KStage.keys_for`), the labels of ``summary.json``
(:data:`LABELS`) and the certificate's arrays (:data:`CERT_KEYS`) are read from the fields.
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping

import numpy as np

from .._repr import result_repr

__all__ = ["KStage", "LABELS", "NOT_NUMBERS", "CERT_KEYS", "HIGH_LABELS"]

_M, _C, _A, _E = "measured", "certified bound", "a-priori bound", "estimate"


def _f(label: str | None, doc: str, *, group: str = "", optional: bool = False):
    meta = {"label": label, "doc": doc, "group": group}
    if optional:
        return dataclasses.field(default=None, metadata={**meta, "optional": True})
    return dataclasses.field(metadata=meta)


@dataclasses.dataclass(frozen=True, eq=False)
class KStage(Mapping):
    """The arrays of stage ``k{k}``: ``(T,)`` series over the saved times unless said.

    A read-only mapping too (``stage["w1"]``, ``"w1_reference" in stage``; an optional field
    that is None is absent), so code and files name the arrays by their field names. Each
    field's label is ``KStage.label(name)``; :data:`LABELS` lists them all.
    """

    __repr__ = result_repr

    # W1(M#μᴺ(t), νᴺ(t)) and the reduced run
    k: np.ndarray = _f(None, "the target dimension (0-d)")
    w1: np.ndarray = _f(_M, "W1(M#μᴺ(t), νᴺ(t)) (exact, or the upper end of a bracket)")
    exact: np.ndarray = _f(_M, "whether w1 is exact at each time")
    lower: np.ndarray = _f(_C, "certified lower end of the W1 bracket")
    upper: np.ndarray = _f(_C, "certified upper end of the W1 bracket")
    coupling: np.ndarray = _f(_M, "Σᵢ wᵢ|(yᵢ, wᵢ) − M(xᵢ, vᵢ)|, the index coupling")
    uniform: np.ndarray = _f(_M, "the same with uniform weights")
    # Theorem 4.3 with the proof's constants
    term_jl: np.ndarray = _f(_A, "√2 D(t) ε_JL, bounds W1(M#μᴺ(t), νᴺ(t))")
    term_quant: np.ndarray = _f(_A, "the quantization term 2C(t)‖M‖ε of eq. (4.17)")
    bound: np.ndarray = _f(_A, "term_quant + term_jl: eq. (4.17) by the proof")
    bound_stated: np.ndarray = _f(_A, "the statement's form 𝒞(t)‖M‖ε̄ of eq. (4.17)")
    C: np.ndarray = _f(_A, "C(t) = exp(Λ t)")
    D_eps: np.ndarray = _f(_A, "D(t) ε_JL, the right-hand side of eq. (3.7)")
    eps_jl: np.ndarray = _f(_M, "running maximum of the distortion (3.4)")
    alpha: np.ndarray = _f(_M, "running maximum of (3.3)")
    beta: np.ndarray = _f(_M, "running maximum of (3.6)")
    Lp: np.ndarray = _f(_A, "L′ (on the running maxima)")
    Lpp: np.ndarray = _f(_A, "L″ (on the running maxima)")
    Lambda: np.ndarray = _f(_A, "the stability rate Λ")
    norm_M: np.ndarray = _f(_M, "operator norm ‖M‖ (0-d)")
    L: np.ndarray = _f(_A, "the constant L (0-d)")
    gamma: np.ndarray = _f(_M, "Γ(t) of the reduced run")
    milling: np.ndarray = _f(_M, "the milling index of the reduced run")
    y_final: np.ndarray = _f(_M, "the reduced positions at T, (N, k)")
    w_final: np.ndarray = _f(_M, "the reduced velocities at T, (N, k)")
    simulate_time: np.ndarray = _f(_M, "seconds of the reduced run (0-d)")
    wall_time: np.ndarray = _f(_M, "seconds of the stage (0-d)")
    # the certificate (kinred.certify; NaN where not certified)
    err_rms: np.ndarray = _f(_M, "the projection error, weighted RMS over agents",
                             group="cert")
    err_max: np.ndarray = _f(_M, "the projection error, maximum over agents", group="cert")
    cert_rms: np.ndarray = _f(_C, "certified bound of err_rms", group="cert")
    cert_max: np.ndarray = _f(_C, "certified bound of err_max", group="cert")
    cert_w1: np.ndarray = _f(_C, "certified bound of the coupling, hence of w1", group="cert")
    cert_saturated: np.ndarray = _f(_C, "where the bound is the trivial |y| + |Mx|",
                                    group="cert")
    paper_rms: np.ndarray = _f(_A, "eq. (2.18)", group="cert")
    paper_max: np.ndarray = _f(_A, "√2 × eq. (2.11)", group="cert")
    bound_mixed: np.ndarray = _f(_A, "term_quant + cert_w1", group="cert")
    vacuous: np.ndarray = _f(_A, "bound above the diameter of supp μᴺ(t)", group="cert")
    cert_time: np.ndarray = _f(_M, "seconds of the certificate (0-d)", group="cert")
    cert_note: np.ndarray = _f(None, "why certified or not (0-d str)", group="cert")
    # a finer reference (only with quantize.reference_atoms)
    w1_reference: np.ndarray | None = _f(_E, "W1(μ_M(t), ν(t)) estimated with the reference",
                                         group="reference", optional=True)
    w1_quantization: np.ndarray | None = _f(_E, "W1(μᴺ(t), μᴺ′(t)) in ℝ²ᵈ",
                                            group="reference", optional=True)

    # -- the names --------------------------------------------------------------------------
    @classmethod
    def label(cls, name: str) -> str | None:
        """What the array ``name`` is (None: not a number)."""
        return _FIELDS[name].metadata["label"]

    @classmethod
    def names(cls, group: str | None = None) -> tuple:
        """The field names (of ``group``: ``"cert"``, ``"reference"``, ``""``), in order."""
        return tuple(n for n, f in _FIELDS.items() if group is None
                     or f.metadata["group"] == group)

    @classmethod
    def keys_for(cls, reference: bool) -> tuple:
        """The arrays a stage file must hold (with the reference's when ``reference``)."""
        return tuple(n for n, f in _FIELDS.items()
                     if reference or not f.metadata.get("optional"))

    @classmethod
    def from_arrays(cls, arrays: Mapping) -> KStage:
        """The stage of a mapping of arrays (a stage file's; other entries are ignored)."""
        return cls(**{n: arrays[n] for n in _FIELDS if n in arrays})

    def arrays(self) -> dict:
        """``{name: value}`` of the fields that are set (what the stage file holds)."""
        return dict(self.items())

    # -- the mapping ------------------------------------------------------------------------
    def __getitem__(self, name):
        value = getattr(self, name, None) if name in _FIELDS else None
        if value is None:
            raise KeyError(name)
        return value

    def __iter__(self):
        return (n for n in _FIELDS if getattr(self, n) is not None)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __eq__(self, other):
        if not isinstance(other, Mapping):
            return NotImplemented
        return set(self) == set(other) and all(
            np.array_equal(np.asarray(self[n]), np.asarray(other[n])) for n in self)

    __hash__ = None


_FIELDS = {f.name: f for f in dataclasses.fields(KStage)}

#: Arrays the certificate adds to a k stage (always present; NaN when not certified).
CERT_KEYS = KStage.names("cert")

#: What the arrays of ``RunResult.high`` are (those of μᴺ(t), the original system).
HIGH_LABELS = types.MappingProxyType({
    "gamma": _M, "milling": _M, "diameter": _C, "diameter_lower": _M, "eps_reference": _A,
    "x_final": _M, "v_final": _M, "weights": _M, "w1_quantization": _E,
})

#: What every number of a run is (per-k arrays and ``high``): "measured", "certified bound",
#: "a-priori bound" (the paper's constants) or "estimate". Not numbers: :data:`NOT_NUMBERS`.
LABELS = types.MappingProxyType({
    **{n: f.metadata["label"] for n, f in _FIELDS.items() if f.metadata["label"]},
    **HIGH_LABELS})

#: Stage entries that are not numbers: the target dimension, the certificate's note and the
#: reference's atom count (parameters and text).
NOT_NUMBERS = tuple(n for n, f in _FIELDS.items() if f.metadata["label"] is None) + (
    "n_atoms_reference",)
