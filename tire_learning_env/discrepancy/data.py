"""From a driving log to the arrays of the multiple-shooting residual.

:func:`prepare` reads only :attr:`~tire_learning_env.io.DrivingLog.sensors` (never the
``true_*`` columns), checks that the log can support a fit, and builds

- the inputs per row: ``t``, ``delta``, ``vx``, ``psi_dot_des = vx kappa``;
- the measurements: camera ``e1``/``e2`` on rows with a frame, IMU ``yaw_rate``/``ay`` on
  rows that have them, each with a weight ``1 / sigma_channel``;
- the windows (consecutive stretches of ``window`` seconds, each simulated from
  ``preroll`` seconds before its first measurement) and a first guess of each window's
  initial state from local polynomial fits.

The noise standard deviation of each channel is estimated from the data (third
differences, which cancel any smooth signal) and floored (:class:`.config.DiscrepancyConfig`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..io import DrivingLog, LogFormatError
from ._model import CH_AY, CH_E1, CH_E2, CH_YAW, CHANNELS
from .config import DiscrepancyConfig

__all__ = ["ModelData", "prepare", "noise_std"]


@dataclass
class ModelData:
    """Inputs, measurements and windows of one log (see module docstring).

    Attributes
    ----------
    t, delta, vx, pdd : ndarray, shape (N,)
        Time [s], steering [rad], speed [m/s], desired yaw rate ``vx kappa`` [rad/s].
    dslope : ndarray, shape (N,)
        Steering slope between row ``j`` and ``j + 1`` [rad/s] (:func:`steering_slope`).
    kappa : ndarray, shape (N,)
        Path curvature [1/m].
    meas_row, meas_chan : ndarray of int64, shape (M,)
        Row and channel (``CH_*``) of each measurement, grouped by window.
    meas_val, meas_w : ndarray, shape (M,)
        Measured value and weight ``1 / sigma`` of its channel.
    sigma : ndarray, shape (4,)
        Noise standard deviation used per channel (``e1, e2, yaw_rate, ay``).
    sigma_estimated : ndarray, shape (4,)
        The data's own estimate before flooring (NaN for an absent channel).
    channels : tuple of str
        Channels present.
    win_sim, win_meas, win_end : ndarray of int64, shape (W,)
        Per window: first simulated row, first measured row, last row.
    meas_ptr : ndarray of int64, shape (W + 1,)
        Measurements of window ``w`` are ``meas_ptr[w]:meas_ptr[w+1]``.
    x0_guess : ndarray, shape (W, 4)
        First guess of the error state at ``win_sim``.
    speed_variation : float
        ``(vx_p95 - vx_p5) / median(vx)`` over the fitted rows [-].
    notes : list of str
        What was cleaned or skipped.
    """

    t: NDArray
    delta: NDArray
    dslope: NDArray
    vx: NDArray
    pdd: NDArray
    kappa: NDArray
    meas_row: NDArray
    meas_chan: NDArray
    meas_val: NDArray
    meas_w: NDArray
    sigma: NDArray
    sigma_estimated: NDArray
    channels: tuple[str, ...]
    win_sim: NDArray
    win_meas: NDArray
    win_end: NDArray
    meas_ptr: NDArray
    x0_guess: NDArray
    speed_variation: float
    notes: list[str] = field(default_factory=list)

    @property
    def n_windows(self) -> int:
        return len(self.win_sim)

    @property
    def n_measurements(self) -> int:
        return len(self.meas_row)

    def channel_mask(self, channel: str | int) -> NDArray:
        """Boolean mask of the measurements of one channel."""
        ch = CHANNELS.index(channel) if isinstance(channel, str) else int(channel)
        return self.meas_chan == ch

    def window_of_measurement(self) -> NDArray:
        """Window index of every measurement, shape (M,)."""
        return np.repeat(np.arange(self.n_windows), np.diff(self.meas_ptr))


def noise_std(y: NDArray) -> float:
    """Standard deviation of white noise on a smooth signal sampled at ``y`` (NaN-free).

    Third differences ``y[k+3] - 3 y[k+2] + 3 y[k+1] - y[k]`` cancel a locally quadratic
    signal; for white noise their variance is ``20 sigma^2``. Differences beyond five
    robust standard deviations (jumps) are dropped.
    """
    y = np.asarray(y, dtype=float)
    if len(y) < 8:
        return math.nan
    d3 = y[3:] - 3.0 * y[2:-1] + 3.0 * y[1:-2] - y[:-3]
    scale = 1.4826 * np.median(np.abs(d3 - np.median(d3)))
    if scale > 0:
        d3 = d3[np.abs(d3) <= 5.0 * scale]
    return float(np.sqrt(np.mean(d3**2) / 20.0))


STEERING_MODES = ("hold", "linear", "curvature")


def steering_slope(t: NDArray, delta: NDArray, kappa: NDArray, vx: NDArray, mode: str) -> NDArray:
    """Slope [rad/s] of the steering between row ``j`` and ``j + 1`` (``delta[j] + slope (t - t[j])``).

    - ``hold``: zero-order hold of the logged value;
    - ``linear``: linear interpolation between rows (a continuous steering signal);
    - ``curvature``: the steering follows the path curvature continuously between rows,
      ``d delta = g(vx) d kappa`` with ``g = g0 + g2 vx^2`` regressed from the log (the
      feed-forward of a lane-keeping controller), and any other change happens at the
      rows (a sampled controller acting on camera frames).
    """
    dt = np.diff(t)
    out = np.zeros(len(t))
    if mode == "hold":
        return out
    if mode == "linear":
        out[:-1] = np.diff(delta) / dt
        return out
    if mode == "curvature":
        # regress steering on curvature: delta ~ c + (g0 + g2 vx^2) kappa
        X = np.column_stack([np.ones_like(kappa), kappa, vx**2 * kappa])
        coef, *_ = np.linalg.lstsq(X, delta, rcond=None)
        g = coef[1] + coef[2] * vx**2
        out[:-1] = 0.5 * (g[:-1] + g[1:]) * np.diff(kappa) / dt
        return out
    raise ValueError(f"steering mode must be one of {STEERING_MODES}, got {mode!r}")


def _local_state(t: NDArray, y: NDArray, t0: float, half: float) -> tuple[float, float]:
    """Value and slope at ``t0`` of a quadratic least-squares fit to samples within ``t0 +/- half``."""
    sel = np.abs(t - t0) <= half
    if sel.sum() < 4:
        idx = np.argsort(np.abs(t - t0))[:4]
        sel = np.zeros(len(t), dtype=bool)
        sel[idx] = True
    tt = t[sel] - t0
    if len(tt) < 3 or np.ptp(tt) == 0:
        return float(np.mean(y[sel])), 0.0
    deg = 2 if len(tt) >= 5 else 1
    c = np.polyfit(tt, y[sel], deg)
    return float(c[-1]), float(c[-2])


def prepare(log: DrivingLog, config: DiscrepancyConfig | None = None) -> ModelData:
    """Arrays of the residual from a camera log (see module docstring).

    Raises
    ------
    LogFormatError
        Not a camera log, too short, too few frames, or no stretch fast enough to use.
    """
    config = config or DiscrepancyConfig()
    src = log.source or "log"
    if log.kind != "camera":
        raise LogFormatError(
            f"{src}: the discrepancy workflow needs a camera log (columns e1, e2, kappa); this is an IMU-only log"
        )
    s = log.sensors
    notes: list[str] = []
    t = np.asarray(s["t"], dtype=float)
    delta = np.asarray(s["delta"], dtype=float)
    vx = np.asarray(s["vx"], dtype=float)
    kappa = np.asarray(s["kappa"], dtype=float).copy()
    bad_k = ~np.isfinite(kappa)
    if bad_k.any():
        kappa[bad_k] = np.interp(t[bad_k], t[~bad_k], kappa[~bad_k]) if (~bad_k).any() else 0.0
        notes.append(f"kappa missing on {int(bad_k.sum())} rows: interpolated")
    pdd = vx * kappa
    dslope = steering_slope(t, delta, kappa, vx, config.steering)
    e1 = np.asarray(s["e1"], dtype=float)
    e2 = np.asarray(s["e2"], dtype=float)
    frames = np.isfinite(e1) & np.isfinite(e2)
    min_frames = 50
    if frames.sum() < min_frames:
        raise LogFormatError(
            f"{src}: only {int(frames.sum())} camera frames; at least {min_frames} are needed to fit anything"
        )

    # usable rows: fast enough, no long gaps
    dt = np.diff(t)
    med_dt = float(np.median(dt))
    gap = max(10.0 * med_dt, 0.25)
    slow = vx < config.min_speed
    if slow.any():
        notes.append(f"{int(slow.sum())} rows slower than {config.min_speed} m/s are not fitted")
    breaks = np.flatnonzero(dt > gap)
    if len(breaks):
        notes.append(f"{len(breaks)} gap(s) longer than {gap:.3g} s split the windows")

    # windows over contiguous usable stretches
    segments = []
    start = 0
    for b in list(breaks) + [len(t) - 1]:
        segments.append((start, b))
        start = b + 1
    win_sim, win_meas, win_end = [], [], []
    for a, b in segments:
        ok = ~slow[a : b + 1]
        # split further at slow rows
        idx = np.arange(a, b + 1)
        runs = np.split(idx[ok], np.flatnonzero(np.diff(idx[ok]) > 1) + 1) if ok.any() else []
        for run in runs:
            if len(run) < 2:
                continue
            ta = t[run[0]] + config.preroll
            tb = t[run[-1]]
            if tb - ta < 0.5 * config.window:
                continue
            n_w = max(1, int(math.floor((tb - ta) / config.window + 0.5)))
            edges = ta + (tb - ta) * np.arange(n_w + 1) / n_w
            for k in range(n_w):
                jm = int(np.searchsorted(t, edges[k], side="left"))
                je = int(np.searchsorted(t, edges[k + 1], side="left")) - 1 if k < n_w - 1 else int(run[-1])
                js = int(np.searchsorted(t, t[jm] - config.preroll - 1e-9, side="left"))
                js = max(js, int(run[0]))
                if je - jm < 3:
                    continue
                win_sim.append(js)
                win_meas.append(jm)
                win_end.append(je)
    if not win_sim:
        raise LogFormatError(
            f"{src}: too short to fit anything: no stretch of at least {0.5 * config.window + config.preroll:.3g} s "
            f"above {config.min_speed} m/s"
        )
    win_sim = np.array(win_sim, dtype=np.int64)
    win_meas = np.array(win_meas, dtype=np.int64)
    win_end = np.array(win_end, dtype=np.int64)
    total = float(np.sum(t[win_end] - t[win_meas]))
    if total < 2.0 * config.window:
        raise LogFormatError(
            f"{src}: too short to fit anything: {total:.3g} s of usable data, "
            f"at least {2 * config.window:.3g} s are needed"
        )

    # channels and their noise
    values = {CH_E1: e1, CH_E2: e2}
    present = {CH_E1: frames, CH_E2: frames}
    if config.use_imu:
        for ch, name in ((CH_YAW, "yaw_rate"), (CH_AY, "ay")):
            if name in s and np.isfinite(s[name]).sum() >= min_frames:
                values[ch] = np.asarray(s[name], dtype=float)
                present[ch] = np.isfinite(values[ch])
    sigma_est = np.full(4, math.nan)
    sigma = np.full(4, math.nan)
    floors = config.floors
    for ch, y in values.items():
        sigma_est[ch] = noise_std(y[present[ch]])
        est = sigma_est[ch] if math.isfinite(sigma_est[ch]) else 0.0
        sigma[ch] = max(est, floors[ch])

    table = np.full((4, len(t)), np.nan)
    for ch, y in values.items():
        table[ch] = y
    rows, chans, vals = [], [], []
    ptr = [0]
    for w in range(len(win_sim)):
        r = np.arange(win_meas[w], win_end[w] + 1)
        per = []
        for ch in sorted(values):
            rr = r[present[ch][r]]
            per.append((rr, np.full(len(rr), ch)))
        rr = np.concatenate([p[0] for p in per])
        cc = np.concatenate([p[1] for p in per])
        order = np.lexsort((cc, rr))
        rows.append(rr[order])
        chans.append(cc[order])
        vals.append(table[cc[order], rr[order]])
        ptr.append(ptr[-1] + len(rr))
    meas_row = np.concatenate(rows).astype(np.int64)
    meas_chan = np.concatenate(chans).astype(np.int64)
    meas_val = np.concatenate(vals)
    meas_w = 1.0 / sigma[meas_chan]

    # initial-state guesses at each window's first simulated row
    tf, y1, y2 = t[frames], e1[frames], e2[frames]
    x0 = np.zeros((len(win_sim), 4))
    for w, js in enumerate(win_sim):
        x0[w, 0], x0[w, 1] = _local_state(tf, y1, t[js], 0.75)
        x0[w, 2], x0[w, 3] = _local_state(tf, y2, t[js], 0.75)
        if CH_YAW in values and np.isfinite(values[CH_YAW][js]):
            x0[w, 3] = values[CH_YAW][js] - pdd[js]
    used = np.concatenate([np.arange(win_sim[w], win_end[w] + 1) for w in range(len(win_sim))])
    v_used = vx[used]
    variation = float((np.percentile(v_used, 95) - np.percentile(v_used, 5)) / np.median(v_used))
    chan_names = tuple(CHANNELS[c] for c in sorted(values))
    notes.append(
        f"{len(win_sim)} windows of ~{config.window:g} s, {len(meas_row)} measurements on channels {list(chan_names)}"
    )
    return ModelData(
        t=t, delta=delta, dslope=dslope, vx=vx, pdd=pdd, kappa=kappa, meas_row=meas_row, meas_chan=meas_chan,
        meas_val=meas_val, meas_w=meas_w, sigma=sigma, sigma_estimated=sigma_est, channels=chan_names,
        win_sim=win_sim, win_meas=win_meas, win_end=win_end, meas_ptr=np.array(ptr, dtype=np.int64),
        x0_guess=x0, speed_variation=variation, notes=notes,
    )  # fmt: skip
