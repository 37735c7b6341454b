"""Atoms of the quantization: the curse and the delayed curse.

Atoms from :func:`kinred.quantize.quantize` with an atom budget for two tensor products in the
same dimension ``d``: *isotropic*, ``U[0,1]ᵈ`` (the curse: a grid with ``N`` atoms has error
∝ ``N^(−1/d)``), and *decaying*, ``U[0, ρʲ]`` for ``j = 0..d−1`` (the delayed curse, eq.
(4.22)). The error is the product-ℓ1 W1 (exact: the sum of exact 1-D
marginal errors, Lemma 4.1) -- an **upper bound** of the Euclidean W1 -- and, at small sizes,
the exact Euclidean W1 (network simplex) to a much finer quantization. Time: budget + atoms
(materialized).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._validate import as_int
from ._base import Study, StudyConfig, clock, draw_front

_STYLES = (("isotropic", "o-"), ("decaying", "s-"))


@dataclass(frozen=True)
class QuantizationConfig(StudyConfig):
    """Atom budgets for ``U[0,1]ᵈ`` and ``∏ⱼ U[0, ρʲ]`` (defaults: the full study)."""

    study = "quantization"
    _QUICK = dict(d=6, atoms=(1, 4, 16, 64, 256, 1024, 4096, 16384), fine=2048, exact_max=128)
    _SMOKE = dict(d=3, atoms=(1, 8, 64, 512), fine=512, exact_max=64)

    d: int = 8
    rho: float = 0.5
    atoms: tuple = (1, 4, 16, 64, 256, 1024, 4096, 16384, 65536, 262144)
    #: atoms of the fine reference of the exact Euclidean W1
    fine: int = 4096
    #: the exact Euclidean W1 is computed up to this many atoms (0: never)
    exact_max: int = 256
    #: the target of the headline's atom budgets
    eps: float = 0.05

    def __post_init__(self):
        self._ints("d", "fine", low=1)
        self._ints("exact_max", low=0)
        self._floats("eps", low=0.0, low_open=True)
        self._floats("rho", low=0.0, high=1.0, low_open=True)
        self._each("atoms", as_int, low=1)


def _fmt_int(n: int) -> str:
    return str(n) if n < 10**9 else f"{float(n):.2e}"


def _rows(cfg: QuantizationConfig, mu, fine, bar) -> list:
    """One timed quantization per budget: product-ℓ1 error, bound, exact W1 when small."""
    from ...distance import w1
    from ...quantize import quantize

    rows = []
    for n in cfg.atoms:
        def one():
            q = quantize(mu, atoms=int(n))
            return q, q.materialize(max_atoms=max(int(n), 1))

        (q, atoms), secs = clock(one)
        err, t_err = clock(lambda: q.error)
        row = dict(atoms_budget=int(n), n_atoms=int(q.n_atoms), counts=list(q.counts),
                   time_s=secs, product_l1=float(err), product_l1_time_s=t_err,
                   bound=float(q.bound))
        if q.n_atoms <= cfg.exact_max and fine is not None:
            r, t_ex = clock(lambda: w1(atoms.points, fine.points, "auto", a=atoms.weights,
                                       b=fine.weights), max_repeat=1)   # dense, or sparse
            row.update(euclidean_to_fine=float(r), euclidean_time_s=t_ex)
        rows.append(row)
        bar.update(1)
    return rows


class QuantizationStudy(Study):
    """Atom budget for an isotropic and a decaying tensor product."""

    name = "quantization"
    title = "Atoms: the curse and the delayed curse"
    Config = QuantizationConfig
    key = 3

    def n_units(self, cfg: QuantizationConfig) -> int:
        return len(_STYLES) * len(cfg.atoms)

    def run(self, cfg: QuantizationConfig, *, seed: int, bar) -> dict:
        from ...measures import TensorProduct, Uniform
        from ...quantize import budget, quantize

        d, rho = cfg.d, cfg.rho
        measures = {
            "isotropic": TensorProduct([Uniform(0.0, 1.0) for _ in range(d)]),
            "decaying": TensorProduct([Uniform(0.0, rho ** j) for j in range(d)]),
        }
        fine = {name: quantize(mu, atoms=cfg.fine).materialize() if cfg.exact_max else None
                for name, mu in measures.items()}
        out = {name: _rows(cfg, mu, fine[name], bar) for name, mu in measures.items()}
        b_iso = budget(np.ones(d), eps=cfg.eps)
        b_dec = budget(rho ** np.arange(d), eps=cfg.eps)
        return dict(setting=dict(d=d, rho=rho, isotropic="U[0,1]^d",
                                 decaying="prod_j U[0, rho^j], j = 0..d-1", rule="midpoint",
                                 fine_atoms=cfg.fine,
                                 error="product-l1: exact W1 for the l1 ground cost (sum of exact "
                                       "1-D marginal errors), an upper bound of the Euclidean W1"),
                    rows=out,
                    eps_target=cfg.eps,
                    atoms_for_eps=dict(isotropic=str(b_iso.n_atoms), decaying=str(b_dec.n_atoms),
                                       isotropic_counts=list(b_iso.counts)[:3],
                                       decaying_counts=list(b_dec.counts)))

    def table(self, result: dict):
        from ...report import Table

        rows = []
        for name, rs in result["rows"].items():
            for x in rs:
                rows.append([name, x["n_atoms"], " ".join(map(str, x["counts"])), x["time_s"],
                             x["product_l1"], x["bound"], x.get("euclidean_to_fine", "")])
        return Table(["measure", "N", "N_j", "time [s]", "product-l1 (≥ W1)", "bound",
                      "exact W1 to fine"], rows)

    def figure(self, result: dict, plt):
        fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
        _draw_atoms(axes[0], result)
        ax = axes[1]
        for name, style in _STYLES:
            rs = result["rows"][name]
            t = [x["time_s"] for x in rs]
            e = [x["product_l1"] for x in rs]
            ax.loglog(t, e, style, label=name)
            if name == "decaying":
                draw_front(ax, t, e)
        ax.set_xlabel("wall time: budget + materialized atoms [s]")
        ax.set_ylabel("product-l1 W1 error (upper bound)")
        ax.set_title("error vs time")
        ax.legend(fontsize=8)
        return fig

    def headline(self, result: dict, cfg: QuantizationConfig) -> dict:
        q = result
        a = q["atoms_for_eps"]
        iso, dec = int(a["isotropic"]), int(a["decaying"])
        return {"quantization": dict(
            eps=q["eps_target"], d=q["setting"]["d"], atoms_isotropic=a["isotropic"],
            atoms_decaying=a["decaying"],
            text=(f"the delayed-curse budget reaches eps = {q['eps_target']:g} (product-l1 bound) "
                  f"with N = {dec} atoms for widths {q['setting']['rho']:g}^j in d = "
                  f"{q['setting']['d']}, where the isotropic grid needs N = {_fmt_int(iso)}"))}


def _draw_atoms(ax, q: dict) -> None:
    """Left panel: error against atoms, the budget bound and the isotropic slope -1/d."""
    d = q["setting"]["d"]
    for name, style in _STYLES:
        rs = q["rows"][name]
        n = np.array([x["n_atoms"] for x in rs], dtype=float)
        e = np.array([x["product_l1"] for x in rs])
        ax.loglog(n, e, style, label=f"{name}: product-l1 (upper bound of W1)")
        ex = [(x["n_atoms"], x["euclidean_to_fine"]) for x in rs if "euclidean_to_fine" in x]
        if ex:
            ax.loglog(*zip(*ex), style[0] + ":", mfc="none",
                      label=f"{name}: exact Euclidean W1 to {q['setting']['fine_atoms']} atoms")
        ax.loglog(n, [x["bound"] for x in rs], "--", lw=1, alpha=0.7,
                  label=f"{name}: budget bound (4.22)")
        if name == "isotropic":
            m = n > 1
            if np.any(m):
                c = e[m][0] * n[m][0] ** (1.0 / d)
                ax.loglog(n[m], c * n[m] ** (-1.0 / d), "k-", lw=0.8,
                          label=f"slope -1/d = -1/{d} (the curse)")
    ax.set_xlabel("atoms N")
    ax.set_ylabel("W1 error")
    ax.set_title(f"atoms: d = {d}, widths 1 vs {q['setting']['rho']:g}^j")
    ax.legend(fontsize=7)


STUDY = QuantizationStudy()
