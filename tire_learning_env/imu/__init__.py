"""IMU measurement variant of the neuro-adaptive observer (yaw rate and lateral acceleration).

- :mod:`.model`: body-coordinate bicycle model ``[vy, r]``, ``a_y`` as a force feedthrough.
- :mod:`.gains`: speed-scheduled gains from vertex LMIs over a speed polytope, common
  Lyapunov matrix, numpy certificate, disk cache.
- :mod:`.observer`: the compiled observer (sensitivity-RLS weights, direct ``a_y`` term).
- :mod:`.kalman`: the source paper's linear Kalman filter (peer baseline).
- :mod:`.logs`: checks and causal cleaning of real IMU logs, reported.
- :mod:`.scoring`: sideslip RMSE and measured tire curves from a reference sensor.
- :mod:`.estimate`: :func:`estimate_imu` and :func:`estimate_imu_log` (the ``estimate`` command).
- :mod:`.simulate`: simulated IMU drives (Pacejka truth, varying speed) for tests.
"""

from .estimate import ESTIMATE_COLUMNS, ImuConfig, ImuResult, build_imu_observer, estimate_imu, estimate_imu_log, imu_basis
from .gains import ImuGains, InfeasibleLMIError, synthesize_imu_gains
from .kalman import LinearKalmanBaseline
from .logs import CleaningReport, clean_imu_log, read_imu_log
from .model import BodyState
from .observer import ImuObserver, ImuTrace
from .simulate import simulate_imu_drive

__all__ = [
    "ESTIMATE_COLUMNS",
    "ImuConfig",
    "ImuResult",
    "build_imu_observer",
    "estimate_imu",
    "estimate_imu_log",
    "imu_basis",
    "ImuGains",
    "InfeasibleLMIError",
    "synthesize_imu_gains",
    "LinearKalmanBaseline",
    "CleaningReport",
    "clean_imu_log",
    "read_imu_log",
    "BodyState",
    "ImuObserver",
    "ImuTrace",
    "simulate_imu_drive",
]
