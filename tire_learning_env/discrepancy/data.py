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

An IMU-only log (no ``e1``, ``e2``, ``kappa``) goes to :func:`prepare_imu`: inputs
``delta``, ``vx`` and a smoothed ``ax``, measurements ``yaw_rate`` and ``ay``, windows as
above, initial state ``[vy, r]`` of the body-frame model (:mod:`._body_model`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..io import DrivingLog, LogFormatError
from ..metrics import centred_moving_average
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
    kind : {"camera", "imu"}
        Which model compares: the error-coordinate model (camera log) or the body-frame
        model (IMU-only log, :mod:`._body_model`).
    ax : ndarray, shape (N,), optional
        Longitudinal acceleration input of the body-frame model [m/s^2] (IMU logs).
    primary : tuple of int
        Channels that carry real measurement noise and enter the whiteness test and the
        per-window limits: ``e1, e2`` for a camera log, ``yaw_rate, ay`` for an IMU log.
    ay_guess : ndarray, shape (W,), optional
        IMU logs: locally fitted ``a_y`` at each window's first row (for the ``vy`` guess).
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
    kind: str = "camera"
    ax: NDArray | None = None
    primary: tuple[int, ...] = (CH_E1, CH_E2)
    ay_guess: NDArray | None = None

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


def window_subset(data: ModelData, windows: NDArray) -> ModelData:
    """The same log restricted to some of its windows (rows shared, measurements of those windows only)."""
    from dataclasses import replace

    windows = np.asarray(windows, dtype=np.int64)
    idx = np.concatenate([np.arange(data.meas_ptr[w], data.meas_ptr[w + 1]) for w in windows])
    ptr = np.concatenate([[0], np.cumsum([data.meas_ptr[w + 1] - data.meas_ptr[w] for w in windows])])
    return replace(
        data, meas_row=data.meas_row[idx], meas_chan=data.meas_chan[idx], meas_val=data.meas_val[idx],
        meas_w=data.meas_w[idx], win_sim=data.win_sim[windows], win_meas=data.win_meas[windows],
        win_end=data.win_end[windows], meas_ptr=ptr.astype(np.int64), x0_guess=data.x0_guess[windows].copy(),
        notes=list(data.notes), ay_guess=None if data.ay_guess is None else data.ay_guess[windows],
    )  # fmt: skip


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



def _windows(t: NDArray, vx: NDArray, config: DiscrepancyConfig, src: str, notes: list[str]):
    """Windows over contiguous usable stretches (fast enough, no long gaps): first simulated,
    first measured and last row of each. Raises :class:`LogFormatError` when nothing is usable."""
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
    return win_sim, win_meas, win_end


def _measurements(
    values: dict, present: dict, win_meas: NDArray, win_end: NDArray, config: DiscrepancyConfig, n_rows: int
):
    """Noise levels per channel and the measurement arrays grouped by window."""
    sigma_est = np.full(4, math.nan)
    sigma = np.full(4, math.nan)
    floors = config.floors
    for ch, y in values.items():
        sigma_est[ch] = noise_std(y[present[ch]])
        est = sigma_est[ch] if math.isfinite(sigma_est[ch]) else 0.0
        sigma[ch] = max(est, floors[ch])

    table = np.full((4, n_rows), np.nan)
    for ch, y in values.items():
        table[ch] = y
    rows, chans, vals = [], [], []
    ptr = [0]
    for w in range(len(win_meas)):
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
    return sigma, sigma_est, meas_row, meas_chan, meas_val, meas_w, ptr


def prepare(log: DrivingLog, config: DiscrepancyConfig | None = None, camera_x: float = 0.0) -> ModelData:
    """Arrays of the residual from a camera log, or from an IMU-only log (:func:`prepare_imu`).

    A camera ``camera_x`` [m] ahead of the CG (:attr:`~tire_learning_env.params.VehicleParams.camera_x`) sees
    ``e1 + camera_x sin(e2) - kappa camera_x^2 / 2``: the path's own bend over ``camera_x`` (``kappa`` is known)
    is added back onto the logged ``e1`` here, and the model measures the rest
    (:func:`._model.predict_measurements`), as the estimator does.

    Raises
    ------
    LogFormatError
        Too short, too few frames / IMU samples, or no stretch fast enough to use.
    """
    config = config or DiscrepancyConfig()
    src = log.source or "log"
    if log.kind != "camera":
        return prepare_imu(log, config)
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
    dslope = steering_slope(t, delta, kappa, vx, "curvature" if config.steering == "auto" else config.steering)
    e1 = np.asarray(s["e1"], dtype=float)
    if camera_x:
        from ..observer.model import camera_path_bend  # here: the observer package is not imported otherwise

        e1 = e1 + camera_path_bend(kappa, camera_x)
    e2 = np.asarray(s["e2"], dtype=float)
    frames = np.isfinite(e1) & np.isfinite(e2)
    min_frames = 50
    if frames.sum() < min_frames:
        raise LogFormatError(
            f"{src}: only {int(frames.sum())} camera frames; at least {min_frames} are needed to fit anything"
        )

    win_sim, win_meas, win_end = _windows(t, vx, config, src, notes)

    # channels and their noise
    values = {CH_E1: e1, CH_E2: e2}
    present = {CH_E1: frames, CH_E2: frames}
    if config.use_imu:
        for ch, name in ((CH_YAW, "yaw_rate"), (CH_AY, "ay")):
            if name in s and np.isfinite(s[name]).sum() >= min_frames:
                values[ch] = np.asarray(s[name], dtype=float)
                present[ch] = np.isfinite(values[ch])
    sigma, sigma_est, meas_row, meas_chan, meas_val, meas_w, ptr = _measurements(
        values, present, win_meas, win_end, config, len(t)
    )

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


#: how an IMU-only log is named in error messages (the reader says which kind of log it found)
IMU_LOG = "IMU-only log, not a camera log: compared on yaw_rate and ay"
#: centred moving-average widths of the longitudinal acceleration input [s]: the slope of vx, and
#: the slow part of the logged ax (:func:`prepare_imu`)
AX_SMOOTHING = 0.1
AX_SLOW = 1.0


def prepare_imu(log: DrivingLog, config: DiscrepancyConfig | None = None) -> ModelData:
    """Arrays of the residual from an IMU-only log (``t, vx, delta, yaw_rate, ay`` [, ``ax``]).

    The body-frame model (:mod:`._body_model`) is compared with the IMU channels
    ``yaw_rate`` and ``ay``; the longitudinal acceleration input (it enters the longitudinal
    load transfer only) is the slope of ``vx`` averaged over :data:`AX_SMOOTHING` s plus
    the slow part (:data:`AX_SLOW` s) of the logged ``ax`` minus that slope. Steering
    between rows is ``linear`` (a continuous signal) unless ``config.steering`` is ``hold``
    (``curvature`` needs a path curvature and falls back to ``linear``, noted). Windows have
    no pre-roll: the state is fitted at each window's first measured row. Only sensors are
    read (never ``true_*``).
    """
    config = config or DiscrepancyConfig()
    src = f"{log.source or 'log'} ({IMU_LOG})"
    s = log.sensors
    notes: list[str] = []
    if not config.use_imu:
        raise LogFormatError(f"{src}: use_imu is off, but an IMU-only log has no other channel to compare")
    missing = [c for c in ("yaw_rate", "ay") if c not in s]
    if missing:
        raise LogFormatError(f"{src}: needs columns yaw_rate [rad/s] and ay [m/s^2]; missing {missing}")
    t = np.asarray(s["t"], dtype=float)
    delta = np.asarray(s["delta"], dtype=float)
    vx = np.asarray(s["vx"], dtype=float)
    mode = config.steering
    if mode in ("curvature", "auto"):
        mode = "linear"
        notes.append("steering between rows: linear (an IMU-only log has no path curvature)")
    dslope = steering_slope(t, delta, np.zeros_like(t), vx, mode)
    # longitudinal acceleration: the slope of vx (clean: vx comes from GNSS/INS or wheel speeds) over
    # AX_SMOOTHING, plus the slow part of (logged ax - slope) over AX_SLOW (grade, -r vy, sensor offset:
    # the specific force is what transfers load), a complementary filter of the two
    slope = np.gradient(vx, t) if len(t) > 1 else np.zeros_like(t)
    ax = centred_moving_average(t, slope, AX_SMOOTHING)
    if "ax" in s and np.isfinite(s["ax"]).sum() >= 0.5 * len(t):
        ax_log = np.asarray(s["ax"], dtype=float).copy()
        bad = ~np.isfinite(ax_log)
        if bad.any():
            ax_log[bad] = np.interp(t[bad], t[~bad], ax_log[~bad])
            notes.append(f"ax missing on {int(bad.sum())} rows: interpolated")
        ax = ax + centred_moving_average(t, ax_log - slope, AX_SLOW)
        what = (f"slope of vx ({AX_SMOOTHING:g} s centred moving average) + slow part of logged ax - slope "
                f"({AX_SLOW:g} s)")  # fmt: skip
    else:
        what = f"slope of vx ({AX_SMOOTHING:g} s centred moving average; no ax column)"
    notes.append(f"longitudinal acceleration input (load transfer only): {what}")
    min_samples = 50
    values, present = {}, {}
    for ch, name in ((CH_YAW, "yaw_rate"), (CH_AY, "ay")):
        y = np.asarray(s[name], dtype=float)
        ok = np.isfinite(y)
        if ok.sum() < min_samples:
            raise LogFormatError(f"{src}: only {int(ok.sum())} valid {name} samples; at least {min_samples} are needed")
        values[ch], present[ch] = y, ok

    # no pre-roll: the body-frame state is fitted at the window's first measured row, where the
    # gyro pins r (the fast lateral modes could otherwise turn any initial state into a fit);
    # a steering delay reads the logged steering before the window directly
    win_sim, win_meas, win_end = _windows(t, vx, config.replace(preroll=0.0), src, notes)
    sigma, sigma_est, meas_row, meas_chan, meas_val, meas_w, ptr = _measurements(
        values, present, win_meas, win_end, config, len(t)
    )
    # initial-state guesses: yaw rate and lateral acceleration from local fits (the residual
    # model turns a_y into a lateral velocity with the nominal vehicle, :class:`.ResidualModel`)
    x0 = np.zeros((len(win_sim), 2))
    ay0 = np.zeros(len(win_sim))
    for w, js in enumerate(win_sim):
        for ch, out in ((CH_YAW, None), (CH_AY, ay0)):
            fin = present[ch]
            value, _ = _local_state(t[fin], values[ch][fin], t[js], 0.1)
            if out is None:
                x0[w, 1] = value
            else:
                out[w] = value
    used = np.concatenate([np.arange(win_sim[w], win_end[w] + 1) for w in range(len(win_sim))])
    v_used = vx[used]
    variation = float((np.percentile(v_used, 95) - np.percentile(v_used, 5)) / np.median(v_used))
    chan_names = ("yaw_rate", "ay")
    notes.append(
        f"IMU-only log: body-frame model; {len(win_sim)} windows of ~{config.window:g} s, {len(meas_row)} "
        f"measurements on channels {list(chan_names)}"
    )
    zeros = np.zeros_like(t)
    return ModelData(
        t=t, delta=delta, dslope=dslope, vx=vx, pdd=zeros, kappa=zeros, meas_row=meas_row, meas_chan=meas_chan,
        meas_val=meas_val, meas_w=meas_w, sigma=sigma, sigma_estimated=sigma_est, channels=chan_names,
        win_sim=win_sim, win_meas=win_meas, win_end=win_end, meas_ptr=np.array(ptr, dtype=np.int64),
        x0_guess=x0, speed_variation=variation, notes=notes, kind="imu", ax=ax, primary=(CH_YAW, CH_AY),
        ay_guess=ay0,
    )  # fmt: skip
