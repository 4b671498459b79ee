"""Simulated IMU logs from the low-order body-frame plant (Pacejka truth, varying speed).

The truth the IMU observer is tested against: the body-frame bicycle model of
:mod:`.model` with Magic-Formula axle tires (:class:`..tires.PacejkaTire`), integrated with
classical RK4 at ``substeps`` per sample, a speed profile between ``speed_range`` (the
measured ``vx`` is an input, as on the real car) and a steering pattern that sweeps the
lateral acceleration up to ``ay_max`` in both directions (a feed-forward on the kinematic
steering angle plus a light yaw-rate feedback, like a driver). The IMU adds white noise
to ``a_y`` and ``r``, optionally band-limited vibration on ``a_y`` (engine and road: white
noise through a 2nd-order Butterworth band-pass, scaled to the given std; the band is cut at
0.9 of the Nyquist frequency of the sample rate) and constant sensor offsets. Returns the
shared log columns (``t, vx, delta, yaw_rate, ay, ax``) and the truth (``true_vy``,
``true_beta``, slips, axle forces) apart.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

from .._kernels import bicycle_slip_angles
from ..params import ParameterError, TireParams, VehicleParams
from ..tires import PacejkaTire

__all__ = ["simulate_imu_drive", "band_limited_noise", "DriveState"]


class DriveState(IntEnum):
    """Components of the simulated body state ``x`` (the IMU model's ``[vy, r]``)."""

    VY = 0  # lateral velocity at the CG [m/s]
    R = 1  # yaw rate [rad/s]


def band_limited_noise(n: int, dt: float, std: float, f_low: float, f_high: float, seed=0) -> NDArray:
    """``n`` samples of white noise through a 2nd-order Butterworth band-pass ``f_low``-``f_high``
    [Hz], scaled to std ``std``. At a low sample rate the band is cut at 0.9 of the Nyquist
    frequency ``1/(2 dt)`` and ``f_low`` lowered to at most half that top (a vibration above
    the Nyquist frequency appears aliased in the band the log can hold)."""
    from scipy.signal import butter, sosfilt

    nyq = 0.5 / dt
    hi = min(f_high, 0.9 * nyq)
    lo = min(f_low, 0.5 * hi)
    if not (std >= 0 and 0 < lo < hi):
        raise ParameterError(f"vibration needs std >= 0 and 0 < f_low < f_high, got {std}, {f_low}, {f_high}")
    sos = butter(2, [lo / nyq, hi / nyq], btype="band", output="sos")
    w = sosfilt(sos, np.random.default_rng(seed).normal(size=n + 200))[200:]  # filter transient dropped
    sd = float(np.std(w))
    return std * w / sd if sd > 0 else w


def simulate_imu_drive(
    vehicle: VehicleParams,
    duration: float = 120.0,
    dt: float = 0.01,
    tire: TireParams | None = None,
    true_vehicle: VehicleParams | None = None,
    speed_range: tuple[float, float] = (18.0, 55.0),
    speed_period: float = 47.0,
    ay_max: float = 8.0,
    noise_std: tuple[float, float] = (0.5, 0.003),
    seed: int = 0,
    substeps: int = 10,
    vibration: tuple[float, float, float] | None = None,
    offsets: tuple[float, float] = (0.0, 0.0),
    steering: str = "held",
) -> tuple[dict[str, NDArray], dict[str, NDArray], tuple[PacejkaTire, PacejkaTire]]:
    """Simulate a drive; returns ``(sensors, truth, (front_tire, rear_tire))``.

    Parameters
    ----------
    vehicle : VehicleParams
        Rigid-body parameters (and, unless ``true_vehicle`` is given, the truth stiffness).
    duration, dt : float
        Length [s] and sample period [s].
    tire : TireParams, optional
        Magic-Formula shape (``mu``, ``shape``, ``curvature``); default ``mu = 1``.
    true_vehicle : VehicleParams, optional
        Vehicle whose ``Cf``, ``Cr`` set the *true* tire stiffness (to test recovery of a
        stiffness the observer does not know).
    speed_range : (float, float)
        ``vx`` oscillates between these [m/s] with period ``speed_period`` [s].
    ay_max : float
        Peak commanded lateral acceleration [m/s^2].
    noise_std : (float, float)
        IMU noise std ``(a_y [m/s^2], r [rad/s])``.
    seed : int
        Noise and steering-pattern seed.
    substeps : int
        RK4 steps per sample.
    vibration : (float, float, float), optional
        Band-limited ``a_y`` vibration ``(std [m/s^2], f_low [Hz], f_high [Hz])`` added to the
        white noise (its own generator, seeded from ``seed``: the other draws are unchanged).
    offsets : (float, float)
        Constant sensor offsets ``(a_y [m/s^2], r [rad/s])`` added to the measurements.
    steering : {"held", "continuous"}
        ``held``: the steering is computed at each sample and held until the next (a
        zero-order hold at the log rate). ``continuous``: the driver acts at every RK4
        substep (``dt / substeps``) and the log samples the steering at its rows, as a logger
        samples a real steering wheel (what :func:`~tire_learning_env.observer.estimate`
        assumes by default between rows, ``steering_hold="ramp"``).
    """
    if not (duration > 0 and dt > 0 and substeps >= 1):
        raise ParameterError("duration, dt must be > 0 and substeps >= 1")
    if steering not in ("held", "continuous"):
        raise ParameterError(f"steering must be 'held' or 'continuous', got {steering!r}")
    rng = np.random.default_rng(seed)
    tire = tire or TireParams()
    tv = true_vehicle or vehicle
    front = PacejkaTire.for_axle(tv, tire, "front")
    rear = PacejkaTire.for_axle(tv, tire, "rear")
    ff, fr = front.force, rear.force
    m, Iz, lf, lr = vehicle.m, vehicle.Iz, vehicle.lf, vehicle.lr
    L = vehicle.wheelbase
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    v_mid, v_amp = 0.5 * (speed_range[0] + speed_range[1]), 0.5 * (speed_range[1] - speed_range[0])
    vx = v_mid - v_amp * np.cos(2 * math.pi * t / speed_period)
    ax = np.gradient(vx, t)
    # lateral-acceleration command: two sines with a slowly varying envelope (both signs)
    phases = rng.uniform(0, 2 * math.pi, 3)

    def command(tt):
        env = 0.55 + 0.45 * np.sin(2 * math.pi * tt / 31.0 + phases[0])
        return ay_max * env * (0.7 * np.sin(2 * math.pi * 0.21 * tt + phases[1]) + 0.3 * np.sin(2 * math.pi * 0.53 * tt + phases[2]))

    a_cmd = command(t)
    kus = m * (lr / (2 * vehicle.Cf) - lf / (2 * vehicle.Cr)) / L  # understeer gradient [rad/(m/s^2)]
    x = np.zeros(len(DriveState))
    out = np.zeros((n, len(DriveState)))
    delta = np.zeros(n)
    forces = np.zeros((n, 2))
    slips = np.zeros((n, 2))
    h = dt / substeps
    VY, R = DriveState.VY, DriveState.R  # read once: an enum attribute read costs ~0.3 us in the RK4 loop
    slip = bicycle_slip_angles.py_func  # eq. (13), the package's one implementation (plain Python in this loop)

    def rhs(x, d, v):
        vy, r = x[VY], x[R]
        a_f, a_r = slip(vy, r, d, v, lf, lr)
        Ff, Fr = ff(a_f), fr(a_r)
        cd = math.cos(d)
        return np.array([(Ff * cd + Fr) / m - v * r, (lf * Ff * cd - lr * Fr) / Iz])  # in DriveState order

    for k in range(n):
        v = vx[k]
        r_des = a_cmd[k] / v
        d = (L / v**2 + kus) * a_cmd[k] + 0.05 * (r_des - x[R])  # feed-forward + light yaw feedback
        delta[k] = d
        a_f, a_r = slip(x[VY], x[R], d, v, lf, lr)
        out[k] = x
        slips[k] = (a_f, a_r)
        forces[k] = (ff(a_f), fr(a_r))
        if k == n - 1:
            break
        for j in range(substeps):  # inputs held over the sample (ZOH) or the substep, speed interpolated
            v0 = vx[k] + (vx[k + 1] - vx[k]) * j / substeps
            if steering == "continuous" and j > 0:  # the driver keeps steering between the logged rows
                a_j = float(command(t[k] + j * h))
                d = (L / v0**2 + kus) * a_j + 0.05 * (a_j / v0 - x[R])
            v1 = vx[k] + (vx[k + 1] - vx[k]) * (j + 0.5) / substeps
            v2 = vx[k] + (vx[k + 1] - vx[k]) * (j + 1) / substeps
            k1 = rhs(x, d, v0)
            k2 = rhs(x + 0.5 * h * k1, d, v1)
            k3 = rhs(x + 0.5 * h * k2, d, v1)
            k4 = rhs(x + h * k3, d, v2)
            x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    ay_true = (forces[:, 0] * np.cos(delta) + forces[:, 1]) / m
    sensors = {
        "t": t,
        "vx": vx,
        "delta": delta,
        "yaw_rate": out[:, R] + rng.normal(0.0, noise_std[1], n) + float(offsets[1]),
        "ay": ay_true + rng.normal(0.0, noise_std[0], n) + float(offsets[0]),
        "ax": ax,
    }
    if vibration is not None and vibration[0] > 0:
        sensors["ay"] = sensors["ay"] + band_limited_noise(n, dt, *vibration, seed=[seed, 1])
    truth = {
        "true_vy": out[:, VY].copy(),
        "true_beta": np.arctan2(out[:, VY], vx),
        "true_alpha_f": slips[:, 0].copy(),
        "true_alpha_r": slips[:, 1].copy(),
        "true_Fyf": forces[:, 0].copy(),
        "true_Fyr": forces[:, 1].copy(),
    }
    return sensors, truth, (front, rear)
