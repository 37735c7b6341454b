"""Tables and text of the ``kinred run`` report (:mod:`kinred.experiments.kinetic_report`).

Every column names what its numbers are: measured, certified bound, a-priori bound or
estimate. Columns of the certificate (``cert_w1``, ``err_rms``, ...) and of the reference
appear only when the result has them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["shows_milling", "summary_table", "k_table", "method_text", "vacuous"]

#: Effects that make mills: the milling index is shown only for scenes with one of them.
MILLING_EFFECTS = frozenset({"self_propulsion", "morse"})


def shows_milling(cfg) -> bool:
    """Whether the scene's effects call for the milling index (self-propulsion or Morse).

    Examples
    --------
    >>> from kinred.scenefile import SMALL_SCENE, config_from_dict
    >>> shows_milling(config_from_dict(SMALL_SCENE))      # Cucker–Smale alignment only
    False
    """
    return any(typ in MILLING_EFFECTS for typ, _ in cfg.effects)


def vacuous(result, r) -> np.ndarray | None:
    """Per saved time, whether the a-priori bound exceeds the cloud's diameter (None: unknown).

    ``r["vacuous"]`` when the result has it, else ``bound > high["diameter"]`` when the
    diameter is known.
    """
    if "vacuous" in r:
        return np.asarray(r["vacuous"], dtype=bool)
    diam = result.high.get("diameter")
    if diam is None:
        return None
    with np.errstate(invalid="ignore"):
        return np.asarray(r["bound"], float) > np.asarray(diam, float)


def _finite(r, key) -> bool:
    """Whether ``r[key]`` exists and has a finite value (NaN: the k was not certified)."""
    return key in r and bool(np.any(np.isfinite(np.asarray(r[key], dtype=float))))


def _verdict(g, cfg) -> str:
    from ..observables import flocking_verdict

    return flocking_verdict(float(max(g, 0.0)), yes_below=cfg.yes_below, no_above=cfg.no_above)


def _bound_cell(result, r, i=-1) -> str:
    b = float(r["bound"][i])
    vac = vacuous(result, r)
    return f"{b:.3g}" + (" (vacuous)" if vac is not None and vac[i] else "")


def summary_table(result):
    """One row per system at T: measured W1, its certified bound and estimate, the a-priori
    bound (marked vacuous), Γ and verdict, milling when the scene mills."""
    from ..report import Table

    cfg, per_k = result.config, result.per_k
    cert = any(_finite(r, "cert_w1") for r in per_k.values())
    ref = any("w1_reference" in r for r in per_k.values())
    mill = shows_milling(cfg)
    head = ["system", "W₁(T) measured", "max_t W₁ measured"]
    head += ["W₁(T) certified bound"] if cert else []
    head += ["W₁(μ_M, ν)(T) estimate"] if ref else []
    head += ["a-priori bound(T), eq. (4.17)", "Γ(T) measured", "flocking verdict"]
    head += ["milling(T) measured"] if mill else []
    g = float(result.high["gamma"][-1])
    row = [f"original, d = {cfg.d}", "—", "—"] + ["—"] * (cert + ref) + \
        ["—", f"{g:.3g}", _verdict(g, cfg)]
    rows = [row + ([f"{float(result.high['milling'][-1]):.3f}"] if mill else [])]
    for k, r in per_k.items():
        row = [f"reduced, k = {k}", float(r["w1"][-1]), float(np.max(r["w1"]))]
        row += [float(r["cert_w1"][-1]) if _finite(r, "cert_w1") else "—"] if cert else []
        row += [float(r["w1_reference"][-1]) if "w1_reference" in r else "—"] if ref else []
        row += [_bound_cell(result, r), f"{r['gamma'][-1]:.3g}", _verdict(r["gamma"][-1], cfg)]
        row += [f"{float(r['milling'][-1]):.3f}"] if mill else []
        rows.append(row)
    return Table(head, rows, caption=f"At T = {cfg.t_final:g}: W₁(M#μᴺ(T), νᴺ(T)) on ℝ²ᵏ per "
                                     f"reduced system; N = {result.n_atoms}, "
                                     f"ε = {result.eps:.4g} (a-priori bound of W₁(μ₀, μ₀ᴺ))")


def method_text(result) -> list:
    """Paragraphs saying how each kind of number is obtained."""
    cfg, high = result.config, result.high
    cert = any(_finite(r, "cert_w1") for r in result.per_k.values())
    text = ["Measured: W₁(M#μᴺ(t), νᴺ(t)) is exact (the optimal transport plan between "
            "the two atomic measures on phase space ℝ²ᵏ, k position and k velocity "
            "coordinates, by a network simplex or an assignment solver, proved optimal by its "
            "dual beyond a few thousand atoms); Γ"
            + (" and the milling index are" if shows_milling(cfg) else " is")
            + " evaluated on the atoms."]
    if cert:
        text.append("Certified bound: an upper bound of the measured W₁ from the certificate of "
                    "the particle errors y − Mx, w − Mv, propagated step by step with measured "
                    "quantities (docs/certificates.md).")
    text.append("A-priori bound: the right-hand side of eq. (4.17) as the proof of Theorem 4.3 "
                "yields it, 2C(t)‖M‖ε + √2·D(t)·ε_JL, with C(t) = exp(Λt) (Dobrushin "
                "stability) and D(t)·ε_JL the right-hand side of eq. (3.7); α, β, ε_JL are "
                "measured on the trajectories and L, L′, L″ come from the effects' kernels "
                "(docs/kinetic.md). It is not tuned.")
    diam = high.get("diameter")
    if diam is not None:
        d_t = float(np.asarray(diam)[-1])
        text.append(f"The diameter of supp μᴺ(T) in ℝ²ᵈ is at most {d_t:.4g} (certified "
                    "upper bound, docs/certificates.md); a W₁ bound above it says nothing about "
                    "a cloud of that size: it is marked vacuous.")
    if "w1_quantization" in high:
        wq = np.asarray(high["w1_quantization"], float)
        text.append(f"Estimate: W₁(μ_M(t), ν(t)) between the kinetic solutions, from a finer "
                    f"quantization with N′ = {high.get('n_atoms_reference')} atoms; the two "
                    f"particle solutions differ by W₁(μᴺ(T), μᴺ′(T)) = {wq[-1]:.4g} on ℝ²ᵈ "
                    "(measured).")
    text.append(f"Flocking verdict: the paper's rule on Γ(T): pos if < {cfg.yes_below:g}, neg "
                f"if > {cfg.no_above:g}, n/a otherwise.")
    return text


_COLUMNS = (  # (key, header, group); group None: always
    ("w1", "W₁ measured (exact)", None), ("exact", "exact?", None),
    ("coupling", "coupling ≥ W₁, measured", None), ("uniform", "E(t) measured", None),
    ("cert_w1", "W₁ certified bound", "cert"), ("err_rms", "RMS error measured", "cert"),
    ("cert_rms", "RMS error certified bound", "cert"),
    ("err_max", "max error measured", "cert"), ("cert_max", "max error certified bound", "cert"),
    ("paper_rms", "RMS error a-priori bound, eq. (2.18)", "cert"),
    ("paper_max", "max error a-priori bound, √2 × eq. (2.11)", "cert"),
    ("bound_mixed", "2C‖M‖ε + certified W₁, a-priori", "cert"),
    ("term_jl", "√2·D·ε_JL a-priori", None), ("term_quant", "2C‖M‖ε a-priori", None),
    ("bound", "a-priori bound, eq. (4.17)", None), ("eps_jl", "ε_JL measured", None),
    ("C", "C(t) a-priori constant", None),
    ("w1_reference", "W₁(μ_M, ν) estimate", "ref"),
    ("w1_quantization", "W₁(μᴺ, μᴺ′) on ℝ²ᵈ measured", "ref"),
)


def _cell(v):
    v = np.asarray(v).item() if np.ndim(v) == 0 else v
    return bool(v) if isinstance(v, (bool, np.bool_)) else float(v)


def k_table(result, k, r):
    """Every per-time number of the reduced system ``k`` (columns present in ``r``)."""
    from ..report import Table

    cols = [(key, head) for key, head, _ in _COLUMNS if key in r]
    vac = vacuous(result, r)
    head = ["t"] + [h for _, h in cols] + (["vacuous?"] if vac is not None else [])
    rows = []
    for i, ti in enumerate(result.t):
        row = [float(ti)] + [_cell(np.asarray(r[key])[i]) for key, _ in cols]
        rows.append(row + ([bool(vac[i])] if vac is not None else []))
    return Table(head, rows, caption=f"k = {k}: every saved time")
