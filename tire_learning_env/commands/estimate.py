"""``tire-learning estimate``: learn the tire curves from a driving log (camera, IMU or both).

Nothing about the camera, the IMU or the tires needs to be known: the sensor noise, the
camera latency and the cornering stiffness are estimated from the log itself
(:func:`tire_learning_env.observer.estimate`), and ``metrics.json`` records what was estimated
and what was assumed. Flags let a user who *does* know something say so.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from ..io import DrivingLog, atomic_directory, atomic_write_json, read_log, write_table
from ..params import ParameterError
from ._common import add_noise_arguments, add_vehicle_argument, camera_from_noise_args, vehicle_from_args

CAMERA_COLUMNS = ("e1", "e2", "kappa")
IMU_COLUMNS = ("ay", "yaw_rate")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimate",
        help="learn the tire curves from a driving log (camera e1/e2, IMU, or both)",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        description="Run the neuro-adaptive observer on a log in the shared format (LOG_FORMAT.md). The sensor set "
        "is picked from the log's columns (camera e1/e2/kappa, IMU ay/yaw_rate, or both) and printed. Sensor noise, "
        "camera latency and cornering stiffness are estimated from the log unless given. Writes DIR/estimates.csv, "
        "DIR/metrics.json (summary with +/-2 sigma bands and the identifiability verdict; what was estimated and "
        "what was assumed; ground-truth scores when true_* columns exist, which the estimator never reads), "
        "DIR/tire_curves.csv and DIR/tire_curves.png. IMU-only and fused (--sensors both) runs also write the linear "
        "Kalman filter baseline (beta_kf) and, with a reference sideslip column, its RMSE beside the estimate's.",
    )
    p.add_argument("log", type=Path, help="driving log (CSV in the shared format)")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    add_vehicle_argument(p)
    p.add_argument("--sensors", choices=["auto", "camera", "imu", "both"], default="auto",
                   help="measurement model; auto = the camera when the log has one, else the IMU")  # fmt: skip
    p.add_argument("--camera-noise", type=float, nargs=2, metavar=("E1_STD", "E2_STD"), default=None,
                   help="camera noise STANDARD DEVIATION (not a half-width), e1 [m] and e2 [rad]; a uniform "
                        "+/-h noise (HALF-WIDTH h, as simulate --noise uniform/paper) has std h/sqrt(3), e.g. "
                        "simulate --noise paper = 0.00577 0.01008; default: estimated from the log")  # fmt: skip
    add_noise_arguments(p, default="estimated", extra_kinds=("estimated",),
                        extra_help="; estimated = measured from the log (the default). The same grammar as simulate; "
                        "or give STANDARD DEVIATIONS directly with --camera-noise")  # fmt: skip
    p.add_argument("--imu-noise", type=float, nargs=2, metavar=("AY_STD", "R_STD"), default=None,
                   help="IMU noise standard deviation, a_y [m/s^2] and yaw rate [rad/s]; default: estimated from the log")
    p.add_argument("--latency", type=float, default=None, metavar="S",
                   help="camera latency [s]; default: estimated from the log")
    p.add_argument("--stiffness-known", action="store_true",
                   help="trust the vehicle file's Cf, Cr: pin the curve to them in the linear region "
                        "(default: the stiffness is learned)")  # fmt: skip
    p.add_argument("--basis", choices=["two_sided", "paper"], default="two_sided", help="activation basis")
    p.add_argument("--no-offline", action="store_true",
                   help="report the causal (on-line) pass only, without the offline refinement over the whole log")
    p.set_defaults(func=run)


def _has(sensors: dict, name: str) -> bool:
    return name in sensors and bool(np.any(np.isfinite(np.asarray(sensors[name], dtype=float))))


def choose_sensors(log: DrivingLog, requested: str = "auto") -> tuple[str, str]:
    """``(sensors, why)``: the measurement model for ``log`` and a sentence that says why.

    Raises :class:`ParameterError` naming the missing columns when the request cannot be met.
    """
    s = log.sensors
    cam_missing = [c for c in CAMERA_COLUMNS if not _has(s, c)]
    imu_missing = [c for c in IMU_COLUMNS if not _has(s, c)]
    need = {"camera": cam_missing, "imu": imu_missing, "both": cam_missing + imu_missing}
    if requested != "auto":
        if need[requested]:
            raise ParameterError(f"{log.source}: --sensors {requested} needs column(s) {need[requested]} with data")
        return requested, "given (--sensors)"
    if not cam_missing and not imu_missing:
        from ..observer.estimator import FUSION_NOTE

        return "camera", f"the log has camera (e1, e2, kappa) and IMU (ay, yaw_rate) columns; {FUSION_NOTE}"
    if not cam_missing:
        return "camera", "the log has camera columns (e1, e2, kappa) and no IMU columns"
    if not imu_missing:
        partial = [c for c in CAMERA_COLUMNS if c not in cam_missing]
        why = "the log has IMU columns (ay, yaw_rate) and no camera columns"
        if partial:
            why = (f"the log has IMU columns (ay, yaw_rate) but the camera columns {cam_missing} are missing or empty "
                   f"(present: {partial}), so the camera is not used")  # fmt: skip
        return "imu", why
    missing = [f"'{c}'" for c in cam_missing]
    raise ParameterError(
        f"{log.source}: cannot estimate: camera column(s) {', '.join(missing)} missing or empty, and no IMU "
        f"columns {list(IMU_COLUMNS)}"
    )


def config_from_args(args: argparse.Namespace, sensors: str):
    from ..observer import ObserverConfig

    if args.latency is not None and not (math.isfinite(args.latency) and args.latency >= 0):
        raise ParameterError(f"--latency must be a finite number of seconds >= 0, got {args.latency}")
    camera_noise = args.camera_noise
    if args.noise != "estimated":
        if camera_noise is not None:
            raise ParameterError("give the camera noise either as --noise KIND [--e1-noise --e2-noise] or as "
                                 "--camera-noise E1_STD E2_STD, not both")  # fmt: skip
        camera_noise = tuple(camera_from_noise_args(args, 20.0).noise_std)
    return ObserverConfig(
        sensors=sensors, basis=args.basis, camera_noise=camera_noise, imu_noise=args.imu_noise,
        latency=args.latency, stiffness_known=args.stiffness_known, offline=not args.no_offline,
    )  # fmt: skip


def run(args: argparse.Namespace) -> int:
    log = read_log(args.log)
    vehicle = vehicle_from_args(args)
    sensors, why = choose_sensors(log, args.sensors)
    if not getattr(args, "quiet", False):
        print(f"sensors: {sensors} ({why})", file=sys.stderr)
    config = config_from_args(args, sensors)
    if sensors == "imu":
        from ..imu import estimate_imu_log

        metrics = estimate_imu_log(log, vehicle, args.out, config=config)
        print(_imu_line(args.out, metrics))
        return 0
    return _run_camera(log, vehicle, config, args, why)


def _imu_line(out: Path, metrics: dict) -> str:
    line = f"wrote {out}: IMU log"
    summ = metrics.get("summary", {})
    if summ:
        line += "; " + _stiffness_text(summ)
    return line + _reference_text(metrics)


def _reference_text(metrics: dict) -> str:
    """The printed line's part on the reference sideslip scores (IMU-only and fused runs; empty without them)."""
    ref = metrics.get("reference_scores")
    if not ref or "sideslip_rmse_deg" not in ref:
        return ""
    parts = [f"{k} {v['whole']:.3f}" for k, v in ref["sideslip_rmse_deg"].items() if isinstance(v, dict) and "whole" in v]
    text = "; sideslip RMSE [deg]: " + ", ".join(parts)
    comparison = ref.get("reported_vs_linear_kf") or {}
    if comparison.get("reported_worse_than_linear_kf", {}).get("whole"):
        text += f" (the reported {comparison['reported']} is WORSE than the linear KF)"
    return text


