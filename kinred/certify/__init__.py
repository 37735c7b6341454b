"""Certificates for projected dynamics: certified error bounds of a projected Euler run.

:func:`certify` runs a second-order scene with :func:`~kinred.integrate.simulate` (forward
Euler) and its projection by a JL matrix ``M`` alongside, and returns a :class:`Certificate`:
the measured error ``y − Mx`` (weighted RMS and maximum over agents), certified upper bounds
for both (the proofs of Theorems 2.2 and 2.3 applied step by step with measured quantities),
the bound of the middle term of Theorem 4.3, and the paper's own right-hand sides (eq.
(2.11), (2.18)) for comparison. Every number is labelled
(``Certificate.labels``). The per-step machinery is :class:`CertificateObserver`, an observer
of ``simulate`` (``simulate(..., observers=[CertificateObserver(scene, M, x0, v0)])``);
:func:`check_scene` refuses a scene certificates do not cover before any work.

Derivation, the inequalities used and their limits: ``docs/certificates.md``.
"""

from ._certify import LABELS, Certificate, certify, check_scene
from ._observer import CertificateObserver
from ._roundoff import step_allowance

__all__ = ["certify", "Certificate", "CertificateObserver", "LABELS", "step_allowance",
           "check_scene"]
