"""``kinred demo`` (``make demo``): the kinetic pipeline end to end on built-in defaults.

Quantize a phase-space measure in d = 100 (decaying widths) with the delayed-curse budget,
simulate the weighted Cucker–Smale particle system, project with k ∈ {2, 5, 10, 25}, compute
W1 between projected and reduced solutions over time (exact, POT) next to Theorem 4.3's bound,
estimate W1(μ_M(t), ν(t)) with a finer reference, and give the flocking verdicts. Prints a
short table and the path of ``report.html`` (see :mod:`kinred.experiments.demo`).

Results go to ``results/demo`` (``results/demo-smoke`` with ``--smoke``); a previous demo
there is replaced (said in one line), ``--resume`` continues an interrupted one, and a folder
holding other files is refused (the rule of :mod:`kinred.commands._output`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from . import _output

NAME = "demo"
HELP = "main job: quantize → kinetic solution → projected vs reduced W1 with Theorem 4.3's bound"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None, metavar="DIR",
                        help="result folder (default results/demo, results/demo-smoke with "
                             "--smoke; a previous demo there is replaced unless --resume)")
    parser.add_argument("--resume", action="store_true", help="continue an interrupted demo in --out")
    parser.add_argument("--no-progress", action="store_true",
                        help="hide the progress bar (shown on stderr when it is a terminal)")
    parser.add_argument("--smoke", action="store_true", help="tiny sizes (seconds)")
    parser.add_argument("--dim", type=int, help="dimension d (default 100)")
    parser.add_argument("--atoms", type=int, help="atom budget N (default 600; reference 3N)")
    parser.add_argument("--k", type=int, nargs="+", help="target dimensions (default 2 5 10 25)")


def run(args) -> int:
    from ..experiments import demo

    cfg = demo.DemoConfig(d=args.dim, atoms=args.atoms, ks=tuple(args.k) if args.k else None,
                          smoke=args.smoke)
    layout = _output.LAYOUTS["demo"]
    out = Path(args.out) if args.out else _output.default_out(
        "demo", size="smoke" if args.smoke else None)
    _output.prepare(out, layout, resume=args.resume)
    res = demo.run(cfg, out_dir=out, resume=args.resume,
                   progress=False if args.no_progress else None)
    _output.record(out, layout)
    print("\n".join(demo.story(res)))
    print(f"\nwall time {res.wall_time:.1f} s; stages: "
          + ", ".join(f"{k}: {v}" for k, v in res.stages.items()))
    print(f"report: {res.out_dir / 'report.html'}")
    return 0
