"""W1 between the same pair of clouds by every method: exact, exact-lazy, bracket, sliced.

``w1`` (eq. (4.5) of the paper, label ``wasserstein``) returns exact values from POT's network
simplex (dense or lazily evaluated cost) or a certified bracket ``lower <= W1 <= upper``;
``sliced_w1`` is a different (smaller) distance and says so.

    python examples/w1_methods.py [--smoke]
"""

import argparse
import time

import numpy as np

from kinred.distance import sliced_w1, w1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (for the test suite)")
    args = ap.parse_args(argv)
    n, d = (200, 5) if args.smoke else (1500, 10)

    rng = np.random.default_rng(0)
    mu = rng.uniform(0.0, 1.0, (n, d))
    nu = rng.uniform(0.0, 1.0, (n, d)) + 0.2          # shifted copy: W1 >= 0.2 * sqrt(d)
    print(f"two clouds of {n} points in R^{d}; W1 >= {0.2 * np.sqrt(d):.4f} (mean shift)")
    print(f"{'method':>12} {'value':>9} {'lower':>9} {'upper':>9} {'exact':>6} {'seconds':>8}")
    for method in ("exact", "exact-lazy", "bracket"):
        t0 = time.perf_counter()
        r = w1(mu, nu, method=method, seed=1)
        dt = time.perf_counter() - t0
        print(f"{r.method:>12} {r.value:9.5f} {r.lower:9.5f} {r.upper:9.5f} {str(r.exact):>6} {dt:8.3f}")
    t0 = time.perf_counter()
    s = sliced_w1(mu, nu, n_projections=256, seed=1)
    dt = time.perf_counter() - t0
    print(f"{'sliced':>12} {s.value:9.5f} {'':>9} {'':>9} {'--':>6} {dt:8.3f}   (stderr {s.stderr:.1e}; a different distance)")
    print("done")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
