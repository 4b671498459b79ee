"""Reading and cleaning real IMU-only driving logs (``LOG_FORMAT.md``, IMU-only form).

:func:`..io.read_log` does the generic, strict part (required columns, monotonic time,
units of ``delta``, truth kept apart). This module adds what an IMU log needs and what a
real one gets wrong, and *reports* everything it changes (:class:`CleaningReport`, also
appended to ``log.notes``):

Errors (:class:`..io.LogFormatError`, naming the problem)
    - no ``yaw_rate`` or ``ay`` column;
    - a stretch without rows (:func:`..io.row_gaps`: a step over 10x the median and
      over 0.5 s, the reader's gap), unless ``allow_gaps`` (the ``estimate`` command: every
      estimator restarts its state after such a pause, :func:`.estimate.estimate_imu`);
    - ``yaw_rate`` that cannot be in rad/s (``|r| > 5 rad/s``: deg/s?);
    - ``ay`` that cannot be in m/s^2 or has the wrong sign: while cornering, ``a_y`` must
      follow ``vx r`` (slope 0.5-2; a slope near 0.1 means g units, a negative one the
      opposite sign convention);
    - ``delta`` whose sign disagrees with the yaw rate (``delta`` vs ``L r / vx``);
    - too few rows with a valid IMU sample at or above :data:`MIN_SPEED`.

Accepted and named (``LOG_FORMAT.md`` allows them)
    - timestamp jitter: steps off the median by more than 25 % (below the gap threshold). Every
      estimator predicts over each row's own step (the observer's kernel, the linear KF, the
      blend's switching); only the observer's certified gains are designed for the median step.
      Counted in ``CleaningReport.sampling``, a warning and the notes.
    - rows slower than :data:`MIN_SPEED` (a drive starting or stopping at standstill, reversing):
      the bicycle model is singular at ``vx = 0`` (every estimator floors the speed there), so
      their ``ay`` and ``yaw_rate`` become NaN: the estimators predict through them without a
      correction, as the camera path does between frames. Counted in ``CleaningReport.low_speed``,
      a warning and the notes.

Cleaning (causal: each sample is judged from the past only, as a car would on line)
    - ``delta`` and ``yaw_rate`` samples that jump from the last accepted value by more
      than a physical rate allows (road-wheel rate ``max_steer_rate``, yaw acceleration
      ``max_yaw_accel``) are replaced by that value: a single-sample spike (the 1 kHz ->
      100 Hz decimation defect of the Revs steering channel) disappears; genuine motion is
      never that fast. A jump that persists over 3 samples is accepted as a real level
      change (and counted).
    - ``ay`` beyond ``max_abs_ay`` (3 g: no road car tire makes that) becomes NaN.
    - NaN ``ay``/``yaw_rate`` samples are kept as NaN: the observer predicts through them.

Accelerometer position (``VehicleParams.imu_x``, the vehicle file's ``imu_x``)
    An accelerometer ``x`` ahead of the centre of gravity reads ``a_y + x r_dot``; the model's
    ``a_y`` is the CG's. With ``imu_x`` set, ``a_y - imu_x r_dot`` is used
    (:func:`accelerometer_at_cg`; ``r_dot`` from the yaw rate, a centred derivative of its
    0.1 s moving mean, so this step alone looks 0.05 s ahead). Left in, the learned curves absorb it:
    on an independent single-track log 0.3 m ahead gave +5.5 / +8.4 % stiffness and 1.0 m
    +20 / +33 %, identified with bands that missed. Default 0: at the CG (``metrics.json``
    ``not_modelled`` says so).

Noise is *not* filtered here: the certified gains (H2, noise std in the design) and the
regression weight the measurements; vibration bursts in ``a_y`` (kerbs) are real signal
content of the accelerometer and are counted, not removed.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..io import DrivingLog, LogFormatError, read_log, row_gaps
from ..metrics import centred_moving_average
from ..observer._kernel import V_FLOOR
from ..params import VehicleParams

__all__ = ["CleaningReport", "MIN_SPEED", "accelerometer_at_cg", "clean_imu_log", "read_imu_log", "check_imu_log"]

#: rows slower than this carry no IMU correction [m/s]: the estimators' speed floor (``V_FLOOR``), where
#: the bicycle model stops describing the car (singular at standstill)
MIN_SPEED = V_FLOOR


@dataclass
class CleaningReport:
    """What :func:`clean_imu_log` found and changed.

    Attributes
    ----------
    rows : int
    dt : float
        Median sample period [s].
    steering_spikes : dict
        ``count``, ``t`` (times), ``max_deviation_rad`` of the replaced ``delta`` samples,
        and ``level_jumps_accepted``.
    yaw_rate_spikes : dict
        The same for ``yaw_rate``.
    ay_out_of_range : dict
        ``count`` and ``t`` of ``a_y`` samples set to NaN.
    missing : dict
        NaN counts of ``ay`` and ``yaw_rate`` after cleaning (prediction-only rows).
    repeated_fraction : dict
        Fraction of rows repeating the previous value exactly (sample-and-hold of a
        slower sensor; information only).
    ay_high_frequency_std : float
        Std of ``a_y`` minus its 3-sample moving mean [m/s^2] (vibration level; information).
    checks : dict
        Unit and sign checks with their measured values.
    low_speed : dict
        ``count`` of rows slower than :data:`MIN_SPEED` whose ``ay`` and ``yaw_rate`` became NaN,
        ``limit_mps`` and their ``spans_s`` (first and last time of each run, at most 20).
    sampling : dict
        ``median_dt_s``, ``min_dt_s``, ``max_dt_s`` and ``jitter_steps``: steps off the median by
        more than 25 % (accepted: each is predicted over its own duration).
    """

    rows: int
    dt: float
    steering_spikes: dict = field(default_factory=dict)
    yaw_rate_spikes: dict = field(default_factory=dict)
    ay_out_of_range: dict = field(default_factory=dict)
    missing: dict = field(default_factory=dict)
    repeated_fraction: dict = field(default_factory=dict)
    ay_high_frequency_std: float = float("nan")
    checks: dict = field(default_factory=dict)
    low_speed: dict = field(default_factory=lambda: {"count": 0})
    sampling: dict = field(default_factory=lambda: {"jitter_steps": 0})
    imu_position: dict = field(default_factory=lambda: {"imu_x_m": 0.0})

    def to_dict(self) -> dict:
        return {
            "rows": self.rows,
            "dt_s": self.dt,
            "steering_spikes": self.steering_spikes,
            "yaw_rate_spikes": self.yaw_rate_spikes,
            "ay_out_of_range": self.ay_out_of_range,
            "missing_samples": self.missing,
            "repeated_value_fraction": self.repeated_fraction,
            "ay_high_frequency_std_mps2": self.ay_high_frequency_std,
            "checks": self.checks,
            "low_speed": self.low_speed,
            "sampling": self.sampling,
            "imu_position": self.imu_position,
        }

    def notes(self) -> list[str]:
        """One line per cleaning action (for ``log.notes``)."""
        out = [
            f"steering: {self.steering_spikes['count']} spike sample(s) replaced by the previous value"
            + (f" at t = {self.steering_spikes['t'][:10]}" if self.steering_spikes["count"] else ""),
            f"yaw_rate: {self.yaw_rate_spikes['count']} spike sample(s) replaced by the previous value",
            f"ay: {self.ay_out_of_range['count']} sample(s) beyond the physical bound set to NaN",
            f"missing (prediction-only) samples: ay {self.missing['ay']}, yaw_rate {self.missing['yaw_rate']}",
        ]
        if self.low_speed.get("count"):
            out.append(_low_speed_note(self.low_speed))
        if self.sampling.get("jitter_steps"):
            out.append(_jitter_note(self.sampling))
        if self.imu_position.get("imu_x_m"):
            out.append(f"ay: accelerometer {self.imu_position['imu_x_m']:+g} m ahead of the CG (vehicle file imu_x): "
                       f"ay - imu_x * r_dot used (rms correction {self.imu_position['rms_correction_mps2']:.3g} m/s^2)")
        return out


def accelerometer_at_cg(t: NDArray, ay: NDArray, yaw_rate: NDArray, imu_x: float, smooth_s: float = 0.1) -> NDArray:
    """Lateral acceleration at the centre of gravity from an accelerometer ``imu_x`` ahead of it.

    A rigid body's point ``x`` ahead of the CG has the lateral acceleration ``a_y + x r_dot``;
    this returns ``ay - imu_x * r_dot`` with ``r_dot`` the centred derivative (``np.gradient``
    over ``t``) of the yaw rate's ``smooth_s`` moving mean (:func:`..metrics.centred_moving_average`;
    missing yaw-rate samples interpolated for the derivative only). NaN ``ay`` stays NaN.

    Parameters
    ----------
    t : array (n,)
        Time [s], increasing.
    ay : array (n,)
        Measured lateral acceleration [m/s^2].
    yaw_rate : array (n,)
        Measured yaw rate [rad/s].
    imu_x : float
        Accelerometer position ahead of the CG [m] (negative: behind).
    smooth_s : float
        Width of the moving mean applied to the yaw rate before differentiating [s].

    Returns
    -------
    array (n,)
    """
    ay = np.asarray(ay, dtype=float)
    if imu_x == 0.0:
        return ay.copy()
    t = np.asarray(t, dtype=float)
    r = np.asarray(yaw_rate, dtype=float)
    ok = np.isfinite(r)
    if ok.sum() < 3:
        return ay.copy()
    r = centred_moving_average(t, np.interp(t, t[ok], r[ok]), smooth_s)
    r_dot = np.gradient(r, t)
    return ay - imu_x * r_dot


def _low_speed_note(low: dict) -> str:
    spans = ", ".join(f"{a:.6g}-{b:.6g} s" for a, b in low["spans_s"][:5]) + (" ..." if len(low["spans_s"]) > 5 else "")
    return (f"low speed: {low['count']} row(s) slower than {low['limit_mps']:g} m/s (t = {spans}) carry no IMU "
            "correction (ay and yaw_rate read as missing): the bicycle model is singular at standstill, so the "
            "estimators predict through them")


def _jitter_note(sam: dict) -> str:
    return (f"non-uniform sampling: {sam['jitter_steps']} step(s) off the median {sam['median_dt_s']:.4g} s by more "
            f"than 25 % (steps {sam['min_dt_s']:.4g}-{sam['max_dt_s']:.4g} s): every estimator predicts over each "
            "row's own step; the observer's gains are certified for the median step")


def _runs(mask: NDArray, t: NDArray, limit: int = 20) -> list[list[float]]:
    """``[t_first, t_last]`` of each run of True in ``mask`` (at most ``limit``)."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [[float(t[a]), float(t[b - 1])] for a, b in zip(edges[::2], edges[1::2])][:limit]


