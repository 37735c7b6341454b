"""Two threads simulating one Scene at once (issue 21, item 4e): the strip counters of the pair
sums are incremented under a lock, and the scene's plan cache is filled and evicted under one,
so concurrent runs give the serial runs' numbers bit for bit and exact counter totals."""

import collections
import importlib
import threading
import time

import numpy as np
import pytest

from kinred.dynamics import Alignment, AttractionRepulsion, CuckerSmale, Morse, Scene
from kinred.integrate import SaveAt, simulate
from kinred import _parallel
from kinred.pairsum import Dense, dense

_kernels = importlib.import_module("kinred.pairsum._kernels")
scene_mod = importlib.import_module("kinred.dynamics.scene")


def _scenes():
    return {
        "alignment": Scene([Alignment(CuckerSmale(1.0, 0.5))], "mean", block=4),
        "morse": Scene([AttractionRepulsion(Morse())], "mean", block=4),
    }


def _run(sc, seed, n):
    rng = np.random.default_rng(seed)
    x0, v0 = rng.uniform(0, 1, (n, 3)), rng.uniform(-1, 1, (n, 3))
    tr = simulate(sc, x0, v0, (0, 0.4), 0.01, save=SaveAt(every=40, states=True))
    return tr.x, tr.v


def _concurrently(jobs):
    out, errors = [None] * len(jobs), []
    barrier = threading.Barrier(len(jobs))

    def work(i, job):
        try:
            barrier.wait()
            out[i] = job()
        except BaseException as exc:  # noqa: BLE001 - reported by the test below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(i, j)) for i, j in enumerate(jobs)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    return out


class _YieldingCounter(collections.Counter):
    """A Counter whose read lets other threads run before the write, as a free-threaded
    interpreter (or a GIL switch) may: ``COUNTERS[s] += 1`` without a lock loses counts."""

    def __getitem__(self, key):
        value = super().__getitem__(key)
        time.sleep(0)
        return value


@pytest.mark.parametrize("name", ["alignment", "morse"])
def test_threads_simulating_one_scene_match_serial_runs_and_count_exactly(name, monkeypatch):
    """Main lost strip counts (and built plans twice, see below); the numbers must be bit for
    bit those of the serial runs, and the counters exactly twice the serial totals."""
    monkeypatch.setattr(_kernels, "COUNTERS", _YieldingCounter())
    # two-group regions even at these sizes (their pool is what the concurrent runs share)
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS", 0.0)
    monkeypatch.setattr(dense, "PARALLEL_MIN_SECONDS_LOOP", 0.0)
    sizes = [24, 25, 26, 27, 28, 29]       # more shapes than the cache keeps: plans are evicted
    with _parallel.num_threads(2):
        sc = _scenes()[name]
        serial = [_run(sc, i, n) for i, n in enumerate(sizes)]
        per_run = dict(_kernels.COUNTERS)
        assert sum(per_run.values()) > 0
        sc = _scenes()[name]                # a fresh scene: empty plan cache
        _kernels.COUNTERS.clear()
        conc = _concurrently([lambda i=i, n=n: _run(sc, i, n)
                              for _ in range(2) for i, n in enumerate(sizes)])
    for k, (x, v) in enumerate(conc):
        xs, vs = serial[k % len(sizes)]
        assert np.array_equal(x, xs) and np.array_equal(v, vs)
    assert dict(_kernels.COUNTERS) == {s: 2 * c for s, c in per_run.items()}
    assert len(sc._plans) <= scene_mod._PLANS_KEEP


def test_two_threads_build_one_plan(monkeypatch):
    """The plan cache is filled under a lock: two threads asking for the same shape at once
    get one plan, built once (main built it in both)."""
    built = []
    real = Dense.plan

    def slow_plan(self, scene, n, dim):
        built.append((n, dim))
        time.sleep(0.2)                     # both threads miss the cache meanwhile
        return real(self, scene, n, dim)

    monkeypatch.setattr(Dense, "plan", slow_plan)
    sc = _scenes()["alignment"]
    with _parallel.num_threads(1):
        plans = _concurrently([lambda: sc._plan(30, 3)] * 2)
    assert built == [(30, 3)] and plans[0] is plans[1]


def test_counter_increments_from_many_threads_are_not_lost(monkeypatch):
    monkeypatch.setattr(_kernels, "COUNTERS", _YieldingCounter())
    _concurrently([lambda: [_kernels.count("t") for _ in range(2000)]] * 8)
    assert _kernels.COUNTERS["t"] == 8 * 2000
