r"""Peer baseline: the linear Kalman filter of the Revs data's source paper (Leanza, Reina,
Blanco-Claraco 2021), with the same verbs as every estimator of the package.

Implemented from its description: linear bicycle model, states sideslip ``beta`` [rad]
and yaw rate ``r`` [rad/s], measurements lateral acceleration and yaw rate, *axle*
cornering stiffness ``C_f``, ``C_r`` (70,000 / 120,000 N/rad for the Ferrari 250 LM),
forward-Euler discretisation with the measured (time-varying) speed::

    beta_dot = -(C_f + C_r)/(m vx) beta - (1 + (lf C_f - lr C_r)/(m vx^2)) r + C_f/(m vx) delta
    r_dot    = -(lf C_f - lr C_r)/Iz beta - (lf^2 C_f + lr^2 C_r)/(Iz vx) r + lf C_f/Iz delta
    a_y      = -(C_f + C_r)/m beta - (lf C_f - lr C_r)/(m vx) r + C_f/m delta

Process noise enters through the steering input (``Q_d = B_d B_d^T sigma_delta^2``: model
error expressed as an equivalent steering error), measurement noise
``R = diag(sigma_ay^2, sigma_r^2)``; initial state 0, initial covariance ``1e4 I`` (as the
source). Causal.

Verbs (the same as :class:`~tire_learning_env.observer.NeuroAdaptiveObserver`):
:meth:`LinearKalmanFilter.reset`, :meth:`~LinearKalmanFilter.predict` (the car moves with
the inputs held), :meth:`~LinearKalmanFilter.update` (a sensor speaks),
:meth:`~LinearKalmanFilter.run` (rows in compiled code: per row correct with the row's
sample, record, predict to the next row with the row's inputs), returning an
:class:`~tire_learning_env.observer.trace.EstimateTrace` (state ``[vy, r]`` with
``vy = vx tan(beta)``, slip angles by eq. 13, the linear axle forces, innovations, NIS).

>>> import numpy as np
>>> from tire_learning_env.params import VehicleParams
>>> kf = LinearKalmanFilter(VehicleParams(), physics_dt=0.01)
>>> _ = kf.reset().update({"ay": 1.0, "yaw_rate": 0.05}, delta=0.01, vx=20.0).predict(0.01, delta=0.01, vx=20.0)
>>> tr = kf.run({"t": np.arange(5) * 0.01, "delta": np.zeros(5), "vx": np.full(5, 20.0),
...              "ay": np.zeros(5), "yaw_rate": np.zeros(5)})
>>> tr.state.shape, tr.state_names
((5, 2), ('vy', 'yaw_rate'))
"""

from __future__ import annotations

import math
from enum import IntEnum
from pathlib import Path
from typing import Mapping

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from .._jit_cache import key_on_family
from ..observer._kernel import CH_AY, CH_R, KERNEL_FAMILY, N_CHANNELS, V_FLOOR, slip_angles
from ..observer.model import StateIndex, check_sensor_columns
from ..observer.trace import EstimateTrace
from ..params import ParameterError, VehicleParams

__all__ = ["LinearKalmanFilter", "LinearKalmanBaseline"]



class KalmanState(IntEnum):
    """Entries of the kernel state vector ``s``: the filter state and its covariance's upper triangle."""

    BETA = 0  # sideslip [rad]
    R = 1  # yaw rate [rad/s]
    P_BETA = 2  # variance of beta [rad^2]
    P_BETA_R = 3  # covariance of beta and r [rad^2/s]
    P_R = 4  # variance of r [rad^2/s^2]



