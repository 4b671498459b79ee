"""Scoring of IMU estimates against a reference sensor (``true_vy`` / ``true_beta``). Scoring only.

Nothing here feeds an estimator. The "measured" tire curves follow ``data/README.md``:

- slip angles from the reference lateral velocity, the yaw rate and the steering::

      alpha_f = delta - (true_vy + lf r)/vx,     alpha_r = -(true_vy - lr r)/vx

- axle forces from Newton with the measured ``a_y`` and a filtered derivative of ``r``
  (zero-phase 2nd-order Butterworth low-pass at ``cutoff_hz``, then central differences)::

      m a_y = F_yf cos(delta) + F_yr,      Iz r_dot = lf F_yf cos(delta) - lr F_yr

- the measured *curve* of an axle is the binned mean force against slip (40 bins over the
  covered range, the 0.5-99.5 % slip quantiles; bins with fewer than 20 samples dropped),
  linearly interpolated.

The curve score is :func:`..metrics.curve_nrmse`: RMS difference on a 201-point grid over
the covered range divided by the largest ``|F|`` of the measured curve there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, filtfilt

from .._kernels import bicycle_slip_angles
from ..metrics import AXLES, curve_nrmse, excited_range
from ..params import VehicleParams

__all__ = [
    "MeasuredTireData",
    "measured_tire_data",
    "MeasuredCurve",
    "sideslip_rmse_deg",
    "sideslip_scores",
    "split_masks",
    "reference_beta",
    "near_zero_stiffness",
]


def reference_beta(truth: dict, vx: NDArray) -> NDArray | None:
    """Reference sideslip [rad]: ``true_beta``, else ``atan(true_vy/vx)``, else ``None``."""
    if "true_beta" in truth:
        return np.asarray(truth["true_beta"], dtype=float)
    if "true_vy" in truth:
        return np.arctan2(np.asarray(truth["true_vy"], dtype=float), vx)
    return None


@dataclass
class MeasuredTireData:
    """Reference (slip, force) samples per axle: ``slip`` (n, 2) [rad], ``force`` (n, 2) [N]."""

    t: NDArray
    slip: NDArray
    force: NDArray
    yaw_accel: NDArray
    cutoff_hz: float


def measured_tire_data(sensors: dict, truth: dict, vehicle: VehicleParams, cutoff_hz: float = 5.0) -> MeasuredTireData | None:
    """The README's measured slips and axle forces, or ``None`` without ``true_vy``/``true_beta``."""
    t = np.asarray(sensors["t"], dtype=float)
    vx = np.asarray(sensors["vx"], dtype=float)
    if "true_vy" in truth:
        vy = np.asarray(truth["true_vy"], dtype=float)
    elif "true_beta" in truth:
        vy = vx * np.tan(np.asarray(truth["true_beta"], dtype=float))
    else:
        return None
    r = np.asarray(sensors["yaw_rate"], dtype=float)
    ay = np.asarray(sensors["ay"], dtype=float)
    delta = np.asarray(sensors["delta"], dtype=float)
    fs = 1.0 / float(np.median(np.diff(t)))
    r_f = np.interp(t, t[np.isfinite(r)], r[np.isfinite(r)])
    if len(t) > 12 and cutoff_hz < 0.5 * fs:
        b, a = butter(2, cutoff_hz / (0.5 * fs))
        r_f = filtfilt(b, a, r_f)
    r_dot = np.gradient(r_f, t)
    lf, lr, L = vehicle.lf, vehicle.lr, vehicle.wheelbase
    alpha_f, alpha_r = bicycle_slip_angles.py_func(vy, r, delta, vx, lf, lr)  # eq. (13) on the arrays
    Fyf = (vehicle.m * lr * ay + vehicle.Iz * r_dot) / (L * np.cos(delta))
    Fyr = (vehicle.m * lf * ay - vehicle.Iz * r_dot) / L
    return MeasuredTireData(t, np.column_stack([alpha_f, alpha_r]), np.column_stack([Fyf, Fyr]), r_dot, cutoff_hz)


