r"""Certificates in the kinetic pipeline (``kinred run``, ``kinred demo``, ``kinred certify``).

For every k the stage ``k{k}`` of :mod:`kinred.experiments.kinetic_run` may certify its
reduced run: a :class:`~kinred.certify.CertificateObserver` (the machinery of
:func:`kinred.certify.certify`) rides on a forward-Euler re-run of the weighted particle system
from the solution's initial atoms, steps the projected system alongside and bounds

* the weighted RMS error ``(Σᵢ wᵢ(|yᵢ − Mxᵢ|² + |wᵢ − Mvᵢ|²))^{1/2}`` (``cert_rms``) and its
  maximum over atoms (``cert_max``), beside their measured values (``err_rms``, ``err_max``);
* the middle term of Theorem 4.3, ``W1((μᴺ)_M(t), νᴺ(t)) ≤ Σᵢ wᵢ|(yᵢ, wᵢ) − M(xᵢ, vᵢ)|``
  (``cert_w1``), beside the exact W1 (``w1``) and the coupling (``coupling``).

The projected run of the certificate must be the pipeline's reduced solution and its
high-dimensional run the pipeline's solution: both are compared at every saved time (they are
bit-identical: the same ``simulate`` calls on the same data) and a certificate of another run
is not reported. Where a k is not certified, the arrays are NaN and ``cert_note`` says why.

When: :func:`decide` (``[certify] enabled``: true / false / absent = when cheap).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidInput, NotProjectable, SimulationDiverged
from ._kinetic_stage import CERT_KEYS as _CERT_KEYS

__all__ = ["AUTO_MAX_ATOMS", "CERT_KEYS", "Decision", "decide", "check_certifiable",
           "certify_stage", "measured_errors", "phase_diameter", "worst_ratio",
           "summary_numbers"]

#: Without ``[certify] enabled``, certify only up to this many atoms (the certificate re-runs
#: the particle system: O(N²(d + k)) per step and k).
AUTO_MAX_ATOMS = 2000

#: Arrays the certificate adds to a k stage (always present; NaN when not certified): the
#: fields of ``KStage`` (:mod:`kinred.experiments.kinetic_run`) of the group ``"cert"``.
CERT_KEYS = _CERT_KEYS

#: Relative tolerance of the comparison between the certificate's runs and the pipeline's.
SAME_RUN_RTOL = 1e-12


@dataclass(frozen=True)
class Decision:
    """Whether the k stages certify (``on``) and, if not, why (``note``); ``explicit``: the
    scene's ``[certify] enabled`` was given (not the automatic choice)."""

    on: bool
    note: str
    explicit: bool


def _uncertifiable(cfg, scene, n_atoms: int) -> str:
    """Why the scene cannot be certified ("" if it can)."""
    from ..certify import check_scene
    from ..pairsum import is_exact

    if cfg.method != "euler":
        return (f"the certificate covers forward Euler only (integrate.method = "
                f"{cfg.method!r})")
    if not is_exact(scene.pairsum):
        return (f"the pair-sum backend {scene.pairsum!r} is approximate; the certificate "
                "bounds the exact (dense) scheme")
    try:
        check_scene(scene, n_atoms)
    except (NotProjectable, InvalidInput) as exc:
        return f"the scene is not covered by certificates: {exc}"
    return ""


def check_certifiable(cfg) -> None:
    """Refuse a scene ``kinred certify`` cannot certify, before any work.

    Raises
    ------
    ConfigError
        Not forward Euler, an approximate pair sum, an effect the certificate does not cover
        (noise, fields, unsoftened Morse, ...).
    """
    from ..errors import ConfigError

    why = _uncertifiable(cfg, cfg.scene(), 2)
    if why:
        raise ConfigError(f"{cfg.source}: cannot certify: {why}")


