"""Read logs as vehicle loggers write them: ASAM MDF4 (``.mf4``), Parquet, MCAP, ROS 2 bags.

Each reader yields the logger's channels (sample times [s], values, the unit stored in the
file); :func:`read_logger_log` picks the channels a :class:`~.channel_map.ChannelMap` names,
converts their units to SI, puts them on one time base, and then applies exactly the checks
:func:`tire_learning_env.io.read_log` applies to a CSV log. What was converted and resampled
is stated in :attr:`DrivingLog.notes`.

Resampling to the common time base (MF4 and MCAP, whose channels carry their own times):
the rows are the sample times of the map's ``time_base`` column (default ``vx``).
Continuous channels are interpolated linearly (rows outside a channel's time span are
dropped at the ends of the log); the camera channels ``e1``/``e2`` are frames, not signals:
a frame lands on the nearest row within half a row period and rows without a frame stay
NaN, as in the CSV format. Channels sampled at exactly the row times are copied unchanged.
"""

from __future__ import annotations

import contextlib
import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
from numpy.typing import NDArray

from ..io import DrivingLog, LogFormatError, finish_log
from .channel_map import UNITS, ChannelMap, ChannelSpec, convert_unit, find_channel_map, load_channel_map

__all__ = ["LOGGER_SUFFIXES", "read_logger_log", "read_channels", "RawChannel", "default_channel_map", "is_ros2_bag",
           "logger_format"]

LOGGER_SUFFIXES = {".mf4": "mf4", ".mdf": "mf4", ".parquet": "parquet", ".pq": "parquet", ".mcap": "mcap", ".db3": "ros2"}


