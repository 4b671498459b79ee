"""``tire-learning discrepancy``: find and name what a nominal vehicle model misses in a log."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "discrepancy",
        help="find where a nominal model and a driving log disagree and name the missing effect",
        description="Compare the nominal model (bicycle + tire) with a driving log (LOG_FORMAT.md) by "
        "multiple-shooting output error, locate the disagreement, fit every candidate effect of the library, "
        "select by likelihood ratio + BIC, and write DIR/report.json, DIR/report.md and PNG figures. Camera logs "
        "(e1, e2, kappa): error-coordinate model, library tire_relaxation, camera_latency, road_bank, "
        "steering_offset, camera_heading_bias, cornering_stiffness_scale, load_transfer, crosswind, "
        "speed_dependent_stiffness. IMU-only logs (yaw_rate, ay, optional ax): body-frame model compared on "
        "yaw_rate and ay, library tire_relaxation, cornering_stiffness_scale, longitudinal_load_transfer, "
        "lateral_load_transfer, steering_offset, steering_compliance, steering_ratio_nonlinearity, steering_delay, "
        "yaw_rate_bias, ay_bias, road_bank, accelerometer_offset, yaw_inertia_scale, speed_dependent_stiffness. "
        "Verdict: found, none or unexplained. DIR is replaced atomically (never left half-written).",
    )
    p.add_argument("log", type=Path, help="driving log CSV: a camera log (e1, e2, kappa) or an IMU-only log "
                   "(yaw_rate, ay)")
    p.add_argument("--out", type=Path, required=True, help="output folder (see --overwrite)")
    p.add_argument("--vehicle", type=Path, default=None,
                   help="nominal vehicle JSON (m, Iz, lf, lr, Cf, Cr, ...); default: the paper's D-class sedan")
    p.add_argument("--tire", choices=["pacejka", "linear", "learned"], default="pacejka",
                   help="nominal tire: Pacejka (default), linear (the vehicle file's stiffness), or the curve the "
                   "observer learns from this log (the IMU observer for an IMU-only log)")
    p.add_argument("--mu", type=float, default=None,
                   help="friction coefficient of the nominal Pacejka tire (default 1.0)")
    p.add_argument("--window", type=float, default=None, help="multiple-shooting window [s] (default 3)")
    p.add_argument("--no-imu", action="store_true", help="ignore yaw_rate / ay even if the log has them")
    p.add_argument("--steering", choices=["auto", "curvature", "linear", "hold"], default="auto",
                   help="steering between logged rows: auto (default: curvature for rows at 40 Hz and more, else the "
                   "better of curvature and linear on the nominal residual), curvature (a sampled controller with a "
                   "curvature feed-forward, like the simulator's driver; IMU-only logs have no curvature and use "
                   "linear), linear (a continuous signal, e.g. a human driver), hold")
    p.add_argument("--no-input-noise", action="store_true",
                   help="do not estimate the steering error between sparse rows (rows sparser than 40 Hz); the "
                   "residual is then taken for measurement noise only")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo null distributions")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..io import read_log
    from ._common import vehicle_from_args
    from ..params import TireParams
    from ..discrepancy import DiscrepancyConfig, analyze, write_report

    log = read_log(args.log)  # LogFormatError names what is wrong
    vehicle = vehicle_from_args(args)  # ParameterError for an unreadable / invalid file
    overrides = {"use_imu": not args.no_imu, "seed": args.seed, "steering": args.steering,
                 "input_noise": not args.no_input_noise}
    if args.window is not None:
        overrides["window"] = args.window
    config = DiscrepancyConfig(**overrides)
    tire_params = TireParams(mu=args.mu) if args.mu is not None else None
    result = analyze(log, vehicle, args.tire, config, progress=not args.no_progress, tire_params=tire_params)
    write_report(result, args.out)
    summary = {
        "verdict": result.verdict,
        "effects": {e["name"]: e["parameters"] for e in result.effects},
        **({"candidates": [c["name"] for c in result.candidates]} if result.verdict == "ambiguous" else {}),
        "gap_ratio": round(result.gap_ratio, 3),
        "runtime_s": round(result.runtime_s, 1),
    }
    print(json.dumps(summary))
    print(f"wrote {args.out}/report.json and {args.out}/report.md")
    return 0
