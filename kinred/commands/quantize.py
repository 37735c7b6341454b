"""``kinred quantize``: atoms for a measure file, with the delayed-curse budget table.

Usage::

    kinred quantize MEASURE.toml (--eps E | --atoms N) [--rule midpoint|paper]
                    [--out atoms.npz] [--max-atoms M] [--max-bytes B]

The measure file is TOML (full description in ``docs/measures-file.md``)::

    [[coordinate]]                # one table per coordinate, in order
    dist = "uniform"              # any scipy.stats continuous distribution name, or "dirac"
    params = {loc = 0.0, scale = 1.0}
    support = [0.0, 1.0]          # truncation; required for unbounded laws
    repeat = 50                   # optional: 50 copies of this coordinate
    decay = 0.9                   # optional: copy i is the law of decay**i * X

and mixtures are ``[[component]]`` tables with ``weight = ...`` each holding
``[[component.coordinate]]`` tables.

The command prints the budget table -- k̄ (coordinates with more than one atom), the ``N_j``
(run-length compressed), ``N``, the bound of eq. (4.22) -- beside the
paper's simple recipe for the same ε, and the a-posteriori error: for a tensor product the
exact W1 under the ℓ1 ground cost (sum of exact marginal 1-D errors), an upper bound of the
Euclidean W1. ``--out`` writes ``points (N, d)`` and ``weights (N,)`` to an ``.npz`` file
(:func:`kinred.io.atomic_write_npz`: temporary file in the same folder, then ``os.replace``;
permissions follow the umask); it refuses an existing directory or a missing folder before
quantizing, and when the atom count exceeds ``--max-atoms``.

Memory: the per-coordinate quantile arrays and the atom array are priced before they are
built (:func:`kinred.quantize.preflight`); past ``--max-bytes`` (default: the environment
variable ``KINRED_MAX_BYTES``, else 2 GiB) the command stops with one line
``kinred: error: TooLarge: ...`` naming the atoms, the bytes, the limit and the ε that would
fit, and exit code 2, before any large allocation.
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from ..errors import InvalidInput
from ..io import atomic_write_npz
from ..measures import Mixture, TensorProduct, load_measure
from ..quantize import RULE_CONSTANT, Quantization, quantize
from .._validate import fmt_count, parse_bytes

NAME = "quantize"
HELP = "quantize a measure file (TOML) to atoms with a delayed-curse budget and W1 bounds"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("measure", metavar="MEASURE.toml", help="measure file (see docs/measures-file.md)")
    g = parser.add_mutually_exclusive_group(required=True)
    g.add_argument("--eps", type=float, help="target W1 bound ε")
    g.add_argument("--atoms", type=int, help="atom budget N")
    parser.add_argument("--rule", choices=sorted(RULE_CONSTANT), default="midpoint",
                        help="quantile levels: midpoint (2i-1)/(2N), bound σ/(2N), default; "
                             "paper i/N, bound σ/N (eq. 4.21)")
    parser.add_argument("--out", metavar="ATOMS.npz", help="write points and weights to this .npz file")
    parser.add_argument("--max-atoms", type=int, default=None,
                        help="refuse to write more atoms than this (default: no count limit)")
    parser.add_argument("--max-bytes", metavar="B", default=None,
                        help="memory limit of every stage, e.g. 4G or 512M (default: environment "
                             "variable KINRED_MAX_BYTES, else 2G)")


def compress_counts(counts, limit: int = 12) -> str:
    """Run-length text of the N_j, e.g. ``"5 3 2×4 1×190"`` (at most ``limit`` runs shown)."""
    runs: list[list[int]] = []
    for n in counts:
        if runs and runs[-1][0] == n:
            runs[-1][1] += 1
        else:
            runs.append([n, 1])
    parts = [f"{n}" if k == 1 else f"{n}×{k}" for n, k in runs]
    if len(parts) > limit:
        parts = parts[: limit - 1] + [f"… ({len(parts) - limit + 1} more runs)"]
    return " ".join(parts)


def budget_lines(q: Quantization, indent: str = "") -> list[str]:
    """Lines of the budget table for a tensor-product quantization."""
    b = q.budget
    r = b.recipe
    opt = "proven optimal" if b.optimal else f"best found (continuous lower bound {b.lower_bound:.4g})"
    if b.atoms is not None:
        opt = "proven optimal" if b.optimal else f"best found (continuous lower bound on the bound {b.lower_bound:.4g})"
    recipe_nj = f"{r.n_common}×{r.k_bar}" if r.k_bar else "1"
    w = 26
    return [
        f"{indent}{'':<12}{'budget':<{w}}paper recipe (§4.5, same ε = {r.eps:.4g})",
        f"{indent}{'k̄':<12}{b.k_bar:<{w}}{r.k_bar}",
        f"{indent}{'N':<12}{fmt_count(b.n_atoms):<{w}}{fmt_count(r.n_atoms)}",
        f"{indent}{'bound':<12}{b.bound:<{w}.6g}{r.bound:.6g}",
        f"{indent}{'N_j':<12}{compress_counts(b.counts)}",
        f"{indent}{'':<12}recipe N_j: {recipe_nj}",
        f"{indent}{'budget':<12}{opt}",
    ]


def _error_line(q: Quantization, indent: str = "") -> str:
    if q.error_kind == "product-l1":
        what = "W1 under the ℓ1 ground cost (exact: sum of exact marginal 1-D errors; ≥ Euclidean W1)"
    elif q.error_kind == "exact":
        what = "W1 (exact)"
    else:
        what = "upper bound of the Euclidean W1 (Σ w_l × component product-ℓ1 errors)"
    return f"{indent}{what}: {q.error:.6g}"


def _check_out(path: str) -> None:
    """Refuse an ``--out`` that cannot be a new file, before any work is done."""
    if os.path.isdir(path):
        raise InvalidInput(f"--out {path}: is a directory; give the name of the .npz file to write")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InvalidInput(f"--out folder {folder} does not exist")


def _write_npz(path: str, points: np.ndarray, weights: np.ndarray) -> None:
    _check_out(path)
    atomic_write_npz(path, points=points, weights=weights)


def run(args) -> int:
    if args.out:
        _check_out(args.out)
    max_bytes = None if args.max_bytes is None else parse_bytes(args.max_bytes, "--max-bytes")
    if args.max_atoms is not None and args.max_atoms < 1:
        raise InvalidInput(f"--max-atoms must be >= 1, got {args.max_atoms}")
    mu = load_measure(args.measure)
    q = quantize(mu, eps=args.eps, atoms=args.atoms, rule=args.rule, max_bytes=max_bytes)
    c = RULE_CONSTANT[args.rule]
    target = f"eps = {args.eps:g}" if args.eps is not None else f"atoms ≤ {args.atoms}"
    print(f"measure   {args.measure}: {type(mu).__name__}, d = {mu.dim}")
    print(f"rule      {args.rule} (1-D bound {'σ/(2N)' if c == 0.5 else 'σ/N'}); target {target}")
    if isinstance(mu, TensorProduct):
        for line in budget_lines(q):
            print(line)
        print(_error_line(q))
    elif isinstance(mu, Mixture):
        print(f"mixture of {len(mu.components)} components: N = {fmt_count(q.n_atoms)}, "
              f"bound Σ w_l ε_l = {q.bound:.6g} (Lemma 4.2)")
        for l, (w, cq) in enumerate(zip(mu.weights, q.components)):
            print(f"component {l}  weight {w:g}")
            for line in budget_lines(cq, indent="  "):
                print(line)
        print(_error_line(q))
    else:  # pragma: no cover - the file format only makes tensor products and mixtures
        print(f"N = {fmt_count(q.n_atoms)}, bound {q.bound:.6g}")
    if args.out:
        atoms = q.materialize(max_atoms=args.max_atoms, max_bytes=max_bytes)
        _write_npz(args.out, atoms.points, atoms.weights)
        print(f"wrote {atoms.n_atoms} atoms (points {atoms.points.shape}, weights) to {args.out}")
    return 0
