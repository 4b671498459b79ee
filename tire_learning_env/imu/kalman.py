r"""Peer baseline: the linear Kalman filter of the data's source paper (Leanza, Reina, Blanco-Claraco 2021).

Implemented from its description: linear bicycle model, states sideslip ``beta`` [rad]
and yaw rate ``r`` [rad/s], measurements lateral acceleration and yaw rate, *axle*
cornering stiffness ``C_f``, ``C_r`` (70,000 / 120,000 N/rad for the Ferrari 250 LM),
forward-Euler discretisation with the measured (time-varying) speed::

    beta_dot = -(C_f + C_r)/(m vx) beta - (1 + (lf C_f - lr C_r)/(m vx^2)) r + C_f/(m vx) delta
    r_dot    = -(lf C_f - lr C_r)/Iz beta - (lf^2 C_f + lr^2 C_r)/(Iz vx) r + lf C_f/Iz delta
    a_y      = -(C_f + C_r)/m beta - (lf C_f - lr C_r)/(m vx) r + C_f/m delta

Process noise enters through the steering input (``Q_d = B_d B_d^T sigma_delta^2``: model
error expressed as an equivalent steering error), measurement noise
``R = diag(sigma_ay^2, sigma_r^2)``; initial state 0, initial covariance ``1e4 I``
(as the source). Predict with the inputs of the previous row, correct with the current
row's measurement (with the direct ``C_f/m delta`` term). Causal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..params import ParameterError, VehicleParams

__all__ = ["LinearKalmanBaseline", "KalmanTrace"]


@dataclass
class KalmanTrace:
    """``t`` (n,), ``beta`` (n,) [rad], ``yaw_rate`` (n,) [rad/s] estimates."""

    t: NDArray
    beta: NDArray
    yaw_rate: NDArray


@njit(cache=True)
def _kf_kernel(t, delta, vx, ay, yr, m, Iz, lf, lr, cf, cr, q, r_ay, r_r, p0, out):
    n = t.shape[0]
    x0 = 0.0
    x1 = 0.0
    p00 = p0
    p01 = 0.0
    p11 = p0
    out[0, 0] = x0
    out[0, 1] = x1
    for i in range(1, n):
        dt = t[i] - t[i - 1]
        v = vx[i - 1] if vx[i - 1] > 1.0 else 1.0
        a00 = 1.0 - dt * (cf + cr) / (m * v)
        a01 = -dt * (1.0 + (lf * cf - lr * cr) / (m * v * v))
        a10 = -dt * (lf * cf - lr * cr) / Iz
        a11 = 1.0 - dt * (lf * lf * cf + lr * lr * cr) / (Iz * v)
        b0 = dt * cf / (m * v)
        b1 = dt * lf * cf / Iz
        # predict
        n0 = a00 * x0 + a01 * x1 + b0 * delta[i - 1]
        n1 = a10 * x0 + a11 * x1 + b1 * delta[i - 1]
        x0, x1 = n0, n1
        t00 = a00 * p00 + a01 * p01
        t01 = a00 * p01 + a01 * p11
        t10 = a10 * p00 + a11 * p01
        t11 = a10 * p01 + a11 * p11
        p00 = t00 * a00 + t01 * a01 + q * b0 * b0
        p01 = t00 * a10 + t01 * a11 + q * b0 * b1
        p11 = t10 * a10 + t11 * a11 + q * b1 * b1
        if ay[i] == ay[i] and yr[i] == yr[i]:
            vi = vx[i] if vx[i] > 1.0 else 1.0
            c00 = -(cf + cr) / m
            c01 = -(lf * cf - lr * cr) / (m * vi)
            # S = C P C^T + R, C = [[c00, c01], [0, 1]]
            cp00 = c00 * p00 + c01 * p01
            cp01 = c00 * p01 + c01 * p11
            s00 = cp00 * c00 + cp01 * c01 + r_ay
            s01 = cp01
            s11 = p11 + r_r
            det = s00 * s11 - s01 * s01
            i00 = s11 / det
            i01 = -s01 / det
            i11 = s00 / det
            # P C^T = [[cp00, p01], [cp01, p11]]^T rows: column j of C^T
            pc00 = cp00
            pc01 = p01
            pc10 = cp01
            pc11 = p11
            k00 = pc00 * i00 + pc01 * i01
            k01 = pc00 * i01 + pc01 * i11
            k10 = pc10 * i00 + pc11 * i01
            k11 = pc10 * i01 + pc11 * i11
            y0 = ay[i] - (c00 * x0 + c01 * x1 + cf / m * delta[i])
            y1 = yr[i] - x1
            x0 += k00 * y0 + k01 * y1
            x1 += k10 * y0 + k11 * y1
            # P = (I - K C) P
            m00 = 1.0 - k00 * c00
            m01 = -k00 * c01 - k01
            m10 = -k10 * c00
            m11 = 1.0 - k10 * c01 - k11
            n00 = m00 * p00 + m01 * p01
            n01 = m00 * p01 + m01 * p11
            n11 = m10 * p01 + m11 * p11
            p00, p01, p11 = n00, n01, n11
        out[i, 0] = x0
        out[i, 1] = x1


class LinearKalmanBaseline:
    """The source paper's linear Kalman filter (module docstring).

    Parameters
    ----------
    vehicle : VehicleParams
        ``m, Iz, lf, lr``; the axle stiffness defaults to ``2 Cf``, ``2 Cr`` of the vehicle
        (70,000 / 120,000 N/rad for ``revs_250lm_vehicle.json``).
    axle_stiffness : (float, float), optional
        Override ``(C_f, C_r)`` per axle [N/rad].
    steer_noise : float
        Process noise as an equivalent steering error std [rad] (0.01 rad is about a
        700 N front-axle force error at 70,000 N/rad).
    noise_std : (float, float)
        Measurement noise std ``(a_y [m/s^2], r [rad/s])`` (the same IMU noise the
        observer assumes).
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        axle_stiffness: tuple[float, float] | None = None,
        steer_noise: float = 0.01,
        noise_std: tuple[float, float] = (1.0, 0.005),
        initial_var: float = 1e4,
    ) -> None:
        cf, cr = axle_stiffness if axle_stiffness is not None else (2.0 * vehicle.Cf, 2.0 * vehicle.Cr)
        if not (cf > 0 and cr > 0 and steer_noise > 0 and initial_var > 0 and min(noise_std) > 0):
            raise ParameterError("axle stiffness, steer_noise, noise_std and initial_var must be > 0")
        self.vehicle = vehicle
        self.axle_stiffness = (float(cf), float(cr))
        self.steer_noise = float(steer_noise)
        self.noise_std = (float(noise_std[0]), float(noise_std[1]))
        self.initial_var = float(initial_var)

    def run(self, sensors: dict[str, NDArray]) -> KalmanTrace:
        """Filter rows ``t, delta, vx, ay, yaw_rate`` (no ``true_*``)."""
        leaked = [k for k in sensors if str(k).startswith("true")]
        if leaked:
            raise ValueError(f"the baseline must not see ground truth; got columns {leaked}")
        t = np.ascontiguousarray(sensors["t"], dtype=float)
        cols = [np.ascontiguousarray(sensors[k], dtype=float) for k in ("delta", "vx", "ay", "yaw_rate")]
        out = np.zeros((len(t), 2))
        v = self.vehicle
        if len(t):
            _kf_kernel(
                t, *cols, v.m, v.Iz, v.lf, v.lr, *self.axle_stiffness, self.steer_noise**2,
                self.noise_std[0] ** 2, self.noise_std[1] ** 2, self.initial_var, out,
            )  # fmt: skip
        return KalmanTrace(t, out[:, 0], out[:, 1])

    def settings(self) -> dict:
        return {
            "axle_stiffness_N_per_rad": list(self.axle_stiffness),
            "steer_noise_rad": self.steer_noise,
            "noise_std": list(self.noise_std),
            "initial_var": self.initial_var,
            "discretisation": "forward Euler, speed of the previous row",
        }
