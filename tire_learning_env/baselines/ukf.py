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

- Predict (every physics tick, default 1 kHz): scaled unscented transform (Merwe:
  ``alpha=1, beta=2, kappa=0`` -> all weights >= 0) of a classical RK4 step of the model,
  inputs ``delta``, ``vx``, ``ax``, ``psi_dot_des``, ``psi_ddot_des`` held over the tick;
  additive process noise ``Q = diag(q) dt``.
- Update (whenever a camera frame arrived, any rate): ``z = [e1, e2]`` is linear in the
  state, so the unscented update equals the Kalman update, which is used (exact).

Inputs are the ``sensor_log`` rows only (``t, delta, vx, ax, kappa, psi_dot_des,
psi_ddot_des, e1, e2``; NaN = no frame): never ground truth. Camera latency is not
compensated. The compiled kernels (:func:`ukf_predict`, :func:`ukf_update`,
:func:`ukf_run_log`) are the single implementation behind :meth:`JointUKF.predict`,
:meth:`JointUKF.update` and :meth:`JointUKF.run`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from ..params import CameraParams, ParameterError, TireParams, VehicleParams

__all__ = ["JointUKF", "UKFResult", "run_ukf_baseline", "pacejka_axle_force", "PARAM_NAMES", "STATE_NAMES"]

STATE_NAMES = ("e1", "e1_dot", "e2", "e2_dot", "log_cf", "log_cr", "log_mu_f", "log_mu_r")
PARAM_NAMES = ("Cf", "Cr", "mu_f", "mu_r")
# filter state (STATE_NAMES): the error state (dynamics.StateIndex's order), then the log-parameters
X_E1, X_E1_DOT, X_E2, X_E2_DOT, X_LOG_CF, X_LOG_CR, X_LOG_MU_F, X_LOG_MU_R = range(8)
N_ERR = 4  # the error-state prefix
N_X = 8
N_SIGMA = 2 * N_X + 1
# constants vector
K_M, K_IZ, K_LF, K_LR, K_CF0, K_CR0, K_FZF, K_FZR, K_CS, K_E = range(10)
N_CONST = 10
_REQUIRED = ("delta", "vx", "psi_dot_des", "psi_ddot_des", "e1", "e2")


@njit(cache=True)
def _axle_force(alpha, stiffness, peak, cs, e):
    """Pacejka axle force [N] with slope ``stiffness`` [N/rad] at zero slip and peak ``peak`` [N]."""
    b = stiffness / (cs * peak)
    x = b * alpha
    return peak * math.sin(cs * math.atan(x - e * (x - math.atan(x))))


@njit(cache=True)
def _forces(s, delta, vx, pdd, k):
    """Slips (eq. 13) and axle forces of filter state ``s`` -> ``(af, ar, Ff, Fr)``."""
    lf, lr = k[K_LF], k[K_LR]
    vy = s[X_E1_DOT] - vx * s[X_E2]
    r = s[X_E2_DOT] + pdd
    af = delta - (vy + lf * r) / vx
    ar = (lr * r - vy) / vx
    ff = _axle_force(af, 2.0 * k[K_CF0] * math.exp(s[X_LOG_CF]), math.exp(s[X_LOG_MU_F]) * k[K_FZF], k[K_CS], k[K_E])
    fr = _axle_force(ar, 2.0 * k[K_CR0] * math.exp(s[X_LOG_CR]), math.exp(s[X_LOG_MU_R]) * k[K_FZR], k[K_CS], k[K_E])
    return af, ar, ff, fr


@njit(cache=True)
def _rhs(s, delta, vx, ax, pdd, pddd, k, out):
    _, _, ff, fr = _forces(s, delta, vx, pdd, k)
    out[X_E1] = s[X_E1_DOT]
    out[X_E1_DOT] = (ff + fr) / k[K_M] - vx * pdd + ax * s[X_E2]
    out[X_E2] = s[X_E2_DOT]
    out[X_E2_DOT] = (k[K_LF] * ff - k[K_LR] * fr) / k[K_IZ] - pddd
    for i in range(X_LOG_CF, N_X):
        out[i] = 0.0