def decide(cfg, sol) -> Decision:
    """Whether the k stages of ``cfg`` certify ``sol``.

    Parameters
    ----------
    cfg : Config
        The scene (its ``[certify]`` table and ``integrate.method``).
    sol : KineticSolution
        The solution the k stages reduce (its weighted scene and atom count).

    Returns
    -------
    Decision
        ``enabled = false``: off. Otherwise off, with the reason, when the method is not
        forward Euler, the pair sum is approximate or an effect is not covered; without
        ``enabled``, also above :data:`AUTO_MAX_ATOMS` atoms.
    """
    from ..kinetic import KineticSolution
    from ..scenefile import Config

    if not isinstance(cfg, Config) or not isinstance(sol, KineticSolution):
        raise InvalidInput(f"decide needs a kinred.scenefile.Config and a KineticSolution, got "
                           f"{type(cfg).__name__} and {type(sol).__name__}")
    explicit = cfg.certify.enabled is not None
    if cfg.certify.enabled is False:
        return Decision(False, "not certified: [certify] enabled = false", True)
    why = _uncertifiable(cfg, sol.scene, sol.n_atoms)
    if why:
        return Decision(False, f"not certified: {why}", explicit)
    if not explicit and sol.n_atoms > AUTO_MAX_ATOMS:
        return Decision(False, f"not certified: N = {sol.n_atoms} atoms > {AUTO_MAX_ATOMS} "
                               "(the certificate re-runs the particle system, O(N²(d + k)) per "
                               "step); set [certify] enabled = true to certify", False)
    return Decision(True, "", explicit)


def measured_errors(sol, red) -> tuple[np.ndarray, np.ndarray]:
    """Measured ``(Σᵢ wᵢ(|yᵢ − Mxᵢ|² + |wᵢ − Mvᵢ|²))^{1/2}`` and ``maxᵢ`` of the same per atom.

    Parameters
    ----------
    sol : KineticSolution
    red : ReducedSolution
        Its reduced solution (same saved times).

    Returns
    -------
    rms, max : (T,) ndarray
    """
    from ..kinetic import KineticSolution, ReducedSolution

    if not isinstance(sol, KineticSolution) or not isinstance(red, ReducedSolution):
        raise InvalidInput(f"measured_errors needs a KineticSolution and a ReducedSolution, got "
                           f"{type(sol).__name__} and {type(red).__name__}")
    if red.y.shape[:2] != sol.x.shape[:2]:
        raise InvalidInput(f"red must reduce sol: (times, atoms) {red.y.shape[:2]} != "
                           f"{sol.x.shape[:2]}")
    P = red.projection
    w = np.asarray(sol.weights, float)
    T = len(sol.t)
    rms, mx = np.empty(T), np.empty(T)
    for i in range(T):
        e2 = (np.sum((red.y[i] - P.apply(sol.x[i])) ** 2, axis=1)
              + np.sum((red.w[i] - P.apply(sol.v[i])) ** 2, axis=1))
        rms[i], mx[i] = np.sqrt(w @ e2), np.sqrt(np.max(e2))
    return rms, mx


def phase_diameter(x, v) -> tuple[np.ndarray, np.ndarray]:
    """``(upper, lower)`` bounds of the diameter of ``{(xᵢ(t), vᵢ(t))}`` in ``ℝ²ᵈ`` per saved
    time, O(T·N·d) (:func:`kinred.kinetic.diameter_bounds`).

    Parameters
    ----------
    x, v : (T, N, d) array_like

    Returns
    -------
    upper, lower : (T,) ndarray

    Examples
    --------
    >>> x = np.array([[[0.0], [3.0]]]); v = np.array([[[0.0], [4.0]]])
    >>> up, lo = phase_diameter(x, v)
    >>> float(lo[0]), bool(5.0 <= up[0] < 5.0 + 1e-12)
    (5.0, True)
    """
    from ..kinetic import diameter_bounds

    x, v = np.asarray(x, float), np.asarray(v, float)
    if x.ndim != 3 or x.shape != v.shape:
        raise InvalidInput(f"x and v must be (T, N, d) arrays of one shape, got {x.shape} and "
                           f"{v.shape}")
    up, lo = np.empty(len(x)), np.empty(len(x))
    for i in range(len(x)):
        lo[i], up[i] = diameter_bounds(np.concatenate([x[i], v[i]], axis=1))
    return up, lo


