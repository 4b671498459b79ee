"""Where and how the model and the data disagree: gaps, whiteness, time windows, regimes.

All statistics take a residual :class:`~.residuals.Evaluation` (weighted residuals
``(y - y_model) / sigma`` and their initial-state sensitivities) and the log arrays
(:class:`~.data.ModelData`).

- :func:`gap`: RMS of the residual per channel, raw [channel units] and in the
  vehicle-dynamics band (a centred moving average of ``band_width`` seconds within each
  window, -3 dB at 0.443 / band_width Hz: noise above the model's bandwidth is not a
  model error), and the noise-normalised band RMS over all channels (the headline gap).
- :func:`whiteness`: portmanteau statistic of the camera residuals (sum of squared
  autocorrelations over ``whiteness_lags`` seconds, within windows), with a Monte Carlo
  null distribution: white noise of the estimated level pushed through the same
  per-window projection as the initial-state fit. It does not depend on the noise level.
- :func:`locate_windows`, :func:`regimes`, :func:`cross_correlation`: where (time) and
  when (slip level, steering rate, curvature, speed) the residual is large or structured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..metrics import centred_moving_average
from ._model import CH_AY, CH_E1, CH_E2, CH_YAW, CHANNELS, OUT_ALPHA_F, OUT_ALPHA_R
from .data import ModelData
from .residuals import Evaluation

__all__ = [
    "GapSummary",
    "gap",
    "WhitenessTest",
    "whiteness",
    "locate_windows",
    "regimes",
    "cross_correlation",
    "turn_and_braking",
    "UNITS",
]

UNITS = {"e1": "m", "e2": "rad", "yaw_rate": "rad/s", "ay": "m/s^2"}
BAND_WIDTH = 0.5  # [s] moving-average width of the vehicle-dynamics band


def band_residual(data: ModelData, resid: NDArray, width: float = BAND_WIDTH) -> tuple[NDArray, NDArray]:
    """Weighted residual smoothed per channel within each window, and the number of samples averaged.

    Returns ``(smoothed, count)``, both shape (M,).
    """
    out = np.empty_like(resid)
    count = np.empty_like(resid)
    tm = data.t[data.meas_row]
    for w in range(data.n_windows):
        a, b = data.meas_ptr[w], data.meas_ptr[w + 1]
        chan = data.meas_chan[a:b]
        for ch in np.unique(chan):
            idx = a + np.flatnonzero(chan == ch)
            t = tm[idx]
            out[idx] = centred_moving_average(t, resid[idx], width)
            lo = np.searchsorted(t, t - 0.5 * width, side="left")
            hi = np.searchsorted(t, t + 0.5 * width, side="right")
            count[idx] = hi - lo
    return out, count


@dataclass
class GapSummary:
    """Size of the disagreement between a model and the log.

    Attributes
    ----------
    rms : dict
        Raw residual RMS per channel [channel units].
    band_rms : dict
        RMS per channel in the vehicle-dynamics band [channel units].
    normalised_band_rms : dict
        Band RMS per channel divided by the channel's noise level ``sigma``, plus
        ``"camera"`` (e1 and e2 together) and ``"all"`` (every channel). A channel whose
        noise is below its floor counts the floor noise's expected band contribution, so a
        noise-free simulated IMU is not an advantage.
    """

    rms: dict
    band_rms: dict
    normalised_band_rms: dict

    def to_dict(self) -> dict:
        return {
            "rms": self.rms,
            "band_rms": self.band_rms,
            "normalised_band_rms": self.normalised_band_rms,
            "units": {k: UNITS[k] for k in self.rms},
        }


def gap(data: ModelData, evaluation: Evaluation, width: float = BAND_WIDTH) -> GapSummary:
    """Raw and band-limited residual RMS per channel (see module docstring)."""
    r = evaluation.resid
    smooth, count = band_residual(data, r, width)
    rms, band, norm = {}, {}, {}
    sq_all, sq_cam = [], []
    for ch, name in enumerate(CHANNELS):
        m = data.meas_chan == ch
        if not m.any():
            continue
        sigma = data.sigma[ch]
        rms[name] = float(np.sqrt(np.mean(r[m] ** 2)) * sigma)
        band[name] = float(np.sqrt(np.mean(smooth[m] ** 2)) * sigma)
        sq = smooth[m] ** 2
        est = data.sigma_estimated[ch]
        if not math.isfinite(est) or est < sigma:
            # the channel is quieter than its floor: add the floor noise's expected band power
            missing = 1.0 - (est / sigma) ** 2 if math.isfinite(est) else 1.0
            sq = sq + missing / count[m]
        norm[name] = float(np.sqrt(np.mean(sq)))
        sq_all.append(sq)
        if ch in (CH_E1, CH_E2):
            sq_cam.append(sq)
    if sq_cam:
        norm["camera"] = float(np.sqrt(np.mean(np.concatenate(sq_cam))))
    if data.kind == "imu":
        norm["imu"] = float(np.sqrt(np.mean(np.concatenate(sq_all))))
    norm["all"] = float(np.sqrt(np.mean(np.concatenate(sq_all))))
    return GapSummary(rms, band, norm)


def _window_projectors(data: ModelData, jac: NDArray) -> list[NDArray]:
    """Orthonormal basis (Q of a QR) of each window's initial-state sensitivities."""
    out = []
    for w in range(data.n_windows):
        a, b = data.meas_ptr[w], data.meas_ptr[w + 1]
        J = jac[a:b]
        q, rr = np.linalg.qr(J)
        keep = np.abs(np.diag(rr)) > 1e-10 * max(np.abs(np.diag(rr)).max(), 1e-300)
        out.append(q[:, keep])
    return out


