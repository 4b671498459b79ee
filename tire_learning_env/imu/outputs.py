r"""An IMU log in, a results folder out: :func:`estimate_imu_log` (what ``tire-learning estimate``
runs on a log without camera columns).

The log is cleaned (:func:`.logs.clean_imu_log`), estimated (:func:`.estimate.estimate_imu`:
observer, linear KF and their blend), scored against the log's reference sensor when it has one
(:mod:`.scoring`), and written atomically: ``estimates.csv``, ``tire_curves.csv``, the figures
and ``metrics.json`` (:func:`_metrics`, :func:`_write_outputs`).
"""

from __future__ import annotations

import inspect
import math
import time
from pathlib import Path

import numpy as np

from ..io import DrivingLog, atomic_directory, atomic_write_json, write_table
from ..observer import ObserverConfig
from ..params import VehicleParams
from .baseline import KF_WHAT
from .blend import BlendParams
from .estimate import AXLES, ImuEstimate, _rows, estimate_imu, imu_config
from .logs import CleaningReport, clean_imu_log

__all__ = ["estimate_imu_log"]


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
    from .scoring import MeasuredCurve, measured_tire_data, near_zero_stiffness, reference_beta, sideslip_scores, split_masks

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
            "what": KF_WHAT,
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
    betas = {
        "reported_blend": result.blend.beta, "online_blend_causal": result.blend_online.beta,
        "observer_online_causal": core.online.beta,
        **({"observer_online_other_law": result.online_other_law.beta} if result.online_other_law is not None else {}),
        "observer_refined": core.trace.beta, "linear_kf_baseline": result.kalman.beta,
    }  # fmt: skip
    scores = sideslip_scores(t, beta_ref, betas, "reported_blend", "online_blend_causal")
    masks = split_masks(t)
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
    metrics["reference_scores"] = {
        **scores,
        "tire_curve_nrmse": nrmse,
        "covered_slip_range_deg": {k: c.range_deg() for k, c in curves.items()},
        "measured_curve_definition": "binned mean of README's measured (slip, force) samples, 40 bins over the "
        f"0.5-99.5 % slip quantiles, r_dot from a zero-phase {data.cutoff_hz:g} Hz Butterworth-filtered yaw rate",
        "measured_axle_stiffness_near_zero_N_per_rad": near_zero_stiffness(data),
        "targets": {
            **scores["targets"],
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