def worst_ratio(bound, measured, t, t_min: float = 1.0) -> float:
    """``max bound/measured`` over saved times ``t − t[0] ≥ t_min`` with ``measured > 0``
    and a finite bound (NaN if none).

    Examples
    --------
    >>> worst_ratio([1.0, 2.0, 3.0, 4.0], [1.0, 1.0, 2.0, 0.0], [0.0, 0.5, 1.0, 2.0])
    1.5
    """
    t = np.asarray(t, float)
    b, m = np.asarray(bound, float), np.asarray(measured, float)
    if not (t.ndim == 1 and b.shape == m.shape == t.shape and t.size):
        raise InvalidInput(f"bound, measured and t must be 1-D arrays of one non-zero length, "
                           f"got shapes {b.shape}, {m.shape}, {t.shape}")
    sel = (t - t[0] >= t_min - 1e-12) & (m > 0) & np.isfinite(b)
    return float(np.max(b[sel] / m[sel])) if np.any(sel) else float("nan")


def _run(sol, M, paper: bool):
    """The certificate's records (with the projected states) and the re-run's states."""
    from ..certify import CertificateObserver
    from ..integrate import SaveAt, simulate

    t = np.asarray(sol.t, float)
    steps = np.rint((t - t[0]) / sol.dt).astype(np.int64)
    obs = CertificateObserver(sol.scene, M, sol.x[0], sol.v[0], save_steps=steps, paper=paper,
                              states=True)
    tr = simulate(sol.scene, obs.x0, obs.v0, (float(t[0]), float(t[-1])), sol.dt,
                  method="euler", save=SaveAt(t=t, states=True, observables=()),
                  observers=[obs])
    return obs.records(), tr


