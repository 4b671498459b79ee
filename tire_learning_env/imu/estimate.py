r"""IMU logs on the unified estimator core: noise, observer, linear KF, their blend, scores, files.

>>> from tire_learning_env.params import VehicleParams
>>> from tire_learning_env.imu import estimate_imu, simulate_imu_drive
>>> vehicle = VehicleParams(m=982, Iz=1605, lf=1.33, lr=1.07, Cf=35000, Cr=60000)
>>> sensors, truth, tires = simulate_imu_drive(vehicle, duration=30.0)
>>> result = estimate_imu(sensors, vehicle)
>>> result.core.sensors, bool(result.core.gains.certified)
('imu', True)

Steps of :func:`estimate_imu` (the ``estimate`` command runs :func:`estimate_imu_log`):

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

import inspect
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..baselines.kalman import LinearKalmanFilter
from ..io import DrivingLog, atomic_directory, atomic_write_json, write_table
from ..observer import EstimateTrace, EstimationResult, ObserverConfig, estimate
from ..observer.calibration import IMU_NOISE_WINDOW_S, estimate_noise_std
from ..observer.model import check_sensor_columns
from ..params import ParameterError, VehicleParams
from .blend import Blend, BlendParams, blend_traces, causal_fallback_rows, file_not_contradicted
from .logs import MIN_SPEED, CleaningReport, clean_imu_log

__all__ = ["ESTIMATE_COLUMNS", "NOISE_WINDOW_S", "ImuEstimate", "imu_config", "imu_noise_std", "estimate_imu",
           "estimate_imu_log"]  # fmt: skip

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
    if config.imu_noise is None:
        t0 = time.perf_counter()
        noise, noise_info = imu_noise_std(rows["t"], rows["ay"], rows["yaw_rate"])
        config = config.replace(imu_noise=noise)
        runtime["noise"] = time.perf_counter() - t0
    else:
        noise = tuple(config.imu_noise)
        noise_info = {"source": "given (ObserverConfig.imu_noise)", "std": list(noise)}
    noise_used = (max(noise[0], 0.01), max(noise[1], 1e-4))  # the core's floors
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
    dt = float(np.median(np.diff(rows["t"])))
    t0 = time.perf_counter()
    kf = LinearKalmanFilter(vehicle, noise_std=noise_used, physics_dt=dt)
    # the KF's own speed floor (1 m/s) makes its forward-Euler step unstable at standstill for a stiff car or a
    # slow log (1 - dt (Cf + Cr) / (m v) < -1); the observer's floor V_FLOOR keeps it stable where the IMU
    # samples are not used anyway (logs.MIN_SPEED)
    ktrace = _kf_by_segment(kf, dict(rows, vx=np.maximum(rows["vx"], MIN_SPEED)), core.observer.segment_gap_s,
                            vehicle, noise_used, dt)  # fmt: skip
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


def _kf_by_segment(kf: LinearKalmanFilter, rows: dict, gap_s: float, vehicle: VehicleParams, noise, dt: float):
    """The linear KF over ``rows``; after each pause longer than ``gap_s`` [s] (the observer's
    ``segment_gap_s``) a fresh filter starts, as at the start of the log (its forward-Euler step across
    a pause of seconds is unstable, and nothing was measured there). ``kf`` runs the first segment."""
    t = rows["t"]
    cuts = (np.flatnonzero(np.diff(t) > gap_s) + 1).tolist() if math.isfinite(gap_s) else []
    if not cuts:
        return kf.run(rows)
    parts = []
    for i, (a, b) in enumerate(zip([0] + cuts, cuts + [len(t)])):
        f = kf if i == 0 else LinearKalmanFilter(vehicle, noise_std=noise, physics_dt=dt)
        parts.append(f.run({k: v[a:b] for k, v in rows.items()}, predict_last=b == len(t)))
    fields = ("t", "state", "slip", "force", "force_nonlinear", "std", "health", "innovation", "nis", "vx", "kappa")
    out = {f: np.concatenate([getattr(p, f) for p in parts]) for f in fields}
    return EstimateTrace(**out, weights=parts[0].weights, state_names=parts[0].state_names,
                         meta=dict(parts[0].meta, segments=len(parts),
                                   beta=np.concatenate([p.meta["beta"] for p in parts])))  # fmt: skip


# -- the estimate command on an IMU log -------------------------------------------------------------
def estimate_imu_log(
    log: DrivingLog,
    vehicle: VehicleParams,
    out: str | Path,
    config: ObserverConfig | None = None,
    *,
    blend: BlendParams | None = None,
    cache: bool = True,
    basis: str | None = None,
    warm_start: bool | None = None,
) -> dict:
    """Clean an IMU log, estimate (:func:`estimate_imu`), score against a reference sensor when
    the log has one, and write ``out`` atomically.

    Parameters
    ----------
    log : DrivingLog
        From :func:`tire_learning_env.io.read_log` (``kind == "imu"``; ``true_*`` kept apart).
    vehicle : VehicleParams
    out : path
        Output folder (written through :func:`tire_learning_env.io.atomic_directory`).
    config : ObserverConfig, optional
        ``sensors`` is set to ``imu``.
    blend : BlendParams, optional
    cache : bool
    basis, warm_start : optional
        Former keywords of the ``estimate`` command: ``basis`` sets ``config.basis`` (only
        ``two_sided``), ``warm_start=False`` turns the offline refinement off.

    Writes
    ------
    - ``estimates.csv``: :data:`ESTIMATE_COLUMNS` (the blended estimate), then
      ``beta_std`` (its std [rad]), ``mu_observer`` (probability of the observer mode),
      ``beta_hat_online`` (causal blend), ``beta_observer``, ``beta_observer_online`` (the
      observer alone, refined and causal), ``beta_kf`` (the linear KF), ``health`` (of the
      causal observer, :data:`~tire_learning_env.observer.HEALTH_NAMES` index),
      ``beta_observer_online_other_law`` (the causal pass under the other learning law, when run);
    - ``tire_curves.csv`` (learned, its two-sigma band, online, nominal, measured),
      ``tire_curves.png``, ``tire_curve_front.png``, ``tire_curve_rear.png``, ``sideslip.png``,
      ``weights.png``;
    - ``metrics.json``: cleaning, calibration (what was estimated and what was assumed),
      certificate, stiffness with its band and verdict, blend shares, runtime, and with
      ``true_vy``/``true_beta`` the sideslip RMSE and curve NRMSE (whole log and halves).

    Returns
    -------
    dict
        The metrics.
    """
    config = config or ObserverConfig(sensors="imu")
    if basis is not None:
        config = config.replace(basis=basis)
    if warm_start is not None:
        config = config.replace(offline=bool(warm_start))
    config = imu_config(config)
    cleaned, report = clean_imu_log(log, vehicle, allow_gaps=True)  # pauses: segment boundaries (estimate_imu)
    rows = _rows(cleaned.sensors)
    t_start = time.perf_counter()
    result = estimate_imu(rows, vehicle, config, blend=blend, cache=cache)
    wall = time.perf_counter() - t_start
    metrics = _metrics(cleaned, report, vehicle, config, result, wall)
    _write_outputs(out, cleaned, vehicle, result, metrics)
    return metrics


def _speed_coverage(rows: dict, gains) -> dict:
    vx, d = rows["vx"], rows["delta"]
    lo, hi = gains.speed_range
    outside = (vx < lo) | (vx > hi)
    max_steer = float(gains.settings.get("design", {}).get("max_steer", 0.3))
    return {
        "vx_min_mps": float(np.nanmin(vx)),
        "vx_max_mps": float(np.nanmax(vx)),
        "certified_range_mps": [lo, hi],
        "rows_outside_certified_speed_range": int(outside.sum()),
        "rows_beyond_max_steer": int((np.abs(d) > max_steer).sum()),
        "rows_per_cell": np.bincount(gains.cell_index(vx), minlength=gains.n_cells).tolist(),
    }


def _stiffness_block(result: ImuEstimate, vehicle: VehicleParams) -> dict:
    core = result.core
    rep = core.stiffness_report()
    k = core.cornering_stiffness()
    s = core.cornering_stiffness_std()
    ko = core.observer.cornering_stiffness(core.online_weights)
    out = {
        "definition": "slope at zero slip of a polynomial fitted over the linear range of the learned axle curve "
        "(observer.offline.stiffness_readout); per tire = half the axle value; band = +/- 2 sigma from the "
        "estimator's own covariance",
        "verdict": core.verdict,
        "final": {
            "per_tire_N_per_rad": dict(zip(AXLES, k)),
            "per_axle_N_per_rad": {a: 2.0 * v for a, v in zip(AXLES, k)},
            "std_per_tire_N_per_rad": dict(zip(AXLES, s)),
            "band_2sigma_per_axle_N_per_rad": {a: [2.0 * (v - 2 * e), 2.0 * (v + 2 * e)] for a, v, e in zip(AXLES, k, s)},
            "identified": {a: rep[a]["identified"] for a in AXLES},
        },
        "online_end_of_log": {
            "per_tire_N_per_rad": dict(zip(AXLES, ko)),
            "per_axle_N_per_rad": {a: 2.0 * v for a, v in zip(AXLES, ko)},
            "definition": "slope at zero slip of the curve at the end of the causal pass",
        },
        "report": rep,
        "learned_slip_range_deg": core.learned_slip_range(),
        "nominal_per_tire_N_per_rad": {"front": vehicle.Cf, "rear": vehicle.Cr},
        "nominal_per_axle_N_per_rad": {"front": 2 * vehicle.Cf, "rear": 2 * vehicle.Cr},
    }
    h = math.radians(1.0)
    out["secant_pm1deg_per_axle_N_per_rad"] = {
        a: float((result.axle_force(h, a) - result.axle_force(-h, a)) / (2 * h)) for a in AXLES
    }
    return out


def _calibration(result: ImuEstimate) -> dict:
    cal = {k: v for k, v in result.core.calibration.items() if not str(k).startswith("_")}
    noise = dict(cal.get("noise", {}))
    noise["imu"] = result.noise
    cal["noise"] = noise
    return cal


def _vehicle_source() -> str:
    """Where the vehicle came from: the CLI's ``--vehicle`` path or its built-in default (recorded by
    ``vehicle_from_args``), else a caller of the library."""
    from ..io import current_run_context

    info = current_run_context().info.get("vehicle")
    return str(info["source"]) if isinstance(info, dict) and "source" in info else "given by the caller (VehicleParams)"


def _metrics(cleaned: DrivingLog, report: CleaningReport, vehicle, config: ObserverConfig, result: ImuEstimate,
             wall: float) -> dict:  # fmt: skip
    from .scoring import MeasuredCurve, measured_tire_data, near_zero_stiffness, reference_beta, sideslip_rmse_deg, split_masks

    rows = _rows(cleaned.sensors)
    t = rows["t"]
    core = result.core
    obs_rt = core.runtime_s
    metrics: dict = {
        "log": cleaned.source,
        "log_kind": "imu",
        "rows": int(len(t)),
        "duration_s": float(t[-1] - t[0]),
        "dt_s": float(np.median(np.diff(t))),
        "log_notes": cleaned.notes,
        "cleaning": report.to_dict(),
        "vehicle": vehicle.to_dict(),
        "vehicle_source": _vehicle_source(),
        "config": config.to_dict(),
        "summary": core.summary(),
        "calibration": _calibration(result),
        "speed_coverage": _speed_coverage(rows, core.gains),
        "lmi": core.gains.summary(),
        "cornering_stiffness": _stiffness_block(result, vehicle),
        "health": {"online": core.online.health_fraction, "online_final": core.online.final_health,
                   "reported_final": core.trace.final_health},  # fmt: skip
        "innovation_rms": {
            "ay_mps2": float(np.sqrt(np.nanmean(core.trace.innovation[:, 2] ** 2))),
            "yaw_rate_radps": float(np.sqrt(np.nanmean(core.trace.innovation[:, 3] ** 2))),
        },
        "blend": {
            "what": "interacting-multiple-model probabilities of the observer and the linear KF from their a_y and "
            "yaw-rate innovations (imu.blend); the reported states are the mixture",
            "settings": result.blend_params.to_dict(),
            "reported": result.blend.summary(),
            "online": result.blend_online.summary(),
            "reported_fallback": result.blend_fallback,
            "causal_fallback": result.online_fallback,
        },
        "runtime_s": {
            "observer": {k: float(v) for k, v in obs_rt.items()},
            "observer_all_passes": float(obs_rt.get("online_pass", 0.0) + obs_rt.get("offline_refinement", 0.0)),
            "linear_kf": float(result.runtime_s["linear_kf"]),
            "blend": float(result.runtime_s["blend"]),
            "estimate_wall_incl_baselines": float(wall),
            "note": "observer.gains = LMI solve or cache load + numpy re-certification",
        },
        "baseline_linear_kf": {
            "what": "linear Kalman filter of the source paper (states beta, r; measurements a_y, r; axle stiffness "
            "2 Cf, 2 Cr of the vehicle file), baselines.LinearKalmanFilter, with the measured IMU noise",
            "settings": result.kalman_filter.settings(),
            "tire_curve": "linear with the nominal axle stiffness: scored as tire_curve_nrmse.nominal_linear_curve",
            "sideslip_rmse": "reference_scores.sideslip_rmse_deg.linear_kf_baseline",
        },
        "estimates_csv": {
            "beta_hat": "reported: blend of the refined observer pass and the linear KF",
            "beta_hat_online": "blend of the causal observer pass and the linear KF",
            "beta_observer": "refined observer pass alone", "beta_observer_online": "causal observer pass alone",
            "beta_kf": "linear KF alone",
            "beta_observer_online_other_law": "causal observer pass under the other causal learning law (a mode of "
            "the causal blend)",
        },  # fmt: skip
        "not_modelled": [
            "longitudinal load transfer (a_x): the axle curves are learned as functions of slip only",
            "aerodynamic downforce, roll and camber, combined slip under braking/traction, tire relaxation",
            "a force offset at zero slip (not identifiable from a_y, r: F(0) = 0 is imposed); constant a_y and "
            "yaw-rate sensor offsets are learned",
            (f"the IMU's position is not estimated: it is taken from the vehicle file's imu_x (here {vehicle.imu_x:+g} m "
             "ahead of the centre of gravity; 0 = at the CG, the default) and a_y - imu_x * r_dot is used. A wrong "
             "imu_x is absorbed by the learned curves: on an independent single-track log an accelerometer 0.3 m "
             "ahead read as at the CG gave +5.5 / +8.4 % stiffness, 1.0 m +20 / +33 %, identified with bands that "
             "missed"),
            "road bank and grade (g sin(bank) in a_y reads as an a_y offset, not as a slip)",
        ],
        "discrepancy_workflow": (
            "run separately: tire-learning discrepancy LOG.csv --vehicle V.json --tire learned --out DIR "
            "(docs/real_car_discrepancy.md)"
        ),
    }
    beta_ref = reference_beta(cleaned.truth, rows["vx"])
    data = measured_tire_data(cleaned.sensors, cleaned.truth, vehicle)
    if beta_ref is None or data is None:
        metrics["reference_scores"] = None
        return metrics
    masks = split_masks(t)
    rmse = {
        "reported_blend": sideslip_rmse_deg(result.blend.beta, beta_ref, masks),
        "online_blend_causal": sideslip_rmse_deg(result.blend_online.beta, beta_ref, masks),
        "observer_online_causal": sideslip_rmse_deg(core.online.beta, beta_ref, masks),
        **({"observer_online_other_law": sideslip_rmse_deg(result.online_other_law.beta, beta_ref, masks)}
           if result.online_other_law is not None else {}),
        "observer_refined": sideslip_rmse_deg(core.trace.beta, beta_ref, masks),
        "linear_kf_baseline": sideslip_rmse_deg(result.kalman.beta, beta_ref, masks),
    }
    curves = {name: MeasuredCurve(data, m) for name, m in masks.items()}
    nrmse = {
        "final_learned_curve": {a: {k: c.nrmse(result.axle_force, a) for k, c in curves.items()} for a in AXLES},
        "online_curve_end_of_log": {a: {k: c.nrmse(result.online_axle_force, a) for k, c in curves.items()} for a in AXLES},
        "nominal_linear_curve": {a: {k: c.nrmse(result.nominal_axle_force, a) for k, c in curves.items()} for a in AXLES},
    }
    first_end = int(np.flatnonzero(masks["first_half"])[-1])
    curve_mid = core.online_curve_at(first_end)
    nrmse["online_curve_learned_on_first_half_vs_second_half"] = {
        a: curves["second_half"].nrmse(curve_mid, a) for a in AXLES
    }
    kf_whole = rmse["linear_kf_baseline"]["whole"]
    metrics["reference_scores"] = {
        "note": "reference sensor columns (true_vy/true_beta) used here only; all rows scored, no burn-in; halves "
        "split at the middle time of the log",
        "split_time_s": float(0.5 * (t[0] + t[-1])),
        "sideslip_rmse_deg": rmse,
        "tire_curve_nrmse": nrmse,
        "covered_slip_range_deg": {k: c.range_deg() for k, c in curves.items()},
        "measured_curve_definition": "binned mean of README's measured (slip, force) samples, 40 bins over the "
        f"0.5-99.5 % slip quantiles, r_dot from a zero-phase {data.cutoff_hz:g} Hz Butterworth-filtered yaw rate",
        "measured_axle_stiffness_near_zero_N_per_rad": near_zero_stiffness(data),
        "targets": {
            "reported_no_worse_than_linear_kf": bool(rmse["reported_blend"]["whole"] <= kf_whole),
            "online_no_worse_than_linear_kf": bool(rmse["online_blend_causal"]["whole"] <= kf_whole),
            "curve_nrmse_max": 0.10,
            "curve_met_final": {a: bool(nrmse["final_learned_curve"][a]["whole"] <= 0.10) for a in AXLES},
        },
    }
    return metrics


def _write_outputs(out, cleaned: DrivingLog, vehicle, result: ImuEstimate, metrics: dict) -> None:
    from .. import plotting
    from .plots import plot_axle_comparison, plot_sideslip
    from .scoring import MeasuredCurve, measured_tire_data, reference_beta

    core = result.core
    fin, onl, b = core.trace, core.online, result.blend
    rows = _rows(cleaned.sensors)
    data = measured_tire_data(cleaned.sensors, cleaned.truth, vehicle)
    measured = MeasuredCurve(data) if data is not None else None
    with atomic_directory(out) as d:
        cols = {
            "t": b.t, "beta_hat": b.beta, "vy_hat": b.vy, "yaw_rate_hat": b.yaw_rate, "alpha_f_hat": b.slip[:, 0],
            "alpha_r_hat": b.slip[:, 1], "Fyf_hat": b.force[:, 0], "Fyr_hat": b.force[:, 1], "beta_std": b.beta_std,
            "mu_observer": b.mu_observer, "beta_hat_online": result.blend_online.beta, "beta_observer": fin.beta,
            "beta_observer_online": onl.beta, "beta_kf": result.kalman.beta, "health": onl.health.astype(float),
        }  # fmt: skip
        if result.online_other_law is not None:
            cols["beta_observer_online_other_law"] = result.online_other_law.beta
        write_table(d / "estimates.csv", cols)
        grid = np.radians(np.linspace(-10.0, 10.0, 201))
        table = {"alpha": grid}
        for a, key in zip(AXLES, ("Fyf", "Fyr")):
            table[key] = result.axle_force(grid, a)
            table[f"{key}_2sigma"] = 2.0 * result.axle_force_std(grid, a)
            table[f"{key}_online"] = result.online_axle_force(grid, a)
            table[f"{key}_nominal"] = result.nominal_axle_force(grid, a)
            if measured is not None:
                lo, hi = measured.ranges[a]
                table[f"{key}_measured"] = np.where((grid >= lo) & (grid <= hi), measured(grid, a), np.nan)
        write_table(d / "tire_curves.csv", table)
        atomic_write_json(d / "metrics.json", metrics)
        if measured is not None:
            excited = measured.range_deg()
        else:
            excited = {a: [math.degrees(v) for v in np.percentile(fin.slip[:, i], [0.5, 99.5])] for i, a in enumerate(AXLES)}
        samples = {a: (fin.slip[:, i], fin.force[:, i]) for i, a in enumerate(AXLES)}
        shown = {"learned (refined)": result.axle_force, "online (causal, end)": result.online_axle_force,
                 "nominal linear": result.nominal_axle_force}  # fmt: skip
        if measured is not None:

            def measured_in_range(alpha, axle):
                lo, hi = measured.ranges[axle]
                a = np.asarray(alpha, dtype=float)
                return np.where((a >= lo) & (a <= hi), measured(a, axle), np.nan)

            shown = {"measured (reference sensor)": measured_in_range, **shown}
        kw = {}
        if "bands" in inspect.signature(plotting.plot_tire_curves).parameters:
            kw["bands"] = {"learned (refined)": result.axle_force_std}
        plotting.plot_tire_curves(
            shown, None, excited, samples, title=f"learned axle curves (samples: observer estimates): "
            f"{Path(cleaned.source).name}", path=d / "tire_curves.png", **kw,
        )  # fmt: skip
        for i, a in enumerate(AXLES):
            plot_axle_comparison(
                a, fin.slip[:, i], fin.force[:, i], data.slip[:, i] if data is not None else None,
                data.force[:, i] if data is not None else None, result.axle_force, result.nominal_axle_force,
                measured, path=d / f"tire_curve_{a}.png",
            )  # fmt: skip
        beta_ref = reference_beta(cleaned.truth, rows["vx"])
        plot_sideslip(b.t, b.beta, result.kalman.beta, beta_ref, path=d / "sideslip.png", beta_observer=onl.beta)
        if onl.weights.size:
            plotting.plot_weights(onl.t, onl.weights[:, : core.observer.basis.n_weights], core.observer.basis.n_per_axle,
                                  title="weights (causal pass)", path=d / "weights.png")  # fmt: skip
