"""Predictive lateral-acceleration safety filter for a steering offset on top of the driver.

An excitation policy commands a steering offset ``u`` [rad] that the car adds to its
lane-keeping driver for the next policy step. Because the lateral dynamics have momentum,
``a_y`` keeps building after the offset is reduced, and the car's tires (the very thing
being learned) may be stiffer than assumed. :class:`LateralAccelerationFilter` replaces
the requested offset by the nearest offset for which a *safe continuation* exists: the
predicted ``|a_y|`` stays below ``ay_limit - margin`` over a horizon at **every corner**
of the tire-stiffness uncertainty box, when ``u`` is held for one policy step and then a backup
is applied (the offset released to zero, or held).

Prediction model (everything a car knows)
-----------------------------------------
The nominal linear bicycle model in error coordinates (SPEC §1, eqs. 7-8, 13) closed with
the car's own lane-keeping law (:mod:`tire_learning_env.driver`,
``delta = g_ff kappa - k (e1 + vx T_la e2) - k_i z + u``, ``z_dot = e1``), from the
observer's state estimate and the driver's integral state, at the current speed and road
curvature. The model lets the driver see the true state continuously; the real driver holds
noisy camera frames (30 Hz in the excitation env), which the margin and the per-tick guard
below cover. On the highway, the driver's curvature preview and lane-change reference are
not modelled. The lateral acceleration the IMU measures is
``a_y = (2 C_f alpha_f + 2 C_r alpha_r) / m`` (eq. 13 slips), linear in the state and
input, so over the horizon ``a_y(t_k) = f_k + g_k u`` for each backup and each corner of
the stiffness box ``C_i in [(1 - s) C_i, (1 + s) C_i]``: the admissible offsets are an
interval per (corner, backup), intersected over the corners and united over the backups.
a_y is not linear in the stiffness, so a point inside the box could be worse than every
corner; ``benchmarks/bench_safety_filter.py`` re-predicts decisions on a 9 x 9 grid over the
box and found none.
Linear tires over-predict the force of a saturating tire at the same slip, so tire
saturation errs on the safe side.

With ``lane_margin`` set, the same prediction also keeps ``|e1|`` inside the lane margin
(the error state's first component; the constraint is again affine in ``u``).

Recursive feasibility: a step accepted with backup "release" can always be followed by
``u = 0`` (whose own backup is the same trajectory), one accepted with backup "hold" by the
same ``u``; so, within the horizon (there is no terminal constraint beyond it), the filter
never has to choose between two unsafe options while the model holds. The filter limits what the policy *adds* to the driver: where the driver alone
(``u = 0``) is already predicted beyond a limit (a curve that needs more, or a model error),
the offset may not make any predicted sample worse there, and ``u = 0`` is always
admissible, so this filter never counter-steers against the driver's path following (only
the per-tick guard below clamps the total steering, at the limit itself).

Second layer: the per-tick IMU guard
------------------------------------
Within a policy step the driver reacts to each noisy camera frame, which the step-level
prediction cannot see. :meth:`~tire_learning_env.driver.LaneKeepingDriver.set_ay_guard`
clamps, at every physics tick, the change of the total steering so that the last IMU
``a_y`` plus the change times the (uncertain) instantaneous steering-to-``a_y`` gain
``2 C_f / m`` stays within the limit (:func:`~tire_learning_env._kernels.guard_steering`).
:class:`~tire_learning_env.wrappers.excitation.ExcitationWrapper` turns both layers on with
``ExcitationConfig.safety_filter``; the guard acts on the last reading, so ``a_y`` may move
on by one tick of the lateral dynamics (``safety_tick_margin`` leaves that room). It relies
on the front tire's instantaneous force response: with a tire relaxation length
(``PlantEffects.relaxation_length``) the steering-to-``a_y`` gain of one tick is near zero and
the guard no longer bounds ``a_y``. While it clamps, the driver's integral keeps running.

Margin
------
The driver reacts to every noisy camera frame, which moves the steering (and through the
front tire, ``a_y``) within a policy step where the filter cannot act. The margin is
``noise_sigmas`` standard deviations of that instantaneous ``a_y`` response (so the guard
rarely has to act):
``sigma = (1 + s) 2 C_f / m * k sqrt(sigma_e1^2 + (vx T_la sigma_e2)^2)``.

>>> from tire_learning_env.params import CameraParams, DriverParams, VehicleParams
>>> filt = LateralAccelerationFilter(VehicleParams(), DriverParams(), ay_limit=4.0,
...                                  dt_step=0.05, camera=CameraParams())
>>> import numpy as np
>>> filt.filter(0.05, np.zeros(4), 0.0, vx=30.0, kappa=0.0) < 0.05   # a full offset from rest is too much
True
>>> filt.filter(0.001, np.zeros(4), 0.0, vx=30.0, kappa=0.0)         # a small one passes unchanged
0.001
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

from ..dynamics import error_state_matrices
from ..params import CameraParams, DriverParams, ParameterError, VehicleParams

__all__ = ["LateralAccelerationFilter", "FilterDecision", "camera_noise_std"]


def camera_noise_std(camera: CameraParams) -> tuple[float, float]:
    """Standard deviation of the camera's ``e1`` [m] and ``e2`` [rad] noise."""
    if camera.noise == "none":
        return 0.0, 0.0
    if camera.noise == "uniform":
        return camera.e1_noise / math.sqrt(3.0), camera.e2_noise / math.sqrt(3.0)
    return float(camera.e1_noise), float(camera.e2_noise)


