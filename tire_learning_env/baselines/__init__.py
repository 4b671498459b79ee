"""Peer baselines the observer is compared with (they read the sensor log only).

- :mod:`.ukf`: :class:`JointUKF`, a joint state-and-parameter unscented Kalman filter on
  the bicycle model with a Pacejka axle curve (cornering stiffness and peak friction per
  axle in its state).
"""

from .ukf import JointUKF, UKFResult, run_ukf_baseline

__all__ = ["JointUKF", "UKFResult", "run_ukf_baseline"]
