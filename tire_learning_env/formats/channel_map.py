"""Channel maps: a logger's channel names and units -> the log format's columns (SI).

A channel map is a small YAML or JSON file::

    # drive.channels.yaml
    time_base: vx              # optional: the column whose sample times become the rows (default vx)
    columns:
      vx:       {channel: VehicleSpeed, unit: km/h}
      delta:    {channel: SteeringWheelAngle, unit: deg, scale: 0.0625}   # / steering ratio 16
      yaw_rate: {channel: YawRate, unit: deg/s}
      ay:       {channel: LatAcc, unit: g}
      e1:       {channel: "/camera/lane:offset", unit: m}                # MCAP: "topic:field"
      t:        {channel: timestamp, unit: ms}                           # Parquet: the time column

``channel`` names the logger's channel (MF4 channel name, Parquet column, MCAP
``topic:field`` with dots for nested fields); ``unit`` is the unit the logger wrote (when
absent, the unit stored in the file is used, else SI is assumed); ``scale`` multiplies
after the unit conversion (e.g. ``1/steering ratio`` to turn a steering-wheel angle into
the road-wheel angle). A shorthand ``vx: VehicleSpeed`` names the channel only.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from ..io import KNOWN_COLUMNS, LogFormatError

__all__ = [
    "COLUMN_UNITS",
    "UNITS",
    "ChannelSpec",
    "ChannelMap",
    "load_channel_map",
    "find_channel_map",
    "convert_unit",
]

# SI unit of every log column (LOG_FORMAT.md).
COLUMN_UNITS: dict[str, str] = {
    "t": "s", "vx": "m/s", "delta": "rad", "kappa": "1/m", "e1": "m", "e2": "rad", "yaw_rate": "rad/s",
    "ay": "m/s^2", "ax": "m/s^2", "true_e1": "m", "true_e1_dot": "m/s", "true_e2": "rad", "true_e2_dot": "rad/s",
    "true_alpha_f": "rad", "true_alpha_r": "rad", "true_Fyf": "N", "true_Fyr": "N", "true_vy": "m/s", "true_beta": "rad",
}  # fmt: skip

# unit as a logger writes it -> (SI unit, factor): value_SI = factor * value.
UNITS: dict[str, tuple[str, float]] = {
    "s": ("s", 1.0), "sec": ("s", 1.0), "ms": ("s", 1e-3), "us": ("s", 1e-6), "µs": ("s", 1e-6), "ns": ("s", 1e-9),
    "m/s": ("m/s", 1.0), "km/h": ("m/s", 1 / 3.6), "kph": ("m/s", 1 / 3.6), "kmh": ("m/s", 1 / 3.6),
    "mph": ("m/s", 0.44704),
    "rad": ("rad", 1.0), "deg": ("rad", math.pi / 180), "°": ("rad", math.pi / 180), "mrad": ("rad", 1e-3),
    "rad/s": ("rad/s", 1.0), "deg/s": ("rad/s", math.pi / 180), "°/s": ("rad/s", math.pi / 180),
    "m/s^2": ("m/s^2", 1.0), "m/s2": ("m/s^2", 1.0), "m/s²": ("m/s^2", 1.0), "g": ("m/s^2", 9.80665),
    "m": ("m", 1.0), "cm": ("m", 1e-2), "mm": ("m", 1e-3),
    "1/m": ("1/m", 1.0), "1/km": ("1/m", 1e-3),
    "N": ("N", 1.0), "kN": ("N", 1e3),
}  # fmt: skip

_SPEC_KEYS = {"channel", "unit", "scale"}
_MAP_KEYS = {"columns", "time_base", "description"}


def convert_unit(values: NDArray, unit: str, column: str, channel: str = "") -> NDArray:
    """``values`` given in ``unit`` converted to the SI unit of ``column``.

    Raises
    ------
    LogFormatError
        ``unit`` is unknown, or of another quantity than ``column`` (e.g. ``deg`` for ``vx``).
    """
    si = COLUMN_UNITS.get(column)
    where = f"column {column!r}" + (f" (channel {channel!r})" if channel else "")
    if si is None:
        raise LogFormatError(f"{where}: not a column of the log format (LOG_FORMAT.md)")
    key = unit.strip()
    if key not in UNITS:
        known = sorted(u for u, (s, _) in UNITS.items() if s == si)
        raise LogFormatError(f"{where}: unknown unit {unit!r}; units for {si}: {', '.join(known)}")
    target, factor = UNITS[key]
    if target != si:
        raise LogFormatError(f"{where}: unit {unit!r} is a unit of {target}, but {column!r} is in {si}")
    return np.asarray(values, dtype=float) * factor


@dataclass(frozen=True)
class ChannelSpec:
    """Where one log column comes from.

    Attributes
    ----------
    column : str
        Log-format column (``vx``, ``delta``, ...).
    channel : str
        The logger's channel name (MCAP: ``topic:field``).
    unit : str or None
        Unit the logger wrote; None = the file's unit metadata, else SI.
    scale : float
        Multiplier applied after the unit conversion [-].
    """

    column: str
    channel: str
    unit: str | None = None
    scale: float = 1.0

    def __post_init__(self) -> None:
        if self.column not in COLUMN_UNITS:
            raise LogFormatError(f"channel map: {self.column!r} is not a column of the log format; columns: "
                                 f"{', '.join(COLUMN_UNITS)}")  # fmt: skip
        if not isinstance(self.channel, str) or not self.channel:
            raise LogFormatError(f"channel map: column {self.column!r} needs a channel name")
        if not (isinstance(self.scale, (int, float)) and math.isfinite(self.scale) and self.scale != 0):
            raise LogFormatError(f"channel map: column {self.column!r}: scale must be a finite non-zero number")
        if self.unit is not None:
            convert_unit(np.zeros(1), self.unit, self.column, self.channel)  # unknown / wrong-quantity unit: error now


@dataclass(frozen=True)
class ChannelMap:
    """Log columns -> logger channels, with units (see the module docstring).

    Attributes
    ----------
    columns : dict of str -> ChannelSpec
    time_base : str
        Column whose sample times become the log's rows (MF4, MCAP).
    source : str
        File it was read from (or a description).
    """

    columns: dict[str, ChannelSpec]
    time_base: str = "vx"
    source: str = "identity (channels named as the log columns)"
    description: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if self.time_base not in self.columns and self.columns:
            raise LogFormatError(f"channel map {self.source}: time_base {self.time_base!r} is not one of its columns "
                                 f"{sorted(self.columns)}")  # fmt: skip

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any], source: str = "channel map") -> "ChannelMap":
        """Build from the parsed YAML/JSON document; unknown keys are an error naming them."""
        if not isinstance(doc, Mapping):
            raise LogFormatError(f"{source}: a channel map is a mapping with a 'columns' key")
        unknown = sorted(set(doc) - _MAP_KEYS)
        if unknown:
            raise LogFormatError(f"{source}: unknown key(s) {unknown}; allowed: {sorted(_MAP_KEYS)}")
        cols = doc.get("columns")
        if not isinstance(cols, Mapping) or not cols:
            raise LogFormatError(f"{source}: 'columns' must map log columns to channels")
        specs = {}
        for column, spec in cols.items():
            if isinstance(spec, str):
                spec = {"channel": spec}
            if not isinstance(spec, Mapping):
                raise LogFormatError(f"{source}: column {column!r}: give a channel name or {{channel, unit, scale}}")
            bad = sorted(set(spec) - _SPEC_KEYS)
            if bad:
                raise LogFormatError(f"{source}: column {column!r}: unknown key(s) {bad}; allowed: {sorted(_SPEC_KEYS)}")
            try:
                specs[str(column)] = ChannelSpec(str(column), spec.get("channel"), spec.get("unit"), spec.get("scale", 1.0))
            except LogFormatError as exc:
                raise LogFormatError(f"{source}: {exc}") from None
        return cls(specs, str(doc.get("time_base", "vx")), source, str(doc.get("description", "")))

    @classmethod
    def identity(cls, channels: list[str]) -> "ChannelMap":
        """Every channel named like a log column maps to it, unit from the file or SI."""
        specs = {c: ChannelSpec(c, c) for c in channels if c in COLUMN_UNITS}
        base = "vx" if "vx" in specs else (next(iter(specs)) if specs else "vx")
        return cls(specs, base)

    def to_dict(self) -> dict:
        cols = {}
        for c, s in self.columns.items():
            d: dict[str, Any] = {"channel": s.channel}
            if s.unit is not None:
                d["unit"] = s.unit
            if s.scale != 1.0:
                d["scale"] = s.scale
            cols[c] = d
        out: dict[str, Any] = {"time_base": self.time_base, "columns": cols}
        if self.description:
            out["description"] = self.description
        return out


def load_channel_map(path: str | Path) -> ChannelMap:
    """Read a channel map from a ``.yaml``/``.yml`` or ``.json`` file.

    Raises
    ------
    LogFormatError
        The file cannot be read or parsed, or a key, column or unit is wrong (named).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise LogFormatError(f"cannot read channel map {path}: {exc.strerror or exc}") from None
    if path.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:  # pragma: no cover - PyYAML is in the fleet extra
            raise LogFormatError(f"channel map {path}: reading YAML needs PyYAML (pip install "
                                 "'tire_learning_env[fleet]'), or write the map as JSON") from None  # fmt: skip
        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise LogFormatError(f"channel map {path}: not valid YAML ({str(exc).splitlines()[0]})") from None
    else:
        try:
            doc = json.loads(text)
        except ValueError as exc:
            raise LogFormatError(f"channel map {path}: not valid JSON ({exc})") from None
    return ChannelMap.from_dict(doc, str(path))


MAP_SUFFIXES = (".yaml", ".yml", ".json")


def find_channel_map(log: str | Path) -> Path | None:
    """The channel-map file beside ``log``: ``<stem>.channels.{yaml,yml,json}``, else
    ``channels.{yaml,yml,json}`` in the same folder; None when there is none."""
    log = Path(log)
    for name in [f"{log.stem}.channels{s}" for s in MAP_SUFFIXES] + [f"channels{s}" for s in MAP_SUFFIXES]:
        candidate = log.parent / name
        if candidate.is_file():
            return candidate
    return None


def known_columns() -> tuple[str, ...]:
    """The log-format columns a channel map can fill."""
    return tuple(c for c in KNOWN_COLUMNS if c in COLUMN_UNITS)
