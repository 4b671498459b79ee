"""Unit plausibility checks of a driving log (:func:`check_log_units`)."""

from __future__ import annotations

import warnings
from typing import Mapping

import numpy as np
from numpy.typing import NDArray

from .log import LogFormatError

__all__ = ["check_log_units", "UNIT_CHECKS_HINT"]


def _windows(t: NDArray, width: float) -> NDArray:
    """Indices of ``t`` about ``width`` apart (window edges)."""
    edges = np.arange(t[0], t[-1], width)
    return np.unique(np.searchsorted(t, edges))


def _slope(y: NDArray, x: NDArray, z: NDArray | None = None) -> tuple[float, float]:
    """Least-squares slope of ``y`` on ``x`` (with ``z`` as a nuisance regressor) and the fit's R^2."""
    cols = [x] if z is None else [x, z]
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ coef
    ss = float(np.sum(y**2))
    r2 = 1.0 - float(np.sum(resid**2)) / ss if ss > 0 else 0.0
    return float(coef[0]), r2


def _integral(t: NDArray, y: NDArray) -> NDArray:
    out = np.zeros_like(t)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))
    return out


UNIT_CHECKS_HINT = "if you are sure the units are SI, pass --no-unit-checks"


def check_log_units(columns: Mapping[str, NDArray], kind: str, source: str = "log") -> list[str]:
    """Raise :class:`LogFormatError` naming a column whose unit looks wrong and the likely unit.

    Checks: the time step (ms instead of s), the speed (km/h instead of m/s: median above
    70 m/s), the steering and the heading error (degrees: ``|delta|`` above 1 rad, ``|e2|``
    above 0.5 rad), and the physics linking the columns, fitted over ~1 s windows where the
    log holds enough excitation: ``e1`` changes by the integral of ``vx e2`` on camera logs
    (a constant heading bias is allowed for; a negative slope means ``e1`` and ``e2`` have
    opposite sign conventions), ``a_y = vx yaw_rate`` on IMU logs, and the heading change
    against the integral of ``vx delta / L`` (degrees give a wheelbase 50x too long; a
    negative slope means the opposite steering sign convention).

    A camera log with IMU columns gets the IMU check too, as a warning (the camera estimate does not
    use ``ay`` and ``yaw_rate``, but ``a_y = vx r`` still tells a speed in km/h, which the camera's own
    kinematics cannot tell from sideslip): a city drive in km/h ran to ``not_identifiable`` unnamed.

    Returns
    -------
    list of str
        The warnings given (for the log notes).
    """
    found: list[str] = []
    t, vx, delta = columns["t"], columns["vx"], columns["delta"]
    dt = np.diff(t)
    fix = f"; {UNIT_CHECKS_HINT}"
    med_dt = float(np.median(dt))
    if med_dt >= 0.5:
        unit = "milliseconds" if med_dt < 500 else "microseconds or a timestamp"
        raise LogFormatError(f"{source}: column 't' steps by {med_dt:g} (median): t looks like {unit}; it must be "
                             f"in seconds{fix}")
    v_med = float(np.median(vx))
    if v_med > 70.0:
        raise LogFormatError(f"{source}: column 'vx' has a median of {v_med:.4g}: that looks like km/h "
                             f"({v_med / 3.6:.3g} m/s); vx must be in m/s{fix}")
    if kind == "camera":
        e2 = columns["e2"]
        big = np.nanmax(np.abs(e2), initial=0.0)
        if big > 0.5:
            raise LogFormatError(f"{source}: |e2| reaches {big:.3g}: that looks like degrees; e2 must be in radians{fix}")
        _check_camera_kinematics(columns, source, fix)
        if "yaw_rate" in columns and "ay" in columns:
            try:
                _check_imu_kinematics(columns, source, "")
            except LogFormatError as err:
                message = (f"{err} (this camera log's IMU columns disagree with vx: the camera estimate does not "
                           "use ay and yaw_rate, but it does use vx)")
                warnings.warn(message, stacklevel=4)
                found.append(message.split(": ", 1)[1])
    if kind == "imu":
        _check_imu_kinematics(columns, source, fix)
    _check_steering(columns, kind, source, fix)
    return found


