"""Peer baselines the observer is compared with (they read the sensor log only).

- :mod:`.ukf`: :class:`JointUKF`, a joint state-and-parameter unscented Kalman filter on
  the bicycle model with a Pacejka axle curve (cornering stiffness and peak friction per
  axle in its state).
- :mod:`.kalman`: :class:`LinearKalmanFilter`, the linear Kalman filter of the Revs data's
  source paper (states sideslip and yaw rate, measurements ``a_y`` and yaw rate, fixed
  linear tires), with the observer's verbs ``reset``/``predict``/``update``/``run``.
"""

from .kalman import LinearKalmanFilter
from .ukf import JointUKF, UKFResult, run_ukf_baseline

__all__ = ["JointUKF", "UKFResult", "run_ukf_baseline", "LinearKalmanFilter"]