def _fused_kf_text(metrics: dict) -> str:
    """The printed line's part on a fused run's linear KF baseline."""
    kf = metrics["baseline_linear_kf"]
    if "skipped" in kf:
        return f"; no linear KF baseline ({kf['skipped']})"
    return "; linear KF baseline in estimates.csv (beta_kf)" + _reference_text(metrics)


def _stiffness_text(summary: dict) -> str:
    reason = summary.get("verdict_reason") or ""
    if summary.get("verdict") != "identified" and "weights at their bound" in reason:
        return f"stiffness NOT IDENTIFIED: {reason} (see metrics.json: calibration.weight_bounds)"
    if summary.get("verdict") != "identified":
        widths = []
        for a in ("front", "rear"):
            band = summary.get(f"stiffness_{a}_2sigma_N_per_rad")
            if band and all(np.isfinite(band)) and band[0] + band[1] > 0:
                widths.append(f"{a} +/-{100 * (band[1] - band[0]) / (band[1] + band[0]):.0f} %")
        detail = f" (2 sigma band {', '.join(widths)})" if widths else ""
        return ("stiffness NOT IDENTIFIABLE from this drive: the band is too wide to name a value" + detail
                + "; too little excitation, too much noise or model mismatch (see metrics.json)")
    out = []
    for a in ("front", "rear"):
        k = summary.get(f"stiffness_{a}_N_per_rad")
        band = summary.get(f"stiffness_{a}_2sigma_N_per_rad")
        if k is None:
            out.append(f"{a} not identifiable")
        else:
            out.append(f"{a} {k:.0f} N/rad (+/-{0.5 * (band[1] - band[0]):.0f}, 2 sigma)")
    text = "stiffness per tire " + ", ".join(out)
    if summary.get("model_error_detected"):
        text += ("; MODEL ERROR detected (the camera innovations turned correlated as the process noise fell: "
                 "dynamics the single-track model lacks, such as tire relaxation or roll); the value may differ "
                 "from the steady-state stiffness by more than its band (metrics.json: summary.model_error_evidence)")
    return text


