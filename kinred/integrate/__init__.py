"""Integrators as objects (Diffrax style): solvers, step-size controllers, the save grid,
per-step observers, and ``simulate``, the short loop that joins them.

* solvers (:class:`Solver`: ``init``/``step``): :class:`ExplicitRK` from a Butcher table
  (:data:`EULER`, :data:`HEUN`, :data:`RK4`, :data:`DOPRI5`, :data:`BS32`),
  :class:`EulerMaruyama` for noise;
* controllers: :class:`ConstantStep`, :class:`AdaptiveStep` (tolerances, step floor, step
  budget, stiffness test);
* :class:`SaveAt`: what to record and when (:func:`save_grid` its points on a run,
  :func:`save_points` and :func:`check_save_size` the preflight of what it records, for
  runners that call ``simulate``); observers (:class:`Observer`) see every accepted
  step as a :class:`StepState`;
* the registry :data:`SOLVERS` (name → :class:`SolverSpec`), read by ``simulate``, the
  scene-file loader and the cost study; :func:`register_solver` adds an integrator;
  :data:`ALIASES` and :func:`method_name`: other names (``"RK45"``, ``"dopri5"``, ``"bs23"``).
"""

from ._controllers import AdaptiveStep, ConstantStep
from ._observers import Observer, StepState, working_frame
from ._registry import (ALIASES, METHODS, SOLVERS, SolverSpec, method_name, register_solver,
                        unregister_solver)
from ._save import SaveAt, SaveGrid, check_save_size, save_grid, save_points
from ._simulate import Trajectory, simulate
from ._solvers import EulerMaruyama, ExplicitRK, Solver, VectorField
from ._tables import BS32, DOPRI5, EULER, HEUN, RK4, TABLES, RKTable

__all__ = ["simulate", "SaveAt", "SaveGrid", "save_grid", "save_points", "check_save_size", "Trajectory", "METHODS", "SOLVERS", "ALIASES", "SolverSpec",
           "method_name", "register_solver", "unregister_solver", "Solver", "ExplicitRK", "EulerMaruyama",
           "VectorField", "ConstantStep", "AdaptiveStep", "Observer", "StepState", "working_frame", "RKTable",
           "EULER", "HEUN", "RK4", "DOPRI5", "BS32", "TABLES"]