@dataclass(frozen=True)
class FilterDecision:
    """What the filter did in one step.

    Attributes
    ----------
    requested, applied : float
        Steering offsets [rad].
    predicted_peak, predicted_max_e1 : float
        Worst-case predicted ``|a_y|`` [m/s^2] and ``|e1|`` [m] over the vertices for the
        applied offset, with the backup that keeps the plan furthest inside the limits.
    driver_beyond_limit : bool
        True when the driver alone (zero offset) is predicted beyond the filter's ``a_y``
        bound (``ay_limit`` minus the margin) at some stiffness corner: the offset was then
        only kept from making any predicted sample worse.
    """

    requested: float
    applied: float
    predicted_peak: float
    predicted_max_e1: float
    driver_beyond_limit: bool

    @property
    def active(self) -> bool:
        """True when the filter changed the offset."""
        return self.applied != self.requested


class LateralAccelerationFilter:
    """Robust predictive ``|a_y|`` filter for a steering offset (module docstring).

    Parameters
    ----------
    vehicle : VehicleParams
        Nominal vehicle (mass, inertia, geometry, per-tire stiffness ``Cf``, ``Cr``).
    driver : DriverParams
        The car's lane-keeping law (gains).
    ay_limit : float
        Lateral-acceleration limit [m/s^2].
    dt_step : float
        Policy step [s]: how long a requested offset is held.
    camera : CameraParams
        The lane camera (its noise sets the margin).
    stiffness_uncertainty : float
        Relative half-width ``s`` of the per-axle stiffness box [-] (0.2: +/-20 %).
    horizon : float
        Prediction horizon [s].
    noise_sigmas : float
        Margin in standard deviations of the frame-noise ``a_y`` response [-].
    dt_predict : float
        Prediction grid [s] (a divisor of ``dt_step``).
    lane_margin : float, optional
        Also keep the predicted ``|e1|`` below ``lane_margin`` minus ``noise_sigmas``
        camera ``e1`` noise standard deviations [m] (``None``: ``a_y`` only).
    """

    BACKUPS = ("release", "hold")

    def __init__(
        self,
        vehicle: VehicleParams,
        driver: DriverParams,
        ay_limit: float,
        dt_step: float,
        camera: CameraParams,
        stiffness_uncertainty: float = 0.2,
        horizon: float = 2.0,
        noise_sigmas: float = 2.0,
        dt_predict: float = 0.005,
        lane_margin: float | None = None,
    ) -> None:
        if not ay_limit > 0:
            raise ParameterError(f"ay_limit must be > 0, got {ay_limit!r}")
        if not 0.0 <= stiffness_uncertainty < 1.0:
            raise ParameterError(f"stiffness_uncertainty must be in [0, 1), got {stiffness_uncertainty!r}")
        if not horizon >= dt_step > 0:
            raise ParameterError(f"need horizon >= dt_step > 0, got horizon={horizon!r}, dt_step={dt_step!r}")
        if lane_margin is not None and not lane_margin > 0:
            raise ParameterError(f"lane_margin must be > 0 or None, got {lane_margin!r}")
        if not noise_sigmas >= 0:
            raise ParameterError(f"noise_sigmas must be >= 0, got {noise_sigmas!r}")
        n_hold = dt_step / dt_predict
        if not dt_predict > 0 or abs(n_hold - round(n_hold)) > 1e-6:
            raise ParameterError(f"dt_predict must divide dt_step, got dt_predict={dt_predict!r}, dt_step={dt_step!r}")
        self.vehicle = vehicle
        self.driver = driver
        self.ay_limit = float(ay_limit)
        self.dt_step = float(dt_step)
        self.camera = camera
        self.stiffness_uncertainty = float(stiffness_uncertainty)
        self.horizon = float(horizon)
        self.noise_sigmas = float(noise_sigmas)
        self.dt_predict = float(dt_predict)
        self.lane_margin = None if lane_margin is None else float(lane_margin)
        self.n_hold = int(round(n_hold))
        self.n_horizon = max(self.n_hold, int(round(horizon / dt_predict)))
        if not self.margin(vehicle.vx) < self.ay_limit:
            raise ParameterError(
                f"the camera-noise margin {self.margin(vehicle.vx):.3f} m/s^2 (noise_sigmas={noise_sigmas}) "
                f"is not below ay_limit={ay_limit} m/s^2"
            )
        s = self.stiffness_uncertainty
        self.vertices: tuple[tuple[float, float], ...] = tuple(
            (sf, sr) for sf in (1.0 - s, 1.0 + s) for sr in (1.0 - s, 1.0 + s)
        ) if s > 0 else ((1.0, 1.0),)  # fmt: skip
        self._cache: dict[float, tuple[NDArray, NDArray, NDArray]] = {}

    # -- model ---------------------------------------------------------------------------
    def margin(self, vx: float) -> float:
        """``noise_sigmas`` standard deviations of the frame-noise ``a_y`` [m/s^2] (module docstring)."""
        s1, s2 = camera_noise_std(self.camera)
        d = self.driver
        sigma_delta = d.gain * math.hypot(s1, vx * d.lookahead_time * s2)
        cf2_max = 2.0 * self.vehicle.Cf * (1.0 + self.stiffness_uncertainty)
        return self.noise_sigmas * cf2_max / self.vehicle.m * sigma_delta

    def lane_safety_margin(self) -> float:
        """``noise_sigmas`` standard deviations of the camera's ``e1`` noise [m]."""
        return self.noise_sigmas * camera_noise_std(self.camera)[0]

    def _closed_loop(self, vx: float, scale_f: float, scale_r: float):
        """Continuous closed loop ``s_dot = Acl s + Bu u + Bk kappa``, ``a_y = Cy s + Dy u + Ey kappa``."""
        veh = self.vehicle.replace(Cf=self.vehicle.Cf * scale_f, Cr=self.vehicle.Cr * scale_r)
        A, B1, B2, _, _, _ = error_state_matrices(veh, vx)
        d = self.driver
        L = veh.wheelbase
        nominal = self.vehicle  # the driver's feed-forward uses the nominal model
        e2_per_kappa = -nominal.lr + nominal.lf * nominal.m * vx * vx / (2.0 * nominal.Cr * L)
        g_ff = L + nominal.understeer_gradient * vx * vx + d.gain * vx * d.lookahead_time * e2_per_kappa
        # delta = Kd s + u + g_ff kappa, s = [e1, e1_dot, e2, e2_dot, z]
        Kd = np.array([-d.gain, 0.0, -d.gain * vx * d.lookahead_time, 0.0, -d.integral_gain])
        Acl = np.zeros((5, 5))
        Acl[:4, :4] = A
        Acl[:4, :] += np.outer(B1, Kd)
        Acl[4, 0] = 1.0
        Bu = np.append(B1, 0.0)
        Bk = np.append(B1 * g_ff + B2 * vx, 0.0)  # psi_dot_des = vx kappa
        # a_y = (cf2 alpha_f + cr2 alpha_r)/m with eq. (13) slips and psi_dot_des = vx kappa
        cf2, cr2, m = 2.0 * veh.Cf, 2.0 * veh.Cr, veh.m
        lf, lr = veh.lf, veh.lr
        slip_f = np.array([0.0, -1.0 / vx, 1.0, -lf / vx, 0.0])
        slip_r = np.array([0.0, -1.0 / vx, 1.0, lr / vx, 0.0])
        Cy = (cf2 * (slip_f + Kd) + cr2 * slip_r) / m
        Dy = cf2 / m
        Ey = (cf2 * (g_ff - lf) + cr2 * lr) / m
        return Acl, Bu, Bk, Cy, Dy, Ey

    def _response(self, vx: float) -> tuple[NDArray, NDArray, NDArray]:
        """Per vertex: ``a_y`` over the horizon as ``M s0 + q kappa + G[backup] u`` (cached per speed)."""
        key = max(round(float(vx), 1), 0.1)
        if key in self._cache:
            return self._cache[key]
        n, h = self.n_horizon, self.dt_predict
        nv = len(self.vertices)
        # outputs: a_y (rows 0..n-1) and e1 (rows n..2n-1)
        M = np.empty((nv, 2 * n, 5))
        q = np.empty((nv, 2 * n))
        G = np.empty((nv, len(self.BACKUPS), 2 * n))
        for v, (sf, sr) in enumerate(self.vertices):
            Acl, Bu, Bk, Cy, Dy, Ey = self._closed_loop(key, sf, sr)
            # exact zero-order-hold discretisation of [s; u; kappa]
            aug = np.zeros((7, 7))
            aug[:5, :5], aug[:5, 5], aug[:5, 6] = Acl, Bu, Bk
            E = expm(aug * h)
            Ad, Bud, Bkd = E[:5, :5], E[:5, 5], E[:5, 6]
            phi = np.eye(5)  # state transition to sample k
            su = {b: np.zeros(5) for b in self.BACKUPS}  # state response to u
            sk = np.zeros(5)  # state response to kappa
            for k in range(n):
                M[v, k], M[v, n + k] = Cy @ phi, phi[0]
                q[v, k], q[v, n + k] = Cy @ sk + Ey, sk[0]
                for j, b in enumerate(self.BACKUPS):
                    on = k < self.n_hold or b == "hold"
                    G[v, j, k] = Cy @ su[b] + (Dy if on else 0.0)
                    G[v, j, n + k] = su[b][0]
                    su[b] = Ad @ su[b] + (Bud if on else 0.0)
                phi = Ad @ phi
                sk = Ad @ sk + Bkd
        self._cache[key] = (M, q, G)
        return self._cache[key]

    def predict(
        self, offset: float, state: ArrayLike, integral: float, vx: float, kappa: float, output: str = "ay"
    ) -> NDArray:
        """Predicted ``a_y`` [m/s^2] (``output="ay"``) or ``e1`` [m] (``"e1"``) for ``offset``.

        Returns
        -------
        ndarray, shape (vertices, backups, horizon samples)
        """
        if output not in ("ay", "e1"):
            raise ValueError(f"output must be 'ay' or 'e1', got {output!r}")
        f, G = self._affine(state, integral, vx, kappa)
        rows = slice(0, self.n_horizon) if output == "ay" else slice(self.n_horizon, 2 * self.n_horizon)
        return f[:, None, rows] + G[:, :, rows] * float(offset)

    @staticmethod
    def _start(state: ArrayLike, integral: float) -> NDArray:
        """The closed loop's start ``[e1, e1_dot, e2, e2_dot, z]``."""
        s0 = np.empty(5)
        s0[:4] = np.asarray(state, dtype=float).reshape(4)
        s0[4] = float(integral)
        return s0

    def _affine(self, state, integral, vx, kappa):
        M, q, G = self._response(vx)
        f = M @ self._start(state, integral) + q * float(kappa)  # (vertices, horizon)
        return f, G

    # -- decision --------------------------------------------------------------------------
    def decide(
        self, requested: float, state: ArrayLike, integral: float, vx: float, kappa: float, max_offset: float | None = None
    ) -> FilterDecision:
        """The applied offset for ``requested`` [rad] from the estimated error state and driver integral.

        Parameters
        ----------
        requested : float
            Offset the policy asks for [rad].
        state : array_like, shape (4,)
            Estimated ``[e1, e1_dot, e2, e2_dot]`` now.
        integral : float
            The driver's integral of ``e1`` [m s].
        vx, kappa : float
            Speed [m/s] and road curvature [1/m] now (held over the horizon).
        max_offset : float, optional
            The offset range ``[-max_offset, max_offset]`` [rad] (default ``|requested|``
            widened to include zero).
        """
        requested = float(requested)
        if not math.isfinite(requested):
            raise ValueError(f"requested offset must be finite, got {requested!r}")
        if not vx > 0:
            raise ValueError(f"vx must be > 0 for the a_y prediction, got {vx!r}")
        bound = abs(requested) if max_offset is None else float(max_offset)
        n = self.n_horizon
        bound_ay = self.ay_limit - self.margin(vx)
        if not bound_ay > 0:
            raise ParameterError(
                f"the camera-noise margin {self.margin(vx):.3f} m/s^2 at vx={vx} m/s leaves nothing of "
                f"ay_limit={self.ay_limit} m/s^2: lower noise_sigmas or raise the limit"
            )
        M, q, G = self._response(vx)
        s0 = self._start(state, integral)
        lane_limit = math.inf if self.lane_margin is None else self.lane_margin - self.lane_safety_margin()
        applied, peak, max_e1, beyond = _decide_kernel(M, q, G, s0, float(kappa), n, bound_ay, lane_limit,
                                                       requested, bound)  # fmt: skip
        return FilterDecision(
            requested=requested, applied=applied, predicted_peak=peak, predicted_max_e1=max_e1, driver_beyond_limit=beyond
        )

    def filter(
        self, requested: float, state: ArrayLike, integral: float, vx: float, kappa: float, max_offset: float | None = None
    ) -> float:
        """Shortcut for ``decide(...).applied`` [rad]."""
        return self.decide(requested, state, integral, vx, kappa, max_offset).applied


