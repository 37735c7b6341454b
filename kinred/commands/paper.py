"""``kinred paper STUDY``: reproduce the paper's numerical experiments.

* ``kinred paper table1`` -- Table 1 and Figures 1-3 (§3.4.1, flocking from projections).
* ``kinred paper calibrate`` -- which coupling convention (G, initial data) matches the most
  of Table 1's cells (docs/dynamics.md, "Calibrating G").
* ``kinred paper fig4`` -- Figure 4 (§3.4.2, projection and l1-recovery errors over time).
* ``kinred paper strategies`` -- the three recovery strategies of §3.3.1 at equal work.

Every study writes to ``results/paper-<study>`` (``results/paper-<study>-quick`` with
``--quick``; ``--out`` to choose), shows a progress bar with the time remaining, writes its
numbers as they are produced and continues an interrupted run with ``--resume``; without it,
a previous run of the same study in the folder is replaced (the rule of
:mod:`kinred.commands._output`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from . import _output

NAME = "paper"
HELP = "reproduce the paper's experiments (table1, calibrate, fig4, strategies)"


def _add_output(p: argparse.ArgumentParser, study: str) -> None:
    """--out, --quick, --resume and --no-progress: the options every study has."""
    d = _output.default_out(f"paper {study}").as_posix()
    p.add_argument("--out", default=None, metavar="DIR",
                   help=f"result folder (default {d}, {d}-quick with --quick; a previous "
                        f"`kinred paper {study}` run there is replaced unless --resume)")
    p.add_argument("--quick", action="store_true", help="reduced sizes, about a minute")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _add_ensemble(p: argparse.ArgumentParser) -> None:
    p.add_argument("--executor", choices=("serial", "processes", "dask"), default="processes")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: cores)")
    p.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    p.add_argument("--seed", type=int, default=None, help="master seed of the projections")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="study", metavar="STUDY")
    sub.required = True
    t1 = sub.add_parser("table1", help="Table 1 and Figures 1-3 of §3.4.1")
    _add_output(t1, "table1")
    _add_ensemble(t1)
    t1.add_argument("--N", type=int, default=None, help="number of agents (default 1000; quick 200)")
    t1.add_argument("--projections", type=int, default=None, help="projections per k")
    t1.add_argument("--precision", choices=("mixed", "double"), default=None,
                    help="pair sums in float32 with float64 state (mixed, the default: about "
                         "half the time, same verdicts) or everything in float64 (double)")
    ca = sub.add_parser("calibrate", help="calibrate Table 1's coupling G against the paper's cells")
    _add_output(ca, "calibrate")
    _add_ensemble(ca)
    ca.add_argument("--projections", type=int, default=None,
                    help="projections per (beta, k) and candidate (default 3; quick 2)")
    f4 = sub.add_parser("fig4", help="Figure 4 of §3.4.2")
    _add_output(f4, "fig4")
    st = sub.add_parser("strategies", help="the three recovery strategies of §3.3.1")
    _add_output(st, "strategies")
    st.add_argument("--L", type=int, default=5, help="number of projections (default 5)")


def run(args) -> int:
    study = {"table1": _table1, "calibrate": _calibrate, "fig4": _fig4,
             "strategies": _strategies}[args.study]
    layout = _output.LAYOUTS[f"paper {args.study}"]
    out = Path(args.out) if args.out else _output.default_out(
        layout.command, size="quick" if args.quick else None)
    progress = False if args.no_progress else None
    code = study(args, out, layout, progress)
    _output.record(out, layout)
    return code


def _results_line(wall_time: float, out: Path, files: str) -> str:
    return f"wall time {wall_time:.1f} s; results in {out.resolve()} ({files})"


def _table1(args, out: Path, layout, progress) -> int:
    from ..experiments import table1

    over = {}
    if args.N is not None:
        over["N"] = args.N
    if args.projections is not None:
        over["n_projections"] = args.projections
    if args.seed is not None:
        over["seed"] = args.seed
    if args.precision is not None:
        over["precision"] = args.precision
    cfg = table1.Table1Config.quick(**over) if args.quick else table1.Table1Config(**over)
    _output.prepare(out, layout, resume=args.resume)
    res = table1.run(cfg, out_dir=out, executor=args.executor, workers=args.workers,
                     scheduler=args.scheduler, resume=args.resume,
                     progress=progress is not False)
    print(table1.format_table(res.counts, title=f"Table 1 (kinred; coupling normalize="
                                                f"{cfg.normalize!r}, G={cfg.G:g}, "
                                                f"precision={cfg.precision})"))
    print()
    print(table1.format_table({b: v for b, v in table1.PAPER_TABLE1.items() if b in res.counts},
                              title="Table 1 (paper)"))
    print("\n" + _results_line(res.wall_time, out, "table1.json, figures, report.html"))
    return 0


def _calibrate(args, out: Path, layout, progress) -> int:
    from ..experiments import calibrate_table1 as cal

    over = {}
    if args.projections is not None:
        over["n_projections"] = args.projections
    if args.seed is not None:
        over["seed"] = args.seed
    cfg = cal.CalibrationConfig.quick(**over) if args.quick else cal.CalibrationConfig(**over)
    n_cand = len(cal.candidates(cfg))
    est = cal.estimate_seconds(cfg, args.workers)
    _output.prepare(out, layout, resume=args.resume)
    print(f"Table 1 calibration: {n_cand} candidates x {len(cfg.betas)} betas x (1 + "
          f"{len(cfg.ks)} k x {cfg.n_projections} projections) simulations at N={cfg.N}; "
          f"estimated wall time {est / 60:.0f} min ({est:.0f} s)"
          + ("; --quick: reduced sizes, its numbers are not the paper's" if args.quick else ""),
          flush=True)
    res = cal.run(cfg, out_dir=out, executor=args.executor, workers=args.workers,
                  scheduler=args.scheduler, resume=args.resume, progress=progress is not False)
    print(res.to_text())
    print(_results_line(res.wall_time, out, "calibration.json, calibration.txt, calibration.png"))
    return 0


def _stages_line(stages: dict) -> str:
    loaded = [s for s, v in stages.items() if v == "loaded"]
    if not loaded:
        return f"stages: {len(stages)} computed"
    return (f"stages: {len(loaded)} loaded from the previous run ({', '.join(loaded)}), "
            f"{len(stages) - len(loaded)} computed")


def _fig4(args, out: Path, layout, progress) -> int:
    from ..experiments import fig4

    cfg = fig4.Fig4Config.quick() if args.quick else fig4.Fig4Config()
    _output.prepare(out, layout, resume=args.resume)
    res = fig4.run(cfg, out_dir=out, resume=args.resume, progress=progress)
    print(f"Figure 4 (coupling normalize={cfg.normalize!r}, G={cfg.G:g}; N = {cfg.N}, "
          f"d = {cfg.d}, {cfg.steps} Euler steps of {cfg.dt:g})")
    print("relative projection error of v (measured), certified bound at T:  " + ", ".join(
        f"k={k}: max {e.max():.3f}, final {e[-1]:.3f} (bound {res.projection_bound[k][-1]:.3f})"
        for k, e in res.projection_error.items()))
    print("relative recovery error of v (measured):  " + ", ".join(
        f"L={L}: max {e.max():.3f}, final {e[-1]:.3f}" for L, e in res.recovery_error.items()))
    print(_stages_line(res.stages))
    print(_results_line(res.wall_time, out, "fig4.json, fig4.png, report.html"))
    return 0


def _strategies(args, out: Path, layout, progress) -> int:
    from ..experiments import fig4, recovery_strategies

    from .._validate import as_int

    cfg = fig4.Fig4Config.quick() if args.quick else fig4.Fig4Config()
    as_int(args.L, "--L", low=1)
    _output.prepare(out, layout, resume=args.resume)
    res = recovery_strategies.strategies(cfg, L=args.L, out_dir=out, resume=args.resume,
                                         progress=progress)
    print(res.to_text())
    print(_stages_line(res.stages))
    print(_results_line(res.wall_time, out, "strategies.json, strategies.txt"))
    return 0
