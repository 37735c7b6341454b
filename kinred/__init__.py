"""kinred: interacting-agent systems in high dimension, random projections, kinetic limits.

The public API is re-exported here explicitly; see ``docs/`` for the tour.
"""

__version__ = "0.1.0"

from .errors import (
    ConfigError,
    InvalidInput,
    KinredError,
    NotConverged,
    NotProjectable,
    SimulationDiverged,
    TooLarge,
)

__all__ = [
    "__version__",
    "KinredError",
    "InvalidInput",
    "ConfigError",
    "SimulationDiverged",
    "NotConverged",
    "TooLarge",
    "NotProjectable",
]