@njit(cache=True)
def _decide_kernel(M, q, G, s0, kappa, n, bound_ay, lane_limit, requested, bound):
    """:meth:`LateralAccelerationFilter.decide` on the cached responses (one pass, no temporaries).

    Rows ``0..n-1`` of ``M, q, G`` are ``a_y``, rows ``n..2n-1`` are ``e1``. Each row's limit is
    ``max(bound, |f|)`` with ``f`` the zero-offset prediction (so ``u = 0`` is admissible); the
    ``e1`` rows bind only with a finite ``lane_limit``. Returns ``(applied, predicted |a_y| peak,
    predicted |e1| max, driver beyond the a_y bound)`` for the continuation furthest inside.
    """
    n_corner, n_backup, n_row = G.shape
    rows = n_row if lane_limit < math.inf else n
    f = np.empty((n_corner, n_row))
    beyond = False
    for v in range(n_corner):
        for k in range(n_row):
            acc = q[v, k] * kappa
            for i in range(5):
                acc += M[v, k, i] * s0[i]
            f[v, k] = acc
            if k < n and abs(acc) > bound_ay:
                beyond = True
    lower = np.full(n_backup, -bound)
    upper = np.full(n_backup, bound)
    for j in range(n_backup):
        for v in range(n_corner):
            for k in range(rows):
                g = G[v, j, k]
                if abs(g) <= 1e-12:
                    continue
                fk = f[v, k]
                lim = max(bound_ay if k < n else lane_limit, abs(fk))
                a = (-lim - fk) / g
                b = (lim - fk) / g
                lo = min(a, b)
                hi = max(a, b)
                if lo > lower[j]:
                    lower[j] = lo
                if hi < upper[j]:
                    upper[j] = hi
    applied = 0.0
    best_gap = math.inf
    for j in range(n_backup):
        if lower[j] <= upper[j]:
            u = min(max(requested, lower[j]), upper[j])
            if abs(u - requested) < best_gap:
                best_gap = abs(u - requested)
                applied = u
    # the continuation furthest inside its limits, and its predicted extremes
    best, best_ratio = 0, math.inf
    for j in range(n_backup):
        ratio = 0.0
        for v in range(n_corner):
            for k in range(rows):
                fk = f[v, k]
                lim = max(bound_ay if k < n else lane_limit, abs(fk))
                r = abs(fk + G[v, j, k] * applied) / lim
                if r > ratio:
                    ratio = r
        if ratio < best_ratio:
            best, best_ratio = j, ratio
    peak = 0.0
    max_e1 = 0.0
    for v in range(n_corner):
        for k in range(n_row):
            y = abs(f[v, k] + G[v, best, k] * applied)
            if k < n:
                peak = max(peak, y)
            else:
                max_e1 = max(max_e1, y)
    return applied, peak, max_e1, beyond
