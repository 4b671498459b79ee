"""Write the package's logs as a vehicle logger would: MF4, Parquet, MCAP, with a channel map.

Used to make the shipped examples (``tire_learning_env/data/example_drive.*``) and the
format round-trip tests and benchmarks. The files use logger-style channel names and
non-SI units (km/h, deg, deg/s, g, ms) on purpose, so reading them back exercises the
channel map and the unit conversion; the camera channels are written only at the
instants a frame arrived (their own time base in MF4 and MCAP).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Mapping

import numpy as np
from numpy.typing import NDArray

from ..io import atomic_write_text
from .channel_map import UNITS, ChannelMap
from .readers import LOGGER_SUFFIXES

__all__ = ["LOGGER_CHANNELS", "logger_channel_map", "write_logger_log", "save_channel_map", "write_example_logs",
           "write_ros2_bag", "ROS2_CHANNELS"]

# log column -> (logger channel, unit written, scale); the file holds SI / unit factor / scale.
LOGGER_CHANNELS: dict[str, tuple[str, str, float]] = {
    "vx": ("VehSpd", "km/h", 1.0),
    "delta": ("SteerWhlAng", "deg", 1 / 16),  # steering-wheel angle, steering ratio 16
    "kappa": ("LaneCrv", "1/m", 1.0),
    "e1": ("LaneLatOffs", "m", 1.0),
    "e2": ("LaneHdgErr", "deg", 1.0),
    "yaw_rate": ("YawRate", "deg/s", 1.0),
    "ay": ("LatAcc", "g", 1.0),
    "ax": ("LongAcc", "g", 1.0),
}
# MCAP topic of each group of channels.
MCAP_TOPICS = {"vehicle": "/vehicle/state", "camera": "/camera/lane", "imu": "/imu", "truth": "/truth"}
CAMERA = ("e1", "e2")
IMU = ("yaw_rate", "ay", "ax")


def _group(column: str) -> str:
    if column in CAMERA:
        return "camera"
    if column in IMU:
        return "imu"
    if column.startswith("true_"):
        return "truth"
    return "vehicle"


def _channel(column: str, fmt: str) -> tuple[str, str, float]:
    name, unit, scale = LOGGER_CHANNELS.get(column, (column, None, 1.0))
    if unit is None:
        from .channel_map import COLUMN_UNITS

        unit = COLUMN_UNITS[column]
    if fmt == "mcap":
        name = f"{MCAP_TOPICS[_group(column)]}:{name}"
    return name, unit, scale


def logger_channel_map(columns: list[str], fmt: str) -> ChannelMap:
    """The channel map of a file written by :func:`write_logger_log` with ``columns``."""
    doc: dict = {"time_base": "vx", "columns": {},
                 "description": "written by tire_learning_env.formats.write_logger_log (simulated drive)"}  # fmt: skip
    doc["columns"]["t"] = {"channel": "timestamp_ms", "unit": "ms"}  # the time column of a table (Parquet)
    for c in columns:
        if c == "t":
            continue
        name, unit, scale = _channel(c, fmt)
        doc["columns"][c] = {"channel": name, "unit": unit, **({"scale": scale} if scale != 1.0 else {})}
    return ChannelMap.from_dict(doc, f"<{fmt} logger map>")


def write_example_logs(folder: str | Path, duration: float = 30.0, seed: int = 7) -> list[Path]:
    """Simulate a drive and write it as ``example_drive.mf4``, ``example_drive.parquet`` and
    their shared channel map ``example_drive.channels.yaml`` (how the shipped examples in
    ``tire_learning_env/data/`` were made).

    Parameters
    ----------
    folder : str or Path
    duration : float
        Simulated time [s] (30 s at 50 rows/s keeps each file under 300 kB).
    seed : int
        Seed of the camera noise.
    """
    from ..params import CameraParams
    from ..simulation import simulate

    folder = Path(folder)
    log = simulate("study1", duration, camera=CameraParams.paper_noise(rate=20.0), physics_rate=1000.0, seed=seed)
    cols = log.to_columns()
    keep = np.zeros(len(cols["t"]), dtype=bool)
    keep[::20] = True  # 50 rows/s, plus every camera frame
    keep |= np.isfinite(cols["e1"])
    cols = {k: v[keep] for k, v in cols.items() if k not in ("true_vy", "true_beta")}
    paths = [folder / "example_drive.mf4", folder / "example_drive.parquet"]
    for p in paths:
        write_logger_log(p, cols)
    save_channel_map(logger_channel_map(list(cols), "mf4"), folder / "example_drive.channels.yaml")
    return paths + [folder / "example_drive.channels.yaml"]


def _raw(column: str, values: NDArray, fmt: str) -> tuple[str, str, NDArray]:
    name, unit, scale = _channel(column, fmt)
    return name, unit, np.asarray(values, dtype=float) / UNITS[unit][1] / scale


@contextlib.contextmanager
def _atomic_path(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp" + path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _write_mf4(path: Path, cols: Mapping[str, NDArray]) -> None:
    from asammdf import MDF, Signal

    t = np.asarray(cols["t"], dtype=float)
    frame = np.isfinite(cols["e1"]) if "e1" in cols else np.zeros(len(t), bool)
    groups: dict[str, list] = {}
    for c, v in cols.items():
        if c == "t":
            continue
        name, unit, raw = _raw(c, v, "mf4")
        g = _group(c)
        tt, vv = (t[frame], raw[frame]) if g == "camera" else (t, raw)
        groups.setdefault(g, []).append(Signal(vv, tt, name=name, unit=unit))
    mdf = MDF(version="4.10")
    for g, signals in groups.items():
        mdf.append(signals, comment=f"{g} channels")
    with _atomic_path(path) as tmp:
        mdf.save(str(tmp), overwrite=True, compression=2)


def _write_parquet(path: Path, cols: Mapping[str, NDArray]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields, arrays = [], []
    fields.append(pa.field("timestamp_ms", pa.float64(), metadata={"unit": "ms"}))
    arrays.append(pa.array(np.asarray(cols["t"], dtype=float) * 1e3))
    for c, v in cols.items():
        if c == "t":
            continue
        name, unit, raw = _raw(c, v, "parquet")
        fields.append(pa.field(name, pa.float64(), metadata={"unit": unit}))
        arrays.append(pa.array(raw, from_pandas=True))  # NaN -> null (no camera frame)
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields))
    with _atomic_path(path) as tmp:
        pq.write_table(table, str(tmp), compression="zstd")


def _write_mcap(path: Path, cols: Mapping[str, NDArray]) -> None:
    from mcap.writer import Writer

    t_ns = np.round(np.asarray(cols["t"], dtype=float) * 1e9).astype(np.int64)
    frame = np.isfinite(cols["e1"]) if "e1" in cols else np.zeros(len(t_ns), bool)
    by_group: dict[str, dict[str, tuple[str, NDArray]]] = {}
    for c, v in cols.items():
        if c == "t":
            continue
        name, unit, raw = _raw(c, v, "mcap")
        topic, fld = name.split(":", 1)
        by_group.setdefault(topic, {})[fld] = (unit, raw)
    with _atomic_path(path) as tmp, open(tmp, "wb") as fh:
        writer = Writer(fh)
        writer.start(profile="", library="tire_learning_env")
        channel_ids = {}
        for topic, fields in by_group.items():
            schema = {"type": "object", "properties": {f: {"type": ["number", "null"]} for f in fields}}
            sid = writer.register_schema(name=topic.strip("/").replace("/", "_"), encoding="jsonschema",
                                         data=json.dumps(schema).encode())  # fmt: skip
            channel_ids[topic] = writer.register_channel(
                topic=topic, message_encoding="json", schema_id=sid,
                metadata={f"unit:{f}": unit for f, (unit, _) in fields.items()},
            )  # fmt: skip
        camera_topic = MCAP_TOPICS["camera"]
        for i, ns in enumerate(t_ns.tolist()):
            for topic, fields in by_group.items():
                if topic == camera_topic and not frame[i]:
                    continue
                msg = {f: (None if not np.isfinite(raw[i]) else float(raw[i])) for f, (_, raw) in fields.items()}
                writer.add_message(channel_ids[topic], log_time=ns, publish_time=ns, data=json.dumps(msg).encode())
        writer.finish()


# ROS 2: log column -> (topic, message type, field, unit written, scale); ROS uses SI (REP 103)
# except the steering-wheel angle, published in degrees as many CAN bridges do.
ROS2_CHANNELS: dict[str, tuple[str, str, str, str, float]] = {
    "vx": ("/vehicle/twist", "geometry_msgs/msg/TwistStamped", "twist.linear.x", "m/s", 1.0),
    "delta": ("/steering/wheel_angle", "std_msgs/msg/Float64", "data", "deg", 1 / 16),
    "kappa": ("/lane/curvature", "std_msgs/msg/Float64", "data", "1/m", 1.0),
    "e1": ("/lane/offset", "std_msgs/msg/Float64", "data", "m", 1.0),
    "e2": ("/lane/heading", "std_msgs/msg/Float64", "data", "rad", 1.0),
    "yaw_rate": ("/imu/data", "sensor_msgs/msg/Imu", "angular_velocity.z", "rad/s", 1.0),
    "ay": ("/imu/data", "sensor_msgs/msg/Imu", "linear_acceleration.y", "m/s^2", 1.0),
    "ax": ("/imu/data", "sensor_msgs/msg/Imu", "linear_acceleration.x", "m/s^2", 1.0),
}


def _ros2_spec(column: str) -> tuple[str, str, str, str, float]:
    if column in ROS2_CHANNELS:
        return ROS2_CHANNELS[column]
    from .channel_map import COLUMN_UNITS

    return (f"/truth/{column}", "std_msgs/msg/Float64", "data", COLUMN_UNITS[column], 1.0)


def write_ros2_bag(path: str | Path, columns: Mapping[str, NDArray], channel_map: str | Path | None = None,
                   storage: str = "sqlite3") -> ChannelMap:  # fmt: skip
    """Write log-format ``columns`` as a ROS 2 bag folder (rosbags; ``sqlite3`` or ``mcap`` storage).

    Topics: ``/vehicle/twist`` (TwistStamped), ``/imu/data`` (Imu), ``/steering/wheel_angle``
    (Float64, steering-wheel angle in deg), ``/lane/offset``, ``/lane/heading`` (Float64, only
    when a camera frame arrived), ``/lane/curvature`` and ``/truth/<column>`` (Float64).
    Message times (bag and header stamps) are ``t`` [s]. ``path`` must not exist yet.

    Returns
    -------
    ChannelMap
        Reads the bag back into the same columns.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.LATEST)
    T = ts.types
    path = Path(path)
    cols = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    t = cols["t"]
    ns = np.round(t * 1e9).astype(np.int64)
    frame = np.isfinite(cols["e1"]) if "e1" in cols else np.zeros(len(t), bool)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    by_topic: dict[str, tuple[str, dict[str, NDArray]]] = {}
    doc: dict = {"time_base": "vx", "columns": {}, "description": "written by tire_learning_env.formats.write_ros2_bag"}
    for c, v in cols.items():
        if c == "t":
            continue
        topic, msgtype, fld, unit, scale = _ros2_spec(c)
        by_topic.setdefault(topic, (msgtype, {}))[1][fld] = v / UNITS[unit][1] / scale
        doc["columns"][c] = {"channel": f"{topic}:{fld}", "unit": unit, **({"scale": scale} if scale != 1.0 else {})}
    zeros9 = np.zeros(9)

    def stamp(i: int):
        sec, nsec = divmod(int(ns[i]), 10**9)
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="base_link")

    def vec(fields: dict, prefix: str, i: int):
        return T["geometry_msgs/msg/Vector3"](**{a: float(fields.get(f"{prefix}.{a}", np.zeros(len(t)))[i]) for a in "xyz"})

    def message(msgtype: str, fields: dict, i: int):
        if msgtype == "std_msgs/msg/Float64":
            return T[msgtype](data=float(fields["data"][i]))
        if msgtype == "geometry_msgs/msg/TwistStamped":
            twist = T["geometry_msgs/msg/Twist"](linear=vec(fields, "twist.linear", i), angular=vec(fields, "twist.angular", i))
            return T[msgtype](header=stamp(i), twist=twist)
        return T[msgtype](header=stamp(i), orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                          orientation_covariance=zeros9, angular_velocity=vec(fields, "angular_velocity", i),
                          angular_velocity_covariance=zeros9, linear_acceleration=vec(fields, "linear_acceleration", i),
                          linear_acceleration_covariance=zeros9)  # fmt: skip

    with Writer(path, version=9, storage_plugin=plugin) as writer:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=ts) for topic, (msgtype, _) in by_topic.items()}
        for i in range(len(t)):
            for topic, (msgtype, fields) in by_topic.items():
                if topic in ("/lane/offset", "/lane/heading") and not frame[i]:
                    continue
                writer.write(conns[topic], int(ns[i]), ts.serialize_cdr(message(msgtype, fields, i), msgtype))
    cmap = ChannelMap.from_dict(doc, "<ros2 logger map>")
    if channel_map is not None:
        save_channel_map(cmap, channel_map)
    return cmap