def _spike_hold(x: NDArray, max_step: float, max_hold: int = 3) -> tuple[NDArray, NDArray, int]:
    """Causal spike removal: a sample that jumps more than ``max_step`` from the last accepted
    value is replaced by that value (held); after ``max_hold`` consecutive such samples
    the new level is accepted (a real level change, counted).

    NaN samples pass through. Returns ``(y, replaced_mask, accepted_jumps)``.
    """
    y = np.array(x, dtype=float, copy=True)
    replaced = np.zeros(len(y), dtype=bool)
    last = np.nan
    held = 0
    accepted = 0
    for k in range(len(y)):
        v = y[k]
        if v != v:
            continue
        if last == last and abs(v - last) > max_step:
            if held < max_hold:
                y[k] = last
                replaced[k] = True
                held += 1
                continue
            accepted += 1
        held = 0
        last = v
    return y, replaced, accepted


def check_imu_log(log: DrivingLog, vehicle: VehicleParams | None = None, allow_gaps: bool = False) -> dict:
    """The error checks of the module docstring; returns the measured values.

    Rows slower than :data:`MIN_SPEED` take no part in the checks (their IMU samples are not used).
    ``allow_gaps``: a stretch without rows is no error (the caller treats it as a segment boundary).

    Raises
    ------
    LogFormatError
    """
    s = log.sensors
    src = log.source or "log"
    missing = [c for c in ("yaw_rate", "ay") if c not in s]
    if missing:
        raise LogFormatError(f"{src}: an IMU log needs columns yaw_rate [rad/s] and ay [m/s^2]; missing {missing}")
    t = s["t"]
    if len(t) < 3:
        raise LogFormatError(f"{src}: only {len(t)} rows; an IMU log needs at least 3")
    dt = np.diff(t)
    med = float(np.median(dt))
    gaps, limit = row_gaps(t)
    if len(gaps) and not allow_gaps:
        i = int(gaps[np.argmax(dt[gaps])])
        raise LogFormatError(
            f"{src}: non-uniform sampling with a gap: no rows for {dt[i]:.4g} s from t={t[i]:.6g} (median step "
            f"{med:.4g} s; {len(gaps)} step(s) over {limit:.3g} s). Nothing, not even the steering, was logged there; "
            "split the log at the gap."
        )
    r, ay, vx, delta = s["yaw_rate"], s["ay"], s["vx"], s["delta"]
    moving = vx >= MIN_SPEED
    fin = np.isfinite(r) & np.isfinite(ay) & moving
    if fin.sum() < 3:
        raise LogFormatError(f"{src}: fewer than 3 rows have both ay and yaw_rate at a speed of at least {MIN_SPEED:g} "
                             f"m/s (fastest vx {float(np.nanmax(vx)):.3g}): the IMU observer needs forward motion (m/s)")
    rmax = float(np.nanmax(np.abs(r)))
    if rmax > 5.0:
        raise LogFormatError(f"{src}: |yaw_rate| reaches {rmax:.3g} > 5 rad/s: yaw_rate must be in rad/s (deg/s given?)")
    checks: dict = {"median_dt_s": med}
    vr = vx * r
    turning = fin & (np.abs(vr) > 2.0)
    if turning.sum() >= 50:
        slope = float(np.sum(ay[turning] * vr[turning]) / np.sum(vr[turning] ** 2))
        checks["ay_vs_vx_r_slope"] = slope
        if slope < 0:
            raise LogFormatError(
                f"{src}: ay follows -vx*yaw_rate (slope {slope:.3g}): opposite sign convention of ay or "
                "yaw_rate (both must be positive to the left)"
            )
        if not 0.5 <= slope <= 2.0:
            hint = " (ay in g? it must be in m/s^2)" if 0.05 <= slope <= 0.2 else ""
            raise LogFormatError(f"{src}: ay / (vx*yaw_rate) = {slope:.3g}, not near 1: wrong units of ay{hint}")
    else:
        checks["ay_vs_vx_r_slope"] = None
        checks["note"] = "too little cornering to check the units and sign of ay"
    if vehicle is not None:
        kin = vehicle.wheelbase * r / np.maximum(vx, MIN_SPEED)
        sel = fin & (np.abs(r) > 0.05)
        if sel.sum() >= 50:
            corr = float(np.corrcoef(delta[sel], kin[sel])[0, 1])
            checks["delta_vs_L_r_over_vx_corr"] = corr
            if corr < 0:
                raise LogFormatError(
                    f"{src}: delta correlates negatively ({corr:.2f}) with L*yaw_rate/vx: opposite steering sign "
                    "convention (delta must be positive to the left)"
                )
    return checks


