"""A small ensemble on the serial executor and on Dask: identical numbers.

Member i of a run with master seed s draws from ``member_seed(s, i)`` whatever executes it,
so results do not depend on the executor or on the number of workers. Here each member draws
a JL map of a given kind and measures its distortion on a fixed cloud.

    python examples/ensemble_dask.py [--smoke]

Dask is optional (``pip install kinred[dask]``); without it the script compares serial with
the process pool.
"""

import argparse
import importlib.util

import numpy as np

from kinred.ensemble import grid, run_ensemble


def member(params, seed):
    """One member: distortion of one random map (top-level, so that workers can unpickle it)."""
    from kinred.projection import distortion, jl_matrix

    pts = np.random.default_rng(12345).standard_normal((params["n"], params["d"]))
    M = jl_matrix(params["k"], params["d"], kind=params["kind"], seed=seed)
    return {"eps": distortion(M, pts).eps}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
    args = ap.parse_args(argv)
    n, d = (30, 64) if args.smoke else (200, 1024)
    members = grid(n=[n], d=[d], kind=["gaussian", "srht"], k=[16, 32],
                   realization=range(2 if args.smoke else 10))
    other = "dask" if importlib.util.find_spec("distributed") else "processes"

    runs = {}
    for executor in ("serial", other):
        res = run_ensemble(member, members, master_seed=7, executor=executor, workers=2,
                           progress=False)
        runs[executor] = np.array([r["eps"] for r in res.results])
        print(f"{executor:>9}: {len(members)} members in {res.total_time:.2f} s")
    a, b = runs["serial"], runs[other]
    print("mean distortion eps per (kind, k) over realizations:")
    for kind in ("gaussian", "srht"):
        for k in (16, 32):
            idx = [i for i, m in enumerate(members) if m["kind"] == kind and m["k"] == k]
            print(f"  {kind:>9} k={k:<3d} {a[idx].mean():.6f}")
    same = bool(np.array_equal(a, b))
    print(f"serial and {other} identical: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
