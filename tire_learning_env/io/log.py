"""The driving-log record: its columns (``LOG_FORMAT.md``), :class:`DrivingLog` and :class:`LogFormatError`.

Ground truth is kept apart: :attr:`DrivingLog.sensors` never contains a ``true_*``
column, so an estimator that reads only ``sensors`` cannot see the answer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["SENSOR_COLUMNS", "TRUTH_COLUMNS", "KNOWN_COLUMNS", "LogFormatError", "DrivingLog"]

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

