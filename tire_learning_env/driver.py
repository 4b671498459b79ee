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

from ._kernels import driver_steer
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
        self.state = np.zeros(1)

    def reset(self) -> None:
        """Zero the integral state."""
        self.state[0] = 0.0

    def steer(self, e1: float, e2: float, kappa: float, vx: float, dt: float) -> float:
        """Road-wheel angle [rad] from measured ``e1`` [m], ``e2`` [rad] and curvature [1/m].

        ``dt`` [s] is the time since the previous call (integral update). NaN
        measurements (no frame yet) give pure feed-forward.
        """
        return driver_steer(e1, e2, kappa, vx, dt, self.param_vec, self.state)

    @property
    def integral(self) -> float:
        return float(self.state[0])