@njit(cache=True)
def _rk4(s, dt, delta, vx, ax, pdd, pddd, k, work):
    """In place RK4 step of the (deterministic part of the) model; ``work`` (5, N_X)."""
    k1, k2, k3, k4, y = work[0], work[1], work[2], work[3], work[4]
    _rhs(s, delta, vx, ax, pdd, pddd, k, k1)
    vm = vx + 0.5 * dt * ax
    for i in range(N_X):
        y[i] = s[i] + 0.5 * dt * k1[i]
    _rhs(y, delta, vm, ax, pdd, pddd, k, k2)
    for i in range(N_X):
        y[i] = s[i] + 0.5 * dt * k2[i]
    _rhs(y, delta, vm, ax, pdd, pddd, k, k3)
    for i in range(N_X):
        y[i] = s[i] + dt * k3[i]
    _rhs(y, delta, vx + dt * ax, ax, pdd, pddd, k, k4)
    for i in range(N_X):
        s[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def _cholesky(P, L):
    """Lower Cholesky factor of symmetric ``P`` into ``L``; non-positive pivots are floored."""
    n = P.shape[0]
    for j in range(n):
        d = P[j, j]
        for m in range(j):
            d -= L[j, m] * L[j, m]
        if d < 1e-30:
            d = 1e-30
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            v = P[i, j]
            for m in range(j):
                v -= L[i, m] * L[j, m]
            L[i, j] = v / L[j, j]
        for i in range(j):
            L[i, j] = 0.0


@njit(cache=True)
def ukf_predict(x, P, q, dt, delta, vx, ax, pdd, pddd, k, wm, wc, gamma, sig, work, L):
    """Unscented predict over ``dt`` [s], in place on ``x`` (N_X,) and ``P`` (N_X, N_X).

    ``q`` (N_X,): process-noise intensities (``Q = diag(q) dt``); ``wm``, ``wc`` the
    sigma-point weights, ``gamma = sqrt(n + lambda)``; ``sig`` (N_SIGMA, N_X), ``work``
    (5, N_X) and ``L`` (N_X, N_X) are scratch.
    """
    n = N_X
    _cholesky(P, L)
    for i in range(n):
        sig[0, i] = x[i]
    for j in range(n):
        for i in range(n):
            sig[1 + j, i] = x[i] + gamma * L[i, j]
            sig[1 + n + j, i] = x[i] - gamma * L[i, j]
    for p in range(2 * n + 1):
        _rk4(sig[p], dt, delta, vx, ax, pdd, pddd, k, work)
    for i in range(n):
        acc = 0.0
        for p in range(2 * n + 1):
            acc += wm[p] * sig[p, i]
        x[i] = acc
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for p in range(2 * n + 1):
                acc += wc[p] * (sig[p, i] - x[i]) * (sig[p, j] - x[j])
            P[i, j] = acc
            P[j, i] = acc
        P[i, i] += q[i] * dt


@njit(cache=True)
def ukf_update(x, P, z1, z2, r1, r2):
    """Kalman update with the camera frame ``z = [e1, e2]`` (variances ``r1``, ``r2``), in place."""
    n = N_X
    s11 = P[X_E1, X_E1] + r1
    s12 = P[X_E1, X_E2]
    s22 = P[X_E2, X_E2] + r2
    det = s11 * s22 - s12 * s12
    i11, i12, i22 = s22 / det, -s12 / det, s11 / det
    y1, y2 = z1 - x[X_E1], z2 - x[X_E2]
    Kg = np.empty((n, 2))
    for i in range(n):
        Kg[i, 0] = P[i, X_E1] * i11 + P[i, X_E2] * i12
        Kg[i, 1] = P[i, X_E1] * i12 + P[i, X_E2] * i22
    for i in range(n):
        x[i] += Kg[i, 0] * y1 + Kg[i, 1] * y2
    # P <- P - K S K^T = P - K [P(0,:); P(2,:)]
    row0 = P[X_E1].copy()
    row2 = P[X_E2].copy()
    for i in range(n):
        for j in range(n):
            P[i, j] -= Kg[i, 0] * row0[j] + Kg[i, 1] * row2[j]
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@njit(cache=True)
def ukf_run_log(x, P, q, r1, r2, dt, delta, vx, ax, pdd, pddd, e1, e2, k, wm, wc, gamma, out_x, out_pd, out_aux):
    """Filter a whole sensor log (row ``j`` = instant ``t_j``); fills the posteriors at each ``t_j``.

    Per row: update with the frame delivered at ``t_j`` (if not NaN), record, then predict
    to ``t_{j+1}`` with the row's inputs. ``out_aux`` (n, 4) = estimated ``af, ar, Ff, Fr``.
    Returns the number of rows done (< n if the estimate became non-finite).
    """
    n = delta.shape[0]
    sig = np.empty((N_SIGMA, N_X))
    work = np.empty((5, N_X))
    L = np.zeros((N_X, N_X))
    for j in range(n):
        if e1[j] == e1[j] and e2[j] == e2[j]:
            ukf_update(x, P, e1[j], e2[j], r1, r2)
        for i in range(N_X):
            out_x[j, i] = x[i]
            out_pd[j, i] = P[i, i]
        af, ar, ff, fr = _forces(x, delta[j], vx[j], pdd[j], k)
        out_aux[j, 0] = af
        out_aux[j, 1] = ar
        out_aux[j, 2] = ff
        out_aux[j, 3] = fr
        ok = True
        for i in range(N_X):
            if not math.isfinite(x[i]):
                ok = False
        if not ok:
            return j
        ukf_predict(x, P, q, dt, delta[j], vx[j], ax[j], pdd[j], pddd[j], k, wm, wc, gamma, sig, work, L)
    return n


def pacejka_axle_force(alpha: ArrayLike, stiffness: float, mu: float, fz: float, shape: float, curvature: float) -> NDArray:
    """The filter's axle curve [N]: Magic Formula with slope ``2 stiffness`` at zero and peak ``mu fz``.

    ``stiffness`` per tire [N/rad], ``fz`` static axle load [N], ``shape`` ``Cs``, ``curvature`` ``E``.
    """
    d = mu * fz
    b = 2.0 * stiffness / (shape * d)
    x = b * np.asarray(alpha, dtype=float)
    return d * np.sin(shape * np.arctan(x - curvature * (x - np.arctan(x))))


@dataclass
class UKFResult:
    """Per-tick output of :meth:`JointUKF.run` (row ``j`` = posterior at ``t_j``).

    Attributes
    ----------
    t : ndarray, shape (n,)
    xi : ndarray, shape (n, 4)
        Estimated ``[e1, e1_dot, e2, e2_dot]``.
    slip : ndarray, shape (n, 2)
        Estimated axle slips (eq. 13) [rad].
    force : ndarray, shape (n, 2)
        Estimated total axle lateral forces at the estimated slips [N].
    params : ndarray, shape (n, 4)
        ``Cf``, ``Cr`` (per tire) [N/rad], ``mu_f``, ``mu_r`` [-] over time.
    std : ndarray, shape (n, 8)
        Posterior standard deviations of the filter state (log-parameters for the last 4).
    axle_loads : (float, float)
        Static axle loads of the nominal vehicle [N] (the curve's ``F_z``).
    shape, curvature : float
        The curve's fixed ``Cs`` and ``E``.
    runtime_s : float
        Wall time of the run [s].
    """

    t: NDArray
    xi: NDArray
    slip: NDArray
    force: NDArray
    params: NDArray
    std: NDArray
    axle_loads: tuple[float, float]
    shape: float
    curvature: float
    runtime_s: float = float("nan")

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
        Predict step [s] (the physics tick of the sensor log).
    tire : TireParams, optional
        Fixed Pacejka shape ``Cs`` and curvature ``E`` and the initial friction ``mu``.
    measurement_std : (float, float)
        Camera noise standard deviations of ``e1`` [m] and ``e2`` [rad] (``R``). Use
        :meth:`for_camera` to take them from a camera spec (with a floor).
    initial_state_std : (4 floats)
        Prior std of ``xi`` (the prior mean is zero, or ``xi0`` in :meth:`reset`).
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

    # -- estimator verbs ----------------------------------------------------------------
    def reset(self, xi0: ArrayLike | None = None) -> "JointUKF":
        """Back to the prior: ``xi0`` (default 0), nominal stiffness, friction ``tire.mu``."""
        x = np.zeros(N_X)
        if xi0 is not None:
            x[:N_ERR] = np.asarray(xi0, dtype=float).reshape(N_ERR)
        x[X_LOG_MU_F] = x[X_LOG_MU_R] = math.log(self.tire.mu)
        self.x_ = x
        self.P_ = np.diag(np.array([*self.initial_state_std, self.stiffness_std, self.stiffness_std, self.mu_std, self.mu_std]) ** 2)
        return self

    def predict(self, delta: float, vx: float, psi_dot_des: float, psi_ddot_des: float, ax: float = 0.0, dt: float | None = None) -> "JointUKF":
        """Unscented predict over ``dt`` (default the filter's) with inputs held [rad, m/s, rad/s, rad/s^2, m/s^2]."""
        if not vx > 0:
            raise ValueError(f"vx must be > 0, got {vx!r}")
        ukf_predict(
            self.x_, self.P_, self._q, self.dt if dt is None else float(dt), float(delta), float(vx), float(ax),
            float(psi_dot_des), float(psi_ddot_des), self._k, self._wm, self._wc, self._gamma, self._sig, self._work, self._L,
        )  # fmt: skip
        return self

    def update(self, z: ArrayLike) -> "JointUKF":
        """Correct with a camera frame ``z = [e1 [m], e2 [rad]]``; a NaN frame is skipped."""
        z = np.asarray(z, dtype=float).reshape(2)
        if np.all(np.isfinite(z)):
            r1, r2 = self.measurement_std[0] ** 2, self.measurement_std[1] ** 2
            ukf_update(self.x_, self.P_, z[0], z[1], r1, r2)
        return self

    def run(self, sensor_log: Mapping[str, ArrayLike] | Any) -> UKFResult:
        """Filter a whole sensor log from the prior (see :meth:`reset`); also stored as ``result_``.

        Parameters
        ----------
        sensor_log : mapping or object with ``.sensors``
            Per-tick rows ``t, delta, vx, ax, psi_dot_des, psi_ddot_des, e1, e2`` (``ax``
            optional). Only these keys are read; a log object's ``truth`` is never touched.

        Raises
        ------
        ParameterError
            A required column is missing or the log is empty.
        FloatingPointError
            The estimate became non-finite (names the time).
        """
        cols = getattr(sensor_log, "sensors", sensor_log)
        if not isinstance(cols, Mapping):
            raise ParameterError(f"sensor_log must be a mapping of columns, got {type(cols).__name__}")
        missing = [k for k in _REQUIRED if k not in cols]
        if missing:
            raise ParameterError(f"sensor_log is missing column(s) {missing}")
        get = lambda key: np.ascontiguousarray(np.asarray(cols[key], dtype=float))  # noqa: E731
        delta, vx = get("delta"), get("vx")
        n = len(delta)
        if n == 0:
            raise ParameterError("sensor_log is empty")
        if not np.all(vx > 0):
            raise ParameterError("sensor_log column vx must be > 0 everywhere")
        ax = get("ax") if "ax" in cols else np.zeros(n)
        t = get("t") if "t" in cols else np.arange(n) * self.dt
        self.reset()
        t0 = time.perf_counter()
        out_x = np.empty((n, N_X))
        out_pd = np.empty((n, N_X))
        aux = np.empty((n, 4))
        done = ukf_run_log(
            self.x_, self.P_, self._q, self.measurement_std[0] ** 2, self.measurement_std[1] ** 2, self.dt,
            delta, vx, ax, get("psi_dot_des"), get("psi_ddot_des"), get("e1"), get("e2"),
            self._k, self._wm, self._wc, self._gamma, out_x, out_pd, aux,
        )  # fmt: skip
        if done < n:
            raise FloatingPointError(f"UKF estimate became non-finite at t={t[done]:.4f} s: {dict(zip(STATE_NAMES, out_x[done]))}")
        params = np.column_stack(
            [self.vehicle.Cf * np.exp(out_x[:, X_LOG_CF]), self.vehicle.Cr * np.exp(out_x[:, X_LOG_CR]), np.exp(out_x[:, X_LOG_MU_F]),
             np.exp(out_x[:, X_LOG_MU_R])]
        )
        self.result_ = UKFResult(
            t=t, xi=out_x[:, :N_ERR], slip=aux[:, :2], force=aux[:, 2:], params=params, std=np.sqrt(np.maximum(out_pd, 0.0)),
            axle_loads=self.vehicle.static_axle_loads, shape=self.tire.shape, curvature=self.tire.curvature,
            runtime_s=time.perf_counter() - t0,
        )  # fmt: skip
        return self.result_

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
        Tick [s]; default the median spacing of the log's ``t``.
    **kwargs
        Further :class:`JointUKF` settings.
    """
    cols = getattr(sensors, "sensors", sensors)
    if dt is None:
        t = np.asarray(cols["t"], dtype=float) if isinstance(cols, Mapping) and "t" in cols else None
        dt = float(np.median(np.diff(t))) if t is not None and len(t) > 1 else 1e-3
    return JointUKF.for_camera(nominal_vehicle, camera, dt=dt, **kwargs).run(cols)
