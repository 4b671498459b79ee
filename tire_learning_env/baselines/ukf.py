"""Joint state-and-parameter unscented Kalman filter on the bicycle model (peer baseline).

The kind of estimator the paper's related work uses for tire-parameter identification:
the error state of SPEC §1 is augmented with the parameters of a Pacejka-type axle curve,
the parameters follow a random walk, and an unscented Kalman filter estimates both from
the lane camera.

Model (per axle ``i`` in front/rear; eq. (13) slips, Newton in error coordinates as
:func:`~tire_learning_env.dynamics.error_state_derivative`)::

    F_i(alpha) = D_i sin(Cs atan(B_i alpha - E (B_i alpha - atan(B_i alpha))))
    D_i = mu_i F_z,i     (static axle load of the nominal vehicle)
    B_i = 2 C_i / (Cs D_i)   (so that the slope at zero slip is the axle stiffness 2 C_i)

Filter state (8): ``[e1, e1_dot, e2, e2_dot, ln(Cf/Cf0), ln(Cr/Cr0), ln(mu_f), ln(mu_r)]``
(log-parameters keep stiffness and friction positive; ``Cf0``, ``Cr0`` are the nominal
vehicle's). Shape ``Cs`` and curvature ``E`` are fixed (defaults of
:class:`~tire_learning_env.params.TireParams`).

- Predict (from row to row of the log, any spacing): scaled unscented transform (Merwe:
  ``alpha=1, beta=2, kappa=0`` -> all weights >= 0) of a classical RK4 step of the model,
  inputs ``delta``, ``vx``, ``ax``, ``psi_dot_des = vx kappa`` and ``psi_ddot_des``
  held over the step; additive process noise ``Q = diag(q) dt``.
- Update (whenever a camera frame arrived, any rate): ``z = [e1, e2]`` is linear in the
  state, so the unscented update equals the Kalman update, which is used (exact).

Inputs are the log's rows only (``t, delta, vx, kappa, e1, e2``, ``ax`` optional; NaN = no
frame): never ground truth. ``psi_ddot_des`` is ``ax kappa + vx kappa_rate`` with the backward
difference of ``kappa``, as the observer has it; a simulator's rows that carry the path's
``psi_dot_des`` and ``psi_ddot_des`` (:data:`tire_learning_env.simulation.SENSOR_KEYS`) are
used as they are (``psi_dot_des = vx kappa`` there exactly). Camera latency is not
compensated. The filter has the verbs of every estimator of the package (``reset``,
``predict``, ``update``, ``run`` with the observer's argument order) and its result is an
:class:`~tire_learning_env.observer.EstimateTrace` (:class:`UKFResult`). The compiled
kernels (:func:`ukf_predict`, :func:`ukf_update`, :func:`ukf_run_rows`) are the single
implementation behind them; the slip angles are the core's eq. (13).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..observer._kernel import CH_E1, CH_E2, N_CHANNELS
from ..observer.model import StateIndex, camera_path_bend, check_sensor_columns
from ..observer.trace import EstimateTrace
from ..params import CameraParams, ParameterError, TireParams, VehicleParams
from ._ukf_kernels import (N_ERR, N_SIGMA, N_X, STATE_NAMES, PARAM_NAMES, U_AX, U_DELTA, U_PDD, U_PDDD, U_VX, UKF_FAMILY,  # noqa: F401
                           X_E1, X_E1_DOT, X_E2, X_E2_DOT, X_LOG_CF, X_LOG_CR, X_LOG_MU_F, X_LOG_MU_R, ukf_predict,
                           ukf_run_rows, ukf_update)

__all__ = ["JointUKF", "UKFResult", "run_ukf_baseline", "pacejka_axle_force", "PARAM_NAMES", "STATE_NAMES"]

def pacejka_axle_force(alpha: ArrayLike, stiffness: float, mu: float, fz: float, shape: float, curvature: float) -> NDArray:
    """The filter's axle curve [N]: Magic Formula with slope ``2 stiffness`` at zero and peak ``mu fz``.

    ``stiffness`` per tire [N/rad], ``fz`` static axle load [N], ``shape`` ``Cs``, ``curvature`` ``E``.
    """
    d = mu * fz
    b = 2.0 * stiffness / (shape * d)
    x = b * np.asarray(alpha, dtype=float)
    return d * np.sin(shape * np.arctan(x - curvature * (x - np.arctan(x))))


@dataclass
class UKFResult(EstimateTrace):
    """Per-row output of :meth:`JointUKF.run` (row ``j`` = posterior at ``t_j``): the common
    :class:`~tire_learning_env.observer.EstimateTrace` of every estimator, plus the filter's
    parameters.

    The common fields: ``state = [vy, r, e1, e2]`` (``state_names``), its ``std``, the axle
    ``slip`` (eq. 13) and total ``force`` at the estimated slips, ``force_nonlinear`` (the part
    beyond the nominal ``2 C alpha``), ``weights`` = the learned log-parameters
    ``[ln(Cf/Cf0), ln(Cr/Cr0), ln mu_f, ln mu_r]``, the camera ``innovation`` (columns ``e1``,
    ``e2``) and its ``nis``, ``health`` (all rows ``ok``: the filter has no health test; ``meta``
    says so), the rows' ``vx`` and ``kappa``.

    Attributes
    ----------
    params : ndarray, shape (n, 4)
        ``Cf``, ``Cr`` (per tire) [N/rad], ``mu_f``, ``mu_r`` [-] over time.
    filter_std : ndarray, shape (n, 8)
        Posterior standard deviations of the filter state (:data:`STATE_NAMES`; the
        log-parameters for the last 4).
    error_state : ndarray, shape (n, 4)
        The filter's own ``[e1, e1_dot, e2, e2_dot]`` (:attr:`xi`).
    axle_loads : (float, float)
        Static axle loads of the nominal vehicle [N] (the curve's ``F_z``).
    shape, curvature : float
        The curve's fixed ``Cs`` and ``E``.
    runtime_s : float
        Wall time of the run [s].
    """

    params: NDArray = None
    filter_std: NDArray = None
    error_state: NDArray = None
    axle_loads: tuple = (float("nan"), float("nan"))
    shape: float = float("nan")
    curvature: float = float("nan")
    runtime_s: float = float("nan")

    @property
    def xi(self) -> NDArray:
        """Estimated ``[e1, e1_dot, e2, e2_dot]`` (the filter's state, exactly)."""
        return self.error_state

    def cornering_stiffness(self, k: int = -1) -> tuple[float, float]:
        """Per-tire cornering stiffness (front, rear) [N/rad] at row ``k`` (default: the end)."""
        return float(self.params[k, 0]), float(self.params[k, 1])

    def peak_friction(self, k: int = -1) -> tuple[float, float]:
        """Peak friction (front, rear) [-] at row ``k`` (default: the end)."""
        return float(self.params[k, 2]), float(self.params[k, 3])

    def axle_force(self, alpha: ArrayLike, axle: str, k: int = -1) -> NDArray:
        """Total axle force [N] of the learned curve (parameters of row ``k``, default the end)."""
        if axle not in ("front", "rear"):
            raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")
        i = 0 if axle == "front" else 1
        return pacejka_axle_force(alpha, self.params[k, i], self.params[k, 2 + i], self.axle_loads[i], self.shape, self.curvature)

    def curve_history(self, step_s: float = 0.5):
        """``(times, k -> curve)`` of the online estimate every ``step_s`` [s] (for convergence metrics)."""
        idx = np.unique(np.searchsorted(self.t, np.arange(self.t[0], self.t[-1] + 1e-9, step_s)))
        idx = idx[idx < len(self.t)]

        def curve_at(j: int):
            row = int(idx[j])
            return lambda alpha, axle: self.axle_force(alpha, axle, row)

        return self.t[idx], curve_at


class JointUKF:
    """Joint unscented Kalman filter of the error state and Pacejka axle-tire parameters.

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle: ``m``, ``Iz``, ``lf``, ``lr`` and the initial per-tire stiffness
        guesses ``Cf``, ``Cr`` [N/rad] (``Cf0``, ``Cr0``).
    dt : float
        Default predict step [s] (:meth:`predict` without ``dt``; :meth:`run` steps from row
        to row of the log's ``t``).
    tire : TireParams, optional
        Fixed Pacejka shape ``Cs`` and curvature ``E`` and the initial friction ``mu``.
    measurement_std : (float, float)
        Camera noise standard deviations of ``e1`` [m] and ``e2`` [rad] (``R``). Use
        :meth:`for_camera` to take them from a camera spec (with a floor).
    initial_state_std : (4 floats)
        Prior std of the error state ``[e1, e1_dot, e2, e2_dot]`` (the prior mean is zero, or the
        ``state`` given to :meth:`reset`).
    stiffness_std : float
        Prior std of ``ln(C/C0)`` [-] (0.2 ~ +/-20 %).
    mu_std : float
        Prior std of ``ln(mu)`` [-].
    accel_noise : (float, float)
        Process-noise intensities of ``e1_ddot`` [m^2/s^3] and ``e2_ddot`` [rad^2/s^3].
    param_walk : (float, float)
        Random-walk intensities of the log-stiffnesses and log-frictions [1/s].
    sigma_alpha, sigma_beta, sigma_kappa : float
        Merwe scaled sigma-point parameters.

    Examples
    --------
    >>> from tire_learning_env import VehicleParams, simulate
    >>> log = simulate("lane_changes", 5.0)
    >>> ukf = JointUKF(VehicleParams().replace(Cf=1.1e5, Cr=1.1e5))
    >>> res = ukf.run(log.sensors)
    >>> res.xi.shape, len(ukf.cornering_stiffness())
    ((5000, 4), 2)
    """

    def __init__(
        self,
        vehicle: VehicleParams,
        *,
        dt: float = 1e-3,
        tire: TireParams | None = None,
        measurement_std: tuple[float, float] = (1e-3, 1e-3),
        initial_state_std: tuple[float, float, float, float] = (0.05, 0.05, 0.005, 0.005),
        stiffness_std: float = 0.2,
        mu_std: float = 0.2,
        accel_noise: tuple[float, float] = (1e-3, 1e-4),
        param_walk: tuple[float, float] = (1e-6, 1e-6),
        sigma_alpha: float = 1.0,
        sigma_beta: float = 2.0,
        sigma_kappa: float = 0.0,
    ) -> None:
        if not isinstance(vehicle, VehicleParams):
            raise ParameterError(f"vehicle must be a VehicleParams, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.tire = tire if tire is not None else TireParams()
        self.dt = float(dt)
        if not self.dt > 0:
            raise ParameterError(f"dt must be > 0, got {dt!r}")
        checks = {
            "measurement_std": (measurement_std, 2),
            "initial_state_std": (initial_state_std, 4),
            "accel_noise": (accel_noise, 2),
            "param_walk": (param_walk, 2),
        }
        for name, (value, size) in checks.items():
            arr = np.asarray(value, dtype=float)
            if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ParameterError(f"{name} must be {size} finite values >= 0, got {value!r}")
        if not np.all(np.asarray(measurement_std) > 0):
            raise ParameterError(f"measurement_std must be > 0 (use a small floor for a noise-free camera), got {measurement_std!r}")
        for name, value in (("stiffness_std", stiffness_std), ("mu_std", mu_std)):
            if not (math.isfinite(value) and value > 0):
                raise ParameterError(f"{name} must be > 0, got {value!r}")
        self.measurement_std = tuple(float(v) for v in measurement_std)
        self.initial_state_std = tuple(float(v) for v in initial_state_std)
        self.stiffness_std, self.mu_std = float(stiffness_std), float(mu_std)
        self.accel_noise = tuple(float(v) for v in accel_noise)
        self.param_walk = tuple(float(v) for v in param_walk)
        fzf, fzr = vehicle.static_axle_loads
        self._k = np.array(
            [vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr, vehicle.Cf, vehicle.Cr, fzf, fzr, self.tire.shape, self.tire.curvature]
        )
        # Merwe scaled sigma points
        n = N_X
        lam = sigma_alpha**2 * (n + sigma_kappa) - n
        if not n + lam > 0:
            raise ParameterError("sigma-point parameters give n + lambda <= 0")
        self._gamma = math.sqrt(n + lam)
        self._wm = np.full(2 * n + 1, 0.5 / (n + lam))
        self._wc = self._wm.copy()
        self._wm[0] = lam / (n + lam)
        self._wc[0] = lam / (n + lam) + (1.0 - sigma_alpha**2 + sigma_beta)
        self._q = np.array([0.0, self.accel_noise[0], 0.0, self.accel_noise[1], *([self.param_walk[0]] * 2), *([self.param_walk[1]] * 2)])
        self._sig = np.empty((N_SIGMA, N_X))
        self._work = np.empty((5, N_X))
        self._L = np.zeros((N_X, N_X))
        self.reset()

    @classmethod
    def for_camera(cls, vehicle: VehicleParams, camera: CameraParams, floor: tuple[float, float] = (1e-3, 1e-3), **kwargs: Any) -> "JointUKF":
        """Filter whose ``R`` is the camera's noise std (what its spec sheet says), floored."""
        s1, s2 = camera.noise_std
        return cls(vehicle, measurement_std=(max(s1, floor[0]), max(s2, floor[1])), **kwargs)

    # -- estimator verbs (the observer's and the linear Kalman filter's signatures) -------------
    def reset(self, state: ArrayLike | None = None, weights: ArrayLike | None = None) -> "JointUKF":
        """Back to the prior and to the first row of the next :meth:`run`.

        Parameters
        ----------
        state : array_like of 4, optional
            ``[vy [m/s], r [rad/s], e1 [m], e2 [rad]]`` (:class:`~tire_learning_env.observer.model.StateIndex`
            order, as every estimator), converted to the error state at the vehicle's nominal
            speed on a straight path; default 0.
        weights : array_like of 4, optional
            The learned parameters ``[ln(Cf/Cf0), ln(Cr/Cr0), ln mu_f, ln mu_r]``; default the
            nominal stiffness and friction ``tire.mu``.
        """
        x = np.zeros(N_X)
        if state is not None:
            s = np.asarray(state, dtype=float).reshape(4)
            vx = self.vehicle.vx
            x[X_E1] = s[StateIndex.E1]
            x[X_E2] = s[StateIndex.E2]
            x[X_E1_DOT] = s[StateIndex.VY] + vx * s[StateIndex.E2]  # vy = e1_dot - vx e2
            x[X_E2_DOT] = s[StateIndex.R]  # r = e2_dot + psi_dot_des, psi_dot_des = 0
        if weights is None:
            x[X_LOG_MU_F] = x[X_LOG_MU_R] = math.log(self.tire.mu)
        else:
            x[X_LOG_CF:] = np.asarray(weights, dtype=float).reshape(4)
        self.x_ = x
        self.P_ = np.diag(np.array([*self.initial_state_std, self.stiffness_std, self.stiffness_std, self.mu_std, self.mu_std]) ** 2)
        self._u = np.array([0.0, self.vehicle.vx, 0.0, 0.0, 0.0])  # inputs held since the last row (U_*)
        self._started = False
        self._path = None  # (t, kappa) of the last row filtered
        self.t = 0.0
        return self

    @property
    def state(self) -> NDArray:
        """Current ``[vy, r, e1, e2]`` (at the speed and path yaw rate of the last inputs)."""
        x, u = self.x_, self._u
        out = np.empty(4)
        out[StateIndex.VY] = x[X_E1_DOT] - u[U_VX] * x[X_E2]
        out[StateIndex.R] = x[X_E2_DOT] + u[U_PDD]
        out[StateIndex.E1] = x[X_E1]
        out[StateIndex.E2] = x[X_E2]
        return out

    @property
    def weights(self) -> NDArray:
        """Current learned parameters ``[ln(Cf/Cf0), ln(Cr/Cr0), ln mu_f, ln mu_r]``."""
        return self.x_[X_LOG_CF:].copy()

    def predict(self, dt: float | None = None, delta: float = 0.0, vx: float | None = None, kappa: float = 0.0,
                ax: float = 0.0, kappa_rate: float = 0.0) -> "JointUKF":  # fmt: skip
        """Unscented predict over ``dt`` [s] (default the filter's ``dt``) with the inputs held:
        steering ``delta`` [rad], speed ``vx`` [m/s] (default the vehicle's), path curvature
        ``kappa`` [1/m] and its rate ``kappa_rate`` [1/(m s)], ``ax`` [m/s^2]. The path's yaw
        rate is ``psi_dot_des = vx kappa`` and its derivative ``ax kappa + vx kappa_rate``."""
        dt = self.dt if dt is None else float(dt)
        vx = self.vehicle.vx if vx is None else float(vx)
        if not vx > 0:
            raise ValueError(f"vx must be > 0, got {vx!r}")
        pdd, pddd = vx * float(kappa), float(ax) * float(kappa) + vx * float(kappa_rate)
        ukf_predict(
            self.x_, self.P_, self._q, dt, float(delta), vx, float(ax), pdd, pddd, self._k, self._wm, self._wc,
            self._gamma, self._sig, self._work, self._L,
        )  # fmt: skip
        self._u[:] = (float(delta), vx, float(ax), pdd, pddd)
        self.t += dt
        return self

    def update(self, z: ArrayLike | Mapping[str, float], delta: float = 0.0, vx: float | None = None) -> "JointUKF":
        """Correct with a camera frame now: ``z = [e1 [m], e2 [rad]]``, the four channels
        ``[e1, e2, a_y, r]`` (the IMU channels are not used: the filter is camera-only) or a
        mapping with ``e1``, ``e2``; a frame with a NaN channel is skipped. ``delta`` [rad] and
        ``vx`` [m/s] are the current inputs."""
        if isinstance(z, Mapping):
            z1, z2 = float(z.get("e1", np.nan)), float(z.get("e2", np.nan))
        else:
            zz = np.asarray(z, dtype=float).reshape(-1)
            if zz.size not in (2, N_CHANNELS):
                raise ParameterError(f"z must hold (e1, e2) or (e1, e2, a_y, r), got {zz.size} values")
            z1, z2 = zz[CH_E1], zz[CH_E2]
        if math.isfinite(z1) and math.isfinite(z2):
            xc = float(self.vehicle.camera_x)
            if xc:  # the path's bend over camera_x, at the curvature of the last predict (psi_dot_des / vx)
                z1 += float(camera_path_bend(self._u[U_PDD] / self._u[U_VX], xc))
            ukf_update(self.x_, self.P_, z1, z2, self.measurement_std[0] ** 2, self.measurement_std[1] ** 2, xc)
        self._u[U_DELTA] = float(delta)
        self._u[U_VX] = self.vehicle.vx if vx is None else float(vx)
        self._started = True
        return self

    def run(self, sensors: Mapping[str, ArrayLike] | Any, predict_last: bool = True) -> UKFResult:
        """Filter rows, continuing from the current state (the first call after :meth:`reset`
        starts at the first row, from the prior); the result is also stored as ``result_``.

        Parameters
        ----------
        sensors : mapping or object with ``.sensors``
            Rows ``t, delta, vx, kappa, e1, e2`` (the driving-log format; ``ax`` optional; NaN:
            no frame). The path's yaw rate is ``vx kappa`` and its derivative ``ax kappa + vx
            kappa_rate`` with the backward difference of ``kappa`` (what the observer uses);
            a simulator's rows may carry ``psi_dot_des``, ``psi_ddot_des`` instead of ``kappa``,
            which are then used. Without ``t`` the rows are ``dt`` apart. Ground truth is refused.
        predict_last : bool
            Predict ``dt`` past the last row (where the next call's rows start).

        Raises
        ------
        ParameterError
            A required column is missing, the columns differ in length, ``t`` is not
            increasing, or the log is empty.
        FloatingPointError
            The estimate became non-finite (names the time).
        """
        cols = getattr(sensors, "sensors", sensors)
        if not isinstance(cols, Mapping):
            raise ParameterError(f"sensors must be a mapping of columns, got {type(cols).__name__}")
        path = ("psi_dot_des", "psi_ddot_des") if "kappa" not in cols and "psi_dot_des" in cols else ("kappa",)
        check_sensor_columns(cols, ("delta", "vx", "e1", "e2", *path), "the joint UKF")
        get = lambda key: np.ascontiguousarray(np.asarray(cols[key], dtype=float))  # noqa: E731
        delta, vx = get("delta"), get("vx")
        n = len(delta)
        if n == 0:
            raise ParameterError("the joint UKF got an empty log")
        t = get("t") if "t" in cols else self.t + np.arange(n) * self.dt
        ax = get("ax") if "ax" in cols else np.zeros(n)
        e1, e2 = get("e1"), get("e2")
        if not all(len(c) == n for c in (t, vx, ax, e1, e2)):
            raise ParameterError("sensor columns must have equal lengths")
        if not np.all(vx > 0):
            raise ParameterError("sensor column vx must be > 0 everywhere")
        if n > 1 and not np.all(np.diff(t) > 0):
            raise ParameterError("sensor column t must be strictly increasing")
        if "psi_dot_des" in cols and "psi_ddot_des" in cols:
            pdd, pddd = get("psi_dot_des"), get("psi_ddot_des")
            kappa = get("kappa") if "kappa" in cols else pdd / vx
        else:
            kappa = get("kappa")
            kappa_rate = np.zeros(n)
            kappa_rate[1:] = np.diff(kappa) / np.diff(t)
            if self._started and self._path is not None and t[0] > self._path[0]:  # across calls, as in one
                kappa_rate[0] = (kappa[0] - self._path[1]) / (t[0] - self._path[0])
            pdd, pddd = vx * kappa, ax * kappa + vx * kappa_rate
        xc = float(self.vehicle.camera_x)
        if xc:  # e1 measured camera_x ahead of the CG: the path's bend over camera_x back onto it (ukf_update)
            e1 = e1 + camera_path_bend(kappa, xc)
        t0 = time.perf_counter()
        out_x, out_pd, out_c12, aux = np.empty((n, N_X)), np.empty((n, N_X)), np.empty(n), np.empty((n, 4))
        out_nu, out_nis = np.full((n, 2), np.nan), np.full(n, np.nan)
        t_now = self.t if self._started else float(t[0])
        dt_last = float(t[-1] - t[-2]) if n > 1 else self.dt
        done, t_end = ukf_run_rows(
            self.x_, self.P_, self._q, self.measurement_std[0] ** 2, self.measurement_std[1] ** 2, t, delta, vx, ax,
            pdd, pddd, e1, e2, self._k, self._wm, self._wc, self._gamma, self._u, t_now, dt_last, bool(predict_last),
            out_x, out_pd, out_c12, aux, out_nu, out_nis, xc,
        )  # fmt: skip
        if done < n:
            raise FloatingPointError(f"UKF estimate became non-finite at t={t[done]:.4f} s: {dict(zip(STATE_NAMES, out_x[done]))}")
        self.t, self._started = float(t_end), True
        self._path = (float(t[-1]), float(kappa[-1]))  # the backward difference of the next call's first row
        self.result_ = self._result(t, vx, kappa, pdd, out_x, out_pd, out_c12, aux, out_nu, out_nis, time.perf_counter() - t0)
        return self.result_

    def _result(self, t, vx, kappa, pdd, out_x, out_pd, out_c12, aux, out_nu, out_nis, runtime) -> UKFResult:
        n = len(t)
        xi = out_x[:, :N_ERR]
        state = np.empty((n, 4))
        state[:, StateIndex.VY] = xi[:, X_E1_DOT] - vx * xi[:, X_E2]
        state[:, StateIndex.R] = xi[:, X_E2_DOT] + pdd
        state[:, StateIndex.E1] = xi[:, X_E1]
        state[:, StateIndex.E2] = xi[:, X_E2]
        var = np.empty((n, 4))  # vy = e1_dot - vx e2: its variance takes the covariance of e1_dot and e2
        var[:, StateIndex.VY] = out_pd[:, X_E1_DOT] + vx**2 * out_pd[:, X_E2] - 2.0 * vx * out_c12
        var[:, StateIndex.R] = out_pd[:, X_E2_DOT]
        var[:, StateIndex.E1] = out_pd[:, X_E1]
        var[:, StateIndex.E2] = out_pd[:, X_E2]
        slip, force = aux[:, :2].copy(), aux[:, 2:].copy()
        innovation = np.full((n, N_CHANNELS), np.nan)
        innovation[:, [CH_E1, CH_E2]] = out_nu
        params = np.column_stack([self.vehicle.Cf * np.exp(out_x[:, X_LOG_CF]), self.vehicle.Cr * np.exp(out_x[:, X_LOG_CR]),
                                  np.exp(out_x[:, X_LOG_MU_F]), np.exp(out_x[:, X_LOG_MU_R])])  # fmt: skip
        meta = {"estimator": "joint_ukf", "weights": "ln(Cf/Cf0), ln(Cr/Cr0), ln mu_f, ln mu_r",
                "health": "not assessed: the joint UKF has no health test (every row reads ok)"}  # fmt: skip
        return UKFResult(
            t.copy(), state, slip, force, force - slip * 2.0 * np.array([self.vehicle.Cf, self.vehicle.Cr]),
            out_x[:, X_LOG_CF:].copy(), np.sqrt(np.maximum(var, 0.0)), np.zeros(n, dtype=np.int8), innovation, out_nis,
            vx.copy(), kappa.copy(), ("vy", "yaw_rate", "e1", "e2"), meta,
            params=params, filter_std=np.sqrt(np.maximum(out_pd, 0.0)), error_state=xi.copy(),
            axle_loads=self.vehicle.static_axle_loads, shape=self.tire.shape, curvature=self.tire.curvature, runtime_s=runtime,
        )  # fmt: skip

    # -- learned tire ---------------------------------------------------------------------
    def cornering_stiffness(self) -> tuple[float, float]:
        """Current per-tire cornering stiffness estimate (front, rear) [N/rad]."""
        return float(self.vehicle.Cf * math.exp(self.x_[X_LOG_CF])), float(self.vehicle.Cr * math.exp(self.x_[X_LOG_CR]))

    def peak_friction(self) -> tuple[float, float]:
        """Current peak-friction estimate (front, rear) [-]."""
        return float(math.exp(self.x_[X_LOG_MU_F])), float(math.exp(self.x_[X_LOG_MU_R]))

    def axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Total axle lateral force [N] of the learned curve at slip(s) ``alpha`` [rad]; ``axle`` in {"front", "rear"}."""
        if axle not in ("front", "rear"):
            raise ParameterError(f"axle must be 'front' or 'rear', got {axle!r}")
        i = 0 if axle == "front" else 1
        fz = self.vehicle.static_axle_loads[i]
        return pacejka_axle_force(alpha, self.cornering_stiffness()[i], self.peak_friction()[i], fz, self.tire.shape, self.tire.curvature)


def run_ukf_baseline(
    sensors: Mapping[str, ArrayLike] | Any,
    nominal_vehicle: VehicleParams,
    camera: CameraParams,
    dt: float | None = None,
    **kwargs: Any,
) -> UKFResult:
    """The baseline as the studies run it: :meth:`JointUKF.for_camera` on ``nominal_vehicle``, then :meth:`JointUKF.run`.

    Parameters
    ----------
    sensors : mapping or object with ``.sensors``
        The sensor log (never truth).
    nominal_vehicle : VehicleParams
        What the filter assumes (initial ``Cf``, ``Cr``).
    camera : CameraParams
        The camera spec (noise std for ``R``).
    dt : float, optional
        The filter's default step [s] (:meth:`JointUKF.predict`; rows without ``t``); default
        the median spacing of the log's ``t``.
    **kwargs
        Further :class:`JointUKF` settings.
    """
    cols = getattr(sensors, "sensors", sensors)
    if dt is None:
        t = np.asarray(cols["t"], dtype=float) if isinstance(cols, Mapping) and "t" in cols else None
        dt = float(np.median(np.diff(t))) if t is not None and len(t) > 1 else 1e-3
    return JointUKF.for_camera(nominal_vehicle, camera, dt=dt, **kwargs).run(cols)
