"""kinred: interacting-agent systems in high dimension, random projections, kinetic limits.

The public API is re-exported here explicitly (nothing else happens on import). The data flow
of the paper (Fornasier, Haškovec, Vybíral) maps onto the packages::

    measure --quantize--> atoms --simulate(scene)--> mu^N(t) --+
       |                     |                                 +--> W1 / errors / bounds
       +--push(M)--> M#mu    +--project(M)--> simulate in R^k --+--> recover (l1)

See ``docs/`` and ``docs/architecture.md``.
"""

from ._version import __version__

from .errors import (
    ConfigError,
    InvalidInput,
    KinredError,
    NotConverged,
    NotProjectable,
    SimulationDiverged,
    TooLarge,
)
from .measures import (
    Atomic,
    Dirac,
    Empirical1D,
    Measure,
    Mixture,
    PushForward,
    TensorProduct,
    Uniform,
    Univariate,
    load_measure,
)
from .quantize import Budget, Quantization, budget, paper_recipe, quantize_1d
from .distance import SlicedW1Result, W1Result, sliced_w1, w1
from .projection import (
    DenseProjection,
    Projection,
    as_projection,
    distortion,
    jl_matrix,
    jl_min_dim,
    trajectory_distortion,
)
from .dynamics import (
    Aggregation,
    Alignment,
    AttractionRepulsion,
    CuckerSmale,
    Drift,
    Effect,
    Field,
    Morse,
    Noise,
    Quadratic,
    Scene,
    SelfPropulsion,
    project_state,
    set_num_threads,
)
from .integrate import METHODS, SaveAt, Trajectory, simulate
from .observables import (above_floor, centre, flocking_verdict, gamma, gamma_floor, lambda_,
                          mean_velocity, relative_error)
from .ensemble import EnsembleResult, grid, run_ensemble
from .io import ResultFolder
# Naming rule (docs/architecture.md): kinred.X for a subpackage or module X is always that
# module; a function is re-exported here only under a name that is no module's, so a
# subpackage's namesake function is reached through it (kinred.quantize.quantize,
# kinred.certify.certify).
from . import certify, kinetic, quantize

__all__ = [
    "__version__",
    # errors
    "KinredError", "InvalidInput", "ConfigError", "SimulationDiverged", "NotConverged",
    "TooLarge", "NotProjectable",
    # measures and quantization
    "Measure", "Univariate", "Uniform", "Dirac", "Empirical1D", "TensorProduct", "Mixture",
    "PushForward", "Atomic", "load_measure",
    "quantize_1d", "budget", "paper_recipe", "Quantization", "Budget",
    # distances
    "w1", "sliced_w1", "W1Result", "SlicedW1Result",
    # projections
    "Projection", "DenseProjection", "as_projection", "jl_matrix", "jl_min_dim", "distortion",
    "trajectory_distortion",
    # dynamics
    "Scene", "Effect", "Alignment", "AttractionRepulsion", "Aggregation", "SelfPropulsion",
    "Noise", "Drift", "Field", "CuckerSmale", "Morse", "Quadratic", "project_state",
    "set_num_threads",
    "simulate", "SaveAt", "Trajectory", "METHODS",
    "gamma", "lambda_", "centre", "mean_velocity", "flocking_verdict", "relative_error",
    "gamma_floor", "above_floor",
    # ensembles and results
    "run_ensemble", "grid", "EnsembleResult", "ResultFolder",
    # subpackages, modules whatever their functions are called (the rule above `from . import`):
    # kinred.quantize.quantize, kinred.certify.certify / Certificate,
    # kinred.kinetic.solve / reduce / compare / theorem_bound
    "quantize",
    "certify",
    "kinetic",
]