def is_ros2_bag(path: str | Path) -> bool:
    """True for a ROS 2 bag folder (it holds ``metadata.yaml``) or a ``.db3`` file inside one."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() == ".db3"


def logger_format(path: str | Path) -> str | None:
    """``"mf4"``, ``"parquet"``, ``"mcap"``, ``"ros2"`` (a bag folder or its ``.db3``), or None (CSV)."""
    path = Path(path)
    if path.is_dir():
        return "ros2" if is_ros2_bag(path) else None
    return LOGGER_SUFFIXES.get(path.suffix.lower())
EVENT_COLUMNS = ("e1", "e2")  # camera frames: NaN where no frame arrived
EPOCH_THRESHOLD_S = 1e6  # times above this are absolute (epoch) times and are made relative


@dataclass
class RawChannel:
    """One logger channel: sample times [s] (None: the rows of a table), values, stored unit."""

    name: str
    t: NDArray | None
    values: NDArray
    unit: str | None


def _need(module: str, fmt: str, source: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise LogFormatError(f"{source}: reading {fmt} logs needs the '{module.split('.')[0]}' package: "
                             "pip install 'tire_learning_env[fleet]'") from None  # fmt: skip


def _missing(source: str, spec: ChannelSpec, cmap: ChannelMap, available: list[str]) -> LogFormatError:
    shown = ", ".join(repr(a) for a in available[:12]) + (f" and {len(available) - 12} more" if len(available) > 12 else "")
    return LogFormatError(f"{source}: channel {spec.channel!r} (column {spec.column!r} in channel map {cmap.source}) "
                          f"is not in the file; its channels: {shown or 'none'}")  # fmt: skip


# --- MF4 -----------------------------------------------------------------------------------
def _mf4_channels(path: Path, source: str) -> tuple[list[str], Callable[[str], RawChannel]]:
    asammdf = _need("asammdf", "MF4", source)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mdf = asammdf.MDF(str(path))
    except Exception as exc:  # noqa: BLE001 - asammdf raises many types for a corrupt file
        raise LogFormatError(f"{source}: not a readable MF4 file ({type(exc).__name__}: {exc})") from None
    names = [n for n in mdf.channels_db if n != "time"]

    def get(name: str) -> RawChannel:
        if name not in mdf.channels_db:
            raise KeyError(name)
        try:
            sig = mdf.get(name)
        except Exception as exc:  # noqa: BLE001 - e.g. the name occurs in several channel groups
            raise LogFormatError(f"{source}: channel {name!r} cannot be read: {exc}") from None
        return RawChannel(name, np.asarray(sig.timestamps, dtype=float), np.asarray(sig.samples, dtype=float),
                          sig.unit or None)  # fmt: skip

    return names, get


# --- Parquet -------------------------------------------------------------------------------
def _parquet_channels(path: Path, source: str) -> tuple[list[str], Callable[[str], RawChannel]]:
    _need("pyarrow", "Parquet", source)
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(str(path))
    except Exception as exc:  # noqa: BLE001
        raise LogFormatError(f"{source}: not a readable Parquet file ({type(exc).__name__}: {exc})") from None
    names = list(table.column_names)

    def get(name: str) -> RawChannel:
        if name not in names:
            raise KeyError(name)
        fld = table.schema.field(name)
        meta = fld.metadata or {}
        unit = meta.get(b"unit", b"").decode() or None
        col = table.column(name)
        import pyarrow as pa

        if pa.types.is_timestamp(fld.type) or pa.types.is_duration(fld.type):
            values = col.cast(pa.int64()).to_numpy(zero_copy_only=False).astype(float)
            unit = {"s": "s", "ms": "ms", "us": "us", "ns": "ns"}[fld.type.unit]
        else:
            try:
                values = col.cast(pa.float64()).to_numpy(zero_copy_only=False).astype(float)  # null -> NaN
            except (TypeError, ValueError, pa.ArrowException) as exc:
                raise LogFormatError(f"{source}: column {name!r} is not numeric ({fld.type}): {exc}") from None
        return RawChannel(name, None, values, unit)

    return names, get


# --- MCAP ----------------------------------------------------------------------------------
def _field(obj: Any, path: str) -> Any:
    for part in path.split("."):
        obj = obj[part] if isinstance(obj, dict) else getattr(obj, part)
    return obj


def _collect(data: dict, wanted: list[str], topic: str, t: float, msg: Any) -> None:
    """Append the fields of ``msg`` (on ``topic`` at ``t`` [s]) that ``wanted`` names."""
    for w in wanted:
        w_topic, _, fld = w.partition(":")
        if w_topic != topic:
            continue
        try:
            value = _field(msg, fld)
        except (KeyError, AttributeError, TypeError):
            continue
        data[w][0].append(t)
        data[w][1].append(np.nan if value is None else float(value))


class _CdrDecoder:
    """ROS 2 CDR messages decoded with rosbags' type store (types of the bag registered from
    their definitions when the store does not know them)."""

    def __init__(self, source: str) -> None:
        _need("rosbags", "ROS 2 (CDR)", source)
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.LATEST)
        self.source = source

    def register(self, msgtype: str, definition: str | None, kind: str = "msg") -> None:
        if msgtype in self.store.types or not definition:
            return
        from rosbags.typesys import get_types_from_idl, get_types_from_msg

        try:
            types = get_types_from_idl(definition) if kind == "idl" else get_types_from_msg(definition, msgtype)
            self.store.register(types)
        except Exception as exc:  # noqa: BLE001
            raise LogFormatError(f"{self.source}: cannot read the definition of message type {msgtype!r}: {exc}") from None

    def __call__(self, raw: bytes, msgtype: str) -> Any:
        if msgtype not in self.store.types:
            raise LogFormatError(f"{self.source}: message type {msgtype!r} is unknown and the file has no definition of it")
        return self.store.deserialize_cdr(raw, msgtype)


def _mcap_channels(path: Path, source: str, wanted: list[str]) -> tuple[list[str], Callable[[str], RawChannel]]:
    """MCAP messages -> channels ``topic:field``: JSON messages, and ROS 2 (CDR) messages through
    rosbags. Times are the messages' log times."""
    _need("mcap", "MCAP", source)
    from mcap.reader import make_reader

    topics = sorted({w.split(":", 1)[0] for w in wanted})
    data: dict[str, tuple[list[float], list[float]]] = {w: ([], []) for w in wanted}
    units: dict[str, str] = {}
    available: set[str] = set()
    try:
        with open(path, "rb") as fh:
            reader = make_reader(fh)
            summary = reader.get_summary()
            if summary is not None:
                for ch in summary.channels.values():
                    available.add(ch.topic)
                    for k, v in (ch.metadata or {}).items():
                        if k.startswith("unit:"):
                            units[f"{ch.topic}:{k[5:]}"] = v
            cdr = None
            for schema, channel, message in reader.iter_messages(topics=topics):
                available.add(channel.topic)
                if channel.message_encoding == "json":
                    msg = json.loads(message.data)
                elif channel.message_encoding == "cdr" and schema is not None:
                    if cdr is None:
                        cdr = _CdrDecoder(source)
                    cdr.register(schema.name, schema.data.decode(errors="replace"),
                                 "idl" if schema.encoding == "ros2idl" else "msg")  # fmt: skip
                    msg = cdr(message.data, schema.name)
                else:
                    raise LogFormatError(f"{source}: topic {channel.topic!r} has message encoding "
                                         f"{channel.message_encoding!r}; JSON and ROS 2 CDR are supported")  # fmt: skip
                _collect(data, wanted, channel.topic, message.log_time * 1e-9, msg)
    except LogFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - mcap raises many types for a corrupt file
        raise LogFormatError(f"{source}: not a readable MCAP file ({type(exc).__name__}: {exc})") from None
    return sorted(available), _getter(data, units)


