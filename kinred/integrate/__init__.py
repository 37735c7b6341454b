"""Integrators: explicit RK tables, adaptive embedded pairs, Euler–Maruyama, ``simulate``."""

from ._simulate import METHODS, SaveAt, Trajectory, simulate
from ._tables import BS32, DOPRI5, EULER, HEUN, RK4, TABLES, RKTable

__all__ = ["simulate", "SaveAt", "Trajectory", "METHODS", "RKTable", "EULER", "HEUN", "RK4",
           "DOPRI5", "BS32", "TABLES"]
