"""The demo's terminal story (``kinred.experiments.demo.story``): labelled numbers that agree
with the run they describe, and three closing lines computed from them."""

import re

import numpy as np
import pytest

from kinred.experiments import demo


@pytest.fixture(scope="module")
def smoke():
    # the smoke demo's run, kept in memory: the story is made from the result's numbers (its
    # report and files, which demo.run also writes, are not read here)
    from kinred.experiments import kinetic_run

    return kinetic_run.run(demo.scene_config(demo.DemoConfig(smoke=True)), progress=False)


def test_story_rows_are_the_runs_numbers(smoke):
    lines = demo.story(smoke)
    text = "\n".join(lines)
    assert f"Phase space R^{2 * smoke.config.d}" in text
    head = next(ln for ln in lines if "measured" in ln and "certified bound" in ln)
    assert "(estimate)" in head and "a-priori bound" in head
    for k, r in smoke.per_k.items():
        row = next(ln for ln in lines if re.match(rf"^\s+{k}\s+\d", ln))
        cells = row.split()
        assert float(cells[1]) == pytest.approx(float(r["w1"][-1]), rel=1e-3)
        assert float(cells[3]) == pytest.approx(float(r["cert_w1"][-1]), rel=1e-3)
        # the certificate is valid, so its worst ratio over t >= 1 is at least 1
        sel = (smoke.t >= 1.0) & (r["w1"] > 0)
        expected = float(np.max(r["cert_w1"][sel] / r["w1"][sel]))
        worst = float(cells[5])
        assert worst == pytest.approx(expected, abs=0.006) and 1.0 <= worst < 10.0
        assert ("vacuous" in row) == bool(r["vacuous"][-1])


def test_story_closing_lines_follow_the_numbers(smoke):
    lines = demo.story(smoke)
    i = lines.index("What this shows:")
    tail = "\n".join(lines[i + 1:])
    assert re.search(r"^\s+1\. ", tail, re.M) and re.search(r"^\s+2\. ", tail, re.M)
    assert re.search(r"^\s+3\. ", tail, re.M)
    assert "holds at every saved time" in tail           # the certificate is valid
    ks = list(smoke.per_k)
    w = [float(smoke.per_k[k]["w1"][-1]) for k in ks]
    assert ("as k grows" in tail) == bool(np.all(np.diff(w) < 0))
    rel = max(abs(float(smoke.per_k[k]["w1_reference"][-1]) - w[j]) / w[j]
              for j, k in enumerate(ks))
    assert f"at most {100 * rel:.0f} %" in tail
