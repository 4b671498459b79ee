"""Discrepancy workflow: where a nominal vehicle model and a driving log disagree, and why.

An engineer brings a driving log (``LOG_FORMAT.md``) and a nominal model (bicycle model +
linear, Pacejka or learned tire); :func:`analyze` compares them without open-loop drift
(multiple-shooting output error, :mod:`.residuals`), locates the disagreement in time and
by regime (:mod:`.diagnostics`), names the missing physical effect from a library of
candidate augmentations (:mod:`.effects`) by fitting each one and selecting greedily with
a likelihood-ratio test and the BIC (:mod:`.selection`), adds it and reports the gap
before and after (:mod:`.report`). The verdict is ``found``, ``ambiguous`` (candidates that fit
equally well, with the manoeuvre that separates them, :mod:`.separation`), ``none`` or
``unexplained`` (:mod:`.workflow`). The steering a sparse log does not show is part of the noise
(:mod:`.noise`). Simulated logs with named hidden effects come from :mod:`tire_learning_env.scenarios`.

>>> from tire_learning_env.discrepancy import EFFECT_NAMES
>>> EFFECT_NAMES[:3]
('tire_relaxation', 'camera_latency', 'road_bank')
"""

from .config import DiscrepancyConfig
from .effects import EFFECT_NAMES, LIBRARY, CandidateEffect, get_effect

__all__ = [
    "DiscrepancyConfig",
    "EFFECT_NAMES",
    "LIBRARY",
    "CandidateEffect",
    "get_effect",
    "TIRE_CHOICES",
    "DiscrepancyResult",
    "analyze",
    "write_report",
]

_LAZY = {"TIRE_CHOICES": "nominal", "DiscrepancyResult": "result", "analyze": "workflow", "write_report": "report"}


def __getattr__(name: str):
    # the workflow (scipy.optimize/stats) and the report (matplotlib) load on first use, so that
    # importing the effect library stays quick
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
