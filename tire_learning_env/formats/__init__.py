"""Logs as vehicle loggers write them: ASAM MDF4, Parquet, MCAP, ROS 2 bags, with channel maps.

:func:`tire_learning_env.io.read_log` dispatches ``.mf4``/``.mdf``, ``.parquet``/``.pq``, ``.mcap``
files and ROS 2 bag folders (or their ``.db3``) here (:func:`read_logger_log`); CSV stays in
:mod:`tire_learning_env.io`.
The readers need the ``fleet`` extra (``pip install 'tire_learning_env[fleet]'``).
"""

from .channel_map import (COLUMN_UNITS, UNITS, ChannelMap, ChannelSpec, convert_unit, find_channel_map,
                          load_channel_map)  # fmt: skip
from .readers import LOGGER_SUFFIXES, default_channel_map, is_ros2_bag, logger_format, read_logger_log
from .writers import (LOGGER_CHANNELS, logger_channel_map, save_channel_map, write_example_logs, write_logger_log,
                      write_ros2_bag)

__all__ = [
    "COLUMN_UNITS",
    "UNITS",
    "ChannelMap",
    "ChannelSpec",
    "convert_unit",
    "find_channel_map",
    "load_channel_map",
    "LOGGER_SUFFIXES",
    "read_logger_log",
    "default_channel_map",
    "is_ros2_bag",
    "logger_format",
    "LOGGER_CHANNELS",
    "logger_channel_map",
    "save_channel_map",
    "write_logger_log",
    "write_example_logs",
    "write_ros2_bag",
]
