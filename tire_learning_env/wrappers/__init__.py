"""Single-purpose Gymnasium wrappers."""

from .estimator import ESTIMATE_OBSERVATION_NAMES, EstimatorWrapper

__all__ = ["EstimatorWrapper", "ESTIMATE_OBSERVATION_NAMES"]