def _getter(data: dict, units: dict) -> Callable[[str], RawChannel]:
    def get(name: str) -> RawChannel:
        if name not in data or not data[name][0]:
            raise KeyError(name)
        t, v = data[name]
        return RawChannel(name, np.asarray(t), np.asarray(v, dtype=float), units.get(name))

    return get


# --- ROS 2 bags (rosbag2: sqlite3 or MCAP storage) ------------------------------------------
def _ros2_channels(path: Path, source: str, wanted: list[str]) -> tuple[list[str], Callable[[str], RawChannel]]:
    """A ROS 2 bag folder -> channels ``topic:field`` (dots for nested fields, e.g.
    ``/imu/data:angular_velocity.z``); times are the bag's receive times."""
    _need("rosbags", "ROS 2 bag", source)
    from rosbags.rosbag2 import Reader

    bag = path if path.is_dir() else path.parent
    topics = {w.split(":", 1)[0] for w in wanted}
    data: dict[str, tuple[list[float], list[float]]] = {w: ([], []) for w in wanted}
    try:
        with Reader(bag) as reader:
            available = sorted({c.topic for c in reader.connections})
            conns = [c for c in reader.connections if c.topic in topics]
            cdr = _CdrDecoder(source)
            for c in conns:
                msgdef = getattr(c, "msgdef", None)
                text = getattr(msgdef, "data", msgdef) if msgdef is not None else None
                fmt = getattr(getattr(msgdef, "format", None), "name", "msg") if msgdef is not None else "msg"
                cdr.register(c.msgtype, text if isinstance(text, str) else None, "idl" if str(fmt).lower() == "idl" else "msg")
            for conn, stamp, raw in reader.messages(connections=conns):
                _collect(data, wanted, conn.topic, stamp * 1e-9, cdr(raw, conn.msgtype))
    except LogFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many types for a corrupt bag
        raise LogFormatError(f"{source}: not a readable ROS 2 bag ({type(exc).__name__}: {exc})") from None
    return available, _getter(data, {})


def read_channels(path: str | Path, channels: list[str]) -> tuple[str, list[str], Callable[[str], RawChannel]]:
    """``(format, available channel names, get)`` for a logger file; ``get(name)`` raises
    :class:`KeyError` for a channel the file lacks."""
    path = Path(path)
    source = str(path)
    fmt = logger_format(path)
    if fmt is None:
        raise LogFormatError(f"{source}: unknown log suffix {path.suffix!r}; known: .csv, {', '.join(LOGGER_SUFFIXES)} "
                             "and ROS 2 bag folders")  # fmt: skip
    if not (path.is_file() or (fmt == "ros2" and path.is_dir())):
        raise LogFormatError(f"cannot read log {path}: no such file")
    if fmt == "mf4":
        names, get = _mf4_channels(path, source)
    elif fmt == "parquet":
        names, get = _parquet_channels(path, source)
    elif fmt == "mcap":
        names, get = _mcap_channels(path, source, channels)
    else:
        names, get = _ros2_channels(path, source, channels)
    return fmt, names, get


def _resample(base: NDArray, t: NDArray, v: NDArray, column: str) -> NDArray:
    if len(t) == len(base) and np.array_equal(t, base):
        return v
    if column in EVENT_COLUMNS:
        out = np.full(len(base), np.nan)
        ok = np.isfinite(v)
        tf, vf = t[ok], v[ok]
        half = 0.5 * float(np.median(np.diff(base))) if len(base) > 1 else np.inf
        j = np.clip(np.searchsorted(base, tf), 1, len(base) - 1) if len(base) > 1 else np.zeros(len(tf), int)
        if len(base) > 1:
            j = np.where(np.abs(base[j - 1] - tf) <= np.abs(base[j] - tf), j - 1, j)
        near = np.abs(base[j] - tf) <= half
        out[j[near]] = vf[near]
        return out
    ok = np.isfinite(v)
    if ok.sum() == 0:
        return np.full(len(base), np.nan)
    out = np.interp(base, t[ok], v[ok])
    out[(base < t[ok][0]) | (base > t[ok][-1])] = np.nan
    return out