def _check_camera_kinematics(columns, source, fix) -> None:
    t, vx, e1, e2 = columns["t"], columns["vx"], columns["e1"], columns["e2"]
    frame = np.isfinite(e1) & np.isfinite(e2)
    if frame.sum() < 50:
        return
    tf, e1f, e2f, vf = t[frame], e1[frame], e2[frame], vx[frame]
    big_i = _integral(tf, vf * e2f)
    dist = _integral(tf, vf)
    idx = _windows(tf, 1.0)
    if len(idx) < 10:
        return
    de1, di, dd = np.diff(e1f[idx]), np.diff(big_i[idx]), np.diff(dist[idx])
    if float(np.sum(di**2)) < 0.1:  # too little heading excitation to tell
        return
    k, r2 = _slope(de1, di, dd)
    if r2 < 0.5:
        return
    # (km/h would give k = 0.28, but fast manoeuvres do too (sideslip), so speed is judged by its median only)
    if k < 0:
        raise LogFormatError(
            f"{source}: e1 changes against vx*e2 (slope {k:.3g}, a car gives about +1): 'e1' and 'e2' have opposite "
            "sign conventions; both must be positive to the left (e1 left of the path, e2 heading to its left): "
            f"flip one of them{fix}")
    if k < 0.1:
        raise LogFormatError(
            f"{source}: e1 changes {1 / k:.3g}x slower than vx*e2 predicts: 'e2' looks like degrees (must be rad){fix}")
    if k > 5.0:
        raise LogFormatError(
            f"{source}: e1 changes {k:.3g}x faster than vx*e2 predicts: 'e1' looks like cm or mm (must be m){fix}")


def _check_imu_kinematics(columns, source, fix) -> None:
    vx, r, ay = columns["vx"], columns["yaw_rate"], columns["ay"]
    pred = vx * r
    ok = np.isfinite(pred) & np.isfinite(ay) & (np.abs(pred) > 2.0)
    if ok.sum() < 50:
        return
    k, r2 = _slope(ay[ok], pred[ok])
    if r2 < 0.5:
        return
    if 0.4 <= k <= 2.5:
        return
    if -2.5 <= k <= -0.4:
        why = ("ay and yaw_rate have the opposite sign convention of ay (the log format: ay and yaw_rate both "
               "positive to the left); flip one of them")
    elif 0.2 <= k < 0.4:
        why = "'vx' looks like km/h (must be m/s)"
    elif 0.012 <= k <= 0.025:
        why = "'yaw_rate' looks like deg/s (must be rad/s)"
    elif 0 < k < 0.012:
        why = "'yaw_rate' is far too large for the a_y: it looks like deg/s or another unit (must be rad/s)"
    elif 0.07 <= k <= 0.14:
        why = "'ay' looks like g (must be m/s^2)"
    else:
        why = "check the units of vx [m/s], yaw_rate [rad/s] and ay [m/s^2]"
    raise LogFormatError(f"{source}: ay = {k:.3g} x vx*yaw_rate (a car gives about 1): {why}{fix}")


def _check_steering(columns, kind, source, fix) -> None:
    t, vx, delta = columns["t"], columns["vx"], columns["delta"]
    if kind == "imu":
        heading = _integral(t, columns["yaw_rate"])
    else:
        e2 = columns["e2"]
        frame = np.isfinite(e2)
        if frame.sum() < 50:
            return
        e2i = np.interp(t, t[frame], e2[frame])
        heading = e2i + _integral(t, vx * np.nan_to_num(columns["kappa"]))
    steer = _integral(t, vx * delta)
    idx = _windows(t, 2.0)
    if len(idx) < 10:
        return
    dh, ds = np.diff(heading[idx]), np.diff(steer[idx])
    if float(np.sum(dh**2)) < 0.01:  # too little turning to tell
        return
    inv_l, r2 = _slope(dh, ds)
    if r2 < 0.5:
        return
    if inv_l < 0:
        raise LogFormatError(f"{source}: the car turns against the steering 'delta' (heading change = "
                             f"{inv_l:.3g} x the integral of vx*delta, a car gives about +1/wheelbase): opposite "
                             "steering sign convention; 'delta' must be positive to the left, as kappa, e2 and "
                             f"yaw_rate{fix}")
    if inv_l == 0:
        return
    length = 1.0 / inv_l  # the wheelbase plus understeer the log implies [m]
    if length > 100.0:
        raise LogFormatError(f"{source}: the steering 'delta' is about {length / 3:.0f}x too large for the car's "
                             f"turning: it looks like degrees (must be the road-wheel angle in rad){fix}")
    if length > 30.0:
        raise LogFormatError(f"{source}: the steering 'delta' is about {length / 3:.0f}x too large for the car's "
                             f"turning: it looks like the steering-wheel angle (must be the road-wheel angle in rad; "
                             f"divide by the steering ratio){fix}")

