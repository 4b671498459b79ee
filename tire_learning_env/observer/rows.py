"""Sensor columns to the compiled kernel's row arrays (:func:`sensor_rows`); re-exported by
:mod:`.neuro_adaptive`."""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..params import ParameterError
from .model import MeasurementModel, check_sensor_columns

__all__ = ["sensor_rows", "CHANNELS"]

#: measurement channels in the order of the kernel's ``z`` columns
CHANNELS = ("e1", "e2", "ay", "yaw_rate")


class _KernelRows(dict):
    """Rows already in the kernel's layout (:func:`sensor_rows`): :meth:`NeuroAdaptiveObserver.run`
    skips the validation (the block law's pieces of one validated call)."""


def sensor_rows(sensors: Mapping[str, ArrayLike], model: MeasurementModel) -> dict[str, NDArray]:
    """The kernel's row arrays from sensor columns: ``t, delta, vx, ax, kappa`` and ``z`` (n, 4).

    ``kappa`` comes from ``kappa`` or ``psi_dot_des / vx``; channels the model does not read
    are NaN. Ground truth (``true_*``) is refused.
    """
    need = ["t", "delta", "vx"]
    if model.uses_camera:
        need += ["e1", "e2"] + ([] if "psi_dot_des" in sensors else ["kappa"])
    if model.uses_imu:
        need += ["ay", "yaw_rate"]
    check_sensor_columns(sensors, need, f"{model.name} estimation")
    get = lambda k: np.ascontiguousarray(np.asarray(sensors[k], dtype=float))  # noqa: E731
    t, delta, vx = get("t"), get("delta"), get("vx")
    n = len(t)
    if not (len(delta) == len(vx) == n):
        raise ParameterError("sensor columns must have equal lengths")
    ax = get("ax") if "ax" in sensors else np.zeros(n)
    ax = np.where(np.isfinite(ax), ax, 0.0)
    if model.uses_camera:
        kappa = get("kappa") if "kappa" in sensors else get("psi_dot_des") / np.maximum(vx, 1e-3)
        kappa = np.where(np.isfinite(kappa), kappa, 0.0)
    else:
        kappa = np.zeros(n)
    z = np.full((n, 4), np.nan)
    if model.uses_camera:
        z[:, 0], z[:, 1] = get("e1"), get("e2")
    if model.uses_imu:
        z[:, 2], z[:, 3] = get("ay"), get("yaw_rate")
    return {"t": t, "delta": delta, "vx": vx, "ax": ax, "kappa": np.ascontiguousarray(kappa), "z": z}
