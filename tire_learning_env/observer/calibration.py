r"""Self-calibration from the log itself: measurement noise and sampling of every channel.

A user rarely knows the noise of their lane camera or IMU, so the estimator measures it.

Noise (:func:`estimate_noise_std`). A measured channel is a smooth signal (vehicle motion:
a few hertz at most) plus white noise. Around every sample, a polynomial of degree ``p`` in
time is fitted by least squares to the ``m`` nearest valid samples (any spacing: dropped
frames and non-uniform sampling are handled exactly), and the centre sample's residual
``r_i`` is divided by ``sqrt(1 - h_ii)``, ``h_ii`` its leverage: for white noise of std
``sigma``, ``E[r_i^2] = sigma^2 (1 - h_ii)`` exactly (the hat matrix is a symmetric
projection), whatever the noise distribution (uniform, gaussian, quantised). The smooth
signal leaks only through its ``(p+1)``-th derivative over the window, which at the camera
and IMU rates of 10 Hz and above is orders of magnitude below the noise. Residuals beyond
8 robust standard deviations (a frame-to-frame jump, a spike) are left out and counted.
Why this and not innovation-based identification (autocovariance least squares): it
needs no model and no gain, so it is not biased by a wrong nominal stiffness or an
unknown latency, and it is exact for irregular sampling; the vehicle model is then
designed for the noise it measured.

Latency is a property of the camera relative to the vehicle's response, so it needs the
model: :mod:`.latency` profiles the prediction-error cost over candidate latencies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from ..params import CameraParams
    from .config import ObserverConfig
    from .model import MeasurementModel

__all__ = ["NoiseEstimate", "estimate_noise_std", "sample_period"]

#: smallest noise std used per channel (e1 [m], e2 [rad], a_y [m/s^2], r [rad/s]): resolution
NOISE_FLOOR = np.array([1e-4, 1e-4, 0.01, 1e-4])
#: noise assumed when a channel has too few samples to measure it
NOISE_DEFAULT = np.array([0.01, 0.005, 0.5, 0.005])


@dataclass
class NoiseEstimate:
    """Noise std of one channel, with what it was computed from."""

    std: float
    samples: int
    outliers: int
    relative_se: float  # approximate relative standard error of ``std``

    def to_dict(self) -> dict:
        return {"std": float(self.std), "samples": int(self.samples), "outliers": int(self.outliers),
                "relative_standard_error": float(self.relative_se)}  # fmt: skip


#: time span of the local polynomial fits that measure an IMU channel's noise [s]: band-limited
#: vibration (tens of Hz) counts in full at any sample rate (a 9-sample window at 200 Hz saw about
#: 40 % of 15-45 Hz vibration, and the fused estimate read a 1.6 m/s^2 vibration as 0.15)
IMU_NOISE_WINDOW_S = 0.1


def imu_noise_window(t: ArrayLike, z: ArrayLike) -> int:
    """Samples per local fit for an IMU channel: :data:`IMU_NOISE_WINDOW_S` at its sample
    period (odd, at least 9)."""
    t = np.asarray(t, dtype=float)
    ok = np.isfinite(np.asarray(z, dtype=float))
    dt = float(np.median(np.diff(t[ok]))) if ok.sum() > 2 else float(np.median(np.diff(t)))
    return max(9, int(round(IMU_NOISE_WINDOW_S / max(dt, 1e-6))) | 1)


def estimate_noise_std(t: ArrayLike, z: ArrayLike, window: int = 9, degree: int = 4) -> NoiseEstimate:
    """White-noise std of a channel from local polynomial residuals (module docstring).

    Parameters
    ----------
    t : array (n,)
        Sample times [s].
    z : array (n,)
        Channel values (NaN: no sample).
    window : int
        Samples per local fit (odd; the centre sample and ``window // 2`` valid neighbours
        on each side).
    degree : int
        Polynomial degree.

    Returns
    -------
    NoiseEstimate
        ``std = nan`` with fewer than ``window + 10`` valid samples.
    """
    t = np.asarray(t, dtype=float)
    z = np.asarray(z, dtype=float)
    ok = np.isfinite(z) & np.isfinite(t)
    tv, zv = t[ok], z[ok]
    n = len(zv)
    half = window // 2
    if n < window + 10:
        return NoiseEstimate(float("nan"), n, 0, float("nan"))
    idx = np.arange(half, n - half)
    offs = np.arange(-half, half + 1)
    win = idx[:, None] + offs[None, :]
    dt = tv[win] - tv[idx][:, None]
    scale = np.maximum(np.abs(dt).max(axis=1, keepdims=True), 1e-12)
    u = dt / scale
    X = u[:, :, None] ** np.arange(degree + 1)[None, None, :]  # (n, m, p+1)
    XtX = np.einsum("nmi,nmj->nij", X, X)
    Xtz = np.einsum("nmi,nm->ni", X, zv[win])
    e0 = np.zeros(degree + 1)
    e0[0] = 1.0
    try:
        inv_row = np.linalg.solve(XtX, np.broadcast_to(e0, (len(idx), degree + 1))[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return NoiseEstimate(float("nan"), n, 0, float("nan"))
    fit = np.einsum("ni,ni->n", inv_row, Xtz)  # value of the local fit at the centre
    lev = inv_row[:, 0]  # h_ii = [(X^T X)^-1]_00 at the centre (u = 0)
    r = (zv[idx] - fit) / np.sqrt(np.maximum(1.0 - lev, 1e-6))
    mad = 1.4826 * np.median(np.abs(r - np.median(r)))
    if not mad > 0:
        # exactly smooth data (a noise-free simulation): the residuals are round-off
        return NoiseEstimate(float(np.sqrt(np.mean(r**2))), n, 0, float("nan"))
    keep = np.abs(r) <= 8.0 * mad
    sigma = float(np.sqrt(np.mean(r[keep] ** 2)))
    # residuals of neighbouring centres share samples: about window/(degree+1) effective repeats
    n_eff = max(keep.sum() * (degree + 1) / window, 1.0)
    return NoiseEstimate(sigma, int(keep.sum()), int((~keep).sum()), float(np.sqrt(1.0 / (2.0 * n_eff))))


def sample_period(t: ArrayLike, z: ArrayLike | None = None) -> float:
    """Median spacing [s] of the rows where ``z`` is valid (all rows without ``z``).

    Dropped samples lengthen single intervals only, so the median is the nominal period.
    """
    t = np.asarray(t, dtype=float)
    if z is not None:
        t = t[np.isfinite(np.asarray(z, dtype=float))]
    if len(t) < 2:
        return float("nan")
    return float(np.median(np.diff(t)))


def _noise(config: ObserverConfig, rows: Mapping, model: MeasurementModel, camera: CameraParams | None) -> tuple[NDArray, dict]:
    """Noise std of the 4 channels and how each was obtained."""
    out = NOISE_DEFAULT.copy()
    info: dict = {}
    t = np.asarray(rows["t"], dtype=float)
    given = {}
    if config.camera_noise is not None:
        given["camera"] = config.camera_noise
    elif camera is not None:
        given["camera"] = tuple(camera.noise_std)
    if config.imu_noise is not None:
        given["imu"] = config.imu_noise
    for group, chans, idx in (("camera", ("e1", "e2"), (0, 1)), ("imu", ("ay", "yaw_rate"), (2, 3))):
        used = model.uses_camera if group == "camera" else model.uses_imu
        if not used:
            continue
        if group in given:
            out[list(idx)] = given[group]
            info[group] = {"source": "given", "std": [float(v) for v in given[group]]}
            continue
        est = {}
        for c, i in zip(chans, idx):
            window = imu_noise_window(t, rows[c]) if group == "imu" else 9
            e = estimate_noise_std(t, rows[c], window=window)
            est[c] = dict(e.to_dict(), window_samples=window)
            if math.isfinite(e.std):
                out[i] = e.std
        info[group] = {"source": "estimated from the log (local polynomial residuals)", "channels": est}
    floored = np.maximum(out, NOISE_FLOOR)
    info["std_used"] = dict(zip(("e1_m", "e2_rad", "ay_mps2", "yaw_rate_radps"), floored.tolist()))
    info["floor"] = NOISE_FLOOR.tolist()
    return floored, info
