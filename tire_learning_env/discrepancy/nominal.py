"""The nominal tire of the discrepancy workflow: linear, Pacejka or learned from the log itself.

:func:`nominal_tires` gives the front and rear axle tires the model compares with the log
(:mod:`.workflow`) and a description for ``report.json``.
"""

from __future__ import annotations

import math

import numpy as np

from ..io import DrivingLog
from ..params import CameraParams, ParameterError, TireParams, VehicleParams
from ..tires import CallableTire, LinearTire, TireModel, axle_tires
from .data import noise_std

__all__ = ["TIRE_CHOICES", "nominal_tires"]

TIRE_CHOICES = ("pacejka", "linear", "learned")


def nominal_tires(
    log: DrivingLog, vehicle: VehicleParams, tire: str, tire_params: TireParams | None = None
) -> tuple[TireModel, TireModel, dict]:
    """Front/rear axle tires of the nominal model and a description.

    ``learned`` runs the neuro-adaptive observer on the log (:func:`~tire_learning_env.observer.estimate`;
    for an IMU-only log with ``sensors="imu"`` and the IMU noise measured by
    :func:`~tire_learning_env.imu.imu_noise_std`) and uses the learned axle curves (refined
    pass). Only the curves are used: the observer's state estimates (e.g. its causal
    sideslip) never enter the comparison.
    """
    if tire == "learned" and log.kind == "imu":
        from ..imu import imu_noise_std
        from ..observer import ObserverConfig, estimate

        s = log.sensors
        rows = {k: np.asarray(s[k], dtype=float) for k in ("t", "delta", "vx", "ay", "yaw_rate")}
        noise, _ = imu_noise_std(rows["t"], rows["ay"], rows["yaw_rate"])
        result = estimate(rows, vehicle, config=ObserverConfig(sensors="imu", imu_noise=noise))
        cf, cr = result.cornering_stiffness()
        front = CallableTire(lambda a: result.axle_force(a, "front"), "learned front (IMU observer)")
        rear = CallableTire(lambda a: result.axle_force(a, "rear"), "learned rear (IMU observer)")
        h = math.radians(1.0)
        secant = {a: float((result.axle_force(h, a) - result.axle_force(-h, a)) / (2 * h)) for a in ("front", "rear")}
        return front, rear, {
            "kind": "learned",
            "learner": "neuro-adaptive observer on the IMU (tire_learning_env.observer.estimate, sensors='imu'), "
            "refined curves; only its axle curves are used, never its state estimates",
            "cornering_stiffness_per_tire": {"front": cf, "rear": cr},
            "secant_pm1deg_per_axle_N_per_rad": secant,
        }
    if tire == "linear":
        return LinearTire(2.0 * vehicle.Cf), LinearTire(2.0 * vehicle.Cr), {"kind": "linear"}
    if tire == "pacejka":
        tp = tire_params or TireParams()
        f, r = axle_tires(vehicle, "pacejka", tp)
        return f, r, {"kind": "pacejka", "mu": tp.mu, "shape": tp.shape, "curvature": tp.curvature}
    if tire == "learned":
        from ..observer import ObserverConfig, estimate
        from ..observer.rows import fill_path_curvature

        s = log.sensors
        t = s["t"]
        kappa = fill_path_curvature(np.asarray(t, dtype=float), np.asarray(s["kappa"], dtype=float))
        pdd = s["vx"] * kappa
        rows = {
            "t": t, "delta": s["delta"], "vx": s["vx"], "psi_dot_des": pdd,
            "psi_ddot_des": np.gradient(pdd, t), "e1": s["e1"], "e2": s["e2"],
        }  # fmt: skip
        frames = np.flatnonzero(np.isfinite(s["e1"]) & np.isfinite(s["e2"]))
        rate = 1.0 / float(np.median(np.diff(t[frames])))
        # gains designed for the camera noise estimated from the log itself
        n1, n2 = noise_std(s["e1"][frames]), noise_std(s["e2"][frames])
        camera = CameraParams(rate=rate)
        if n1 > 0 and n2 > 0:
            camera = CameraParams(rate=rate, noise="gaussian", e1_noise=n1, e2_noise=n2)
        result = estimate(rows, vehicle, camera, ObserverConfig(), physics_dt=float(np.median(np.diff(t))))
        cf, cr = result.cornering_stiffness()
        front = CallableTire(lambda a: result.axle_force(a, "front"), "learned front")
        rear = CallableTire(lambda a: result.axle_force(a, "rear"), "learned rear")
        return front, rear, {"kind": "learned", "cornering_stiffness_per_tire": {"front": cf, "rear": cr}}
    raise ParameterError(f"tire must be one of {TIRE_CHOICES}, got {tire!r}")
