"""The linear Kalman filter baseline on a log's IMU rows, as every ``estimate`` path runs it.

The IMU-only path (:func:`.estimate.estimate_imu`) blends it with the observer; the fused path
(camera and IMU, :mod:`.fused`) writes it beside the fused estimate. Both run it through
:func:`linear_kf_baseline`, so the two report the same filter on the same rows.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..baselines.kalman import LinearKalmanFilter
from ..observer import EstimateTrace
from ..params import VehicleParams
from .logs import MIN_SPEED

__all__ = ["KF_WHAT", "kf_by_segment", "linear_kf_baseline"]

#: what the baseline is (``metrics.json``, ``baseline_linear_kf.what``)
KF_WHAT = ("linear Kalman filter of the source paper (states beta, r; measurements a_y, r; axle stiffness 2 Cf, "
           "2 Cr of the vehicle file), baselines.LinearKalmanFilter, with the measured IMU noise")  # fmt: skip


def linear_kf_baseline(
    rows: dict[str, NDArray], vehicle: VehicleParams, noise: tuple[float, float], gap_s: float
) -> tuple[EstimateTrace, LinearKalmanFilter]:
    """The linear KF over a log's IMU rows.

    Parameters
    ----------
    rows : dict of str -> array
        ``t, delta, vx, ay, yaw_rate`` (NaN = no sample), cleaned as for an IMU-only log
        (:func:`.logs.clean_imu_log`).
    vehicle : VehicleParams
        The vehicle file (its ``Cf``, ``Cr`` are the filter's tires).
    noise : (float, float)
        IMU noise std, ``a_y`` [m/s^2] and yaw rate [rad/s]; floored at the observer core's floors.
    gap_s : float
        The observer's ``segment_gap_s``: a fresh filter after every longer pause (:func:`kf_by_segment`).

    Returns
    -------
    trace : EstimateTrace
        The filter's pass over every row (``trace.beta``: its sideslip).
    kf : LinearKalmanFilter
        The filter of the first segment (``kf.settings()`` for ``metrics.json``).
    """
    noise_used = (max(noise[0], 0.01), max(noise[1], 1e-4))  # the core's floors
    dt = float(np.median(np.diff(rows["t"])))
    kf = LinearKalmanFilter(vehicle, noise_std=noise_used, physics_dt=dt)
    # the KF's own speed floor (1 m/s) makes its forward-Euler step unstable at standstill for a stiff car or a
    # slow log (1 - dt (Cf + Cr) / (m v) < -1); the observer's floor V_FLOOR keeps it stable where the IMU
    # samples are not used anyway (logs.MIN_SPEED)
    trace = kf_by_segment(kf, dict(rows, vx=np.maximum(rows["vx"], MIN_SPEED)), gap_s, vehicle, noise_used, dt)
    return trace, kf


def kf_by_segment(kf: LinearKalmanFilter, rows: dict, gap_s: float, vehicle: VehicleParams, noise, dt: float):
    """The linear KF over ``rows``; after each pause longer than ``gap_s`` [s] (the observer's
    ``segment_gap_s``) a fresh filter starts, as at the start of the log (its forward-Euler step across
    a pause of seconds is unstable, and nothing was measured there). ``kf`` runs the first segment."""
    t = rows["t"]
    cuts = (np.flatnonzero(np.diff(t) > gap_s) + 1).tolist() if math.isfinite(gap_s) else []
    if not cuts:
        return kf.run(rows)
    parts = []
    for i, (a, b) in enumerate(zip([0] + cuts, cuts + [len(t)])):
        f = kf if i == 0 else LinearKalmanFilter(vehicle, noise_std=noise, physics_dt=dt)
        parts.append(f.run({k: v[a:b] for k, v in rows.items()}, predict_last=b == len(t)))
    fields = ("t", "state", "slip", "force", "force_nonlinear", "std", "health", "innovation", "nis", "vx", "kappa")
    out = {f: np.concatenate([getattr(p, f) for p in parts]) for f in fields}
    return EstimateTrace(**out, weights=parts[0].weights, state_names=parts[0].state_names,
                         meta=dict(parts[0].meta, segments=len(parts),
                                   beta=np.concatenate([p.meta["beta"] for p in parts])))  # fmt: skip
