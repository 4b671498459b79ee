"""The neuro-adaptive estimator: one core for the lane camera, the IMU and both together.

- :mod:`.model`: the vehicle model and the measurement models (camera, IMU, both);
- :mod:`.basis`: the soft-clip tire-force basis (eq. 30);
- :mod:`.gains`: certified gains from vertex LMIs (one pipeline for every measurement model);
  :mod:`.certificate`: what it returns (the gains and their certificates);
- :mod:`._kernel`: the compiled estimator loop;
- :mod:`.neuro_adaptive`: :class:`NeuroAdaptiveObserver` (``reset``/``predict``/``update``/``run``);
  :mod:`.settings`: its settings; :mod:`.rows`: sensor columns to the kernel's rows;
- :mod:`.calibration`: noise measured from the log; :mod:`.latency`: the camera latency from the log;
  :mod:`.reexpression`: steps of the camera's ``e1`` no motion explains (lane changes), found and removed;
- :mod:`.offline`: prediction-error refinement over a whole log, bands, verdict; :mod:`.longrun`: the
  scores' long-run variance; :mod:`.prior_length`: the smooth-curve prior's length from the log's evidence;
  :mod:`.readout`: the curve and stiffness read-outs of the weights;
- :mod:`.estimator`: :func:`estimate` (all of it in one call); :mod:`.config`: :class:`ObserverConfig`;
  :mod:`.result`: :class:`EstimationResult`;
- :mod:`.warm_start`: the paper's least-squares warm start (SPEC §4).
"""

from .basis import SoftClipBasis, imu_basis, make_basis, paper_basis, two_sided_basis
from .gains import GainDesign, InfeasibleLMIError, ObserverGains, synthesize_gains
from .model import MEASUREMENT_MODELS, MeasurementModel, StateIndex, measurement_model
from .neuro_adaptive import AdaptationParams, HealthParams, NeuroAdaptiveObserver
from .trace import HEALTH_NAMES, EstimateTrace
from .warm_start import least_squares_weights
from .estimator import EstimationResult, ObserverConfig, build_observer, detect_sensors, estimate

__all__ = [
    "SoftClipBasis",
    "make_basis",
    "paper_basis",
    "two_sided_basis",
    "imu_basis",
    "GainDesign",
    "InfeasibleLMIError",
    "ObserverGains",
    "synthesize_gains",
    "MeasurementModel",
    "MEASUREMENT_MODELS",
    "measurement_model",
    "StateIndex",
    "AdaptationParams",
    "HealthParams",
    "NeuroAdaptiveObserver",
    "EstimateTrace",
    "HEALTH_NAMES",
    "least_squares_weights",
    "ObserverConfig",
    "build_observer",
    "detect_sensors",
    "estimate",
    "EstimationResult",
]
