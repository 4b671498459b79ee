"""Error-coordinate bicycle model (SPEC §1, paper eqs. 1-8 and 13).

State ``xi = [e1, e1_dot, e2, e2_dot]`` (:class:`StateIndex`): lateral offset from the
reference path [m], its rate [m/s], heading error [rad], its rate [rad/s].

Pure functions of ``(x, u, params)``:

- :func:`error_state_matrices` returns ``(A, B1, B2, B3, F, C)`` exactly as in SPEC §1;
- :func:`slip_angles` implements eq. (13);
- :func:`error_state_derivative` is Newton's law in error coordinates for any axle forces.

:class:`BicyclePlant` is a thin stateful shell: the truth vehicle integrated with
classical RK4 (fourth order; the step costs a few microseconds in pure Python) with any
pair of axle tire models, an optional tire relaxation length and the physical effects of
:class:`PlantEffects` (used to hide effects from the discrepancy workflow).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .params import ParameterError, VehicleParams, _Params
from ._kernels import S_E1, S_E1_DOT, S_E2, S_E2_DOT, bicycle_rhs, bicycle_rk4_step, bicycle_slip_angles
from .tires import TireModel

__all__ = [
    "StateIndex",
    "error_state_matrices",
    "slip_angles",
    "error_state_derivative",
    "PlantEffects",
    "PlantOutput",
    "BicyclePlant",
]


class StateIndex(IntEnum):
    """Names of the error-state components (also the first four entries of a plant's ``state``,
    :data:`~._kernels.S_E1` ... in the compiled kernels)."""

    E1 = S_E1  # lateral offset [m]
    E1_DOT = S_E1_DOT  # lateral offset rate [m/s]
    E2 = S_E2  # heading error [rad]
    E2_DOT = S_E2_DOT  # heading error rate [rad/s]


STATE_NAMES = ("e1", "e1_dot", "e2", "e2_dot")


def error_state_matrices(
    vehicle: VehicleParams, vx: float | None = None
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
    """Matrices of ``xi_dot = A xi + B1 delta + B2 psi_dot_des + B3 psi_ddot_des + F f`` (eq. 7-8).

    Parameters
    ----------
    vehicle : VehicleParams
        Mass, inertia, geometry and the nominal per-tire stiffness ``Cf``, ``Cr``.
    vx : float, optional
        Speed [m/s]; defaults to ``vehicle.vx``.

    Returns
    -------
    A : ndarray, shape (4, 4)
    B1 : ndarray, shape (4,)
        Steering input [per rad].
    B2 : ndarray, shape (4,)
        Desired yaw rate ``psi_dot_des = vx kappa`` input.
    B3 : ndarray, shape (4,)
        Desired yaw acceleration ``psi_ddot_des`` input.
    F : ndarray, shape (4, 2)
        Input of the nonlinear axle forces ``f = [f_yf, f_yr]`` [N].
    C : ndarray, shape (2, 4)
        Camera output ``z = [e1, e2]``.
    """
    m, Iz, lf, lr = vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr
    vx = vehicle.vx if vx is None else float(vx)
    if not vx > 0:
        raise ParameterError(f"vx must be > 0, got {vx!r}")
    cf2, cr2 = 2.0 * vehicle.Cf, 2.0 * vehicle.Cr  # axle stiffness [N/rad]
    A = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [0.0, -(cf2 + cr2) / (m * vx), (cf2 + cr2) / m, (-cf2 * lf + cr2 * lr) / (m * vx)],
            [0.0, 0.0, 0.0, 1.0],
            [0.0, (-cf2 * lf + cr2 * lr) / (Iz * vx), (cf2 * lf - cr2 * lr) / Iz, -(cf2 * lf**2 + cr2 * lr**2) / (Iz * vx)],
        ]
    )
    B1 = np.array([0.0, cf2 / m, 0.0, cf2 * lf / Iz])
    B2 = np.array([0.0, (-cf2 * lf + cr2 * lr) / (m * vx) - vx, 0.0, -(cf2 * lf**2 + cr2 * lr**2) / (Iz * vx)])
    B3 = np.array([0.0, 0.0, 0.0, -1.0])
    F = np.array([[0.0, 0.0], [1.0 / m, 1.0 / m], [0.0, 0.0], [lf / Iz, -lr / Iz]])
    C = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    return A, B1, B2, B3, F, C


def slip_jacobian(vehicle: VehicleParams, vx: float | None = None) -> NDArray:
    """``H = d[alpha_f, alpha_r]/d xi`` (eq. 13), shape (2, 4)."""
    vx = vehicle.vx if vx is None else float(vx)
    return np.array(
        [
            [0.0, -1.0 / vx, 1.0, -vehicle.lf / vx],
            [0.0, -1.0 / vx, 1.0, vehicle.lr / vx],
        ]
    )


def slip_angles(
    xi: ArrayLike, delta: ArrayLike, psi_dot_des: ArrayLike, vx: ArrayLike, lf: float, lr: float
) -> tuple[NDArray, NDArray]:
    """Front and rear axle slip angles [rad] in error coordinates (eq. 13).

    ``alpha_f = delta - (e1_dot - vx e2 + lf e2_dot + lf psi_dot_des) / vx``
    ``alpha_r =       - (e1_dot - vx e2 - lr e2_dot - lr psi_dot_des) / vx``

    Parameters
    ----------
    xi : array_like, shape (..., 4)
        Error state(s).
    delta, psi_dot_des, vx : array_like, broadcastable to ``xi[..., 0]``
        Road-wheel steering [rad], desired yaw rate [rad/s], speed [m/s].
    lf, lr : float
        Axle distances [m].
    """
    xi = np.asarray(xi, dtype=float)
    vx = np.asarray(vx, dtype=float)
    vy = xi[..., 1] - vx * xi[..., 2]  # body states from the error state (SPEC section 1)
    r = xi[..., 3] + np.asarray(psi_dot_des, dtype=float)
    return bicycle_slip_angles.py_func(vy, r, np.asarray(delta, dtype=float), vx, lf, lr)  # eq. (13), the one implementation


def error_state_derivative(
    xi: ArrayLike,
    psi_dot_des: ArrayLike,
    psi_ddot_des: ArrayLike,
    force_front: ArrayLike,
    force_rear: ArrayLike,
    vehicle: VehicleParams,
    vx: ArrayLike | None = None,
    ax: ArrayLike = 0.0,
    lateral_force: ArrayLike = 0.0,
    yaw_moment: ArrayLike = 0.0,
) -> NDArray:
    """Newton's law in error coordinates (eq. 1 and 5).

    ``e1_ddot = (F_yf + F_yr + F_ext)/m - vx psi_dot_des + ax e2``,
    ``e2_ddot = (lf F_yf - lr F_yr + M_ext)/Iz - psi_ddot_des``.
    With a linear tire and ``ax = 0`` this is exactly ``A xi + B1 delta + B2 psi_dot_des + B3 psi_ddot_des``.

    Returns
    -------
    ndarray, shape like ``xi``
    """
    xi = np.asarray(xi, dtype=float)
    vx = vehicle.vx if vx is None else vx
    out = np.empty_like(xi)
    out[..., 0] = xi[..., 1]
    out[..., 1] = (np.asarray(force_front) + force_rear + lateral_force) / vehicle.m - np.asarray(vx) * psi_dot_des + np.asarray(ax) * xi[..., 2]
    out[..., 2] = xi[..., 3]
    out[..., 3] = (vehicle.lf * np.asarray(force_front) - vehicle.lr * np.asarray(force_rear) + yaw_moment) / vehicle.Iz - np.asarray(psi_ddot_des)
    return out


@dataclass(frozen=True)
class PlantEffects(_Params):
    """Physical effects of the truth vehicle that the bicycle model of SPEC §1 lacks.

    All default to zero (the plain bicycle model). The discrepancy workflow hides them
    in simulated logs and must find them.

    Parameters
    ----------
    relaxation_length : float
        Tire relaxation length [m]: slip acts through a first-order lag with time
        constant ``relaxation_length / vx`` on both axles.
    steering_offset : float
        Constant error between commanded (logged) and actual road-wheel angle [rad].
    bank_angle : float
        Road bank angle [rad]; positive raises the left edge, so gravity pulls the car
        to the right with ``-g sin(bank_angle)``.
    crosswind_force : float
        Constant lateral aerodynamic force, positive to the left [N].
    crosswind_arm : float
        Distance of its centre of pressure ahead of the centre of gravity [m].
    cornering_stiffness_scale_front, cornering_stiffness_scale_rear : float
        Multiply the truth axle force (and so the true stiffness) [-].
    load_transfer : float
        Strength of lateral load transfer [-]: with ``r = |a_y| h_cg / (g track)`` the
        relative load moved to the outer wheels (rigid body), both axle forces drop by
        the factor ``1 - load_transfer * r^2 / 2`` (the concavity of tire force in load).
    """

    relaxation_length: float = 0.0  # [m]
    steering_offset: float = 0.0  # [rad]
    bank_angle: float = 0.0  # [rad]
    crosswind_force: float = 0.0  # [N]
    crosswind_arm: float = 0.0  # [m]
    cornering_stiffness_scale_front: float = 1.0  # [-]
    cornering_stiffness_scale_rear: float = 1.0  # [-]
    load_transfer: float = 0.0  # [-]

    _positive: ClassVar[tuple[str, ...]] = ("cornering_stiffness_scale_front", "cornering_stiffness_scale_rear")
    _non_negative: ClassVar[tuple[str, ...]] = ("relaxation_length", "load_transfer")


@dataclass(frozen=True)
class PlantOutput:
    """Ground truth of the plant at one instant (for scoring only)."""

    xi: NDArray  # (4,) error state
    slip: NDArray  # (2,) kinematic slip angles [rad]
    force: NDArray  # (2,) axle lateral forces [N]
    force_nonlinear: NDArray  # (2,) force minus the nominal linear part 2C alpha [N]
    yaw_rate: float  # [rad/s]
    ay: float  # IMU lateral acceleration (specific force) [m/s^2]
    vy: float  # lateral velocity at the CG [m/s]


def vehicle_vector(vehicle: VehicleParams) -> NDArray:
    """The vehicle as the compiled kernels' parameter vector (``_kernels.V_*`` layout)."""
    fzf, fzr = vehicle.static_axle_loads
    return np.array(
        [vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr, vehicle.Cf, vehicle.Cr, vehicle.h_cg, vehicle.track, fzf, fzr,
         vehicle.camera_x]
    )  # fmt: skip


