"""``kinred cost``: error against wall time for every knob of the toolkit, on this machine.

Usage::

    kinred cost [--quick | --smoke] [--out DIR] [--resume] [--only STUDY ...] [--no-progress]

Measures one study per knob (the registry of :mod:`kinred.experiments.cost`): projected
dimension k and projection kind, number of projections L and solver tolerance of the recovery,
atoms of the quantization (isotropic vs decaying widths: the curse and the delayed curse), time
step and integrator, and the W1 method. Each is drawn as a Pareto plot (error vs time,
log-log) with its numbers in a table. The result folder (default ``results/cost`` or
``results/cost-quick``, ``results/cost-smoke``) holds ``stages/`` (one file per study, written
as it finishes), ``cost.json``, ``cost.txt``, ``summary.json`` (written once the numbers are on
disk), ``cost_<study>.png`` and ``report.html``. ``--resume`` continues an interrupted run
(finished studies are loaded with the times measured then); without it a previous ``kinred
cost`` in the folder is replaced (said in one line) and a folder holding other files is
refused (the rule of :mod:`kinred.commands._output`). The full run takes a few minutes;
``--quick`` about 20 s; ``--smoke`` a few seconds (tests). The headline sentences are
printed at the end, then the result folder.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import _output

NAME = "cost"
HELP = "measure what accuracy costs in time for every knob (Pareto plots, tables, report)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..experiments.cost import STUDIES

    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="reduced sizes, about 20 s")
    size.add_argument("--smoke", action="store_true", help="tiny sizes, a few seconds (tests)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="result folder (default results/cost, results/cost-quick, "
                             "results/cost-smoke; a previous `kinred cost` there is replaced "
                             "unless --resume)")
    parser.add_argument("--resume", action="store_true",
                        help="continue an interrupted run in --out (finished studies are loaded)")
    parser.add_argument("--only", nargs="+", choices=STUDIES, metavar="STUDY",
                        help=f"run only these studies (of {', '.join(STUDIES)})")
    parser.add_argument("--seed", type=int, default=None, help="master seed (default 7)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar (shown on stderr when it is a terminal)")


def run(args) -> int:
    from ..experiments.cost import CostConfig
    from ..experiments.cost import run as run_cost

    overrides = {}
    if args.only:
        overrides["studies"] = tuple(args.only)
    if args.seed is not None:
        overrides["seed"] = args.seed
    if args.smoke:
        cfg, size = CostConfig.smoke(**overrides), "smoke"
    elif args.quick:
        cfg, size = CostConfig.quick(**overrides), "quick"
    else:
        cfg, size = CostConfig(**overrides), None
    layout = _output.LAYOUTS["cost"]
    out = Path(args.out) if args.out else _output.default_out("cost", size=size)
    _output.prepare(out, layout, resume=args.resume)
    progress = not args.no_progress and sys.stderr.isatty()
    result = run_cost(cfg, out_dir=out, resume=args.resume, progress=progress)
    _output.record(out, layout)
    loaded = [n for n, v in result.stages.items() if v == "loaded"]
    print(f"kinred cost: {result.wall_time:.1f} s on {result.machine['cpu']} "
          f"({result.machine['cores']} cores)"
          + (f"; studies loaded from the previous run: {', '.join(loaded)}" if loaded else ""))
    for h in result.headline.values():
        print(f"  - {h['text']}")
    print(f"results: {out.resolve()} (report.html, cost.txt, cost.json, cost_<study>.png)")
    sys.stdout.flush()
    return 0