def write_logger_log(path: str | Path, columns: Mapping[str, NDArray], channel_map: str | Path | None = None) -> ChannelMap:
    """Write log-format ``columns`` (SI) as a logger file; the format follows the suffix.

    Parameters
    ----------
    path : str or Path
        ``.mf4``, ``.parquet`` or ``.mcap`` (written atomically).
    columns : mapping of str -> ndarray
        Log-format columns (``t`` [s], ``vx`` [m/s], ...), e.g. ``SimulationLog.to_columns()``.
    channel_map : str or Path, optional
        Also write the file's channel map there (``.yaml`` or ``.json``).

    Returns
    -------
    ChannelMap
        Reads the file back into the same columns.
    """
    path = Path(path)
    fmt = LOGGER_SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: suffix must be one of {sorted(LOGGER_SUFFIXES)}")
    cols = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    {"mf4": _write_mf4, "parquet": _write_parquet, "mcap": _write_mcap}[fmt](path, cols)
    cmap = logger_channel_map(list(cols), fmt)
    if channel_map is not None:
        save_channel_map(cmap, channel_map)
    return cmap


def save_channel_map(cmap: ChannelMap, path: str | Path) -> Path:
    """Write ``cmap`` as YAML (``.yaml``/``.yml``) or JSON, atomically."""
    path = Path(path)
    doc = cmap.to_dict()
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        text = "# channel map: log column <- logger channel [unit] (x scale); see docs/fleet.md\n"
        text += yaml.safe_dump(doc, sort_keys=False)
    else:
        text = json.dumps(doc, indent=2) + "\n"
    return atomic_write_text(path, text)