class MeasuredCurve:
    """Binned-mean measured axle curves over the covered slip range (module docstring).

    Parameters
    ----------
    data : MeasuredTireData
    mask : bool array (n,), optional
        Rows used (e.g. one half of the log).
    """

    def __init__(self, data: MeasuredTireData, mask: NDArray | None = None, n_bins: int = 40, min_count: int = 20):
        keep = np.ones(len(data.t), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        self.ranges: dict[str, tuple[float, float]] = {}
        self._curves: dict[str, tuple[NDArray, NDArray]] = {}
        self.counts: dict[str, int] = {}
        for i, axle in enumerate(AXLES):
            a, f = data.slip[keep, i], data.force[keep, i]
            ok = np.isfinite(a) & np.isfinite(f)
            a, f = a[ok], f[ok]
            lo, hi = excited_range(a)
            edges = np.linspace(lo, hi, n_bins + 1)
            idx = np.digitize(a, edges) - 1
            centres, means = [], []
            for k in range(n_bins):
                sel = idx == k
                if sel.sum() >= min_count:
                    centres.append(float(a[sel].mean()))
                    means.append(float(f[sel].mean()))
            self.ranges[axle] = (lo, hi)
            self._curves[axle] = (np.array(centres), np.array(means))
            self.counts[axle] = int(len(a))

    def __call__(self, alpha, axle: str) -> NDArray:
        """The measured axle force at ``alpha`` [rad]; NaN when fewer than two bins hold ``min_count``
        samples (a log too short to measure a curve: its NRMSE scores are NaN, written as null)."""
        c, m = self._curves[axle]
        alpha = np.asarray(alpha, dtype=float)
        if len(c) < 2:
            return np.full(alpha.shape, np.nan)
        return np.interp(alpha, c, m)

    def nrmse(self, curve, axle: str) -> float:
        """:func:`..metrics.curve_nrmse` of ``curve(alpha, axle)`` against this measured curve."""
        lo, hi = self.ranges[axle]
        return curve_nrmse(curve, self, axle, lo, hi)

    def range_deg(self) -> dict:
        return {a: [math.degrees(v) for v in self.ranges[a]] for a in AXLES}


def split_masks(t: NDArray) -> dict[str, NDArray]:
    """``whole``, ``first_half`` (``t < t_mid``) and ``second_half`` masks, ``t_mid`` the middle time."""
    t = np.asarray(t, dtype=float)
    mid = 0.5 * (t[0] + t[-1])
    return {"whole": np.ones(len(t), dtype=bool), "first_half": t < mid, "second_half": t >= mid}


def sideslip_rmse_deg(beta_hat: NDArray, beta_ref: NDArray, masks: dict[str, NDArray]) -> dict[str, float]:
    """RMSE [deg] of the sideslip estimate on every mask (all rows, no burn-in)."""
    err = np.degrees(np.asarray(beta_hat, dtype=float) - np.asarray(beta_ref, dtype=float))
    return {k: float(np.sqrt(np.nanmean(err[m] ** 2))) for k, m in masks.items()}


def sideslip_scores(t: NDArray, beta_ref: NDArray, estimates: dict[str, NDArray], reported: str, online: str) -> dict:
    """Sideslip RMSE of every estimate against the reference, and of the reported one beside the linear KF's.

    The part of ``metrics.json``'s ``reference_scores`` that the IMU-only and the fused ``estimate``
    paths share (same keys, so one reader handles both).

    Parameters
    ----------
    t : array (n,)
        Row times [s]; the halves split at the middle time (:func:`split_masks`).
    beta_ref : array (n,)
        Reference sideslip [rad] (:func:`reference_beta`).
    estimates : dict of str -> array (n,)
        Sideslip [rad] of each estimator, ``linear_kf_baseline`` among them.
    reported : str
        The key of ``estimates`` the command reports.
    online : str
        The key of the causal estimate (what a car gets on line).

    Returns
    -------
    dict
        ``note``, ``split_time_s``, ``sideslip_rmse_deg`` (per estimator: ``whole``, ``first_half``,
        ``second_half``), ``reported_vs_linear_kf`` (``reported``, ``online``, the RMSE difference
        reported - KF [deg] and ``reported_worse_than_linear_kf`` per part, the same for ``online``) and
        ``targets`` (``reported_no_worse_than_linear_kf``, ``online_no_worse_than_linear_kf``: whole log).
    """
    masks = split_masks(t)
    rmse = {name: sideslip_rmse_deg(beta, beta_ref, masks) for name, beta in estimates.items()}
    kf = rmse["linear_kf_baseline"]
    comparison: dict = {"reported": reported, "online": online}
    for role, name in (("reported", reported), ("online", online)):
        comparison[f"{role}_minus_linear_kf_deg"] = {k: rmse[name][k] - kf[k] for k in masks}
        comparison[f"{role}_worse_than_linear_kf"] = {k: bool(rmse[name][k] > kf[k]) for k in masks}
    return {
        "note": "reference sensor columns (true_vy/true_beta) used here only; all rows scored, no burn-in; halves "
        "split at the middle time of the log",
        "split_time_s": float(0.5 * (t[0] + t[-1])),
        "sideslip_rmse_deg": rmse,
        "reported_vs_linear_kf": comparison,
        "targets": {
            "reported_no_worse_than_linear_kf": bool(rmse[reported]["whole"] <= kf["whole"]),
            "online_no_worse_than_linear_kf": bool(rmse[online]["whole"] <= kf["whole"]),
        },
    }


def near_zero_stiffness(data: MeasuredTireData, mask: NDArray | None = None, limit: float = math.radians(1.0)) -> dict:
    """Least-squares slope through the origin of the measured cloud for ``|alpha| <= limit`` [N/rad] per axle."""
    keep = np.ones(len(data.t), dtype=bool) if mask is None else mask
    out = {}
    for i, axle in enumerate(AXLES):
        a, f = data.slip[keep, i], data.force[keep, i]
        sel = np.isfinite(a) & np.isfinite(f) & (np.abs(a) <= limit)
        out[axle] = float(np.sum(a[sel] * f[sel]) / np.sum(a[sel] ** 2)) if sel.sum() > 10 else float("nan")
    return out
