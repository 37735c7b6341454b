"""The studies of ``kinred cost``, in report order.

Adding a knob: write its module (a :class:`~._base.Study` subclass and ``STUDY``; copy
``w1.py``, the shortest) and add one line below.
"""

from __future__ import annotations

from . import integrators, projection, quantization, recovery, w1
from ._base import registry

#: ``{name: study}``, read-only, in report order.
REGISTRY = registry(
    projection.STUDY,
    recovery.STUDY,
    quantization.STUDY,
    integrators.STUDY,
    w1.STUDY,
)
