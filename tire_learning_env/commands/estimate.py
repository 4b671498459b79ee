"""``tire-learning estimate``: run the observer offline on a driving log."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ..io import DrivingLog, atomic_directory, atomic_write_json, read_log, write_table
from ..params import CameraParams, ParameterError
from ._common import add_vehicle_argument, vehicle_from_args


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimate",
        help="learn the tire curve from a driving log (camera e1/e2, or IMU-only)",
        description="Run the neuro-adaptive observer on a log in the shared format (LOG_FORMAT.md). "
        "Camera logs use e1/e2; IMU-only logs use yaw rate and lateral acceleration. Writes "
        "DIR/estimates.csv, DIR/metrics.json (ground-truth scores when true_* columns exist; "
        "the estimator never reads them), the learned tire curves (PNG and CSV). DIR is replaced atomically.",
    )
    p.add_argument("log", type=Path, help="driving log CSV")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    add_vehicle_argument(p)
    p.add_argument("--camera-noise", type=float, nargs=2, metavar=("E1_STD", "E2_STD"), default=None,
                   help="camera noise std [m] [rad] the gains are designed for (default: noise-free)")
    p.add_argument("--basis", choices=["two_sided", "paper"], default="two_sided", help="activation basis")
    p.add_argument("--no-warm-start", action="store_true", help="single causal pass (no least-squares restart)")
    p.add_argument("--linear-region-deg", type=float, default=0.5,
                   help="warm start: slip below which f_hat is set to zero [deg]; 0 if the nominal stiffness is uncertain")
    p.set_defaults(func=run)


def camera_sensors(log: DrivingLog) -> tuple[dict, float]:
    """Observer rows from a camera log: ``psi_dot_des = vx kappa``, ``psi_ddot_des`` by differentiation."""
    s = log.sensors
    t = s["t"]
    dt = float(np.median(np.diff(t)))
    kappa = np.nan_to_num(s["kappa"])
    pdd = s["vx"] * kappa
    pddd = np.gradient(pdd, t)
    rows = {"t": t, "delta": s["delta"], "vx": s["vx"], "psi_dot_des": pdd, "psi_ddot_des": pddd, "e1": s["e1"], "e2": s["e2"]}
    return rows, dt


def run(args: argparse.Namespace) -> int:
    log = read_log(args.log)
    vehicle = vehicle_from_args(args)
    if log.kind == "imu":
        from ..imu import estimate_imu_log

        metrics = estimate_imu_log(log, vehicle, args.out, basis=args.basis, warm_start=not args.no_warm_start)
        k = metrics["cornering_stiffness"]["final"]["per_axle_N_per_rad"]
        line = f"wrote {args.out}: IMU log, axle stiffness front {k['front']:.0f} N/rad, rear {k['rear']:.0f} N/rad"
        ref = metrics.get("reference_scores")
        if ref:
            rm = ref["sideslip_rmse_deg"]
            line += (f"; sideslip RMSE {rm['observer_online_causal']['whole']:.3f} deg (causal observer), "
                     f"{rm['linear_kf_baseline']['whole']:.3f} deg (linear KF)")  # fmt: skip
        print(line)
        return 0
    return _run_camera(log, vehicle, args)


def _run_camera(log: DrivingLog, vehicle, args) -> int:
    from .. import plotting
    from ..metrics import AXLES, compute_metrics, excited_range
    from ..observer import ObserverConfig, estimate

    rows, dt = camera_sensors(log)
    frames = np.flatnonzero(np.isfinite(rows["e1"]))
    if len(frames) < 10:
        raise ParameterError(f"{log.source}: only {len(frames)} camera frames; too few to estimate anything")
    rate = 1.0 / float(np.median(np.diff(rows["t"][frames])))
    noise = args.camera_noise or (0.0, 0.0)
    camera = CameraParams(rate=rate, noise="gaussian" if any(noise) else "none", e1_noise=noise[0], e2_noise=noise[1])
    config = ObserverConfig(basis=args.basis, warm_start=not args.no_warm_start, linear_region_deg=args.linear_region_deg)
    result = estimate(rows, vehicle, camera, config, physics_dt=dt)
    trace = result.trace
    metrics: dict = {
        "log": log.source,
        "log_notes": log.notes,
        "rows": len(trace.t),
        "camera_rate_hz": rate,
        "cornering_stiffness_estimated": dict(zip(AXLES, result.cornering_stiffness())),
        "excited_slip_range_deg": {
            a: [math.degrees(v) for v in excited_range(trace.slip[:, i])] for i, a in enumerate(AXLES)
        },
        "innovation_rms": {"e1": float(np.sqrt(np.nanmean(trace.innovation[:, 0] ** 2))),
                           "e2": float(np.sqrt(np.nanmean(trace.innovation[:, 1] ** 2)))},
        "diverged": bool(trace.diverged),
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
        metrics["ground_truth"] = compute_metrics(
            t=trace.t, xi_hat=trace.xi, slip_hat=trace.slip, force_nonlinear_hat=trace.force_nonlinear,
            truth=t_truth, curve=result.axle_force, true_curve=true_curve,
            stiffness_hat=result.cornering_stiffness(), stiffness_true=_stiffness_from(true_curve),
            nominal_stiffness=(vehicle.Cf, vehicle.Cr), lmi=result.gains.summary(), runtime_s=result.runtime_s,
        )  # fmt: skip
        metrics["ground_truth"]["note"] = (
            "true curve = binned mean of the log's true (slip, force) samples; true stiffness = its slope near zero"
        )
    with atomic_directory(args.out) as out:
        write_table(out / "estimates.csv", {
            "t": trace.t, "e1_hat": trace.xi[:, 0], "e1_dot_hat": trace.xi[:, 1], "e2_hat": trace.xi[:, 2],
            "e2_dot_hat": trace.xi[:, 3], "alpha_f_hat": trace.slip[:, 0], "alpha_r_hat": trace.slip[:, 1],
            "Fyf_hat": trace.force[:, 0], "Fyr_hat": trace.force[:, 1],
        })  # fmt: skip
        grid = np.radians(np.linspace(-8, 8, 161))
        write_table(out / "tire_curves.csv", {
            "alpha": grid, "Fyf": result.axle_force(grid, "front"), "Fyr": result.axle_force(grid, "rear"),
        })  # fmt: skip
        atomic_write_json(out / "metrics.json", metrics)
        samples = {a: (trace.slip[:, i], trace.force[:, i]) for i, a in enumerate(AXLES)}
        plotting.plot_tire_curves({"learned": result.axle_force}, None, metrics["excited_slip_range_deg"], samples,
                                  title=f"learned tire curves: {Path(log.source).name}", path=out / "tire_curves.png")
    print(f"wrote {args.out}: stiffness per tire front {result.cornering_stiffness()[0]:.0f} N/rad, "
          f"rear {result.cornering_stiffness()[1]:.0f} N/rad")
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