def _run_camera(log: DrivingLog, vehicle, config, args, why: str) -> int:
    from .. import plotting
    from ..metrics import AXLES, compute_metrics, excited_range
    from ..observer import StateIndex, estimate

    frames = np.flatnonzero(np.isfinite(log.sensors["e1"]))
    if len(frames) < 10:
        raise ParameterError(f"{log.source}: only {len(frames)} camera frames; too few to estimate anything")
    sensors = log.sensors
    imu_x = float(getattr(vehicle, "imu_x", 0.0))
    if imu_x and all(c in sensors for c in IMU_COLUMNS) and getattr(config, "sensors", "camera") != "camera":
        from ..imu.logs import accelerometer_at_cg

        # the model's a_y is the CG's: an accelerometer imu_x ahead of it reads imu_x * r_dot more
        sensors = dict(sensors, ay=accelerometer_at_cg(sensors["t"], sensors["ay"], sensors["yaw_rate"], imu_x))
        log.notes.append(f"ay: accelerometer {imu_x:+g} m ahead of the CG (vehicle file imu_x): ay - imu_x * r_dot used")
    result = estimate(sensors, vehicle, None, config=config)
    steps = result.calibration.get("e1_reexpressions") or {}
    if steps.get("detected"):  # lane changes (or lane-line hand-overs) re-expressed e1: say what was done
        log.notes.append("e1: " + steps["note"] + " (metrics.json: calibration.e1_reexpressions)")
    baseline = None
    if getattr(config, "sensors", "camera") == "both":  # the IMU path's linear KF beside the fused estimate
        from ..imu.fused import fused_linear_kf

        baseline = fused_linear_kf(log, vehicle, config, result.observer.segment_gap_s)
    trace = result.trace
    online = result.online
    summary = result.summary()
    calibration = {k: v for k, v in result.calibration.items() if not k.startswith("_")}
    calibration["sensors_reason"] = why
    k_online = result.observer.cornering_stiffness(result.online_weights)
    calibration["vehicle_source"] = str(args.vehicle) if args.vehicle else "built-in default (the paper's D-class sedan)"
    metrics: dict = {
        "log": log.source,
        "log_notes": log.notes,
        "rows": len(trace.t),
        "summary": summary,
        "stiffness": result.stiffness_report(),
        "learned_slip_range_deg": result.learned_slip_range(),
        "cornering_stiffness_estimated": dict(zip(AXLES, result.cornering_stiffness())),
        "cornering_stiffness_online": dict(zip(AXLES, k_online)),
        "excited_slip_range_deg": {
            a: [math.degrees(v) for v in excited_range(trace.slip[:, i])] for i, a in enumerate(AXLES)
        },
        "innovation_rms": {
            c: float(np.sqrt(np.nanmean(online.innovation[:, j] ** 2)))
            for j, c in enumerate(("e1", "e2", "ay", "yaw_rate"))
            if np.any(np.isfinite(online.innovation[:, j]))
        },
        "health": {"final": online.final_health, "fraction": online.health_fraction},
        "calibration": calibration,
        "lmi": result.gains.summary(),
        "runtime_s": result.runtime_s,
    }
    truth = log.truth
    if all(k in truth for k in ("true_e1", "true_e1_dot", "true_e2", "true_e2_dot", "true_alpha_f", "true_alpha_r", "true_Fyf", "true_Fyr")):
        t_truth = {
            "true_state": np.column_stack([truth[k] for k in ("true_e1", "true_e1_dot", "true_e2", "true_e2_dot")]),
            "true_slip": np.column_stack([truth["true_alpha_f"], truth["true_alpha_r"]]),
            "true_force": np.column_stack([truth["true_Fyf"], truth["true_Fyr"]]),
        }
        true_curve = _empirical_curve(t_truth)
        stiffness_true = _stiffness_from(true_curve)
        scores = {}
        for name, tr, curve, k_hat in (
            ("offline", trace, result.axle_force, result.cornering_stiffness()),
            ("online", online, result.online_axle_force, k_online),
        ):
            scores[name] = compute_metrics(
                t=tr.t, xi_hat=tr.xi, slip_hat=tr.slip, force_nonlinear_hat=tr.force_nonlinear,
                truth=t_truth, curve=curve, true_curve=true_curve, stiffness_hat=k_hat, stiffness_true=stiffness_true,
                nominal_stiffness=(vehicle.Cf, vehicle.Cr), lmi=result.gains.summary(),
                runtime_s=result.runtime_s["total"],
            )  # fmt: skip
        if result.offline is not None:
            gt = scores["offline"]
            gt["online"] = scores["online"]
        else:  # no offline pass: the causal scores are the reported ones (not stored inside themselves)
            gt = dict(scores["online"])
        rep = result.stiffness_report()
        gt["stiffness_inside_2sigma_band"] = {
            a: bool(rep[a]["band_2sigma_N_per_rad"][0] <= stiffness_true[i] <= rep[a]["band_2sigma_N_per_rad"][1])
            for i, a in enumerate(AXLES)
        }
        gt["note"] = "true curve = binned mean of the log's true (slip, force) samples; true stiffness = its slope near zero"
        metrics["ground_truth"] = gt
    if baseline is not None:
        from ..imu.fused import FUSED_BETA_COLUMNS, fused_reference_scores

        metrics["baseline_linear_kf"] = baseline.metrics
        metrics["estimates_csv"] = {k: v for k, v in FUSED_BETA_COLUMNS.items() if k != "beta_kf" or baseline.trace is not None}
        metrics["reference_scores"] = fused_reference_scores(log, trace, online, baseline.trace)
    with atomic_directory(args.out) as out:
        cols = {"t": trace.t}
        names = ("e1_hat", "e1_dot_hat", "e2_hat", "e2_dot_hat")
        xi = trace.xi
        for j, c in enumerate(names):
            cols[c] = xi[:, j]
        cols.update(alpha_f_hat=trace.slip[:, 0], alpha_r_hat=trace.slip[:, 1], Fyf_hat=trace.force[:, 0],
                    Fyr_hat=trace.force[:, 1], vy_hat=trace.state[:, StateIndex.VY], yaw_rate_hat=trace.state[:, StateIndex.R])  # fmt: skip
        if trace.std.size:
            cols.update(vy_std=trace.std[:, StateIndex.VY], yaw_rate_std=trace.std[:, StateIndex.R])
        cols.update(health=online.health.astype(float), alpha_f_online=online.slip[:, 0], alpha_r_online=online.slip[:, 1])
        if baseline is not None:
            cols.update(beta_hat=trace.beta, beta_observer_online=online.beta)
            if baseline.trace is not None:
                cols["beta_kf"] = baseline.trace.beta
        write_table(out / "estimates.csv", cols)
        grid = np.radians(np.linspace(-8, 8, 161))
        write_table(out / "tire_curves.csv", {
            "alpha": grid, "Fyf": result.axle_force(grid, "front"), "Fyf_std": result.axle_force_std(grid, "front"),
            "Fyr": result.axle_force(grid, "rear"), "Fyr_std": result.axle_force_std(grid, "rear"),
            "Fyf_nominal": result.nominal_axle_force(grid, "front"), "Fyr_nominal": result.nominal_axle_force(grid, "rear"),
        })  # fmt: skip
        atomic_write_json(out / "metrics.json", metrics)
        samples = {a: (trace.slip[:, i], trace.force[:, i]) for i, a in enumerate(AXLES)}
        curves = {"learned": result.axle_force, "nominal (vehicle file)": result.nominal_axle_force}
        plotting.plot_tire_curves(curves, None, metrics["excited_slip_range_deg"], samples,
                                  title=f"learned tire curves: {Path(log.source).name}", path=out / "tire_curves.png",
                                  bands={"learned": result.axle_force_std})  # fmt: skip
    line = f"wrote {args.out}: {_stiffness_text(summary)}; health {online.final_health}"
    lat = calibration.get("latency", {})
    if lat.get("source", "").startswith("estimated"):
        line += f"; camera latency estimated {1e3 * lat['latency_s']:.0f} ms"
    if baseline is not None:
        line += _fused_kf_text(metrics)
    print(line)
    return 0


def _empirical_curve(truth: dict):
    """Binned-mean truth curve from logged (slip, force) samples (for logs without a tire model)."""
    curves = []
    for i in (0, 1):
        a, f = truth["true_slip"][:, i], truth["true_force"][:, i]
        edges = np.linspace(a.min(), a.max(), 81)
        idx = np.clip(np.digitize(a, edges) - 1, 0, 79)
        centres, means = [], []
        for k in range(80):
            sel = idx == k
            if sel.sum() >= 5:
                centres.append(a[sel].mean())
                means.append(f[sel].mean())
        curves.append((np.array(centres), np.array(means)))

    def curve(alpha, axle):
        c, m = curves[0 if axle == "front" else 1]
        return np.interp(alpha, c, m)

    return curve


def _stiffness_from(curve) -> tuple[float, float]:
    h = math.radians(0.25)
    return tuple(float((curve(h, a) - curve(-h, a)) / (4 * h)) for a in ("front", "rear"))