def _portmanteau(data: ModelData, resid: NDArray, lags: dict[int, int]) -> NDArray:
    """``n sum_l rho_l^2`` per primary channel (pairs within windows only); resid may be (M,) or (M, D).

    The lag products are summed over windows by FFT (each window's segment zero-padded, so no pair
    crosses a window boundary): the same sums as a direct loop over lags, in ``O(n log n)``.
    """
    r2 = resid if resid.ndim == 2 else resid[:, None]
    wid = data.window_of_measurement()
    out = np.zeros((len(lags), r2.shape[1]))
    for i, (ch, n_lag) in enumerate(sorted(lags.items())):
        idx = np.flatnonzero(data.meas_chan == ch)
        x = r2[idx]
        x = x - x.mean(axis=0)
        w = wid[idx]
        denom = np.sum(x * x, axis=0)
        # segments per window: position of each sample within its window's run
        starts = np.flatnonzero(np.concatenate([[True], w[1:] != w[:-1]]))
        lengths = np.diff(np.concatenate([starts, [len(w)]]))
        seg = np.repeat(np.arange(len(starts)), lengths)
        pos = np.arange(len(w)) - np.repeat(starts, lengths)
        nfft = 1 << int(math.ceil(math.log2(max(int(lengths.max()) + n_lag + 1, 2))))
        q = np.zeros(r2.shape[1])
        for d0 in range(0, r2.shape[1], 8):
            d1 = min(r2.shape[1], d0 + 8)
            pad = np.zeros((len(starts), nfft, d1 - d0))
            pad[seg, pos] = x[:, d0:d1]
            f = np.fft.rfft(pad, axis=1)
            acf = np.fft.irfft((f * np.conj(f)).real, n=nfft, axis=1)[:, 1 : n_lag + 1].sum(axis=0)  # (L, D)
            q[d0:d1] = np.sum((acf / denom[d0:d1]) ** 2, axis=0)
        out[i] = len(idx) * q
    return out.sum(axis=0)


@dataclass
class WhitenessTest:
    """Portmanteau whiteness test of the camera residual with a Monte Carlo null.

    Attributes
    ----------
    statistic : float
        Observed ``sum_channels n sum_l rho_l^2``.
    null_mean, null_q99 : float
        Mean and 99th percentile of the null distribution.
    p_value : float
        Tail probability of ``statistic`` under a scaled chi-square fitted to the null
        draws' mean and variance (the portmanteau statistic is close to chi-square).
    lags : dict
        Lags used per camera channel.
    acf : dict
        Autocorrelation per camera channel at lags 1..L (for the report).
    """

    statistic: float
    null_mean: float
    null_q99: float
    p_value: float
    lags: dict
    acf: dict

    def to_dict(self) -> dict:
        return {
            "statistic": self.statistic,
            "null_mean": self.null_mean,
            "null_q99": self.null_q99,
            "p_value": self.p_value,
            "lags": self.lags,
        }


