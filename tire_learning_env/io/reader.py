"""The strict driving-log reader: CSV parsing, column checks, the sensor/truth split; the vehicle file.

A missing required column, a non-increasing ``t``, values whose units cannot be right
(:mod:`.units`), or an empty file raise :class:`~.log.LogFormatError` naming the problem.
Unknown columns are ignored with a warning naming them.
"""

from __future__ import annotations

import dataclasses
import json
import re
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..params import ParameterError, VehicleParams
from .log import KNOWN_COLUMNS, SENSOR_COLUMNS, DrivingLog, LogFormatError
from .outputs import current_run_context
from .camera_checks import camera_warnings, frozen_frames
from .units import check_log_units

__all__ = ["read_log", "finish_log", "read_vehicle", "row_gaps", "VEHICLE_FILE_KEYS", "ROW_GAP_FACTOR", "ROW_GAP_MIN_S"]


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
    # empty cells become "nan" before the array is made: a column whose longest cell is shorter than
    # "nan" ("0", "1", or all empty) would otherwise get a 1- or 2-character dtype that truncates it
    cells = np.array([v.strip() or "nan" for v in values], dtype=str)
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


_SLOW_PATH_CHARS = re.compile("[\"#\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")


def _parse_csv_fast(text: str) -> tuple[list[str], dict[str, NDArray]] | None:
    """The columns of a plain log at C speed, or ``None`` when the strict parser must read it.

    A plain log has unquoted, unpadded, distinct column names, no quotes, comment signs or carriage
    returns anywhere, and the header's number of fields on every non-empty line. Its known and
    ``true_*`` columns are then parsed by numpy's C ``loadtxt`` with the empty cells written as
    ``nan`` first: each cell goes through the C routine behind Python's ``float``, so the floats are
    the strict parser's, bit for bit. Anything ``loadtxt`` refuses (text in a numeric cell, a blank
    cell of spaces, ``1_000``) falls back to :func:`_parse_csv`, which names the problem or accepts
    the file as before. On a 30 min, 100 Hz log (180,000 rows, 11 columns) ``read_log`` takes 0.45 s
    instead of 1.05 s (``csv_read_s`` of ``benchmarks/bench_estimate_runtime.py``).
    """
    head_end = text.find("\n")
    if head_end <= 0 or _SLOW_PATH_CHARS.search(text) is not None:
        return None
    cells = text[:head_end].split(",")
    names = [c.strip() for c in cells]
    if len(names) < 2 or names != cells or "" in names or len(set(names)) != len(names) or "'" in text[:head_end]:
        return None
    body = text[head_end + 1 :]
    raw = np.frombuffer(body.encode("utf-8"), dtype=np.uint8)
    if not len(raw):
        return None
    ends = np.flatnonzero(raw == 10)
    if raw[-1] != 10:
        ends = np.r_[ends, len(raw)]
    starts = np.r_[0, ends[:-1] + 1]
    commas = np.flatnonzero(raw == 44)  # positions (a cumulative count would be 8 bytes per byte of the file)
    per_line = np.searchsorted(commas, ends) - np.searchsorted(commas, starts)
    filled = ends > starts  # empty lines are skipped, by both parsers
    del raw, commas
    if not np.any(filled) or np.any(per_line[filled] != len(names) - 1):
        return None
    wanted = [j for j, n in enumerate(names) if n in KNOWN_COLUMNS or n.startswith("true_")]
    if not wanted:
        return None
    # empty cells as "nan" (what the strict parser reads them as): runs of empty cells need the pair twice
    body = body.replace(",,", ",nan,").replace(",,", ",nan,").replace("\n,", "\nnan,").replace(",\n", ",nan\n")
    if body.startswith(","):
        body = "nan" + body
    if body.endswith(","):
        body += "nan"
    import io

    try:
        table = np.loadtxt(io.StringIO(body), delimiter=",", comments=None, usecols=wanted, dtype=float, ndmin=2)
    except ValueError:  # text in a numeric cell, a cell of spaces: the strict parser names it or reads it
        return None
    if table.shape != (int(np.count_nonzero(filled)), len(wanted)):
        return None
    return names, {names[j]: np.ascontiguousarray(table[:, k]) for k, j in enumerate(wanted)}


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
        from ..formats import read_logger_log  # logger files and ROS 2 bag folders

        return read_logger_log(path, channel_map, min_rows=min_rows, check_units=check_units, sensors=sensors)
    source = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise LogFormatError(f"cannot read log {path}: {exc.strerror or exc}") from None
    notes: list[str] = []
    text = _decode(raw, source, notes)
    fast = _parse_csv_fast(text)
    if fast is None:
        names, cells, first_line = _parse_csv(text, source, notes)
        if not cells[names[0]]:
            raise LogFormatError(f"{source}: the log has no rows")
    else:
        names, parsed = fast
    unknown = [n for n in names if n not in KNOWN_COLUMNS and not n.startswith("true_")]
    if unknown:
        cased = {n: n.lower() for n in unknown if n.lower() in KNOWN_COLUMNS or n.lower().startswith("true_")}
        hint = (f" (column names are case-sensitive and lower case: {', '.join(f'{a!r} -> {b!r}' for a, b in cased.items())}?)"
                if cased else "")  # fmt: skip
        warnings.warn(f"{source}: ignoring unknown column(s) {unknown}{hint}", stacklevel=2)
    if fast is None:
        columns = {n: _to_float(cells[n], n, source, first_line) for n in names if n not in unknown}
    else:  # the fast path parsed exactly the known and true_* columns, in the header's order
        columns = parsed
    return finish_log(columns, source, notes, min_rows, check_units, sensors)


