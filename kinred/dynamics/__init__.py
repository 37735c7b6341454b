"""Dynamics: effects, kernels and scenes (the vector fields of the paper's models).

See docs/dynamics.md for the model, the effects and the normalization conventions.
"""

from .._parallel import get_num_threads, set_num_threads
from .effects import (
    Aggregation,
    Alignment,
    AttractionRepulsion,
    Drift,
    Effect,
    Field,
    Noise,
    PairwiseEffect,
    SelfPropulsion,
)
from .kernels import CuckerSmale, Kernel, Morse, Quadratic
from .scene import ProjectedSystem, Scene, project_state

__all__ = [
    "Scene",
    "ProjectedSystem",
    "project_state",
    "Effect",
    "PairwiseEffect",
    "Alignment",
    "AttractionRepulsion",
    "Aggregation",
    "SelfPropulsion",
    "Noise",
    "Drift",
    "Field",
    "Kernel",
    "CuckerSmale",
    "Morse",
    "Quadratic",
    "set_num_threads",
    "get_num_threads",
]