def whiteness(
    data: ModelData, evaluation: Evaluation, lag_span: float, draws: int, rng: np.random.Generator
) -> WhitenessTest:
    """Portmanteau test of the residuals of the primary channels (see module docstring).

    Primary channels (``data.primary``): camera ``e1, e2`` for a camera log, ``yaw_rate,
    ay`` for an IMU-only log (there they carry the real measurement noise).
    """
    lags = {}
    for ch in data.primary:
        rows = data.meas_row[data.meas_chan == ch]
        if len(rows) < 20:
            continue
        rate = 1.0 / float(np.median(np.diff(data.t[rows])))
        lags[ch] = max(1, int(round(lag_span * rate)))
    stat = float(_portmanteau(data, evaluation.resid, lags)[0])
    # null: white noise through the same per-window projection
    qs = _window_projectors(data, evaluation.jac)
    m = data.n_measurements
    null = []
    for start in range(0, draws, 25):
        noise = rng.standard_normal((m, min(25, draws - start)))
        for w, q in enumerate(qs):
            a, b = data.meas_ptr[w], data.meas_ptr[w + 1]
            block = noise[a:b]
            noise[a:b] = block - q @ (q.T @ block)
        null.append(_portmanteau(data, noise, lags))
    null = np.concatenate(null)
    # p-value from a chi-square matched to the null draws' mean and variance (smooth in the tail)
    mean, var = float(np.mean(null)), float(np.var(null, ddof=1))
    if mean > 0 and var > 0:
        scale = var / (2.0 * mean)
        p = float(stats.chi2.sf(stat / scale, 2.0 * mean**2 / var))
    else:  # nothing to test (no camera channel long enough)
        p = 1.0
    acf = {}
    wid = data.window_of_measurement()
    for ch, n_lag in lags.items():
        idx = np.flatnonzero(data.meas_chan == ch)
        x = evaluation.resid[idx] - evaluation.resid[idx].mean()
        w = wid[idx]
        d = float(x @ x)
        values = []
        for lag in range(1, n_lag + 1):
            same = w[lag:] == w[:-lag]
            values.append(float(np.sum(x[lag:][same] * x[:-lag][same]) / d))
        acf[CHANNELS[ch]] = values
    return WhitenessTest(
        stat, float(np.mean(null)), float(np.quantile(null, 0.99)), p, {CHANNELS[c]: n for c, n in lags.items()}, acf
    )


def locate_windows(data: ModelData, evaluation: Evaluation, level: float = 0.01) -> list[dict]:
    """Per window: time span, normalised residual mean square per channel, and whether it is excessive.

    A window is flagged when the mean square of its primary residuals (camera ``e1, e2``;
    ``yaw_rate, ay`` for an IMU-only log: the channels with real measurement noise) exceeds
    the chi-square ``1 - level`` quantile of pure noise for its number of samples, or when
    another (IMU) channel's mean square exceeds the same limit for that channel (its noise
    level being the floor when it is quieter).
    """
    out = []
    r = evaluation.resid
    n_state = evaluation.x0.shape[1] if evaluation.x0.ndim == 2 else 4
    for w in range(data.n_windows):
        a, b = data.meas_ptr[w], data.meas_ptr[w + 1]
        rr = r[a:b]
        chan = data.meas_chan[a:b]
        per = {CHANNELS[c]: float(np.mean(rr[chan == c] ** 2)) for c in np.unique(chan)}
        cam = np.isin(chan, data.primary)
        dof = max(int(cam.sum()) - n_state, 1)
        ms = float(np.sum(rr[cam] ** 2)) / dof
        limit = float(stats.chi2.isf(level, dof)) / dof
        flagged = ms > limit
        for c in np.unique(chan):
            if c not in data.primary:
                k = int(np.sum(chan == c))
                flagged |= per[CHANNELS[c]] > float(stats.chi2.isf(level, k)) / k
        out.append(
            {
                "t_start": float(data.t[data.win_meas[w]]),
                "t_end": float(data.t[data.win_end[w]]),
                "mean_square": ms,
                "limit": limit,
                "flagged": bool(flagged),
                "per_channel": per,
            }
        )
    return out


