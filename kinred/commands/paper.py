"""``kinred paper STUDY``: reproduce the paper's numerical experiments.

* ``kinred paper table1`` -- Table 1 and Figures 1-3 (§3.4.1, flocking from projections).
* ``kinred paper calibrate`` -- which coupling convention (G, initial data) matches the most
  of Table 1's cells (docs/dynamics.md, "Calibrating G").
* ``kinred paper fig4`` -- Figure 4 (§3.4.2, projection and l1-recovery errors over time).
* ``kinred paper strategies`` -- the three recovery strategies of §3.3.1 at equal work.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NAME = "paper"
HELP = "reproduce the paper's experiments (table1, calibrate, fig4, strategies)"


def _add_common(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument("--out", default=default_out, help="result folder (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="reduced sizes, about a minute")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    p.add_argument("--executor", choices=("serial", "processes", "dask"), default="processes")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: cores)")
    p.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler")
    p.add_argument("--seed", type=int, default=None, help="master seed of the projections")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="study", metavar="STUDY")
    sub.required = True
    t1 = sub.add_parser("table1", help="Table 1 and Figures 1-3 of §3.4.1")
    _add_common(t1, "kinred-results/table1")
    t1.add_argument("--N", type=int, default=None, help="number of agents (default 1000; quick 200)")
    t1.add_argument("--projections", type=int, default=None, help="projections per k")
    t1.add_argument("--precision", choices=("mixed", "double"), default=None,
                    help="pair sums in float32 with float64 state (mixed, the default: about "
                         "half the time, same verdicts) or everything in float64 (double)")
    ca = sub.add_parser("calibrate", help="calibrate Table 1's coupling G against the paper's cells")
    _add_common(ca, "kinred-results/calibrate")
    ca.add_argument("--projections", type=int, default=None,
                    help="projections per (beta, k) and candidate (default 3; quick 2)")
    f4 = sub.add_parser("fig4", help="Figure 4 of §3.4.2")
    f4.add_argument("--out", default="kinred-results/fig4", help="result folder (default: %(default)s)")
    f4.add_argument("--quick", action="store_true", help="reduced sizes (N = d = 100)")
    st = sub.add_parser("strategies", help="the three recovery strategies of §3.3.1")
    st.add_argument("--quick", action="store_true", help="reduced sizes (N = d = 100)")
    st.add_argument("--L", type=int, default=5, help="number of projections (default 5)")


def run(args) -> int:
    if args.study == "table1":
        return _table1(args)
    if args.study == "calibrate":
        return _calibrate(args)
    if args.study == "fig4":
        return _fig4(args)
    if args.study == "strategies":
        return _strategies(args)
    raise SystemExit(f"unknown study {args.study}")  # pragma: no cover - argparse guards


def _table1(args) -> int:
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
    res = table1.run(cfg, out_dir=args.out, executor=args.executor, workers=args.workers,
                     scheduler=args.scheduler, resume=args.resume, progress=not args.no_progress)
    print(table1.format_table(res.counts, title=f"Table 1 (kinred; coupling normalize="
                                                f"{cfg.normalize!r}, G={cfg.G:g}, "
                                                f"precision={cfg.precision})"))
    print()
    print(table1.format_table({b: v for b, v in table1.PAPER_TABLE1.items() if b in res.counts},
                              title="Table 1 (paper)"))
    print(f"\nwall time {res.wall_time:.1f} s; results in {Path(args.out).resolve()}"
          f" (table1.json, figures, report.html)", file=sys.stdout)
    return 0


def _calibrate(args) -> int:
    from ..experiments import calibrate_table1 as cal

    over = {}
    if args.projections is not None:
        over["n_projections"] = args.projections
    if args.seed is not None:
        over["seed"] = args.seed
    cfg = cal.CalibrationConfig.quick(**over) if args.quick else cal.CalibrationConfig(**over)
    n_cand = len(cal.candidates(cfg))
    est = cal.estimate_seconds(cfg, args.workers)
    print(f"Table 1 calibration: {n_cand} candidates x {len(cfg.betas)} betas x (1 + "
          f"{len(cfg.ks)} k x {cfg.n_projections} projections) simulations at N={cfg.N}; "
          f"estimated wall time {est / 60:.0f} min ({est:.0f} s)"
          + ("; --quick: reduced sizes, its numbers are not the paper's" if args.quick else ""),
          flush=True)
    res = cal.run(cfg, out_dir=args.out, executor=args.executor, workers=args.workers,
                  scheduler=args.scheduler, resume=args.resume, progress=not args.no_progress)
    print(res.to_text())
    print(f"wall time {res.wall_time:.1f} s; results in {Path(args.out).resolve()}"
          f" (calibration.json, calibration.txt, calibration.png)")
    return 0


def _fig4(args) -> int:
    from ..experiments import fig4

    cfg = fig4.Fig4Config.quick() if args.quick else fig4.Fig4Config()
    res = fig4.run(cfg, out_dir=args.out)
    print(f"Figure 4 (coupling normalize={cfg.normalize!r}, G={cfg.G:g})")
    print("relative projection error of v:  " + ", ".join(
        f"k={k}: max {e.max():.3f}, final {e[-1]:.3f} (certified <= "
        f"{res.projection_bound[k][-1]:.3f})" for k, e in res.projection_error.items()))
    print("relative recovery error of v:    " + ", ".join(
        f"L={L}: max {e.max():.3f}, final {e[-1]:.3f}" for L, e in res.recovery_error.items()))
    print(f"wall time {res.wall_time:.1f} s; results in {Path(args.out).resolve()}")
    return 0


def _strategies(args) -> int:
    from ..experiments import fig4

    cfg = fig4.Fig4Config.quick() if args.quick else fig4.Fig4Config()
    res = fig4.strategies(cfg, L=args.L)
    print(res.to_text())
    return 0