def finish_log(columns: dict[str, NDArray], source: str, notes: list[str], min_rows: int, check_units: bool | None,
               sensors: str) -> DrivingLog:  # fmt: skip
    """The checks and the sensor/truth split every reader ends with (CSV here, the logger
    formats in :mod:`tire_learning_env.formats`): columns, sensor set, row count, units."""
    if "t" in columns and not len(columns["t"]):
        raise LogFormatError(f"{source}: the log has no rows")
    _infinite_as_missing(columns, source, notes)
    kind = _validate(columns, source)
    kind = _choose_sensors(columns, kind, sensors, source, notes)
    if len(columns["t"]) < min_rows:
        raise LogFormatError(f"{source}: only {len(columns['t'])} rows; at least {min_rows} are needed")
    if check_units is None:
        check_units = current_run_context().check_units
    if check_units:
        notes.extend(check_log_units(columns, kind, source))
    else:
        notes.append("unit plausibility checks skipped (--no-unit-checks)")
    _note_row_gaps(columns["t"], source, notes)
    if kind == "camera":
        gaps = int(np.sum(~np.isfinite(columns["kappa"])))
        if 0 < gaps < len(columns["kappa"]):  # (an empty column: the sensor choice names it)
            message = (f"{source}: column 'kappa' is empty on {gaps} of {len(columns['t'])} rows: the estimators "
                       "interpolate the path curvature in time between its values")
            warnings.warn(message, stacklevel=3)
            notes.append(message.split(": ", 1)[1])
        symptoms = camera_warnings(columns)  # a frozen or interpolated camera, a missing kappa
        frozen = frozen_frames(columns)
        if frozen.any():  # a frozen camera's repeats: no new frame (camera_checks)
            for k in ("e1", "e2"):
                columns[k] = np.where(frozen, np.nan, columns[k])
        for symptom in symptoms:
            warnings.warn(f"{source}: {symptom}", stacklevel=3)
            notes.append(symptom)
    sensor_cols = {k: columns[k] for k in SENSOR_COLUMNS if k in columns}
    if kind == "imu":
        for k in ("e1", "e2", "kappa"):
            sensor_cols.pop(k, None)
    truth = {k: v for k, v in columns.items() if k.startswith("true_")}
    return DrivingLog(sensor_cols, truth, kind, source, [f"read {len(columns['t'])} rows, {kind} log"] + notes)


def _infinite_as_missing(columns: dict[str, NDArray], source: str, notes: list[str]) -> None:
    """Read ``inf``/``-inf`` cells of the measurement and truth columns as missing (NaN), with a warning.

    ``t``, ``vx`` and ``delta`` are left to :func:`_validate`, which refuses them; in every other column an
    infinite value is no measurement (a logger's overflow), and NaN is what the format has for
    that. Left as they were, they reached the estimators and the JSON writer, which refused them
    at the end of the run.

    Parameters
    ----------
    columns : dict of str -> ndarray
        The log's columns, changed in place.
    source : str
        The log's name for the message.
    notes : list of str
        Appended to.
    """
    if "t" not in columns:  # (_validate names it)
        return
    t = columns["t"]
    for name, values in columns.items():
        if name in ("t", "vx", "delta"):
            continue
        bad = np.isinf(values)
        if bad.any():
            columns[name] = np.where(bad, np.nan, values)
            message = (f"{source}: column {name!r} has {int(bad.sum())} infinite value(s) (the first at "
                       f"t={t[int(np.argmax(bad))]:.6g} s): read as missing")
            warnings.warn(message, stacklevel=4)
            notes.append(message.split(": ", 1)[1])


#: a step between rows this many times the median step, and at least ``ROW_GAP_MIN_S``, is a gap in the log
ROW_GAP_FACTOR = 10.0
ROW_GAP_MIN_S = 0.5


def row_gaps(t: NDArray) -> tuple[NDArray, float]:
    """The stretches of a log without rows (a logger pause).

    Parameters
    ----------
    t : ndarray
        Row times [s], strictly increasing.

    Returns
    -------
    gaps : ndarray of int
        Indices ``i`` with ``t[i + 1] - t[i]`` over the limit (the gap lies after row ``i``).
    limit : float
        ``max(ROW_GAP_FACTOR * median step, ROW_GAP_MIN_S)`` [s] (``inf`` for fewer than 3 rows).
    """
    t = np.asarray(t, dtype=float)
    if len(t) < 3:
        return np.zeros(0, dtype=np.int64), float("inf")
    dt = np.diff(t)
    limit = max(ROW_GAP_FACTOR * float(np.median(dt)), ROW_GAP_MIN_S)
    return np.flatnonzero(dt > limit), limit


def _note_row_gaps(t: NDArray, source: str, notes: list[str]) -> None:
    """Name the stretches with no rows at all (a logger pause) in a warning and the notes.

    Nothing is measured there, not even the steering: the estimators treat such a gap as a segment
    boundary (:func:`tire_learning_env.observer.estimator.log_segments`), and the user should know
    it is there.

    Parameters
    ----------
    t : ndarray
        Row times [s], strictly increasing.
    source : str
        The log's name for the message.
    notes : list of str
        Appended to.
    """
    gaps, limit = row_gaps(t)
    dt = np.diff(t)
    if not len(gaps):
        return
    i = int(gaps[np.argmax(dt[gaps])])
    message = (f"{source}: the log has no rows over {len(gaps)} stretch(es) longer than {limit:.3g} s (the longest "
               f"{dt[i]:.3g} s, from t={t[i]:.6g} s): nothing, not even the steering, was logged there, so the "
               "estimators treat each as a segment boundary: nothing is predicted or fitted across it, the state "
               "restarts after it as at the start of the log and the learned curve carries over")
    warnings.warn(message, stacklevel=4)
    notes.append(message.split(": ", 1)[1])


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

