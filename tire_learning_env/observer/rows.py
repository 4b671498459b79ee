"""Sensor columns to the compiled kernel's row arrays (:func:`sensor_rows`); re-exported by
:mod:`.neuro_adaptive`."""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import ParameterError
from ._kernel_types import CH_AY, CH_E1, CH_E2, CH_R, N_CHANNELS
from .model import MeasurementModel, check_sensor_columns

__all__ = ["sensor_rows", "fill_path_curvature", "steering_roughness", "SMOOTH_STEERING_ROUGHNESS", "steering_half_power_share",
           "CONTINUOUS_STEERING_HALF_POWER_SHARE", "steering_character", "MIDPOINT_FRAME_SHARE", "CHANNELS"]

#: measurement channels in the order of the kernel's ``z`` columns
CHANNELS = ("e1", "e2", "ay", "yaw_rate")
assert (CHANNELS[CH_E1], CHANNELS[CH_E2], CHANNELS[CH_AY], CHANNELS[CH_R]) == ("e1", "e2", "ay", "yaw_rate")


class _KernelRows(dict):
    """Rows already in the kernel's layout (:func:`sensor_rows`): :meth:`NeuroAdaptiveObserver.run`
    skips the validation (the block law's pieces of one validated call)."""


def fill_path_curvature(t: NDArray, kappa: NDArray) -> NDArray:
    """The path curvature on every row: empty (NaN) cells interpolated linearly in time.

    A camera that reports the lane's curvature with its frames leaves ``kappa`` empty between
    them; the curvature of a road is smooth, so the rows between two values get the line
    between them, and the rows before the first (after the last) value hold it.

    Parameters
    ----------
    t : ndarray
        Row times [s], increasing.
    kappa : ndarray
        Path curvature [1/m] per row; NaN or inf = no value.

    Returns
    -------
    ndarray
        ``kappa`` with its non-finite cells filled (a copy when any were filled).

    Raises
    ------
    ParameterError
        No row has a finite curvature.
    """
    ok = np.isfinite(kappa)
    if ok.all():
        return kappa
    if not ok.any():
        raise ParameterError("column 'kappa' (path curvature) has no values: the camera model needs it")
    return np.interp(t, t[ok], kappa[ok])


def sensor_rows(sensors: Mapping[str, ArrayLike], model: MeasurementModel) -> dict[str, NDArray]:
    """The kernel's row arrays from sensor columns: ``t, delta, vx, ax, kappa``, ``z`` (n, 4) and
    ``e1_release`` (n,).

    ``kappa`` comes from ``kappa`` or ``psi_dot_des / vx``; its empty cells are interpolated in
    time (:func:`fill_path_curvature`); channels the model does not read are NaN. ``e1_release``
    [m^2]: the variance added to ``e1`` before the frame of a row whose ``e1`` was re-expressed
    (:mod:`.reexpression`; the column of that name, else zeros). Ground truth (``true_*``) is refused.
    """
    need = ["t", "delta", "vx"]
    if model.uses_camera:
        need += ["e1", "e2"] + ([] if "psi_dot_des" in sensors else ["kappa"])
    if model.uses_imu:
        need += ["ay", "yaw_rate"]
    check_sensor_columns(sensors, need, f"{model.name} estimation")
    get = lambda k: np.ascontiguousarray(np.asarray(sensors[k], dtype=float))  # noqa: E731
    t, delta, vx = get("t"), get("delta"), get("vx")
    n = len(t)
    if not (len(delta) == len(vx) == n):
        raise ParameterError("sensor columns must have equal lengths")
    ax = get("ax") if "ax" in sensors else np.zeros(n)
    ax = np.where(np.isfinite(ax), ax, 0.0)
    if model.uses_camera:
        kappa = get("kappa") if "kappa" in sensors else get("psi_dot_des") / np.maximum(vx, 1e-3)
        kappa = fill_path_curvature(t, kappa)
    else:
        kappa = np.zeros(n)
    z = np.full((n, N_CHANNELS), np.nan)
    if model.uses_camera:
        z[:, CH_E1], z[:, CH_E2] = get("e1"), get("e2")
    if model.uses_imu:
        z[:, CH_AY], z[:, CH_R] = get("ay"), get("yaw_rate")
    release = get("e1_release") if model.uses_camera and "e1_release" in sensors else np.zeros(n)
    if len(release) != n:
        raise ParameterError("sensor columns must have equal lengths")
    return {"t": t, "delta": delta, "vx": vx, "ax": ax, "kappa": np.ascontiguousarray(kappa), "z": z, "e1_release": release}


#: :func:`steering_roughness` below which the logged steering is a smooth, well-sampled signal (the ramp between rows
#: is its reconstruction, not one of two guesses): a staircase of independent steps gives sqrt(2), white sensor noise
#: sqrt(3), a smooth signal of frequency ``f`` sampled every ``h`` about ``2 pi f h``; a smooth signal plus steps,
#: ``sqrt(2 s)`` with ``s`` the steps' share of the increments' power, so 0.7 is a quarter. Measured: 0.12-0.49 on an
#: independent generator's logs (smooth), 1.41 on the package's simulator (steps), 0.98 on a highway-env drive of the
#: generalisation benchmark's highway family (scenario 3, 1 kHz rows, a 13 Hz camera: steps and a smooth lane-change
#: steering; +0.22 / -0.31 % at the midpoint, -0.23 / -0.75 % ramped), which keeps the midpoint.
SMOOTH_STEERING_ROUGHNESS = 0.7