def regimes(data: ModelData, evaluation: Evaluation, trajectories: NDArray, n_bins: int = 4) -> dict:
    """Normalised residual mean square binned by regime: |slip|, |steering rate|, |curvature|, speed.

    For an IMU-only log: |slip|, |steering rate|, |a_y|, speed, a_x and signed a_y
    (measured), with the signed mean residual per channel in each bin as well.

    ``trajectories`` are the model's per-row outputs (:meth:`.ResidualModel.trajectories`),
    from which the slip level is taken. Each regime has quantile bins with their edges,
    counts and mean squares (1 = noise level).
    """
    r2 = evaluation.resid**2
    rows = data.meas_row
    cam = np.isin(data.meas_chan, data.primary)
    dt = np.gradient(data.t)
    steer_rate = np.abs(np.gradient(data.delta) / dt)
    slip = np.maximum(np.abs(trajectories[:, OUT_ALPHA_F]), np.abs(trajectories[:, OUT_ALPHA_R]))
    if data.kind == "imu":
        ay = _measured(data, CH_AY)
        variables = {
            "slip_angle_abs": (slip, "rad"),
            "steering_rate_abs": (steer_rate, "rad/s"),
            "ay_abs": (np.abs(ay), "m/s^2"),
            "speed": (data.vx, "m/s"),
            "ax": (data.ax, "m/s^2"),
            "ay": (ay, "m/s^2"),
        }
    else:
        variables = {
            "slip_angle_abs": (slip, "rad"),
            "steering_rate_abs": (steer_rate, "rad/s"),
            "curvature_abs": (np.abs(data.kappa), "1/m"),
            "speed": (data.vx, "m/s"),
        }
    out = {}
    for name, (values, unit) in variables.items():
        v = values[rows]
        ok = np.isfinite(v) & cam
        if ok.sum() < n_bins * 10:
            continue
        edges = np.unique(np.quantile(v[ok], np.linspace(0, 1, n_bins + 1)))
        if len(edges) < 2:
            continue
        idx = np.clip(np.searchsorted(edges, v[ok], side="right") - 1, 0, len(edges) - 2)
        bins = []
        for k in range(len(edges) - 1):
            sel = idx == k
            entry = {
                "low": float(edges[k]),
                "high": float(edges[k + 1]),
                "count": int(sel.sum()),
                "mean_square": float(np.mean(r2[ok][sel])) if sel.any() else math.nan,
            }
            if data.kind == "imu":
                # signed mean residual per channel [channel units]: a bias-like structure shows here
                # (e.g. the same sign in left and right turns)
                bin_rows = rows[ok][sel]
                chans = data.meas_chan[ok][sel]
                res = evaluation.resid[ok][sel]
                entry["mean_residual"] = {
                    CHANNELS[c]: float(np.mean(res[chans == c]) * data.sigma[c]) for c in data.primary
                    if np.any(chans == c)
                }
                entry["row_count"] = int(len(np.unique(bin_rows)))
            bins.append(entry)
        out[name] = {"unit": unit, "bins": bins}
    return out


#: thresholds of :func:`turn_and_braking` [m/s^2]
TURN_AY = 2.0
BRAKE_AX = 2.0


