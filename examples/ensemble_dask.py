"""
Ensembles: serial and Dask
==========================

A small ensemble on the serial executor and on Dask: identical numbers.

Member ``i`` of a run with master seed ``s`` draws from ``member_seed(s, i)`` whatever
executes it, so results do not depend on the executor or on the number of workers
(:func:`kinred.ensemble.run_ensemble`). Here each member draws a JL map of a given kind and
measures its distortion on a fixed cloud.

Run it with ``python examples/ensemble_dask.py [--smoke]``; ``--smoke`` uses tiny sizes (what
the test suite runs). Dask is optional (``pip install kinred[dask]``); without it the script
compares serial with the process pool. The full run takes about 30 s on two cores, so the
documentation's gallery runs the smoke sizes: ``docs/conf.py`` sets the environment variable
``KINRED_EXAMPLES_SMOKE=1``, which this script reads like ``--smoke``.
"""

# %%
# One member
# ----------
# A member is a top-level function of ``(params, seed)``, so that workers can unpickle it.

import argparse
import importlib.util
import os

import matplotlib.pyplot as plt
import numpy as np

from kinred.ensemble import grid, run_ensemble


def member(params, seed):
    """One member: distortion of one random map."""
    from kinred.projection import distortion, jl_matrix

    pts = np.random.default_rng(12345).standard_normal((params["n"], params["d"]))
    M = jl_matrix(params["k"], params["d"], kind=params["kind"], seed=seed)
    return {"eps": distortion(M, pts).eps}


ap = argparse.ArgumentParser(description="Ensembles: serial and Dask")
ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
args = ap.parse_args()
smoke = args.smoke or os.environ.get("KINRED_EXAMPLES_SMOKE") == "1"
n, d = (30, 64) if smoke else (200, 1024)
members = grid(n=[n], d=[d], kind=["gaussian", "srht"], k=[16, 32],
               realization=range(2 if smoke else 10))
other = "dask" if importlib.util.find_spec("distributed") else "processes"

# %%
# The same ensemble on two executors
# ----------------------------------
# Two workers for the parallel executor; the serial one runs in this process. Worker
# processes are started with ``spawn`` and re-import this script, so everything that runs
# the ensemble sits under ``if __name__ == "__main__":`` (the member above must stay
# importable).


def compare(members, other):
    """Run the ensemble serially and on ``other``; the two arrays of distortions."""
    runs = {}
    for executor in ("serial", other):
        res = run_ensemble(member, members, master_seed=7, executor=executor, workers=2,
                           progress=False)
        runs[executor] = np.array([r["eps"] for r in res.results])
        print(f"{executor:>9}: {len(members)} members in {res.total_time:.2f} s")
    return runs["serial"], runs[other]


groups = [(kind, k) for kind in ("gaussian", "srht") for k in (16, 32)]
if __name__ == "__main__":
    a, b = compare(members, other)
    print("mean distortion eps per (kind, k) over realizations:")
    for kind, k in groups:
        idx = [i for i, m in enumerate(members) if m["kind"] == kind and m["k"] == k]
        print(f"  {kind:>9} k={k:<3d} {a[idx].mean():.6f}")
    same = bool(np.array_equal(a, b))
    print(f"serial and {other} identical: {same}")

# %%
# Every member, on both executors
# -------------------------------
# Each circle is one member computed serially, each cross the same member computed on the
# other executor: they coincide.

if __name__ == "__main__":
    fig, ax = plt.subplots(figsize=(6.4, 4), layout="constrained")
    for g, (kind, k) in enumerate(groups):
        idx = [i for i, m in enumerate(members) if m["kind"] == kind and m["k"] == k]
        ax.plot(np.full(len(idx), g), a[idx], "o", ms=9, mfc="none", color="tab:blue",
                label="serial" if g == 0 else None)
        ax.plot(np.full(len(idx), g), b[idx], "x", color="tab:orange",
                label=other if g == 0 else None)
    ax.set_xticks(range(len(groups)), [f"{kind}\nk = {k}" for kind, k in groups])
    ax.set_xlabel("kind of map and target dimension")
    ax.set_ylabel("worst distortion eps of squared distances")
    ax.set_title(f"{len(members)} members, {n} points in R^{d}")
    ax.legend(fontsize="small")
    plt.show()
    if not same:
        raise RuntimeError(f"serial and {other} results differ")
