"""``kinred paper STUDY``: reproduce the paper's numerical experiments.

* ``kinred paper table1`` -- Table 1 and Figures 1-3 (§3.4.1, flocking from projections).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NAME = "paper"
HELP = "reproduce the paper's experiments (table1)"


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


def run(args) -> int:
    if args.study == "table1":
        return _table1(args)
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
    cfg = table1.Table1Config.quick(**over) if args.quick else table1.Table1Config(**over)
    res = table1.run(cfg, out_dir=args.out, executor=args.executor, workers=args.workers,
                     scheduler=args.scheduler, resume=args.resume, progress=not args.no_progress)
    print(table1.format_table(res.counts, title=f"Table 1 (kinred; coupling normalize="
                                                f"{cfg.normalize!r}, G={cfg.G:g})"))
    print()
    print(table1.format_table({b: v for b, v in table1.PAPER_TABLE1.items() if b in res.counts},
                              title="Table 1 (paper)"))
    print(f"\nwall time {res.wall_time:.1f} s; results in {Path(args.out).resolve()}"
          f" (table1.json, figures, report.html)", file=sys.stdout)
    return 0