def clean_imu_log(
    log: DrivingLog,
    vehicle: VehicleParams | None = None,
    max_steer_rate: float = 2.0,
    max_yaw_accel: float = 20.0,
    max_abs_ay: float = 30.0,
    allow_gaps: bool = False,
) -> tuple[DrivingLog, CleaningReport]:
    """Checked and cleaned copy of an IMU log, and the report of what was done.

    Parameters
    ----------
    log : DrivingLog
        From :func:`..io.read_log` (truth stays in ``log.truth``, untouched).
    vehicle : VehicleParams, optional
        Enables the steering sign check; its ``imu_x`` places the accelerometer (module docstring).
    max_steer_rate : float
        Largest physical road-wheel rate [rad/s] (2 rad/s is ~1500 deg/s at a 13.5:1
        steering wheel: beyond any driver).
    max_yaw_accel : float
        Largest physical yaw acceleration [rad/s^2].
    max_abs_ay : float
        Largest physical lateral acceleration [m/s^2].
    allow_gaps : bool
        Accept stretches without rows (:func:`check_imu_log`); they stay out of the jitter count.
    """
    checks = check_imu_log(log, vehicle, allow_gaps=allow_gaps)
    s = {k: np.array(v, dtype=float, copy=True) for k, v in log.sensors.items()}
    t = s["t"]
    dt = float(np.median(np.diff(t)))
    raw_delta = s["delta"]
    delta, lim_d, jumps_d = _spike_hold(raw_delta, max_steer_rate * dt)
    yaw, lim_r, jumps_r = _spike_hold(s["yaw_rate"], max_yaw_accel * dt)
    imu_x = float(vehicle.imu_x) if vehicle is not None else 0.0
    ay_raw = s["ay"]
    ay = accelerometer_at_cg(t, ay_raw, yaw, imu_x)  # the model's a_y is the CG's (module docstring)
    corr = ay - ay_raw
    position = {"imu_x_m": imu_x,
                "rms_correction_mps2": float(np.sqrt(np.nanmean(corr**2))) if np.isfinite(corr).any() else 0.0}
    out = np.abs(ay) > max_abs_ay
    ay = np.where(out, np.nan, ay)
    slow = ~(s["vx"] >= MIN_SPEED)  # standstill, reversing: no correction (module docstring)
    ay = np.where(slow, np.nan, ay)
    yaw = np.where(slow, np.nan, yaw)
    s["delta"], s["yaw_rate"], s["ay"] = delta, yaw, ay
    src = log.source or "log"
    low = {"count": int(slow.sum()), "limit_mps": float(MIN_SPEED), "spans_s": _runs(slow, t)}
    steps = np.diff(t)
    steps = np.delete(steps, row_gaps(t)[0])  # pauses are no jitter (estimate: segment boundaries)
    sampling = {"median_dt_s": dt, "min_dt_s": float(steps.min()), "max_dt_s": float(steps.max()),
                "jitter_steps": int(np.sum(np.abs(steps - dt) > 0.25 * dt))}  # fmt: skip
    for on, note in ((low["count"], _low_speed_note), (sampling["jitter_steps"], _jitter_note)):
        if on:
            warnings.warn(f"{src}: " + note(low if note is _low_speed_note else sampling), stacklevel=2)

    def rep_frac(x):
        x = x[np.isfinite(x)]
        return float(np.mean(np.diff(x) == 0)) if len(x) > 1 else 0.0

    fin = ay[np.isfinite(ay)]
    hf = float(np.std(fin[1:-1] - (fin[:-2] + fin[1:-1] + fin[2:]) / 3.0)) if len(fin) > 3 else float("nan")
    report = CleaningReport(
        rows=len(t),
        dt=dt,
        steering_spikes={
            "count": int(lim_d.sum()),
            "t": t[lim_d].round(4).tolist(),
            "max_deviation_rad": float(np.max(np.abs(raw_delta - delta))) if lim_d.any() else 0.0,
            "limit_rad_per_s": max_steer_rate,
            "level_jumps_accepted": jumps_d,
        },
        yaw_rate_spikes={
            "count": int(lim_r.sum()),
            "t": t[lim_r].round(4).tolist()[:50],
            "limit_rad_per_s2": max_yaw_accel,
            "level_jumps_accepted": jumps_r,
        },
        ay_out_of_range={"count": int(out.sum()), "t": t[out].round(4).tolist()[:50], "limit_mps2": max_abs_ay},
        missing={"ay": int(np.isnan(ay).sum()), "yaw_rate": int(np.isnan(yaw).sum())},
        low_speed=low,
        sampling=sampling,
        imu_position=position,
        repeated_fraction={k: rep_frac(log.sensors[k]) for k in ("delta", "yaw_rate", "ay", "vx")},
        ay_high_frequency_std=hf,
        checks=checks,
    )
    cleaned = DrivingLog(s, log.truth, log.kind, log.source, list(log.notes) + report.notes())
    return cleaned, report


def read_imu_log(path: str | Path, vehicle: VehicleParams | None = None, **cleaning) -> tuple[DrivingLog, CleaningReport]:
    """:func:`..io.read_log` then :func:`clean_imu_log` (keyword arguments go to the latter)."""
    log = read_log(path)
    return clean_imu_log(log, vehicle, **cleaning)
