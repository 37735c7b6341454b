"""The configuration and the result of ``kinred cost`` (:mod:`kinred.experiments.cost`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ..._repr import result_repr
from ..._validate import as_choice, as_int
from ...errors import InvalidInput
from ...io import to_jsonable
from ._base import PRESETS
from ._registry import REGISTRY

#: Names of the studies of :func:`kinred.experiments.cost.run`, in report order.
STUDIES = tuple(REGISTRY)


@dataclass(frozen=True)
class CostConfig:
    """The master seed, the studies to run and one config per study (default: the full run).

    Use :meth:`quick` (about 20 s on 2 cores) or :meth:`smoke` (seconds, for tests).

    Parameters
    ----------
    seed : int
        Master seed (non-negative); each study draws its own streams from it.
    studies : tuple of str
        The studies to run, of ``kinred.experiments.cost.STUDIES`` (run and reported in that order).
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

    __repr__ = result_repr  # shapes and headline numbers, never whole arrays

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
