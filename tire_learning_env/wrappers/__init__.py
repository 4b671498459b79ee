"""Single-purpose Gymnasium wrappers."""

from .estimator import ESTIMATE_OBSERVATION_NAMES, EstimatorWrapper
from .excitation import ExcitationConfig, ExcitationWrapper, TruthRandomization, make_excitation_env  # noqa: F401

__all__ = ["EstimatorWrapper", "ESTIMATE_OBSERVATION_NAMES"]
