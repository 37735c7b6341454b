"""Johnson–Lindenstrauss distortion against k, next to the bound jl_min_dim.

For n points, a random M: R^d -> R^k keeps every squared pairwise distance within
(1 ± eps) (eq. (2.1) of the paper, label ``eq:JLlem``) with high probability once
k >= jl_min_dim(n, eps) = 4 ln n / (eps²/2 - eps³/3). The measured worst distortion is
usually much smaller than the bound suggests.

    python examples/jl_distortion.py [--smoke]
"""

import argparse

import numpy as np

from kinred.projection import distortion, jl_matrix, jl_min_dim


def bound_eps(n, k):
    """Smallest eps in (0, 1) with jl_min_dim(n, eps) <= k (bisection), or None."""
    lo, hi = 1e-3, 0.999
    if jl_min_dim(n, hi) > k:
        return None
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if jl_min_dim(n, mid) <= k else (mid, hi)
    return hi


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
    args = ap.parse_args(argv)
    n, d = (50, 256) if args.smoke else (200, 1024)
    ks = [16, 64, 128] if args.smoke else [16, 32, 64, 128, 256, 512]
    kinds = ("gaussian", "srht") if args.smoke else ("gaussian", "rademacher", "achlioptas",
                                                      "srht", "dct")

    pts = np.random.default_rng(0).standard_normal((n, d))
    print(f"{n} points in R^{d}: worst squared-distance distortion eps over all pairs")
    print(f"{'k':>5} " + " ".join(f"{kind:>10}" for kind in kinds) + f" {'bound eps':>10}")
    for k in ks:
        eps = [distortion(jl_matrix(k, d, kind=kind, seed=k), pts).eps for kind in kinds]
        b = bound_eps(n, k)
        print(f"{k:>5} " + " ".join(f"{e:10.3f}" for e in eps)
              + (f" {b:10.3f}" if b is not None else f" {'(none<1)':>10}"))
    print("bound eps: the smallest eps with jl_min_dim(n, eps) <= k")
    print("done")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
