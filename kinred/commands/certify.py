"""``kinred certify SCENE.toml [--out DIR] [--resume] [--smoke] [--norm N]``: certified bounds.

Runs the scene's kinetic pipeline (as ``kinred run``, same result folder layout and
``--resume`` semantics: a stage store in ``OUT/stages``) with ``[certify] enabled = true``:
every reduced run is certified (:mod:`kinred.experiments.kinetic_certify`). Stages that
``kinred run`` computed for the same scene (its folder ``results/run-<scene name>[-smoke]``, or
``--from-run DIR``) are reused, not recomputed, where their configuration digest matches
(:class:`kinred.experiments.kinetic_run.SharedStages`); they are listed as ``shared``. Prints per k the
measured error of the projected run, its certified bound, their worst ratio over ``t ≥ 1``,
the paper's a-priori bound, and a one-line verdict. Default folder
``results/certify-<scene name>``. Exit status 0 when every k is certified and valid, 1 when
one is not certified or (a bug) a measured value exceeds its certified bound; scenes the
certificate does not cover (not forward Euler, noise, an approximate pair sum, ...) are
refused before any work (status 2).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from . import _output

NAME = "certify"
HELP = ("certify a scene's projected runs: measured error, certified bound, ratio and the "
        "paper's bound per k")

#: A worst ratio certified/measured (t ≥ 1) up to this is called tight.
TIGHT = 10.0

#: ``(title, measured key, certified key, a-priori key, a-priori's name)`` per printed norm.
_NORMS = {
    "rms": ("weighted RMS error (Theorem 2.3's norm)", "err_rms", "cert_rms", "paper_rms",
            "eq. (2.18)"),
    "max": ("max error over atoms (Theorems 2.2, 3.1)", "err_max", "cert_max", "paper_max",
            "√2·eq. (2.11)"),
    "w1": ("W1(M#μᴺ(t), νᴺ(t)), Theorem 4.3's middle term", "w1", "cert_w1", "term_jl",
           "√2·D(t)·ε_JL"),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _output.add_scene_arguments(parser, "certify")
    parser.add_argument("--from-run", metavar="DIR",
                        help="result folder of `kinred run` for this scene whose stages are "
                             "reused where their configuration digest matches (default: "
                             "results/run-<scene name>[-smoke])")
    parser.add_argument("--norm", choices=("rms", "max", "both"),
                        help="norms to print (default: the scene's [certify] norm, else both)")


def _config(args):
    from ..experiments import kinetic_certify
    from ..scenefile import load_config

    cfg = load_config(args.scene, smoke=args.smoke)
    kinetic_certify.check_certifiable(cfg)
    return dataclasses.replace(cfg, certify=dataclasses.replace(cfg.certify, enabled=True))


def _table(result, norm: str):
    from ..experiments.kinetic_certify import worst_ratio
    from ..report import Table

    title, meas, cert, paper, pname = _NORMS[norm]
    rows = []
    for k, r in result.per_k.items():
        rows.append([f"k={k}", float(r[meas][-1]), float(r[cert][-1]),
                     worst_ratio(r[cert], r[meas], result.t), float(r[paper][-1]),
                     "yes" if np.any(r["cert_saturated"]) else "no"])
    return Table(["k", "at T: measured", "certified bound", "certified/measured max t≥1",
                  f"a-priori bound {pname}", "saturated"], rows, caption=title)


def verdict(k, r, t) -> tuple[bool, str]:
    """``(ok, line)``: the one-line verdict of one k stage ``r`` at saved times ``t``."""
    from ..experiments.kinetic_certify import worst_ratio

    note = str(r["cert_note"])
    if not np.all(np.isfinite(r["cert_w1"])):
        return False, f"k={k}: {note}"
    bad = [(name, np.flatnonzero(~(r[m] <= r[c]))) for name, (_, m, c, _, _) in _NORMS.items()]
    bad = [(name, idx) for name, idx in bad if idx.size]
    if bad:
        where = "; ".join(f"{name} at t = {', '.join(f'{t[i]:g}' for i in idx[:5])}"
                          for name, idx in bad)
        return False, (f"k={k}: INVALID: a measured value exceeds its certified bound ({where}): "
                       "a bug, please report it with the scene file")
    ratios = {name: worst_ratio(r[c], r[m], t) for name, (_, m, c, _, _) in _NORMS.items()}
    worst = max((x for x in ratios.values() if np.isfinite(x)), default=float("nan"))
    shown = ", ".join(f"{name} {x:.3g}" for name, x in ratios.items())
    kind = ("tight" if worst <= TIGHT else "loose") if np.isfinite(worst) else "no t ≥ 1"
    line = (f"k={k}: valid: measured ≤ certified bound at all {len(t)} saved times; worst "
            f"certified/measured over t ≥ 1: {shown}: {kind}"
            + (f" (≤ {TIGHT:g}×)" if kind == "tight" else "")
            + ("; saturated at some times (the trivial bound |y| + |Mx|)"
               if np.any(r["cert_saturated"]) else ""))
    return True, line


def run(args) -> int:
    from ..experiments import kinetic_run

    cfg = _config(args)
    layout = _output.LAYOUTS["certify"]
    out = Path(args.out) if args.out else _output.default_out(
        "certify", scene=Path(args.scene).stem, size="smoke" if args.smoke else None)
    source = Path(args.from_run) if args.from_run else _output.default_out(
        "run", scene=Path(args.scene).stem, size="smoke" if args.smoke else None)
    _output.prepare(out, layout, resume=args.resume)
    result = kinetic_run.run(cfg, out_dir=out, resume=args.resume,
                             progress=False if args.no_progress else None,
                             label=f"kinred certify {Path(cfg.source).name}",
                             share_from=source if source.resolve() != out.resolve() else None,
                             figures=not args.no_figures)
    _output.record(out, layout)
    print(f"kinred certify: {cfg.title}: d = {cfg.d}, N = {result.n_atoms} atoms, "
          f"{cfg.method} dt = {cfg.dt:g}, T = {cfg.t_final:g}, k ∈ {list(cfg.ks)}")
    norm = args.norm or cfg.certify.norm          # what is printed (both are computed)
    norms = ("rms", "max") if norm == "both" else (norm,)
    for norm in norms + ("w1",):
        table = _table(result, norm)
        print(f"\n{table.caption}:")
        print(table.to_text())
    print()
    ok = True
    for k, r in result.per_k.items():
        good, line = verdict(k, r, result.t)
        ok &= good
        print(line)
    cost = sum(float(r["cert_time"]) for r in result.per_k.values())
    print("labels: measured (the runs), certified bound (kinred.certify, for the forward-Euler "
          "runs made), a-priori bound (the paper's constants)")
    print("stages: " + ", ".join(f"{k}: {v}" for k, v in result.stages.items())
          + (f" (shared: taken from `kinred run` in {source}, same configuration digest)"
             if "shared" in result.stages.values() else ""))
    print(f"wall time {result.wall_time:.1f} s (certificates: {cost:.1f} s, when their stages "
          "were computed)")
    print(f"report: {out / 'report.html'}")
    sys.stdout.flush()
    return 0 if ok else 1
