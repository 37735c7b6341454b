"""``kinred run SCENE.toml [--out DIR] [--resume] [--smoke] [--no-figures]``: run a scene file.

Prints a header first -- the scene, d, the atom count N (and why it differs from the
requested one), the quantization's a-priori bound ε, T, the step, the k's and the pair-sum
backend -- then runs. Writes a result folder (default ``results/run-<scene stem>``,
``results/run-<scene stem>-smoke`` with ``--smoke``): ``stages/*.npz`` as they finish,
``results.npz`` and ``summary.json`` (the run is complete), then PNG figures and
``report.html`` (a figure that cannot be drawn is a note in the report). ``--resume``
continues an interrupted run without recomputing finished stages; a damaged stage file is
named in a warning and recomputed. Without ``--resume`` a previous ``kinred run`` in the
folder is replaced (said in one line) and a folder holding other files is refused (the rule
of :mod:`kinred.commands._output`). ``--smoke`` uses the scene's ``[smoke]`` sizes (tiny;
what the tests run). ``--no-figures`` writes the report without drawing its figures (a note
in place of each). Scene-file reference: ``docs/scene-file.md``.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

from . import _output

NAME = "run"
HELP = "run a scene file: kinetic and reduced solutions, W1 vs Theorem 4.3's bound, HTML report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _output.add_scene_arguments(parser, "run")


def run(args) -> int:
    from ..experiments import kinetic_run
    from ..scenefile import load_config

    cfg = load_config(args.scene, smoke=args.smoke)
    layout = _output.LAYOUTS["run"]
    out = Path(args.out) if args.out else _output.default_out(
        "run", scene=Path(args.scene).stem, size="smoke" if args.smoke else None)
    header = header_lines(cfg)
    _output.prepare(out, layout, resume=args.resume)
    print("\n".join(header), flush=True)
    result = kinetic_run.run(cfg, out_dir=out, resume=args.resume,
                             progress=False if args.no_progress else None,
                             figures=not args.no_figures)
    _output.record(out, layout)
    print(result.table().to_text())
    done = ", ".join(f"{k}: {v}" for k, v in result.stages.items())
    print(f"stages: {done}")
    print(f"wall time {result.wall_time:.1f} s")
    print(f"report: {out / 'report.html'}")
    sys.stdout.flush()
    return 0


# ------------------------------------------------------------------------------------------
# the header
# ------------------------------------------------------------------------------------------
def header_lines(cfg) -> list[str]:
    """The header of ``kinred run`` for the scene configuration ``cfg`` (a scenefile.Config).

    The atom count and ε come from the same quantization the run makes
    (:func:`kinred.quantize.quantize` with the scene's ``eps``/``atoms`` and rule); only its
    budget is computed here, not the atoms.
    """
    n, eps, why = _quantization_text(cfg.initial_measure(), cfg.eps, cfg.atoms, cfg.rule)
    name = cfg.title or Path(cfg.source).stem
    lines = [f"kinred run: {name} ({cfg.source}{', smoke sizes' if cfg.smoke else ''})"]
    if cfg.description:
        lines.append(f"  scene    {cfg.description}")
    lines += [
        f"  d        {cfg.d} (the measure lives on phase space R^{2 * cfg.d}: positions and "
        "velocities)",
        f"  N        {n} atoms{why}",
        f"  ε        {eps:.4g} (a-priori quantization bound: W1(μ₀, μ₀ᴺ) ≤ ε, eq. (4.14))",
        f"  T        {cfg.t_final:g}, {cfg.method} dt = {cfg.dt:g}"
        + (f", saved every {cfg.save_every} steps" if (cfg.save_every or 1) > 1 else ""),
        f"  k        {', '.join(str(k) for k in cfg.ks)} ({cfg.kind} projections)",
        f"  backend  {_backend_text(cfg)}",
    ]
    if cfg.reference_atoms:
        lines.append(f"  ref      N′ ≤ {cfg.reference_atoms} atoms (a finer quantization: estimates "
                     "how far μᴺ(t) is from the kinetic solution)")
    return [lines[0]] + [part for line in lines[1:] for part in _wrap(line)]


def _wrap(text: str) -> list[str]:
    """``text`` wrapped to 96 columns, continuation lines under the value column."""
    return textwrap.wrap(text, width=96, subsequent_indent=" " * 11, break_on_hyphens=False)


def _backend_text(cfg) -> str:
    method, params = cfg.pairsum if cfg.pairsum is not None else ("dense", {})
    opts = ", ".join(f"{k}={v}" for k, v in params.items())
    if method == "auto":
        opts = ", ".join(filter(None, [opts, "chosen per system among dense, nufft, cells by "
                                             "estimated cost"]))
    return f"{method} pair sums{f' ({opts})' if opts else ''}, precision {cfg.precision}"


def _quantization_text(mu, eps, atoms, rule) -> tuple[int, float, str]:
    """``(N, ε, explanation)`` of the quantization of ``mu`` the run makes."""
    from ..measures import Atomic
    from ..quantize import quantize

    if isinstance(mu, Atomic) and eps is None and atoms is None:
        return mu.n_atoms, 0.0, ": the points of the data file, used as they are"
    q = quantize(mu, eps=eps, atoms=atoms, rule=rule)
    n, bound = int(q.n_atoms), float(q.bound)
    how, tail = _count_text(q, atoms)
    if atoms is None:
        return n, bound, f", chosen by the budget of eq. (4.22) for ε ≤ {eps:g}: {how}"
    if n == atoms:
        return n, bound, f": {how}"
    return n, bound, f", asked for {atoms}: {how}; {tail}"


def _product(counts) -> str:
    """``4·3^2·2`` for the counts (4, 3, 3, 2, 1, ...): the factors above 1, grouped."""
    big = sorted((c for c in counts if c > 1), reverse=True)
    if not big:
        return "1"
    parts, i = [], 0
    while i < len(big):
        j = i
        while j < len(big) and big[j] == big[i]:
            j += 1
        parts.append(f"{big[i]}" if j - i == 1 else f"{big[i]}^{j - i}")
        i = j
    if len(parts) > 8:
        parts = parts[:7] + ["…"]
    return "·".join(parts)


def _count_text(q, atoms) -> tuple[str, str]:
    """Why the quantization ``q`` has ``q.n_atoms`` atoms, and why not ``atoms``, in words."""
    from ..quantize import MixtureQuantization, PushQuantization, TensorQuantization

    if isinstance(q, PushQuantization):
        how, tail = _count_text(q.base, atoms)
        return how + " (then mapped into the lifted space)", tail
    if isinstance(q, TensorQuantization):
        k_bar = sum(1 for c in q.counts if c > 1)
        return (f"a tensor grid puts N_j atoms on coordinate j and N = ∏ N_j = "
                f"{_product(q.counts)} = {q.n_atoms} ({k_bar} of {len(q.counts)} coordinates "
                "with N_j > 1)",
                f"the budget of eq. (4.22) takes the counts with the smallest a-priori bound "
                f"under ∏ N_j ≤ {atoms}, and a product of integers seldom hits {atoms} exactly")
    if isinstance(q, MixtureQuantization):
        sizes = [int(c.n_atoms) for c in q.components]
        grids = {_product(c.counts) for c in q.components if isinstance(c, TensorQuantization)}
        grid = f" (each a {grids.pop()} grid)" if len(grids) == 1 and len(set(sizes)) == 1 else ""
        total = (f"{len(sizes)} × {sizes[0]}" if len(set(sizes)) == 1
                 else " + ".join(str(s) for s in sizes))
        return (f"the mixture's {len(sizes)} components are quantized as tensor grids to one "
                f"common accuracy and N = {total} = {q.n_atoms}{grid}",
                f"that accuracy is the finest whose total fits in {atoms} atoms")
    return f"N = {q.n_atoms}", f"the quantizer's counts do not reach {atoms} exactly"