@njit(cache=True)
def _kf_predict(s, dt, delta, vx, m, Iz, lf, lr, cf, cr, q):
    """Forward-Euler step of ``dt`` [s] with the inputs held (module docstring)."""
    if dt <= 0.0:
        return
    v = vx if vx > 1.0 else 1.0
    a00 = 1.0 - dt * (cf + cr) / (m * v)
    a01 = -dt * (1.0 + (lf * cf - lr * cr) / (m * v * v))
    a10 = -dt * (lf * cf - lr * cr) / Iz
    a11 = 1.0 - dt * (lf * lf * cf + lr * lr * cr) / (Iz * v)
    b0 = dt * cf / (m * v)
    b1 = dt * lf * cf / Iz
    x0, x1 = s[KalmanState.BETA], s[KalmanState.R]
    p00, p01, p11 = s[KalmanState.P_BETA], s[KalmanState.P_BETA_R], s[KalmanState.P_R]
    s[KalmanState.BETA] = a00 * x0 + a01 * x1 + b0 * delta
    s[KalmanState.R] = a10 * x0 + a11 * x1 + b1 * delta
    t00 = a00 * p00 + a01 * p01
    t01 = a00 * p01 + a01 * p11
    t10 = a10 * p00 + a11 * p01
    t11 = a10 * p01 + a11 * p11
    s[KalmanState.P_BETA] = t00 * a00 + t01 * a01 + q * b0 * b0
    s[KalmanState.P_BETA_R] = t00 * a10 + t01 * a11 + q * b0 * b1
    s[KalmanState.P_R] = t10 * a10 + t11 * a11 + q * b1 * b1


@njit(cache=True)
def _kf_update(s, ay, yr, delta, vx, m, lf, lr, cf, cr, r_ay, r_r, nu):
    """Correct with ``a_y`` [m/s^2] and ``r`` [rad/s] (NaN: not measured); innovations into
    ``nu[0:2]``, returns ``(nis, dof)``."""
    v = vx if vx > 1.0 else 1.0
    x0, x1 = s[KalmanState.BETA], s[KalmanState.R]
    p00, p01, p11 = s[KalmanState.P_BETA], s[KalmanState.P_BETA_R], s[KalmanState.P_R]
    c00 = -(cf + cr) / m
    c01 = -(lf * cf - lr * cr) / (m * v)
    have_ay = ay == ay
    have_r = yr == yr
    nu[0] = np.nan
    nu[1] = np.nan
    if not have_ay and not have_r:
        return 0.0, 0
    y0 = ay - (c00 * x0 + c01 * x1 + cf / m * delta)
    y1 = yr - x1
    cp00 = c00 * p00 + c01 * p01  # (C P) row 0
    cp01 = c00 * p01 + c01 * p11
    if have_ay and have_r:
        s00 = cp00 * c00 + cp01 * c01 + r_ay
        s01 = cp01
        s11 = p11 + r_r
        det = s00 * s11 - s01 * s01
        i00 = s11 / det
        i01 = -s01 / det
        i11 = s00 / det
        k00 = cp00 * i00 + p01 * i01
        k01 = cp00 * i01 + p01 * i11
        k10 = cp01 * i00 + p11 * i01
        k11 = cp01 * i01 + p11 * i11
        nis = y0 * y0 * i00 + 2.0 * y0 * y1 * i01 + y1 * y1 * i11
        dof = 2
        nu[0] = y0
        nu[1] = y1
    elif have_ay:
        s00 = cp00 * c00 + cp01 * c01 + r_ay
        k00 = cp00 / s00
        k10 = cp01 / s00
        k01 = 0.0
        k11 = 0.0
        y1 = 0.0
        nis = y0 * y0 / s00
        dof = 1
        nu[0] = y0
    else:
        s11 = p11 + r_r
        k00 = 0.0
        k10 = 0.0
        k01 = p01 / s11
        k11 = p11 / s11
        y0 = 0.0
        nis = y1 * y1 / s11
        dof = 1
        nu[1] = y1
    s[KalmanState.BETA] = x0 + k00 * y0 + k01 * y1
    s[KalmanState.R] = x1 + k10 * y0 + k11 * y1
    # P = (I - K C) P with C = [[c00, c01], [0, 1]]
    m00 = 1.0 - k00 * c00
    m01 = -k00 * c01 - k01
    m10 = -k10 * c00
    m11 = 1.0 - k10 * c01 - k11
    s[KalmanState.P_BETA] = m00 * p00 + m01 * p01
    s[KalmanState.P_BETA_R] = m00 * p01 + m01 * p11
    s[KalmanState.P_R] = m10 * p01 + m11 * p11
    return nis, dof


