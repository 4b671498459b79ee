"""Driving logs (``LOG_FORMAT.md``) and result files.

Readers are strict: a missing required column, a non-increasing ``t``, values whose units
cannot be right, or an empty file raise :class:`LogFormatError` naming the problem.
Unknown columns are ignored with a warning naming them. Writers are atomic: a file (or a
whole output directory) appears complete or not at all, and nothing already there is
lost half-way.

Ground truth is kept apart: :attr:`DrivingLog.sensors` never contains a ``true_*``
column, so an estimator that reads only ``sensors`` cannot see the answer.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
from numpy.typing import NDArray

from .params import ParameterError, VehicleParams

__all__ = [
    "LogFormatError",
    "DrivingLog",
    "read_log",
    "write_log",
    "write_table",
    "read_vehicle",
    "atomic_write_text",
    "atomic_write_json",
    "atomic_directory",
    "check_output_dir",
    "check_output_file",
    "OutputPathError",
    "MANIFEST_NAME",
    "read_manifest",
    "run_context",
    "current_run_context",
    "record_run_info",
    "KNOWN_COLUMNS",
    "check_log_units",
    "VEHICLE_FILE_KEYS",
]

SENSOR_COLUMNS = ("t", "vx", "delta", "kappa", "e1", "e2", "yaw_rate", "ay", "ax")
TRUTH_COLUMNS = (
    "true_e1",
    "true_e1_dot",
    "true_e2",
    "true_e2_dot",
    "true_alpha_f",
    "true_alpha_r",
    "true_Fyf",
    "true_Fyr",
    "true_vy",
    "true_beta",
)
KNOWN_COLUMNS = SENSOR_COLUMNS + TRUTH_COLUMNS


class LogFormatError(ValueError):
    """A driving log that does not follow ``LOG_FORMAT.md``; the message names the problem."""


@dataclass
class DrivingLog:
    """A driving log split into what the car measured and ground truth.

    Attributes
    ----------
    sensors : dict of str -> ndarray
        Measured columns (``t, vx, delta`` always; ``kappa, e1, e2`` for a camera log;
        ``yaw_rate, ay, ax`` when present). ``e1``/``e2`` are NaN where no frame arrived.
    truth : dict of str -> ndarray
        ``true_*`` columns (scoring only; estimators must not read them).
    kind : {"camera", "imu"}
        ``camera`` when ``e1``, ``e2`` and ``kappa`` are present, else ``imu``.
    source : str
        Where it came from (path or description).
    notes : list of str
        What the reader noticed or cleaned (reported, never hidden).
    """

    sensors: dict[str, NDArray]
    truth: dict[str, NDArray]
    kind: str
    source: str = ""
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.sensors["t"])

    @property
    def duration(self) -> float:
        t = self.sensors["t"]
        return float(t[-1] - t[0])

    @property
    def has_truth(self) -> bool:
        return bool(self.truth)

    def slice(self, t_start: float | None = None, t_end: float | None = None) -> "DrivingLog":
        """Rows with ``t_start <= t < t_end``."""
        t = self.sensors["t"]
        mask = np.ones(len(t), dtype=bool)
        if t_start is not None:
            mask &= t >= t_start
        if t_end is not None:
            mask &= t < t_end
        return DrivingLog(
            {k: v[mask] for k, v in self.sensors.items()},
            {k: v[mask] for k, v in self.truth.items()},
            self.kind,
            self.source,
            list(self.notes),
        )


def _validate(columns: dict[str, NDArray], source: str) -> str:
    for name in ("t", "vx", "delta"):
        if name not in columns:
            raise LogFormatError(f"{source}: required column {name!r} is missing")
    has_camera = all(c in columns for c in ("e1", "e2", "kappa"))
    has_imu = all(c in columns for c in ("yaw_rate", "ay"))
    if not has_camera and not has_imu:
        missing = [c for c in ("kappa", "e1", "e2") if c not in columns]
        raise LogFormatError(
            f"{source}: required column(s) {missing} are missing (a log needs e1, e2 and kappa, "
            "or, for an IMU-only log, yaw_rate and ay)"
        )
    n = len(columns["t"])
    if n == 0:
        raise LogFormatError(f"{source}: the log has no rows")
    t = columns["t"]
    if not np.all(np.isfinite(t)):
        raise LogFormatError(f"{source}: column 't' has empty or non-finite values")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise LogFormatError(f"{source}: time is not strictly increasing at row {i + 1} (t={t[i]} then {t[i + 1]})")
    for name in ("vx", "delta"):
        if not np.all(np.isfinite(columns[name])):
            raise LogFormatError(f"{source}: column {name!r} has empty or non-finite values")
    if np.all(columns["vx"] <= 0):
        raise LogFormatError(f"{source}: vx <= 0 over the whole log; speed must be in m/s and positive")
    big = np.abs(columns["delta"]) > 1.0
    if np.any(big):
        i = int(np.argmax(big))
        raise LogFormatError(
            f"{source}: |delta| = {abs(columns['delta'][i]):.3g} > 1 rad at t={t[i]}: delta must be the "
            "road-wheel angle in radians (not degrees, not the steering-wheel angle)"
        )
    if has_camera and np.any(np.abs(columns["kappa"][np.isfinite(columns["kappa"])]) > 1.0):
        raise LogFormatError(f"{source}: |kappa| > 1 1/m: curvature must be in 1/m")
    if has_camera and np.nanmax(np.abs(columns["e2"]), initial=0.0) > np.pi:
        raise LogFormatError(f"{source}: |e2| > pi: heading error must be in radians")
    return "camera" if has_camera else "imu"


_MAGIC = (
    (b"\x1f\x8b", "gzip-compressed; decompress it first (gunzip)"),
    (b"PK\x03\x04", "a zip archive (or an Excel .xlsx file); extract or export it as CSV"),
    (b"BZh", "bzip2-compressed; decompress it first (bunzip2)"),
    (b"\xfd7zXZ\x00", "xz-compressed; decompress it first (unxz)"),
    (b"\x28\xb5\x2f\xfd", "zstd-compressed; decompress it first (unzstd)"),
    (b"PAR1", "a Parquet file; export it as CSV"),
    (b"\xd0\xcf\x11\xe0", "an old Excel/Office file; export it as CSV"),
    (b"\xff\xfe", "UTF-16 text; save it as UTF-8 CSV"),
    (b"\xfe\xff", "UTF-16 text; save it as UTF-8 CSV"),
)


def _decode(raw: bytes, source: str, notes: list[str]) -> str:
    for magic, what in _MAGIC:
        if raw.startswith(magic):
            raise LogFormatError(f"{source}: the file is {what}, not a plain-text CSV log")
    if b"\x00" in raw[:65536]:
        raise LogFormatError(f"{source}: the file is binary (it contains NUL bytes), not a plain-text CSV log")
    if raw.startswith(b"\xef\xbb\xbf"):
        notes.append("removed a UTF-8 byte-order mark")
        raw = raw[3:]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise LogFormatError(
            f"{source}: not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line}); save the log as a UTF-8 CSV"
        ) from None


def _to_float(values: list[str], name: str, source: str, first_line: int) -> NDArray:
    """One column as floats; empty cells are NaN; anything else that is not a number raises."""
    cells = np.array([v.strip() for v in values], dtype=str)
    cells[cells == ""] = "nan"
    try:
        return cells.astype(float)
    except ValueError:
        pass
    for i, v in enumerate(cells.tolist()):
        try:
            float(v)
        except ValueError:
            shown = v if len(v) <= 30 else v[:27] + "..."
            hint = ""
            if "," in v or (v.count(".") == 0 and "," in values[i]):
                hint = " (a decimal comma? the format needs a '.' decimal point)"
            raise LogFormatError(
                f"{source}: column {name!r}, line {first_line + i}: {shown!r} is not a number{hint}"
            ) from None
    raise AssertionError("unreachable")  # pragma: no cover


def _parse_csv(text: str, source: str, notes: list[str]) -> tuple[list[str], dict[str, list[str]], int]:
    """Header names, raw cells per column and the file line of the first data row."""
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines or not lines[0].strip():
        raise LogFormatError(f"{source}: the file is empty (no header row)")
    head = lines[0]
    if "," not in head:
        for sep, label in ((";", "';'"), ("\t", "a tab"), ("|", "'|'")):
            if sep in head:
                raise LogFormatError(
                    f"{source}: the columns look separated by {label} (header {head[:60]!r}); the log format "
                    "needs ',' separators and '.' decimal points"
                )
    import csv

    rows = csv.reader(lines)
    try:
        header = next(rows)
    except csv.Error as exc:
        raise LogFormatError(f"{source}: malformed header: {exc}") from None
    names = [h.strip().strip('"').strip("'").strip() for h in header]
    if '"' in head or any(h.strip().startswith("'") for h in header):
        notes.append("removed quotes around the column names")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise LogFormatError(f"{source}: duplicate column name(s) {dup} in the header")
    if "" in names:
        raise LogFormatError(f"{source}: the header has an empty column name (column {names.index('') + 1})")
    cells: dict[str, list[str]] = {n: [] for n in names}
    width = len(names)
    try:
        for lineno, row in enumerate(rows, start=2):
            if not row or (len(row) == 1 and not row[0].strip()):
                continue
            if len(row) != width:
                hint = ""
                if len(row) > width and any(c.strip().isdigit() for c in row[1::2]):
                    hint = " (decimal commas? the format needs '.' decimal points and ',' separators)"
                raise LogFormatError(
                    f"{source}: line {lineno} has {len(row)} values but the header names {width} columns{hint}"
                )
            for n, v in zip(names, row):
                cells[n].append(v)
    except csv.Error as exc:
        raise LogFormatError(f"{source}: malformed CSV: {exc}") from None
    return names, cells, 2


def read_log(path: str | Path, min_rows: int = 2, check_units: bool | None = None,
             sensors: str = "auto", channel_map: str | Path | None = None) -> DrivingLog:
    """Read a driving log in the shared CSV format (or, by suffix, a logger's MF4, Parquet, MCAP or ROS 2 bag).

    ``.mf4``/``.mdf``, ``.parquet``/``.pq``, ``.mcap`` files and ROS 2 bag folders (``.db3``) go
    to :func:`tire_learning_env.formats.read_logger_log` with ``channel_map`` (None: a
    ``<stem>.channels.yaml``/``.json`` beside the log, else channels named as the columns);
    everything else is read as CSV below.

    Accepted and noted: a UTF-8 byte-order mark, quoted column names. Refused with a short
    message naming the problem: binary or compressed files, non-UTF-8 text, ``;``/tab
    separators, decimal commas, rows of the wrong length, text in a numeric cell (column
    and line named), and units that cannot be right (:func:`check_log_units`).

    Parameters
    ----------
    path : str or Path
        CSV file with one header row.
    min_rows : int
        Fewer rows is an error (too short to use).
    check_units : bool or None
        Check the units for plausibility; None takes the running command's setting
        (``--no-unit-checks``), true outside the CLI.
    sensors : {"auto", "camera", "imu"}
        Which sensor set to use. ``auto``: the camera (``e1, e2, kappa``) when all three are
        present, else the IMU (``yaw_rate, ay``); the choice and its reason are in
        ``notes``, and a warning names missing camera columns when some are present.

    Returns
    -------
    DrivingLog
    """
    if sensors not in ("auto", "camera", "imu"):
        raise ValueError(f"sensors must be 'auto', 'camera' or 'imu', got {sensors!r}")
    path = Path(path)
    if path.suffix.lower() in (".mf4", ".mdf", ".parquet", ".pq", ".mcap", ".db3") or (path / "metadata.yaml").is_file():
        from .formats import read_logger_log  # logger files and ROS 2 bag folders

        return read_logger_log(path, channel_map, min_rows=min_rows, check_units=check_units, sensors=sensors)
    source = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise LogFormatError(f"cannot read log {path}: {exc.strerror or exc}") from None
    notes: list[str] = []
    text = _decode(raw, source, notes)
    names, cells, first_line = _parse_csv(text, source, notes)
    if not cells[names[0]]:
        raise LogFormatError(f"{source}: the log has no rows")
    unknown = [n for n in names if n not in KNOWN_COLUMNS and not n.startswith("true_")]
    if unknown:
        warnings.warn(f"{source}: ignoring unknown column(s) {unknown}", stacklevel=2)
    columns = {n: _to_float(cells[n], n, source, first_line) for n in names if n not in unknown}
    return finish_log(columns, source, notes, min_rows, check_units, sensors)


def finish_log(columns: dict[str, NDArray], source: str, notes: list[str], min_rows: int, check_units: bool | None,
               sensors: str) -> DrivingLog:  # fmt: skip
    """The checks and the sensor/truth split every reader ends with (CSV here, the logger
    formats in :mod:`tire_learning_env.formats`): columns, sensor set, row count, units."""
    if not len(columns.get("t", ())):
        raise LogFormatError(f"{source}: the log has no rows")
    kind = _validate(columns, source)
    kind = _choose_sensors(columns, kind, sensors, source, notes)
    if len(columns["t"]) < min_rows:
        raise LogFormatError(f"{source}: only {len(columns['t'])} rows; at least {min_rows} are needed")
    if check_units is None:
        check_units = current_run_context().check_units
    if check_units:
        check_log_units(columns, kind, source)
    else:
        notes.append("unit plausibility checks skipped (--no-unit-checks)")
    sensor_cols = {k: columns[k] for k in SENSOR_COLUMNS if k in columns}
    if kind == "imu":
        for k in ("e1", "e2", "kappa"):
            sensor_cols.pop(k, None)
    truth = {k: v for k, v in columns.items() if k.startswith("true_")}
    return DrivingLog(sensor_cols, truth, kind, source, [f"read {len(columns['t'])} rows, {kind} log"] + notes)


def _choose_sensors(columns: dict, kind: str, sensors: str, source: str, notes: list[str]) -> str:
    camera = ("e1", "e2", "kappa")
    missing_camera = [c for c in camera if c not in columns]
    if sensors == "camera":
        if missing_camera:
            raise LogFormatError(f"{source}: camera column(s) {missing_camera} are missing (sensors forced to camera)")
        notes.append("camera log (e1, e2, kappa), as requested")
        return "camera"
    if sensors == "imu":
        missing = [c for c in ("yaw_rate", "ay") if c not in columns]
        if missing:
            raise LogFormatError(f"{source}: IMU column(s) {missing} are missing (sensors forced to IMU)")
        notes.append("IMU log (yaw_rate, ay), as requested" + (": camera columns ignored" if not missing_camera else ""))
        return "imu"
    if kind == "camera":
        notes.append("camera log: e1, e2 and kappa present")
        return kind
    if len(missing_camera) < len(camera):
        message = (f"{source}: camera column(s) {missing_camera} are missing, so the camera columns "
                   f"{[c for c in camera if c in columns]} are not used: using the IMU (yaw_rate, ay) instead")
        warnings.warn(message, stacklevel=3)
        notes.append(message.split(": ", 1)[1])
    else:
        notes.append("IMU-only log: no e1, e2, kappa; using yaw_rate and ay")
    return kind


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


def check_log_units(columns: Mapping[str, NDArray], kind: str, source: str = "log") -> None:
    """Raise :class:`LogFormatError` naming a column whose unit looks wrong and the likely unit.

    Checks: the time step (ms instead of s), the speed (km/h instead of m/s: median above
    70 m/s), the steering and the heading error (degrees: ``|delta|`` above 1 rad, ``|e2|``
    above 0.5 rad), and the physics linking the columns, fitted over ~1 s windows where the
    log holds enough excitation: ``e1`` changes by the integral of ``vx e2`` on camera logs
    (a constant heading bias is allowed for), ``a_y = vx yaw_rate`` on IMU logs, and the
    heading change against the integral of ``vx delta / L`` (degrees give a wheelbase
    50x too long).
    """
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
    if kind == "imu":
        _check_imu_kinematics(columns, source, fix)
    _check_steering(columns, kind, source, fix)


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
    if r2 < 0.5 or inv_l <= 0:
        return
    length = 1.0 / inv_l  # the wheelbase plus understeer the log implies [m]
    if length > 100.0:
        raise LogFormatError(f"{source}: the steering 'delta' is about {length / 3:.0f}x too large for the car's "
                             f"turning: it looks like degrees (must be the road-wheel angle in rad){fix}")
    if length > 30.0:
        raise LogFormatError(f"{source}: the steering 'delta' is about {length / 3:.0f}x too large for the car's "
                             f"turning: it looks like the steering-wheel angle (must be the road-wheel angle in rad; "
                             f"divide by the steering ratio){fix}")


def write_table(path: str | Path, columns: Mapping[str, NDArray]) -> Path:
    """Write equal-length numeric columns as CSV (header row, NaN as empty), atomically."""
    names = list(columns)
    n = {len(np.asarray(columns[c])) for c in names}
    if len(n) != 1:
        raise ValueError(f"columns have different lengths: { {c: len(columns[c]) for c in names} }")
    table = np.column_stack([np.asarray(columns[c], dtype=float) for c in names])
    body = "\n".join(",".join("" if v != v else "%.10g" % v for v in row) for row in table)
    return atomic_write_text(path, ",".join(names) + "\n" + body + "\n")


def write_log(path: str | Path, columns: Mapping[str, NDArray]) -> Path:
    """Write a shared-format log CSV, atomically: known columns first, in their order."""
    names = [c for c in KNOWN_COLUMNS if c in columns] + [c for c in columns if c not in KNOWN_COLUMNS]
    return write_table(path, {c: columns[c] for c in names})


VEHICLE_FILE_KEYS = ("m", "Iz", "lf", "lr", "Cf", "Cr")


def read_vehicle(path: str | Path | None) -> VehicleParams:
    """Vehicle JSON: ``m, Iz, lf, lr, Cf, Cr`` required, other :class:`VehicleParams` fields optional.

    ``None`` gives the paper's D-class sedan. A missing required key (never filled in from
    the sedan), an unknown key, a value of the wrong type (``true``, ``"heavy"``), an
    implausible value (:meth:`VehicleParams.check_plausible`), an unreadable file and
    invalid JSON raise :class:`~tire_learning_env.params.ParameterError` naming the file
    and the key.
    """
    if path is None:
        return VehicleParams()
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError(f"cannot read vehicle file {path}: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParameterError(f"vehicle file {path} is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ParameterError(f"vehicle file {path}: expected a JSON object {{\"m\": ..., ...}}, got {type(data).__name__}")
    allowed = [f.name for f in dataclasses.fields(VehicleParams)]
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise ParameterError(f"vehicle file {path}: unknown key(s) {unknown}; allowed keys are {sorted(allowed)}")
    missing = [k for k in VEHICLE_FILE_KEYS if k not in data]
    if missing:
        raise ParameterError(
            f"vehicle file {path}: required key(s) {missing} missing (a vehicle file needs "
            f"{', '.join(VEHICLE_FILE_KEYS)}; nothing is filled in from the default sedan)"
        )
    try:
        return VehicleParams.from_dict(data).check_plausible()
    except ParameterError as exc:
        raise ParameterError(f"vehicle file {path}: {exc}") from None


def _umask_mode(mode: int = 0o666) -> int:
    """``mode`` with the process umask applied (what ``open()`` would give a new file)."""
    mask = os.umask(0)
    os.umask(mask)
    return mode & ~mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` via a temporary file and ``os.replace`` (normal file permissions)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.bool_):
        return bool(obj)
    if hasattr(obj, "to_dict"):
        return obj.to_dict()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_jsonable(obj: Any) -> Any:
    """``obj`` with numpy values turned into plain Python (NaN becomes ``None``)."""
    return json.loads(json.dumps(obj, default=_json_default, allow_nan=True).replace("NaN", "null"))


def atomic_write_json(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON, atomically (numpy values converted; NaN -> null)."""
    return atomic_write_text(path, json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n")


MANIFEST_NAME = ".tire_learning_manifest.json"


class OutputPathError(FileExistsError):
    """An output path that must not be written or replaced; the message names it and says why."""


@dataclass
class RunContext:
    """What the running ``tire-learning`` command allows and records (set by :func:`run_context`).

    Attributes
    ----------
    overwrite : bool
        The user passed ``--overwrite``: a non-empty folder (or file) that the package did not
        write may be replaced. Folders that hold an input, the current directory, its parents
        and the home directory are never replaced.
    inputs : tuple of Path
        Input files of the command; never replaced, never deleted.
    command, argv : str, tuple of str
        Recorded in every output manifest.
    check_units : bool
        :func:`read_log` checks the log's units for plausibility (``--no-unit-checks`` turns
        this off).
    info : dict
        Extra facts recorded in the manifest (e.g. the vehicle used and where it came from).
    """

    overwrite: bool = False
    inputs: tuple[Path, ...] = ()
    command: str = ""
    argv: tuple[str, ...] = ()
    check_units: bool = True
    info: dict = field(default_factory=dict)


_CONTEXT: list[RunContext] = [RunContext()]


def current_run_context() -> RunContext:
    """The innermost active :class:`RunContext` (a permissive-nothing default outside the CLI)."""
    return _CONTEXT[-1]


@contextlib.contextmanager
def run_context(**kwargs: Any) -> Iterator[RunContext]:
    """Activate a :class:`RunContext` for the body (the CLI wraps every command in one)."""
    kwargs["inputs"] = tuple(Path(p) for p in kwargs.get("inputs", ()))
    ctx = RunContext(**kwargs)
    _CONTEXT.append(ctx)
    try:
        yield ctx
    finally:
        for i in range(len(_CONTEXT) - 1, 0, -1):
            if _CONTEXT[i] is ctx:
                del _CONTEXT[i]
                break


def record_run_info(key: str, value: Any) -> None:
    """Record ``value`` under ``key`` in the manifests of the outputs written from now on."""
    current_run_context().info[key] = value


def _real(path: str | Path) -> Path:
    return Path(os.path.realpath(os.path.abspath(os.fspath(path))))


def _is_within(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def _protected_reason(real: Path) -> str | None:
    """Why ``real`` (a resolved path) may never be replaced, or None."""
    cwd = _real(os.getcwd())
    if _is_within(cwd, real):
        return "it is the current directory or one of its parents"
    home = _real(Path.home())
    if _is_within(home, real):
        return "it is the home directory or one of its parents"
    if real == Path(real.anchor):
        return "it is a file-system root"
    return None


def _files_in(folder: Path) -> list[str]:
    """Relative paths of every file (and symlink) below ``folder``, sorted."""
    found = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            found.append((rel / name).as_posix())
    return sorted(found)


def read_manifest(folder: str | Path) -> dict | None:
    """The manifest a previous run wrote into ``folder``, or None (absent or unreadable)."""
    try:
        doc = json.loads((Path(folder) / MANIFEST_NAME).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("written_by") != "tire_learning_env" or not isinstance(doc.get("files"), list):
        return None
    return doc


def _foreign_files(folder: Path) -> list[str]:
    """Files in ``folder`` that no manifest of the package lists (all of them without a manifest)."""
    files = [f for f in _files_in(folder) if f != MANIFEST_NAME]
    manifest = read_manifest(folder)
    listed = set(manifest["files"]) if manifest else set()
    return [f for f in files if f not in listed]


def _short_list(names: list[str], n: int = 5) -> str:
    shown = ", ".join(repr(x) for x in names[:n])
    return shown + (f" and {len(names) - n} more" if len(names) > n else "")


def _inputs_inside(real: Path, inputs: tuple[Path, ...] | list) -> list[Path]:
    return [p for p in inputs if _is_within(_real(p), real)]


def _check_creatable(path: Path, what: str) -> None:
    """Raise :class:`OutputPathError` unless ``path``'s parent exists or can be created and is
    writable (probed by creating and removing a temporary directory)."""
    parent = path.parent
    existing = parent
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if not existing.is_dir():
        raise OutputPathError(f"cannot write {what} {path}: {existing} is a file, not a folder")
    try:
        probe = tempfile.mkdtemp(dir=existing, prefix=".tire_learning_probe.")
        os.rmdir(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputPathError(f"cannot write {what} {path}: folder {existing} is not writable ({reason})") from None


def _replace_refusal(out: Path, force: bool, inputs) -> str | None:
    """Why the existing directory ``out`` must not be replaced, or None if it may be."""
    real = _real(out)
    reason = _protected_reason(real)
    if reason:
        return f"refusing to replace {out}: {reason}; choose a new sub-folder for --out"
    held = _inputs_inside(real, inputs)
    if held:
        return (f"refusing to replace {out}: it holds the input {_short_list([str(p) for p in held])}, which would be "
                "deleted (even with --overwrite); choose another --out folder")
    foreign = _foreign_files(out)
    if foreign and not force:
        has_manifest = read_manifest(out) is not None
        why = (f"holds files that tire-learning did not write ({_short_list(foreign)})" if has_manifest else
               f"is not empty and was not written by tire-learning (no {MANIFEST_NAME}; it holds {_short_list(foreign)})")
        return (f"refusing to replace {out}: it {why}; replacing it would delete them. Choose a new folder, "
                "or pass --overwrite to replace it and everything in it")
    return None


def check_output_dir(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Check, before any work, that a command may write the output folder ``path``.

    A folder that does not exist, an empty folder, or one the package wrote before (it
    holds the manifest ``.tire_learning_manifest.json`` listing every file in it) may be
    replaced. A non-empty folder the package did not write is refused unless ``overwrite``.
    Never replaced, whatever ``overwrite`` says: a folder that holds one of ``inputs``, the
    current directory or one of its parents, the home directory, a file-system root.
    The parent must exist or be creatable, and be writable.

    Raises
    ------
    OutputPathError
        Naming the folder and what to do.
    """
    out = Path(path)
    if str(path).strip() == "":
        raise OutputPathError("--out is empty; name an output folder")
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise OutputPathError(f"--out {out} is a file, not a folder; choose a folder path")
        refusal = _replace_refusal(out, overwrite, tuple(inputs))
        if refusal:
            raise OutputPathError(refusal)
    reason = _protected_reason(_real(out))
    if reason:
        raise OutputPathError(f"refusing to write results as {out}: {reason}; choose a new sub-folder for --out")
    _check_creatable(_real(out), "the output folder")
    return out


def check_output_file(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Check that a command may write the output file ``path``.

    An existing file is replaced only with ``overwrite`` (and never when it is one of
    ``inputs``); a folder is never replaced. The parent must exist or be creatable, and be
    writable.

    Raises
    ------
    OutputPathError
    """
    out = Path(path)
    if str(path).strip() == "":
        raise OutputPathError("--out is empty; name an output file")
    if out.is_dir():
        raise OutputPathError(f"--out {out} is a folder; this command writes one file, give a file path")
    if out.exists():
        if _inputs_inside(_real(out), tuple(inputs)):
            raise OutputPathError(f"refusing to overwrite {out}: it is an input of this command (even with --overwrite)")
        if not overwrite:
            raise OutputPathError(f"refusing to overwrite the existing file {out}; choose another name, "
                                  "or pass --overwrite to replace it")
    _check_creatable(_real(out), "the output file")
    return out


def _write_manifest(folder: Path, out: Path) -> None:
    ctx = current_run_context()
    doc = {
        "written_by": "tire_learning_env",
        "version": _package_version(),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "command": ctx.command,
        "argv": list(ctx.argv),
        "output": str(out),
        "inputs": [str(p) for p in ctx.inputs],
        **{k: v for k, v in ctx.info.items() if k not in ("files",)},
        "files": _files_in(folder),
    }
    atomic_write_json(folder / MANIFEST_NAME, doc)


def _package_version() -> str:
    try:
        from . import __version__

        return str(__version__)
    except ImportError:  # pragma: no cover
        return "unknown"


@contextlib.contextmanager
def atomic_directory(out: str | Path, overwrite: bool = True, *, force: bool | None = None) -> Iterator[Path]:
    """Fill a fresh temporary directory, then swap it in as ``out`` at the end.

    If the body raises, ``out`` is left exactly as it was. The new folder gets a manifest
    (``.tire_learning_manifest.json``: command, time, inputs, every file written), which is
    what lets a later run replace it.

    An existing ``out`` is replaced only after the body succeeded, and only if it is empty or
    the package wrote it (its manifest lists every file in it). A non-empty folder the
    package did not write is refused (:class:`OutputPathError`) unless ``force`` is true;
    ``force=None`` takes the ``--overwrite`` flag of the running command (false outside the
    CLI). A folder that holds an input of the command, the current directory, its parents
    and the home directory are never replaced. The check runs before the body and again
    before the swap.

    Parameters
    ----------
    out : str or Path
        The output folder.
    overwrite : bool
        False refuses any existing ``out`` (:class:`FileExistsError`).
    force : bool or None
        Replace a folder the package did not write (see above).
    """
    out = Path(out)
    ctx = current_run_context()
    force = ctx.overwrite if force is None else force
    if (out.exists() or out.is_symlink()) and not out.is_dir():
        raise OutputPathError(f"{out} exists and is not a directory")
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True (or --overwrite) to replace it")

    def check() -> None:
        if out.exists():
            refusal = _replace_refusal(out, force, ctx.inputs)
            if refusal:
                raise OutputPathError(refusal)
        else:
            reason = _protected_reason(_real(out))
            if reason:
                raise OutputPathError(f"refusing to write results as {out}: {reason}")

    check()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    os.chmod(tmp, _umask_mode(0o777))
    try:
        yield tmp
        _write_manifest(tmp, out)
        check()  # again: files may have appeared in out while the body ran
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if out.exists():
        old = out.parent / f".{out.name}.old.{os.getpid()}"
        os.replace(out, old)
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
