"""``kinred cost``: error against wall time for every knob of the toolkit, on this machine.

Usage::

    kinred cost [--quick | --smoke] [--out DIR] [--only STUDY ...] [--no-progress]

Measures one study per knob (the registry of :mod:`kinred.experiments.cost`): projected
dimension k and projection kind, number of projections L and solver tolerance of the recovery,
atoms of the quantization (isotropic vs decaying widths: the curse and the delayed curse), time
step and integrator, and the W1 method. Each is drawn as a Pareto plot (error vs time,
log-log) with its numbers in a table. The result folder (default ``results/cost`` or
``results/cost-quick``) holds ``cost.json``, ``cost.txt``, ``summary.json`` (written once the
numbers are on disk), ``cost_<study>.png`` and ``report.html``. The full run takes a few
minutes; ``--quick`` about a minute; ``--smoke`` a few seconds (tests). The headline sentences
are printed at the end.
"""

from __future__ import annotations

import argparse
import sys

NAME = "cost"
HELP = "measure what accuracy costs in time for every knob (Pareto plots, tables, report)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..experiments.cost import STUDIES

    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="reduced sizes, about a minute")
    size.add_argument("--smoke", action="store_true", help="tiny sizes, a few seconds (tests)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="result folder (default results/cost, results/cost-quick, results/cost-smoke)")
    parser.add_argument("--only", nargs="+", choices=STUDIES, metavar="STUDY",
                        help=f"run only these studies (of {', '.join(STUDIES)})")
    parser.add_argument("--seed", type=int, default=None, help="master seed (default 7)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")


def run(args) -> int:
    from ..experiments.cost import CostConfig
    from ..experiments.cost import run as run_cost

    overrides = {}
    if args.only:
        overrides["studies"] = tuple(args.only)
    if args.seed is not None:
        overrides["seed"] = args.seed
    if args.smoke:
        cfg, default_out = CostConfig.smoke(**overrides), "results/cost-smoke"
    elif args.quick:
        cfg, default_out = CostConfig.quick(**overrides), "results/cost-quick"
    else:
        cfg, default_out = CostConfig(**overrides), "results/cost"
    out = args.out or default_out
    result = run_cost(cfg, out_dir=out, progress=not args.no_progress)
    print(f"kinred cost: {result.wall_time:.1f} s on {result.machine['cpu']} "
          f"({result.machine['cores']} cores); results in {out}/ (report.html)")
    for h in result.headline.values():
        print(f"  - {h['text']}")
    sys.stdout.flush()
    return 0