def effects_vector(effects: PlantEffects) -> NDArray:
    """The effects as the compiled kernels' vector (``_kernels.X_*`` layout)."""
    return np.array(
        [
            effects.relaxation_length,
            effects.steering_offset,
            effects.bank_angle,
            effects.crosswind_force,
            effects.crosswind_arm,
            effects.cornering_stiffness_scale_front,
            effects.cornering_stiffness_scale_rear,
            effects.load_transfer,
        ]
    )


class BicyclePlant:
    """Truth vehicle: the error-coordinate bicycle model with nonlinear axle tires.

    Parameters
    ----------
    vehicle : VehicleParams
        Geometry, mass, nominal per-tire stiffness (``2 Cf`` is used for the reported
        nonlinear part ``F_yf - 2 Cf alpha_f``).
    front_tire, rear_tire : TireModel
        Axle tire models (any :class:`~.tires.TireModel`; other than linear and Pacejka
        they are tabulated every 1e-4 rad for the compiled loop).
    effects : PlantEffects, optional
        Extra physics hidden from the observer.

    Notes
    -----
    The state ``[e1, e1_dot, e2, e2_dot, lag_alpha_f, lag_alpha_r]`` is integrated with
    classical RK4 (:func:`._kernels.bicycle_rk4_step`), steering held over the step
    (zero-order hold) and the desired yaw rate sampled at the start, middle and end of
    the step. The last two states are the relaxation-lagged slip angles (unused without
    relaxation).
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        front_tire: TireModel,
        rear_tire: TireModel,
        effects: PlantEffects | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.front_tire = front_tire
        self.rear_tire = rear_tire
        self.effects = effects or PlantEffects()
        self.veh_vec = vehicle_vector(vehicle)
        self.tire_f, self.table_f = front_tire.kernel_vector()
        self.tire_r, self.table_r = rear_tire.kernel_vector()
        self.eff_vec = effects_vector(self.effects)
        self.state = np.zeros(6)
        self.reset()

    def reset(self, xi: ArrayLike | None = None) -> None:
        """Set the error state (default zero); the tire lag states start at zero slip."""
        xi = np.zeros(4) if xi is None else np.asarray(xi, dtype=float).reshape(4)
        if not np.all(np.isfinite(xi)):
            raise ValueError(f"initial state must be finite, got {xi}")
        self.state[:] = 0.0
        self.state[S_E1 : S_E2_DOT + 1] = xi
        self._last_inputs = (0.0, self.vehicle.vx, 0.0, 0.0, 0.0)

    def step(
        self,
        delta: float,
        dt: float,
        psi_dot_des: tuple[float, float, float],
        psi_ddot_des: tuple[float, float, float],
        vx: float | None = None,
        ax: float = 0.0,
    ) -> tuple[float, float, float, float, float, float]:
        """Advance one RK4 step of ``dt`` [s].

        Parameters
        ----------
        delta : float
            Commanded road-wheel angle [rad], held over the step.
        dt : float
            Step [s].
        psi_dot_des, psi_ddot_des : tuple of 3 floats
            Desired yaw rate [rad/s] and acceleration [rad/s^2] at the start, middle and
            end of the step.
        vx, ax : float
            Speed [m/s] (default: the vehicle's) and longitudinal acceleration [m/s^2].

        Returns
        -------
        tuple of float
            Truth at the *start* of the step: slip ``alpha_f, alpha_r`` [rad], axle
            forces ``F_yf, F_yr`` [N], yaw rate [rad/s], IMU lateral acceleration [m/s^2].
        """
        if vx is None:
            vx = self.vehicle.vx
        p0, p1, p2 = psi_dot_des
        q0, q1, q2 = psi_ddot_des
        before = self.state.copy()
        out = bicycle_rk4_step(self.state, delta, dt, p0, p1, p2, q0, q1, q2, vx, ax, *self.kernel_params())
        if not np.all(np.isfinite(self.state)):
            raise FloatingPointError(
                f"plant state became non-finite: {self.state.tolist()} from {before.tolist()}, delta={delta}, vx={vx}"
            )
        self._last_inputs = (delta, vx + dt * ax, ax, p2, q2)
        return out

    def hold_inputs(self, delta: float, vx: float, ax: float, psi_dot_des: float, psi_ddot_des: float) -> None:
        """Record the inputs held at the current state, as :meth:`step` does, for :meth:`output`.

        A loop that advances :attr:`state` itself (the compiled chunk loop) calls this at its end.

        Parameters
        ----------
        delta : float
            Road-wheel angle [rad].
        vx, ax : float
            Speed [m/s] and longitudinal acceleration [m/s^2].
        psi_dot_des, psi_ddot_des : float
            Desired yaw rate [rad/s] and acceleration [rad/s^2].
        """
        self._last_inputs = (delta, vx, ax, psi_dot_des, psi_ddot_des)

    def kernel_params(self) -> tuple:
        """Parameter arrays in the order the compiled kernels take them (``veh, tf, tr, tabf, tabr, eff``)."""
        return self.veh_vec, self.tire_f, self.tire_r, self.table_f, self.table_r, self.eff_vec

    @property
    def xi(self) -> NDArray:
        """Current error state ``[e1, e1_dot, e2, e2_dot]``."""
        return self.state[S_E1 : S_E2_DOT + 1].copy()

    def true_axle_curve(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Steady-state truth axle force [N] at slip ``alpha`` (tire times stiffness scale)."""
        if axle == "front":
            return self.front_tire.lateral_force(alpha) * self.effects.cornering_stiffness_scale_front
        if axle == "rear":
            return self.rear_tire.lateral_force(alpha) * self.effects.cornering_stiffness_scale_rear
        raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")

    def true_cornering_stiffness(self) -> tuple[float, float]:
        """Per-tire truth cornering stiffness: half the slope of the truth axle curve at zero [N/rad]."""
        h = 1e-7
        return tuple(
            float((self.true_axle_curve(h, a) - self.true_axle_curve(-h, a)) / (4.0 * h)) for a in ("front", "rear")
        )

    def output(self) -> PlantOutput:
        """Ground truth at the current state (using the inputs of the last step)."""
        delta, vx, ax, pdd, pddd = self._last_inputs
        e1, e1d, e2, e2d, laf, lar = self.state
        *_, af, ar, Fyf, Fyr = bicycle_rhs(e1d, e2, e2d, laf, lar, delta, vx, ax, pdd, pddd, *self.kernel_params())
        veh = self.vehicle
        return PlantOutput(
            xi=self.xi,
            slip=np.array([af, ar]),
            force=np.array([Fyf, Fyr]),
            force_nonlinear=np.array([Fyf - 2.0 * veh.Cf * af, Fyr - 2.0 * veh.Cr * ar]),
            yaw_rate=e2d + pdd,
            ay=(Fyf + Fyr + self.effects.crosswind_force) / veh.m,
            vy=e1d - vx * e2,
        )
