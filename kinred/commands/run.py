"""``kinred run SCENE.toml [--out DIR] [--resume] [--smoke]``: run a scene file.

Writes a result folder (default ``results/<scene name>``): ``stages/*.npz`` as they finish,
``results.npz`` and ``summary.json`` (the run is complete), then PNG figures and
``report.html`` (a figure that cannot be drawn is a note in the report). ``--resume``
continues an interrupted run without recomputing finished stages; a damaged stage file is
named in a warning and recomputed. ``--smoke`` uses the
scene's ``[smoke]`` sizes (tiny; what the tests run). Scene-file reference:
``docs/scene-file.md``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NAME = "run"
HELP = "run a scene file: kinetic and reduced solutions, W1 vs Theorem 4.3's bound, HTML report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE.toml", help="scene file (see docs/scene-file.md)")
    parser.add_argument("--out", metavar="DIR", help="result folder (default results/<scene name>)")
    parser.add_argument("--resume", action="store_true",
                        help="continue an interrupted run in --out (finished stages are loaded)")
    parser.add_argument("--smoke", action="store_true",
                        help="tiny sizes from the scene's [smoke] table (seconds)")


def run(args) -> int:
    from ..experiments import kinetic_run
    from ..scenefile import load_config

    cfg = load_config(args.scene, smoke=args.smoke)
    out = Path(args.out) if args.out else Path("results") / (Path(args.scene).stem +
                                                            ("-smoke" if args.smoke else ""))
    result = kinetic_run.run(cfg, out_dir=out, resume=args.resume)
    print(result.table().to_text())
    done = ", ".join(f"{k}: {v}" for k, v in result.stages.items())
    print(f"stages: {done}")
    print(f"wall time {result.wall_time:.1f} s")
    print(f"report: {out / 'report.html'}")
    sys.stdout.flush()
    return 0
