"""Driving logs (``LOG_FORMAT.md``) and result files.

Readers are strict: a missing required column, a non-increasing ``t``, values whose units
cannot be right, or an empty file raise :class:`LogFormatError` naming the problem.
Unknown columns are ignored with a warning naming them. Writers are atomic: a file (or a
whole output directory) appears complete or not at all, and nothing already there is
lost half-way.

Ground truth is kept apart: :attr:`DrivingLog.sensors` never contains a ``true_*``
column, so an estimator that reads only ``sensors`` cannot see the answer.

The modules, by responsibility (every name below is importable from here):

- :mod:`.log`: the log record (:class:`DrivingLog`, :class:`LogFormatError`, the column names);
- :mod:`.reader`: :func:`read_log` (CSV; logger formats dispatched to :mod:`tire_learning_env.formats`),
  :func:`finish_log` (the checks and split every reader ends with), :func:`read_vehicle`;
- :mod:`.units`: :func:`check_log_units`;
- :mod:`.writers`: :func:`write_log`, :func:`write_table`, :func:`atomic_write_text`, :func:`atomic_write_json`;
- :mod:`.outputs`: the run context, the output-path checks, the manifest and :func:`atomic_directory`.
"""

from .log import KNOWN_COLUMNS, SENSOR_COLUMNS, TRUTH_COLUMNS, DrivingLog, LogFormatError
from .outputs import (
    MANIFEST_NAME,
    OutputPathError,
    RunContext,
    atomic_directory,
    check_output_dir,
    check_output_file,
    current_run_context,
    read_manifest,
    record_run_info,
    run_context,
)
from .reader import ROW_GAP_FACTOR, ROW_GAP_MIN_S, VEHICLE_FILE_KEYS, finish_log, read_log, read_vehicle, row_gaps
from .units import UNIT_CHECKS_HINT, check_log_units
from .writers import atomic_write_json, atomic_write_text, to_jsonable, write_log, write_table

__all__ = [
    "LogFormatError",
    "DrivingLog",
    "read_log",
    "write_log",
    "write_table",
    "read_vehicle",
    "row_gaps",
    "ROW_GAP_FACTOR",
    "ROW_GAP_MIN_S",
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
    "SENSOR_COLUMNS",
    "TRUTH_COLUMNS",
    "RunContext",
    "finish_log",
    "to_jsonable",
    "UNIT_CHECKS_HINT",
]
