r"""The main job (``kinred demo`` / ``make demo``): the kinetic pipeline end to end.

On built-in defaults: a phase-space measure on ``ℝ²ᵈ`` with ``d = 100`` whose coordinate
widths decay (``σⱼ = 1.6·0.5ʲ`` in positions and velocities) is quantized with the
delayed-curse budget (eq. (4.22)); the weighted Cucker–Smale particle
system gives ``μᴺ(t)``; for ``k ∈ {2, 5, 10, 25}`` a Gaussian JL matrix ``M`` starts the reduced
system from ``M#μ₀ᴺ``; ``W1(M#μᴺ(t), νᴺ(t))`` (exact, POT) is set beside Theorem 4.3's bound
(eq. (4.17), with the proof's constants) and a finer reference
estimates ``W1(μ_M(t), ν(t))``; every reduced run is certified (:mod:`kinred.certify`: a
certified bound of the middle term of eq. (4.17) beside the measured W1); flocking verdicts
are given for every system. It is a
:mod:`kinred.experiments.kinetic_run` scene (:data:`DEMO_SCENE`), so the output folder has the
same layout as ``kinred run``'s.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

from .._validate import as_int
from ..errors import InvalidInput
from .. import scenefile
from . import kinetic_run

__all__ = ["DemoConfig", "DEMO_SCENE", "run", "scene_config"]

#: The built-in scene of the demo (the scene-file format of ``docs/scene-file.md``).
DEMO_SCENE = {
    "title": "kinred demo: projected vs reduced kinetic solutions",
    "description": ("Cucker–Smale alignment (G = 2, β = 0.5) of a quantized phase-space measure "
                    "in d = 100 with decaying widths 1.6·0.5^j."),
    "seed": 0,
    "dynamics": {"d": 100, "effect": [{"type": "alignment", "G": 2.0, "beta": 0.5}]},
    "initial": {
        "positions": {"coordinate": [{"dist": "uniform", "params": {"loc": -0.8, "scale": 1.6},
                                      "repeat": 100, "decay": 0.5}]},
        "velocities": {"coordinate": [{"dist": "uniform", "params": {"loc": -0.8, "scale": 1.6},
                                       "repeat": 100, "decay": 0.5}]},
    },
    "quantize": {"atoms": 400, "reference_atoms": 1200},
    "projection": {"k": [2, 5, 10, 25], "kind": "gaussian", "seed": 2024},
    "integrate": {"method": "euler", "dt": 0.05, "t_final": 20.0, "save_every": 25},
    "output": {"yes_below": 1e-10, "no_above": 1e-3},
    "certify": {"enabled": True},
    "smoke": {"atoms": 24, "reference_atoms": 48, "k": [2, 5], "t_final": 1.0, "dt": 0.1,
              "save_every": 5},
}


@dataclass(frozen=True)
class DemoConfig:
    """Knobs of the demo on top of :data:`DEMO_SCENE` (None keeps the scene's value)."""

    d: int | None = None
    atoms: int | None = None
    ks: tuple | None = None
    t_final: float | None = None
    smoke: bool = False

    def __post_init__(self):
        if self.d is not None:
            as_int(self.d, "d", low=1)
        if self.atoms is not None:
            as_int(self.atoms, "atoms", low=1)
        if self.ks is not None:
            if not self.ks:
                raise InvalidInput("ks must not be empty")
            for k in self.ks:
                as_int(k, "k", low=1)


def scene_config(cfg: DemoConfig | None = None) -> scenefile.Config:
    """The :class:`kinred.scenefile.Config` of the demo with ``cfg``'s overrides applied."""
    cfg = cfg or DemoConfig()
    scene = copy.deepcopy(DEMO_SCENE)
    if cfg.d is not None:
        scene["dynamics"]["d"] = cfg.d
        for part in ("positions", "velocities"):
            scene["initial"][part]["coordinate"][0]["repeat"] = cfg.d
    if cfg.atoms is not None:
        scene["quantize"]["atoms"] = cfg.atoms
        scene["quantize"]["reference_atoms"] = 3 * cfg.atoms
    if cfg.ks is not None:
        scene["projection"]["k"] = [int(k) for k in cfg.ks]
    if cfg.t_final is not None:
        scene["integrate"]["t_final"] = float(cfg.t_final)
    return scenefile.config_from_dict(scene, source="<kinred demo>", smoke=cfg.smoke)


def _clear(out: Path) -> None:
    """Remove the stage files of a previous demo run (only kinred's own names)."""
    st = out / "stages"
    if st.is_dir():
        for p in st.iterdir():
            if p.is_file() and (p.suffix == ".npz" or p.name == "config.json" or p.name.endswith(".tmp")):
                p.unlink()
    s = out / "summary.json"
    if s.is_file():
        s.unlink()


def run(cfg: DemoConfig | None = None, *, out_dir="results/demo", resume: bool = False,
        progress: bool | None = None) -> kinetic_run.RunResult:
    """Run the demo; without ``resume`` a previous demo in ``out_dir`` is replaced."""
    sc = scene_config(cfg)
    out = Path(out_dir)
    if not resume:
        _clear(out)
    return kinetic_run.run(sc, out_dir=out, resume=resume, progress=progress)