_DEFAULT_MAPS: list[str | Path | ChannelMap] = []


@contextlib.contextmanager
def default_channel_map(channel_map: str | Path | ChannelMap | None) -> Iterator[None]:
    """In the body, logger files without a map beside them use ``channel_map``.

    This is how ``tire-learning batch --channel-map`` reaches the readers inside the
    estimate and discrepancy commands (which call :func:`~tire_learning_env.io.read_log`
    with the log path only). Precedence: the ``channel_map`` argument of the reader, a map
    beside the log, this default, the channels named as the columns.
    """
    if channel_map is None:
        yield
        return
    _DEFAULT_MAPS.append(channel_map)
    try:
        yield
    finally:
        _DEFAULT_MAPS.pop()


def _given_map(path: Path, channel_map) -> tuple[ChannelMap | None, str]:
    """The channel map given, found beside the log, or the default, and a note saying which (None: none)."""
    if isinstance(channel_map, ChannelMap):
        return channel_map, f"channel map {channel_map.source}"
    if channel_map is not None:
        return load_channel_map(channel_map), f"channel map {channel_map}"
    found = find_channel_map(path)
    if found is not None:
        return load_channel_map(found), f"channel map {found} (found beside the log)"
    if _DEFAULT_MAPS:
        default = _DEFAULT_MAPS[-1]
        cmap = default if isinstance(default, ChannelMap) else load_channel_map(default)
        return cmap, f"channel map {cmap.source} (the default given to the batch)"
    return None, ""


def read_logger_log(path: str | Path, channel_map: str | Path | ChannelMap | None = None, min_rows: int = 2,
                    check_units: bool | None = None, sensors: str = "auto") -> DrivingLog:  # fmt: skip
    """Read an MF4, Parquet or MCAP log into a :class:`~tire_learning_env.io.DrivingLog`.

    Parameters
    ----------
    path : str or Path
        ``.mf4``/``.mdf``, ``.parquet``/``.pq`` or ``.mcap`` file, or a ROS 2 bag folder
        (or its ``.db3``).
    channel_map : str, Path, ChannelMap or None
        Channel map; None looks for ``<stem>.channels.{yaml,yml,json}`` then
        ``channels.{yaml,yml,json}`` beside the log, else uses the channels named like the
        log's columns.
    min_rows, check_units, sensors
        As :func:`tire_learning_env.io.read_log`.

    Returns
    -------
    DrivingLog
        In SI units on one time base; ``notes`` say which map, which unit conversions and
        which resampling were applied.

    Raises
    ------
    LogFormatError
        Unreadable file, a mapped channel missing from the file (named, with the file's
        channels), an unknown unit, or any problem :func:`~tire_learning_env.io.read_log`
        would name on the same data as CSV.
    """
    if sensors not in ("auto", "camera", "imu"):
        raise ValueError(f"sensors must be 'auto', 'camera' or 'imu', got {sensors!r}")
    path = Path(path)
    source = str(path)
    cmap, map_note = _given_map(path, channel_map)
    wanted = [spec.channel for c, spec in cmap.columns.items() if c != "t"] if cmap is not None else []
    fmt, names, get = read_channels(path, wanted)
    if cmap is None:
        cmap = ChannelMap.identity(names)
        map_note = "no channel map: channels named as the log columns are used, in the file's units or SI"
    if not cmap.columns:
        raise LogFormatError(f"{source}: no channel map found and no channel is named like a log column "
                             f"(t, vx, delta, ...); write a channel map <stem>.channels.yaml beside the log")  # fmt: skip
    notes = [f"{fmt.upper()} log", map_note]
    converted = []
    raw: dict[str, RawChannel] = {}
    values: dict[str, NDArray] = {}
    for column, spec in cmap.columns.items():
        if column == "t" and fmt != "parquet":
            notes.append(f"the map's 't' <- {spec.channel!r} is for tables; {fmt.upper()} channels carry their own times")
            continue
        try:
            ch = get(spec.channel)
        except KeyError:
            raise _missing(source, spec, cmap, names) from None
        unit = spec.unit
        if unit is None:
            unit = ch.unit if ch.unit and ch.unit.strip() in UNITS else None
            if ch.unit and unit is None:
                raise LogFormatError(f"{source}: channel {spec.channel!r} (column {column!r}) has unit {ch.unit!r} in "
                                     "the file, which is not a known unit; state its unit in the channel map")  # fmt: skip
        elif ch.unit and ch.unit.strip() in UNITS and UNITS[ch.unit.strip()] != UNITS[unit.strip()]:
            notes.append(f"{column}: the channel map's unit {unit!r} used; the file says {ch.unit!r}")
        v = convert_unit(ch.values, unit, column, spec.channel) if unit else np.asarray(ch.values, dtype=float)
        if spec.scale != 1.0:
            v = v * spec.scale
        if (unit and UNITS[unit.strip()][1] != 1.0) or spec.scale != 1.0:
            converted.append(f"{column} <- {spec.channel} [{unit or 'SI'}]" + (f" x {spec.scale:g}" if spec.scale != 1.0 else ""))
        raw[column] = ch
        values[column] = v
    if converted:
        notes.append("converted to SI: " + "; ".join(converted))
    if fmt == "parquet":
        columns = _table_time(values, raw, cmap, source, notes)
    else:
        columns = _common_time_base(values, raw, cmap, source, notes)
    return _finish(columns, source, notes, min_rows, check_units, sensors)