@njit(cache=True)
def _kf_rows(t, delta, vx, ay, yr, prm, s, u_prev, t_now, dt_last, predict_last, out_x, out_p, out_nu, out_nis, out_slip):
    """Per row: predict from ``t_now`` to the row (inputs of the previous row held), correct,
    record (slip angles by eq. 13 with ``vy = vx tan(beta)``; ``out_x`` holds ``beta``, ``r`` and
    ``out_p`` their variances, in the columns ``KalmanState.BETA``, ``KalmanState.R``); then predict
    ``dt_last`` past the last row. Returns the time reached."""
    m, Iz, lf, lr, cf, cr, q, r_ay, r_r = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8]
    n = t.shape[0]
    nu = np.empty(2)
    for i in range(n):
        if i > 0:
            _kf_predict(s, t[i] - t_now, delta[i - 1], vx[i - 1], m, Iz, lf, lr, cf, cr, q)
        elif t[0] > t_now:  # continue from the previous call with its last inputs
            _kf_predict(s, t[0] - t_now, u_prev[0], u_prev[1], m, Iz, lf, lr, cf, cr, q)
        t_now = t[i]
        nis, dof = _kf_update(s, ay[i], yr[i], delta[i], vx[i], m, lf, lr, cf, cr, r_ay, r_r, nu)
        out_x[i, KalmanState.BETA] = s[KalmanState.BETA]
        out_x[i, KalmanState.R] = s[KalmanState.R]
        out_p[i, KalmanState.BETA] = s[KalmanState.P_BETA]
        out_p[i, KalmanState.R] = s[KalmanState.P_R]
        out_nu[i, 0] = nu[0]
        out_nu[i, 1] = nu[1]
        out_nis[i] = nis if dof > 0 else np.nan
        v = vx[i] if vx[i] > V_FLOOR else V_FLOOR
        beta, r = s[KalmanState.BETA], s[KalmanState.R]
        out_slip[i, 0], out_slip[i, 1] = slip_angles(v * math.tan(beta), r, delta[i], vx[i], lf, lr)
    if n > 0:
        u_prev[0] = delta[n - 1]
        u_prev[1] = vx[n - 1]
    if predict_last and n > 0:
        _kf_predict(s, dt_last, delta[n - 1], vx[n - 1], m, Iz, lf, lr, cf, cr, q)
        t_now = t[n - 1] + dt_last
    return t_now


