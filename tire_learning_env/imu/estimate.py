r"""IMU logs on the unified estimator core: noise, observer, linear KF, their blend, scores, files.

>>> from tire_learning_env.params import VehicleParams
>>> from tire_learning_env.imu import estimate_imu, simulate_imu_drive
>>> vehicle = VehicleParams(m=982, Iz=1605, lf=1.33, lr=1.07, Cf=35000, Cr=60000)
>>> sensors, truth, tires = simulate_imu_drive(vehicle, duration=30.0)
>>> result = estimate_imu(sensors, vehicle)
>>> result.core.sensors, bool(result.core.gains.certified)
('imu', True)

Steps of :func:`estimate_imu` (the ``estimate`` command runs :func:`.outputs.estimate_imu_log`, which
cleans the log first and writes the results):

1. **Noise** of ``a_y`` and ``r`` from the log (:func:`imu_noise_std`): residuals of local
   polynomial fits over 0.1 s. The bicycle model explains the car's motion up to a few hertz;
   whatever is faster in the accelerometer (engine and road vibration, often band-limited
   at tens of hertz, not white) is noise *for the model*. The core's default window of 9
   samples sees only the top of the band at 200 Hz (1.7 instead of 4.5 m/s^2 on a
   15-45 Hz vibration), so the log layer measures over a fixed time span instead and hands
   the result to the core as the IMU noise.
2. **The neuro-adaptive observer** (:func:`tire_learning_env.observer.estimate` with
   ``sensors="imu"``): certified gains for that noise and the log's speed range, causal
   pass, offline refinement over the whole log, stiffness with its two-sigma band, verdict.
3. **The linear Kalman filter** (:class:`~tire_learning_env.baselines.LinearKalmanFilter`)
   with the same measured noise.
4. **Blend** (:mod:`.blend`): interacting-multiple-model probabilities of the two from their
   ``a_y``/``r`` innovations; the reported states are the mixture, so wherever the learned
   curve predicts the IMU worse than fixed linear tires the estimate falls back to the KF.
   Done for the causal pass (``online``, causal probabilities) and for the refined pass
   (reported; smoothed probabilities, since that pass used the whole log anyway). When an
   axle's stiffness is not identified and the vehicle file lies inside the learned band on
   both axles, the reported blend keeps the prior weights (:func:`.blend.file_not_contradicted`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..baselines.kalman import LinearKalmanFilter
from ..observer import EstimateTrace, EstimationResult, ObserverConfig, estimate
from ..observer.calibration import IMU_NOISE_WINDOW_S, estimate_noise_std
from ..observer.model import check_sensor_columns
from ..params import ParameterError, VehicleParams
from .blend import Blend, BlendParams, blend_traces, causal_fallback_rows, file_not_contradicted
from .baseline import linear_kf_baseline

__all__ = ["ESTIMATE_COLUMNS", "NOISE_WINDOW_S", "ImuEstimate", "imu_config", "imu_noise_std", "estimate_imu"]

#: the first columns of ``estimates.csv``, in this order (the reported, blended estimate)
ESTIMATE_COLUMNS = ("t", "beta_hat", "vy_hat", "yaw_rate_hat", "alpha_f_hat", "alpha_r_hat", "Fyf_hat", "Fyr_hat")
#: time span of the local polynomial fits that measure the IMU noise [s] (the core's)
NOISE_WINDOW_S = IMU_NOISE_WINDOW_S
AXLES = ("front", "rear")
#: the causal learning law the causal blend weighs beside the core's (``AdaptationParams.causal_update``)
OTHER_LAW = {"rls": "block", "block": "rls"}
_COLUMNS = ("t", "delta", "vx", "ax", "ay", "yaw_rate")


def imu_config(config: ObserverConfig | None = None) -> ObserverConfig:
    """``config`` (default :class:`ObserverConfig`) with ``sensors="imu"``; the IMU-only
    basis is the two-sided one (the paper's cannot be told from a sideslip offset)."""
    config = config or ObserverConfig(sensors="imu")
    if config.sensors != "imu":
        config = config.replace(sensors="imu")
    if config.basis != "two_sided":
        raise ParameterError(
            f"basis {config.basis!r} is not available for IMU logs: the paper's basis is one-sided (flat for negative "
            "slip) and carries bias members that an IMU cannot tell from a sideslip offset; use 'two_sided'"
        )
    return config


def imu_noise_std(t: ArrayLike, ay: ArrayLike, yaw_rate: ArrayLike, window_s: float = NOISE_WINDOW_S) -> tuple[tuple[float, float], dict]:
    """Noise std of ``a_y`` [m/s^2] and ``r`` [rad/s]: everything faster than the vehicle's motion.

    Local polynomial residuals (:func:`~tire_learning_env.observer.calibration.estimate_noise_std`,
    degree 4) over windows of ``window_s`` seconds (at least 9 samples), so band-limited
    vibration counts in full at any sample rate (module docstring).

    Returns
    -------
    (ay_std, r_std), info
        ``info`` says how, for ``metrics.json``.
    """
    t = np.asarray(t, dtype=float)
    dt = float(np.median(np.diff(t)))
    window = max(9, int(round(window_s / dt)) | 1)
    est = {name: estimate_noise_std(t, z, window=window) for name, z in (("ay", ay), ("yaw_rate", yaw_rate))}
    default = {"ay": 0.5, "yaw_rate": 0.005}
    std = tuple(float(e.std) if math.isfinite(e.std) else default[k] for k, e in est.items())
    info = {
        "source": f"estimated from the log by the IMU log layer: residuals of local degree-4 polynomial fits over "
        f"{window} samples ({window * dt:.3g} s); what the vehicle motion cannot explain",
        "window_samples": window,
        "channels": {k: e.to_dict() for k, e in est.items()},
        "std": list(std),
    }
    return (std[0], std[1]), info


def imu_noise(rows: Mapping[str, NDArray], given: tuple[float, float] | None) -> tuple[tuple[float, float], dict]:
    """The IMU noise every estimator of a log uses: ``given`` (``ObserverConfig.imu_noise``), else
    :func:`imu_noise_std` of the rows.

    Returns
    -------
    (ay_std, r_std), info
        ``info`` says how, for ``metrics.json``.
    """
    if given is None:
        return imu_noise_std(rows["t"], rows["ay"], rows["yaw_rate"])
    noise = tuple(given)
    return (noise[0], noise[1]), {"source": "given (ObserverConfig.imu_noise)", "std": list(noise)}


@dataclass
class ImuEstimate:
    """What :func:`estimate_imu` returns.

    Attributes
    ----------
    core : EstimationResult
        The unified core's result: ``online`` (causal) and ``trace`` (refined) passes, learned
        curves, ``cornering_stiffness()`` with ``cornering_stiffness_std()``, ``verdict``,
        ``calibration``, gains.
    kalman : EstimateTrace
        The linear Kalman filter over the same rows.
    kalman_filter : LinearKalmanFilter
    blend : Blend
        Mixture of the refined observer pass and the KF: the reported states.
    blend_online : Blend
        Mixture of the causal observer pass, the causal pass under the other learning law
        (:attr:`online_other_law`, with ``BlendParams.other_causal_law``) and the KF: what a car
        gets on line.
    noise : dict
        How the IMU noise was obtained.
    runtime_s : dict
        Wall times [s].
    blend_params : BlendParams
    online_other_law : EstimateTrace or None
        The observer's causal pass under the other causal learning law (``"block"`` when the core
        ran ``"rls"``, the IMU default, and the other way round).
    blend_fallback : dict or None
        :func:`~.blend.file_not_contradicted` for the learned curve and the vehicle file, with
        ``applied``: the reported blend kept the prior mode probabilities (curve not identified,
        file inside its band on both axles).
    online_fallback : dict or None
        :func:`~.blend.causal_fallback_rows` for the causal blend: ``applied`` (some rows held to the
        linear KF), ``rows_held_fraction``, ``blocks``, ``blocks_fallback``.
    """

    core: EstimationResult
    kalman: EstimateTrace
    kalman_filter: LinearKalmanFilter
    blend: Blend
    blend_online: Blend
    noise: dict
    runtime_s: dict
    blend_params: BlendParams = BlendParams()
    online_other_law: EstimateTrace | None = None
    blend_fallback: dict | None = None
    online_fallback: dict | None = None

    @property
    def online(self) -> EstimateTrace:
        """The observer's causal pass."""
        return self.core.online

    @property
    def trace(self) -> EstimateTrace:
        """The observer's refined pass (the causal one without offline refinement)."""
        return self.core.trace

    @property
    def gains(self):
        return self.core.gains

    def axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Learned total axle force [N] (the refined curve)."""
        return self.core.axle_force(alpha, axle)

    def axle_force_std(self, alpha: ArrayLike, axle: str) -> NDArray:
        """Standard deviation of :meth:`axle_force` [N]."""
        return self.core.axle_force_std(alpha, axle)

    def online_axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """The curve at the end of the causal pass [N]."""
        return self.core.online_axle_force(alpha, axle)

    def nominal_axle_force(self, alpha: ArrayLike, axle: str) -> NDArray:
        """The vehicle file's linear curve ``2 C alpha`` [N] (the KF's)."""
        return self.core.nominal_axle_force(alpha, axle)

    def cornering_stiffness(self) -> tuple[float, float]:
        """Per-tire cornering stiffness of the learned curves [N/rad]."""
        return self.core.cornering_stiffness()


def _rows(sensors: Mapping[str, ArrayLike]) -> dict[str, NDArray]:
    check_sensor_columns(sensors, ("t", "delta", "vx", "ay", "yaw_rate"), "IMU estimation")
    rows = {k: np.asarray(sensors[k], dtype=float) for k in _COLUMNS if k in sensors}
    rows.setdefault("ax", np.zeros_like(rows["t"]))
    return rows


def estimate_imu(
    sensors: Mapping[str, ArrayLike],
    vehicle: VehicleParams,
    config: ObserverConfig | None = None,
    blend: BlendParams | None = None,
    cache: bool = True,
) -> ImuEstimate:
    """Estimate states and tire curves from IMU rows (module docstring).

    Parameters
    ----------
    sensors : mapping of str -> array
        ``t, delta, vx, ay, yaw_rate`` (``ax`` optional); NaN = no sample. No ``true_*``.
    vehicle : VehicleParams
        The vehicle file (its ``Cf``, ``Cr`` are the starting curve and the KF's tires).
    config : ObserverConfig, optional
        ``sensors`` is set to ``imu``; ``imu_noise`` given there is used instead of measured.
    blend : BlendParams, optional
    cache : bool
        Disk cache of the certified gains.
    """
    config = imu_config(config)
    rows = _rows(sensors)
    t_all = time.perf_counter()
    runtime: dict = {}
    t0 = time.perf_counter()
    noise, noise_info = imu_noise(rows, config.imu_noise)
    if config.imu_noise is None:
        config = config.replace(imu_noise=noise)
        runtime["noise"] = time.perf_counter() - t0
    core = estimate(rows, vehicle, config=config, cache=cache)
    runtime["observer"] = core.runtime_s
    params = blend or BlendParams()
    other = None
    if params.other_causal_law:  # the causal pass again under the other learning law (a mode of the causal blend)
        t0 = time.perf_counter()
        law = core.observer.adaptation.causal_update
        alt = estimate(rows, vehicle, config=config.replace(causal_update=OTHER_LAW[law], offline=False), cache=cache)
        other = (f"observer_{OTHER_LAW[law]}", alt.online)
        runtime["observer_other_causal_law"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ktrace, kf = linear_kf_baseline(rows, vehicle, noise, core.observer.segment_gap_s)
    runtime["linear_kf"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    # the refined pass used the whole log: its mode probabilities may too (smoothed); the causal one stays causal
    # ... unless the log left the curve's scale open and did not contradict the vehicle file (blend docstring)
    fallback = file_not_contradicted(core.stiffness_report(), (vehicle.Cf, vehicle.Cr))
    fallback["applied"] = bool(params.unidentified_fallback and config.offline and fallback["fallback"])
    b_final = blend_traces(core.trace, ktrace, params, smooth=config.offline, evidence=not fallback["applied"])
    # the causal blend's own fallback: the verdict of the "block" law's fit over the rows so far (blend docstring)
    block_pass = core.online if core.observer.adaptation.causal_update == "block" else (other[1] if other else None)
    online_fallback: dict = {"applied": False}
    hold = None
    if params.causal_fallback and block_pass is not None and "causal_stiffness" in block_pass.meta:
        hold, online_fallback = causal_fallback_rows(rows["t"], block_pass.meta["causal_stiffness"],
                                                     (vehicle.Cf, vehicle.Cr), config.identifiable_rel_2sigma)  # fmt: skip
        online_fallback["applied"] = bool(hold.any())
    b_online = blend_traces(core.online, ktrace, params, alternatives=(other,) if other else (), hold=hold)
    runtime["blend"] = time.perf_counter() - t0
    runtime["total"] = time.perf_counter() - t_all
    return ImuEstimate(core, ktrace, kf, b_final, b_online, noise_info, runtime, params,
                       online_other_law=other[1] if other else None, blend_fallback=fallback,
                       online_fallback=online_fallback)  # fmt: skip
