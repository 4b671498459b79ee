"""Built-in lane-keeping steering controller.

``delta = g_ff(vx) kappa - k (e1 + vx T_la e2) - k_i integral(e1)``

It feeds back the *measured* camera ``e1``, ``e2`` (the latest delivered frame, held
between frames) and feeds forward the path curvature with the steady-state steering of
the nominal linear bicycle model, so a circle is followed with zero offset:

``g_ff = L + K_us vx^2 + k vx T_la e2_ss/kappa``, ``e2_ss/kappa = -lr + lf m vx^2 / (2 Cr L)``
(Rajamani, *Vehicle Dynamics and Control*, Sec. 3.2). The law itself is the compiled
:func:`~tire_learning_env._kernels.driver_steer`.
"""

from __future__ import annotations

import numpy as np

from ._kernels import (
    DS_INTEGRAL,
    GUARD_AY,
    GUARD_GAIN_HIGH,
    GUARD_GAIN_LOW,
    GUARD_LIMIT,
    N_DRIVER_STATE,
    N_GUARD,
    driver_steer,
)
from .params import DriverParams, VehicleParams

__all__ = ["LaneKeepingDriver", "driver_vector"]


def driver_vector(params: DriverParams, vehicle: VehicleParams) -> np.ndarray:
    """Gains and nominal vehicle as the compiled kernel's vector (``_kernels.DRV_*`` layout)."""
    L = vehicle.wheelbase
    return np.array(
        [
            params.gain,
            params.lookahead_time,
            params.integral_gain,
            params.max_steering,
            L,
            vehicle.understeer_gradient,
            vehicle.lr,
            vehicle.lf * vehicle.m / (2.0 * vehicle.Cr * L),
        ]
    )


class LaneKeepingDriver:
    """Stateful lane-keeping controller (the integral of ``e1`` is its state).

    Parameters
    ----------
    params : DriverParams
        Gains and steering limit.
    vehicle : VehicleParams
        Nominal vehicle used for the feed-forward.
    """

    def __init__(self, params: DriverParams, vehicle: VehicleParams) -> None:
        self.params = params
        self.vehicle = vehicle
        self.param_vec = driver_vector(params, vehicle)
        self.state = np.zeros(N_DRIVER_STATE)
        self.guard = np.zeros(N_GUARD)
        self.guard[GUARD_LIMIT] = np.inf

    def reset(self) -> None:
        """Zero the integral state and the a_y guard's last IMU reading."""
        self.state[DS_INTEGRAL] = 0.0
        self.guard[GUARD_AY] = 0.0

    def set_ay_guard(self, limit: float, gain_low: float, gain_high: float) -> None:
        """Turn on the steering a_y guard (:func:`~tire_learning_env._kernels.guard_steering`).

        Every physics tick, the change of the total steering (driver plus offset) is
        clamped so that the last IMU ``a_y`` plus the change times any steering-to-``a_y``
        gain in ``[gain_low, gain_high]`` stays within ``+/-limit`` (an ``a_y`` beyond
        the limit is steered back). It clamps the total steering, the driver's included:
        the limit is hard, also on a curve that would need more. ``limit = inf`` turns it
        off.

        Parameters
        ----------
        limit : float
            Lateral-acceleration limit [m/s^2].
        gain_low, gain_high : float
            Bounds of the instantaneous steering-to-``a_y`` gain ``2 C_f / m`` [m/s^2/rad].
        """
        if not limit > 0:
            raise ValueError(f"guard limit must be > 0, got {limit!r}")
        if not 0 < gain_low <= gain_high < np.inf:
            raise ValueError(f"need 0 < gain_low <= gain_high < inf, got {gain_low!r}, {gain_high!r}")
        self.guard[GUARD_LIMIT] = limit
        self.guard[GUARD_GAIN_LOW] = gain_low
        self.guard[GUARD_GAIN_HIGH] = gain_high

    def kernel_args(self) -> tuple:
        """``(gains, integral state, a_y guard)`` for the compiled loop (updated in place there)."""
        return self.param_vec, self.state, self.guard

    def steer(self, e1: float, e2: float, kappa: float, vx: float, dt: float) -> float:
        """Road-wheel angle [rad] from measured ``e1`` [m], ``e2`` [rad] and curvature [1/m].

        ``dt`` [s] is the time since the previous call (integral update). NaN
        measurements (no frame yet) give pure feed-forward.
        """
        return driver_steer(e1, e2, kappa, vx, dt, self.param_vec, self.state)

    @property
    def integral(self) -> float:
        return float(self.state[DS_INTEGRAL])