def steering_roughness(t, delta) -> float:
    """How far the logged steering is from the line between its neighbouring rows, per increment.

    ``RMS(2 (delta_j - lin_j)) / RMS(delta_j - delta_{j-1})`` with ``lin_j`` the linear interpolation of
    rows ``j - 1`` and ``j + 1`` at ``t_j`` (on uniform rows: ``RMS(second difference) / RMS(first
    difference) = sqrt(2 (1 - r_1))``, ``r_1`` the lag-one autocorrelation of the increments). Measured:
    0.12 on an independent generator's 1 kHz rows and 0.22-0.40 on its 100 Hz rows (a driver through an
    80 ms steering actuator); 1.41 on every drive of the package's simulator, whose driver steps the
    road-wheel angle at each camera frame (1 kHz rows, the same decimated to 100 Hz, and a 100 Hz
    simulation); 1.62 on the real car's 100 Hz steering sensor (its noise). NaN with fewer than 3 rows
    or a constant steering.
    """
    t = np.asarray(t, dtype=float)
    d = np.asarray(delta, dtype=float)
    ok = np.isfinite(t) & np.isfinite(d)
    t, d = t[ok], d[ok]
    if len(d) < 3:
        return float("nan")
    span = t[2:] - t[:-2]
    good = span > 0
    w = np.where(good, (t[1:-1] - t[:-2]) / np.where(good, span, 1.0), 0.5)
    lin = d[:-2] + w * (d[2:] - d[:-2])
    dev = 2.0 * (d[1:-1] - lin)
    inc = np.diff(d)
    denom = float(np.sqrt(np.mean(inc**2)))
    return float(np.sqrt(np.mean(dev**2)) / denom) if denom > 0 else float("nan")


#: :func:`steering_half_power_share` above which a rough steering is a continuous signal seen through sensor noise
#: (rough at every row), not steps. Theory: gaussian increments give 0.124, uniform ones more, laplacian 0.069; a
#: staircase stepping on a share ``p`` of the rows ``0.124 p`` (below 0.05 for ``p < 0.4``; the estimator's midpoint
#: applies only where frames are on fewer than 60 % of the rows). Measured: 0.10-0.14 on an independent generator's
#: smooth steering with 0.003-0.03 deg of gaussian sensor noise, some quantised at 0.007 deg (roughness 0.85-1.72);
#: 0.0006-0.0142 on all 60 drives of the generalisation benchmark and on ten highway-env drives (roughness 0.98-1.42,
#: steps at 1-10 % of the rows). A 99th-over-50th-percentile ratio of the changes was tried first: it called six of
#: the 60 drives noise, those whose steps fall on fewer than 1 % of the rows (the percentile misses them).
CONTINUOUS_STEERING_HALF_POWER_SHARE = 0.05


def steering_half_power_share(delta) -> float:
    """The smallest share of the rows whose steering changes carry half the power of all of them.

    The changes are ``delta_k - delta_{k-1}`` over the finite rows, their power the sum of squares. A
    continuous wheel seen through a noisy or quantising sensor changes at every row by about as much
    (gaussian changes: 0.124); a steering held between steps on a share ``p`` of the rows changes at few
    (``0.124 p``). With :func:`steering_roughness` it tells a rough signal made by sensor noise from one
    made by steps. NaN with fewer than 2 finite rows or no change at all.
    """
    d = np.asarray(delta, dtype=float)
    power = np.sort(np.diff(d[np.isfinite(d)]) ** 2)[::-1]
    if not len(power) or power[0] == 0.0:
        return float("nan")
    cumulative = np.cumsum(power)
    return float(np.searchsorted(cumulative, 0.5 * cumulative[-1]) + 1) / len(power)


#: camera frames on fewer than this share of the rows: a camera log whose steering steps between frames is
#: answered at the midpoint of the two holds (the estimator's rule; :func:`steering_character` says when it steps)
MIDPOINT_FRAME_SHARE = 0.6


def steering_character(t, delta) -> dict:
    """What the logged steering did between its rows, as the estimator decides it.

    Returns
    -------
    dict
        ``roughness`` (:func:`steering_roughness`), ``half_power_share`` (:func:`steering_half_power_share`),
        ``sensor_noise`` (rough, but with changes at every row: a continuous wheel through a noisy sensor) and
        ``smooth`` (smooth at the row rate, or sensor noise on a continuous wheel: the line between the rows
        is its reconstruction).
    """
    roughness = steering_roughness(t, delta)
    share = steering_half_power_share(delta)
    noisy = bool(roughness >= SMOOTH_STEERING_ROUGHNESS and share > CONTINUOUS_STEERING_HALF_POWER_SHARE)
    return {"roughness": roughness, "half_power_share": share, "sensor_noise": noisy,
            "smooth": bool(roughness < SMOOTH_STEERING_ROUGHNESS or noisy)}
