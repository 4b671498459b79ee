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
