r"""The estimator's vehicle model and its measurement models (one of each, for every sensor set).

State ``x = [vy, r, e1, e2]`` (:class:`StateIndex`): lateral velocity of the centre of gravity
in the body frame [m/s], yaw rate [rad/s], lateral offset [m] and heading error [rad] to the
path. The error state of SPEC §1 is a change of coordinates of it
(:func:`to_error_state`)::

    e1_dot = vy + vx e2,        e2_dot = r - psi_dot_des,        psi_dot_des = vx kappa

Dynamics (SPEC §1-2 in body coordinates; the compiled version is
:mod:`._kernel`)::

    alpha_f = delta - (vy + lf r)/vx,          alpha_r = -(vy - lr r)/vx                (eq. 13)
    vy_dot  = (F_f cos(delta) + F_r)/m - vx r,  r_dot = (lf F_f cos(delta) - lr F_r)/Iz
    F_i     = 2 C_i alpha_i + f_i(alpha_i),    f_i = gamma_i sum_j W_ij sigma_ij     (eqs. 14, 29)

A *measurement model* (:class:`MeasurementModel`) says which sensors the estimator reads:

- ``camera``: lane camera ``[e1, e2]`` (SPEC's ``z = C xi``), 4 states;
- ``imu``: ``[a_y, r]`` with ``a_y = (F_f cos(delta) + F_r)/m`` (the learned force seen
  directly), 2 states (no path needed: IMU-only logs have no ``kappa``);
- ``both``: camera and IMU fused, 4 states.

It supplies the linearised matrices the gain synthesis needs (:func:`linear_matrices`,
:meth:`MeasurementModel.output_matrices`); everything else (gains, calibration, bands,
health, offline refinement) is common.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import ParameterError, VehicleParams

__all__ = [
    "check_sensor_columns",
    "StateIndex",
    "STATE_NAMES",
    "MeasurementModel",
    "MEASUREMENT_MODELS",
    "measurement_model",
    "linear_matrices",
    "slip_jacobian",
    "to_error_state",
    "from_error_state",
    "camera_path_bend",
]


class StateIndex(IntEnum):
    """Components of the estimator state ``x`` (body states first)."""

    VY = 0  # lateral velocity at the CG [m/s]
    R = 1  # yaw rate [rad/s]
    E1 = 2  # lateral offset from the path [m]
    E2 = 3  # heading error to the path [rad]


STATE_NAMES = ("vy", "yaw_rate", "e1", "e2")
ERROR_STATE_NAMES = ("e1", "e1_dot", "e2", "e2_dot")


@dataclass(frozen=True)
class MeasurementModel:
    """Which sensors the estimator reads (the strategy handed to the estimator core).

    Attributes
    ----------
    name : {"camera", "imu", "both"}
    uses_camera, uses_imu : bool
    nx : int
        State dimension (4 with a camera, 2 for IMU only).
    columns : tuple of str
        Log columns read (besides ``t, delta, vx``).
    """

    name: str
    uses_camera: bool
    uses_imu: bool

    @property
    def nx(self) -> int:
        return 4 if self.uses_camera else 2

    @property
    def columns(self) -> tuple[str, ...]:
        cols: tuple[str, ...] = ()
        if self.uses_camera:
            cols += ("kappa", "e1", "e2")
        if self.uses_imu:
            cols += ("ay", "yaw_rate")
        return cols

    @property
    def state_names(self) -> tuple[str, ...]:
        return STATE_NAMES[: self.nx]

    def camera_output(self, camera_x: float = 0.0) -> NDArray:
        """``C`` (2, nx) of the camera channels ``[e1, e2]`` linearised at ``e2 = 0``: ``e1`` measured
        ``camera_x`` [m] ahead of the CG is ``e1 + camera_x sin(e2)`` (:attr:`.VehicleParams.camera_x`)."""
        C = np.zeros((2, self.nx))
        C[0, StateIndex.E1] = 1.0
        C[0, StateIndex.E2] = float(camera_x)
        C[1, StateIndex.E2] = 1.0
        return C

    def imu_output(self, vehicle: VehicleParams, vx: float, k_f: float, k_r: float) -> tuple[NDArray, NDArray]:
        """``(C, D)`` of the IMU channels ``[a_y, r]`` linearised at total axle slopes ``k_f``, ``k_r``
        [N/rad] (front including ``cos(delta)``): ``a_y`` error ``= C e + D d`` with ``d`` the
        axle force error [N]."""
        m, lf, lr = vehicle.m, vehicle.lf, vehicle.lr
        C = np.zeros((2, self.nx))
        C[0, StateIndex.VY] = -(k_f + k_r) / (m * vx)
        C[0, StateIndex.R] = -(k_f * lf - k_r * lr) / (m * vx)
        C[1, StateIndex.R] = 1.0
        D = np.array([[1.0 / m, 1.0 / m], [0.0, 0.0]])
        return C, D


MEASUREMENT_MODELS = {
    "camera": MeasurementModel("camera", True, False),
    "imu": MeasurementModel("imu", False, True),
    "both": MeasurementModel("both", True, True),
}


def measurement_model(name: str | MeasurementModel) -> MeasurementModel:
    """The model by name (``camera``, ``imu``, ``both``) or the model itself."""
    if isinstance(name, MeasurementModel):
        return name
    try:
        return MEASUREMENT_MODELS[name]
    except KeyError:
        raise ParameterError(f"unknown sensor set {name!r}; choose one of {sorted(MEASUREMENT_MODELS)}") from None


def linear_matrices(vehicle: VehicleParams, vx: float, k_f: float, k_r: float, nx: int = 4) -> tuple[NDArray, NDArray]:
    """``(A, F)``: ``x_dot = A x + F d`` linearised at total axle slopes ``k_f``, ``k_r`` [N/rad].

    ``d`` is an axle force error [N] (front, rear). ``k_f`` includes ``cos(delta)``.
    """
    m, Iz, lf, lr = vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr
    A = np.zeros((nx, nx))
    A[0, 0] = -(k_f + k_r) / (m * vx)
    A[0, 1] = -(k_f * lf - k_r * lr) / (m * vx) - vx
    A[1, 0] = -(k_f * lf - k_r * lr) / (Iz * vx)
    A[1, 1] = -(k_f * lf**2 + k_r * lr**2) / (Iz * vx)
    if nx == 4:
        A[StateIndex.E1, StateIndex.VY] = 1.0
        A[StateIndex.E1, StateIndex.E2] = vx
        A[StateIndex.E2, StateIndex.R] = 1.0
    F = np.zeros((nx, 2))
    F[0] = 1.0 / m
    F[1] = (lf / Iz, -lr / Iz)
    return A, F


def camera_path_bend(kappa: ArrayLike, camera_x: float) -> NDArray:
    """``kappa camera_x^2 / 2`` [m]: how far the path bends away from its tangent over ``camera_x``.

    A lane camera ``camera_x`` [m] ahead of the CG (:attr:`.VehicleParams.camera_x`) sees
    ``e1 + camera_x sin(e2) - kappa camera_x^2 / 2``. The estimators measure the first two terms
    and add this one back onto the logged ``e1`` (``kappa`` is known; NaN curvature counts as 0).
    """
    return 0.5 * np.nan_to_num(np.asarray(kappa, dtype=float)) * (camera_x * camera_x)


def slip_jacobian(vehicle: VehicleParams, vx: float, nx: int = 4) -> NDArray:
    """``d[alpha_f, alpha_r]/dx`` (2, nx) (eq. 13)."""
    H = np.zeros((2, nx))
    H[0, :2] = (-1.0 / vx, -vehicle.lf / vx)
    H[1, :2] = (-1.0 / vx, vehicle.lr / vx)
    return H


def to_error_state(x: ArrayLike, vx: ArrayLike, kappa: ArrayLike) -> NDArray:
    """``[e1, e1_dot, e2, e2_dot]`` (SPEC §1) from ``[vy, r, e1, e2]``, shape (..., 4)."""
    x = np.asarray(x, dtype=float)
    vx = np.asarray(vx, dtype=float)
    xi = np.empty_like(x)
    xi[..., 0] = x[..., StateIndex.E1]
    xi[..., 1] = x[..., StateIndex.VY] + vx * x[..., StateIndex.E2]
    xi[..., 2] = x[..., StateIndex.E2]
    xi[..., 3] = x[..., StateIndex.R] - vx * np.asarray(kappa, dtype=float)
    return xi


def from_error_state(xi: ArrayLike, vx: ArrayLike, kappa: ArrayLike) -> NDArray:
    """``[vy, r, e1, e2]`` from the SPEC §1 error state ``[e1, e1_dot, e2, e2_dot]``."""
    xi = np.asarray(xi, dtype=float)
    vx = np.asarray(vx, dtype=float)
    x = np.empty_like(xi)
    x[..., StateIndex.VY] = xi[..., 1] - vx * xi[..., 2]
    x[..., StateIndex.R] = xi[..., 3] + vx * np.asarray(kappa, dtype=float)
    x[..., StateIndex.E1] = xi[..., 0]
    x[..., StateIndex.E2] = xi[..., 2]
    return x


def check_sensor_columns(sensors: Mapping, needed: tuple[str, ...] | list[str], who: str) -> None:
    """Refuse ground truth (``true_*`` columns, :class:`ValueError`) and name the columns of
    ``needed`` that ``sensors`` lacks (:class:`ParameterError`); ``who`` says which estimator."""
    leaked = [k for k in sensors if str(k).startswith("true")]
    if leaked:
        raise ValueError(f"{who} must not see ground truth; got columns {leaked}")
    missing = [k for k in needed if k not in sensors]
    if missing:
        raise ParameterError(f"{who} needs sensor columns {missing}")