def _difference(a, b) -> float:
    """``max|a − b|`` relative to ``1 + max|b|`` (inf for shape mismatches)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return float("inf")
    return float(np.max(np.abs(a - b), initial=0.0) / (1.0 + np.max(np.abs(b), initial=0.0)))


def certify_stage(cfg, sol, red, M, decision: Decision, *, w1, term_quant, bound,
                  diameter) -> dict:
    """The arrays :data:`CERT_KEYS` of one k stage (see the module docstring).

    Parameters
    ----------
    cfg : Config
    sol : KineticSolution
    red : ReducedSolution
        The pipeline's reduced solution of ``sol`` by ``M``.
    M : (k, d) ndarray or Projection
    decision : Decision
        :func:`decide`'s.
    w1, term_quant, bound, diameter : (T,) array_like
        The stage's exact W1, Theorem 4.3's a-priori terms ``2C(t)‖M‖ε`` and bound, and the
        upper bound of the diameter of ``supp μᴺ(t)`` (``vacuous``: ``bound > diameter``).

    Returns
    -------
    dict
        ``{name: array}`` for :data:`CERT_KEYS`; NaN certified arrays and the reason in
        ``cert_note`` where not certified (a refused scene, a diverged certificate, runs
        that are not the pipeline's), never an exception for those.
    """
    if not isinstance(decision, Decision):
        raise InvalidInput(f"decision must be a Decision (from decide), got {decision!r}")
    T = len(sol.t)
    nan = np.full(T, np.nan)
    out = dict(cert_rms=nan, cert_max=nan.copy(), cert_w1=nan.copy(),
               cert_saturated=np.zeros(T, bool), paper_rms=nan.copy(), paper_max=nan.copy(),
               bound_mixed=nan.copy(), cert_time=0.0,
               vacuous=np.asarray(bound, float) > np.asarray(diameter, float))
    note = decision.note
    if decision.on:
        t0 = time.perf_counter()
        try:
            rec, tr = _run(sol, M, bool(cfg.certify.paper))
        except (NotProjectable, InvalidInput, SimulationDiverged) as exc:
            rec, note = None, f"not certified: the certificate failed: {exc}"
        out["cert_time"] = time.perf_counter() - t0
        if rec is not None:
            note = _accept(out, rec, tr, sol, red, w1, term_quant)
    if "err_rms" not in out:
        out["err_rms"], out["err_max"] = measured_errors(sol, red)
    out["cert_note"] = np.array(note)
    return out


def _accept(out, rec, tr, sol, red, w1, term_quant) -> str:
    """Fill ``out`` from the certificate's records if it certified the pipeline's runs."""
    diffs = {"x": _difference(tr.x, sol.x), "v": _difference(tr.v, sol.v),
             "y": _difference(rec["y"], red.y), "w": _difference(rec["w"], red.w)}
    worst = max(diffs.values())
    if not worst <= SAME_RUN_RTOL:
        which = ", ".join(f"{k} {d:.3g}" for k, d in diffs.items() if not d <= SAME_RUN_RTOL)
        return ("not certified: the certificate's runs differ from the pipeline's (relative "
                f"max difference {which} > {SAME_RUN_RTOL:g}); it would certify another run")
    out.update(err_rms=rec["error"], err_max=rec["error_max"], cert_rms=rec["bound"],
               cert_max=rec["bound_max"], cert_w1=rec["w1_bound"],
               cert_saturated=rec["saturated"] > 0, paper_rms=rec["paper_bound"],
               paper_max=rec["paper_bound_max"],
               bound_mixed=np.asarray(term_quant, float) + rec["w1_bound"])
    same = "bit-identical" if worst == 0.0 else f"equal to {worst:.2g} relative"
    note = (f"certified (forward Euler; the certificate's runs are {same} to the pipeline's "
            "solution and reduced solution; round-off allowance estimated, docs/certificates.md)")
    if np.any(out["cert_saturated"]):
        note += ("; saturated at some saved times: there the bound is the trivial |y| + |Mx| "
                 "(the projected run has lost the high-dimensional one)")
    if not np.all(np.asarray(w1) <= out["cert_w1"]):
        note += "; INVALID: the exact W1 exceeds the certified bound at some saved time"
    return note


def _finite(x):
    """``x`` as a float, None (JSON null) when not finite."""
    x = float(x)
    return x if np.isfinite(x) else None


def summary_numbers(t, r) -> dict:
    """The certificate's numbers of one k stage ``r`` for ``summary.json`` (None where not
    certified): ``cert_w1_final``, ``cert_ratio_max`` (the worst ``cert_w1 / w1`` over
    ``t ≥ 1``; ``cert_ratio_rms_max``, ``cert_ratio_max_norm``: the same for the RMS and max
    norms), ``cert_valid`` (every measured value ≤ its certified bound), ``vacuous`` (the
    a-priori bound above the diameter at T; ``vacuous_count``: at how many saved times)."""
    certified = bool(np.all(np.isfinite(r["cert_w1"])))
    valid = certified and bool(np.all(r["err_rms"] <= r["cert_rms"])
                               and np.all(r["err_max"] <= r["cert_max"])
                               and np.all(r["coupling"] <= r["cert_w1"])
                               and np.all(r["w1"] <= r["cert_w1"]))
    return {"certified": certified, "cert_note": str(r["cert_note"]),
            "cert_w1_final": _finite(r["cert_w1"][-1]),
            "cert_rms_final": _finite(r["cert_rms"][-1]),
            "err_rms_final": float(r["err_rms"][-1]),
            "cert_ratio_max": _finite(worst_ratio(r["cert_w1"], r["w1"], t)),
            "cert_ratio_rms_max": _finite(worst_ratio(r["cert_rms"], r["err_rms"], t)),
            "cert_ratio_max_norm": _finite(worst_ratio(r["cert_max"], r["err_max"], t)),
            "cert_valid": valid if certified else None,
            "cert_saturated": bool(np.any(r["cert_saturated"])),
            "cert_time_s": float(r["cert_time"]),
            "paper_rms_final": _finite(r["paper_rms"][-1]),
            "vacuous": bool(r["vacuous"][-1]),
            "vacuous_count": int(np.sum(r["vacuous"]))}