def turn_and_braking(data: ModelData, evaluation: Evaluation) -> dict:
    """IMU logs: mean band-limited residual per channel by turn direction and longitudinal phase.

    Cells: turn (measured ``a_y`` averaged over 0.5 s: ``left`` > 2 m/s^2, ``straight``,
    ``right`` < -2 m/s^2) times phase (``a_x`` input: ``braking`` < -2 m/s^2, ``neutral``,
    ``traction`` > 2 m/s^2). Per phase also the parts of the turning residual that are
    *odd* in the turn direction, ``(left - right) / 2`` (the car turns more or less than the
    model: tire, load transfer, steering), and *even*, ``(left + right) / 2`` (the same sign
    in left and right turns: a pull, a bias, a sensor or reference effect). Residual in
    channel units [rad/s], [m/s^2]; ``n`` = samples.
    """
    smooth, _ = band_residual(data, evaluation.resid)
    ay = _measured(data, CH_AY)
    fin = np.isfinite(ay)
    ay_s = np.full(len(data.t), np.nan)
    if fin.any():

        ay_s[fin] = centred_moving_average(data.t[fin], ay[fin], 0.5)
    turns = {"left": lambda a: a > TURN_AY, "straight": lambda a: np.abs(a) <= TURN_AY, "right": lambda a: a < -TURN_AY}
    phases = {"braking": lambda x: x < -BRAKE_AX, "neutral": lambda x: np.abs(x) <= BRAKE_AX,
              "traction": lambda x: x > BRAKE_AX}  # fmt: skip
    out: dict = {"thresholds_mps2": {"turn_ay": TURN_AY, "brake_ax": BRAKE_AX}, "cells": {}, "odd": {}, "even": {}}
    for ch in data.primary:
        name = CHANNELS[ch]
        m = data.meas_chan == ch
        rows = data.meas_row[m]
        r = smooth[m] * data.sigma[ch]
        a, x = ay_s[rows], data.ax[rows]
        for ph, fp in phases.items():
            means = {}
            for tn, ft in turns.items():
                sel = np.isfinite(a) & ft(a) & fp(x)
                cell = out["cells"].setdefault(f"{ph}/{tn}", {})
                cell["n"] = int(sel.sum())
                cell[name] = float(np.mean(r[sel])) if sel.sum() >= 20 else math.nan
                means[tn] = cell[name]
            out["odd"].setdefault(ph, {})[name] = 0.5 * (means["left"] - means["right"])
            out["even"].setdefault(ph, {})[name] = 0.5 * (means["left"] + means["right"])
    return out


def _measured(data: ModelData, channel: int) -> NDArray:
    """Measured values of a channel per row (NaN where it has none), shape (N,)."""
    out = np.full(len(data.t), np.nan)
    m = data.meas_chan == channel
    out[data.meas_row[m]] = data.meas_val[m]
    return out


def cross_correlation(data: ModelData, evaluation: Evaluation, max_lag: float = 1.0) -> dict:
    """Correlation of each channel's residual with the inputs at lags ``-max_lag..max_lag``.

    Inputs: steering, steering rate, curvature, speed (at the measurement rows); for an
    IMU-only log steering, steering rate, speed, ``ax`` and the measured ``a_y``. Returns
    per (channel, input) the lag [s] and value of the largest correlation and the
    ``2 / sqrt(n)`` band of a white residual.
    """
    dt_row = np.gradient(data.t)
    if data.kind == "imu":
        inputs = {
            "delta": data.delta,
            "steering_rate": np.gradient(data.delta) / dt_row,
            "vx": data.vx,
            "ax": data.ax,
            "ay_measured": np.nan_to_num(_measured(data, CH_AY)),
        }
    else:
        inputs = {
            "delta": data.delta,
            "steering_rate": np.gradient(data.delta) / dt_row,
            "kappa": data.kappa,
            "vx": data.vx,
        }
    out = {}
    for ch in (CH_E1, CH_E2, CH_YAW, CH_AY):
        m = data.meas_chan == ch
        if m.sum() < 20:
            continue
        rows = data.meas_row[m]
        r = evaluation.resid[m] - evaluation.resid[m].mean()
        rate = 1.0 / float(np.median(np.diff(data.t[rows])))
        n_lag = max(1, int(round(max_lag * rate)))
        for name, u in inputs.items():
            x = u[rows] - u[rows].mean()
            denom = math.sqrt(float(r @ r) * float(x @ x))
            if denom == 0:
                continue
            best = (0.0, 0.0)
            for lag in range(-n_lag, n_lag + 1):
                if lag >= 0:
                    c = float(r[lag:] @ x[: len(x) - lag]) / denom
                else:
                    c = float(r[:lag] @ x[-lag:]) / denom
                if abs(c) > abs(best[1]):
                    best = (lag / rate, c)
            out[f"{CHANNELS[ch]}~{name}"] = {
                "lag_s": best[0],
                "correlation": best[1],
                "white_band": 2.0 / math.sqrt(len(r)),
            }
    return out
