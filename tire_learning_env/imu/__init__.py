"""IMU-only logs (yaw rate and lateral acceleration, no lane camera) on the unified estimator core.

The estimator itself is :mod:`tire_learning_env.observer` with ``sensors="imu"``; this
package is the IMU *log layer*:

- :mod:`.logs`: checks and causal cleaning of real IMU logs, reported.
- :mod:`.estimate`: :func:`estimate_imu` (noise, observer, linear KF, blend);
- :mod:`.outputs`: :func:`estimate_imu_log` (the ``estimate`` command: cleaning, scores and files).
- :mod:`.baseline`: the linear KF on a log's IMU rows, as the IMU-only and the fused paths run it.
- :mod:`.fused`: that KF and the reference sideslip scores beside a fused (camera and IMU) estimate.
- :mod:`.blend`: interacting-multiple-model weighting of the observer and the linear KF by
  their innovations (never worse than the KF where the prediction errors tell them apart).
- :mod:`.scoring`: sideslip RMSE and measured tire curves from a reference sensor.
- :mod:`.simulate`: simulated IMU drives (Pacejka truth, varying speed, white noise, band-limited
  ``a_y`` vibration, sensor offsets) for tests and the generalisation benchmark's IMU families.
- :mod:`.plots`: figures of the ``estimate`` command.

The linear Kalman filter lives in :mod:`tire_learning_env.baselines.kalman` (re-exported here).
"""

from ..baselines.kalman import LinearKalmanBaseline, LinearKalmanFilter
from .blend import Blend, BlendParams, blend_traces, causal_fallback_rows, file_not_contradicted, mode_probabilities
from .estimate import ESTIMATE_COLUMNS, ImuEstimate, estimate_imu, imu_config, imu_noise_std
from .logs import CleaningReport, clean_imu_log, read_imu_log
from .outputs import estimate_imu_log
from .simulate import simulate_imu_drive

__all__ = [
    "ESTIMATE_COLUMNS",
    "ImuEstimate",
    "estimate_imu",
    "estimate_imu_log",
    "imu_config",
    "imu_noise_std",
    "Blend",
    "BlendParams",
    "blend_traces",
    "file_not_contradicted",
    "causal_fallback_rows",
    "mode_probabilities",
    "LinearKalmanFilter",
    "LinearKalmanBaseline",
    "CleaningReport",
    "clean_imu_log",
    "read_imu_log",
    "simulate_imu_drive",
]
