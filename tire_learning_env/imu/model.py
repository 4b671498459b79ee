r"""Body-coordinate bicycle model measured by an IMU (the model of the IMU observer variant).

State ``x = [vy, r]`` (:class:`BodyState`): lateral velocity of the centre of gravity in
the body frame [m/s] and yaw rate [rad/s]. Known inputs per sample: front road-wheel
steering ``delta`` [rad] and the (time-varying, measured) longitudinal speed ``vx`` [m/s].

Slip angles (the body-frame form of SPEC eq. 13)::

    alpha_f = delta - (vy + lf r) / vx,        alpha_r = -(vy - lr r) / vx

Axle forces: nominal linear part plus the neural nonlinear part (SPEC §1-2, eq. 14)::

    F_yf = 2 Cf alpha_f + gamma_f sum_j W_fj sigma_fj(alpha_f)        (rear alike)

Newton in the body frame (rigid body in the plane; exact for a time-varying ``vx``)::

    m (vy_dot + vx r) = F_yf cos(delta) + F_yr
    Iz r_dot          = lf F_yf cos(delta) - lr F_yr

Measurements ``z = [a_y, r]`` (accelerometer at the CG and gyro)::

    a_y = (F_yf cos(delta) + F_yr) / m        <- depends on the tire forces directly

so the lateral acceleration is a *feedthrough* of the learned force: its sensitivity to
the weights has a direct term (``D_w`` below) besides the one through the state.

Linearisation about an estimate, with ``k_f`` / ``k_r`` the *effective* axle slopes
``cos(delta) dF_yf/dalpha`` and ``dF_yr/dalpha`` [N/rad] (:func:`body_matrices`)::

    A = [[-(k_f + k_r)/(m vx),          -(k_f lf - k_r lr)/(m vx) - vx],
         [-(k_f lf - k_r lr)/(Iz vx),   -(k_f lf^2 + k_r lr^2)/(Iz vx)]]
    C = [[-(k_f + k_r)/(m vx),          -(k_f lf - k_r lr)/(m vx)],
         [0,                             1]]
    E = [[1/m, 1/m], [lf/Iz, -lr/Iz]]     (force error -> state derivative)
    D = [[1/m, 1/m], [0, 0]]              (force error -> measurement: the feedthrough)

Every entry of ``A`` and ``C`` is affine in each of ``k_f``, ``k_r``, ``1/vx`` and ``vx``
separately (multi-affine): the property the speed-polytope LMIs of :mod:`.gains` use.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import VehicleParams

__all__ = [
    "BodyState",
    "MEASUREMENTS",
    "slip_angles",
    "body_matrices",
    "body_derivative",
    "lateral_acceleration",
    "V_FLOOR",
]

#: speed below which the model uses ``V_FLOOR`` (slip angles are singular at standstill) [m/s]
V_FLOOR = 3.0
#: measured channels, in the order of ``z``
MEASUREMENTS = ("ay", "yaw_rate")


class BodyState(IntEnum):
    """Indices of the body-coordinate state ``x``."""

    VY = 0  # lateral velocity at the CG [m/s]
    R = 1  # yaw rate [rad/s]


def slip_angles(vy: ArrayLike, r: ArrayLike, delta: ArrayLike, vx: ArrayLike, vehicle: VehicleParams):
    """Front and rear axle slip angles [rad] (body-frame SPEC eq. 13), vectorised.

    ``vx`` is floored at :data:`V_FLOOR`.
    """
    v = np.maximum(np.asarray(vx, dtype=float), V_FLOOR)
    vy = np.asarray(vy, dtype=float)
    r = np.asarray(r, dtype=float)
    alpha_f = np.asarray(delta, dtype=float) - (vy + vehicle.lf * r) / v
    alpha_r = -(vy - vehicle.lr * r) / v
    return alpha_f, alpha_r


def lateral_acceleration(Fyf: ArrayLike, Fyr: ArrayLike, delta: ArrayLike, vehicle: VehicleParams) -> NDArray:
    """``a_y = (F_yf cos(delta) + F_yr) / m`` [m/s^2]."""
    return (np.asarray(Fyf) * np.cos(delta) + np.asarray(Fyr)) / vehicle.m


def body_derivative(x: ArrayLike, Fyf: float, Fyr: float, delta: float, vx: float, vehicle: VehicleParams) -> NDArray:
    """``[vy_dot, r_dot]`` of the body-frame bicycle model for given axle forces [N]."""
    x = np.asarray(x, dtype=float)
    cd = math.cos(delta)
    return np.array(
        [
            (Fyf * cd + Fyr) / vehicle.m - vx * x[BodyState.R],
            (vehicle.lf * Fyf * cd - vehicle.lr * Fyr) / vehicle.Iz,
        ]
    )


def body_matrices(vehicle: VehicleParams, vx: float, k_f: float, k_r: float, inv_vx: float | None = None):
    """Linearised ``(A, C, E, D)`` of the module docstring.

    Parameters
    ----------
    vehicle : VehicleParams
    vx : float
        Longitudinal speed [m/s] (the ``- vx`` kinematic term).
    k_f, k_r : float
        Effective axle slopes [N/rad] (``cos(delta) dF_yf/dalpha`` and ``dF_yr/dalpha``).
    inv_vx : float, optional
        Value used for ``1/vx`` (default ``1/vx``). Passing it separately evaluates the
        multi-affine matrices at the vertices of a ``(1/vx, vx)`` box (:mod:`.gains`).

    Returns
    -------
    A : (2, 2) [1/s], C : (2, 2), E : (2, 2), D : (2, 2)
    """
    m, Iz, lf, lr = vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr
    s = 1.0 / vx if inv_vx is None else inv_vx
    a11 = -(k_f + k_r) * s / m
    a12 = -(k_f * lf - k_r * lr) * s / m
    A = np.array([[a11, a12 - vx], [-(k_f * lf - k_r * lr) * s / Iz, -(k_f * lf**2 + k_r * lr**2) * s / Iz]])
    C = np.array([[a11, a12], [0.0, 1.0]])
    E = np.array([[1.0 / m, 1.0 / m], [lf / Iz, -lr / Iz]])
    D = np.array([[1.0 / m, 1.0 / m], [0.0, 0.0]])
    return A, C, E, D