class LinearKalmanFilter:
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
        Measurement noise std ``(a_y [m/s^2], r [rad/s])`` (e.g. the noise the estimator
        measured on the log).
    initial_var : float
        Initial covariance ``initial_var I`` of ``(beta [rad], r [rad/s])``.
    physics_dt : float
        Default step of :meth:`predict` and the prediction after the last row of :meth:`run` [s].
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        axle_stiffness: tuple[float, float] | None = None,
        steer_noise: float = 0.01,
        noise_std: tuple[float, float] = (1.0, 0.005),
        initial_var: float = 1e4,
        physics_dt: float = 0.01,
    ) -> None:
        cf, cr = axle_stiffness if axle_stiffness is not None else (2.0 * vehicle.Cf, 2.0 * vehicle.Cr)
        if not (cf > 0 and cr > 0 and steer_noise > 0 and initial_var > 0 and min(noise_std) > 0 and physics_dt > 0):
            raise ParameterError("axle stiffness, steer_noise, noise_std, initial_var and physics_dt must be > 0")
        self.vehicle = vehicle
        self.axle_stiffness = (float(cf), float(cr))
        self.steer_noise = float(steer_noise)
        self.noise_std = (float(noise_std[0]), float(noise_std[1]))
        self.initial_var = float(initial_var)
        self.dt = float(physics_dt)
        v = vehicle
        self._prm = np.array([v.m, v.Iz, v.lf, v.lr, *self.axle_stiffness, self.steer_noise**2,
                              self.noise_std[0] ** 2, self.noise_std[1] ** 2])  # fmt: skip
        self.reset()

    # -- state ------------------------------------------------------------------------------------
    def reset(self, state: ArrayLike | None = None, weights: ArrayLike | None = None) -> "LinearKalmanFilter":
        """Start again from ``state = [vy [m/s], r [rad/s]]`` (default zero, as the source) with the
        initial covariance. ``weights`` is accepted for the common signature and must be empty
        (the filter learns nothing)."""
        if weights is not None and np.asarray(weights).size:
            raise ParameterError("the linear Kalman filter has no weights")
        x = np.zeros(2) if state is None else np.asarray(state, dtype=float).reshape(2)
        self._s = np.zeros(len(KalmanState))
        self._s[KalmanState.BETA] = math.atan2(float(x[StateIndex.VY]), max(self.vehicle.vx, V_FLOOR))
        self._s[KalmanState.R] = x[StateIndex.R]
        self._s[KalmanState.P_BETA] = self._s[KalmanState.P_R] = self.initial_var
        self._u = np.array([0.0, self.vehicle.vx])  # inputs held since the last row (delta, vx)
        self._started = False
        self.t = 0.0
        return self

    @property
    def state(self) -> NDArray:
        """Current ``[vy, r]`` (``vy = vx tan(beta)`` at the speed of the last input; the vehicle's
        nominal speed before any)."""
        beta, r = self._s[KalmanState.BETA], self._s[KalmanState.R]
        return np.array([max(float(self._u[1]), V_FLOOR) * math.tan(beta), r])  # in StateIndex order (VY, R)

    @property
    def beta(self) -> float:
        """Current sideslip estimate [rad]."""
        return float(self._s[KalmanState.BETA])

    @property
    def covariance(self) -> NDArray:
        """Current covariance of ``(beta, r)``."""
        s = self._s
        p00, p01, p11 = s[KalmanState.P_BETA], s[KalmanState.P_BETA_R], s[KalmanState.P_R]
        return np.array([[p00, p01], [p01, p11]])

    # -- verbs ------------------------------------------------------------------------------------
    def predict(self, dt: float | None = None, delta: float = 0.0, vx: float | None = None, kappa: float = 0.0,
                ax: float = 0.0) -> "LinearKalmanFilter":  # fmt: skip
        """Advance ``dt`` [s] (default ``physics_dt``) with steering ``delta`` [rad] and speed
        ``vx`` [m/s] held (``kappa``, ``ax`` are accepted for the common signature; unused)."""
        dt = self.dt if dt is None else float(dt)
        vx = self.vehicle.vx if vx is None else float(vx)
        p = self._prm
        _kf_predict(self._s, dt, float(delta), vx, p[0], p[1], p[2], p[3], p[4], p[5], p[6])
        self._u[:] = (float(delta), vx)
        self.t += dt
        return self

    def update(self, z: ArrayLike | Mapping[str, float], delta: float = 0.0, vx: float | None = None) -> "LinearKalmanFilter":
        """Correct with a measurement now: ``z = [e1, e2, a_y, r]`` (camera channels ignored; NaN:
        not measured), ``[a_y, r]``, or a mapping with ``ay``/``yaw_rate``; ``delta`` [rad],
        ``vx`` [m/s] are the current inputs."""
        vx = self.vehicle.vx if vx is None else float(vx)
        if isinstance(z, Mapping):
            ay, yr = float(z.get("ay", np.nan)), float(z.get("yaw_rate", np.nan))
        else:
            zz = np.asarray(z, dtype=float).reshape(-1)
            if zz.size == 4:
                ay, yr = zz[CH_AY], zz[CH_R]
            elif zz.size == 2:
                ay, yr = zz
            else:
                raise ParameterError(f"z must hold (a_y, r) or (e1, e2, a_y, r), got {zz.size} values")
        p = self._prm
        _kf_update(self._s, float(ay), float(yr), float(delta), vx, p[0], p[2], p[3], p[4], p[5], p[7], p[8], np.empty(2))
        self._u[:] = (float(delta), vx)
        self._started = True
        return self

    def run(self, sensors: Mapping[str, ArrayLike], predict_last: bool = True) -> EstimateTrace:
        """Filter rows ``t, delta, vx, ay, yaw_rate`` (NaN: no sample), continuing from the
        current state (the first call starts at the first row). Ground truth is refused.

        Returns
        -------
        EstimateTrace
            ``state = [vy, r]``, slip angles (eq. 13), linear axle forces ``C alpha``,
            ``std`` of ``[vy, r]``, innovations of ``a_y`` and ``r`` (columns 2, 3), NIS;
            ``force_nonlinear`` is zero and ``weights`` empty (nothing is learned).
        """
        check_sensor_columns(sensors, ("t", "delta", "vx", "ay", "yaw_rate"), "the linear Kalman filter")
        t, delta, vx, ay, yr = (np.ascontiguousarray(sensors[k], dtype=float) for k in ("t", "delta", "vx", "ay", "yaw_rate"))
        n = len(t)
        if not (len(delta) == len(vx) == len(ay) == len(yr) == n):
            raise ParameterError("sensor columns must have equal lengths")
        out_x, out_p, out_nu, out_nis = np.zeros((n, 2)), np.zeros((n, 2)), np.full((n, 2), np.nan), np.full(n, np.nan)
        out_slip = np.zeros((n, 2))
        if n:
            t_now = self.t if self._started else float(t[0])
            self.t = float(_kf_rows(t, delta, vx, ay, yr, self._prm, self._s, self._u, t_now, self.dt, bool(predict_last),
                                    out_x, out_p, out_nu, out_nis, out_slip))  # fmt: skip
            self._started = True
        return self._trace(t, vx, out_x, out_p, out_nu, out_nis, out_slip)

    def _trace(self, t, vx, out_x, out_p, out_nu, out_nis, slip) -> EstimateTrace:
        n = len(t)
        vxf = np.maximum(vx, V_FLOOR)
        beta, r = out_x[:, KalmanState.BETA], out_x[:, KalmanState.R]
        vy = vxf * np.tan(beta)
        force = slip * np.array(self.axle_stiffness)
        std = np.column_stack([vxf * np.sqrt(np.maximum(out_p[:, KalmanState.BETA], 0.0)) / np.cos(beta) ** 2,
                               np.sqrt(np.maximum(out_p[:, KalmanState.R], 0.0))])  # fmt: skip
        nu = np.full((n, N_CHANNELS), np.nan)
        nu[:, [CH_AY, CH_R]] = out_nu
        return EstimateTrace(
            t.copy(), np.column_stack([vy, r]), slip, force, np.zeros((n, 2)), np.zeros((n, 0)), std,
            np.zeros(n, dtype=np.int8), nu, out_nis, vx.copy(), np.zeros(n), ("vy", "yaw_rate"),
            {"estimator": "linear_kalman_filter", "beta": beta.copy()},
        )  # fmt: skip

    def settings(self) -> dict:
        """The filter's settings (for ``metrics.json``)."""
        return {
            "axle_stiffness_N_per_rad": list(self.axle_stiffness),
            "steer_noise_rad": self.steer_noise,
            "noise_std": list(self.noise_std),
            "initial_var": self.initial_var,
            "discretisation": "forward Euler, inputs of the previous row held",
        }


#: former name (``tire_learning_env.imu.LinearKalmanBaseline``)
LinearKalmanBaseline = LinearKalmanFilter


#: the observer's compiled family plus this file: an edit to the slip angles invalidates this module's numba cache
#: (:func:`tire_learning_env._jit_cache.key_on_family`)
KALMAN_FAMILY = (*KERNEL_FAMILY, Path(__file__))
key_on_family(globals(), KALMAN_FAMILY)
