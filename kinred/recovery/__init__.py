"""Batched ℓ1 recovery of high-dimensional vectors from stacked projections (§3.3.1 of the paper).

* :func:`basis_pursuit` / :func:`lasso` — many problems (3.16) sharing one
  matrix, solved by batched ADMM with a certified polish; :class:`RecoveryResult`.
* :func:`estimate_eta` — the automatic noise level (cross-validation over the L blocks).
* :func:`recover` — x♯ᵢ(t) from L projected simulations (3.17), with the §3.4.2 error.
* ``kinred.recovery._reference`` — exact slow references (HiGHS LP, Clarabel SOCP) for tests.
"""

from ._eta import EtaEstimate, estimate_eta
from ._recover import TrajectoryRecovery, recover, relative_error
from ._solver import STATUSES, RecoveryResult, basis_pursuit, lasso, stack_projections

__all__ = [
    "RecoveryResult",
    "STATUSES",
    "basis_pursuit",
    "lasso",
    "stack_projections",
    "EtaEstimate",
    "estimate_eta",
    "TrajectoryRecovery",
    "recover",
    "relative_error",
]
