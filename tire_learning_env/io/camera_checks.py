"""Camera-log symptoms the estimators cannot see for themselves (:func:`camera_warnings`).

Each of these logs reads and runs; the estimate then comes out ``not_identifiable`` or with a
wrong band without a word about why. The reader names the likely cause in a warning and the
log notes (never an error: each check looks at a symptom, and the user may know better), and
reads the repeats of a frozen camera as missing frames (:func:`frozen_frames`): a camera
repeating e1 and e2 to the last digit for a second while the car steers measured nothing new.
Measured on independent single-track logs and this package's simulated ones: each check
fires on the log it is written for and on none of about 70 good logs (sedans, SUVs, vans, race
cars; 5-300 Hz cameras, latencies, dropouts, jitter, pauses, straight roads).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numpy.typing import NDArray

__all__ = ["camera_warnings", "frozen_frames", "FROZEN_MIN_S", "FROZEN_MIN_FRAMES", "INTERPOLATED_FRACTION", "ASSUMED_WHEELBASE_M"]

#: identical consecutive camera frames (both ``e1`` and ``e2``) over at least this long [s] and this many
#: frames, while the steering moves, are named as a frozen camera
FROZEN_MIN_S = 1.0
FROZEN_MIN_FRAMES = 10
#: frames on (nearly) every row that lie on a straight line with their neighbours on at least this fraction
#: of the rows are named as a camera interpolated to every row
INTERPOLATED_FRACTION = 0.5
#: wheelbase [m] for the steering's implied heading change (a car's 2.3-3.2 m; the check has a 10x margin)
ASSUMED_WHEELBASE_M = 3.0


def _integral(t: NDArray, y: NDArray) -> NDArray:
    out = np.zeros_like(t)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))
    return out


def _frozen_runs(t: NDArray, e1: NDArray, e2: NDArray, delta: NDArray) -> list[tuple[int, int]]:
    """``(first_row, last_row)`` of each run of frames repeating the previous one exactly (both ``e1`` and
    ``e2``) over at least :data:`FROZEN_MIN_S` and :data:`FROZEN_MIN_FRAMES` while the steering moved."""
    frame = np.flatnonzero(np.isfinite(e1) & np.isfinite(e2))
    if len(frame) < FROZEN_MIN_FRAMES + 1:
        return []
    same = (np.diff(e1[frame]) == 0) & (np.diff(e2[frame]) == 0)
    edges = np.flatnonzero(np.diff(np.r_[0, same.astype(np.int8), 0]))
    found = []
    for a, b in zip(edges[::2], edges[1::2]):  # same[a:b]: frames a+1 .. b repeat frame a
        i0, i1 = int(frame[a]), int(frame[b])
        if b - a + 1 < FROZEN_MIN_FRAMES or t[i1] - t[i0] < FROZEN_MIN_S:
            continue
        steer = delta[i0 : i1 + 1]
        steer = steer[np.isfinite(steer)]
        if len(steer) and float(np.ptp(steer)) > 1e-3:
            found.append((i0, i1))
    return found


def frozen_frames(columns: Mapping[str, NDArray]) -> NDArray:
    """Rows whose camera frame only repeats the one before a frozen stretch (the module's first symptom).

    Parameters
    ----------
    columns : mapping of str -> ndarray
        ``t`` [s], ``delta`` [rad], ``e1`` [m], ``e2`` [rad] (NaN: no frame).

    Returns
    -------
    ndarray of bool
        True on the repeats (every frame of a frozen run but its first); the reader reads them as missing.
    """
    t, delta, e1, e2 = (np.asarray(columns[k], dtype=float) for k in ("t", "delta", "e1", "e2"))
    mask = np.zeros(len(t), dtype=bool)
    frame = np.isfinite(e1) & np.isfinite(e2)
    for i0, i1 in _frozen_runs(t, e1, e2, delta):
        mask[i0 + 1 : i1 + 1] = frame[i0 + 1 : i1 + 1]
    return mask


def _frozen(t: NDArray, e1: NDArray, e2: NDArray, delta: NDArray) -> str | None:
    runs = _frozen_runs(t, e1, e2, delta)
    if not runs:
        return None
    spans = [(float(t[b] - t[a]), float(t[a]), float(t[b])) for a, b in runs]
    longest = max(spans)
    repeats = int(frozen_frames({"t": t, "delta": delta, "e1": e1, "e2": e2}).sum())
    return (f"the camera repeats the same e1 and e2 exactly over {len(runs)} stretch(es) of "
            f"{sum(s[0] for s in spans):.3g} s in all (the longest {longest[0]:.3g} s, t={longest[1]:.6g}-"
            f"{longest[2]:.6g} s) while the steering moves: a frozen camera or a logger holding its last value; "
            f"its {repeats} repeated frame(s) are read as missing (no new frame)")


def _interpolated(e1: NDArray, e2: NDArray) -> str | None:
    """Frames on nearly every row that lie on straight lines between a slower camera's frames."""
    frame = np.isfinite(e1) & np.isfinite(e2)
    if frame.sum() < 100 or frame.mean() < 0.9:
        return None
    from numpy.lib.stride_tricks import sliding_window_view

    share = []
    for x in (e1[frame], e2[frame]):
        d1 = np.abs(np.diff(x))
        d2 = np.abs(np.diff(x, 2))
        # between a slower camera's frames the second difference vanishes, at its frames it jumps: 100x below
        # the largest within +/-3 rows (a smooth signal, however densely sampled, bends as much row by row)
        near = np.max(sliding_window_view(np.pad(d2, 3, mode="edge"), 7), axis=1)
        share.append(float(np.mean((d1[1:] > 0) & (d2 <= 0.01 * near))))
    if min(share) < INTERPOLATED_FRACTION:
        return None
    return (f"e1 and e2 are on (nearly) every row and lie on a straight line with their neighbours on "
            f"{100 * min(share):.0f} % of the rows: the camera looks interpolated to every row. The estimators take "
            "every row as an independent frame, which overstates the data and hides the camera's own rate and "
            "latency; leave the rows between the camera's frames empty (NaN)")


def _kappa_zero(t: NDArray, vx: NDArray, delta: NDArray, e2: NDArray, kappa: NDArray) -> str | None:
    """``kappa`` zero on every row while the steering turns the car and the heading error does not follow."""
    fin = np.isfinite(kappa)
    frame = np.isfinite(e2)
    if fin.sum() < 50 or np.any(kappa[fin] != 0) or frame.sum() < 50:
        return None
    if not (np.all(np.isfinite(vx)) and np.all(np.isfinite(delta))):
        return None
    heading = np.interp(t, t[frame], e2[frame])  # the car's heading change on a straight path
    steer = _integral(t, vx * delta) / ASSUMED_WHEELBASE_M  # the heading change the steering implies
    dist = _integral(t, vx)
    idx = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], 2.0)))
    if len(idx) < 10:
        return None
    dh, ds, dd = np.diff(heading[idx]), np.diff(steer[idx]), np.diff(dist[idx])
    # the steering's excitation beyond a constant offset (its projection on the distance)
    exc = ds - (ds @ dd) / max(float(dd @ dd), 1e-12) * dd
    rms = float(np.sqrt(np.mean(exc**2)))
    if rms < 0.05:  # a straight road: the steering barely turns the car
        return None
    coef, *_ = np.linalg.lstsq(np.column_stack([ds, dd]), dh, rcond=None)
    follows = float(coef[0])  # 1 for a car of the assumed wheelbase; ~0.3 with strong understeer
    if follows >= 0.1:
        return None
    return (f"kappa is 0 on every row, yet the steering turns the car by {rms:.2g} rad per 2 s (RMS beyond an "
            f"offset, for a {ASSUMED_WHEELBASE_M:g} m wheelbase) and the heading error e2 follows only "
            f"{100 * max(follows, 0.0):.0f} % of it: a curvy road whose curvature is missing (kappa must be the path "
            "curvature in 1/m), or a steering 'delta' that is not the road-wheel angle in rad (degrees, the "
            "steering-wheel angle)")


def camera_warnings(columns: Mapping[str, NDArray]) -> list[str]:
    """The symptoms of the module docstring found in a camera log's columns.

    Parameters
    ----------
    columns : mapping of str -> ndarray
        ``t`` [s], ``vx`` [m/s], ``delta`` [rad], ``e1`` [m], ``e2`` [rad], ``kappa`` [1/m] (NaN: no value).

    Returns
    -------
    list of str
        One message per symptom found (empty for a log without any).
    """
    if not all(k in columns for k in ("t", "vx", "delta", "e1", "e2")):
        return []
    t, vx, delta = (np.asarray(columns[k], dtype=float) for k in ("t", "vx", "delta"))
    e1, e2 = (np.asarray(columns[k], dtype=float) for k in ("e1", "e2"))
    if len(t) < 3:
        return []
    found = [_frozen(t, e1, e2, delta), _interpolated(e1, e2)]
    if "kappa" in columns:
        found.append(_kappa_zero(t, vx, delta, e2, np.asarray(columns["kappa"], dtype=float)))
    return [m for m in found if m]
