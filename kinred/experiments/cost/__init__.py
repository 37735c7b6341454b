"""``kinred cost``: what accuracy costs in time, for every knob of the toolkit, on this machine.

One study per knob, each a set of (wall time, error) points drawn as a Pareto plot (log-log)
with its numbers in a table; the module of each study states what it measures and how:

* :mod:`kinred.experiments.cost.projection` -- projected dimension ``k``, projection kind,
  and the engine's precision (Cucker–Smale in ℝᵈ vs ℝᵏ, §3.4.1);
* :mod:`kinred.experiments.cost.recovery` -- number of projections ``L`` and tolerance of
  basis pursuit (Figure 4 right, §3.4.2);
* :mod:`kinred.experiments.cost.quantization` -- atoms: the curse and the delayed curse
  (eq. (4.22));
* :mod:`kinred.experiments.cost.integrators` -- time step and integrator;
* :mod:`kinred.experiments.cost.w1` -- the W1 method.

:func:`run` measures the studies of a :class:`CostConfig` (a master seed, the selected
studies, one small config per study with ``full``/``quick``/``smoke`` presets);
:func:`write_outputs` writes the result folder. Times are wall-clock seconds of single calls
(the minimum of a few repetitions below 20 ms) after a warm-up run, so numba compilation is
not timed.

**Adding a knob** is adding one file and one line. The file,
``kinred/experiments/cost/<knob>.py``, holds a frozen config dataclass (a
:class:`StudyConfig` with its ``_QUICK`` and ``_SMOKE`` presets), a :class:`Study` subclass
(``name``, ``title``, ``Config``, an unused random-stream ``key``; ``run``, ``n_units``,
``table``, ``figure``, ``headline``) and ``STUDY = TheStudy()``; the line adds ``<knob>.STUDY``
to the list in ``_registry.py``. :func:`run`, the progress total, the headline, the report,
``kinred cost --only`` and :class:`CostConfig` all iterate over :data:`REGISTRY`.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..._validate import as_choice, as_int
from ...errors import InvalidInput
from ...io import to_jsonable
from ._base import (PRESETS, Study, StudyConfig, machine_info, pareto_front, progress_bar,
                    time_to_reach)
from . import _registry
from ._report import write_outputs

__all__ = ["CostConfig", "CostResult", "run", "write_outputs", "headline", "pareto_front",
           "time_to_reach", "STUDIES", "REGISTRY", "Study", "StudyConfig"]

#: The studies, ``{name: Study}`` (read-only), in report order.
REGISTRY = _registry.REGISTRY
#: Names of the studies of :func:`run`, in report order.
STUDIES = tuple(REGISTRY)


@dataclass(frozen=True)
class CostConfig:
    """The master seed, the studies to run and one config per study (default: the full run).

    Use :meth:`quick` (about a minute on 2 cores) or :meth:`smoke` (seconds, for tests).

    Parameters
    ----------
    seed : int
        Master seed (non-negative); each study draws its own streams from it.
    studies : tuple of str
        The studies to run, of :data:`STUDIES` (run and reported in that order).
    configs : mapping, optional
        ``{name: config}`` with the config class of each study (``REGISTRY[name].Config``);
        a study missing here gets its full preset.
    """

    seed: int = 7
    studies: tuple = STUDIES
    configs: Mapping = field(default_factory=dict)

    def __post_init__(self):
        as_int(self.seed, "seed", low=0)
        if isinstance(self.studies, str) or not isinstance(self.studies, (tuple, list)):
            raise InvalidInput(f"studies must be a tuple of study names, got {self.studies!r}")
        for s in self.studies:
            as_choice(s, "studies", STUDIES)
        if not isinstance(self.configs, Mapping):
            raise InvalidInput(f"configs must be a mapping {{study: config}}, got {self.configs!r}")
        for name, c in self.configs.items():
            as_choice(name, "configs", STUDIES)
            if not isinstance(c, REGISTRY[name].Config):
                raise InvalidInput(f"configs[{name!r}] must be a {REGISTRY[name].Config.__name__}, "
                                   f"got {type(c).__name__}")
        configs = {n: self.configs[n] if n in self.configs else s.Config.full()
                   for n, s in REGISTRY.items()}
        object.__setattr__(self, "studies", tuple(self.studies))
        object.__setattr__(self, "configs", configs)

    def __hash__(self):
        return hash((self.seed, self.studies, tuple(self.configs.items())))

    @classmethod
    def preset(cls, name: str = "full", *, seed: int = 7, studies=STUDIES, **settings):
        """The preset ``name`` (``"full"``, ``"quick"``, ``"smoke"``) of every study.

        ``settings`` replace fields per study: ``recovery={"Ls": (1, 3)}`` (or a whole config
        object, ``recovery=RecoveryConfig(...)``).
        """
        as_choice(name, "preset", PRESETS)
        configs = {}
        for key, value in settings.items():
            study = REGISTRY[as_choice(key, "study", STUDIES)]
            if isinstance(value, study.Config):
                configs[key] = value
            elif isinstance(value, Mapping):
                configs[key] = study.Config.preset(name, **value)
            else:
                raise InvalidInput(f"{key} must be a mapping of {key} settings or a "
                                   f"{study.Config.__name__}, got {value!r}")
        for key, study in REGISTRY.items():
            configs.setdefault(key, study.Config.preset(name))
        return cls(seed=seed, studies=studies, configs=configs)

    @classmethod
    def full(cls, **overrides) -> "CostConfig":
        """The full study: a few minutes on 2 cores (see :meth:`preset` for ``overrides``)."""
        return cls.preset("full", **overrides)

    @classmethod
    def quick(cls, **overrides) -> "CostConfig":
        """About a minute on 2 cores: smaller systems, fewer knob values."""
        return cls.preset("quick", **overrides)

    @classmethod
    def smoke(cls, **overrides) -> "CostConfig":
        """A few seconds: for the test suite (tiny systems, every code path)."""
        return cls.preset("smoke", **overrides)

    def to_json(self) -> dict:
        return {"seed": self.seed, "studies": list(self.studies),
                "configs": {n: c.to_json() for n, c in self.configs.items()}}


@dataclass(frozen=True)
class CostResult:
    """Numbers of the cost study (``studies``: one JSON-ready dict per study), headline, machine."""

    config: CostConfig
    studies: dict
    headline: dict
    machine: dict
    wall_time: float
    study_times: dict = field(default_factory=dict)
    stages: dict = field(default_factory=dict)      # {study: "loaded" | "computed"}

    def to_json(self) -> dict:
        return to_jsonable({"config": self.config.to_json(), "machine": self.machine,
                            "wall_time_s": self.wall_time, "study_wall_time_s": self.study_times,
                            "stages": self.stages,
                            "headline": self.headline, **self.studies})


def headline(studies: Mapping, cfg: CostConfig) -> dict:
    """Quotable sentences (and their numbers) from the studies that were run, in report order."""
    if not isinstance(cfg, CostConfig):
        raise InvalidInput(f"cfg must be a CostConfig, got {type(cfg).__name__}")
    if not isinstance(studies, Mapping):
        raise InvalidInput(f"studies must be a mapping {{study: result}}, "
                           f"got {type(studies).__name__}")
    out: dict = {}
    for name, study in REGISTRY.items():
        if studies.get(name):
            out.update(study.headline(studies[name], cfg.configs[name]))
    return out


def run(cfg: CostConfig | None = None, *, out_dir=None, resume: bool = False,
        progress: bool = True) -> CostResult:
    """Run the studies of ``cfg``; with ``out_dir`` write the result folder (:func:`write_outputs`).

    Each study's numbers are written to ``out_dir/stages/<study>.npz`` (a JSON document in
    an ``.npz`` archive, a :class:`kinred.io.StageStore`) as soon as it finishes.

    Parameters
    ----------
    cfg : CostConfig, optional
        Default: the full study (:class:`CostConfig`).
    out_dir : path, optional
    resume : bool
        Load the studies already in ``out_dir/stages`` (with the times measured when they
        ran) and measure only the others; the store must hold a run of the same ``cfg``.
    progress : bool
        tqdm bar on stderr (with time remaining).

    Returns
    -------
    CostResult
    """
    from ...io import StageStore

    cfg = CostConfig() if cfg is None else cfg
    if not isinstance(cfg, CostConfig):
        raise InvalidInput(f"cfg must be a CostConfig, got {type(cfg).__name__}")
    chosen = [(n, s) for n, s in REGISTRY.items() if n in cfg.studies]
    digest = hashlib.sha256(json.dumps(cfg.to_json(), sort_keys=True).encode()).hexdigest()
    stages = StageStore(None if out_dir is None else Path(out_dir) / "stages", digest,
                        resume=resume, describe={"config": cfg.to_json()}, item="study")
    t0 = time.perf_counter()
    studies, times = {}, {}
    with progress_bar(sum(s.n_units(cfg.configs[n]) for n, s in chosen), progress) as bar:
        for name, study in chosen:
            bar.set_postfix_str(name)
            start = bar.n
            doc = _document(stages.get_or_compute(
                name, lambda name=name, study=study: _measure(study, cfg, name, bar),
                load=_load_study))
            studies[name], times[name] = doc["result"], doc["wall_time_s"]
            bar.update(max(0, start + study.n_units(cfg.configs[name]) - bar.n))
    result = CostResult(cfg, studies, headline(studies, cfg), machine_info(),
                        time.perf_counter() - t0, times, dict(stages.status))
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def _measure(study: Study, cfg: CostConfig, name: str, bar) -> dict:
    """Run one study; its numbers as a JSON document in a one-array ``.npz`` stage."""
    ts = time.perf_counter()
    numbers = study.run(cfg.configs[name], seed=cfg.seed, bar=bar)
    doc = {"result": to_jsonable(numbers), "wall_time_s": time.perf_counter() - ts}
    return {"json": np.array(json.dumps(doc))}


def _document(arrays: dict) -> dict:
    """The JSON document of a study stage (ValueError if it is not one)."""
    doc = json.loads(str(arrays["json"]))
    if not isinstance(doc, dict) or not {"result", "wall_time_s"} <= set(doc):
        raise ValueError("no result or wall_time_s")
    return doc


def _load_study(path) -> dict:
    """Read back a study stage written by :func:`_measure` (damaged: DamagedFile)."""
    from ...errors import DamagedFile
    from ...io import read_npz

    arrays = read_npz(path, what="study file", keys=("json",))
    try:
        _document(arrays)
    except ValueError as exc:
        raise DamagedFile(f"{path}: damaged study file: {exc}", path=str(path)) from None
    return arrays
