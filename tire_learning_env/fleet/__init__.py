"""Fleets of logs and Monte Carlo sweeps on Ray (docs/fleet.md).

:func:`run_items` maps a function over work items as Ray tasks (local Ray by default, an
existing cluster with ``address``), records failures as rows, streams every result to a
JSON-lines store as it finishes and skips finished items on a re-run.
:mod:`tire_learning_env.fleet.batch` runs ``tire-learning estimate`` or ``discrepancy`` on
every log of a fleet (``tire-learning batch``). Ray is in the ``fleet`` extra; the serial
engine needs nothing extra.
"""

from .runner import THREAD_ENV, ItemResult, ResultStore, RunnerError, ray_available, run_items

__all__ = ["ItemResult", "ResultStore", "RunnerError", "ray_available", "run_items", "THREAD_ENV"]
