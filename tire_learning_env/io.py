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
import json
import os
import shutil
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
from numpy.typing import NDArray

from .params import VehicleParams

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
    "KNOWN_COLUMNS",
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


def read_log(path: str | Path, min_rows: int = 2) -> DrivingLog:
    """Read a driving log in the shared CSV format.

    Parameters
    ----------
    path : str or Path
        CSV file with one header row.
    min_rows : int
        Fewer rows is an error (too short to use).

    Returns
    -------
    DrivingLog
    """
    path = Path(path)
    source = str(path)
    try:
        with path.open() as fh:
            header = fh.readline()
    except OSError as exc:
        raise LogFormatError(f"cannot read log {path}: {exc}") from exc
    if not header.strip():
        raise LogFormatError(f"{source}: the file is empty (no header row)")
    names = [h.strip() for h in header.strip().split(",")]
    if len(set(names)) != len(names):
        raise LogFormatError(f"{source}: duplicate column names in header {names}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # empty file body
            data = np.genfromtxt(path, delimiter=",", skip_header=1, dtype=float, ndmin=2, invalid_raise=True)
    except ValueError as exc:
        raise LogFormatError(f"{source}: malformed CSV body: {exc}") from exc
    if data.size == 0:
        raise LogFormatError(f"{source}: the log has no rows")
    if data.shape[1] != len(names):
        raise LogFormatError(f"{source}: {data.shape[1]} values per row but {len(names)} column names")
    columns = {name: data[:, i] for i, name in enumerate(names)}
    unknown = [n for n in names if n not in KNOWN_COLUMNS and not n.startswith("true_")]
    if unknown:
        warnings.warn(f"{source}: ignoring unknown column(s) {unknown}", stacklevel=2)
    kind = _validate(columns, source)
    if len(columns["t"]) < min_rows:
        raise LogFormatError(f"{source}: only {len(columns['t'])} rows; at least {min_rows} are needed")
    sensors = {k: columns[k] for k in SENSOR_COLUMNS if k in columns}
    truth = {k: v for k, v in columns.items() if k.startswith("true_")}
    return DrivingLog(sensors, truth, kind, source, [f"read {len(columns['t'])} rows, {kind} log"])


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


def read_vehicle(path: str | Path | None) -> VehicleParams:
    """Vehicle JSON (``m, Iz, lf, lr, Cf, Cr`` and optionally other :class:`VehicleParams` fields).

    ``None`` gives the paper's D-class sedan. Unknown keys, unreadable files and invalid
    values raise :class:`~tire_learning_env.params.ParameterError`.
    """
    if path is None:
        return VehicleParams()
    return VehicleParams.from_json(path)


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


@contextlib.contextmanager
def atomic_directory(out: str | Path, overwrite: bool = True) -> Iterator[Path]:
    """Fill a fresh temporary directory, then swap it in as ``out`` at the end.

    If the body raises, ``out`` is left exactly as it was. If ``out`` exists and
    ``overwrite`` is true, it is replaced only after the body succeeded (the previous
    contents are moved aside and deleted last).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a directory")
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True (or --overwrite) to replace it")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    os.chmod(tmp, _umask_mode(0o777))
    try:
        yield tmp
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
