"""Neuro-adaptive observer: basis, certified gains, observer, warm start, tire curves."""

from .basis import SoftClipBasis, make_basis, paper_basis, two_sided_basis
from .gains import InfeasibleLMIError, ObserverGains, discretize, synthesize_gains
from .neuro_adaptive import AdaptationParams, NeuroAdaptiveObserver, ObserverTrace
from .warm_start import least_squares_weights
from .estimator import EstimationResult, ObserverConfig, build_observer, estimate

__all__ = [
    "SoftClipBasis",
    "make_basis",
    "paper_basis",
    "two_sided_basis",
    "InfeasibleLMIError",
    "ObserverGains",
    "discretize",
    "synthesize_gains",
    "AdaptationParams",
    "NeuroAdaptiveObserver",
    "ObserverTrace",
    "least_squares_weights",
    "ObserverConfig",
    "build_observer",
    "estimate",
    "EstimationResult",
]
