"""The linear KF baseline and the reference scores of a fused (camera and IMU) ``estimate`` run.

The fused estimate (``tire-learning estimate LOG --sensors both``) is the observer's, on the
camera and the IMU together. Beside it the command writes what the IMU-only path writes
(:func:`.outputs.estimate_imu_log`): the package's linear Kalman filter on the log's IMU rows,
cleaned as for an IMU-only log (:func:`.logs.clean_imu_log`, with the vehicle file's ``imu_x``),
with the same noise (:func:`.estimate.imu_noise`) and the same filter
(:func:`.baseline.linear_kf_baseline`); and, when the log has a reference sideslip
(``true_beta`` / ``true_vy``, read for scoring only), the sideslip RMSE of the fused estimate
beside the KF's (:func:`.scoring.sideslip_scores`, the IMU path's keys).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..io import DrivingLog, LogFormatError
from ..observer import EstimateTrace, ObserverConfig
from ..params import VehicleParams
from .baseline import KF_WHAT, linear_kf_baseline
from .estimate import _rows, imu_noise
from .logs import clean_imu_log
from .scoring import reference_beta, sideslip_scores

__all__ = ["FUSED_BETA_COLUMNS", "FusedBaseline", "fused_linear_kf", "fused_reference_scores"]

#: the fused run's sideslip columns in ``estimates.csv`` and what they are
FUSED_BETA_COLUMNS = {
    "beta_hat": "reported: the fused observer's refined pass (the causal one with --no-offline)",
    "beta_observer_online": "the fused observer's causal pass",
    "beta_kf": "linear KF alone, on the IMU channels only (baseline_linear_kf)",
}


@dataclass
class FusedBaseline:
    """What :func:`fused_linear_kf` returns.

    Attributes
    ----------
    trace : EstimateTrace or None
        The linear KF over the log's rows; ``None`` when the IMU channels failed the IMU-only
        path's checks (``metrics["skipped"]`` says why).
    metrics : dict
        ``metrics.json``'s ``baseline_linear_kf`` block.
    """

    trace: EstimateTrace | None
    metrics: dict


def fused_linear_kf(log: DrivingLog, vehicle: VehicleParams, config: ObserverConfig, gap_s: float) -> FusedBaseline:
    """The linear KF baseline of a fused run (module docstring).

    Parameters
    ----------
    log : DrivingLog
        The log as read (:func:`tire_learning_env.io.read_log`); its IMU channels are cleaned here
        for the KF only (the fused observer reads them as logged).
    vehicle : VehicleParams
        The vehicle file (tires of the KF; ``imu_x`` places the accelerometer).
    config : ObserverConfig
        The run's configuration; its ``imu_noise``, when given, is the KF's noise too.
    gap_s : float
        The fused observer's ``segment_gap_s``.

    Returns
    -------
    FusedBaseline
        Without a trace when the IMU channels fail :func:`.logs.check_imu_log` (wrong units or sign,
        too few moving rows): the error's message is kept in ``metrics["skipped"]``.
    """
    try:
        cleaned, report = clean_imu_log(log, vehicle, allow_gaps=True)
    except LogFormatError as exc:
        return FusedBaseline(None, {"what": KF_WHAT, "skipped": f"the IMU channels fail the IMU-only checks: {exc}"})
    rows = _rows(cleaned.sensors)
    noise, noise_info = imu_noise(rows, config.imu_noise)
    trace, kf = linear_kf_baseline(rows, vehicle, noise, gap_s)
    return FusedBaseline(trace, {
        "what": KF_WHAT,
        "inputs": "the log's a_y and yaw rate cleaned as for an IMU-only log (imu.logs.clean_imu_log: spikes held, "
        "a_y beyond 3 g and rows below the speed floor dropped, a_y moved to the CG by the vehicle file's imu_x); "
        "the fused observer reads them as logged (a_y moved to the CG by imu_x)",
        "settings": kf.settings(),
        "noise": noise_info,
        "cleaning": report.to_dict(),
        "sideslip_rmse": "reference_scores.sideslip_rmse_deg.linear_kf_baseline",
    })  # fmt: skip


def fused_reference_scores(
    log: DrivingLog, fused: EstimateTrace, online: EstimateTrace, kf: EstimateTrace | None
) -> dict | None:
    """Sideslip RMSE of the fused estimate and of the linear KF against the log's reference sideslip.

    Parameters
    ----------
    log : DrivingLog
        Its ``truth`` (``true_beta``, else ``true_vy``) is the reference; scoring only.
    fused, online : EstimateTrace
        The fused observer's reported (refined) and causal passes.
    kf : EstimateTrace or None
        The linear KF (:func:`fused_linear_kf`).

    Returns
    -------
    dict or None
        :func:`.scoring.sideslip_scores` with the keys ``observer_refined`` (reported),
        ``observer_online_causal`` and ``linear_kf_baseline``; ``None`` without a reference
        sideslip or without the KF.
    """
    t = np.asarray(log.sensors["t"], dtype=float)
    beta_ref = reference_beta(log.truth, np.asarray(log.sensors["vx"], dtype=float))
    if beta_ref is None or kf is None:
        return None
    betas: dict[str, NDArray] = {"observer_refined": fused.beta, "observer_online_causal": online.beta,
                                 "linear_kf_baseline": kf.beta}  # fmt: skip
    return sideslip_scores(t, beta_ref, betas, "observer_refined", "observer_online_causal")
