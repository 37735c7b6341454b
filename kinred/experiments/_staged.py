"""Stages and a progress bar for the paper studies that are not ensembles (Figure 4, §3.3.1).

A study is cut into named stages whose numbers are written to a
:class:`kinred.io.StageStore` in ``OUT/stages`` as soon as each finishes, so an interrupted
run resumes (``resume=True``, ``--resume``) with the numbers of an uninterrupted one. One
tqdm bar (time elapsed and remaining, on stderr) counts work units: each stage has a
weight, simulations advance it step by step (:meth:`Staged.ticker`), and a stage loaded from
the store advances it by its whole weight at once.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

from ..io import StageStore, read_npz, to_jsonable

__all__ = ["Staged", "config_digest"]


def config_digest(config: dict) -> str:
    """SHA-256 of a JSON configuration (what a resumed run must match)."""
    blob = json.dumps(to_jsonable(config), sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


class Staged:
    """The stage store and progress bar of one study run.

    Parameters
    ----------
    config : dict
        JSON configuration of the run (its digest ties the stage files to it).
    out_dir : path or None
        Result folder; the stages go to ``out_dir/stages`` (None: nothing is stored).
    resume : bool
        Load the stages already in the store.
    total : int
        Work units of the whole run (sum of the stage weights).
    desc : str
        Label of the bar.
    progress : bool or None
        Show the bar (None: when stderr is a terminal).
    """

    def __init__(self, config: dict, out_dir, *, resume: bool, total: int, desc: str,
                 progress: bool | None):
        from tqdm import tqdm

        folder = None if out_dir is None else Path(out_dir) / "stages"
        self.store = StageStore(folder, config_digest(config), resume=resume,
                                describe={"config": config})
        if progress is None:
            progress = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
        self.bar = tqdm(total=int(total), desc=desc, disable=not progress, file=sys.stderr,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed} elapsed, "
                                   "{remaining} left{postfix}", mininterval=0.5)

    def stage(self, name: str, weight: int, compute, keys=()):
        """The arrays of stage ``name``: loaded from the store, or ``compute()`` (a dict of
        arrays) written to it; the bar ends ``weight`` units further either way."""
        self.bar.set_postfix_str(name, refresh=False)
        start = self.bar.n
        value = self.store.get_or_compute(
            name, compute, load=lambda path: read_npz(path, what="stage file", keys=keys))
        self.bar.update(max(0, start + int(weight) - self.bar.n))
        return value

    def ticker(self, per_step: int = 1):
        """A :func:`kinred.integrate.simulate` observer advancing the bar by ``per_step`` per step."""
        bar = self.bar

        def tick(t, state, scene):
            bar.update(per_step)

        return tick

    @property
    def status(self) -> dict:
        """``{stage: "loaded" | "computed"}`` in the order asked for."""
        return dict(self.store.status)

    def close(self) -> None:
        self.bar.close()
        self.store.close()