def _relative_time(t: NDArray, notes: list[str], what: str) -> NDArray:
    if len(t) and t[0] > EPOCH_THRESHOLD_S:
        notes.append(f"{what} are absolute times: t is relative to the first row (absolute start {t[0]:.6f} s)")
        return t - t[0]
    return t


def _table_time(values, raw, cmap, source, notes) -> dict[str, NDArray]:
    if "t" not in values:
        raise LogFormatError(f"{source}: no time column: the Parquet file has no column 't' and the channel map "
                             f"{cmap.source} maps none to 't'")  # fmt: skip
    out = dict(values)
    out["t"] = _relative_time(values["t"], notes, "the time column's values")
    notes.append("one row per Parquet row (no resampling)")
    return out


def _common_time_base(values, raw, cmap, source, notes) -> dict[str, NDArray]:
    base_col = cmap.time_base if cmap.time_base in values else next(iter(values))
    base = raw[base_col].t
    t0 = base[0] if len(base) and base[0] > EPOCH_THRESHOLD_S else 0.0
    copied, resampled = [], []
    out: dict[str, NDArray] = {}
    for column, v in values.items():
        if column == "t":
            continue  # MF4/MCAP channels carry their own times
        t = raw[column].t
        if len(t) == len(base) and np.array_equal(t, base):
            out[column] = v
            copied.append(column)
        else:
            out[column] = _resample(base, t, v, column)
            resampled.append(f"{column} ({len(t)} samples, " + ("nearest frame" if column in EVENT_COLUMNS else "linear") + ")")
    cont = [c for c in out if c not in EVENT_COLUMNS]
    keep = np.ones(len(base), dtype=bool)
    for c in cont:
        ok = np.isfinite(out[c])
        if ok.any():
            first, last = int(np.argmax(ok)), len(ok) - 1 - int(np.argmax(ok[::-1]))
            keep[:first] = False
            keep[last + 1:] = False
    dropped = int((~keep).sum())
    out = {c: v[keep] for c, v in out.items()}
    out["t"] = base[keep] - t0
    if t0:
        notes.append(f"sample times are absolute: t is relative to the first row (absolute start {t0:.6f} s)")
    text = f"time base: the {len(base)} sample times of column {base_col!r} (channel {raw[base_col].name!r})"
    if resampled:
        text += "; resampled onto it: " + ", ".join(resampled)
    else:
        text += "; every channel shares it (no resampling)"
    if dropped:
        text += f"; {dropped} row(s) at the ends dropped where a channel had no samples"
    notes.append(text)
    return out


def _finish(columns: dict[str, NDArray], source: str, notes: list[str], min_rows: int, check_units: bool | None,
            sensors: str) -> DrivingLog:  # fmt: skip
    """The same checks and split as :func:`tire_learning_env.io.read_log` after its CSV parsing."""
    return finish_log(columns, source, notes, min_rows, check_units, sensors)
