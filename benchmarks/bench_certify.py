"""Benchmark: certificates of projected runs (issue 16) – tightness and overhead.

For each case, every ``k``: the certified/measured ratio (worst over saved times ``t >= 1``,
weighted RMS norm and max-over-agents norm), validity (``bound >= error`` everywhere), and the
time of ``certify`` against the two plain simulations it contains (``simulate`` of the scene
and of its projection, same steps), whose ratio is the certificate's overhead (target ≤ 1.5×),
in wall time and in process CPU time (``cpu ovh``, steadier on a shared machine).

Cases (full sizes; ``--quick`` shrinks N, d, T and the k lists so that everything runs in a
few minutes on a loaded machine):

* ``demo`` – the demo's scene (``kinred.experiments.demo``): Cucker–Smale G = 2, β = 0.5 on
  the quantized phase-space measure (400 weighted atoms, d = 100), k = 2, 5, 10, 25,
  h = 0.05, T = 20;
* ``fig4`` – Figure 4's left panel (``kinred.experiments.fig4``): N = d = 200, β = 0.4, G = 1,
  normal data, k = 20, 40, 60, 100, 140, 180, h = 0.02, T = 30;
* ``table1`` – Table 1 (``kinred.experiments.table1``): N = 1000, d = 200, G = 0.8,
  ``normalize="sum"``, β = 1.5 and 1.62, k = 25, 50, 100, 150, h = 0.02, T = 30 (float64);
* ``table1-nonflock`` – the same at β = 1.7 (goal ≤ 100, reported);
* ``mill`` – the D'Orsogna mill scenes ``examples/scenes/dorsogna-mill-2d.toml`` and
  ``dorsogna-mill-lift-200.toml`` (self-propulsion + softened Morse; goal ≤ 100, reported).

Run from the repository root (the full run takes hours: use an idle machine)::

    python benchmarks/bench_certify.py                 # full sizes
    python benchmarks/bench_certify.py --quick         # reduced sizes
    python benchmarks/bench_certify.py --only fig4 mill
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from kinred._rng import member_seed  # noqa: E402
from kinred.certify import certify  # noqa: E402
from kinred.dynamics import Alignment, CuckerSmale, Scene, project_state  # noqa: E402
from kinred.integrate import SaveAt, simulate  # noqa: E402
from kinred.projection import jl_matrix  # noqa: E402


def _atoms_case(cfg, atoms, t_final):
    """Scene, initial data and projection maker of a kinetic_run scene file config."""
    from kinred.kinetic import weighted_scene
    from kinred.quantize import quantize

    mu0 = cfg.initial_measure()
    at = quantize(mu0, atoms=atoms, rule=cfg.rule).materialize()
    d = cfg.d
    x0, v0 = at.points[:, :d], at.points[:, d:]
    scene = weighted_scene(cfg.scene(), at.weights)

    def make_M(k):
        return jl_matrix(k, d, kind=cfg.kind, seed=member_seed(cfg.projection_seed, k))

    return scene, x0, v0, make_M, cfg.dt, t_final


def case_demo(quick):
    from kinred.experiments import demo

    cfg = demo.scene_config(demo.DemoConfig(atoms=120 if quick else None))
    scene, x0, v0, make_M, dt, T = _atoms_case(cfg, cfg.atoms, 5.0 if quick else cfg.t_final)
    return [("demo", scene, x0, v0, make_M, (2, 5, 10, 25), dt, T, 25)]


def case_fig4(quick):
    from kinred.experiments.fig4 import Fig4Config

    cfg = Fig4Config(N=100, d=100, steps=500) if quick else Fig4Config()
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(0,)))
    x0 = rng.standard_normal((cfg.N, cfg.d))
    v0 = rng.standard_normal((cfg.N, cfg.d))
    scene = Scene([Alignment(CuckerSmale(G=cfg.G, beta=cfg.beta))], normalize=cfg.normalize)
    ks = (20, 60) if quick else cfg.ks

    def make_M(k):
        return jl_matrix(k, cfg.d, kind=cfg.kind, seed=member_seed(cfg.seed, (1, k, 0)))

    return [("fig4", scene, x0, v0, make_M, ks, cfg.dt, cfg.steps * cfg.dt, cfg.record_every)]


def _table1(quick, betas, name):
    from kinred.experiments.table1 import Table1Config, initial_data

    cfg = Table1Config()
    N, G, T = (200, cfg.G * cfg.N / 200, 10.0) if quick else (cfg.N, cfg.G, cfg.steps * cfg.dt)
    x0, v0 = initial_data(N, cfg.d, cfg.data_seed)
    ks = (25, 100) if quick else (25, 50, 100, 150)
    out = []
    for beta in betas:
        scene = Scene([Alignment(CuckerSmale(G=G, beta=beta))], normalize="sum")

        def make_M(k):
            return jl_matrix(k, cfg.d, kind=cfg.kind, seed=member_seed(cfg.seed, k))

        out.append((f"{name} beta={beta}", scene, x0, v0, make_M, ks, cfg.dt, T, 50))
    return out


def case_table1(quick):
    return _table1(quick, (1.5, 1.62), "table1")


def case_table1_nonflock(quick):
    return _table1(quick, (1.7,), "table1")


def case_mill(quick):
    from kinred.experiments import kinetic_run

    out = []
    for fname in ("dorsogna-mill-2d.toml", "dorsogna-mill-lift-200.toml"):
        cfg = kinetic_run.load_config(os.path.join(ROOT, "examples", "scenes", fname))
        atoms = 60 if quick else cfg.atoms
        T = 4.0 if quick else cfg.t_final
        scene, x0, v0, make_M, dt, T = _atoms_case(cfg, atoms, T)
        out.append((f"mill {fname}", scene, x0, v0, make_M, cfg.ks, dt, T, cfg.save_every))
    return out


CASES = {"demo": case_demo, "fig4": case_fig4, "table1": case_table1,
         "table1-nonflock": case_table1_nonflock, "mill": case_mill}


def _clock():
    return np.array([time.perf_counter(), time.process_time()])


def plain_time(scene, x0, v0, M, dt, T, every):
    """Wall and CPU seconds of the two plain simulations a certificate contains."""
    save = SaveAt(every=every, observables=())
    t = _clock()
    simulate(scene, x0, v0, (0.0, T), dt, save=save)
    y0, w0 = project_state(M, x0, v0)
    simulate(scene.project(M), y0, w0, (0.0, T), dt, save=save)
    return _clock() - t


def run_case(name, scene, x0, v0, make_M, ks, dt, T, every, timing):
    print(f"\n== {name}: N={x0.shape[0]}, d={x0.shape[1]}, h={dt}, T={T}, {scene!r}")
    print(f"{'k':>5} {'worst rms ratio':>16} {'worst max ratio':>16} {'valid':>6} "
          f"{'saturated':>9} {'error(T)':>10} {'bound(T)':>10} {'certify s':>10} "
          f"{'plain s':>8} {'overhead':>8} {'cpu ovh':>8}")
    if timing:          # load the compiled kernels outside the timings (one step of each)
        certify(scene, make_M(ks[0]), x0, v0, t_span=(0.0, dt), dt=dt, paper=False)
        plain_time(scene, x0, v0, make_M(ks[0]), dt, dt, 1)
    for k in ks:
        M = make_M(k)
        t = _clock()
        c = certify(scene, M, x0, v0, t_span=(0.0, T), dt=dt, save=SaveAt(every=every),
                    paper=False)
        tc = _clock() - t
        tp = plain_time(scene, x0, v0, M, dt, T, every) if timing else np.full(2, np.nan)
        print(f"{k:>5} {c.worst_ratio_after(1.0):>16.3g} {c.worst_ratio_after(1.0, 'max'):>16.3g} "
              f"{str(c.valid):>6} {np.mean(c.saturated[c.t >= 1.0]):>9.0%} "
              f"{c.error[-1]:>10.3g} {c.bound[-1]:>10.3g} "
              f"{tc[0]:>10.2f} {tp[0]:>8.2f} {tc[0] / tp[0]:>8.2f} {tc[1] / tp[1]:>8.2f}",
              flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes")
    ap.add_argument("--only", nargs="*", choices=sorted(CASES), help="run only these cases")
    ap.add_argument("--no-timing", action="store_true", help="skip the plain simulations")
    args = ap.parse_args(argv)
    names = args.only or list(CASES)
    print(f"bench_certify ({'quick' if args.quick else 'full'}): worst ratios over t >= 1")
    for nm in names:
        for case in CASES[nm](args.quick):
            run_case(*case, timing=not args.no_timing)


if __name__ == "__main__":
    main()
